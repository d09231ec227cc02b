"""The one cache: a record per file content, shared by every command.

A record is named by the BLAKE2b digest of a file's bytes, so a file is
never trusted to be unchanged for its size or time (``git checkout`` and
``rsync -t`` restore times). It holds named sections, each what one stage
made of those bytes: the reader's tables (``tables``, ``calibrations``) and
the solver's metrics of the distortion rows (``metrics``). Nothing rendered
is kept: a record does not depend on how a command shows the file.

Where: ``$LENSAUDIT_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/lensaudit``
(if that is an absolute path, as the XDG specification requires), else
``~/.cache/lensaudit``; records are the files of its ``files`` directory.

Integrity: a record file starts with a fixed header, the fingerprint of
the code that made it (lensaudit's version and a digest of the reader's,
the normalizer's, the solver's and the metrics' sources) and the digest of
the content it is for (a record renamed or copied to another name is no
record), then a
:mod:`marshal` table of sections, each sealed with a BLAKE2b digest of its
bytes that is checked before they are unmarshalled. A damaged, truncated or
foreign record reads as no record; marshal data cannot run code. Records
are written whole to a temporary file and renamed, so a reader sees the
old record or the new one. After writing, the least recently used records
beyond :data:`MAX_RECORDS` files or :data:`MAX_BYTES` bytes are removed.
The cache is an optimization only: any problem reading or writing it means
working as if it were not there, without a word.
"""

from __future__ import annotations

import functools
import marshal
import os
import re
import time
from pathlib import Path

from ..version import __version__
from ..writing import running, write_file, writer_of
from .paths import read_file

# typing only for type checkers
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any

try:  # BLAKE2 alone: hashlib would also load OpenSSL, which a warm scan does not need
    from _blake2 import blake2b
except ImportError:  # pragma: no cover - every CPython has _blake2
    from hashlib import blake2b

#: Records kept at most, and their total size at most (least recently used go first).
MAX_RECORDS = 20_000
MAX_BYTES = 1 << 30
_MAGIC = b"lensaudit record 4\n"
_DIGEST_SIZE = 16
_SUFFIX = ".rec"
_ABANDONED_SECONDS = 3600  # a temporary file this old belongs to no running writer
#: The name of a temporary record of earlier versions: RECORD.PID.tmp
_EARLIER_TEMPORARY = re.compile(r"[^.].*\.rec\.([0-9]+)\.tmp")
#: The sources whose output the cache keeps, relative to the package.
_CODE = (
    "read/*.py", "normalizer.py", "solver/*.py", "metrics.py", "pipeline.py", "columns.py",
    "__init__.py",
)  # fmt: skip
_ERRORS = (OSError, ValueError, EOFError, TypeError, KeyError, IndexError)


def content_digest(data: bytes) -> bytes:
    """The key of a file's bytes."""
    return blake2b(data, digest_size=_DIGEST_SIZE).digest()


def content_hasher(data: bytes = b"") -> Any:
    """A hash object (``update``, ``digest``) that gives :func:`content_digest`
    of all the bytes it is given, for what is made of pieces."""
    return blake2b(data, digest_size=_DIGEST_SIZE)


def cache_dir() -> Path:
    """Directory holding lensaudit's cache.

    ``$LENSAUDIT_CACHE_DIR`` if set and not empty; else ``lensaudit`` in
    ``$XDG_CACHE_HOME`` if that is an absolute path; else ``~/.cache/lensaudit``.
    """
    explicit = os.environ.get("LENSAUDIT_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME", "")
    if not os.path.isabs(base):  # the XDG specification says to ignore relative paths
        base = os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "lensaudit"


@functools.cache
def fingerprint() -> bytes:
    """What records are valid for: the version and the code that makes them."""
    package = Path(__file__).resolve().parent.parent
    digest = blake2b(f"lensaudit {__version__}".encode(), digest_size=_DIGEST_SIZE)
    for pattern in _CODE:
        for path in sorted(package.glob(pattern)):
            digest.update(path.name.encode() + b"\0")
            try:
                digest.update(path.read_bytes())
            except OSError:
                pass
    return digest.digest()


