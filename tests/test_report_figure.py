"""Figure 5: the histogram drawn is the count of finite r_normalized in entries.csv."""

from __future__ import annotations

import bisect
import csv
import math

import numpy as np
import pytest
from lxml import etree

from lensaudit.pipeline import run
from lensaudit.report import figures, histogram, write_report


@pytest.fixture(scope="module")
def bundled_report(bundled_db, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    audit = run(bundled_db)
    write_report(audit, out)
    return audit, out


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


def test_bins_are_ten_per_decade_and_one_is_an_edge(bundled_report):
    edges = np.array(read_bins(bundled_report[1])[0])
    assert np.allclose(np.log10(edges[1:] / edges[:-1]), 0.1)
    assert np.isclose(edges, 1.0).sum() == 1


def test_drawn_bars_are_the_counts(bundled_report):
    audit, out = bundled_report
    figure = figures.figure5(histogram.figure5(audit))
    edges, counts, counts_paper = read_bins(out)
    for axes, expected in zip(figure.axes[:2], (counts, counts_paper), strict=True):
        bars = sorted((p.get_x(), p.get_height()) for p in axes.patches)
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
