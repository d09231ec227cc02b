"""Peak memory against the size of the largest input file.

One file of growing size, made of the bundled database's lenses repeated,
read by `lensaudit scan --no-cache` and `lensaudit check --no-cache` in a
fresh process; "x file" is the process's peak resident size over the
file's size (the goal: at most 8x). The reader parses a file as a stream
of its top-level elements, so that it holds one `<lens>` at a time.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path

from benchmarks.scan import compile_bytecode, lensaudit_command, measure

TITLE = "Peak memory vs the largest input file (fresh processes, --no-cache)"

SIZES_MB = (20, 50, 200)
GOAL = 8.0


def build(path: Path, source: Path, megabytes: int) -> int:
    """A database file of about ``megabytes`` MB, of the lenses of ``source``; its size."""
    bodies = []
    for file in sorted(source.glob("*.xml")):
        data = file.read_bytes()
        start = data.index(b">", data.index(b"<lensdatabase")) + 1
        bodies.append(data[start : data.rindex(b"</lensdatabase>")])
    body = b"".join(bodies)
    copies = max(1, megabytes * 1_000_000 // len(body))
    with open(path, "wb") as stream:
        stream.write(b'<lensdatabase version="2">')
        for _ in range(copies):
            stream.write(body)
        stream.write(b"</lensdatabase>\n")
    return path.stat().st_size


def run(quick: bool) -> list[dict]:
    from lensaudit.read.paths import bundled_database_path

    compile_bytecode()
    scratch = Path(tempfile.mkdtemp(prefix="lensaudit-bench-"))
    rows = []
    try:
        environment = dict(os.environ, LENSAUDIT_CACHE_DIR=str(scratch / "cache"))
        baseline = measure([sys.executable, "-c", "import lensaudit.read, lxml.etree"], environment)
        for megabytes in SIZES_MB[:2] if quick else SIZES_MB:
            database = scratch / f"db-{megabytes}"
            database.mkdir()
            size = build(database / "big.xml", bundled_database_path(), megabytes)
            for command in ("scan", "check"):
                arguments = [command, "--no-cache", str(database)]
                if command == "scan":
                    arguments += ["-f", "csv", "-o", os.devnull]
                wall, _, peak = measure(lensaudit_command(*arguments), environment, check=False)
                ratio = peak * 2**20 / size
                rows.append(
                    {
                        "work": f"{command}, one file of {size / 1e6:.0f} MB",
                        "seconds": wall,
                        "peak MB": peak,
                        "x file": ratio,
                        "goal": f"<= {GOAL:g}x",
                        "met": "yes" if ratio <= GOAL else "NO",
                    }
                )
            shutil.rmtree(database)
        rows.append({"work": "(Python, lensaudit.read and lxml imported)", "peak MB": baseline[2]})
        return rows
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
