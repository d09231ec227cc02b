"""Run lensaudit's commands and print the SHA-256 of each output, as JSON.

    python tests/golden/capture.py BUNDLED_DB LENSFUN_CLONE > digests.json

The digests in ``tests/golden/digests.json`` were made by this script with
the code of the commit named there, before the one-reader redesign; the test
``tests/test_golden.py`` runs it with the code of today and compares. An
output that changes on purpose is listed, with why, in that file's
``changed`` and must be captured again.

Outputs that name paths of this machine (the database label, its paths) are
made independent of them first: each database path is replaced by a fixed
name. Nothing with a time stamp is compared (report.html, trend.png/svg).
"""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

#: The report's files that are compared (the rest are figures or hold a time stamp).
REPORT_FILES = (
    "entries.csv",
    "folding.csv",
    "fig5_r_normalized.csv",
    "table1.csv",
    "table2.csv",
    "vignetting.csv",
    "tca.csv",
    "summary.json",
)


def _run(arguments: list[str], cwd: Path) -> subprocess.CompletedProcess:
    environment = {**os.environ, "LC_ALL": "C.UTF-8", "COLUMNS": "200"}
    return subprocess.run(
        [sys.executable, "-m", "lensaudit", *arguments],
        cwd=cwd,
        capture_output=True,
        env=environment,
        check=False,
    )


def _digest(data: bytes, replacements: dict[str, str]) -> str:
    text = data.decode("utf-8")
    for old, new in replacements.items():
        text = text.replace(old, new)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def capture(database: Path, name: str, work: Path, replacements: dict[str, str]) -> dict:
    """Digests of scan (csv, json, vignetting and tca csv), check json and the
    report's CSV and JSON files of one database."""
    found: dict[str, str] = {}
    commands = {
        "scan.csv": ["scan", "--no-cache", "--format", "csv", str(database)],
        "scan.json": ["scan", "--no-cache", "--format", "json", str(database)],
        "scan-vignetting.csv": ["scan", "--kind", "vignetting", "--format", "csv", str(database)],
        "scan-tca.csv": ["scan", "--kind", "tca", "--format", "csv", str(database)],
        "check.json": ["check", "--no-cache", "--format", "json", str(database)],
    }
    for output, arguments in commands.items():
        result = _run(arguments, work)
        found[f"{name}/{output}"] = _digest(result.stdout, replacements)
        found[f"{name}/{output}:exit"] = str(result.returncode)
    report = work / f"report-{name}"
    _run(["report", "-o", str(report), str(database)], work)
    for file in REPORT_FILES:
        path = report / file
        found[f"{name}/report/{file}"] = (
            _digest(path.read_bytes(), replacements) if path.exists() else "missing"
        )
    return found


def capture_history(clone: Path, work: Path) -> dict:
    """Digests of history.csv and introduced.csv of the whole history."""
    out = work / "history"
    _run(["history", "--no-cache", "-q", "-o", str(out), str(clone)], work)
    return {
        f"history/{file}": _digest((out / file).read_bytes(), {})
        for file in ("history.csv", "introduced.csv")
    }


def main() -> int:
    bundled, clone = Path(sys.argv[1]).resolve(), Path(sys.argv[2]).resolve()
    master = clone / "data" / "db"
    with tempfile.TemporaryDirectory() as directory:
        work = Path(directory)
        replacements = {str(bundled): "<bundled>", str(master): "<master>"}
        # The three at once, each its commands one after another (a database's
        # commands share its cache records): what one process leaves idle of
        # the CPUs, another takes.
        with ThreadPoolExecutor(3) as pool:
            parts = [
                pool.submit(capture, bundled, "bundled", work, replacements),
                pool.submit(capture, master, "master", work, replacements),
                pool.submit(capture_history, clone, work),
            ]
            found = {k: v for part in parts for k, v in part.result().items()}
    json.dump(found, sys.stdout, indent=1, sort_keys=True)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
