"""The refit of one distortion model, the core of :mod:`lensaudit.fix`: the
linear program, the exact verdict, the change of D and the rounding (the
method is described there).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.polynomial import polynomial as P

from . import metrics
from .columns import FOLD_MARGIN
from .read.records import MODEL_COEFFICIENTS

#: Frame in which changes are reported, for messages and documentation, and
#: its half diagonal in pixels.
FRAME = "6000x4000"
HALF_DIAGONAL_PX = math.hypot(3000.0, 2000.0)
#: The r_normalized a fixed model reaches: check's margin (see FOLD_MARGIN).
DEFAULT_MARGIN = FOLD_MARGIN
#: Least slope D' a fixed model keeps from the centre to where D reaches the
#: margin: undistorting stretches the image radially by 1 / D', so at most
#: five times. The linear program asks for a little more
#: (:data:`FLOOR_SLACK`), so that the model keeps it between grid points
#: and after rounding; the verification asks for this, exactly.
SLOPE_FLOOR = 0.2
FLOOR_SLACK = 1.01
#: D(T) must exceed the distorted radius to reach by this relative margin, so
#: that rounding in the audit's own arithmetic cannot turn it back into a fold.
REACH_SLACK = 1e-5
#: Least number of significant digits a new coefficient is written with.
MIN_SIGNIFICANT_DIGITS = 5


GRID_POINTS = 161  # points of the image's grid of the linear program
#: The slope's grid: s = r / (1 + r) at every 1/SLOPE_STEPS of [0, 1] up to the radius T.
SLOPE_STEPS = 256
#: The radii T tried: s = T / (1 + T) at every 1/RADIUS_STEPS of [0, 1], T = k / (64 - k),
#: and T = inf. The same radii for every target, so that the radii tried for a
#: target are those tried for any larger one, and more (see :func:`radii_from`).
RADIUS_STEPS = 32
_SEARCH_POINTS = 17  # values of the reach radius R tried before the bounded search
#: Least slope the linear program asks beyond R, up to T: D' > 0 there (r_max
#: beyond T), with room for the points between the grid's and for rounding.
RISE = 0.02
_REFINEMENTS = 12  # rounds of grid refinement before giving up
EXTRA_DIGITS = 12  # digits added at most when rounding breaks a fix
_GAUSS_POINTS = 48  # Gauss-Legendre nodes per axis for the RMS over the frame

# D(r) = r + sum of coefficient x term(r); terms as polynomial coefficients, lowest power first.
_TERMS: dict[str, tuple[tuple[float, ...], ...]] = {
    "ptlens": ((0, -1, 0, 0, 1), (0, -1, 0, 1), (0, -1, 1)),
    "poly3": ((0, -1, 0, 1),),
    "poly5": ((0, 0, 0, 1), (0, 0, 0, 0, 0, 1)),
}
_IDENTITY = np.array([0.0, 1.0])
#: Degree of D' in r, per model.
_SLOPE_DEGREE = {model: max(map(len, terms)) - 2 for model, terms in _TERMS.items()}


def distortion_polynomial(model: str, coefficients: Sequence[float]) -> np.ndarray:
    """D(r) of a model as polynomial coefficients, lowest power first (Hugin units).
    Raises ``ValueError`` for an unknown model or a coefficient that is not a
    finite number."""
    if model not in _TERMS:
        raise ValueError(f"unknown model {model!r}: not one of {', '.join(_TERMS)}")
    if not all(math.isfinite(value) for value in coefficients):
        raise ValueError(f"{model} coefficients {list(coefficients)} are not all finite numbers")
    result = _IDENTITY.copy()
    for value, term in zip(coefficients, _TERMS[model], strict=True):
        result = P.polyadd(result, value * np.asarray(term, dtype=np.float64))
    return result


def term_matrix(model: str) -> np.ndarray:
    """One row per coefficient: its term of D, padded to degree 5."""
    rows = np.zeros((len(_TERMS[model]), 6))
    for index, term in enumerate(_TERMS[model]):
        rows[index, : len(term)] = term
    return rows


def pixels_per_unit(aspect_ratio: float) -> float:
    """Pixels of the 6000x4000 frame per Hugin unit of a model calibrated at
    ``aspect_ratio``, as liblensfun applies it: it matches the diagonal of
    the calibration's frame (aspect x 1 Hugin units, corner hypot(aspect,
    1)) to the image's, so 2000 px at 3:2 and 2163 px at 4:3."""
    return HALF_DIAGONAL_PX / float(metrics.image_corner(aspect_ratio))


