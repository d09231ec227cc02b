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
from ..git import GitError, GitUnavailable, top_level
from ..read import LoadError
from .options import (
    cache_option,
    database_paths,
    fail,
    output_file,
    output_stream,
    refuse_writing_inputs,
)

if TYPE_CHECKING:
    from ..check import CheckResult

FORMAT_NAMES = ("text", "json", "github", "junit")

#: Exit status when a finding fails the check.
EXIT_FINDINGS = 1


#: The help of `lensaudit check`: what it reports and its exit status.
CHECK_HELP = """Fail when a Lensfun database, or a change to it, has models that fold.

PATH is a database directory (every *.xml in it), a Lensfun checkout
(its data/db) or XML files. Without PATH: the database of the Lensfun
checkout around the working directory, else the one bundled with
lensfunpy.

\b
Errors (fail the check):
  fold-in-image        the model folds back inside its own image:
                       D(r_max) < image corner hypot(aspect, 1)
                       (a circular fisheye: its image circle, 1)
  xml-error            the file is not well-formed XML (line, column)
  not-a-database, missing-attribute, bad-value, unknown-model,
  no-lens, duplicate-lens, duplicate-focal, unreadable,
  r-max-not-computable (the input errors also for <vignetting>
  and <tca> elements, which their messages name)
  liblensfun-refuses   liblensfun master stops loading the file
                       there and loses the lenses after it
  vignetting-zero-in-image  C(r) <= 0 inside the image: the
                       correction divides by zero or flips sign
  tca-fold-in-image    a colour channel folds inside the image
  fold-between-calibrations  a zoom's model, as liblensfun
                       interpolates it between two calibrations
                       that do not fold, folds inside the image
Warnings: fold-near-image (D(r_max) below MARGIN times the corner);
  vignetting-low-in-image (C(r) < 0.1 inside the image);
  vignetting-brightens (C(r) > 1.05 inside the image: brighter
  than the centre, which no lens is); undefined-mount (a mount no
  <mount> of the database defines); conflicting-calibration (two
  calibrations of one lens for the same focal length, aperture and
  distance; liblensfun uses the first); vignetting-starting-values
  (k1=-0.3, k2=0, k3=0: the calibration script's start);
  focal-series-outlier (a distortion entry far from what its
  neighbours in focal length predict); duplicate-lens and
  duplicate-focal when the two are identical;
  inversion-fails-in-image (liblensfun's reverse transform cannot
  invert the model by its Newton steps inside the image);
  encoding-mismatch (the XML declaration names an encoding the
  bytes are not in: liblensfun reads UTF-8, other readers follow it).
Notices: baseline-unreadable (how a baseline file that cannot be parsed
  was replaced).
Notices with --verbose: fold-outside-image (any other finite r_max),
  vignetting-not-monotone (C(r) turns inside the image).

With --baseline, findings the baseline already has are reported as known
and do not fail, so only new or changed entries fail the check. Entries
are matched by content (lens name ignoring case and white space, and the
entry's own values), never by line. A git revision is read with git
ls-tree and git cat-file; the work tree is not touched. A baseline file
that cannot be parsed is replaced by its last version in git that can.

With --cache (the default), a file whose bytes an earlier check, report
or `scan --kind` read whole (the baseline's files too) is not parsed
again; the output is the same.

\b
Exit status:
  0  no finding fails the check (warnings and known findings do not)
  1  at least one new error
  2  bad usage, or input or baseline that could not be read at all
"""


@click.command(help=CHECK_HELP)
@database_paths
@click.option(
    "--baseline",
    metavar="DIR_OR_REV",
    default=None,
    help="Only fail on entries that are new or changed since this database: "
    "an existing directory (a Lensfun checkout meaning its data/db) or file, "
    "else a git revision of the repository holding PATH, e.g. origin/master or HEAD.",
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
def check(
    paths: tuple[Path, ...],
    baseline: str | None,
    margin: float,
    output_format: str,
    output: Path | None,
    verbose: bool,
    cache: bool,
) -> None:
    """`lensaudit check`: see :data:`CHECK_HELP`."""
    if not margin >= 1 or math.isinf(margin):
        raise click.BadParameter(f"{margin} is not a finite number >= 1", param_hint="--margin")
    baselines = [baseline] if baseline is not None and os.path.exists(baseline) else []
    refuse_writing_inputs([output], paths, *baselines)
    with cycle_collector_off():
        result = _run(paths, baseline, margin, verbose, output_format, cache)
        with output_stream(output) as stream:
            writer(output_format)(result, stream)
    if result.failed:
        raise SystemExit(EXIT_FINDINGS)


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
