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
import tempfile

from benchmarks.scan import (
    BASELINE,
    Runs,
    compile_bytecode,
    in_turns,
    lensaudit_command,
    measure,
    ratio_rows,
)

TITLE = "lensaudit report and plot of the bundled database vs liblensfun's own load"

#: The entry the plots draw.
ENTRY = "slr-tokina.xml:17"


def run(quick: bool) -> list[dict]:
    turns = 3 if quick else 7
    compile_bytecode()
    with tempfile.TemporaryDirectory(prefix="lensaudit-bench-") as scratch:
        report = lensaudit_command("report", "--force", "-o", os.path.join(scratch, "report"))
        warm = os.path.join(scratch, "warm")
        runs: Runs = {
            "liblensfun load (lensfunpy.Database)": (BASELINE, ""),
            "report, cold (--no-cache)": (report + ["--no-cache"], ""),
            "report, first (empty cache)": (report, None),
            "report, warm (cache)": (report, warm),
        }
        for kind in ("warp", "curve"):
            image = os.path.join(scratch, f"{kind}.png")
            runs[f"plot {kind} {ENTRY}, warm (cache)"] = (
                lensaudit_command("plot", kind, ENTRY, "-o", image),
                warm,
            )
        for argv, cache in runs.values():
            if cache:  # primes the cache, and checks that the command works
                measure(argv, dict(os.environ, LENSAUDIT_CACHE_DIR=cache))
        return ratio_rows(in_turns(runs, turns, scratch))
