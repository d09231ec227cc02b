"""Read-only access to git repositories, through the git command.

Only plumbing is used, in an environment that never takes optional locks
(``GIT_OPTIONAL_LOCKS=0``: a run never refreshes the index), never prompts
for credentials, reads pathspecs literally and gives git's messages in
English, so that the work tree, the index and the refs of the repository
are left as they are, whatever else runs in it.
"""

from __future__ import annotations

import os
import subprocess
import threading
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

# typing only for type checkers, as elsewhere in lensaudit.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import IO

#: Added to the environment of every git command.
ENVIRONMENT = {
    "GIT_OPTIONAL_LOCKS": "0",
    "GIT_TERMINAL_PROMPT": "0",
    "GIT_LITERAL_PATHSPECS": "1",
    "LC_ALL": "C",
}


class GitError(Exception):
    """git ran and failed; the message is the last line git wrote on standard error."""


class GitUnavailable(Exception):
    """git could not be run at all (not installed, say); the message says why."""


@dataclass(frozen=True)
class TreeEntry:
    """One line of ``git ls-tree``: mode (``100644``), type (``blob``), object id, path."""

    mode: str
    type: str
    oid: str
    path: str


def _why_not_run(error: OSError) -> str:
    """Why git could not be started, in words for the user."""
    if isinstance(error, FileNotFoundError):
        return "no git command on PATH"
    return f"git: {error.strerror or error}"


def _environment() -> dict[str, str]:
    return {**os.environ, **ENVIRONMENT}


def _command(repository: str | os.PathLike[str], arguments: Sequence[str]) -> list[str]:
    return ["git", "-C", os.fspath(repository), "-c", "log.showSignature=false", *arguments]


def run(repository: str | os.PathLike[str], *arguments: str, stdin: bytes | None = None) -> bytes:
    """Standard output of ``git ARGUMENTS`` run in ``repository`` (any directory
    inside it). Raises :class:`GitError` when git fails, :class:`GitUnavailable`
    when it cannot run."""
    try:
        completed = subprocess.run(
            _command(repository, arguments),
            input=stdin,
            capture_output=True,
            check=False,
            env=_environment(),
        )
    except OSError as error:
        raise GitUnavailable(_why_not_run(error)) from None
    if completed.returncode != 0:
        lines = completed.stderr.decode("utf-8", "replace").strip().splitlines()
        raise GitError(lines[-1] if lines else f"git {arguments[0]} failed")
    return completed.stdout


def top_level(path: str | os.PathLike[str]) -> Path:
    """The top directory of the work tree holding ``path`` (a directory).
    Raises :class:`GitError` when it is in no repository."""
    return Path(os.fsdecode(run(path, "rev-parse", "--show-toplevel").strip()))


def resolve_commit(repository: str | os.PathLike[str], revision: str) -> str:
    """The full id of the commit ``revision`` names (a tag is followed to its
    commit). Raises :class:`GitError` when it names none; a revision that
    starts with ``-`` is never taken for an option."""
    return (
        run(
            repository,
            "rev-parse",
            "--verify",
            "--quiet",
            "--end-of-options",
            f"{revision}^{{commit}}",
        )
        .decode("ascii", "replace")
        .strip()
    )


def list_tree(
    repository: str | os.PathLike[str],
    commit: str,
    paths: Sequence[str] = (),
    recursive: bool = False,
) -> list[TreeEntry]:
    """The entries of ``commit``'s tree under ``paths`` (relative to the top
    of the repository; a directory is listed with a trailing ``/``, the whole
    tree's top level without paths); with ``recursive``, the files in their
    subdirectories too, and not the subdirectories themselves."""
    listing = run(
        repository,
        "ls-tree",
        "-z",
        "--full-tree",
        *(["-r"] if recursive else []),
        commit,
        *(["--", *paths] if paths else []),
    )
    entries = []
    for record in listing.split(b"\0"):
        meta, _, path = record.partition(b"\t")
        fields = meta.split()
        if len(fields) == 3:
            mode, kind, oid = (field.decode("ascii", "replace") for field in fields)
            entries.append(TreeEntry(mode, kind, oid, os.fsdecode(path)))
    return entries


def log(
    repository: str | os.PathLike[str],
    revision: str,
    path: str | None = None,
    max_count: int | None = None,
) -> list[str]:
    """Ids of the commits reachable from ``revision``, newest first, that
    change ``path`` (all of them without one), at most ``max_count``."""
    arguments = ["log", "--format=%H"]
    if max_count is not None:
        arguments.append(f"--max-count={max_count}")
    arguments += ["--end-of-options", revision, "--"]
    if path is not None:
        arguments.append(path)
    return run(repository, *arguments).decode("ascii").split()


def _cat_file(repository: str | os.PathLike[str]) -> subprocess.Popen[bytes]:
    """A ``git cat-file --batch`` of ``repository``, its input and output piped here."""
    try:
        return subprocess.Popen(
            _command(repository, ["cat-file", "--batch"]),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            env=_environment(),
        )
    except OSError as error:
        raise GitUnavailable(_why_not_run(error)) from None


def objects(
    repository: str | os.PathLike[str], names: Sequence[str | bytes]
) -> Iterator[tuple[str, str, bytes] | None]:
    """(object id, type, content) for each name (an object id or
    ``<revision>:<path>``), in order, or None for a name that names no
    object (or more than one).

    One ``git cat-file --batch`` process answers all of them; a thread writes
    the requests while the answers are read, so that neither side waits on
    the other, and is done when the last answer has been read. Raises
    :class:`GitUnavailable`, or :class:`GitError` when git stops early.
    """
    if not names:
        return
    process = _cat_file(repository)
    assert process.stdin is not None and process.stdout is not None
    requests = b"".join(
        (name if isinstance(name, bytes) else name.encode("utf-8", "surrogateescape")) + b"\n"
        for name in names
    )

    def feed() -> None:
        try:
            process.stdin.write(requests)
            process.stdin.close()
        except OSError:
            pass  # git stopped early; the reader says so

    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    answers = process.stdout
    try:
        for _ in names:
            yield _answer(answers)
    finally:
        process.kill()
        feeder.join()
        answers.close()
        process.wait()


def _answer(answers: IO[bytes]) -> tuple[str, str, bytes] | None:
    """The next answer of a ``git cat-file --batch``: (object id, type, content), or
    None for a name that names no object. Raises GitError when git has stopped."""
    header = answers.readline()
    if not header:
        raise GitError("git cat-file stopped before answering every request")
    parts = header.split()
    if len(parts) != 3:  # "<name> missing" or "<name> ambiguous"
        return None
    size = int(parts[2])
    data = answers.read(size)
    answers.read(1)  # the newline after the content
    if len(data) != size:
        raise GitError("git cat-file stopped before answering every request")
    return parts[0].decode("ascii", "replace"), parts[1].decode("ascii", "replace"), data


def object_sizes(repository: str | os.PathLike[str], names: Sequence[str]) -> list[int | None]:
    """The size in bytes of each object named (an object id), in order; None for a
    name that names no object. One ``git cat-file --batch-check``."""
    if not names:
        return []
    answer = run(
        repository, "cat-file", "--batch-check", stdin="".join(f"{n}\n" for n in names).encode()
    )
    sizes: list[int | None] = []
    for line in answer.splitlines():
        parts = line.split()
        sizes.append(int(parts[2]) if len(parts) == 3 else None)
    if len(sizes) != len(names):
        raise GitError("git cat-file stopped before answering every request")
    return sizes
