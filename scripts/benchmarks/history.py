"""The Lensfun database's whole git history: ``lensaudit history``, cold and warm,
against a cold ``lensaudit scan`` of one revision, and against auditing
every revision from scratch.

Every command runs in a fresh process, in turns, and the medians are shown
with their ratio to the anchor: a cold ``lensaudit scan --no-cache`` of the
head revision's ``data/db``. "cold" is ``lensaudit history`` with an empty
cache, "warm" the same run again, "one new commit" a run whose cache holds
the history up to the parent of the head. Each of the history's memos (the
reader's memo of pieces, :class:`lensaudit.read.Pieces`, whole; its use of
the last document read; the summary of each piece; the solver's memo of
entries) is switched off in turn by a patch for an A/B of "cold"; "saves"
is the share of that time the memo saves. The naive way (read each revision
through git, parse, audit) is timed in-process on revisions spread evenly
over the history and extrapolated to all of them. Needs
../shared/data/lensfun-db-history.bundle beside the project (cloned into a
temporary directory first, not timed).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.scan import lensaudit_command
from lensaudit.history import audit_history, audit_revision

TITLE = "history: whole Lensfun DB history (fresh processes; x = times a cold scan of the head)"

BUNDLE = Path(__file__).resolve().parents[3] / "shared" / "data" / "lensfun-db-history.bundle"

#: The goals, as multiples of a cold scan of one revision (cold: issue 22's, which was 25x before).
GOALS = {"cold": 10.0, "warm": 5.0}

_RUN = "from lensaudit.console import run\nrun()\n"
#: The history's memos, each switched off by a patch (the A/B of "cold").
SWITCHES = {
    # Every version read whole: no piece is kept, nor summarized on its own.
    "piece memo": "import lensaudit.read.xml as x\nx.Pieces._scan = lambda *a: None\n",
    # Each version scanned from its start, none taken from the last one.
    "last-document memo": (
        "import lensaudit.read.xml as x\n"
        "x._common_prefix = lambda a, b: 0\n"
        "x._common_suffix = lambda a, b, limit: 0\n"
    ),
    # A piece's summary made again for each version that holds it.
    "summary memo": "import lensaudit.history.versions as v\nv.MEMO_PIECES = -1\n",
    "solver memo": (
        "import lensaudit.history.versions as v\n"
        "real_file, real_columns = v.file_metrics, v.metric_columns\n"
        "v.file_metrics = lambda tables, cache, memo=None: real_file(tables, cache)\n"
        "v.metric_columns = lambda columns, memo=None: real_columns(columns)\n"
    ),
}


def _command(*arguments: str, patch: str = "") -> list[str]:
    if patch:
        return [sys.executable, "-c", patch + _RUN, *arguments]
    return lensaudit_command(*arguments)


def _timed(arguments: list[str], environment: dict[str, str], patch: str = "") -> float:
    started = time.perf_counter()
    subprocess.run(
        _command(*arguments, patch=patch),
        check=True,
        env=environment,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    return time.perf_counter() - started


def run(quick: bool) -> list[dict]:
    if not BUNDLE.exists():
        return [{"method": f"skipped: {BUNDLE} not found"}]
    with tempfile.TemporaryDirectory() as temporary:
        work = Path(temporary)
        clone = work / "lensfun-db"
        subprocess.run(
            ["git", "clone", "-q", str(BUNDLE), str(clone)], check=True, capture_output=True
        )
        environment = dict(os.environ, LENSAUDIT_CACHE_DIR=str(work / "unused-cache"))
        out = str(work / "out")
        history = ["history", str(clone), "-o", out, "-q", "--cache-dir"]
        times: dict[str, list[float]] = {"scan": [], "cold": [], "warm": [], "new": []}
        times |= {name: [] for name in SWITCHES}
        for turn in range(3 if quick else 5):
            times["scan"].append(
                _timed(
                    [
                        "scan",
                        "--no-cache",
                        str(clone / "data" / "db"),
                        "-f",
                        "csv",
                        "-o",
                        out + ".csv",
                    ],
                    environment,
                )
            )
            cache = str(work / f"cache-{turn}")
            if turn < (1 if quick else 3):
                times["cold"].append(_timed([*history, cache], environment))
            else:
                _timed([*history, cache], environment)
            times["warm"].append(_timed([*history, cache], environment))
            for name, patch in SWITCHES.items():
                if turn < (1 if quick else 3):
                    off = str(work / f"cache-{name.replace(' ', '-')}-{turn}")
                    times[name].append(_timed([*history, off], environment, patch))
            if turn < (1 if quick else 3):
                parent = str(work / f"cache-parent-{turn}")
                _timed([*history, parent, "--rev", "HEAD~1"], environment)
                times["new"].append(_timed([*history, parent], environment))
        scan = statistics.median(times["scan"])
        cold = statistics.median(times["cold"])
        labels = {
            "scan": "lensaudit scan --no-cache, head revision (the anchor)",
            "cold": "lensaudit history, empty cache",
            "warm": "lensaudit history again (warm)",
            "new": "lensaudit history, cache up to the head's parent",
            **{name: f"lensaudit history, empty cache, {name} off (A/B)" for name in SWITCHES},
        }
        rows = []
        for key, label in labels.items():
            seconds = statistics.median(times[key])
            goal = GOALS.get(key)
            rows.append(
                {
                    "method": label,
                    "runs": len(times[key]),
                    "seconds": seconds,
                    "x scan": seconds / scan,
                    "goal": f"<= {goal:g}x" if goal else "",
                    "met": ("yes" if seconds / scan <= goal else "NO") if goal else "",
                    "saves": f"{1 - cold / seconds:.0%}" if key in SWITCHES else "",
                }
            )

        result = audit_history(clone)
        count = len(result.revisions)
        samples = 5 if quick else 20
        step = max(1, count // samples)
        chosen = [r.commit.hash for r in result.revisions[step // 2 :: step]][:samples]
        started = time.perf_counter()
        for commit in chosen:
            audit_revision(clone, commit)
        each = (time.perf_counter() - started) / len(chosen)
        rows.append(
            {
                "method": f"every one of {count:,} revisions from scratch "
                f"(in-process, {len(chosen)} timed, extrapolated)",
                "runs": 1,
                "seconds": each * count,
                "x scan": each * count / scan,
                "goal": "",
                "met": "",
                "saves": "",
            }
        )
    return rows
