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

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.polynomial import polynomial as P

from . import refit
from .interpolation import weights
from .read.records import MODEL_COEFFICIENTS, STATUS_OK, DistortionEntry

# typing only for type checkers
TYPE_CHECKING = False
if TYPE_CHECKING:
    from .pipeline import Audit

#: Focal lengths are swept every this many millimetres (and at each calibration)...
SWEEP_STEP = 0.01
#: ... or, over a range longer than that many steps (400 mm, longer than any zoom's),
#: at this many focal lengths evenly spread: a focal length mistyped 100,000 would
#: otherwise make ten million of them.
MAX_SWEEP_SAMPLES = 40_001
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
    return calibration_sets_of(audit.entries, audit.metrics.r_corner.tolist())


def calibration_sets_of(
    entries: Sequence[DistortionEntry], image_radius: Sequence[float]
) -> list[CalibrationSet]:
    """:func:`calibration_sets` of distortion ``entries`` with the radius of
    each one's image (``r_corner``, Hugin units); indices are into ``entries``."""
    groups: dict[tuple, list[int]] = {}
    for index, entry in enumerate(entries):
        if entry.status != STATUS_OK or entry.model not in MODEL_COEFFICIENTS:
            continue
        key = (entry.file, entry.maker, entry.lens, entry.mounts, entry.crop_factor,
               entry.aspect_ratio)  # fmt: skip
        groups.setdefault(key, []).append(index)
    found = []
    for indices in groups.values():
        model = entries[indices[0]].model
        kept = tuple(i for i in indices if entries[i].model == model)
        first = entries[kept[0]]
        found.append(
            CalibrationSet(
                kept,
                tuple(entries[i].focal for i in kept),
                model,
                first.aspect_ratio,
                float(image_radius[kept[0]]),
            )
        )
    return found


def coefficient_table(
    calibrations: CalibrationSet, entries: Sequence[DistortionEntry]
) -> list[tuple[float, ...]]:
    """The coefficients of each calibration of a set, in its model's order."""
    names = MODEL_COEFFICIENTS[calibrations.model]
    return [tuple(getattr(entries[i], name) for name in names) for i in calibrations.indices]


def focal_samples(focals: Sequence[float], step: float = SWEEP_STEP) -> np.ndarray:
    """Focal lengths from the first calibrated to the last, every ``step`` mm
    (at most :data:`MAX_SWEEP_SAMPLES` of them, evenly spread), and every
    calibrated one."""
    low, high = min(focals), max(focals)
    step = max(step, (high - low) / (MAX_SWEEP_SAMPLES - 1))
    count = int(math.floor((high - low) / step + 1e-9))
    between = np.minimum(low + step * np.arange(count + 1), high)  # rounding: never beyond
    return np.unique(np.concatenate([between, np.asarray(focals)]))


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
    _, d_max = _extrema([model] * count, np.asarray(rows, dtype=np.float64))
    return d_max / image_radius


