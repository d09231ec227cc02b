"""Files of records in lensaudit's cache directory: the storage under every cache.

A store file is ``<kind>-<name>.cache``, with ``kind`` one of :data:`KINDS`,
and holds one value as :mod:`marshal` data (plain values only: reading one
cannot run code). It starts with a fixed header and a BLAKE2b-256 checksum
of the value and of the file's fingerprint, a text naming whatever made the
value (lensaudit's version, the layout of the records, a digest of the
code). The checksum is verified before anything is unmarshalled: a flipped
byte, a truncated file or a file of another fingerprint reads as no file.

A file may also hold its value as sealed parts (:meth:`RecordFile.write_parts`):
a head, checksummed as above with the seal of each part, then the parts,
each marshal data of its own, checked against its seal (:func:`unseal`)
only when it is used. Parts are sealed where they are made (a worker
process, for one), so that writing the file is mostly copying bytes.

A file is written whole to a temporary file beside it, then renamed over
it: a reader finds the old value or the new one, never a mixture. After each
write, the least recently used store files of the directory (of every kind)
beyond a number of files or a total size are removed, the one just written
excepted, and so are temporary files left behind for more than an hour.
Reading a file marks it as recently used.

The store raises nothing for a file that cannot be read; writing raises
OSError (the directory cannot be written) or ValueError (a value marshal
cannot store, or larger than the size bound), for each cache to decide
whether that is worth a word.
"""

from __future__ import annotations

import marshal
import os
import stat as stat_module
import time
from collections.abc import Callable
from pathlib import Path

try:  # BLAKE2 alone: hashlib would also load OpenSSL, a few ms a warm scan does not need
    from _blake2 import blake2b
except ImportError:
    from hashlib import blake2b

#: The kinds of store file; eviction considers only files named after one of them.
KINDS = ("parsed", "history", "check")

MAGIC = b"lensaudit cache\n"
#: The header of a file of sealed parts (as long as MAGIC).
PARTS_MAGIC = b"lensaudit parts\n"
CHECKSUM_SIZE = 32
_LENGTH_SIZE = 8  # the head's length, in a file of sealed parts
SUFFIX = ".cache"
_TEMPORARY_SUFFIX = ".tmp"
_ABANDONED_SECONDS = 3600  # a temporary file this old belongs to no running writer
# Opening a temporary file: it must not exist yet (nor be a link to anything).
_CREATE_NEW = (
    os.O_WRONLY
    | os.O_CREAT
    | os.O_EXCL
    | getattr(os, "O_NOFOLLOW", 0)
    | getattr(os, "O_CLOEXEC", 0)
    | getattr(os, "O_BINARY", 0)
)


def checksum(fingerprint: bytes, body: bytes | memoryview) -> bytes:
    """The checksum a store file carries for ``body`` made under ``fingerprint``."""
    digest = blake2b(fingerprint, digest_size=CHECKSUM_SIZE)
    digest.update(body)
    return digest.digest()


def seal(body: bytes | memoryview) -> bytes:
    """The seal of a part: BLAKE2b-256 of its bytes."""
    return blake2b(body, digest_size=CHECKSUM_SIZE).digest()


def sealed(value: object) -> tuple[bytes, bytes]:
    """``value`` as a part (its :mod:`marshal` data) and that part's seal:
    ``(seal, body)``. Raises ValueError for a value marshal cannot store."""
    body = marshal.dumps(value)
    return seal(body), body


def unseal(part_seal: bytes, body: bytes | memoryview) -> object:
    """The value of a part, or None if its bytes do not match ``part_seal``
    or are not marshal data."""
    if seal(body) != part_seal:
        return None
    try:
        return marshal.loads(body)
    except (EOFError, ValueError, TypeError):
        return None


