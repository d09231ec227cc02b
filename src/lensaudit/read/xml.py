"""The one XML parser of lensaudit: safe, and strict where liblensfun is.

Parsing never touches the network, never loads a DTD or an external entity
(a FIFO named as one cannot hang the run), never applies an ``<!ATTLIST>``
default and never expands an entity. A file that refers to an entity other
than XML's five (``&lt;`` ...) or a character reference (``&#246;``) is
refused, as liblensfun (GLib's GMarkup) refuses it: libxml2 would otherwise
give such a value as empty or with the entity's text.

Line numbers are those of the file: CR-only line ends count as line breaks
(libxml2 would see one long line), and lines beyond 65,535 keep their number.

Bytes that are UTF-8 are read as UTF-8, whatever the XML declaration says,
as GMarkup reads them (liblensfun hands it the bytes, and it takes the
declaration for a processing instruction): a file declared ISO-8859-1 whose
bytes are UTF-8 gives the names liblensfun gives ("Görlitz", not
"GÃ¶rlitz"), and :func:`encoding_disagreement` says where a reader that
follows the declaration reads other text. A file liblensfun refuses for its
encoding (UTF-16 or UTF-32, or bytes that are not UTF-8 in the encoding it
declares) is read as its byte-order mark or declaration says, so that what
it holds is still audited; :func:`lensaudit.read.liblensfun.leading_refusal`
says that liblensfun reads none of it. Undeclared bytes that are not UTF-8
make a file not well-formed.
"""

from __future__ import annotations

import re
from collections import namedtuple

from .records import STATUS_NOT_DATABASE, STATUS_OK, STATUS_XML_ERROR

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Callable
    from typing import Any, Protocol, TypeVar

    from lxml import etree

    class Visitor(Protocol):
        """What :func:`parse` hands a document to, piece by piece, in document
        order: each child of the root element once it is complete (or the
        root itself, where it is one of the elements read), with the
        function that gives an element's line."""

        def add(self, piece: etree._Element, line_of: Callable[[etree._Element], int]) -> None: ...

    V = TypeVar("V", bound=Visitor)

#: The root element of a Lensfun database file.
DATABASE_ROOT = "lensdatabase"

_POSITION = re.compile(r",? ?(?:\(<string>, )?line (\d+), column (\d+)\)?\s*$")
_PARSER_HINTS = re.compile(
    r",? *(?:try XML_PARSE_HUGE|use XML_PARSE_HUGE option"
    r"|see xmlCtxtSetMaxAmplification)\.?\s*"
)
# Where entity references can stand: not in comments, CDATA sections,
# processing instructions or the document type's declarations. The last
# alternative is a reference to anything but the five and a character.
_REFERENCE = re.compile(
    rb"<!--.*?-->|<!\[CDATA\[.*?\]\]>|<\?.*?\?>|<!DOCTYPE(?:[^\[>]|\[.*?\]\s*)*>"
    rb"|(&(?!(?:lt|gt|amp|quot|apos|#[0-9]+|#x[0-9a-fA-F]+);)[^;\s<&\"']{0,40};?)",
    re.DOTALL,
)

#: A reference to anything but the five and a character, wherever it stands.
_SUSPECT = re.compile(rb"&(?!(?:lt|gt|amp|quot|apos|#[0-9]+|#x[0-9a-fA-F]+);)")


class Parsed(
    namedtuple(
        "Parsed",
        ("status", "line", "column", "problem"),
        defaults=(STATUS_OK, 0, 0, ""),
    )
):
    """What is wrong with a file as a whole: ``status`` is ``ok``, ``xml_error``
    or ``not_database`` (the root is not ``<lensdatabase>``); ``line`` and
    ``column`` say where, ``problem`` says what, without the position."""

    __slots__ = ()

    @property
    def error(self) -> str:
        """The file's error message with its position, "" if none."""
        if self.status == STATUS_XML_ERROR:
            return f"XML is not well-formed at line {self.line}, column {self.column}: " + (
                self.problem
            )
        return self.problem

    @property
    def entry_message(self) -> str:
        """What each entry of a file with a problem is marked with."""
        if self.status == STATUS_XML_ERROR:
            return (
                f"file is not well-formed XML (line {self.line}, column {self.column}: "
                f"{self.problem}); entry read in recovery mode"
            )
        return self.problem


def parser(recover: bool = False) -> etree.XMLParser:
    """An lxml parser that never touches the network, DTDs or entities."""
    from lxml import etree  # lxml: only to parse XML, which a warm scan does not

    return etree.XMLParser(recover=recover, **_OPTIONS)


