"""The console command (``lensaudit`` / ``python -m lensaudit``) as a shell runs it.

The command ends its process without Python's teardown once its output is
flushed; these tests check that nothing is lost that way: the whole output,
the exit status, and a quiet end when the reader goes away.
"""

from __future__ import annotations

import array
import fcntl
import os
import subprocess
import sys
import termios
import time
import xml.etree.ElementTree as ElementTree
from collections.abc import Callable
from pathlib import Path

import pytest

from conftest import lens_xml

#: More bytes than the CSV header line of a scan.
HEADER_BYTES = 4096

# A poly3 model with k1 = -0.5 peaks at r = sqrt(1 / 1.5) = 0.816 (D' = 1 - 3 * 0.5 r^2):
# inside the 3:2 frame's corner at hypot(1.5, 1) = 1.80, so `check` finds it folds.
FOLDING = '<distortion model="poly3" focal="10" k1="-0.5"/>'


def run(*arguments: str, **options) -> subprocess.CompletedProcess:
    environment = {**os.environ, "PYTHONWARNINGS": "error"}
    return subprocess.run(
        [sys.executable, "-m", "lensaudit", *arguments],
        capture_output=True,
        env=environment,
        timeout=120,
        **options,
    )


def distortion_count(directory: Path) -> int:
    """<distortion> elements under a database directory, by the standard library's parser."""
    return sum(
        sum(1 for _ in ElementTree.parse(path).getroot().iter("distortion"))
        for path in sorted(directory.glob("*.xml"))
    )


def test_whole_csv_reaches_a_pipe(bundled_db: Path) -> None:
    result = run("scan", "--no-cache", "-f", "csv", str(bundled_db))
    assert result.returncode == 0, result.stderr
    lines = result.stdout.decode().splitlines()
    assert len(lines) == 1 + distortion_count(bundled_db)
    assert lines[-1].count(",") >= lines[0].count(",")  # the last row is whole


def test_output_file_is_whole(bundled_db: Path, tmp_path: Path) -> None:
    target = tmp_path / "entries.csv"
    result = run("scan", "-f", "csv", "-o", str(target), str(bundled_db))
    assert result.returncode == 0, result.stderr
    assert len(target.read_text().splitlines()) == 1 + distortion_count(bundled_db)


def test_exit_statuses_are_kept(write_xml: Callable[..., Path], tmp_path: Path) -> None:
    folding = write_xml(lens_xml(FOLDING), "folding.xml")
    result = run("check", "--format", "text", str(folding))
    assert result.returncode == 1, result.stderr
    assert b"fold" in result.stdout
    missing = tmp_path / "missing"
    result = run("scan", str(missing))
    assert result.returncode == 2
    assert result.stderr.decode().strip().endswith("no such file or directory")
    assert run("--version").returncode == 0
    assert run("scan", "--no-such-option").returncode == 2


def unread(stream) -> int:
    """Bytes waiting in the pipe ``stream`` reads."""
    count = array.array("i", [0])
    fcntl.ioctl(stream.fileno(), termios.FIONREAD, count)
    return count[0]


@pytest.mark.parametrize("when", ["before the output", "during a write"])
def test_reader_that_goes_away_ends_quietly(bundled_db: Path, when: str) -> None:
    # "during a write": the pipe is full, so the command is held inside one
    # write (the CSV is a megabyte, its rows written at once) when the reader
    # takes a line and goes: what that write did not pass on is lost, and the
    # status must say so. "before the output": the reader is gone first.
    command = [
        sys.executable,
        "-m",
        "lensaudit",
        "scan",
        "--no-cache",
        "-f",
        "csv",
        str(bundled_db),
    ]
    with subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE) as process:
        assert process.stdout is not None and process.stderr is not None
        if when == "during a write":
            # More than the header in the pipe: the rows' one write has begun,
            # and cannot end (a megabyte) before the pipe is read.
            deadline = time.monotonic() + 120
            while unread(process.stdout) <= HEADER_BYTES:
                assert process.poll() is None and time.monotonic() < deadline
                time.sleep(0.005)
            process.stdout.readline()
        process.stdout.close()  # the reader is gone, as `| head -1` goes
        error = process.stderr.read()
        status = process.wait(timeout=120)
    assert status == 1
    assert error == b""
