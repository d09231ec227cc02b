"""``vignetting-starting-values``: a ``<vignetting>`` whose k1, k2 and k3 are
exactly -0.3, 0 and 0, the values ``tools/calibrate/calibrate.py`` starts its
fit from, left when the fit fails."""

from __future__ import annotations

from collections.abc import Iterable

from ...read.records import STATUS_OK
from ...read.tables import VIGNETTING
from ..matching import calibration_content, lens_identity
from ..parsing import ParsedSource
from ..result import Finding, Identified, clip, clip_key, entry_key
from . import WARNING, Context, Rule
from .conflicting_calibration import calibration_name, point_text

ORDER = 100

VIGNETTING_STARTING_VALUES = Rule(
    "vignetting-starting-values",
    WARNING,
    "entry",
    "k1=-0.3, k2=0, k3=0: the calibration script's start",
    "a `<vignetting>` with exactly k1=-0.3, k2=0, k3=0, the values Lensfun's calibration "
    "script starts its fit from, left when the fit fails",
    "Such an entry measures nothing: calibrate again, or remove it.",
    fails="slr-nikon.xml:1734, AF Zoom-Nikkor 28-85mm at 28 mm f/5: k1=-0.3, k2=0, k3=0",
    passes="the same lens at 28 mm f/5.6 (slr-nikon.xml:1736): k1=-0.3114649, a real fit",
)
RULES = (VIGNETTING_STARTING_VALUES,)

#: k1, k2, k3 that ``tools/calibrate/calibrate.py`` starts its vignetting fit from.
STARTING_VALUES = (-0.3, 0.0, 0.0)


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
        where = point_text((entry.focal, entry.aperture, entry.distance))
        name = calibration_name(entry, VIGNETTING, where)
        text = (
            "k1=-0.3, k2=0, k3=0 are the values Lensfun's calibration script "
            "(tools/calibrate/calibrate.py) starts its fit from, left when the fit fails: "
            "this entry measures nothing; calibrate it again or remove it"
        )
        finding = Finding(
            VIGNETTING_STARTING_VALUES.severity,
            VIGNETTING_STARTING_VALUES.code,
            entry.file,
            entry.line,
            0,
            clip(f"{name}: {text}"),
            clip_key(entry_key(entry)),
        )
        rule = VIGNETTING_STARTING_VALUES
        content = (rule.severity, rule.code, calibration_content(entry))
        keys = ((*content, lens_identity(entry.maker, entry.lens)), content)
        yield Identified(finding, keys, (file.source.file_name,))


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each vignetting entry at the calibration script's starting values, file by file."""
    for index, file in enumerate(context.read):
        for item in starting_values(file):
            yield index, item
