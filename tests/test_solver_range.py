"""The solver over the whole binary64 range, against exact rational arithmetic.

The reference (tests/exact.py) isolates the smallest positive root of odd
multiplicity with Sturm sequences in exact rationals on the binary64 inputs,
with no floating point at all.
"""

from __future__ import annotations

import math
import warnings
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from exact import exceeds_max_float, odd_root_bracket
from lensaudit import normalizer
from lensaudit.read import read
from lensaudit.read.paths import bundled_database_path
from lensaudit.solver.arrays import PATHS, min_positive_root, min_positive_root_paths

TOLERANCE = Fraction(1, 10**12)
SMALLEST_NORMAL = Fraction(2) ** -1022
EXACT_PATH = PATHS.index("exact")


def solve_quietly(a: float, b: float, c: float) -> float:
    """min_positive_root, failing on any warning numpy or Python would emit."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(all="raise"):
            return min_positive_root(a, b, c)


def check_against_exact(a: float, b: float, c: float) -> None:
    got = solve_quietly(a, b, c)
    if exceeds_max_float(a, b, c):
        assert got == math.inf, f"{(a, b, c)}: no sign change up to the largest double, got {got}"
        return
    lo, hi = odd_root_bracket(a, b, c)
    assert math.isfinite(got) and got > 0, f"{(a, b, c)}: root {float(lo)!r}, got {got}"
    if lo >= SMALLEST_NORMAL:
        error = max(abs(Fraction(got) - lo), abs(Fraction(got) - hi)) / lo
        assert error <= TOLERANCE, f"{(a, b, c)}: root {float(lo)!r}, got {got!r}, error {error}"


# -- strategies ----------------------------------------------------------------------

#: Any finite double: hypothesis favours zeros, subnormals and the extremes.
any_double = st.floats(allow_nan=False, allow_infinity=False)

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

sign = st.sampled_from([-1, 1])


def dyadic(mantissa_bits: int, low: int, high: int) -> st.SearchStrategy[Fraction]:
    """m 2^e with 0 < m < 2^mantissa_bits: products of a few stay exact in binary64.

    The callers keep low and high such that their cubics stay below 2^1024.
    """
    return st.builds(
        lambda m, e: Fraction(m) * Fraction(2) ** e,
        st.integers(1, 2**mantissa_bits - 1),
        st.integers(low, high),
    )


def rounded(*coefficients: Fraction) -> tuple[float, ...]:
    return tuple(float(x) for x in coefficients)


@st.composite
def double_roots(draw) -> tuple[float, float, float]:
    """(1 - rho w)^2 (1 - sigma w): a double root at 1/rho, exact when rho, sigma are near."""
    rho = draw(sign) * draw(dyadic(8, -330, 300))
    sigma = draw(sign) * rho * draw(dyadic(8, -30, 22))
    return rounded(-(2 * rho + sigma), rho * rho + 2 * rho * sigma, -rho * rho * sigma)


@st.composite
def triple_roots(draw) -> tuple[float, float, float]:
    """(1 - rho w)^3, exact: a crossing at 1/rho when rho > 0."""
    rho = draw(sign) * draw(dyadic(17, -330, 320))
    return rounded(-3 * rho, 3 * rho * rho, -(rho**3))


@st.composite
def near_tangencies(draw) -> tuple[float, float, float]:
    """(1 - rho w)^2 plus a tiny cubic term, which alone decides whether p crosses."""
    rho = draw(dyadic(20, -330, 310))
    tiny = draw(sign) * rho**3 * Fraction(2) ** -draw(st.integers(1, 1400))
    return rounded(-2 * rho, rho * rho, tiny)


@st.composite
def perturbed_double_roots(draw) -> tuple[float, float, float]:
    """(1 - rho w)^2 (1 + tau w) with tau tiny, expanded and rounded to binary64."""
    rho = draw(dyadic(30, -330, 300))
    tau = draw(sign) * rho * Fraction(2) ** -draw(st.integers(1, 700))
    return rounded(tau - 2 * rho, rho * rho - 2 * rho * tau, rho * rho * tau)


# -- the whole range ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("a", "b", "c"),
    [
        (1e40, -1e-84, 0.0),  # the positive root at 1e124 is decided by the tiny b
        (1.5e268, -1.6e29, 0.0),  # the scale factor for b alone would overflow
        (1e200, -1e200, -1e200),  # a root near 0.618 among huge coefficients
    ],
)
def test_coefficients_of_very_different_sizes_give_the_exact_root(a, b, c):
    check_against_exact(a, b, c)


def test_a_root_beyond_the_largest_double_is_infinite():
    # 1 - 1e-320 w: the root 1e320 is no double.
    assert solve_quietly(-1e-320, 0.0, 0.0) == math.inf


@pytest.mark.parametrize("steps", range(-3, 4))
def test_roots_next_to_the_largest_double_are_decided_exactly(steps):
    # 1 + a w with a within a few doubles of -1 / 1.8e308: the root 1/|a| lies
    # just below or just beyond the largest double.
    a = -1 / 1.7976931348623157e308
    for _ in range(abs(steps)):
        a = math.nextafter(a, 0.0 if steps > 0 else -1.0)
    check_against_exact(a, 0.0, 0.0)
    check_against_exact(a, 0.0, 1e-320)


def test_a_subnormal_root_is_finite_and_positive():
    root = solve_quietly(-1.7e308, 0.0, 0.0)  # 1 / 1.7e308, below the smallest normal
    assert 0 < root < 2.0**-1022


@settings(max_examples=300, deadline=None)
@given(any_double, any_double, any_double)
def test_any_finite_doubles_give_the_exact_decision_and_root(a, b, c):
    check_against_exact(a, b, c)


@settings(max_examples=300, deadline=None)
@given(spread_double, spread_double, spread_double)
@example(1e-300, -1e300, 1e-300)
@example(3e-300, -7e250, 5e-310)
def test_exponents_spread_over_the_whole_range_give_the_exact_root(a, b, c):
    check_against_exact(a, b, c)


@settings(max_examples=150, deadline=None)
@given(double_roots())
def test_a_double_root_is_never_taken_for_a_crossing(cubic):
    check_against_exact(*cubic)


@settings(max_examples=100, deadline=None)
@given(triple_roots())
def test_a_triple_root_is_a_crossing(cubic):
    check_against_exact(*cubic)


@settings(max_examples=150, deadline=None)
@given(near_tangencies())
@example((-2.0, 1.0, 1e-300))  # (1 - w)^2 + tiny w^3 never reaches zero for w > 0
@example((-2.0, 1.0, -1e-300))  # ... but crosses near w = 1 when the tiny term is negative
def test_a_tiny_cubic_term_decides_a_near_tangency(cubic):
    check_against_exact(*cubic)


@settings(max_examples=150, deadline=None)
@given(perturbed_double_roots())
def test_perturbed_double_roots_give_the_exact_root(cubic):
    check_against_exact(*cubic)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(spread_double, spread_double, spread_double), min_size=1, max_size=40))
def test_array_and_scalar_calls_agree(cubics):
    a, b, c = (np.array(column) for column in zip(*cubics, strict=True))
    together = min_positive_root(a, b, c)
    apart = [min_positive_root(*cubic) for cubic in cubics]
    np.testing.assert_array_equal(together, apart)


# -- Lensfun-like cubics stay on the fast path ----------------------------------------------


def test_lensfun_database_cubics_never_need_exact_arithmetic():
    entries = [e for e in read(bundled_database_path()).entries() if e.status == "ok"]
    cubics = [
        normalizer.ptlens(
            *(np.array([getattr(e, n) for e in entries if e.model == "ptlens"]) for n in "abc")
        ),
        normalizer.poly3(np.array([e.k1 for e in entries if e.model == "poly3"])),
        normalizer.poly5(
            *(
                np.array([getattr(e, n) for e in entries if e.model == "poly5"])
                for n in ("k1", "k2")
            )
        ),
    ]
    for cubic in cubics:
        _, paths = min_positive_root_paths(cubic.a, cubic.b, cubic.c)
        assert not np.any(paths == EXACT_PATH)


def test_lensfun_sized_random_cubics_almost_never_need_exact_arithmetic():
    rng = np.random.default_rng(7)
    size = 200_000
    a, b, c = (
        rng.choice([-1.0, 1.0], size) * 10.0 ** rng.uniform(-12, 1, size) * (rng.random(size) > 0.2)
        for _ in range(3)
    )
    _, paths = min_positive_root_paths(a, b, c)
    assert np.mean(paths == EXACT_PATH) < 1e-4
