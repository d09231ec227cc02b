"""`lensaudit report` and `lensaudit plot` on the bundled database, beside liblensfun's own load.

Fresh processes, in turns, as in the scan section. The report writes every
file of its directory (tables, CSV, JSON, Figure 5 as PNG and SVG, the HTML
page), which means auditing distortion, vignetting and TCA and importing
matplotlib. "cold" reports run with --no-cache, "first" with an empty cache
directory each time, "warm" with a cache directory primed once by the same
command. The plots draw one entry (slr-tokina.xml:17, a ptlens model that
folds) with a primed cache. Times are medians; CPU and peak memory as in
the scan section.
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
from pathlib import Path

from benchmarks.scan import BASELINE, compile_bytecode, measure

TITLE = "lensaudit report and plot of the bundled database vs liblensfun's own load"

#: The entry the plots draw.
ENTRY = "slr-tokina.xml:17"


def command(*arguments: str) -> list[str]:
    installed = Path(sys.executable).with_name("lensaudit")
    prefix = [str(installed)] if installed.exists() else [sys.executable, "-m", "lensaudit"]
    return [*prefix, *arguments]


def run(quick: bool) -> list[dict]:
    turns = 3 if quick else 7
    compile_bytecode()
    with tempfile.TemporaryDirectory(prefix="lensaudit-bench-") as scratch:
        report = command("report", "--force", "-o", os.path.join(scratch, "report"))
        warm = os.path.join(scratch, "warm")
        # name -> (command, cache directory: "" for none, None for a new empty one each run)
        runs: dict[str, tuple[list[str], str | None]] = {
            "liblensfun load (lensfunpy.Database)": (BASELINE, ""),
            "report, cold (--no-cache)": (report + ["--no-cache"], ""),
            "report, first (empty cache)": (report, None),
            "report, warm (cache)": (report, warm),
        }
        for kind in ("warp", "curve"):
            image = os.path.join(scratch, f"{kind}.png")
            runs[f"plot {kind} {ENTRY}, warm (cache)"] = (
                command("plot", kind, ENTRY, "-o", image),
                warm,
            )
        for argv, cache in runs.values():
            if cache:  # primes the cache, and checks that the command works
                measure(argv, dict(os.environ, LENSAUDIT_CACHE_DIR=cache))
        results: dict[str, list[tuple[float, float, float]]] = {name: [] for name in runs}
        for _ in range(turns):
            for name, (argv, cache) in runs.items():
                if cache is None:
                    with tempfile.TemporaryDirectory(dir=scratch) as fresh:
                        results[name].append(
                            measure(argv, dict(os.environ, LENSAUDIT_CACHE_DIR=fresh))
                        )
                else:
                    directory = cache or os.path.join(scratch, "unused")
                    results[name].append(
                        measure(argv, dict(os.environ, LENSAUDIT_CACHE_DIR=directory))
                    )
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
    return rows
