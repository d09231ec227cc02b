"""Refit a distortion model that folds inside its image so that it no longer does.

The paper ends by proposing to estimate polynomial coefficients under the
constraint that r_max is infinite, or beyond a chosen radius. This stage does
that for an entry already in a Lensfun database: among the coefficients of
the same model (ptlens a, b, c; poly3 k1; poly5 k1, k2), it finds those whose
curve D(r) stays closest to the original over the image and that

* are increasing (D' >= :data:`SLOPE_FLOOR`) up to the target radius, an
  undistorted radius in Hugin units (by default the image radius times the
  margin, and never less than the image radius), so that r_max lies beyond
  it; and
* reach the distorted radius margin x r_corner while still increasing, so
  that d_max = D(r_max) is at least that: the entry no longer folds inside
  its image (r_normalized >= margin), which is what ``lensaudit scan`` flags.

The image radius r_corner is the audit's: the frame's corner hypot(aspect,
1), or a circular fisheye's image circle (see :mod:`lensaudit.metrics`).

Both are needed: the Tokina 11-16 mm at 11 mm has r_max = 2.19, beyond its
corner 1.80, yet folds inside its image because D only climbs to 1.69.

Method. D is linear in each model's coefficients,

    ptlens  D = r + a (r^4 - r) + b (r^3 - r) + c (r^2 - r)
    poly3   D = r + k1 (r^3 - r)
    poly5   D = r + k1 r^3 + k2 r^5

so for radii R and T the fit is a linear program on grids: minimize t
subject to |D_new(r) - D_old(r)| <= t over [0, r_corner], D_new'(r) >=
SLOPE_FLOOR over [0, R], D_new(R) >= margin x r_corner, and D_new' > 0 over
[R, T] (scipy's HiGHS), the slopes imposed through r = s / (1 - s), so that
T may be inf. R is searched without regard to the target; T runs over a
fixed ladder from the target on (:func:`lensaudit.refit.radii_from`), so that
a smaller target tries all a larger one does and its refit is never worse.
Each is verified with the exact r_max solver (:mod:`lensaudit.metrics`);
where the grid let a fold through, points are added where D' is smallest and
the program solved again. The coefficients are then rounded to the decimals
the file uses for the entry (at least five significant digits) and verified
again, with one more digit where rounding broke them; the pair whose written
coefficients change D least wins.

Slope. A model that only just increases stretches the image without bound
when undistorted (by 1 / D'); the fixed model keeps D' >= :data:`SLOPE_FLOOR`
from the centre to where D reaches the margin, checked exactly at the
ends and where D'' is zero, and reports the smallest D' there.

Units. Radii are Hugin units (r = 1 is half the short side of the image
the model was calibrated on). Changes of D are reported as a fraction of
the half diagonal, and in pixels of a 6000 x 4000 frame as liblensfun
applies the model to it: it matches the diagonals of the calibration's
frame and the image's, so a Hugin unit is 3606 / hypot(aspect, 1) px
(:func:`pixels_per_unit`: 2000 px at 3:2, 2163 px at 4:3). The maximum is
over radii 0 to r_corner, the root mean square over the image (its own
frame, aspect x 1, within r_corner).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from . import metrics, xmlpatch, zooms
from .pipeline import run
from .read.paths import read_file
from .read.records import MODEL_COEFFICIENTS, STATUS_OK, DistortionEntry, parse_number
from .refit import (
    DEFAULT_MARGIN,
    FRAME,
    SLOPE_FLOOR,
    Change,
    Goal,
    Verdict,
    best_refit,
    change_of_distortion,
    decimals_of,
    format_like,
    goal_for,
    judge,
    pixels_per_unit,
)
from .xmlpatch import FilePatch, set_attributes

__all__ = [
    "DEFAULT_MARGIN",
    "DEFAULT_TOLERANCE_PX",
    "FRAME",
    "SLOPE_FLOOR",
    "STATUS_BEYOND_TOLERANCE",
    "STATUS_FIXED",
    "STATUS_NOT_LOCATED",
    "STATUS_NO_SOLUTION",
    "Change",
    "FixResult",
    "Goal",
    "SourceTexts",
    "Verdict",
    "change_of_distortion",
    "decimals_of",
    "fix",
    "fix_audit",
    "fix_entry",
    "format_like",
    "goal_for",
    "judge",
    "matching",
    "patches",
    "pixels_per_unit",
    "read_sources",
    "select",
    "to_dataframe",
    "written_texts",
]

if TYPE_CHECKING:
    import pandas

    from .pipeline import Audit
    from .xmlpatch import FilePatch, StartTag

STATUS_FIXED = "fixed"
STATUS_BEYOND_TOLERANCE = "beyond_tolerance"
STATUS_NO_SOLUTION = "no_solution"
STATUS_NOT_LOCATED = "not_located"
DEFAULT_TOLERANCE_PX = 50.0


@dataclass(frozen=True)
class FixResult:
    """The outcome for one entry that folds.

    ``old`` and ``new`` are the coefficients in the model's order (``names``);
    ``new_texts`` are the new values as they would be written. ``new`` is
    empty when no solution was found. r_max and r_normalized are in Hugin
    units and ratios, as in ``lensaudit scan``; the changes of D are in pixels
    of a 6000x4000 frame as liblensfun scales the model to it
    (:func:`pixels_per_unit`), and the largest as a fraction of the half
    diagonal; ``min_slope_after`` is the smallest D' of the new model from
    the centre to where D reaches the margin.
    """

    entry: DistortionEntry
    names: tuple[str, ...]
    old: tuple[float, ...]
    old_texts: tuple[str, ...]
    new: tuple[float, ...]
    new_texts: tuple[str, ...]
    goal: Goal
    r_max_before: float
    r_max_after: float
    r_normalized_before: float
    r_normalized_after: float
    max_change_px: float
    rms_change_px: float
    status: str
    message: str = ""
    index: int = field(default=-1, compare=False)
    max_change_half_diagonal: float = math.nan
    min_slope_after: float = math.nan
    #: The smallest r_normalized of the models liblensfun interpolates between
    #: the lens's calibrations (every 0.01 mm), before and after, and where
    #: after (NaN for a lens with one calibrated focal length).
    r_normalized_between_before: float = math.nan
    r_normalized_between_after: float = math.nan
    focal_between_after: float = math.nan

    @property
    def where(self) -> str:
        """``file:line`` of the entry's ``<distortion>``."""
        return f"{self.entry.file}:{self.entry.line}"

    @property
    def fixed(self) -> bool:
        """Whether the refit meets its goal within the tolerance (and is written)."""
        return self.status == STATUS_FIXED

    def record(self) -> dict[str, Any]:
        """The result as one flat row (see :data:`RECORD_COLUMNS`)."""
        old = dict(zip(self.names, self.old, strict=True))
        # No new texts where no coefficients were found (no_solution): empty fields.
        new = dict(zip(self.names, self.new_texts, strict=True)) if self.new_texts else {}
        entry = self.entry
        row: dict[str, Any] = {
            "file": entry.file,
            "line": entry.line,
            "maker": entry.maker,
            "lens": entry.lens,
            "focal": entry.focal,
            "crop_factor": entry.crop_factor,
            "model": entry.model,
        }
        for name in ("a", "b", "c", "k1", "k2"):
            row[f"{name}_old"] = old.get(name, math.nan)
        for name in ("a", "b", "c", "k1", "k2"):
            row[f"{name}_new"] = new.get(name, "")
        row["target"] = self.goal.target
        row.update((name, getattr(self, name)) for name in _RESULT_COLUMNS)
        return row


