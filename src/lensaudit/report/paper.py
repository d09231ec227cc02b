"""The paper's Tables 1-2 and named values beside an audit, every difference explained.

The printed values live in ``lensaudit/data/paper_tables.json`` (installed with the
package; ``data/paper_tables.json`` of the source tree links to it).
Each difference gets one line saying where it comes from, found by
computation rather than asserted:

- database version: the entry counts per model differ from the paper's;
- omitted coefficients: Lensfun entries that leave out a coefficient, which
  liblensfun and lensaudit read as 0. Read as undefined (NaN) instead, the
  paper's Algorithm 1 finds no root for them and reports r_max = infinity;
- arithmetic: the paper's Algorithm 1, evaluated here in binary64 exactly as
  printed, against lensaudit's solver;
- units: the paper divides D(r_max), in Hugin units, by a corner radius in
  focal-length units (see :mod:`lensaudit.metrics`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import normalizer
from ..formats.table import text_table
from ..read.paths import lensfunpy_version
from ..read.records import MODEL_COEFFICIENTS
from ..summary import MODELS, TOTAL
from . import select
from .tables import percent, to_markdown

if TYPE_CHECKING:
    from collections.abc import Sequence

    from ..pipeline import Audit
    from ..read import FileTables
    from ..summary import ModelCounts

#: How many entries a difference line names before it says "and N more".
NAMED = 6


class PaperValuesError(Exception):
    """The file of the paper's values is missing or malformed."""


def default_values_path() -> Path:
    """``paper_tables.json`` in the package's ``data`` directory."""
    return Path(__file__).resolve().parents[1] / "data" / "paper_tables.json"


def load_values(path: Path | None = None) -> dict[str, Any]:
    """The paper's printed values (see ``data/paper_tables.json``)."""
    path = path or default_values_path()
    try:
        values = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise PaperValuesError(
            f"the paper's values are not at {path} (they are installed with "
            f"lensaudit as lensaudit/data/paper_tables.json)"
        ) from None
    except (OSError, ValueError) as error:
        raise PaperValuesError(f"cannot read the paper's values from {path}: {error}") from None
    for key in ("table1", "table2", "rectilinear_finite", "rectilinear_below_one", "named_entries"):
        if key not in values:
            raise PaperValuesError(f"{path} has no {key!r}")
    return values


def algorithm1(a: ArrayLike, b: ArrayLike, c: ArrayLike) -> NDArray[np.float64]:
    """The paper's Algorithm 1 (MinPosRoot) in binary64, vectorized, as printed.

    Smallest positive root of 1 + a w + b w^2 + c w^3, or inf. One reading
    is added where the printed pseudocode is silent: a single real root
    (Delta > 0) that is not positive means no positive root. NaN
    coefficients give inf (every comparison with NaN is false).
    """
    a, b, c = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (a, b, c)))
    result = np.full(a.shape, np.inf)
    with np.errstate(all="ignore"):
        cubic = c != 0
        beta = 2 * b**3 - 9 * a * b * c + 27 * c**2
        gamma = b**2 - 3 * a * c
        delta = beta**2 - 4 * gamma**3
        single = cubic & (delta > 0)
        u = np.cbrt((beta + np.sqrt(delta)) / 2)
        root = ((gamma / u) + u + b) / (-3 * c)
        result = np.where(single & (root > 0), root, result)
        three = cubic & ~(delta > 0)
        theta = np.arctan2(np.sqrt(-delta), beta)
        for t in (-1, 0, 1):
            s = (2 * np.sqrt(gamma) * np.cos((theta + 2 * np.pi * t) / 3) + b) / (-3 * c)
            result = np.where(three & (s < result) & (s > 0), s, result)
        quadratic = ~cubic & (b != 0)
        discriminant = a**2 - 4 * b
        denominator = np.sqrt(discriminant) - a
        result = np.where(
            quadratic & (discriminant > 0) & (denominator > 0), 2 / denominator, result
        )
        result = np.where(~cubic & (b == 0) & (a < 0), 1 / -a, result)
    return result


def omitted_coefficients(audit: Audit, files: Sequence[FileTables]) -> dict[int, tuple[str, ...]]:
    """Audited entries whose ``<distortion>`` leaves out coefficients: index -> names.

    ``files`` are the reader's tables the audit was made from, in its order
    (see :class:`lensaudit.report.audits.ReportAudits`).
    """
    omitted = (names for tables in files for names in tables.omitted)
    found = enumerate(zip(omitted, audit.audited.tolist(), strict=True))
    return {index: names for index, (names, audited) in found if names and audited}


