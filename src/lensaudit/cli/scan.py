"""``lensaudit scan``: audit a Lensfun database and print or write the result."""

from __future__ import annotations

from pathlib import Path

import click

from .options import database_paths, fail, output_file, output_stream

FORMAT_NAMES = ("table", "csv", "json")


@click.command()
@database_paths
@click.option(
    "-f",
    "--format",
    "output_format",
    type=click.Choice(FORMAT_NAMES),
    default="table",
    show_default=True,
    help="table: readable summary; csv, json: every entry with its metrics.",
)
@output_file
@click.option(
    "--cache/--no-cache",
    default=True,
    show_default=True,
    help="Reuse files parsed by an earlier run when unchanged (size and time); "
    "the cache is in $LENSAUDIT_CACHE_DIR or ~/.cache/lensaudit.",
)
def scan(paths: tuple[Path, ...], output_format: str, output: Path | None, cache: bool) -> None:
    """Compute r_max for every distortion entry of a Lensfun database.

    PATH is a database directory (every *.xml in it) or XML files. Without
    PATH, the database bundled with lensfunpy is audited.

    \b
    Per entry (CSV/JSON columns):
      r_max         first local maximum of D(r), undistorted, in Hugin units
                    (1 = half the short side of the calibration image)
      d_max         D(r_max), the largest distorted radius the model reaches
      r_normalized  d_max / image corner hypot(aspect, 1); below 1 the model
                    folds inside its own image
      *_paper       the same with the paper's mixed-unit corner (for comparison)
    """
    from ..formats import writer
    from ..loader import LoadError
    from ..pipeline import run

    try:
        audit = run(list(paths) or None, cache=cache)
    except LoadError as error:
        fail(str(error))
    if audit.files and all(f.error for f in audit.files):
        fail("no file could be read: " + "; ".join(f"{f.name}: {f.error}" for f in audit.files))
    with output_stream(output) as stream:
        writer(output_format)(audit, stream)