def _extrema(models: Sequence[str], rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(r_max, d_max) of each row of coefficients (in its model's order, padded
    with anything): the pipeline's solver, its array code (rows come by the
    thousand here)."""
    from . import metrics

    count = len(models)
    columns = {name: np.full(count, math.nan) for name in ("a", "b", "c", "k1", "k2")}
    model_array = np.asarray(models)
    for model in set(models):
        chosen = model_array == model
        for position, name in enumerate(MODEL_COEFFICIENTS[model]):
            columns[name][chosen] = rows[chosen, position]
    ones = np.ones(count)
    found = metrics.compute(
        model_array, *columns.values(), ones, 1.5 * ones, ones, np.ones(count, dtype=bool)
    )  # crop factor, aspect ratio and focal length do not change r_max or d_max
    return found.r_max, found.d_max


def sweep(
    calibrations: CalibrationSet, coefficients: Sequence[Sequence[float]]
) -> tuple[float, float]:
    """(smallest r_normalized, the focal length where) of the models liblensfun
    interpolates from ``coefficients`` (one per calibration), every
    :data:`SWEEP_STEP` mm over the calibrated range (see :func:`focal_samples`);
    (inf, nan) where none folds."""
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
    the smallest r_normalized over the focal range with them; ``largest``:
    the largest change of D of a moving calibration, in pixels
    (:func:`lensaudit.refit.change_of_distortion`)."""

    coefficients: tuple[tuple[float, ...], ...]
    texts: tuple[tuple[str, ...], ...]
    r_normalized_between: float
    focal_between: float
    largest: float = math.nan


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
    no such coefficients. As :func:`lensaudit.refit.best_refit`: the radii R
    and T of :func:`lensaudit.refit.radii_from`, each verified against its
    own T, the one that changes D least (so never worse for a smaller target)."""
    program = _JointProgram(calibrations, old, moving, goal)

    def deviation(radius: float) -> float:
        solved = program.solve(radius, radius, ())
        return math.inf if solved is None else solved[1]

    best = None
    with np.errstate(all="ignore"):
        reach = refit.search_reach(goal.reach, deviation)
        for pair in refit.radii_from(goal.target, reach) if reach is not None else ():
            found = _together_at(program, pair, old_texts)
            if found is not None and (best is None or found.largest < best.largest):
                best = found
    return best


def _together_at(
    program: _JointProgram, radii: tuple[float, float], old_texts: Sequence[Sequence[str]]
) -> JointFit | None:
    """The joint refit for radii R and T, rounded and verified against T; None if it fails."""
    reach, radius = radii
    goal = replace(program.goal, target=radius)
    model, moving = program.sets.model, program.moving
    extra: list[float] = []
    for _ in range(_ROUNDS):
        solved = program.solve(reach, radius, extra)
        if solved is None:
            return None
        for digits in range(refit.EXTRA_DIGITS + 1):
            texts = [
                tuple(refit.rounded_texts(solved[0][p], tuple(old_texts[p]), digits))
                if p in moving else tuple(old_texts[p])
                for p in range(len(old_texts))
            ]  # fmt: skip
            coefficients = [tuple(float(t) for t in row) for row in texts]
            if all(refit.judge(model, coefficients[p], goal).meets_goal for p in moving):
                break
        else:
            return None
        lowest, where = sweep(program.sets, coefficients)
        if lowest >= goal.margin:
            aspect = program.sets.aspect_ratio
            largest = max(
                refit.change_of_distortion(
                    model, program.old[p], coefficients[p], aspect, goal.r_corner
                ).max_px
                for p in moving
            )
            return JointFit(tuple(coefficients), tuple(texts), lowest, where, largest)
        extra.append(where)
    return None


class _JointProgram:
    """The linear program of :func:`refit_together`, for any radii R and T."""

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
        image = np.linspace(0.0, goal.r_corner, refit.GRID_POINTS)[1:]
        self.image_rows = np.stack([P.polyval(image, row) for row in self.terms], axis=1)
        focals = sorted(set(calibrations.focals))
        inside = [
            low + (high - low) * np.arange(1, _INTERVAL_POINTS + 1) / (_INTERVAL_POINTS + 1)
            for low, high in zip(focals, focals[1:], strict=False)
        ]
        self.focals = list(focals) + [float(f) for chunk in inside for f in chunk]

    def solve(
        self, reach: float, radius: float, extra: Sequence[float]
    ) -> tuple[list[tuple[float, ...]], float] | None:
        """(coefficients, largest change of D in Hugin units) for radii R and T
        (as :meth:`lensaudit.refit._Program.solve`), or None."""
        from scipy.optimize import linprog  # scipy: only to refit a model

        size = self.terms.shape[0]
        moving = len(self.moving)
        # Variables: the changes of each moving calibration, then the largest
        # change of D of each (t_k), then the largest of all (t).
        count = size * moving + moving + 1
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
        slopes = _Slopes(self.sets.model, reach, radius)
        for focal in [*self.focals, *extra]:
            found = self._at_focal(float(focal), slopes, count)
            if found is not None:
                blocks.append(found[0])
                limits.append(found[1])
        rows, bounds = np.vstack(blocks), np.concatenate(limits)
        if not (np.isfinite(rows).all() and np.isfinite(bounds).all()):
            return None  # values beyond the floats
        # The largest change first; then each calibration's as small as it can be.
        objective = np.zeros(count)
        objective[size * moving : -1] = _EACH
        objective[-1] = 1.0
        solution = linprog(
            objective,
            A_ub=rows,
            b_ub=bounds,
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
        self, focal: float, slopes: _Slopes, count: int
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Rows for the model interpolated at ``focal``: D' >= the floor on [0, R],
        D(R) >= the reach, D' > 0 on [R, T]; None where no moving calibration enters it."""
        size = self.terms.shape[0]
        mix = dict(weights(self.sets.focals, focal))
        if not any(position in mix for position in self.moving):
            return None
        current = sum(weight * self.old[p] for p, weight in mix.items())
        old_slope = slopes.identity + slopes.rows @ current
        old_reach = slopes.reach + slopes.reach_row @ current
        slope_rows = np.zeros((len(slopes.rows), count))
        reach_row = np.zeros((1, count))
        for column, position in enumerate(self.moving):
            weight = mix.get(position, 0.0)
            span = slice(column * size, (column + 1) * size)
            slope_rows[:, span] = -weight * slopes.rows
            reach_row[0, span] = -weight * slopes.reach_row
        needed = self.goal.reach * (1 + refit.REACH_SLACK)
        return (
            np.vstack([slope_rows, reach_row]),
            np.concatenate([old_slope - slopes.least, [old_reach - needed]]),
        )


