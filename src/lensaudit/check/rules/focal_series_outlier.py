"""Focal-series outliers: a ``<distortion>`` entry that breaks the smooth
course of its lens's calibration over focal length (``focal-series-outlier``,
a warning).

A series is the distortion entries of one ``<lens>`` with the same crop
factor, aspect ratio and model, that loaded (status ``ok``), one per focal
length (the first in the file, where a focal length repeats: the second is
``duplicate-focal``'s), ordered by focal length. Each entry is described by
what it does to the image: its displacement y(t) = D(t R) - t R at
t = 0.5, 0.75 and 1 of the image corner R = hypot(aspect, 1), in Hugin units
(1 = half the short side of the calibration image), where D is the model's
distorted radius. The displacement does not care how a fit traded one
coefficient against another, and a reordered file gives the same series.

An entry is judged against its neighbours, in log focal length:

- an inner entry against the straight line through the entries on either
  side, at its focal length;
- the last (longest focal length) against the range between its
  neighbour's value and the straight line through its two nearest
  neighbours, extended to it (a trend that flattens or goes on is not held
  against it);
- the first (shortest focal length) against its neighbour's value alone,
  with a factor of :data:`SHORT_END_FACTOR` instead of
  :data:`SPREAD_FACTOR`: a zoom's distortion turns fastest at its short end,
  often against the trend of the rest (barrel at the short end, a
  pincushion that peaks and flattens after it).

Its deviation is the largest distance, over the three radii, between its
displacement and that prediction; the series' spread without it is the
largest range, over the three radii, of the other entries' displacements.
The entry is an outlier when its deviation is at least the factor times
that spread and at least :data:`MIN_DEVIATION`. Measuring the spread
without the entry keeps an outlier from hiding itself, and keeps its
neighbours, whose own predictions it spoils, from being flagged: their
spread includes it. A series needs :data:`MIN_SERIES` entries: of three, any
one may be the one that does not lie on the line of the other two.

TCA and vignetting are not judged: vignetting varies over aperture and
distance as well, and a series of TCA entries is mostly within the noise of
its fit.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

from ...read.records import STATUS_OK, DistortionEntry
from ..matching import entry_content, lens_identity
from ..parsing import ParsedSource
from ..result import (
    Identified,
    entry_finding,
    none_if_nan,
)
from . import WARNING, Context, Rule

ORDER = 80

FOCAL_SERIES_OUTLIER = Rule(
    "focal-series-outlier",
    WARNING,
    "entry",
    "a distortion entry far from what its neighbours in focal length predict",
    "a `<distortion>` entry whose displacement D(r) - r lies far from what its neighbours in "
    "focal length predict (see [below](#focal-series-outliers))",
    "A calibration that breaks its lens's smooth course over focal length is often a "
    "mistyped coefficient or a calibration of another lens.",
    fails=(
        "slr-canon.xml:2126, Canon EF 35-80mm f/4-5.6 III at 80 mm (Lensfun issue 1024): 0.0569 "
        "off what 53 and 65 mm predict, 1.7 times the spread"
    ),
    passes="the same series at 53 mm (slr-canon.xml:2124): 0.0028 off, below the 0.01 minimum",
)
RULES = (FOCAL_SERIES_OUTLIER,)


if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import ArrayLike

#: Where the displacement is compared, as fractions of the image corner.
RADII = (0.5, 0.75, 1.0)
#: An outlier's deviation is at least this many times the spread of the rest of its series.
SPREAD_FACTOR = 1.5
#: The factor for the shortest focal length, judged against its neighbour's value alone.
SHORT_END_FACTOR = 10.0
#: An outlier's deviation is at least this, in Hugin units (10 pixels of a 2000-pixel short side).
MIN_DEVIATION = 0.01
#: The fewest entries a series needs to be judged.
MIN_SERIES = 4


def displacement(
    model: ArrayLike,
    a: ArrayLike,
    b: ArrayLike,
    c: ArrayLike,
    k1: ArrayLike,
    k2: ArrayLike,
    radius: ArrayLike,
) -> np.ndarray:
    """D(r) - r of ptlens, poly3 and poly5 entries (``model``) at undistorted
    radius ``r``, both in Hugin units; arrays broadcast together. A
    coefficient an entry lacks (NaN) counts as 0; another model gives NaN."""
    import numpy as np  # numpy: only where arrays are needed, not on importing this module

    a, b, c, k1, k2 = (
        np.nan_to_num(np.asarray(v, dtype=float), nan=0.0) for v in (a, b, c, k1, k2)
    )
    r = np.asarray(radius, dtype=float)
    model = np.asarray(model)
    r2 = r * r
    # a r^3 + b r^2 + c r + d - 1 with d = 1 - a - b - c, grouped so that
    # nothing nearly equal is subtracted near r = 1
    ptlens = r * (a * (r2 * r - 1) + b * (r2 - 1) + c * (r - 1))
    poly3 = r * k1 * (r2 - 1)
    poly5 = r * r2 * (k1 + k2 * r2)
    return np.where(
        model == "ptlens", ptlens,
        np.where(model == "poly3", poly3, np.where(model == "poly5", poly5, np.nan)),
    )  # fmt: skip


def series_outliers(read: Sequence[ParsedSource]) -> Iterable[tuple[int, Identified]]:
    """``focal-series-outlier`` findings of the files that parsed, with the
    index of each one's file (see the module's docstring)."""
    chosen = [
        (index, lens, entry)
        for index, file in enumerate(read)
        if file.problem is None
        for entry, lens in zip(file.entries, file.lens_of_entry, strict=True)
        if lens is not None and entry.status == STATUS_OK and entry.focal > 0
    ]
    if not chosen:
        return
    groups: dict[tuple, int] = {}
    # NaN as None: NaN never equals itself as a key
    group_of = [
        groups.setdefault((index, lens, none_if_nan(e.crop_factor),
                           none_if_nan(e.aspect_ratio), e.model), len(groups))
        for index, lens, e in chosen
    ]  # fmt: skip
    entries = [entry for _, _, entry in chosen]
    for position, deviation, spread, predictors in _outliers(entries, group_of):
        index, _, entry = chosen[position]
        neighbours = [entries[p] for p in predictors]
        yield index, _finding(read[index], entry, deviation, spread, neighbours)


def _outliers(
    entries: list[DistortionEntry], group_of: list[int]
) -> list[tuple[int, float, float, tuple[int, ...]]]:
    """(position in ``entries``, deviation, spread of the rest, positions of
    the entries that predict it) of each outlier; a series is the entries of
    one group (``group_of``), one per focal length."""
    import numpy as np

    columns = np.array([(e.focal, e.aspect_ratio, e.a, e.b, e.c, e.k1, e.k2) for e in entries])
    models = np.array([e.model for e in entries])
    group = np.asarray(group_of)
    # One entry per focal length of a series, the first in the file (the
    # second is a duplicate-focal); then by series and focal length.
    order = np.lexsort((np.arange(len(entries)), columns[:, 0], group))
    repeated = np.zeros(len(order), dtype=bool)
    repeated[1:] = (group[order][1:] == group[order][:-1]) & (
        columns[order, 0][1:] == columns[order, 0][:-1]
    )
    order = order[~repeated]
    columns, models, group = columns[order], models[order], group[order]
    focal = columns[:, 0]
    radii = np.hypot(columns[:, 1], 1.0)[:, None] * np.asarray(RADII)
    with np.errstate(all="ignore"):  # an overflowing coefficient is not judged
        profile = displacement(models[:, None], *columns[:, 2:].T[:, :, None], radii)
    count = len(order)
    size = np.bincount(group)[group]
    start = np.searchsorted(group, group, side="left")
    place = np.arange(count) - start
    finite = np.isfinite(profile).all(axis=1)
    judged = (size >= MIN_SERIES) & (np.bincount(group, weights=~finite)[group] == 0)
    first, last = place == 0, place == size - 1
    near = np.clip(np.where(first, np.arange(count) + 1, np.arange(count) - 1), 0, count - 1)
    far = np.clip(np.where(last, np.arange(count) - 2, np.arange(count) + 1), 0, count - 1)
    x = np.log(focal)
    with np.errstate(all="ignore"):
        line = (
            profile[near]
            + (profile[far] - profile[near]) * (((x - x[near]) / (x[far] - x[near]))[:, None])
        )
        inner = np.abs(profile - line)
        low = np.minimum(profile[near], line)
        high = np.maximum(profile[near], line)
        outside = np.maximum(np.maximum(low - profile, profile - high), 0.0)
        short_end = np.abs(profile - profile[near])
    deviation = np.where(first[:, None], short_end, np.where(last[:, None], outside, inner)).max(
        axis=1
    )
    # The spread of each series without each entry: the range of the others,
    # from the two largest and two smallest values of each series and radius.
    # A series with a value that is not finite is not judged (``judged``): what
    # its spread comes to does not matter, and is worked out without a word.
    spread = np.zeros(count)
    factor = np.where(first, SHORT_END_FACTOR, SPREAD_FACTOR)
    with np.errstate(all="ignore"):
        for k in range(len(RADII)):
            by_value = np.lexsort((profile[:, k], group))  # within each series, by value
            values = profile[by_value, k]
            rank = np.empty(count, dtype=int)
            rank[by_value] = np.arange(count)
            lowest, highest = start, start + size - 1  # positions in ``values``
            top = np.where(rank == highest, values[np.maximum(highest - 1, 0)], values[highest])
            bottom = np.where(
                rank == lowest, values[np.minimum(lowest + 1, count - 1)], values[lowest]
            )
            spread = np.maximum(spread, top - bottom)
        flagged = judged & (deviation >= MIN_DEVIATION) & (deviation >= factor * spread)
    found = []
    for p in np.flatnonzero(flagged).tolist():
        predictors = (near[p],) if first[p] else (near[p], far[p])
        found.append((
            int(order[p]), float(deviation[p]), float(spread[p]),
            tuple(int(order[q]) for q in predictors),
        ))  # fmt: skip
    return found


def _finding(
    file: ParsedSource,
    entry: DistortionEntry,
    deviation: float,
    spread: float,
    neighbours: list[DistortionEntry],
) -> Identified:
    focals = " and ".join(f"{f:g} mm" for f in sorted(e.focal for e in neighbours))
    what = f"its neighbour at {focals} predicts" if len(neighbours) == 1 else (
        f"its neighbours at {focals} predict")  # fmt: skip
    times = (
        f", {deviation / spread:.1f} times the spread of the rest of the series ({spread:.3g})"
        if spread > 0
        else ", where the rest of the series is all alike"
    )
    text = (
        f"breaks the course of its calibration over focal length: its displacement "
        f"D(r) - r lies {deviation:.3g} (Hugin units) from what {what}{times}; "
        f"check this entry against a new calibration"
    )
    rule = FOCAL_SERIES_OUTLIER
    finding = entry_finding(rule.severity, rule.code, entry, text)
    # The entry by its values and its lens's name; then its values alone (the
    # lens was renamed). Not its neighbours: an outlier stays known when they change.
    content = (rule.severity, rule.code, entry_content(entry))
    keys = ((*content, lens_identity(entry.maker, entry.lens)), content)
    return Identified(finding, keys, (file.source.file_name,))


__all__ = [
    "MIN_DEVIATION",
    "MIN_SERIES",
    "RADII",
    "SHORT_END_FACTOR",
    "SPREAD_FACTOR",
    "displacement",
    "series_outliers",
]


def find(context: Context) -> Iterable[tuple[int, Identified]]:
    """Each outlier of its lens's focal series."""
    return series_outliers(context.read)
