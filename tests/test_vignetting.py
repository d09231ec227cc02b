"""The vignetting audit: records, C(r) metrics against sympy, counts, outputs.

References come from sympy on the coefficients as the database writes them
(rationals from the decimal strings), and, for whole databases, from numpy
dense sampling with a proven error bound, every doubtful entry confirmed
with sympy. Nothing here is computed by the code under test.
"""

from __future__ import annotations

import io
import math
import os
import re
import warnings
from decimal import Decimal
from pathlib import Path

import mpmath
import numpy as np
import pytest
import sympy
from hypothesis import example, given, settings
from hypothesis import strategies as st
from lxml import etree

from conftest import lens_xml
from lensaudit import calibrations, vignetting
from lensaudit.check.rules import tca_fold_in_image as tca_rule
from lensaudit.check.rules import vignetting as vignetting_rules
from lensaudit.read import LoadError, read_bytes
from lensaudit.read.paths import bundled_database_path

W = sympy.Symbol("w")


# --- the reference ---------------------------------------------------------


def odd_part(poly: sympy.Poly) -> sympy.Poly:
    """The product of the square-free factors of odd multiplicity: the polynomial
    whose roots are exactly where ``poly`` changes sign."""
    _, factors = poly.sqf_list()
    result = sympy.Poly(1, W)
    for factor, times in factors:
        if times % 2:
            result *= factor
    return result


def roots_inside(poly: sympy.Poly, low: sympy.Rational, high: sympy.Rational) -> int:
    """How many distinct roots ``poly`` has in the open interval (low, high), exactly."""
    if poly.is_zero or poly.degree() <= 0:
        return 0
    closed = poly.count_roots(low, high)
    return closed - (poly.eval(low) == 0) - (poly.eval(high) == 0)


def first_positive_root(poly: sympy.Poly) -> float:
    """The smallest root > 0 of ``poly`` as a float (inf if none), via CRootOf."""
    if poly.is_zero or poly.degree() <= 0 or poly.count_roots(0, None) == poly.count_roots(0, 0):
        return math.inf
    index = poly.count_roots(None, 0)  # real roots at or below 0 come first
    return float(sympy.N(sympy.CRootOf(poly, index), 30))


def reference(k1: str, k2: str, k3: str, w_image: str = "1", roots: bool = True) -> dict:
    """C(w) = 1 + k1 w + k2 w^2 + k3 w^3 on 0 <= w <= w_image, exactly.

    Decisions are exact root counts with sympy (Sturm sequences on the
    rationals the decimal strings denote). The minimum is evaluated with
    mpmath at 1300 digits, enough that no cancellation between binary64-sized
    terms survives; first roots (``roots``) come from sympy's CRootOf.
    """
    q1, q2, q3 = (sympy.Rational(k) for k in (k1, k2, k3))
    limit = sympy.Rational(w_image)
    c = sympy.Poly(1 + q1 * W + q2 * W**2 + q3 * W**3, W)
    derivative = c.diff(W)
    shifted = sympy.Poly(c.as_expr() - sympy.Rational(1, 10), W)
    raised = sympy.Poly(c.as_expr() - sympy.Rational(21, 20), W)
    with mpmath.workdps(1300):
        m1, m2, m3, w_max = (mpmath.mpf(q.p) / q.q for q in (q1, q2, q3, limit))
        points = [mpmath.mpf(0), w_max]
        if m3 != 0:
            discriminant = m2 * m2 - 3 * m1 * m3
            if discriminant >= 0:
                points += [(-m2 + e * mpmath.sqrt(discriminant)) / (3 * m3) for e in (-1, 1)]
        elif m2 != 0:
            points.append(-m1 / (2 * m2))
        values = [(1 + x * (m1 + x * (m2 + x * m3)), x) for x in points if 0 <= x <= w_max]
        c_min, w_min = min(values)
        c_max, w_max = max(values)
        c_min, w_min, c_max, w_max = float(c_min), float(w_min), float(c_max), float(w_max)
    result = {
        "c_min": c_min,
        "r_min": math.sqrt(w_min),
        "c_max": c_max,
        "r_cmax": math.sqrt(w_max),
        # C(0) = 1 > 0: C <= 0 somewhere in [0, W] exactly when C has a root in (0, W].
        "zero_in_image": c.count_roots(0, limit) > 0,
        # C < 1/10 somewhere exactly when C(W) < 1/10 or C - 1/10 changes sign in (0, W).
        "low_in_image": c.eval(limit) < sympy.Rational(1, 10)
        or roots_inside(odd_part(shifted), 0, limit) > 0,
        # C(0) = 1: C > 21/20 somewhere exactly when C(W) > 21/20 or C - 21/20
        # changes sign in (0, W).
        "brightens": c.eval(limit) > sympy.Rational(21, 20)
        or roots_inside(odd_part(raised), 0, limit) > 0,
        "monotone": derivative.is_zero or roots_inside(odd_part(derivative), 0, limit) == 0,
        "size": float(1 + abs(q1) * limit + abs(q2) * limit**2 + abs(q3) * limit**3),
    }
    if roots:
        result["r_zero"] = math.sqrt(first_positive_root(odd_part(c)))
        result["r_turn"] = math.sqrt(
            first_positive_root(odd_part(derivative)) if not derivative.is_zero else math.inf
        )
        result["repeated_root"] = c.degree() > 1 and sympy.discriminant(c.as_expr(), W) == 0
    return result


