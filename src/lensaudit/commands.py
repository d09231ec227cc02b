"""What lensaudit's commands share without click: the plain scan, output, errors.

``lensaudit scan`` is the command run most, often on a cold start, where
importing click and building its commands is a fifth of the work: :func:`scan_arguments`
reads a plain scan's command line and :func:`scan` runs it, for the
console command (:mod:`lensaudit.console`) and for the click command alike.
"""

from __future__ import annotations

import errno
import gc
import io
import os
import sys
from collections import namedtuple
from collections.abc import Iterator
from contextlib import contextmanager
from importlib import import_module
from pathlib import Path

from . import writing
from .formats import printable, writer
from .pipeline import run as audit
from .read import Cache, read
from .read.paths import display_path, resolve
from .read.records import LoadError

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any, NoReturn, TextIO

#: Exit status for bad usage or input that could not be read at all.
EXIT_INPUT_ERROR = 2
#: The output formats of the commands that write every entry (scan, fix).
FORMAT_NAMES = ("table", "csv", "json")
#: What ``scan --kind`` audits.
KIND_NAMES = ("distortion", "vignetting", "tca")

#: The options of ``lensaudit scan``: name -> the field of :class:`ScanArguments` it sets.
SCAN_OPTIONS: dict[str, str] = {
    "-f": "output_format",
    "--format": "output_format",
    "-k": "kind",
    "--kind": "kind",
    "-o": "output",
    "--output": "output",
    "--cache": "cache",
    "--no-cache": "cache",
    "--cache-dir": "cache_dir",
}
#: Of those, the flags (the others take a value).
SCAN_FLAGS = ("--cache", "--no-cache")


class ScanArguments(
    namedtuple(
        "ScanArguments",
        ("paths", "output_format", "kind", "output", "cache", "cache_dir"),
        defaults=((), "table", "distortion", None, True, None),
    )
):
    """A scan's command line: database ``paths`` as given (a tuple; none: the
    default database), ``output_format``, ``kind``, ``output`` file (None:
    standard output), ``cache`` (a bool), ``cache_dir`` (None: the default)."""

    __slots__ = ()


def scan_arguments(words: list[str]) -> ScanArguments | None:
    """What ``lensaudit scan WORDS...`` asks for, or None unless that is plain:
    help asked for, an option or value that click would refuse, an output
    that is a directory."""
    paths: list[str] = []
    settings: dict[str, object] = {}
    rest = iter(words)
    for word in rest:
        if word == "--":
            paths += rest
            break
        if not word.startswith("-") or word == "-":
            paths.append(word)
            continue
        if word.startswith("--"):
            name, equals, value = word.partition("=")
        else:  # a short option's value follows it at once, "=" included: -fcsv, -o=x
            name, equals, value = word[:2], word[2:3], word[2:]
        setting = SCAN_OPTIONS.get(name)
        if setting is None:
            return None
        if name in SCAN_FLAGS:
            if equals:
                return None
            settings["cache"] = name == "--cache"
            continue
        if not equals:
            value = next(rest, None)
            if value is None:
                return None
        settings[setting] = value
    found = ScanArguments(tuple(paths), **settings)  # type: ignore[arg-type]
    if found.output_format not in FORMAT_NAMES or found.kind not in KIND_NAMES:
        return None
    if any(
        not path.strip()
        for path in (*found.paths, found.output, found.cache_dir)
        if path is not None
    ):
        return None  # click's own message: an empty path is no working directory
    if found.output is not None and os.path.isdir(found.output):
        return None  # click's own message says what is wrong with it
    if found.cache_dir is not None and os.path.isfile(found.cache_dir):
        return None
    return found


class _WholeWriter(io.BufferedWriter):
    """A buffered writer that writes all it is given, or raises.

    Python's own returns a short count, without an error, when the reader of
    a pipe goes away during a write larger than its buffer; the text stream
    over it ignores the count, and the rest of the output would be dropped
    silently (exit status 0, as if all had been read).
    """

    def write(self, data: bytes) -> int:  # type: ignore[override]
        view = memoryview(data).cast("B")
        done = super().write(view)
        while done < len(view):
            more = super().write(view[done:])
            if not more:
                raise BrokenPipeError(errno.EPIPE, os.strerror(errno.EPIPE))
            done += more
        return done


