"""``lensaudit project``: project 3D points with a distortion model, flagging those beyond r_max."""

from __future__ import annotations

import csv
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

import click

from .options import fail, output_file, output_stream

if TYPE_CHECKING:
    import numpy as np

    from ..loader import DistortionEntry
    from ..projection import RadialCamera

_BOOLEAN = {True: "true", False: "false"}


@click.command()
@click.argument(
    "points",
    required=False,
    metavar="[POINTS]",
    type=click.Path(path_type=Path, dir_okay=False, allow_dash=True),
)
@click.option(
    "--entry", metavar="FILE:LINE", help="The <distortion> element at LINE of a Lensfun XML file."
)
@click.option(
    "--lens", metavar="TEXT", help="A lens of the database whose name contains TEXT (with --focal)."
)
@click.option("--focal", type=float, metavar="MM", help="Calibrated focal length for --lens.")
@click.option(
    "--db",
    "databases",
    multiple=True,
    metavar="PATH",
    type=click.Path(path_type=Path),
    help="Database directory or XML file for --lens (default: lensfunpy's).",
)
@click.option(
    "--opencv",
    metavar="FX,FY,CX,CY[,K1[,K2[,P1,P2[,K3]]]]",
    help="An OpenCV camera instead: focal and centre in pixels, distortion "
    "coefficients (p1, p2 ignored).",
)
@click.option("--size", metavar="WxH", help="Image size in pixels (needed for Lensfun models).")
@click.option(
    "--crop",
    type=float,
    metavar="CROP",
    help="Camera crop factor (default: the calibration's); with --lens it also "
    "picks among calibrations made at different crop factors.",
)
@click.option(
    "--real-focal",
    type=float,
    metavar="MM",
    help="Real focal length of the calibration (default: from the database).",
)
@click.option("--info", is_flag=True, help="Print the camera and its r_max, read no points.")
@output_file
def project(
    points: Path | None,
    entry: str | None,
    lens: str | None,
    focal: float | None,
    databases: tuple[Path, ...],
    opencv: str | None,
    size: str | None,
    crop: float | None,
    real_focal: float | None,
    info: bool,
    output: Path | None,
) -> None:
    """Project 3D points through a distortion model; flag those beyond r_max.

    POINTS is a CSV file with columns x, y, z (a header row is optional; other
    columns are ignored), a .npy array N x 3, or - / nothing for CSV on
    standard input. Points are in the camera frame (z forward, in front of
    the camera for z > 0).

    The output is CSV with columns u, v, valid: the pixel in the recorded
    (distorted) image, and whether the point is in front of the camera and
    inside the model's valid domain (undistorted radius below r_max). u and v
    are empty where valid is false: there the model folds back, and a point
    far outside the field of view would land inside the image.

    \b
    Examples:
      lensaudit project points.csv --entry slr-tokina.xml:17 --size 6000x4000
      lensaudit project points.npy --lens "Tokina 11-16" --focal 11 --crop 1 \\
          --size 6000x4000
      lensaudit project points.csv --opencv 1000,1000,959.5,539.5,-0.3,0.1
    """
    from ..projection import ProjectionError

    chosen = [
        name
        for name, value in (("--entry", entry), ("--lens", lens), ("--opencv", opencv))
        if value
    ]
    if len(chosen) != 1:
        fail(
            "give exactly one of --entry, --lens (with --focal) or --opencv"
            + (f", not {' and '.join(chosen)}" if chosen else "")
        )
    unused = [
        name
        for name, value, applies in (
            ("--focal", focal, bool(lens)),
            ("--db", databases, bool(lens)),
            ("--crop", crop, not opencv),
            ("--real-focal", real_focal, not opencv),
        )
        if value not in (None, ()) and not applies
    ]
    if unused:
        fail(f"{', '.join(unused)} does not apply to {chosen[0]}")
    try:
        if opencv:
            camera = _opencv_camera(opencv, size)
        else:
            width, height = _size(size)
            camera = _lensfun_camera(entry, lens, focal, databases, width, height, crop, real_focal)
    except ProjectionError as error:
        fail(str(error))
    if info:
        with output_stream(output) as stream:
            _write_info(camera, stream)
        return
    array = _read_points(points)
    try:
        pixels, valid = camera.project(array)
    except ProjectionError as error:
        fail(str(error))
    with output_stream(output) as stream:
        _write_pixels(pixels, valid, stream)


