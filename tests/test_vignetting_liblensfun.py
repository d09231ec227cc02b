"""liblensfun's own vignetting correction (lensfunpy) agrees with the audit's C(r).

A flat image of ones, corrected by liblensfun at an entry's focal length,
aperture and distance, holds 1 / C(r) at each pixel, with r = 1 on the corner
pixels: that fixes the unit the audit uses. Where the audit finds C <= 0
inside the frame, liblensfun cannot correct: the pixels go black (it clamps
the negative gain to 0) or blow up near the zero.
"""

from __future__ import annotations

import numpy as np
import pytest

from lensaudit import vignetting

lensfunpy = pytest.importorskip("lensfunpy")

WIDTH, HEIGHT = 600, 400  # 3:2, as Lensfun's default aspect ratio


@pytest.fixture(scope="module")
def audit(bundled_db):
    return vignetting.audit(bundled_db)


def corrected(liblensfun_lenses, entry) -> np.ndarray:
    """liblensfun's correction of a flat image of ones, for one entry (one channel)."""
    lens = liblensfun_lenses[(entry.maker, entry.lens, float(np.float32(entry.crop_factor)))]
    terms = lens.interpolate_vignetting(entry.focal, entry.aperture, entry.distance).terms
    # At a calibration point liblensfun interpolates nothing: the entry's own terms.
    assert terms == pytest.approx([entry.k1, entry.k2, entry.k3], rel=1e-6)
    modifier = lensfunpy.Modifier(lens, entry.crop_factor, WIDTH, HEIGHT)
    modifier.initialize(
        entry.focal,
        entry.aperture,
        entry.distance,
        pixel_format=np.float32,
        flags=lensfunpy.ModifyFlags.VIGNETTING,
    )
    image = np.ones((HEIGHT, WIDTH, 3), dtype=np.float32)
    assert modifier.apply_color_modification(image)
    return image[:, :, 1].astype(np.float64)


def pixel_radius() -> np.ndarray:
    """Each pixel's radius with r = 1 on the corner pixels' centres."""
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH]
    half_diagonal = np.hypot(WIDTH - 1, HEIGHT - 1) / 2
    return np.hypot(x - (WIDTH - 1) / 2, y - (HEIGHT - 1) / 2) / half_diagonal


def c_of(entry) -> np.ndarray:
    return vignetting.evaluate(entry.k1, entry.k2, entry.k3, pixel_radius())


def entries_with(audit, severity: str) -> list:
    return [
        entry
        for entry, found in zip(audit.entries, audit.metrics["severity"].tolist(), strict=True)
        if found == severity and "circular" not in entry.lens.lower()
    ]


def test_liblensfun_divides_by_c_with_r_one_at_the_corner(audit, liblensfun_lenses):
    for entry in entries_with(audit, "")[::2000] + entries_with(audit, "notice")[::500]:
        c = c_of(entry)
        gain = corrected(liblensfun_lenses, entry)
        # float32 arithmetic and an incremental r^2 in liblensfun: 1e-3 relative.
        assert np.max(np.abs(gain * c - 1)) < 1e-3, f"{entry.file}:{entry.line}"


def test_where_c_is_negative_liblensfun_writes_black(audit, liblensfun_lenses):
    errors = entries_with(audit, "error")
    assert errors
    for entry in errors:
        c = c_of(entry)
        gain = corrected(liblensfun_lenses, entry)
        negative = c < -1e-3
        assert negative.any(), f"{entry.file}:{entry.line}: no pixel with C < 0"
        assert np.all(gain[negative] == 0), f"{entry.file}:{entry.line}"


def test_near_the_zero_of_c_the_correction_explodes(audit, liblensfun_lenses):
    # The Canon EF 8-15 at 8 mm f/4: C crosses zero at r = 0.648 of the half diagonal.
    entry = next(e for e in entries_with(audit, "error") if "8-15" in e.lens and e.focal == 8)
    c = c_of(entry)
    gain = corrected(liblensfun_lenses, entry)
    small = (c > 0) & (c < 0.01)
    assert small.any()
    assert np.all(gain[small] > 50)


def test_the_largest_gain_is_one_over_c_min(audit, liblensfun_lenses):
    warnings = entries_with(audit, "warning")
    assert warnings
    for entry in warnings[::10]:
        index = audit.entries.index(entry)
        c_min = audit.metrics["c_min"][index]
        gain = corrected(liblensfun_lenses, entry)
        # The pixel grid samples C near its minimum (at worst 1/720 of r away).
        assert gain.max() == pytest.approx(1 / c_min, rel=2e-3), f"{entry.file}:{entry.line}"
