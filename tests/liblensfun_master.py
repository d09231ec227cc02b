"""Lensfun master's liblensfun, called through ctypes: how Lensfun itself reads a database file.

lensfunpy ships liblensfun 0.3.4, which refuses database files of version 2. This
module gives tests the library of Lensfun master (source ``lensfun-src-1c8b8f07.tar.gz``
in ``../shared/data`` beside the repository), built once per machine:

- :func:`library` -- the loaded library (a :class:`ctypes.CDLL`), or a pytest skip
  with the reason where the source, cmake, a C++ compiler or GLib's headers are
  missing, or the build fails;
- :func:`load_verdict` -- whether liblensfun loads one file's content, and its error
  code's name (:func:`load_result` adds the parse warning liblensfun prints);
- :func:`lenses` -- every lens liblensfun holds after loading one file, as dicts;
- :func:`interpolate_distortion` -- liblensfun's distortion model at a crop factor
  and focal length, for one of those lenses.

Numbers come from liblensfun's single-precision fields, as Python floats. Master's
parser puts every calibration of a lens into one calibration set (the first), whose
attributes are the lens's ``<cropfactor>`` and ``<aspect-ratio>``; each distortion
keeps the ``<calibration>`` element's attributes of its own. Not read here: TCA,
vignetting, crop and field-of-view calibrations, cameras and ``<mount>`` definitions.
Each call loads the file into a database of its own and destroys it before returning.

The library is built in ``$LENSAUDIT_LIBLENSFUN_DIR`` where that is set, else in
``<tempdir>/lensaudit-liblensfun-<hash of the source's path and size>``, with
``../shared/tools/build-liblensfun.sh``.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import pytest


def _shared() -> Path:
    """``shared/`` beside the repository, or beside the directory of its worktrees."""
    repository = Path(__file__).resolve().parents[1]
    for base in (repository.parent, repository.parent.parent):
        if (base / "shared" / "data").is_dir():
            return base / "shared"
    return repository.parent / "shared"


#: ``shared/`` beside the repository: the source tarball and its build script.
SHARED = _shared()
SOURCE_TARBALL = SHARED / "data" / "lensfun-src-1c8b8f07.tar.gz"
BUILD_SCRIPT = SHARED / "tools" / "build-liblensfun.sh"

#: Environment variable naming the build directory (else one under the temporary directory).
BUILD_DIR_VARIABLE = "LENSAUDIT_LIBLENSFUN_DIR"

#: Where GLib's headers are looked for when pkg-config cannot tell (as Lensfun's FindGLIB2).
GLIB_INCLUDE_DIRS = ("/usr/include", "/usr/local/include", "/opt/local/include")

#: lfError: 0 and the positive codes (negative codes are -errno).
ERROR_NAMES = {0: "", 1: "LF_WRONG_FORMAT", 2: "LF_NO_DATABASE"}

#: lfDistortionModel, by value, as the XML's model attribute spells it.
DISTORTION_MODELS = ("none", "poly3", "poly5", "ptlens", "acm")

#: lfLensType, by value, as the XML's <type> spells it ("unknown" has no XML spelling).
LENS_TYPES = (
    "unknown",
    "rectilinear",
    "fisheye",
    "panoramic",
    "equirectangular",
    "orthographic",
    "stereographic",
    "equisolid",
    "fisheye_thoby",
)

#: lfLens::GetCalibrationSets() const (C++ only; the Itanium ABI's mangled name).
GET_CALIBRATION_SETS = "_ZNK6lfLens18GetCalibrationSetsEv"


class CalibAttributes(ctypes.Structure):
    """``lfLensCalibAttributes``."""

    _fields_ = [("CropFactor", ctypes.c_float), ("AspectRatio", ctypes.c_float)]


class CalibDistortion(ctypes.Structure):
    """``lfLensCalibDistortion``."""

    _fields_ = [
        ("Model", ctypes.c_int),
        ("Focal", ctypes.c_float),
        ("RealFocal", ctypes.c_float),
        ("RealFocalMeasured", ctypes.c_int),
        ("Terms", ctypes.c_float * 5),
        ("CalibAttr", CalibAttributes),
    ]


class Lens(ctypes.Structure):
    """The C part of ``lfLens`` (its C++-only members follow ``Score`` and are not read)."""

    _fields_ = [
        ("Maker", ctypes.c_void_p),
        ("Model", ctypes.c_void_p),
        ("MinFocal", ctypes.c_float),
        ("MaxFocal", ctypes.c_float),
        ("MinAperture", ctypes.c_float),
        ("MaxAperture", ctypes.c_float),
        ("Mounts", ctypes.c_void_p),
        ("Type", ctypes.c_int),
        ("CenterX", ctypes.c_float),
        ("CenterY", ctypes.c_float),
        ("CropFactor", ctypes.c_float),
        ("AspectRatio", ctypes.c_float),
        ("CalibDistortion", ctypes.POINTER(ctypes.POINTER(CalibDistortion))),
        ("CalibTCA", ctypes.c_void_p),
        ("CalibVignetting", ctypes.c_void_p),
        ("CalibCrop", ctypes.c_void_p),
        ("CalibFov", ctypes.c_void_p),
        ("Score", ctypes.c_int),
    ]


class LoadResult(NamedTuple):
    """What liblensfun says of one file: loaded or not, its error code's name, its warnings.

    ``warnings`` holds liblensfun's messages ("file:line:column: message"), one a line.
    """

    ok: bool
    error: str
    warnings: str


class LoadError(Exception):
    """liblensfun refused a file that :func:`lenses` was asked to read."""


@dataclass(frozen=True)
class LensSource:
    """Where a lens of :func:`lenses` comes from: the file's bytes and its place in the list."""

    data: bytes = field(repr=False)
    index: int


