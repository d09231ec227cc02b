"""Which points `project` calls valid, on hostile values, against exact arithmetic.

The documented rule: a point is invalid when it is behind or on the camera
plane (Z <= 0), at or beyond r_max, or not finite (X/Z or Y/Z beyond the
float range included), and valid otherwise. The reference here applies that
rule to X/Z and Y/Z as exact fractions; pixels are held to the model
F(r) = sum of distortion[j] * (r^2)^j evaluated exactly. Nothing here needs
lensfunpy or OpenCV.
"""

from __future__ import annotations

import math
import subprocess
import sys
import warnings
from decimal import Decimal, localcontext
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from conftest import lens_xml
from lensaudit.projection import (
    LensfunCalibration,
    brown_conrady_camera,
    lensfun_camera,
    project,
)

LARGEST = sys.float_info.max

#: Cameras from r_max = 0 to inf, with r_max**2 underflowing (k1 = -1.7e308) and
#: overflowing (k1 = -1e-320) binary64 among them.
CAMERAS = {
    "pinhole": brown_conrady_camera(1000, 1000, 959.5, 539.5),
    "k1 -0.3": brown_conrady_camera(1000, 1000, 959.5, 539.5, -0.3),
    "k1 k2 k3": brown_conrady_camera(800, 900, 640, 360, -0.35, 0.12, -0.02),
    "k1 1e300": brown_conrady_camera(1000, 1000, 500, 500, 1e300),
    "k1 -1e300": brown_conrady_camera(1000, 1000, 500, 500, -1e300),
    "k1 -1.7e308": brown_conrady_camera(1000, 1000, 500, 500, -1.7e308),
    "k3 -1.7e308": brown_conrady_camera(1000, 1000, 500, 500, 0, 0, -1.7e308),
    "k1 -1e-320": brown_conrady_camera(1000, 1000, 500, 500, -1e-320),
    "decreasing": brown_conrady_camera(1000, 1000, 500, 500, 1e308, 0, -1e308),
    "lensfun poly3": lensfun_camera(LensfunCalibration("poly3", 10.0, k1=-0.3), 6000, 4000),
}

hostile = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True),
    st.sampled_from([0.0, -0.0, 5e-324, -5e-324, 1e-310, 2.2250738585072014e-308, LARGEST]),
    st.floats(-10, 10),
)


def exact_ratio(numerator: float, denominator: float) -> Fraction | None:
    """numerator / denominator exactly; None where it rounds beyond the float range."""
    ratio = Fraction(numerator) / Fraction(denominator)
    try:
        float(ratio)
    except OverflowError:
        return None
    return ratio


def expected_valid(point: tuple[float, float, float], r_max: float) -> bool | None:
    """The documented rule in exact arithmetic; None within a rounding of r_max."""
    x, y, z = point
    if not all(math.isfinite(v) for v in point) or z <= 0:
        return False
    ratios = exact_ratio(x, z), exact_ratio(y, z)
    if None in ratios:
        return False
    if math.isinf(r_max):
        return True
    squared = ratios[0] ** 2 + ratios[1] ** 2
    bound = Fraction(r_max) ** 2
    if abs(squared - bound) <= bound * Fraction(1, 10**9):
        return None
    return squared < bound


def expected_pixel(camera, point) -> tuple[Fraction, Fraction, Fraction]:
    """(u, v, scale): the pixel of F(r) evaluated exactly, and a bound on its terms' size."""
    x, y = (Fraction(v) / Fraction(point[2]) for v in point[:2])
    assert camera.power == 2
    w = x * x + y * y
    terms = [Fraction(c) * w**j for j, c in enumerate(camera.distortion)]
    factor = sum(terms)
    size = sum(abs(t) for t in terms)
    u = Fraction(camera.cx) + Fraction(camera.fx) * x * factor
    v = Fraction(camera.cy) + Fraction(camera.fy) * y * factor
    scale = abs(Fraction(camera.cx)) + abs(Fraction(camera.cy))
    scale += (Fraction(camera.fx) * abs(x) + Fraction(camera.fy) * abs(y)) * size
    return u, v, scale


