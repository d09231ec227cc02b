"""Where a report's numbers come from: database, files, hash, versions, date.

The date is the current UTC time, or ``$SOURCE_DATE_EPOCH`` when set, so that
a report regenerated from the same inputs can be byte-identical.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..read.paths import lensfunpy_version, timestamp
from ..version import __version__

if TYPE_CHECKING:
    from ..pipeline import Audit


@dataclass(frozen=True)
class Provenance:
    """Facts identifying what was audited, all as display strings.

    ``timestamp`` is Lensfun's ``timestamp.txt`` (seconds since 1970) of each
    database directory that has one, ``content_hash`` the SHA-256 over the
    names and bytes of the files read (:func:`content_hash`).
    """

    database: str
    location: str
    files: int
    entries: int
    audited: int
    timestamp: str
    content_hash: str
    lensaudit_version: str
    lensfunpy_version: str
    generated: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def items(self) -> list[tuple[str, str]]:
        """(label, value) pairs in display order; empty values are left out."""
        labels = [
            ("Database", self.database),
            ("Location", self.location),
            ("Files read", str(self.files)),
            ("Distortion entries", f"{self.entries} ({self.audited} audited)"),
            ("Lensfun timestamp.txt", self.timestamp),
            ("Content hash (SHA-256)", self.content_hash),
            ("lensaudit", self.lensaudit_version),
            ("lensfunpy", self.lensfunpy_version),
            ("Generated", self.generated),
        ]
        return [(label, value) for label, value in labels if value]


def generated_at() -> str:
    """The report date, ISO 8601 UTC: now, or ``$SOURCE_DATE_EPOCH`` when set."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH", "").strip()
    seconds = int(epoch) if epoch.isdigit() else time.time()
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(seconds))


def _timestamps(paths: tuple[Path, ...]) -> str:
    stamps = []
    for path in paths:
        directory = path if path.is_dir() else path.parent
        stamp = timestamp(directory)
        if stamp:
            readable = stamp
            if stamp.isdigit():
                readable += time.strftime(" (%Y-%m-%d %H:%M UTC)", time.gmtime(int(stamp)))
            stamps.append(readable)
    return "; ".join(dict.fromkeys(stamps))


def content_hash(files: list[Path]) -> str:
    """SHA-256 over the names and bytes of the files, in the order given."""
    import hashlib  # hashlib: only for the report's content hashes

    digest = hashlib.sha256()
    for file in files:
        digest.update(os.fsencode(file.name) + b"\0")
        digest.update(file.read_bytes())
    return digest.hexdigest()


def collect(audit: Audit) -> Provenance:
    """Provenance of an audit (reads the files again to hash them)."""
    source = audit.source
    if source.bundled:
        name = f"Lensfun database bundled with lensfunpy {lensfunpy_version()}"
        location = "lensfunpy/db_files (installed with the lensfunpy package)"
    else:
        name = "Lensfun database"
        location = ", ".join(str(p) for p in source.paths) or source.label
    readable = [f.path for f in audit.files if f.path.is_file()]
    summary = audit.summary
    return Provenance(
        database=name,
        location=location,
        files=len(audit.files),
        entries=summary.entries,
        audited=summary.audited,
        timestamp=_timestamps(source.paths),
        content_hash=content_hash(readable) if readable else "",
        lensaudit_version=__version__,
        lensfunpy_version=lensfunpy_version(),
        generated=generated_at(),
    )
