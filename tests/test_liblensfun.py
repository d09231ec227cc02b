"""lensaudit's d_max against what liblensfun really does to pixels.

liblensfun's undistortion map sends each output (undistorted) pixel to the
source (distorted) pixel it is read from: the map is D itself. Along the
central row of an output wide enough to pass the fold, the source position
rises to D(r_max) and then falls back: its peak is d_max in pixels. A very
large virtual image keeps pixel-grid effects far below the 1% tolerance; only
that one row is computed.
"""

from __future__ import annotations

import numpy as np
import pytest

from lensaudit.pipeline import run

lensfunpy = pytest.importorskip("lensfunpy")

HEIGHT = 20_000  # pixels of the virtual image's short side


@pytest.fixture(scope="module")
def audit(bundled_db):
    return run(bundled_db)


@pytest.fixture(scope="module")
def lenses(liblensfun_lenses):
    return liblensfun_lenses


def central_row(lens, entry, scale):
    """(output x, source x) along the right half of the central row, in Hugin units."""
    width = round(HEIGHT * max(entry.aspect_ratio, 1 / entry.aspect_ratio))
    modifier = lensfunpy.Modifier(lens, entry.crop_factor, width, HEIGHT)
    modifier.initialize(
        entry.focal,
        lens.max_aperture or 2.8,
        scale=scale,
        flags=lensfunpy.ModifyFlags.DISTORTION | lensfunpy.ModifyFlags.SCALE,
    )
    row = modifier.apply_geometry_distortion(0, HEIGHT // 2, width, 1)[0].astype(np.float64)
    centre = (width - 1) / 2
    unit = (HEIGHT - 1) / 2
    output_x = (np.arange(width) - centre) / unit
    source_x = (row[:, 0] - centre) / unit
    right = output_x > 0
    return output_x[right], source_x[right]


def calibrated_once(audit):
    """Indices of entries liblensfun can reproduce: no other entry at the same focal."""
    keys = [(e.maker, e.lens, e.crop_factor, e.focal) for e in audit.entries]
    counts = {}
    for key in keys:
        counts[key] = counts.get(key, 0) + 1
    return {i for i, key in enumerate(keys) if counts[key] == 1}


def test_liblensfun_peaks_at_d_max_for_every_entry_that_folds_in_the_frame(audit, lenses):
    """Every entry whose D(r_max) lies inside the frame's corner, circular fisheyes included."""
    m = audit.metrics
    aspect = np.array([e.aspect_ratio for e in audit.entries])
    inside = np.isfinite(m.r_max) & (m.d_max < np.hypot(np.maximum(aspect, 1 / aspect), 1))
    folding = [i for i in np.flatnonzero(inside) if i in calibrated_once(audit)]
    assert len(folding) >= 5
    checked = _check_peaks(audit, lenses, folding)
    assert checked == len(folding)


def test_liblensfun_peaks_at_d_max_for_a_sample_of_finite_entries(audit, lenses):
    m = audit.metrics
    finite = sorted(
        set(np.flatnonzero(np.isfinite(m.r_max) & audit.audited)) & calibrated_once(audit)
    )
    sample = np.random.default_rng(7).choice(finite, 40, replace=False)
    assert _check_peaks(audit, lenses, sample.tolist()) >= 35


def test_liblensfun_never_folds_where_r_max_is_infinite(audit, lenses):
    m = audit.metrics
    infinite = sorted(
        set(np.flatnonzero(np.isinf(m.r_max) & audit.audited)) & calibrated_once(audit)
    )
    sample = np.random.default_rng(11).choice(infinite, 40, replace=False)
    checked = 0
    for i in sample.tolist():
        entry = audit.entries[i]
        lens = lenses.get((entry.maker, entry.lens, float(np.float32(entry.crop_factor))))
        if lens is None:
            continue
        # Out to r = 4 Hugin units, over twice the image corner. liblensfun works in
        # single precision: allow its rounding noise (1e-3 relative), far below a fold.
        _, source_x = central_row(lens, entry, scale=0.25)
        drop = np.maximum.accumulate(source_x) - source_x
        assert np.all(drop <= 1e-3 * np.abs(source_x)), f"{entry.file}:{entry.line}"
        checked += 1
    assert checked >= 35


def _check_peaks(audit, lenses, indices):
    m = audit.metrics
    checked = 0
    for i in indices:
        entry = audit.entries[i]
        lens = lenses.get((entry.maker, entry.lens, float(np.float32(entry.crop_factor))))
        if lens is None:
            continue
        scale = min(1.0, 0.8 / m.r_max[i])  # the output reaches 1.25 r_max
        output_x, source_x = central_row(lens, entry, scale)
        peak = source_x.max()
        assert peak == pytest.approx(m.d_max[i], rel=0.01), f"{entry.file}:{entry.line}"
        assert output_x[np.argmax(source_x)] * 1 / scale == pytest.approx(m.r_max[i], rel=0.05)
        checked += 1
    return checked