class _Slopes:
    """The slope and reach rows of one model for radii R and T, per unit change
    of each coefficient (see :func:`lensaudit.refit.slope_points`)."""

    def __init__(self, model: str, reach: float, radius: float) -> None:
        s = refit.slope_points(reach, radius)
        self.rows = refit.scaled_slope_rows(model, s)
        self.identity = (1 - s) ** refit.slope_degree(model)  # the scaled slope of D = r
        self.least = refit.least_slopes(model, s, reach)
        self.reach = reach
        self.reach_row = np.array([P.polyval(reach, row) for row in refit.term_matrix(model)])


# ---------------------------------------------------------------------------
# Between calibrated focal lengths, proven: interval arithmetic
# ---------------------------------------------------------------------------

#: How far a box of focal lengths is halved before it is left undecided.
_MAX_DEPTH = 16
#: Boxes of one interval left to halve, at most: an interval that needs more
#: (nothing in it can be proven, e.g. bounds that overflow) is left undecided
#: rather than halved into 2^16 boxes.
_MAX_BOXES = 64
#: Radii boxes from the centre to the radius checked, per box of focal lengths.
_RADIUS_BOXES = 8
#: Rounding allowance, relative to the size of the terms (far above the few
#: units in the last place a few dozen operations can lose).
_ROUNDING = 1e-12
#: Halvings of the search for the radius a box is checked to (any radius
#: where the middle model is past the image serves; this finds one to ~1e-9).
_RADIUS_HALVINGS = 30
#: Boxes whose interval arithmetic is done in one batch of arrays.
_BOXES_AT_ONCE = 1024
_MOST_TERMS = 3  # coefficients of a model at most (ptlens); fewer are padded with zero terms
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
    return between_all([calibrations], [coefficients], threshold)[0]


def between_all(
    sets: Sequence[CalibrationSet],
    coefficients: Sequence[Sequence[Sequence[float]]],
    threshold: float = 1.0,
) -> list[list[Between]]:
    """:func:`between` of many lenses (``coefficients``: one table per set, one
    row per calibration): the boxes of every interval are judged together,
    one round of halving at a time, each round in one batch of arrays."""
    intervals = _Intervals(sets, coefficients, threshold)
    verdicts = intervals.judge()
    found: list[list[Between]] = [[] for _ in sets]
    for owner, verdict in zip(intervals.owner, verdicts, strict=True):
        found[owner].append(verdict)
    return found


@functools.lru_cache(maxsize=4096)
def _interval_slots(focals: tuple[float, ...]) -> tuple[tuple[float, float, tuple[int, ...]], ...]:
    """:func:`lensaudit.interpolation.interval_slots` of a lens's calibrated
    ``focals``, -1 for a slot without a calibration: a function of the focal
    lengths alone, so one lens's calibrations share it with the same lens in
    a baseline."""
    from .interpolation import interval_slots

    return tuple(
        (low, high, tuple(-1 if slot is None else slot for slot in slots))
        for low, high, slots in interval_slots(focals)
    )


def _hermite_weights(no_second_above: np.ndarray, no_second_below: np.ndarray) -> np.ndarray:
    """The cubic g (coefficients of 1, t, t^2, t^3) by which each of an
    interval's four spline slots (second above, above, below, second below)
    weighs its calibration, given which intervals lack the outer slots: the
    spline of :func:`lensaudit.interpolation.spline_terms`, whose tangents
    are half the difference of the neighbours either side, or that of the
    two ends where a neighbour is missing. Sums of halves of small integers:
    exact, as the terms of ``interval_terms`` are."""
    from .interpolation import HERMITE_BASIS

    h00, h10, h01, h11 = (np.array(h, dtype=np.float64) for h in HERMITE_BASIS)
    lone_above = no_second_above[:, None].astype(np.float64)
    lone_below = no_second_below[:, None].astype(np.float64)
    weights = np.empty((len(no_second_above), 4, 4))
    weights[:, 0] = -0.5 * h10
    weights[:, 1] = h00 - lone_above * h10 - (0.5 + 0.5 * lone_below) * h11
    weights[:, 2] = h01 + (0.5 + 0.5 * lone_above) * h10 + lone_below * h11
    weights[:, 3] = 0.5 * h11
    return weights + 0.0  # no negative zeros


