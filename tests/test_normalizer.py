"""Models to cubic form: checked against symbolic differentiation with exact rationals."""

from __future__ import annotations

import random
import warnings
from fractions import Fraction

import numpy as np
import pytest
import sympy

from lensaudit import metrics, normalizer

r = sympy.Symbol("r", positive=True)


def exact_cubic(distortion_expr, power):
    """(a, b, c) of D'(r) / D'(0) as exact rationals in w = r**power."""
    derivative = sympy.expand(sympy.diff(distortion_expr, r))
    poly = sympy.Poly(derivative, r)
    constant = poly.coeff_monomial(1)
    return tuple(poly.coeff_monomial(r ** (power * k)) / constant for k in (1, 2, 3)), constant


def rationals(seed, count, scale=0.1):
    rng = random.Random(seed)
    return [Fraction(rng.uniform(-scale, scale)) for _ in range(count)]


def assert_close_to_exact(value, exact, rel=4e-16):
    exact = float(exact)
    assert value == pytest.approx(exact, rel=rel, abs=1e-300)


@pytest.mark.parametrize("seed", range(20))
def test_ptlens_cubic_is_normalized_derivative(seed):
    a, b, c = rationals(seed, 3)
    d = 1 - a - b - c
    expr = r * (
        sympy.Rational(a) * r**3
        + sympy.Rational(b) * r**2
        + sympy.Rational(c) * r
        + sympy.Rational(d)
    )
    (ea, eb, ec), constant = exact_cubic(expr, 1)
    cubic = normalizer.ptlens(float(a), float(b), float(c))
    assert cubic.power == 1
    for value, exact in zip((cubic.a, cubic.b, cubic.c), (ea, eb, ec), strict=True):
        assert_close_to_exact(float(value), exact, rel=1e-15)
    assert float(cubic.slope_at_centre) == float(constant)  # d to within one rounding


def test_ptlens_constant_is_correctly_rounded_under_cancellation():
    a, b, c = 0.7, -0.3 + 1e-17, 0.6
    exact = 1 - Fraction(a) - Fraction(b) - Fraction(c)
    assert float(normalizer.ptlens_constant(a, b, c)) == float(exact)


@pytest.mark.parametrize("seed", range(10))
def test_poly3_cubic_is_normalized_derivative(seed):
    (k1,) = rationals(seed, 1)
    expr = r * (1 - sympy.Rational(k1) + sympy.Rational(k1) * r**2)
    (ea, eb, ec), _ = exact_cubic(expr, 2)
    cubic = normalizer.poly3(float(k1))
    assert cubic.power == 2 and float(cubic.b) == 0 and float(cubic.c) == 0
    assert_close_to_exact(float(cubic.a), ea, rel=1e-15)


@pytest.mark.parametrize("seed", range(10))
def test_poly5_cubic_is_normalized_derivative(seed):
    k1, k2 = rationals(seed, 2)
    expr = r * (1 + sympy.Rational(k1) * r**2 + sympy.Rational(k2) * r**4)
    (ea, eb, ec), _ = exact_cubic(expr, 2)
    cubic = normalizer.poly5(float(k1), float(k2))
    assert (float(cubic.a), float(cubic.b), float(cubic.c)) == pytest.approx(
        (float(ea), float(eb), float(ec)), rel=1e-15
    )


@pytest.mark.parametrize(
    ("model", "power", "factors"),
    [
        (normalizer.basic_polynomial, 1, (2, 3, 4)),  # paper Eq. 5
        (normalizer.brown_conrady, 2, (3, 5, 7)),  # paper Eq. 6
    ],
)
def test_paper_models_fold_the_derivative_constants_into_the_cubic(model, power, factors):
    cubic = model(0.1, -0.2, 0.3)
    assert cubic.power == power
    assert (float(cubic.a), float(cubic.b), float(cubic.c)) == pytest.approx(
        (factors[0] * 0.1, factors[1] * -0.2, factors[2] * 0.3), rel=1e-15
    )


@pytest.mark.parametrize("seed", range(5))
def test_evaluate_matches_the_model_formula(seed):
    a, b, c = (float(x) for x in rationals(seed, 3))
    radii = np.linspace(0, 3, 7)
    d = 1 - a - b - c
    expected = radii * (a * radii**3 + b * radii**2 + c * radii + d)
    got = normalizer.evaluate(normalizer.ptlens(a, b, c).distortion, radii)
    np.testing.assert_allclose(got, expected, rtol=1e-13, atol=1e-15)
    k1, k2 = a, b
    np.testing.assert_allclose(
        normalizer.evaluate(normalizer.poly5(k1, k2).distortion, radii),
        radii * (1 + k1 * radii**2 + k2 * radii**4),
        rtol=1e-13,
        atol=1e-15,
    )
    np.testing.assert_allclose(
        normalizer.evaluate(normalizer.poly3(k1).distortion, radii),
        radii * (1 - k1 + k1 * radii**2),
        rtol=1e-13,
        atol=1e-15,
    )


def test_leading_sign_is_the_sign_at_infinity():
    rows = np.array([[-0.1, 0.2, 0, 1, 0], [0, 0.2, 0, 1, 0], [0, 0, 0, 1, 0], [0, -1e-9, 5, 1, 0]])
    assert normalizer.leading_sign(rows).tolist() == [-1, 1, 1, -1]


@pytest.mark.parametrize(
    ("build", "coefficients"),
    [
        (normalizer.ptlens, (1e308, -1e308, 1e308)),
        (normalizer.ptlens, (-1e308, -1e308, -1e308)),
        (normalizer.poly3, (1e308,)),
        (normalizer.poly5, (1e308, -1e308)),
        (normalizer.basic_polynomial, (1e308, 1e308, -1e308)),
        (normalizer.brown_conrady, (0.0, 0.0, -3e307)),
    ],
)
def test_coefficients_near_the_largest_double_make_no_warning(build, coefficients):
    # The cubic overflows (inf or NaN there): metrics.compute and the cameras of
    # lensaudit.projection decide such models exactly; no RuntimeWarning on the way.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cubic = build(*coefficients)
        metrics.cubic_r_max(cubic)
