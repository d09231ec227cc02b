"""Writing without losing anything: an output never lands on an input, a
command's files appear all together or not at all, and a file patched in
place keeps its mode, owner and group.

Every file is first written to a temporary file beside it, named
``.NAME.PID.N.tmp`` (the writer's process id, a number), then renamed over
its name (:class:`OutputSet`, :func:`write_file`); the renames of a set are
done with SIGINT and SIGTERM held back, so that Ctrl-C or ``kill`` leaves
either every file of the set or none of it, and the old files in place.
An interrupted command ends with :class:`Interrupted` (exit status 130 for
SIGINT, 143 for SIGTERM), its temporary files removed; a temporary file
left by a process that is gone (``kill -9``, a crash) is removed by the
next run that writes into its directory. Whether the outputs can be
written at all is asked before the work (:func:`unwritable`).
"""

from __future__ import annotations

import itertools
import os
import re
import signal
import stat
import sys
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

# typing only for type checkers: a warm scan never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import IO, Any

#: The exit status of a command interrupted by Ctrl-C (128 + SIGINT), as shells give it.
EXIT_INTERRUPTED = 130
#: The exit status of a command ended by SIGTERM (128 + SIGTERM), as shells give it.
EXIT_TERMINATED = 143


class Interrupted(BaseException):
    """Ctrl-C (SIGINT) or SIGTERM, raised in place of KeyboardInterrupt so that
    click does not turn it into "Aborted!" and exit status 1, and so that a
    SIGTERM unwinds as Ctrl-C does, removing temporary files (see
    :func:`catch_interrupts`)."""

    def __init__(self, signum: int = signal.SIGINT) -> None:
        super().__init__(signum)
        self.signum = int(signum)

    @property
    def status(self) -> int:
        """The exit status: 130 for SIGINT, 143 for SIGTERM (128 + the signal)."""
        return 128 + self.signum

    @property
    def message(self) -> str:
        """What the command says as it ends."""
        return "terminated" if self.signum == signal.SIGTERM else "interrupted"


class WriteError(OSError):
    """A file that cannot be written as asked: the message names it, and
    :attr:`strerror` is the reason alone (as for the OSError behind it)."""

    def __init__(self, message: str, reason: str = "") -> None:
        super().__init__(message)
        self.strerror = reason or message

    def __str__(self) -> str:
        return str(self.args[0])


#: The signal (SIGINT or SIGTERM) that came since :func:`catch_interrupts`, or 0
#: (a list: set by the handler).
_interrupted = [0]


def catch_interrupts() -> None:
    """Make Ctrl-C (SIGINT) and SIGTERM raise :class:`Interrupted` in this
    process (and in the processes it forks).

    Code that is not lensaudit's can lose the exception (lxml's module
    initialisation does, when Ctrl-C comes while it registers its classes
    with :mod:`abc`): the first signal is also remembered, for
    :func:`raise_if_interrupted`. A second one ends the process at once,
    with "lensaudit: interrupted" (or "terminated") and its status, wherever
    it comes (in the handling of the first, say)."""

    def interrupted(signum: int, frame: Any) -> None:
        if _interrupted[0]:
            stop = Interrupted(signum)
            try:
                os.write(2, f"lensaudit: {stop.message}\n".encode())
            except OSError:  # standard error closed: the status says it
                pass
            os._exit(stop.status)
        _interrupted[0] = signum
        raise Interrupted(signum)

    for each in (signal.SIGINT, signal.SIGTERM):
        signal.signal(each, interrupted)


def raise_if_interrupted() -> None:
    """Raise :class:`Interrupted` if Ctrl-C came since :func:`catch_interrupts`
    (its exception lost on the way), before output is written."""
    if _interrupted[0]:
        raise Interrupted(_interrupted[0])


