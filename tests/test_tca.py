"""The TCA audit: records, r_fold per channel against sympy and mpmath, outputs.

r_d(r) = r (b r^2 + c r + v) folds where r_d'(r) = v + 2 c r + 3 b r^2
first changes sign from + to -. References: sympy's exact root counts on the
rationals the decimal strings denote, mpmath at high precision for values,
and for whole databases numpy dense sampling with a proven bound.
"""

from __future__ import annotations

import math
import warnings

import mpmath
import numpy as np
import pytest
import sympy
from hypothesis import example, given, settings
from hypothesis import strategies as st
from lxml import etree

from conftest import lens_xml
from lensaudit import calibrations, tca
from lensaudit.check.rules import tca_fold_in_image as tca_rule

R = sympy.Symbol("r")


# --- the reference ---------------------------------------------------------


def reference(v: str, c: str, b: str, r_corner: str) -> dict:
    """r_fold of r (b r^2 + c r + v) and whether it is below r_corner, exactly.

    r_fold is 0 when r_d' is negative just right of 0 (or r_d is 0), else the
    first root > 0 where r_d' changes sign (from + to -), inf if none.
    """
    qv, qc, qb = (sympy.Rational(x) for x in (v, c, b))
    limit = sympy.Rational(r_corner)
    slope = sympy.Poly(qv + 2 * qc * R + 3 * qb * R**2, R)
    first = next((x for x in (qv, qc, qb) if x != 0), sympy.Integer(0))
    if first <= 0:
        return {"r_fold": 0.0, "folds": True}
    if slope.degree() <= 0:
        return {"r_fold": math.inf, "folds": False}
    _, factors = slope.sqf_list()
    odd = sympy.Poly(1, R)
    for factor, times in factors:
        if times % 2:
            odd *= factor
    if odd.degree() <= 0 or odd.count_roots(0, None) == odd.count_roots(0, 0):
        return {"r_fold": math.inf, "folds": False}
    inside = odd.count_roots(0, limit) - (odd.eval(0) == 0) - (odd.eval(limit) == 0)
    index = odd.count_roots(None, 0)
    with mpmath.workdps(60):
        value = float(sympy.N(sympy.CRootOf(odd, index), 30))
    return {"r_fold": value, "folds": inside > 0}


def computed(v: str, c: str, b: str, r_corner: float) -> tuple[float, bool]:
    radius, folds = tca.r_fold([float(v)], [float(c)], [float(b)], [r_corner])
    return float(radius[0]), bool(folds[0])


def assert_matches(v: str, c: str, b: str, r_corner: float = math.hypot(1.5, 1)) -> None:
    got_radius, got_folds = computed(v, c, b, r_corner)
    want = reference(v, c, b, repr(r_corner))
    where = f"v, c, b = {v}, {c}, {b}; r_corner {r_corner}"
    assert got_folds == want["folds"], where
    assert got_radius == pytest.approx(want["r_fold"], rel=1e-10), where


# --- records ---------------------------------------------------------------


def test_every_tca_element_of_the_bundled_database_is_one_record(bundled_db):
    expected = []
    for path in sorted(bundled_db.glob("*.xml")):
        root = etree.parse(str(path)).getroot()
        expected += [(path.name, element.sourceline) for element in root.iter("tca")]
    records = tca_records(calibrations.load(bundled_db))
    assert [(e.file, e.line) for e in records] == expected
    assert len(expected) > 3000
    assert {e.status for e in records} == {"ok"}


def tca_records(database) -> calibrations.CalibrationRecords:
    """The <tca> records of a database read with its calibrations."""
    return calibrations.CalibrationRecords("tca", *database.rows("tca"))


def load_one(write_xml, element: str, **lens):
    (entry,) = tca_records(calibrations.load(write_xml(lens_xml(element, **lens))))
    return entry


def test_missing_poly3_coefficients_take_liblensfuns_defaults(write_xml):
    entry = load_one(write_xml, '<tca model="poly3" focal="10"/>')
    assert (entry.vr, entry.vb, entry.cr, entry.cb, entry.br, entry.bb) == (1, 1, 0, 0, 0, 0)
    assert entry.status == "ok" and math.isnan(entry.kr)


def test_a_linear_entry_reads_kr_and_kb(write_xml):
    entry = load_one(write_xml, '<tca model="linear" focal="10" kr="1.0002"/>')
    assert (entry.kr, entry.kb, entry.status) == (1.0002, 1.0, "ok")
    assert math.isnan(entry.vr)


