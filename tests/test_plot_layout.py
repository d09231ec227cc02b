"""Everything a figure draws lies inside it: warp captions, inset titles, D(r) sketches."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from lxml import etree

from conftest import lens_xml
from lensaudit import metrics
from lensaudit.pipeline import run
from lensaudit.report import curves, figures, select, warp

CAPTION = (
    "Tokina 11-16mm f/2.8 AT-X 116 AF Pro DX at 11 mm, crop 1, ptlens "
    "(slr-tokina.xml:17): r_max = 2.194, r_normalized = 0.936, scale 0.548"
)


@pytest.fixture(scope="module")
def audit(bundled_db):
    return run(bundled_db)


def drawn_warp(width, height, caption=CAPTION):
    """The warp figure of a stand-in model at ``width`` x ``height``, drawn."""
    identity = [0.0, 0.0, 1.0, 0.0]
    result = warp.hugin_warp(identity, 1.5, 1.2, width, height)
    inset = warp.input_image(240, max(2, round(240 * height / width)))
    figure = figures.warp_figure(result, inset, caption)
    figure.canvas.draw()
    return figure


def texts(figure):
    return [t for axes in figure.axes for t in axes.texts + [axes.title]] + figure.texts


def inside(box, frame, slack=0.5):
    return (
        frame.x0 - slack <= box.x0
        and box.x1 <= frame.x1 + slack
        and frame.y0 - slack <= box.y0
        and box.y1 <= frame.y1 + slack
    )


@pytest.mark.parametrize(
    "width, height", [(600, 400), (1000, 666), (301, 77), (257, 133), (120, 700), (999, 41)]
)
def test_warp_caption_lies_inside_the_figure(width, height):
    figure = drawn_warp(width, height)
    renderer = figure.canvas.get_renderer()
    (caption,) = [t for t in texts(figure) if "r_normalized" in t.get_text()]
    assert caption.get_text().split() == CAPTION.split()
    assert inside(caption.get_window_extent(renderer), figure.bbox)
    assert inside(caption.get_bbox_patch().get_window_extent(renderer), figure.bbox)


@pytest.mark.parametrize("width, height", [(600, 400), (257, 133), (120, 700), (301, 77)])
def test_warp_caption_keeps_clear_of_the_inset(width, height):
    figure = drawn_warp(width, height)
    renderer = figure.canvas.get_renderer()
    (caption,) = [t for t in texts(figure) if "r_normalized" in t.get_text()]
    block = caption.get_bbox_patch().get_window_extent(renderer)
    for inset in figure.axes[1:]:
        assert block.y1 <= inset.get_window_extent(renderer).y0


@pytest.mark.parametrize(
    "width, height", [(16, 16), (40, 17), (600, 400), (121, 90), (33, 500), (1000, 666)]
)
def test_no_text_of_a_warp_figure_is_cut(width, height):
    figure = drawn_warp(width, height)
    renderer = figure.canvas.get_renderer()
    for text in texts(figure):
        if text.get_text():
            assert inside(text.get_window_extent(renderer), figure.bbox), text.get_text()


def test_a_caption_too_long_for_a_tiny_figure_is_left_out_not_cut():
    figure = drawn_warp(16, 16)
    assert not [t for t in texts(figure) if "r_normalized" in t.get_text()]


def test_warp_figure_keeps_the_requested_pixel_size():
    figure = drawn_warp(301, 77)
    assert figure.canvas.get_width_height() == (301, 77)


@settings(max_examples=80, deadline=None)
@given(
    words=st.lists(st.text("abcdefghij", min_size=1, max_size=12), min_size=1, max_size=30),
    width=st.integers(min_value=1, max_value=60),
)
def test_wrapped_lines_fit_and_keep_every_word(words, width):
    wrapped = figures.wrap_to_width(" ".join(words), width, len)
    if max(len(w) for w in words) > width:
        assert wrapped is None
    else:
        lines = wrapped.split("\n")
        assert all(len(line) <= width for line in lines)
        assert " ".join(lines).split() == words
        # Greedy: no line could have taken the next line's first word.
        for line, following in zip(lines, lines[1:], strict=False):
            assert len(line) + 1 + len(following.split()[0]) > width


def folding_sketches(audit):
    """(entry, Curve, svg) of every entry of the audit that folds inside its image."""
    m = audit.metrics
    for index in audit.summary.folding:
        entry = audit.entries[index]
        curve = curves.sketch_sample(
            entry, float(m.r_max[index]), float(m.d_max[index]), float(m.r_corner[index])
        )
        yield entry, curve, curves.sketch_svg(curve)


def svg_points(svg):
    root = etree.fromstring(svg)
    width, height = (float(v) for v in root.get("viewBox").split()[2:])
    frame = root.find("rect")
    box = [float(frame.get(k)) for k in ("x", "y", "width", "height")]
    return root, width, height, box


def test_every_folding_sketch_draws_its_curve_inside_the_plot(audit):
    sketches = list(folding_sketches(audit))
    assert len(sketches) == len(audit.summary.folding) >= 4
    for entry, _, svg in sketches:
        root, _, _, (x0, y0, w, h) = svg_points(svg)
        points = [
            tuple(map(float, p.split(","))) for p in root.find("polyline").get("points").split()
        ]
        assert all(x0 <= x <= x0 + w and y0 <= y <= y0 + h for x, y in points), entry.lens
        # The curve is not squashed against the frame: at most its last point touches
        # the bottom (where the sketch ends) and none the top.
        assert sum(y == pytest.approx(y0 + h, abs=0.05) for _, y in points) <= 1, entry.lens
        assert not any(y == pytest.approx(y0, abs=0.05) for _, y in points), entry.lens


def test_sketch_curve_is_d_of_r_without_clamping(audit):
    for entry, curve, _ in folding_sketches(audit):
        # D(r) written out from the coefficients, independently of the normalizer.
        if entry.model == "ptlens":
            d = 1 - entry.a - entry.b - entry.c
            expected = curve.r * (
                entry.a * curve.r**3 + entry.b * curve.r**2 + entry.c * curve.r + d
            )
        elif entry.model == "poly3":
            expected = curve.r * (1 - entry.k1 + entry.k1 * curve.r**2)
        else:
            expected = curve.r * (1 + entry.k1 * curve.r**2 + entry.k2 * curve.r**4)
        assert np.allclose(curve.d, expected, rtol=1e-12, atol=1e-12)
        # The range: 1.15 times the larger of the corner and D(r_max), down to
        # half of that below zero.
        top = 1.15 * max(curve.r_corner, curve.d_max)
        assert expected.max() <= top * (1 + 1e-9), entry.lens
        assert expected.min() >= -0.5 * top * (1 + 1e-9), entry.lens
        assert curve.r[-1] > curve.r_max


def test_sigma_fisheye_sketch_reaches_past_its_fold_and_back_below_zero(audit):
    index = select.by_location(audit, "slr-sigma.xml", 3239)
    entry = audit.entries[index]
    curve = curves.sketch_sample(
        entry,
        float(audit.metrics.r_max[index]),
        float(audit.metrics.d_max[index]),
        # Judged against its image circle it does not fold; sketched against the
        # frame's corner, as in `plot curve`, it must still be drawn whole.
        float(metrics.image_corner(entry.aspect_ratio)),
    )
    assert entry.lens.startswith("Sigma 4.5mm")
    assert curve.d[-1] < 0 < curve.d.max() and curve.r[-1] > 1.5 * curve.r_max


def text_box(element):
    """A generous box of an SVG text: 0.62 em per character, 1 em tall above the baseline."""
    x, y = float(element.get("x")), float(element.get("y"))
    size = float(element.get("font-size"))
    width = 0.62 * size * len(element.text)
    anchor = element.get("text-anchor")
    left = x - width / 2 if anchor == "middle" else (x - width if anchor == "end" else x)
    return left, y - size, left + width, y + 0.25 * size


def test_every_folding_sketch_keeps_its_labels_inside_the_view_box(audit):
    for entry, _, svg in folding_sketches(audit):
        root, width, height, _ = svg_points(svg)
        for element in root.iter("text", "line", "circle"):
            if element.tag == "text":
                x0, y0, x1, y1 = text_box(element)
            elif element.tag == "line":
                xs = [float(element.get(k)) for k in ("x1", "x2")]
                ys = [float(element.get(k)) for k in ("y1", "y2")]
                x0, x1, y0, y1 = min(xs), max(xs), min(ys), max(ys)
            else:
                cx, cy, r = (float(element.get(k)) for k in ("cx", "cy", "r"))
                x0, y0, x1, y1 = cx - r, cy - r, cx + r, cy + r
            assert 0 <= x0 and x1 <= width and 0 <= y0 and y1 <= height, (entry.lens, element.text)


def test_r_max_label_stays_inside_when_r_max_is_at_the_end():
    curve = curves.Curve(
        r=np.linspace(0, 2.0, 50),
        d=np.linspace(0, 1.0, 50),
        slope=np.ones(50),
        r_max=2.0,
        d_max=1.0,
        r_corner=1.8,
    )
    root = etree.fromstring(curves.sketch_svg(curve))
    (label,) = [t for t in root.iter("text") if t.text.startswith("r_max")]
    assert text_box(label)[2] <= float(root.get("width"))
    assert re.fullmatch(r"r_max 2", label.text)


def test_sketch_of_a_model_that_never_folds_has_no_r_max_mark():
    curve = curves.Curve(
        r=np.linspace(0, 2.0, 50),
        d=np.linspace(0, 2.0, 50),
        slope=np.ones(50),
        r_max=math.inf,
        d_max=math.inf,
        r_corner=1.8,
    )
    root = etree.fromstring(curves.sketch_svg(curve))
    assert not root.findall("circle")
    assert not [t for t in root.iter("text") if t.text.startswith("r_max")]


def test_sketch_of_a_model_that_rises_again_ends_at_its_top(write_xml):
    # poly3 k1 = 2: D(r) = r (2 r^2 - 1) falls from the centre (r_max = 0), then
    # rises for good; the sketch's top is 1.15 times the corner hypot(1.5, 1).
    audit = run(write_xml(lens_xml('<distortion model="poly3" focal="10" k1="2"/>')))
    (index,) = audit.summary.folding
    m = audit.metrics
    curve = curves.sketch_sample(
        audit.entries[index], float(m.r_max[index]), float(m.d_max[index]), float(m.r_corner[index])
    )
    top = 1.15 * math.hypot(1.5, 1.0)
    roots = np.roots([2.0, 0.0, -1.0, -top])
    crossing = max(r.real for r in roots if abs(r.imag) < 1e-12)
    assert curve.r[-1] == pytest.approx(crossing, rel=1e-9)
    root, *_ = svg_points(curves.sketch_svg(curve))
    assert root.find("polyline") is not None and float(m.r_max[index]) == 0.0


@pytest.mark.parametrize(
    "lens",
    ["Sigma 4.5mm f/2.8 EX DC HSM circular fisheye", "A" * 40 + " " + "very long name " * 12],
)
def test_curve_figure_title_lies_inside_the_figure(audit, lens):
    index = select.by_location(audit, "slr-sigma.xml", 3239)
    m = audit.metrics
    curve = curves.sample(
        audit.entries[index], float(m.r_max[index]), float(m.d_max[index]), float(m.r_corner[index])
    )
    title = f"{lens} at 4.5 mm, crop 1.534, ptlens (slr-sigma.xml:3239)\nr_normalized = 0.604"
    figure = figures.curve_figure(curve, title)
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    shown = figure.axes[0].title
    assert shown.get_text().split() == title.split()
    assert inside(shown.get_window_extent(renderer), figure.bbox)
    assert shown.get_window_extent(renderer).y0 >= figure.axes[0].get_window_extent(renderer).y1