#: The options of every parser: no network, DTD, entity or attribute default.
_OPTIONS = dict(
    resolve_entities=False,
    no_network=True,
    load_dtd=False,
    dtd_validation=False,
    attribute_defaults=False,
    huge_tree=False,
    remove_pis=False,  # a processing instruction splits text, as in liblensfun
    encoding="utf-8",  # whatever the declaration says: see decoded()
    # collect_ids is left on: lxml opens the external DTD without it (a FIFO named
    # as one would hang the run).
)
#: Bytes fed to the parser at a time: the tree read so far is cleared between feeds.
_FEED = 1 << 20
#: What a Lensfun database holds at its top level; other children are visited in order too.
_TOP_LEVEL = ("lens", "camera", "mount")


def parse(
    data: bytes,
    visitor: Callable[[], V],
    read: tuple[str, ...] = (),
    pieces: Pieces | None = None,
) -> tuple[Parsed, V]:
    """Parse one file's content as liblensfun reads it (without namespaces),
    handing its pieces to a visitor made by ``visitor()``; ``read`` names
    the elements the visitor reads (for a root that is one of them).

    The document is parsed as a stream: each top-level piece is visited as
    soon as it is complete, then dropped, so that memory holds one piece at
    a time. A file that is not well-formed is visited again, from the start,
    by a new visitor, as far as libxml2's recovery mode can read it.

    With ``pieces``, the top-level ``<lens>``, ``<camera>`` and ``<mount>``
    elements it has met before are not parsed again (see :class:`Pieces`).
    """
    from lxml import etree  # lxml: only to parse XML, which a warm scan does not

    data, found = _normalized(decoded(data))
    if found is not None:
        return _recovered(data, visitor, read, *found)
    lines = _Lines(data) if data.count(b"\n") >= _LIBXML2_LINES else None
    if pieces is not None and lines is None and pieces.usable(data, read):
        known = pieces.parse(data, visitor)
        if known is not None:
            return _checked_root(*known, lines)
    visiting = visitor()
    _show_document(data, visiting)
    try:
        # Read as one tree: names in namespaces, a root that is an element read,
        # and a document type with declarations of its own, which is dropped before
        # anything is read (libxml2 would give an <!ATTLIST> default as the value
        # of an attribute not written).
        if b"xmlns" in data or _declares(data) or _root_name(data) in read:
            root = etree.fromstring(data, parser())
            root.getroottree().docinfo.clear()
            if b"xmlns" in data:
                _use_local_names(root)
            _visit_tree(root, visiting, read, _line_getter(lines, root))
        else:
            root = _stream(data, visiting, lines)
    except etree.XMLSyntaxError as error:
        return _recovered(data, visitor, read, *syntax_error(data, error))
    return _checked_root(root, visiting, lines)


def read_pieces(data: bytes, visitor: Callable[[], V], pieces: Pieces) -> list[Any] | None:
    """The tables of each piece of a document that :func:`parse` with
    ``pieces`` reads as nothing but those pieces (see :meth:`Pieces.placed`),
    as ``visitor().taken()`` gives them, in order; None for any other."""
    data, found = _normalized(decoded(data))
    return pieces.placed(data, visitor) if found is None else None


def _normalized(data: bytes) -> tuple[bytes, tuple[int, int, str] | None]:
    """A document with XML's line-end normalization done (first, so that lines
    count), and where it refers to an entity liblensfun does not know (see
    :func:`unknown_reference`), or None."""
    if b"\r" in data:
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    found = unknown_reference(data) if b"&" in data and b"<!DOCTYPE" in data else None
    return data, found


def _checked_root(root: Any, visiting: V, lines: _Lines | None) -> tuple[Parsed, V]:
    """What a well-formed document whose root is ``root`` is: a database or not."""
    _judge_root(root, visiting, lines)
    if root.tag != DATABASE_ROOT:
        tag = root.tag if isinstance(root.tag, str) else "?"
        if len(tag) > 40:
            tag = tag[:40] + "..."
        problem = f"root element is <{tag}>, not <{DATABASE_ROOT}>: not a Lensfun database file"
        line = lines.first if lines is not None else root.sourceline or 1
        return Parsed(STATUS_NOT_DATABASE, line, 0, problem), visiting
    return Parsed(), visiting


def _show_document(data: bytes, visiting: Any) -> None:
    """Hand the bytes of a document about to be read to a visitor that looks
    at them first (``document(data)``)."""
    look = getattr(visiting, "document", None)
    if look is not None:
        look(data)


def _judge_root(root: Any, visiting: Any, lines: _Lines | None) -> None:
    """Hand the root element to a visitor that judges it (``root(element, line)``)."""
    judge = getattr(visiting, "root", None)
    if judge is not None:
        judge(root, lines.first if lines is not None else root.sourceline or 1)


