"""What the audit of a history gives: revisions with their counts, the entries
of the newest revision with their introducers, and the :class:`History`."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from ..columns import COLUMNS
from ..read.records import MODEL_COEFFICIENTS, DistortionEntry
from .commits import Commit
from .outputs import write_csv

if TYPE_CHECKING:
    import pandas

MODELS = tuple(MODEL_COEFFICIENTS)

#: Counts kept per file version and summed per revision, in this order.
COUNT_COLUMNS = (
    "entries",
    "audited",
    "ptlens",
    "poly3",
    "poly5",
    "finite",
    "ptlens_finite",
    "poly3_finite",
    "poly5_finite",
    "folds_in_image",
    "folds_in_image_rectilinear",
    "folds_in_image_paper_units_rectilinear",
)

#: Columns of ``history.csv``: one row per commit that changes the database.
HISTORY_COLUMNS = (
    "commit",
    "date",
    "author_date",
    "author",
    "subject",
    "merge",
    "mainline",
    "files",
    "files_with_errors",
    *COUNT_COLUMNS[:2],
    "not_audited",
    *COUNT_COLUMNS[2:6],
    "share_finite",
    *COUNT_COLUMNS[6:],
    "errors",
)

#: Columns of ``introduced.csv``: one row per entry of the newest revision
#: with a finite r_max, and the commit that introduced its coefficients.
INTRODUCED_COLUMNS = tuple(
    name for name in COLUMNS
    if name not in {"real_focal", "tail", "r_corner", "r_corner_paper", "status", "message"}
) + ("commit", "date", "author", "subject")  # fmt: skip


#: Columns of ``events.csv``.
EVENT_COLUMNS = (
    "commit", "date", "author", "subject", "event", "maker", "lens", "crop_factor", "model",
    "focal", "coefficients", "branch_commit", "branch_subject",
)  # fmt: skip
#: The events of :class:`FoldEvent`.
FOLDS, NO_LONGER_FOLDS = "folds", "no-longer-folds"


@dataclass(frozen=True)
class FoldEvent:
    """An entry that starts folding inside its image at a commit of the
    first-parent line (``folds``), or stops (``no-longer-folds``: fixed,
    changed or removed). ``identity`` is the entry's (maker, lens, crop
    factor, model, focal, coefficients). Where ``commit`` merges a branch,
    ``branch_commit`` is the commit of that branch where it happened (None
    if none is found)."""

    commit: Commit
    event: str
    identity: tuple
    branch_commit: Commit | None = None

    def record(self) -> dict[str, Any]:
        """The row of ``events.csv`` as a dict, keys in :data:`EVENT_COLUMNS` order."""
        maker, lens, crop, model, focal, coefficients = self.identity
        c, b = self.commit, self.branch_commit
        return dict(
            zip(
                EVENT_COLUMNS,
                (c.short, c.date, c.author, c.subject, self.event, maker, lens, crop, model,
                 focal, " ".join(f"{name}={value!r}" for name, value in zip(
                     MODEL_COEFFICIENTS[model], coefficients, strict=True)),
                 b.short if b else "", b.subject if b else ""),
                strict=True,
            )
        )  # fmt: skip


@dataclass(frozen=True)
class Revision:
    """The database at one commit that changes it: counts over all its files.

    ``counts`` holds :data:`COUNT_COLUMNS`; ``mainline`` says whether the
    commit is on the first-parent line of the revision audited (a commit of
    a merged branch is not). ``errors`` lists files that are not well-formed.
    """

    commit: Commit
    mainline: bool
    files: int
    counts: dict[str, int]
    errors: tuple[str, ...] = ()

    def __getitem__(self, name: str) -> Any:
        return self.record()[name]

    @property
    def share_finite(self) -> float:
        """Share of audited entries with a finite r_max (0 to 1; NaN if none)."""
        audited = self.counts["audited"]
        return self.counts["finite"] / audited if audited else float("nan")

    def record(self) -> dict[str, Any]:
        """The row of ``history.csv`` as a dict, keys in :data:`HISTORY_COLUMNS` order."""
        c = self.commit
        values = dict(
            self.counts,
            commit=c.hash,
            date=c.date,
            author_date=c.author_date,
            author=c.author,
            subject=c.subject,
            merge=len(c.parents) > 1,
            mainline=self.mainline,
            files=self.files,
            files_with_errors=len(self.errors),
            not_audited=self.counts["entries"] - self.counts["audited"],
            share_finite=self.share_finite,
            errors="; ".join(self.errors),
        )
        return {name: values[name] for name in HISTORY_COLUMNS}


@dataclass(frozen=True)
class IntroducedEntry:
    """An entry of the newest revision with a finite r_max, and who introduced it.

    ``commit`` is None when the coefficients were already there before the
    oldest commit examined (a history cut by ``since``). r_max and d_max are
    in Hugin units; ``r_normalized_paper`` uses the paper's mixed units.
    """

    entry: DistortionEntry
    r_max: float
    d_max: float
    r_normalized: float
    r_normalized_paper: float
    folds_in_image: bool
    commit: Commit | None

    def record(self) -> dict[str, Any]:
        """The row of ``introduced.csv`` as a dict, keys in :data:`INTRODUCED_COLUMNS` order."""
        e, c = self.entry, self.commit
        values = {name: getattr(e, name) for name in INTRODUCED_COLUMNS[:14]}
        values.update(
            r_max=self.r_max,
            d_max=self.d_max,
            r_normalized=self.r_normalized,
            r_normalized_paper=self.r_normalized_paper,
            folds_in_image=self.folds_in_image,
            commit=c.hash if c else "",
            date=c.date if c else "",
            author=c.author if c else "",
            subject=c.subject if c else "",
        )
        return values


@dataclass
class History:
    """The audit of a database's history (see :func:`audit_history`).

    ``revisions`` are the commits that change the database, oldest first;
    ``newest`` is the newest commit on the first-parent line, whose entries
    ``introduced`` describes. The remaining fields say what the run cost:
    ``commits`` examined, distinct file versions (``blobs``), those read
    through :mod:`lensaudit.read` (``blobs_read``: parsed, or taken from the
    one cache), those whose audit was the last run's, taken whole from the
    history's index (``blobs_reused``), and ``seconds``.
    """

    repository: Path
    path: str
    revision: str
    first_parent: bool
    revisions: list[Revision]
    newest: Commit
    introduced: list[IntroducedEntry]
    commits: int
    blobs: int
    blobs_read: int
    blobs_reused: int
    seconds: float
    warnings: list[str] = field(default_factory=list)
    #: Entries starting and stopping to fold along the first-parent line, oldest first.
    events: list[FoldEvent] = field(default_factory=list)

    def records(self) -> list[dict[str, Any]]:
        """Rows of ``history.csv``, oldest commit first."""
        return [revision.record() for revision in self.revisions]

    def introduced_records(self) -> list[dict[str, Any]]:
        """Rows of ``introduced.csv``, in database order (file, then line)."""
        return [entry.record() for entry in self.introduced]

    def to_dataframe(self) -> pandas.DataFrame:
        """``history.csv`` as a DataFrame; ``date`` and ``author_date`` as UTC datetimes."""
        import pandas  # pandas: only for a DataFrame, which no command needs

        frame = pandas.DataFrame(self.records(), columns=list(HISTORY_COLUMNS))
        for name in ("date", "author_date"):
            frame[name] = pandas.to_datetime(frame[name], utc=True)
        return frame

    def introduced_dataframe(self) -> pandas.DataFrame:
        """``introduced.csv`` as a DataFrame."""
        import pandas  # pandas: only for a DataFrame, which no command needs

        return pandas.DataFrame(self.introduced_records(), columns=list(INTRODUCED_COLUMNS))

    def write_csv(self, stream: TextIO) -> None:
        """Write ``history.csv``: floats round-trip, booleans ``true``/``false``."""
        write_csv(stream, HISTORY_COLUMNS, self.records())

    def write_events_csv(self, stream: TextIO) -> None:
        """Write ``events.csv``: each entry starting or stopping to fold, oldest first."""
        write_csv(stream, EVENT_COLUMNS, [event.record() for event in self.events])

    def write_introduced_csv(self, stream: TextIO) -> None:
        """Write ``introduced.csv``: floats round-trip, ``inf`` for infinite values."""
        write_csv(stream, INTRODUCED_COLUMNS, self.introduced_records())
