"""End-to-end `lensaudit scan --format csv` beside liblensfun loading the same database.

Both run as fresh processes, in turns, on the database bundled with
lensfunpy: liblensfun's own load is `python -c "import lensfunpy;
lensfunpy.Database()"`. "cold" scans parse and audit every file (--no-cache);
"first" scans do the same with an empty cache directory each time, and write
the cache; "warm" scans find the files unchanged in lensaudit's cache of
parsed and audited files (a fresh cache directory, primed once), which still
reads and hashes every file. Times are medians;
memory is the peak resident size.
In-process rows time the same work without interpreter start-up and imports.
"""

from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TITLE = "Whole bundled database: lensaudit scan vs liblensfun's own load"

BASELINE = [sys.executable, "-c", "import lensfunpy; lensfunpy.Database()"]


def scan_command() -> list[str]:
    installed = Path(sys.executable).with_name("lensaudit")
    prefix = [str(installed)] if installed.exists() else [sys.executable, "-m", "lensaudit"]
    return prefix + ["scan", "--format", "csv", "-o", os.devnull]


def wall_time(command: list[str], env: dict[str, str], empty_cache: bool = False) -> float:
    """Seconds one run of ``command`` takes; ``empty_cache`` gives it a new cache directory."""
    if empty_cache:
        with tempfile.TemporaryDirectory(prefix="lensaudit-bench-") as fresh:
            return wall_time(command, dict(env, LENSAUDIT_CACHE_DIR=fresh))
    start = time.perf_counter()
    subprocess.run(command, check=True, env=env, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def peak_memory_mb(command: list[str], env: dict[str, str], empty_cache: bool = False) -> float:
    """Peak resident size of one run of ``command``, in MB."""
    if empty_cache:
        with tempfile.TemporaryDirectory(prefix="lensaudit-bench-") as fresh:
            return peak_memory_mb(command, dict(env, LENSAUDIT_CACHE_DIR=fresh))
    probe = (
        "import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, "
        "stdout=subprocess.DEVNULL); "
        "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)"
    )
    out = subprocess.run(
        [sys.executable, "-c", probe, *command], check=True, env=env, capture_output=True, text=True
    ).stdout
    return int(out.strip()) / 1024


def in_process(repeats: int) -> dict[str, float]:
    import lensfunpy

    from lensaudit.pipeline import run

    times: dict[str, list[float]] = {"liblensfun": [], "cold": [], "first": [], "warm": []}
    primed = os.environ["LENSAUDIT_CACHE_DIR"]
    run(cache=True)
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(prefix="lensaudit-bench-") as fresh:
            os.environ["LENSAUDIT_CACHE_DIR"] = fresh
            start = time.perf_counter()
            run(cache=True)
            times["first"].append(time.perf_counter() - start)
            os.environ["LENSAUDIT_CACHE_DIR"] = primed
        start = time.perf_counter()
        lensfunpy.Database()
        times["liblensfun"].append(time.perf_counter() - start)
        start = time.perf_counter()
        run(cache=False)
        times["cold"].append(time.perf_counter() - start)
        start = time.perf_counter()
        run(cache=True)
        times["warm"].append(time.perf_counter() - start)
    return {k: statistics.median(v) for k, v in times.items()}


def run(quick: bool) -> list[dict]:
    repeats = 5 if quick else 15
    cache = tempfile.mkdtemp(prefix="lensaudit-bench-")
    env = dict(os.environ, LENSAUDIT_CACHE_DIR=cache)
    try:
        scan = scan_command()
        commands = {
            "liblensfun load (lensfunpy.Database)": BASELINE,
            "lensaudit scan, cold (--no-cache)": scan + ["--no-cache"],
            "lensaudit scan, first (empty cache)": scan,
            "lensaudit scan, warm (cache)": scan,
        }
        wall_time(scan, env)  # primes the cache
        times: dict[str, list[float]] = {name: [] for name in commands}
        for _ in range(repeats):
            for name, command in commands.items():
                times[name].append(wall_time(command, env, empty_cache="first" in name))
        medians = {name: statistics.median(values) for name, values in times.items()}
        baseline = medians["liblensfun load (lensfunpy.Database)"]
        rows = [
            {
                "run": name,
                "median s": medians[name],
                "vs liblensfun": medians[name] / baseline,
                "peak MB": peak_memory_mb(command, env, empty_cache="first" in name),
            }
            for name, command in commands.items()
        ]
        os.environ["LENSAUDIT_CACHE_DIR"] = cache
        inside = in_process(repeats)
        for name, label in (
            ("liblensfun", "in-process: liblensfun load"),
            ("cold", "in-process: lensaudit load + audit, cold"),
            ("first", "in-process: lensaudit load + audit, first (empty cache)"),
            ("warm", "in-process: lensaudit load + audit, warm"),
        ):
            rows.append(
                {
                    "run": label,
                    "median s": inside[name],
                    "vs liblensfun": inside[name] / inside["liblensfun"],
                    "peak MB": "",
                }
            )
        return rows
    finally:
        shutil.rmtree(cache, ignore_errors=True)
