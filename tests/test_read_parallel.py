"""Parsing on every core (lensaudit.read.parallel.map_sized): the serial results,
in order, whatever a forked process does; small inputs are done here."""

from __future__ import annotations

import math
import os
import threading
import time
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import no_child_left
from lensaudit import pipeline
from lensaudit.read import parallel, read
from lensaudit.read.parallel import map_sized, shares

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this system")


@pytest.fixture
def forced(monkeypatch):
    """Processes for any amount of work, as if three CPUs were free."""
    monkeypatch.setattr(parallel, "MIN_BYTES", 0)
    monkeypatch.setattr(parallel, "cpus", lambda: 3)
    assert threading.active_count() == 1, "another thread runs: nothing would be forked"


@pytest.fixture
def one_cpu(monkeypatch):
    monkeypatch.setattr(parallel, "cpus", lambda: 1)


def test_results_are_the_serial_ones_in_order(forced):
    parent = os.getpid()
    items = list(range(40))

    def squared(n: int) -> tuple[int, str, bool]:
        time.sleep(0.001)  # time enough for the forked processes to take some
        return n * n, str(n), os.getpid() != parent

    found = map_sized(squared, items, [1] * 40)
    assert [(square, text) for square, text, _ in found] == [(n * n, str(n)) for n in items]
    assert any(elsewhere for _, _, elsewhere in found)  # forked processes took part
    assert no_child_left()


def test_results_follow_the_items_whatever_their_sizes(forced):
    sizes = [5, 1, 40, 3, 3, 17, 0, 2, 8, 8, 1]
    found = map_sized(lambda item: item.upper(), [f"item {i}" for i in range(11)], sizes)
    assert found == [f"ITEM {i}" for i in range(11)]


def test_the_share_of_a_process_that_raises_is_done_here(forced):
    parent = os.getpid()

    def square_here_only(n: int) -> tuple[int, int]:
        if os.getpid() != parent:
            raise ValueError("only in a forked process")
        return n * n, os.getpid()

    found = map_sized(square_here_only, list(range(20)), [1] * 20)
    assert found == [(n * n, parent) for n in range(20)]
    assert no_child_left()


def test_the_share_of_a_process_that_dies_is_done_here(forced):
    parent = os.getpid()

    def square_or_die(n: int) -> int:
        if os.getpid() != parent:
            os._exit(3)
        return n * n

    assert map_sized(square_or_die, list(range(20)), [1] * 20) == [n * n for n in range(20)]


def test_an_error_of_the_function_shows_here(forced, tmp_path):
    parent = os.getpid()
    marker = tmp_path / "forked"

    def fails_on_seven(n: int) -> int:
        if os.getpid() != parent:  # every forked process fails: its share comes here
            marker.write_text("a process was forked")
            raise RuntimeError("in a forked process")
        if n == 7:
            raise ValueError("bad item 7")
        return n

    with pytest.raises(ValueError, match="bad item 7"):
        map_sized(fails_on_seven, list(range(10)), [1] * 10)
    assert marker.exists()
    assert no_child_left()


def test_a_result_that_is_not_plain_data_is_made_here(forced):
    # marshal cannot send an object: the process fails, and its share is done here.
    parent = os.getpid()

    class Made:
        def __init__(self, n: int) -> None:
            self.n, self.here = n, os.getpid() == parent

    found = map_sized(Made, list(range(12)), [1] * 12)
    assert [m.n for m in found] == list(range(12)) and all(m.here for m in found)


def test_processes_are_ended_when_the_work_here_fails(forced):
    parent = os.getpid()

    def interrupted_here(n: int) -> int:
        if os.getpid() == parent:
            raise KeyboardInterrupt
        time.sleep(0.05)  # slow elsewhere: an item is left for this process
        return n

    with pytest.raises(KeyboardInterrupt):
        map_sized(interrupted_here, list(range(10)), [1] * 10)
    assert no_child_left()