class _Intervals:
    """Every interval of every set as arrays: the spline's cubic Q(t) (times f)
    of each coefficient, the focal lengths at t = 0 and 1, each model's terms
    of D and of D' (padded to :data:`_MOST_TERMS`), and the radius to reach."""

    def __init__(
        self,
        sets: Sequence[CalibrationSet],
        coefficients: Sequence[Sequence[Sequence[float]]],
        threshold: float,
    ) -> None:
        self.threshold = threshold
        owner: list[int] = []
        bounds: list[tuple[float, float]] = []
        models: list[str] = []
        radius: list[float] = []
        scaled: list[list[float]] = []  # each calibration's coefficients times its focal length
        focals: list[float] = []  # each calibration's focal length
        slots: list[tuple[int, ...]] = []  # each interval's spline slots, as rows of scaled
        for index, (found, table) in enumerate(zip(sets, coefficients, strict=True)):
            first_row = len(scaled)
            for low, high, own in _interval_slots(tuple(found.focals)):
                bounds.append((low, high))
                slots.append(tuple(slot + first_row if slot >= 0 else -1 for slot in own))
            count = len(bounds) - len(owner)
            owner += [index] * count
            models += [found.model] * count
            radius += [found.image_radius] * count
            padding = [0.0] * (_MOST_TERMS - len(MODEL_COEFFICIENTS[found.model]))
            scaled += [
                [value * focal for value in row] + padding
                for row, focal in zip(table, found.focals, strict=True)
            ]
            focals += found.focals
        slot_rows = np.array(slots, dtype=np.intp).reshape(-1, 4)
        present = slot_rows >= 0
        weights = _hermite_weights(~present[:, 0], ~present[:, 3])
        # The terms of interval_terms, in its order (by interval, then by
        # calibration): the same numbers summed the same way.
        which = np.broadcast_to(np.arange(len(slot_rows))[:, None], slot_rows.shape)[present]
        rows, cubics = slot_rows[present], weights[present]
        order = np.lexsort((rows, which))
        q = np.zeros((len(owner), _MOST_TERMS, 4))
        if owner:
            all_rows = np.asarray(scaled, dtype=np.float64)[rows[order]]
            np.add.at(q, which[order], all_rows[:, :, None] * cubics[order][:, None, :])
        self.owner, self.bounds = owner, bounds
        self.models = np.asarray(models, dtype=str)
        self.q = q
        focal_of_row = np.asarray(focals, dtype=np.float64)
        self.f0, self.f1 = focal_of_row[slot_rows[:, 1]], focal_of_row[slot_rows[:, 2]]
        self.image_radius = np.asarray(radius, dtype=np.float64)
        padded = {}
        for model in set(models):
            matrix = np.zeros((_MOST_TERMS, 6))
            own_terms = refit.term_matrix(model)
            matrix[: len(own_terms)] = own_terms
            padded[model] = matrix
        self.terms = np.asarray([padded[m] for m in models]).reshape(len(owner), _MOST_TERMS, 6)
        self.slopes = self.terms[:, :, 1:] * np.arange(1, 6)

    def judge(self) -> list[Between]:
        """Every interval's verdict: boxes of focal lengths, halved round by round."""
        count = len(self.owner)
        verdicts: list[Between | None] = [None] * count
        decided = np.zeros(count, dtype=bool)  # whether verdicts[i] is not None
        box = np.arange(count)  # the interval each box belongs to
        t_low, t_high = np.zeros(count), np.ones(count)
        for depth in range(_MAX_DEPTH + 1):
            if not len(box):
                break
            middle = (t_low + t_high) / 2
            focal = self.f0[box] + middle * (self.f1[box] - self.f0[box])
            rows = _horner(self.q[box], middle[:, None]) / focal[:, None]
            r_max, d_max = _extrema(self.models[box], rows)
            with np.errstate(all="ignore"):
                value = d_max / self.image_radius[box]
            folds = value < self.threshold
            # The witness of an interval that folds: its lowest focal length found folding.
            witnesses = np.flatnonzero(folds)[np.argsort(focal[folds], kind="stable")]
            self._decide(verdicts, decided, box, witnesses, FOLDS, focal, value)
            live = ~decided[box]
            # Bounds that overflow are not finite, and prove nothing: the box is halved.
            with np.errstate(all="ignore"):
                reach = self.threshold * self.image_radius[box]
                radius = _radius_past(rows, self.terms[box], reach, value / self.threshold, r_max)
                # Each box is judged alone: a few at a time, the arrays stay in the cache.
                starts = range(0, len(box), _BOXES_AT_ONCE)
                parts = [slice(start, start + _BOXES_AT_ONCE) for start in starts]
                clear = live & np.concatenate(
                    [self._clear(box[p], t_low[p], t_high[p], radius[p], reach[p]) for p in parts]
                )
            left = live & ~clear
            crowded = np.bincount(box[left], minlength=count) > _MAX_BOXES // 2
            if depth == _MAX_DEPTH or crowded.any():
                last = left if depth == _MAX_DEPTH else left & crowded[box]
                self._decide(verdicts, decided, box, np.flatnonzero(last), UNDECIDED, focal, value)
                if depth == _MAX_DEPTH:
                    break
                left &= ~crowded[box]
            box, middle = box[left], middle[left]
            t_low, t_high = t_low[left], t_high[left]
            box = np.concatenate([box, box])
            t_low, t_high = np.concatenate([t_low, middle]), np.concatenate([middle, t_high])
        return [
            v if v is not None else Between(*self.bounds[i], CLEAR) for i, v in enumerate(verdicts)
        ]

    def _decide(
        self,
        verdicts: list[Between | None],
        decided: np.ndarray,
        box: np.ndarray,
        positions: np.ndarray,
        verdict: str,
        focal: np.ndarray,
        value: np.ndarray,
    ) -> None:
        """Give the interval of each box at ``positions``, in that order, the
        ``verdict`` at that box's focal length, unless it has one already."""
        for position in positions:
            interval = int(box[position])
            if verdicts[interval] is None:
                low, high = self.bounds[interval]
                verdicts[interval] = Between(
                    low, high, verdict, float(focal[position]), float(value[position])
                )
        decided[box[positions]] = True

    def _clear(
        self,
        box: np.ndarray,
        t_low: np.ndarray,
        t_high: np.ndarray,
        radius: np.ndarray,
        reach: np.ndarray,
    ) -> np.ndarray:
        """Whether, for every t in each box: f D'(r) > 0 for r in [0, radius] and
        f (D(radius) - reach) > 0 (f = f0 + t (f1 - f0)).

        Both are linear in (f, Q_1(t), Q_2(t), Q_3(t)), a cubic curve in t that
        lies in the convex hull of its four Bernstein control points over the
        box: each holds for every t when it holds at those four points. At
        each point, f D'(r) is one polynomial in r, bounded below on boxes of
        r by interval arithmetic; rounding is allowed for throughout."""
        f0, f1 = self.f0[box], self.f1[box]
        width = t_high - t_low
        # Control points of f (linear: its values at u = 0, 1/3, 2/3, 1) and of each Q_i.
        thirds = np.arange(4) / 3
        f_points = (f0 + t_low * (f1 - f0))[:, None] + (width * (f1 - f0))[:, None] * thirds
        f_size = np.abs(f0)[:, None] + np.abs(f1 - f0)[:, None] * (t_high[:, None] + 1)
        q_points, q_size = _bernstein(self.q[box], t_low, width)  # (boxes, terms, 4)
        # f (D(R) - reach) = f (R - reach) + sum_i Q_i term_i(R), at each control point
        terms = self.terms[box]
        term_at = _horner(terms, radius[:, None])[:, :, None]
        term_size = _horner(np.abs(terms), radius[:, None])[:, :, None]
        excess = f_points * (radius - reach)[:, None] + (q_points * term_at).sum(axis=1)
        size = f_size * (radius + reach)[:, None] + (q_size * term_size).sum(axis=1)
        reaches = np.all(excess - _ROUNDING * size > 0, axis=1)
        # f D'(r) = f + sum_i Q_i s_i(r): one polynomial in r per control point.
        slopes = self.slopes[box]  # (boxes, terms, powers)
        curve = np.einsum("bij,bik->bjk", q_points, slopes)  # (boxes, 4 points, powers)
        curve[:, :, 0] += f_points
        curve_size = np.einsum("bij,bik->bjk", q_size, np.abs(slopes))
        curve_size[:, :, 0] += f_size
        edges = radius[:, None] * np.linspace(0.0, 1.0, _RADIUS_BOXES + 1)
        lower, _, partial = _interval_polynomial(
            curve[:, :, None, :], edges[:, None, :-1], edges[:, None, 1:]
        )
        magnitude = _horner(curve_size[:, :, None, :], edges[:, None, 1:])
        rising = np.all(lower - _ROUNDING * (partial + magnitude) > 0, axis=(1, 2))
        return reaches & rising


