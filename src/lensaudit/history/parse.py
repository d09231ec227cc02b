"""Stage 3, parse: each file version as plain data, parsed piece by piece in
forked worker processes.

A worker turns a file version into summaries (:data:`Summary`): per audited
entry, its identity across revisions (:func:`entry_identity`), what its
metrics depend on (its audit key) and whether its lens is rectilinear.
"""

from __future__ import annotations

import hashlib
import re
import threading
from collections.abc import Callable, Sequence
from operator import attrgetter
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .. import loader
from ..loader import MODEL_COEFFICIENTS, STATUS_OK, DistortionEntry

if TYPE_CHECKING:
    from .audit import Auditor, Parsed
    from .commits import BlobReader


def _coefficient_getter(names: tuple[str, ...]) -> Callable[[DistortionEntry], tuple]:
    getter = attrgetter(*names)
    return getter if len(names) > 1 else lambda entry: (getter(entry),)


# model -> function giving an entry's coefficients of that model, as a tuple.
_COEFFICIENTS = {model: _coefficient_getter(names) for model, names in MODEL_COEFFICIENTS.items()}


def entry_identity(entry: DistortionEntry) -> tuple:
    """How an entry is recognised in another revision: maker, lens, crop factor,
    model, focal (mm) and the model's coefficients."""
    return (
        entry.maker,
        entry.lens,
        entry.crop_factor,
        entry.model,
        entry.focal,
        _COEFFICIENTS[entry.model](entry),
    )


#: What a run of entries holds, as plain data (a worker process sends it back
#: marshalled): the number of entries, then, per audited entry, its identity,
#: its audit key and whether its lens is rectilinear.
Summary = tuple[int, list[tuple], list[tuple], list[bool]]


def summarize(entries: Sequence[DistortionEntry]) -> Summary:
    """The summary of ``entries`` (see :data:`Summary`)."""
    from ..metrics import is_circular_fisheye

    identities, keys, rectilinear = [], [], []
    for entry in entries:
        if entry.status != STATUS_OK:
            continue
        identity = entry_identity(entry)
        identities.append(identity)
        # What the metrics depend on: model, coefficients, crop, aspect, focal
        # and whether the image is a circle.
        keys.append(
            (
                entry.model,
                identity[5],
                entry.crop_factor,
                entry.aspect_ratio,
                entry.focal,
                is_circular_fisheye(entry.lens, entry.type),
            )
        )
        rectilinear.append(entry.type == "rectilinear")
    return len(entries), identities, keys, rectilinear


#: What ``seen`` gives for a piece not parsed yet (see :func:`parse_blob`).
_UNSEEN: Any = object()

#: The top-level elements a file version is cut into: lenses, cameras, mounts.
_PIECE = re.compile(rb"<(lens|camera|mount)>")
_PLACEHOLDER_TAG = "lensaudit-piece"
_PLACEHOLDER = f"<{_PLACEHOLDER_TAG}/>".encode()
_DECLARED_ENCODING = re.compile(rb"""\A(?:\xef\xbb\xbf)?<\?xml[^>]*?encoding\s*=\s*["']([^"']*)""")

#: A parsed file version as plain data (a worker process sends it back
#: marshalled): its error or "", the digests of its pieces in order (empty:
#: the file was read whole), and the summaries this process made for pieces
#: it had not seen before (the whole file's under the digest b"").
Pieces = tuple[str, list[bytes], list[tuple[bytes, Summary]]]


def _internal_subset(data: bytes) -> bool:
    """Whether the document type declares anything itself (entities, say); an
    external one is never loaded."""
    doctype = data.find(b"<!DOCTYPE")
    return doctype >= 0 and b"[" in data[doctype : data.find(b">", doctype)]


def _piece_spans(data: bytes) -> list[tuple[int, int]]:
    """(start, end) of each ``<lens>...</lens>`` (camera, mount) in the text."""
    spans = []
    position = 0
    while match := _PIECE.search(data, position):
        closing = b"</" + match.group(1) + b">"
        end = data.find(closing, match.end())
        if end < 0:
            break  # the skeleton will not parse
        position = end + len(closing)
        spans.append((match.start(), position))
    return spans


