"""A zoom's calibrations as liblensfun applies them between calibrated focal
lengths, and refitted together so that none of the models it interpolates
folds.

liblensfun interpolates a lens's distortion coefficients between its
calibrated focal lengths (:mod:`lensaudit.interpolation`). The set of
models that do not fold is not convex: refitting two neighbouring
calibrations that fold one at a time (a 10-20 mm zoom folding at 10 and
11 mm) leaves liblensfun folding in between, and two calibrations that
clear the image may fold in between where the spline overshoots. So the
calibrations of a lens are judged over its whole focal range
(:func:`sweep`), and, where that finds a fold, refitted together
(:func:`refit_together`): one linear program over the coefficients of
every calibration that moves, with the goal of :mod:`lensaudit.fix` (D'
at least the slope floor up to a radius T, D(T) at least margin x the
image radius) imposed at each calibrated focal length and at focal lengths
in between, where the interpolated coefficients are fixed linear
combinations of the calibrations'.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import polynomial as P

from . import refit
from .interpolation import weights
from .pipeline import metric_columns
from .read.records import MODEL_COEFFICIENTS, STATUS_OK

# typing only for type checkers
TYPE_CHECKING = False
if TYPE_CHECKING:
    from .pipeline import Audit

#: Focal lengths are swept every this many millimetres (and at each calibration).
SWEEP_STEP = 0.01
_INTERVAL_POINTS = 24  # focal lengths imposed in each interval of the linear program
_ROUNDS = 6  # rounds of adding the focal lengths the sweep finds folding
_EACH = 1e-2  # weight of each calibration's own largest change, beside the largest of all


@dataclass(frozen=True)
class CalibrationSet:
    """The distortion calibrations of one lens that liblensfun interpolates
    between: audit entry ``indices`` (file order, the first model met),
    their ``focals``, the ``model``, and the image's aspect ratio and radius."""

    indices: tuple[int, ...]
    focals: tuple[float, ...]
    model: str
    aspect_ratio: float
    image_radius: float


def calibration_sets(audit: Audit) -> list[CalibrationSet]:
    """Every lens's set of audited distortion calibrations: entries of one lens
    of one file with the same crop factor and aspect ratio, of the model of
    the first of them (liblensfun ignores the others)."""
    groups: dict[tuple, list[int]] = {}
    for index, entry in enumerate(audit.entries):
        if entry.status != STATUS_OK or entry.model not in MODEL_COEFFICIENTS:
            continue
        key = (entry.file, entry.maker, entry.lens, entry.mounts, entry.crop_factor,
               entry.aspect_ratio)  # fmt: skip
        groups.setdefault(key, []).append(index)
    found = []
    for indices in groups.values():
        model = audit.entries[indices[0]].model
        kept = tuple(i for i in indices if audit.entries[i].model == model)
        first = audit.entries[kept[0]]
        found.append(
            CalibrationSet(
                kept,
                tuple(audit.entries[i].focal for i in kept),
                model,
                first.aspect_ratio,
                float(audit.metrics.r_corner[kept[0]]),
            )
        )
    return found


def focal_samples(focals: Sequence[float], step: float = SWEEP_STEP) -> np.ndarray:
    """Focal lengths from the first calibrated to the last, every ``step`` mm,
    and every calibrated one."""
    low, high = min(focals), max(focals)
    count = int(math.floor((high - low) / step + 1e-9))
    return np.unique(np.concatenate([low + step * np.arange(count + 1), np.asarray(focals)]))


def interpolated_rows(
    coefficients: Sequence[Sequence[float]], focals: Sequence[float], at: Sequence[float]
) -> np.ndarray:
    """The coefficients liblensfun applies at each focal length of ``at`` (one row each)."""
    table = np.asarray(coefficients, dtype=np.float64)
    rows = np.zeros((len(at), table.shape[1]))
    for row, focal in enumerate(at):
        for index, weight in weights(focals, float(focal)):
            rows[row] += weight * table[index]
    return rows


