"""lensaudit.inversion against liblensfun's own reverse transform (Lensfun master).

A pixel liblensfun cannot invert is NaN (poly3) or left uncorrected (ptlens,
poly5). Left uncorrected is told from a converged point that happens not to
move by two things: the output equals, bit for bit, that of a lens without
distortion (ptlens 0, 0, 0 at the same real focal length, so the same
normalization), and the true inverse, found by bisection on the entry's
model in float64, lies more than half a pixel away. Where the true
correction is under half a pixel the two cannot be told apart, and such a
pixel is not counted as failing.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from lensaudit import inversion, pipeline
from lensaudit.metrics import image_radius, is_circular_fisheye
from lensaudit.read.records import DistortionEntry
from liblensfun_master import lenses
from liblensfun_modifier import (
    centre,
    loaded,
    reverse_distortion,
    reverse_row,
    single_lens_database,
)

FRAMES = ((6000, 4000), (4000, 3000))


def _kernel(entries: list[DistortionEntry]) -> inversion.Inversion:
    column = {n: [getattr(e, n) for e in entries] for n in inversion.MODEL_FIELDS}
    model = inversion.liblensfun_model(*column.values())
    circular = [is_circular_fisheye(e.lens, e.type) for e in entries]
    return inversion.inversion_failures(model, image_radius(column["aspect_ratio"], circular))


def _true_shift_px(entry: DistortionEntry, radius_px: np.ndarray, frame) -> np.ndarray:
    """|r_u - r_d| in pixels for distorted pixel radii, by bisection on the
    entry's own model in Hugin units (inf where D never reaches r_d)."""
    width, height = frame
    half = math.hypot(width, height) / 2
    corner = math.hypot(entry.aspect_ratio, 1)
    coefficients = [0.0 if v != v else v for v in (entry.a, entry.b, entry.c, entry.k1, entry.k2)]
    a, b, c, k1, k2 = coefficients
    if entry.model == "ptlens":
        d = 1 - a - b - c

        def D(r):
            return r * (a * r**3 + b * r**2 + c * r + d)
    elif entry.model == "poly3":
        d = 1 - k1

        def D(r):
            return r * (1 - k1 + k1 * r**2)
    else:
        d = 1.0

        def D(r):
            return r * (1 + k1 * r**2 + k2 * r**4)

    target = radius_px / half * corner
    grid = np.linspace(0, 6 * corner, 60001)
    # The running maximum of D on the grid, as far out as the largest target needs.
    peaks, top = [], -math.inf
    for start in range(0, grid.size, 2048):
        peaks.append(np.maximum(np.maximum.accumulate(D(grid[start : start + 2048])), top))
        top = float(peaks[-1][-1])
        if top >= target.max(initial=-math.inf):
            break
    # The first grid point where D reaches the target, then bisection below it.
    first = np.searchsorted(np.concatenate(peaks), target, side="left")
    found = first < grid.size
    upper = grid[np.minimum(first, grid.size - 1)]
    lower = np.maximum(upper - grid[1], 0)
    for _ in range(60):
        middle = (lower + upper) / 2
        below = D(middle) < target
        lower, upper = np.where(below, middle, lower), np.where(below, upper, middle)
    r_u_px = upper * d * half / corner
    return np.where(found, np.abs(r_u_px - radius_px), np.inf)


def _tolerance_px(entry: DistortionEntry, real_focal: float, frame) -> float:
    """liblensfun's convergence tolerance in pixels: 1e-5 in its focal units
    (times |k1'| for poly3, whose residual is divided by it), by the scales of
    libs/lensfun/modifier.cpp and mod-coord.cpp."""
    norm_scale = math.hypot(36, 24) / entry.crop_factor / math.hypot(*frame) / real_focal
    h = math.hypot(36, 24) / entry.crop_factor / math.hypot(entry.aspect_ratio, 1) / 2
    s = real_focal / h
    weight = abs(entry.k1) * s**2 / (1 - entry.k1) ** 3 if entry.model == "poly3" else 1.0
    return 1e-5 * max(1.0, weight) / norm_scale


def _failing_pixels(entry, real_focal, frame, radius_px, output, reference) -> np.ndarray:
    """Which outputs are liblensfun's failure: NaN, or unmoved where the true
    correction is over half a pixel and over three times liblensfun's
    tolerance (see the module's docstring)."""
    unmoved = np.all(output == reference, axis=1)
    threshold = max(0.5, 3 * _tolerance_px(entry, real_focal, frame))
    # The true correction, radius by radius, matters only where the pixel is unmoved.
    far = np.zeros_like(unmoved)
    far[unmoved] = _true_shift_px(entry, radius_px[unmoved], frame) > threshold
    return np.isnan(output).any(axis=1) | far


