"""Stage 1, commits: the repository, read through :mod:`lensaudit.git`, and the
commits of the selection (``git log`` with dates and ``--first-parent``),
parents before children.

Nothing is checked out: the work tree, the index and the refs are left as
they are.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path, PurePosixPath

from .. import git as gitlayer
from ..read.paths import read_file


class HistoryError(Exception):
    """The history cannot be audited: no git, not a repository, no database in it."""


@dataclass(frozen=True)
class Commit:
    """A commit: full hash, parent hashes, ISO 8601 dates, author name, subject.

    ``date`` is the committer date, the one ``--since``/``--until`` select on.
    """

    hash: str
    parents: tuple[str, ...]
    date: str
    author_date: str
    author: str
    subject: str

    @property
    def short(self) -> str:
        return self.hash[:7]


def _unavailable(error: gitlayer.GitUnavailable) -> str:
    """The line that says git cannot be run at all (not installed, say)."""
    return f"cannot run git to read the history: {error}"


class Git:
    """One repository, read through :mod:`lensaudit.git`; git's failures as
    :class:`HistoryError`."""

    def __init__(self, repository: str | os.PathLike[str]) -> None:
        if not os.fsdecode(repository).strip():  # Path("") would be the working directory
            raise HistoryError(f"{os.fsdecode(repository)!r}: an empty or blank path: give REPO")
        self.repository = Path(repository)
        self.given = repository  # as the user wrote it, for messages
        if not self.repository.is_dir():
            problem = "not a directory" if self.repository.exists() else "no such directory"
            raise HistoryError(f"{repository}: {problem}")
        try:
            found = gitlayer.run(
                self.repository, "rev-parse", "--git-path", "shallow", "--git-path", "info/grafts"
            ).decode("utf-8", "replace")
        except gitlayer.GitUnavailable as error:
            raise HistoryError(_unavailable(error)) from None
        except gitlayer.GitError:
            raise HistoryError(f"{repository}: not a git repository") from None
        #: The files that cut a history short (a shallow clone) or graft one on.
        self._boundary_files = [self.repository / line for line in found.splitlines()]

    def boundary(self) -> str:
        """What makes the history of a commit other than its ancestors as stored:
        the commits a shallow clone stops at, grafts and replacements."""
        texts = []
        for path in self._boundary_files:
            try:
                texts.append(read_file(path).decode("utf-8", "replace"))
            except OSError:  # none: the usual case
                texts.append("")
        texts.append(self.run("for-each-ref", "--format=%(refname) %(objectname)", "refs/replace/"))
        return "\0".join(texts)

    def run(self, *args: str) -> str:
        """Standard output of ``git ARGS``; HistoryError with git's message on failure."""
        try:
            return gitlayer.run(self.repository, *args).decode("utf-8", "replace")
        except gitlayer.GitUnavailable as error:
            raise HistoryError(_unavailable(error)) from None
        except gitlayer.GitError as error:
            raise HistoryError(str(error)) from None

    def resolve_commit(self, revision: str) -> str:
        """The full id of the commit ``revision`` names; HistoryError if none."""
        try:
            return gitlayer.resolve_commit(self.repository, revision)
        except gitlayer.GitUnavailable as error:
            raise HistoryError(_unavailable(error)) from None
        except gitlayer.GitError:
            raise HistoryError(f"{revision!r} is not a commit of {self.given}") from None

    def objects(self, names: Sequence[str]) -> Iterator[tuple[str, str, bytes] | None]:
        """(object id, type, content) for each name (``<rev>:<path>`` or an id),
        or None, through one ``git cat-file --batch`` (see :func:`lensaudit.git.objects`)."""
        try:
            yield from gitlayer.objects(self.repository, names)
        except gitlayer.GitUnavailable as error:
            raise HistoryError(_unavailable(error)) from None
        except gitlayer.GitError as error:
            raise HistoryError(str(error)) from None

    def object_sizes(self, names: Sequence[str]) -> list[int | None]:
        """The size of each object named, or None (see :func:`lensaudit.git.object_sizes`)."""
        try:
            return gitlayer.object_sizes(self.repository, names)
        except gitlayer.GitUnavailable as error:
            raise HistoryError(_unavailable(error)) from None
        except gitlayer.GitError as error:
            raise HistoryError(str(error)) from None


def normalized_path(path: str) -> str:
    """``path`` inside the repository in git's form (``a/b``); HistoryError if it
    leaves the repository or is empty or blank (``.`` is the root)."""
    if not path.strip():
        raise HistoryError(f"{path!r}: an empty or blank database path: give one, . for the root")
    parts = [p for p in PurePosixPath(path.replace("\\", "/")).parts if p not in ("", ".")]
    if ".." in parts or any("\n" in p for p in parts) or path.startswith("/"):
        raise HistoryError(f"{path!r}: give the database path relative to the repository root")
    return "/".join(parts)


_ISO_DATE = re.compile(r"\d{4}-\d{2}-\d{2}(?:[T ]\d{2}:\d{2}(?::\d{2})?(?:Z|[+-]\d{2}:?\d{2})?)?\Z")


def _git_date(text: str | None, *, end_of_day: bool) -> str | None:
    """An ISO 8601 date or date-time for git; a bare date means its start or end.

    git would read almost anything as a date (an unknown word as "now"), so
    only ISO 8601 is accepted. A time without a zone is local time, as in git.
    """
    if text is None:
        return None
    text = text.strip()
    try:
        if not _ISO_DATE.match(text):
            raise ValueError(text)
        datetime.fromisoformat(text.replace("Z", "+00:00"))  # month 13, day 32
    except ValueError:
        raise HistoryError(
            f"{text!r} is not a date: use YYYY-MM-DD or YYYY-MM-DDTHH:MM[:SS][+HH:MM]"
        ) from None
    if len(text) == 10:  # git reads a bare date as that day at the current time
        text += "T23:59:59" if end_of_day else "T00:00:00"
    return text


_LOG_FORMAT = "%H%x1f%P%x1f%cI%x1f%aI%x1f%an%x1f%s%x1e"


def selection(since: str | None, until: str | None) -> list[str]:
    """``git log`` options selecting commits between the dates ``since`` and ``until``."""
    filters = [f"--since={d}" for d in [_git_date(since, end_of_day=False)] if d]
    return filters + [f"--until={d}" for d in [_git_date(until, end_of_day=True)] if d]


def log(
    git: Git, tip: str, filters: list[str], first_parent: bool, revision: str
) -> tuple[list[Commit], list[str]]:
    """The commits of ``git log`` from ``tip`` (with ``filters``), parents before
    children, oldest first, and the hashes of its first-parent line, newest first.

    Raises HistoryError when no commit is selected (``revision`` names ``tip``).
    """
    selected = filters + (["--first-parent"] if first_parent else [])
    text = git.run(
        "log", "--date-order", "--reverse", f"--format={_LOG_FORMAT}", *selected, tip, "--"
    )
    commits = []
    for record in text.split("\x1e"):
        record = record.strip("\n")
        if not record:
            continue
        hash_, parents, date, author_date, author, subject = record.split("\x1f")
        commits.append(Commit(hash_, tuple(parents.split()), date, author_date, author, subject))
    mainline = git.run("rev-list", "--first-parent", *filters, tip, "--").split()
    if not commits or not mainline:
        raise HistoryError(f"no commit of {revision} between the dates given")
    return commits, mainline