_library: ctypes.CDLL | None = None
_skip_reason: str | None = None


def build_directory() -> Path:
    """The directory liblensfun is built in (the same for every session on this machine)."""
    configured = os.environ.get(BUILD_DIR_VARIABLE)
    if configured:
        return Path(configured)
    size = SOURCE_TARBALL.stat().st_size if SOURCE_TARBALL.is_file() else 0
    key = hashlib.sha256(f"{SOURCE_TARBALL}\0{size}".encode()).hexdigest()[:12]
    return Path(tempfile.gettempdir()) / f"lensaudit-liblensfun-{key}"


def missing_prerequisite() -> str | None:
    """Why liblensfun cannot be built here, or None when everything it needs is present."""
    if not SOURCE_TARBALL.is_file():
        return f"no Lensfun master source at {SOURCE_TARBALL} (../shared/data beside the repo)"
    if not BUILD_SCRIPT.is_file():
        return f"no liblensfun build script at {BUILD_SCRIPT}"
    if shutil.which("cmake") is None:
        return "cmake is not installed (apt-get install -y cmake)"
    compilers = [os.environ.get("CXX", ""), "c++", "g++", "clang++"]
    if not any(name and shutil.which(name) for name in compilers):
        return "no C++ compiler (apt-get install -y g++)"
    if not _glib_headers_present():
        return "GLib's headers are not installed (apt-get install -y libglib2.0-dev)"
    return None


def _glib_headers_present() -> bool:
    if shutil.which("pkg-config"):
        found = subprocess.run(
            ["pkg-config", "--exists", "glib-2.0"], capture_output=True, check=False
        )
        if found.returncode == 0:
            return True
    return any(Path(base, "glib-2.0", "glib.h").is_file() for base in GLIB_INCLUDE_DIRS)


def library() -> ctypes.CDLL:
    """liblensfun of Lensfun master, built if need be and loaded; skips the test otherwise.

    The first call of a process builds (or finds built) and loads it; later calls return
    the same library, or skip for the same reason.
    """
    global _library, _skip_reason
    if _library is None and _skip_reason is None:
        try:
            _library = _declare(ctypes.CDLL(str(_build())))
        except _Unavailable as reason:
            _skip_reason = str(reason)
        except OSError as error:
            _skip_reason = f"cannot load the liblensfun built from {SOURCE_TARBALL.name}: {error}"
    if _library is None:
        pytest.skip(_skip_reason)
    return _library


class _Unavailable(Exception):
    """liblensfun cannot be built here; the message says why."""