def computed(k1: str, k2: str, k3: str, r_corner: float = 1.0) -> dict:
    """lensaudit's metrics of one entry, as plain values."""
    result = vignetting.compute([float(k1)], [float(k2)], [float(k3)], [r_corner])
    return {name: values[0] for name, values in result.items()}


def assert_matches(k1: str, k2: str, k3: str, r_corner: float = 1.0) -> None:
    got = computed(k1, k2, k3, r_corner)
    want = reference(k1, k2, k3, repr(r_corner * r_corner))
    where = f"k = {k1}, {k2}, {k3}"
    for flag in ("zero_in_image", "low_in_image", "brightens", "monotone"):
        assert bool(got[flag]) == want[flag], f"{flag}: {where}"
    assert got["c_min"] == pytest.approx(want["c_min"], rel=1e-12, abs=1e-12 * want["size"]), where
    assert got["c_max"] == pytest.approx(want["c_max"], rel=1e-12, abs=1e-12 * want["size"]), where
    assert got["r_min"] == pytest.approx(want["r_min"], rel=1e-6, abs=1e-6) or got[
        "c_min"
    ] == pytest.approx(want["c_min"], rel=1e-15), where
    if not want["repeated_root"]:
        assert got["r_zero"] == pytest.approx(want["r_zero"], rel=1e-10), where
    assert got["r_turn"] == pytest.approx(want["r_turn"], rel=1e-9), where


# --- records ---------------------------------------------------------------


def vignetting_lines(database: Path) -> list[tuple[str, int]]:
    """(file, line) of every <vignetting> element, read with lxml directly."""
    found = []
    for path in sorted(database.glob("*.xml")):
        root = etree.parse(str(path)).getroot()
        found += [(path.name, element.sourceline) for element in root.iter("vignetting")]
    return found


def records_of(database, kind: str = "vignetting") -> calibrations.CalibrationRecords:
    """The records of one kind of a database read with its calibrations."""
    return calibrations.CalibrationRecords(kind, *database.rows(kind))


def test_every_vignetting_element_of_the_bundled_database_is_one_record(bundled_db):
    records = records_of(calibrations.load(bundled_db))
    assert [(e.file, e.line) for e in records] == vignetting_lines(bundled_db)
    assert len(records) > 20000
    assert set(records.column("status")) == {"ok"}


def load_one(write_xml, *elements: str, **lens) -> list:
    path = write_xml(lens_xml(*elements, **lens))
    return list(records_of(calibrations.load(path)))


def test_a_record_carries_the_lens_and_the_calibration_overrides(write_xml):
    (entry,) = load_one(
        write_xml,
        '<vignetting model="pa" focal="10" aperture="2.8" distance="1000" '
        'k1="-0.5" k2="0.1" k3="-0.01"/>',
        cropfactor="1.5",
        extra="<type>fisheye</type><aspect-ratio>4:3</aspect-ratio>",
        calibration=' cropfactor="2" aspect-ratio="16:9"',
    )
    assert (entry.maker, entry.lens, entry.type) == ("Test", "Test 10mm", "fisheye")
    assert (entry.crop_factor, entry.aspect_ratio) == (2.0, 16 / 9)
    assert (entry.focal, entry.aperture, entry.distance) == (10.0, 2.8, 1000.0)
    assert (entry.k1, entry.k2, entry.k3, entry.status) == (-0.5, 0.1, -0.01, "ok")