def paper_r_max(audit: Audit, omitted: dict[int, tuple[str, ...]]) -> NDArray[np.float64]:
    """r_max as the paper's pipeline plausibly computed it: Algorithm 1 in binary64,
    with omitted coefficients read as NaN. NaN for entries that were not audited."""
    result = np.full(len(audit.entries), np.nan)
    for model in MODELS:
        rows = [i for i, e in enumerate(audit.entries) if audit.audited[i] and e.model == model]
        if not rows:
            continue
        values = {
            name: np.array([_coefficient(audit.entries[i], name, omitted.get(i, ())) for i in rows])
            for name in ("a", "b", "c", "k1", "k2")
        }
        if model == "ptlens":
            cubic = normalizer.ptlens(values["a"], values["b"], values["c"])
        elif model == "poly3":
            cubic = normalizer.poly3(values["k1"])
        else:
            cubic = normalizer.poly5(values["k1"], values["k2"])
        w = algorithm1(cubic.a, cubic.b, cubic.c)
        result[rows] = np.sqrt(w) if cubic.power == 2 else w
    return result


def _coefficient(entry, name: str, omitted: tuple[str, ...]) -> float:
    return math.nan if name in omitted else getattr(entry, name)


@dataclass(frozen=True)
class Comparison:
    """The paper's numbers and this audit's, side by side, and why they differ."""

    database: str
    table1: list[tuple[str, list[tuple[str, str]]]]
    table2: list[tuple[str, list[tuple[str, str]]]]
    other: list[tuple[str, str, str]]
    differences: list[str] = field(default_factory=list)
    agreements: list[str] = field(default_factory=list)


def _where(audit: Audit, indices: list[int] | NDArray[np.int64]) -> str:
    indices = list(indices)
    names = [f"{audit.entries[i].file}:{audit.entries[i].line}" for i in indices[:NAMED]]
    if len(indices) > NAMED:
        names.append(f"and {len(indices) - NAMED} more")
    return ", ".join(names)


def _tables(
    finite: NDArray[np.bool_],
    tail: NDArray[np.int8],
    audited: NDArray[np.bool_],
    model: NDArray[np.str_],
) -> dict[str, dict[str, int]]:
    counts = {}
    for name in (*MODELS, TOTAL):
        mine = audited & ((model == name) if name != TOTAL else True)
        fin = mine & finite
        counts[name] = dict(
            finite=int(fin.sum()),
            infinite=int((mine & ~finite).sum()),
            positive=int((fin & (tail > 0)).sum()),
            negative=int((fin & (tail < 0)).sum()),
        )
    return counts


def compare(
    audit: Audit, values: dict[str, Any], omitted: dict[int, tuple[str, ...]]
) -> Comparison:
    """Compare an audit with the paper's printed values, explaining each difference;
    ``omitted`` are the coefficients its entries leave out (:func:`omitted_coefficients`)."""
    m = audit.metrics
    audited = audit.audited
    model = np.array([e.model for e in audit.entries], dtype=object)
    rectilinear = np.array([e.type == "rectilinear" for e in audit.entries], dtype=bool)
    finite = audited & np.isfinite(m.r_max)
    here = {r.model: r for r in audit.summary.rows}
    paper1 = {row["model"]: row for row in values["table1"]}
    paper2 = {row["model"]: row for row in values["table2"]}

    omitted_mask = np.zeros(len(audit.entries), dtype=bool)
    omitted_mask[list(omitted)] = True
    emulated = paper_r_max(audit, omitted)
    emulated_finite = audited & np.isfinite(emulated)
    emulated_counts = _tables(emulated_finite, m.tail, audited, model)

    differences: list[str] = []
    agreements: list[str] = []
    same_database = all(here[name].total == paper1[name]["total"] for name in paper1)
    (agreements if same_database else differences).append(
        _database_line(here, paper1, same_database)
    )
    explain = _Explainer(audit, omitted_mask, same_database)

    table1 = []
    table2 = []
    for name in (*MODELS, TOTAL):
        r, p1, p2 = here[name], paper1[name], paper2[name]
        table1.append((name, _table1_cells(r, p1)))
        table2.append((name, _table2_cells(r, p2)))
        mine = audited & ((model == name) if name != TOTAL else True)
        differences += _table_differences(
            explain, name, r, p1, p2, mine & finite, m.tail, emulated_counts[name]
        )

    other, found = _rectilinear_finite(explain, values, finite, rectilinear, emulated_finite)
    differences += found
    rows, found = _rectilinear_below_one(audit, values, finite, rectilinear, same_database)
    other += rows
    differences += found

    for named in values["named_entries"]:
        other_row, line = _named(audit, named)
        other.append(other_row)
        (differences if line.startswith("!") else agreements).append(line.lstrip("!"))

    agreements.append(_arithmetic(audit, emulated, omitted_mask))
    if _tables_match(emulated_counts, paper1, paper2) and omitted:
        agreements.append(
            "Reading omitted coefficients as NaN and running Algorithm 1 as printed "
            "reproduces the paper's Tables 1 and 2 exactly."
        )
    return Comparison(database_name(audit), table1, table2, other, differences, agreements)