def r_normalized_at(
    model: str, rows: np.ndarray, aspect_ratio: float, image_radius: float
) -> np.ndarray:
    """r_normalized (d_max over the image radius) of each row of coefficients,
    computed as the pipeline computes every entry's metrics."""
    count = len(rows)
    values = dict(zip(MODEL_COEFFICIENTS[model], np.asarray(rows).T.tolist(), strict=True))
    nan = [math.nan] * count
    columns = {name: values.get(name, nan) for name in ("a", "b", "c", "k1", "k2")}
    columns |= {
        "status": [STATUS_OK] * count,
        "lens": [""] * count,
        "type": ["rectilinear"] * count,
        "model": [model] * count,
        "crop_factor": [1.0] * count,
        "aspect_ratio": [aspect_ratio] * count,
        "focal": [1.0] * count,
    }
    return np.asarray(metric_columns(columns)["d_max"], dtype=np.float64) / image_radius


def sweep(
    calibrations: CalibrationSet, coefficients: Sequence[Sequence[float]]
) -> tuple[float, float]:
    """(smallest r_normalized, the focal length where) of the models liblensfun
    interpolates from ``coefficients`` (one per calibration), every
    :data:`SWEEP_STEP` mm over the calibrated range; (inf, nan) where none folds."""
    at = focal_samples(calibrations.focals)
    rows = interpolated_rows(coefficients, calibrations.focals, at)
    values = r_normalized_at(
        calibrations.model, rows, calibrations.aspect_ratio, calibrations.image_radius
    )
    lowest = int(np.argmin(values))
    if not math.isfinite(values[lowest]):
        return math.inf, math.nan
    return float(values[lowest]), float(at[lowest])


def neighbours(calibrations: CalibrationSet, focal: float) -> set[int]:
    """Positions (in the set) of the calibrations liblensfun interpolates ``focal`` from."""
    return {position for position, _ in weights(calibrations.focals, focal)}


@dataclass(frozen=True)
class JointFit:
    """Coefficients of every calibration of a set (rounded where they moved), and
    the smallest r_normalized over the focal range with them."""

    coefficients: tuple[tuple[float, ...], ...]
    texts: tuple[tuple[str, ...], ...]
    r_normalized_between: float
    focal_between: float


def refit_together(
    calibrations: CalibrationSet,
    old: Sequence[Sequence[float]],
    old_texts: Sequence[Sequence[str]],
    moving: set[int],
    goal: refit.Goal,
) -> JointFit | None:
    """Refit the calibrations at positions ``moving`` together (the others stay
    as they are) so that every calibration and every model liblensfun
    interpolates between them meets ``goal``; None where the program finds
    no such coefficients."""
    program = _JointProgram(calibrations, old, moving, goal)
    extra: list[float] = []
    for _ in range(_ROUNDS):
        solved = program.best(extra)
        if solved is None:
            return None
        for digits in range(refit.EXTRA_DIGITS + 1):
            texts = [
                tuple(refit.rounded_texts(solved[p], tuple(old_texts[p]), digits))
                if p in moving else tuple(old_texts[p])
                for p in range(len(old))
            ]  # fmt: skip
            coefficients = [tuple(float(t) for t in row) for row in texts]
            judged = [refit.judge(calibrations.model, coefficients[p], goal) for p in moving]
            if all(verdict.meets_goal for verdict in judged):
                break
        lowest, where = sweep(calibrations, coefficients)
        if lowest >= goal.margin:
            return JointFit(tuple(coefficients), tuple(texts), lowest, where)
        extra.append(where)
    return None