def _liblensfun_row(entries, frame):
    """Per entry: pixel radii 0..half diagonal along the centre row and
    liblensfun's failing mask there (None where it enables no distortion)."""
    width, height = frame
    x0, y0 = centre(width, height)
    count = int(math.hypot(width, height) / 2) + 2
    radius_px = np.arange(count, dtype=np.float64)
    identity = [
        e._replace(model="ptlens", a=0.0, b=0.0, c=0.0, real_focal=float(rf)) for e, rf in entries
    ]
    plain = [e for e, _ in entries]
    rows = []
    with loaded(single_lens_database(plain + identity)) as held:
        for index, entry in enumerate(plain):
            lens = held[f"entry {index}"]
            flat = held[f"entry {index + len(plain)}"]
            output = reverse_row(lens, entry.focal, entry.crop_factor, width, height, x0, y0, count)
            if output is None:
                rows.append(None)
                continue
            reference = reverse_row(
                flat, entry.focal, entry.crop_factor, width, height, x0, y0, count
            )
            mask = _failing_pixels(entry, entries[index][1], frame, radius_px, output, reference)
            # A circular fisheye's image is its image circle (r = 1, the short side's half).
            if is_circular_fisheye(entry.lens, entry.type):
                inside = radius_px <= math.hypot(*frame) / 2 / math.hypot(entry.aspect_ratio, 1)
                mask &= inside
            rows.append(mask)
    return radius_px, rows


def _with_real_focal(entries):
    """Entries with liblensfun's real focal length (as it stores it), read back from liblensfun."""
    data = single_lens_database(entries)
    held = {lens["model"]: lens for lens in lenses(data)}
    return [(e, held[f"entry {i}"]["distortion"][0]["real_focal"]) for i, e in enumerate(entries)]


def _audited(path) -> list[DistortionEntry]:
    audit = pipeline.run(path)
    return [e for e, ok in zip(audit.entries, audit.audited.tolist(), strict=True) if ok]


@pytest.fixture(scope="module", params=["bundled", "master"])
def database(request, bundled_db):
    # Lensfun master: the last commit of the history bundle (skips without it).
    path = bundled_db if request.param == "bundled" else request.getfixturevalue("lensfun_head")
    entries = _audited(path)
    return entries, _kernel(entries)


def test_every_failure_named_is_a_failure_of_liblensfun_at_that_radius(database):
    entries, found = database
    failing = np.flatnonzero(found.fails).tolist()
    assert failing, "the databases hold entries whose inversion fails"
    chosen = _with_real_focal([entries[i] for i in failing])
    for frame in FRAMES:
        radius_px, rows = _liblensfun_row(chosen, frame)
        half = math.hypot(*frame) / 2
        for index, mask in zip(failing, rows, strict=True):
            named = found.fraction[index] * half
            first = radius_px[mask][0] if mask.any() else math.inf
            assert abs(first - named) <= 2, (entries[index], first, named)


@pytest.mark.exhaustive
def test_no_entry_said_to_invert_fails_in_liblensfun(database):
    entries, found = database
    fine = [e for e, fails in zip(entries, found.fails.tolist(), strict=True) if not fails]
    chosen = _with_real_focal(fine)
    for frame in FRAMES:
        _, rows = _liblensfun_row(chosen, frame)
        bad = [chosen[i][0] for i, mask in enumerate(rows) if mask is not None and mask.any()]
        assert bad == []


def test_no_failure_on_the_diagonal_of_a_sample_of_entries_said_to_invert(bundled_db):
    entries = _audited(bundled_db)
    found = _kernel(entries)
    fine = [e for e, fails in zip(entries, found.fails.tolist(), strict=True) if not fails]
    # The entries with the strongest distortion, where the loop works hardest.
    strength = [
        abs(e.a if e.a == e.a else 0)
        + abs(e.c if e.c == e.c else 0)
        + abs(e.k1 if e.k1 == e.k1 else 0)
        for e in fine
    ]
    sample = [fine[i] for i in np.argsort(strength)[-25:]]
    chosen = _with_real_focal(sample)
    width, height = 6000, 4000
    x0, y0 = centre(width, height)
    steps = np.arange(int(math.hypot(width, height) / 2) + 1, dtype=np.float64)
    direction = np.array([width - 1, height - 1]) / math.hypot(width - 1, height - 1)
    points = np.array([x0, y0]) + steps[:, None] * direction
    identity = [
        e._replace(model="ptlens", a=0.0, b=0.0, c=0.0, real_focal=float(rf)) for e, rf in chosen
    ]
    with loaded(single_lens_database(sample + identity)) as held:
        for index, entry in enumerate(sample):
            output = reverse_distortion(
                held[f"entry {index}"], entry.focal, entry.crop_factor, width, height, points
            )
            flat = reverse_distortion(
                held[f"entry {index + len(sample)}"],
                entry.focal,
                entry.crop_factor,
                width,
                height,
                points,
            )
            if output is None:
                continue
            mask = _failing_pixels(entry, chosen[index][1], (width, height), steps, output, flat)
            if is_circular_fisheye(entry.lens, entry.type):
                mask &= steps <= math.hypot(width, height) / 2 / math.hypot(entry.aspect_ratio, 1)
            assert not mask.any(), (entry, steps[mask][:5])


