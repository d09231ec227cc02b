"""A projected point is valid only where its pixel is a finite number: a point
whose pixel overflows the float range is never reported valid, through the
library and through `lensaudit project`, judged against exact rational
arithmetic (fractions), not the projection code."""

from __future__ import annotations

import math
import subprocess
import sys
from fractions import Fraction

import numpy as np
import pytest

from lensaudit import projection

LARGEST = Fraction(sys.float_info.max)


def exact_pixel(camera, point) -> tuple[Fraction, Fraction] | None:
    """The pixel as exact rationals; None where the inputs are not finite or z <= 0."""
    if not all(math.isfinite(v) for v in point) or point[2] <= 0:
        return None
    x, y, z = (Fraction(v) for v in point)
    x, y = x / z, y / z
    w = x * x + y * y
    if camera.power == 1:
        return None  # not used here: the cameras below are polynomials in r^2
    factor = sum(Fraction(c) * w**j for j, c in enumerate(camera.distortion))
    return (
        Fraction(camera.cx) + Fraction(camera.fx) * x * factor,
        Fraction(camera.cy) + Fraction(camera.fy) * y * factor,
    )


def expected_valid(camera, point) -> bool:
    """Inside r_max, z > 0, finite, and a pixel well inside the float range."""
    pixel = exact_pixel(camera, point)
    if pixel is None:
        return False
    x, y, z = (Fraction(v) for v in point)
    inside = math.isinf(camera.r_max) or (x / z) ** 2 + (y / z) ** 2 < Fraction(camera.r_max) ** 2
    return inside and all(abs(p) < LARGEST / 2 for p in pixel)


CAMERAS = {
    # k1 > 0 on OpenCV's model: never folds, so only the float range ends it.
    "opencv": projection.opencv_camera(
        [[1000, 0, 500], [0, 1000, 500], [0, 0, 1]], [0.1, 0.01, 0, 0, 0.001], 1000, 1000
    ),
    "brown": projection.brown_conrady_camera(800, 800, 400, 300, 0.05, 0.0, 0.0, 800, 600),
}
POINTS = [
    (1e200, 0.0, 1.0),
    (1.0, 0.5, 1e-300),
    (1e150, 1e150, 1.0),
    (1e60, 0.0, 1.0),
    (1e70, 1e70, 1.0),
    (1.0, 0.0, 1.0),
    (-3.0, 2.0, 5.0),
    (0.0, 0.0, 1.0),
    (1e-300, 1e-300, 1.0),
    (math.nan, 0.0, 1.0),
    (0.0, math.nan, 1.0),
    (0.0, 0.0, math.nan),
    (math.inf, 0.0, 1.0),
    (1.0, 1.0, -1.0),
]


@pytest.mark.parametrize("name", sorted(CAMERAS))
@pytest.mark.parametrize("nan_for_invalid", [True, False])
def test_a_valid_point_has_a_finite_pixel(name, nan_for_invalid):
    camera = CAMERAS[name]
    pixels, valid = projection.project(np.array(POINTS), camera, nan_for_invalid=nan_for_invalid)
    for point, pixel, ok in zip(POINTS, pixels, valid, strict=True):
        assert bool(ok) == expected_valid(camera, point), point
        if ok:
            exact = exact_pixel(camera, point)
            assert np.isfinite(pixel).all()
            assert pixel.tolist() == pytest.approx([float(v) for v in exact], rel=1e-12), point
        elif nan_for_invalid:
            assert np.isnan(pixel).all(), point


def test_one_point_alone_is_judged_as_in_an_array():
    camera = CAMERAS["opencv"]
    for point in POINTS:
        pixel, ok = projection.project(point, camera)
        assert bool(ok) == expected_valid(camera, point), point
        assert np.isfinite(pixel).all() if ok else np.isnan(pixel).all()


def test_a_ptlens_model_that_never_folds_is_ended_by_the_float_range():
    # The Tokina 11-16 mm at 11 mm as fix refits it for --target inf: r_max = inf.
    lens = projection.LensfunCalibration("ptlens", 11.0, a=0.026039, b=-0.17414, c=0.18908)
    camera = projection.lensfun_camera(lens, 6000, 4000)
    assert math.isinf(camera.r_max) and camera.power == 1
    # On the x axis r = |x / z| exactly, so the pixel is a rational function of it.
    points = [(1.0, 0.0, 1e-300), (1e100, 0.0, 1.0), (1e60, 0.0, 1.0), (0.3, 0.0, 1.0)]
    pixels, valid = projection.project(np.array(points), camera)
    for point, pixel, ok in zip(points, pixels, valid, strict=True):
        r = abs(Fraction(point[0]) / Fraction(point[2]))
        factor = sum(Fraction(c) * r**j for j, c in enumerate(camera.distortion))
        u = Fraction(camera.cx) + Fraction(camera.fx) * r * factor
        assert bool(ok) == (abs(u) < LARGEST / 2), point
        assert np.isfinite(pixel).all() if ok else np.isnan(pixel).all()


def run_project(arguments, text):
    return subprocess.run(
        [sys.executable, "-m", "lensaudit", "project", *arguments],
        input=text, capture_output=True, text=True, check=False,
    )  # fmt: skip


def test_the_command_never_prints_a_pixel_that_overflows_as_valid():
    opencv = ["--opencv", "1000,1000,500,500,0.1,0.01,0,0,0.001", "--size", "1000x1000"]
    finite = [p for p in POINTS if all(math.isfinite(v) for v in p)]
    result = run_project(opencv, "".join(f"{x!r},{y!r},{z!r}\n" for x, y, z in finite))
    assert result.returncode == 0, result.stderr
    rows = result.stdout.splitlines()[1:]
    assert len(rows) == len(finite)
    for point, row in zip(finite, rows, strict=True):
        u, v, valid = row.split(",")
        assert valid == ("true" if expected_valid(CAMERAS["opencv"], point) else "false"), point
        assert "inf" not in row and "nan" not in row.lower(), row
        assert (u != "" and v != "") == (valid == "true"), row


def test_the_command_refuses_points_that_are_not_numbers():
    opencv = ["--opencv", "1000,1000,500,500,0.1,0.01,0,0,0.001"]
    for text in ("nan,0,1\n", "0,0,inf\n"):
        result = run_project(opencv, text)
        assert result.returncode == 2 and "<stdin>:1" in result.stderr, result.stderr
        assert "Traceback" not in result.stderr
