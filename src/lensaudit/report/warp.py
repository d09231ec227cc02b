"""Undistort a synthetic coloured checkerboard with one model (paper Figure 6).

The input (distorted) image is a ``width`` x ``height`` checkerboard whose
colour encodes position, so that content repeated by a fold shows where it
came from. Each pixel of the undistorted output takes the colour of the
input at the source position the model gives it; ``scale`` < 1 zooms out
(liblensfun's Modifier scale) so that the output reaches past r_max.

When :mod:`lensaudit.projection` is available, the lens is placed on the
image exactly as liblensfun places it (its undistortion map and valid-region
mask). Otherwise the output is computed here in Hugin units of the
calibration image (r = 1 is half its short side): an output point p reads
the input at p * D(|p|) / |p|, and the valid region is |p| < r_max.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .curves import distortion_coefficients

if TYPE_CHECKING:
    from ..read.records import DistortionEntry

#: Squares along the short side of the input image.
SQUARES = 12
BACKGROUND = (48, 48, 48)

GEOMETRY_LIBLENSFUN = "lens placed on the image as liblensfun does (lensaudit.projection)"
GEOMETRY_HUGIN = "Hugin units of the calibration image"


def checkerboard(
    x: ArrayLike, y: ArrayLike, half_width: float, half_height: float = 1.0, squares: int = SQUARES
) -> NDArray[np.uint8]:
    """RGB colours (uint8, shape (..., 3)) of the test pattern at (x, y), y up.

    The image spans [-half_width, half_width] x [-half_height, half_height];
    squares are 2 / ``squares`` wide. Red grows to the right, blue upwards;
    light and dark squares alternate. Outside the image: :data:`BACKGROUND`.
    """
    x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    inside = (np.abs(x) <= half_width) & (np.abs(y) <= half_height)
    size = 2.0 / squares
    with np.errstate(invalid="ignore"):
        parity = (np.floor((x + half_width) / size) + np.floor((y + half_height) / size)) % 2
        red = np.clip((x + half_width) / (2 * half_width), 0, 1)
        blue = np.clip((y + half_height) / (2 * half_height), 0, 1)
    green = np.full_like(red, 0.55)
    colour = np.stack([0.15 + 0.85 * red, green, 0.15 + 0.85 * blue], axis=-1)
    colour = np.where((parity == 0)[..., None], colour, colour * 0.3)
    rgb = np.round(np.nan_to_num(colour) * 255).astype(np.uint8)
    rgb[~inside] = BACKGROUND
    return rgb


def image_frame(width: int, height: int) -> tuple[float, float, float]:
    """(pixels per unit, half width, half height) of a pixel image in its own Hugin units.

    As liblensfun measures an image: between the centres of its border pixels,
    one unit being half the short side.
    """
    unit = (min(width, height) - 1) / 2
    return unit, (width - 1) / 2 / unit, (height - 1) / 2 / unit


def input_image(width: int, height: int) -> NDArray[np.uint8]:
    """The checkerboard itself: the distorted input image, ``width`` x ``height`` pixels."""
    unit, half_width, half_height = image_frame(width, height)
    x = (np.arange(width) - (width - 1) / 2) / unit
    y = ((height - 1) / 2 - np.arange(height)) / unit
    return checkerboard(x[np.newaxis, :], y[:, np.newaxis], half_width, half_height)


def source_positions(
    distortion: ArrayLike, x: ArrayLike, y: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Where undistorted points (x, y) are read from: (x, y) * D(r) / r, Hugin units.

    ``distortion`` holds the coefficients of D, highest power first. At r = 0
    the factor is its limit D'(0). Where D(r) < 0 the source lies on the
    opposite side of the centre.
    """
    coefficients = np.asarray(distortion, dtype=np.float64).reshape(-1)
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    radius = np.hypot(x, y)
    distorted = np.polyval(coefficients, radius)
    slope0 = np.polyval(np.polyder(coefficients), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        factor = np.where(radius > 0, distorted / np.where(radius > 0, radius, 1.0), slope0)
    return x * factor, y * factor


@dataclass(frozen=True)
class Warp:
    """An undistorted checkerboard: pixels, valid region and the r_max circle.

    ``centre`` is the centre of distortion in output pixels (x right, y
    down), ``r_max_pixels`` the radius of the valid circle there (inf: the
    model never folds), ``valid`` True where the output is read from inside
    the valid domain.
    """

    image: NDArray[np.uint8]
    valid: NDArray[np.bool_]
    centre: tuple[float, float]
    r_max_pixels: float
    scale: float
    geometry: str


def default_scale(r_max_pixels: float, width: int, height: int) -> float:
    """A zoom-out that puts the r_max circle at 2/3 of the output's half diagonal.

    ``r_max_pixels`` is r_max at scale 1. Between 1/6 and 1/1.3, so that the
    whole image and some of its surroundings are always in view.
    """
    half_diagonal = math.hypot((width - 1) / 2, (height - 1) / 2)
    if not (math.isfinite(r_max_pixels) and r_max_pixels > 0):
        return 1 / 1.5
    return min(max(half_diagonal / (1.5 * r_max_pixels), 1 / 6), 1 / 1.3)


def hugin_warp(
    distortion: ArrayLike,
    aspect: float,
    r_max: float,
    width: int,
    height: int,
    scale: float | None = None,
) -> Warp:
    """The warp in Hugin units of the calibration image (no liblensfun placement).

    The output shows the ``width`` x ``height`` input image, of aspect
    ``aspect`` (long / short side), zoomed out by ``scale``.
    """
    if width < 2 or height < 2:
        raise ValueError("the output needs at least 2 x 2 pixels")
    aspect = max(aspect, 1.0 / aspect)
    half_width, half_height = (aspect, 1.0) if width >= height else (1.0, aspect)
    # Fit the calibration image into the output, as liblensfun fits sensors: by diagonals.
    pixels_per_unit = math.hypot((width - 1) / 2, (height - 1) / 2) / math.hypot(aspect, 1.0)
    if scale is None:
        scale = default_scale(r_max * pixels_per_unit, width, height)
    x = (np.arange(width) - (width - 1) / 2) / (pixels_per_unit * scale)
    y = ((height - 1) / 2 - np.arange(height)) / (pixels_per_unit * scale)
    x, y = np.meshgrid(x, y)
    source_x, source_y = source_positions(distortion, x, y)
    image = checkerboard(source_x, source_y, half_width, half_height)
    return Warp(
        image,
        np.hypot(x, y) < r_max,
        ((width - 1) / 2, (height - 1) / 2),
        r_max * pixels_per_unit * scale,
        scale,
        GEOMETRY_HUGIN,
    )


def lensfun_warp(
    entry: DistortionEntry, width: int, height: int, scale: float | None = None
) -> Warp:
    """The warp of liblensfun's undistortion map for the entry on a ``width`` x ``height``
    image (camera crop factor = the calibration's), from :mod:`lensaudit.projection`."""
    # optional: lensaudit.projection may be absent (see projection_available)
    from .. import projection

    camera = projection.lensfun_camera(entry, width, height)
    if scale is None:
        scale = default_scale(camera.r_max_pixels(1.0), width, height)
    source = projection.undistortion_map(width, height, camera, scale=scale)
    valid = projection.valid_region_mask(width, height, camera, scale=scale)
    unit, half_width, half_height = image_frame(width, height)
    source_x = (source[..., 0] - (width - 1) / 2) / unit
    source_y = ((height - 1) / 2 - source[..., 1]) / unit
    image = checkerboard(source_x, source_y, half_width, half_height)
    return Warp(
        image,
        valid,
        ((width - 1) / 2, (height - 1) / 2),
        float(camera.r_max_pixels(scale)),
        scale,
        GEOMETRY_LIBLENSFUN,
    )


def projection_available() -> bool:
    """Whether :mod:`lensaudit.projection` offers what :func:`lensfun_warp` uses."""
    try:  # optional: lensaudit.projection may be absent
        from .. import projection
    except ImportError:
        return False
    return all(
        hasattr(projection, name)
        for name in ("lensfun_camera", "undistortion_map", "valid_region_mask")
    )


def warp_entry(
    entry: DistortionEntry, r_max: float, width: int, height: int, scale: float | None = None
) -> Warp:
    """The warp of an audited entry: liblensfun's placement when available, else Hugin units.

    ``r_max`` is the entry's, in Hugin units (used without liblensfun placement).
    """
    if projection_available():
        return lensfun_warp(entry, width, height, scale)
    return hugin_warp(
        distortion_coefficients(entry), entry.aspect_ratio, r_max, width, height, scale
    )