def test_a_missing_coefficient_is_zero_as_in_liblensfun(write_xml):
    (entry,) = load_one(write_xml, '<vignetting model="pa" focal="10" aperture="4" distance="10"/>')
    assert (entry.k1, entry.k2, entry.k3, entry.status) == (0.0, 0.0, 0.0, "ok")


@pytest.mark.parametrize(
    "element, status, words",
    [
        (
            '<vignetting model="pa" aperture="4" distance="10" k1="-1"/>',
            "missing_attribute",
            "focal",
        ),
        ('<vignetting model="pa" focal="10" distance="10"/>', "missing_attribute", "aperture"),
        ('<vignetting model="pa" focal="10" aperture="4"/>', "missing_attribute", "distance"),
        ('<vignetting focal="10" aperture="4" distance="10"/>', "missing_attribute", "model="),
        (
            '<vignetting model="pa" focal="10" aperture="4" distance="10" k1="x"/>',
            "bad_value",
            "k1",
        ),
        (
            '<vignetting model="pa" focal="10" aperture="4" distance="10" k2="nan"/>',
            "bad_value",
            "k2",
        ),
        (
            '<vignetting model="pa" focal="10" aperture="4" distance="10" k3="1e999"/>',
            "bad_value",
            "k3",
        ),
        ('<vignetting model="pa" focal="10" aperture="0" distance="10"/>', "bad_value", "aperture"),
        ('<vignetting model="pa" focal="-5" aperture="4" distance="10"/>', "bad_value", "focal"),
        ('<vignetting model="acm" focal="10" aperture="4" distance="10"/>', "unknown_model", "acm"),
    ],
)
def test_a_bad_element_is_a_record_with_a_status_and_why(write_xml, element, status, words):
    (entry,) = load_one(write_xml, element)
    assert entry.status == status
    assert words in entry.message


def test_an_element_outside_a_lens_is_no_lens(write_xml):
    path = write_xml(
        '<lensdatabase><calibration><vignetting model="pa" focal="10" aperture="4" '
        'distance="10" k1="-0.3"/></calibration></lensdatabase>'
    )
    (entry,) = records_of(calibrations.load(path))
    assert (entry.status, entry.line) == ("no_lens", 1)


def test_a_broken_file_is_one_error_record_then_what_recovery_reads(write_xml):
    text = lens_xml(
        '<vignetting model="pa" focal="10" aperture="4" distance="10" k1="-0.3"/>'
    ).replace("</lensdatabase>", "")
    database = calibrations.load(write_xml(text))
    head, salvaged = records_of(database)
    assert head.status == salvaged.status == "xml_error"
    assert "not well-formed" in head.message and head.line > 0
    assert salvaged.k1 == -0.3 and "recovery" in salvaged.message
    # The TCA audit accounts for the file too.
    assert records_of(database, "tca")[0].status == "xml_error"


def test_a_file_that_is_not_a_database_is_one_record_then_its_elements(write_xml):
    path = write_xml(
        '<notlensfun><lens><calibration><vignetting model="pa" focal="10" aperture="4" '
        'distance="10"/></calibration></lens></notlensfun>'
    )
    statuses = [e.status for e in records_of(calibrations.load(path))]
    assert statuses == ["not_database", "not_database"]


def test_a_file_that_cannot_be_read_is_one_unreadable_record(write_xml, tmp_path):
    good = write_xml(lens_xml())
    os.mkfifo(good.parent / "fifo.xml")
    records = records_of(calibrations.load(good.parent))
    assert [(e.file, e.status) for e in records] == [("fifo.xml", "unreadable")]


def test_a_path_that_does_not_exist_raises_load_error(tmp_path):
    with pytest.raises(LoadError, match="no such file"):
        calibrations.load(tmp_path / "missing")