def test_a_tca_record_carries_the_calibration_overrides(write_xml):
    entry = load_one(
        write_xml,
        '<tca model="poly3" focal="10" vr="1.001" br="-0.002"/>',
        calibration=' cropfactor="1.6" aspect-ratio="4:3"',
    )
    assert (entry.crop_factor, entry.aspect_ratio, entry.vr, entry.br) == (
        1.6,
        4 / 3,
        1.001,
        -0.002,
    )


@pytest.mark.parametrize(
    "element, status, words",
    [
        ('<tca model="poly3" vr="1"/>', "missing_attribute", "focal"),
        ('<tca model="acm" focal="10" alpha0="1"/>', "unknown_model", "acm"),
        ('<tca model="poly3" focal="10" vr="1,0"/>', "bad_value", "vr"),
        ('<tca model="linear" focal="0" kr="1"/>', "bad_value", "focal"),
    ],
)
def test_a_bad_tca_element_is_a_record_with_a_status_and_why(write_xml, element, status, words):
    entry = load_one(write_xml, element)
    assert entry.status == status and words in entry.message


# --- r_fold against sympy --------------------------------------------------


def test_a_negative_cubic_term_folds_where_the_slope_vanishes():
    # r_d' = 1 - 0.6 r^2 vanishes at r = sqrt(1 / 0.6) = 1.29, inside a 3:2 frame.
    radius, folds = computed("1", "0", "-0.2", math.hypot(1.5, 1))
    assert folds and radius == pytest.approx(math.sqrt(1 / 0.6), rel=1e-15)
    assert_matches("1", "0", "-0.2")


def test_a_channel_shrinking_from_the_centre_folds_at_once():
    assert computed("-1", "0", "0", 1.8) == (0.0, True)
    assert computed("0", "-0.1", "1", 1.8) == (0.0, True)
    assert computed("0", "0", "0", 1.8) == (0.0, True)


def test_a_fold_exactly_at_the_corner_is_not_inside():
    # r_d' = 3 - 0.75 r^2 vanishes at r = 2, the corner itself.
    assert computed("3", "0", "-0.25", 2.0) == (2.0, False)
    assert computed("3", "0", "-0.25", 2.0000000001)[1]
    assert_matches("3", "0", "-0.25", 2.0)


def test_a_linear_model_never_folds_unless_k_is_not_positive():
    result = tca.compute(
        ["linear", "linear"], [1.0003, 1.0], [0.9998, -0.5], *[[np.nan] * 2] * 6, [1.8, 1.8]
    )
    assert result["r_fold_red"].tolist() == [math.inf, math.inf]
    assert result["r_fold_blue"].tolist() == [math.inf, 0.0]
    assert result["folds_in_image"].tolist() == [False, True]


@pytest.mark.parametrize(
    "v, c, b",
    [
        ("0.9994318", "0.0018212", "-0.0008996"),  # Panasonic FZ150, red
        ("1.0001793", "0.0043072", "-0.0027042"),  # Panasonic FZ150, blue
        ("1", "-0.6", "0.1"),  # two turns: falls, then rises
        ("1", "0.5", "-0.1"),
        ("1", "0", "0"),
        ("1e-6", "-1e-3", "1"),
    ],
)
def test_hand_made_and_real_channels_match_sympy(v, c, b):
    assert_matches(v, c, b)
    assert_matches(v, c, b, 1.0)


corners = st.sampled_from([math.hypot(1.5, 1), math.hypot(4 / 3, 1), math.hypot(16 / 9, 1), 1.0])
near_one = st.decimals(min_value="0.9", max_value="1.1", places=6).map(str)
small = st.decimals(min_value="-0.6", max_value="0.6", places=6).map(str)


@settings(max_examples=150, deadline=None)
@given(near_one, small, small, corners)
def test_any_decimal_channel_matches_sympy(v, c, b, corner):
    assert_matches(v, c, b, corner)


finite_doubles = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=200, deadline=None)
@given(finite_doubles, finite_doubles, finite_doubles, corners)
@example(1.0, 1e300, -1e300, 1.8)
@example(5e-324, -1e-300, 1e-300, 1.0)
def test_any_finite_doubles_give_the_exact_fold_and_no_warning(v, c, b, corner):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        radius, folds = computed(repr(v), repr(c), repr(b), corner)
    want = reference(repr(v), repr(c), repr(b), repr(corner))
    assert folds == want["folds"]
    assert radius == pytest.approx(want["r_fold"], rel=1e-9)