def test_every_item_is_done_once_however_many_there_are(forced, tmp_path):
    # More items than a pipe holds tickets for: each ticket is a run of items.
    count = 3 * parallel._Queue.MOST + 5

    def marked(n: int) -> int:
        (tmp_path / str(n)).touch(exist_ok=False)  # a second time would raise
        return -n

    assert map_sized(marked, list(range(count)), list(range(count))) == [-n for n in range(count)]
    assert len(list(tmp_path.iterdir())) == count
    assert no_child_left()


def test_a_slow_process_takes_fewer_items(forced):
    # This process is slowed (as by the report's drawing beside it): the others
    # take the items it would have had in a share of its own.
    parent = os.getpid()

    def slow_here(n: int) -> int:
        if os.getpid() == parent:
            time.sleep(0.2)
        else:
            time.sleep(0.002)
        return os.getpid()

    found = map_sized(slow_here, list(range(60)), [1] * 60)
    assert found.count(parent) <= 2 < len(found)


def test_items_are_taken_largest_first(forced):
    # Whatever the others take, the items this process takes come in the order
    # of their sizes, largest first.
    parent = os.getpid()
    sizes = [5, 1, 40, 3, 3, 17, 0, 2, 8, 9, 1, 30, 6, 12, 4, 22]
    here: list[int] = []

    def noted(n: int) -> int:
        if os.getpid() == parent:
            here.append(n)
        else:
            time.sleep(0.02)
        return n

    assert map_sized(noted, list(range(len(sizes))), sizes) == list(range(len(sizes)))
    taken = [sizes[n] for n in here]
    assert len(taken) > 1 and taken == sorted(taken, reverse=True)


def test_meanwhile_is_done_here_once_while_the_others_take_items(forced, tmp_path):
    parent = os.getpid()

    def meanwhile() -> None:
        (tmp_path / f"meanwhile-{os.getpid()}").touch(exist_ok=False)
        time.sleep(0.1)  # the others take items meanwhile

    found = map_sized(lambda n: (n, os.getpid()), list(range(30)), [1] * 30, meanwhile)
    assert [n for n, _ in found] == list(range(30))
    assert [p.name for p in tmp_path.iterdir()] == [f"meanwhile-{parent}"]
    assert {pid for _, pid in found} != {parent}  # taken elsewhere while this one waited


def test_the_cpus_of_the_others_are_held_meanwhile(monkeypatch):
    # Work spread over the CPUs meanwhile (the history reads its newest files
    # so) is spread over those the others do not take.
    monkeypatch.setattr(parallel, "MIN_BYTES", 0)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2}, raising=False)
    assert parallel.cpus() == 3
    seen = []
    found = map_sized(lambda n: n, list(range(6)), [1] * 6, lambda: seen.append(parallel.cpus()))
    assert (found, seen, parallel.cpus()) == (list(range(6)), [1], 3)
    with pytest.raises(KeyError):  # freed when meanwhile fails too
        map_sized(lambda n: n, list(range(6)), [1] * 6, lambda: {}["x"])
    assert parallel.cpus() == 3


def test_meanwhile_is_done_when_nothing_is_forked(one_cpu, tmp_path):
    done = []
    assert map_sized(lambda n: n + 1, [1, 2], [1, 1], lambda: done.append(1)) == [2, 3]
    assert done == [1]


