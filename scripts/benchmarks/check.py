"""`lensaudit check` of the whole bundled database beside liblensfun's own load.

Fresh processes, in turns, on the database bundled with lensfunpy: liblensfun
is `python -c "import lensfunpy; lensfunpy.Database()"`; the check reads,
audits (distortion, vignetting and TCA) and judges every file, alone and
with the same database as a directory baseline (every file parsed twice).
The check exits 1 on this database (it has findings); that is its answer,
not a failure. Times are medians; CPU and peak memory as in the scan
section. The in-process row times ``lensaudit.check.check()`` alone,
without interpreter start-up, imports or output.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.scan import BASELINE, compile_bytecode, measure

TITLE = "lensaudit check of the whole bundled database vs liblensfun's own load"


def check_command(*arguments: str) -> list[str]:
    """A check that counts as done when it exits 0 (passed) or 1 (findings)."""
    installed = Path(sys.executable).with_name("lensaudit")
    prefix = [str(installed)] if installed.exists() else [sys.executable, "-m", "lensaudit"]
    command = [*prefix, "check", *arguments, "-o", os.devnull]
    return ["sh", "-c", '"$@"; [ $? -le 1 ]', "sh", *command]


def in_process(repeats: int) -> float:
    from lensaudit.check import check

    check()  # imports, and the solver's first call
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        check()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def run(quick: bool) -> list[dict]:
    from lensaudit.database import bundled_database_path

    turns = 5 if quick else 15
    compile_bytecode()
    database = str(bundled_database_path())
    runs = {
        "liblensfun: lensfunpy.Database()": BASELINE,
        "lensaudit check": check_command(),
        "lensaudit check -f json": check_command("-f", "json"),
        "lensaudit check --baseline (the same directory)": check_command("--baseline", database),
    }
    results: dict[str, list[tuple[float, float, float]]] = {name: [] for name in runs}
    with tempfile.TemporaryDirectory(prefix="lensaudit-bench-") as cache:
        env = dict(os.environ, LENSAUDIT_CACHE_DIR=cache)
        for _ in range(turns):
            for name, command in runs.items():
                results[name].append(measure(command, env))
    base = statistics.median(r[0] for r in results[next(iter(runs))])
    rows = []
    for name, measured in results.items():
        wall = statistics.median(r[0] for r in measured)
        rows.append(
            {
                "work": name,
                "wall s": wall,
                "CPU s": statistics.median(r[1] for r in measured),
                "peak MB": statistics.median(r[2] for r in measured),
                "x liblensfun": wall / base,
            }
        )
    seconds = in_process(turns)
    rows.append(
        {
            "work": "lensaudit.check.check(), in-process",
            "wall s": seconds,
            "CPU s": "",
            "peak MB": "",
            "x liblensfun": "",
        }
    )
    return rows
