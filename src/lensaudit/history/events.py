"""Events: along the first-parent line, each entry that starts
folding inside its image and each that stops (fixed, changed or removed),
with the commit where it happens.

A revision's folding entries are the union, over its files, of the
identities of the entries that fold in each file version (see
:class:`~.audit.BlobAudit`). The first revision examined starts from
nothing when it is the repository's first commit (everything folding in it
starts there); otherwise from itself (what folds there was already there).

An event at a merge names, as its branch commit, the first commit of the
merged branch (oldest first) whose own revision shows the change.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace

from .audit import BlobAudit
from .commits import Commit
from .results import FOLDS, NO_LONGER_FOLDS, FoldEvent


def fold_events(
    line: Sequence[Commit],
    files: dict[str, dict[str, str]],
    audits: dict[str, BlobAudit],
    identities: Sequence[tuple],
    branch: Callable[[Commit], list[Commit]] | None = None,
) -> list[FoldEvent]:
    """The events along ``line`` (the first-parent commits, oldest first), each
    commit's files ({name: blob}) audited in ``audits``; ``identities`` gives
    the identity of each interned number. ``branch(merge)`` gives the
    commits a merge brings in, oldest first."""

    def folding(commit: Commit) -> set[int] | None:
        found = files.get(commit.hash)
        if found is None:
            return None
        return {i for blob in found.values() for i in audits[blob].folding}

    def ordered(numbers: set[int]) -> list[tuple]:
        # By what the entries are, not by their numbers: those depend on the
        # order identities were met in, which an index kept from other runs sets.
        return sorted((identities[i] for i in numbers), key=_identity_order)

    events: list[FoldEvent] = []
    before: set[int] | None = set() if line and not line[0].parents else None
    for commit in line:
        now = folding(commit) or set()
        if before is not None:
            made = [FoldEvent(commit, FOLDS, identity) for identity in ordered(now - before)]
            made += [
                FoldEvent(commit, NO_LONGER_FOLDS, identity) for identity in ordered(before - now)
            ]
            if made and len(commit.parents) > 1 and branch is not None:
                made = _on_branch(made, branch(commit), folding, identities)
            events += made
        before = now
    return events


def _identity_order(identity: tuple) -> tuple:
    """A sort key of an entry's identity (maker, lens, crop factor, model, focal
    length, coefficients): by maker, lens, model, then the numbers (NaN last)."""
    maker, lens, crop, model, focal, coefficients = identity
    return (maker, lens, model, _number_order(crop), _number_order(focal), repr(coefficients))


def _number_order(value: float) -> tuple[bool, float]:
    return (True, 0.0) if value != value else (False, value)


def _on_branch(
    made: list[FoldEvent],
    commits: list[Commit],
    folding: Callable[[Commit], set[int] | None],
    identities: Sequence[tuple],
) -> list[FoldEvent]:
    """The events of a merge, each with the first commit of the merged branch
    whose revision shows it."""
    number = {identity: i for i, identity in enumerate(identities)}
    states = [(c, folding(c)) for c in commits]
    found = []
    for event in made:
        ident = number[event.identity]
        wanted = event.event == FOLDS
        where = next(
            (c for c, state in states if state is not None and (ident in state) == wanted),
            None,
        )
        found.append(replace(event, branch_commit=where))
    return found
