"""r_max of Lensfun models whose cubic leaves binary64's normal range: a first
turn beyond w = 1.8e308 (r_max up to 1.3e154 and beyond, for w = r^2) and
coefficients that are subnormal in the cubic. Judged against sympy's exact
root isolation of D'(r) on the binary64 inputs taken as rationals."""

from __future__ import annotations

import math
import random
import warnings
from fractions import Fraction

import pytest
import sympy

from lensaudit.metrics import compute
from lensaudit.solver import kernel

LARGEST = Fraction(1.7976931348623157e308)


def distortion_of(model: str, a: float, b: float, c: float, k1: float, k2: float) -> list:
    """D(r), highest power first, exactly as Lensfun writes the model."""
    if model == "ptlens":
        A, B, C = Fraction(a), Fraction(b), Fraction(c)
        return [A, B, C, 1 - A - B - C, Fraction(0)]
    if model == "poly3":
        return [Fraction(k1), Fraction(0), 1 - Fraction(k1), Fraction(0)]
    return [Fraction(k2), Fraction(0), Fraction(k1), Fraction(0), Fraction(1), Fraction(0)]


def exact_r_max(distortion: list[Fraction]) -> Fraction | None:
    """The first r > 0 where D' changes sign (to 25 digits), None if none; 0 if D'(0) <= 0."""
    if distortion[-2] <= 0:
        return Fraction(0)
    r = sympy.symbols("r")
    slope = sympy.Poly([sympy.Rational(x.numerator, x.denominator) for x in distortion], r).diff(r)
    odd = sympy.Poly(1, r, domain=sympy.QQ)
    for factor, multiplicity in slope.sqf_list()[1]:
        if multiplicity % 2:
            odd = odd * factor
    positive = [box for box, _ in odd.intervals() if box[1] > 0] if odd.degree() > 0 else []
    if not positive:
        return None
    low, high = min(positive)
    while low <= 0 or high - low > low / 10**25:  # to 25 digits relative
        low, high = odd.refine_root(low, high, eps=(high - low) / 2**40)
    middle = (low + high) / 2
    return Fraction(int(middle.p), int(middle.q))


def audited(model: str, **coefficients: float) -> tuple[float, tuple | None]:
    """compute()'s r_max of one entry, with no warning, and the kernel's metrics (or None)."""
    values = {name: coefficients.get(name, 0.0) for name in ("a", "b", "c", "k1", "k2")}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        found = compute(
            [model],
            *([values[n]] for n in ("a", "b", "c", "k1", "k2")),
            [1.0],
            [1.5],
            [50.0],
            [True],
        )
    scalar = kernel.entry_metrics(model, *values.values(), 1.0, 1.5, 50.0, False)
    return float(found.r_max[0]), scalar


def assert_exact(model: str, r_max: float, **coefficients: float) -> None:
    values = {name: coefficients.get(name, 0.0) for name in ("a", "b", "c", "k1", "k2")}
    expected = exact_r_max(distortion_of(model, **values))
    if expected is None or expected > LARGEST:  # never turns, or beyond every double
        assert r_max == math.inf
    elif expected == 0:
        assert r_max == 0
    else:
        assert math.isfinite(r_max), (model, coefficients, float(expected))
        assert abs(Fraction(r_max) - expected) <= Fraction(1, 10**12) * expected


@pytest.mark.parametrize(
    ("model", "coefficients"),
    [
        # First turns at w = r^2 beyond the largest double: r_max 7.7e154, 5.8e159.
        ("poly5", dict(k1=1e10, k2=-1e-300)),
        ("poly3", dict(k1=-1e-320)),
        ("poly5", dict(k1=-1e-310)),
        ("poly5", dict(k2=-5e-320)),
        # A subnormal coefficient in the cubic (4a/d): its digits kept.
        ("ptlens", dict(a=-4.57e-321, c=0.094)),
        ("ptlens", dict(a=1e-320, b=1e-320, c=-1e-320)),
        # 4a/d underflows to 0 in floats: the cubic term still turns D, at r = 7e107.
        ("ptlens", dict(a=-1e-320, b=0.0, c=-1e10)),
    ],
)
def test_first_turns_beyond_the_normal_range_are_found(model, coefficients):
    r_max, scalar = audited(model, **coefficients)
    assert_exact(model, r_max, **coefficients)
    assert scalar is None or scalar[0] == r_max


def _draw(generator: random.Random) -> float:
    """A double of any size: a random sign, exponent and mantissa; now and then 0."""
    if generator.random() < 0.15:
        return 0.0
    value = math.ldexp(generator.random() + 0.5, generator.randint(-1075, 1000))
    return value if generator.random() < 0.5 else -value


@pytest.mark.parametrize("model", ["ptlens", "poly3", "poly5"])
def test_r_max_across_the_whole_range_is_the_exact_first_turn(model):
    generator = random.Random(f"metrics-range-{model}")
    names = {"ptlens": ("a", "b", "c"), "poly3": ("k1",), "poly5": ("k1", "k2")}[model]
    for _ in range(120):
        coefficients = {name: _draw(generator) for name in names}
        r_max, scalar = audited(model, **coefficients)
        assert_exact(model, r_max, **coefficients)
        assert scalar is None or scalar[0] == r_max


def test_a_camera_finds_a_first_turn_beyond_the_normal_range_as_the_metrics_do():
    from lensaudit.projection import brown_conrady_camera

    # OpenCV's k1, k2 are poly5's: D'(r) = 1 + 3e10 r^2 - 5e-300 r^4, first turn at r = 7.7e154.
    camera = brown_conrady_camera(1000.0, 1000.0, 500.0, 400.0, k1=1e10, k2=-1e-300)
    r_max, _ = audited("poly5", k1=1e10, k2=-1e-300)
    assert camera.r_max == r_max
    assert_exact("poly5", camera.r_max, k1=1e10, k2=-1e-300)
