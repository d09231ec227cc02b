"""``vignetting-starting-values``: a ``<vignetting>`` left at the values
Lensfun's calibration script starts its fit from (see
:func:`lensaudit.check.metadata.starting_values`)."""

from __future__ import annotations

from collections.abc import Iterable

from ..metadata import starting_values
from ..result import Identified
from . import WARNING, Context, Rule

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


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each vignetting entry at the calibration script's starting values, file by file."""
    for index, file in enumerate(context.read):
        for item in starting_values(file):
            yield index, item