def parse_blob(data: bytes, name: str, seen: dict[bytes, bytes | None]) -> Pieces:
    """What one file version holds, reading each distinct piece of it once.

    Successive versions of a file share most of their lenses, so the file is
    cut into its top-level ``<lens>``, ``<camera>`` and ``<mount>`` elements
    (the pieces) by their text, each known by a digest of its bytes. The
    rest of the file, with a placeholder element for each piece, must parse
    as a ``<lensdatabase>`` whose children include exactly those
    placeholders, and each piece must parse alone; then the file is
    well-formed and its entries are those of its pieces in order, since an
    entry's context comes from its own ``<lens>``. ``seen`` maps the pieces
    this process has parsed (their bytes: a dictionary lookup hashes them
    faster than a digest would) to their digest, or None if they did not
    parse. A file
    that does not qualify (not well-formed, namespaces, declarations in its
    document type, an encoding other than UTF-8, entries outside the pieces)
    is read whole, as the loader reads it.
    """
    from lxml import etree

    made: list[tuple[bytes, Summary]] = []

    def whole() -> Pieces:
        entries, error = loader.read_bytes(data, name)
        made.append((b"", summarize(entries)))
        return error, [], made

    declared = _DECLARED_ENCODING.match(data)
    if (
        b"xmlns" in data
        or _internal_subset(data)
        or _PLACEHOLDER_TAG.encode() in data
        or (declared is not None and declared.group(1).lower() not in (b"utf-8", b"utf8"))
    ):
        return whole()
    spans = _piece_spans(data)
    if not spans:
        return whole()
    parser = loader.make_parser()
    skeleton, position = [], 0
    for start, end in spans:
        skeleton += (data[position:start], _PLACEHOLDER)
        position = end
    skeleton.append(data[position:])
    try:
        root = etree.fromstring(b"".join(skeleton), parser)
    except etree.XMLSyntaxError:
        return whole()
    if (
        root.tag != loader.DATABASE_ROOT
        or sum(child.tag == _PLACEHOLDER_TAG for child in root) != len(spans)
        or next(root.iter("distortion"), None) is not None
    ):
        return whole()
    digests = []
    for start, end in spans:
        piece = data[start:end]
        digest = seen.get(piece, _UNSEEN)
        if digest is _UNSEEN:
            try:
                element = etree.fromstring(b"<lensdatabase>" + piece + b"</lensdatabase>", parser)
            except etree.XMLSyntaxError:
                element = None
            digest = None
            if element is not None:
                digest = hashlib.blake2b(piece, digest_size=16).digest()
                made.append((digest, summarize(list(loader.entries_from_tree(element, name)))))
            seen[piece] = digest
        if digest is None:
            return whole()
        digests.append(digest)
    return "", digests, made


def parse_blobs(
    blobs: Sequence[str],
    sizes: Sequence[int],
    names: dict[str, str],
    keep: set[str],
    auditor: Auditor,
    reader: BlobReader,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Parsed]:
    """Parse file versions (``blobs``, of ``sizes`` bytes, ``names`` their file names)
    in worker processes (:mod:`lensaudit.workers`) while this process parses
    those whose entries are kept (``keep``, the newest revision's). Each
    process reads what it parses through ``reader``, as it goes, so that
    reading overlaps parsing and no process holds every version at once.
    ``progress(done, total)`` is called as file versions are taken up."""
    from .. import workers

    others = [(blob, size) for blob, size in zip(blobs, sizes, strict=True) if blob not in keep]
    jobs = [workers.Job(Path(blob), names[blob], size=size) for blob, size in others]
    seen: dict[bytes, bytes | None] = {}  # pieces parsed, per process (each worker has its own)
    parsed: dict[str, Parsed] = {}
    kept = [blob for blob in blobs if blob in keep]
    done = [0, 0]  # kept, others (the others' count may come from another thread)
    reporting = threading.Lock()

    def report(others: int = -1, _: int = 0) -> None:
        with reporting:
            if others >= 0:
                done[1] = max(done[1], others)
            if progress is not None:
                progress(sum(done), len(kept) + len(jobs))

    def parse_kept() -> None:
        for blob in kept:
            parsed[blob] = auditor.parse(reader.read(blob), names[blob], keep=True)
            done[0] += 1
            report()

    def parse_other(job: workers.Job) -> Pieces:
        return parse_blob(reader.read(job.path.name), job.name, seen)

    results = workers.parse_all(jobs, parse_other, parse_kept, report)
    for result in results:
        auditor.add_pieces(result[2])
    for (blob, _), result in zip(others, results, strict=True):
        parsed[blob] = auditor.assemble(result)
    return parsed