def code_digest(package: Path, patterns: tuple[str, ...]) -> str:
    """Digest of the source files of ``package`` that ``patterns`` match (with
    their names), for a fingerprint: what a cache holds is valid only for the
    code that made it, and the version alone does not change while that code
    does. Files that cannot be read are left out (an installation without
    source files has its version to go by)."""
    digest = blake2b(digest_size=16)
    for module in sorted(path for pattern in patterns for path in package.glob(pattern)):
        try:
            name = module.relative_to(package).as_posix()
            digest.update(name.encode() + b"\0" + module.read_bytes())
        except (OSError, ValueError):
            pass
    return digest.hexdigest()


class RecordFile:
    """One store file: ``<kind>-<name>.cache`` in ``directory``, valid for ``fingerprint``.

    ``fingerprint`` may be given as a function that computes it, called once
    the first time it is needed (a file that is not there is read without
    it). ``max_files`` and ``max_bytes`` bound the store files of the
    directory after a write (and a file larger than ``max_bytes`` is neither
    read nor written).
    """

    def __init__(
        self,
        directory: Path,
        kind: str,
        name: str,
        fingerprint: bytes | Callable[[], bytes],
        *,
        max_files: int,
        max_bytes: int,
    ) -> None:
        if kind not in KINDS:
            raise ValueError(f"unknown store kind {kind!r}")
        self.kind = kind
        self.path = directory / f"{kind}-{name}{SUFFIX}"
        self._fingerprint = fingerprint
        self.max_files = max_files
        self.max_bytes = max_bytes

    @property
    def fingerprint(self) -> bytes:
        """What the file's value is valid for."""
        if callable(self._fingerprint):
            self._fingerprint = self._fingerprint()
        return self._fingerprint

    def _data(self) -> bytes | None:
        """The file's bytes, or None if it is missing, too large or not a regular file."""
        try:
            # Non-blocking, and regular files only: a FIFO put here must not hang a run.
            handle = os.open(self.path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        except OSError:
            return None
        try:
            status = os.fstat(handle)
            if not stat_module.S_ISREG(status.st_mode) or status.st_size > self.max_bytes:
                return None
            with os.fdopen(handle, "rb") as stream:
                handle = -1
                return stream.read()
        except OSError:
            return None
        finally:
            if handle != -1:
                os.close(handle)

    def _used(self) -> None:
        try:  # recently used: last to be evicted
            os.utime(self.path)
        except OSError:
            pass

    def read(self) -> object:
        """The value stored, or None if the file is missing, damaged, of another
        fingerprint, too large, or not a regular file."""
        data = self._data()
        if data is None:
            return None
        start = len(MAGIC) + CHECKSUM_SIZE
        body = memoryview(data)[start:]
        if not data.startswith(MAGIC) or data[len(MAGIC) : start] != checksum(
            self.fingerprint, body
        ):
            return None
        try:
            value = marshal.loads(body)
        except (EOFError, ValueError, TypeError):
            return None
        self._used()
        return value

    def read_parts(self) -> tuple[object, list[tuple[bytes, memoryview]]] | None:
        """The head and the parts written by :meth:`write_parts`: each part as its
        seal and its bytes, not yet checked (see :func:`unseal`). None if the
        file is missing, of another fingerprint or layout, or its head or
        length is damaged."""
        data = self._data()
        if data is None or not data.startswith(PARTS_MAGIC):
            return None
        start = len(PARTS_MAGIC) + CHECKSUM_SIZE
        view = memoryview(data)
        head_end = (
            start + _LENGTH_SIZE + int.from_bytes(view[start : start + _LENGTH_SIZE], "little")
        )
        body = view[start + _LENGTH_SIZE : head_end]
        if head_end > len(data) or view[len(PARTS_MAGIC) : start] != checksum(
            self.fingerprint, body
        ):
            return None
        try:
            head, seals = marshal.loads(body)
            spans = []  # each part's seal, and where its bytes start and end
            position = head_end
            for part_seal, length in seals:
                if not isinstance(part_seal, bytes) or not isinstance(length, int) or length < 0:
                    return None
                spans.append((part_seal, position, position + length))
                position += length
        except (EOFError, ValueError, TypeError):
            return None
        if position != len(data):
            return None
        self._used()
        return head, [(part_seal, view[first:end]) for part_seal, first, end in spans]

    def write(self, value: object) -> None:
        """Store ``value`` (see :meth:`write_body`)."""
        self.write_body(marshal.dumps(value))

    def write_body(self, body: bytes) -> None:
        """Store ``body``, a value as :func:`marshal.dumps` gives it, then evict.

        Raises OSError when the file cannot be written, ValueError when it
        would be larger than ``max_bytes`` (it would be evicted, never read).
        """
        self._write([MAGIC + checksum(self.fingerprint, body), body])

    def write_parts(self, head: object, parts: list[tuple[bytes, bytes | memoryview]]) -> None:
        """Store ``head`` and sealed ``parts`` (``(seal, body)`` pairs, as
        :func:`sealed` makes them), then evict; raises as :meth:`write_body`.

        The parts are written as they are: their seals, not their bytes, are
        what the file's checksum covers.
        """
        body = marshal.dumps((head, [(part_seal, len(part)) for part_seal, part in parts]))
        length = len(body).to_bytes(_LENGTH_SIZE, "little")
        start = PARTS_MAGIC + checksum(self.fingerprint, body) + length
        self._write([start, body, *(part for _, part in parts)])

    def _write(self, pieces: list[bytes | memoryview]) -> None:
        """Write the file as ``pieces`` in a row (through a temporary file), then evict."""
        if sum(map(len, pieces)) > self.max_bytes:
            raise ValueError(f"{self.path.name} would take more than {self.max_bytes:,} bytes")
        directory = self.path.parent
        directory.mkdir(parents=True, exist_ok=True)
        # A new file of a random name, as tempfile.mkstemp makes one (without
        # importing tempfile, which would add a few milliseconds to a first scan).
        temporary = directory / f"{self.kind}-{os.urandom(8).hex()}{_TEMPORARY_SUFFIX}"
        handle = os.open(temporary, _CREATE_NEW, 0o600)
        try:
            with os.fdopen(handle, "wb") as stream:
                for piece in pieces:
                    stream.write(piece)
            os.replace(temporary, self.path)
        except BaseException:
            try:
                os.unlink(temporary)
            except OSError:
                pass
            raise
        evict(directory, self.path, self.max_files, self.max_bytes)


def _store_name(name: str) -> bool:
    kind, dash, _ = name.partition("-")
    return bool(dash) and kind in KINDS and name.endswith((SUFFIX, _TEMPORARY_SUFFIX))


def evict(directory: Path, keep: Path, max_files: int, max_bytes: int) -> None:
    """Remove the least recently used store files of ``directory`` beyond ``max_files``
    files or ``max_bytes`` bytes in all (``keep`` stays and counts), and abandoned
    temporary files."""
    now = time.time()
    found = []
    try:
        candidates = [entry for entry in os.scandir(directory) if _store_name(entry.name)]
    except OSError:
        return
    for candidate in candidates:
        try:
            status = candidate.stat(follow_symlinks=False)
            if candidate.name.endswith(_TEMPORARY_SUFFIX):
                if now - status.st_mtime > _ABANDONED_SECONDS:
                    os.unlink(candidate.path)
                continue
            if candidate.name != keep.name and stat_module.S_ISREG(status.st_mode):
                found.append((status.st_mtime_ns, status.st_size, candidate.path))
        except OSError:
            continue
    try:
        count, total = 1, keep.stat().st_size
    except OSError:
        count, total = 0, 0
    full = False
    for _, size, candidate in sorted(found, key=lambda item: item[0], reverse=True):
        count, total = count + 1, total + size
        # Least recently used first out: once one does not fit, no older one is kept.
        full = full or count > max_files or total > max_bytes
        if full:
            try:
                os.unlink(candidate)
            except OSError:
                pass
