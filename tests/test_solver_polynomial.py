"""The general solver (lensaudit.solver.polynomial) against exact root isolation with sympy.

The reference takes the binary64 inputs exactly as rationals, keeps the
factors of odd multiplicity (sympy's square-free decomposition) and counts
their roots on closed rational intervals (sympy's count_roots): no floating
point at all. A finite answer w must have the first sign change strictly
between its two neighbouring doubles, an infinite one none up to the largest
double.
"""

from __future__ import annotations

import math
import tarfile
import warnings
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy
from hypothesis import example, given, settings
from hypothesis import strategies as st

from lensaudit.normalizer import as_polynomial, opencv_fisheye, poly5, ptlens
from lensaudit.solver import min_positive_root, polynomial
from lensaudit.solver.fold import first_fold, opencv_fisheye_fold
from lensaudit.solver.polynomial import (
    PATHS,
    exact_first_sign_change,
    first_sign_change,
    first_sign_change_paths,
)

W = sympy.Symbol("w")
MAX = 1.7976931348623157e308
FAST = PATHS.index("fast")
EXACT = PATHS.index("exact")
GYROFLOW = (
    Path(__file__).resolve().parents[2]
    / "shared"
    / "data"
    / "gyroflow-lens-profiles-886fc616.tar.gz"
)


def rational(x: float | Fraction) -> sympy.Rational:
    n, d = Fraction(x).as_integer_ratio()
    return sympy.Rational(n, d)


def odd_part(coefficients) -> sympy.Poly:
    """The product of the odd-multiplicity factors of 1 + c1 w + ..., exactly (sympy)."""
    p = sympy.Poly([rational(c) for c in reversed(coefficients)] + [1], W)
    odd = sympy.Poly(1, W)
    for factor, multiplicity in p.sqf_list()[1]:
        if multiplicity % 2:
            odd *= factor
    return odd


def sign_changes_in(odd: sympy.Poly, lo, hi) -> int:
    """Roots of the odd part in [lo, hi]: sign changes of p."""
    if odd.degree() == 0:
        return 0
    return odd.count_roots(rational(lo), rational(hi))


def check(coefficients, got: float, correctly_rounded: bool = False) -> None:
    """got is within one ulp of the first sign change (correctly rounded if asked), or inf."""
    odd = odd_part(coefficients)
    if sign_changes_in(odd, 0, MAX) == 0:
        assert got == math.inf, (
            f"{coefficients}: no sign change up to the largest double, got {got}"
        )
        return
    assert math.isfinite(got) and got > 0, f"{coefficients}: a sign change exists, got {got}"
    lo, hi = Fraction(math.nextafter(got, 0)), Fraction(math.nextafter(got, math.inf))
    if correctly_rounded:
        lo, hi = (lo + Fraction(got)) / 2, (hi + Fraction(got)) / 2
    if hi > MAX:
        hi = Fraction(MAX)
    before = sign_changes_in(odd, 0, lo)
    assert before == 0 or (correctly_rounded and odd.eval(rational(lo)) == 0 and before == 1), (
        f"{coefficients}: a sign change at or below {float(lo)!r}, got {got!r}"
    )
    assert sign_changes_in(odd, lo, hi) >= 1, f"{coefficients}: none in [{lo}, {hi}], got {got!r}"


