"""Stage 5, introduced: which commit introduced each entry's coefficients.

Walking the commits parents first, each entry of a changed file inherits the
introducer of an identical entry (same identity) in its first parent that
holds one, the same file first; a commit introduces what no parent holds.

A lens renamed, or its crop factor corrected, keeps its calibrations: an
entry no parent holds inherits the introducer of an entry with the same
calibration (model, focal length and coefficients) that the same commit
removed from the previous version of its file, so that the introducer is
the calibration's commit, not a later clean-up. A calibration copied to a
new lens while the old one stays is the copy's own.
"""

from __future__ import annotations

from .. import read
from ..read.records import ROW_FIELDS, STATUS_OK, DistortionEntry
from .audit import BlobAudit, revision
from .commits import Commit
from .results import IntroducedEntry, Revision

_STATUS = ROW_FIELDS.index("status")
# Index into a history's commits meaning "already there before the first commit examined".
_BEFORE = -1


class _FileState:
    """One file of one revision, as the history sees it: its blob, the
    identities of its entries and, for each, the commit that introduced it."""

    __slots__ = ("blob", "idents", "introducers", "_index")

    def __init__(self, blob: str, idents: tuple[int, ...], introducers: tuple[int, ...]):
        self.blob = blob
        self.idents = idents
        self.introducers = introducers
        self._index: dict[int, int] | None = None

    def introducer(self, ident: int) -> int | None:
        """Introducer of the first entry with this identity, or None."""
        return self.index().get(ident)

    def index(self) -> dict[int, int]:
        """Identity -> introducer of the first entry with it."""
        if self._index is None:
            # Built reversed, so that the first occurrence of an identity wins.
            self._index = dict(zip(reversed(self.idents), reversed(self.introducers), strict=True))
        return self._index


_State = dict[str, _FileState]


def _find_introducer(ident: int, path: str, parents: list[_State]) -> int | None:
    """Introducer of an identical entry in the first parent that has one (same
    file first), or None when no parent has it."""
    for parent in parents:
        same = parent.get(path)
        if same is not None:
            found = same.introducer(ident)
            if found is not None:
                return found
        # The other files in order (the same one, searched above, holds no such entry).
        for index in map(_FileState.index, parent.values()):
            found = index.get(ident)
            if found is not None:
                return found
    return None


def _next_state(
    index: int,
    files: dict[str, str],
    parents: list[_State],
    audits: dict[str, BlobAudit],
    calibration: list[int],
    met: set[int],
) -> _State:
    """The file states of commit ``index``, given those of its parents
    (``calibration``: the calibration identity of each entry identity;
    ``met``: every identity of the states made so far, which this adds to)."""
    first = parents[0] if parents else {}
    state: _State = {}
    for path, blob in files.items():
        previous = first.get(path)
        if previous is not None and previous.blob == blob:
            state[path] = previous
            continue
        audit = audits[blob]
        if audit.error:
            # Unreadable: keep the entries of the file's last readable version.
            carried = next((p[path] for p in parents if path in p), None)
            state[path] = _FileState(
                blob, carried.idents if carried else (), carried.introducers if carried else ()
            )
            continue
        # Most entries of a changed file are those of its previous version: looked
        # up there directly (where _find_introducer looks first), the others searched.
        known = previous.index() if previous is not None else {}
        introducers = list(map(known.get, audit.idents))
        if None in introducers:
            removed: dict[int, int] | None = None  # calibration -> introducer, of entries gone
            for position, ident in enumerate(audit.idents):
                if introducers[position] is not None:
                    continue
                found = None
                # An identity no state has held is in no parent: not searched for.
                if ident in met:
                    found = _find_introducer(ident, path, parents)
                if found is None and previous is not None:
                    if removed is None:
                        removed = _removed(previous, set(audit.idents), calibration)
                    found = removed.get(calibration[ident])
                introducers[position] = index if found is None else found
        state[path] = _FileState(blob, audit.idents, tuple(introducers))  # type: ignore[arg-type]
        met.update(audit.idents)
    return state