def finite_pixel(camera, point) -> bool | None:
    """Whether the exact pixel is within the float range (a valid point's must be);
    None within a rounding of its end, or where r^2 or a term is beyond it on
    the way (the pixel is then inf or NaN, and the point not valid)."""
    u, v, scale = expected_pixel(camera, point)
    largest = Fraction(sys.float_info.max)
    if max(abs(u), abs(v)) > largest * (1 + Fraction(1, 10**9)):
        return False
    if scale > Fraction(10) ** 300 or max(abs(point[0]), abs(point[1])) >= 1e150 * point[2]:
        return None
    return True


@pytest.mark.parametrize(
    "point",
    [(1.0, 1.0, 1.0), (1e-310, 1e-310, 1e-310), (0.0, 0.0, 5e-324), (5e-324, -5e-324, 5e-324)],
)
def test_subnormal_z_in_front_of_the_camera_is_valid_like_any_other(point):
    camera = CAMERAS["pinhole"]
    pixel, valid = project(point, camera)
    assert valid
    # x / z = y / z = 1 or 0 or +-1: by hand, u = 959.5 + 1000 x / z.
    x, y = point[0] / point[2], point[1] / point[2]
    assert pixel.tolist() == [959.5 + 1000 * x, 539.5 + 1000 * y]


@pytest.mark.parametrize("name", sorted(CAMERAS))
@settings(max_examples=300, deadline=None)
@given(point=st.tuples(hostile, hostile, hostile))
@example(point=(3.0, 3.0, 2.2250738585072014e-308))  # x/z finite, the radius not
def test_validity_is_the_documented_rule_in_exact_arithmetic(name, point):
    camera = CAMERAS[name]
    expected = expected_valid(point, camera.r_max)
    if expected:
        expected = finite_pixel(camera, point)
    assume(expected is not None)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pixels, valid = project([point], camera)
    assert bool(valid[0]) is expected, (point, camera.r_max)
    if not expected:
        assert np.isnan(pixels[0]).all()
        return
    u, v, scale = expected_pixel(camera, point)
    if scale > Fraction(10) ** 300 or max(abs(point[0]), abs(point[1])) >= 1e150 * point[2]:
        return  # r^2 or the pixel is beyond the float range on the way (documented)
    tolerance = scale * Fraction(1, 10**12) + Fraction(10) ** -300
    assert abs(Fraction(float(pixels[0, 0])) - u) <= tolerance, (point, pixels[0])
    assert abs(Fraction(float(pixels[0, 1])) - v) <= tolerance, (point, pixels[0])


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_blocks_of_hostile_points_agree_with_points_one_by_one(name):
    camera = CAMERAS[name]
    values = [0.0, -0.0, 5e-324, 1e-310, 1e-200, 0.5, 1.0, 3.0, 1e154, 1e200, LARGEST]
    values += [-v for v in values] + [math.inf, -math.inf, math.nan]
    rng = np.random.default_rng(23)
    points = rng.choice(values, size=(5000, 3))
    pixels, valid = project(points, camera)
    for index in range(0, 5000, 97):
        one_pixel, one_valid = project(points[index], camera)
        assert one_valid == valid[index]
        np.testing.assert_array_equal(one_pixel, pixels[index])


def test_r_max_of_a_k3_near_the_float_limit_is_the_root_of_its_cubic():
    # D'(r) = 1 + 7 k3 r^6 = 0: r_max = (-1 / (7 k3)) ** (1/6), in 40 digits.
    k3 = -1.7e308
    with localcontext() as context:
        context.prec = 40
        r_max = (Decimal(-1) / (7 * Decimal(k3))) ** (Decimal(1) / 6)
    camera = CAMERAS["k3 -1.7e308"]
    assert camera.r_max == pytest.approx(float(r_max), rel=1e-12)
    # d_max = D(r_max) = r_max (1 + k3 r_max^6) = r_max * 6 / 7.
    assert camera.d_max == pytest.approx(float(r_max) * 6 / 7, rel=1e-12)


