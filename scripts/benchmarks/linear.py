"""`lensaudit scan -f csv` on databases of 1, 4, 16 and 64 copies of the bundled one:
time and memory per entry must not grow with the database.

Each copy of a file is the same XML under a new name, in one directory.
"cold" scans parse and audit every file (--no-cache), "first" scans do the
same into an empty cache, "warm" scans find every file in the cache. Fresh
processes, in turns, medians; CPU time counts the worker processes a scan
forks, and peak memory is that of the largest process. The cache is bounded
to 64 MiB; here its bound is raised so that the largest database (about
230 MB of cache) is cached at all, as the point is how the cost grows.
"""

from __future__ import annotations

import os
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

from benchmarks.scan import compile_bytecode, measure

TITLE = "Cost per entry as the database grows (scan -f csv, copies of the bundled database)"

COPIES = (1, 4, 16, 64)
# The lensaudit command, with the cache's size bound out of the way.
LAUNCH = (
    "import lensaudit.read.cache\n"
    "lensaudit.read.cache.MAX_BYTES = 1 << 40\n"
    "from lensaudit.console import run\n"
    "run()\n"
)


def build(directory: Path, source: Path, copies: int) -> int:
    """``copies`` copies of every XML file of ``source`` in ``directory``; entries made."""
    directory.mkdir()
    entries = 0
    for file in sorted(source.glob("*.xml")):
        data = file.read_bytes()
        for copy in range(copies):
            (directory / f"{file.stem}-{copy:02d}.xml").write_bytes(data)
        entries += data.count(b"<distortion") * copies
    return entries


def run(quick: bool) -> list[dict]:
    from lensaudit.read.paths import bundled_database_path

    repeats = 1 if quick else 3
    compile_bytecode()
    source = bundled_database_path()
    scratch = Path(tempfile.mkdtemp(prefix="lensaudit-linear-"))
    rows = []
    try:
        for copies in COPIES:
            database = scratch / f"db-{copies}"
            entries = build(database, source, copies)
            scan = [sys.executable, "-c", LAUNCH, "scan", str(database), "-f", "csv"]
            scan += ["-o", os.devnull]
            warm = scratch / f"warm-{copies}"
            runs = {
                "cold": (scan + ["--no-cache"], str(scratch / "unused")),
                "first": (scan, None),
                "warm": (scan, str(warm)),
            }
            measure(scan, dict(os.environ, LENSAUDIT_CACHE_DIR=str(warm)))  # primes it
            samples: dict[str, list] = {name: [] for name in runs}
            for _ in range(repeats):
                for name, (command, cache) in runs.items():
                    with tempfile.TemporaryDirectory(dir=scratch) as fresh:
                        env = dict(os.environ, LENSAUDIT_CACHE_DIR=cache or fresh)
                        samples[name].append(measure(command, env))
            for name, values in samples.items():
                wall, cpu, peak = (statistics.median(v) for v in zip(*values, strict=True))
                rows.append(
                    {
                        "copies": copies,
                        "entries": entries,
                        "run": name,
                        "median s": wall,
                        "us/entry": 1e6 * wall / entries,
                        "CPU us/entry": 1e6 * cpu / entries,
                        "peak MB": peak,
                        "peak KB/entry": 1024 * peak / entries,
                    }
                )
            shutil.rmtree(database)
            shutil.rmtree(warm, ignore_errors=True)
        return rows
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
