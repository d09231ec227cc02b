"""Figure 5: the histogram drawn is the count of finite r_normalized in entries.csv."""

from __future__ import annotations

import bisect
import csv
import decimal
import io
import math
import warnings
from decimal import Decimal

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from lxml import etree
from matplotlib.container import BarContainer
from matplotlib.text import Annotation

from lensaudit.report import audit, figures, histogram, write_report


@pytest.fixture(scope="module")
def bundled_report(bundled_db, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    audits = audit(bundled_db)
    write_report(audits, out)
    return audits.distortion, out


def rectilinear_finite(out, column):
    """Values of ``column`` for rectilinear entries with finite r_max, read from the CSV."""
    with (out / "entries.csv").open(newline="") as stream:
        return [
            float(row[column])
            for row in csv.DictReader(stream)
            if row["status"] == "ok"
            and row["type"] == "rectilinear"
            and row["r_max"] not in ("", "inf")
        ]


def read_bins(out):
    with (out / "fig5_r_normalized.csv").open(newline="") as stream:
        rows = list(csv.DictReader(stream))
    edges = [float(rows[0]["bin_low"])] + [float(r["bin_high"]) for r in rows]
    return edges, [int(r["count"]) for r in rows], [int(r["count_paper_units"]) for r in rows]


def count_by_hand(values, edges):
    counts = [0] * (len(edges) - 1)
    for value in values:
        if value > 0:
            counts[bisect.bisect_right(edges, value) - 1] += 1
    return counts


@pytest.mark.parametrize("column, which", [("r_normalized", 1), ("r_normalized_paper", 2)])
def test_histogram_counts_equal_a_count_from_the_csv(bundled_report, column, which):
    _, out = bundled_report
    values = rectilinear_finite(out, column)
    bins = read_bins(out)
    edges = bins[0]
    assert edges[0] < min(v for v in values if v > 0) and max(values) < edges[-1]
    assert bins[which] == count_by_hand(values, edges)
    assert sum(bins[which]) == sum(1 for v in values if v > 0)


def decimal_edge(k):
    """10 ** (k / 10) rounded to 6 significant digits, from 40-digit decimal arithmetic."""
    with decimal.localcontext() as context:
        context.prec = 40
        exact = Decimal(10) ** (Decimal(k) / 10)
        return float(exact.quantize(Decimal(1).scaleb(exact.adjusted() - 5)))


def test_bins_are_ten_per_decade_and_one_is_an_edge(bundled_report):
    edges = read_bins(bundled_report[1])[0]
    first = round(10 * math.log10(edges[0]))
    assert edges == [decimal_edge(first + i) for i in range(len(edges))]
    assert edges.count(1.0) == 1


def test_edges_are_powers_of_ten_rounded_to_six_digits_everywhere():
    # Rounding the platform's pow must land on the decimal of the exact power:
    # over the whole range of binary64 the edges are the same on every machine.
    for k in range(-3070, 3081):
        assert histogram.edge(k) == decimal_edge(k), k
    assert histogram.edge(0) == 1.0 and histogram.edge(10) == 10.0


def test_csv_edges_are_written_as_their_decimals(bundled_report):
    with (bundled_report[1] / "fig5_r_normalized.csv").open(newline="") as stream:
        rows = list(csv.DictReader(stream))
    for row in rows:
        for column in ("bin_low", "bin_high"):
            text = row[column]
            digits = text.split("e")[0].replace(".", "").replace("-", "").strip("0")
            assert len(digits) <= 6 and float(text) == decimal_edge(
                round(10 * math.log10(float(text)))
            )


def bar_patches(axes):
    return [patch for c in axes.containers if isinstance(c, BarContainer) for patch in c]


def test_drawn_bars_are_the_counts(bundled_report):
    audit, out = bundled_report
    figure = figures.figure5(histogram.figure5(audit))
    edges, counts, counts_paper = read_bins(out)
    for axes, expected in zip(figure.axes[:2], (counts, counts_paper), strict=True):
        bars = sorted((p.get_x(), p.get_height()) for p in bar_patches(axes))
        wanted = [(low, n) for low, n in zip(edges, expected, strict=False) if n]
        assert [n for _, n in bars] == [n for _, n in wanted]
        assert np.allclose([x for x, _ in bars], [x for x, _ in wanted], rtol=1e-12)
        assert axes.get_xscale() == "log" and axes.get_yscale() == "log"
        assert any(list(line.get_xdata()) == [1.0, 1.0] for line in axes.get_lines())


def test_entries_below_one_match_the_folding_count(bundled_report):
    audit, out = bundled_report
    below = [v for v in rectilinear_finite(out, "r_normalized") if v < 1]
    data = histogram.figure5(audit)
    assert data.below_one == len(below) == audit.summary.folding_rectilinear
    assert data.entries == len(rectilinear_finite(out, "r_normalized"))


def test_figure_files_are_a_png_and_well_formed_svg(bundled_report):
    out = bundled_report[1]
    assert (out / "fig5_r_normalized.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    root = etree.parse(str(out / "fig5_r_normalized.svg")).getroot()
    assert root.tag == "{http://www.w3.org/2000/svg}svg"


def test_values_that_a_log_axis_cannot_show_are_counted_apart():
    values = np.array([0.0, 0.5, 2.0, math.inf, math.nan])
    edges = histogram.log_edges(values)
    assert edges[0] <= 0.5 < 2.0 < edges[-1]
    assert histogram._count(values, edges).sum() == 2


@pytest.fixture(scope="module")
def bundled_figure(bundled_report):
    figure = figures.figure5(histogram.figure5(bundled_report[0]))
    figure.canvas.draw()
    return figure


@pytest.mark.parametrize("column, panel", [("r_normalized", 0), ("r_normalized_paper", 1)])
def test_x_axis_reaches_below_one_and_below_the_smallest_value(
    bundled_report, bundled_figure, column, panel
):
    values = [v for v in rectilinear_finite(bundled_report[1], column) if v > 0]
    left, right = bundled_figure.axes[panel].get_xlim()
    # At least a fifth of a decade of margin, so that the bins below 1 stand clear.
    assert math.log10(min(min(values), 1.0)) - math.log10(left) >= 0.2
    assert right > max(values)


def test_x_axis_reaches_far_below_one_when_a_value_does():
    data = histogram.from_values(np.array([0.03, 0.5, 2.0, 40.0]), np.array([1.5, 2.0, 3.0, 4.0]))
    figure = figures.figure5(data)
    for axes in figure.axes[:2]:
        assert math.log10(0.03) - math.log10(axes.get_xlim()[0]) >= 0.2


def below_one_labels(axes):
    return sorted(
        (a.xy[0], a.get_text()) for a in axes.texts if isinstance(a, Annotation) and a.xy[0] < 1
    )


@pytest.mark.parametrize("column, panel", [("r_normalized", 0), ("r_normalized_paper", 1)])
def test_bins_below_one_carry_their_counts(bundled_report, bundled_figure, column, panel):
    out = bundled_report[1]
    edges = read_bins(out)[0]
    below = [v for v in rectilinear_finite(out, column) if 0 < v < 1]
    by_hand = count_by_hand(below, edges)
    expected = [str(n) for low, n in zip(edges, by_hand, strict=False) if n and low < 1]
    labels = below_one_labels(bundled_figure.axes[panel])
    assert [text for _, text in labels] == expected and expected
    assert sum(int(t) for _, t in labels) == len(below)


def test_bars_below_one_stand_out_in_colour():
    data = histogram.from_values(np.array([0.3, 0.9, 2.0, 40.0]), np.array([0.5, 2.0, 3.0, 4.0]))
    axes = figures.figure5(data).axes[0]
    below = {tuple(p.get_facecolor()) for p in bar_patches(axes) if p.get_x() + p.get_width() <= 1}
    above = {tuple(p.get_facecolor()) for p in bar_patches(axes) if p.get_x() >= 1}
    assert len(below) == 1 and below.isdisjoint(above)
    assert [t for _, t in below_one_labels(axes)] == ["1", "1"]


def test_minor_ticks_mark_two_and_five_times_each_power_of_ten(bundled_figure):
    for axes in bundled_figure.axes[:2]:
        for axis, (low, high) in ((axes.xaxis, axes.get_xlim()), (axes.yaxis, axes.get_ylim())):
            shown = [t for t in axis.get_minorticklocs() if low <= t <= high]
            mantissas = {round(t / 10 ** math.floor(math.log10(t) + 1e-9), 6) for t in shown}
            assert shown and mantissas == {2.0, 5.0}


def test_figure5_draws_nothing_outside_its_canvas(bundled_figure):
    renderer = bundled_figure.canvas.get_renderer()
    canvas = bundled_figure.bbox
    drawn = bundled_figure.get_tightbbox(renderer).transformed(bundled_figure.dpi_scale_trans)
    assert canvas.x0 <= drawn.x0 and drawn.x1 <= canvas.x1
    assert canvas.y0 <= drawn.y0 and drawn.y1 <= canvas.y1
    for axes in bundled_figure.axes[:2]:
        frame = axes.get_window_extent(renderer)
        for label in axes.texts:
            box = label.get_window_extent(renderer)
            assert frame.x0 <= box.x0 and box.x1 <= frame.x1, label.get_text()
            assert frame.y0 <= box.y0 and box.y1 <= frame.y1, label.get_text()


values_strategy = st.lists(
    st.floats(min_value=1e-6, max_value=1e6, allow_nan=False), min_size=1, max_size=40
)


@settings(max_examples=60, deadline=None)
@given(values=values_strategy, data=st.data())
def test_histogram_does_not_depend_on_the_order_of_entries(values, data):
    shuffled = data.draw(st.permutations(values))
    first = histogram.from_values(np.array(values), np.array(values) * 3)
    second = histogram.from_values(np.array(shuffled), np.array(shuffled) * 3)
    assert first.rows() == second.rows()


@settings(max_examples=60, deadline=None)
@given(values=values_strategy)
def test_every_value_falls_in_the_bin_its_written_edges_give(values):
    data = histogram.from_values(np.array(values), np.array(values))
    rows = data.rows()
    edges = [float(rows[0][0])] + [float(r[1]) for r in rows]
    assert [r[2] for r in rows] == count_by_hand(values, edges)
    assert 1.0 in edges


@pytest.mark.parametrize(
    "values",
    [[1e-300, 1e300], [1.7e308, 0.5], [5e-324, 2.0], [1e-30, 1e30], [], [0.0, -1.0, math.nan]],
)
def test_figure5_of_extreme_values_is_drawn_without_warnings(values):
    data = histogram.from_values(np.array(values, dtype=float), np.array(values, dtype=float))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        figure = figures.figure5(data)
        figures.save(figure, io.BytesIO(), "png")
        figures.svg_text(figure)
    left, right = figure.axes[0].get_xlim()
    assert 0 < left < 1 < right < math.inf


@pytest.mark.parametrize("values", [[4.5], [0.9, 3.0], [2.0, 3.0, 40.0], [1e-30, 1e30]])
def test_every_tick_label_of_figure5_is_plain_text(values):
    # Mathtext (a label in $...$) looks up fonts of its own, and matplotlib
    # says on stderr when they are missing: every label is a plain number.
    data = histogram.from_values(np.array(values), np.array(values) * 5)
    figure = figures.figure5(data)
    figure.canvas.draw()
    labels = [
        label.get_text()
        for axes in figure.axes[:2]
        for axis in (axes.xaxis, axes.yaxis)
        for label in (*axis.get_majorticklabels(), *axis.get_minorticklabels())
    ]
    assert any(labels) and not [label for label in labels if "$" in label]
    minor = [label.get_text() for label in figure.axes[0].yaxis.get_minorticklabels()]
    if len(values) == 1:  # one entry: the y axis spans less than a decade, its 2 is labelled
        assert "2" in minor