def test_small_inputs_are_done_here(monkeypatch):
    monkeypatch.setattr(parallel, "cpus", lambda: 3)
    parent = os.getpid()
    sizes = [parallel.MIN_BYTES // 10] * 9  # 90 % of the threshold in all
    found = map_sized(lambda n: (n, os.getpid()), list(range(9)), sizes)
    assert found == [(n, parent) for n in range(9)]


def test_one_cpu_or_one_item_is_done_here(monkeypatch, one_cpu):
    monkeypatch.setattr(parallel, "MIN_BYTES", 0)
    parent = os.getpid()
    assert map_sized(lambda n: (n, os.getpid()), [1, 2, 3], [1, 1, 1]) == [
        (1, parent),
        (2, parent),
        (3, parent),
    ]
    monkeypatch.setattr(parallel, "cpus", lambda: 3)
    assert map_sized(lambda n: (n, os.getpid()), [5], [1 << 30]) == [(5, parent)]


def test_nothing_is_forked_while_another_thread_runs(monkeypatch):
    monkeypatch.setattr(parallel, "MIN_BYTES", 0)
    monkeypatch.setattr(parallel, "cpus", lambda: 3)
    parent = os.getpid()
    release = threading.Event()
    thread = threading.Thread(target=release.wait)
    thread.start()
    try:
        found = map_sized(lambda n: os.getpid(), list(range(10)), [1] * 10)
    finally:
        release.set()
        thread.join()
    assert found == [parent] * 10


def test_no_items_give_no_results(forced):
    assert map_sized(lambda n: n, [], []) == []


@given(st.lists(st.integers(0, 10**6), max_size=60), st.integers(1, 8))
def test_shares_hold_every_item_once_and_are_about_equal(sizes, count):
    found = shares(sizes, count)
    assert sorted(i for share in found for i in share) == list(range(len(sizes)))
    assert len(found) <= count and all(share == sorted(share) for share in found)
    if len(found) == count:  # largest first, each to the lightest: within one item
        totals = [sum(sizes[i] for i in share) for share in found]
        assert max(totals) - min(totals) <= max(sizes)


# -- the reader and the audit on every core -------------------------------------------


def comparable(rows) -> list[str]:
    return [repr(tuple(row)) for row in rows]


def test_a_read_on_every_core_is_the_read_in_one_process(bundled_db, monkeypatch):
    monkeypatch.setattr(parallel, "cpus", lambda: 1)
    alone = read(bundled_db, calibrations=True)
    monkeypatch.setattr(parallel, "MIN_BYTES", 0)
    monkeypatch.setattr(parallel, "cpus", lambda: 3)
    shared = read(bundled_db, calibrations=True)
    assert comparable(shared.entries()) == comparable(alone.entries())
    assert comparable(shared.source_files()) == comparable(alone.source_files())
    for kind in ("vignetting", "tca"):
        assert shared.rows(kind)[0] == alone.rows(kind)[0]
        assert comparable(shared.rows(kind)[1]) == comparable(alone.rows(kind)[1])
    for mine, theirs in zip(shared.files, alone.files, strict=True):
        assert comparable(mine.lenses) == comparable(theirs.lenses)


def audit_columns(audit: pipeline.Audit) -> dict[str, list]:
    return {
        name: ["nan" if isinstance(v, float) and math.isnan(v) else v for v in values]
        for name, values in audit.columns().items()
    }


def test_an_audit_on_every_core_is_the_audit_in_one_process(bundled_db, monkeypatch):
    monkeypatch.setattr(parallel, "cpus", lambda: 1)
    alone = pipeline.run(bundled_db)
    monkeypatch.setattr(parallel, "MIN_BYTES", 0)
    monkeypatch.setattr(parallel, "cpus", lambda: 3)
    shared = pipeline.run(bundled_db)
    assert audit_columns(shared) == audit_columns(alone)
    assert [(f.name, f.entries, f.error) for f in shared.files] == [
        (f.name, f.entries, f.error) for f in alone.files
    ]


def test_a_read_on_every_core_parses_in_other_processes(bundled_db, monkeypatch, tmp_path):
    # The parse of each file, marked with the process it ran in.
    from lensaudit.read import xml

    parent = os.getpid()
    real = xml.parse
    marks = tmp_path / "marks"
    marks.mkdir()

    def marking(data, *arguments, **options):
        if os.getpid() != parent:
            Path(marks, str(os.getpid())).touch()
        return real(data, *arguments, **options)

    monkeypatch.setattr(xml, "parse", marking)
    monkeypatch.setattr(parallel, "MIN_BYTES", 0)
    monkeypatch.setattr(parallel, "cpus", lambda: 3)
    read(bundled_db)
    assert 1 <= len(list(marks.iterdir())) <= 2  # the other two shares
