"""The cubic solver, against exact arithmetic on the exact binary64 inputs."""

from __future__ import annotations

import math
import random
import warnings

import mpmath
import numpy as np
import pytest

import lensaudit.solver
from exact import reference
from lensaudit.solver import (
    arrays,
    min_positive_root,
    min_positive_root_paper,
    min_positive_root_paper_vectorized,
)

#: Accuracy the solver promises for roots separated from the others by more
#: than SEPARATION (relative).
TOLERANCE = 1e-12
SEPARATION = 1e-6


def from_roots(*roots: complex) -> tuple[float, float, float]:
    """(a, b, c) of prod(1 - w / r), rounded to binary64; up to 3 roots."""
    coefficients = np.array([1.0 + 0j])
    for root in roots:
        coefficients = np.convolve(coefficients, [1.0, -1.0 / root])
    coefficients = list(np.real(coefficients)) + [0.0] * (4 - len(coefficients))
    return float(coefficients[1]), float(coefficients[2]), float(coefficients[3])


# -- behaviour on hand-derivable cases ------------------------------------------------


@pytest.mark.parametrize(
    ("roots", "expected"),
    [
        ((2.0,), 2.0),  # linear
        ((0.5, 4.0), 0.5),  # quadratic, two crossings
        ((-1.0, 3.0), 3.0),  # negative root ignored
        ((-1.0, -2.0), math.inf),  # no positive root
        ((0.25, 0.5, 8.0), 0.25),  # three positive roots
        ((-0.5, -4.0, 16.0), 16.0),
    ],
)
def test_roots_of_products_of_linear_factors(roots, expected):
    assert min_positive_root(*from_roots(*roots)) == pytest.approx(expected, rel=1e-15)


def test_double_root_is_not_a_fold():
    assert min_positive_root(-2.0, 1.0, 0.0) == math.inf  # (1 - w)^2
    assert min_positive_root(*from_roots(2.0, 2.0)) == math.inf  # exact in binary


def test_double_root_before_a_crossing_is_skipped():
    a, b, c = from_roots(0.5, 0.5, 4.0)  # exactly representable: (1 - 2w)^2 (1 - w/4)
    assert min_positive_root(a, b, c) == 4.0


def test_triple_root_is_a_fold():
    assert min_positive_root(-3.0, 3.0, -1.0) == 1.0  # (1 - w)^3 changes sign


def test_complex_pair_gives_no_fold():
    assert min_positive_root(0.0, 1.0, 0.0) == math.inf  # 1 + w^2


@pytest.mark.parametrize(
    ("a", "b", "c"), [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1e-10), (1.0, 1.0, 1.0)]
)
def test_never_negative_means_infinite(a, b, c):
    assert min_positive_root(a, b, c) == math.inf


def test_lower_degrees_are_exact_cases():
    assert min_positive_root(-4.0, 0.0, 0.0) == 0.25
    assert min_positive_root(0.0, -4.0, 0.0) == 0.5
    assert min_positive_root(0.0, 0.0, -8.0) == 0.5


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_coefficients_give_nan(bad):
    assert math.isnan(min_positive_root(bad, 0.0, -1.0))
    assert math.isnan(min_positive_root(-1.0, bad, 0.0))
    assert math.isnan(min_positive_root(-1.0, 0.0, bad))


def test_scalars_give_a_float_and_arrays_broadcast():
    assert isinstance(min_positive_root(-1.0, 0.0, 0.0), float)
    result = min_positive_root(np.array([[-1.0], [-4.0]]), 0.0, np.zeros(3))
    assert result.shape == (2, 3)
    np.testing.assert_array_equal(result, [[1.0] * 3, [0.25] * 3])


def test_no_numpy_warnings_for_any_input():
    values = np.array(
        [0.0, -0.0, 1e-300, -1e-300, 1e300, -1e300, np.nan, np.inf, -np.inf, 1.0, -1.0, 5e-324]
    )
    a, b, c = np.meshgrid(values, values, values)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(all="raise"):
            result = min_positive_root(a, b, c)
    assert result.shape == a.shape


# -- the adversarial set --------------------------------------------------------------


def adversarial_cases(
    seed: int = 2022, per_kind: int = 400
) -> list[tuple[str, float, float, float]]:
    """Deterministic hard cases, by kind."""
    rng = random.Random(seed)

    def magnitude(low, high):
        return rng.choice((-1, 1)) * 10 ** rng.uniform(low, high)

    cases = []
    for _ in range(per_kind):
        cases.append(("wide magnitudes", magnitude(-10, 6), magnitude(-10, 6), magnitude(-10, 6)))
        a, b = magnitude(-3, 3), magnitude(-3, 3)
        cases.append(("nearly quadratic", a, b, magnitude(-10, -6) * max(abs(a), abs(b)) ** 1.5))
        a = magnitude(-3, 3)
        cases.append(("nearly linear", a, magnitude(-10, -6) * a * a, magnitude(-10, -6) * a**3))
        root = 10 ** rng.uniform(-3, 3)
        spread = 10 ** rng.uniform(-12, -1)
        third = magnitude(-3, 3)
        cases.append(("clustered roots", *from_roots(root, root * (1 + spread), third)))
        cases.append(
            (
                "near-double complex pair",
                *from_roots(complex(root, root * spread), complex(root, -root * spread), third),
            )
        )
        cases.append(
            ("near-double real pair", *from_roots(root * (1 - spread), root * (1 + spread), third))
        )
        exact_root = rng.choice((0.25, 0.5, 1.0, 2.0, 4.0, 0.125, 3.0, 1.5))
        cases.append(
            (
                "exact double root",
                *from_roots(
                    exact_root, exact_root, rng.choice((-1, 1)) * 2.0 ** rng.randint(-3, 5)
                ),
            )
        )
        a, b, c = magnitude(-10, 6), magnitude(-10, 6), magnitude(-10, 6)
        zeros = rng.choice(((a, 0.0, c), (a, b, 0.0), (0.0, b, c), (0.0, 0.0, c), (0.0, b, 0.0)))
        cases.append(("exact zeros", *zeros))
    return cases