class Pieces:
    """The top-level ``<lens>``, ``<camera>`` and ``<mount>`` elements met so
    far, by their bytes: for reading many versions of the same files in one
    run (``lensaudit history``), where nearly every piece of a version is one
    of an earlier version, often on other lines.

    A document is read with each piece met before (or, met for the first
    time, parsed alone into its own document) taken as the tables it was
    read into, moved to its line (``taken()`` and ``extend(found, line)``
    of :class:`~lensaudit.read.tables.FileReader`). This gives what parsing
    the whole document would, because:

    - a piece is used only where it parsed alone, inside a root element, as
      exactly one element: so it parses to the same tree, with the same
      lines relative to its first, wherever it stands in a root's content,
      in any document without namespaces, entities declared, or an
      encoding other than UTF-8 (only such documents are read this way);
    - what stands around the pieces must be well-formed with each piece in
      its place as a child of the root (not inside a comment or text), and
      the document must not hold such instructions itself: so the document
      is well-formed with each piece in place, and every line outside the
      pieces is where it was. Where only white space and comments stand
      between the pieces, that is the document with the pieces and what
      stands between them (the comments) left out and one processing
      instruction in their place, which must be a child of the root beside
      comments only; elsewhere it is the document with each piece replaced
      by a processing instruction that holds its number and as many line
      breaks, each of which must be found, in order, as a child of the root.

    Anything else, an error included, is parsed again whole, so messages
    and positions are those of the document itself. Only pieces whose every
    row is ``ok`` are kept (a message may name a line). Bounded: everything
    is forgotten past :attr:`MAX_BYTES` of pieces kept.

    The pieces of a document are found as the last document's were where
    the two are the same (see :meth:`_scan`), and :meth:`placed` gives the
    tables of each piece of a document read as nothing but its pieces, for
    what is made of a piece's rows to be kept by piece.
    """

    MAX_BYTES = 64 << 20

    def __init__(self) -> None:
        #: kind -> {bytes: (tables, line breaks) of a piece, or _UNUSABLE}.
        self._known: dict[Any, dict[bytes, Any]] = {}
        self._size = 0
        #: kind -> (bytes, pieces found) of the last document scanned.
        self._last: dict[Any, tuple[bytes, list[tuple]]] = {}

    def usable(self, data: bytes, read: tuple[str, ...]) -> bool:
        """Whether a document may be read this way (see above)."""
        return b"xmlns" not in data and _PLACE not in data and _plain_prolog(data)

    def parse(self, data: bytes, visitor: Callable[[], V]) -> tuple[Any, V] | None:
        """(root, visitor) of a document read this way; None where it cannot be."""
        scanned = self._scan(data, visitor)
        if scanned is None:
            return None
        placed, outside, _ = scanned
        visiting = visitor()
        root = _alone_in_root(outside) if outside is not None else None
        if root is not None:
            for _, _, line, tables, *_ in placed:
                visiting.extend(tables, line)
            return root, visiting
        from lxml import etree  # lxml: only to parse XML, which a warm scan does not

        parts: list[bytes] = []
        position = 0
        for number, (start, end, _, _, breaks, *_) in enumerate(placed):
            parts += (data[position:start], b"<?%s %d%s?>" % (_PLACE, number, b"\n" * breaks))
            position = end
        parts.append(data[position:])
        document = b"".join(parts)
        _show_document(document, visiting)
        placing = _Placing(visiting, [(line, tables) for _, _, line, tables, *_ in placed])
        try:
            root = _stream(document, placing, None)
        except etree.XMLSyntaxError:
            return None
        return (root, visiting) if placing.complete() else None

    def placed(self, data: bytes, visitor: Callable[[], V]) -> list[Any] | None:
        """The tables of each piece of a document (line ends normalized, no
        reference to an unknown entity) that :func:`parse` reads as nothing
        but those pieces, with only white space and comments between them:
        in order, their lines counted from each piece's first; None for any
        other document.

        As :meth:`usable` and :meth:`parse` decide, with what they look for in
        the whole document (a namespace, this class's instruction) looked for
        only outside the pieces: no piece with a namespace is kept, and an
        instruction of this class inside a piece, or anywhere but in the
        root, changes nothing of what is read this way."""
        if not _plain_prolog(data):
            return None
        scanned = self._scan(data, visitor)
        if scanned is None or scanned[1] is None or scanned[2] >= _LIBXML2_LINES:
            return None
        placed, outside, _ = scanned
        if b"xmlns" in outside:
            return None
        root = _alone_in_root(outside)
        if root is None or root.tag != DATABASE_ROOT:  # (a problem of the file: see parse())
            return None
        return [piece[3] for piece in placed]

    def _scan(
        self, data: bytes, visitor: Callable[[], V]
    ) -> tuple[list[tuple], bytes | None, int] | None:
        """(start, end, line, tables, line breaks, what stands before it, how far
        the scan looked to find it) of each piece of a document that can be
        used, learning those met for the first time; where only white space
        and comments stand between them, the document without them (its
        pieces and what stands between them left out, one processing
        instruction in their place), else None; and the number of line breaks
        in the document. None if there is no such piece.

        The pieces of a document are found one after another, each from where
        the one before ends, so that from the same place in the same bytes the
        same pieces follow. So the pieces of the last document scanned (for
        the same kind of reader) are taken as they are as far as the two
        documents are the same from their start and the scan looked no
        further to find them, and the rest as they are once this scan finds a
        piece where one of them starts, where the two are the same to the end."""
        kind = getattr(visitor(), "kind", None)
        known = self._known.get(kind)
        if known is None:
            known = self._known[kind] = {}
        between, find, search = _BETWEEN.fullmatch, data.find, _PIECE_START.search
        placed, old, synced, shift = self._as_last(kind, data)
        position, line = (placed[-1][1], placed[-1][2] + placed[-1][4]) if placed else (0, 1)
        # Each piece: from a start tag to the first end tag of its kind after it
        # (a guess: inside a comment, nested ... which the rest checks).
        started = search(data, position)
        reach = position  # how far the scan has looked since the last piece
        while started is not None:
            start = started.start()
            end_tag, end_match = _PIECE_END[started[1]]
            at = find(end_tag, start)
            closed = end_match.match(data, at) if at >= 0 else None
            if closed is None:
                reach = len(data)  # (where the match ends does not say how far it looked)
                started = search(data, start + 4)
                continue
            end = closed.end()
            reach = max(reach, end)
            started = search(data, end)
            number = synced.get(start)
            if number is not None:
                found = old[number][3], old[number][4]
            else:
                piece = data[start:end]
                found = known.get(piece)
                if found is None:
                    found = self._learn(known, piece, visitor)
                if found is _UNUSABLE:
                    continue
            if not placed:
                gap = None
            elif between(data, position, start) is None:
                gap = _UNUSABLE
            else:
                gap = data[position:start] if find(b"<", position, start) >= 0 else None
            line += data.count(b"\n", position, start)
            tables, breaks = found
            placed.append((start, end, line, tables, breaks, gap, reach))
            line += breaks
            position = reach = end
            if number is not None:  # the rest as in the last document
                moved = line - old[number][2] - breaks
                placed += [
                    (start + shift, end + shift, line + moved, tables, breaks, gap, reach + shift)
                    for start, end, line, tables, breaks, gap, reach in old[number + 1 :]
                ]
                position, line = placed[-1][1], placed[-1][2] + placed[-1][4]
                break
        self._last[kind] = (data, placed)
        if not placed:
            return None
        breaks = line - 1 + data.count(b"\n", position)
        gaps = [piece[5] for piece in placed[1:] if piece[5] is not None]
        if _UNUSABLE in gaps:
            return placed, None, breaks
        outside = data[: placed[0][0]] + b"<?%s?>" % _PLACE + b"".join(gaps) + data[position:]
        return placed, outside, breaks

    def _as_last(self, kind: Any, data: bytes) -> tuple[list[tuple], list[tuple], dict, int]:
        """What :meth:`_scan` takes of the last document scanned for ``kind``: its
        pieces found as far as the two are the same from their start (and the
        scan looked no further), its pieces, where those in the part the two
        share to their end start in ``data`` (with their number), and how
        much longer ``data`` is."""
        last = self._last.get(kind)
        if last is None:
            return [], [], {}, 0
        before, old = last
        same = _common_prefix(data, before)
        taken = []
        for piece in old:
            if piece[6] > same:
                break
            taken.append(piece)
        tail = _common_suffix(data, before, min(len(data), len(before)) - same)
        shift = len(data) - len(before)
        synced = {
            piece[0] + shift: number
            for number, piece in enumerate(old)
            if piece[0] >= len(before) - tail
        }
        return taken, old, synced, shift

    def _learn(self, known: dict[bytes, Any], piece: bytes, visitor: Callable[[], V]) -> Any:
        """(tables, line breaks) of a piece met for the first time, parsed
        alone, kept in ``known``; or :data:`_UNUSABLE`."""
        from lxml import etree  # lxml: only to parse XML, which a warm scan does not

        found = _UNUSABLE
        try:
            # In a root like the document's: liblensfun judges a lens by its parent.
            root = etree.fromstring(b"<lensdatabase>" + piece + b"</lensdatabase>", parser())
        except etree.XMLSyntaxError:
            root = None
        # The bytes start with "<lens" (or "<camera", "<mount") and end with ">":
        # one child, one element. Names in a namespace are read otherwise.
        if root is not None and len(root) == 1 and b"xmlns" not in piece:
            visiting = visitor()
            visiting.add(root[0], _relative_line)
            taken = visiting.taken()  # type: ignore[attr-defined]
            if taken is not None:
                found = (taken, piece.count(b"\n"))
        if self._size + len(piece) > self.MAX_BYTES:
            for kept in self._known.values():
                kept.clear()
            self._size = 0
        known[piece] = found
        self._size += len(piece)
        return found


