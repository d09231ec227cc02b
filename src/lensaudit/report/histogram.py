"""The data of the paper's Figure 5: a log-binned histogram of finite r_normalized.

As in the paper, the population is the rectilinear entries whose r_max is
finite. Two histograms share the bins: ``r_normalized`` in correct units
(D(r_max) over the corner hypot(aspect, 1), both Hugin units) and the
paper's mixed-unit ``r_normalized_paper``. Values that cannot be drawn on a
log axis (r_normalized <= 0: the model decreases from the centre, r_max = 0)
are counted in ``not_drawn``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    from ..pipeline import Audit

#: Bins per decade of r_normalized; edges are 10 ** (k / BINS_PER_DECADE).
BINS_PER_DECADE = 10
#: Significant digits of the bin edges. The edges *are* these decimals, so that
#: the CSV states them exactly, whatever the platform's ``pow`` rounds to.
EDGE_DIGITS = 6

POPULATION = "rectilinear"


@dataclass(frozen=True)
class Histogram:
    """Counts per bin ``[edges[i], edges[i+1])`` for both unit conventions."""

    edges: NDArray[np.float64]
    counts: NDArray[np.int64]
    counts_paper: NDArray[np.int64]
    entries: int
    not_drawn: int
    not_drawn_paper: int
    below_one: int
    below_one_paper: int

    def rows(self) -> list[tuple[str, str, int, int]]:
        """CSV rows: bin_low, bin_high, count (correct units), count_paper_units.

        Edges are written as the decimals they were rounded to
        (:func:`edge_text`), so that two runs give the same bytes.
        """
        return [
            (edge_text(low), edge_text(high), int(n), int(m))
            for low, high, n, m in zip(
                self.edges[:-1], self.edges[1:], self.counts, self.counts_paper, strict=True
            )
        ]


def edge_text(edge: float) -> str:
    """A bin edge as written in the CSV: :data:`EDGE_DIGITS` significant digits."""
    return f"{float(edge):.{EDGE_DIGITS}g}"


def edge(k: int) -> float:
    """The k-th bin edge: 10 ** (k / BINS_PER_DECADE) rounded to :data:`EDGE_DIGITS` digits.

    Edge 0 is exactly 1, so r_normalized < 1 is exactly the bins below it.
    Beyond the largest float the edge is infinite.
    """
    try:
        return float(edge_text(10.0 ** (k / BINS_PER_DECADE)))
    except OverflowError:
        return math.inf


def log_edges(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Bin edges :func:`edge` (k) with every positive value strictly inside.

    Always spans 1, so that the bins below 1 (entries folding inside their
    image) have a place even when no value lies there.
    """
    positive = values[np.isfinite(values) & (values > 0)]
    if positive.size == 0:
        low, high = -BINS_PER_DECADE, BINS_PER_DECADE
    else:
        smallest, largest = float(positive.min()), float(positive.max())
        low = min(math.floor(math.log10(smallest) * BINS_PER_DECADE), -1)
        high = max(math.floor(math.log10(largest) * BINS_PER_DECADE) + 1, 1)
        # log10 and the rounded edges may be off by one bin: widen until the
        # extreme values are really inside.
        while edge(low) > smallest:
            low -= 1
        while edge(high) <= largest:
            high += 1
    return np.array([edge(k) for k in range(low, high + 1)], dtype=np.float64)


def _count(values: NDArray[np.float64], edges: NDArray[np.float64]) -> NDArray[np.int64]:
    drawn = values[np.isfinite(values) & (values > 0)]
    index = np.searchsorted(edges, drawn, side="right") - 1
    return np.bincount(index, minlength=edges.size - 1).astype(np.int64)


def population(audit: Audit) -> NDArray[np.bool_]:
    """Mask of the entries Figure 5 is about: audited, rectilinear, finite r_max."""
    rectilinear = np.fromiter(
        (e.type == POPULATION for e in audit.entries), bool, len(audit.entries)
    )
    return audit.audited & rectilinear & np.isfinite(audit.metrics.r_max)


def from_values(values: NDArray[np.float64], values_paper: NDArray[np.float64]) -> Histogram:
    """Figure 5's histograms of r_normalized in correct units and in the paper's.

    Both arrays hold one value per entry of the population. Values a log axis
    cannot show (zero, negative, NaN) are counted in ``not_drawn``; infinite
    ones are left out of the bins too. The result does not depend on the
    order of the entries.
    """
    values = np.asarray(values, dtype=np.float64)
    values_paper = np.asarray(values_paper, dtype=np.float64)
    edges = log_edges(np.concatenate([values, values_paper]))
    with np.errstate(invalid="ignore"):
        return Histogram(
            edges=edges,
            counts=_count(values, edges),
            counts_paper=_count(values_paper, edges),
            entries=int(values.size),
            not_drawn=int((~(values > 0)).sum()),
            not_drawn_paper=int((~(values_paper > 0)).sum()),
            below_one=int((values < 1).sum()),
            below_one_paper=int((values_paper < 1).sum()),
        )


def figure5(audit: Audit) -> Histogram:
    """Figure 5's histograms of an audit (its :func:`population`)."""
    chosen = population(audit)
    return from_values(audit.metrics.r_normalized[chosen], audit.metrics.r_normalized_paper[chosen])