# --- metrics against sympy -------------------------------------------------


def test_c_touching_zero_at_the_corner_is_an_error_without_a_crossing():
    # C = (1 - w)^2: zero at the corner, never negative, monotone on (0, 1).
    got = computed("-2", "1", "0")
    assert got["zero_in_image"] and got["c_min"] == 0 and got["r_zero"] == math.inf
    assert got["monotone"] and got["severity"] == "error"
    assert_matches("-2", "1", "0")


def test_c_crossing_zero_exactly_at_the_corner_is_an_error():
    got = computed("-0.5", "-0.5", "0")
    assert got["zero_in_image"] and got["r_zero"] == 1.0
    assert_matches("-0.5", "-0.5", "0")


def test_a_turning_point_exactly_at_the_corner_in_decimal_is_monotone():
    # Panasonic 14-140 (mil-panasonic.xml): k1 + 2 k2 + 3 k3 is 0 in decimal, but
    # -2^-60 in binary64, which would put the turning point just inside the frame.
    got = computed("0.0065", "0.0053", "-0.0057")
    assert got["monotone"] and got["r_turn"] == pytest.approx(1.0, abs=1e-15)
    assert_matches("0.0065", "0.0053", "-0.0057")


def test_c_just_above_a_tenth_at_the_corner_is_not_low():
    # 1 - 0.9 = 0.1 exactly in decimal: not below 0.1.
    got = computed("-0.9", "0", "0")
    assert not got["low_in_image"] and got["severity"] == ""
    assert_matches("-0.9", "0", "0")
    assert computed("-0.9000001", "0", "0")["severity"] == "warning"


def test_an_interior_minimum_below_zero_is_found():
    # C falls below zero and rises again before the corner.
    assert_matches("-4", "4", "0")
    got = computed("-4", "4", "0")
    assert got["c_min"] == 0 and got["r_min"] == pytest.approx(math.sqrt(0.5))


@pytest.mark.parametrize(
    "k1, k2, k3",
    [
        ("-0.7420100", "2.4739900", "-15.1648903"),  # Canon EF 8-15 at 8 mm f/4
        ("-1.8", "1.2", "-0.3"),
        ("0.3", "-1.6", "0.6"),  # rises, then falls below zero
        ("-0.3", "0.05", "0"),
        ("0", "0", "0"),
        ("0", "0", "-1"),
        ("1e-8", "-3e-8", "2e-8"),
        ("-1.5", "0.75", "-0.125"),  # (1 - w/2)^3: triple root at w = 2
        ("-3", "3", "-1"),  # (1 - w)^3: triple root at the corner
        ("-0.0001", "0.00005", "0.00000001"),
    ],
)
def test_hand_made_and_real_entries_match_sympy(k1, k2, k3):
    assert_matches(k1, k2, k3)


def test_a_circular_fisheye_is_judged_at_its_image_circle():
    # 3:2 frame: the circle inscribed in the short side is at r = 1 / hypot(1.5, 1).
    circle = 1 / math.hypot(1.5, 1)
    assert_matches("-0.7", "-0.2", "-0.2", circle)
    assert computed("-0.7", "-0.2", "-0.2", circle)["severity"] == ""
    assert computed("-0.7", "-0.2", "-0.2")["severity"] == "error"


decimals = st.decimals(min_value=-30, max_value=30, places=5, allow_nan=False).map(str)


@settings(max_examples=150, deadline=None)
@given(decimals, decimals, decimals)
def test_any_decimal_coefficients_match_sympy(k1, k2, k3):
    assert_matches(k1, k2, k3)


small_integers = st.integers(min_value=-50_000, max_value=50_000)


@settings(max_examples=60, deadline=None)
@given(small_integers, small_integers)
@example(0, 0)
def test_a_zero_placed_exactly_at_the_corner_is_always_found(a, b):
    k1, k2 = Decimal(a) / 10_000, Decimal(b) / 10_000
    k3 = -(1 + k1 + k2)
    assert computed(str(k1), str(k2), str(k3))["zero_in_image"]
    assert_matches(str(k1), str(k2), str(k3))