#: What :class:`Pieces` keeps of a piece it cannot use.
_UNUSABLE = object()
#: The target of the processing instruction that stands for a piece (see :class:`Pieces`).
_PLACE = b"lensaudit-piece"
#: The start tag of a piece (see :class:`Pieces`), and the end tag of each kind.
_PIECE_START = re.compile(rb"<(lens|camera|mount)[ \t\n>]")
_PIECE_END = {
    name: (b"</" + name, re.compile(rb"</" + name + rb"\s*>"))
    for name in (b"lens", b"camera", b"mount")
}
#: What may stand between two pieces for the document to be checked without
#: them: white space and comments (whose characters libxml2 then judges).
#: Each byte can be matched one way only: no backtracking to speak of.
_BETWEEN = re.compile(rb"(?:[ \t\n]|<!--(?:[^-]|-[^-])*-->)*")


def _common_prefix(a: bytes, b: bytes) -> int:
    """The length of the longest start ``a`` and ``b`` have in common."""
    return _longest(lambda low, high: a[low:high] == b[low:high], min(len(a), len(b)))


def _common_suffix(a: bytes, b: bytes, limit: int) -> int:
    """The length of the longest end ``a`` and ``b`` have in common, up to
    ``limit`` (no more than the length of either)."""
    end_a, end_b = len(a), len(b)
    return _longest(
        lambda low, high: a[end_a - high : end_a - low] == b[end_b - high : end_b - low], limit
    )


