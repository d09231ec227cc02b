"""A/B of every speed mechanism that is left: each one switched off alone.

A mechanism stays only where it saves at least 5% of a cold or a warm scan.
Each row is `lensaudit scan` of the bundled database run with one mechanism
switched off by the launcher (a patch applied before the command runs; the
code itself has no switch), beside the same scan with everything on, in
turns, in fresh processes; cold is --no-cache, warm finds every file in a
primed cache. "saves" is the share of the time with the mechanism off that
it saves.

- parallel parse: files parsed on every core (lensaudit.read.parallel);
- scalar kernel: the solver's plain-Python kernel answers the scan without
  numpy (lensaudit.solver.kernel);
- scan without click: a plain scan's command line read without building the
  click group (lensaudit.console.scan_arguments);
- no teardown: the process ends with os._exit once its output is flushed;
- gc off: the cycle collector paused during the scan;
- float texts by value: a column's repeated floats written once
  (lensaudit.columns.float_texts).
"""

from __future__ import annotations

import os
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

from benchmarks.scan import compile_bytecode, measure

TITLE = "Speed mechanisms: a scan of the bundled database with each one off (A/B, in turns)"

_RUN = "import sys\nfrom lensaudit.console import run\nrun()\n"
#: Mechanism -> the patch that switches it off.
SWITCHES = {
    "(all on)": "",
    "parallel parse": "import lensaudit.read.parallel as p\np.MIN_BYTES = 1 << 62\n",
    "scalar kernel": (
        "import lensaudit.solver.kernel as k\n"
        "k.column_metrics = lambda columns, audited, memo=None: None\n"
    ),
    "scan without click": "import lensaudit.console as c\nc.scan_arguments = lambda words: None\n",
    "no teardown": (
        "import lensaudit.console as c, sys\n"
        "def run():\n"
        "    code = c.dispatch(sys.argv[1:])\n"
        "    sys.stdout.flush()\n"
        "    sys.exit(code)\n"
        "c.run = run\n"
    ),
    "gc off": "import gc\ngc.disable = lambda: None\n",
    "float texts by value": (
        "import lensaudit.columns as m\n"
        "def float_texts(values, special=None):\n"
        "    texts = list(map(repr, values))\n"
        "    return [special.get(t, t) for t in texts] if special else texts\n"
        "m.float_texts = float_texts\n"
    ),
}


def command(patch: str, *arguments: str) -> list[str]:
    return [sys.executable, "-c", patch + _RUN, "scan", *arguments, "-o", os.devnull]


def run(quick: bool) -> list[dict]:
    turns = 5 if quick else 15
    compile_bytecode()
    scratch = Path(tempfile.mkdtemp(prefix="lensaudit-bench-"))
    try:
        warm = str(scratch / "warm")
        env = dict(os.environ)
        cold_env = dict(env, LENSAUDIT_CACHE_DIR=str(scratch / "unused"))
        warm_env = dict(env, LENSAUDIT_CACHE_DIR=warm)
        rows = []
        for output_format in ("table", "csv", "json"):
            measure(command("", "-f", output_format), warm_env)  # primes the cache
            times: dict[tuple[str, str], list[float]] = {}
            for _ in range(turns):
                for name, patch in SWITCHES.items():
                    for kind, extra, environment in (
                        ("cold", ["--no-cache"], cold_env),
                        ("warm", [], warm_env),
                    ):
                        arguments = ["-f", output_format, *extra]
                        wall = measure(command(patch, *arguments), environment)[0]
                        times.setdefault((name, kind), []).append(wall)
            medians = {key: statistics.median(values) for key, values in times.items()}
            for name in SWITCHES:
                row = {"format": output_format, "switched off": name}
                for kind in ("cold", "warm"):
                    off, on = medians[(name, kind)], medians[("(all on)", kind)]
                    row[f"{kind} s"] = off
                    row[f"{kind} saves"] = f"{(off - on) / off:+.0%}" if name != "(all on)" else ""
                rows.append(row)
        return rows
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