@dataclass(frozen=True)
class Change:
    """How far a new model's D is from the old one's: in pixels of the reporting
    frame (scaled as liblensfun scales it, see :func:`pixels_per_unit`), and
    the largest as a fraction of the half diagonal."""

    max_px: float
    rms_px: float
    max_half_diagonal: float = 0.0


def change_of_distortion(
    model: str,
    old: Sequence[float],
    new: Sequence[float],
    aspect_ratio: float,
    image_radius: float | None = None,
) -> Change:
    """Maximum and RMS of |D_new - D_old| over the image, in pixels of the
    6000x4000 frame as liblensfun scales the model to it (:func:`pixels_per_unit`).

    The image is the frame (aspect x 1 Hugin units) within ``image_radius``
    of its centre: by default the corner, hypot(aspect, 1), so the whole
    frame; a smaller radius (a circular fisheye's image circle) leaves out
    the rest. The maximum is over radii 0 to that radius, found exactly at
    the end points and the real roots of the difference's derivative; the
    RMS is over the image's area, every pixel alike. Raises ``ValueError``
    for an aspect ratio that is not a positive number, and as
    :func:`distortion_polynomial` does.
    """
    if not (aspect_ratio > 0 and math.isfinite(aspect_ratio)):
        raise ValueError(f"aspect ratio {aspect_ratio!r} is not a positive number")
    difference = P.polysub(distortion_polynomial(model, new), distortion_polynomial(model, old))
    difference = np.trim_zeros(difference, "b")
    aspect = max(aspect_ratio, 1.0 / aspect_ratio)
    r_corner = math.hypot(aspect, 1.0)
    radius = r_corner if image_radius is None else min(image_radius, r_corner)
    if difference.size == 0:
        return Change(0.0, 0.0, 0.0)
    radii = [0.0, radius]
    if difference.size > 2:
        roots = P.polyroots(P.polyder(difference))
        radii += [
            root.real
            for root in roots
            if abs(root.imag) <= 1e-12 * max(1.0, abs(root)) and 0 < root.real < radius
        ]
    largest = float(np.max(np.abs(P.polyval(np.array(radii), difference))))
    nodes, weights = np.polynomial.legendre.leggauss(_GAUSS_POINTS)
    if radius >= r_corner:
        # The whole frame: a tensor Gauss-Legendre rule over a quarter of it.
        x = (nodes + 1) * aspect / 2
        y = (nodes + 1) / 2
        squares = P.polyval(np.hypot(x[:, None], y[None, :]), difference) ** 2
        mean_square = float(np.einsum("i,j,ij->", weights, weights, squares) / 4)
    else:
        mean_square = _mean_square_within(difference, aspect, radius, nodes, weights)
    unit = pixels_per_unit(aspect_ratio)
    return Change(largest * unit, math.sqrt(mean_square) * unit, largest / r_corner)


def _mean_square_within(
    difference: np.ndarray, aspect: float, radius: float, nodes: np.ndarray, weights: np.ndarray
) -> float:
    """Mean of difference(r)^2 over the quarter frame [0, aspect] x [0, 1] within ``radius``.

    In polar form: the integral of f(r)^2 r theta(r) dr, with theta(r) the
    angle of the circle of radius r inside the quarter frame. theta has
    square-root kinks where the circle leaves the frame's sides (r = 1, r =
    aspect); each piece is integrated with r = low + (high - low) u^2, which
    smooths them for the Gauss-Legendre rule.
    """
    u = (nodes + 1) / 2
    edges = sorted({0.0, *(e for e in (1.0, aspect) if e < radius), radius})
    total = area = 0.0
    for low, high in zip(edges, edges[1:], strict=False):
        r = low + (high - low) * u**2
        jacobian = 2 * (high - low) * u * weights / 2
        with np.errstate(invalid="ignore"):
            theta = np.where(
                r <= 1, math.pi / 2, np.arcsin(np.minimum(1.0, 1.0 / np.maximum(r, 1e-300)))
            )
            theta = theta - np.where(r > aspect, np.arccos(np.minimum(1.0, aspect / r)), 0.0)
        weight = r * theta * jacobian
        total += float(np.sum(P.polyval(r, difference) ** 2 * weight))
        area += float(np.sum(weight))
    return total / area