def _longest(same: Callable[[int, int], bool], limit: int) -> int:
    """The largest length up to ``limit`` whose bytes are all the same, where
    ``same(low, high)`` says whether those from ``low`` to ``high`` are: in
    runs that double, then halving the run that is not."""
    low, step = 0, 1024
    while low < limit:  # the first low bytes are the same
        high = min(low + step, limit)
        if not same(low, high):
            break
        low, step = high, 2 * step
    else:
        return limit
    while high - low > 1:  # those from low to high are not
        middle = (low + high) // 2
        if same(low, middle):
            low = middle
        else:
            high = middle
    return low


def _plain_prolog(data: bytes) -> bool:
    """Whether a document declares no encoding but UTF-8, no document type
    with declarations of its own, and has a database root."""
    declared = _ENCODING.match(data)
    return (
        (declared is None or declared.group(1).lower() in (b"utf-8", b"utf8"))
        and not _declares(data)
        and _root_name(data) == DATABASE_ROOT
    )


def _alone_in_root(data: bytes) -> Any:
    """The root of a document whose root holds nothing but one processing
    instruction of :data:`_PLACE` and comments; None if it is not such a
    well-formed document."""
    from lxml import etree  # lxml: only to parse XML, which a warm scan does not

    try:
        root = etree.fromstring(data, parser())
    except etree.XMLSyntaxError:
        return None
    place = _PLACE.decode()
    kinds = [
        "place" if getattr(child, "target", None) == place and not child.text
        else "comment" if child.tag is etree.Comment
        else "other"
        for child in root
    ]  # fmt: skip
    return root if kinds.count("place") == 1 and "other" not in kinds else None


_ENCODING = re.compile(rb"\s*<\?xml[^>]*?encoding\s*=\s*[\"']([^\"']*)[\"']")


def decoded(data: bytes) -> bytes:
    """A document's bytes as they are parsed, as UTF-8 (see the module's
    description): as they are where they are UTF-8 or declare no other
    encoding; a UTF-16 or UTF-32 document, or one whose bytes are not UTF-8
    but are in the encoding it declares, decoded as such. Line ends, and so
    lines, are kept."""
    wide = wide_encoding(data)
    if wide is not None:
        return data.decode(wide[0], "replace").encode("utf-8")
    if not declares_other_encoding(data) or data.isascii():
        return data
    try:
        data.decode("utf-8")
        return data
    except UnicodeDecodeError:
        pass
    try:
        return data.decode(declared_encoding(data) or "utf-8").encode("utf-8")
    except (LookupError, UnicodeDecodeError):
        return data  # no encoding Python knows: not well-formed, as liblensfun has it


def declares_other_encoding(data: bytes) -> bool:
    """Whether a document's XML declaration names an encoding other than UTF-8."""
    declared = _ENCODING.match(data)
    return declared is not None and declared.group(1).lower() not in (b"utf-8", b"utf8")


def declared_encoding(data: bytes) -> str | None:
    """The encoding a document's XML declaration names, None without one."""
    declared = _ENCODING.match(data)
    return declared.group(1).decode("ascii", "replace") if declared is not None else None


