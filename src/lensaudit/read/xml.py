"""The one XML parser of lensaudit: safe, and strict where liblensfun is.

Parsing never touches the network, never loads a DTD or an external entity
(a FIFO named as one cannot hang the run), never applies an ``<!ATTLIST>``
default and never expands an entity. A file that refers to an entity other
than XML's five (``&lt;`` ...) or a character reference (``&#246;``) is
refused, as liblensfun (GLib's GMarkup) refuses it: libxml2 would otherwise
give such a value as empty or with the entity's text.

Line numbers are those of the file: CR-only line ends count as line breaks
(libxml2 would see one long line), and lines beyond 65,535 keep their number.
"""

from __future__ import annotations

import re
from collections import namedtuple

from .records import STATUS_NOT_DATABASE, STATUS_OK, STATUS_XML_ERROR

# typing only for type checkers
TYPE_CHECKING = False
if TYPE_CHECKING:
    from lxml import etree

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


class Parsed(
    namedtuple(
        "Parsed",
        ("root", "status", "line", "column", "problem"),
        defaults=(STATUS_OK, 0, 0, ""),
    )
):
    """A file's XML tree and what is wrong with the file as a whole.

    ``status`` is ``ok``, ``xml_error`` (``root`` is then what libxml2's
    recovery mode can still read, or None) or ``not_database`` (the root is
    not ``<lensdatabase>``); ``line`` and ``column`` say where, ``problem``
    says what, without the position.
    """

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
    from lxml import etree

    return etree.XMLParser(
        recover=recover,
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        attribute_defaults=False,
        huge_tree=False,
        remove_pis=True,
        collect_ids=False,  # no table of xml:id values: nothing looks them up
    )


def parse(data: bytes) -> Parsed:
    """Parse one file's content, as liblensfun reads it: without namespaces."""
    from lxml import etree

    if b"\r" in data:  # XML's line-end normalization, done first so lines count
        data = data.replace(b"\r\n", b"\n").replace(b"\r", b"\n")
    try:
        root = etree.fromstring(data, parser())
    except etree.XMLSyntaxError as error:
        line, column, problem = syntax_error(data, error)
        return Parsed(_recovered(data), STATUS_XML_ERROR, line, column, problem)
    if b"&" in data and b"<!DOCTYPE" in data:
        found = unknown_reference(data)
        if found is not None:
            line, column, problem = found
            return Parsed(_recovered(data), STATUS_XML_ERROR, line, column, problem)
    if b"xmlns" in data:
        _use_local_names(root)
    if root.tag != DATABASE_ROOT:
        tag = root.tag if isinstance(root.tag, str) else "?"
        if len(tag) > 40:
            tag = tag[:40] + "..."
        problem = f"root element is <{tag}>, not <{DATABASE_ROOT}>: not a Lensfun database file"
        return Parsed(root, STATUS_NOT_DATABASE, root.sourceline or 1, 0, problem)
    return Parsed(root)


def unknown_reference(data: bytes) -> tuple[int, int, str] | None:
    """(line, column, problem) of the first reference to an entity other than
    XML's five, or None."""
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


def _recovered(data: bytes) -> etree._Element | None:
    """What libxml2's recovery mode can still read of a broken file, or None."""
    from lxml import etree

    try:
        root = etree.fromstring(data, parser(recover=True))
    except etree.XMLSyntaxError:
        return None
    if root is not None and b"xmlns" in data:
        _use_local_names(root)
    return root


def _use_local_names(root: etree._Element) -> None:
    """Drop namespaces from element names, in place: liblensfun's parser does not
    know them, so an element in a default namespace has its plain name."""
    for element in root.iter():
        tag = element.tag
        if isinstance(tag, str) and tag.startswith("{"):
            element.tag = tag.partition("}")[2]


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
            text += (
                f" (byte 0x{data[decode_error.start]:02X} at offset {decode_error.start}"
                f" is not UTF-8; Lensfun database files are UTF-8)"
            )
    return line, column, text
