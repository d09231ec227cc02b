"""Counts over an audit: the paper's Table 1 and Table 2, statuses, folds.

Table 1 counts audited entries per model by finite or infinite r_max;
Table 2 counts the finite ones by the sign of D(r) beyond r_max.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from .loader import MODEL_COEFFICIENTS

if TYPE_CHECKING:
    from .pipeline import Audit

MODELS = tuple(MODEL_COEFFICIENTS)
TOTAL = "Total"


@dataclass(frozen=True)
class ModelCounts:
    """One row of Tables 1 and 2 (``model`` is a model name or "Total")."""

    model: str
    finite: int
    infinite: int
    positive: int
    negative: int

    @property
    def total(self) -> int:
        return self.finite + self.infinite

    @property
    def percent_finite(self) -> float:
        return 100.0 * self.finite / self.total if self.total else float("nan")

    @property
    def percent_negative(self) -> float:
        return 100.0 * self.negative / self.finite if self.finite else float("nan")


@dataclass(frozen=True)
class Summary:
    """What the audit found, in numbers.

    ``folding`` lists the indices (into the audit's entries) of entries whose
    fold lies inside their own image, by increasing r_normalized.
    ``folding_paper_units`` counts rectilinear entries the paper's mixed-unit
    formula would call folding, for comparison with the paper.
    """

    entries: int
    audited: int
    files: int
    statuses: dict[str, int]
    rows: list[ModelCounts]
    folding: list[int]
    folding_rectilinear: int
    folding_paper_units_rectilinear: int
    models_not_audited: dict[str, int] = field(default_factory=dict)

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


def summarize(audit: Audit) -> Summary:
    """Tables 1 and 2, status counts and the folding entries of an audit."""
    entries = audit.entries
    m = audit.metrics
    audited = audit.audited
    model = np.array([e.model for e in entries], dtype=object)
    rectilinear = np.array([e.type == "rectilinear" for e in entries], dtype=bool)
    finite = audited & np.isfinite(m.r_max)
    rows = []
    for name in MODELS:
        mine = audited & (model == name)
        rows.append(_counts(name, mine, finite, m.tail))
    rows.append(_counts(TOTAL, audited, finite, m.tail))
    folding = np.flatnonzero(m.folds_in_image)
    folding = folding[np.argsort(m.r_normalized[folding], kind="stable")]
    with np.errstate(invalid="ignore"):
        paper_folds = finite & rectilinear & (m.r_normalized_paper < 1)
    statuses = Counter(e.status for e in entries)
    not_audited = Counter(e.model or "(none)" for e in entries if e.status != "ok")
    return Summary(
        entries=len(entries),
        audited=int(audited.sum()),
        files=len(audit.files),
        statuses=dict(sorted(statuses.items(), key=lambda kv: (kv[0] != "ok", kv[0]))),
        rows=rows,
        folding=folding.tolist(),
        folding_rectilinear=int((m.folds_in_image & rectilinear).sum()),
        folding_paper_units_rectilinear=int(paper_folds.sum()),
        models_not_audited=dict(not_audited),
    )


def _counts(name: str, mask: np.ndarray, finite: np.ndarray, tail: np.ndarray) -> ModelCounts:
    fin = mask & finite
    return ModelCounts(
        model=name,
        finite=int(fin.sum()),
        infinite=int((mask & ~finite).sum()),
        positive=int((fin & (tail > 0)).sum()),
        negative=int((fin & (tail < 0)).sum()),
    )
