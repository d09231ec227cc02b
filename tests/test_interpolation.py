"""lensaudit.interpolation against liblensfun built from Lensfun master's
source: the coefficients lf_lens_interpolate_distortion gives between
calibrated focal lengths, for every model, with neighbours on one side or
both, unsorted and repeated focal lengths, and outside the calibrated range."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lensaudit.interpolation import interpolated, interval_terms, spline_terms, weights
from liblensfun_master import interpolate_distortion, lenses, library

NAMES = {"ptlens": ("a", "b", "c"), "poly3": ("k1",), "poly5": ("k1", "k2")}


@pytest.fixture(scope="module", autouse=True)
def liblensfun():
    """Lensfun master's liblensfun; skips the module where it cannot be built."""
    return library()


def lens_file(model: str, calibrations: list[tuple[float, tuple[float, ...]]]) -> bytes:
    rows = "".join(
        f'<distortion model="{model}" focal="{focal!r}" '
        + " ".join(f'{n}="{v!r}"' for n, v in zip(NAMES[model], values, strict=True))
        + "/>"
        for focal, values in calibrations
    )
    return (
        '<lensdatabase version="2"><lens><maker>M</maker><model>Zoom</model>'
        "<mount>Test</mount><cropfactor>1.5</cropfactor>"
        f"<calibration>{rows}</calibration></lens></lensdatabase>"
    ).encode()


def compare(model: str, calibrations: list[tuple[float, tuple[float, ...]]], focal: float):
    (lens,) = lenses(lens_file(model, calibrations))
    found = interpolate_distortion(lens, 1.5, focal)
    assert found is not None and found[0] == model
    ours = interpolated([values for _, values in calibrations], [f for f, _ in calibrations], focal)
    scale = max(1e-3, *(abs(v) for _, values in calibrations for v in values))
    # liblensfun computes in single precision.
    assert found[1][: len(ours)] == pytest.approx(ours, abs=2e-6 * scale * 20), focal


@pytest.mark.parametrize("model", sorted(NAMES))
def test_a_zoom_is_interpolated_as_liblensfun_does(model):
    count = len(NAMES[model])
    calibrations = [
        (10.0, tuple(0.01 * (i + 1) for i in range(count))),
        (11.0, tuple(-0.02 * (i + 1) for i in range(count))),
        (20.0, tuple(0.005 * (i + 2) for i in range(count))),
        (35.0, tuple(-0.001 * (i + 3) for i in range(count))),
    ]
    for focal in (8.0, 10.0, 10.25, 10.62, 11.0, 12.5, 19.9, 27.0, 34.99, 35.0, 50.0):
        compare(model, calibrations, focal)


focal_lengths = st.floats(4, 200, allow_nan=False).map(lambda f: round(f, 2))
coefficient = st.floats(-0.25, 0.25, allow_nan=False, width=32)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.lists(st.tuples(focal_lengths, st.tuples(coefficient, coefficient, coefficient)),
             min_size=1, max_size=6),
    focal_lengths,
)  # fmt: skip
def test_any_calibrations_in_any_order_are_interpolated_as_liblensfun_does(calibrations, focal):
    compare("ptlens", calibrations, focal)


def test_the_weights_of_a_calibrated_focal_length_are_its_own():
    assert weights([20.0, 10.0, 10.0], 10.0) == [(1, 1.0)]
    assert weights([], 10.0) == []
    # Between two calibrations with no neighbour outside, the spline is a line of k x focal.
    (low, w_low), (high, w_high) = weights([10.0, 20.0], 15.0)
    assert (low, high) == (0, 1) and (w_low, w_high) == pytest.approx((1 / 3, 2 / 3))


def test_repeated_focal_lengths_are_taken_in_liblensfuns_order():
    calibrations = [
        (20.0, (0.01, -0.02, 0.03)),
        (10.0, (0.02, 0.01, -0.01)),
        (15.0, (-0.01, 0.02, 0.01)),
        (10.0, (0.05, -0.04, 0.02)),
        (20.0, (-0.03, 0.01, 0.04)),
        (30.0, (0.0, 0.01, -0.02)),
    ]
    for focal in (12.0, 17.5, 25.0):
        compare("ptlens", calibrations, focal)


def liblensfun_slots(focals: list[float], focal: float) -> list[int | None]:
    """lfLens::InterpolateDistortion's four slots, its loop transcribed: two
    calibrations above the focal length (slot 1 the nearest), two below
    (slot 2 the nearest), by strict comparison in the order met."""
    slots: list[int | None] = [None] * 4
    distances = [-math.inf, -math.inf, math.inf, math.inf]
    for index, calibrated in enumerate(focals):
        distance = focal - calibrated
        if distance < 0:
            if distance > distances[1]:
                slots[0], distances[0] = slots[1], distances[1]
                slots[1], distances[1] = index, distance
            elif distance > distances[0]:
                slots[0], distances[0] = index, distance
        elif distance > 0:
            if distance < distances[2]:
                slots[3], distances[3] = slots[2], distances[2]
                slots[2], distances[2] = index, distance
            elif distance < distances[3]:
                slots[3], distances[3] = index, distance
    return slots


@settings(max_examples=500, deadline=None)
@given(
    st.lists(st.sampled_from([8.0, 10.0, 12.0, 18.0, 24.0, 35.0, 55.0]), min_size=2, max_size=9),
    st.floats(6.0, 60.0),
)
def test_the_spline_takes_the_calibrations_liblensfuns_loop_takes(focals, focal):
    """Repeated focal lengths included: the first met is the nearest, the
    second fills the outer slot, as liblensfun's strict comparisons have it."""
    start, end, terms = spline_terms(focals, focal)
    slots = liblensfun_slots(focals, focal)
    if focal in focals or None in (slots[1], slots[2]):
        return  # one calibration applies, checked by the tests above
    assert (start, end) == (slots[1], slots[2])
    used = {index for index, _ in terms}
    expected = {slots[1], slots[2]} | {s for s in (slots[0], slots[3]) if s is not None}
    assert used == expected


@settings(max_examples=300, deadline=None)
@given(st.lists(st.sampled_from([8.0, 10.0, 12.0, 18.0, 24.0, 35.0, 55.0]), min_size=2, max_size=9))
def test_every_interval_at_once_is_what_the_spline_takes_at_its_middle(focals):
    for low, high, start, end, terms in interval_terms(focals):
        assert (start, end, terms) == spline_terms(focals, (low + high) / 2)
    assert len(interval_terms(focals)) == len(set(focals)) - 1


def test_no_calibration_interpolates_to_nothing_and_mismatches_are_refused():
    assert weights([], 10.0) == [] and interpolated([], [], 10.0) == ()
    with pytest.raises(ValueError, match="1 sequences of coefficients for 2 focal lengths"):
        interpolated([[0.1]], [10.0, 20.0], 15.0)
    for focal in (0.0, -5.0, math.nan):
        with pytest.raises(ValueError, match="is not a positive number"):
            weights([10.0, 20.0], focal)
