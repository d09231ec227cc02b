"""Refitted models as liblensfun itself applies them, from the patched database files.

liblensfun's undistortion map sends each output (undistorted) pixel to the
source (distorted) pixel it is read from; along the image diagonal its
distance from the centre is D(r) in pixels. After ``fix`` has written a
copy of the bundled database, that map must rise monotonically up to the
target radius, and differ from the original database's map by no more than
the change ``fix`` reported (converted from its 6000x4000 frame to the image
used here), while reaching that change somewhere on the diagonal.
"""

from __future__ import annotations

import math
import shutil
from fractions import Fraction

import numpy as np
import pytest

from lensaudit import fix
from lensaudit.pipeline import run
from lensaudit.xmlpatch import write

lensfunpy = pytest.importorskip("lensfunpy")

SHORT_SIDE = 4000  # pixels, about; adjusted so that the aspect ratio is exact
SAMPLES = 600  # points along the half diagonal
#: liblensfun computes in single precision: about 1e-7 of 4000 px per step.
NOISE_PX = 0.01
#: r_normalized below which `lensaudit check` warns, the margin fix reaches.
CHECK_MARGIN = 1.1


@pytest.fixture(scope="module")
def databases(bundled_db, tmp_path_factory):
    """(original database, patched database, results, flagged): every fold refitted and
    written, and the (file, line) of the entries `scan` flags in the original."""
    original = tmp_path_factory.mktemp("original") / "db"
    shutil.copytree(bundled_db, original)
    patched = tmp_path_factory.mktemp("patched") / "db"
    shutil.copytree(bundled_db, patched)
    results, patches = fix.fix(str(patched), tolerance=math.inf)
    for patch in patches:
        write(patch)

    def open_database(directory):
        files = [str(p) for p in sorted(directory.glob("*.xml"))]
        database = lensfunpy.Database(paths=files, load_common=False, load_bundled=False)
        return {
            (lens.maker.strip(), lens.model.strip(), float(np.float32(lens.crop_factor))): lens
            for lens in reversed(database.lenses)  # the first of equal keys wins
        }

    audit = run(str(original))
    flagged = {
        (e.file, e.line)
        for e, r_max, r_normalized in zip(
            audit.entries, audit.metrics.r_max, audit.metrics.r_normalized, strict=True
        )
        if math.isfinite(r_max) and r_normalized < CHECK_MARGIN
    }
    return open_database(original), open_database(patched), results, flagged


def frame(aspect_ratio: float) -> tuple[int, int]:
    """Width and height whose (W - 1) / (H - 1) is exactly the aspect ratio.

    liblensfun measures an image between the centres of its border pixels.
    """
    ratio = Fraction(aspect_ratio).limit_denominator(100)
    short = ratio.denominator * round(SHORT_SIDE / ratio.denominator)
    return int(short * ratio) + 1, short + 1


def diagonal(
    lens, entry, reach: float = 1.0, size: tuple[int, int] | None = None
) -> tuple[np.ndarray, float]:
    """Where along the half diagonal its source pixels are read, and pixels per Hugin unit.

    Positions are signed distances from the centre along the diagonal: D(r),
    which a model that folds takes back through the centre. ``reach`` is how
    far along the half diagonal to go (1: to the corner). ``size``: the
    image's width and height in pixels, by default a frame of the entry's
    own aspect ratio.
    """
    width, height = size or frame(entry.aspect_ratio)
    modifier = lensfunpy.Modifier(lens, entry.crop_factor, width, height)
    modifier.initialize(
        entry.focal, lens.max_aperture or 2.8, scale=1.0, flags=lensfunpy.ModifyFlags.DISTORTION
    )
    centre_x, centre_y = (width - 1) / 2, (height - 1) / 2
    length = math.hypot(centre_x, centre_y)
    positions = []
    for t in np.linspace(0.0, reach, SAMPLES):
        x, y = centre_x * (1 + t), centre_y * (1 + t)
        source = modifier.apply_geometry_distortion(x, y, 1, 1)[0, 0].astype(np.float64)
        along = (source[0] - centre_x) * centre_x + (source[1] - centre_y) * centre_y
        positions.append(along / length)
    return np.array(positions), (height - 1) / 2