def _size(text: str | None) -> tuple[int, int]:
    if text is None:
        fail("--size WxH is needed for a Lensfun model (the image size in pixels)")
    width, sep, height = text.lower().partition("x")
    try:
        if not sep:
            raise ValueError
        size = int(width), int(height)
    except ValueError:
        fail(f"--size {text!r}: expected WIDTHxHEIGHT in pixels, e.g. 6000x4000")
    if min(size) < 2:
        fail(f"--size {text!r}: the image must be at least 2x2 pixels")
    return size


def _numbers(text: str, option: str) -> list[float]:
    try:
        values = [float(part) for part in text.split(",")]
    except ValueError:
        fail(f"{option} {text!r}: expected comma-separated numbers")
    if not all(math.isfinite(v) for v in values):
        fail(f"{option} {text!r}: numbers must be finite")
    return values


def _opencv_camera(text: str, size: str | None) -> RadialCamera:
    from ..projection import opencv_camera

    values = _numbers(text, "--opencv")
    if len(values) not in (4, 5, 6, 8, 9):
        fail(
            f"--opencv: {len(values)} numbers; expected FX,FY,CX,CY, then k1 or k1,k2 "
            "or k1,k2,p1,p2 or k1,k2,p1,p2,k3"
        )
    fx, fy, cx, cy, *coefficients = values
    if len(coefficients) < 4:
        coefficients += [0.0] * (4 - len(coefficients))
    width = height = None
    if size is not None:
        width, height = _size(size)
    return opencv_camera([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], coefficients, width, height)


def _lensfun_camera(
    entry: str | None,
    lens: str | None,
    focal: float | None,
    databases: tuple[Path, ...],
    width: int,
    height: int,
    crop: float | None,
    real_focal: float | None,
) -> RadialCamera:
    from ..projection import lensfun_camera, real_focal_from_xml

    if entry:
        found, path = _entry_at(entry)
    else:
        if focal is None:
            fail("--lens needs --focal MM (a focal length the lens is calibrated at)")
        found, path = _entry_by_name(lens or "", focal, crop, databases)
    if real_focal is None and path is not None:
        real_focal = real_focal_from_xml(path, found.line)
    return lensfun_camera(found, width, height, crop, real_focal=real_focal)


def _entry_at(text: str) -> tuple[DistortionEntry, Path]:
    """The entry at FILE:LINE; a FILE that does not exist is looked for in the bundled database."""
    from ..loader import STATUS_OK, LoadError, load

    name, sep, line_text = text.rpartition(":")
    if not sep or not line_text.isdigit():
        fail(f"--entry {text!r}: expected FILE:LINE, e.g. slr-tokina.xml:17")
    path = Path(name)
    if not path.is_file():
        from ..database import bundled_database_path

        try:
            bundled = bundled_database_path() / name
        except LoadError:
            bundled = None
        if bundled is None or not bundled.is_file():
            fail(f"--entry {text!r}: no such file {name!r} (nor in the bundled database)")
        path = bundled
    line = int(line_text)
    entries = load([path]).entries
    matches = [e for e in entries if e.line == line]
    if not matches:
        lines = ", ".join(str(e.line) for e in entries[:8] if e.line)
        fail(
            f"{name}:{line}: no <distortion> element starts on that line"
            + (f" (entries start on lines {lines}, ...)" if lines else "")
        )
    found = matches[0]
    if found.status != STATUS_OK:
        fail(f"{name}:{line}: entry cannot be used ({found.status}: {found.message})")
    return found, path


def _entry_by_name(
    text: str, focal: float, crop: float | None, databases: tuple[Path, ...]
) -> tuple[DistortionEntry, Path | None]:
    from ..database import resolve
    from ..loader import STATUS_OK, LoadError, load

    try:
        loaded = load(list(resolve(list(databases) or None).paths))
    except LoadError as error:
        fail(str(error))
    needle = text.casefold()
    named = [
        e
        for e in loaded.entries
        if e.status == STATUS_OK and needle in f"{e.maker} {e.lens}".casefold()
    ]
    if not named:
        fail(f"--lens {text!r}: no usable distortion entry of a lens with that name")
    lenses = sorted({e.lens for e in named})
    exact = [name for name in lenses if name.casefold() == needle]
    if len(lenses) > 1 and not exact:
        shown = "; ".join(lenses[:5]) + ("; ..." if len(lenses) > 5 else "")
        fail(f"--lens {text!r} matches {len(lenses)} lenses: {shown}")
    if exact:
        named = [e for e in named if e.lens == exact[0]]
    at_focal = [e for e in named if math.isclose(e.focal, focal, rel_tol=1e-9)]
    if not at_focal:
        focals = ", ".join(f"{f:g}" for f in sorted({e.focal for e in named}))
        fail(f"--lens {text!r} has no calibration at {focal:g} mm (calibrated: {focals} mm)")
    if len(at_focal) > 1 and crop is not None:
        same_crop = [e for e in at_focal if math.isclose(e.crop_factor, crop, rel_tol=1e-6)]
        at_focal = same_crop or at_focal
    if len(at_focal) > 1:
        places = ", ".join(f"{e.file}:{e.line} (crop {e.crop_factor:g})" for e in at_focal[:5])
        fail(
            f"--lens {text!r} at {focal:g} mm has {len(at_focal)} calibrations: {places}; "
            "choose one with --entry FILE:LINE"
        )
    found = at_focal[0]
    paths = {f.name: f.path for f in loaded.files}
    return found, paths.get(found.file)