#: The columns of :meth:`FixResult.record` that are fields of the result.
_RESULT_COLUMNS = (
    "r_max_before", "r_max_after", "r_normalized_before", "r_normalized_after",
    "max_change_px", "rms_change_px", "max_change_half_diagonal", "min_slope_after",
    "r_normalized_between_before", "r_normalized_between_after", "focal_between_after",
    "status", "message",
)  # fmt: skip
#: Columns of :meth:`FixResult.record`, in order.
RECORD_COLUMNS = (
    "file", "line", "maker", "lens", "focal", "crop_factor", "model",
    "a_old", "b_old", "c_old", "k1_old", "k2_old",
    "a_new", "b_new", "c_new", "k1_new", "k2_new",
    "r_max_before", "r_max_after", "r_normalized_before", "r_normalized_after", "target",
    "max_change_px", "rms_change_px", "max_change_half_diagonal", "min_slope_after",
    "r_normalized_between_before", "r_normalized_between_after", "focal_between_after",
    "status", "message",
)  # fmt: skip


def coefficients_of(entry: DistortionEntry) -> tuple[float, ...]:
    """The entry's coefficients in its model's order (a, b, c; k1; k1, k2)."""
    return tuple(getattr(entry, name) for name in MODEL_COEFFICIENTS[entry.model])


