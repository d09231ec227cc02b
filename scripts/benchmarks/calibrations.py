"""Vignetting and TCA audits of whole databases: reading, auditing, and the command line.

For the database bundled with lensfunpy and for the head of Lensfun's
history (../shared/data/lensfun-db-history.bundle, cloned into a temporary
directory first, not timed): reading every file's <vignetting> and <tca>
elements, the vignetting audit, the TCA audit, and, in turns with the
distortion scan, fresh ``lensaudit scan --kind ... -f csv`` processes.
In-process times are medians of repeated runs; process times medians of
runs taken in turns.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from benchmarks.scan import lensaudit_command
from lensaudit import calibrations, tca, vignetting
from lensaudit.read.paths import bundled_database_path

TITLE = "calibrations: vignetting and TCA audits of whole databases"

BUNDLE = Path(__file__).resolve().parents[3] / "shared" / "data" / "lensfun-db-history.bundle"


def _median_seconds(work, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        work()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def _command(*arguments: str) -> list[str]:
    return lensaudit_command("scan", *arguments, "-f", "csv", "-o", os.devnull)


def _in_process_rows(name: str, database: Path, repeats: int) -> list[dict]:
    loaded = calibrations.load(database)
    read = _median_seconds(lambda: calibrations.load(database), repeats)
    audit_v = _median_seconds(lambda: vignetting.of_database(loaded), repeats)
    audit_t = _median_seconds(lambda: tca.of_database(loaded), repeats)
    counts = {kind: len(loaded.rows(kind)[1]) for kind in ("vignetting", "tca")}
    rows = []
    for what, entries, seconds in (
        ("read every element (distortion, vignetting, TCA)", sum(counts.values()), read),
        ("audit vignetting", counts["vignetting"], audit_v),
        ("audit TCA", counts["tca"], audit_t),
    ):
        rows.append(
            {
                "database": name,
                "work": what,
                "entries": entries,
                "ms": 1000 * seconds,
                "entries per s": entries / seconds,
            }
        )
    return rows


def _process_rows(name: str, database: Path, turns: int) -> list[dict]:
    kinds = ("distortion", "vignetting", "tca")
    times: dict[str, list[float]] = {kind: [] for kind in kinds}
    with tempfile.TemporaryDirectory(prefix="lensaudit-bench-") as cache:
        environment = dict(os.environ, LENSAUDIT_CACHE_DIR=cache)
        for _ in range(turns):
            for kind in kinds:
                arguments = [str(database), "--kind", kind]
                if kind == "distortion":
                    arguments.append("--no-cache")  # the others have no cache
                started = time.perf_counter()
                subprocess.run(
                    _command(*arguments), check=True, env=environment, stdout=subprocess.DEVNULL
                )
                times[kind].append(time.perf_counter() - started)
    base = statistics.median(times["distortion"])
    return [
        {
            "database": name,
            "work": f"lensaudit scan --kind {kind}, fresh process"
            + (" (--no-cache)" if kind == "distortion" else ""),
            "entries": "",
            "ms": 1000 * statistics.median(times[kind]),
            "entries per s": "",
            "x distortion scan": statistics.median(times[kind]) / base,
        }
        for kind in kinds
    ]


def run(quick: bool) -> list[dict]:
    repeats, turns = (3, 3) if quick else (9, 7)
    databases = [("bundled", bundled_database_path())]
    with tempfile.TemporaryDirectory() as temporary:
        if BUNDLE.exists():
            clone = Path(temporary) / "lensfun"
            subprocess.run(
                ["git", "clone", "-q", str(BUNDLE), str(clone)], check=True, capture_output=True
            )
            databases.append(("Lensfun head", clone / "data" / "db"))
        rows = []
        for name, database in databases:
            rows += _in_process_rows(name, database, repeats)
            rows += _process_rows(name, database, turns)
        if not BUNDLE.exists():
            rows.append({"database": f"Lensfun head skipped: {BUNDLE} not found"})
    # Every row with every key, so that the table prints them all.
    keys = list(dict.fromkeys(k for row in rows for k in row))
    return [{k: row.get(k, "") for k in keys} for row in rows]
