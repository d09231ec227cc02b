"""The data behind `lensaudit plot`: D(r) curves, the undistortion warp, r_max maps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from conftest import lens_xml
from lensaudit import normalizer
from lensaudit.pipeline import run
from lensaudit.report import curves, select, warp
from lensaudit.report.rmax_map import rmax_map


@pytest.fixture(scope="module")
def audit(bundled_db):
    return run(bundled_db)


@pytest.fixture
def poly3_entry(write_xml):
    """One poly3 entry, k1 = -0.3: r_max = sqrt(1.3 / 0.9)."""
    return run(write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.3"/>'))).entries[0]


def poly3_coefficients(k1):
    """D(r) = r (1 - k1 + k1 r^2), highest power first, written out by hand."""
    return [k1, 0.0, 1.0 - k1, 0.0]


def test_source_of_a_point_beyond_the_fold_is_mirrored():
    # k1 = -0.45: D(2) = 2 (1 + 3 k1) = -0.7, so (2, 0) reads the input at (-0.7, 0).
    x, y = warp.source_positions(poly3_coefficients(-0.45), [2.0, 0.0], [0.0, 1.0])
    assert x[0] == pytest.approx(-0.7, abs=1e-15) and y[0] == 0
    # On the axis: D(1) = 1 for poly3, whatever k1.
    assert (x[1], y[1]) == (0.0, pytest.approx(1.0, abs=1e-15))


def test_centre_of_the_image_reads_the_centre():
    x, y = warp.source_positions(poly3_coefficients(-0.45), [0.0], [0.0])
    assert (x[0], y[0]) == (0.0, 0.0)


def test_undistorted_pixel_beyond_the_fold_shows_the_mirrored_input():
    # A 9 x 3 output at 2 pixels per unit: pixel (8, 1) shows the point (2, 0).
    pixels_per_unit = math.hypot(4, 1) / math.hypot(1.5, 1)
    result = warp.hugin_warp(
        poly3_coefficients(-0.45), 1.5, math.inf, 9, 3, scale=2 / pixels_per_unit
    )
    mirrored = warp.checkerboard(-0.7, 0.0, 1.5)
    direct = warp.checkerboard(0.7, 0.0, 1.5)
    assert list(result.image[1, 8]) == list(mirrored) != list(direct)


def test_the_identity_model_gives_back_the_input_image():
    identity = [0.0, 0.0, 1.0, 0.0]  # D(r) = r
    width, height = 241, 161
    result = warp.hugin_warp(identity, 240 / 160, math.inf, width, height, scale=1.0)
    assert np.array_equal(result.image, warp.input_image(width, height))
    assert result.valid.all() and math.isinf(result.r_max_pixels)


def test_points_outside_the_input_image_get_the_background():
    colour = warp.checkerboard(np.array([1.6, 0.0]), np.array([0.0, -1.01]), 1.5)
    assert [tuple(c) for c in colour] == [warp.BACKGROUND, warp.BACKGROUND]


def test_valid_region_is_the_circle_of_radius_r_max():
    r_max = math.sqrt(1.3 / 0.9)
    width, height, scale = 301, 201, 0.5
    result = warp.hugin_warp(poly3_coefficients(-0.3), 1.5, r_max, width, height, scale)
    # 300 x 200 pixels between border centres: 100 pixels per unit at scale 1.
    x = (np.arange(width) - 150) / 50
    y = (np.arange(height) - 100) / 50
    expected = np.hypot(x[None, :], y[:, None]) < r_max
    assert np.array_equal(result.valid, expected)
    assert result.r_max_pixels == pytest.approx(50 * r_max)
    assert result.valid.any() and not result.valid.all()


def test_default_scale_puts_r_max_at_two_thirds_of_the_half_diagonal():
    half_diagonal = math.hypot(150, 100)
    assert warp.default_scale(300.0, 301, 201) == pytest.approx(half_diagonal / 450)
    assert warp.default_scale(100.0, 301, 201) == pytest.approx(1 / 1.3)
    assert warp.default_scale(1e6, 301, 201) == pytest.approx(1 / 6)
    assert warp.default_scale(math.inf, 301, 201) == pytest.approx(1 / 1.5)


@pytest.mark.skipif(not warp.projection_available(), reason="lensaudit.projection is absent")
def test_liblensfun_placement_agrees_with_hugin_units_when_the_image_is_the_sensor(audit):
    # On a 301 x 201 image (3:2 between border pixel centres) with the calibration's
    # crop factor, liblensfun's placement is Hugin units of the calibration image.
    index = select.by_location(audit, "slr-tokina.xml", 17)
    entry = audit.entries[index]
    placed = warp.lensfun_warp(entry, 301, 201, scale=0.5)
    hugin = warp.hugin_warp(
        curves.distortion_coefficients(entry),
        entry.aspect_ratio,
        float(audit.metrics.r_max[index]),
        301,
        201,
        scale=0.5,
    )
    assert placed.r_max_pixels == pytest.approx(hugin.r_max_pixels, rel=1e-9)
    assert (placed.valid != hugin.valid).sum() <= 2
    differing = np.any(placed.image != hugin.image, axis=-1).sum()
    assert differing <= 0.002 * placed.valid.size


def test_curve_peaks_at_r_max_with_zero_slope(poly3_entry):
    entry = poly3_entry
    r_max = math.sqrt(1.3 / 0.9)
    d_max = r_max * (1.3 - 0.3 * r_max**2)
    curve = curves.sample(entry, r_max, d_max, math.hypot(1.5, 1), points=2001, extent=2 * r_max)
    peak = int(np.argmax(curve.d))
    assert curve.r[peak] == pytest.approx(r_max, abs=1e-3)
    assert curve.d[peak] == pytest.approx(d_max, rel=1e-6)
    assert abs(curve.slope[peak]) < 1e-2


def test_the_sketch_marks_r_max_and_the_corner(poly3_entry):
    entry = poly3_entry
    r_max = math.sqrt(1.3 / 0.9)
    curve = curves.sample(entry, r_max, r_max * (1.3 - 0.3 * r_max**2), 1.8)
    svg = curves.sketch_svg(curve)
    assert svg.startswith("<svg") and svg.endswith("</svg>")
    assert f"r_max {r_max:.3g}" in svg and "1.80" in svg and "<polyline" in svg


def test_plot_extent_shows_r_max_and_the_corner_within_limits():
    assert curves.plot_extent(2.0, 1.8) == pytest.approx(3.0)
    assert curves.plot_extent(0.5, 1.8) == pytest.approx(1.3 * 1.8)
    assert curves.plot_extent(7000.0, 1.8) == pytest.approx(6 * 1.8)
    assert curves.plot_extent(math.inf, 1.8) == pytest.approx(1.5 * 1.8)


def test_map_matches_closed_forms_for_brown_conrady():
    grid = rmax_map(k3=(0.0, 0.5, -0.5), k_range=(-1.0, 1.0), resolution=9)
    axis = grid.k1
    k3_zero = grid.r_max[0]
    # k2 = k3 = 0: D'(r) = 1 + 3 k1 r^2, r_max = 1 / sqrt(-3 k1) for k1 < 0.
    row = int(np.flatnonzero(grid.k2 == 0)[0])
    for column, k1 in enumerate(axis):
        expected = 1 / math.sqrt(-3 * k1) if k1 < 0 else math.inf
        assert k3_zero[row, column] == pytest.approx(expected, rel=1e-12)
    # The paper: all coefficients >= 0 never fold; k3 < 0 always folds.
    positive = (grid.k1[None, :] >= 0) & (grid.k2[:, None] >= 0)
    assert np.isinf(grid.r_max[1][positive]).all()
    assert np.isfinite(grid.r_max[2]).all()


def test_map_agrees_with_the_normalizer_one_point_at_a_time():
    grid = rmax_map(k3=(0.2,), k_range=(-0.5, 0.5), resolution=5)
    k1, k2 = grid.k1[1], grid.k2[3]
    cubic = normalizer.brown_conrady(k1, k2, 0.2)
    # 1 + 3 k1 w + 5 k2 w^2 + 7 k3 w^3 by numpy's companion-matrix roots.
    roots = np.roots([7 * 0.2, 5 * k2, 3 * k1, 1.0])
    positive = sorted(r.real for r in roots if abs(r.imag) < 1e-12 and r.real > 0)
    expected = math.sqrt(positive[0]) if positive else math.inf
    assert (cubic.a, cubic.b) == (3 * k1, 5 * k2)
    assert grid.r_max[0, 3, 1] == pytest.approx(expected, rel=1e-9)


def test_query_words_may_come_in_any_order(audit):
    index = select.by_query(audit, select.Query("11-16 tokina", 11.0, 1.0))
    entry = audit.entries[index]
    assert (entry.file, entry.focal, entry.crop_factor) == ("slr-tokina.xml", 11.0, 1.0)


def test_location_may_be_given_as_a_path(audit):
    index = select.by_location(audit, "/some/where/slr-tokina.xml", 17)
    assert audit.entries[index].lens.startswith("Tokina 11-16mm")


def test_parse_location():
    assert select.parse_location("slr-tokina.xml:17") == ("slr-tokina.xml", 17)
    assert select.parse_location("C:/db/a.xml:3") == ("C:/db/a.xml", 3)
    assert select.parse_location("slr-tokina.xml") is None
    assert select.parse_location(":17") is None
    assert select.parse_location("a.xml:x") is None