def encoding_disagreement(data: bytes) -> tuple[int, str] | None:
    """(line, problem) where a document's XML declaration names an encoding
    its bytes (UTF-8, as liblensfun reads them) are not: a reader that
    follows the declaration reads other text than liblensfun, or cannot read
    the file. None where the two read the same (a declaration of ISO-8859-1
    on a file of ASCII only, say), or where the bytes are not UTF-8 (then the
    file is not well-formed, and its error says so)."""
    declared = _ENCODING.match(data)
    if declared is None or declared.group(1).lower() in (b"utf-8", b"utf8"):
        return None
    if wide_encoding(data) is not None:  # read as such: liblensfun's refusal says why
        return None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        return None
    name = declared.group(1).decode("ascii", "replace")
    try:
        other = data.decode(name)
    except (LookupError, UnicodeDecodeError):
        other = None
    if other == text:
        return None
    line = _line_at(text, len(data[: declared.start(1)].decode("utf-8")))
    problem = f"the XML declaration says encoding={name!r}, but the bytes are UTF-8"
    if other is None:
        return line, (
            f"{problem}: liblensfun reads them as UTF-8; a reader that follows "
            f"the declaration cannot read the file"
        )
    differs = next(
        (i for i, (a, b) in enumerate(zip(text, other, strict=False)) if a != b),
        min(len(text), len(other)),
    )
    return line, (
        f"{problem}: liblensfun reads them as UTF-8 ({_word_at(text, differs)!r} at line "
        f"{_line_at(text, differs)}), a reader that follows the declaration "
        f"as {_word_at(other, differs)!r}"
    )


def _line_at(text: str, position: int) -> int:
    """The line of ``position`` in ``text`` (CR-only line ends counted too)."""
    before = text[:position]
    return before.count("\n") + before.count("\r") - before.count("\r\n") + 1


def _word_at(text: str, position: int) -> str:
    """The run of characters other than white space and markup around ``position``."""
    start = position
    while start > 0 and not text[start - 1].isspace() and text[start - 1] not in "<>\"'=":
        start -= 1
    end = position
    while end < len(text) and not text[end].isspace() and text[end] not in "<>\"'=":
        end += 1
    word = text[start:end]
    return word if len(word) <= 40 else word[:40] + "..."


#: The byte-order marks of UTF-32 and UTF-16 (UTF-32's first: it starts as UTF-16LE's).
_WIDE_MARKS = (
    (b"\xff\xfe\x00\x00", "utf-32", "UTF-32"),
    (b"\x00\x00\xfe\xff", "utf-32", "UTF-32"),
    (b"\xff\xfe", "utf-16", "UTF-16"),
    (b"\xfe\xff", "utf-16", "UTF-16"),
)


#: Two ASCII characters (white space, "<", "?") in UTF-32 or UTF-16 without a
#: byte-order mark: their zero bytes tell the width and the byte order.
_WIDE_START = re.compile(
    rb"(?P<utf_32_le>[\x01-\x7f]\x00\x00\x00[\x01-\x7f]\x00\x00\x00)"
    rb"|(?P<utf_32_be>\x00\x00\x00[\x01-\x7f]\x00\x00\x00[\x01-\x7f])"
    rb"|(?P<utf_16_le>[\x01-\x7f]\x00[\x01-\x7f]\x00)"
    rb"|(?P<utf_16_be>\x00[\x01-\x7f]\x00[\x01-\x7f])"
)


def wide_encoding(data: bytes) -> tuple[str, str] | None:
    """(Python's codec, the problem) of a document in UTF-16 or UTF-32, by its
    byte-order mark or, without one, by the zero bytes of its first
    character (``<`` or white space, as XML's appendix F guesses encodings);
    None for any other. liblensfun reads UTF-8 only, and refuses such a file
    on its first line."""
    marked = [(m, c, n) for m, c, n in _WIDE_MARKS if data.startswith(m)]
    if marked:
        mark, codec, name = marked[0]
        how = f"byte-order mark {mark.hex(' ').upper()}"
    else:
        found = _WIDE_START.match(data)
        if found is None:
            return None
        codec = found.lastgroup.replace("_", "-")  # type: ignore[union-attr]
        name = codec.upper().replace("-LE", "LE").replace("-BE", "BE")
        how = "no byte-order mark"
    return codec, f"the file is {name} ({how}), and liblensfun reads UTF-8 only"


def _relative_line(element: Any) -> int:
    """An element's line, relative to the first line of a piece parsed alone."""
    return (element.sourceline or 1) - 1


class _Placing:
    """A visitor that hands the pieces :class:`Pieces` put in place of their
    instructions to another, checking that each is found once, in order."""

    def __init__(self, visiting: Any, placed: list[tuple[int, Any]]) -> None:
        self.add = visiting.add
        self._extend = visiting.extend
        self._placed = placed
        self._next = 0
        self._wrong = False

    def instruction(self, instruction: Any) -> None:
        if instruction.target != _PLACE.decode():
            return
        if self._next >= len(self._placed) or (instruction.text or "").split() != [str(self._next)]:
            self._wrong = True
            return
        line, found = self._placed[self._next]
        self._extend(found, line)
        self._next += 1

    def complete(self) -> bool:
        return not self._wrong and self._next == len(self._placed)