@dataclass(frozen=True)
class Goal:
    """What a fixed model must do, in Hugin units.

    ``target``: undistorted radius up to which D must be increasing (r_max
    beyond it; ``inf`` for a model that never folds). ``reach``: distorted
    radius D must attain before it folds (d_max >= reach). ``margin``: the
    r_normalized = d_max / r_corner the fixed model must have at least.
    ``aspect_ratio`` is the image's, and r_corner = hypot(aspect, 1).
    """

    aspect_ratio: float
    r_corner: float
    target: float
    reach: float
    margin: float


def goal_for(
    aspect_ratio: float,
    margin: float = DEFAULT_MARGIN,
    target: float | None = None,
    image_radius: float | None = None,
) -> Goal:
    """The goal for an image of the given aspect ratio.

    ``image_radius`` is the radius of the image the model must not fold
    inside (Hugin units), by default its corner hypot(aspect, 1); the goal's
    ``r_corner`` is that radius. The target defaults to that radius times
    the margin, and is never below it.
    """
    if image_radius is None:
        r_corner = float(metrics.image_corner(aspect_ratio))
    else:
        r_corner = float(image_radius)
    if target is None:
        target = r_corner * max(margin, 1.0)
    return Goal(aspect_ratio, r_corner, float(target), r_corner * margin, margin)


@dataclass(frozen=True)
class Verdict:
    """The audit of one model: r_max, d_max, r_normalized, the smallest slope
    D' from the centre to where D reaches the goal's distorted radius (NaN
    if it folds first), and whether it meets the goal."""

    r_max: float
    d_max: float
    r_normalized: float
    meets_goal: bool
    min_slope: float = math.nan


def smallest_slope(model: str, coefficients: Sequence[float], reach: float, r_max: float) -> float:
    """The smallest D'(r) for r from 0 to where D first reaches ``reach`` before
    ``r_max`` (NaN if it does not): at the ends and where D'' is zero."""
    curve = np.trim_zeros(distortion_polynomial(model, coefficients), "b")
    crossings = [
        root.real
        for root in P.polyroots(P.polysub(curve, [reach]))
        if abs(root.imag) <= 1e-9 * max(1.0, abs(root)) and 0 < root.real <= r_max
    ]
    if not crossings:
        return math.nan
    radius = min(crossings)
    slope = P.polyder(curve)
    points = [0.0, radius]
    if slope.size > 2:
        points += [
            root.real
            for root in P.polyroots(P.polyder(slope))
            if abs(root.imag) <= 1e-12 * max(1.0, abs(root)) and 0 < root.real < radius
        ]
    return float(np.min(P.polyval(np.array(points), slope)))


def judge(model: str, coefficients: Sequence[float], goal: Goal) -> Verdict:
    """Audit coefficients with the same exact solver as ``lensaudit scan``.

    The goal is met when r_max is beyond the target (or infinite),
    r_normalized is at least the margin, and D' is at least
    :data:`SLOPE_FLOOR` until D reaches the margin.
    """
    values = dict(zip(MODEL_COEFFICIENTS[model], coefficients, strict=True))
    a, b, c, k1, k2 = ([values.get(name, math.nan)] for name in ("a", "b", "c", "k1", "k2"))
    # Crop factor and focal length only enter the paper's columns, unused here.
    result = metrics.compute([model], a, b, c, k1, k2, [1.0], [goal.aspect_ratio], [1.0], [True])
    r_max = float(result.r_max[0])
    d_max = float(result.d_max[0])
    r_normalized = d_max / goal.r_corner
    beyond = r_max > goal.target or math.isinf(r_max)
    reaches = bool(beyond and r_normalized >= goal.margin)
    slope = smallest_slope(model, coefficients, goal.reach, r_max) if reaches else math.nan
    meets = reaches and slope >= SLOPE_FLOOR
    return Verdict(r_max, d_max, r_normalized, meets, slope)


@dataclass(frozen=True)
class Fit:
    """Coefficients found by the linear program, before rounding."""

    coefficients: tuple[float, ...]
    radius: float  # the T used: increasing on [0, T] (r_max beyond it)
    deviation: float  # the program's objective, Hugin units, on its grid
    reach_radius: float = math.nan  # the R used: D' >= floor on [0, R], D(R) >= reach


@dataclass(frozen=True)
class Refit:
    """A fit as it is written: rounded (:func:`rounded_fit`), judged against a
    goal whose target is the fit's radius T, and its change of D."""

    fit: Fit
    texts: tuple[str, ...]
    coefficients: tuple[float, ...]
    verdict: Verdict
    change: Change


