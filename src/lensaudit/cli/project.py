"""``lensaudit project``: project 3D points with a distortion model, flagging those beyond r_max."""

from __future__ import annotations

import array
import csv
import io
import math
import os
import stat
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import click

from .. import read
from ..formats import printable
from ..formats.csv_format import write_rows
from ..read import LoadError, display_path
from ..read.records import STATUS_OK
from .options import (
    GivenPath,
    fail,
    output_file,
    output_stream,
    refuse_unwritable,
    refuse_writing_inputs,
)

if TYPE_CHECKING:
    import numpy as np

    from ..projection import RadialCamera
    from ..read import DistortionEntry


@click.command()
@click.argument(
    "points",
    required=False,
    metavar="[POINTS]",
    # Checked when read: click's own checks would give a multi-line usage error.
    type=GivenPath(path_type=Path, allow_dash=True, readable=False),
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
    type=GivenPath(path_type=Path),
    help="Database directory or XML file for --lens and --entry [default: the "
    "database of the Lensfun checkout around the working directory, else the one "
    "bundled with lensfunpy].",
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
    columns are ignored), a .npy array N x 3, or - / nothing for standard
    input (CSV, or .npy recognised by its header). Without POINTS a terminal
    is not read (exit 2): pipe the points in, or give - to type them. Points
    are in the camera frame (z forward, in front of the camera for z > 0).

    The output is CSV with columns u, v, valid: the pixel in the recorded
    (distorted) image, and whether the point is in front of the camera and
    inside the model's valid domain (undistorted radius below r_max) with a
    finite pixel; valid is not "inside the image". u and v are empty where
    valid is false: there the model folds back, and a point far outside the
    field of view would land inside the image, or the pixel is beyond the
    float range.

    \b
    Examples:
      lensaudit project points.csv --entry slr-tokina.xml:17 --size 6000x4000
      lensaudit project points.npy --lens "Tokina 11-16" --focal 11 --crop 1 \\
          --size 6000x4000
      lensaudit project points.csv --opencv 1000,1000,959.5,539.5,-0.3,0.1
    """
    from ..projection import ProjectionError  # numpy: --help stays quick

    _check_choice(entry, lens, opencv, focal, databases, crop, real_focal)
    if points is None and not info and _stdin_is_terminal():
        # Waiting for a terminal the user did not mean to type into looks like a hang.
        fail(
            "no POINTS: give a CSV or .npy file of x, y, z, pipe the points in, "
            "or give - to type them"
        )
    given = [points] if points is not None and str(points) != "-" else []
    refuse_writing_inputs([output], None if opencv else databases, *given)
    refuse_unwritable([output])
    chosen = ""
    try:
        if opencv:
            camera = _opencv_camera(opencv, size)
        else:
            width, height = _size(size)
            camera, chosen = _lensfun_camera(
                entry, lens, focal, databases, width, height, crop, real_focal
            )
    except ProjectionError as error:
        fail(str(error))
    if info:
        with output_stream(output) as stream:
            _write_info(camera, stream)
    else:
        array = _read_points(points)
        try:
            pixels, valid = camera.project(array)
        except ProjectionError as error:
            fail(str(error))
        with output_stream(output) as stream:
            _write_pixels(pixels, valid, stream)
    if chosen:
        click.echo(printable(chosen), err=True)


def _check_choice(
    entry: str | None,
    lens: str | None,
    opencv: str | None,
    focal: float | None,
    databases: tuple[Path, ...],
    crop: float | None,
    real_focal: float | None,
) -> None:
    """Exit with status 2 unless exactly one model is chosen and every option applies to it."""
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
    from ..projection import opencv_camera  # numpy: --help stays quick

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
) -> tuple[RadialCamera, str]:
    """The camera of the entry chosen, and a line saying which entry it is."""
    from ..projection import ProjectionError, lensfun_camera  # numpy: --help stays quick

    if entry:
        found, named = _entry_at(entry)
    else:
        if focal is None:
            fail("--lens needs --focal MM (a focal length the lens is calibrated at)")
        found, named = _entry_by_name(lens or "", focal, crop, databases)
    try:
        # Without --real-focal, the entry's own (its attribute, else <real-focal-length>).
        camera = lensfun_camera(found, width, height, crop, real_focal=real_focal)
    except ProjectionError as error:
        # FILE:LINE as given, else where the lens found by name is.
        where = named if entry else f"{found.file}:{found.line}"
        fail(f"{where}: {error}")
    # Said once the points are projected: a problem is then the one line on stderr.
    return camera, f"lensaudit project: {found.lens} at {found.focal:g} mm, from {named}"


def _entry_at(text: str) -> tuple[DistortionEntry, str]:
    """The entry at FILE:LINE; a FILE that does not exist is looked for in the
    default database (the Lensfun checkout around the working directory,
    else the one bundled with lensfunpy)."""

    name, sep, line_text = text.rpartition(":")
    if not sep or not line_text.isdigit():
        fail(f"--entry {text!r}: expected FILE:LINE, e.g. slr-tokina.xml:17")
    path = Path(name)
    line = int(line_text)
    where = f"{display_path(path)}:{line}"
    if not path.is_file():
        try:
            source = read.resolve(None)
        except LoadError as error:
            fail(f"--entry {text!r}: no such file {name!r}, and no default database: {error}")
        path = source.paths[0] / name
        where = f"{name}:{line} in {source.label}"
        if not path.is_file():
            fail(f"--entry {text!r}: no such file {name!r}, nor in {source.label}")
    entries = read.read([path]).entries()
    matches = [e for e in entries if e.line == line]
    if not matches:
        lines = ", ".join(str(e.line) for e in entries[:8] if e.line)
        fail(
            f"{where}: no <distortion> element starts on that line"
            + (f" (entries start on lines {lines}, ...)" if lines else "")
        )
    found = matches[0]
    if found.status != STATUS_OK:
        fail(f"{where}: entry cannot be used ({found.status}: {found.message})")
    return found, where


def _entry_by_name(
    text: str, focal: float, crop: float | None, databases: tuple[Path, ...]
) -> tuple[DistortionEntry, str]:

    try:
        database = read.read(list(databases) or None)
    except LoadError as error:
        fail(str(error))
    entries, label = database.entries(), database.source.label
    needle = text.casefold()
    named = [
        e for e in entries if e.status == STATUS_OK and needle in f"{e.maker} {e.lens}".casefold()
    ]
    if not named:
        fail(f"--lens {text!r}: no usable distortion entry of a lens with that name in {label}")
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
    return found, label


#: What a .npy file starts with (NumPy's format documentation).
_NPY_MAGIC = b"\x93NUMPY"
#: What .npz archives and spreadsheets saved as .xlsx start with.
_ZIP_MAGIC = b"PK\x03\x04"
#: Longest name or cell shown in a message; the middle of longer ones is cut.
_SHOWN_LIMIT = 80
_FILE_KINDS = (
    (stat.S_ISDIR, "a directory"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
)


def _read_points(path: Path | None) -> np.ndarray:
    """The N x 3 points of POINTS: a .npy array (by suffix or header), else CSV."""
    if path is None or str(path) == "-":
        name, data = "<stdin>", _read_stdin()
        is_npy = data.startswith(_NPY_MAGIC)
    else:
        name = _shown(display_path(path))
        data = _read_file(path, name)
        is_npy = path.suffix.lower() == ".npy" or data.startswith(_NPY_MAGIC)
    if data.startswith(_ZIP_MAGIC):
        fail(f"{name}: a zip archive (.npz, .xlsx?); give CSV or a .npy array")
    return _parse_npy(data, name) if is_npy else _parse_csv(data, name)


def _stdin_is_terminal() -> bool:
    try:
        return sys.stdin is not None and sys.stdin.isatty()
    except (OSError, ValueError):  # closed: _read_stdin says so
        return False


def _read_stdin() -> bytes:
    stream = sys.stdin
    if stream is None:
        fail("<stdin>: standard input is closed; give a file of points")
    try:
        # Bytes, not text: the platform's newline and encoding handling must
        # not decide what a bare CR or a non-UTF-8 byte means.
        buffer = getattr(stream, "buffer", None)
        return buffer.read() if buffer is not None else stream.read().encode("utf-8")
    except UnicodeError:
        fail("<stdin>: not UTF-8 text")
    except (OSError, ValueError) as error:
        fail(f"<stdin>: cannot read: {getattr(error, 'strerror', None) or error}")
    raise AssertionError("unreachable")


def _read_file(path: Path, name: str) -> bytes:
    """The bytes of a regular file; anything else is refused before it is read."""
    # O_NONBLOCK: opening a FIFO without a writer must not wait forever; the
    # file is then refused by its type.
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    try:
        descriptor = os.open(path, flags)
    except OSError as error:
        fail(f"{name}: cannot read: {error.strerror or error}")
    reason = None
    try:
        mode = os.fstat(descriptor).st_mode
        if stat.S_ISREG(mode):
            with os.fdopen(descriptor, "rb", closefd=False) as stream:
                return stream.read()
    except OSError as error:
        reason = error.strerror or str(error)
    finally:
        os.close(descriptor)
    if reason is not None:
        fail(f"{name}: cannot read: {reason}")
    kind = next((kind for test, kind in _FILE_KINDS if test(mode)), "not a file")
    fail(f"{name}: {kind}, not a regular file; give a CSV or .npy file, or - for standard input")
    raise AssertionError("unreachable")


def _line_at(data: bytes, offset: int) -> int:
    """The line number of a byte offset, counting CR LF, lone CR and lone LF as line ends."""
    before = data[:offset]
    return before.count(b"\n") + before.count(b"\r") - before.count(b"\r\n") + 1


def _parse_csv(data: bytes, name: str) -> np.ndarray:
    """x, y, z from CSV: by header names when there is a header, else the first three columns."""
    import numpy as np  # numpy: --help stays quick

    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        fail(f"{name}: UTF-16 text; save it as UTF-8 CSV")
    nul = data.find(b"\0")
    if nul >= 0:
        fail(f"{name}:{_line_at(data, nul)}: NUL byte at offset {nul}; not a CSV text file")
    try:
        # Checked whole here, then read again in lines: one str of the whole
        # input would be kept as four bytes a character by io.StringIO.
        empty = not data.decode("utf-8-sig").strip()
    except UnicodeDecodeError as error:
        fail(
            f"{name}:{_line_at(data, error.start)}: not UTF-8 text "
            f"(byte 0x{data[error.start]:02x} at offset {error.start})"
        )
    if empty:
        fail(f"{name}: empty; expected CSV with columns x, y, z")
    # Floats packed as they are read: a list of tuples would take four times the memory.
    values = array.array("d")
    append = values.append
    rows, (cx, cy, cz) = _csv_rows(data, name)
    try:
        for row in rows:
            try:
                append(float(row[cx]))
                append(float(row[cy]))
                append(float(row[cz]))
            except (ValueError, IndexError):
                del values[len(values) - len(values) % 3 :]
                if _is_blank(row):
                    continue
                expected = (
                    "three numbers x, y, z"
                    if (cx, cy, cz) == (0, 1, 2)
                    else f"numbers x, y, z in columns {cx + 1}, {cy + 1}, {cz + 1} of the header"
                )
                fail(f"{name}:{rows.line_num}: expected {expected}, got {_row_cells(row)}")
    except csv.Error as error:
        _csv_error(error, rows.line_num, name)
    if not values:
        fail(f"{name}: no points, only a header")
    points = np.frombuffer(values, dtype=np.float64).reshape(-1, 3)
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():
        line = _line_of_point(data, name, int(np.argmin(finite)))
        point = points[int(np.argmin(finite))].tolist()
        fail(f"{name}:{line}: x, y, z must be finite numbers, got {point}")
    return points


def _csv_rows(data: bytes, name: str) -> tuple[Any, tuple[int, int, int]]:
    """A CSV reader positioned after the header (if any), and the columns of x, y, z.

    data is UTF-8 text with at least one line that is not blank.
    """
    # newline="": the csv module then reads CR, LF and CR LF line ends alike.
    stream = io.TextIOWrapper(io.BytesIO(data), encoding="utf-8-sig", newline="")
    first_line = next(line for line in stream if line.strip())
    stream.seek(0)
    # Comma-separated, or what spreadsheets in decimal-comma locales write.
    delimiter = next((d for d in ";\t" if d in first_line), ",")
    reader = csv.reader(stream, delimiter=delimiter)
    try:
        row = next((row for row in reader if not _is_blank(row)), None)
    except csv.Error as error:
        _csv_error(error, reader.line_num, name)
    if row is None:
        fail(f"{name}: no points, only empty cells")
    if not _is_header(row):
        # Read the first data row again with the others.
        stream.seek(0)
        return csv.reader(stream, delimiter=delimiter), (0, 1, 2)
    names = [cell.strip().lower() for cell in row]
    missing = [c for c in "xyz" if c not in names]
    if missing:
        fail(f"{name}:{reader.line_num}: header has no column {', '.join(missing)}")
    x, y, z = (names.index(c) for c in "xyz")
    return reader, (x, y, z)


def _line_of_point(data: bytes, name: str, index: int) -> int:
    """The line of the index-th point (from 0), read again as _parse_csv read it."""
    rows, _ = _csv_rows(data, name)
    for row in rows:
        if not _is_blank(row):
            if index == 0:
                return rows.line_num
            index -= 1
    raise AssertionError("fewer rows than points")


def _csv_error(error: csv.Error, line: int, name: str) -> None:
    if "field larger" in str(error):
        fail(f"{name}:{line}: a field longer than {csv.field_size_limit()} characters")
    fail(f"{name}:{line}: not CSV ({error})")


def _is_blank(row: list[str]) -> bool:
    """An empty line, or one of empty cells as spreadsheets write them (",,")."""
    return not any(cell.strip() for cell in row)


def _is_header(row: list[str]) -> bool:
    """A header has no number among its first three cells ("1,2,a" is a bad data row)."""
    for cell in row[:3]:
        try:
            float(cell)
        except ValueError:
            continue
        return False
    return True


def _row_cells(row: Sequence[str]) -> str:
    shown = [repr(_shown(cell, 24)) for cell in row[:4]]
    return "[" + ", ".join(shown) + (", ...]" if len(row) > 4 else "]")


def _shown(text: str, limit: int = _SHOWN_LIMIT) -> str:
    """Text for a one-line message: control characters escaped, long text cut in the middle."""
    if not text.isprintable():
        text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    if len(text) > limit:
        half = (limit - 3) // 2
        text = f"{text[:half]}...{text[-half:]}"
    return text


def _parse_npy(data: bytes, name: str) -> np.ndarray:
    """An N x 3 numeric array from .npy bytes; never unpickles anything."""
    import numpy as np  # numpy: --help stays quick
    from numpy.lib import format as npy_format

    if not data.startswith(_NPY_MAGIC):
        fail(f"{name}: not a .npy array (no NumPy header)")
    stream = io.BytesIO(data)
    try:
        with warnings.catch_warnings():
            # A header in Python 2 style earns a warning from numpy: no news to a user.
            warnings.simplefilter("ignore")
            version = npy_format.read_magic(stream)
            if version == (1, 0):
                shape, fortran_order, dtype = npy_format.read_array_header_1_0(stream)
            elif version == (2, 0):
                shape, fortran_order, dtype = npy_format.read_array_header_2_0(stream)
            else:
                # Version 3 only adds UTF-8 field names, i.e. structured arrays.
                fail(f"{name}: .npy format version {version[0]}.{version[1]} is not supported")
    except Exception as error:  # whatever fails to parse in untrusted bytes is damage
        reason = _shown(str(error).splitlines()[0] if str(error) else type(error).__name__)
        fail(f"{name}: damaged .npy header: {reason}")
    if dtype.hasobject:
        fail(f"{name}: the array holds Python objects (pickled data), which are never loaded")
    if len(shape) != 2 or shape[1] != 3 or dtype.kind not in "iuf":
        shown_shape = " x ".join(map(str, shape)) or "scalar"
        fail(f"{name}: expected a numeric N x 3 array, not {dtype} {shown_shape}")
    if shape[0] == 0:
        fail(f"{name}: no points (a 0 x 3 array)")
    count = shape[0] * 3
    needed, available = count * dtype.itemsize, len(data) - stream.tell()
    if available < needed:
        fail(
            f"{name}: truncated: the header announces {shape[0]} x 3 {dtype} "
            f"({needed} bytes of data), the file has {available}"
        )
    array = np.frombuffer(data, dtype=dtype, count=count, offset=stream.tell())
    array = array.reshape(shape, order="F" if fortran_order else "C")
    with np.errstate(over="ignore", invalid="ignore"):  # long doubles beyond float64 become inf
        array = array.astype(np.float64)
    finite = np.isfinite(array).all(axis=1)
    if not finite.all():
        index = int(np.argmin(finite))
        fail(f"{name}: row {index} (from 0) is not finite: {array[index].tolist()}")
    return array


def _write_pixels(pixels: np.ndarray, valid: np.ndarray, stream: TextIO) -> None:

    write_rows(stream, ("u", "v", "valid"), (*pixels.T.tolist(), valid.tolist()))


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
        stream.write(f"{label.ljust(width)}  {printable(value)}\n")
