"""Figure 5 drawn in a forked process (lensaudit.report.drawing): the drawing made
here, whatever the process does, and no process left behind."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

from conftest import no_child_left
from lensaudit.read import parallel
from lensaudit.report import drawing, histogram

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this system")

HISTOGRAM = histogram.from_values(np.array([0.3, 0.9, 2.0, 40.0]), np.array([0.5, 2.0, 3.0, 4.0]))


@pytest.fixture
def forked(monkeypatch):
    """A process for the drawing, as if two CPUs were free."""
    monkeypatch.setattr(parallel, "cpus", lambda: 2)
    assert threading.active_count() == 1, "another thread runs: nothing would be forked"


def drawn_by_pid(_: histogram.Histogram) -> tuple[bytes, str]:
    return str(os.getpid()).encode(), "svg"


def test_the_forked_process_draws_what_is_drawn_here(forked):
    with drawing.Figure5Drawing() as figure5:
        figure5.send(HISTOGRAM)
        png, svg = figure5.result()
    assert (png, svg) == drawing.draw(HISTOGRAM)
    assert png.startswith(b"\x89PNG\r\n\x1a\n") and svg.lstrip().startswith("<?xml")
    assert no_child_left()


def test_the_figure_is_drawn_in_the_forked_process(forked, monkeypatch):
    monkeypatch.setattr(drawing, "draw", drawn_by_pid)
    with drawing.Figure5Drawing() as figure5:
        figure5.send(HISTOGRAM)
        png, _ = figure5.result()
    assert png != str(os.getpid()).encode()
    assert no_child_left()


def test_what_a_failing_process_had_to_draw_is_drawn_here(forked, monkeypatch):
    parent = os.getpid()

    def fails_elsewhere(data: histogram.Histogram) -> tuple[bytes, str]:
        if os.getpid() != parent:
            raise RuntimeError("only in the forked process")
        return drawn_by_pid(data)

    monkeypatch.setattr(drawing, "draw", fails_elsewhere)
    with drawing.Figure5Drawing() as figure5:
        figure5.send(HISTOGRAM)
        assert figure5.result() == (str(parent).encode(), "svg")
    assert no_child_left()


def test_what_a_killed_process_had_to_draw_is_drawn_here(forked, monkeypatch):
    monkeypatch.setattr(drawing, "draw", drawn_by_pid)
    with drawing.Figure5Drawing() as figure5:
        assert figure5._pid is not None
        os.kill(figure5._pid, 9)
        figure5.send(HISTOGRAM)
        assert figure5.result() == drawn_by_pid(HISTOGRAM)
    assert no_child_left()


def test_a_drawing_not_waited_for_ends_its_process(forked):
    with pytest.raises(KeyError), drawing.Figure5Drawing() as figure5:
        assert figure5._pid is not None
        figure5.send(HISTOGRAM)
        raise KeyError("the report failed before its figure was wanted")
    assert no_child_left()


def test_nothing_is_forked_on_one_cpu(monkeypatch):
    monkeypatch.setattr(parallel, "cpus", lambda: 1)
    monkeypatch.setattr(drawing, "draw", drawn_by_pid)
    with drawing.Figure5Drawing() as figure5:
        assert figure5._pid is None
        figure5.send(HISTOGRAM)
        assert figure5.result() == drawn_by_pid(HISTOGRAM)


def test_nothing_is_forked_while_another_thread_runs(forked):
    release = threading.Event()
    other = threading.Thread(target=release.wait)
    other.start()
    try:
        with drawing.Figure5Drawing() as figure5:
            assert figure5._pid is None
    finally:
        release.set()
        other.join()


def test_a_result_before_a_histogram_is_an_error():
    with pytest.raises(RuntimeError):
        drawing.Figure5Drawing().result()


def test_the_drawing_process_holds_a_cpu_while_it_runs(monkeypatch):
    # Two CPUs: while Figure 5 is drawn beside it, this process reads alone,
    # rather than three processes sharing two CPUs.
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    assert threading.active_count() == 1, "another thread runs: nothing would be forked"
    parent = os.getpid()
    assert parallel.cpus() == 2
    with drawing.Figure5Drawing() as figure5:
        assert parallel.cpus() == 1
        sizes = [parallel.MIN_BYTES] * 4
        read_meanwhile = parallel.map_sized(lambda n: os.getpid(), list(range(4)), sizes)
        assert read_meanwhile == [parent] * 4
        figure5.send(HISTOGRAM)
        assert figure5.result()[0].startswith(b"\x89PNG")
        assert parallel.cpus() == 2  # ended: its CPU is free again
    with drawing.Figure5Drawing():  # a drawing not waited for frees its CPU too
        assert parallel.cpus() == 1
    assert parallel.cpus() == 2
    assert no_child_left()
