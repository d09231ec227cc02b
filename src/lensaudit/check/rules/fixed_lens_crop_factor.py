"""``fixed-lens-crop-factor``: the lens of a fixed-lens camera whose crop
factor is not its camera's.

A fixed lens is calibrated on the one sensor it is built onto, so its
``<cropfactor>`` is its camera's. liblensfun scales a model from the crop
factor it was calibrated at to the crop factor of the image's camera, so a
wrong one rescales the correction of every image that camera takes by the
ratio of the two. A lens whose every ``<mount>`` is a fixed-lens mount (a
name starting with a lower-case letter, see :func:`.undefined_mount.is_fixed_lens_mount`)
is compared with the ``<camera>`` elements of the database on those mounts;
it is reported when its crop factor is more than :data:`TOLERANCE` away
from every one of theirs.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from ..matching import lens_identity
from ..result import Finding, Identified, clip, clip_key, lens_name
from . import WARNING, Context, Rule
from .undefined_mount import is_fixed_lens_mount, mount_key, mount_uses

ORDER = 125
ACROSS_FILES = True

#: Crop factors this close (a ratio) are the same sensor written with other rounding.
TOLERANCE = 1.05

FIXED_LENS_CROP_FACTOR = Rule(
    "fixed-lens-crop-factor",
    WARNING,
    "lens",
    "a fixed lens whose crop factor is not its camera's",
    "the lens of a fixed-lens camera (every `<mount>` of it a fixed-lens mount) whose "
    "`<cropfactor>` is more than 5% from that of every `<camera>` on its mount: liblensfun "
    "rescales its models by the ratio for that camera's images",
    "A fixed lens is calibrated on its own camera's sensor. A crop factor that is not the "
    "camera's makes liblensfun scale the correction of each of its images by the ratio of "
    "the two, so that distortion, TCA and vignetting are corrected at the wrong radius.",
    fails=(
        "compact-canon.xml:1203 of lensfunpy 1.18.0's database, Canon DIGITAL IXUS i "
        "(Standard): crop 4.843 while the IXUS i and PowerShot SD10 on its mount have 6.144 "
        "(a ratio of 1.27), in every revision since 2013"
    ),
    passes=(
        "the 266 other fixed lenses of the same database with a camera on their mount, such "
        "as compact-canon.xml:2474, the PowerShot G1X Mark II's, crop 1.93 like its camera"
    ),
)
RULES = (FIXED_LENS_CROP_FACTOR,)


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each fixed lens whose crop factor no camera of its mount has."""
    cameras: dict[str, list[tuple[float, str]]] = {}
    for file in context.read:
        for use in mount_uses(file):  # a camera's mount is its last, as liblensfun reads it
            crop = _number(use.crop_text)
            if use.kind == "camera" and crop > 0:
                cameras.setdefault(mount_key(use.mount), []).append((crop, use.model))
    if not cameras:
        return
    for index, file in enumerate(context.read):
        if file.problem is not None:
            continue
        for lens in file.tables.lenses:
            crop = lens.crop_factor
            if not lens.mounts or not all(is_fixed_lens_mount(m) for m in lens.mounts):
                continue
            theirs = [c for m in lens.mounts for c in cameras.get(mount_key(m), ())]
            if not crop > 0 or not theirs:
                continue
            if all(abs(math.log(crop / other)) > math.log(TOLERANCE) for other, _ in theirs):
                yield index, _finding(file, lens, theirs)


def _number(text: str | None) -> float:
    try:
        return float(text) if text is not None else math.nan
    except ValueError:
        return math.nan


def _finding(file, lens, theirs: list[tuple[float, str]]) -> Identified:
    rule = FIXED_LENS_CROP_FACTOR
    closest, camera = min(theirs, key=lambda pair: abs(math.log(lens.crop_factor / pair[0])))
    text = (
        f"lens {lens_name(lens.maker, lens.model)} (crop {lens.crop_factor:g}) is a fixed "
        f"lens, but its camera {clip(camera, 40)} has crop factor {closest:g}: liblensfun "
        f"scales its models by {closest / lens.crop_factor:.3g} for that camera's images; "
        "write the camera's crop factor"
    )
    finding = Finding(
        rule.severity,
        rule.code,
        file.source.display,
        lens.line,
        0,
        clip(text),
        clip_key((lens.maker, lens.model, lens.crop_factor)),
    )
    content = (rule.severity, rule.code, lens.crop_factor, closest)
    keys = ((*content, lens_identity(lens.maker, lens.model)), content)
    return Identified(finding, keys, (file.source.file_name,))