class _JointProgram:
    """The linear program of :func:`refit_together`, for any radius T."""

    def __init__(
        self,
        calibrations: CalibrationSet,
        old: Sequence[Sequence[float]],
        moving: set[int],
        goal: refit.Goal,
    ) -> None:
        self.sets = calibrations
        self.old = np.asarray(old, dtype=np.float64)
        self.moving = sorted(moving)
        self.goal = goal
        model = calibrations.model
        self.terms = refit.term_matrix(model)
        self.slope_terms = np.array([P.polyder(row) for row in self.terms])
        image = np.linspace(0.0, goal.r_corner, refit.GRID_POINTS)[1:]
        self.image_rows = np.stack([P.polyval(image, row) for row in self.terms], axis=1)
        focals = sorted(set(calibrations.focals))
        inside = [
            low + (high - low) * np.arange(1, _INTERVAL_POINTS + 1) / (_INTERVAL_POINTS + 1)
            for low, high in zip(focals, focals[1:], strict=False)
        ]
        self.focals = list(focals) + [float(f) for chunk in inside for f in chunk]

    def best(self, extra: Sequence[float]) -> list[tuple[float, ...]] | None:
        """Each calibration's coefficients, for the best T of a scan; None if none is feasible."""
        found = None
        for radius in np.geomspace(self.goal.target, refit.SEARCH_SPAN * self.goal.target, 9):
            solved = self.solve(float(radius), extra)
            if solved is not None and (found is None or solved[1] < found[1]):
                found = solved
        return None if found is None else found[0]

    def solve(
        self, radius: float, extra: Sequence[float]
    ) -> tuple[list[tuple[float, ...]], float] | None:
        """(coefficients, largest change of D in Hugin units) for a radius T, or None."""
        from scipy.optimize import linprog  # scipy: only to refit a model

        size = self.terms.shape[0]
        moving = len(self.moving)
        # Variables: the changes of each moving calibration, then the largest
        # change of D of each (t_k), then the largest of all (t).
        count = size * moving + moving + 1
        radii = np.linspace(0.0, radius, refit.GRID_POINTS)
        slope_at = np.stack([P.polyval(radii, row) for row in self.slope_terms], axis=1)
        reach_at = np.array([P.polyval(radius, row) for row in self.terms])
        blocks, limits = [], []
        for column in range(moving):  # |change of D| <= t_k <= t over the image
            rows = np.zeros((2 * len(self.image_rows) + 1, count))
            span = slice(column * size, (column + 1) * size)
            rows[: len(self.image_rows), span] = self.image_rows
            rows[len(self.image_rows) : -1, span] = -self.image_rows
            rows[:-1, size * moving + column] = -1.0
            rows[-1, size * moving + column] = 1.0
            rows[-1, -1] = -1.0
            blocks.append(rows)
            limits.append(np.zeros(len(rows)))
        for focal in [*self.focals, *extra]:
            found = self._at_focal(float(focal), slope_at, reach_at, count, radius)
            if found is not None:
                blocks.append(found[0])
                limits.append(found[1])
        # The largest change first; then each calibration's as small as it can be.
        objective = np.zeros(count)
        objective[size * moving : -1] = _EACH
        objective[-1] = 1.0
        solution = linprog(
            objective,
            A_ub=np.vstack(blocks),
            b_ub=np.concatenate(limits),
            bounds=[(None, None)] * (size * moving) + [(0, None)] * (moving + 1),
            method="highs",
        )
        if solution.status != 0:
            return None
        new = [tuple(row) for row in self.old.tolist()]
        for column, position in enumerate(self.moving):
            change = solution.x[column * size : (column + 1) * size]
            new[position] = tuple((self.old[position] + change).tolist())
        return new, float(solution.x[-1])

    def _at_focal(
        self, focal: float, slope_at: np.ndarray, reach_at: np.ndarray, count: int, radius: float
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Rows for the model interpolated at ``focal``: D' >= the floor on [0, T] and
        D(T) >= the reach; None where no moving calibration enters it."""
        size = self.terms.shape[0]
        mix = dict(weights(self.sets.focals, focal))
        if not any(position in mix for position in self.moving):
            return None
        current = sum(weight * self.old[p] for p, weight in mix.items())
        old_slope = 1.0 + slope_at @ current
        old_reach = radius + reach_at @ current
        slope_rows = np.zeros((len(slope_at), count))
        reach_row = np.zeros((1, count))
        for column, position in enumerate(self.moving):
            weight = mix.get(position, 0.0)
            span = slice(column * size, (column + 1) * size)
            slope_rows[:, span] = -weight * slope_at
            reach_row[0, span] = -weight * reach_at
        floor = refit.SLOPE_FLOOR * refit.FLOOR_SLACK
        needed = self.goal.reach * (1 + refit.REACH_SLACK)
        return (
            np.vstack([slope_rows, reach_row]),
            np.concatenate([old_slope - floor, [old_reach - needed]]),
        )


# ---------------------------------------------------------------------------
# Between calibrated focal lengths, proven: interval arithmetic
# ---------------------------------------------------------------------------

#: How far a box of focal lengths is halved before it is left undecided.
_MAX_DEPTH = 16
#: Radii boxes from the centre to the radius checked, per box of focal lengths.
_RADIUS_BOXES = 32
#: Rounding allowance, relative to the size of the terms (far above the few
#: units in the last place a few dozen operations can lose).
_ROUNDING = 1e-12
CLEAR, FOLDS, UNDECIDED = "clear", "folds", "undecided"


@dataclass(frozen=True)
class Between:
    """What liblensfun's model does between two neighbouring calibrated focal
    lengths ``low`` and ``high`` of a lens, judged against ``threshold`` x
    the image radius: ``verdict`` ``clear`` (proven: at every focal length
    in between, D increases until it reaches that radius), ``folds`` (at
    ``focal``, where the model's r_normalized is ``r_normalized``, below
    the threshold) or ``undecided``."""

    low: float
    high: float
    verdict: str
    focal: float = math.nan
    r_normalized: float = math.nan


def between(
    calibrations: CalibrationSet,
    coefficients: Sequence[Sequence[float]],
    threshold: float = 1.0,
) -> list[Between]:
    """Every interval between neighbouring calibrated focal lengths of a lens,
    judged for every focal length in it (not a sample of them): where the
    interpolated coefficients are Q(t) / f with Q cubic in t, a box of focal
    lengths is clear when, with interval arithmetic (rounding allowed for),
    f D'(r) > 0 for r from 0 to a radius R where f (D(R) - threshold x the
    image radius) > 0; boxes that are not are halved, and a focal length
    whose model folds below the threshold (by the exact solver) is a
    witness."""
    focals = sorted(set(calibrations.focals))
    table = np.asarray(coefficients, dtype=np.float64)
    found = []
    for low, high in zip(focals, focals[1:], strict=False):
        found.append(_judge_interval(calibrations, table, low, high, threshold))
    return found


def _judge_interval(
    calibrations: CalibrationSet, table: np.ndarray, low: float, high: float, threshold: float
) -> Between:
    from .interpolation import spline_terms

    start, end, terms = spline_terms(calibrations.focals, (low + high) / 2)
    assert start is not None and end is not None
    f0, f1 = calibrations.focals[start], calibrations.focals[end]
    # f x coefficient i = Q_i(t): one row of cubic coefficients (of 1, t, t^2, t^3) per i.
    q = sum(np.outer(table[k] * calibrations.focals[k], g) for k, g in terms)
    model = calibrations.model
    terms_r = refit.term_matrix(model)
    slopes_r = np.array([P.polyder(row) for row in terms_r])
    reach = threshold * calibrations.image_radius
    boxes = [(0.0, 1.0, 0)]
    while boxes:
        t_low, t_high, depth = boxes.pop()
        middle = (t_low + t_high) / 2
        focal = f0 + middle * (f1 - f0)
        row = np.array([[np.polyval(q[i][::-1], middle) / focal for i in range(len(q))]])
        value = float(r_normalized_at(model, row, calibrations.aspect_ratio,
                                      calibrations.image_radius)[0])  # fmt: skip
        if value < threshold:
            return Between(low, high, FOLDS, focal, value)
        # Bounds that overflow are not finite, and prove nothing: the box is halved.
        with np.errstate(all="ignore"):
            radius = _radius_to_check(model, row[0], reach, value / threshold)
            if radius is not None and _clear(q, (t_low, t_high), (f0, f1), terms_r, slopes_r,
                                             radius, reach):  # fmt: skip
                continue
        if depth >= _MAX_DEPTH:
            return Between(low, high, UNDECIDED, focal, value)
        boxes += [(t_low, middle, depth + 1), (middle, t_high, depth + 1)]
    return Between(low, high, CLEAR)


def _radius_to_check(
    model: str, coefficients: np.ndarray, reach: float, ratio: float
) -> float | None:
    """A radius where the model at a box's middle is past ``reach``, halfway to
    its d_max (or 5% past where it never folds), before it folds; None if none."""
    curve = refit.distortion_polynomial(model, coefficients)
    aim = reach * (1 + (min(ratio, 1.1) - 1) / 2) if math.isfinite(ratio) else reach * 1.05
    roots = [
        z.real for z in P.polyroots(P.polysub(curve, [aim]))
        if abs(z.imag) <= 1e-9 * max(1.0, abs(z)) and z.real > 0
    ]  # fmt: skip
    return min(roots) if roots else None


def _interval_polynomial(
    coefficients: np.ndarray, low: np.ndarray | float, high: np.ndarray | float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lower, upper, size) of a polynomial (coefficients of 1, x, ...) over x in
    [low, high], by Horner's rule in interval arithmetic; ``size`` bounds
    the magnitude of every partial result (for the rounding allowance)."""
    low, high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    lower = upper = np.full(np.broadcast(low, high).shape, float(coefficients[-1]))
    size = np.abs(lower)
    scale = np.maximum(np.abs(low), np.abs(high))
    for coefficient in coefficients[-2::-1]:
        products = (lower * low, lower * high, upper * low, upper * high)
        lower = np.minimum.reduce(products) + coefficient
        upper = np.maximum.reduce(products) + coefficient
        size = size * scale + abs(coefficient)
    return lower, upper, size


