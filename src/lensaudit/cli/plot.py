"""``lensaudit plot``: one entry's D(r) curve or undistortion, and Brown-Conrady r_max maps."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from ..formats import printable
from ..pipeline import run
from ..read import LoadError
from ..writing import OutputSet
from .options import (
    EXIT_INPUT_ERROR,
    GivenPath,
    cache_option,
    fail,
    refuse_unwritable,
    refuse_writing_inputs,
)

if TYPE_CHECKING:
    from ..pipeline import Audit

FIGURE_FORMATS = ("png", "svg", "pdf")


def _output(function: Callable[..., Any]) -> Callable[..., Any]:
    return click.option(
        "-o",
        "--output",
        required=True,
        metavar="FILE",
        type=GivenPath(path_type=Path, dir_okay=False),
        help="Image to write: .png, .svg or .pdf.",
    )(function)


def _entry_options(function: Callable[..., Any]) -> Callable[..., Any]:
    options = [
        click.argument("entry", required=False, metavar="[ENTRY]"),
        click.option(
            "--lens",
            default="",
            help="Words that must all appear in "
            '"maker lens" (case-insensitive), e.g. "Tokina 11-16".',
        ),
        click.option("--focal", type=float, default=None, help="Focal length in mm."),
        click.option("--crop", type=float, default=None, help="Crop factor."),
        click.option(
            "--db",
            "databases",
            multiple=True,
            metavar="PATH",
            type=GivenPath(path_type=Path),
            help="Database directory or XML file (repeatable) [default: the "
            "database of the Lensfun checkout around the working directory, else the one "
            "bundled with lensfunpy].",
        ),
        cache_option,
    ]
    for option in reversed(options):
        function = option(function)
    return function


def _check_format(output: Path) -> str:
    fmt = output.suffix.lstrip(".").lower()
    if fmt not in FIGURE_FORMATS:
        fail(f"cannot write {output}: give a .png, .svg or .pdf file name")
    return fmt


def _check_output(output: Path, entry: str | None, databases: tuple[Path, ...]) -> None:
    """Exit with status 2 for a figure format not known, or an output that is an input."""
    _check_format(output)
    named = (entry or "").rpartition(":")[0]
    refuse_writing_inputs([output], databases, *([named] if named and Path(named).exists() else []))
    refuse_unwritable([output])


def _audit(paths: list[Path] | None, cache: bool) -> Audit:

    try:
        return run(paths or None, cache=cache)
    except LoadError as error:
        fail(str(error))
        raise  # unreachable: fail() exits


def resolve_entry(
    entry: str | None,
    lens: str,
    focal: float | None,
    crop: float | None,
    databases: tuple[Path, ...],
    cache: bool = True,
) -> tuple[Audit, int]:
    """The audit holding the named entry and the entry's index; exits 2 on bad input.

    An ambiguous query prints every candidate as FILE:LINE before exiting.
    """
    from ..report import select  # numpy and matplotlib: --help stays quick

    query = select.Query(lens, focal, crop)
    if entry and query:
        fail("name the entry either as FILE:LINE or with --lens/--focal/--crop, not both")
    try:
        if entry:
            location = select.parse_location(entry)
            if location is None:
                fail(
                    f"{entry!r} is not FILE:LINE (the line of a <distortion> element, "
                    f"e.g. slr-tokina.xml:17); to search by name use --lens"
                )
            file, line = location
            paths = list(databases) or ([Path(file)] if Path(file).is_file() else None)
            audit = _audit(paths, cache)
            return audit, select.by_location(audit, file, line)
        if not query:
            fail('name an entry: FILE:LINE, or a query such as --lens "Tokina 11-16" --focal 11')
        audit = _audit(list(databases), cache)
        return audit, select.by_query(audit, query)
    except select.SelectionError as error:
        click.echo(f"lensaudit: error: {printable(f'{error}, in {audit.source.label}')}", err=True)
        for index in error.candidates:
            click.echo(f"  {printable(select.describe(audit.entries[index]))}", err=True)
        raise SystemExit(EXIT_INPUT_ERROR) from None


def _save(figure: Any, output: Path) -> None:
    from ..report.figures import save  # matplotlib: --help stays quick

    try:
        with OutputSet() as outputs:
            save(figure, outputs.path(output), _check_format(output))
    except OSError as error:
        fail(f"cannot write {output}: {error.strerror or error}")
    click.echo(f"Wrote {printable(str(output))}")


def _from(audit: Audit) -> None:
    """The first line: the database read."""
    click.echo(f"lensaudit plot: {printable(audit.source.label)}")


@click.group()
def plot() -> None:
    """Plot one entry's D(r), its undistortion, or r_max maps.

    ENTRY is FILE:LINE, the file name and line of a <distortion> element as
    `lensaudit scan` lists them (e.g. slr-tokina.xml:17), or a path to an XML
    file with a line. Instead of ENTRY, a query names one entry:
    --lens "Tokina 11-16" --focal 11 --crop 1. When several entries match,
    they are listed and nothing is drawn (exit status 2).
    """


@plot.command()
@_entry_options
@_output
def curve(
    entry: str | None,
    lens: str,
    focal: float | None,
    crop: float | None,
    databases: tuple[Path, ...],
    cache: bool,
    output: Path,
) -> None:
    """D(r) and D'(r) of one entry, with r_max and the image corner marked.

    Radii in Hugin units (1 = half the short side of the calibration image).
    The model folds inside the image when D peaks (at r_max) below the corner.
    """
    _check_output(output, entry, databases)
    audit, index = resolve_entry(entry, lens, focal, crop, databases, cache)
    _from(audit)
    from ..report import curves, figures, select  # numpy and matplotlib: --help stays quick

    m = audit.metrics
    chosen = audit.entries[index]
    sampled = curves.sample(
        chosen, float(m.r_max[index]), float(m.d_max[index]), float(m.r_corner[index])
    )
    title = (
        f"{select.describe(chosen)}\nr_normalized = {m.r_normalized[index]:.3f} "
        f"(paper's units {m.r_normalized_paper[index]:.3f})"
    )
    _save(figures.curve_figure(sampled, title), output)


def _size(text: str) -> tuple[int, int]:
    width, sep, height = text.lower().partition("x")
    if (
        not sep
        or not width.isdigit()
        or not height.isdigit()
        or not (16 <= int(width) <= 8000 and 16 <= int(height) <= 8000)
    ):
        raise click.BadParameter("give WIDTHxHEIGHT in pixels, each 16 to 8000, e.g. 1000x666")
    return int(width), int(height)


@plot.command()
@_entry_options
@_output
@click.option(
    "--size", default="1000x666", show_default=True, metavar="WxH", help="Output size in pixels."
)
@click.option(
    "--scale",
    type=float,
    default=None,
    metavar="S",
    help="Zoom: the output shows the image reduced by S (liblensfun's Modifier "
    "scale; default: far enough out to show the fold).",
)
def warp(
    entry: str | None,
    lens: str,
    focal: float | None,
    crop: float | None,
    databases: tuple[Path, ...],
    cache: bool,
    output: Path,
    size: str,
    scale: float | None,
) -> None:
    """A coloured checkerboard undistorted with one entry's model (paper Figure 6).

    The checkerboard is the distorted input image (inset, top left); its colour
    encodes position. The output reaches past the image, so that the fold
    shows: outside the green circle (r = r_max) the model repeats image
    content, mirrored where D(r) < 0.
    """
    _check_output(output, entry, databases)
    width, height = _size(size)
    if scale is not None and not (0 < scale <= 10 and math.isfinite(scale)):
        fail("--scale must be a number in (0, 10]")
    audit, index = resolve_entry(entry, lens, focal, crop, databases, cache)
    _from(audit)
    from ..report import figures, select  # numpy and matplotlib: --help stays quick
    from ..report import warp as warping  # numpy and matplotlib: --help stays quick

    m = audit.metrics
    chosen = audit.entries[index]
    r_max = float(m.r_max[index])
    try:
        result = warping.warp_entry(chosen, r_max, width, height, scale)
    except ValueError as error:
        fail(f"{chosen.file}:{chosen.line}: {error}")
    inset = warping.input_image(240, max(2, round(240 * height / width)))
    caption = (
        f"{select.describe(chosen)}: r_max = {r_max:.4g}, "
        f"r_normalized = {m.r_normalized[index]:.3f}, scale {result.scale:.3g}"
    )
    _save(figures.warp_figure(result, inset, caption), output)


#: The largest k1, k2 or k3 a map takes: D'(r)'s coefficients (7 k3) stay finite.
_LARGEST_COEFFICIENT = 1e300


@plot.command(name="map")
@_output
@click.option(
    "--k3",
    "k3_values",
    type=float,
    multiple=True,
    metavar="K3",
    help="A k3 value, one panel each (repeatable; default -0.5, 0, 0.5, 1).",
)
@click.option(
    "--range",
    "k_range",
    type=float,
    nargs=2,
    default=(-1.0, 1.0),
    show_default=True,
    metavar="MIN MAX",
    help="Range of k1 and k2.",
)
@click.option(
    "--resolution",
    type=click.IntRange(2, 2000),
    default=301,
    show_default=True,
    help="Grid points along k1 and k2.",
)
def map_command(
    output: Path, k3_values: tuple[float, ...], k_range: tuple[float, float], resolution: int
) -> None:
    """r_max of the Brown-Conrady model over (k1, k2), for several k3 (paper Figure 3).

    Radii in normalized camera coordinates (OpenCV's k1, k2, k3). Green: no
    fold (r_max infinite); red: r_max near 0.
    """
    _check_format(output)
    refuse_unwritable([output])
    if not k_range[0] < k_range[1]:
        fail("--range needs MIN < MAX")
    for option, values in (("--range", k_range), ("--k3", k3_values)):
        if not all(abs(value) <= _LARGEST_COEFFICIENT for value in values):
            shown = " ".join(f"{value:g}" for value in values)
            fail(f"{option} {shown}: expected numbers from -1e300 to 1e300")
    from ..report import figures  # numpy and matplotlib: --help stays quick
    from ..report.rmax_map import DEFAULT_K3, rmax_map  # numpy: --help stays quick

    grid = rmax_map(tuple(k3_values) or DEFAULT_K3, k_range, resolution)
    _save(figures.map_figure(grid), output)