def _removed(previous: _FileState, kept: set[int], calibration: list[int]) -> dict[int, int]:
    """The calibration identity of each entry of ``previous`` that is not in
    ``kept``, with its introducer (the first of each)."""
    removed: dict[int, int] = {}
    for ident, introducer in zip(previous.idents, previous.introducers, strict=True):
        if ident not in kept:
            removed.setdefault(calibration[ident], introducer)
    return removed


def calibration_identities(identities: list[tuple]) -> list[int]:
    """For each entry identity (interned, see :func:`~.versions.row_identity`),
    a small integer for its calibration alone: model, focal length and
    coefficients, without maker, lens and crop factor."""
    numbers: dict[tuple, int] = {}
    return [numbers.setdefault(identity[3:], len(numbers)) for identity in identities]


def parents_of(commit: Commit, first_parent: bool) -> tuple[str, ...]:
    """The parents the history follows from ``commit``."""
    return commit.parents[:1] if first_parent else commit.parents


def changes_database(commit: Commit, files: dict[str, dict[str, str]], first_parent: bool) -> bool:
    """Whether ``commit`` holds other file versions than its first parent
    (``files``: {commit: {name: blob id}}), or has no parent followed."""
    parents = parents_of(commit, first_parent)
    return not parents or files[parents[0]] != files[commit.hash]


def revisions(
    commits: list[Commit],
    files: dict[str, dict[str, str]],
    first_parent: bool,
    mainline: set[str],
    audits: dict[str, BlobAudit],
) -> list[Revision]:
    """The revisions of the commits that change the database, counted."""
    return [
        revision(commit, commit.hash in mainline, files[commit.hash], audits)
        for commit in commits
        if changes_database(commit, files, first_parent)
    ]


def walk(
    commits: list[Commit],
    outside: list[str],
    files: dict[str, dict[str, str]],
    first_parent: bool,
    audits: dict[str, BlobAudit],
    identities: list[tuple],
) -> dict[str, _State]:
    """The file states of every commit, walking parents before children
    (``files``: {commit: {name: blob id}}; ``identities``: the entry identity
    of each interned number). The entries of ``outside`` commits, parents of
    the first ones examined, count as there before them."""
    calibration = calibration_identities(identities)
    states: dict[str, _State] = {
        p: {
            name: _FileState(blob, audits[blob].idents, (_BEFORE,) * len(audits[blob].idents))
            for name, blob in files[p].items()
        }
        for p in outside
    }
    met = {ident for state in states.values() for file in state.values() for ident in file.idents}
    for index, commit in enumerate(commits):
        parent_hashes = parents_of(commit, first_parent)
        if not changes_database(commit, files, first_parent):
            states[commit.hash] = states[parent_hashes[0]]
            continue
        parent_states = [states[p] for p in parent_hashes]
        states[commit.hash] = _next_state(
            index, files[commit.hash], parent_states, audits, calibration, met
        )
    return states


def introduced_entries(
    newest: dict[str, tuple[read.FileTables, dict[str, list]]],
    state: _State,
    commits: list[Commit],
) -> list[IntroducedEntry]:
    """Entries of the newest revision with a finite r_max, with their introducers;
    ``newest`` maps each of its file names to the file's tables and metric columns."""
    introduced = []
    for name in sorted(newest):
        tables, metrics = newest[name]
        if tables.error:
            continue  # an unreadable file has no audited entry
        audited = [(row, i) for i, row in enumerate(tables.distortion) if row[_STATUS] == STATUS_OK]
        for (row, index), introducer in zip(audited, state[name].introducers, strict=True):
            r_max = metrics["r_max"][index]
            if r_max - r_max != 0:  # not finite
                continue
            introduced.append(
                IntroducedEntry(
                    DistortionEntry(name, *row),
                    r_max,
                    metrics["d_max"][index],
                    metrics["r_normalized"][index],
                    metrics["r_normalized_paper"][index],
                    bool(metrics["folds_in_image"][index]),
                    None if introducer == _BEFORE else commits[introducer],
                )
            )
    return introduced