@settings(max_examples=60, deadline=None)
@given(small_integers, small_integers)
@example(0, 0)
def test_c_placed_exactly_at_the_brightening_threshold_at_the_corner_is_decided_exactly(a, b):
    # C(1) = 1 + k1 + k2 + k3 = 1.05 exactly in decimal: not above it there.
    k2, k3 = Decimal(a) / 10_000, Decimal(b) / 10_000
    k1 = Decimal("0.05") - k2 - k3
    assert_matches(str(k1), str(k2), str(k3))


def test_the_fe_85_gm_entry_lensfun_removed_brightens_its_corners_3_4_fold():
    # Removed in Lensfun's 5599955b: k1=0.026, k2=1.27, k3=1.13.
    got = computed("0.026", "1.27", "1.13")
    assert got["brightens"] and got["severity"] == "warning"
    assert got["c_max"] == pytest.approx(3.426, rel=1e-15) and got["r_cmax"] == 1
    (finding,) = vignetting_rules.findings([{**dict.fromkeys(vignetting.COLUMNS, ""), **got,
                                       "file": "f.xml", "line": 3, "status": "ok"}])  # fmt: skip
    assert finding[1] == vignetting_rules.BRIGHTENS.code and "3.43 times as bright" in finding[4]


@settings(max_examples=60, deadline=None)
@given(small_integers, small_integers)
def test_a_turning_point_placed_exactly_at_the_corner_is_decided_as_sympy_does(b, c):
    # C'(1) = k1 + 2 k2 + 3 k3 = 0 exactly in decimal.
    k2, k3 = Decimal(b) / 10_000, Decimal(c) / 10_000
    k1 = -2 * k2 - 3 * k3
    assert_matches(str(k1), str(k2), str(k3))


finite_doubles = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=300, deadline=None)
@given(finite_doubles, finite_doubles, finite_doubles)
@example(1e300, -1e300, 1e300)
@example(5e-324, -5e-324, 1e308)
def test_any_finite_doubles_give_exact_flags_and_no_warning(k1, k2, k3):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = computed(repr(k1), repr(k2), repr(k3))
    want = reference(repr(k1), repr(k2), repr(k3), roots=False)
    for flag in ("zero_in_image", "low_in_image", "brightens", "monotone"):
        assert bool(got[flag]) == want[flag], flag
    if math.isfinite(want["c_min"]):
        assert got["c_min"] == pytest.approx(want["c_min"], rel=1e-9, abs=1e-12 * want["size"])


# --- whole databases against an independent computation --------------------


def independent_flags(entries: list, w_image: np.ndarray, points: int = 2001) -> dict:
    """zero/low/monotone per entry by dense sampling of C and C' in w, with the
    sampling error bounded by max |C''|; doubtful entries are decided by sympy.

    Sampling at spacing h: a minimum between samples is at most max|C''| h^2 / 8
    below the nearest sample, and C' can hide a pair of sign changes between
    samples only where some sample of |C'| is within max|C''| h of zero.
    """
    k = np.array([[e.k1, e.k2, e.k3] for e in entries])
    texts = [(repr(e.k1), repr(e.k2), repr(e.k3)) for e in entries]
    zero = np.zeros(len(entries), dtype=bool)
    low = np.zeros(len(entries), dtype=bool)
    bright = np.zeros(len(entries), dtype=bool)
    turns = np.zeros(len(entries), dtype=bool)
    doubtful = np.zeros(len(entries), dtype=bool)
    fraction = np.linspace(0.0, 1.0, points)
    for start in range(0, len(entries), 2000):
        block = slice(start, start + 2000)
        k1, k2, k3 = (k[block, i : i + 1] for i in range(3))
        limit = w_image[block, None]
        w = fraction[None, :] * limit
        h = limit[:, 0] / (points - 1)
        c = 1 + k1 * w + k2 * w**2 + k3 * w**3
        slope = k1 + 2 * k2 * w + 3 * k3 * w**2
        curvature = (2 * np.abs(k2) + 6 * np.abs(k3) * limit)[:, 0]
        rounding = 1e-12 * (1 + np.abs(k1) + np.abs(k2) + np.abs(k3))[:, 0]
        c_min = c.min(axis=1)
        band = curvature * h**2 / 8 + rounding
        c_max = c.max(axis=1)
        zero[block] = c_min <= 0
        low[block] = c_min < 0.1
        bright[block] = c_max > 1.05
        doubtful[block] |= (np.abs(c_min) <= band) | (np.abs(c_min - 0.1) <= band)
        doubtful[block] |= np.abs(c_max - 1.05) <= band
        # A sign change between two samples whose signs rounding cannot flip is
        # certain; without one, C' may still change sign twice between samples
        # (or at an end) only where it comes within max|C''| h of zero.
        signs = np.where(np.abs(slope) > rounding[:, None], np.sign(slope), 0)
        turns[block] = (signs[:, :-1] * signs[:, 1:] < 0).any(axis=1)
        near_zero = np.abs(slope).min(axis=1) <= curvature * h + rounding
        doubtful[block] |= near_zero & ~turns[block]
    for index in np.flatnonzero(doubtful):
        want = reference(*texts[index], repr(float(w_image[index])))
        zero[index], low[index] = want["zero_in_image"], want["low_in_image"]
        bright[index] = want["brightens"]
        turns[index] = not want["monotone"]
    return {"zero_in_image": zero, "low_in_image": low, "brightens": bright, "monotone": ~turns}