def _database_line(
    here: dict[str, ModelCounts], paper1: dict[str, Any], same_database: bool
) -> str:
    """Whether the database has the paper's number of entries per model, in one line."""
    if same_database:
        return (
            "Database: the same number of entries per model as the paper's "
            "(" + ", ".join(f"{paper1[n]['total']} {n}" for n in MODELS) + ")."
        )
    return (
        "Database version: this database has "
        + ", ".join(f"{here[n].total} {n}" for n in MODELS)
        + " entries, the paper's "
        + ", ".join(f"{paper1[n]['total']} {n}" for n in MODELS)
        + "; a different Lensfun "
        "revision, so the counts below differ for that reason first."
    )


def _table1_cells(r: ModelCounts, p1: dict[str, Any]) -> list[tuple[str, str]]:
    """One model's Table 1 cells: (paper, here) for finite, infinite, %finite, total."""
    return [
        (str(p1["finite"]), str(r.finite)),
        (str(p1["infinite"]), str(r.infinite)),
        (p1["percent_finite"], percent(r.percent_finite)),
        (str(p1["total"]), str(r.total)),
    ]


def _table2_cells(r: ModelCounts, p2: dict[str, Any]) -> list[tuple[str, str]]:
    """One model's Table 2 cells: (paper, here) for positive, negative, %negative, total."""
    return [
        (str(p2["positive"]), str(r.positive)),
        (str(p2["negative"]), str(r.negative)),
        (p2["percent_negative"], percent(r.percent_negative)),
        (str(p2["total"]), str(r.finite)),
    ]


@dataclass(frozen=True)
class _Explainer:
    """What a difference is explained against: omitted coefficients and the database."""

    audit: Audit
    omitted_mask: NDArray[np.bool_]
    same_database: bool

    def line(
        self, head: str, counted: NDArray[np.bool_], what: str, mine: int, paper: int, emulated: int
    ) -> str:
        """One line: the difference and the computed reason for it."""
        with_omitted = np.flatnonzero(counted & self.omitted_mask)
        if with_omitted.size and mine - with_omitted.size == paper and emulated == paper:
            return (
                f"{head}: {with_omitted.size} of them omit a coefficient in the XML "
                f"({_where(self.audit, with_omitted)}); liblensfun and lensaudit read it as 0 "
                f"and find {what}; read as NaN, Algorithm 1 returns infinity for them, "
                f"which gives the paper's {paper}."
            )
        if not self.same_database:
            return f"{head}: database version (different entries; see the first line)."
        if emulated == paper:
            return (
                f"{head}: the paper's Algorithm 1 in binary64 gives {emulated}, lensaudit's "
                f"solver {mine} (arithmetic; see the solver's accuracy tests)."
            )
        return f"{head}: not explained by database version, omitted coefficients or arithmetic."


def _table_differences(
    explain: _Explainer,
    name: str,
    r: ModelCounts,
    p1: dict[str, Any],
    p2: dict[str, Any],
    finite: NDArray[np.bool_],
    tail: NDArray[np.int8],
    emulated_counts: dict[str, int],
) -> list[str]:
    """One model's differences from the paper's Tables 1 and 2; ``finite``: its
    audited entries with a finite r_max."""
    differences = []
    if (r.finite, r.infinite) != (p1["finite"], p1["infinite"]):
        differences.append(
            explain.line(
                f"Table 1, {name}: finite {r.finite} here, {p1['finite']} in the paper",
                finite,
                "a finite r_max",
                r.finite,
                p1["finite"],
                emulated_counts["finite"],
            )
        )
    for column in ("positive", "negative"):
        mine_value, paper_value = getattr(r, column), p2[column]
        if mine_value != paper_value:
            sign = 1 if column == "positive" else -1
            head = f"Table 2, {name}: {column} {mine_value} here, {paper_value} in the paper"
            differences.append(
                explain.line(
                    head,
                    finite & (tail == sign),
                    f"a {column} tail",
                    mine_value,
                    paper_value,
                    emulated_counts[column],
                )
            )
    return differences


