"""Lensfun master's image modifier, called through ctypes: what liblensfun does to pixels.

Builds on :mod:`liblensfun_master` (its :func:`~liblensfun_master.library`, which
skips a test with the reason when the library cannot be built). Declared here,
as include/lensfun/lensfun.h.in declares them: ``lf_modifier_create``,
``lf_modifier_enable_distortion_correction``, ``lf_modifier_apply_geometry_distortion``
and ``lf_modifier_destroy``.

- :func:`single_lens_database` -- XML for one lens per distortion entry, named by
  its position, so that liblensfun's lens of each entry is found by name;
- :func:`loaded` -- the lenses liblensfun holds after loading such XML, by name;
- :func:`reverse_distortion` -- liblensfun's reverse transform (an undistorted
  image made to look as if shot with the lens: the Newton inversion of
  libs/lensfun/mod-coord.cpp) applied to points, each point on its own, so that
  the scalar code runs and not the SSE one;
- :func:`reverse_row` -- the same for a run of points one pixel apart along x,
  in one call, on a buffer that is not 16-byte aligned (the scalar code again).
"""

from __future__ import annotations

import ctypes
import math
from collections.abc import Iterator
from contextlib import contextmanager
from xml.sax.saxutils import escape, quoteattr

import numpy as np

from liblensfun_master import Lens, _null_terminated, library

#: lfPixelFormat LF_PF_F32 (the pixel format plays no part in geometry).
PIXEL_FORMAT_F32 = 3
#: lfModifyFlags LF_MODIFY_DISTORTION.
MODIFY_DISTORTION = 0x00000008

_declared: set[int] = set()


def _lib() -> ctypes.CDLL:
    lib = library()
    if id(lib) not in _declared:
        vp, lens = ctypes.c_void_p, ctypes.POINTER(Lens)
        lib.lf_modifier_create.argtypes = [
            lens, ctypes.c_float, ctypes.c_float, ctypes.c_int, ctypes.c_int,
            ctypes.c_int, ctypes.c_bool,
        ]  # fmt: skip
        lib.lf_modifier_create.restype = vp
        lib.lf_modifier_destroy.argtypes, lib.lf_modifier_destroy.restype = [vp], None
        lib.lf_modifier_enable_distortion_correction.argtypes = [vp]
        lib.lf_modifier_enable_distortion_correction.restype = ctypes.c_int
        lib.lf_modifier_apply_geometry_distortion.argtypes = [
            vp, ctypes.c_float, ctypes.c_float, ctypes.c_int, ctypes.c_int, vp,
        ]  # fmt: skip
        lib.lf_modifier_apply_geometry_distortion.restype = ctypes.c_int
        lib.lf_db_get_lenses.restype = ctypes.POINTER(ctypes.POINTER(Lens))
        _declared.add(id(lib))
    return lib


def single_lens_database(entries) -> bytes:
    """A database with one lens per entry (``lensaudit.read`` entries), lens i
    named "entry i", holding that entry's model, focal, real focal, crop
    factor, aspect ratio and type, written as shortest round-trip decimals."""
    parts = ['<lensdatabase version="2">']
    for index, e in enumerate(entries):
        coefficients = {"ptlens": ("a", "b", "c"), "poly3": ("k1",), "poly5": ("k1", "k2")}
        attributes = {"model": e.model, "focal": repr(e.focal)}
        if e.real_focal == e.real_focal:
            attributes["real-focal"] = repr(e.real_focal)
        for name in coefficients[e.model]:
            value = getattr(e, name)
            attributes[name] = repr(value if value == value else 0.0)
        text = " ".join(f"{k}={quoteattr(v)}" for k, v in attributes.items())
        parts.append(
            f"<lens><maker>test</maker><model>entry {index}</model><mount>M</mount>"
            f"<type>{escape(e.type)}</type><cropfactor>{e.crop_factor!r}</cropfactor>"
            f"<aspect-ratio>{e.aspect_ratio!r}</aspect-ratio>"
            f"<calibration><distortion {text}/></calibration></lens>"
        )
    parts.append("</lensdatabase>")
    return "\n".join(parts).encode()


@contextmanager
def loaded(data: bytes) -> Iterator[dict[str, object]]:
    """The lenses liblensfun holds after loading ``data``, by model name, valid
    inside the block (the database is destroyed after it)."""
    lib = _lib()
    db = lib.lf_db_create()
    try:
        code = lib.lf_db_load_str(db, data, len(data))
        assert code == 0, f"liblensfun does not load the XML: error {code}"
        held = {}
        for pointer in _null_terminated(lib.lf_db_get_lenses(db)):
            name = ctypes.string_at(pointer.contents.Model).decode()
            held[name] = pointer
        yield held
    finally:
        lib.lf_db_destroy(db)


@contextmanager
def _modifier(lens, focal: float, crop: float, width: int, height: int) -> Iterator[int]:
    lib = _lib()
    modifier = lib.lf_modifier_create(lens, focal, crop, width, height, PIXEL_FORMAT_F32, True)
    try:
        flags = lib.lf_modifier_enable_distortion_correction(modifier)
        yield modifier if flags & MODIFY_DISTORTION else 0
    finally:
        lib.lf_modifier_destroy(modifier)


def reverse_distortion(
    lens, focal: float, crop: float, width: int, height: int, points: np.ndarray
) -> np.ndarray | None:
    """Where liblensfun's reverse transform of a ``width`` x ``height`` image
    looks up each point (pixel coordinates, (n, 2)), one call per point; None
    when liblensfun enables no distortion for the lens."""
    lib = _lib()
    out = np.empty_like(np.asarray(points, dtype=np.float64))
    result = (ctypes.c_float * 2)()
    with _modifier(lens, focal, crop, width, height) as modifier:
        if not modifier:
            return None
        for index, (x, y) in enumerate(np.asarray(points, dtype=np.float64).tolist()):
            lib.lf_modifier_apply_geometry_distortion(modifier, x, y, 1, 1, result)
            out[index] = result[0], result[1]
    return out


def reverse_row(
    lens, focal: float, crop: float, width: int, height: int, x: float, y: float, count: int
) -> np.ndarray | None:
    """liblensfun's reverse transform of ``count`` points (x + i, y), i = 0..count-1
    (pixel coordinates; they may run past the image's edge), in one call; (count, 2),
    or None when liblensfun enables no distortion for the lens."""
    lib = _lib()
    # 4 bytes past a 16-byte boundary: liblensfun's SSE code takes aligned buffers only.
    raw = (ctypes.c_float * (2 * count + 8))()
    offset = (16 - ctypes.addressof(raw) % 16) % 16 + 4
    address = ctypes.addressof(raw) + offset
    with _modifier(lens, focal, crop, width, height) as modifier:
        if not modifier:
            return None
        lib.lf_modifier_apply_geometry_distortion(modifier, x, y, count, 1, address)
        values = (ctypes.c_float * (2 * count)).from_address(address)
        return np.array(values, dtype=np.float64).reshape(count, 2)


def centre(width: int, height: int) -> tuple[float, float]:
    """The image centre liblensfun uses (a lens centred on the frame), in pixel coordinates."""
    return (width - 1) / 2, (height - 1) / 2


def half_diagonal(width: int, height: int) -> float:
    """Distance from the centre to the corner pixel's centre, in pixels."""
    return math.hypot(width - 1, height - 1) / 2
