"""Circular fisheyes are judged against their image circle, not the frame's corner.

Lensfun says a lens is a circular fisheye in its name; the image circle then
lies inside the frame, at most the circle inscribed in the short side, r = 1
in Hugin units. References: D(r_max) in exact arithmetic with sympy.
"""

from __future__ import annotations

import csv
import io
import math

import pytest
import sympy
from click.testing import CliRunner

from conftest import lens_xml
from lensaudit import metrics
from lensaudit.cli import main

SIGMA_45 = "Sigma 4.5mm f/2.8 EX DC HSM circular fisheye"


def exact_d_max(distortion) -> float:
    """D(r_max) of D given as a function of a sympy symbol: D at the first
    positive root of D' where D' changes sign."""
    r = sympy.symbols("r", positive=True)
    d = distortion(r)
    slope = sympy.Poly(sympy.diff(d, r), r)
    roots = sorted(
        root
        for root in sympy.real_roots(slope)
        if root > 0 and slope.eval(root - sympy.Rational(1, 10**12)) > 0
    )
    return float(d.subs(r, roots[0]).evalf(30))


def ptlens(a: str, b: str, c: str):
    a, b, c = (sympy.Rational(v) for v in (a, b, c))
    return lambda r: r * (a * r**3 + b * r**2 + c * r + 1 - a - b - c)


def poly5(k1: str, k2: str):
    k1, k2 = sympy.Rational(k1), sympy.Rational(k2)
    return lambda r: r * (1 + k1 * r**2 + k2 * r**4)


def scan_rows(*arguments: str) -> list[dict[str, str]]:
    result = CliRunner().invoke(main, ["scan", "--format", "csv", *arguments])
    assert result.exit_code == 0, result.output
    return list(csv.DictReader(io.StringIO(result.output)))


def test_the_database_names_its_circular_fisheyes():
    assert metrics.is_circular_fisheye(SIGMA_45, "fisheye")
    assert metrics.is_circular_fisheye("Sigma 8mm f/3.5 EX DG Circular", "equisolid")
    assert not metrics.is_circular_fisheye("Sigma 10mm f/2.8 EX DC HSM Fisheye", "fisheye")
    assert not metrics.is_circular_fisheye("Circular Polariser Test 50mm", "rectilinear")


def test_sigma_4_5mm_circular_is_judged_against_its_image_circle(bundled_db):
    [row] = [r for r in scan_rows(str(bundled_db / "slr-sigma.xml")) if r["lens"] == SIGMA_45]
    d_max = exact_d_max(ptlens(row["a"], row["b"], row["c"]))
    # The point of the rule: inside the frame's corner, outside the image circle.
    assert 1 < d_max < math.hypot(1.5, 1)
    assert float(row["r_corner"]) == 1.0
    assert float(row["r_normalized"]) == pytest.approx(d_max, rel=1e-12)
    assert row["folds_in_image"] == "false"


def test_circular_fisheye_that_folds_inside_its_circle_is_flagged(write_xml):
    text = lens_xml(
        '<distortion model="poly5" focal="8" k1="-0.3" k2="-0.1"/>',
        extra="<type>fisheye</type>",
    ).replace("Test 10mm", "Test 8mm circular fisheye")
    [row] = scan_rows(str(write_xml(text)))
    # ptlens and poly3 have D(1) = 1, so only a poly5 model can fold inside r = 1.
    d_max = exact_d_max(poly5("-0.3", "-0.1"))
    assert d_max < 1
    assert float(row["r_corner"]) == 1.0
    assert row["folds_in_image"] == "true"


def test_the_same_model_on_a_full_frame_lens_is_judged_against_the_corner(write_xml):
    text = lens_xml('<distortion model="ptlens" focal="8" a="-0.21693" b="-0.44076" c="-0.47357"/>')
    [row] = scan_rows(str(write_xml(text)))
    assert float(row["r_corner"]) == pytest.approx(math.hypot(1.5, 1), rel=1e-15)
    assert row["folds_in_image"] == "true"