class _Closed(io.RawIOBase):
    """Where a standard stream that was closed when lensaudit started is
    written: writing to it is an error (``strerror``: "NAME is closed")."""

    def __init__(self, name: str) -> None:
        super().__init__()
        self._name = name

    def writable(self) -> bool:
        return True

    def write(self, data: object) -> int:
        raise OSError(errno.EBADF, f"{self._name} is closed")


class _Discarded(io.RawIOBase):
    """Standard error closed: messages go nowhere (the exit status says it)."""

    def writable(self) -> bool:
        return True

    def write(self, data: bytes) -> int:  # type: ignore[override]
        return len(memoryview(data))


def standard_streams() -> None:
    """Set up standard output and error for a command.

    Text a terminal's encoding cannot show is written as Python escapes
    (``\\u0417``: "backslashreplace"), never an error; files written with
    ``--output`` are UTF-8 whatever the terminal. A write is whole or an
    error (see :class:`_WholeWriter`). Standard output closed (``>&-``) is an
    error at the first write ("standard output is closed", exit status 2);
    standard error closed, messages are dropped. A closed descriptor 0, 1 or
    2 is opened on the null device, so that no file this process opens takes
    its number (and a child process's standard stream with it).
    """
    closed = {name: getattr(sys, name) is None for name in ("stdin", "stdout", "stderr")}
    for descriptor in range(3):
        try:
            os.fstat(descriptor)
        except OSError:  # the lowest number free, the lower ones being open: this one
            os.open(os.devnull, os.O_RDWR)
    if closed["stdout"]:
        writer: Any = _Closed("standard output")
        sys.stdout = io.TextIOWrapper(writer, encoding="utf-8", write_through=True)
    else:
        sys.stdout = _escaping(sys.stdout)
    if closed["stderr"]:
        discarded: Any = _Discarded()
        sys.stderr = io.TextIOWrapper(discarded, encoding="utf-8")
    else:
        sys.stderr = _escaping(sys.stderr)


def _escaping(stream: TextIO) -> TextIO:
    """``stream`` writing what its encoding cannot show as escapes, whole writes only."""
    stream.flush()
    try:
        descriptor = stream.fileno()
    except (AttributeError, OSError, ValueError):
        descriptor = -1
    if os.name != "posix" or descriptor < 0:  # a console of its own, or no descriptor
        if hasattr(stream, "reconfigure"):
            stream.reconfigure(errors="backslashreplace")
        return stream
    raw = io.FileIO(descriptor, "w", closefd=False)
    return io.TextIOWrapper(  # type: ignore[return-value]
        _WholeWriter(raw),
        encoding=stream.encoding,
        errors="backslashreplace",
        newline="\n",
        line_buffering=stream.line_buffering,
    )


def use_cache_dir(directory: str | os.PathLike[str]) -> None:
    """Make ``directory`` the cache's directory for this run (and the processes
    it starts): what ``--cache-dir`` does, the same as $LENSAUDIT_CACHE_DIR."""
    os.environ["LENSAUDIT_CACHE_DIR"] = os.fspath(directory)


def fail(message: str) -> NoReturn:
    """Print a one-line error and exit with status 2 (no traceback); what it
    quotes (names from a database, paths) cannot move the terminal's cursor."""
    try:
        sys.stderr.write(f"lensaudit: error: {printable(message)}\n")
        sys.stderr.flush()
    except (AttributeError, OSError, ValueError):  # standard error closed: the status says it
        pass
    sys.exit(EXIT_INPUT_ERROR)


def os_error_message(error: OSError) -> str:
    """The one line an error of the file system is reported with."""
    where = f"{display_path(error.filename)}: " if error.filename is not None else ""
    return f"lensaudit: error: {printable(where + str(error.strerror or error))}"