def fix_entry(
    entry: DistortionEntry,
    *,
    margin: float = DEFAULT_MARGIN,
    target: float | None = None,
    tolerance: float = DEFAULT_TOLERANCE_PX,
    texts: Mapping[str, str] | None = None,
    image_radius: float | None = None,
) -> FixResult:
    """Refit one audited entry so that it no longer folds inside its image.

    ``margin``: the r_normalized the new model must reach (1: the image
    radius). ``target``: undistorted radius (Hugin units, may be ``inf``) up
    to which the new model must increase; by default r_corner x margin, at
    least r_corner. ``tolerance``: largest change of D over the image, in
    pixels of a 6000x4000 frame, for the result to count as fixed.
    ``texts``: the coefficient attributes as written in the file (their
    decimals and style are kept); by default the shortest form of each value.
    ``image_radius``: the radius of the image in Hugin units, as the audit's
    ``r_corner`` column gives it; by default the corner hypot(aspect, 1).
    """
    if entry.status != STATUS_OK or entry.model not in MODEL_COEFFICIENTS:
        raise ValueError(f"{entry.file}:{entry.line}: entry was not audited ({entry.status})")
    names = MODEL_COEFFICIENTS[entry.model]
    old = coefficients_of(entry)
    old_texts = written_texts(names, old, texts)
    goal = goal_for(entry.aspect_ratio, margin, target, image_radius)
    before = judge(entry.model, old, goal)
    common = dict(
        entry=entry,
        names=names,
        old=old,
        old_texts=old_texts,
        goal=goal,
        r_max_before=before.r_max,
        r_normalized_before=before.r_normalized,
    )
    refitted = best_refit(entry.model, old, goal, old_texts)
    if refitted is None:
        return FixResult(
            **common,
            new=(),
            new_texts=(),
            r_max_after=math.nan,
            r_normalized_after=math.nan,
            max_change_px=math.nan,
            rms_change_px=math.nan,
            status=STATUS_NO_SOLUTION,
            message=f"no {entry.model} coefficients are increasing up to r = "
            f"{goal.target:.4g} and reach {goal.reach:.4g} before folding with "
            f"D' >= {SLOPE_FLOOR:g}",
        )
    new_texts, new, change = refitted.texts, refitted.coefficients, refitted.change
    # Verified against its own radius T >= the target, so it meets the goal too.
    after = judge(entry.model, new, goal)
    status, message = STATUS_FIXED, ""
    if change.max_px > tolerance:
        status = STATUS_BEYOND_TOLERANCE
        message = _beyond_tolerance(entry, names, change, tolerance, before, goal)
    return FixResult(
        **common,
        new=new,
        new_texts=tuple(new_texts),
        r_max_after=after.r_max,
        r_normalized_after=after.r_normalized,
        max_change_px=change.max_px,
        rms_change_px=change.rms_px,
        status=status,
        message=message,
        max_change_half_diagonal=change.max_half_diagonal,
        min_slope_after=after.min_slope,
    )


def written_texts(
    names: Sequence[str], values: Sequence[float], texts: Mapping[str, str] | None
) -> tuple[str, ...]:
    """Each coefficient as the file writes it (``texts``, its attribute values),
    a missing one as 0; without ``texts``, the shortest form of each value."""
    if texts is None:
        texts = {name: repr(value) for name, value in zip(names, values, strict=True)}
    return tuple(texts.get(name) or "0" for name in names)


