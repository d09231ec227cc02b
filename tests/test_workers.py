"""Parsing in worker processes: the same results as parsing here, whatever a worker does."""

from __future__ import annotations

import math
import os
import threading
import time
from functools import partial
from pathlib import Path

import pytest

from lensaudit import pipeline, workers
from lensaudit.loader import expand
from lensaudit.workers import Job, parse_all

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this system")


@pytest.fixture
def forced_workers(monkeypatch):
    """Workers for any amount of work, as if three CPUs were free."""
    monkeypatch.setattr(workers, "MIN_BYTES", 0)
    monkeypatch.setattr(workers, "_cpus", lambda: 3)
    monkeypatch.setattr(workers, "_can_fork", lambda: True)


@pytest.fixture
def no_workers(monkeypatch):
    monkeypatch.setattr(workers, "_cpus", lambda: 1)


def busy() -> None:
    """The caller's own work: long enough for the workers to take every job."""
    time.sleep(0.3)


def bundled_jobs(bundled_db: Path) -> list[Job]:
    return [Job(path.resolve(), name) for path, name in expand(bundled_db)]


def in_workers_only(value: int, parent: int) -> int:
    """A parse that fails, hard, in any process but the test's."""
    if os.getpid() != parent:
        os._exit(3)
    return value * value


def test_workers_give_what_parsing_here_gives(bundled_db, forced_workers):
    jobs = bundled_jobs(bundled_db)
    parse = partial(pipeline._parse, formats=("csv", "json"))
    expected = [parse(job) for job in jobs]
    assert parse_all(jobs, parse, busy) == expected


def test_workers_take_part(forced_workers):
    jobs = [Job(Path(f"/{n}"), str(n), b"x" * n) for n in range(1, 40)]
    parent = os.getpid()
    found = parse_all(jobs, lambda job: (len(job.data), os.getpid() != parent), busy)
    assert [size for size, _ in found] == list(range(1, 40))
    assert any(in_worker for _, in_worker in found)


def test_what_a_failing_worker_did_not_return_is_parsed_here(forced_workers):
    jobs = [Job(Path(f"/{n}"), str(n), b"x" * n) for n in range(1, 20)]
    parent = os.getpid()
    found = parse_all(jobs, lambda job: in_workers_only(len(job.data), parent), busy)
    assert found == [n * n for n in range(1, 20)]


def test_an_error_in_parsing_is_raised_here(forced_workers):
    def parse(job: Job) -> int:
        if job.name == "7":
            raise ValueError("bad job")
        return 0

    jobs = [Job(Path(f"/{n}"), str(n), b"x") for n in range(10)]
    with pytest.raises(ValueError, match="bad job"):
        parse_all(jobs, parse, lambda: None)


def test_workers_are_reaped_when_the_caller_fails(forced_workers):
    def meanwhile() -> None:
        raise KeyboardInterrupt

    jobs = [Job(Path(f"/{n}"), str(n), b"x") for n in range(10)]
    with pytest.raises(KeyboardInterrupt):
        parse_all(jobs, lambda job: 0, meanwhile)
    with pytest.raises(ChildProcessError):
        os.waitpid(-1, os.WNOHANG)


def test_a_process_with_other_threads_does_not_fork():
    release = threading.Event()
    thread = threading.Thread(target=release.wait)
    thread.start()
    try:
        assert not workers._can_fork()
    finally:
        release.set()
        thread.join()


def test_parsing_in_a_thread_gives_the_same_results(bundled_db, no_workers):
    jobs = bundled_jobs(bundled_db)
    parse = partial(pipeline._parse, formats=("csv",))
    ran = []
    assert parse_all(jobs, parse, lambda: ran.append(True)) == [parse(job) for job in jobs]
    assert ran == [True]


def comparable(audit: pipeline.Audit) -> dict[str, list]:
    return {
        name: ["nan" if isinstance(v, float) and math.isnan(v) else v for v in values]
        for name, values in audit.columns().items()
    }