def _edge(radius: float) -> float:
    """s = r / (1 + r) of a radius (1 for inf)."""
    return 1.0 if math.isinf(radius) else radius / (1.0 + radius)


_SLOPE_GRID = np.arange(SLOPE_STEPS + 1) / SLOPE_STEPS


def slope_points(reach: float, radius: float, extra: Sequence[float] = ()) -> np.ndarray:
    """The values of s = r / (1 + r) where the linear program asks for a slope,
    for radii R (``reach``) and T (``radius``, may be inf): a fixed grid up
    to T, R, T, and ``extra``."""
    middle, edge = _edge(reach), _edge(max(radius, reach))
    s = np.concatenate([_SLOPE_GRID[_SLOPE_GRID < edge], [middle, edge], np.asarray(extra)])
    return s[(s >= 0) & (s <= edge)]


def slope_degree(model: str) -> int:
    """The degree of D' of a model."""
    return _SLOPE_DEGREE[model]


def scaled_slope_rows(model: str, s: np.ndarray) -> np.ndarray:
    """(1 - s)^k D'(s / (1 - s)) per unit change of each coefficient (one column
    each), k the degree of D': bounded for any radius, up to s = 1 (r = inf)."""
    degree = _SLOPE_DEGREE[model]
    terms = term_matrix(model)
    return np.stack([_scaled(P.polyder(row), s, degree) for row in terms], axis=1)


def least_slopes(model: str, s: np.ndarray, reach: float) -> np.ndarray:
    """(1 - s)^k x the least slope the program asks at each s: the floor (with
    :data:`FLOOR_SLACK`) up to the reach radius R, then :data:`RISE`."""
    least = np.where(s <= _edge(reach), SLOPE_FLOOR * FLOOR_SLACK, RISE)
    return least * (1 - s) ** _SLOPE_DEGREE[model]


class _Program:
    """The linear program of one entry, for any radii R and T (see the module docstring)."""

    def __init__(self, model: str, coefficients: Sequence[float], goal: Goal) -> None:
        self.model = model
        self.old = np.asarray(coefficients, dtype=np.float64)
        self.goal = goal
        self.terms = term_matrix(model)
        self.old_curve = distortion_polynomial(model, coefficients)
        self.old_slope = P.polyder(self.old_curve)
        image = np.linspace(0.0, goal.r_corner, GRID_POINTS)[1:]  # D(0) = 0 always
        self.image_rows = np.stack([P.polyval(image, row) for row in self.terms], axis=1)

    def solve(self, reach: float, radius: float, extra: Sequence[float] = ()) -> Fit | None:
        """The closest coefficients with D' >= the floor on [0, R] (``reach``),
        D(R) >= the goal's reach and D' > 0 on [R, T] (``radius``, may be inf),
        or None.

        Both slopes are imposed on r = s / (1 - s) for s on a fixed grid, and
        at s = R / (1 + R) and T / (1 + T), as (1 - s)^k D'(s / (1 - s)) >=
        (1 - s)^k x the slope: a polynomial in s whose rows stay bounded for
        any radius, up to T = inf (s = 1, where its value is D''s leading
        coefficient). ``extra``: more values of s.
        """
        from scipy.optimize import linprog  # scipy: only to refit a model

        count = len(self.old)
        s = slope_points(reach, radius, extra)
        slope_rows = scaled_slope_rows(self.model, s)
        degree = _SLOPE_DEGREE[self.model]
        slope_limits = _scaled(self.old_slope, s, degree) - least_slopes(self.model, s, reach)
        # Variables: the change of each coefficient, then t. All rows "<=".
        ones = np.ones((self.image_rows.shape[0], 1))
        reach_row = np.array([P.polyval(reach, row) for row in self.terms] + [0.0])
        needed = self.goal.reach * (1 + REACH_SLACK)
        rows = np.vstack(
            [
                np.hstack([self.image_rows, -ones]),
                np.hstack([-self.image_rows, -ones]),
                np.hstack([-slope_rows, np.zeros((slope_rows.shape[0], 1))]),
                -reach_row[None, :],
            ]
        )
        bounds = np.concatenate(
            [np.zeros(2 * len(ones)), slope_limits, [P.polyval(reach, self.old_curve) - needed]]
        )
        if not (np.isfinite(rows).all() and np.isfinite(bounds).all()):
            return None  # values beyond the floats (a coefficient near the largest double)
        objective = np.zeros(count + 1)
        objective[-1] = 1.0
        solution = linprog(
            objective,
            A_ub=rows,
            b_ub=bounds,
            bounds=[(None, None)] * count + [(0, None)],
            method="highs",
        )
        if solution.status != 0:
            return None
        change = solution.x[:count]
        return Fit(
            tuple((self.old + change).tolist()),
            max(radius, reach),
            float(solution.x[-1]),
            reach,
        )

    def slope_minimum(self, fit: Fit) -> list[float]:
        """Values of s to add to the grid: where the fit's slope, scaled as in
        :meth:`solve`, is furthest below (or least above) what is asked."""
        slope = P.polyder(distortion_polynomial(self.model, fit.coefficients))
        s = np.linspace(0.0, _edge(fit.radius), 20 * SLOPE_STEPS)
        spare = _scaled(slope, s, _SLOPE_DEGREE[self.model])
        spare -= least_slopes(self.model, s, fit.reach_radius)
        low = int(np.argmin(spare))
        step = s[1] - s[0]
        return [float(s[low]), float(max(s[low] - step / 2, 0)), float(s[low] + step / 2)]


