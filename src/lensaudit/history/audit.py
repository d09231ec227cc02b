"""Stage 4, audit: each distinct (model, coefficients, crop factor, aspect
ratio, focal, image circle) audited once, however many file versions repeat
it, then counted per file version and summed per revision."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from .. import loader
from ..loader import MODEL_COEFFICIENTS, STATUS_OK, DistortionEntry
from .commits import Commit
from .parse import Pieces, Summary, summarize
from .results import COUNT_COLUMNS, MODELS, Revision

if TYPE_CHECKING:
    from .. import metrics


@dataclass(frozen=True)
class BlobAudit:
    """What one file version holds: its error, :data:`COUNT_COLUMNS`, and the
    identities (interned) of its audited entries, in file order."""

    error: str
    counts: tuple[int, ...]
    idents: tuple[int, ...]


class Interner:
    """Small integers for equal tuples: identities compared and hashed cheaply."""

    def __init__(self) -> None:
        self.ids: dict[tuple, int] = {}
        self.values: list[tuple] = []

    def __call__(self, value: tuple) -> int:
        found = self.ids.get(value)
        if found is None:
            found = self.ids[value] = len(self.values)
            self.values.append(value)
        return found


@dataclass
class Parsed:
    """One file version just parsed: its audited entries as interned identities
    and audit keys; the entries themselves only when asked to keep them."""

    entries: int
    error: str
    idents: list[int]
    audit_keys: list[int]
    rectilinear: list[bool]
    kept: list[DistortionEntry] | None = None


class Auditor:
    """Parses file versions, then audits each distinct (model, coefficients,
    crop factor, aspect ratio, focal, image circle) once, however many versions
    repeat it."""

    def __init__(self) -> None:
        self.idents = Interner()
        self.audit_keys = Interner()
        self.metrics: metrics.Metrics | None = None
        # piece digest -> (entries, interned identities, audit keys, rectilinear)
        self.pieces: dict[bytes, tuple[int, list[int], list[int], list[bool]]] = {}

    def parse(self, data: bytes, name: str, keep: bool = False) -> Parsed:
        """One file version parsed whole in this process; its entries kept if ``keep``."""
        entries, error = loader.read_bytes(data, name)
        count, identities, keys, rectilinear = summarize(entries)
        return Parsed(
            count,
            error,
            [self.idents(i) for i in identities],
            [self.audit_keys(k) for k in keys],
            rectilinear,
            [e for e in entries if e.status == STATUS_OK] if keep else None,
        )

    def _intern(self, summary: Summary) -> tuple[int, list[int], list[int], list[bool]]:
        count, identities, keys, rectilinear = summary
        return (
            count,
            [self.idents(tuple(i)) for i in identities],
            [self.audit_keys(tuple(k)) for k in keys],
            list(rectilinear),
        )

    def add_pieces(self, made: list[tuple[bytes, Summary]]) -> None:
        """Intern the summaries of pieces (see :func:`~.parse.parse_blob`) not seen yet."""
        for digest, summary in made:
            if digest and digest not in self.pieces:
                self.pieces[digest] = self._intern(summary)

    def assemble(self, result: Pieces) -> Parsed:
        """A file version from :func:`~.parse.parse_blob`, once :meth:`add_pieces` has
        seen the summaries of every file version of the run."""
        error, digests, made = result
        if not digests:
            count, idents, keys, rectilinear = self._intern(dict(made)[b""])
            return Parsed(count, error, idents, keys, rectilinear)
        parsed = Parsed(0, error, [], [], [])
        for digest in digests:
            count, idents, keys, rectilinear = self.pieces[digest]
            parsed.entries += count
            parsed.idents.extend(idents)
            parsed.audit_keys.extend(keys)
            parsed.rectilinear.extend(rectilinear)
        return parsed

    def finish(self, parsed: dict[str, Parsed]) -> dict[str, BlobAudit]:
        """Compute the metrics of every audit key at once, then count per file version."""
        import numpy as np

        from .. import metrics

        keys = self.audit_keys.values
        size = len(keys)
        columns = {name: np.full(size, np.nan) for name in ("a", "b", "c", "k1", "k2")}
        for index, (model, coefficients, *_) in enumerate(keys):
            for name, value in zip(MODEL_COEFFICIENTS[model], coefficients, strict=True):
                columns[name][index] = value
        crop, aspect, focal = (np.array([k[i] for k in keys], dtype=np.float64) for i in (2, 3, 4))
        result = self.metrics = metrics.compute(
            np.array([k[0] for k in keys], dtype=object),
            *columns.values(),
            crop,
            aspect,
            focal,
            np.ones(size, dtype=bool),
            np.array([k[5] for k in keys], dtype=bool),
        )
        finite = np.isfinite(result.r_max)
        folds = result.folds_in_image
        with np.errstate(invalid="ignore"):
            folds_paper = finite & (result.r_normalized_paper < 1)
        model_index = np.array([MODELS.index(k[0]) for k in keys], dtype=np.intp)
        audits = {}
        for oid, blob in parsed.items():
            keys_of = np.array(blob.audit_keys, dtype=np.intp)
            rectilinear = np.array(blob.rectilinear, dtype=bool)
            models = model_index[keys_of]
            fin, fold, paper = finite[keys_of], folds[keys_of], folds_paper[keys_of]
            counts = (
                blob.entries,
                len(keys_of),
                *(int((models == m).sum()) for m in range(len(MODELS))),
                int(fin.sum()),
                *(int((fin & (models == m)).sum()) for m in range(len(MODELS))),
                int(fold.sum()),
                int((fold & rectilinear).sum()),
                int((paper & rectilinear).sum()),
            )
            audits[oid] = BlobAudit(blob.error, counts, tuple(blob.idents))
        return audits


def revision(
    commit: Commit, mainline: bool, files: dict[str, str], audits: dict[str, BlobAudit]
) -> Revision:
    """The revision of ``commit``: its ``files`` ({name: blob id}) counted and summed."""
    names = sorted(files)
    file_audits = [audits[files[name]] for name in names]
    # Column sums at C speed: a revision has dozens of files, a history thousands.
    totals = list(map(sum, zip(*(audit.counts for audit in file_audits), strict=True)))
    totals = totals or [0] * len(COUNT_COLUMNS)
    errors = [
        f"{name}: {audit.error}"
        for name, audit in zip(names, file_audits, strict=True)
        if audit.error
    ]
    return Revision(
        commit, mainline, len(files), dict(zip(COUNT_COLUMNS, totals, strict=True)), tuple(errors)
    )
