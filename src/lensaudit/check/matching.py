"""Matching against the baseline: what makes two findings the same, which of
the current findings the baseline already has, and which of its findings are
gone.

Identity is content, never position or line: an entry is its lens (maker and
model, compared without case or white space) and its own values.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Hashable, Sequence
from dataclasses import fields, replace

from .. import read as reader
from ..read.records import STATUS_OK, DistortionEntry
from .inputs import last_readable
from .parsing import LensRecord, ParsedSource, parse_sources
from .result import (
    FILE_CODES,
    Finding,
    Identified,
    clip,
    none_if_nan,
    normalized_name,
)
from .rules.baseline_unreadable import BASELINE_UNREADABLE
from .rules.file_errors import file_identified
from .rules.liblensfun_refuses import liblensfun_refusals


def identity_name(text: str) -> str:
    """A maker or model name as identities compare it: without case or any
    white space, so that "RF200-800mm" and "RF 200-800mm" are one lens."""
    return "".join(text.split()).casefold()


def lens_identity(maker: str, model: str) -> tuple[str, str]:
    """A lens as identities compare it: maker and model, see :func:`identity_name`."""
    return identity_name(maker), identity_name(model)


_LINE_NUMBER = re.compile(r"\bline \d+")


def entry_content(entry: DistortionEntry) -> tuple:
    """An entry's own values, without its lens's name, file or line."""
    message = "" if entry.status == STATUS_OK else _LINE_NUMBER.sub("line", entry.message)
    return (
        entry.model,
        entry.type,
        entry.status,
        message,
        *(
            none_if_nan(getattr(entry, name))
            for name in ("focal", "crop_factor", "aspect_ratio", "real_focal")
        ),
        *(none_if_nan(getattr(entry, name)) for name in ("a", "b", "c", "k1", "k2")),
    )


_CALIBRATION_SKIPPED = frozenset({"file", "line", "maker", "lens"})


def calibration_content(entry: object) -> tuple:
    """A vignetting or TCA record's own values, without its lens's name, file
    or line (NaN as None, line numbers left out of the message)."""
    values = []
    for name in _content_fields(type(entry)):
        value = getattr(entry, name)
        if name == "message":
            value = _LINE_NUMBER.sub("line", value)
        elif isinstance(value, float):
            value = none_if_nan(value)
        values.append(value)
    return tuple(values)


@functools.cache
def _content_fields(record_type: type) -> tuple[str, ...]:
    """The fields of a record type that :func:`calibration_content` keeps."""
    return tuple(f.name for f in fields(record_type) if f.name not in _CALIBRATION_SKIPPED)


def readable_baseline(
    read: list[ParsedSource], depth: int, cache: reader.Cache | None = None
) -> tuple[list[ParsedSource], list[Identified], list[tuple[str, str]], set[str]]:
    """The baseline's files with each one that cannot be parsed replaced by its
    last readable version from git, among the last ``depth`` commits that
    changed it (read through ``cache``, if given).

    Also returns the file-level findings of the replaced files (the baseline
    had them, whatever the older version holds: its ``xml-error``, and where
    liblensfun stops reading it, ``liblensfun-refuses``), the (name, commit)
    of each replacement, and the names of files left without a readable
    version.
    """
    read = list(read)
    kept: list[Identified] = []
    replaced: list[tuple[str, str]] = []
    incomparable: set[str] = set()
    for index, file in enumerate(read):
        if file.problem is None:
            continue
        older = last_readable(file.source, depth, cache)
        if older is None:
            incomparable.add(file.source.file_name)
            continue
        kept.append(file_identified(file))
        kept += liblensfun_refusals(file)
        read[index] = parse_sources([older[0]], cache)[0]
        replaced.append((file.source.file_name, older[1]))
    return read, kept, replaced, incomparable


def compare(
    current: list[Identified],
    before: list[Identified],
    read: Sequence[ParsedSource],
    incomparable: set[str],
) -> tuple[list[Finding], int]:
    """The current findings with those the baseline has marked known, and the
    number of the baseline's findings that are gone (resolved).

    Matching goes from the most specific key to the least: first every
    finding that has an unmatched baseline finding with its first key, then
    those left by their second key, and so on; each baseline finding matches
    once. A second key that is the first without its last item (the lens's
    name) stands for a renamed lens: a baseline finding matches by it only
    where no lens of the database checked has that name any more, so that
    a copy of a known finding under a new lens is new even when the change
    also edits the original. Findings in a file whose baseline could not be
    read are known too, but for its own file-level finding.
    """
    used = [False] * len(before)
    known = [False] * len(current)
    present = lens_names(read)
    tiers = max((len(item.keys) for item in (*current, *before)), default=0)
    for tier in range(tiers):
        pool: dict[Hashable, list[int]] = {}
        for position, item in enumerate(before):
            if used[position] or tier >= len(item.keys):
                continue
            if tier == 1 and _renamed_lens(item.keys) in present:
                continue  # the lens was not renamed: its finding is not another's
            pool.setdefault(item.keys[tier], []).append(position)
        for position, item in enumerate(current):
            if known[position] or tier >= len(item.keys):
                continue
            candidates = pool.get(item.keys[tier])
            if candidates:
                used[candidates.pop(0)] = True
                known[position] = True
    for position, item in enumerate(current):
        if item.finding.code not in FILE_CODES and incomparable.intersection(item.names):
            known[position] = True
    findings = [
        replace(item.finding, known=True) if is_known else item.finding
        for item, is_known in zip(current, known, strict=True)
    ]
    # Entries of a file that no longer parses are not checked: their findings
    # are not gone, only unseen.
    unseen = {f.source.file_name for f in read if f.problem is not None}
    resolved = sum(
        not used[position] and not unseen.intersection(item.names)
        for position, item in enumerate(before)
    )
    return findings, resolved


def lens_key(lens: LensRecord) -> tuple:
    """A lens as the duplicate rules compare lenses: maker, model and crop factor."""
    return normalized_name(lens.maker), normalized_name(lens.model), lens.crop_factor


def lens_names(read: Sequence[ParsedSource]) -> set[Hashable]:
    """The name of every lens of the files, as the findings' keys hold it: by
    :func:`lens_identity`, and as the duplicate rules compare lenses (with
    their crop factor, :func:`lens_key`)."""
    names: set[Hashable] = set()
    for file in read:
        for lens in file.lenses:
            names.add(lens_identity(lens.maker, lens.model))
            names.add(lens_key(lens))
    return names


_NO_LENS = object()


def _renamed_lens(keys: tuple[Hashable, ...]) -> Hashable:
    """The lens a finding's second key leaves out, where that key is its first
    without its last item (see :func:`compare`); else a name no lens has."""
    first, second = keys[0], keys[1]
    if (
        isinstance(first, tuple)
        and isinstance(second, tuple)
        and len(first) == len(second) + 1
        and first[:-1] == second
    ):
        return first[-1]
    return _NO_LENS


def baseline_notices(
    read: Sequence[ParsedSource],
    label: str,
    replaced: list[tuple[str, str]],
    incomparable: set[str],
) -> list[Finding]:
    """A notice for each readable file whose baseline version could not be parsed."""
    readable = {f.source.file_name: f.source.display for f in read if f.problem is None}
    texts = [
        (
            name,
            f"the baseline's version ({label}) could not be parsed; compared with the "
            f"last version that can, of commit {commit[:12]}",
        )
        for name, commit in replaced
    ]
    texts += [
        (
            name,
            f"the baseline's version ({label}) could not be parsed, and no earlier "
            f"version that can was found: the findings in this file are not counted as new",
        )
        for name in sorted(incomparable)
    ]
    rule = BASELINE_UNREADABLE
    return [
        Finding(rule.severity, rule.code, readable[name], 0, 0, clip(text))
        for name, text in texts
        if name in readable
    ]
