"""Project 3D points through a distortion model, keeping only those inside its valid domain.

Beyond r_max a polynomial distortion folds back: a scene point far outside
the field of view lands inside the image as if it were in view. This module
is the filter for that: :func:`project` maps camera-frame points to pixels
and says which of them the model can be trusted for, and
:func:`valid_region_mask` says which pixels of an undistorted image (the
output of liblensfun's ``Modifier``) are read from inside the valid domain.

Two kinds of model make a :class:`RadialCamera`:

* a Lensfun calibration (:func:`lensfun_camera`, from a
  :class:`~lensaudit.read.records.DistortionEntry` or raw coefficients), placed on
  an image exactly as liblensfun 0.3.x does it (see below);
* OpenCV's Brown-Conrady model (:func:`opencv_camera`): a camera matrix and
  the radial coefficients k1, k2, k3. The tangential coefficients p1, p2 are
  ignored: the valid domain is a property of the radial part, and the pixels
  returned here are those of ``cv2.projectPoints`` with p1 = p2 = 0.

Pinhole units are x/z and y/z. A camera's ``r_max`` is the largest valid
undistorted radius in those units (``inf`` when the model never folds).

liblensfun's conventions, as measured through lensfunpy's ``Modifier``
(agreement to about 1e-3 px, see tests/test_projection.py):

* The image centre is pixel ((W - 1) / 2, (H - 1) / 2), and one Hugin unit of
  the image is (min(W, H) - 1) / 2 pixels: liblensfun measures the image
  between the centres of its border pixels, also for its aspect ratio
  (max(W, H) - 1) / (min(W, H) - 1).
* A Hugin unit of the calibration sensor is ``cc`` units of the image, with
  cc = (calibration crop / camera crop) * hypot(calibration aspect, 1) /
  hypot(image aspect, 1): the two sensors are matched along their diagonals.
* The distortion acts on Hugin units of the calibration sensor. An
  undistorted radius r there is r * h / f_g in pinhole units, where
  h = hypot(36, 24) / (2 * crop * hypot(aspect, 1)) mm is half the short side
  of the calibration sensor and f_g = real_focal / d is liblensfun's geometry
  focal length (d = 1 - a - b - c for ptlens, 1 - k1 for poly3, 1 for poly5).
  Without a real focal length in the database, liblensfun takes
  real_focal = focal * d (Hugin's focal-length convention), so f_g is the
  nominal focal length itself.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import metrics, normalizer
from .metrics import HALF_DIAGONAL_MM
from .read.records import MODEL_COEFFICIENTS, STATUS_OK, DistortionEntry

# Exact arithmetic is imported where it is needed: only models near 1e308 take that path.
if TYPE_CHECKING:
    from fractions import Fraction

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Lens types whose undistorted image is a pinhole (x/z, y/z) projection.
PINHOLE_TYPES = frozenset({"rectilinear"})

#: Points are projected in blocks of this many, so that the temporaries stay in cache.
BLOCK = 1 << 14

#: Between these, r**2 = x**2 + y**2 neither overflows nor loses digits to underflow;
#: a camera whose r_max**2 is outside them has its r_max compared with the radius itself.
_SQUARES_SMALL = 2.0**-1000
_SQUARES_LARGE = 2.0**1000


class ProjectionError(ValueError):
    """A model, image or entry that cannot be projected; the message says why."""


@dataclass(frozen=True)
class LensfunCalibration:
    """One Lensfun distortion calibration and the sensor it was made on.

    ``model`` is "ptlens" (a, b, c), "poly3" (k1) or "poly5" (k1, k2); unused
    coefficients are ignored. ``focal`` and ``real_focal`` are in millimetres
    (``real_focal`` NaN when the database gives none); ``crop_factor`` and
    ``aspect_ratio`` are those of the calibration sensor.
    """

    model: str
    focal: float
    a: float = 0.0
    b: float = 0.0
    c: float = 0.0
    k1: float = 0.0
    k2: float = 0.0
    crop_factor: float = 1.0
    aspect_ratio: float = 1.5
    real_focal: float = math.nan
    type: str = "rectilinear"

    def __post_init__(self) -> None:
        if self.model not in MODEL_COEFFICIENTS:
            raise ProjectionError(f"model {self.model!r} is not one of ptlens, poly3, poly5")
        for name in MODEL_COEFFICIENTS[self.model]:
            if not math.isfinite(getattr(self, name)):
                raise ProjectionError(f"{self.model} coefficient {name} is not a finite number")
        for name in ("focal", "crop_factor", "aspect_ratio"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ProjectionError(f"{name.replace('_', ' ')} {value:g} is not positive")
        if not (
            math.isnan(self.real_focal) or (math.isfinite(self.real_focal) and self.real_focal > 0)
        ):
            raise ProjectionError(f"real focal {self.real_focal:g} is not positive")

    @classmethod
    def from_entry(
        cls, entry: DistortionEntry, real_focal: float | None = None
    ) -> LensfunCalibration:
        """The calibration of a loaded entry; ``real_focal`` overrides the entry's."""
        if entry.status != STATUS_OK:
            raise ProjectionError(
                f"{entry.file}:{entry.line}: entry is not usable ({entry.status}: {entry.message})"
            )
        coefficients = {name: getattr(entry, name) for name in MODEL_COEFFICIENTS[entry.model]}
        return cls(
            entry.model,
            entry.focal,
            crop_factor=entry.crop_factor,
            aspect_ratio=entry.aspect_ratio,
            real_focal=entry.real_focal if real_focal is None else real_focal,
            type=entry.type,
            **coefficients,
        )

    def cubic(self) -> normalizer.Cubic:
        """The model in the normalizer's form (D(r) in Hugin units).

        Coefficients near 1e308 overflow the cubic to +-inf; :attr:`r_max_hugin`
        then takes the model's exact coefficients instead.
        """
        with np.errstate(over="ignore", invalid="ignore"):
            if self.model == "ptlens":
                return normalizer.ptlens(self.a, self.b, self.c)
            if self.model == "poly3":
                return normalizer.poly3(self.k1)
            return normalizer.poly5(self.k1, self.k2)

    def exact_distortion(self) -> list[Fraction]:
        """D(r)'s coefficients, highest power first, in exact arithmetic."""
        return metrics.exact_distortion(self.model, self.a, self.b, self.c, self.k1, self.k2)

    @property
    def hugin_correction(self) -> float:
        """d = D'(0): 1 - a - b - c (ptlens), 1 - k1 (poly3), 1 (poly5)."""
        return float(self.cubic().slope_at_centre)

    @property
    def half_short_side_mm(self) -> float:
        """h: half the short side of the calibration sensor, in millimetres."""
        return HALF_DIAGONAL_MM / (self.crop_factor * math.hypot(self.aspect_ratio, 1.0))

    @property
    def geometry_focal(self) -> float:
        """liblensfun's focal length for pinhole geometry, in mm: real_focal / d, or focal."""
        if math.isnan(self.real_focal):
            return self.focal
        d = self.hugin_correction
        return self.real_focal / d if d != 0 else math.inf

    @property
    def hugin_per_pinhole(self) -> float:
        """Hugin units of the calibration sensor per pinhole unit: f_g / h."""
        half_short_side = self.half_short_side_mm
        return self.geometry_focal / half_short_side if half_short_side > 0 else math.inf

    @property
    def r_max_hugin(self) -> float:
        """r_max in Hugin units of the calibration sensor (0: no valid domain; inf: none needed)."""
        return _domain(self.cubic(), self.exact_distortion)[0]


