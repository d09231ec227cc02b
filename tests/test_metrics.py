"""Per-entry metrics on models whose r_max has a closed form."""

from __future__ import annotations

import math
import warnings
from fractions import Fraction

import mpmath
import numpy as np
import pytest

from exact import odd_root_bracket
from lensaudit import metrics


def compute(
    model, a=np.nan, b=np.nan, c=np.nan, k1=np.nan, k2=np.nan, crop=1.0, aspect=1.5, focal=20.0
):
    return metrics.compute([model], [a], [b], [c], [k1], [k2], [crop], [aspect], [focal], [True])


@pytest.mark.parametrize("k1", [-0.01, -0.1, -0.3, -1.0])
def test_poly3_with_negative_k1_folds_at_the_closed_form_radius(k1):
    # D'(r) = (1 - k1) + 3 k1 r^2 = 0  =>  r_max^2 = (1 - k1) / (-3 k1)
    mpmath.mp.dps = 40
    k = mpmath.mpf(k1)
    r_max = mpmath.sqrt((1 - k) / (-3 * k))
    d_max = r_max * (1 - k + k * r_max**2)
    result = compute("poly3", k1=k1)
    assert float(result.r_max[0]) == pytest.approx(float(r_max), rel=1e-14)
    assert float(result.d_max[0]) == pytest.approx(float(d_max), rel=1e-14)
    assert result.tail[0] == -1


@pytest.mark.parametrize("k1", [0.0, 0.01, 0.5])
def test_poly3_with_non_negative_k1_below_one_never_folds(k1):
    result = compute("poly3", k1=k1)
    assert math.isinf(result.r_max[0]) and math.isinf(result.d_max[0])
    assert result.tail[0] == 0 and not result.folds_in_image[0]


def test_model_decreasing_at_the_centre_has_no_valid_domain():
    result = compute("poly3", k1=1.5)  # D'(0) = 1 - k1 < 0
    assert result.r_max[0] == 0 and result.folds_in_image[0]


def test_ptlens_that_dips_and_recovers_has_a_positive_tail():
    # a = 1/11, b = 0, c = -14/11 give D'(r) = (4/11)(r - 1)(r - 2)(r + 3):
    # D rises to r = 1, falls to r = 2, then rises for ever. D(1) = 1 for any ptlens.
    result = compute("ptlens", a=1 / 11, b=0.0, c=-14 / 11)
    assert result.r_max[0] == pytest.approx(1.0, rel=1e-14)
    assert result.d_max[0] == pytest.approx(1.0, rel=1e-14)
    assert result.tail[0] == 1


def test_ptlens_with_negative_leading_coefficient_has_a_negative_tail():
    result = compute("ptlens", a=-0.024, b=-0.002, c=0.005)
    assert np.isfinite(result.r_max[0]) and result.tail[0] == -1


def test_image_corner_is_in_hugin_units_independent_of_focal():
    assert float(metrics.image_corner(1.5)) == pytest.approx(math.sqrt(13) / 2, rel=1e-15)
    assert float(metrics.image_corner(4 / 3)) == pytest.approx(5 / 3, rel=1e-15)
    assert float(metrics.image_corner(2 / 3)) == float(metrics.image_corner(1.5))
    a = compute("poly3", k1=-0.1, focal=10)
    b = compute("poly3", k1=-0.1, focal=100)
    assert a.r_normalized[0] == b.r_normalized[0]


def test_paper_corner_is_the_papers_equation_29():
    result = compute("poly3", k1=-0.1, crop=1.5, focal=20)
    assert result.r_corner_paper[0] == pytest.approx(math.hypot(18, 12) / 30, rel=1e-15)
    assert result.r_normalized_paper[0] == pytest.approx(
        result.d_max[0] / (math.hypot(18, 12) / 30), rel=1e-15
    )


def test_folds_in_image_means_d_max_below_the_corner():
    mild = compute("poly3", k1=-0.05)  # fold far outside the corner
    strong = compute("poly3", k1=-0.3)  # fold inside
    assert mild.r_normalized[0] > 1 and not mild.folds_in_image[0]
    assert strong.r_normalized[0] < 1 and strong.folds_in_image[0]