def _beyond_tolerance(
    entry: DistortionEntry,
    names: tuple[str, ...],
    change: Change,
    tolerance: float,
    before: Verdict,
    goal: Goal,
) -> str:
    """Why a fit that changes D by more than ``tolerance`` pixels is not a fix."""
    message = (
        f"the closest {entry.model} curve without the fold (D' >= {SLOPE_FLOOR:g} until D "
        f"reaches {goal.margin:g} x the image radius) changes D by up to "
        f"{change.max_px:.0f} px over the image, more than the {tolerance:g} px "
        f"tolerance ({FRAME} frame): the model folds at D = {before.d_max:.3g}, "
        f"{before.r_normalized:.0%} of the image radius {goal.r_corner:.3g}"
    )
    if len(names) == 1:
        message += f"; {entry.model} has a single coefficient"
    frame_corner = float(metrics.image_corner(entry.aspect_ratio))
    if entry.type not in ("rectilinear", "") and goal.r_corner >= frame_corner:
        # Judged against the frame's corner: a fisheye's picture may end
        # at an image circle short of it (one its name does not announce).
        message += (
            f"; the lens is of type {entry.type}: if its image circle ends inside "
            "the frame, the fold may lie outside the picture"
        )
    return message


def select(
    audit: Audit,
    *,
    margin: float = DEFAULT_MARGIN,
    lens: str | None = None,
    focal: float | None = None,
) -> list[int]:
    """Indices of audited entries with r_normalized < margin, optionally filtered
    (see :func:`matching`)."""
    m = audit.metrics
    with np.errstate(invalid="ignore"):
        folding = audit.audited & np.isfinite(m.r_max) & (m.r_normalized < margin)
    return matching(audit, np.flatnonzero(folding).tolist(), lens=lens, focal=focal)


def matching(
    audit: Audit, indices: Sequence[int], *, lens: str | None = None, focal: float | None = None
) -> list[int]:
    """Those of ``indices`` whose entry matches: ``lens`` "maker lens" as a
    substring, ignoring case and with runs of white space as one space (as
    ``lensaudit check`` suggests the command), ``focal`` the calibrated focal
    length in millimetres."""
    chosen = []
    needle = _spaced(lens) if lens else None
    for index in indices:
        entry = audit.entries[index]
        if needle is not None and needle not in _spaced(f"{entry.maker} {entry.lens}"):
            continue
        if focal is not None and not math.isclose(entry.focal, focal, rel_tol=1e-9):
            continue
        chosen.append(index)
    return chosen


def _spaced(text: str) -> str:
    """``text`` without case, runs of white space as one space."""
    return " ".join(text.split()).casefold()


def _matches(entry: DistortionEntry) -> Any:
    """A test on raw attribute texts: are these the entry's model, focal and coefficients?"""

    def same(values: Mapping[str, str]) -> bool:
        if (values.get("model") or "").strip() != entry.model:
            return False
        try:
            if parse_number(values.get("focal")) != entry.focal:
                return False
            return all(
                parse_number(values.get(name, "0")) == getattr(entry, name)
                for name in MODEL_COEFFICIENTS[entry.model]
            )
        except ValueError:
            return False

    return same


@dataclass
class SourceTexts:
    """The files behind some entries: their bytes, each entry's start tag, and
    why an entry's element could not be found (by entry index)."""

    files: dict[str, tuple[Any, bytes]] = field(default_factory=dict)  # name -> (path, bytes)
    tags: dict[int, StartTag] = field(default_factory=dict)  # entry index -> tag
    problems: dict[int, str] = field(default_factory=dict)  # entry index -> why not found

    def merge(self, other: SourceTexts) -> None:
        """Add what ``other`` read (of other entries) to this."""
        self.files.update(other.files)
        self.tags.update(other.tags)
        self.problems.update(other.problems)

    def texts(self, index: int) -> dict[str, str] | None:
        """The raw attribute values of an entry's ``<distortion>``, if found."""
        tag = self.tags.get(index)
        return tag.values() if tag is not None else None


