"""The check's rules on every core: each process a share of the files, the
findings the same as in one process, in the same order, and sent back whole
(a share whose process failed would be done again here)."""

from __future__ import annotations

import os
import re
import threading
from pathlib import Path

import pytest

from lensaudit.check import check
from lensaudit.check import findings as rules
from lensaudit.check.rules import duplicate_lens
from lensaudit.read import parallel

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this system")


def _checked(database: Path, verbose: bool, baseline: Path | None = None):
    result = check(database, baseline=baseline, verbose=verbose)
    return result.findings, result.resolved


@pytest.fixture
def rules_here(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """The number of files each call of the rules in this process was given."""
    calls: list[int] = []
    made = rules._rules

    def counted(read, *args, **kwargs):
        calls.append(len(read))
        return made(read, *args, **kwargs)

    monkeypatch.setattr(rules, "_rules", counted)
    return calls


@pytest.mark.parametrize("verbose", [False, True])
def test_the_rules_on_three_cores_find_what_one_finds(
    bundled_db: Path, monkeypatch: pytest.MonkeyPatch, rules_here: list[int], verbose: bool
) -> None:
    monkeypatch.setattr(parallel, "cpus", lambda: 1)
    alone = _checked(bundled_db, verbose)
    assert rules_here == [len(list(bundled_db.glob("*.xml")))]
    rules_here.clear()
    monkeypatch.setattr(parallel, "cpus", lambda: 3)
    assert threading.active_count() == 1, "another thread runs: nothing would be forked"
    shared = _checked(bundled_db, verbose)
    assert shared == alone
    assert len(alone[0]) > 100  # there is something to send back
    # One share done here; the two others came back whole from their processes.
    assert len(rules_here) == 1
    assert 0 < rules_here[0] < len(list(bundled_db.glob("*.xml")))


def test_the_rules_against_a_baseline_on_three_cores_find_what_one_finds(
    bundled_db: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    changed = tmp_path / "db"
    changed.mkdir()
    for path in sorted(bundled_db.glob("*.xml")):
        data = path.read_bytes()
        # Every file's first distortion entry made to fold: poly3 with k1 = -0.5,
        # D(r) = r (1.5 - 0.5 r^2), peaks at r = 1, inside any image.
        data = re.sub(rb'(<distortion [^>]*?)k1="[^"]*"', rb'\1k1="-0.5"', data, count=1)
        data = re.sub(rb'<distortion model="\w+"', b'<distortion model="poly3"', data, count=1)
        (changed / path.name).write_bytes(data)
    monkeypatch.setattr(parallel, "cpus", lambda: 1)
    alone = _checked(changed, False, bundled_db)
    monkeypatch.setattr(parallel, "cpus", lambda: 3)
    assert _checked(changed, False, bundled_db) == alone
    assert sum(f.code == "fold-in-image" and not f.known for f in alone[0]) > 20


def test_the_rules_across_files_on_another_core_find_what_they_find_here(
    bundled_db: Path, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(parallel, "cpus", lambda: 1)
    alone = _checked(bundled_db, verbose=False)
    # The duplicate-lens, undefined-mount and liblensfun-refuses rules look at
    # every file: one more item of the rules' work, which the first core free
    # takes. This process is slowed here, so that the other takes it.
    parent = os.getpid()
    made, duplicates = rules._rules, duplicate_lens.duplicate_lenses

    def slow_here(*args, **kwargs):
        if os.getpid() == parent:
            import time

            time.sleep(1.0)
        return made(*args, **kwargs)

    def marked(*args, **kwargs):
        (tmp_path / f"across-{os.getpid()}").touch()
        return duplicates(*args, **kwargs)

    monkeypatch.setattr(rules, "_rules", slow_here)
    monkeypatch.setattr(duplicate_lens, "duplicate_lenses", marked)
    monkeypatch.setattr(parallel, "cpus", lambda: 2)
    assert _checked(bundled_db, verbose=False) == alone
    assert [p.name for p in tmp_path.iterdir()] != [f"across-{parent}"]
    assert len(list(tmp_path.iterdir())) == 1
    assert any(f.code == "liblensfun-refuses" for f in alone[0])
    assert any(f.code == "undefined-mount" for f in alone[0])