@contextmanager
def output_stream(path: Path | str | None) -> Iterator[TextIO]:
    """Standard output, or a stream (UTF-8) whose content becomes ``path`` when
    the block ends normally: an interrupted or failed command leaves the
    file as it was (see :mod:`lensaudit.writing`)."""
    try:
        with writing.output_stream(path) as stream:
            yield stream  # type: ignore[misc]
    except writing.WriteError as error:
        fail(str(error))


def refuse_writing_inputs(
    outputs: list[Path | str | None],
    paths: tuple | list | None,
    *others: Path | str,
) -> None:
    """Exit with status 2, before anything is read or written, when an output
    would land on an input: the database at ``paths`` (the default database
    without), or one of ``others``."""
    if all(output is None or str(output) == "-" for output in outputs):
        return
    try:
        database = resolve(list(paths or ()) or None).paths
    except LoadError:
        database = tuple(Path(p) for p in paths or ())
    problem = writing.output_in_input(outputs, [*database, *others])
    if problem is not None:
        fail(f"{problem}: nothing read or written (an output never replaces an input)")


def refuse_unwritable(files: list[Path | str | None], directory: Path | str | None = None) -> None:
    """Exit with status 2, before any work, naming the first output that cannot
    be written: of ``files`` (None and ``-``, standard output, always can;
    see :func:`lensaudit.writing.unwritable`), or, given ``directory`` (made
    where it is not there), of the directory and the ``files`` in it."""
    if directory is not None:
        problems = [writing.unwritable(directory, directory=True)]
        problems += [f"cannot write {f}: it is a directory" for f in files if os.path.isdir(f)]
    else:
        problems = [writing.unwritable(f) for f in files if f is not None]
    problem = next(filter(None, problems), None)
    if problem is not None:
        fail(problem)


def single_blas_thread() -> None:
    """Ask numpy's BLAS, if this process is the one to load it, for one thread.

    The audits do no linear algebra, and starting a BLAS thread pool makes
    importing numpy slower (much slower on a busy machine). Only this
    process is affected, and only when the user has not chosen.
    """
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def scan(arguments: ScanArguments) -> None:
    """Run ``lensaudit scan`` (see ``lensaudit scan --help``)."""
    paths = [Path(path) for path in arguments.paths]
    output = None if arguments.output is None else Path(arguments.output)
    refuse_writing_inputs([output], paths)
    refuse_unwritable([output])
    if arguments.cache_dir is not None:
        use_cache_dir(arguments.cache_dir)
    single_blas_thread()
    with cycle_collector_off():
        if arguments.kind != "distortion":
            _scan_calibrations(paths, arguments, output)
            return
        try:
            result = audit(paths or None, cache=arguments.cache)
        except LoadError as error:
            fail(str(error))
        _fail_if_none_read(result.files)
        with output_stream(output) as stream:
            writer(arguments.output_format)(result, stream)


@contextmanager
def cycle_collector_off() -> Iterator[None]:
    """The block runs without Python's cycle collector (as it was after it).

    What a command allocates lives until it ends: the collector would only
    walk it over and over (a tenth of importing numpy, for one). What the
    block allocated is handed to the oldest generation unwalked, where a
    full collection finds it: re-enabled as it is, the collector would walk
    all of it at the next allocation (a tenth of a cold report).
    """
    collecting = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if collecting:
            if not gc.get_freeze_count():  # nobody else's frozen objects to thaw
                gc.freeze()
                gc.unfreeze()
            gc.enable()


def _fail_if_none_read(files: list) -> None:
    """Exit with status 2 when not one of the files (each with a ``name`` and an
    ``error``) could be read."""
    if files and all(f.error for f in files):
        fail("no file could be read: " + "; ".join(f"{f.name}: {f.error}" for f in files))


def _scan_calibrations(paths: list[Path], arguments: ScanArguments, output: Path | None) -> None:
    """``scan --kind vignetting|tca``: read the elements of that kind and audit them."""
    try:
        cache = Cache() if arguments.cache else None
        database = read(paths or None, cache=cache, calibrations=True)
    except LoadError as error:
        fail(str(error))
    _fail_if_none_read(database.files)
    audit = import_module(f"lensaudit.{arguments.kind}").of_database(database)
    with output_stream(output) as stream:
        audit.write(arguments.output_format, stream)