def read_sources(audit: Audit, indices: Sequence[int]) -> SourceTexts:
    """Read the files of the given entries and find each entry's start tag.

    An entry whose element is no longer on its line with its values (the
    file changed since the audit read it), or whose file cannot be read, is
    noted in ``problems`` with the reason.
    """
    paths = {f.name: f.path for f in audit.files}
    unreadable: dict[str, str] = {}
    sources = SourceTexts()
    for index in indices:
        entry = audit.entries[index]
        if entry.file not in sources.files and entry.file not in unreadable:
            try:
                data = read_file(paths[entry.file])
            except OSError as error:
                unreadable[entry.file] = f"cannot read the file again: {error.strerror or error}"
            else:
                if data[:2] in (b"\xff\xfe", b"\xfe\xff") or b"\0" in data[:4]:
                    # Patched as bytes, where a tag is ASCII: UTF-16 and UTF-32 are not.
                    unreadable[entry.file] = (
                        "the file is UTF-16 or UTF-32 text, which is not patched: "
                        "save it as UTF-8 and run again"
                    )
                else:
                    sources.files[entry.file] = (paths[entry.file], data)
        if entry.file in unreadable:
            sources.problems[index] = unreadable[entry.file]
            continue
        data = sources.files[entry.file][1]
        try:
            sources.tags[index] = xmlpatch.locate(data, "distortion", entry.line, _matches(entry))
        except xmlpatch.PatchError as error:
            reason = re.sub(r"^line \d+: ", "", str(error))
            sources.problems[index] = (
                f"{reason}: the file changed since it was read (run again), or writes "
                "the element in a form that is not patched (character references)"
            )
    return sources


def fix_audit(
    audit: Audit,
    indices: Sequence[int],
    *,
    margin: float = DEFAULT_MARGIN,
    target: float | None = None,
    tolerance: float = DEFAULT_TOLERANCE_PX,
    sources: SourceTexts | None = None,
    progress: Callable[[int, int], object] | None = None,
) -> list[FixResult]:
    """:func:`fix_entry` for the given entries of an audit (see :func:`select`),
    then each lens's calibrations judged together as liblensfun interpolates
    them, and refitted together where that folds (:func:`fix_zooms`).

    With ``sources`` (:func:`read_sources`), the number format of each entry
    is taken from its file, and an entry whose element was not found there
    gets status ``not_located`` (its refit is still computed and shown).
    ``progress(done, total)`` is called as each entry is refitted.
    """
    results = []
    for done, index in enumerate(indices, start=1):
        texts = sources.texts(index) if sources is not None else None
        result = fix_entry(
            audit.entries[index],
            margin=margin,
            target=target,
            tolerance=tolerance,
            texts=texts,
            image_radius=float(audit.metrics.r_corner[index]),
        )
        results.append(_located(replace(result, index=index), sources))
        if progress is not None:
            progress(done, len(indices))
    return fix_zooms(audit, results, sources, margin=margin, target=target, tolerance=tolerance)


def _located(result: FixResult, sources: SourceTexts | None) -> FixResult:
    """The result, ``not_located`` where its element was not found in its file."""
    if sources is not None and result.index in sources.problems:
        return replace(result, status=STATUS_NOT_LOCATED, message=sources.problems[result.index])
    return result


def fix_zooms(
    audit: Audit,
    results: list[FixResult],
    sources: SourceTexts | None,
    *,
    margin: float = DEFAULT_MARGIN,
    target: float | None = None,
    tolerance: float = DEFAULT_TOLERANCE_PX,
) -> list[FixResult]:
    """The results, each lens's judged over its focal range as liblensfun
    interpolates it (:func:`lensaudit.zooms.sweep`). Where the entries fixed
    one at a time leave an interpolated model below the margin, the
    calibrations involved are refitted together
    (:func:`lensaudit.zooms.refit_together`) and all of them are written,
    or none; results are added for calibrations that move with them."""
    by_index = {r.index: r for r in results}
    found: dict[int, FixResult] = dict(by_index)
    for calibrations in zooms.calibration_sets(audit):
        if len(set(calibrations.focals)) < 2 or not by_index.keys() & set(calibrations.indices):
            continue
        lens = _ZoomLens(audit, calibrations, by_index, sources)
        found.update(lens.judged(margin, target, tolerance))
    return list(found.values())