def assert_database_matches(database: Path) -> dict:
    audit = vignetting.audit(database)
    audited = [e for e in audit.entries if e.status == "ok"]
    ok = np.array(audit.audited)
    circular = np.array(["circular" in e.lens.lower() and e.type != "rectilinear" for e in audited])
    aspect = np.array([max(e.aspect_ratio, 1 / e.aspect_ratio) for e in audited])
    r_corner = np.where(circular, 1 / np.hypot(aspect, 1), 1.0)
    assert audit.metrics["r_corner"][ok].tolist() == r_corner.tolist()
    want = independent_flags(audited, r_corner**2)
    counts = {}
    for flag in ("zero_in_image", "low_in_image", "brightens", "monotone"):
        got = audit.metrics[flag][ok]
        wrong = [
            f"{e.file}:{e.line}" for e, g, w in zip(audited, got, want[flag], strict=True) if g != w
        ]
        assert not wrong, f"{flag}: {wrong[:10]}"
        counts[flag] = int(want[flag].sum())
    summary = audit.summary()
    assert summary["zero_in_image"] == counts["zero_in_image"]
    assert summary["low_in_image"] == counts["low_in_image"]
    assert summary["brightens"] == counts["brightens"]
    assert summary["not_monotone"] == len(audited) - counts["monotone"]
    return counts


def test_bundled_database_counts_match_an_independent_computation(bundled_db):
    counts = assert_database_matches(bundled_db)
    assert counts["zero_in_image"] > 50 and counts["brightens"] > 10


def test_lensfun_head_counts_match_an_independent_computation(lensfun_head):
    counts = assert_database_matches(lensfun_head)
    assert counts["zero_in_image"] > 50


def test_severity_follows_the_flags(bundled_db):
    audit = vignetting.audit(bundled_db)
    m = audit.metrics
    expected = np.where(
        m["zero_in_image"],
        "error",
        np.where(
            m["low_in_image"] | m["brightens"],
            "warning",
            np.where(~m["monotone"], "notice", ""),
        ),
    )
    assert m["severity"].tolist() == expected.tolist()


# --- findings --------------------------------------------------------------


def test_findings_give_one_per_entry_with_its_code_and_severity(write_xml):
    path = write_xml(
        lens_xml(
            '<vignetting model="pa" focal="8" aperture="4" distance="1000" k1="-0.5" k2="-0.6"/>',
            '<vignetting model="pa" focal="9" aperture="4" distance="1000" k1="-0.95"/>',
            '<vignetting model="pa" focal="10" aperture="4" distance="1000" k1="-0.4" k2="0.3"/>',
            '<vignetting model="pa" focal="11" aperture="4" distance="1000" k1="-0.3"/>',
            '<vignetting model="pa" focal="12" aperture="4" k1="-0.3"/>',
        )
    )
    found = vignetting_rules.findings(vignetting.audit(path.parent).records())
    assert [(severity, code, line) for severity, code, _, line, _ in found] == [
        ("error", "vignetting-zero-in-image", 10),
        ("warning", "vignetting-low-in-image", 11),
        ("notice", "vignetting-not-monotone", 12),
        ("error", "missing-attribute", 14),
    ]
    assert all(file == "test.xml" for _, _, file, _, _ in found)
    assert "Test 10mm <vignetting> at 8 mm, f/4, 1000 m" in found[0][4]


