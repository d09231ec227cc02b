"""Stage 4, audit: the summaries of file versions, their entries' identities
interned, and summed per revision."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from .commits import Commit
from .results import COUNT_COLUMNS, Revision


@dataclass(frozen=True)
class BlobAudit:
    """What one file version holds: its error, :data:`COUNT_COLUMNS`, and the
    identities (interned) of its audited entries, in file order."""

    error: str
    counts: tuple[int, ...]
    idents: tuple[int, ...]
    folding: tuple[int, ...] = ()  # the identities of the entries that fold in their image


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

    def audit(
        self,
        error: str,
        counts: tuple[int, ...],
        identities: Sequence[tuple],
        folding: Sequence[int] = (),
    ) -> BlobAudit:
        """A file version's summary (the fields of a :class:`~.versions.Summary`),
        its identities interned."""
        idents = tuple(map(self, identities))
        return BlobAudit(error, counts, idents, tuple(idents[i] for i in folding))


#: The column sums of a revision's counts and the error of each of its files that
#: has one (what :func:`revision` counts).
Counted = tuple[list[int], dict[str, str]]


def revision(
    commit: Commit,
    mainline: bool,
    files: dict[str, str],
    audits: dict[str, BlobAudit],
    parent: tuple[dict[str, str], Counted] | None = None,
) -> tuple[Revision, Counted]:
    """The revision of ``commit``: its ``files`` ({name: blob id}) counted and
    summed, and what was counted; from what was counted of the files of a
    parent (``parent``), changed by the files that differ, where given."""
    if parent is None:
        # Column sums at C speed: a revision has dozens of files, a history thousands.
        totals = list(map(sum, zip(*(audits[blob].counts for blob in files.values()), strict=True)))
        totals = totals or [0] * len(COUNT_COLUMNS)
        errors = {name: audits[blob].error for name, blob in files.items() if audits[blob].error}
    else:
        before, (totals, errors) = parent
        totals, errors = list(totals), dict(errors)
        for name, blob in before.items() - files.items():  # gone, or changed: taken out
            totals = [t - c for t, c in zip(totals, audits[blob].counts, strict=True)]
            errors.pop(name, None)
        for name, blob in files.items() - before.items():  # new, or changed
            totals = [t + c for t, c in zip(totals, audits[blob].counts, strict=True)]
            if audits[blob].error:
                errors[name] = audits[blob].error
    counts = dict(zip(COUNT_COLUMNS, totals, strict=True))
    shown = tuple(f"{name}: {errors[name]}" for name in sorted(errors))
    return Revision(commit, mainline, len(files), counts, shown), (totals, errors)
