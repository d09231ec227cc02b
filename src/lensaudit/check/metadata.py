"""Metadata Lensfun's own CI does not check (its ``check_database.py`` runs
xmllint against the schema and looks for duplicate keys only): mounts that
no file defines, calibrations that contradict each other, and vignetting
left at the calibration script's starting values. All three are warnings.

- ``undefined-mount``: a ``<lens>`` or ``<camera>`` whose ``<mount>`` names a
  mount that no top-level ``<mount><name>`` of the database defines. Names
  are compared as liblensfun compares them (``_lf_strcmp`` in
  ``libs/lensfun/auxfun.cpp``, used by ``lfDatabase::FindMount`` and by the
  lens search): without letter case, leading and trailing white space, and
  with each run of white space as one space. A name that starts with a
  lower-case letter is a fixed-lens camera's own mount, which Lensfun never
  defines (``lfMount::Name`` in ``lensfun.h``), and is not reported; nor is
  anything when the files checked define no mount at all (a fragment).
- ``conflicting-calibration``: within one ``<lens>`` (liblensfun puts every
  calibration of a lens into one set, ``lfLens::GetCalibrationSetForAttributes``),
  a second ``<distortion>``, ``<tca>`` or ``<vignetting>`` for the same crop
  factor and focal length (and aperture and distance, for vignetting) whose
  model or coefficients differ from the first one's: liblensfun takes the
  first exact match and never sees the other. Two distortion entries of one
  calibration (same crop factor and aspect ratio) are ``duplicate-focal``'s
  (an error), and two ``<lens>`` elements of one name and crop factor are
  ``duplicate-lens``'s (an error when they differ at all): neither is
  reported again here.
- ``vignetting-starting-values``: a ``<vignetting>`` whose k1, k2 and k3 are
  exactly -0.3, 0 and 0, the values ``tools/calibrate/calibrate.py`` starts
  its fit from, left when the fit fails.

What each file defines and names comes from the reader's tables
(:attr:`lensaudit.read.FileTables.mount_names`, ``cameras`` and each lens's
``mounts`` and ``mount_lines``).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any

from ..read.records import STATUS_OK
from ..read.tables import SPECS, TCA, VIGNETTING
from .matching import calibration_content, entry_content, lens_identity
from .parsing import ParsedSource, crop_factor_key
from .result import (
    CONFLICTING_CALIBRATION,
    SEVERITY_WARNING,
    UNDEFINED_MOUNT,
    VIGNETTING_STARTING_VALUES,
    Finding,
    Identified,
    clip,
    clip_key,
    entry_finding,
    entry_key,
    lens_name,
    none_if_nan,
)

#: k1, k2, k3 that ``tools/calibrate/calibrate.py`` starts its vignetting fit from.
STARTING_VALUES = (-0.3, 0.0, 0.0)

DISTORTION = "distortion"


@dataclass(frozen=True)
class MountUse:
    """A ``<mount>`` of a ``<lens>`` or ``<camera>`` (``kind``): its owner's
    maker and model (the untranslated names) and crop factor as written
    (None without one), the mount's name and line."""

    kind: str
    maker: str
    model: str
    crop_text: str | None
    mount: str
    line: int


def mount_uses(file: ParsedSource) -> list[MountUse]:
    """The mounts a file's lenses and cameras name, as liblensfun reads them
    (``database.cpp``): a lens has every ``<mount>`` it names, a camera the
    last one; an empty name is skipped."""
    found = []
    tables = file.tables
    owners = [("lens", lens, lens.crop_text) for lens in tables.lenses]
    owners += [("camera", camera, camera.crop_text) for camera in tables.cameras]
    for kind, owner, crop_text in owners:
        named = [(m, owner.line + offset) for m, offset in zip(owner.mounts, owner.mount_lines,
                                                                 strict=True) if m]  # fmt: skip
        if kind == "camera":
            named = named[-1:]
        found += [MountUse(kind, owner.maker, owner.model, crop_text, m, line) for m, line in named]
    return found


def mount_key(name: str) -> str:
    """A mount name as liblensfun compares it (``_lf_strcmp``): lower case,
    without leading or trailing white space, each run of white space one space."""
    return " ".join(name.split()).lower()


def is_fixed_lens_mount(name: str) -> bool:
    """True for a fixed-lens camera's own mount: its name starts with a
    lower-case letter, and Lensfun defines no such mount."""
    first = name.strip()[:1]
    return first.islower()