def _clear(
    q: np.ndarray,
    t_box: tuple[float, float],
    ends: tuple[float, float],
    terms_r: np.ndarray,
    slopes_r: np.ndarray,
    radius: float,
    reach: float,
) -> bool:
    """Whether, for every t in ``t_box``: f D'(r) > 0 for r in [0, radius] and
    f D(radius) > f reach (f = ends[0] + t (ends[1] - ends[0]))."""
    t_low, t_high = t_box
    f_a, f_b = ends[0] + t_low * (ends[1] - ends[0]), ends[0] + t_high * (ends[1] - ends[0])
    f_low, f_high = min(f_a, f_b), max(f_a, f_b)
    q_parts = [_interval_polynomial(row, t_low, t_high) for row in q]
    # f (D(R) - reach) = f (R - reach) + sum_i Q_i(t) term_i(R)
    lower = min(f_low * (radius - reach), f_high * (radius - reach))
    size = f_high * (radius + reach)
    for (q_low, q_high, q_size), term in zip(q_parts, terms_r, strict=True):
        value = float(np.polynomial.polynomial.polyval(radius, term))
        lower = lower + min(q_low * value, q_high * value)
        size = size + q_size * abs(value)
    if not lower - _ROUNDING * size > 0:
        return False
    # f D'(r) = f + sum_i Q_i(t) s_i(r), on boxes of r from 0 to R.
    edges = np.linspace(0.0, radius, _RADIUS_BOXES + 1)
    lower, size = np.full(_RADIUS_BOXES, f_low), np.full(_RADIUS_BOXES, f_high)
    for (q_low, q_high, q_size), slope in zip(q_parts, slopes_r, strict=True):
        s_low, s_high, s_size = _interval_polynomial(slope, edges[:-1], edges[1:])
        products = (q_low * s_low, q_low * s_high, q_high * s_low, q_high * s_high)
        lower = lower + np.minimum.reduce(products)
        size = size + q_size * s_size
    return bool(np.all(lower - _ROUNDING * size > 0))
