"""What the vignetting and TCA audits share: their records, the audit of one
kind as columns, and where the derivative of a cubic changes sign.

The records are the rows :mod:`lensaudit.read` reads from every
``<vignetting>`` and ``<tca>`` element (with the lens context a
``<distortion>`` gets, a ``status`` and a ``message``); a file that cannot
be read, is not well-formed or is not a database has a row of its own in
both, so that the vignetting and TCA audits each account for every file.

The numerical kernel both audits share decides where the derivative of a
cubic changes sign exactly on the binary64 inputs.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from fractions import Fraction
from operator import attrgetter, itemgetter
from typing import TYPE_CHECKING, Any

from .formats.csv_format import write_rows
from .metrics import is_circular_fisheye
from .read import read
from .read.paths import DatabaseSource
from .read.records import (
    NAN,
    STATUS_NOT_DATABASE,
    STATUS_OK,
    STATUS_UNREADABLE,
    STATUS_XML_ERROR,
    SourceFile,
)
from .read.tables import SPECS, TCA, VIGNETTING
from .version import __version__

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray


@dataclass(slots=True)
class CalibrationEntry:
    """What every ``<vignetting>`` and ``<tca>`` record starts with: where it is,
    its lens (with the overrides of ``<calibration>`` applied), its model and
    focal length in millimetres."""

    file: str
    line: int
    maker: str
    lens: str
    type: str
    crop_factor: float
    aspect_ratio: float
    model: str
    focal: float


@dataclass(slots=True)
class VignettingEntry(CalibrationEntry):
    """One ``<vignetting>`` element: C(r) = 1 + k1 r^2 + k2 r^4 + k3 r^6.

    r = 1 at half the diagonal of the calibration sensor (see
    :mod:`lensaudit.vignetting`). ``focal`` in millimetres, ``aperture`` an
    f-number, ``distance`` in metres, as Lensfun writes them. Coefficients
    are NaN for entries that were not audited.
    """

    aperture: float = NAN
    distance: float = NAN
    k1: float = NAN
    k2: float = NAN
    k3: float = NAN
    status: str = STATUS_OK
    message: str = ""


@dataclass(slots=True)
class TCAEntry(CalibrationEntry):
    """One ``<tca>`` element: per channel (red, blue), r_d = r (b r^2 + c r + v).

    ``poly3`` fills ``vr vb cr cb br bb``; ``linear`` fills ``kr kb``
    (r_d = k r); the other model's coefficients are NaN. r is in Hugin
    units, 1 = half the short side (see :mod:`lensaudit.tca`).
    """

    kr: float = NAN
    kb: float = NAN
    vr: float = NAN
    vb: float = NAN
    cr: float = NAN
    cb: float = NAN
    br: float = NAN
    bb: float = NAN
    status: str = STATUS_OK
    message: str = ""


#: The entry class of each kind.
ENTRY_CLASSES = {VIGNETTING: VignettingEntry, TCA: TCAEntry}
#: Model names each kind can audit.
MODELS = {kind: tuple(spec.models) for kind, spec in SPECS.items()}


class CalibrationRecords(Sequence[Any]):
    """The records of one kind (``vignetting`` or ``tca``), held as rows.

    A sequence of :class:`VignettingEntry` or :class:`TCAEntry` objects, each
    made when it is asked for; :meth:`column` gives one field of every
    record without making any.
    """

    def __init__(self, kind: str, names: list[str], rows: list[tuple]) -> None:
        self.kind = kind
        self._entry = ENTRY_CLASSES[kind]
        self._names = names  # the file of each row
        self._rows = rows
        self._columns: dict[str, list[Any]] = {}

    @classmethod
    def of_file(cls, kind: str, name: str, rows: list[tuple]) -> CalibrationRecords:
        """The rows of one file, named ``name``."""
        return cls(kind, [name] * len(rows), rows)

    @classmethod
    def of_entries(cls, kind: str, entries: Iterable[Any]) -> CalibrationRecords:
        """Records made from entry objects of ``kind``."""
        if isinstance(entries, CalibrationRecords):
            return entries
        getter = attrgetter("file", *SPECS[kind].row_fields)
        values = [getter(entry) for entry in entries]
        return cls(kind, [v[0] for v in values], [v[1:] for v in values])

    @classmethod
    def joined(cls, kind: str, parts: Iterable[CalibrationRecords]) -> CalibrationRecords:
        """The records of ``parts``, one after the other."""
        names: list[str] = []
        rows: list[tuple] = []
        for part in parts:
            names += part._names
            rows += part._rows
        return cls(kind, names, rows)

    def part(self, start: int, stop: int) -> CalibrationRecords:
        """The records from ``start`` up to ``stop`` (not included)."""
        return CalibrationRecords(self.kind, self._names[start:stop], self._rows[start:stop])

    def __len__(self) -> int:
        return len(self._rows)

    def __getitem__(self, index: Any) -> Any:
        if isinstance(index, slice):
            names, rows = self._names[index], self._rows[index]
            return [self._entry(n, *r) for n, r in zip(names, rows, strict=True)]
        return self._entry(self._names[index], *self._rows[index])

    def __iter__(self) -> Iterator[Any]:
        entry = self._entry
        for name, row in zip(self._names, self._rows, strict=True):
            yield entry(name, *row)

    def __repr__(self) -> str:
        return f"CalibrationRecords({self.kind!r}, {len(self)} records)"

    def each(self, name: str) -> Iterator[Any]:
        """One field of every record, in order, for one pass: unlike :meth:`column`,
        nothing is kept (a rule that looks once leaves no column behind)."""
        if name == "file":
            return iter(self._names)
        if name in self._columns:
            return iter(self._columns[name])
        return map(itemgetter(SPECS[self.kind].row_fields.index(name)), self._rows)

    def column(self, name: str) -> list[Any]:
        """One field of every record, in order; kept, so callers must not change it."""
        if name == "file":
            return self._names
        values = self._columns.get(name)
        if values is None:
            index = SPECS[self.kind].row_fields.index(name)
            values = self._columns[name] = list(map(itemgetter(index), self._rows))
        return values


def load(paths: Any = None) -> Any:
    """The database (see :func:`lensaudit.read.read`) of directories and/or XML
    files, read with its vignetting and TCA rows; the bundled database
    without ``paths``. Raises :class:`lensaudit.read.LoadError` when the paths
    cannot be read at all."""
    return read(paths, calibrations=True)


# ---------------------------------------------------------------------------
# Shared numerics: where the derivative of a cubic changes sign.
#
# Both audits ask where q(x) = c1 + 2 c2 x + 3 c3 x^2, the derivative of
# c0 + c1 x + c2 x^2 + c3 x^3, changes sign: vignetting for C(w) in w = r^2,
# TCA for r_d(r) = v r + c r^2 + b r^3. The floating-point answer is taken
# where it is far from every decision boundary; the rest is decided exactly
# in rational arithmetic on the numbers as written (see as_written).
# ---------------------------------------------------------------------------

#: Relative margin within which a floating-point decision is redone exactly.
#: The computed quantities are accurate to about 1e-7 relative in the worst
#: case the float path accepts (a discriminant 1e-9 of its terms), so a
#: margin of 1e-6 leaves room to spare.
MARGIN = 1e-6
#: Coefficients outside this magnitude (other than 0) go to the exact path, so
#: that no square or product in the float path overflows or underflows.
_SAFE_LOW, _SAFE_HIGH = 2.0**-300, 2.0**300


def _safe(*values: NDArray[np.float64]) -> NDArray[np.bool_]:
    import numpy as np  # numpy: only where arrays are needed, not on importing this module

    ok = np.ones(np.shape(values[0]), dtype=bool)
    for value in values:
        magnitude = np.abs(value)
        ok &= np.isfinite(value) & (
            (magnitude == 0) | ((magnitude > _SAFE_LOW) & (magnitude < _SAFE_HIGH))
        )
    return ok


def turning_points(
    c1: NDArray[np.float64], c2: NDArray[np.float64], c3: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """The roots of c1 + 2 c2 x + 3 c3 x^2 where it changes sign, smaller first.

    Returns (x_low, x_high, reliable): NaN where there is no such root (a
    double root is not a sign change), both roots of the quadratic or the
    one of the linear case. ``reliable`` is False where the float answer
    may be wrong in kind (a discriminant within 1e-9 of its terms, an input
    outside [2^-300, 2^300]); those need :func:`exact_turning_points`.
    """
    import numpy as np  # numpy: only where arrays are needed, not on importing this module

    c1, c2, c3 = (np.asarray(v, dtype=np.float64) for v in (c1, c2, c3))
    low = np.full(c1.shape, np.nan)
    high = np.full(c1.shape, np.nan)
    reliable = _safe(c1, c2, c3)
    with np.errstate(all="ignore"):
        # Quarter discriminant of 3 c3 x^2 + 2 c2 x + c1.
        square, product = c2 * c2, 3.0 * c1 * c3
        discriminant = square - product
        scale = square + np.abs(product)
        quadratic = c3 != 0
        reliable &= ~quadratic | (np.abs(discriminant) > 1e-9 * scale)
        two = quadratic & (discriminant > 0)
        root = np.sqrt(np.where(two, discriminant, 0.0))
        # The stable pair: no subtraction of nearly equal numbers.
        s = -(c2 + np.copysign(root, c2))
        first = s / (3.0 * c3)
        second = np.where(s != 0, c1 / s, 0.0)
        low = np.where(two, np.minimum(first, second), low)
        high = np.where(two, np.maximum(first, second), high)
        linear = ~quadratic & (c2 != 0)
        low = np.where(linear, -(c1 / c2) / 2.0, low)
    return low, high, reliable


def first_sign_change(
    c1: NDArray[np.float64], c2: NDArray[np.float64], c3: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """(x, reliable): the smallest x > 0 where c1 + 2 c2 x + 3 c3 x^2 changes sign.

    ``inf`` where there is none; see :func:`turning_points` for ``reliable``.
    """
    import numpy as np  # numpy: only where arrays are needed, not on importing this module

    low, high, reliable = turning_points(c1, c2, c3)
    with np.errstate(invalid="ignore"):
        x = np.where(low > 0, low, np.where(high > 0, high, np.inf))
    return x, reliable


def as_written(value: float) -> Fraction:
    """A coefficient as the database writes it: the shortest decimal that reads
    back as ``value`` (exact for every decimal of up to 15 significant digits).

    Exact decisions are taken on these rather than on the binary64 values:
    they differ in kind on real entries (k1 + 2 k2 + 3 k3 = 0 in decimal, and
    -2^-60 in binary64, puts a turning point exactly at the frame corner or
    just inside it).
    """
    return Fraction(repr(float(value)))


def sign_of(value: Fraction | int) -> int:
    """-1, 0 or 1: the sign of an exact number."""
    return (value > 0) - (value < 0)


def sign_of_surd(u: Fraction, v: Fraction, d: Fraction) -> int:
    """Sign of u + v sqrt(d) for d >= 0, exactly."""
    su, sv = sign_of(u), sign_of(v) if d else 0
    if sv == 0:
        return su
    if su == 0 or su == sv:
        return sv
    # Opposite signs: the larger square wins.
    return su * sign_of(u * u - v * v * d)


def _sqrt_fraction(d: Fraction, bits: int = 160) -> Fraction:
    """sqrt(d) to about 2^-bits relative (d >= 0), as a fraction."""
    if d == 0:
        return Fraction(0)
    magnitude = d.numerator.bit_length() - d.denominator.bit_length()
    shift = max(0, bits - magnitude // 2)
    return Fraction(math.isqrt((d.numerator << (2 * shift)) // d.denominator), 1 << shift)


def to_float(value: Fraction) -> float:
    """A fraction rounded to a double; beyond the double range, an infinity."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