def solve_quietly(coefficients) -> tuple[float, int]:
    """(root, path) of one polynomial, failing on any warning numpy or Python would emit."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(all="raise"):
            roots, paths = first_sign_change_paths([coefficients])
    return float(roots[0]), int(paths[0])


def check_solver(coefficients) -> None:
    got, path = solve_quietly(coefficients)
    check(coefficients, got, correctly_rounded=path == EXACT)


# -- strategies ----------------------------------------------------------------------

#: Exponents uniform over the whole range, subnormals included.
spread_double = st.one_of(
    st.just(0.0),
    st.builds(
        lambda sign, mantissa, exponent: sign * math.ldexp(mantissa, exponent),
        st.sampled_from([-1.0, 1.0]),
        st.floats(0.5, 1.0, exclude_max=True),
        st.integers(-1074, 1024),
    ),
)
any_double = st.floats(allow_nan=False, allow_infinity=False)
sign = st.sampled_from([-1, 1])


@st.composite
def quartics(draw, element=spread_double) -> tuple[float, ...]:
    """Four coefficients, the highest ones zero for a lower degree one time in three."""
    coefficients = [draw(element) for _ in range(4)]
    degree = draw(st.sampled_from([4, 4, 4, 4, 3, 2, 1, 0]))
    return tuple(coefficients[:degree] + [0.0] * (4 - degree))


def dyadic(bits: int, low: int, high: int) -> st.SearchStrategy[Fraction]:
    """m 2^e with 0 < m < 2^bits: products of four stay exact in binary64."""
    return st.builds(
        lambda m, e: Fraction(m) * Fraction(2) ** e,
        st.integers(1, 2**bits - 1),
        st.integers(low, high),
    )


def expand(*factors: list[Fraction]) -> tuple[float, ...]:
    """c1 ... c4 of the product of factors (each constant term first, constant 1), rounded."""
    product = [Fraction(1)]
    for factor in factors:
        result = [Fraction(0)] * (len(product) + len(factor) - 1)
        for i, x in enumerate(product):
            for j, y in enumerate(factor):
                result[i + j] += x * y
        product = result
    product += [Fraction(0)] * (5 - len(product))
    return tuple(float(x) for x in product[1:5])


@st.composite
def repeated_roots(draw) -> tuple[float, ...]:
    """(1 - rho w)^m (1 - sigma w)^(4 - m), m = 2, 3 or 4, exact: rho a root of multiplicity m."""
    scale = draw(st.integers(-250, 240))
    rho = draw(sign) * draw(dyadic(6, scale - 4, scale + 4))
    sigma = draw(sign) * draw(dyadic(6, scale - 4, scale + 4))
    multiplicity = draw(st.sampled_from([2, 3, 4]))
    return expand(
        *[[Fraction(1), -rho]] * multiplicity, *[[Fraction(1), -sigma]] * (4 - multiplicity)
    )


@st.composite
def tangent_with_pair(draw) -> tuple[float, ...]:
    """(1 - rho w)^2 (1 + beta w + gamma w^2): a double root, then a real pair or none."""
    scale = draw(st.integers(-250, 240))
    rho = draw(dyadic(6, scale - 3, scale + 3))
    beta = draw(sign) * draw(dyadic(6, scale - 3, scale + 3))
    gamma = draw(sign) * draw(dyadic(6, 2 * scale - 3, 2 * scale + 3))
    return expand([Fraction(1), -rho], [Fraction(1), -rho], [Fraction(1), beta, gamma])


@st.composite
def plus_minus_plus(draw) -> tuple[float, ...]:
    """(1 - w/r1)(1 - w/r2)(1 + a w + b w^2), 0 < r1 < r2, b > a^2 / 4: the derivative is
    positive, negative, then positive again (a fold, then an unfold), rounded to binary64."""
    scale = Fraction(2) ** draw(st.integers(-240, 240))
    r1 = scale * Fraction(draw(st.integers(10**5, 10**6)), 10**6)
    r2 = r1 * (
        1 + Fraction(draw(st.integers(1, 10**6)), draw(st.sampled_from([10, 10**6, 10**12])))
    )
    a = draw(sign) * Fraction(draw(st.integers(0, 10**6)), 10**6) / scale
    b = a * a / 4 + Fraction(draw(st.integers(1, 10**6)), 10**6) / (scale * scale)
    return expand([Fraction(1), -1 / r1], [Fraction(1), -1 / r2], [Fraction(1), a, b])


@st.composite
def clustered_roots(draw) -> tuple[float, ...]:
    """Four real roots within a relative 2^-k of each other (k up to 60), rounded."""
    scale = Fraction(2) ** draw(st.integers(-240, 240))
    spread = Fraction(2) ** -draw(st.integers(4, 60))
    roots = [scale * (1 + spread * draw(st.integers(-8, 8))) for _ in range(4)]
    return expand(*[[Fraction(1), -1 / draw(sign) / r] for r in roots])


def lens_k(size: float) -> st.SearchStrategy[float]:
    """A k of a real lens's size: zero, or between 1e-8 and size in magnitude."""
    return st.floats(-size, size).filter(lambda k: k == 0 or abs(k) >= 1e-8)


@st.composite
def four_positive_roots(draw) -> tuple[float, ...]:
    """(1 - w/r1)(1 - w/r2)(1 - w/r3)(1 - w/r4), 0 < r1 < ... < r4 apart, rounded: the
    first of two folds, with an unfold between."""
    scale = Fraction(2) ** draw(st.integers(-240, 240))
    gaps = [
        Fraction(draw(st.integers(1, 1000)), draw(st.sampled_from([10, 1000, 10**6])))
        for _ in range(4)
    ]
    roots = [scale * sum(gaps[: i + 1]) for i in range(4)]
    return expand(*[[Fraction(1), -1 / r] for r in roots])