def test_entries_not_audited_get_no_metrics():
    result = metrics.compute(
        ["poly3", "acm"],
        [np.nan] * 2,
        [np.nan] * 2,
        [np.nan] * 2,
        [-0.1, 0.2],
        [np.nan] * 2,
        [1, 1],
        [1.5, 1.5],
        [10, 10],
        [True, False],
    )
    assert np.isfinite(result.r_max[0]) and np.isnan(result.r_max[1])
    assert not result.folds_in_image[1] and result.tail[1] == 0


# -- coefficients near the top of the binary64 range -------------------------------------


def exact_fold(distortion: list[Fraction], power: int) -> tuple[Fraction, Fraction]:
    """(r_max, d_max) in exact arithmetic: D(r) highest power first, w = r**power."""
    degree = len(distortion) - 1
    slope = [(j + 1) * distortion[degree - j - 1] for j in range(degree)]  # D', lowest first
    cubic = (slope[::power] + [Fraction(0)] * 4)[:4]
    lo, hi = odd_root_bracket(*(x / cubic[0] for x in cubic[1:]))
    w = (lo + hi) / 2
    # The root of w = r^2 to 80 bits, by bisection in rationals.
    r = w
    if power == 2:
        low, high = Fraction(0), max(w, Fraction(1))
        for _ in range(200):
            middle = (low + high) / 2
            low, high = (middle, high) if middle * middle < w else (low, middle)
        r = low
    d_max = Fraction(0)
    for x in distortion:
        d_max = d_max * r + x
    return r, d_max


def relative_error(got: float, expected: Fraction) -> float:
    return float(abs(Fraction(got) - expected) / abs(expected))


@pytest.mark.parametrize(
    ("model", "coefficients", "distortion", "power"),
    [
        # D'(r) = 4e308 r^3 - 2e308 r + 1 first falls to zero near r = 5e-309.
        ("ptlens", dict(a=1e308, b=0.0, c=-1e308), [1e308, 0, -1e308, 1, 0], 1),
        ("ptlens", dict(a=-1e308, b=1e308, c=0.0), [-1e308, 1e308, 0, 1, 0], 1),
        ("poly5", dict(k1=1e308, k2=-1e308), [-1e308, 0, 1e308, 0, 1, 0], 2),
        ("poly3", dict(k1=-1e308), [-1e308, 0, 1 + Fraction(1e308), 0], 2),
    ],
)
def test_coefficients_near_the_largest_double_keep_every_number_without_warnings(
    model, coefficients, distortion, power
):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = compute(model, **coefficients)
    r_max, d_max = exact_fold([Fraction(x) for x in distortion], power)
    corner = Fraction(math.sqrt(13) / 2)
    assert relative_error(result.r_max[0], r_max) < 1e-12
    assert relative_error(result.d_max[0], d_max) < 1e-12
    assert relative_error(result.r_normalized[0], d_max / corner) < 1e-12
    assert result.tail[0] == (1 if distortion[0] > 0 else -1)
    assert result.folds_in_image[0] == (d_max < corner)


def test_exact_values_beyond_the_largest_double_round_to_infinity():
    """D(r_max) of the exact path can exceed every double: it becomes +-inf, not an error."""
    from fractions import Fraction

    from lensaudit.metrics import _nearest_double

    assert _nearest_double(Fraction(10) ** 400) == math.inf
    assert _nearest_double(-(Fraction(10) ** 400)) == -math.inf
    assert _nearest_double(Fraction(3, 2)) == 1.5


def test_columns_of_another_length_are_refused_and_single_values_stand_for_all():
    one = metrics.compute("poly3", 0.0, 0.0, 0.0, -0.3, 0.0, 1.5, 1.5, 10.0, True)
    many = metrics.compute(["poly3"] * 3, 0.0, 0.0, 0.0, [-0.3] * 3, 0.0, 1.5, 1.5, 10.0, True)
    assert list(many.r_max) == [one.r_max[0]] * 3 and bool(one.folds_in_image[0])
    with pytest.raises(ValueError, match=r"k1 has shape \(2,\): one value per entry needs \(3,\)"):
        metrics.compute(["poly3"] * 3, 0, 0, 0, [-0.3, 0.1], 0, 1.5, 1.5, 10.0, True)