def output_in_input(
    outputs: Iterable[str | os.PathLike[str] | None], inputs: Iterable[str | os.PathLike[str]]
) -> str | None:
    """Why an output would land on an input: an output that is an input, is
    inside an input directory, or is another name of an input file; None if
    none does. ``-`` and None (standard output) are never an input."""
    resolved = [(Path(i), Path(os.path.realpath(i))) for i in inputs]
    for output in outputs:
        if output is None or str(output) == "-":
            continue
        target = Path(os.path.realpath(output))
        for given, real in resolved:
            if target == real or _same_file(target, real):
                same = os.path.abspath(output) == os.path.abspath(given)
                return f"{output} is an input" if same else f"{output} is the input {given}"
            if real.is_dir() and target.is_relative_to(real):
                return f"{output} is inside the input directory {given}"
    return None


def _same_file(first: Path, second: Path) -> bool:
    try:
        return os.path.samefile(first, second)
    except OSError:
        return False


#: Numbers for temporary files, unique in this process.
_NUMBERS = itertools.count()
#: The name of a temporary file of lensaudit's: .NAME.PID.N.tmp
_TEMPORARY = re.compile(r"\..+\.(?P<pid>[0-9]+)\.[0-9]+\.tmp")
#: The directories whose abandoned temporary files this process has removed.
_SWEPT: set[str] = set()


def temporary_beside(path: Path) -> Path:
    """A new name for a temporary file that will become ``path``, beside it:
    ``.NAME.PID.N.tmp``, hidden, with this process's id."""
    return path.with_name(f".{path.name}.{os.getpid()}.{next(_NUMBERS)}.tmp")


def writer_of(name: str) -> int | None:
    """The process id in the name of one of lensaudit's temporary files
    (:func:`temporary_beside`); None for any other name."""
    found = _TEMPORARY.fullmatch(name)
    return int(found["pid"]) if found else None


def running(pid: int) -> bool:
    """Whether the process ``pid`` exists (another user's included): signal 0
    asks without sending anything."""
    if pid == os.getpid() or pid <= 0:  # <= 0 names a group, never asked: kept
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process (PermissionError), or cannot tell: kept
        return True
    return True


def remove_abandoned(directory: str | os.PathLike[str]) -> None:
    """Remove the temporary files of lensaudit (:func:`temporary_beside`'s
    names, no other) in ``directory`` whose process is gone: left by a run
    killed with SIGKILL, or by a crash. Those of a running process, another
    run writing there now, are kept. Each directory once per process."""
    key = os.path.realpath(directory)
    if key in _SWEPT:
        return
    _SWEPT.add(key)
    try:
        entries = list(os.scandir(key))
    except OSError:
        return
    for entry in entries:
        pid = writer_of(entry.name)
        if pid is None or running(pid):
            continue
        try:
            if entry.is_file(follow_symlinks=False):
                os.unlink(entry.path)
        except OSError:
            pass