def test_findings_leave_whole_file_problems_to_the_distortion_check(write_xml):
    path = write_xml("<lensdatabase><lens>")
    assert vignetting_rules.findings(vignetting.audit(path).records()) == []


# --- the report ------------------------------------------------------------


@pytest.fixture
def report_dir(write_xml, tmp_path):
    from lensaudit.report import audit, write_report

    database = write_xml(
        lens_xml(
            '<distortion model="poly3" focal="8" k1="-0.01"/>',
            '<vignetting model="pa" focal="8" aperture="4" distance="1000" k1="-0.5" k2="-0.6"/>',
            '<vignetting model="pa" focal="9" aperture="4" distance="1000" k1="-0.95"/>',
            '<vignetting model="pa" focal="10" aperture="4" distance="1000" k1="x"/>',
            '<tca model="poly3" focal="8" vr="1" br="-0.2"/>',
        )
    ).parent
    out = tmp_path / "report"
    write_report(audit(database), out)
    return database, out


def test_the_report_writes_vignetting_and_tca_csv_as_scan_does(report_dir):
    from click.testing import CliRunner

    from lensaudit.cli import main

    database, out = report_dir
    for kind in ("vignetting", "tca"):
        result = CliRunner().invoke(main, ["scan", str(database), "-k", kind, "-f", "csv"])
        assert (out / f"{kind}.csv").read_text(encoding="utf-8") == result.output


def test_the_report_page_counts_and_lists_the_vignetting_and_tca_findings(report_dir):
    _, out = report_dir
    page = etree.parse(str(out / "report.html"), etree.HTMLParser())
    counts = page.xpath('//table[@id="calibration-counts"]/tbody/tr')
    cells = [[td.text for td in row.xpath("td")] for row in counts]
    assert cells == [["vignetting", "3", "2", "1", "1", "0"], ["tca", "1", "1", "1", "0", "0"]]
    worst = page.xpath('//table[@id="vignetting-worst"]/tbody/tr/td[last()]/text()')
    assert worst == ["test.xml:11", "test.xml:12"]
    assert page.xpath('//table[@id="tca-folding"]/tbody/tr/td[last()]/text()') == ["test.xml:14"]
    assert "1 not audited" in page.xpath('string(//section[@id="vignetting-tca"])')


# --- the short path of the reader agrees with the full one -----------------

attribute_texts = st.one_of(
    decimals,
    st.sampled_from(["0", "-1", " 2.5 ", "1_0", "nan", "inf", "-infinity", "1e999", "", "x", "٣"]),
)


@settings(max_examples=200, deadline=None)
@given(
    st.sampled_from(["pa", "acm", "", None]),
    st.dictionaries(
        st.sampled_from(["focal", "aperture", "distance", "k1", "k2", "k3"]), attribute_texts
    ),
)
def test_the_short_path_gives_the_record_the_full_examination_gives(model, attributes):
    element = etree.Element("vignetting")
    if model is not None:
        element.set("model", model)
    for key, value in attributes.items():
        element.set(key, value)
    import copy

    from lensaudit.read.tables import SPECS, LensContext

    spec = SPECS["vignetting"]
    examined = copy.copy(spec)
    examined._fast = {}  # no short path: every element examined in full
    # A lens without problems.
    context = LensContext(("M", "L", ("Mount",), "rectilinear", 1.5, 1.5))
    fast = spec.row(element, context, 7, NUMBERS_MET)
    full = examined.row(element, context, 7, {})
    assert repr(fast) == repr(full)


#: The texts of numbers met across the examples, as a file's reader keeps them:
#: a number met before gives the value its text gives, sign and all.
NUMBERS_MET: dict[str, float] = {}


# --- mutated real files: no crash, no warning, every element once ----------

