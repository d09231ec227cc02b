"""The Lensfun database's whole git history: incremental audit vs every revision from scratch.

The incremental audit (``lensaudit history``) parses each distinct file
version once; the naive way audits every revision that changes the database
in full (read its files through git, parse, audit). The naive way is timed
on revisions spread evenly over the history and extrapolated to all of them.
Needs ../shared/data/lensfun-db-history.bundle beside the project (cloned
into a temporary directory first, not timed).
"""

from __future__ import annotations

import subprocess
import tempfile
import time
from pathlib import Path

from lensaudit.history import audit_history, audit_revision

TITLE = "history: whole Lensfun DB history, incremental vs each revision from scratch"

BUNDLE = Path(__file__).resolve().parents[3] / "shared" / "data" / "lensfun-db-history.bundle"


def _row(method: str, revisions: int, seconds: float, total: float, baseline: float) -> dict:
    return {
        "method": method,
        "revisions": revisions,
        "seconds": seconds,
        "ms per revision": 1000 * seconds / revisions,
        "seconds, all revisions": total,
        "x incremental": total / baseline,
    }


def run(quick: bool) -> list[dict]:
    if not BUNDLE.exists():
        return [{"method": f"skipped: {BUNDLE} not found"}]
    with tempfile.TemporaryDirectory() as temporary:
        repository = Path(temporary) / "lensfun-db.git"
        subprocess.run(
            ["git", "clone", "-q", "--bare", str(BUNDLE), str(repository)],
            check=True,
            capture_output=True,
        )
        started = time.perf_counter()
        history = audit_history(repository)
        cold = time.perf_counter() - started
        count = len(history.revisions)
        rows = [
            _row(
                f"incremental, {history.blobs_parsed} file versions parsed", count, cold, cold, cold
            )
        ]
        if not quick:
            cache = Path(temporary) / "cache"
            audit_history(repository, cache_dir=cache)
            started = time.perf_counter()
            warm = audit_history(repository, cache_dir=cache)
            seconds = time.perf_counter() - started
            rows.append(
                _row(
                    f"incremental, disk cache ({warm.blobs_cached} cached)",
                    count,
                    seconds,
                    seconds,
                    cold,
                )
            )
        samples = 5 if quick else 20
        step = max(1, count // samples)
        chosen = [r.commit.hash for r in history.revisions[step // 2 :: step]][:samples]
        started = time.perf_counter()
        for commit in chosen:
            audit_revision(repository, commit)
        seconds = time.perf_counter() - started
        rows.append(
            _row(
                f"from scratch, {len(chosen)} revisions timed, extrapolated",
                len(chosen),
                seconds,
                seconds / len(chosen) * count,
                cold,
            )
        )
    return rows