def _scaled(polynomial: np.ndarray, s: np.ndarray, degree: int) -> np.ndarray:
    """(1 - s)^degree p(s / (1 - s)) = sum_j p_j s^j (1 - s)^(degree - j), at s in [0, 1]."""
    polynomial = np.trim_zeros(np.asarray(polynomial, dtype=np.float64), "b")
    if polynomial.size > degree + 1:
        raise ValueError("polynomial of higher degree than the model's slope")
    total = np.zeros_like(s)
    for power, coefficient in enumerate(polynomial):
        total = total + coefficient * s**power * (1 - s) ** (degree - power)
    return total


def radii_from(target: float, reach: float) -> list[tuple[float, float]]:
    """The pairs (R, T) tried for a target, given the best reach radius R
    found without regard to it (:func:`search_reach`).

    T runs over R itself and a fixed ladder k / (RADIUS_STEPS - k) (s = T / (1
    + T) = k / RADIUS_STEPS) beyond R, then inf, each from the target on.
    Each T is tried with that R (D' > 0 from R to T) and, beyond R, also as
    its own reach radius (D' >= the floor all the way to T, where R folds
    before the target would). Nothing else depends on the target, so a
    smaller target tries every pair a larger one tries: its best refit is
    never worse.
    """
    steps = RADIUS_STEPS
    ladder = [k / (steps - k) for k in range(1, steps) if k / (steps - k) > reach]
    pairs = [(reach, reach)] if reach >= target else []
    for radius in [*ladder, math.inf]:
        if radius >= target:
            pairs.append((reach, radius))
            if math.isfinite(radius):
                pairs.append((radius, radius))
    return pairs


def best_refit(
    model: str, coefficients: Sequence[float], goal: Goal, templates: Sequence[str]
) -> Refit | None:
    """The refit that changes D least, over the radii R and T of :func:`radii_from`.

    The reach radius R is searched first, without regard to the target
    (:func:`search_reach`). Then each pair of radii is refitted, rounded as the
    file writes the entry (``templates``: its coefficients as written) and
    verified exactly against a goal with T as its target, whatever
    ``goal.target`` is; that is what keeps the answer for a smaller target at
    least as good. None when no coefficients of the model meet the goal (or
    the program cannot find them within its refinements), and for a margin
    beyond what floats can pose the program with.
    """
    if not math.isfinite(goal.reach * (1 + REACH_SLACK)):
        return None
    best: Refit | None = None
    with np.errstate(all="ignore"):  # a program that overflows is not solved (see solve)
        program = _Program(model, coefficients, goal)
        reach = search_reach(goal.reach, _deviation(program))
        if reach is None:
            return None
        for pair in radii_from(goal.target, reach):
            found = _refit_at(program, *pair, templates)
            if found is not None and (best is None or found.change.max_px < best.change.max_px):
                best = found
    return best


def search_reach(reach: float, deviation: Callable[[float], float]) -> float | None:
    """The reach radius R whose program with T = R changes D least (``deviation``,
    inf where infeasible): a coarse scan of [reach / 2, reach / floor], then a
    bounded search; None if none is feasible. Past reach / floor, D' >= floor
    alone takes D to the goal's ``reach``. Nothing here depends on the target."""
    from scipy.optimize import minimize_scalar  # scipy: only to refit a model

    radii = np.geomspace(reach / 2, reach / SLOPE_FLOOR, _SEARCH_POINTS)
    values = [deviation(float(r)) for r in radii]
    best = int(np.argmin(values))
    if not math.isfinite(values[best]):
        return None
    low = float(radii[max(best - 1, 0)])
    high = float(radii[min(best + 1, len(radii) - 1)])
    refined = minimize_scalar(
        deviation, bounds=(low, high), method="bounded", options={"xatol": 1e-3 * reach}
    )
    return float(refined.x) if refined.fun < values[best] else float(radii[best])