class _ZoomLens:
    """One lens's distortion calibrations (:class:`lensaudit.zooms.CalibrationSet`),
    with the results of those refitted one at a time (by position in the set)."""

    def __init__(
        self,
        audit: Audit,
        calibrations: zooms.CalibrationSet,
        by_index: dict[int, FixResult],
        sources: SourceTexts | None,
    ) -> None:
        self.audit = audit
        self.sets = calibrations
        self.sources = sources
        self.old = [coefficients_of(audit.entries[i]) for i in calibrations.indices]
        self.results = {p: by_index[i] for p, i in enumerate(calibrations.indices) if i in by_index}

    def judged(self, margin: float, target: float | None, tolerance: float) -> dict[int, FixResult]:
        """The lens's results, with the sweep of its focal range before and after;
        refitted together where the one-at-a-time refits leave a fold between."""
        before = zooms.sweep(self.sets, self.old)
        current = [
            self.results[p].new if p in self.results and self.results[p].fixed else old
            for p, old in enumerate(self.old)
        ]
        after = zooms.sweep(self.sets, current)
        # Refitted together only where each entry refitted alone is fixed: one that
        # is not keeps its fold, at its own focal length and around it.
        if after[0] >= margin or not all(r.fixed for r in self.results.values()):
            return {
                r.index: replace(
                    r,
                    r_normalized_between_before=before[0],
                    r_normalized_between_after=after[0],
                    focal_between_after=after[1],
                )
                for r in self.results.values()
            }
        goal = goal_for(self.sets.aspect_ratio, margin, target, self.sets.image_radius)
        moving = {p for p, r in self.results.items() if r.new}
        joint = None
        for widened in (moving | zooms.neighbours(self.sets, after[1]), set(range(len(self.old)))):
            self._read_sources(widened)
            joint = zooms.refit_together(self.sets, self.old, self._texts(), widened, goal)
            if joint is not None:
                moving = widened
                break
        if joint is None:
            return self._unsolved(before, after, margin)
        return self._together(joint, moving, goal, tolerance, before, after)

    def _read_sources(self, positions: set[int]) -> None:
        """Read where the calibrations at ``positions`` are written, where not yet read."""
        extra = [self.sets.indices[p] for p in positions if p not in self.results]
        if self.sources is not None and extra:
            self.sources.merge(read_sources(self.audit, extra))

    def _texts(self) -> list[tuple[str, ...]]:
        """Each calibration's coefficients as written (as ``repr`` where not read)."""
        names = MODEL_COEFFICIENTS[self.sets.model]
        return [
            written_texts(
                names, old, self.sources.texts(index) if self.sources is not None else None
            )
            for index, old in zip(self.sets.indices, self.old, strict=True)
        ]

    def _unsolved(
        self, before: tuple[float, float], after: tuple[float, float], margin: float
    ) -> dict[int, FixResult]:
        """No coefficients keep the interpolation clear: nothing of the lens is written."""
        message = (
            f"refitted alone, liblensfun's interpolation of this lens would fold at "
            f"{after[1]:g} mm (r_normalized {after[0]:.3f} < {margin:g}), and no "
            f"coefficients of its calibrations refitted together avoid it"
        )
        return {
            r.index: replace(
                r,
                status=STATUS_NO_SOLUTION if r.fixed else r.status,
                message="; ".join(filter(None, [r.message, message])),
                r_normalized_between_before=before[0],
                r_normalized_between_after=math.nan,
            )
            for r in self.results.values()
        }

    def _together(
        self,
        joint: zooms.JointFit,
        moving: set[int],
        goal: Goal,
        tolerance: float,
        before: tuple[float, float],
        after: tuple[float, float],
    ) -> dict[int, FixResult]:
        """Results for the calibrations refitted together: all written, or none."""
        focals = ", ".join(f"{self.sets.focals[p]:g}" for p in sorted(moving))
        note = (
            f"refitted together with the calibrations at {focals} mm of this lens: refitted "
            f"alone, liblensfun's interpolation would fold at {after[1]:g} mm "
            f"(r_normalized {after[0]:.3f})"
        )
        found = {}
        texts = self._texts()
        for position in sorted(moving):
            if joint.texts[position] == texts[position]:
                continue  # left as it was
            found[position] = self._member(
                position, (joint, texts[position]), goal, tolerance, note, before
            )
        if any(not r.fixed for r in found.values()):
            blocked = ", ".join(r.where for r in found.values() if not r.fixed)
            for position, r in found.items():
                if r.fixed:
                    found[position] = replace(
                        r,
                        status=STATUS_BEYOND_TOLERANCE,
                        message=f"{r.message}; not written: {blocked} is not fixed, and the "
                        "calibrations refitted together are written together or not at all",
                    )
        return {r.index: r for r in found.values()}

    def _member(
        self,
        position: int,
        fitted: tuple[zooms.JointFit, tuple[str, ...]],
        goal: Goal,
        tolerance: float,
        note: str,
        before: tuple[float, float],
    ) -> FixResult:
        """The result of one calibration refitted with the others (the joint
        fit, and the calibration's coefficients as written)."""
        joint, old_texts = fitted
        index = self.sets.indices[position]
        entry = self.audit.entries[index]
        old, new = self.old[position], joint.coefficients[position]
        change = change_of_distortion(entry.model, old, new, entry.aspect_ratio, goal.r_corner)
        was, now = judge(entry.model, old, goal), judge(entry.model, new, goal)
        fixed = change.max_px <= tolerance
        message = note if fixed else f"{note}; it changes D by up to {change.max_px:.0f} px"
        result = FixResult(
            entry=entry,
            names=MODEL_COEFFICIENTS[entry.model],
            old=old,
            old_texts=old_texts,
            new=new,
            new_texts=joint.texts[position],
            goal=goal,
            r_max_before=was.r_max,
            r_max_after=now.r_max,
            r_normalized_before=was.r_normalized,
            r_normalized_after=now.r_normalized,
            max_change_px=change.max_px,
            rms_change_px=change.rms_px,
            status=STATUS_FIXED if fixed else STATUS_BEYOND_TOLERANCE,
            message=message,
            index=index,
            max_change_half_diagonal=change.max_half_diagonal,
            min_slope_after=now.min_slope,
            r_normalized_between_before=before[0],
            r_normalized_between_after=joint.r_normalized_between,
            focal_between_after=joint.focal_between,
        )
        return _located(result, self.sources)


