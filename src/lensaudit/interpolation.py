"""A lens's distortion between its calibrated focal lengths, as liblensfun
interpolates it (``lfLens::InterpolateDistortion`` in Lensfun master's
``libs/lensfun/lens.cpp``).

liblensfun takes the calibrations of the lens's calibration set (those
whose model is the first one met), and for a focal length f:

- a calibration at exactly f: its coefficients;
- f below the first or above the last calibrated focal length: the nearest
  calibration's coefficients;
- else, with f1 < f < f2 the calibrations either side and f0, f3 the next
  ones out (if any), each coefficient k is a cubic Hermite spline of
  k x focal through (f1, k1 f1) and (f2, k2 f2), with tangents
  (k2 f2 - k0 f0) / 2 and (k3 f3 - k1 f1) / 2 (one-sided, k2 f2 - k1 f1,
  where f0 or f3 is missing), at t = (f - f1) / (f2 - f1), divided by f.

Each interpolated coefficient is therefore a linear combination of the
calibrations' own (:func:`weights`), with weights that depend on f only,
and the distortion D_f(r) is linear in the calibrations' coefficients. The
spline can overshoot: two calibrations whose models both clear the image
corner may fold inside it in between. liblensfun computes in single
precision; these weights are its formulas in double precision.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


def weights(focals: Sequence[float], focal: float) -> list[tuple[int, float]]:
    """(index, weight) pairs: the coefficients at ``focal`` are the sum of
    weight x the coefficients of calibration ``index``, for calibrations at
    ``focals``, in the order liblensfun meets them (which decides between
    equal focal lengths); empty without calibrations."""
    # liblensfun's four spline slots: two calibrations above the focal length
    # (slot 1 the nearest), two below (slot 2 the nearest), by f - calibrated.
    slots: list[int | None] = [None] * 4
    distances = [-math.inf, -math.inf, math.inf, math.inf]
    for index, calibrated in enumerate(focals):
        distance = focal - calibrated
        if distance == 0:
            return [(index, 1.0)]
        if distance < 0:
            if distance > distances[1]:
                slots[0], distances[0] = slots[1], distances[1]
                slots[1], distances[1] = index, distance
            elif distance > distances[0]:
                slots[0], distances[0] = index, distance
        elif distance < distances[2]:
            slots[3], distances[3] = slots[2], distances[2]
            slots[2], distances[2] = index, distance
        elif distance < distances[3]:
            slots[3], distances[3] = index, distance
    start, end = slots[1], slots[2]
    if start is None or end is None:
        side = start if start is not None else end
        return [] if side is None else [(side, 1.0)]
    t = (focal - focals[start]) / (focals[end] - focals[start])
    t2, t3 = t * t, t * t * t
    found: dict[int, float] = {}

    def add(index: int, weight: float) -> None:
        # The spline runs through the values k x focal, divided by f after.
        found[index] = found.get(index, 0.0) + weight * focals[index] / focal

    add(start, 2 * t3 - 3 * t2 + 1)
    add(end, -2 * t3 + 3 * t2)
    for slot, end_weight in ((0, t3 - 2 * t2 + t), (3, t3 - t2)):
        # Tangents: half the difference of the neighbours either side, or
        # the difference of the two ends where a neighbour is missing.
        outer = slots[slot]
        if outer is None:
            add(end, end_weight)
            add(start, -end_weight)
        elif slot == 0:
            add(end, end_weight / 2)
            add(outer, -end_weight / 2)
        else:
            add(outer, end_weight / 2)
            add(start, -end_weight / 2)
    return sorted(found.items())


def interpolated(
    coefficients: Sequence[Sequence[float]], focals: Sequence[float], focal: float
) -> tuple[float, ...]:
    """The coefficients liblensfun applies at ``focal``, from calibrations with
    ``coefficients`` (one sequence each, the model's order) at ``focals``."""
    size = len(coefficients[0])
    total = [0.0] * size
    for index, weight in weights(focals, focal):
        for position in range(size):
            total[position] += weight * coefficients[index][position]
    return tuple(total)