def _synthetic(model: str, values: tuple[float, ...], focal: float) -> DistortionEntry:
    names = {"ptlens": ("a", "b", "c"), "poly3": ("k1",), "poly5": ("k1", "k2")}[model]
    return DistortionEntry(
        "synthetic.xml", 1, "test", "synthetic", ("M",), "rectilinear", 1.0, 1.5, model,
        focal, math.nan, **dict(zip(names, values, strict=True)),
    )  # fmt: skip


@st.composite
def models(draw):
    """ptlens, poly3 and poly5 models, many of them nearly flat somewhere inside the image."""
    model = draw(st.sampled_from(["ptlens", "poly3", "poly5"]))
    focal = draw(st.sampled_from([4.0, 10.5, 18.0, 50.0]))
    coefficient = st.floats(-0.5, 0.5, allow_nan=False, width=32)
    if model == "ptlens":
        values = (draw(coefficient) / 4, draw(coefficient) / 2, draw(coefficient))
    elif model == "poly3":
        values = (draw(st.floats(-0.25, 0.25, width=32)),)
    else:
        values = (draw(coefficient) / 2, draw(coefficient) / 8)
    return _synthetic(model, values, focal)


def _residual_is_rounding(entry: DistortionEntry) -> bool:
    """Whether liblensfun's poly3 residual, which mod-coord.cpp divides by k1,
    rounds by more than its tolerance (NEWTON_EPS) inside the image: for a
    k1 so small, the terms of the residual near the corner reach beyond
    NEWTON_EPS / 2^-53, so whether a radius converges depends on the last
    bits of that radius, pixel by pixel, and only whether some radius fails
    can be compared, not which one fails first."""
    if entry.model != "poly3":
        return False
    column = {n: [getattr(entry, n)] for n in inversion.MODEL_FIELDS}
    model = inversion.liblensfun_model(*column.values())
    k1 = abs(float(model.terms[0, 0]))
    corner = float(image_radius([entry.aspect_ratio], [False])[0] / model.scale[0])
    return k1 > 0 and corner / k1 * 2.0**-53 > inversion.NEWTON_EPS / 8


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(models())
@example(_synthetic("poly3", (2.220446049250313e-16,), 4.0))
# liblensfun fails at 2841 px, passes at 2842 and fails from 2843 on (named: 2843.2 px)
@example(_synthetic("ptlens", (0.0, -0.25, 0.46022897958755493), 4.0))
def test_synthetic_models_fail_where_liblensfun_fails(entry):
    found = _kernel([entry])
    chosen = _with_real_focal([entry])
    frame = FRAMES[0]
    radius_px, [mask] = _liblensfun_row(chosen, frame)
    if mask is None:
        assert not found.fails[0]
        return
    if _residual_is_rounding(entry):
        assert found.fails[0] == mask.any()
        return
    if found.fails[0]:
        named = found.fraction[0] * math.hypot(*frame) / 2
        assert mask.any()
        first, settled = _onset(radius_px, mask)
        assert first - 2 <= named <= settled + 2, (first, settled, named)
    else:
        assert not mask.any(), radius_px[mask][:5]


def _onset(radius_px: np.ndarray, mask: np.ndarray, run: int = 8) -> tuple[float, float]:
    """Where liblensfun's failures start along a row: the first pixel that fails,
    and the first from which the next ``run`` all fail. Between the two,
    pixels may fail and pass in turn: liblensfun hands its iteration
    single-precision coordinates, whose rounding decides, where the
    iteration is about to stop converging, whether a pixel converges."""
    failing = np.flatnonzero(mask)
    settled = next(
        (i for i in failing if mask[i : i + run].all() or i + run > len(mask)), failing[-1]
    )
    return float(radius_px[failing[0]]), float(radius_px[settled])


def test_one_entry_given_as_scalars_is_judged_as_a_column_of_one():
    nan = float("nan")
    columns = ("ptlens", 0.2, -0.6, 0.9, 0.0, 0.0, 24.0, nan, 1.5, 1.5)
    scalars = inversion.liblensfun_model(*columns)
    column = inversion.liblensfun_model(*([value] for value in columns))
    for radius in (0.5, 1.8):
        one = inversion.inversion_failures(scalars, [radius])
        assert list(one.fails) == list(inversion.inversion_failures(column, [radius]).fails)
