"""SIGINT and SIGTERM while a command writes leave no temporary file: the
command ends in one line, status 130 (SIGINT) or 143 (SIGTERM), its outputs
all there or none; and a temporary file left by a process that is gone
(SIGKILL) is removed by the next run, one of a running process kept.

The moment is made exact: the command runs under a hook (:data:`HOOK`) that
stops it as it opens its Nth temporary file and says so, then the signal
is sent."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import FOLDING_LENS, GIT_ENVIRONMENT, ended_pid, git_repository
from lensaudit.console import dispatch

#: Runs `lensaudit ARGS...` as the console command does, stopping for a minute
#: once the HOOK_AT-th temporary file (``*.tmp``) is opened (0: never), after
#: naming it in HOOK_SEEN; every temporary file opened is added to HOOK_SEEN.
HOOK = """\
import builtins, os, runpy, sys, time
seen, stop_at, opened, count = os.environ["HOOK_SEEN"], int(os.environ["HOOK_AT"]), open, [0]
def hooked(file, mode="r", *args, **kwargs):
    stream = opened(file, mode, *args, **kwargs)
    if isinstance(file, (str, os.PathLike)) and str(file).endswith(".tmp") and "r" not in mode:
        count[0] += 1
        with opened(seen, "a") as log:
            log.write(os.fspath(file) + "\\n")
        if count[0] == stop_at:
            with opened(seen + ".stopped", "w"):
                pass
            time.sleep(60)
    return stream
builtins.open = hooked
sys.argv = ["lensaudit", *sys.argv[1:]]
runpy.run_module("lensaudit", run_name="__main__")
"""

ENDINGS = {
    signal.SIGINT: (130, "lensaudit: interrupted"),
    signal.SIGTERM: (143, "lensaudit: terminated"),
}


def hooked_run(tmp_path: Path, words: list, stop_at: int, signum: int | None) -> tuple:
    """Run the command under the hook, send ``signum`` once it stops at its
    ``stop_at``-th temporary file; (completed process, temporary files opened)."""
    hook = tmp_path / "hook.py"
    hook.write_text(HOOK)
    seen = tmp_path / "seen.log"
    seen.unlink(missing_ok=True)
    stopped = Path(f"{seen}.stopped")
    stopped.unlink(missing_ok=True)
    environment = {**os.environ, **GIT_ENVIRONMENT, "HOOK_SEEN": str(seen), "HOOK_AT": str(stop_at)}
    process = subprocess.Popen(
        [sys.executable, str(hook), *map(str, words)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=environment,
    )
    if signum is not None:
        deadline = time.monotonic() + 120
        while not stopped.exists() and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert stopped.exists(), f"the command did not reach temporary file {stop_at}"
        process.send_signal(signum)
    out, err = process.communicate(timeout=120)
    done = subprocess.CompletedProcess(process.args, process.returncode, out, err)
    return done, seen.read_text().splitlines() if seen.exists() else []


def temporaries(*directories: Path) -> list[Path]:
    return [p for d in directories if d.exists() for p in d.rglob("*.tmp")]


def fix_case(tmp_path: Path) -> tuple[list, list[Path], Path]:
    """fix --write of a database in a git checkout (a file left there is one
    git shows as untracked)."""
    repository = git_repository(tmp_path / "lensfun", {"data/db/a.xml": FOLDING_LENS})
    db = repository / "data" / "db"
    return ["fix", "--write", "--tolerance", "5000", db], [db], repository


def report_case(tmp_path: Path) -> tuple[list, list[Path], Path]:
    db = tmp_path / "db"
    db.mkdir()
    (db / "a.xml").write_text(FOLDING_LENS)
    out = tmp_path / "report"
    return ["report", db, "-o", out, "--force"], [out], out


def history_case(tmp_path: Path) -> tuple[list, list[Path], Path]:
    repository = git_repository(tmp_path / "lensfun", {"data/db/a.xml": FOLDING_LENS})
    out = tmp_path / "history"
    return ["history", repository, "-o", out, "-q"], [out], out


def scan_case(tmp_path: Path) -> tuple[list, list[Path], Path]:
    db = tmp_path / "db"
    db.mkdir()
    (db / "a.xml").write_text(FOLDING_LENS)
    out = tmp_path / "out"
    out.mkdir()
    return ["scan", db, "-f", "csv", "-o", out / "scan.csv"], [out], out


CASES = {"fix": fix_case, "report": report_case, "history": history_case, "scan": scan_case}


def snapshot(directory: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(directory)): p.read_bytes()
        for p in sorted(directory.rglob("*"))
        if p.is_file() and ".git" not in p.parts
    }


@pytest.mark.parametrize("command", sorted(CASES))
def test_a_signal_while_writing_leaves_no_temporary_file(tmp_path, command):
    words, watched, outputs = CASES[command](tmp_path)
    cache = tmp_path / "cache"
    words = [*words, "--cache-dir", cache]
    # Every temporary file the command writes, the cache's included, in order.
    first, opened = hooked_run(tmp_path, words, 0, None)
    assert first.returncode == 0, first.stderr
    assert opened and not temporaries(*watched, cache)
    after = snapshot(outputs)
    # Again from the state before (the cache empty, the database as it was).
    for signum in ENDINGS:
        for stop_at in sorted({1, (len(opened) + 1) // 2, len(opened)}):
            run_dir = tmp_path / f"{signum.name}-{stop_at}"
            run_dir.mkdir()
            words, watched, outputs = CASES[command](run_dir)
            cache = run_dir / "cache"
            words = [*words, "--cache-dir", cache]
            before = snapshot(outputs) if outputs.exists() else {}
            done, _ = hooked_run(run_dir, words, stop_at, signum)
            status, line = ENDINGS[signum]
            where = f"{signum.name} at temporary file {stop_at} of {len(opened)}"
            assert done.returncode == status, (where, done.stderr)
            assert done.stderr == line + "\n", where  # one line, no traceback
            assert temporaries(*watched, cache) == [], where
            now = snapshot(outputs) if outputs.exists() else {}
            assert now in (before, after), where  # all of the outputs or none
            if command == "fix":
                untracked = subprocess.run(
                    ["git", "-C", outputs, "status", "--porcelain", "--untracked-files=all"],
                    capture_output=True,
                    text=True,
                    check=True,
                ).stdout
                assert untracked in ("", " M data/db/a.xml\n"), where


def plant(directory: Path, name: str, pid: int) -> Path:
    """A temporary file of lensaudit's naming, for ``name``, of process ``pid``."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f".{name}.{pid}.0.tmp"
    path.write_bytes(b"half written")
    return path


@pytest.mark.parametrize("command", ["fix", "report", "history"])
def test_a_temporary_file_of_a_process_gone_is_removed_by_the_next_run(
    tmp_path, capsys, running_pid, command
):
    words, watched, outputs = CASES[command](tmp_path)
    directory = watched[0]
    name = {"fix": "a.xml", "report": "entries.csv", "history": "history.csv"}[command]
    gone = ended_pid()
    abandoned = [plant(directory, name, gone), plant(directory, "b.xml", gone)]
    writing_now = plant(directory, name, running_pid)  # another run, writing now
    other = directory / f".{name}.tmp"  # not lensaudit's naming: someone else's
    other.write_bytes(b"")
    code = dispatch([str(w) for w in [*words, "--no-cache"]])
    assert code == 0, capsys.readouterr().err
    assert not any(path.exists() for path in abandoned)
    assert writing_now.exists() and other.exists()