def _rectilinear_finite(
    explain: _Explainer,
    values: dict[str, Any],
    finite: NDArray[np.bool_],
    rectilinear: NDArray[np.bool_],
    emulated_finite: NDArray[np.bool_],
) -> tuple[list[tuple[str, str, str]], list[str]]:
    """(rows, differences): rectilinear entries with a finite r_max, here and in the paper."""
    rect_finite = int((finite & rectilinear).sum())
    rows = [
        (
            "rectilinear entries with finite r_max",
            str(values["rectilinear_finite"]),
            str(rect_finite),
        )
    ]
    differences = []
    if rect_finite != values["rectilinear_finite"]:
        emulated_rect = int((emulated_finite & rectilinear).sum())
        differences.append(
            explain.line(
                f"Rectilinear with finite r_max: {rect_finite} here, "
                f"{values['rectilinear_finite']} in the paper",
                finite & rectilinear,
                "a finite r_max",
                rect_finite,
                values["rectilinear_finite"],
                emulated_rect,
            )
        )
    return rows, differences


def _rectilinear_below_one(
    audit: Audit,
    values: dict[str, Any],
    finite: NDArray[np.bool_],
    rectilinear: NDArray[np.bool_],
    same_database: bool,
) -> tuple[list[tuple[str, str, str]], list[str]]:
    """(rows, differences): rectilinear entries with r_normalized < 1, in the paper's
    units and in correct ones."""
    m = audit.metrics
    with np.errstate(invalid="ignore"):
        below_paper = np.flatnonzero(finite & rectilinear & (m.r_normalized_paper < 1))
        below = np.flatnonzero(finite & rectilinear & (m.r_normalized < 1))
    rows = [
        (
            "rectilinear entries with r_normalized < 1, paper's units",
            str(values["rectilinear_below_one"]),
            str(below_paper.size),
        ),
        ("rectilinear entries with r_normalized < 1, correct units", "", str(below.size)),
    ]
    differences = []
    if below_paper.size != values["rectilinear_below_one"]:
        differences.append(
            f"Rectilinear entries below 1 in the paper's units: {below_paper.size} here "
            f"({_where(audit, below_paper)}), {values['rectilinear_below_one']} in the paper; "
            + (
                "same database counts, so a change of coefficients or of the solver"
                if same_database
                else "a different database revision"
            )
        )
    below = below[np.argsort(m.r_normalized[below], kind="stable")]
    if set(below.tolist()) != set(below_paper.tolist()):
        listed = "; ".join(f"{_name(audit, i)} {m.r_normalized[i]:.3f}" for i in below[:NAMED])
        differences.append(
            f"Units: with the corner in the same Hugin units as D(r_max), hypot(aspect, 1), "
            f"{below.size} rectilinear entries fold inside their image ({listed}); the paper's "
            f"Eq. 29 corner hypot(18, 12) / (crop * focal) is in focal-length units and agrees "
            f"with the Hugin-unit corner only where crop * focal is near 12 mm (3:2 images)."
        )
    return rows, differences


def _tables_match(
    emulated_counts: dict[str, dict[str, int]], paper1: dict[str, Any], paper2: dict[str, Any]
) -> bool:
    """Whether Algorithm 1 as the paper ran it gives every count of its Tables 1 and 2."""
    return all(
        emulated_counts[n]["finite"] == paper1[n]["finite"]
        and emulated_counts[n]["infinite"] == paper1[n]["infinite"]
        and emulated_counts[n]["positive"] == paper2[n]["positive"]
        and emulated_counts[n]["negative"] == paper2[n]["negative"]
        for n in (*MODELS, TOTAL)
    )


def database_name(audit: Audit) -> str:
    """How the compared database is named: its label, without local paths for the bundled one."""
    if audit.source.bundled:
        return f"the Lensfun database bundled with lensfunpy {lensfunpy_version()}"
    return audit.source.label


def _name(audit: Audit, index: int) -> str:
    entry = audit.entries[index]
    return f"{entry.lens} at {entry.focal:g} mm ({entry.file}:{entry.line})"


