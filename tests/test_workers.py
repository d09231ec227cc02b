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
