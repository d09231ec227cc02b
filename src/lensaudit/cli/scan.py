"""``lensaudit scan``: audit a Lensfun database and print or write the result."""

from __future__ import annotations

from pathlib import Path

import click

from ..commands import KIND_NAMES, ScanArguments
from ..commands import scan as run_scan
from .options import cache_option, database_paths, format_option, output_file


@click.command()
@database_paths
@format_option("table: readable summary; csv, json: every entry with its metrics.")
@click.option(
    "-k",
    "--kind",
    type=click.Choice(KIND_NAMES),
    default="distortion",
    show_default=True,
    help="Which models to audit: distortion (r_max), vignetting (where the correction "
    "divides by zero) or tca (where a colour channel folds).",
)
@output_file
@cache_option
def scan(
    paths: tuple[Path, ...], output_format: str, kind: str, output: Path | None, cache: bool
) -> None:
    """Compute r_max for every distortion entry of a Lensfun database.

    PATH is a database directory (the files liblensfun reads there: every
    *.xml, also in subdirectories named *.xml), a Lensfun checkout
    (its data/db) or XML files. Without PATH: the database of the Lensfun
    checkout around the working directory, else the one bundled with
    lensfunpy. --kind vignetting or tca audits those models instead
    (see docs/vignetting.md).

    \b
    Per entry (CSV/JSON columns):
      r_max         first local maximum of D(r), undistorted, in Hugin units
                    (1 = half the short side of the calibration image)
      d_max         D(r_max), the largest distorted radius the model reaches
      r_normalized  d_max / image corner hypot(aspect, 1) (1 for a circular
                    fisheye's image circle); below 1 the model folds inside
                    its own image
      *_paper       the same with the paper's mixed-unit corner (for comparison)

    \b
    --kind vignetting: C(r) = 1 + k1 r^2 + k2 r^4 + k3 r^6, r = 1 at half
    the diagonal (the frame corner), per <vignetting> entry:
      r_corner       image judged: 1, or a circular fisheye's circle
      r_zero         first r where C changes sign (inf: never)
      c_min, r_min   minimum of C over the image, and where
      r_turn         first r where C' changes sign (inf: never)
      zero_in_image  C <= 0 in the image: correction divides by zero (error)
      low_in_image   C < 0.1 in the image: gain above 10 (warning)
      monotone       no turning point inside the image (false: notice)

    \b
    --kind tca: r_d = r (b r^2 + c r + v) per channel, Hugin units, per
    <tca> entry:
      r_corner         image judged: hypot(aspect, 1), or 1 (circular fisheye)
      r_fold_red/blue  first local maximum of r_d (inf: never)
      folds_in_image   a channel folds inside the image (error)

    Every kind has file, line, the lens, the model as written, severity
    (vignetting, tca), status and message; see docs/vignetting.md. The
    cache keeps every kind's rows (the reader's work), not the audits.
    """
    run_scan(
        ScanArguments(
            tuple(map(str, paths)),
            output_format,
            kind,
            None if output is None else str(output),
            cache,
        )
    )