def undefined_mounts(read: Sequence[ParsedSource]) -> Iterable[tuple[int, Identified]]:
    """A lens or camera whose mount no file of ``read`` defines.

    Definitions count in every file that parses, or that libxml2's recovery
    mode reads (so that one broken file does not turn every lens of its
    mounts into a finding); lenses and cameras only in files that parse.
    Files that define no mount at all are a fragment of a database (one
    file of it, a hand-made example), not a database: nothing is reported.
    """
    defined: dict[str, str] = {}
    for file in read:
        for _, name in file.tables.mount_names:
            defined.setdefault(mount_key(name), name)
    if not defined:
        return
    for index, file in enumerate(read):
        if file.problem is not None:
            continue
        for use in mount_uses(file):
            key = mount_key(use.mount)
            if key in defined or is_fixed_lens_mount(use.mount):
                continue
            yield index, _undefined_mount(file, use, key, defined)


def _undefined_mount(
    file: ParsedSource, use: MountUse, key: str, defined: dict[str, str]
) -> Identified:
    close = difflib.get_close_matches(key, list(defined), n=1, cutoff=0.8)
    # Double quotes: clip() shortens text between single quotes.
    hint = f' (did you mean "{defined[close[0]]}"?)' if close else ""
    if use.kind == "lens":
        what = f"lens {lens_name(use.maker, use.model)}"
        effect = "a camera finds this lens only through a mount of exactly that name"
        owner = (use.maker, use.model, crop_factor_key(use.crop_text))
    else:
        what = f"camera {lens_name(use.maker, use.model)}"
        effect = "liblensfun knows no mount compatible with it"
        owner = (use.maker, use.model)
    text = (
        f'{what}: its mount "{clip(use.mount, 40)}" is defined nowhere in the database '
        f"(no top-level <mount> has that <name>, ignoring case and spacing){hint}: {effect}"
    )
    finding = Finding(
        SEVERITY_WARNING,
        UNDEFINED_MOUNT,
        file.source.display,
        use.line,
        0,
        clip(text),
        clip_key(owner),
    )
    # The owner by name and the mount; then the mount alone, for a renamed owner.
    content = (SEVERITY_WARNING, UNDEFINED_MOUNT, use.kind, key)
    keys = ((*content, lens_identity(use.maker, use.model)), content)
    return Identified(finding, keys, (file.source.file_name,))


def conflicting_calibrations(file: ParsedSource) -> Iterable[Identified]:
    """Second calibrations of one lens, crop factor and calibration point whose
    model or coefficients differ from the first's, in a file that parsed
    (see the module's docstring for what ``duplicate-focal`` keeps)."""
    if file.problem is not None:
        return
    yield from _conflicting_distortion(file)
    tables = file.tables
    lens_of = {VIGNETTING: tables.lens_of_vignetting, TCA: tables.lens_of_tca}
    for kind, records in file.calibrations.items():
        # Keys from the columns; entry objects only for the repeats (a file has thousands).
        lenses = lens_of[kind] or []
        # Each lens's first calibration of each crop factor and point, kept until
        # its last row (a lens's rows come together: few are kept at once).
        last = {lens: position for position, lens in enumerate(lenses)}
        first: dict[int | None, dict[tuple, int]] = {}
        names = ("focal", "aperture", "distance") if kind == VIGNETTING else ("focal",)
        points = zip(*map(records.each, names), strict=True)
        statuses, crops = records.each("status"), records.each("crop_factor")
        for position, (lens, status, crop, point) in enumerate(
            zip(lenses, statuses, crops, points, strict=False)
        ):
            if lens is None or status != STATUS_OK:
                continue
            own = first.setdefault(lens, {})
            earlier_position = own.setdefault((crop, point), position)
            if last[lens] == position:
                del first[lens]
            if earlier_position == position:
                continue
            entry, earlier = records[position], records[earlier_position]
            if _coefficients(kind, entry) == _coefficients(kind, earlier):
                continue
            content, first_content = calibration_content(entry), calibration_content(earlier)
            yield _conflict(file, kind, entry, earlier.line, point, content, first_content)


#: The coefficients of each kind, by name (the rest of its fields are where it applies).
_COEFFICIENTS = {
    DISTORTION: ("a", "b", "c", "k1", "k2"),
    **{
        kind: tuple(f for f in spec.fields if f not in ("aperture", "distance"))
        for kind, spec in SPECS.items()
    },
}


def _coefficients(kind: str, entry: Any) -> tuple:
    """The model and coefficients of an entry (NaN, a coefficient its model
    does not have, as None)."""
    return (entry.model, *(none_if_nan(getattr(entry, n)) for n in _COEFFICIENTS[kind]))