FUZZ_FILES = ("actioncams.xml", "slr-vivitar.xml")
FUZZ_VALUES = ["", "0", "-1", "1e308", "-1e308", "1e-320", "1e999", "nan", "inf", "abc", "1,5"]
FUZZ_VALUES += [" 2 ", "1_0", "\u0661", "9" * 400, "pa", "poly3", "linear", "acm", "none"]
_CALIBRATION_VALUE = re.compile(rb'<(?:vignetting|tca|calibration)\b[^>]*?="([^"]*)"')


@st.composite
def mutated_files(draw) -> tuple[str, bytes]:
    name = draw(st.sampled_from(FUZZ_FILES))
    data = (bundled_database_path() / name).read_bytes()
    rng = draw(st.randoms(use_true_random=False))
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["value", "value", "line", "insert", "truncate"]))
        if kind == "value":
            matches = list(_CALIBRATION_VALUE.finditer(data))
            if not matches:  # an earlier mutation removed them all
                continue
            match = rng.choice(matches)
            value = draw(st.one_of(st.sampled_from(FUZZ_VALUES), st.floats().map(repr)))
            data = data[: match.start(1)] + value.encode() + data[match.end(1) :]
        elif kind == "line" and data:
            lines = data.splitlines(keepends=True)
            line = lines.pop(rng.randrange(len(lines)))
            if draw(st.booleans()):
                lines.insert(rng.randint(0, len(lines)), line)
            data = b"".join(lines)
        elif kind == "insert":
            position = rng.randint(0, len(data))
            text = draw(st.text(st.sampled_from(list('<>/="&; abc1.')), min_size=1, max_size=6))
            data = data[:position] + text.encode() + data[position:]
        elif kind == "truncate":
            data = data[: rng.randint(0, len(data))]
    return name, data


def _well_formed(data: bytes) -> bool:
    import xml.parsers.expat

    parser = xml.parsers.expat.ParserCreate()
    try:
        parser.Parse(data, True)
    except xml.parsers.expat.ExpatError:
        return False
    return True


@pytest.mark.filterwarnings("error")
@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(mutated_files())
def test_a_mutated_file_never_crashes_and_every_element_is_one_record(mutated):
    from lensaudit import tca

    name, data = mutated
    tables = read_bytes(data, name, calibrations=True)
    vignetting_records = calibrations.CalibrationRecords.of_file(
        "vignetting", name, tables.vignetting
    )
    tca_records = calibrations.CalibrationRecords.of_file("tca", name, tables.tca)
    error = tables.error
    for records, audit_entries, module in (
        (vignetting_records, vignetting.audit_entries, vignetting_rules),
        (tca_records, tca.audit_entries, tca_rule),
    ):
        audit = audit_entries(records)
        module.findings(audit.records())
        audit.write_csv(io.StringIO())
        audit.write_json(io.StringIO())
        audit.write_table(io.StringIO())
    if not _well_formed(data):
        assert error and vignetting_records[0].status == tca_records[0].status == "xml_error"
        return
    root = etree.fromstring(data)
    head = 1 if root.tag != "lensdatabase" else 0
    for tag, records in (("vignetting", vignetting_records), ("tca", tca_records)):
        lines = [element.sourceline for element in root.iter(tag)]
        assert [r.line for r in records[head:]] == lines
        assert all(r.status != "xml_error" for r in records)


def test_coefficients_that_are_not_finite_give_no_metrics_and_no_error():
    # VignettingEntry's k1, k2, k3 default to NaN (with status "ok"): an entry made
    # without them is audited as unknown, as TCA's are, not sent to exact arithmetic.
    from lensaudit.calibrations import VignettingEntry
    from lensaudit.vignetting import VignettingAudit

    entry = VignettingEntry("f.xml", 1, "M", "L", "rectilinear", 1.0, 1.5, "pa", 50.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        record = VignettingAudit.of_entries([entry]).records()[0]
        found = vignetting.compute(
            [0.1, math.nan, -0.5], [0.0, 0.0, math.inf], [0.0] * 3, [1.0, 1.0, 1.0]
        )
    assert math.isnan(record["c_min"]) and record["severity"] == ""
    assert math.isnan(found["c_min"][1]) and math.isnan(found["c_min"][2])
    assert not found["zero_in_image"][1:].any() and list(found["severity"][1:]) == ["", ""]
    assert found["c_min"][0] == 1.0