@dataclass(frozen=True)
class RadialCamera:
    """A pinhole camera with a radial distortion and the domain where it is valid.

    A point (X, Y, Z) has pinhole coordinates x = X/Z, y = Y/Z, radius r; its
    pixel is (cx + fx x F(r), cy + fy y F(r)), with F(r) = sum of
    ``distortion[j] * w**j``, w = r**power (power 1 or 2). ``r_max`` and
    ``d_max = r_max F(r_max)`` are in pinhole units. ``width`` and ``height``
    are the image size in pixels when known. An r_max whose square is beyond
    the float range (above about 1e154, a model near no distortion) is inf.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, ...]
    power: int
    r_max: float
    d_max: float
    width: int | None = None
    height: int | None = None
    lens_type: str = "rectilinear"
    description: str = ""
    notes: tuple[str, ...] = field(default=(), compare=False)

    @property
    def max_angle_degrees(self) -> float:
        """The valid half field of view: atan(r_max), in degrees (90 when r_max is inf)."""
        return math.degrees(math.atan(self.r_max))

    def r_max_pixels(self, scale: float = 1.0) -> float:
        """r_max around (cx, cy) in pixels of an undistorted output at ``scale``.

        Along x; along y it is ``fy / fx`` times this (equal for Lensfun
        cameras, whose pixels are square). ``scale`` as liblensfun's Modifier:
        below 1 the output shows more of the scene.
        """
        return self.r_max * self.fx * scale

    def project(
        self, points: ArrayLike, *, nan_for_invalid: bool = True
    ) -> tuple[FloatArray, BoolArray]:
        """See :func:`project`."""
        return project(points, self, nan_for_invalid=nan_for_invalid)

    def valid_region_mask(
        self, width: int | None = None, height: int | None = None, scale: float = 1.0
    ) -> BoolArray:
        """See :func:`valid_region_mask`."""
        return valid_region_mask(width, height, self, scale=scale)

    def undistortion_map(
        self, width: int | None = None, height: int | None = None, scale: float = 1.0
    ) -> FloatArray:
        """See :func:`undistortion_map`."""
        return undistortion_map(width, height, self, scale=scale)


LensLike = DistortionEntry | LensfunCalibration | RadialCamera


def _domain(
    cubic: normalizer.Cubic, exact_distortion: Callable[[], list[Fraction]]
) -> tuple[float, float]:
    """(r_max, d_max) of one model, in the units of its D(r).

    In binary64, except where that may be wrong (see
    :func:`lensaudit.metrics.needs_exact`): there from the model's exact
    coefficients, as the metrics do.
    """
    with np.errstate(all="ignore"):
        r_max, d_max, _ = metrics.model_r_max(cubic)
        exact = bool(np.any(metrics.needs_exact(cubic, r_max, d_max)))
    if exact:
        return metrics.exact_model_r_max(exact_distortion(), cubic.power)[:2]
    return float(r_max), float(d_max)


def _exact(values: list[float]) -> list[Fraction]:
    from fractions import Fraction  # fractions: only for the exact path, rarely reached

    return [Fraction(x) for x in values]


def _polynomial_in_w(cubic: normalizer.Cubic) -> list[float]:
    """F(r) = D(r) / r as ascending coefficients in w = r**power."""
    descending = np.asarray(cubic.distortion, dtype=np.float64).reshape(-1)[:-1]
    return descending[:: -cubic.power].tolist()


def _check_size(width: int, height: int) -> tuple[int, int]:
    if isinstance(width, bool) or isinstance(height, bool):
        raise ProjectionError("image size must be two integers")
    try:
        w, h = int(width), int(height)
    except (TypeError, ValueError, OverflowError):  # OverflowError: int(inf)
        raise ProjectionError(f"image size {width}x{height} is not two integers") from None
    if w != width or h != height or w < 2 or h < 2:
        raise ProjectionError(f"image size {width}x{height}: need whole pixels, at least 2x2")
    return w, h


def lensfun_camera(
    lens: DistortionEntry | LensfunCalibration,
    width: int,
    height: int,
    crop_factor: float | None = None,
    *,
    real_focal: float | None = None,
) -> RadialCamera:
    """The camera of a Lensfun calibration on a ``width`` x ``height`` image.

    ``crop_factor`` is the camera's (default: the calibration's); pixels and
    r_max then follow liblensfun's placement (module docstring), so that
    :func:`undistortion_map` matches ``lensfunpy.Modifier`` for the same lens,
    crop factor and image size. ``real_focal`` (mm) overrides the entry's
    (which the reader takes from the ``real-focal`` attribute, else from the
    ``<real-focal-length>`` of its focal length). Raises :class:`ProjectionError` for an
    entry that is not usable or an image smaller than 2 x 2 pixels.
    """
    calibration = lens
    if isinstance(lens, DistortionEntry):
        calibration = LensfunCalibration.from_entry(lens, real_focal)
    elif real_focal is not None:
        calibration = replace(lens, real_focal=real_focal)
    width, height = _check_size(width, height)
    camera_crop = calibration.crop_factor if crop_factor is None else float(crop_factor)
    if not (math.isfinite(camera_crop) and camera_crop > 0):
        raise ProjectionError(f"crop factor {camera_crop:g} is not positive")
    if not calibration.half_short_side_mm > 0:
        raise ProjectionError(
            f"crop factor {calibration.crop_factor:g} with aspect ratio "
            f"{calibration.aspect_ratio:g}: a sensor too small for floats"
        )
    hugin_per_pinhole = calibration.hugin_per_pinhole
    if not (math.isfinite(hugin_per_pinhole) and hugin_per_pinhole > 0):
        raise ProjectionError(
            f"focal length {calibration.geometry_focal:g} mm (real focal / d) is not positive"
        )
    short, long = sorted((width - 1, height - 1))
    image_aspect = long / short
    correction = (
        calibration.crop_factor
        / camera_crop
        * math.hypot(calibration.aspect_ratio, 1.0)
        / math.hypot(image_aspect, 1.0)
    )
    pixels_per_hugin = short / 2 / correction
    cubic = calibration.cubic()
    r_max_hugin, d_max_hugin = _domain(cubic, calibration.exact_distortion)
    # F's coefficient of w**j in pinhole units: times hugin_per_pinhole**(power j),
    # which may overflow; a zero coefficient stays zero rather than 0 * inf.
    polynomial = _polynomial_in_w(cubic)
    with np.errstate(over="ignore", under="ignore"):
        scales = np.float64(hugin_per_pinhole) ** (cubic.power * np.arange(len(polynomial)))
        pairs = zip(polynomial, scales, strict=True)
        distortion = tuple(float(value * scale) if value else 0.0 for value, scale in pairs)
    focal_pixels = pixels_per_hugin * hugin_per_pinhole
    if not (math.isfinite(focal_pixels) and focal_pixels > 0):
        raise ProjectionError(
            f"focal length {calibration.geometry_focal:g} mm (real focal / d) on this image is "
            f"{focal_pixels:g} px: beyond what floats hold"
        )
    notes = ()
    if calibration.type not in PINHOLE_TYPES:
        notes = (f"{calibration.type} lens: project() needs a rectilinear one",)
    return RadialCamera(
        focal_pixels,
        focal_pixels,
        (width - 1) / 2,
        (height - 1) / 2,
        distortion,
        cubic.power,
        r_max_hugin / hugin_per_pinhole,
        d_max_hugin / hugin_per_pinhole,
        width,
        height,
        calibration.type,
        f"Lensfun {calibration.model} at {calibration.focal:g} mm, "
        f"calibration crop {calibration.crop_factor:g}, camera crop {camera_crop:g}",
        notes,
    )


def brown_conrady_camera(
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    k1: float = 0.0,
    k2: float = 0.0,
    k3: float = 0.0,
    width: int | None = None,
    height: int | None = None,
) -> RadialCamera:
    """OpenCV's radial model F(r) = 1 + k1 r^2 + k2 r^4 + k3 r^6 with focal and centre in pixels."""
    values = dict(fx=fx, fy=fy, cx=cx, cy=cy, k1=k1, k2=k2, k3=k3)
    for name, value in values.items():
        if not math.isfinite(float(value)):
            raise ProjectionError(f"{name} is not a finite number")
    if not (fx > 0 and fy > 0):
        raise ProjectionError("fx and fy must be positive")
    with np.errstate(over="ignore"):  # coefficients near 1e308: _domain's exact path
        cubic = normalizer.brown_conrady(k1, k2, k3)
    r_max, d_max = _domain(cubic, lambda: _exact(cubic.distortion.tolist()))
    if width is not None or height is not None:
        width, height = _check_size(width, height)
    return RadialCamera(
        float(fx),
        float(fy),
        float(cx),
        float(cy),
        tuple(_polynomial_in_w(cubic)),
        cubic.power,
        r_max,
        d_max,
        width,
        height,
        "rectilinear",
        f"Brown-Conrady k1={k1:g} k2={k2:g} k3={k3:g}",
    )