def _bernstein(
    cubics: np.ndarray, t_low: np.ndarray, width: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The Bernstein control points over [t_low, t_low + width] of cubics
    (coefficients of 1, t, t^2, t^3 along the last axis; one box per row),
    and a bound on the magnitude of every partial result (for rounding)."""
    low, span = t_low[:, None, None], width[:, None, None]

    def controls(values: np.ndarray) -> np.ndarray:
        c0, c1, c2, c3 = (part[..., None] for part in np.moveaxis(values, -1, 0))
        # Taylor coefficients at t_low, times powers of the width: the cubic in u.
        a0 = c0 + low * (c1 + low * (c2 + low * c3))
        a1 = span * (c1 + low * (2 * c2 + 3 * low * c3))
        a2 = span**2 * (c2 + 3 * low * c3)
        a3 = span**3 * c3
        return np.concatenate(
            [a0, a0 + a1 / 3, a0 + 2 * a1 / 3 + a2 / 3, a0 + a1 + a2 + a3], axis=-1
        )

    # t_low >= 0: the same steps on magnitudes bound every partial result.
    return controls(cubics), controls(np.abs(cubics))


def _horner(coefficients: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Polynomials (coefficients of 1, x, ..., along the last axis) at ``x``
    (broadcast against the other axes)."""
    result = coefficients[..., -1] * np.ones_like(x)
    for power in range(coefficients.shape[-1] - 2, -1, -1):
        result = result * x + coefficients[..., power]
    return result


def _radius_past(
    rows: np.ndarray, terms: np.ndarray, reach: np.ndarray, ratio: np.ndarray, r_max: np.ndarray
) -> np.ndarray:
    """For each model (``rows`` of coefficients times ``terms``): a radius where
    it is past ``reach`` (halfway to its d_max, or 5% past where it never
    folds) and still rising; NaN where none is found. D rises from 0 to
    r_max, so the radius is found by halving."""
    curve = np.einsum("bi,bij->bj", rows, terms)
    curve[:, 1] += 1.0  # D(r) = r + sum of coefficient x term
    aim = np.where(np.isfinite(ratio), reach * (1 + (np.minimum(ratio, 1.1) - 1) / 2), reach * 1.05)
    low = np.zeros(len(rows))
    high = np.where(np.isfinite(r_max), r_max, np.maximum(aim, 1.0))
    for _ in range(64):  # a model that never folds rises without bound: double until past
        short = ~np.isfinite(r_max) & (_horner(curve, high) < aim)
        if not short.any():
            break
        high = np.where(short, 2 * high, high)
    for _ in range(_RADIUS_HALVINGS):
        middle = (low + high) / 2
        past = _horner(curve, middle) >= aim
        low, high = np.where(past, low, middle), np.where(past, middle, high)
    return np.where(_horner(curve, high) >= aim, high, math.nan)


def _interval_polynomial(
    coefficients: np.ndarray, low: np.ndarray, high: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lower, upper, size) of polynomials (coefficients of 1, x, ... along the
    last axis) over x in [low, high] (broadcast against the other axes), by
    Horner's rule in interval arithmetic; ``size`` bounds the magnitude of
    every partial result (for the rounding allowance)."""
    shape = np.broadcast_shapes(coefficients.shape[:-1], low.shape, high.shape)
    lower = upper = np.broadcast_to(coefficients[..., -1], shape)
    size = np.abs(lower)
    scale = np.maximum(np.abs(low), np.abs(high))
    for power in range(coefficients.shape[-1] - 2, -1, -1):
        a, b, c, d = lower * low, lower * high, upper * low, upper * high
        coefficient = coefficients[..., power]
        lower = np.minimum(np.minimum(a, b), np.minimum(c, d)) + coefficient
        upper = np.maximum(np.maximum(a, b), np.maximum(c, d)) + coefficient
        size = size * scale + np.abs(coefficient)
    return lower, upper, size