@dataclass(frozen=True)
class ExactTurn:
    """A root x = (p + e sqrt(d)) / q of the derivative, exactly; e is -1, 0 or 1."""

    p: Fraction
    e: int
    d: Fraction
    q: Fraction

    def sign_minus(self, bound: Fraction) -> int:
        """Sign of x - bound."""
        return sign_of_surd(self.p - bound * self.q, Fraction(self.e), self.d) * sign_of(self.q)

    def value(self) -> Fraction:
        """x to about 2^-150 relative."""
        root = self.e * _sqrt_fraction(self.d)
        if sign_of(self.p) * sign_of(root) < 0:
            # p + e sqrt(d) would cancel: (p^2 - d) / (p - e sqrt(d)) does not.
            return (self.p * self.p - self.d) / ((self.p - root) * self.q)
        return (self.p + root) / self.q


def exact_turning_points(c1: float, c2: float, c3: float) -> list[ExactTurn]:
    """The positive roots of c1 + 2 c2 x + 3 c3 x^2 where it changes sign, in order
    (coefficients taken :func:`as_written`)."""
    a1, a2, a3 = as_written(c1), as_written(c2), as_written(c3)
    roots: list[ExactTurn] = []
    if a3 == 0:
        if a2 != 0:
            roots.append(ExactTurn(-a1, 0, Fraction(0), 2 * a2))
    else:
        discriminant = a2 * a2 - 3 * a1 * a3
        if discriminant > 0:
            # Smaller root first: for a3 > 0 it takes -sqrt, for a3 < 0 +sqrt.
            order = (-1, 1) if a3 > 0 else (1, -1)
            roots = [ExactTurn(-a2, e, discriminant, 3 * a3) for e in order]
    return [root for root in roots if root.sign_minus(Fraction(0)) > 0]