class Cache:
    """Records by content digest (see the module's description).

    :meth:`get` a section of a record; :meth:`put` one, kept in memory until
    :meth:`save` writes every record that changed.
    """

    def __init__(self, root: str | os.PathLike[str] | None = None) -> None:
        #: The cache directory (:func:`cache_dir` unless given).
        self.root = Path(root) if root is not None else cache_dir()
        #: Where the records are.
        self.directory = self.root / "files"
        self._records: dict[bytes, dict[str, tuple[bytes, bytes]]] = {}
        self._changed: set[bytes] = set()

    def _path(self, digest: bytes) -> Path:
        return self.directory / (digest.hex() + _SUFFIX)

    def _record(self, digest: bytes) -> dict[str, tuple[bytes, bytes]]:
        record = self._records.get(digest)
        if record is None:
            record = self._records[digest] = self._load(digest)
        return record

    def _load(self, digest: bytes) -> dict[str, tuple[bytes, bytes]]:
        path = self._path(digest)
        try:
            data = read_file(path)  # never blocks, even on a FIFO put in its place
            head = _MAGIC + fingerprint() + digest  # a record renamed or copied is no record
            if data[: len(head)] != head:
                return {}
            sections = marshal.loads(memoryview(data)[len(head) :])
            if not isinstance(sections, dict) or not all(
                isinstance(k, str) and isinstance(v, tuple) and len(v) == 2
                for k, v in sections.items()
            ):
                return {}
        except _ERRORS:
            return {}
        try:
            os.utime(path)  # recently used: the last to be evicted
        except OSError:
            pass
        return sections

    def get(self, digest: bytes, section: str) -> object | None:
        """A section of the record of ``digest``, or None."""
        found = self._record(digest).get(section)
        if found is None:
            return None
        seal, body = found
        try:
            if blake2b(body, digest_size=_DIGEST_SIZE).digest() != seal:
                return None
            return marshal.loads(body)
        except _ERRORS:
            return None

    def put(self, digest: bytes, section: str, value: object) -> None:
        """Keep ``value`` (plain data) as a section of the record of ``digest``."""
        try:
            body = marshal.dumps(value)
        except ValueError:
            return
        record = self._record(digest)
        record[section] = (blake2b(body, digest_size=_DIGEST_SIZE).digest(), body)
        self._changed.add(digest)

    def save(self) -> None:
        """Write every record that changed, then remove the least recently used
        beyond the bounds; silently does nothing where the directory cannot be
        written."""
        if not self._changed:
            return
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
            for digest in sorted(self._changed):
                self._write(digest)
        except (OSError, ValueError):
            return
        finally:
            self._changed.clear()
        evict(self.directory, MAX_RECORDS, MAX_BYTES)

    def _write(self, digest: bytes) -> None:
        path = self._path(digest)
        body = _MAGIC + fingerprint() + digest + marshal.dumps(self._records[digest])
        write_file(path, body)  # its temporary file removed, even on Ctrl-C or SIGTERM


def _abandoned(name: str, age: float) -> bool:
    """Whether the temporary file ``name``, ``age`` seconds old, is no writer's:
    the process named in it is gone (a run killed with SIGKILL); one of an
    earlier version's naming (RECORD.PID.tmp) is judged by its process as
    well; any other, by its age."""
    pid = writer_of(name)
    if pid is None:
        found = _EARLIER_TEMPORARY.fullmatch(name)
        pid = int(found[1]) if found else None
    if pid is None:
        return age > _ABANDONED_SECONDS
    return not running(pid)


def evict(directory: Path, max_records: int, max_bytes: int) -> None:
    """Remove the least recently written records of ``directory`` beyond
    ``max_records`` files or ``max_bytes`` bytes, and abandoned temporary files."""
    now = time.time()
    found = []
    try:
        entries = list(os.scandir(directory))
    except OSError:
        return
    for entry in entries:
        try:
            status = entry.stat(follow_symlinks=False)
            if entry.name.endswith(".tmp"):
                if _abandoned(entry.name, now - status.st_mtime):
                    os.unlink(entry.path)
            elif entry.name.endswith(_SUFFIX):
                found.append((status.st_mtime_ns, status.st_size, entry.path))
        except OSError:
            continue
    found.sort(reverse=True)
    count = total = 0
    for _, size, path in found:
        count, total = count + 1, total + size
        if count > max_records or total > max_bytes:
            try:
                os.unlink(path)
            except OSError:
                pass