def opencv_camera(
    camera_matrix: ArrayLike,
    dist_coeffs: ArrayLike = (),
    width: int | None = None,
    height: int | None = None,
) -> RadialCamera:
    """The radial part of an OpenCV calibration: K (3 x 3) and (k1, k2, p1, p2[, k3]).

    p1 and p2 are ignored (noted in ``notes`` when nonzero); longer
    coefficient vectors (rational or thin-prism models) are refused unless
    their extra terms are zero. Skew in K is refused.
    """
    matrix = np.asarray(camera_matrix, dtype=np.float64)
    if matrix.shape != (3, 3):
        raise ProjectionError(f"camera matrix must be 3 x 3, not {matrix.shape}")
    if matrix[0, 1] != 0 or matrix[1, 0] != 0 or np.any(matrix[2] != (0, 0, 1)):
        raise ProjectionError("camera matrix must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]")
    coefficients = np.asarray(dist_coeffs, dtype=np.float64).reshape(-1)
    if coefficients.size not in (0, 4, 5, 8, 12, 14):
        raise ProjectionError(
            f"{coefficients.size} distortion coefficients: OpenCV takes 4, 5, 8, 12 or 14"
        )
    padded = np.zeros(14)
    padded[: coefficients.size] = coefficients
    if np.any(padded[5:] != 0):
        raise ProjectionError(
            "only k1, k2, k3 (and p1, p2, ignored) are supported; "
            "the rational and thin-prism terms must be zero"
        )
    k1, k2, p1, p2, k3 = padded[:5]
    camera = brown_conrady_camera(
        matrix[0, 0], matrix[1, 1], matrix[0, 2], matrix[1, 2], k1, k2, k3, width, height
    )
    if p1 != 0 or p2 != 0:
        camera = replace(camera, notes=(*camera.notes, f"tangential p1={p1:g} p2={p2:g} ignored"))
    return camera


