"""Every matplotlib figure of lensaudit: Figures 3, 4, 5 and 6 of the paper.

Figures are drawn on the Agg canvas explicitly, without pyplot, so that no
display is needed and no global plotting state is touched. Output is
reproducible: no dates in the files, fixed SVG ids.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.patches import Circle
from matplotlib.ticker import FuncFormatter, LogFormatter, LogLocator, NullFormatter

from .histogram import BINS_PER_DECADE

if TYPE_CHECKING:
    from .curves import Curve
    from .histogram import Histogram
    from .rmax_map import RMaxMap
    from .warp import Warp

RED = "#d62728"
BLUE = "#1f77b4"
GREEN = "#2ca02c"
GREY = "#7f7f7f"

#: Colour range of r_max maps; values beyond are drawn in the end colours.
R_MAX_SHOWN = (0.25, 4.0)

_STYLE = {"svg.hashsalt": "lensaudit", "svg.fonttype": "path", "font.size": 9}
_METADATA = {
    "svg": {"Date": None, "Creator": None, "Format": None, "Type": None},
    "png": {"Software": None},
}


def new_figure(
    width_inches: float, height_inches: float, dpi: float = 100, layout: str | None = None
) -> Figure:
    """A figure on an Agg canvas."""
    figure = Figure(figsize=(width_inches, height_inches), dpi=dpi, layout=layout)
    FigureCanvasAgg(figure)
    return figure


def save(figure: Figure, path: Path | io.IOBase, fmt: str | None = None) -> None:
    """Write ``figure`` as PNG or SVG (format from ``fmt`` or the file suffix)."""
    fmt = fmt or Path(str(path)).suffix.lstrip(".").lower()
    with matplotlib.rc_context(_STYLE):
        figure.savefig(path, format=fmt, metadata=_METADATA.get(fmt))


def svg_text(figure: Figure) -> str:
    """The figure as a standalone SVG document (the text :func:`save` writes)."""
    buffer = io.StringIO()
    save(figure, buffer, "svg")
    return buffer.getvalue()


#: Below 1 the model folds inside its image; those bars and their counts are red.
FOLD_SHADE = "#fbe3e3"
#: Margin of Figure 5's x axis beyond the outer bin edges, in decades.
X_MARGIN_DECADES = 0.3
#: Figure 5's minor ticks, as multiples of each power of ten.
MINOR_TICKS = (2.0, 5.0)
#: Figure 5's x axis stays within [1 / X_SHOWN_MAX, X_SHOWN_MAX]: matplotlib's
#: log ticks overflow on ranges of hundreds of decades. Only absurd models
#: reach beyond; their bars are cut at the frame (they are in the CSV).
X_SHOWN_MAX = 1e200


def figure5_x_limits(edges: np.ndarray) -> tuple[float, float]:
    """x range of Figure 5: every bin, 1 and a margin of :data:`X_MARGIN_DECADES` below
    both the first edge and 1 (so that the bins below 1 never sit on the frame),
    within :data:`X_SHOWN_MAX`."""
    finite = edges[np.isfinite(edges) & (edges > 0)]
    low = min(float(finite[0]) if finite.size else 1.0, 1.0)
    high = max(float(finite[-1]) if finite.size else 1.0, 1.0)
    margin = 10.0**X_MARGIN_DECADES
    return max(low / margin, 1 / X_SHOWN_MAX), min(high * margin, X_SHOWN_MAX)


def _bars(axes, histogram: Histogram, counts: np.ndarray, colour: str, label: str) -> None:
    # Scales and limits first: autoscaling a log axis to bars near the largest
    # float would overflow.
    axes.set_xscale("log")
    axes.set_yscale("log")
    low, high = figure5_x_limits(histogram.edges)
    axes.set_xlim(low, high)
    top = np.finfo(np.float64).max
    edges = np.minimum(histogram.edges, top)
    shown = counts > 0
    below_one = edges[1:] <= 1.0
    for part, part_colour in ((shown & ~below_one, colour), (shown & below_one, RED)):
        axes.bar(
            edges[:-1][part],
            counts[part],
            width=np.diff(edges)[part],
            align="edge",
            color=part_colour,
            edgecolor="white",
            linewidth=0.4,
            label=label,
        )
    axes.axvspan(low, 1.0, color=FOLD_SHADE, linewidth=0, zorder=0)
    axes.axvline(1.0, color=RED, linestyle="--", linewidth=1.2)
    # The bins below 1 are the point of the figure but only a few pixels wide
    # on a log axis: write their counts over them.
    for start, end, count in zip(edges[:-1], edges[1:], counts, strict=True):
        if count > 0 and end <= 1.0:
            axes.annotate(
                str(int(count)),
                (math.sqrt(start * end), count),
                xytext=(0, 3),
                textcoords="offset points",
                ha="center",
                va="bottom",
                color=RED,
                fontsize=8,
                fontweight="bold",
                # Over the dashed line at 1 when the bin touches it: keep the count legible.
                bbox={"facecolor": "white", "edgecolor": "none", "pad": 0.6},
            )
    # Plain numbers (0.5, 1, 10, 100) read better than powers of ten here, and
    # need no mathtext.
    plain = FuncFormatter(lambda value, _: f"{value:g}")
    axes.xaxis.set_major_formatter(plain)
    axes.yaxis.set_major_formatter(plain)
    # On an axis of few decades matplotlib labels some minor ticks too: in plain
    # text as well (its default writes them as mathtext, which looks up fonts
    # of its own and says so on stderr where they are missing).
    axes.xaxis.set_minor_formatter(LogFormatter(labelOnlyBase=False))
    axes.yaxis.set_minor_formatter(LogFormatter(labelOnlyBase=False))
    # Minor ticks at 2 and 5 times each power of ten: the 1-2-5 marks read
    # as well as eight per decade, and each tick is a costly matplotlib object.
    axes.xaxis.set_minor_locator(LogLocator(subs=MINOR_TICKS))
    axes.yaxis.set_minor_locator(LogLocator(subs=MINOR_TICKS))
    axes.grid(True, which="major", color="#dddddd", linewidth=0.5)
    axes.set_axisbelow(True)


def figure5(histogram: Histogram) -> Figure:
    """The paper's Figure 5, correct units (left) beside its mixed units (right).

    Bars are drawn for non-empty bins only (a log axis has no zero). The
    x axis reaches below 1 and below the smallest value; left of the dashed
    r_normalized = 1 line (shaded) the models fold inside their image, and
    those bars are red with their counts written over them.
    """
    figure = new_figure(10, 4.2)
    left, right = figure.subplots(1, 2, sharey=True)
    _bars(left, histogram, histogram.counts, BLUE, "r_normalized")
    _bars(right, histogram, histogram.counts_paper, GREY, "r_normalized_paper")
    # At the top of each panel (y=1), where matplotlib would place them anyway
    # (nothing is drawn above the panels): it then skips working that out
    # from every tick label at each draw.
    left.set_title("Correct units: D(r_max) / hypot(aspect, 1)", fontsize=9, y=1.0)
    right.set_title(
        "Paper's mixed units: D(r_max) / (hypot(18, 12) / (crop \u00b7 focal))", fontsize=9, y=1.0
    )
    left.set_xlabel("r_normalized (Hugin units, both sides)")
    right.set_xlabel("r_normalized_paper (as in the paper's Figure 5)")
    left.set_ylabel("entries per bin")
    top = max(int(histogram.counts.max(initial=0)), int(histogram.counts_paper.max(initial=0)), 1)
    left.set_ylim(0.7, top * 2.5)
    for axes, below, not_drawn in (
        (left, histogram.below_one, histogram.not_drawn),
        (right, histogram.below_one_paper, histogram.not_drawn_paper),
    ):
        note = f"{below} below 1 (fold inside the image)"
        if not_drawn:
            note += f"\n{not_drawn} with r_normalized \u2264 0 not drawn"
        axes.text(
            0.98, 0.96, note, transform=axes.transAxes, ha="right", va="top", color=RED, fontsize=8
        )
        axes.text(
            1.0,
            0.90,
            " r_normalized = 1",
            transform=axes.get_xaxis_transform(),
            color=RED,
            fontsize=8,
            va="top",
            ha="left",
        )
    figure.suptitle(
        f"Finite r_normalized of {histogram.entries} rectilinear entries "
        f"(log-log histogram, {BINS_PER_DECADE} bins per decade)",
        fontsize=10,
    )
    figure.subplots_adjust(left=0.07, right=0.99, bottom=0.13, top=0.86, wspace=0.06)
    return figure


def curve_figure(curve: Curve, title: str) -> Figure:
    """D(r) and D'(r) of one entry with r_max and the image corner marked (Figure 4 style).

    Radii in Hugin units. The dashed blue line is the image corner radius
    (distorted); the model folds inside the image when D peaks below it.
    """
    figure = new_figure(7, 6)
    top, bottom = figure.subplots(2, 1, sharex=True)
    top.plot(curve.r, curve.d, color="black", linewidth=1.5, label="D(r)")
    top.plot(curve.r, curve.r, color=GREY, linewidth=0.8, linestyle=":", label="D(r) = r")
    top.axhline(
        curve.r_corner,
        color=BLUE,
        linestyle="--",
        linewidth=1,
        label=f"image corner (circle of a circular fisheye) = {curve.r_corner:.3f}",
    )
    bottom.plot(curve.r, curve.slope, color="black", linewidth=1.5, label="D'(r)")
    bottom.axhline(0.0, color=GREY, linewidth=0.8)
    end = float(curve.r[-1])
    if math.isfinite(curve.r_max) and curve.r_max <= end:
        for axes in (top, bottom):
            axes.axvline(curve.r_max, color=RED, linestyle="--", linewidth=1)
        top.plot(
            [curve.r_max],
            [curve.d_max],
            "o",
            color=RED,
            label=f"r_max = {curve.r_max:.4g}, D(r_max) = {curve.d_max:.4g}",
        )
    elif math.isfinite(curve.r_max):
        top.plot([], [], " ", label=f"r_max = {curve.r_max:.4g} (beyond the plot)")
    else:
        top.plot([], [], " ", label="r_max = \u221e (D is increasing)")
    low, high = np.nanmin(curve.d), np.nanmax(curve.d)
    span = max(high, curve.r_corner) * 1.15
    top.set_ylim(max(low, -0.6 * span) - 0.05 * span, span)
    slope_low = max(float(np.nanmin(curve.slope)), -2.0)
    bottom.set_ylim(slope_low - 0.1, max(float(np.nanmax(curve.slope)), 1.0) + 0.1)
    top.set_ylabel("distorted radius D(r)")
    bottom.set_ylabel("D'(r)")
    bottom.set_xlabel("undistorted radius r (Hugin units: 1 = half the short image side)")
    top.set_xlim(0, end)
    for axes in (top, bottom):
        axes.grid(True, color="#e5e5e5", linewidth=0.5)
        axes.legend(loc="best", fontsize=8, frameon=False)
    # Long lens names: wrap the title to the figure's width and make room for it.
    renderer = figure.canvas.get_renderer()
    font = FontProperties(size=9)

    def measure(line: str) -> float:
        return renderer.get_text_width_height_descent(line, font, ismath=False)[0]

    left, right = 0.11, 0.98
    # The title is centred over the axes, so it has twice the shorter distance
    # from their centre to an edge of the figure.
    usable = 2 * min((left + right) / 2, 1 - (left + right) / 2) * figure.bbox.width - 12
    lines = [wrap_to_width(line, usable, measure) or line for line in title.split("\n")]
    top.set_title("\n".join(lines), fontsize=9)
    count = sum(line.count("\n") + 1 for line in lines)
    title_pixels = count * 1.25 * 9 * figure.dpi / 72 + 12
    figure.subplots_adjust(
        left=left,
        right=right,
        top=1 - title_pixels / figure.bbox.height,
        bottom=0.09,
        hspace=0.08,
    )
    return figure


#: Font sizes (points) tried for a warp's caption, largest first.
CAPTION_SIZES = (8.0, 7.0, 6.0, 5.0)
#: Smallest inset (input image) worth drawing, in pixels along either side.
MIN_INSET_PIXELS = 24
_CAPTION_PAD_POINTS = 3.0
_INSET_TITLE_POINTS = 7.0


def wrap_to_width(text: str, width_pixels: float, measure: Callable[[str], float]) -> str | None:
    """``text`` broken at spaces into lines no wider than ``width_pixels``.

    ``measure`` gives a line's width in pixels. None when a single word is
    already too wide.
    """
    lines: list[str] = []
    for word in text.split():
        if measure(word) > width_pixels:
            return None
        if lines and measure(f"{lines[-1]} {word}") <= width_pixels:
            lines[-1] = f"{lines[-1]} {word}"
        else:
            lines.append(word)
    return "\n".join(lines)


def _fit_caption(
    figure: Figure, caption: str, width_pixels: float, height_pixels: float
) -> tuple[str, float] | None:
    """(wrapped caption, font size) of the largest of :data:`CAPTION_SIZES` whose
    block, with its padding, fits ``width_pixels`` x ``height_pixels``; None if none does."""
    renderer = figure.canvas.get_renderer()
    points = figure.dpi / 72
    pad = 2 * _CAPTION_PAD_POINTS * points
    for size in CAPTION_SIZES:
        font = FontProperties(size=size)

        def measure(line: str, font: FontProperties = font) -> float:
            return renderer.get_text_width_height_descent(line, font, ismath=False)[0]

        wrapped = wrap_to_width(caption, width_pixels - pad, measure)
        if wrapped is None:
            continue
        probe = figure.text(0, 0, wrapped, fontsize=size)
        block = probe.get_window_extent(renderer)
        probe.remove()
        if block.width + pad <= width_pixels and block.height + pad <= height_pixels:
            return wrapped, size
    return None


def warp_figure(warp: Warp, inset: np.ndarray | None, caption: str) -> Figure:
    """The undistorted checkerboard at its native pixel size (Figure 6 style).

    The valid region is outlined in green (the r_max circle); pixels outside
    it are dimmed, since the model folds there and repeats image content.
    ``inset`` (the input checkerboard) is shown in the top-left corner, with
    its title inside the figure; it is left out when it would be smaller than
    :data:`MIN_INSET_PIXELS`. The caption is wrapped (and its font made
    smaller) to fit the width under the inset; when even the smallest of
    :data:`CAPTION_SIZES` cannot fit, it is left out rather than cut.
    """
    height, width = warp.image.shape[:2]
    figure = new_figure(width / 100, height / 100, dpi=100)
    axes = figure.add_axes((0, 0, 1, 1))
    image = np.where(warp.valid[..., None], warp.image, (warp.image * 0.55).astype(np.uint8))
    axes.imshow(image, interpolation="nearest", extent=(-0.5, width - 0.5, height - 0.5, -0.5))
    if math.isfinite(warp.r_max_pixels) and warp.r_max_pixels > 0:
        axes.add_patch(Circle(warp.centre, warp.r_max_pixels, fill=False, color=GREEN, linewidth=2))
    axes.set_xlim(-0.5, width - 0.5)
    axes.set_ylim(height - 0.5, -0.5)
    axes.set_axis_off()
    points = figure.dpi / 72
    margin = 2.0  # pixels kept free along the figure's edges
    caption_top = height - margin
    title_height = 1.4 * _INSET_TITLE_POINTS * points
    inset_width, inset_height = 0.26 * width, 0.28 * height
    if (
        inset is not None
        and min(inset_width, inset_height) >= MIN_INSET_PIXELS
        and inset_height + title_height + 2 * margin <= 0.6 * height
    ):
        inset_top = height - margin - title_height
        box = figure.add_axes(
            (
                0.01,
                (inset_top - inset_height) / height,
                inset_width / width,
                inset_height / height,
            )
        )
        box.imshow(inset, interpolation="nearest")
        box.set_xticks([])
        box.set_yticks([])
        box.set_title("input", fontsize=_INSET_TITLE_POINTS, color="white", pad=2)
        caption_top = inset_top - inset_height - margin
    fitted = _fit_caption(figure, caption, width - 2 * margin, caption_top - margin)
    if fitted is not None:
        wrapped, size = fitted
        pad = _CAPTION_PAD_POINTS * points
        axes.text(
            0.5,
            (margin + pad) / height,
            wrapped,
            transform=figure.transFigure,
            ha="center",
            va="bottom",
            multialignment="center",
            fontsize=size,
            color="white",
            bbox={"facecolor": "black", "alpha": 0.6, "edgecolor": "none", "pad": 3},
        )
    return figure


def map_figure(grid: RMaxMap) -> Figure:
    """r_max of Brown-Conrady over (k1, k2), one panel per k3 (paper Figure 3).

    Colour is log r_max (red: near 0, blue: large); green: r_max = infinity.
    """
    panels = len(grid.k3)
    columns = min(panels, 4)
    rows = math.ceil(panels / columns)
    figure = new_figure(3.0 * columns + 1.2, 3.0 * rows + 0.6, layout="constrained")
    axes = np.atleast_1d(figure.subplots(rows, columns, squeeze=False)).ravel()
    norm = LogNorm(vmin=R_MAX_SHOWN[0], vmax=R_MAX_SHOWN[1])
    cmap = matplotlib.colormaps["RdYlBu"].with_extremes(bad=GREEN)
    extent = (grid.k1[0], grid.k1[-1], grid.k2[0], grid.k2[-1])
    image = None
    for index, k3 in enumerate(grid.k3):
        values = np.ma.masked_where(
            ~np.isfinite(grid.r_max[index]), np.clip(grid.r_max[index], *R_MAX_SHOWN)
        )
        image = axes[index].imshow(
            values,
            origin="lower",
            extent=extent,
            cmap=cmap,
            norm=norm,
            interpolation="nearest",
            aspect="auto",
        )
        axes[index].set_title(f"k3 = {k3:g}", fontsize=9)
        axes[index].set_xlabel("k1")
        if index % columns == 0:
            axes[index].set_ylabel("k2")
    for extra in axes[panels:]:
        extra.set_visible(False)
    bar = figure.colorbar(image, ax=list(axes[:panels]), fraction=0.04, pad=0.02)
    bar.set_label("r_max (normalized camera coordinates)\ngreen: \u221e (no fold)")
    ticks = [t for t in (0.25, 0.5, 1.0, 2.0, 4.0) if R_MAX_SHOWN[0] <= t <= R_MAX_SHOWN[1]]
    bar.set_ticks(ticks, labels=[f"{t:g}" for t in ticks])
    bar.ax.yaxis.set_minor_formatter(NullFormatter())
    figure.suptitle("Brown-Conrady maximum valid radius over (k1, k2)", fontsize=10)
    return figure
