"""Counts over an audit: the paper's Table 1 and Table 2, statuses, folds.

Table 1 counts audited entries per model by finite or infinite r_max;
Table 2 counts the finite ones by the sign of D(r) beyond r_max.

A summary is made of a tally of the entries (:func:`tally`): the entries
counted by everything the tables tell apart, and the folding entries.
"""

from __future__ import annotations

import math
from collections import Counter, namedtuple
from itertools import compress

from .read.records import MODEL_COEFFICIENTS, STATUS_OK

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any, Protocol

    class Audit(Protocol):
        """What a summary needs of an audit (see :class:`lensaudit.pipeline.Audit`)."""

        files: list

        def __len__(self) -> int: ...
        def entry_column(self, name: str) -> list: ...
        def metric_columns(self) -> dict[str, list]: ...


MODELS = tuple(MODEL_COEFFICIENTS)
TOTAL = "Total"


# Named tuples, not dataclasses: every scan that prints a summary imports
# this module, and making a dataclass costs more than the class is worth.


class ModelCounts(
    namedtuple("ModelCounts", ("model", "finite", "infinite", "positive", "negative"))
):
    """One row of Tables 1 and 2 (``model`` is a model name or "Total"): audited
    entries with a ``finite`` and an ``infinite`` r_max, and of the finite
    ones, those whose D(r) beyond r_max is ``positive`` or ``negative``."""

    __slots__ = ()

    @property
    def total(self) -> int:
        return self.finite + self.infinite

    @property
    def percent_finite(self) -> float:
        return 100.0 * self.finite / self.total if self.total else float("nan")

    @property
    def percent_negative(self) -> float:
        return 100.0 * self.negative / self.finite if self.finite else float("nan")


class Summary(
    namedtuple(
        "Summary",
        (
            "entries",
            "audited",
            "files",
            "statuses",
            "rows",
            "folding",
            "folding_rectilinear",
            "folding_paper_units_rectilinear",
            "models_not_audited",
        ),
    )
):
    """What the audit found, in numbers.

    ``entries``, ``audited`` and ``files`` are counts; ``statuses`` counts
    entries by status; ``rows`` are the :class:`ModelCounts` of each model,
    then of all. ``folding`` lists the indices (into the audit's entries) of
    entries whose fold lies inside their own image, by increasing
    r_normalized, ``folding_rectilinear`` counts the rectilinear ones.
    ``folding_paper_units_rectilinear`` counts rectilinear entries the
    paper's mixed-unit formula would call folding, for comparison with the
    paper. ``models_not_audited`` counts entries not audited, by model.
    """

    __slots__ = ()

    @property
    def total(self) -> ModelCounts:
        return self.rows[-1]

    def table1(self) -> list[dict[str, Any]]:
        """Rows of Table 1: model, finite, infinite, percent_finite, total."""
        return [
            dict(
                model=r.model,
                finite=r.finite,
                infinite=r.infinite,
                percent_finite=r.percent_finite,
                total=r.total,
            )
            for r in self.rows
        ]

    def table2(self) -> list[dict[str, Any]]:
        """Rows of Table 2: model, positive, negative, percent_negative, total."""
        return [
            dict(
                model=r.model,
                positive=r.positive,
                negative=r.negative,
                percent_negative=r.percent_negative,
                total=r.finite,
            )
            for r in self.rows
        ]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return dict(
            entries=self.entries,
            audited=self.audited,
            files=self.files,
            statuses=self.statuses,
            table1=self.table1(),
            table2=self.table2(),
            folds_in_image=len(self.folding),
            folds_in_image_rectilinear=self.folding_rectilinear,
            folds_in_image_paper_units_rectilinear=self.folding_paper_units_rectilinear,
            not_audited_by_model=self.models_not_audited,
        )


#: A tally: entries counted by (model, status, finite r_max, tail
#: sign, rectilinear, paper's r_normalized < 1), as pairs (key, number); and
#: its folding entries as (index in the file, r_normalized, rectilinear).
Tally = tuple


def tally(
    models: list[str], statuses: list[str], types: list[str], metrics: dict[str, list]
) -> Tally:
    """The tally of entries given as columns of the same length, for :func:`summarize`."""
    # Counted at C speed, by everything the tables tell apart.
    kinds = Counter(
        zip(
            models,
            statuses,
            map(math.isfinite, metrics["r_max"]),
            metrics["tail"],
            map("rectilinear".__eq__, types),
            map((1.0).__gt__, metrics["r_normalized_paper"]),
            strict=True,
        )
    )
    r_normalized = metrics["r_normalized"]
    folding = [
        (index, r_normalized[index], types[index] == "rectilinear")
        for index in compress(range(len(statuses)), metrics["folds_in_image"])
    ]
    return list(kinds.items()), folding


def summarize(audit: Audit) -> Summary:
    """Tables 1 and 2, status counts and the folding entries of an audit, from
    the tally of its entries (see :func:`tally`).

    Counted in plain Python: a summary needs neither the entries as objects
    nor numpy.
    """
    # model name -> [finite, infinite, positive, negative] over audited entries
    counts = {name: [0, 0, 0, 0] for name in (*MODELS, TOTAL)}
    audited = paper_folds = 0
    not_audited: Counter[str] = Counter()
    found: Counter[str] = Counter()
    columns = [audit.entry_column(name) for name in ("model", "status", "type")]
    kinds, folding = tally(*columns, audit.metric_columns())
    for (model, status, finite, sign, rectilinear, paper_below_one), number in kinds:
        found[status] += number
        if status != STATUS_OK:
            not_audited[model or "(none)"] += number
            continue
        audited += number
        if finite:
            row = (number, 0, number if sign > 0 else 0, number if sign < 0 else 0)
            paper_folds += number if rectilinear and paper_below_one else 0
        else:
            row = (0, number, 0, 0)
        for key in (model, TOTAL) if model in MODELS else (TOTAL,):
            counts[key] = [total + value for total, value in zip(counts[key], row, strict=True)]
    # By r_normalized, ties in entry order; NaN (never a fold, but safe) last.
    folding.sort(key=lambda fold: (fold[1] != fold[1], fold[1]))
    return Summary(
        entries=len(audit),
        audited=audited,
        files=len(audit.files),
        statuses=dict(sorted(found.items(), key=lambda kv: (kv[0] != "ok", kv[0]))),
        rows=[ModelCounts(name, *counts[name]) for name in (*MODELS, TOTAL)],
        folding=[index for index, _, _ in folding],
        folding_rectilinear=sum(rectilinear for _, _, rectilinear in folding),
        folding_paper_units_rectilinear=paper_folds,
        models_not_audited=dict(not_audited),
    )
