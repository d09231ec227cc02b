"""lensaudit.zooms.between: every focal length between two calibrations
judged, not a sample of them, against liblensfun built from Lensfun master's
source (lf_lens_interpolate_distortion): a zoom whose neighbouring
calibrations both fold, one whose calibrations both clear the image corner
by 11% but fold in between (the spline overshoots), random zooms, and the
counts on the bundled database and the bundle's master."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lensaudit import zooms
from lensaudit.metrics import compute
from lensaudit.pipeline import run
from lensaudit.read.records import MODEL_COEFFICIENTS
from liblensfun_master import interpolate_distortion, lenses, library

CORNER = math.hypot(1.5, 1)


@pytest.fixture(scope="module", autouse=True)
def liblensfun():
    """Lensfun master's liblensfun; skips the module where it cannot be built."""
    return library()


def zoom_file(calibrations: list[tuple[float, tuple[float, float, float]]]) -> str:
    rows = "".join(
        f'<distortion model="ptlens" focal="{f!r}" a="{a!r}" b="{b!r}" c="{c!r}"/>'
        for f, (a, b, c) in calibrations
    )
    return (
        '<lensdatabase version="2"><lens><maker>Test</maker><model>Zoom</model>'
        "<mount>Test</mount><cropfactor>1.5</cropfactor>"
        f"<calibration>{rows}</calibration></lens></lensdatabase>"
    )


def judged(tmp_path, calibrations) -> tuple[list[zooms.Between], dict]:
    path = tmp_path / "zoom.xml"
    path.write_text(zoom_file(calibrations))
    audit = run(str(path))
    (found,) = zooms.calibration_sets(audit)
    coefficients = [tuple(v for v in values) for _, values in calibrations]
    (lens,) = lenses(path.read_bytes())
    return zooms.between(found, coefficients), lens


def liblensfun_r_normalized(lens: dict, focals: np.ndarray) -> np.ndarray:
    """r_normalized of the models liblensfun master applies at ``focals``."""
    terms = np.array([interpolate_distortion(lens, 1.5, float(f))[1][:3] for f in focals])
    count = len(focals)
    nan = np.full(count, math.nan)
    found = compute(["ptlens"] * count, terms[:, 0], terms[:, 1], terms[:, 2], nan, nan,
                    np.ones(count), np.full(count, 1.5), np.ones(count),
                    np.ones(count, dtype=bool))  # fmt: skip
    return np.asarray(found.d_max) / CORNER


#: Both clear the image corner by 11-13%; the 20 mm calibration bends the spline.
OVERSHOOT = [
    (10.0, (-0.0216, 0.0348, -0.0408)),
    (11.0, (-0.0238, 0.0404, -0.0404)),
    (20.0, (0.3135, 0.0292, -0.8963)),
]
#: Both neighbouring calibrations fold.
ADJACENT = [
    (10.0, (-0.026, -0.002, 0.005)),
    (11.0, (-0.024, -0.002, 0.005)),
    (20.0, (0.02, -0.01, 0.01)),
]


def test_two_calibrations_that_clear_the_image_yet_fold_in_between(tmp_path):
    found, lens = judged(tmp_path, OVERSHOOT)
    ends = liblensfun_r_normalized(lens, np.array([10.0, 11.0]))
    assert np.all(ends > 1.1)  # each calibration clears the corner by 11% or more
    first, second = found
    assert first.verdict == zooms.FOLDS and 10 < first.focal < 11
    assert liblensfun_r_normalized(lens, np.array([first.focal]))[0] < 1
    assert second.verdict == zooms.CLEAR
    swept = liblensfun_r_normalized(lens, np.round(np.arange(1100, 2001) / 100, 2))
    assert swept.min() >= 1 - 1e-4  # proven clear: no focal length of 11-20 mm folds


def test_two_neighbouring_calibrations_that_fold(tmp_path):
    found, lens = judged(tmp_path, ADJACENT)
    assert found[0].verdict == zooms.FOLDS and 10 < found[0].focal < 11
    assert liblensfun_r_normalized(lens, np.array([found[0].focal]))[0] < 1


coefficient = st.floats(-0.06, 0.06, allow_nan=False)
far = st.floats(-0.6, 0.6, allow_nan=False)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.lists(st.floats(4, 60).map(lambda f: round(f, 1)), min_size=2, max_size=4, unique=True),
    st.lists(st.tuples(coefficient, coefficient, coefficient), min_size=4, max_size=4),
    st.tuples(far, far, far),
)
def test_every_verdict_is_what_liblensfun_does(tmp_path_factory, focals, values, outlier):
    calibrations = [(f, v) for f, v in zip(sorted(focals), values, strict=False)]
    calibrations[-1] = (calibrations[-1][0], outlier)  # one far calibration bends the spline
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning on the way
        found, lens = judged(tmp_path_factory.mktemp("zoom"), calibrations)
    for interval in found:
        if interval.verdict == zooms.FOLDS:
            at = np.array([interval.focal])
            assert liblensfun_r_normalized(lens, at)[0] < 1 + 1e-4
        elif interval.verdict == zooms.CLEAR:
            steps = np.linspace(interval.low, interval.high, 301)
            assert liblensfun_r_normalized(lens, steps).min() >= 1 - 1e-4


@pytest.mark.parametrize("database, intervals", [("bundled", 4430), ("master", 4903)])
def test_no_real_zoom_folds_where_no_calibration_does(database, intervals, bundled_db, request):
    # docs/fix.md quotes these counts.
    source = bundled_db if database == "bundled" else request.getfixturevalue("lensfun_head")
    audit = run(str(source))
    verdicts = []
    for found in zooms.calibration_sets(audit):
        if len(set(found.focals)) < 2:
            continue
        names = MODEL_COEFFICIENTS[found.model]
        coefficients = [tuple(getattr(audit.entries[i], n) for n in names) for i in found.indices]
        folding = {
            audit.entries[i].focal for i in found.indices if audit.metrics.r_normalized[i] < 1
        }
        for interval in zooms.between(found, coefficients):
            verdicts.append((interval.verdict, bool({interval.low, interval.high} & folding)))
    assert (zooms.UNDECIDED, False) not in verdicts
    # Folds between calibrations only next to a calibration that folds itself (3 of them).
    assert [v for v in verdicts if v[0] == zooms.FOLDS] == [(zooms.FOLDS, True)] * 3
    assert len(verdicts) == intervals