def lens_of(lenses, entry):
    lens = lenses.get((entry.maker, entry.lens, float(np.float32(entry.crop_factor))))
    assert lens is not None, f"{entry.file}:{entry.line}: lens not found by liblensfun"
    return lens


def test_every_fold_below_checks_margin_was_refitted(databases):
    _, _, results, flagged = databases
    assert {(r.entry.file, r.entry.line) for r in results} == flagged
    assert len(results) >= 4
    assert all(r.status == fix.STATUS_FIXED for r in results)


def up_to_target(result) -> float:
    """How far along the half diagonal the fixed model must increase: to its target."""
    corner = math.hypot(max(result.entry.aspect_ratio, 1 / result.entry.aspect_ratio), 1)
    return min(1.0, result.goal.target / corner)


def test_liblensfun_undistorts_monotonically_up_to_the_target_after_the_fix(databases):
    _, patched, results, _ = databases
    for result in results:
        entry = result.entry
        radii, _ = diagonal(lens_of(patched, entry), entry, up_to_target(result))
        assert np.all(np.diff(radii) > 0), result.where


def test_liblensfun_folds_before_the_margin_without_the_fix(databases):
    original, _, results, _ = databases
    folded = 0
    for result in results:
        radii, unit = diagonal(lens_of(original, result.entry), result.entry, CHECK_MARGIN)
        # The old model turns back before its source reaches margin x the image's radius.
        folded += bool(radii.max() < CHECK_MARGIN * result.goal.r_corner * unit)
    assert folded == len(results)


def test_liblensfun_moves_pixels_by_no_more_than_the_reported_change(databases):
    original, patched, results, _ = databases
    for result in results:
        entry = result.entry
        # The change is reported within the image's radius (the corner, or an
        # image circle); the diagonal is followed that far.
        corner = math.hypot(max(entry.aspect_ratio, 1 / entry.aspect_ratio), 1)
        within = min(1.0, result.goal.r_corner / corner)
        old, unit = diagonal(lens_of(original, entry), entry, within)
        new, _ = diagonal(lens_of(patched, entry), entry, within)
        # The frame's half diagonal is corner x unit pixels.
        reported = result.max_change_half_diagonal * corner * unit
        difference = np.abs(new - old)
        assert difference.max() <= reported + NOISE_PX, result.where
        # ... and reaches it: the largest change lies on the diagonal, sampled finely.
        assert difference.max() >= 0.99 * reported - NOISE_PX, result.where


def test_the_reported_change_is_liblensfuns_on_a_6000x4000_frame(databases):
    """The change is reported in pixels of a 6000x4000 frame as liblensfun
    applies the model to it, whatever the aspect ratio it was calibrated at
    (liblensfun matches the diagonals): within 1% of what its Modifier moves
    the pixels on the diagonal of such a frame (6001 x 4001 pixel centres)."""
    original, patched, results, _ = databases
    aspects = set()
    for result in results:
        entry = result.entry
        corner = math.hypot(max(entry.aspect_ratio, 1 / entry.aspect_ratio), 1)
        within = min(1.0, result.goal.r_corner / corner)
        old, _ = diagonal(lens_of(original, entry), entry, within, (6001, 4001))
        new, _ = diagonal(lens_of(patched, entry), entry, within, (6001, 4001))
        largest = float(np.abs(new - old).max())
        assert largest == pytest.approx(result.max_change_px, rel=0.01, abs=NOISE_PX), result.where
        aspects.add(round(entry.aspect_ratio, 3))
    assert {1.333, 1.5} <= aspects  # 4:3 calibrations among them, as the P30 Pro's