def _deviation(program: _Program) -> Callable[[float], float]:
    """The program's objective with R = T, as a function of R (inf where infeasible)."""

    def deviation(radius: float) -> float:
        fit = program.solve(radius, radius)
        return math.inf if fit is None else fit.deviation

    return deviation


def _refit_at(
    program: _Program, reach: float, radius: float, templates: Sequence[str]
) -> Refit | None:
    """The program's refit for radii R and T, rounded and verified; None if it fails."""
    goal = replace(program.goal, target=radius)
    model = program.model
    extra: list[float] = []
    for _ in range(_REFINEMENTS):
        fit = program.solve(reach, radius, extra)
        if fit is None:
            return None
        if judge(model, fit.coefficients, goal).meets_goal:
            break
        extra += program.slope_minimum(fit)
    else:
        return None
    texts, new, verdict = rounded_fit(model, fit.coefficients, templates, goal)
    if not verdict.meets_goal:
        return None
    change = change_of_distortion(model, program.old, new, goal.aspect_ratio, goal.r_corner)
    if not math.isfinite(change.max_px):
        return None
    return Refit(fit, tuple(texts), new, verdict, change)


def rounded_fit(
    model: str, coefficients: Sequence[float], templates: Sequence[str], goal: Goal
) -> tuple[list[str], tuple[float, ...], Verdict]:
    """(texts, coefficients, verdict) of a fit, rounded to the fewest extra digits
    that still meet the goal (:func:`rounded_texts`); unrounded if none do."""
    for extra in range(EXTRA_DIGITS + 1):
        texts = rounded_texts(coefficients, templates, extra)
        new = tuple(float(t) for t in texts)
        verdict = judge(model, new, goal)
        if verdict.meets_goal:
            return texts, new, verdict
    new = tuple(coefficients)
    return [repr(v) for v in new], new, judge(model, new, goal)


def decimals_of(text: str) -> int:
    """Digits after the decimal point of a number as written, exponent included.

    ``"-0.024"`` has 3, ``"-8.6e-05"`` 6, ``"12"`` 0.
    """
    mantissa, _, exponent = text.strip().lower().partition("e")
    fraction = mantissa.partition(".")[2]
    try:
        shift = int(exponent) if exponent else 0
    except ValueError:
        shift = 0
    return max(0, len(fraction) - shift)


def format_like(value: float, decimals: int, template: str) -> str:
    """``value`` rounded to ``decimals`` places, written in the style of ``template``.

    Plain decimals (``-0.020930``) unless the template uses an exponent
    (``-8.6e-05``); then the same exponent letter, sign and zero padding.
    Never ``-0``.
    """
    exponent_letter = next((ch for ch in template if ch in "eE"), None)
    if exponent_letter is None or value == 0:
        text = f"{value:.{max(decimals, 0)}f}"
    else:
        magnitude = math.floor(math.log10(abs(value)))
        text = f"{value:.{max(decimals + magnitude, 0)}e}"
        mantissa, _, exponent = text.partition("e")
        power = int(exponent)
        written = template.strip().lower().partition("e")[2]
        digits = written.lstrip("+-")
        width = len(digits) if digits.startswith("0") else 1
        sign = "-" if power < 0 else ("+" if written.startswith("+") else "")
        text = f"{mantissa}{exponent_letter}{sign}{abs(power):0{width}d}"
    if text.startswith("-") and float(text) == 0:
        text = text[1:]
    return text


def rounded_texts(
    values: Sequence[float], templates: Sequence[str], extra_digits: int = 0
) -> list[str]:
    """New coefficient texts: the entry's decimals, at least 5 significant digits.

    ``templates`` are the entry's coefficient texts as written in the file
    (``"0"`` for a missing one); ``extra_digits`` adds decimal places.
    """
    decimals = max(decimals_of(t) for t in templates)
    texts = []
    for value, template in zip(values, templates, strict=True):
        places = decimals
        if value != 0:
            places = max(places, MIN_SIGNIFICANT_DIGITS - 1 - math.floor(math.log10(abs(value))))
        texts.append(format_like(value, places + extra_digits, template))
    return texts
