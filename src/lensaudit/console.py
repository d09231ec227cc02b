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

import os
import sys

from .commands import (
    EXIT_INPUT_ERROR,
    ScanArguments,
    os_error_message,
    scan,
    scan_arguments,
)
from .writing import EXIT_INTERRUPTED, Interrupted, WriteError, catch_interrupts

# typing only for type checkers
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import NoReturn

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
        sys.stderr.write(os_error_message(error) + "\n")
        return EXIT_INPUT_ERROR
    return 0


def _status(code: object) -> int:
    """The exit status of a ``SystemExit`` code, as Python gives it."""
    if code is None:
        return 0
    if isinstance(code, int):
        return code
    print(code, file=sys.stderr)
    return 1


def dispatch(words: list[str]) -> int:
    """Run ``lensaudit WORDS...``, to its exit status: a plain scan here, the
    rest through the click group. Ctrl-C ends it with status 130 and
    "interrupted", SIGTERM with status 143 and "terminated" (nothing
    half-written is left: see :mod:`lensaudit.writing`)."""
    try:
        return _dispatch(words)
    except Interrupted as stop:
        sys.stderr.write(f"lensaudit: {stop.message}\n")
        return stop.status
    except KeyboardInterrupt:
        sys.stderr.write("lensaudit: interrupted\n")
        return EXIT_INTERRUPTED
    except WriteError as error:
        sys.stderr.write(f"lensaudit: error: {error}\n")
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
    return 0


def run() -> NoReturn:
    """The ``lensaudit`` console command; ends without the interpreter's teardown.

    Once the command is done and its output flushed, tearing the interpreter
    down (freeing every object, finalising numpy and lxml) is work nobody
    sees: a fifth of a cold scan. The process ends without it, with the
    command's exit status. Anything but an exit (a crash) takes Python's
    usual way out.
    """
    catch_interrupts()
    code = dispatch(sys.argv[1:])
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe, a closed stream: nothing to keep
            code = code or 1
    os._exit(code)