# --- whole databases -------------------------------------------------------


def independent_folds(audit, points: int = 2001) -> list[bool]:
    """folds_in_image per audited entry by dense sampling of r_d' on [0, r_corner].

    A sign change between samples whose signs rounding cannot flip is certain;
    without one, r_d' can change sign between samples only where some sample
    comes within max|r_d''| h of zero: those entries are decided by sympy.
    """
    out = []
    for entry, corner in zip(audit.entries, audit.metrics["r_corner"].tolist(), strict=True):
        if entry.status != "ok":
            continue
        channels = (
            [(entry.kr, 0.0, 0.0), (entry.kb, 0.0, 0.0)]
            if entry.model == "linear"
            else [(entry.vr, entry.cr, entry.br), (entry.vb, entry.cb, entry.bb)]
        )
        folds = False
        for v, c, b in channels:
            r = np.linspace(0.0, corner, points)
            slope = v + 2 * c * r + 3 * b * r**2
            rounding = 1e-12 * (abs(v) + abs(c) + abs(b))
            signs = np.where(np.abs(slope) > rounding, np.sign(slope), 0)
            if signs[0] < 0 or (signs[:-1] * signs[1:] < 0).any():
                folds = True  # decreasing at once, or a certain turn inside (0, r_corner)
                continue
            bound = 6 * abs(b) * corner / (points - 1) + rounding
            if signs[0] == 0 or np.abs(slope).min() <= bound:
                folds = folds or reference(repr(v), repr(c), repr(b), repr(corner))["folds"]
        out.append(bool(folds))
    return out


def test_no_bundled_tca_entry_folds_by_an_independent_computation(bundled_db):
    audit = tca.audit(bundled_db)
    ok = np.array(audit.audited)
    assert audit.metrics["folds_in_image"][ok].tolist() == independent_folds(audit)
    assert audit.summary()["folds_in_image"] == 0


def test_bundled_r_fold_values_match_mpmath(bundled_db):
    audit = tca.audit(bundled_db)
    for index, entry in enumerate(audit.entries):
        if entry.model != "poly3":
            continue
        for channel, (v, c, b) in (
            ("red", (entry.vr, entry.cr, entry.br)),
            ("blue", (entry.vb, entry.cb, entry.bb)),
        ):
            with mpmath.workdps(50):
                mv, mc, mb = (mpmath.mpf(repr(x)) for x in (v, c, b))
                roots = []
                if mb != 0:
                    disc = mc * mc - 3 * mv * mb
                    if disc > 0:
                        roots = [(-mc + e * mpmath.sqrt(disc)) / (3 * mb) for e in (-1, 1)]
                elif mc != 0:
                    roots = [-mv / (2 * mc)]
                positive = sorted(x for x in roots if x > 0)
                want = float(positive[0]) if positive and mv > 0 else math.inf
            got = audit.metrics[f"r_fold_{channel}"][index]
            assert got == pytest.approx(want, rel=1e-12), f"{entry.file}:{entry.line} {channel}"


def test_no_tca_entry_of_lensfun_head_folds_by_an_independent_computation(lensfun_head):
    audit = tca.audit(lensfun_head)
    ok = np.array(audit.audited)
    assert audit.metrics["folds_in_image"][ok].tolist() == independent_folds(audit)
    assert ok.sum() == len(audit.entries) > 3700


# --- findings --------------------------------------------------------------


def test_findings_name_the_folding_channel(write_xml):
    path = write_xml(
        lens_xml(
            '<tca model="poly3" focal="10" vr="1" br="-0.2" vb="1"/>',
            '<tca model="poly3" focal="20" vr="1.0002" vb="0.9998"/>',
            '<tca model="poly3" focal="30" vb="-1"/>',
            '<tca model="poly3"/>',
        )
    )
    found = tca_rule.findings(tca.audit(path.parent).records())
    assert [(severity, code, line) for severity, code, _, line, _ in found] == [
        ("error", "tca-fold-in-image", 10),
        ("error", "tca-fold-in-image", 12),
        ("error", "missing-attribute", 13),
    ]
    assert "red channel's r_d peaks at r = 1.291" in found[0][4]
    assert "blue channel's r_d decreases from the centre" in found[1][4]