def test_an_audit_in_workers_equals_one_without(bundled_db, monkeypatch):
    monkeypatch.setattr(workers, "_cpus", lambda: 1)
    alone = pipeline.run(bundled_db)
    monkeypatch.setattr(workers, "MIN_BYTES", 0)
    monkeypatch.setattr(workers, "_cpus", lambda: 3)
    monkeypatch.setattr(workers, "_can_fork", lambda: True)
    shared = pipeline.run(bundled_db, formats=("csv",))
    assert comparable(shared) == comparable(alone)
    assert [(f.name, f.entries, f.error) for f in shared.files] == [
        (f.name, f.entries, f.error) for f in alone.files
    ]


@pytest.mark.parametrize("setting", ["forced_workers", "no_workers"])
def test_progress_counts_up_to_every_job(setting, request):
    request.getfixturevalue(setting)
    jobs = [Job(Path(f"/{n}"), str(n), b"x" * n) for n in range(1, 200)]
    seen: list[tuple[int, int]] = []
    found = parse_all(
        jobs,
        lambda job: len(job.data),
        lambda: None,
        lambda done, total: seen.append((done, total)),
    )
    assert found == list(range(1, 200))
    assert seen[-1] == (199, 199)
    assert all(total == 199 and 0 <= done <= 199 for done, total in seen)
    assert [done for done, _ in seen] == sorted(done for done, _ in seen)


def test_a_job_of_given_size_counts_that_size():
    assert workers._size(Job(Path("/nowhere/at/all"), "x", size=12345)) == 12345
    assert workers._size(Job(Path("/nowhere/at/all"), "x")) == 0


def test_tasks_in_parallel_give_their_results_in_order(forced_workers):
    parent = os.getpid()
    found = workers.in_parallel([lambda n=n: (n * n, os.getpid() != parent) for n in range(5)])
    assert [value for value, _ in found] == [0, 1, 4, 9, 16]
    assert any(elsewhere for _, elsewhere in found)


def test_tasks_that_cannot_be_forked_run_here_one_after_another(monkeypatch):
    monkeypatch.setattr(workers, "_can_fork", lambda: False)
    parent, running = os.getpid(), threading.active_count()
    found = workers.in_parallel(
        [lambda n=n: (n, os.getpid(), threading.active_count()) for n in range(3)]
    )
    assert found == [(n, parent, running) for n in range(3)]


def _results_pipe(data: bytes) -> int:
    read, write = os.pipe()
    os.write(write, data)
    os.close(write)
    return read


@pytest.mark.parametrize(
    "sent",
    [
        b"",  # the worker died before writing
        (2).to_bytes(8, "little") + (5).to_bytes(8, "little"),  # sizes cut short
        (1).to_bytes(8, "little") + (9).to_bytes(8, "little") + b"abc",  # a result cut short
        (1).to_bytes(8, "little") + (3).to_bytes(8, "little") + b"\xff\xfe\xfd",  # not marshal
        (1 << 62).to_bytes(8, "little"),  # an absurd count
    ],
)
def test_results_that_are_cut_short_or_garbled_count_as_none(sent):
    source = _results_pipe(sent)
    try:
        assert workers._collect(source) == {}
    finally:
        os.close(source)


def test_results_are_read_back_as_a_worker_writes_them():
    import marshal

    done = [marshal.dumps((index, {"x": "y" * index})) for index in (3, 0, 7)]
    read, write = os.pipe()
    sizes = b"".join(len(result).to_bytes(8, "little") for result in done)
    workers._write_all(write, [len(done).to_bytes(8, "little"), sizes, *done])
    os.close(write)
    try:
        assert workers._collect(read) == {3: {"x": "yyy"}, 0: {"x": ""}, 7: {"x": "y" * 7}}
    finally:
        os.close(read)
