"""What ``lensaudit check`` keeps between runs, keyed by the content of each file.

One store file of lensaudit's cache directory, ``check-files.cache`` (see
:mod:`lensaudit.store`, bounded with every other store file by
:data:`lensaudit.cache.MAX_CACHE_FILES` and
:data:`lensaudit.cache.MAX_CACHE_BYTES`), holds per
:func:`lensaudit.cache.content_digest` of a file's bytes:

- its summary (:data:`lensaudit.check.parsing.FileSummary`: how many
  distortion records, its file-level problem, its lenses);
- its rows as :func:`lensaudit.check.parsing.read_parts` gives them, as
  marshal data within the record, unpacked only when a rule needs them;
- the findings of its entries, calibrations and duplicate focal lengths, per
  margin and ``--verbose``, without the name the file is shown as (a file of
  the checked database and the same bytes in a baseline share them).

Nothing in a record depends on a file's name or place. A file counts as
unchanged only when its bytes hash to a stored digest: size and modification
time are never trusted. Records are tied to lensaudit's version and to a
digest of the code that makes them (:func:`fingerprint`), so that an upgrade
or an edited checkout recomputes them. The records a run used are kept, then
earlier ones, most recently used first, while their rows take less than
:data:`KEEP_BYTES`.

The cache is an optimization only: a damaged, truncated or foreign store
file, or a record that does not have the expected shape, is not used, and a
cache directory that cannot be read or written means working without it,
without a message; the check's findings are the same either way.
"""

from __future__ import annotations

import marshal
from pathlib import Path

from .. import __version__

KIND = "check"
NAME = "files"
#: Rows of files the latest run did not use kept at most, in bytes of marshal
#: data: about two and a half more versions of Lensfun's whole database.
KEEP_BYTES = 8 * 1024 * 1024
#: Settings (margin, verbosity) whose findings are kept per file, the latest first.
MAX_SETTINGS = 4
_LAYOUT = "lensaudit check cache 1"
#: The code that decides a record: every top-level module (the loader, the
#: calibrations, the audits they use) and the check's stages.
_CODE = ("*.py", "check/*.py")


def fingerprint(package: Path = Path(__file__).parent.parent) -> bytes:
    """What the records are valid for: lensaudit's version, the record layout and
    a digest of the modules that make them."""
    from ..store import code_digest

    return f"{_LAYOUT} {__version__} {code_digest(package, _CODE)}".encode()


def _valid_summary(summary: object) -> bool:
    if not (isinstance(summary, tuple) and len(summary) == 3):
        return False
    count, problem, lenses = summary
    return (
        isinstance(count, int)
        and count >= 0
        and (
            problem is None
            or (
                isinstance(problem, tuple)
                and len(problem) == 5
                and all(isinstance(problem[i], str) for i in (0, 3, 4))
                and all(isinstance(problem[i], int) for i in (1, 2))
            )
        )
        and isinstance(lenses, list)
        and all(
            isinstance(lens, tuple)
            and len(lens) == 4
            and isinstance(lens[0], int)
            and isinstance(lens[1], str)
            and isinstance(lens[2], str)
            and (lens[3] is None or isinstance(lens[3], (float, str)))
            for lens in lenses
        )
    )


def _valid_record(record: object) -> bool:
    return (
        isinstance(record, list)
        and len(record) == 3
        and _valid_summary(record[0])
        and isinstance(record[1], bytes)
        and isinstance(record[2], dict)
    )


class CheckCache:
    """The check's records in ``directory`` (by default lensaudit's cache
    directory); see the module's description."""

    def __init__(self, directory: Path | None = None) -> None:
        from ..cache import cache_dir, record_file

        # digest -> [summary, rows as marshal data, {setting: findings}]
        self._records: dict[bytes, list] = {}
        self._used: dict[bytes, None] = {}  # digests met in this run, in order
        self._changed = False
        self._file = None
        try:
            self._file = record_file(KIND, NAME, fingerprint(), directory or cache_dir())
        except (OSError, RuntimeError, ValueError):
            return
        stored = self._file.read()
        if isinstance(stored, dict):
            self._records = {
                key: record
                for key, record in stored.items()
                if isinstance(key, bytes) and _valid_record(record)
            }

    @property
    def path(self) -> Path | None:
        """The store file, or None when no cache directory could be named."""
        return None if self._file is None else self._file.path

    def file(self, digest: bytes) -> tuple[tuple, bytes] | None:
        """(summary, rows as marshal data) of the content with ``digest``, or None."""
        record = self._records.get(digest)
        if record is None:
            return None
        self._used[digest] = None
        return record[0], record[1]

    def put_file(self, digest: bytes, summary: tuple, body: bytes) -> None:
        """Keep the summary and the rows (marshal data) parsed from content ``digest``."""
        self._used[digest] = None
        record = self._records.get(digest)
        if record is None or record[0] != summary or record[1] != body:
            self._records[digest] = [summary, body, {}]
            self._changed = True

    def findings(self, digest: bytes, setting: str) -> list | None:
        """The findings kept for content ``digest`` under ``setting``, or None."""
        record = self._records.get(digest)
        if record is None:
            return None
        found = record[2].get(setting)
        return found if isinstance(found, list) else None

    def put_findings(self, digest: bytes, setting: str, findings: list) -> None:
        """Keep the findings of content ``digest`` under ``setting`` (plain data)."""
        record = self._records.get(digest)
        if record is None:
            return
        try:
            marshal.dumps(findings)
        except ValueError:  # something marshal cannot store: worked out every time
            return
        settings = {setting: findings}
        for other, kept in record[2].items():
            if other != setting and len(settings) < MAX_SETTINGS:
                settings[other] = kept
        record[2] = settings
        self._changed = True

    def save(self) -> None:
        """Write the records if anything changed: those of this run first, then
        earlier ones within :data:`KEEP_BYTES`; silently skipped when not possible."""
        if self._file is None or not self._changed:
            return
        kept = {digest: self._records[digest] for digest in self._used if digest in self._records}
        size = 0
        for digest, record in self._records.items():
            if digest in kept:
                continue
            size += len(record[1])
            if size > KEEP_BYTES:
                break
            kept[digest] = record
        try:
            self._file.write(kept)
        except (OSError, ValueError):
            pass