def sign_change_before(
    c1: NDArray[np.float64],
    c2: NDArray[np.float64],
    c3: NDArray[np.float64],
    limit: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """(x, before): the first sign change x of c1 + 2 c2 x + 3 c3 x^2 on (0, inf),
    and whether it lies in (0, limit), the latter exactly (on the numbers
    :func:`as_written`).

    ``x`` is ``inf`` where there is none; it is accurate to about 1e-13
    relative (the kind of answer is exact; the value is float-rounded).
    Any finite coefficients; ``limit`` may be ``inf``. A coefficient that is
    not finite, or a NaN limit, gives x = NaN and ``before`` False.
    """
    import numpy as np  # numpy: only where arrays are needed, not on importing this module

    c1, c2, c3, limit = np.broadcast_arrays(
        *(np.asarray(v, dtype=np.float64) for v in (c1, c2, c3, limit))
    )
    x, reliable = first_sign_change(c1, c2, c3)
    with np.errstate(invalid="ignore"):
        near = np.abs(x - limit) <= MARGIN * limit
        before = x < limit
    doubtful = ~reliable | near | ~np.isfinite(limit) | ~(limit > _SAFE_LOW)
    x = x.copy()
    before = before.copy()
    unknown = ~(np.isfinite(c1) & np.isfinite(c2) & np.isfinite(c3)) | np.isnan(limit)
    x[unknown] = np.nan
    before[unknown] = False
    for index in np.flatnonzero(doubtful & ~unknown):
        a, b, c, bound = (float(v[index]) for v in (c1, c2, c3, limit))
        roots = exact_turning_points(a, b, c)
        x[index] = to_float(roots[0].value()) if roots else math.inf
        before[index] = bool(roots) and (
            math.isinf(bound) or roots[0].sign_minus(as_written(bound)) < 0
        )
    return x, before


# ---------------------------------------------------------------------------
# The audit of one kind, as columns, and its output formats.
# ---------------------------------------------------------------------------

SEVERITY_ERROR = "error"
SEVERITY_WARNING = "warning"
SEVERITY_NOTICE = "notice"
SEVERITIES = (SEVERITY_ERROR, SEVERITY_WARNING, SEVERITY_NOTICE)

#: Statuses about a whole file: reported once per file by the distortion audit.
FILE_STATUSES = frozenset({STATUS_XML_ERROR, STATUS_NOT_DATABASE, STATUS_UNREADABLE})
#: One finding: (severity, code, file, line, message).
Finding = tuple[str, str, str, int, str]


class CalibrationAudit:
    """The audit of every entry of one kind: records and metric columns.

    Subclasses name their columns: :attr:`COLUMNS` in output order,
    :attr:`METRIC_COLUMNS` (numpy arrays in ``metrics``) among them, and
    which of those hold floats or booleans.
    """

    kind = ""
    COLUMNS: tuple[str, ...] = ()
    METRIC_COLUMNS: tuple[str, ...] = ()
    FLOAT_COLUMNS: frozenset[str] = frozenset()
    BOOL_COLUMNS: frozenset[str] = frozenset()

    def __init__(
        self,
        source: Any,
        files: list[SourceFile],
        entries: Sequence[Any],
        metrics: dict[str, Any],
    ) -> None:
        self.source = source
        self.files = files
        self.entries = CalibrationRecords.of_entries(self.kind, entries)
        self.metrics = metrics
        self._audited = [status == STATUS_OK for status in self.entries.column("status")]

    @classmethod
    def of_entries(
        cls,
        entries: Sequence[Any],
        source: Any = None,
        files: list[SourceFile] | None = None,
    ) -> Any:
        """The audit of loaded records (:class:`CalibrationRecords`, or entry
        objects): :meth:`compute_audited` on those with status ``ok``; the
        others' metrics are empty (NaN, False or "")."""
        import numpy as np  # numpy: only where arrays are needed, not on importing this module

        records = CalibrationRecords.of_entries(cls.kind, entries)
        size = len(records)
        ok = np.array(records.column("status"), dtype=object) == STATUS_OK
        rows = np.flatnonzero(ok)
        take = itemgetter(*rows.tolist()) if rows.size > 1 else None

        def values(name: str) -> list[Any]:
            column = records.column(name)
            if take is None:
                return [column[i] for i in rows.tolist()]
            return list(take(column))

        def floats(name: str) -> NDArray[np.float64]:
            return np.array(values(name), dtype=np.float64).reshape(rows.size)

        # One answer per lens: a database has a few hundred lenses for its thousands of entries.
        lenses = list(zip(values("lens"), values("type"), strict=True))
        fisheye = {pair: is_circular_fisheye(*pair) for pair in set(lenses)}
        circular = [fisheye[pair] for pair in lenses]
        metrics: dict[str, Any] = {}
        for name, column in cls.compute_audited(values, floats, circular).items():
            if name in cls.BOOL_COLUMNS:
                full = np.zeros(size, dtype=bool)
            elif name == "severity":
                full = np.full(size, "", dtype=object)
            else:
                full = np.full(size, np.nan)
            full[rows] = column
            metrics[name] = full
        if source is None:
            source = DatabaseSource((), "entries given in memory")
        return cls(source, files or [], records, metrics)

    @classmethod
    def of_database(cls, database: Any) -> Any:
        """The audit of the rows of this kind of a database read with its
        calibrations (see :func:`lensaudit.read.read`)."""
        names, rows = database.rows(cls.kind)
        files = [
            SourceFile(f.name, f.path, len(f.vignetting) + len(f.tca), f.error)
            for f in database.files
        ]
        return cls.of_entries(CalibrationRecords(cls.kind, names, rows), database.source, files)

    @classmethod
    def read(cls, paths: Any = None) -> Any:
        """Audit the entries of this kind in database directories and/or XML
        files (the bundled database without ``paths``). Raises
        :class:`lensaudit.read.LoadError` when the paths cannot be read at all."""
        return cls.of_database(load(paths))

    @staticmethod
    def compute_audited(
        values: Callable[[str], list[Any]],
        floats: Callable[[str], NDArray[np.float64]],
        circular: list[bool],
    ) -> dict[str, Any]:
        """The metric columns (numpy arrays) of audited records; ``values(name)``
        gives a field of every audited record as a list, ``floats(name)`` as a
        float array, and ``circular`` says which are circular fisheyes."""
        raise NotImplementedError

    def __len__(self) -> int:
        return len(self.entries)

    @property
    def audited(self) -> list[bool]:
        """Per entry: whether it was audited (status ``ok``)."""
        return self._audited

    def column(self, name: str) -> list[Any]:
        """One output column as a list: floats (NaN where empty), text, or
        booleans (None for entries that were not audited)."""
        if name not in self.METRIC_COLUMNS:
            return list(self.entries.column(name))
        values = self.metrics[name].tolist()
        if name in self.BOOL_COLUMNS:
            return [bool(v) if ok else None for v, ok in zip(values, self.audited, strict=True)]
        return values

    def columns(self) -> dict[str, list[Any]]:
        """All output columns, in :attr:`COLUMNS` order."""
        return {name: self.column(name) for name in self.COLUMNS}

    def records(self) -> list[dict[str, Any]]:
        """One dict per entry, keys in :attr:`COLUMNS` order."""
        columns = self.columns()
        return [
            dict(zip(self.COLUMNS, row, strict=True)) for row in zip(*columns.values(), strict=True)
        ]

    def to_dataframe(self) -> Any:
        """The entries as a pandas DataFrame with :attr:`COLUMNS`."""
        import pandas  # pandas: only for a DataFrame, which no command needs

        frame = pandas.DataFrame(self.columns(), columns=list(self.COLUMNS))
        frame["line"] = frame["line"].astype("int64")
        for name in self.BOOL_COLUMNS:
            frame[name] = frame[name].astype("boolean")
        return frame

    def statuses(self) -> dict[str, int]:
        """Entries per status, ``ok`` first."""
        counts: dict[str, int] = {STATUS_OK: 0}
        for status in self.entries.column("status"):
            counts[status] = counts.get(status, 0) + 1
        return counts

    def severities(self) -> dict[str, int]:
        """Audited entries per severity (``error``, ``warning``, ``notice``, and ``""``)."""
        counts = {s: 0 for s in (*SEVERITIES, "")}
        for severity, ok in zip(self.metrics["severity"].tolist(), self.audited, strict=True):
            if ok:
                counts[severity] += 1
        return counts

    def summary(self) -> dict[str, Any]:
        """Counts, as plain data (the JSON ``summary``)."""
        return {
            "files": len(self.files),
            "entries": len(self.entries),
            "audited": sum(self.audited),
            "statuses": self.statuses(),
            "severities": {k or "ok": v for k, v in self.severities().items()},
        }

    def lines(self) -> list[str]:
        """The terminal summary as lines of text."""
        raise NotImplementedError

    def head_lines(self, summary: dict[str, Any], entries: str) -> list[str]:
        """The first two lines of the terminal summary: the database, and the
        counts of files and of ``entries`` (say, "TCA entries") read and audited."""
        files = summary["files"]
        return [
            f"lensaudit {__version__}: {self.source.label}",
            f"{files} file{'s' if files != 1 else ''}, "
            f"{summary['entries']} {entries}, {summary['audited']} audited",
        ]

    def problem_lines(self, shown: int = 10) -> list[str]:
        """The entries that were not audited: the first ``shown``, then a count."""
        problems = [self.entries[i] for i, ok in enumerate(self.audited) if not ok]
        if not problems:
            return []
        counts = ", ".join(f"{n} {s}" for s, n in self.statuses().items() if s != STATUS_OK)
        out = ["", f"Not audited: {len(problems)} entries ({counts})"]
        out += [f"  {e.file}:{e.line}: {e.status}: {e.message}" for e in problems[:shown]]
        if len(problems) > shown:
            out.append(f"  ... and {len(problems) - shown} more (all of them: --format csv)")
        return out

    def write(self, output_format: str, stream: Any) -> None:
        """Write as ``table``, ``csv`` or ``json``."""
        {"table": self.write_table, "csv": self.write_csv, "json": self.write_json}[output_format](
            stream
        )

    def write_table(self, stream: Any) -> None:
        stream.write("\n".join(self.lines()) + "\n")

    def write_csv(self, stream: Any) -> None:
        """One row per entry (see :func:`lensaudit.formats.csv_format.write_rows`)."""
        write_rows(stream, self.COLUMNS, self.columns().values())

    def document(self) -> dict[str, Any]:
        """The JSON document as Python data (strict JSON: inf as "inf", NaN as null)."""

        def clean(value: Any) -> Any:
            if isinstance(value, float):
                if value != value:
                    return None
                if math.isinf(value):
                    return "inf" if value > 0 else "-inf"
            return value

        return {
            "lensaudit": __version__,
            "kind": self.kind,
            "database": {
                "label": self.source.label,
                "paths": [str(p) for p in self.source.paths],
                "files": [
                    {"file": f.name, "entries": f.entries, "error": f.error} for f in self.files
                ],
            },
            "summary": self.summary(),
            "entries": [{k: clean(v) for k, v in r.items()} for r in self.records()],
        }

    def write_json(self, stream: Any) -> None:
        import json  # json: a scan in another format does not import it

        json.dump(self.document(), stream, indent=1, allow_nan=False)
        stream.write("\n")
