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
        """CSV rows: bin_low, bin_high, count (correct units), count_paper_units."""
        return [
            (repr(float(low)), repr(float(high)), int(n), int(m))
            for low, high, n, m in zip(
                self.edges[:-1], self.edges[1:], self.counts, self.counts_paper, strict=True
            )
        ]


def log_edges(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Bin edges 10 ** (k / BINS_PER_DECADE) with every positive value strictly inside."""
    positive = values[np.isfinite(values) & (values > 0)]
    if positive.size == 0:
        return 10.0 ** (np.arange(-BINS_PER_DECADE, BINS_PER_DECADE + 1) / BINS_PER_DECADE)
    low = math.floor(math.log10(positive.min()) * BINS_PER_DECADE)
    high = math.floor(math.log10(positive.max()) * BINS_PER_DECADE) + 1
    # log10 rounds: widen until the extreme values are really inside.
    while 10.0 ** (low / BINS_PER_DECADE) > positive.min():
        low -= 1
    while 10.0 ** (high / BINS_PER_DECADE) <= positive.max():
        high += 1
    return 10.0 ** (np.arange(low, high + 1) / BINS_PER_DECADE)


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


def figure5(audit: Audit) -> Histogram:
    """Figure 5's histograms of an audit."""
    chosen = population(audit)
    values = audit.metrics.r_normalized[chosen]
    values_paper = audit.metrics.r_normalized_paper[chosen]
    edges = log_edges(np.concatenate([values, values_paper]))
    with np.errstate(invalid="ignore"):
        return Histogram(
            edges=edges,
            counts=_count(values, edges),
            counts_paper=_count(values_paper, edges),
            entries=int(chosen.sum()),
            not_drawn=int((~(values > 0)).sum()),
            not_drawn_paper=int((~(values_paper > 0)).sum()),
            below_one=int((values < 1).sum()),
            below_one_paper=int((values_paper < 1).sum()),
        )