def _read_points(path: Path | None) -> np.ndarray:
    import numpy as np

    if path is not None and str(path) != "-" and path.suffix.lower() == ".npy":
        try:
            array = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as error:
            fail(f"{path}: cannot read as a .npy array: {error}")
        if array.ndim != 2 or array.shape[1] != 3 or array.dtype.kind not in "iuf":
            fail(f"{path}: expected a numeric N x 3 array, not {array.dtype} {array.shape}")
        return array.astype(np.float64, copy=False)
    if path is None or str(path) == "-":
        return _read_csv(sys.stdin, "<stdin>")
    try:
        with open(path, encoding="utf-8-sig", newline="") as stream:
            return _read_csv(stream, str(path))
    except OSError as error:
        fail(f"cannot read {path}: {error.strerror or error}")
    except UnicodeDecodeError:
        fail(f"{path}: not a UTF-8 text file (give .npy files the .npy suffix)")
    raise AssertionError("unreachable")


def _read_csv(stream: TextIO, name: str) -> np.ndarray:
    """x, y, z from CSV: by header names when there is a header, else the first three columns."""
    import numpy as np

    reader = csv.reader(stream)
    columns = (0, 1, 2)
    rows: list[tuple[float, ...]] = []
    first = True
    for row in reader:
        if not row or (len(row) == 1 and not row[0].strip()):
            continue
        if first and _is_header(row):
            first = False
            names = [cell.strip().lower() for cell in row]
            missing = [c for c in "xyz" if c not in names]
            if missing:
                fail(f"{name}:{reader.line_num}: header has no column {', '.join(missing)}")
            columns = tuple(names.index(c) for c in "xyz")
            continue
        first = False
        try:
            rows.append(tuple(float(row[i]) for i in columns))
        except (ValueError, IndexError):
            fail(f"{name}:{reader.line_num}: expected three numbers x, y, z, got {row[:4]!r}")
    return np.array(rows, dtype=np.float64).reshape(-1, 3)


def _is_header(row: list[str]) -> bool:
    try:
        [float(cell) for cell in row[:3]]
    except ValueError:
        return True
    return False


def _write_pixels(pixels: np.ndarray, valid: np.ndarray, stream: TextIO) -> None:
    us = ["" if text == "nan" else text for text in map(repr, pixels[:, 0].tolist())]
    vs = ["" if text == "nan" else text for text in map(repr, pixels[:, 1].tolist())]
    flags = [_BOOLEAN[v] for v in valid.tolist()]
    out = csv.writer(stream, lineterminator="\n")
    out.writerow(("u", "v", "valid"))
    out.writerows(zip(us, vs, flags, strict=True))


def _write_info(camera: RadialCamera, stream: TextIO) -> None:
    rows = [
        ("camera", camera.description),
        ("fx, fy (px)", f"{camera.fx:.6g}, {camera.fy:.6g}"),
        ("centre (px)", f"{camera.cx:.6g}, {camera.cy:.6g}"),
        ("r_max (x/z)", f"{camera.r_max:.6g}"),
        ("valid half field of view (deg)", f"{camera.max_angle_degrees:.4g}"),
        ("r_max (px, undistorted)", f"{camera.r_max_pixels():.6g}"),
        ("d_max (px, distorted)", f"{camera.d_max * camera.fx:.6g}"),
    ]
    if camera.width and camera.height:
        # The farthest image corner, in distorted pinhole units like d_max.
        corner = math.hypot(
            max(camera.cx, camera.width - 1 - camera.cx) / camera.fx,
            max(camera.cy, camera.height - 1 - camera.cy) / camera.fy,
        )
        folds = camera.d_max < corner
        rows.append(("d_max / image corner", f"{camera.d_max / corner:.4g}"))
        rows.append(("folds inside the image", "yes" if folds else "no"))
    rows += [("note", note) for note in camera.notes]
    width = max(len(label) for label, _ in rows)
    for label, value in rows:
        stream.write(f"{label.ljust(width)}  {value}\n")