@st.composite
def realistic_fisheye(draw) -> tuple[float, ...]:
    """OpenCV fisheye k1 ... k4 of the sizes Gyroflow's profiles have, as 3k1 ... 9k4."""
    k = [draw(lens_k(size)) for size in (2.0, 20.0, 200.0, 400.0)]
    return tuple(opencv_fisheye(*k).coefficients.tolist())


# -- properties over the whole range -------------------------------------------------------


@settings(max_examples=400, deadline=None)
@given(quartics())
@example((-1.0, 0.0, 0.0, 0.0))
@example((5e-324, -5e-324, 5e-324, -5e-324))
@example((-MAX, MAX, -MAX, MAX))
@example((-MAX, 0.0, 0.0, 0.0))  # a subnormal root, -1 / c1
@example((0.0, 0.0, 0.0, -5e-324))  # the root 2^268.5
@example((-5e-324, 0.0, 0.0, 0.0))
def test_any_coefficients_over_the_whole_range(coefficients):
    check_solver(coefficients)


@settings(max_examples=200, deadline=None)
@given(quartics(any_double))
def test_any_doubles_hypothesis_favours(coefficients):
    check_solver(coefficients)


@settings(max_examples=200, deadline=None)
@given(repeated_roots())
@example(expand([1, Fraction(-1)], [1, Fraction(-1)], [1, Fraction(-2)], [1, Fraction(-2)]))
def test_double_triple_and_quadruple_roots(coefficients):
    check_solver(coefficients)


@settings(max_examples=150, deadline=None)
@given(tangent_with_pair())
def test_tangencies_before_a_pair(coefficients):
    check_solver(coefficients)


@settings(max_examples=150, deadline=None)
@given(plus_minus_plus())
def test_plus_minus_plus_derivatives(coefficients):
    check_solver(coefficients)


@settings(max_examples=150, deadline=None)
@given(clustered_roots())
def test_clustered_roots(coefficients):
    check_solver(coefficients)


@settings(max_examples=100, deadline=None)
@given(four_positive_roots())
def test_four_positive_roots(coefficients):
    check_solver(coefficients)


@settings(max_examples=200, deadline=None)
@given(realistic_fisheye())
def test_realistic_fisheye_derivatives(coefficients):
    check_solver(coefficients)


@settings(max_examples=60, deadline=None)
@given(st.one_of(quartics(), repeated_roots(), clustered_roots(), plus_minus_plus()))
def test_the_exact_path_is_correctly_rounded(coefficients):
    check(coefficients, exact_first_sign_change(coefficients), correctly_rounded=True)


# -- the certificate, whatever its approximations ---------------------------------------


def careless(approximate_roots, newton, seed: int):
    """Stand-ins for the fast path's approximations that are often wrong: roots
    perturbed and shuffled, Newton's result nudged by ulps or started far off."""
    rng = np.random.default_rng(seed)

    def roots(C):
        z = approximate_roots(C)
        level = rng.choice([0.0, 1e-15, 1e-12, 1e-9, 1e-4, 0.3], size=(z.shape[0], 1))
        z = z * (1 + level * rng.normal(size=z.shape))
        # One root per row sometimes mirrored, turned off the real axis, or
        # replaced by a copy of another.
        rows = np.flatnonzero(rng.random(z.shape[0]) < 0.4)
        first, other = rng.integers(0, z.shape[1], size=(2, rows.size))
        how = rng.integers(0, 3, size=rows.size)
        turned = z[rows, first] * (1 + 1j * rng.choice([1e-9, 1e-4, 0.1], size=rows.size))
        copied = z[rows, other] * (1 + 1e-6)
        z[rows, first] = np.where(how == 0, -z[rows, first], np.where(how == 1, turned, copied))
        return z[:, rng.permutation(z.shape[1])]

    def nudged(C, start, low, high):
        far = rng.random(start.shape) < 0.3
        start = np.where(far, start * rng.choice([0.5, 1.5, 3.0], start.shape), start)
        v = newton(C, start, np.where(far, 0.0, low), np.where(far, np.inf, high))
        ulps = rng.choice([0, 0, 1, -1, 2, -2, 1000], size=v.shape)
        return v + ulps * np.spacing(v)

    return roots, nudged


