"""Writing without losing anything: an output never lands on an input, a
command's files appear all together or not at all, and a file patched in
place keeps its mode, owner and group.

Every file is first written to a temporary file beside it, then renamed
over its name (:class:`OutputSet`); the renames of a set are done with
SIGINT held back, so that Ctrl-C leaves either every file of the set or
none of it, and the old files in place. An interrupted command ends with
:class:`Interrupted` (exit status 130).
"""

from __future__ import annotations

import itertools
import os
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


class Interrupted(BaseException):
    """Ctrl-C, raised in place of KeyboardInterrupt so that click does not turn
    it into "Aborted!" and exit status 1 (see :func:`catch_interrupts`)."""


class WriteError(OSError):
    """A file that cannot be written as asked: the message names it, and
    :attr:`strerror` is the reason alone (as for the OSError behind it)."""

    def __init__(self, message: str, reason: str = "") -> None:
        super().__init__(message)
        self.strerror = reason or message

    def __str__(self) -> str:
        return str(self.args[0])


#: Whether Ctrl-C has come since :func:`catch_interrupts` (a list: set by the handler).
_interrupted = [False]


def catch_interrupts() -> None:
    """Make Ctrl-C raise :class:`Interrupted` in this process (and in the
    processes it forks).

    Code that is not lensaudit's can lose the exception (lxml's module
    initialisation does, when Ctrl-C comes while it registers its classes
    with :mod:`abc`): the first Ctrl-C is also remembered, for
    :func:`raise_if_interrupted`. A second one ends the process at once,
    with "lensaudit: interrupted" and status 130, wherever it comes (in the
    handling of the first, say)."""

    def interrupted(signum: int, frame: Any) -> None:
        if _interrupted[0]:
            try:
                os.write(2, b"lensaudit: interrupted\n")
            except OSError:  # standard error closed: the status says it
                pass
            os._exit(EXIT_INTERRUPTED)
        _interrupted[0] = True
        raise Interrupted

    signal.signal(signal.SIGINT, interrupted)


def raise_if_interrupted() -> None:
    """Raise :class:`Interrupted` if Ctrl-C came since :func:`catch_interrupts`
    (its exception lost on the way), before output is written."""
    if _interrupted[0]:
        raise Interrupted


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
        temporary = str(final.with_name(f".{final.name}.{os.getpid()}.{next(_NUMBERS)}.tmp"))
        try:
            descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except OSError as error:
            reason = error.strerror or str(error)
            raise WriteError(f"cannot write {path}: {reason}", reason) from None
        os.close(descriptor)
        self._staged.append((temporary, final))
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
            raise Interrupted
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
        """Remove every temporary file: nothing of the set is written."""
        for temporary, _ in self._staged:
            try:
                os.unlink(temporary)
            except OSError:
                pass
        self._staged = []


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


def _writable(name: str | os.PathLike[str], target: Path) -> os.stat_result:
    """The status of a file to be replaced; WriteError if it may not be."""
    problem = ""
    try:
        status = os.stat(target)
        if stat.S_ISREG(status.st_mode):
            # Opened for writing (not truncated): the kernel's own answer, for
            # root without the capability to override permissions too.
            os.close(os.open(target, os.O_WRONLY | os.O_NONBLOCK))
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
