"""``lensaudit scan``: audit a Lensfun database and print or write the result."""

from __future__ import annotations

import gc
from pathlib import Path

import click

from .options import (
    cache_option,
    database_paths,
    fail,
    format_option,
    output_file,
    output_stream,
)

KIND_NAMES = ("distortion", "vignetting", "tca")


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

    PATH is a database directory (every *.xml in it), a Lensfun checkout
    (its data/db) or XML files. Without PATH, the database of the Lensfun
    checkout around the working directory is audited, else the one bundled
    with lensfunpy. --kind vignetting or tca audits those models instead
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
    cache serves distortion only.
    """
    from ..loader import LoadError

    if kind != "distortion":
        _scan_calibrations(paths, output_format, kind, output)
        return

    from ..formats import writer
    from ..pipeline import run

    _single_blas_thread()
    collecting = gc.isenabled()
    # What the scan allocates lives until it ends: the cycle collector would
    # only walk it over and over (a tenth of importing numpy, for one).
    gc.disable()
    try:
        try:
            audit = run(list(paths) or None, cache=cache, formats=(output_format,))
        except LoadError as error:
            fail(str(error))
        if audit.files and all(f.error for f in audit.files):
            fail("no file could be read: " + "; ".join(f"{f.name}: {f.error}" for f in audit.files))
        with output_stream(output) as stream:
            writer(output_format)(audit, stream)
    finally:
        if collecting:
            gc.enable()


def _single_blas_thread() -> None:
    """Ask numpy's BLAS, if this process is the one to load it, for one thread.

    The audit does no linear algebra, and starting a BLAS thread pool makes
    importing numpy slower (much slower on a busy machine). Only this
    process is affected, and only when the user has not chosen.
    """
    import os
    import sys

    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def _scan_calibrations(
    paths: tuple[Path, ...], output_format: str, kind: str, output: Path | None
) -> None:
    """``scan --kind vignetting|tca``: read the elements of that kind and audit them."""
    from importlib import import_module

    from ..calibrations import load
    from ..loader import LoadError

    try:
        source, loaded = load(list(paths) or None)
    except LoadError as error:
        fail(str(error))
    if loaded.files and all(f.error for f in loaded.files):
        fail("no file could be read: " + "; ".join(f"{f.name}: {f.error}" for f in loaded.files))
    audit = import_module(f"lensaudit.{kind}").from_load(loaded, source)
    with output_stream(output) as stream:
        audit.write(output_format, stream)
