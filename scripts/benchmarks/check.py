"""`lensaudit check` of the whole bundled database beside liblensfun's own load.

Fresh processes, in turns, on the database bundled with lensfunpy: liblensfun
is `python -c "import lensfunpy; lensfunpy.Database()"`; the check reads,
audits (distortion, vignetting and TCA) and judges every file, alone and
with the same database as a directory baseline (every file parsed twice
without the cache). "cold" checks run with --no-cache; "first" checks with
an empty cache directory each time, which they fill; "warm" checks find
every file's bytes in check's cache (a directory primed once by the same
command), and still read and hash every file. The check exits 1 on this
database (it has findings); that is its answer, not a failure. Times are
medians; CPU and peak memory as in the scan section. The in-process rows
time ``lensaudit.check.check()`` alone, without interpreter start-up,
imports or output.
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time

from benchmarks.scan import (
    BASELINE,
    Runs,
    compile_bytecode,
    in_turns,
    lensaudit_command,
    measure,
    ratio_rows,
)

TITLE = "lensaudit check of the whole bundled database vs liblensfun's own load"


def check_command(*arguments: str) -> list[str]:
    """A check that counts as done when it exits 0 (passed) or 1 (findings)."""
    command = lensaudit_command("check", *arguments, "-o", os.devnull)
    return ["sh", "-c", '"$@"; [ $? -le 1 ]', "sh", *command]


def in_process(repeats: int, warm_cache: str) -> dict[str, float]:
    from lensaudit.check import check

    os.environ["LENSAUDIT_CACHE_DIR"] = warm_cache
    check(cache=True)  # imports, the solver's first call, and the cache primed
    times: dict[str, list[float]] = {"cold": [], "warm": []}
    for _ in range(repeats):
        for name, cache in (("cold", False), ("warm", True)):
            start = time.perf_counter()
            check(cache=cache)
            times[name].append(time.perf_counter() - start)
    return {name: statistics.median(values) for name, values in times.items()}


def run(quick: bool) -> list[dict]:
    from lensaudit.read.paths import bundled_database_path

    turns = 5 if quick else 15
    compile_bytecode()
    database = str(bundled_database_path())
    commands = {
        "lensaudit check": check_command(),
        "lensaudit check -f json": check_command("-f", "json"),
        "lensaudit check --baseline (the same directory)": check_command("--baseline", database),
    }
    with tempfile.TemporaryDirectory(prefix="lensaudit-bench-") as scratch:
        runs: Runs = {"liblensfun: lensfunpy.Database()": (BASELINE, "")}
        for index, (name, command) in enumerate(commands.items()):
            warm = os.path.join(scratch, f"warm-{index}")
            runs[f"{name}, cold (--no-cache)"] = (command + ["--no-cache"], "")
            runs[f"{name}, first (empty cache)"] = (command, None)
            runs[f"{name}, warm (cache)"] = (command, warm)
            measure(command, dict(os.environ, LENSAUDIT_CACHE_DIR=warm))  # primes its cache
        rows = ratio_rows(in_turns(runs, turns, scratch))
        inside = in_process(turns, os.path.join(scratch, "in-process"))
    for name, seconds in inside.items():
        rows.append(
            {
                "work": f"lensaudit.check.check(), in-process, {name}",
                "wall s": seconds,
                "CPU s": "",
                "peak MB": "",
                "x liblensfun": "",
            }
        )
    return rows
