"""The ``lensaudit`` console command.

A plain scan (see :func:`lensaudit.commands.scan_arguments`: paths,
``--format``, ``--kind``, ``--output``, ``--cache/--no-cache``) runs
without click; any other command line, and any that asks for help or that
click would refuse, goes to the click group :func:`lensaudit.cli.main`,
whose ``scan`` command runs the same :func:`lensaudit.commands.scan`. A test
holds :func:`~lensaudit.commands.scan_arguments` to click's reading of the
same words. Every command ends without the interpreter's teardown once its
output is flushed.
"""

from __future__ import annotations

import errno
import os
import sys

from .commands import (
    EXIT_INPUT_ERROR,
    ScanArguments,
    os_error_message,
    scan,
    scan_arguments,
    standard_streams,
)
from .formats import printable
from .writing import (
    EXIT_INTERRUPTED,
    EXIT_TERMINATED,
    Interrupted,
    WriteError,
    catch_interrupts,
    raise_if_interrupted,
)

# typing only for type checkers
TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Callable
    from typing import Any, NoReturn

__all__ = ["ScanArguments", "dispatch", "run", "scan_arguments"]


def _scan_directly(arguments: ScanArguments) -> int:
    """Run a scan as the click command would, to its exit status."""
    try:
        scan(arguments)
    except SystemExit as end:
        return _status(end.code)
    except BrokenPipeError:  # the reader went away: nothing more to say
        return 1
    except OSError as error:
        _say(os_error_message(error))
        return EXIT_INPUT_ERROR
    return 0


def _say(line: str) -> None:
    """Write a line to standard error, if it can still be written."""
    try:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()
    except (AttributeError, OSError, ValueError):  # closed, or its reader gone
        pass


def _status(code: object) -> int:
    """The exit status of a ``SystemExit`` code, as Python gives it."""
    if code is None:
        return 0
    if isinstance(code, int):
        return code
    _say(printable(str(code)))
    return 1


def dispatch(words: list[str]) -> int:
    """Run ``lensaudit WORDS...``, to its exit status: a plain scan here, the
    rest through the click group. Ctrl-C ends it with status 130 and
    "interrupted", SIGTERM with status 143 and "terminated" (nothing
    half-written is left: see :mod:`lensaudit.writing`)."""
    try:
        return _dispatch(words)
    except Interrupted as stop:
        _say(f"lensaudit: {stop.message}")
        return stop.status
    except KeyboardInterrupt:
        _say("lensaudit: interrupted")
        return EXIT_INTERRUPTED
    except WriteError as error:
        _say(f"lensaudit: error: {printable(str(error))}")
        return EXIT_INPUT_ERROR


def _dispatch(words: list[str]) -> int:
    arguments = scan_arguments(words[1:]) if words[:1] == ["scan"] else None
    if arguments is not None:
        return _scan_directly(arguments)
    from .cli import main  # click: a plain scan runs without it

    try:
        main(words)  # click's standalone mode: always ends in SystemExit
    except SystemExit as end:
        return _status(end.code)
    except OSError as error:
        # Standard output closed, written to before any command runs
        # (--help, --version): the commands say so themselves.
        if error.errno != errno.EBADF:
            raise
        _say(f"lensaudit: error: {error.strerror}")
        return EXIT_INPUT_ERROR
    return 0


def _interrupts_kept(hook: Callable[[Any], object]) -> Callable[[Any], object]:
    """``sys.unraisablehook`` that is silent about Ctrl-C: where Python cannot
    raise it (a finaliser, a callback), it is kept for the end of the
    command (:func:`lensaudit.writing.raise_if_interrupted`), not printed
    as "Exception ignored" with a traceback."""

    def unraisable(info: Any) -> None:
        if not isinstance(info.exc_value, (Interrupted, KeyboardInterrupt)):
            hook(info)

    return unraisable


def run() -> NoReturn:
    """The ``lensaudit`` console command; ends without the interpreter's teardown.

    Once the command is done and its output flushed, tearing the interpreter
    down (freeing every object, finalising numpy and lxml) is work nobody
    sees: a fifth of a cold scan. The process ends without it, with the
    command's exit status. Anything but an exit (a crash) takes Python's
    usual way out.

    Ctrl-C at any moment ends it with "lensaudit: interrupted" and status 130
    (SIGTERM: "terminated", 143):
    while it starts (see :mod:`lensaudit`), while it runs, after its output
    (not yet flushed), and where code not lensaudit's lost the exception (see
    :func:`lensaudit.writing.catch_interrupts`).
    """
    try:
        catch_interrupts()
        sys.unraisablehook = _interrupts_kept(sys.unraisablehook)
        standard_streams()
        code = dispatch(sys.argv[1:])
        if code not in (EXIT_INTERRUPTED, EXIT_TERMINATED):
            raise_if_interrupted()
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # a closed pipe, a closed stream: nothing to keep
                code = code or 1
    except Interrupted as stop:
        _say(f"lensaudit: {stop.message}")
        code = stop.status
    except KeyboardInterrupt:
        _say("lensaudit: interrupted")
        code = EXIT_INTERRUPTED
    os._exit(code)
