"""The cubics the zoom proof (lensaudit.zooms) sums, worked out in arrays, are
those of lensaudit.interpolation.interval_terms (held to liblensfun's own
loop in tests/test_interpolation.py): the same terms, summed in the same
order, so the same numbers bit for bit."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from lensaudit import zooms
from lensaudit.interpolation import interval_terms
from lensaudit.pipeline import run
from lensaudit.read.paths import bundled_database_path
from lensaudit.read.records import MODEL_COEFFICIENTS


def _reference(sets, tables) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(Q, f0, f1) of every interval, term by term from interval_terms."""
    q, f0, f1 = [], [], []
    for found, table in zip(sets, tables, strict=True):
        for _, _, start, end, terms in interval_terms(found.focals):
            cubic = np.zeros((3, 4))
            for index, g in terms:
                scaled = np.zeros(3)
                row = [value * found.focals[index] for value in table[index]]
                scaled[: len(row)] = row
                np.add.at(cubic, (slice(None),), scaled[:, None] * np.asarray(g)[None, :])
            q.append(cubic)
            f0.append(found.focals[start])
            f1.append(found.focals[end])
    return np.asarray(q).reshape(-1, 3, 4), np.asarray(f0), np.asarray(f1)


def _assert_same(sets, tables) -> None:
    zooms._interval_slots.cache_clear()
    found = zooms._Intervals(sets, tables, 1.0)
    q, f0, f1 = _reference(sets, tables)
    assert np.array_equal(found.q, q) and np.array_equal(np.signbit(found.q), np.signbit(q))
    assert np.array_equal(found.f0, f0) and np.array_equal(found.f1, f1)


focal_lists = st.lists(
    st.one_of(
        st.sampled_from([10.0, 14.0, 18.0, 24.0, 35.0, 55.0]),  # repeats: second calibrations
        st.floats(1, 1000, allow_nan=False),
        st.sampled_from([math.inf, math.nan, -math.inf]),
    ),
    max_size=9,
)
coefficient = st.floats(-1e3, 1e3, allow_nan=False)


@st.composite
def calibration_sets(draw):
    sets, tables = [], []
    for _ in range(draw(st.integers(1, 4))):
        model = draw(st.sampled_from(sorted(MODEL_COEFFICIENTS)))
        focals = tuple(draw(focal_lists))
        width = len(MODEL_COEFFICIENTS[model])
        table = [tuple(draw(coefficient) for _ in range(width)) for _ in focals]
        sets.append(zooms.CalibrationSet(tuple(range(len(focals))), focals, model, 1.5, 1.8))
        tables.append(table)
    return sets, tables


@given(calibration_sets())
def test_the_cubics_in_arrays_are_those_of_interval_terms(drawn) -> None:
    _assert_same(*drawn)


def test_the_cubics_of_every_bundled_zoom_are_those_of_interval_terms() -> None:
    audit = run(bundled_database_path())
    sets = [s for s in zooms.calibration_sets(audit) if len(set(s.focals)) > 1]
    assert len(sets) > 500
    _assert_same(sets, [zooms.coefficient_table(s, audit.entries) for s in sets])


@given(
    st.lists(
        st.floats(min_value=0.5, max_value=1e6, allow_nan=False),
        min_size=2,
        max_size=8,
        unique=True,
    )
)
def test_the_sweep_takes_every_calibrated_focal_and_at_most_its_bound_between(focals):
    at = zooms.focal_samples(focals)
    low, high = min(focals), max(focals)
    assert at[0] == low and at[-1] == high and set(focals) <= set(at.tolist())
    assert len(at) <= zooms.MAX_SWEEP_SAMPLES + len(focals)
    steps = np.diff(at)
    # Every SWEEP_STEP mm where the range allows it, evenly spread beyond.
    bound = max(zooms.SWEEP_STEP, (high - low) / (zooms.MAX_SWEEP_SAMPLES - 1))
    assert steps.max() <= bound * (1 + 1e-9) + 4 * math.ulp(high)  # roundings of the sums


def test_fix_of_a_zoom_with_a_focal_length_mistyped_huge_ends(tmp_path):
    import subprocess
    import sys

    (tmp_path / "db.xml").write_text(
        '<lensdatabase version="2"><lens><maker>T</maker><model>Test 11-16</model>'
        "<mount>M</mount><cropfactor>1</cropfactor><calibration>"
        '<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>'
        '<distortion model="ptlens" focal="12" a="0.000" b="-0.042" c="0.041"/>'
        '<distortion model="ptlens" focal="110000" a="0.000" b="-0.042" c="0.041"/>'
        "</calibration></lens></lensdatabase>"
    )
    process = subprocess.run(
        [sys.executable, "-m", "lensaudit", "fix", "--no-cache", "-f", "csv", str(tmp_path)],
        capture_output=True,
        timeout=120,  # ten million focal lengths swept before: hours
    )
    assert process.returncode == 0, process.stderr
    assert b",T,Test 11-16,11.0,1.0,ptlens," in process.stdout
