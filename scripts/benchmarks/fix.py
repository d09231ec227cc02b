"""Time to refit every entry of the bundled database that folds inside its image.

Rows, measured in turns, medians of the repetitions:

* ``lensaudit fix`` as a fresh process (empty cache directory, so the
  database is parsed and audited too; nothing written), beside
  ``lensaudit scan --format csv`` under the same conditions: the difference
  is what the refitting costs at the command line, scipy's import included;
* in-process: the whole stage (selection, reading the files, fitting,
  verifying, rounding, building the patches) on an audit already made;
* in-process, per entry: one :func:`lensaudit.fix.fix_entry`, with the
  number of linear programs it solved and the result.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import tempfile
import time

from benchmarks.scan import lensaudit_command

TITLE = "fix: refitting every entry of the bundled database that folds in its image"


def _command(*arguments: str) -> list[str]:
    return lensaudit_command(*arguments)


def _wall_time(command: list[str]) -> float:
    with tempfile.TemporaryDirectory(prefix="lensaudit-bench-") as cache:
        start = time.perf_counter()
        subprocess.run(
            command,
            check=True,
            env=dict(os.environ, LENSAUDIT_CACHE_DIR=cache),
            stdout=subprocess.DEVNULL,
        )
        return time.perf_counter() - start


def run(quick: bool) -> list[dict]:
    from lensaudit import fix, refit
    from lensaudit.pipeline import run as audit_database

    repeats = 3 if quick else 9
    commands = {
        "lensaudit scan --format csv (fresh process)": _command("scan", "-f", "csv"),
        "lensaudit fix (fresh process)": _command("fix"),
    }
    times: dict[str, list[float]] = {name: [] for name in commands}
    times["in-process: fix stage, all folds"] = []
    audit = audit_database()
    fix.fix_audit(audit, fix.select(audit))  # imports scipy once, outside the timings

    def stage() -> list:
        indices = fix.select(audit)
        sources = fix.read_sources(audit, indices)
        found = fix.fix_audit(audit, indices, sources=sources)
        fix.patches(found, sources)
        return found

    for _ in range(repeats):
        for name, command in commands.items():
            times[name].append(_wall_time(command))
        start = time.perf_counter()
        results = stage()
        times["in-process: fix stage, all folds"].append(time.perf_counter() - start)
    rows = [
        {
            "run": name,
            "median s": statistics.median(values),
            "LPs": "",
            "max change px": "",
            "status": f"{sum(r.fixed for r in results)} of {len(results)} fixed"
            if "fix" in name
            else "",
        }
        for name, values in times.items()
    ]

    solved = [0]
    solve = refit._Program.solve

    def counted(self, *args, **kwargs):
        solved[0] += 1
        return solve(self, *args, **kwargs)

    refit._Program.solve = counted
    try:
        for result in results:
            entry_times = []
            for _ in range(repeats):
                solved[0] = 0
                start = time.perf_counter()
                fix.fix_entry(
                    result.entry, texts=dict(zip(result.names, result.old_texts, strict=True))
                )
                entry_times.append(time.perf_counter() - start)
            rows.append(
                {
                    "run": f"  {result.where} ({result.entry.model})",
                    "median s": statistics.median(entry_times),
                    "LPs": solved[0],
                    "max change px": result.max_change_px,
                    "status": result.status,
                }
            )
    finally:
        refit._Program.solve = solve
    return rows
