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

import bisect
import functools
import math
from collections.abc import Sequence

#: The cubic Hermite basis, coefficients of 1, t, t^2, t^3: h00, h10, h01, h11.
HERMITE_BASIS = ((1, 0, -3, 2), (0, 1, -2, 1), (0, 0, 3, -2), (0, 0, -1, 1))
_H00, _H10, _H01, _H11 = HERMITE_BASIS


def spline_terms(
    focals: Sequence[float], focal: float
) -> tuple[int | None, int | None, list[tuple[int, tuple[float, ...]]]]:
    """How liblensfun interpolates at ``focal``: (the calibration below, the
    one above, [(index, g)]) where the coefficients at ``focal`` are the sum
    of g(t) x focal_index / focal x the coefficients of calibration
    ``index``, g a cubic in t = (focal - below) / (above - below) given by
    its coefficients of 1, t, t^2, t^3. At a calibrated focal length, or
    outside the calibrated range, one calibration with g = 1 (and focal /
    focal_index folded into it: the weight is exactly 1)."""
    # liblensfun's four spline slots (lfLens::InterpolateDistortion): the two
    # calibrations nearest above the focal length (slot 1 the nearest), the
    # two nearest below (slot 2 the nearest); among calibrations at the same
    # focal length, the first met wins, and the second fills the outer slot.
    if not math.isfinite(focal):
        return None, None, []  # liblensfun's distances are never less than an infinite one
    distinct, first, second = _calibrated(tuple(focals))
    position = bisect.bisect_left(distinct, focal)
    if position < len(distinct) and distinct[position] == focal:
        index = first[position]
        return None, None, [(index, (focal / focals[index], 0.0, 0.0, 0.0))]
    slots = _slots(distinct, first, second, position)
    start, end = slots[1], slots[2]
    if start is None or end is None:
        side = start if start is not None else end
        return None, None, [] if side is None else [(side, (focal / focals[side], 0.0, 0.0, 0.0))]
    return start, end, _hermite(slots)


def interval_terms(
    focals: Sequence[float],
) -> list[tuple[float, float, int, int, list[tuple[int, tuple[float, ...]]]]]:
    """:func:`spline_terms` of every interval between neighbouring distinct
    calibrated ``focals`` at once: (low, high, the calibration above, the
    one below, [(index, g)]), in ascending order."""
    return [
        (low, high, slots[1], slots[2], _hermite(slots))  # type: ignore[misc]
        for low, high, slots in interval_slots(focals)
    ]


def interval_slots(focals: Sequence[float]) -> list[tuple[float, float, list[int | None]]]:
    """Every interval between neighbouring distinct calibrated ``focals``, in
    ascending order: (low, high, liblensfun's four spline slots), the slots
    being the indices of the second calibration above, the calibration
    above, the one below and the second below (None where there is none),
    whose Hermite spline :data:`HERMITE_BASIS` weighs as :func:`spline_terms` says."""
    distinct, first, second = _calibrated(tuple(focals))
    return [
        (distinct[position - 1], distinct[position], _slots(distinct, first, second, position))
        for position in range(1, len(distinct))
    ]


def _slots(
    distinct: list[float], first: list[int], second: list[int | None], position: int
) -> list[int | None]:
    """liblensfun's four spline slots for a focal length between
    ``distinct[position - 1]`` and ``distinct[position]`` (see :func:`_calibrated`)."""
    slots: list[int | None] = [None] * 4
    if position < len(distinct):  # the calibrations above
        slots[1] = first[position]
        slots[0] = second[position] if second[position] is not None else (
            first[position + 1] if position + 1 < len(distinct) else None
        )  # fmt: skip
    if position > 0:  # the calibrations below
        slots[2] = first[position - 1]
        slots[3] = second[position - 1] if second[position - 1] is not None else (
            first[position - 2] if position > 1 else None
        )  # fmt: skip
    return slots


def _hermite(slots: list[int | None]) -> list[tuple[int, tuple[float, ...]]]:
    """[(index, g)] of the Hermite spline between the calibrations of slots
    1 and 2 (both there), with tangents from the outer slots 0 and 3."""
    start, end = slots[1], slots[2]
    # The spline runs from the calibration above (t = 0) to the one below (t = 1).
    parts = [(start, _H00, 1.0), (end, _H01, 1.0)]
    for slot, basis in ((0, _H10), (3, _H11)):
        # Tangents: half the difference of the neighbours either side, or
        # the difference of the two ends where a neighbour is missing.
        outer = slots[slot]
        if outer is None:
            parts += [(end, basis, 1.0), (start, basis, -1.0)]
        elif slot == 0:
            parts += [(end, basis, 0.5), (outer, basis, -0.5)]
        else:
            parts += [(outer, basis, 0.5), (start, basis, -0.5)]
    found: dict[int, list[float]] = {}
    for index, basis, scale in parts:
        total = found.get(index)
        if total is None:
            found[index] = [0.0 + scale * value for value in basis]
        else:
            for power, value in enumerate(basis):
                total[power] += scale * value
    return sorted((index, tuple(g)) for index, g in found.items())  # type: ignore[misc]


@functools.lru_cache(maxsize=4096)
def _calibrated(
    focals: tuple[float, ...],
) -> tuple[list[float], list[int], list[int | None]]:
    """The distinct calibrated focal lengths, ascending, and for each the
    first and the second calibration (in the order met) at it; a focal
    length that is not finite is never liblensfun's nearest."""
    first: dict[float, int] = {}
    second: dict[float, int] = {}
    for index, calibrated in enumerate(focals):
        if not math.isfinite(calibrated):
            continue
        if calibrated in first:
            second.setdefault(calibrated, index)
        else:
            first[calibrated] = index
    distinct = sorted(first)
    return distinct, [first[f] for f in distinct], [second.get(f) for f in distinct]


def weights(focals: Sequence[float], focal: float) -> list[tuple[int, float]]:
    """(index, weight) pairs: the coefficients at ``focal`` are the sum of
    weight x the coefficients of calibration ``index``, for calibrations at
    ``focals``, in the order liblensfun meets them (which decides between
    equal focal lengths); empty without calibrations. Raises ``ValueError``
    for a focal length that is not a positive number."""
    if not focal > 0:
        raise ValueError(f"focal length {focal!r} is not a positive number")
    start, end, terms = spline_terms(focals, focal)
    if start is None or end is None:
        return [(index, 1.0) for index, _ in terms]
    t = (focal - focals[start]) / (focals[end] - focals[start])
    return [
        (index, (g[0] + t * (g[1] + t * (g[2] + t * g[3]))) * focals[index] / focal)
        for index, g in terms
    ]


def interpolated(
    coefficients: Sequence[Sequence[float]], focals: Sequence[float], focal: float
) -> tuple[float, ...]:
    """The coefficients liblensfun applies at ``focal``, from calibrations with
    ``coefficients`` (one sequence each, the model's order) at ``focals``;
    empty without calibrations. Raises ``ValueError`` where the two do not
    pair up, and as :func:`weights` does."""
    if len(coefficients) != len(focals):
        raise ValueError(
            f"{len(coefficients)} sequences of coefficients for {len(focals)} focal lengths"
        )
    if not coefficients:
        return ()
    size = len(coefficients[0])
    total = [0.0] * size
    for index, weight in weights(focals, focal):
        for position in range(size):
            total[position] += weight * coefficients[index][position]
    return tuple(total)