@settings(max_examples=150, deadline=None)
@given(
    st.one_of(
        repeated_roots(),
        clustered_roots(),
        plus_minus_plus(),
        tangent_with_pair(),
        four_positive_roots(),
        realistic_fisheye(),
    ),
    st.integers(0, 2**32),
)
def test_a_proven_answer_is_right_whatever_the_approximations(coefficients, seed):
    with pytest.MonkeyPatch.context() as patch:
        roots, nudged = careless(polynomial._approximate_roots, polynomial._newton, seed)
        patch.setattr(polynomial, "_approximate_roots", roots)
        patch.setattr(polynomial, "_newton", nudged)
        check_solver(coefficients)


# -- cases -------------------------------------------------------------------------------


def test_sony_a7_iv_sigma_28_70_at_70_mm_folds_at_0_366_rad():
    k = (0.303, 9.42, -168.1, 297.7)
    # Independently: theta_d'(theta) with the exact rationals of the k, by sympy.
    u = sympy.Symbol("u")
    k1, k2, k3, k4 = (rational(x) for x in k)
    slope = sympy.Poly(1 + 3 * k1 * u + 5 * k2 * u**2 + 7 * k3 * u**3 + 9 * k4 * u**4, u)
    first = min(r for r in slope.real_roots() if r > 0)
    theta = sympy.sqrt(first)
    theta_d = theta * (1 + k1 * first + k2 * first**2 + k3 * first**3 + k4 * first**4)
    got_theta, got_theta_d = opencv_fisheye_fold(*k)
    assert round(got_theta, 3) == 0.366
    assert abs(Fraction(got_theta) - Fraction(str(sympy.N(theta, 40)))) <= 2 * math.ulp(got_theta)
    assert abs(Fraction(got_theta_d) - Fraction(str(sympy.N(theta_d, 40)))) <= 2 * math.ulp(
        got_theta_d
    )
    assert first_sign_change(opencv_fisheye(*k).coefficients) == pytest.approx(float(first), 1e-15)


def test_the_fold_and_the_second_root_of_plus_minus_plus():
    # theta_d' > 0, < 0, > 0: the fold is the first of its two positive roots.
    got = first_sign_change([3 * 0.303, 5 * 9.42, 7 * -168.1, 9 * 297.7])
    assert 0.13 < got < 0.14


@pytest.mark.parametrize(
    ("coefficients", "expected"),
    [
        ((-2.0, 1.0, 0.0, 0.0), math.inf),  # (1 - w)^2: touches zero, no fold
        ((-4.0, 6.0, -4.0, 1.0), math.inf),  # (1 - w)^4
        ((-3.0, 3.0, -1.0, 0.0), 1.0),  # (1 - w)^3: a fold
        ((-3.5, 4.5, -2.5, 0.5), 1.0),  # (1 - w)^3 (1 - w / 2): the triple root first
        ((-5.0, 9.0, -7.0, 2.0), 0.5),  # (1 - w)^3 (1 - 2 w): the simple root first
        ((-2.5, 2.0, -0.5, 0.0), 2.0),  # (1 - w)^2 (1 - w / 2): the double root skipped
        ((-1.0, 0.0, 0.0, 0.0), 1.0),  # linear
        ((0.0, -4.0, 0.0, 0.0), 0.5),  # quadratic
        ((0.0, 0.0, -8.0, 0.0), 0.5),  # cubic
        ((0.0, 0.0, 0.0, -16.0), 0.5),  # quartic
        ((0.0, 0.0, 0.0, 0.0), math.inf),  # constant
        ((0.0, 1.0, 0.0, 1.0), math.inf),  # no negative coefficient
        ((-0.1, 1.0, 0.0, 0.0), math.inf),  # a complex pair
    ],
)
def test_exact_cases(coefficients, expected):
    assert first_sign_change(coefficients) == expected
    assert exact_first_sign_change(coefficients) == expected


@pytest.mark.parametrize("c1", [-MAX, -1e308, -(2.0**1023)])
def test_subnormal_roots_are_finite_and_positive(c1):
    got = first_sign_change([c1, 0.0, 0.0, 0.0])
    assert 0 < got < 2.0**-1022
    assert got == float(Fraction(-1) / Fraction(c1))  # correctly rounded
    got = first_sign_change([c1, c1, -c1, c1])
    check((c1, c1, -c1, c1), got)
    assert 0 < got < 2.0**-1021