def _build() -> Path:
    reason = missing_prerequisite()
    if reason:
        raise _Unavailable(reason)
    directory = build_directory()
    try:
        directory.parent.mkdir(parents=True, exist_ok=True)
        with open(f"{directory}.lock", "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # one build at a time, e.g. under pytest-xdist
            built = subprocess.run(
                ["bash", str(BUILD_SCRIPT), str(directory)],
                capture_output=True,
                text=True,
                timeout=900,
                check=False,
            )
    except (OSError, subprocess.TimeoutExpired) as error:
        raise _Unavailable(f"cannot build liblensfun in {directory}: {error}") from error
    path = Path(built.stdout.strip().splitlines()[-1]) if built.stdout.strip() else None
    if built.returncode != 0 or path is None or not path.is_file():
        detail = (built.stderr.strip() or built.stdout.strip())[-500:]
        raise _Unavailable(f"building liblensfun in {directory} failed: {detail}")
    return path


def _declare(lib: ctypes.CDLL) -> ctypes.CDLL:
    """Set the argument and result types of the functions used here."""
    vp, c_float = ctypes.c_void_p, ctypes.c_float
    lib.lf_db_create.argtypes, lib.lf_db_create.restype = [], vp
    lib.lf_db_destroy.argtypes, lib.lf_db_destroy.restype = [vp], None
    lib.lf_db_load_str.argtypes = [vp, ctypes.c_char_p, ctypes.c_size_t]
    lib.lf_db_load_str.restype = ctypes.c_int
    lib.lf_db_get_lenses.argtypes = [vp]
    lib.lf_db_get_lenses.restype = ctypes.POINTER(ctypes.POINTER(Lens))
    lib.lf_lens_get_mount_names.argtypes = [ctypes.POINTER(Lens)]
    lib.lf_lens_get_mount_names.restype = ctypes.POINTER(ctypes.c_char_p)
    lib.lf_lens_interpolate_distortion.argtypes = [
        ctypes.POINTER(Lens),
        c_float,
        c_float,
        ctypes.POINTER(CalibDistortion),
    ]
    lib.lf_lens_interpolate_distortion.restype = ctypes.c_int
    if hasattr(lib, GET_CALIBRATION_SETS):
        sets = getattr(lib, GET_CALIBRATION_SETS)
        sets.argtypes = [ctypes.POINTER(Lens)]
        sets.restype = ctypes.POINTER(ctypes.POINTER(CalibAttributes))
    return lib


def error_name(code: int) -> str:
    """The name of an lfError code: "" for LF_NO_ERROR, "-ENOENT" for -errno codes."""
    if code < 0:
        return "-" + errno.errorcode.get(-code, str(-code))
    return ERROR_NAMES.get(code, f"lfError {code}")


@contextmanager
def _stderr_captured() -> Iterator[list[str]]:
    """Collect what is written to file descriptor 2 (GLib's warnings) into the yielded list."""
    sys.stderr.flush()
    saved = os.dup(2)
    collected: list[str] = []
    with tempfile.TemporaryFile() as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield collected
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            collected.append(sink.read().decode("utf-8", "replace"))


@contextmanager
def _database(data: bytes, name: str) -> Iterator[tuple[int, LoadResult]]:
    """A fresh lfDatabase holding ``data`` (destroyed on exit), and how its load went."""
    lib = library()
    db = lib.lf_db_create()
    if not db:
        raise MemoryError("lf_db_create returned NULL")
    try:
        with _stderr_captured() as stderr:
            code = lib.lf_db_load_str(db, data, len(data))
        yield db, LoadResult(code == 0, error_name(code), _warnings("".join(stderr), name))
    finally:
        lib.lf_db_destroy(db)


def _warnings(stderr: str, name: str) -> str:
    """liblensfun's messages in GLib's warnings, one a line, naming the file ``name``."""
    messages = []
    for line in stderr.splitlines():
        if "[Lensfun] " in line:
            line = line.split("[Lensfun] ", 1)[1]
            # liblensfun names data loaded from memory "MEMORY".
            if line.startswith("MEMORY:"):
                line = name + line[len("MEMORY") :]
        if line.strip():
            messages.append(line.strip())
    return "\n".join(messages)


def load_result(data: bytes, name: str = "test.xml") -> LoadResult:
    """Whether liblensfun loads one file's content, its error code's name and its warnings.

    ``name`` stands for the file in the warnings (liblensfun's "file:line:column: message").
    """
    with _database(data, name) as (_, result):
        return result


def load_verdict(data: bytes, name: str = "test.xml") -> tuple[bool, str]:
    """Whether liblensfun loads one file's content, and its error code's name ("" if it does)."""
    result = load_result(data, name)
    return result.ok, result.error


def _mlstr(address: int | None) -> tuple[str | None, dict[str, str]]:
    """An lfMLstr ("default\\0lang\\0text\\0...\\0\\0"): its default string and translations."""
    if not address:
        return None, {}
    parts: list[str] = []
    offset = 0
    while True:
        raw = ctypes.string_at(address + offset)
        if parts and not raw:  # an empty string where a language would start: the end
            break
        parts.append(raw.decode("utf-8", "replace"))
        offset += len(raw) + 1
    default, rest = parts[0], parts[1:]
    return default, dict(zip(rest[0::2], rest[1::2], strict=True))


def _null_terminated(array) -> Iterator:
    """The items of a NULL-terminated C array of pointers (none for a NULL array)."""
    if not array:
        return
    index = 0
    while array[index]:
        yield array[index]
        index += 1


def _distortion(calibration: CalibDistortion) -> dict:
    return {
        "model": _model_name(calibration.Model),
        "focal": float(calibration.Focal),
        "real_focal": float(calibration.RealFocal),
        "real_focal_measured": bool(calibration.RealFocalMeasured),
        "terms": tuple(float(term) for term in calibration.Terms),
        "crop_factor": float(calibration.CalibAttr.CropFactor),
        "aspect_ratio": float(calibration.CalibAttr.AspectRatio),
    }


def _model_name(model: int) -> str:
    return DISTORTION_MODELS[model] if 0 <= model < len(DISTORTION_MODELS) else str(model)


def _lens(lib: ctypes.CDLL, pointer, source: LensSource) -> dict:
    lens = pointer.contents
    maker, maker_translations = _mlstr(lens.Maker)
    model, model_translations = _mlstr(lens.Model)
    mounts = lib.lf_lens_get_mount_names(pointer)
    calibration_sets = None
    if hasattr(lib, GET_CALIBRATION_SETS):
        sets = getattr(lib, GET_CALIBRATION_SETS)(pointer)
        calibration_sets = [
            (float(s.contents.CropFactor), float(s.contents.AspectRatio))
            for s in _null_terminated(sets)
        ]
    return {
        "maker": maker,
        "maker_translations": maker_translations,
        "model": model,
        "model_translations": model_translations,
        "mounts": [m.decode("utf-8", "replace") for m in _null_terminated(mounts)],
        "crop_factor": float(lens.CropFactor),
        "aspect_ratio": float(lens.AspectRatio),
        "type": LENS_TYPES[lens.Type] if 0 <= lens.Type < len(LENS_TYPES) else str(lens.Type),
        "focal": (float(lens.MinFocal), float(lens.MaxFocal)),
        "aperture": (float(lens.MinAperture), float(lens.MaxAperture)),
        "center": (float(lens.CenterX), float(lens.CenterY)),
        # (crop factor, aspect ratio) of each calibration set; None without the C++ symbol.
        "calibration_sets": calibration_sets,
        "distortion": [_distortion(c.contents) for c in _null_terminated(lens.CalibDistortion)],
        "source": source,
    }


def lenses(data: bytes) -> list[dict]:
    """Every lens liblensfun holds after loading one file, in its order.

    Each is a dict: ``maker`` and ``model`` (default strings) with their
    ``*_translations`` by language, ``mounts``, ``crop_factor``, ``aspect_ratio``,
    ``type`` (XML spelling), ``focal`` and ``aperture`` ((min, max), possibly
    guessed by liblensfun from the model name), ``center`` ((x, y)),
    ``calibration_sets`` ((crop factor, aspect ratio) of each), ``distortion``
    (dicts: ``model``, ``focal``, ``real_focal``, ``real_focal_measured``, ``terms``
    (five floats), ``crop_factor`` and ``aspect_ratio`` of its <calibration>) and
    ``source`` (a :class:`LensSource`, for :func:`interpolate_distortion`).

    Raises :class:`LoadError` when liblensfun does not load the file.
    """
    with _database(data, "test.xml") as (db, result):
        if not result.ok:
            raise LoadError(f"liblensfun does not load this file: {result.error} {result.warnings}")
        lib = library()
        return [
            _lens(lib, pointer, LensSource(data, index))
            for index, pointer in enumerate(_null_terminated(lib.lf_db_get_lenses(db)))
        ]


def interpolate_distortion(
    lens: dict, crop: float, focal: float
) -> tuple[str, tuple[float, ...]] | None:
    """liblensfun's distortion (model, five terms) of a lens of :func:`lenses` at a focal length.

    ``crop`` is the image's crop factor: liblensfun takes the calibration set whose
    crop factor is closest at or below ``crop`` / 0.96. None where liblensfun has no
    distortion for it.
    """
    source: LensSource = lens["source"]
    with _database(source.data, "test.xml") as (db, result):
        if not result.ok:
            raise LoadError(f"liblensfun does not load this file: {result.error}")
        lib = library()
        pointer = list(_null_terminated(lib.lf_db_get_lenses(db)))[source.index]
        found = CalibDistortion()
        if not lib.lf_lens_interpolate_distortion(pointer, crop, focal, ctypes.byref(found)):
            return None
        return _model_name(found.Model), tuple(float(term) for term in found.Terms)
