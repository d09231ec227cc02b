"""``lensaudit check``: the CI gate for a Lensfun database and changes to it."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import TYPE_CHECKING

import click

from ..check_formats import writer
from ..columns import FOLD_MARGIN
from ..commands import cycle_collector_off
from ..formats import printable
from ..git import GitError, GitUnavailable, top_level
from ..read import LoadError
from .options import (
    cache_option,
    database_paths,
    fail,
    output_file,
    output_stream,
    refuse_unwritable,
    refuse_writing_inputs,
)

if TYPE_CHECKING:
    from ..check import CheckResult

FORMAT_NAMES = ("text", "json", "github", "junit")

#: Exit status when a finding fails the check.
EXIT_FINDINGS = 1


#: The help of `lensaudit check`: what it reports and its exit status.
CHECK_HELP = """Fail when a Lensfun database, or a change to it, has models that fold.

PATH is a database directory (the files liblensfun reads there: every
*.xml, also in subdirectories named *.xml), a Lensfun checkout
(its data/db) or XML files. Without PATH: the database of the Lensfun
checkout around the working directory, else the one bundled with
lensfunpy.

{codes}
With --baseline, findings the baseline already has are reported as known
and do not fail, so only new or changed entries fail the check. Entries
are matched by content (lens name ignoring case and white space, and the
entry's own values), never by line. A git revision is read with git
ls-tree and git cat-file; the work tree is not touched. A baseline file
that cannot be parsed is replaced by its last version in git that can.
An empty or blank --baseline (an unset variable) is bad usage, and so is
a directory or file that holds the files checked, by any name: every
finding would be known. HEAD is the baseline of uncommitted work.

With --cache (the default), a file whose bytes an earlier check, report
or `scan --kind` read whole (the baseline's files too) is not parsed
again; the output is the same.

\b
Exit status:
  0  no finding fails the check (warnings and known findings do not)
  1  at least one new error
  2  bad usage, or input or baseline that could not be read at all
"""


class _CheckCommand(click.Command):
    """``check``, whose help lists the codes of the rule registry, read when
    the help is shown (the rules import numpy, which a check needs only later)."""

    def format_help_text(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        from ..check.rules import codes_help

        self.help = CHECK_HELP.replace("{codes}", codes_help())
        super().format_help_text(ctx, formatter)


@click.command(cls=_CheckCommand, help=CHECK_HELP)
@database_paths
@click.option(
    "--baseline",
    metavar="DIR_OR_REV",
    default=None,
    help="Only fail on entries that are new or changed since this database: "
    "an existing directory (a Lensfun checkout meaning its data/db) or file, "
    "else a git revision of the repository holding PATH, e.g. origin/master or HEAD. "
    "Refused when empty or blank, and when on disk it holds the files checked.",
)
@click.option(
    "--margin",
    type=float,
    default=FOLD_MARGIN,
    show_default=True,
    help="Warn about a fold outside the image when D(r_max) is less than "
    "MARGIN times the image corner.",
)
@click.option(
    "-f",
    "--format",
    "output_format",
    type=click.Choice(FORMAT_NAMES),
    default="text",
    show_default=True,
    help="text: one line per finding; json: everything as data; github: "
    "workflow annotations on the pull request's lines; junit: JUnit XML.",
)
@output_file
@click.option(
    "-v",
    "--verbose",
    is_flag=True,
    help="Also report, as notices, every fold outside the image and every "
    "vignetting model that is not monotone inside it.",
)
@cache_option
@click.option(
    "--explain",
    metavar="CODE",
    default=None,
    help="Say what a finding code means, why, and a real example that gets it "
    "and one that does not; check nothing.",
)
def check(
    paths: tuple[Path, ...],
    baseline: str | None,
    margin: float,
    output_format: str,
    output: Path | None,
    verbose: bool,
    cache: bool,
    explain: str | None,
) -> None:
    """`lensaudit check`: see :data:`CHECK_HELP`."""
    if explain is not None:
        _explain(explain)
        return
    if not margin >= 1 or math.isinf(margin):
        raise click.BadParameter(f"{margin} is not a finite number >= 1", param_hint="--margin")
    baselines = [baseline] if baseline is not None and os.path.exists(baseline) else []
    refuse_writing_inputs([output], paths, *baselines)
    refuse_unwritable([output])
    with cycle_collector_off():
        result = _run(paths, baseline, margin, verbose, output_format, cache)
        with output_stream(output) as stream:
            writer(output_format)(result, stream)
    if result.failed:
        raise SystemExit(EXIT_FINDINGS)


def _explain(code: str) -> None:
    """Print what the finding ``code`` means, or fail as bad usage naming the codes."""
    from ..check import rules  # the rules import numpy: only when asked

    try:
        text = rules.explain(code.strip())
    except KeyError:
        raise click.BadParameter(
            f"{code!r} is no finding code; the codes: {', '.join(rules.rules())}",
            param_hint="--explain",
        ) from None
    for line in text.splitlines():  # the records are lensaudit's; escaped all the same
        click.echo(printable(line))


def _run(
    paths: tuple[Path, ...],
    baseline: str | None,
    margin: float,
    verbose: bool,
    output_format: str,
    cache: bool,
) -> CheckResult:
    """The check's result, its paths as ``output_format`` shows them."""
    from ..check import CheckError  # numpy (the audits): --help stays quick
    from ..check import check as run_check  # numpy (the audits): --help stays quick

    try:
        result = run_check(
            list(paths) or None, baseline=baseline, margin=margin, verbose=verbose, cache=cache
        )
    except (CheckError, LoadError) as error:
        fail(str(error))
    if output_format in ("github", "junit"):
        result = result.relative_to(*_repository_roots(paths))
    return result


def _repository_roots(paths: tuple[Path, ...]) -> list[Path]:
    """Where CI systems start their paths: the top level of the git repository
    holding each PATH, found from PATH itself.

    For a PATH in no repository, GITHUB_WORKSPACE when set (GitHub's checkout),
    else the current directory. GITHUB_WORKSPACE never overrides the
    repository that holds PATH: it may be a parent of it, or another
    checkout altogether.
    """
    roots = []
    for start in paths or (Path.cwd(),):
        directory = start if start.is_dir() else start.parent
        top = _git_top_level(directory)
        if top is None:
            top = Path(os.environ.get("GITHUB_WORKSPACE") or Path.cwd())
        if top not in roots:
            roots.append(top)
    return roots


def _git_top_level(directory: Path) -> Path | None:

    try:
        top = top_level(directory)
    except (GitError, GitUnavailable):
        return None
    return top if top.parts else None