def _conflicting_distortion(file: ParsedSource) -> Iterable[Identified]:
    seen_calibration: set[tuple] = set()  # what duplicate_focals groups by
    first: dict[tuple, Any] = {}
    for entry, lens in zip(file.entries, file.lens_of_entry, strict=True):
        if lens is None or entry.focal != entry.focal:
            continue
        crop = none_if_nan(entry.crop_factor)
        calibration = (lens, crop, none_if_nan(entry.aspect_ratio), entry.focal)
        if calibration in seen_calibration:
            continue  # a duplicate-focal
        seen_calibration.add(calibration)
        if entry.status != STATUS_OK:
            continue
        earlier = first.setdefault((lens, crop, entry.focal), entry)
        if earlier is entry:
            continue
        if _coefficients(DISTORTION, entry) == _coefficients(DISTORTION, earlier):
            continue
        content, first_content = entry_content(entry), entry_content(earlier)
        yield _conflict(
            file, DISTORTION, entry, earlier.line, (entry.focal,), content, first_content
        )


def _conflict(
    file: ParsedSource,
    kind: str,
    entry: Any,
    first_line: int,
    point: tuple,
    content: tuple,
    first_content: tuple,
) -> Identified:
    where = _point(point)
    text = (
        f"a second <{kind}> for {where} of this lens and crop factor, with another model "
        f"or other coefficients than the one at line {first_line}: liblensfun uses only "
        f"the first; keep the better one"
    )
    if kind == DISTORTION:
        finding = entry_finding(SEVERITY_WARNING, CONFLICTING_CALIBRATION, entry, text)
    else:
        name = (
            f"{lens_name(entry.maker, entry.lens)} (<{kind}>, {where}, crop {entry.crop_factor:g})"
        )
        finding = Finding(
            SEVERITY_WARNING,
            CONFLICTING_CALIBRATION,
            entry.file,
            entry.line,
            0,
            clip(f"{name}: {text}"),
            clip_key(entry_key(entry)),
        )
    finding = replace(finding, related=((file.source.display, first_line),))
    # The pair, in either order, of the lens by name; then the pair alone (the
    # lens was renamed); then the lens and the calibration point (one of the
    # pair was edited).
    pair = (SEVERITY_WARNING, CONFLICTING_CALIBRATION, kind,
            *sorted((content, first_content), key=repr))  # fmt: skip
    lens = lens_identity(entry.maker, entry.lens)
    keys = ((*pair, lens), pair, (SEVERITY_WARNING, CONFLICTING_CALIBRATION, kind, lens, point))
    return Identified(finding, keys, (file.source.file_name,))


def _calibration_name(entry: Any, kind: str, where: str) -> str:
    """A vignetting or TCA entry in words: its lens, element, point and crop factor."""
    return f"{lens_name(entry.maker, entry.lens)} (<{kind}>, {where}, crop {entry.crop_factor:g})"


def _point(point: tuple) -> str:
    """A calibration point in words: focal length, and aperture and distance."""
    text = f"{point[0]:g} mm"
    if len(point) == 3:
        text += f", f/{point[1]:g}, {point[2]:g} m"
    return text


def starting_values(file: ParsedSource) -> Iterable[Identified]:
    """Each ``<vignetting>`` of a file that parsed whose k1, k2, k3 are the
    calibration script's starting values, -0.3, 0 and 0, exactly."""
    if file.problem is not None or VIGNETTING not in file.calibrations:
        return
    records = file.calibrations[VIGNETTING]
    columns = zip(*map(records.each, ("status", "k1", "k2", "k3")), strict=True)
    for position, (status, *coefficients) in enumerate(columns):
        if status != STATUS_OK or tuple(coefficients) != STARTING_VALUES:
            continue
        entry = records[position]
        where = _point((entry.focal, entry.aperture, entry.distance))
        name = _calibration_name(entry, VIGNETTING, where)
        text = (
            "k1=-0.3, k2=0, k3=0 are the values Lensfun's calibration script "
            "(tools/calibrate/calibrate.py) starts its fit from, left when the fit fails: "
            "this entry measures nothing; calibrate it again or remove it"
        )
        finding = Finding(
            SEVERITY_WARNING,
            VIGNETTING_STARTING_VALUES,
            entry.file,
            entry.line,
            0,
            clip(f"{name}: {text}"),
            clip_key(entry_key(entry)),
        )
        content = (SEVERITY_WARNING, VIGNETTING_STARTING_VALUES, calibration_content(entry))
        keys = ((*content, lens_identity(entry.maker, entry.lens)), content)
        yield Identified(finding, keys, (file.source.file_name,))


__all__ = [
    "STARTING_VALUES",
    "conflicting_calibrations",
    "is_fixed_lens_mount",
    "mount_key",
    "mount_uses",
    "undefined_mounts",
    "starting_values",
]
