"""Folds between calibrated focal lengths, as liblensfun interpolates a zoom.

liblensfun applies, at a focal length between two calibrations of a lens, a
model whose coefficients a spline gives (:mod:`lensaudit.interpolation`);
the spline can overshoot, so two calibrations that clear the image may fold
inside it in between. :func:`lensaudit.zooms.between_all` judges every focal
length of every interval (a proof, not a sample), and each interval that
folds inside the image, next to two calibrations that do not fold themselves,
is a ``fold-between-calibrations`` error at the lower calibration's line,
naming the focal length where it folds, the calibration above, and the
other calibrations the spline weighs there (a change to one of those can
make the fold, away from the finding's line). Next to
a calibration that folds, the interval's fold is that calibration's
``fold-in-image``, and a refit of it (``lensaudit fix`` sweeps the zoom)
mends both. An interval that cannot be decided is a notice, when asked for.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import replace

from ... import zooms
from ...read.records import DistortionEntry
from ..matching import entry_content, lens_identity
from ..result import Identified, entry_finding
from . import ERROR, NOTICE, Context, Rule

ORDER = 70

FOLD_BETWEEN_CALIBRATIONS = Rule(
    "fold-between-calibrations",
    ERROR,
    "entry",
    "a zoom's model, as liblensfun interpolates it between two calibrations that do not fold, "
    "folds inside the image",
    "at a focal length between two calibrations of a zoom, neither of which folds, the model "
    "liblensfun interpolates folds back inside the image (see "
    "[below](#zooms-between-their-calibrations)); a notice, with `--verbose`, where whether "
    "it folds could not be decided",
    "liblensfun interpolates a zoom's coefficients with a spline through the calibrations "
    "either side and their neighbours; the spline can overshoot. Proven over every focal "
    "length of the interval, not sampled; a notice with --verbose where it cannot be decided.",
    fails=(
        "slr-nikon.xml:3085 at Lensfun 09ed743, AF Zoom-Nikkor 28-200mm G: the spline through "
        "28, 38 and a mistyped 48 mm entry folds at 33 mm, 0.753 of the image radius"
    ),
    passes=(
        "the same lens at b7364b6, the same day, with the 48 mm entry removed: nothing between "
        "28 and 38 mm folds"
    ),
    lesser="with --verbose, where whether it folds could not be decided",
    lesser_severity=NOTICE,
)
RULES = (FOLD_BETWEEN_CALIBRATIONS,)


def folds_between(
    entries: Sequence[DistortionEntry],
    image_radius: Sequence[float],
    folding: Sequence[bool],
    file_names: Sequence[str],
    verbose: bool,
) -> Iterable[tuple[int, Identified]]:
    """(position in ``entries``, finding) for every interval between two
    calibrated focal lengths of a lens where liblensfun's interpolated model
    folds inside the image though neither calibration does (``folding``:
    whether each entry folds inside its image; ``image_radius``: each one's
    r_corner, Hugin units; ``file_names``: the name of each entry's file, as
    a baseline knows it), or, with ``verbose``, could not be decided."""
    sets = [
        found
        for found in zooms.calibration_sets_of(entries, image_radius)
        if len(set(found.focals)) > 1 and math.isfinite(found.image_radius)
    ]
    if not sets:
        return
    import numpy as np  # numpy: only where arrays are needed

    tables = [zooms.coefficient_table(found, entries) for found in sets]
    with np.errstate(all="ignore"):  # huge interpolated models prove nothing, and say nothing
        verdicts = zooms.between_all(sets, tables)
    for found, intervals in zip(sets, verdicts, strict=True):
        for interval in intervals:
            if interval.verdict == zooms.CLEAR:
                continue
            if interval.verdict == zooms.UNDECIDED and not verbose:
                continue
            low, high = (_first_at(found, entries, f) for f in (interval.low, interval.high))
            if folding[low] or folding[high]:
                continue  # that calibration's own fold-in-image
            others = [
                entries[i] for i in _spline_calibrations(found, interval) if i not in (low, high)
            ]
            yield low, _finding(entries[low], entries[high], interval, file_names[low], others)


def _spline_calibrations(found: zooms.CalibrationSet, interval: zooms.Between) -> list[int]:
    """The entries (positions in the audit) liblensfun's spline interpolates
    from at the interval's focal length where it folds (or its middle)."""
    focal = interval.focal if interval.focal > 0 else (interval.low + interval.high) / 2
    return sorted(found.indices[position] for position in zooms.neighbours(found, focal))


def _first_at(found: zooms.CalibrationSet, entries: Sequence[DistortionEntry], focal: float) -> int:
    """The first entry of a set calibrated at ``focal`` (its position in ``entries``)."""
    return next(i for i in found.indices if entries[i].focal == focal)


def _finding(
    low: DistortionEntry,
    high: DistortionEntry,
    interval: zooms.Between,
    file_name: str,
    others: Sequence[DistortionEntry] = (),
) -> Identified:
    at = f"{interval.focal:.4g} mm"
    between = (
        f"between the calibrations at {interval.low:g} mm (this line) and "
        f"{interval.high:g} mm (line {high.line})"
    )
    if others:  # the spline weighs its neighbours too: a change to one of them shows here
        between += ", whose spline there also weighs " + ", ".join(
            f"{entry.focal:g} mm (line {entry.line})" for entry in others
        )
    if interval.verdict == zooms.FOLDS:
        severity = FOLD_BETWEEN_CALIBRATIONS.severity
        text = (
            f"liblensfun's interpolated model folds back inside the image at {at}, "
            f"{between}: D(r) peaks at {interval.r_normalized:.3f} times the image radius there"
        )
    else:
        severity = FOLD_BETWEEN_CALIBRATIONS.lesser_severity
        text = f"whether liblensfun's interpolated model folds {between} could not be decided"
    finding = replace(
        entry_finding(severity, FOLD_BETWEEN_CALIBRATIONS.code, low, text),
        related=((high.file, high.line), *((entry.file, entry.line) for entry in others)),
    )
    # The pair of calibrations of the lens by name; then the pair alone (a renamed lens).
    pair = (severity, FOLD_BETWEEN_CALIBRATIONS.code, entry_content(low), entry_content(high))
    keys = ((*pair, lens_identity(low.maker, low.lens)), pair)
    return Identified(finding, keys, (file_name,))


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each interval between two calibrations of a zoom where the interpolated model folds."""
    entries = [entry for _, entry in context.entries]
    names = [context.read[index].source.file_name for index, _ in context.entries]
    folding = [m is not None and not m.r_normalized >= 1 for m in context.metrics]
    for position, item in folds_between(entries, context.corners, folding, names, context.verbose):
        yield context.entries[position][0], item