def _as_camera(
    lens: LensLike, width: int | None, height: int | None, crop_factor: float | None
) -> RadialCamera:
    if isinstance(lens, RadialCamera):
        if crop_factor is not None:
            raise ProjectionError("crop_factor applies to a Lensfun entry, not to a camera")
        return lens
    if width is None or height is None:
        raise ProjectionError("a Lensfun entry needs the image width and height")
    return lensfun_camera(lens, width, height, crop_factor)


def project(
    points: ArrayLike, camera: RadialCamera, *, nan_for_invalid: bool = True
) -> tuple[FloatArray, BoolArray]:
    """Distort and project camera-frame points (N x 3, or one point) to pixels.

    Returns ``(pixels, valid)``: pixels N x 2 (u, v) and a boolean mask,
    False for points behind or on the camera plane (Z <= 0), at or beyond
    r_max, or not finite (also where X/Z or Y/Z exceeds the float range),
    or whose pixel is not finite (beyond the float range: |X/Z| about 1e150
    and more on a model that never folds, or a pixel that overflows on the
    way, 0 * inf); any other point is valid, subnormal coordinates included:
    a valid point always has a finite pixel. Pixels of invalid points are NaN; with
    ``nan_for_invalid=False`` they keep what the polynomial gives (the
    folded-back position), which is faster. Pixels are those of
    the image as the camera recorded it (distorted), in the camera's pixel
    convention (liblensfun's or OpenCV's). Raises :class:`ProjectionError`
    for a lens that is not rectilinear or points not shaped N x 3.
    """
    if camera.lens_type not in PINHOLE_TYPES:
        raise ProjectionError(
            f"{camera.lens_type} lens: project() needs a rectilinear one "
            "(the valid region of an undistorted image still applies)"
        )
    array = np.asarray(points, dtype=np.float64)
    single = array.ndim == 1
    if single:
        array = array[np.newaxis]
    if array.ndim != 2 or array.shape[1] != 3:
        raise ProjectionError(f"points must be N x 3 (x, y, z), not {np.shape(points)}")
    pixels = np.empty((array.shape[0], 2))
    valid = np.empty(array.shape[0], dtype=bool)
    _project_blocks(camera, array, pixels, valid, check=True, nan_for_invalid=nan_for_invalid)
    return (pixels[0], valid[0]) if single else (pixels, valid)


