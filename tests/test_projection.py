"""The projection filter against liblensfun (lensfunpy's Modifier) and OpenCV.

liblensfun is the reference for Lensfun models: its undistortion map sends
each output pixel to the source pixel it is read from. It computes in single
precision, and for whole rows it runs SSE code whose square root is an
estimate (about 1e-3 relative, up to 0.1 px on a 600 px image); mapping one
pixel per call runs its plain C code, so every comparison here does that.
"""

from __future__ import annotations

import csv
import io
import math
from collections import Counter

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import lens_xml
from lensaudit import read
from lensaudit.cli import main
from lensaudit.pipeline import run
from lensaudit.projection import (
    LensfunCalibration,
    ProjectionError,
    brown_conrady_camera,
    lensfun_camera,
    opencv_camera,
    project,
    r_max_pixels,
    source_pixels,
    undistortion_map,
    valid_region_mask,
)

lensfunpy = pytest.importorskip("lensfunpy")

TOLERANCE_PX = 0.05
DISTORTION = lensfunpy.ModifyFlags.DISTORTION
SCALE = lensfunpy.ModifyFlags.SCALE
GEOMETRY = lensfunpy.ModifyFlags.GEOMETRY


@pytest.fixture(scope="module")
def audit(bundled_db):
    return run(bundled_db)


@pytest.fixture(scope="module")
def lenses(liblensfun_lenses):
    return liblensfun_lenses


@pytest.fixture(scope="module")
def reproducible(audit, lenses):
    """Entries liblensfun reproduces as they are: found by name, the only one at their focal,
    of a lens with a single model (liblensfun drops calibrations of other models)."""
    counts = Counter((e.maker, e.lens, e.crop_factor, e.focal) for e in audit.entries)
    models = {}
    for entry in audit.entries:
        models.setdefault((entry.maker, entry.lens, entry.crop_factor), set()).add(entry.model)
    chosen = {}
    for index, entry in enumerate(audit.entries):
        if (
            not audit.audited[index]
            or counts[(entry.maker, entry.lens, entry.crop_factor, entry.focal)] != 1
            or len(models[(entry.maker, entry.lens, entry.crop_factor)]) != 1
        ):
            continue
        lens = lenses.get((entry.maker, entry.lens, float(np.float32(entry.crop_factor))))
        if lens is not None:
            chosen[index] = lens
    return chosen


def by_place(audit, file, line):
    return next(e for e in audit.entries if (e.file, e.line) == (file, line))


def modifier(lens, entry, width, height, crop, scale=1.0, flags=DISTORTION | SCALE, target=None):
    result = lensfunpy.Modifier(lens, crop, width, height)
    options = {} if target is None else {"targeom": target}
    result.initialize(entry.focal, lens.max_aperture or 2.8, scale=scale, flags=flags, **options)
    return result


def liblensfun_sources(mod, xs, ys):
    """Source pixels of output pixels (or sub-pixel points), one liblensfun call each."""
    return np.array(
        [
            mod.apply_geometry_distortion(float(x), float(y), 1, 1)[0, 0]
            for x, y in zip(xs, ys, strict=True)
        ],
        dtype=np.float64,
    ).reshape(-1, 2)


# --- Lensfun pixels: liblensfun's undistortion map ------------------------------------------


