"""Options and helpers shared by the subcommands."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

# Shared with the click-free scan of the console command.
from ..commands import (
    EXIT_INPUT_ERROR,
    FORMAT_NAMES,
    fail,
    output_stream,
    refuse_unwritable,
    refuse_writing_inputs,
    use_cache_dir,
)

__all__ = [
    "EXIT_INPUT_ERROR",
    "GivenPath",
    "ProgressBar",
    "FORMAT_NAMES",
    "cache_option",
    "database_paths",
    "fail",
    "format_option",
    "output_file",
    "output_stream",
    "not_blank",
    "refuse_unwritable",
    "refuse_writing_inputs",
]


def blank(value: object) -> bool:
    """Whether a value given for a path is empty or only white space: what
    ``"$VAR"`` gives when VAR is unset, which a path would read as the working
    directory."""
    return isinstance(value, (str, bytes)) and not os.fsdecode(value).strip()


class GivenPath(click.Path):
    """``click.Path`` that refuses an empty or blank value in one line, rather
    than reading it as the working directory."""

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if blank(value):
            self.fail(
                f"{value!r} is blank (an unset variable?): give a path, . for here", param, ctx
            )
        return super().convert(value, param, ctx)


def not_blank(context: click.Context, parameter: click.Parameter, value: Any) -> Any:
    """A click callback refusing an empty or blank value of an option that
    names something to read."""
    if blank(value):
        raise click.BadParameter(f"{value!r} is blank (an unset variable?): give a value")
    return value


def database_paths(function: Callable[..., Any]) -> Callable[..., Any]:
    """``[PATH ...]``: Lensfun database directories or XML files."""
    return click.argument(
        "paths",
        nargs=-1,
        metavar="[PATH ...]",
        type=GivenPath(path_type=Path, exists=False),
    )(function)


def output_file(function: Callable[..., Any]) -> Callable[..., Any]:
    """``-o FILE``: where to write instead of standard output."""
    return click.option(
        "-o",
        "--output",
        type=GivenPath(path_type=Path, dir_okay=False, allow_dash=True),
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
    """``--cache/--no-cache`` (given as ``cache``: on by default) and
    ``--cache-dir DIR``: lensaudit's one cache, with the same meaning in
    every command."""
    function = click.option(
        "--cache-dir",
        metavar="DIR",
        type=GivenPath(path_type=Path, file_okay=False),
        default=None,
        expose_value=False,
        callback=_use_cache_dir,
        help="The cache's directory [default: $LENSAUDIT_CACHE_DIR, else "
        "$XDG_CACHE_HOME/lensaudit, else ~/.cache/lensaudit].",
    )(function)
    return click.option(
        "--cache/--no-cache",
        default=True,
        show_default=True,
        help="Reuse what an earlier run made of files whose content is unchanged (the "
        "cache is keyed on a hash of each file's bytes).",
    )(function)


def _use_cache_dir(context: click.Context, parameter: click.Parameter, value: Path | None) -> None:
    """--cache-dir DIR: the cache's directory for this run, as $LENSAUDIT_CACHE_DIR names it."""
    if value is not None:
        use_cache_dir(value)


class ProgressBar:
    """click's progress bar on standard error (when ``enabled``), made once the
    total is known: :meth:`update` with (done, total), then :meth:`close`."""

    def __init__(self, label: str, enabled: bool) -> None:
        self.label = label
        self.enabled = enabled
        self.bar: Any = None

    def update(self, done: int, total: int) -> None:
        if not self.enabled:
            return
        if self.bar is None:
            self.bar = click.progressbar(
                length=total, label=self.label, file=sys.stderr, show_pos=True
            )
            self.bar.__enter__()
        self.bar.update(done - self.bar.pos)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.__exit__(None, None, None)
            self.bar = None
