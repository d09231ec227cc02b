"""One entry's distortion curve D(r) and its slope D'(r), sampled for plotting.

Radii are in Hugin units (r = 1 is half the short side of the calibration
image), r undistorted and D(r) distorted, as in :mod:`lensaudit.metrics`.
This module is numpy only: the matplotlib figure is drawn in
:mod:`lensaudit.report.figures`, the small inline SVG sketch here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from html import escape

import numpy as np
from numpy.typing import NDArray

from .. import normalizer
from ..read.records import DistortionEntry

FloatArray = NDArray[np.float64]

#: Plot at most this many image-corner radii out, so that the image stays readable
#: when r_max is very far away (then r_max is noted as off the plot).
MAX_EXTENT_CORNERS = 6.0


def entry_cubic(entry: DistortionEntry) -> normalizer.Cubic:
    """The normalized model of an audited entry (ptlens, poly3 or poly5).

    Raises ``ValueError`` for any other model.
    """
    if entry.model == "ptlens":
        return normalizer.ptlens(entry.a, entry.b, entry.c)
    if entry.model == "poly3":
        return normalizer.poly3(entry.k1)
    if entry.model == "poly5":
        return normalizer.poly5(entry.k1, entry.k2)
    raise ValueError(f"model {entry.model!r} is not one lensaudit can plot")


def distortion_coefficients(entry: DistortionEntry) -> FloatArray:
    """Coefficients of D(r), highest power first (as numpy.polyval expects)."""
    return np.asarray(entry_cubic(entry).distortion, dtype=np.float64).reshape(-1)


def plot_extent(r_max: float, r_corner: float) -> float:
    """Largest undistorted radius worth plotting: past r_max and past the corner.

    1.5 r_max when that shows the corner too, at least 1.3 corner radii, at most
    :data:`MAX_EXTENT_CORNERS` corner radii (r_max may be far off the plot then).
    """
    corner = r_corner if math.isfinite(r_corner) and r_corner > 0 else 1.0
    if math.isfinite(r_max) and r_max > 0:
        return float(min(max(1.5 * r_max, 1.3 * corner), MAX_EXTENT_CORNERS * corner))
    return 1.5 * corner


@dataclass(frozen=True)
class Curve:
    """D(r) and D'(r) at radii ``r`` (all Hugin units; D' is dimensionless)."""

    r: FloatArray
    d: FloatArray
    slope: FloatArray
    r_max: float
    d_max: float
    r_corner: float


def sample(
    entry: DistortionEntry,
    r_max: float,
    d_max: float,
    r_corner: float,
    points: int = 400,
    extent: float | None = None,
) -> Curve:
    """D and D' of an entry at ``points`` radii from 0 to ``extent`` (default
    :func:`plot_extent`)."""
    coefficients = distortion_coefficients(entry)
    end = plot_extent(r_max, r_corner) if extent is None else float(extent)
    r = np.linspace(0.0, end, points)
    d = np.polyval(coefficients, r)
    slope = np.polyval(np.polyder(coefficients), r)
    return Curve(r, d, slope, float(r_max), float(d_max), float(r_corner))


#: How far below zero a sketch shows D(r), as a fraction of its top. Where D
#: falls further, the sketch ends (the fold is plain by then).
SKETCH_FLOOR = 0.5
#: The top of a sketch, as a multiple of the larger of the corner and D(r_max).
SKETCH_HEADROOM = 1.15


def sketch_range(curve: Curve) -> tuple[float, float]:
    """(bottom, top) of the D axis of :func:`sketch_svg`, Hugin units.

    The top is :data:`SKETCH_HEADROOM` times the larger of the image corner
    and D(r_max) (the largest sampled D when the model does not fold); the
    bottom is 0, or lower by at most :data:`SKETCH_FLOOR` times the top.
    """
    finite = curve.d[np.isfinite(curve.d)]
    peak = curve.d_max if math.isfinite(curve.d_max) else None
    if peak is None:
        peak = float(finite.max()) if finite.size else 1.0
    corner = curve.r_corner if math.isfinite(curve.r_corner) else 0.0
    top = SKETCH_HEADROOM * max(corner, peak, 1e-300)
    lowest = float(finite.min()) if finite.size else 0.0
    return min(0.0, max(lowest, -SKETCH_FLOOR * top)), top


def sketch_sample(
    entry: DistortionEntry, r_max: float, d_max: float, r_corner: float, points: int = 160
) -> Curve:
    """D(r) for :func:`sketch_svg`: from 0 to :func:`plot_extent`, or only up to where
    D leaves the sketch's range (see :func:`sketch_range`), so that the whole
    curve fits in the sketch."""
    curve = sample(entry, r_max, d_max, r_corner, points)
    bottom, top = sketch_range(curve)
    outside = np.flatnonzero(~((curve.d >= bottom) & (curve.d <= top)))
    if outside.size == 0 or outside[0] == 0:
        return curve
    # D leaves the range between two samples: bisect for the crossing, then
    # sample again up to it (D is a polynomial, continuous).
    coefficients = distortion_coefficients(entry)
    low, high = float(curve.r[outside[0] - 1]), float(curve.r[outside[0]])
    for _ in range(60):
        middle = 0.5 * (low + high)
        if bottom <= np.polyval(coefficients, middle) <= top:
            low = middle
        else:
            high = middle
    return sample(entry, r_max, d_max, r_corner, points, extent=low)


def _text_width(text: str, size: float) -> float:
    """A generous estimate of the width of sans-serif text (digits and letters)."""
    return 0.62 * size * len(text)


def sketch_svg(curve: Curve, width: int = 480, height: int = 300) -> str:
    """An SVG of D(r) for inlining in HTML: the curve, r_max and the image corner.

    The horizontal line is the image corner radius (distorted); the model folds
    inside the image when the curve's peak at r_max stays below it. Everything
    is drawn inside the ``width`` x ``height`` view box (user units, drawn as CSS
    pixels unless the page scales the SVG): the curve is clamped to the plot
    (use :func:`sketch_sample` so that it does not need to be), labels are kept
    off the edges.
    """
    font = 14
    pad_left, pad_right, pad_top, pad_bottom = 46, 10, 22, 42
    plot_w = width - pad_left - pad_right
    plot_h = height - pad_top - pad_bottom
    plot_bottom = pad_top + plot_h
    bottom, top = sketch_range(curve)
    x_end = float(curve.r[-1]) if curve.r.size and curve.r[-1] > 0 else 1.0

    def x(value: float) -> float:
        return pad_left + plot_w * min(max(value, 0.0), x_end) / x_end

    def y(value: float) -> float:
        clipped = min(max(value, bottom), top) if math.isfinite(value) else bottom
        return pad_top + plot_h * (top - clipped) / (top - bottom)

    points = " ".join(f"{x(r):.1f},{y(d):.1f}" for r, d in zip(curve.r, curve.d, strict=True))
    parts = [
        f'<svg width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" role="img" aria-label="D(r) of this entry">',
        f'<rect x="{pad_left}" y="{pad_top}" width="{plot_w}" height="{plot_h}" '
        f'fill="#fff" stroke="#999"/>',
    ]
    if bottom < 0:
        parts.append(
            f'<line x1="{pad_left}" x2="{pad_left + plot_w}" y1="{y(0):.1f}" '
            f'y2="{y(0):.1f}" stroke="#ccc"/>'
        )
    if math.isfinite(curve.r_corner):
        parts.append(
            f'<line x1="{pad_left}" x2="{pad_left + plot_w}" y1="{y(curve.r_corner):.1f}" '
            f'y2="{y(curve.r_corner):.1f}" stroke="#1f77b4" stroke-width="1.5" '
            f'stroke-dasharray="6 4"/>'
        )
    parts.append(f'<polyline points="{points}" fill="none" stroke="#222" stroke-width="2.5"/>')
    shows_r_max = math.isfinite(curve.r_max) and 0 <= curve.r_max <= x_end
    if shows_r_max:
        parts.append(
            f'<line x1="{x(curve.r_max):.1f}" x2="{x(curve.r_max):.1f}" y1="{pad_top}" '
            f'y2="{plot_bottom}" stroke="#d62728" stroke-width="1.5" stroke-dasharray="5 3"/>'
        )
        parts.append(
            f'<circle cx="{x(curve.r_max):.1f}" cy="{y(curve.d_max):.1f}" r="4.5" fill="#d62728"/>'
        )
    axis_row = plot_bottom + font + 2
    labels = [
        (pad_left, pad_top - 6, "start", "#222", "D(r)"),
        (pad_left - 4, y(0) + 5, "end", "#555", "0"),
        (pad_left, axis_row, "middle", "#555", "0"),
        (pad_left + plot_w, axis_row, "end", "#555", f"r {x_end:.2f}"),
    ]
    if math.isfinite(curve.r_corner):
        labels.append(
            (pad_left - 4, y(curve.r_corner) + 5, "end", "#1f77b4", f"{curve.r_corner:.2f}")
        )
    if shows_r_max:
        text = f"r_max {curve.r_max:.3g}"
        half = _text_width(text, font) / 2
        # Centred under the red line, but never past the sketch's edges.
        centre = min(max(x(curve.r_max), half + 1), width - half - 1)
        labels.append((centre, height - 5, "middle", "#d62728", text))
    for lx, ly, anchor, colour, text in labels:
        parts.append(
            f'<text x="{lx:.1f}" y="{ly:.1f}" text-anchor="{anchor}" fill="{colour}" '
            f'font-size="{font}" font-family="sans-serif">{escape(text)}</text>'
        )
    parts.append("</svg>")
    return "".join(parts)