@pytest.mark.parametrize(("crop_ratio", "portrait"), [(1.0, False), (1.5, False), (0.7, True)])
def test_undistortion_map_agrees_with_liblensfun_inside_the_valid_domain(
    audit, reproducible, crop_ratio, portrait
):
    rng = np.random.default_rng(round(crop_ratio * 10) + portrait)
    indices = sorted(reproducible)
    by_model = {
        m: [i for i in indices if audit.entries[i].model == m] for m in ("ptlens", "poly3", "poly5")
    }
    sample = [
        *rng.choice(by_model["ptlens"], 14, replace=False),
        *rng.choice(by_model["poly3"], 8, replace=False),
        *by_model["poly5"],
    ]
    worst, checked = 0.0, 0
    for index in sample:
        entry, lens = audit.entries[index], reproducible[index]
        width, height = (int(v) for v in rng.integers(300, 7000, 2))
        width, height = sorted((width, height), reverse=not portrait)
        crop = entry.crop_factor * crop_ratio
        scale = float(rng.choice([1.0, 0.75]))
        xs = np.r_[rng.integers(0, width, 150), 0, width - 1, (width - 1) // 2]
        ys = np.r_[rng.integers(0, height, 150), 0, height - 1, (height - 1) // 2]
        expected = liblensfun_sources(modifier(lens, entry, width, height, crop, scale), xs, ys)
        ours, inside = source_pixels(entry, xs, ys, width, height, crop_factor=crop, scale=scale)
        error = np.hypot(*(ours - expected).T)[inside]
        worst = max(worst, float(error.max(initial=0)))
        checked += error.size
    assert checked > 3000
    assert worst < TOLERANCE_PX


def test_undistortion_map_is_liblensfun_map_pixel_for_pixel(audit, reproducible):
    entry = by_place(audit, "slr-tokina.xml", 17)
    index = audit.entries.index(entry)
    width, height, scale = 160, 107, 0.6
    mod = modifier(reproducible[index], entry, width, height, entry.crop_factor, scale)
    ys, xs = (a.ravel() for a in np.mgrid[0:height, 0:width])
    expected = liblensfun_sources(mod, xs, ys).reshape(height, width, 2)
    ours = undistortion_map(width, height, entry, scale=scale)
    mask = valid_region_mask(width, height, entry, scale=scale)
    assert 0.2 < mask.mean() < 0.9  # the output reaches beyond the fold
    # Beyond the fold too: the same polynomial, folded back the same way.
    assert np.abs(ours - expected).max() < TOLERANCE_PX


def test_image_centre_is_the_fixed_point_of_liblensfun_map(audit, reproducible):
    index = next(i for i in sorted(reproducible) if audit.entries[i].model == "ptlens")
    entry = audit.entries[index]
    for width, height in ((6000, 4000), (4001, 3001), (1080, 1920)):
        camera = lensfun_camera(entry, width, height)
        mod = modifier(reproducible[index], entry, width, height, entry.crop_factor)
        source = liblensfun_sources(mod, [camera.cx], [camera.cy])[0]
        assert (camera.cx, camera.cy) == ((width - 1) / 2, (height - 1) / 2)
        assert source == pytest.approx((camera.cx, camera.cy), abs=1e-3)


# --- Pinhole units: liblensfun's geometry focal ----------------------------------------------

# Entries whose database gives a real focal length as a <real-focal-length> element,
# with the value it gives, and entries that give none.
REAL_FOCAL = [
    ("compact-sony.xml", 1297, 3.2),
    ("slr-sigma.xml", 806, 18.14),
    ("compact-panasonic.xml", 521, 5.334),
    ("mil-sony.xml", 845, 20.30),
]
NOMINAL_FOCAL = [
    ("slr-tokina.xml", 17),
    ("mil-olympus.xml", 281),
    ("compact-samsung.xml", 176),
    ("slr-canon.xml", 6500),
    ("compact-canon.xml", 1075),
]


def liblensfun_focal_pixels(mod, centre_x, centre_y, radius):
    """liblensfun's pinhole focal length in pixels, from its geometry conversion alone.

    With a fisheye (equidistant) target and no distortion, the output pixel at
    radius rho is read from the rectilinear source radius f tan(rho / f); that
    equation is solved for f by bisection.
    """
    source = liblensfun_sources(mod, [centre_x + radius], [centre_y])[0]
    target = source[0] - centre_x
    low, high = radius / 1.5, 1e7
    for _ in range(200):
        middle = (low + high) / 2
        if middle * math.tan(radius / middle) > target:
            low = middle
        else:
            high = middle
    return (low + high) / 2


def fisheye_directions(centre_x, centre_y, focal_pixels, xs, ys):
    """Unit 3D directions that an equidistant fisheye output shows at pixels (xs, ys)."""
    dx, dy = np.asarray(xs) - centre_x, np.asarray(ys) - centre_y
    theta = np.hypot(dx, dy) / focal_pixels
    azimuth = np.arctan2(dy, dx)
    return np.stack(
        [np.sin(theta) * np.cos(azimuth), np.sin(theta) * np.sin(azimuth), np.cos(theta)], axis=1
    )


@pytest.mark.parametrize("place", [p[:2] for p in REAL_FOCAL] + NOMINAL_FOCAL)
def test_focal_length_in_pixels_is_liblensfun_geometry_focal(audit, lenses, place):
    entry = by_place(audit, *place)
    lens = lenses[(entry.maker, entry.lens, float(np.float32(entry.crop_factor)))]
    width, height, crop = 3000, 2000, entry.crop_factor * 1.25
    camera = lensfun_camera(entry, width, height, crop)
    mod = modifier(
        lens, entry, width, height, crop, flags=GEOMETRY, target=lensfunpy.LensType.FISHEYE
    )
    expected = liblensfun_focal_pixels(mod, camera.cx, camera.cy, 0.8 * camera.cx)
    assert camera.fx == pytest.approx(expected, rel=2e-5)


@pytest.mark.parametrize("place", [p[:2] for p in REAL_FOCAL] + NOMINAL_FOCAL[:3])
def test_project_agrees_with_liblensfun_for_3d_points(audit, lenses, place):
    entry = by_place(audit, *place)
    lens = lenses[(entry.maker, entry.lens, float(np.float32(entry.crop_factor)))]
    width, height, crop = 1500, 1000, entry.crop_factor
    camera = lensfun_camera(entry, width, height, crop)
    geometry_only = modifier(
        lens, entry, width, height, crop, flags=GEOMETRY, target=lensfunpy.LensType.FISHEYE
    )
    focal = liblensfun_focal_pixels(geometry_only, camera.cx, camera.cy, 0.8 * camera.cx)
    full = modifier(
        lens,
        entry,
        width,
        height,
        crop,
        flags=GEOMETRY | DISTORTION,
        target=lensfunpy.LensType.FISHEYE,
    )
    ys, xs = (a.ravel() for a in np.mgrid[0:height:23, 0:width:23])
    points = fisheye_directions(camera.cx, camera.cy, focal, xs, ys)
    points *= np.random.default_rng(5).uniform(0.5, 50, (len(points), 1))  # any depth
    pixels, valid = project(points, camera)
    expected = liblensfun_sources(full, xs, ys)
    assert valid.mean() > 0.5
    assert np.abs(pixels[valid] - expected[valid]).max() < TOLERANCE_PX


def test_the_cameras_real_focal_is_the_entrys(audit, write_xml):
    for file, line, real_focal in REAL_FOCAL:
        entry = by_place(audit, file, line)
        assert entry.real_focal == pytest.approx(real_focal)
        assert lensfun_camera(entry, 600, 400) == lensfun_camera(
            entry, 600, 400, real_focal=entry.real_focal
        )
    assert math.isnan(by_place(audit, "slr-tokina.xml", 17).real_focal)
    path = write_xml(
        lens_xml(
            '<distortion model="poly3" focal="10" k1="-0.01" real-focal="10.4"/>',
            '<distortion model="poly3" focal="12" k1="-0.01"/>',
            '<real-focal-length focal="12" real-focal="12.5"/>',
        )
    )
    entries = read.read(path).entries()
    assert [e.real_focal for e in entries] == [10.4, 12.5]
    # The real focal length sets the camera's focal length in pixels.
    assert (
        lensfun_camera(entries[0], 600, 400).fx
        != lensfun_camera(entries[0], 600, 400, real_focal=10.0).fx
    )


# --- The valid region: every pixel read from beyond the fold is invalid -----------------------


def liblensfun_fold(mod, centre_x, centre_y, direction, limit, step=0.25):
    """(last radius before, first radius after) liblensfun's source radius stops increasing.

    Along a ray of output pixels from the centre, in steps of ``step`` pixels.
    A decrease of less than 1e-3 px is taken as single-precision noise at the
    flat top of the fold, so the two radii bracket the fold with a small gap.
    """
    radii = np.arange(0.0, limit, step)
    sources = liblensfun_sources(
        mod, centre_x + radii * direction[0], centre_y + radii * direction[1]
    )
    source_radius = np.hypot(sources[:, 0] - centre_x, sources[:, 1] - centre_y)
    steps = np.diff(source_radius)
    falling = np.flatnonzero(steps < -1e-3)
    if falling.size == 0:
        return math.inf, math.inf
    first_fall = falling[0]
    rising = np.flatnonzero(steps[:first_fall] > 1e-3)
    return float(radii[rising[-1]]), float(radii[first_fall + 1])


def test_every_pixel_liblensfun_reads_from_beyond_the_fold_is_invalid(audit, reproducible):
    m = audit.metrics
    finite = [i for i in sorted(reproducible) if np.isfinite(m.r_max[i]) and m.r_max[i] > 0]
    folding = [i for i in finite if m.folds_in_image[i]]
    sample = [*folding, *np.random.default_rng(3).choice(finite, 12, replace=False).tolist()]
    assert len(folding) >= 4
    for index in sample:
        entry = audit.entries[index]
        width, height = 450, 300
        # Zoom out so that the output corner shows 1.4 times r_max.
        corner = math.hypot((width - 1) / 2, (height - 1) / 2)
        full_scale = r_max_pixels(entry, width, height)
        scale = min(1.0, corner / (1.4 * full_scale))
        mod = modifier(reproducible[index], entry, width, height, entry.crop_factor, scale)
        centre = ((width - 1) / 2, (height - 1) / 2)
        brackets = [
            liblensfun_fold(mod, *centre, (math.cos(a), math.sin(a)), corner)
            for a in np.linspace(0, 2 * math.pi, 8, endpoint=False)
        ]
        before = min(b[0] for b in brackets)
        after = max(b[1] for b in brackets)
        assert after - before < 6, f"{entry.file}:{entry.line}: fold not sharp in liblensfun"
        assert before - 0.5 <= r_max_pixels(entry, width, height, scale=scale) <= after + 0.5
        mask = valid_region_mask(width, height, entry, scale=scale)
        ys, xs = np.mgrid[0:height, 0:width]
        radius = np.hypot(xs - centre[0], ys - centre[1])
        beyond, inside = radius > after, radius < before
        assert beyond.sum() > 1000 and inside.sum() > 1000
        assert not mask[beyond].any(), f"{entry.file}:{entry.line}"
        assert mask[inside].all(), f"{entry.file}:{entry.line}"
        # Beyond the fold liblensfun reads pixels it has already read closer in.
        row = liblensfun_sources(mod, xs[height // 2], ys[height // 2])[:, 0]
        right = row[width // 2 :]
        assert np.any(right[~mask[height // 2, width // 2 :]] < right.max() - 1)


def test_valid_region_mask_is_the_disc_of_radius_r_max_pixels(audit):
    entry = by_place(audit, "slr-tokina.xml", 17)
    mask = valid_region_mask(600, 400, entry, scale=0.5)
    radius = r_max_pixels(entry, 600, 400, scale=0.5)
    ys, xs = np.mgrid[0:400, 0:600]
    distance = np.hypot(xs - 299.5, ys - 199.5)
    assert np.array_equal(
        mask[np.abs(distance - radius) > 1e-6],
        (distance < radius)[np.abs(distance - radius) > 1e-6],
    )
    assert 0 < mask.mean() < 1


# --- r_max in pinhole units: exact numbers ---------------------------------------------------


def test_r_max_in_pinhole_units_of_a_poly3_model():
    # poly3 k1 = -0.3: D'(r) = 1.3 - 0.9 r^2 vanishes at r^2 = 13/9 (Hugin units). On a
    # full-frame 3:2 calibration half the short side is 12 mm, so at 10 mm (no real focal:
    # the geometry focal is the nominal one) one Hugin unit is 1.2 in x/z. On a 6001 x 4001
    # image (liblensfun measures 6000 x 4000 between border pixel centres, exactly 3:2) one
    # Hugin unit is 2000 px.
    calibration = LensfunCalibration("poly3", focal=10.0, k1=-0.3)
    camera = lensfun_camera(calibration, 6001, 4001)
    assert calibration.r_max_hugin == pytest.approx(math.sqrt(13 / 9), rel=1e-14)
    assert camera.r_max == pytest.approx(1.2 * math.sqrt(13 / 9), rel=1e-14)
    assert camera.fx == pytest.approx(2000 * 10 / 12, rel=1e-14)
    assert math.tan(math.radians(camera.max_angle_degrees)) == pytest.approx(camera.r_max)


def test_real_focal_divides_by_the_hugin_correction():
    # With a real focal length, liblensfun's geometry focal is real_focal / (1 - a - b - c).
    calibration = LensfunCalibration("ptlens", focal=20.0, a=0.01, b=-0.02, c=0.05, real_focal=19.0)
    assert calibration.geometry_focal == pytest.approx(19.0 / 0.96, rel=1e-14)
    plain = LensfunCalibration("ptlens", focal=20.0, a=0.01, b=-0.02, c=0.05)
    assert plain.geometry_focal == 20.0


# --- Behaviour of project ---------------------------------------------------------------------


@pytest.fixture
def folding_camera():
    return brown_conrady_camera(900.0, 900.0, 639.5, 359.5, k1=-0.2, width=1280, height=720)


def test_points_behind_or_on_the_camera_plane_are_invalid(folding_camera):
    points = [[0.1, 0.1, 1.0], [0.1, 0.1, -1.0], [0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.0, -0.0]]
    pixels, valid = project(points, folding_camera)
    assert valid.tolist() == [True, False, False, False, False]
    assert np.isnan(pixels[1:]).all() and np.isfinite(pixels[0]).all()


def test_points_that_are_not_finite_are_invalid(folding_camera):
    points = [[math.nan, 0, 1], [0, math.inf, 1], [0, 0, math.inf], [0, 0, math.nan]]
    pixels, valid = project(points, folding_camera)
    assert not valid.any() and np.isnan(pixels).all()


def test_points_beyond_r_max_are_invalid_and_inside_are_valid(folding_camera):
    r_max = folding_camera.r_max
    assert r_max == pytest.approx(math.sqrt(1 / 0.6), rel=1e-14)
    radii = np.array([0.0, 0.5 * r_max, r_max * (1 - 1e-9), r_max * (1 + 1e-9), 2 * r_max, 40])
    points = np.stack([radii * 0.6, radii * 0.8, np.ones_like(radii)], axis=1) * 7.0
    _, valid = project(points, folding_camera)
    assert valid.tolist() == [True, True, True, False, False, False]


def test_folded_positions_are_kept_on_request(folding_camera):
    pixels, valid = project([[math.sqrt(5), 0, 1]], folding_camera, nan_for_invalid=False)
    assert not valid[0]
    assert pixels[0] == pytest.approx((639.5, 359.5))


def test_one_point_gives_one_pixel_and_empty_input_gives_empty_output(folding_camera):
    pixel, valid = project([0.0, 0.0, 2.0], folding_camera)
    assert pixel.shape == (2,) and valid.item() is True
    assert tuple(pixel) == (639.5, 359.5)
    pixels, valid = project(np.empty((0, 3)), folding_camera)
    assert pixels.shape == (0, 2) and valid.shape == (0,)


def test_many_points_are_projected_block_by_block_like_one_by_one(folding_camera):
    rng = np.random.default_rng(0)
    points = rng.normal(size=(50_000, 3))
    pixels, valid = project(points, folding_camera)
    some = rng.choice(len(points), 200, replace=False)
    for i in some:
        pixel, ok = project(points[i], folding_camera)
        assert ok == valid[i]
        assert np.array_equal(pixel, pixels[i], equal_nan=True)


def test_points_must_be_n_by_3(folding_camera):
    with pytest.raises(ProjectionError, match="N x 3"):
        project(np.zeros((4, 2)), folding_camera)


def test_model_that_never_folds_keeps_every_point_in_front():
    camera = lensfun_camera(LensfunCalibration("poly3", focal=50.0, k1=0.01), 600, 400)
    assert camera.r_max == math.inf
    _, valid = project([[1e6, 0, 1], [0, 0, 1], [0, 0, -1]], camera)
    assert valid.tolist() == [True, True, False]


def test_model_decreasing_from_the_centre_has_no_valid_point():
    camera = lensfun_camera(LensfunCalibration("ptlens", focal=10.0, a=0.5, b=0.5, c=0.5), 600, 400)
    assert camera.r_max == 0
    _, valid = project([[0.01, 0, 1], [0, 0, 1]], camera)
    assert not valid.any()
    assert not valid_region_mask(600, 400, camera).any()


def test_fisheye_entries_have_a_valid_region_but_no_pinhole_projection(audit):
    entry = by_place(audit, "slr-sigma.xml", 3239)
    assert entry.type == "fisheye"
    assert valid_region_mask(300, 200, entry).any()
    with pytest.raises(ProjectionError, match="rectilinear"):
        project([0, 0, 1], lensfun_camera(entry, 300, 200))


def test_unusable_entries_and_images_are_refused(write_xml):
    path = write_xml(lens_xml('<distortion model="acm" focal="10" k1="0.1"/>'))
    entries = read.read(path).entries()
    with pytest.raises(ProjectionError, match="unknown_model"):
        lensfun_camera(entries[0], 600, 400)
    with pytest.raises(ProjectionError, match="at least 2x2"):
        lensfun_camera(LensfunCalibration("poly3", focal=10.0), 1, 400)
    with pytest.raises(ProjectionError, match="crop factor"):
        lensfun_camera(LensfunCalibration("poly3", focal=10.0), 600, 400, crop_factor=0)


@pytest.mark.parametrize("size", [math.inf, -math.inf, math.nan])
def test_image_sizes_that_are_not_whole_numbers_are_refused_in_one_line(size):
    calibration = LensfunCalibration("ptlens", 24.0, a=0.01, b=-0.05, c=0.02)
    camera = brown_conrady_camera(900, 900, 639.5, 359.5, -0.2)
    calls = [
        lambda: lensfun_camera(calibration, size, 4000),
        lambda: brown_conrady_camera(900, 900, 0, 0, -0.2, 0, 0, size, 720),
        lambda: valid_region_mask(size, 40, camera),
        lambda: valid_region_mask(40, size, camera),
    ]
    for call in calls:
        with pytest.raises(ProjectionError, match="integers"):
            call()


# --- OpenCV's Brown-Conrady model -------------------------------------------------------------


@pytest.fixture(scope="module")
def cv2():
    """OpenCV, a test-only dependency."""
    return pytest.importorskip("cv2")


BROWN_CONRADY = [
    (-0.28, 0.07, 0.0),
    (-0.3, 0.1, -0.01),
    (-0.2, 0.0, 0.0),
    (0.1, -0.05, 0.0),
    (0.05, 0.01, 0.001),
]


def opencv_pixels(cv2, points, camera_matrix, coefficients):
    pixels, _ = cv2.projectPoints(
        np.asarray(points, np.float64).reshape(-1, 1, 3),
        np.zeros(3),
        np.zeros(3),
        camera_matrix,
        np.asarray(coefficients, np.float64),
    )
    return pixels.reshape(-1, 2)


@pytest.mark.parametrize("coefficients", BROWN_CONRADY)
def test_project_agrees_with_opencv_inside_the_valid_domain(cv2, coefficients):
    k1, k2, k3 = coefficients
    matrix = np.array([[1400.0, 0, 955.2], [0, 1380.0, 541.7], [0, 0, 1]])
    camera = opencv_camera(matrix, [k1, k2, 0, 0, k3], 1920, 1080)
    rng = np.random.default_rng(1)
    limit = min(camera.r_max, 3.0)
    radius = limit * np.sqrt(rng.uniform(0, 1, 5000)) * 0.999
    angle = rng.uniform(0, 2 * math.pi, 5000)
    depth = rng.uniform(0.1, 100, 5000)
    points = np.stack([radius * np.cos(angle), radius * np.sin(angle), np.ones(5000)], 1)
    points *= depth[:, None]
    pixels, valid = project(points, camera)
    assert valid.all()
    expected = opencv_pixels(cv2, points, matrix, [k1, k2, 0, 0, k3])
    assert np.abs(pixels - expected).max() < 1e-6


def test_opencv_projects_points_far_outside_the_field_of_view_into_the_image(cv2, folding_camera):
    # A plain barrel model, k1 = -0.2, on a 1280 x 720 image with f = 900 px. The image
    # corner, at distorted radius 0.816 (x/z), is seen at 46.2 degrees off axis; the model
    # folds at r_max = 1.29 (52.2 degrees).
    matrix = np.array([[900.0, 0, 639.5], [0, 900.0, 359.5], [0, 0, 1]])
    corner_distorted = math.hypot(640 / 900, 360 / 900)
    low, high = 0.0, folding_camera.r_max
    for _ in range(100):  # undistort the corner radius by bisection on D(r) = r (1 - 0.2 r^2)
        middle = (low + high) / 2
        low, high = (
            (middle, high) if middle * (1 - 0.2 * middle**2) < corner_distorted else (low, middle)
        )
    field_of_view = math.degrees(math.atan(low))
    # Points 60 and 65.9 degrees off axis, well outside that field of view.
    angles = np.radians([60.0, math.degrees(math.atan(math.sqrt(5)))])
    points = np.stack([np.tan(angles), np.zeros(2), np.ones(2)], axis=1) * 10
    seen_by_opencv = opencv_pixels(cv2, points, matrix, [-0.2, 0, 0, 0, 0])
    inside_image = (
        (seen_by_opencv[:, 0] >= 0)
        & (seen_by_opencv[:, 0] <= 1279)
        & (seen_by_opencv[:, 1] >= 0)
        & (seen_by_opencv[:, 1] <= 719)
    )
    assert field_of_view == pytest.approx(46.2, abs=0.1)
    assert inside_image.all()  # 1263 px (right edge) and 639.5 px (the very centre)
    assert seen_by_opencv[1] == pytest.approx((639.5, 359.5), abs=1e-6)
    pixels, valid = project(points, folding_camera)
    assert not valid.any() and np.isnan(pixels).all()


def test_tangential_coefficients_are_ignored_with_a_note(cv2):
    matrix = np.array([[800.0, 0, 320], [0, 800.0, 240], [0, 0, 1]])
    camera = opencv_camera(matrix, [-0.1, 0.01, 0.002, -0.001, 0.0])
    assert any("p1=0.002" in note for note in camera.notes)
    points = np.array([[0.1, 0.2, 1.0], [-0.3, 0.1, 2.0]])
    pixels, _ = project(points, camera)
    assert np.abs(pixels - opencv_pixels(cv2, points, matrix, [-0.1, 0.01, 0, 0, 0])).max() < 1e-9


def test_opencv_models_beyond_k3_are_refused():
    matrix = np.eye(3)
    with pytest.raises(ProjectionError, match="rational"):
        opencv_camera(matrix, [0.1, 0, 0, 0, 0, 0.2, 0, 0])
    with pytest.raises(ProjectionError, match="3 x 3"):
        opencv_camera(np.eye(2), [])


# --- lensaudit project -----------------------------------------------------------------------


@pytest.fixture
def runner():
    return CliRunner()


@pytest.fixture
def poly3_xml(write_xml):
    return write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.3"/>'))


def rows(output):
    return list(csv.DictReader(io.StringIO(output)))


def test_cli_projects_csv_points_with_an_entry(runner, poly3_xml):
    # r_max = 1.2 sqrt(13/9) = 1.442 in x/z (see the poly3 test above).
    points = "x,y,z\n0,0,1\n0.5,0,1\n1.44,0,1\n1.45,0,1\n0,0,-1\n"
    result = runner.invoke(
        main, ["project", "-", "--entry", f"{poly3_xml}:10", "--size", "600x400"], input=points
    )
    assert result.exit_code == 0, result.output
    out = rows(result.stdout)
    assert [r["valid"] for r in out] == ["true", "true", "true", "false", "false"]
    assert (float(out[0]["u"]), float(out[0]["v"])) == (299.5, 199.5)
    assert out[3]["u"] == "" and out[3]["v"] == ""
    camera = lensfun_camera(LensfunCalibration("poly3", focal=10.0, k1=-0.3), 600, 400)
    expected, _ = project([0.5, 0, 1], camera)
    assert float(out[1]["u"]) == expected[0]


def test_cli_reads_npy_and_headerless_csv(runner, poly3_xml, tmp_path):
    np.save(tmp_path / "points.npy", np.array([[0.0, 0.0, 1.0], [2.0, 0.0, 1.0]]))
    (tmp_path / "points.csv").write_text("0,0,1\n2,0,1\n")
    for name in ("points.npy", "points.csv"):
        result = runner.invoke(
            main,
            ["project", str(tmp_path / name), "--entry", f"{poly3_xml}:10", "--size", "600x400"],
        )
        assert result.exit_code == 0, result.output
        assert [r["valid"] for r in rows(result.stdout)] == ["true", "false"]


def test_cli_finds_a_lens_by_name_and_focal(runner, tmp_path):
    (tmp_path / "points.csv").write_text("x,y,z\n0,0,1\n3,0,1\n")
    result = runner.invoke(
        main,
        [
            "project",
            str(tmp_path / "points.csv"),
            "--lens",
            "Tokina 11-16",
            "--focal",
            "11",
            "--crop",
            "1",
            "--size",
            "6000x4000",
        ],
    )
    assert result.exit_code == 0, result.output
    assert [r["valid"] for r in rows(result.stdout)] == ["true", "false"]


def test_cli_info_reports_r_max_and_the_fold(runner):
    result = runner.invoke(
        main, ["project", "--entry", "slr-tokina.xml:17", "--size", "6000x4000", "--info"]
    )
    assert result.exit_code == 0, result.output
    assert "folds inside the image          yes" in result.output
    result = runner.invoke(main, ["project", "--opencv", "900,900,639.5,359.5,-0.2", "--info"])
    assert "r_max (x/z)                     1.29099" in result.output


@pytest.mark.parametrize(
    ("arguments", "message"),
    [
        (["--size", "600x400"], "exactly one of"),
        (["--entry", "{xml}:10"], "--size WxH is needed"),
        (["--entry", "{xml}:10", "--size", "600"], "expected WIDTHxHEIGHT"),
        (["--entry", "{xml}:3", "--size", "600x400"], "no <distortion> element"),
        (["--entry", "nowhere.xml:3", "--size", "600x400"], "no such file"),
        (["--lens", "No Such Lens", "--focal", "10", "--size", "600x400"], "no usable"),
        (
            ["--lens", "Tokina 11-16", "--focal", "11.5", "--size", "600x400"],
            "no calibration at 11.5",
        ),
        (["--opencv", "1,2,3", "--size", "600x400"], "3 numbers"),
        (["--opencv", "900,900,1,1", "--crop", "1.5"], "does not apply"),
    ],
)
def test_cli_bad_input_is_one_line_and_exit_2(runner, poly3_xml, arguments, message):
    arguments = [a.replace("{xml}", str(poly3_xml)) for a in arguments]
    result = runner.invoke(main, ["project", "-", *arguments], input="0,0,1\n")
    assert result.exit_code == 2
    assert message in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert "Traceback" not in result.output


def test_cli_bad_points_name_the_line(runner, poly3_xml, tmp_path):
    (tmp_path / "bad.csv").write_text("x,y,z\n0,0,1\n0,zero,1\n")
    result = runner.invoke(
        main,
        ["project", str(tmp_path / "bad.csv"), "--entry", f"{poly3_xml}:10", "--size", "600x400"],
    )
    assert result.exit_code == 2
    assert f"{tmp_path / 'bad.csv'}:3: expected three numbers" in result.output
    np.save(tmp_path / "bad.npy", np.zeros((3, 2)))
    result = runner.invoke(
        main,
        ["project", str(tmp_path / "bad.npy"), "--entry", f"{poly3_xml}:10", "--size", "600x400"],
    )
    assert result.exit_code == 2 and "N x 3" in result.output