class OutputSet:
    """Files written together: each to a temporary file beside it
    (:meth:`path`, :meth:`write_bytes`, :meth:`write_text`, :meth:`open`),
    all renamed into place by :meth:`commit`, or all removed by
    :meth:`discard`. As a context manager: committed if the block ends
    normally, discarded if it raises (Ctrl-C included)."""

    def __init__(self) -> None:
        self._staged: list[tuple[str, Path]] = []

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, kind: type | None, *_: object) -> None:
        if kind is None:
            self.commit()
        else:
            self.discard()

    def path(self, path: str | os.PathLike[str]) -> str:
        """A new temporary file that will become ``path``; the caller writes it.
        A symbolic link is followed (its target is written). Where ``path``
        is something other than a regular file (a device such as /dev/null,
        a pipe), it is itself returned, to be written directly."""
        final = Path(os.path.realpath(path))
        try:
            mode = os.stat(final).st_mode
        except OSError:
            mode = None  # not there yet (or unreadable: opening it will say)
        if mode is not None and not stat.S_ISREG(mode):
            return str(final)
        remove_abandoned(final.parent)
        temporary = str(temporary_beside(final))
        # Made and staged together: an interruption after it is made removes it.
        with _signals_held():
            try:
                descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            except OSError as error:
                reason = error.strerror or str(error)
                raise WriteError(f"cannot write {path}: {reason}", reason) from None
            self._staged.append((temporary, final))
        os.close(descriptor)
        if mode is not None:  # a file replaced keeps its permissions
            os.chmod(temporary, stat.S_IMODE(mode))
        return temporary

    def write_bytes(self, path: str | os.PathLike[str], data: bytes) -> None:
        with self.open(path, "wb") as stream:
            stream.write(data)

    def write_text(self, path: str | os.PathLike[str], text: str) -> None:
        with self.open(path) as stream:
            stream.write(text)

    @contextmanager
    def open(self, path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
        """A stream (text, UTF-8; ``mode`` "wb": bytes) whose content will become ``path``."""
        temporary = self.path(path)
        text = {} if "b" in mode else {"encoding": "utf-8", "newline": ""}
        try:
            with open(temporary, mode, **text) as stream:  # type: ignore[call-overload]
                yield stream
        except OSError as error:
            reason = error.strerror or str(error)
            raise WriteError(f"cannot write {path}: {reason}", reason) from None

    def commit(self) -> None:
        """Rename every file into place, SIGINT held back until all are; none
        if Ctrl-C came (see :func:`raise_if_interrupted`)."""
        if _interrupted[0]:
            self.discard()
            raise Interrupted(_interrupted[0])
        with _signals_held():
            done = 0
            try:
                for temporary, final in self._staged:
                    os.replace(temporary, final)
                    done += 1
            except OSError as error:
                self._staged = self._staged[done:]
                self.discard()
                reason = error.strerror or str(error)
                raise WriteError(f"cannot write {final}: {reason}", reason) from None
        self._staged = []

    def discard(self) -> None:
        """Remove every temporary file: nothing of the set is written (a second
        Ctrl-C or SIGTERM waits until they are removed)."""
        with _signals_held():
            for temporary, _ in self._staged:
                try:
                    os.unlink(temporary)
                except OSError:
                    pass
            self._staged = []


def write_file(path: str | os.PathLike[str], data: bytes) -> None:
    """Replace the file ``path`` with ``data``: written to a temporary file
    beside it (:func:`temporary_beside`) and renamed over it, so that a
    reader sees the old content or the new. The temporary file is removed
    whatever ends the writing (an OSError, Ctrl-C, SIGTERM), which is raised
    again as it came. For lensaudit's own files (the cache): no link is
    followed, no abandoned file removed."""
    final = Path(path)
    temporary = temporary_beside(final)
    try:
        with open(temporary, "xb") as stream:
            stream.write(data)
        os.replace(temporary, final)
    except BaseException:
        try:
            os.unlink(temporary)
        except OSError:
            pass
        raise


@contextmanager
def _signals_held() -> Iterator[None]:
    """SIGINT and SIGTERM held back for the block (delivered after it)."""
    held = {signal.SIGINT, signal.SIGTERM}
    if not hasattr(signal, "pthread_sigmask"):  # pragma: no cover - every POSIX Python has it
        yield
        return
    before = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)


def unwritable(path: str | os.PathLike[str], directory: bool = False) -> str | None:
    """Why ``path`` cannot be written, as one line naming it; None if it can.

    A file is written into its directory, which must be there (``-`` is
    standard output; a device or a pipe is written as it is); with
    ``directory``, ``path`` is a directory that files are written into,
    made with its parents where it is not there. Asked before any work, of
    the kernel: a temporary file is made and removed in the directory that
    would receive the files (or the nearest one there, for a directory to be
    made), so that a read-only file system, access control lists and root
    without the capability to override permissions answer as they will.
    """
    if str(path) == "-":
        return None
    try:
        real = Path(os.path.realpath(path))
    except (OSError, ValueError) as error:
        return f"cannot write {path}: {getattr(error, 'strerror', None) or error}"
    if directory:
        if os.path.lexists(real) and not os.path.isdir(real):
            return f"cannot write into {path}: not a directory"
        receiving = real
        while not os.path.lexists(receiving) and receiving != receiving.parent:
            receiving = receiving.parent  # the directories from here down are made
    else:
        if os.path.isdir(real):
            return f"cannot write {path}: it is a directory"
        if os.path.lexists(real) and not os.path.isfile(real):
            return None  # a device or a pipe: written as it is, not replaced
        receiving = real.parent
        if not os.path.lexists(receiving):
            return f"cannot write {path}: no directory {receiving}"
    if not os.path.isdir(receiving):
        return f"cannot write {path}: {receiving} is not a directory"
    problem = _cannot_make_files_in(receiving)
    return f"cannot write {path}: {problem}" if problem else None