#: A document type that declares nothing itself: a name and an external identifier.
_PLAIN_DOCTYPE = re.compile(
    rb"<!DOCTYPE\s+[^\s\[>]+(?:\s+(?:SYSTEM|PUBLIC(?:\s+(?:\"[^\"]*\"|'[^']*')))"
    rb"\s+(?:\"[^\"]*\"|'[^']*'))?\s*>"
)


def _declares(data: bytes) -> bool:
    """Whether the document type may declare anything itself (an internal subset)."""
    start = data.find(b"<!DOCTYPE")
    return start >= 0 and _PLAIN_DOCTYPE.match(data, start) is None


def _root_name(data: bytes) -> str:
    """The name of the first start tag of a document ("" if none)."""
    for match in _MARKUP.finditer(data):
        if match.group(1) is not None:
            return match.group(1).decode("utf-8", "replace")
    return ""


def _stream(data: bytes, visiting: Visitor, lines: _Lines | None) -> Any:
    """Parse ``data`` piece by piece (see :func:`parse`); the root, emptied."""
    from lxml import etree  # lxml: only to parse XML, which a warm scan does not

    pull = etree.XMLPullParser(events=("end",), tag=_TOP_LEVEL, **_OPTIONS)
    line_of = _line_getter(lines, None)
    for start in range(0, len(data), _FEED):
        pull.feed(data[start : start + _FEED])
        for _, element in pull.read_events():
            root = element.getparent()
            if root is None or root.getparent() is not None:
                continue  # not a child of the root: visited with its top-level piece
            # Earlier children (other than lenses, cameras, mounts), then this one.
            while root[0] is not element:
                _visit_piece(root[0], visiting, line_of, lines)
                del root[0]
            _visit_piece(element, visiting, line_of, lines)
            element.clear()
            del root[0]
    root = pull.close()
    for child in root:
        _visit_piece(child, visiting, line_of, lines)
    return root


def _visit_piece(
    piece: Any, visiting: Visitor, line_of: Callable[[Any], int], lines: _Lines | None
) -> None:
    if lines is not None:
        lines.number(piece)
    if isinstance(piece.tag, str):  # comments have a function as tag
        visiting.add(piece, line_of)
    elif hasattr(piece, "target") and hasattr(visiting, "instruction"):
        visiting.instruction(piece)
    if lines is not None:
        lines.release()


def _visit_tree(root: Any, visiting: Visitor, read: tuple[str, ...], line_of: Callable) -> None:
    """Visit a whole tree: its root if it is an element read, else each child."""
    if root.tag in read:
        visiting.add(root, line_of)
        return
    for child in root:
        if isinstance(child.tag, str):
            visiting.add(child, line_of)


def _recovered(
    data: bytes,
    visitor: Callable[[], V],
    read: tuple[str, ...],
    line: int,
    column: int,
    problem: str,
) -> tuple[Parsed, V]:
    """A file that is not well-formed: what recovery mode can read of it, visited."""
    from lxml import etree  # lxml: only to parse XML, which a warm scan does not

    visiting = visitor()
    try:
        root = etree.fromstring(_without_surrogates(data), parser(recover=True))
    except etree.XMLSyntaxError:
        root = None
    if root is not None:
        root.getroottree().docinfo.clear()
        if b"xmlns" in data:
            _use_local_names(root)
        _judge_root(root, visiting, None)
        _visit_tree(root, visiting, read, _line_getter(None, root))
    return Parsed(STATUS_XML_ERROR, line, column, problem), visiting


#: A character reference, its number in group 1 (hexadecimal after an "x").
_CHARACTER_REFERENCE = re.compile(rb"&#(x[0-9a-fA-F]+|[0-9]+);")
_REPLACEMENT_REFERENCE = b"&#xFFFD;"


def _without_surrogates(data: bytes) -> bytes:
    """A document with each character reference to a surrogate (U+D800 to
    U+DFFF, which no XML text may hold) made a reference to U+FFFD instead:
    recovery mode would keep such a character as bytes that are not UTF-8, and
    no text could then be read from the element or attribute that holds it.
    Lines are kept as they are."""
    if b"&#" not in data:
        return data

    def replaced(match: re.Match[bytes]) -> bytes:
        number = match.group(1)
        hexadecimal = number[:1] == b"x"
        digits = (number[1:] if hexadecimal else number).lstrip(b"0")
        if len(digits) > 5:  # beyond U+DFFF (and int() of any length is never asked)
            return match.group(0)
        code = int(digits or b"0", 16 if hexadecimal else 10)
        return _REPLACEMENT_REFERENCE if 0xD800 <= code <= 0xDFFF else match.group(0)

    return _CHARACTER_REFERENCE.sub(replaced, data)


def _use_local_names(root: etree._Element) -> None:
    """Drop namespaces from element names, in place: liblensfun's parser does not
    know them, so an element in a default namespace has its plain name."""
    for element in root.iter():
        tag = element.tag
        if isinstance(tag, str) and tag.startswith("{"):
            element.tag = tag.partition("}")[2]