@pytest.fixture(scope="module")
def judged_cases():
    """Each adversarial case with its exact root and separation."""
    cases = adversarial_cases()
    judged = []
    for kind, a, b, c in cases:
        root, separation = reference(a, b, c)
        judged.append((kind, a, b, c, root, separation))
    return judged


def failures(judged, solve) -> list[tuple]:
    """Cases `solve` gets wrong: finite/infinite swapped, or too inaccurate when separated."""
    failed = []
    for kind, a, b, c, root, separation in judged:
        try:
            got = solve(a, b, c)
        except (ArithmeticError, ValueError):
            failed.append((kind, a, b, c, "exception"))
            continue
        if (root == mpmath.inf) != (got == math.inf) or math.isnan(got):
            failed.append((kind, a, b, c, "misclassified", got, root))
        elif root != mpmath.inf and separation > SEPARATION:
            error = abs(mpmath.mpf(got) - root) / root
            if error > TOLERANCE:
                failed.append((kind, a, b, c, "inaccurate", got, root, error))
    return failed


def test_adversarial_set_has_no_failures(judged_cases):
    wrong = failures(judged_cases, min_positive_root)
    assert wrong == []


def test_adversarial_set_covers_every_kind_with_folds_and_no_folds(judged_cases):
    kinds = {}
    for kind, *_, root, _ in judged_cases:
        finite, total = kinds.get(kind, (0, 0))
        kinds[kind] = (finite + (root != mpmath.inf), total + 1)
    assert len(kinds) == 8
    assert all(
        0 < finite < total for kind, (finite, total) in kinds.items() if kind != "nearly linear"
    ), kinds


def test_vectorized_solver_gives_the_same_answers_as_one_by_one(judged_cases):
    a, b, c = (np.array([case[i] for case in judged_cases]) for i in (1, 2, 3))
    together = min_positive_root(a, b, c)
    apart = np.array([min_positive_root(x, y, z) for x, y, z in zip(a, b, c, strict=True)])
    np.testing.assert_array_equal(together, apart)


def test_the_papers_algorithm_fails_where_this_solver_does_not(judged_cases):
    """The margin: Algorithm 1 as printed misclassifies or loses accuracy on several percent."""
    paper = failures(judged_cases, min_positive_root_paper)
    ours = failures(judged_cases, min_positive_root)
    rate = len(paper) / len(judged_cases)
    misclassified = sum(1 for f in paper if f[4] == "misclassified") / len(judged_cases)
    print(
        f"paper's Algorithm 1: {rate:.1%} wrong ({misclassified:.1%} finite/infinite swapped); "
        f"lensaudit: {len(ours)} wrong of {len(judged_cases)}"
    )
    assert rate > 0.02 and misclassified > 0.01
    assert ours == []


def test_paper_vectorized_matches_paper_scalar_on_ordinary_cubics():
    # Lensfun-sized coefficients, where the two roundings of the formula agree.
    rng = np.random.default_rng(5)
    a, b, c = rng.uniform(-0.5, 0.5, (3, 500))
    vectorized = min_positive_root_paper_vectorized(a, b, c)
    scalar = np.array([min_positive_root_paper(x, y, z) for x, y, z in zip(a, b, c, strict=True)])
    np.testing.assert_allclose(vectorized, scalar, rtol=1e-9)


@pytest.mark.parametrize(("a", "b", "c"), [(6.0, 6.0, 2.0), (0.0, 1e308, 1.0), (1e308, 0.0, -1.0)])
def test_the_papers_algorithm_rounds_as_ieee_does_in_both_forms(a, b, c):
    # 6, 6, 2: gamma = b^2 - 3ac = 0, so gamma / u divides by zero; 1e308: b^3 overflows.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scalar = min_positive_root_paper(a, b, c)
        vectorized = float(min_positive_root_paper_vectorized(a, b, c))
    assert scalar == vectorized or (math.isnan(scalar) and math.isnan(vectorized))


def test_the_papers_algorithm_can_return_a_negative_radius():
    # 1 + w + w^2 + w^3 = (1 + w)(1 + w^2): its only real root is -1. Algorithm 1's
    # single-real-root branch returns it unchecked; there is no fold at all.
    assert min_positive_root_paper(1.0, 1.0, 1.0) == pytest.approx(-1.0)
    assert min_positive_root(1.0, 1.0, 1.0) == math.inf


def test_the_package_gives_the_array_codes_functions():
    for name in lensaudit.solver.__all__:
        assert getattr(lensaudit.solver, name) is getattr(arrays, name)
    assert lensaudit.solver.min_positive_root is min_positive_root


def test_importing_the_solver_package_or_its_kernel_does_not_import_numpy():
    import subprocess
    import sys

    code = (
        "import sys\n"
        "import lensaudit.solver, lensaudit.solver.kernel\n"
        "print('numpy' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False"