def _cannot_make_files_in(directory: Path) -> str | None:
    """Why no file can be made in ``directory``; None if one can (one is made
    and removed, with the signals held so that none is left)."""
    temporary = temporary_beside(directory / "lensaudit")
    try:
        with _signals_held():
            os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
            os.unlink(temporary)
    except OSError as error:
        return error.strerror or str(error)
    return None


@contextmanager
def output_stream(path: str | os.PathLike[str] | None) -> Iterator[IO[str]]:
    """Standard output, or a text stream whose content becomes ``path`` once the
    block ends normally (nothing is written if it raises)."""
    raise_if_interrupted()
    if path is None or str(path) == "-":
        yield sys.stdout
        return
    with OutputSet() as outputs, outputs.open(path) as stream:
        yield stream


def replace_files(contents: list[tuple[str | os.PathLike[str], bytes]]) -> None:
    """Give files new contents, all or none: each file keeps its mode, and its
    owner and group where this user may set them; a symbolic link is
    followed (its target gets the content, the link stays). Raises
    :class:`WriteError`, before anything is written, for a file this user
    may not write or one with other hard links (which would stop sharing
    its content)."""
    staged = []
    for name, data in contents:
        target = Path(os.path.realpath(name))
        status = _writable(name, target)
        staged.append((target, status, data))
    with OutputSet() as outputs:
        for target, status, data in staged:
            temporary = outputs.path(target)
            try:
                with open(temporary, "wb") as stream:
                    stream.write(data)
                    stream.flush()
                    os.fsync(stream.fileno())
                _keep_ownership(temporary, status)
            except OSError as error:
                reason = error.strerror or str(error)
                raise WriteError(
                    f"cannot write {target}: {reason}; nothing written", reason
                ) from None


def check_replaceable(names: Iterable[str | os.PathLike[str]]) -> None:
    """Raise :class:`WriteError` for the first of ``names`` that
    :func:`replace_files` would refuse (one this user may not write, that
    is not a regular file, or has other hard links), before any work."""
    for name in names:
        _writable(name, Path(os.path.realpath(name)))


def _writable(name: str | os.PathLike[str], target: Path) -> os.stat_result:
    """The status of a file to be replaced; WriteError if it may not be."""
    problem = ""
    try:
        status = os.stat(target)
        if stat.S_ISREG(status.st_mode):
            # Opened for writing (not truncated): the kernel's own answer, for
            # root without the capability to override permissions too.
            os.close(os.open(target, os.O_WRONLY | os.O_NONBLOCK))
            # Its new content is written beside it, and renamed over it.
            reason = _cannot_make_files_in(target.parent)
            if reason:
                problem = f"{reason} (in its directory {target.parent})"
        else:
            problem = "not a regular file"
    except OSError as error:
        problem = error.strerror or str(error)
    if problem:
        raise WriteError(f"cannot write {name}: {problem}; nothing written", problem)
    if status.st_nlink > 1:
        raise WriteError(
            f"{name} has {status.st_nlink} hard links, which replacing it would separate; "
            "nothing written (patch a copy, or remove the other links first)"
        )
    return status


def _keep_ownership(path: str, status: os.stat_result) -> None:
    """Give ``path`` the mode of ``status``, and its owner and group where allowed."""
    os.chmod(path, stat.S_IMODE(status.st_mode))
    current = os.stat(path)
    if (current.st_uid, current.st_gid) == (status.st_uid, status.st_gid):
        return
    for owner, group in ((status.st_uid, status.st_gid), (-1, status.st_gid)):
        try:
            os.chown(path, owner, group)
            break
        except OSError:
            continue
    # chown may clear set-user-ID and set-group-ID bits: set the mode again.
    os.chmod(path, stat.S_IMODE(status.st_mode))