#: libxml2 numbers lines up to this; beyond, an element's line is a guess.
_LIBXML2_LINES = 65535
# The markup of a document, for finding where each start tag ends: comments,
# CDATA sections, processing instructions, the document type and end tags
# (group 1 None), and start tags (group 1 their name).
_MARKUP = re.compile(
    rb"<!--.*?-->|<!\[CDATA\[.*?\]\]>|<\?.*?\?>|<!DOCTYPE(?:[^\[>]|\[.*?\]\s*)*>|</[^>]*>"
    rb"|<([^\s/>!?][^\s/>]*)(?:[^>\"']|\"[^\"]*\"|'[^']*')*>",
    re.DOTALL,
)


class _Lines:
    """The lines of a document's elements, for a file longer than libxml2 numbers:
    the line where each start tag ends, in document order, given to the
    elements of each piece as it is visited (:meth:`number`)."""

    def __init__(self, data: bytes) -> None:
        starts = []
        line, position = 1, 0
        for match in _MARKUP.finditer(data):
            if match.group(1) is not None:
                end = match.end() - 1
                line += data.count(b"\n", position, end)
                position = end
                starts.append(line)
        self.first = starts[0] if starts else 1
        self._starts = starts
        self._next = 0  # the start tag of the next element numbered
        self.of: dict[Any, int] = {}

    def skip_root(self) -> None:
        """Leave out the root's start tag: the pieces to come are its children."""
        self._next = max(self._next, 1)

    def number(self, piece: Any) -> None:
        """Number the elements of the next piece in document order."""
        self.release()
        elements = [e for e in piece.iter() if isinstance(e.tag, str)]
        found = self._starts[self._next : self._next + len(elements)]
        self._next += len(elements)
        self.of.update(zip(elements, found, strict=False))  # any left: libxml2 numbers them

    def release(self) -> None:
        """Let go of the elements numbered, while their piece is still in the tree.

        Letting go of an element of a piece cut out of the tree, lxml walks
        the piece in document order up to the first element still referred
        to: after the cut, the references to a piece's n elements, let go
        of in document order, would take time in n squared."""
        self.of.clear()


def _line_getter(lines: _Lines | None, root: Any) -> Callable[[Any], int]:
    """The function giving an element's line: libxml2's, or from ``lines``
    (for a whole tree given as ``root``, numbered at once)."""
    if lines is None:
        return _libxml2_line
    if root is not None:
        lines.number(root)
    else:
        lines.skip_root()
    of = lines.of

    def line_of(element: Any) -> int:
        found = of.get(element)
        return found if found is not None else _libxml2_line(element)

    return line_of


def _libxml2_line(element: Any) -> int:
    return element.sourceline or 0


def unknown_reference(data: bytes) -> tuple[int, int, str] | None:
    """(line, column, problem) of the first reference to an entity other than
    XML's five, or None."""
    if _SUSPECT.search(data) is None:  # no reference to anything else anywhere
        return None
    for match in _REFERENCE.finditer(data):
        if match.group(1) is not None:
            start = match.start()
            line = data.count(b"\n", 0, start) + 1
            column = start - data.rfind(b"\n", 0, start)
            name = match.group(1).decode("utf-8", "replace")
            return (
                line,
                column,
                (
                    f"reference to the entity {name}: only &lt; &gt; &amp; &quot; &apos; and "
                    "character references are allowed (liblensfun refuses the file)"
                ),
            )
    return None


def syntax_error(data: bytes, error: Exception) -> tuple[int, int, str]:
    """(line, column, sentence) of a libxml2 error, in words a user can act on."""
    text = (getattr(error, "msg", None) or str(error)).strip()
    match = _POSITION.search(text)
    if match:
        line, column, text = int(match.group(1)), int(match.group(2)), text[: match.start()]
    else:
        line = getattr(error, "lineno", 0) or 0
        column = (getattr(error, "offset", 0) or 0) + 1
    hinted = _PARSER_HINTS.search(text) is not None
    text = " ".join(_PARSER_HINTS.sub(" ", text).split())
    if not data.strip():
        return 1, 1, "the file is empty; a Lensfun database file holds a <lensdatabase> element"
    if hinted and "amplification" in text:
        text += " (entities are never expanded)"
    elif hinted:
        text += " (values and text over 10 MB and nesting over 256 levels are refused)"
    elif "encoding" in text.lower() or "utf-8" in text.lower():
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as decode_error:
            declared = declared_encoding(data)
            said = (
                f": liblensfun reads every file as UTF-8, whatever its declaration says"
                f" ({declared})"
                if declared is not None and declared.lower() not in ("utf-8", "utf8")
                else "; Lensfun database files are UTF-8"
            )
            text += (
                f" (byte 0x{data[decode_error.start]:02X} at offset {decode_error.start}"
                f" is not UTF-8{said})"
            )
    return line, column, text
