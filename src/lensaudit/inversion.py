"""Where liblensfun cannot invert a distortion model inside the image.

liblensfun inverts a model, r_u from D(r_u) = r_d, only in its reverse
transform (``lf_modifier_create(..., reverse=true)``: an undistorted image
made to look as if shot with the lens). For every output pixel it runs
Newton's method from r_u = r_d (libs/lensfun/mod-coord.cpp,
``ModifyCoord_UnDist_Poly3``, ``_Poly5``, ``_PTLens``): at most six steps,
in double precision on single-precision coefficients, until the residual is
within 1e-5 of zero (for poly3, the residual of D divided by its rescaled
k1). Where it does not get there, or ends at a negative radius, poly3 sets
the pixel to NaN and ptlens and poly5 leave it uncorrected. This happens
inside the image for some models that never fold.

The iteration runs in liblensfun's own units, the pinhole units of the real
focal length, after the rescaling of libs/lensfun/mod-coord.cpp
(``rescale_polynomial_coefficients``): r_focal = r_hugin / s with
s = real_focal / h and h half the short side of the calibration sensor in
millimetres. The image is the calibration's (its crop factor and aspect
ratio), so the corner is ``r_corner`` / s. This module repeats that
arithmetic, float32 where liblensfun stores floats, and the Newton loop in
float64 in liblensfun's order of operations.

Radii are sampled: :data:`SAMPLES` distorted radii evenly spaced up to the
corner, at least one per pixel of radius of a 6000 x 4000 frame (half
diagonal 3606 pixels). A band of :data:`BAND` consecutive samples is skipped
when a bound proves that Newton's method converges everywhere in it (see
:func:`_proven_bands`); only the other bands are iterated. Between samples
of an unproven band nothing is claimed. ptlens on an SSE build with aligned
buffers takes another path (libs/lensfun/mod-coord-sse.cpp: four unchecked
steps in single precision with approximate reciprocals), which this module
does not follow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

#: liblensfun's NEWTON_EPS (libs/lensfun/lensfunprv.h): a residual within it has converged.
NEWTON_EPS = 1e-5
#: Newton steps liblensfun takes before it gives up (it evaluates the residual once more).
NEWTON_STEPS = 6
#: The frame whose pixel radii the samples cover: 6000 x 4000 pixels.
FRAME_PIXELS = (6000, 4000)
#: Distorted radii sampled from the centre to the corner (> 3606, the frame's half diagonal).
SAMPLES = 4096
#: Consecutive samples judged together by :func:`_proven_bands`.
BAND = 64
#: Rows whose bands are sampled in one batch of arrays (a few MB of them).
_ROWS_AT_ONCE = 256
#: Samples iterated in one batch of arrays.
_SAMPLES_AT_ONCE = 8192
#: Rows whose whole range is judged in one batch of arrays (about 2 KB a row).
_RANGES_AT_ONCE = 4096

#: What liblensfun does at a radius where the inversion fails.
OUTCOME_NONE = 0
OUTCOME_NAN = 1
OUTCOME_UNCORRECTED = 2
OUTCOME_NAMES = {OUTCOME_NONE: "", OUTCOME_NAN: "NaN", OUTCOME_UNCORRECTED: "uncorrected"}

_HALF_DIAGONAL_MM = float(np.hypot(36.0, 24.0))
_MODELS = ("ptlens", "poly3", "poly5")
#: The entry fields :func:`liblensfun_model` takes, in order.
MODEL_FIELDS = (
    "model", "a", "b", "c", "k1", "k2", "focal", "real_focal", "crop_factor", "aspect_ratio",
)  # fmt: skip


@dataclass(frozen=True)
class Inversion:
    """Per entry: ``fails``, whether liblensfun's inversion fails at a sampled
    radius inside the image; ``r_fail``, the smallest such distorted radius in
    Hugin units (NaN where none); ``fraction``, r_fail / r_corner (the
    fraction of the half diagonal); ``outcome``, :data:`OUTCOME_NAN` or
    :data:`OUTCOME_UNCORRECTED` there (:data:`OUTCOME_NONE` where none)."""

    fails: NDArray[np.bool_]
    r_fail: FloatArray
    fraction: FloatArray
    outcome: NDArray[np.int8]


@dataclass(frozen=True)
class LiblensfunModel:
    """Entries as liblensfun's reverse transform holds them, in focal units.

    ``terms`` (n, 3), float32 values as float64: ptlens (a', b', c'), poly3
    (k1', 0, 0), poly5 (k1', k2', 0). ``scale`` is s (Hugin radius = focal
    radius * s). ``kind`` is 0 ptlens, 1 poly3, 2 poly5, -1 not inverted
    (another model, a poly3 whose k1' is 0, or values that are not finite).
    """

    terms: FloatArray
    scale: FloatArray
    kind: NDArray[np.int8]


def _f32(x: ArrayLike) -> FloatArray:
    """x rounded to float32, held as float64 (as liblensfun stores a float)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return np.asarray(x, dtype=np.float64).astype(np.float32).astype(np.float64)


def liblensfun_model(
    model: ArrayLike,
    a: ArrayLike,
    b: ArrayLike,
    c: ArrayLike,
    k1: ArrayLike,
    k2: ArrayLike,
    focal: ArrayLike,
    real_focal: ArrayLike,
    crop_factor: ArrayLike,
    aspect_ratio: ArrayLike,
) -> LiblensfunModel:
    """The coefficients liblensfun's reverse transform iterates on, for an
    image with the calibration's crop factor and focal length.

    Coefficients a, b, c, k1, k2 in Hugin units (NaN: 0); ``real_focal`` NaN
    where the entry gives none, in which case liblensfun takes focal * d
    (ptlens, poly3) or focal (libs/lensfun/database.cpp).
    """
    model = np.atleast_1d(np.asarray(model, dtype=object))  # one entry may be given as scalars
    kind = np.full(model.shape, -1, dtype=np.int8)
    for index, name in enumerate(_MODELS):
        kind[model == name] = index
    a, b, c, k1, k2 = (
        _f32(np.nan_to_num(np.asarray(x, np.float64), nan=0.0)) for x in (a, b, c, k1, k2)
    )
    focal, crop, aspect = _f32(focal), _f32(crop_factor), _f32(aspect_ratio)
    real_focal = np.asarray(real_focal, dtype=np.float64)
    a, b, c, k1, k2, focal, crop, aspect, real_focal = (
        np.broadcast_to(x, kind.shape) for x in (a, b, c, k1, k2, focal, crop, aspect, real_focal)
    )
    with np.errstate(all="ignore"):
        # float arithmetic, as liblensfun's: 1 - T0 - T1 - T2 in single precision.
        d_ptlens = _f32(_f32(_f32(1.0 - a) - b) - c)
        d_poly3 = _f32(1.0 - k1)
        first = np.where(kind == 1, k1, a)
        d = np.where(kind == 0, d_ptlens, np.where(kind == 1, d_poly3, 1.0))
        guessed = np.where(kind == 2, focal, _f32(focal * d))
        real = np.where(real_focal > 0, _f32(real_focal), guessed)
        h = _f32(_HALF_DIAGONAL_MM / crop / np.hypot(aspect, 1.0) / 2.0)
        s = _f32(real / h)
        terms = np.zeros((*kind.shape, 3))
        terms[..., 0] = np.where(
            kind == 0,
            _f32(a * (np.power(s, 3.0) / np.power(d, 4.0))),
            np.where(
                kind == 1,
                _f32(first * (np.power(s, 2.0) / np.power(d, 3.0))),
                _f32(k1 * np.power(s, 2.0)),
            ),
        )
        terms[..., 1] = np.where(
            kind == 0,
            _f32(b * (np.power(s, 2.0) / np.power(d, 3.0))),
            np.where(kind == 2, _f32(k2 * np.power(s, 4.0)), 0.0),
        )
        terms[..., 2] = np.where(kind == 0, _f32(c * (s / np.power(d, 2.0))), 0.0)
    finite = np.isfinite(terms).all(axis=-1) & np.isfinite(s) & (s > 0)
    kind[~finite | ((kind == 1) & (terms[..., 0] == 0))] = -1
    terms[kind < 0] = 0.0
    return LiblensfunModel(terms, np.where(kind >= 0, s, np.nan), kind)


def newton_outcome(model: LiblensfunModel, rows: ArrayLike, rd: ArrayLike) -> NDArray[np.int8]:
    """What liblensfun's reverse transform does at distorted radii ``rd``
    (focal units, > 0) of entries ``rows`` of ``model``: :data:`OUTCOME_NONE`
    where Newton's method converges to a radius >= 0, else NaN or uncorrected.

    The loop of libs/lensfun/mod-coord.cpp, operation for operation in
    float64 on the float32 terms; ``rd`` is taken as liblensfun's float
    radius (rounded to float32).
    """
    rows = np.asarray(rows, dtype=np.intp)
    rd = _f32(rd)
    kind = model.kind[rows]
    t0, t1, t2 = (model.terms[rows, i] for i in range(3))
    outcome = np.zeros(rd.shape, dtype=np.int8)
    with np.errstate(all="ignore"):
        # poly3 iterates on D / k1': ru^3 + ru q - rd q with q = 1/k1' and rd q in float.
        q = _f32(1.0 / np.where(kind == 1, t0, 1.0))
        target = np.where(kind == 1, _f32(rd * q), rd)
        # The derivative's factors are float products in liblensfun (int * float).
        a4, b3, c2 = _f32(4 * t0), _f32(3 * t1), _f32(2 * t2)
        k3, k5 = _f32(3 * t0), _f32(5 * t1)
        ptlens, poly3 = kind == 0, kind == 1
        ru = rd.copy()
        active = np.ones(rd.shape, dtype=bool)
        converged = np.zeros(rd.shape, dtype=bool)
        for step in range(NEWTON_STEPS + 1):
            index = np.flatnonzero(active)
            if index.size == 0:
                break
            r = ru[index]
            residual, slope = _residual_and_slope(
                r, target[index], ptlens[index], poly3[index],
                t0[index], t1[index], t2[index], q[index],
                a4[index], b3[index], c2[index], k3[index], k5[index],
            )  # fmt: skip
            done = (residual >= -NEWTON_EPS) & (residual < NEWTON_EPS)
            converged[index[done]] = True
            active[index[done]] = False
            if step == NEWTON_STEPS:
                break
            moving = ~done
            ru[index[moving]] = r[moving] - residual[moving] / slope[moving]
        failed = ~converged | (ru < 0.0)
    outcome[failed] = np.where(kind[failed] == 1, OUTCOME_NAN, OUTCOME_UNCORRECTED)
    return outcome


def _residual_and_slope(r, target, ptlens, poly3, t0, t1, t2, q, a4, b3, c2, k3, k5):
    """liblensfun's residual and its derivative at r, each model in its own
    order (each sample computed by its own model's formula only)."""
    residual, slope = np.empty_like(r), np.empty_like(r)
    poly5 = ~(ptlens | poly3)
    # ptlens: ru * (a ru ru ru + b ru ru + c ru + 1) - rd, slope 4a ru^3 + 3b ru^2 + 2c ru + 1
    if ptlens.any():
        x = r[ptlens]
        a, b, c = t0[ptlens], t1[ptlens], t2[ptlens]
        residual[ptlens] = x * (a * x * x * x + b * x * x + c * x + 1) - target[ptlens]
        slope[ptlens] = a4[ptlens] * x * x * x + b3[ptlens] * x * x + c2[ptlens] * x + 1
    # poly3: ru ru ru + ru q - rd q, slope 3 ru ru + q
    if poly3.any():
        x, k = r[poly3], q[poly3]
        residual[poly3] = x * x * x + x * k - target[poly3]
        slope[poly3] = 3 * x * x + k
    # poly5: ru (1 + k1 ru2 + k2 ru2 ru2) - rd, slope 1 + 3 k1 ru2 + 5 k2 ru2 ru2
    if poly5.any():
        x = r[poly5]
        x2 = x * x
        residual[poly5] = x * (1.0 + t0[poly5] * x2 + t1[poly5] * x2 * x2) - target[poly5]
        slope[poly5] = 1.0 + k3[poly5] * x2 + k5[poly5] * x2 * x2
    return residual, slope


def _polynomial(model: LiblensfunModel) -> FloatArray:
    """D(r) = sum P_i r^i, i = 0..5, in focal units, as the loop iterates it
    (poly3: k1 = 1/q, q liblensfun's float 1/k1'); (n, 6)."""
    kind, terms = model.kind, model.terms
    p = np.zeros((kind.size, 6))
    p[:, 1] = 1.0
    ptlens, poly3, poly5 = kind == 0, kind == 1, kind == 2
    p[ptlens, 2], p[ptlens, 3], p[ptlens, 4] = terms[ptlens, 2], terms[ptlens, 1], terms[ptlens, 0]
    with np.errstate(all="ignore"):
        p[poly3, 3] = 1.0 / _f32(1.0 / terms[poly3, 0])
    p[poly5, 3], p[poly5, 5] = terms[poly5, 0], terms[poly5, 1]
    return p


def _taylor(p: FloatArray, centre: FloatArray) -> FloatArray:
    """Coefficients of D(centre + t) in powers of t, by repeated Horner division."""
    t = np.array(np.broadcast_to(p, (*np.shape(centre), p.shape[-1])))
    degree = p.shape[-1] - 1
    for low in range(degree):
        for i in range(degree - 1, low - 1, -1):
            t[..., i] += centre * t[..., i + 1]
    return t


def _bounds(p: FloatArray, lo: FloatArray, hi: FloatArray) -> tuple[FloatArray, ...]:
    """Lower bound of D', upper bounds of |D'| and |D''| on [lo, hi] (Taylor at the midpoint)."""
    centre, radius = (lo + hi) / 2, (hi - lo) / 2
    t = _taylor(p, centre)
    slope = t[..., 1]
    t = np.abs(t)
    spread = sum(i * t[..., i] * radius ** (i - 1) for i in range(2, 6))
    curvature = sum(i * (i - 1) * t[..., i] * radius ** (i - 2) for i in range(2, 6))
    # A relative margin for the rounding of the bounds themselves.
    margin = 1e-9 * (np.abs(slope) + spread + curvature)
    return slope - spread - margin, np.abs(slope) + spread + margin, curvature + margin


def _proven(p: FloatArray, weight: FloatArray, u: FloatArray, v: FloatArray) -> NDArray[np.bool_]:
    """Whether liblensfun's Newton loop provably converges, to a radius > 0,
    within its steps for every distorted radius in [u, v] (focal units, u >= 0).

    With D' >= m on an interval J holding the start r_d, the root and every
    iterate, and |D''| <= M2 there: the root is within delta = G / m of the
    start (G bounds |D(r_d) - r_d|), and Newton's error obeys
    e' <= K e^2 with K = M2 / (2 m); with theta = K delta < 1 the error
    after six steps is at most theta^63 delta, and the iterates stay within
    delta of the root, so J = [u - 2 delta, v + 2 delta]. The residual left
    (|D'| times that error, times ``weight``: 1, or 1/k1 for poly3's scaled
    residual), with a generous bound on float64 rounding, must be below
    NEWTON_EPS. The root is > 0: D(0) = 0 and D increases on J. m is tried
    at several fractions of D''s lower bound on [u, v].
    """
    # |D(r) - r| on [u, v], and liblensfun's float target (poly3: rd q rounded to float).
    shifted = p.copy()
    shifted[..., 1] -= 1.0
    half = (v - u) / 2
    t = np.abs(_taylor(shifted, (u + v) / 2))
    gap = sum(t[..., i] * half**i for i in range(6)) * (1 + 1e-9) + 2.0**-23 * v
    m_band, _, _ = _bounds(p, u, v)
    proven = np.zeros(np.shape(gap), dtype=bool)
    with np.errstate(all="ignore"):
        for fraction in (0.9, 0.6, 0.3):
            m = m_band * fraction
            delta = gap / m
            lo, hi = u - 2 * delta, v + 2 * delta
            m_j, slope_j, curvature_j = _bounds(p, lo, hi)
            theta = curvature_j * delta / (2 * m)
            reach = np.maximum(np.abs(lo), np.abs(hi))
            size = (
                reach
                + v
                + np.sum(np.abs(p[..., 2:]) * np.stack([reach**i for i in range(2, 6)], -1), -1)
            )
            left = weight * (
                slope_j * delta * theta ** (2**NEWTON_STEPS - 1)
                + 2.0**-46 * size * (1 + slope_j / m)
            )
            proven |= (m > 0) & (m_j >= m) & (theta < 1) & (left <= NEWTON_EPS / 2)
    return proven


def inversion_failures(model: LiblensfunModel, r_corner: ArrayLike) -> Inversion:
    """Where liblensfun's Newton inversion first fails inside the image, per entry.

    ``r_corner`` is the image radius in Hugin units (hypot(aspect, 1), or a
    circular fisheye's 1); entries whose ``kind`` is -1 or whose r_corner is
    not a positive number never fail. See the module's docstring for what is
    sampled and what is proven.
    """
    kind = model.kind
    n = kind.size
    r_fail = np.full(n, np.nan)
    outcome = np.zeros(n, dtype=np.int8)
    with np.errstate(all="ignore"):
        corner = np.asarray(r_corner, dtype=np.float64) / model.scale
    candidates = np.flatnonzero((kind >= 0) & (corner > 0) & np.isfinite(corner))
    if candidates.size:
        p = _polynomial(model)[candidates]
        with np.errstate(all="ignore"):
            weight = np.where(
                kind[candidates] == 1, np.abs(_f32(1.0 / model.terms[candidates, 0])), 1.0
            )
        # Samples are float32 radii; the bands cover them with room for that rounding.
        top = corner[candidates] * (1 + 2.0**-20)
        parts = [slice(at, at + _RANGES_AT_ONCE) for at in range(0, top.size, _RANGES_AT_ONCE)]
        proven = np.concatenate(
            [_proven(p[at], weight[at], np.zeros_like(top[at]), top[at]) for at in parts]
        )
        doubtful = candidates[~proven]
        # Each row's samples are its own: rows a few at a time keep the arrays small.
        for start in range(0, doubtful.size, _ROWS_AT_ONCE):
            _sample_bands(model, doubtful[start : start + _ROWS_AT_ONCE], corner, r_fail, outcome)
    with np.errstate(all="ignore"):
        r_fail_hugin = r_fail * model.scale
        fraction = r_fail_hugin / np.asarray(r_corner, dtype=np.float64)
    return Inversion(outcome > 0, r_fail_hugin, fraction, outcome)


def _sample_bands(
    model: LiblensfunModel,
    rows: NDArray[np.intp],
    corner: FloatArray,
    r_fail: FloatArray,
    outcome: NDArray[np.int8],
) -> None:
    """Iterate the samples of the bands of ``rows`` that :func:`_proven` cannot
    clear; write the first failing radius (focal units) and its outcome."""
    bands = SAMPLES // BAND
    first = np.arange(bands) * BAND
    step = corner[rows, None] / SAMPLES
    u = first * step
    v = (first + BAND) * step * (1 + 2.0**-20)
    p = _polynomial(model)[rows][:, None, :]
    with np.errstate(all="ignore"):
        weight = np.where(model.kind[rows] == 1, np.abs(_f32(1.0 / model.terms[rows, 0])), 1.0)
    open_rows, open_bands = np.nonzero(~_proven(p, weight[:, None], u, v))
    if open_rows.size == 0:
        return
    index = first[open_bands, None] + np.arange(1, BAND + 1)
    rd = _f32(index * step[open_rows])
    entry = np.repeat(rows[open_rows], BAND)
    radii = rd.ravel()
    found = np.concatenate(
        [
            newton_outcome(
                model, entry[at : at + _SAMPLES_AT_ONCE], radii[at : at + _SAMPLES_AT_ONCE]
            )
            for at in range(0, entry.size, _SAMPLES_AT_ONCE)
        ]
    )
    failing = found > 0
    if not failing.any():
        return
    # The smallest failing radius of each entry: radii grow along each entry's samples.
    entry, radius, what = entry[failing], radii[failing], found[failing]
    order = np.lexsort((radius, entry))
    entry, radius, what = entry[order], radius[order], what[order]
    head = np.ones(entry.size, dtype=bool)
    head[1:] = entry[1:] != entry[:-1]
    r_fail[entry[head]] = radius[head]
    outcome[entry[head]] = what[head]