def patches(results: Sequence[FixResult], sources: SourceTexts) -> list[FilePatch]:
    """The file changes that write the fixed entries: one patch per file.

    Only entries with status ``fixed`` are written; only their coefficient
    attributes change.
    """
    edits: dict[str, list] = {}
    for result in results:
        if not result.fixed:
            continue
        values = dict(zip(result.names, result.new_texts, strict=True))
        edits.setdefault(result.entry.file, []).append((sources.tags[result.index], values))
    found = []
    for name, file_edits in edits.items():
        path, data = sources.files[name]
        found.append(FilePatch(path, name, data, set_attributes(data, file_edits)))
    return found


def fix(
    paths: Sequence[str] | str | None = None,
    *,
    margin: float = DEFAULT_MARGIN,
    target: float | None = None,
    tolerance: float = DEFAULT_TOLERANCE_PX,
    lens: str | None = None,
    focal: float | None = None,
) -> tuple[list[FixResult], list[FilePatch]]:
    """Fix every entry of a database that folds inside its image.

    Returns the results and the file patches that would write them (see
    :func:`lensaudit.xmlpatch.write`); nothing is written here.
    """
    audit = run(paths)
    indices = select(audit, margin=margin, lens=lens, focal=focal)
    sources = read_sources(audit, indices)
    results = fix_audit(
        audit, indices, margin=margin, target=target, tolerance=tolerance, sources=sources
    )
    return results, patches(results, sources)


def to_dataframe(results: Sequence[FixResult]) -> pandas.DataFrame:
    """The results as a pandas DataFrame with :data:`RECORD_COLUMNS`."""
    import pandas  # pandas: only for a DataFrame, which no command needs

    return pandas.DataFrame([r.record() for r in results], columns=list(RECORD_COLUMNS))