def test_roots_beyond_the_largest_double_are_infinite():
    assert first_sign_change([-(2.0**-1024), 0.0, 0.0, 0.0]) == math.inf
    assert first_sign_change([-(2.0**-1074), 0.0, 1e-300, 0.0]) == math.inf
    assert first_sign_change([0.0, 0.0, 0.0, -(2.0**-1074)]) == 2.0**268.5  # finite
    for c1 in (-1 / MAX, -math.nextafter(1 / MAX, 1), -math.nextafter(1 / MAX, 0)):
        check((c1, 0.0, 0.0, 0.0), first_sign_change([c1, 0.0, 0.0, 0.0]))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_coefficients_give_nan(bad):
    assert math.isnan(first_sign_change([0.0, bad, 0.0, 0.0]))
    assert np.isnan(first_sign_change([[0.0, bad, 0.0, 0.0], [-1.0, 0, 0, 0]])).tolist() == [
        True,
        False,
    ]


def test_shapes_one_row_gives_a_float_and_arrays_keep_their_leading_axes():
    assert isinstance(first_sign_change([-1.0, 0.0, 0.0, 0.0]), float)
    rows = np.zeros((2, 3, 4))
    rows[..., 0] = -np.arange(1, 7).reshape(2, 3)
    assert first_sign_change(rows).shape == (2, 3)
    assert first_sign_change(rows)[1, 2] == 1 / 6
    assert first_sign_change(np.zeros((0, 4))).shape == (0,)
    with pytest.raises(ValueError):
        first_sign_change(1.0)


def test_any_number_of_coefficients():
    assert first_sign_change([-1.0]) == 1.0
    assert first_sign_change([0.0, 0.0, 0.0, 0.0, -32.0]) == 0.5  # degree five
    assert first_sign_change(np.zeros((3, 0))).tolist() == [math.inf] * 3


# -- the cubic as a special case ---------------------------------------------------------


def cubics(count: int, seed: int) -> np.ndarray:
    """Random cubics of every size and sign, with zeros, and the edge cubics."""
    rng = np.random.default_rng(seed)
    random = rng.normal(0, 1, (count, 3)) * np.exp(rng.normal(0, 4, (count, 3)))
    random[rng.random((count, 3)) < 0.2] = 0.0
    edges = np.array(
        [
            (-3.0, 3.0, -1.0),
            (-2.0, 1.0, 0.0),
            (-2.5, 2.0, -0.5),
            (0.0, 0.0, -(2.0**-1074)),
            (-MAX, 0.0, 0.0),
            (-MAX, MAX, -MAX),
            (1e-300, -1e-300, 1e-300),
            (-6.0, 12.0, -8.0),  # (1 - 2 w)^3
            (-1.0, 0.25, 0.0),  # (1 - w / 2)^2
        ]
    )
    return np.concatenate([random, edges])


def test_with_c4_zero_the_cubic_solver_decides_alike_and_agrees_within_its_bound():
    abc = cubics(4000, 7)
    cubic = min_positive_root(abc[:, 0], abc[:, 1], abc[:, 2])
    general = first_sign_change(np.concatenate([abc, np.zeros((len(abc), 1))], axis=1))
    assert np.array_equal(np.isinf(cubic), np.isinf(general))
    finite = np.isfinite(general)
    # min_positive_root is within 2^-43 (it says so); this one within one ulp.
    assert np.all(np.abs(cubic[finite] - general[finite]) <= 2.0**-43 * general[finite])
    assert np.mean(cubic == general) > 0.75


def test_with_c4_zero_where_the_two_differ_this_one_holds_the_exact_root():
    abc = cubics(3000, 11)
    cubic = min_positive_root(abc[:, 0], abc[:, 1], abc[:, 2])
    general = first_sign_change(np.concatenate([abc, np.zeros((len(abc), 1))], axis=1))
    differ = np.flatnonzero(cubic != general)
    assert differ.size
    for i in differ[:60]:
        check(tuple(abc[i].tolist()) + (0.0,), float(general[i]))