def _project_blocks(
    camera: RadialCamera,
    points: FloatArray,
    pixels: FloatArray,
    valid: BoolArray,
    check: bool,
    nan_for_invalid: bool = True,
) -> None:
    """The projection kernel, in place, block by block (``check`` False: no validity).

    Each block is first copied to contiguous (3, n) scratch: numpy's loops
    over the strided columns of an N x 3 array are several times slower.
    """
    count = points.shape[0]
    r_max_squared = camera.r_max * camera.r_max
    # Where r_max**2 is beyond the range in which x**2 + y**2 is exact to a rounding,
    # the few points on that side of it are compared by their radius instead.
    # Halved on the large side: the radius of a point whose x / z is near the
    # largest float is itself beyond it.
    if r_max_squared > _SQUARES_LARGE:
        suspect, bound, half = np.greater, _SQUARES_LARGE, 0.5
    elif r_max_squared < _SQUARES_SMALL:
        suspect, bound, half = np.less, _SQUARES_SMALL, 1.0
    else:
        suspect = None
    coefficients = _highest_first(camera)
    size = min(BLOCK, count)
    xyz = np.empty((3, size))
    w, f, scratch = (np.empty(size) for _ in range(3))
    invalid = np.empty(size, dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for start in range(0, count, BLOCK):
            stop = min(start + BLOCK, count)
            n = stop - start
            block_xyz = xyz[:, :n]
            np.copyto(block_xyz, points[start:stop].T)
            x, y, z = block_xyz
            wb, fb, sb, bad = w[:n], f[:n], scratch[:n], invalid[:n]
            # x / z, not x * (1 / z): 1 / z overflows for a subnormal z where x / z need not.
            x /= z
            y /= z
            np.multiply(x, x, out=wb)
            np.multiply(y, y, out=sb)
            wb += sb
            if check:
                good = valid[start:stop]
                np.less(wb, r_max_squared, out=good)
                if suspect is not None:
                    suspect(wb, bound, out=bad)
                    rows = np.flatnonzero(bad)
                    radius = np.hypot(x[rows] * half, y[rows] * half)
                    good[rows] = radius < camera.r_max * half
                np.greater(z, 0.0, out=bad)
                good &= bad
                # z = +inf is not a point, though x / z is a number there.
                np.less(z, math.inf, out=bad)
                good &= bad
            if camera.power == 1:
                np.sqrt(wb, out=wb)
            fb.fill(coefficients[0])
            for coefficient in coefficients[1:]:
                fb *= wb
                fb += coefficient
            if check and nan_for_invalid:
                # good / good is 1 where valid and 0/0 = NaN where not; a NaN factor
                # makes both coordinates NaN. Cheaper than any masked write.
                np.divide(good, good, out=sb)
                fb *= sb
            for coordinate, focal, centre, column in (
                (x, camera.fx, camera.cx, 0),
                (y, camera.fy, camera.cy, 1),
            ):
                coordinate *= fb
                coordinate *= focal
                coordinate += centre
                pixels[start:stop, column] = coordinate
            if check:
                # A pixel beyond the float range (or 0 * inf = NaN) is no position.
                _finite_pixels(pixels[start:stop], good, bad, nan_for_invalid)


def _finite_pixels(pixels: FloatArray, good: BoolArray, bad: BoolArray, nan: bool) -> None:
    """Points whose pixel is not finite made invalid (and their pixels NaN with ``nan``)."""
    np.isfinite(pixels[:, 0], out=bad)
    good &= bad
    np.isfinite(pixels[:, 1], out=bad)
    good &= bad
    if nan and not good.all():
        pixels[~good] = math.nan


def _highest_first(camera: RadialCamera) -> tuple[float, ...]:
    """F's coefficients for Horner, highest power first, without zero high powers.

    A zero coefficient of a high power would turn an overflowed w = inf into
    0 * inf = NaN where F itself is finite.
    """
    coefficients = camera.distortion[::-1]
    first = next((i for i, value in enumerate(coefficients) if value), len(coefficients) - 1)
    return coefficients[first:]


def valid_region_mask(
    width: int | None,
    height: int | None,
    lens: LensLike,
    *,
    crop_factor: float | None = None,
    scale: float = 1.0,
) -> BoolArray:
    """Which pixels of an undistorted output image are read from inside the valid domain.

    ``lens`` is a :class:`~lensaudit.read.records.DistortionEntry` or
    :class:`LensfunCalibration` (placed on the ``width`` x ``height`` image
    as liblensfun does, with the camera ``crop_factor``), or a
    :class:`RadialCamera` (its own centre and focal; width and height default
    to its image size). ``scale`` is liblensfun's Modifier scale: the output
    pixel p shows the undistorted point (p - c) / (f * scale). Returns a
    (height, width) boolean array, True strictly inside r_max.
    """
    camera = _as_camera(lens, width, height, crop_factor)
    width, height = _output_size(camera, width, height)
    x, y = _output_pinhole(camera, np.arange(width), np.arange(height), scale)
    with np.errstate(over="ignore"):  # far beyond any r_max: inf compares as it should
        return (x * x)[np.newaxis, :] + (y * y)[:, np.newaxis] < camera.r_max * camera.r_max


def undistortion_map(
    width: int | None,
    height: int | None,
    lens: LensLike,
    *,
    crop_factor: float | None = None,
    scale: float = 1.0,
) -> FloatArray:
    """For each pixel of an undistorted output, the source pixel it is read from.

    A (height, width, 2) float64 array of (x, y) source coordinates, the same
    layout as ``lensfunpy.Modifier.apply_geometry_distortion`` (arguments as
    :func:`valid_region_mask`). It is computed everywhere, also beyond r_max,
    where it folds back exactly as liblensfun's map does.
    """
    camera = _as_camera(lens, width, height, crop_factor)
    width, height = _output_size(camera, width, height)
    xs = np.broadcast_to(np.arange(width, dtype=np.float64), (height, width))
    ys = np.broadcast_to(np.arange(height, dtype=np.float64)[:, np.newaxis], (height, width))
    return source_pixels(camera, xs, ys, scale=scale)[0]


def source_pixels(
    lens: LensLike,
    xs: ArrayLike,
    ys: ArrayLike,
    width: int | None = None,
    height: int | None = None,
    *,
    crop_factor: float | None = None,
    scale: float = 1.0,
) -> tuple[FloatArray, BoolArray]:
    """Source pixels of output pixels (xs, ys) of an undistorted image, and their validity.

    The sparse form of :func:`undistortion_map` and :func:`valid_region_mask`
    (same arguments): xs and ys may be any (broadcastable) shape and need not
    be whole pixels. Returns ``(sources, valid)``, sources of shape
    (..., 2), valid True where the output pixel is strictly inside r_max.
    """
    camera = _as_camera(lens, width, height, crop_factor)
    x, y = _output_pinhole(camera, xs, ys, scale)
    x, y = np.broadcast_arrays(x, y)
    coefficients = _highest_first(camera)
    # Far beyond r_max the folded map overflows to +-inf or NaN, as liblensfun's would.
    with np.errstate(over="ignore", invalid="ignore"):
        w = x * x + y * y
        valid = w < camera.r_max * camera.r_max
        if camera.power == 1:
            w = np.sqrt(w)
        factor = np.full_like(w, coefficients[0])
        for coefficient in coefficients[1:]:
            factor *= w
            factor += coefficient
        sources = np.empty((*w.shape, 2))
        sources[..., 0] = camera.cx + camera.fx * x * factor
        sources[..., 1] = camera.cy + camera.fy * y * factor
    return sources, valid


def r_max_pixels(
    lens: LensLike,
    width: int | None = None,
    height: int | None = None,
    *,
    crop_factor: float | None = None,
    scale: float = 1.0,
) -> float:
    """r_max in pixels of the undistorted output, around its centre ((W-1)/2, (H-1)/2).

    Arguments as :func:`valid_region_mask`. 0 when the model has no valid
    domain, ``inf`` when it never folds.
    """
    return _as_camera(lens, width, height, crop_factor).r_max_pixels(scale)


def _output_size(camera: RadialCamera, width: int | None, height: int | None) -> tuple[int, int]:
    width = camera.width if width is None else width
    height = camera.height if height is None else height
    if width is None or height is None:
        raise ProjectionError("the output image size is needed")
    try:
        whole = int(width) == width and int(height) == height
    except (TypeError, ValueError, OverflowError):  # not numbers, NaN or inf
        whole = False
    if isinstance(width, bool) or isinstance(height, bool) or not whole or width < 1 or height < 1:
        raise ProjectionError(f"output size {width}x{height} is not two positive integers")
    return int(width), int(height)


def _output_pinhole(
    camera: RadialCamera, xs: ArrayLike, ys: ArrayLike, scale: float
) -> tuple[FloatArray, FloatArray]:
    """Pinhole coordinates shown by output pixels (xs, ys) at ``scale``."""
    if not (math.isfinite(scale) and scale > 0):
        raise ProjectionError(f"scale {scale:g} is not positive")
    with np.errstate(over="ignore"):  # a focal near 1e-308 px: +-inf, beyond any r_max
        x = (np.asarray(xs, dtype=np.float64) - camera.cx) / (camera.fx * scale)
        y = (np.asarray(ys, dtype=np.float64) - camera.cy) / (camera.fy * scale)
    return x, y