def _named(audit: Audit, named: dict[str, Any]) -> tuple[tuple[str, str, str], str]:
    label = f"r_normalized of {named['printed_as']} ({named['where_in_paper']})"
    query = select.Query(named["lens"], named.get("focal"), named.get("crop"))
    try:
        index = select.by_query(audit, query)
    except select.SelectionError as error:
        return (label, f"{named['r_normalized']:.3f}", "-"), f"!{label}: {error}."
    m = audit.metrics
    mine = float(m.r_normalized_paper[index])
    correct = float(m.r_normalized[index])
    row = (label, f"{named['r_normalized']:.3f}", f"{mine:.3f} (correct units {correct:.3f})")
    entry = audit.entries[index]
    where = f"{entry.file}:{entry.line}"
    if round(mine, 3) == named["r_normalized"]:
        return row, (
            f"{named['printed_as']} ({where}): {mine:.3f} in the paper's units, as "
            f"printed; {correct:.3f} in correct units."
        )
    d_max = float(m.d_max[index])
    corner = float(m.r_corner_paper[index])
    coefficients = ", ".join(
        f"{n}={getattr(entry, n):g}" for n in MODEL_COEFFICIENTS.get(entry.model, ())
    )
    return row, (
        f"!{named['printed_as']} ({where}): {mine:.3f} here, {named['r_normalized']} "
        f"printed. With {coefficients}, D(r_max) = {d_max:.4f} and the paper's corner "
        f"{corner:.4f} give {mine:.3f}; the printed value would need D(r_max) = "
        f"{named['r_normalized'] * corner:.4f}. Not explained by units or arithmetic "
        f"(correct units: {correct:.3f})."
    )


def _arithmetic(
    audit: Audit, emulated: NDArray[np.float64], omitted_mask: NDArray[np.bool_]
) -> str:
    m = audit.metrics
    usable = audit.audited & ~omitted_mask & (m.r_max != 0)
    disagree = np.flatnonzero(usable & (np.isfinite(emulated) != np.isfinite(m.r_max)))
    both = usable & np.isfinite(emulated) & np.isfinite(m.r_max)
    with np.errstate(invalid="ignore", divide="ignore"):
        relative = np.where(both, np.abs(emulated - m.r_max) / np.abs(m.r_max), 0.0)
    worst = int(np.argmax(relative)) if relative.size else 0
    total = int(usable.sum())
    if disagree.size:
        text = (
            f"Arithmetic: the paper's Algorithm 1 in binary64 and lensaudit's solver "
            f"disagree on whether r_max is finite for {disagree.size} of {total} entries"
        )
    else:
        text = (
            f"Arithmetic: the paper's Algorithm 1 in binary64 and lensaudit's solver "
            f"agree on whether r_max is finite for all {total} entries"
        )
    if disagree.size:
        text += f" ({_where(audit, disagree)})"
    if both.any():
        entry = audit.entries[worst]
        text += (
            f"; the largest relative difference in r_max is {relative[worst]:.1e} "
            f"({entry.file}:{entry.line})"
        )
    return text + "."


def text_lines(comparison: Comparison) -> list[str]:
    """The comparison as plain text, for a terminal."""
    out = [
        f"The paper's values (left of |) beside lensaudit's (right) for {comparison.database}",
        "",
    ]
    for title, header, rows in (
        ("Table 1", ["model", "finite", "infinite", "%finite", "total"], comparison.table1),
        ("Table 2", ["model", "positive", "negative", "%negative", "total"], comparison.table2),
    ):
        out.append(f"{title} (paper | lensaudit)")
        out += text_table(
            header, [[name] + [f"{p} | {h}" for p, h in cells] for name, cells in rows]
        )
        out.append("")
    out.append("Other values (paper | lensaudit)")
    out += text_table(
        ["quantity", "paper", "lensaudit"], comparison.other, right=[False, True, False]
    )
    out.append("")
    out.append(f"Differences ({len(comparison.differences)}), one line each:")
    out += [f"- {line}" for line in comparison.differences] or ["- none"]
    out.append("")
    out.append("Agreements:")
    out += [f"- {line}" for line in comparison.agreements]
    return out


def markdown(comparison: Comparison) -> str:
    """The comparison as Markdown (``paper_comparison.md`` of a report)."""
    out = [
        f"# The paper reproduced: {comparison.database}",
        "",
        "Each cell: the paper's printed value | lensaudit's.",
        "",
    ]
    for title, header, rows in (
        ("Table 1", ("model", "finite", "infinite", "%finite", "total"), comparison.table1),
        ("Table 2", ("model", "positive", "negative", "%negative", "total"), comparison.table2),
    ):
        out.append(
            to_markdown(
                header,
                [[name] + [f"{p} | {h}" for p, h in cells] for name, cells in rows],
                caption=f"## {title}",
            )
        )
    out.append(
        to_markdown(("quantity", "paper", "lensaudit"), comparison.other, caption="## Other values")
    )
    out.append("## Differences, one line each\n")
    out += [f"- {line}" for line in comparison.differences] or ["- none"]
    out.append("\n## Agreements\n")
    out += [f"- {line}" for line in comparison.agreements]
    return "\n".join(out) + "\n"
