"""Options and helpers shared by the subcommands."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

# Shared with the click-free scan of the console command.
from ..commands import EXIT_INPUT_ERROR, FORMAT_NAMES, fail, output_stream, refuse_writing_inputs

__all__ = [
    "EXIT_INPUT_ERROR",
    "FORMAT_NAMES",
    "cache_option",
    "database_paths",
    "fail",
    "format_option",
    "output_file",
    "output_stream",
    "refuse_writing_inputs",
]


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
