"""Options and helpers shared by the subcommands."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TextIO

import click

#: Exit status for bad usage or input that could not be read at all.
EXIT_INPUT_ERROR = 2
#: The output formats of the commands that write every entry (scan, fix).
FORMAT_NAMES = ("table", "csv", "json")


def database_paths(function: Callable[..., Any]) -> Callable[..., Any]:
    """``[PATH ...]``: Lensfun database directories or XML files."""
    return click.argument(
        "paths",
        nargs=-1,
        metavar="[PATH ...]",
        type=click.Path(path_type=Path, exists=False),
    )(function)


def output_file(function: Callable[..., Any]) -> Callable[..., Any]:
    """``-o FILE``: where to write instead of standard output."""
    return click.option(
        "-o",
        "--output",
        type=click.Path(path_type=Path, dir_okay=False, allow_dash=True),
        default=None,
        help="Write to FILE instead of standard output.",
    )(function)


def format_option(help: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """``-f/--format table|csv|json`` (default table, given as ``output_format``),
    with ``help`` saying what each format holds for the command."""
    return click.option(
        "-f",
        "--format",
        "output_format",
        type=click.Choice(FORMAT_NAMES),
        default="table",
        show_default=True,
        help=help,
    )


def cache_option(function: Callable[..., Any]) -> Callable[..., Any]:
    """``--cache/--no-cache``: the parse cache, on by default (scan, fix, report, plot)."""
    return click.option(
        "--cache/--no-cache",
        default=True,
        show_default=True,
        help="Reuse what an earlier run made of files whose content is unchanged (the "
        "cache is keyed on a hash of each file's bytes); it is in $LENSAUDIT_CACHE_DIR "
        "or ~/.cache/lensaudit.",
    )(function)


def fail(message: str) -> None:
    """Print a one-line error and exit with status 2 (no traceback)."""
    click.echo(f"lensaudit: error: {message}", err=True)
    sys.exit(EXIT_INPUT_ERROR)


@contextmanager
def output_stream(path: Path | None) -> Iterator[TextIO]:
    """Standard output, or ``path`` opened for writing (UTF-8)."""
    if path is None or str(path) == "-":
        yield sys.stdout
        return
    try:
        stream = open(path, "w", encoding="utf-8", newline="")  # noqa: SIM115
    except OSError as error:
        fail(f"cannot write {path}: {error.strerror or error}")
    with stream:
        yield stream
