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
