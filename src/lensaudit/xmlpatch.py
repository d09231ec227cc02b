"""Change attribute values of XML elements in place, leaving every other byte alone.

An XML library that parses and serializes a file rewrites it: quotes,
attribute order, whitespace, comments and the declaration may all change,
and a one-number fix turns into a diff of the whole file. This module works
on the bytes instead. It finds an element's start tag by the line on which
the tag ends (the line :mod:`lensaudit.read` gives an element: libxml2's,
with CR LF, CR and LF each ending one line) and by its attribute values,
and replaces only the text between the quotes of the attributes that
change. Everything else, the quote style included, stays as it was.

Comments, CDATA sections, processing instructions and the document type
declaration are skipped when looking for start tags, so that a commented-out
element is never taken for the real one.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from .writing import replace_files


class PatchError(Exception):
    """An element could not be found or changed safely; the message says why."""


@dataclass(frozen=True)
class Attribute:
    """One attribute of a start tag: its raw value and where that value lies.

    ``start`` and ``end`` delimit the value's bytes, between the quotes.
    """

    name: str
    value: str
    quote: str
    start: int
    end: int


@dataclass(frozen=True)
class StartTag:
    """A start tag (or empty-element tag) found in a file's bytes.

    ``line`` is the 1-based line on which the tag ends (its ``>``), counted
    as the reader counts lines: CR LF, CR and LF each end one.
    ``attributes_end`` is the offset just after the last attribute, where a
    new attribute can go.
    """

    tag: str
    start: int
    end: int
    line: int
    attributes: dict[str, Attribute]
    attributes_end: int

    def values(self) -> dict[str, str]:
        """Attribute name -> raw value text."""
        return {name: attribute.value for name, attribute in self.attributes.items()}


# Regions in which a "<" does not start an element.
_SKIPPED = (
    (b"<!--", b"-->"),
    (b"<![CDATA[", b"]]>"),
    (b"<?", b"?>"),
)
_ATTRIBUTE = re.compile(rb"""[ \t\r\n]+([^\s=/>"']+)[ \t\r\n]*=[ \t\r\n]*(?:"([^"]*)"|'([^']*)')""")
_TAG_END = re.compile(rb"[ \t\r\n]*(/?)>")


def start_tags(data: bytes, tag: str) -> Iterator[StartTag]:
    """Every start tag named ``tag`` in ``data``, in document order.

    Raises :class:`PatchError` for a tag that is not well formed (an
    attribute without quotes, say): the file is then not one to patch.
    """
    opening = b"<" + tag.encode("ascii")
    position = 0
    line = 1
    counted = 0  # offset up to which line ends have been counted
    # A CR LF pair never straddles the offsets counted up to: each is at a "<" or after a ">".
    carriage_returns = b"\r" in data
    while True:
        found = data.find(b"<", position)
        if found < 0:
            return
        skipped = _skipped_region_end(data, found)
        if skipped is not None:
            position = skipped
            continue
        after = found + len(opening)
        if not data.startswith(opening, found) or (
            after < len(data) and data[after : after + 1] not in b" \t\r\n/>"
        ):
            position = found + 1
            continue
        attributes: dict[str, Attribute] = {}
        cursor = after
        while True:
            match = _ATTRIBUTE.match(data, cursor)
            if match is None:
                break
            name = match.group(1).decode("utf-8", "replace")
            quote = '"' if match.group(2) is not None else "'"
            group = 2 if quote == '"' else 3
            attributes[name] = Attribute(
                name,
                match.group(group).decode("utf-8", "replace"),
                quote,
                match.start(group),
                match.end(group),
            )
            cursor = match.end()
        end = _TAG_END.match(data, cursor)
        line += _line_ends(data, counted, found, carriage_returns)
        if end is None:
            raise PatchError(f"line {line}: <{tag}> start tag is not well formed")
        line += _line_ends(data, found, end.end(), carriage_returns)
        counted = end.end()
        yield StartTag(tag, found, end.end(), line, attributes, cursor)
        position = end.end()


def _line_ends(data: bytes, start: int, end: int, carriage_returns: bool) -> int:
    """Line ends in ``data[start:end]``: CR LF, CR and LF count one each."""
    count = data.count(b"\n", start, end)
    if carriage_returns:
        count += data.count(b"\r", start, end) - data.count(b"\r\n", start, end)
    return count


def _skipped_region_end(data: bytes, position: int) -> int | None:
    """End of the comment, CDATA section, PI or DOCTYPE starting at ``position``."""
    for start, stop in _SKIPPED:
        if data.startswith(start, position):
            end = data.find(stop, position + len(start))
            return len(data) if end < 0 else end + len(stop)
    if data.startswith(b"<!DOCTYPE", position):
        # An internal subset ([...]) may hold ">" inside its declarations.
        bracket = data.find(b"[", position)
        close = data.find(b">", position)
        if 0 <= bracket < close:
            end = data.find(b"]", bracket)
            close = data.find(b">", end) if end >= 0 else -1
        return len(data) if close < 0 else close + 1
    return None


def locate(
    data: bytes, tag: str, line: int, match: Callable[[Mapping[str, str]], bool]
) -> StartTag:
    """The one start tag ``tag`` ending on ``line`` whose raw attributes ``match``.

    Raises :class:`PatchError` when there is no such tag, or more than one.
    """
    candidates = [t for t in start_tags(data, tag) if t.line == line]
    matching = [t for t in candidates if match(t.values())]
    if len(matching) == 1:
        return matching[0]
    if not matching:
        if candidates:
            raise PatchError(f"line {line}: <{tag}> has other attribute values than expected")
        raise PatchError(f"line {line}: no <{tag}> element ends on this line")
    raise PatchError(f"line {line}: {len(matching)} <{tag}> elements match; cannot tell which")


def _check_value(name: str, text: str, quote: str) -> None:
    if not re.fullmatch(r"[^\s=/>\"'<&]+", name):
        raise PatchError(f"{name!r} is not an attribute name this module writes")
    if quote in text or "<" in text or "&" in text:
        raise PatchError(f"{name}={text!r} would need escaping; not written")


def set_attributes(data: bytes, edits: Sequence[tuple[StartTag, Mapping[str, str]]]) -> bytes:
    """``data`` with the given attribute values set on the given start tags.

    Each edit is a tag found in ``data`` and the new raw values of some of
    its attributes. An attribute the tag does not have is added after its
    last attribute, with the quote character that attribute uses. Nothing
    else changes. Raises :class:`PatchError` for a value that would need
    escaping (only plain text such as numbers is written).
    """
    replacements: list[tuple[int, int, bytes]] = []
    for element, values in edits:
        existing = list(element.attributes.values())
        default_quote = existing[-1].quote if existing else '"'
        for name, text in values.items():
            attribute = element.attributes.get(name)
            if attribute is not None:
                _check_value(name, text, attribute.quote)
                if text != attribute.value:
                    replacements.append((attribute.start, attribute.end, text.encode("utf-8")))
            else:
                _check_value(name, text, default_quote)
                added = f" {name}={default_quote}{text}{default_quote}".encode()
                replacements.append((element.attributes_end, element.attributes_end, added))
    replacements.sort(key=lambda item: (item[0], item[1]))
    pieces = []
    position = 0
    for start, end, text in replacements:
        if start < position:
            raise PatchError("two edits change the same bytes")
        pieces += [data[position:start], text]
        position = end
    pieces.append(data[position:])
    return b"".join(pieces)


@dataclass(frozen=True)
class FilePatch:
    """The new content of one file, with the content it was computed from."""

    path: Path
    name: str
    original: bytes
    patched: bytes

    @property
    def changed(self) -> bool:
        """Whether the patch changes anything."""
        return self.original != self.patched


def unified_diff(patch: FilePatch) -> str:
    """A unified diff of the patch, as ``diff -u`` or ``git diff`` would show it."""
    old = patch.original.decode("utf-8", "replace").splitlines(keepends=True)
    new = patch.patched.decode("utf-8", "replace").splitlines(keepends=True)
    lines = difflib.unified_diff(old, new, f"a/{patch.name}", f"b/{patch.name}")
    text = ""
    for line in lines:
        text += line if line.endswith("\n") else line + "\n\\ No newline at end of file\n"
    return text


def check_unchanged(patch: FilePatch) -> None:
    """Raise :class:`PatchError` unless the file still holds what the patch was
    computed from."""
    try:
        current = Path(patch.path).read_bytes()
    except OSError as error:
        raise PatchError(f"{patch.name}: cannot read again: {error.strerror or error}") from None
    if current != patch.original:
        raise PatchError(f"{patch.name}: the file changed since it was read; nothing written")


def write(patches: FilePatch | list[FilePatch]) -> None:
    """Write patched contents in place of their files: all, or none.

    Every file is read again first: if one is no longer what its patch was
    computed from, nothing is written and :class:`PatchError` says so. The
    files are then replaced as :func:`lensaudit.writing.replace_files`
    replaces them (atomically, keeping mode, owner and group, through
    symbolic links; refusing a file this user may not write or one with
    other hard links, with :class:`lensaudit.writing.WriteError`).
    """
    patches = [patches] if isinstance(patches, FilePatch) else patches
    for patch in patches:
        check_unchanged(patch)
    replace_files([(patch.path, patch.patched) for patch in patches])