def test_the_cubic_models_describe_the_same_polynomial():
    cubic = ptlens(0.01, -0.05, 0.02)
    polynomial = as_polynomial(cubic)
    assert polynomial.coefficients.tolist() == [float(cubic.a), float(cubic.b), float(cubic.c)]
    assert first_sign_change(polynomial.coefficients) == min_positive_root(
        cubic.a, cubic.b, cubic.c
    )
    cubic = poly5(-0.3, 0.01)
    r_fold, d_fold = first_fold(as_polynomial(cubic))
    w = min_positive_root(cubic.a, cubic.b, cubic.c)
    assert r_fold == pytest.approx(math.sqrt(w), rel=2.0**-43)
    assert d_fold == pytest.approx(r_fold * (1 - 0.3 * w + 0.01 * w * w), rel=1e-15)


# -- the model and its fold ------------------------------------------------------------------


def test_opencv_fisheye_describes_its_derivative():
    model = opencv_fisheye(0.1, -0.2, 0.3, -0.4)
    assert model.power == 2
    assert model.coefficients.tolist() == [0.1 * 3, -0.2 * 5, 0.3 * 7, -0.4 * 9]
    theta = 0.7
    theta_d = np.polyval(model.distortion, theta)
    u = theta * theta
    assert theta_d == pytest.approx(theta * (1 + 0.1 * u - 0.2 * u**2 + 0.3 * u**3 - 0.4 * u**4))


def test_a_fisheye_that_never_folds_has_an_infinite_fold():
    assert opencv_fisheye_fold(0.0, 0.0, 0.0, 0.0) == (math.inf, math.inf)
    assert opencv_fisheye_fold(-0.01, 0.001, 0.0, 0.0) == (math.inf, math.inf)  # complex pair


def test_a_fold_whose_theta_d_overflows_gives_inf_for_theta_d_alone():
    # 1 + 7 u^3 - 9e-202 u^4: the fold at u = 7e201 / 9, theta_d about 1e706.
    theta, theta_d = opencv_fisheye_fold(0.0, 0.0, 1.0, -1e-202)
    assert theta == pytest.approx(math.sqrt(7 / 9e-202), rel=1e-15)
    assert theta_d == math.inf


@settings(max_examples=40, deadline=None)
@given(lens_k(0.5), lens_k(2.0), lens_k(20.0), lens_k(40.0))
def test_theta_d_at_the_fold_within_a_few_ulps(k1, k2, k3, k4):
    theta, theta_d = opencv_fisheye_fold(k1, k2, k3, k4)
    ks = [rational(k) for k in (k1, k2, k3, k4)]
    u = sympy.Symbol("u")
    slope = sympy.Poly(1 + sum((2 * i + 3) * k * u ** (i + 1) for i, k in enumerate(ks)), u)
    odd = sympy.Poly(1, u)
    for factor, multiplicity in slope.sqf_list()[1]:
        if multiplicity % 2:
            odd *= factor
    positive = [r for r in odd.real_roots() if r > 0] if odd.degree() > 0 else []
    if not positive:
        assert (theta, theta_d) == (math.inf, math.inf)
        return
    first = min(positive)
    exact = sympy.N(
        sympy.sqrt(first) * (1 + sum(k * first ** (i + 1) for i, k in enumerate(ks))), 40
    )
    assert abs(Fraction(theta_d) - Fraction(str(exact))) <= 4 * math.ulp(theta_d)


# -- speed and paths on real profiles ------------------------------------------------------


@pytest.fixture(scope="module")
def gyroflow_coefficients() -> np.ndarray:
    if not GYROFLOW.is_file():
        pytest.skip(f"no Gyroflow profiles at {GYROFLOW} (../shared/data from the repository)")
    import json

    ks = []
    with tarfile.open(GYROFLOW) as archive:
        for member in archive:
            if not member.name.endswith(".json"):
                continue
            try:
                k = json.load(archive.extractfile(member))["fisheye_params"]["distortion_coeffs"]
            except (KeyError, TypeError, ValueError):
                continue
            if isinstance(k, list) and len(k) == 4:
                ks.append([float(x) for x in k])
    return opencv_fisheye(*np.array(ks).T).coefficients


def test_every_gyroflow_profile_takes_a_proven_path_and_a_sample_agrees_with_exact(
    gyroflow_coefficients,
):
    roots, paths = first_sign_change_paths(gyroflow_coefficients)
    assert len(roots) > 9000
    assert np.mean(paths == EXACT) < 0.01
    sample = np.random.default_rng(3).choice(len(roots), 300, replace=False)
    for i in sample:
        exact = exact_first_sign_change(tuple(gyroflow_coefficients[i].tolist()))
        assert roots[i] == exact or abs(roots[i] - exact) < math.ulp(exact)