@settings(max_examples=200, deadline=None)
@given(
    coefficients=st.lists(
        st.one_of(
            st.floats(allow_nan=False, allow_infinity=False),
            st.sampled_from([1.7e308, -1.7e308, 1e-320, -1e-320, 0.0]),
        ),
        min_size=3,
        max_size=3,
    ),
    model=st.sampled_from(["opencv", "ptlens", "poly3", "poly5"]),
)
def test_no_model_coefficients_make_numpy_warn(coefficients, model):
    points = [[1, 1, 1], [1e-310, 1e-310, 1e-310], [1e300, -1e300, 1e-300], [0, 0, 5e-324]]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        if model == "opencv":
            camera = brown_conrady_camera(1000, 1000, 500, 500, *coefficients, 1000, 800)
        else:
            names = {"ptlens": "abc", "poly3": ["k1"], "poly5": ["k1", "k2"]}[model]
            values = dict(zip(names, coefficients, strict=False))
            try:
                calibration = LensfunCalibration(model, 10.0, **values)
                camera = lensfun_camera(calibration, 1000, 800)
            except ValueError:  # ProjectionError: a model liblensfun cannot place either
                return
        project(points, camera)
        camera.valid_region_mask(40, 30)
        camera.undistortion_map(40, 30)
    assert not math.isnan(camera.r_max)


HUGE_OPENCV = [
    "1000,1000,500,500,0,0,0,0,-1.7e308",
    "1000,1000,500,500,1e308,1e308,0,0,-1e308",
    "1000,1000,500,500,-1.7e308,1.7e308",
    "1e-320,1e-320,-1.7e308,1.7e308,1e300,-1e300,0,0,1e-320",
]


@pytest.mark.parametrize("opencv", HUGE_OPENCV)
@pytest.mark.parametrize("info", [False, True], ids=["points", "info"])
def test_huge_opencv_coefficients_leave_standard_error_empty(tmp_path, opencv, info):
    points = tmp_path / "points.csv"
    points.write_text("x,y,z\n1,1,1\n1e-310,1e-310,1e-310\n1e300,1e300,1e-300\n0,0,5e-324\n")
    arguments = ["--info"] if info else [str(points)]
    completed = subprocess.run(
        [sys.executable, "-m", "lensaudit", "project", *arguments, "--opencv", opencv],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert completed.returncode == 0, completed.stderr
    assert completed.stderr == ""
    assert completed.stdout


def distortion_line(path: Path) -> int:
    """The line of the (first) <distortion> of a file."""
    lines = enumerate(path.read_text().splitlines(), start=1)
    return next(number for number, text in lines if "<distortion" in text)


def project_command(*words: str) -> subprocess.CompletedProcess:
    """``lensaudit project WORDS...`` in a fresh process, as a user runs it."""
    return subprocess.run(
        [sys.executable, "-m", "lensaudit", "project", *words],
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_a_lensfun_entry_near_the_float_limit_writes_no_warning(write_xml, tmp_path):
    path = write_xml(lens_xml('<distortion model="poly5" focal="10" k1="1e308" k2="-1.7e308"/>'))
    line = distortion_line(path)
    points = tmp_path / "points.csv"
    points.write_text("0.001,0,1\n1,1,1\n")
    completed = project_command(str(points), "--entry", f"{path}:{line}", "--size", "600x400")
    assert completed.returncode == 0, completed.stderr
    # Standard error holds only the note naming the entry and its database.
    assert completed.stderr.splitlines() == [
        f"lensaudit project: Test 10mm at 10 mm, from {path}:{line}"
    ]


@pytest.mark.parametrize(
    ("crop", "distortion", "expected"),
    [
        ("1e308", 'focal="11"', "crop factor 1e+308"),
        ("1", 'focal="11" real-focal="1e308"', "beyond what floats hold"),
        ("1", 'focal="1e308"', "beyond what floats hold"),
    ],
)
@pytest.mark.parametrize("info", [False, True])
def test_a_camera_beyond_the_floats_is_one_line_naming_the_entry(
    write_xml, tmp_path, crop, distortion, expected, info
):
    distortion = f'<distortion model="ptlens" {distortion} a="-0.024" b="-0.002" c="0.005"/>'
    path = write_xml(lens_xml(distortion, cropfactor=crop))
    line = distortion_line(path)
    points = tmp_path / "points.csv"
    points.write_text("0.1,0.2,1\n")
    shown = "--info" if info else str(points)
    completed = project_command(shown, "--entry", f"{path}:{line}", "--size", "6000x4000")
    assert completed.returncode == 2, completed.stderr
    (message,) = completed.stderr.splitlines()
    assert message.startswith(f"lensaudit: error: {path}:{line}: ") and expected in message
