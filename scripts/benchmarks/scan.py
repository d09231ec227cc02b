"""End-to-end `lensaudit scan`, every output format, beside liblensfun loading the same database.

Everything runs as fresh processes, in turns, on the database bundled with
lensfunpy: liblensfun's own load is `python -c "import lensfunpy;
lensfunpy.Database()"`. "cold" scans parse and audit every file
(--no-cache); "first" scans do the same with an empty cache directory each
time, and write the cache; "warm" scans find the files unchanged in
lensaudit's cache (a cache directory primed once by the same command), which
still reads and hashes every file. Output goes to /dev/null.

Times are medians; "CPU s" is the median user + system time of the process
and the worker processes it forks; "peak MB" is the largest resident size of
any one of them (workers share most of their memory with the scan that
forked them). lensaudit's bytecode is compiled first, as pip does when it
installs a package (PYTHONDONTWRITEBYTECODE would otherwise have every run
compile it from source). In-process rows time pipeline.run() alone, without
interpreter start-up, imports or output.
"""

from __future__ import annotations

import compileall
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TITLE = "Whole bundled database: lensaudit scan vs liblensfun's own load"

BASELINE = [sys.executable, "-c", "import lensfunpy; lensfunpy.Database()"]
FORMATS = ("table", "csv", "json")


def lensaudit_command(*arguments: str) -> list[str]:
    """The installed ``lensaudit`` command (as a user runs it) with ``arguments``."""
    installed = Path(sys.executable).with_name("lensaudit")
    prefix = [str(installed)] if installed.exists() else [sys.executable, "-m", "lensaudit"]
    return [*prefix, *arguments]


def scan_command(output_format: str) -> list[str]:
    return lensaudit_command("scan", "--format", output_format, "-o", os.devnull)


def compile_bytecode() -> None:
    """Compile lensaudit's modules, as an installed package has them."""
    import lensaudit

    compileall.compile_dir(Path(lensaudit.__file__).parent, quiet=1)


# A small process starts each measured run and reports it: Linux carries a
# process's peak resident size over into the children it forks (and across
# their exec), so runs forked from this process, which holds the solver
# section's arrays, would all report this process's peak instead of theirs.
_LAUNCHER = (
    "import os, subprocess, sys, time\n"
    "start = time.perf_counter()\n"
    "child = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL)\n"
    "_, status, usage = os.wait4(child.pid, 0)\n"
    "wall = time.perf_counter() - start\n"
    "print(wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024,"
    " os.waitstatus_to_exitcode(status))\n"
)


def measure(
    command: list[str], env: dict[str, str], check: bool = True
) -> tuple[float, float, float]:
    """Wall seconds, CPU seconds (with waited-for children) and peak MB of one run;
    with ``check``, a run that does not exit 0 is an error."""
    report = subprocess.run(
        [sys.executable, "-c", _LAUNCHER, *command],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    wall, cpu, peak, returncode = (
        float(report[0]),
        float(report[1]),
        float(report[2]),
        int(report[3]),
    )
    if check and returncode != 0:
        raise subprocess.CalledProcessError(returncode, command)
    return wall, cpu, peak


#: Commands to time, by name: (command, cache directory: "" for none, None
#: for a new empty one each run, else that directory).
Runs = dict[str, tuple[list[str], "str | None"]]


def in_turns(runs: Runs, turns: int, scratch: str) -> dict[str, list[tuple[float, float, float]]]:
    """(wall, CPU, peak MB) of each command of ``runs``, run ``turns`` times in
    turns, with ``$LENSAUDIT_CACHE_DIR`` as its entry says (new directories in
    ``scratch``)."""
    results: dict[str, list[tuple[float, float, float]]] = {name: [] for name in runs}
    for _ in range(turns):
        for name, (command, cache) in runs.items():
            if cache is None:
                with tempfile.TemporaryDirectory(dir=scratch) as fresh:
                    results[name].append(
                        measure(command, dict(os.environ, LENSAUDIT_CACHE_DIR=fresh))
                    )
            else:
                directory = cache or os.path.join(scratch, "unused")
                results[name].append(
                    measure(command, dict(os.environ, LENSAUDIT_CACHE_DIR=directory))
                )
    return results


def ratio_rows(results: dict[str, list[tuple[float, float, float]]]) -> list[dict]:
    """One row per command: medians, and the wall time as a multiple of the first's."""
    medians = {
        name: [statistics.median(column) for column in zip(*measured, strict=True)]
        for name, measured in results.items()
    }
    base = next(iter(medians.values()))[0]
    return [
        {"work": name, "wall s": wall, "CPU s": cpu, "peak MB": peak, "x liblensfun": wall / base}
        for name, (wall, cpu, peak) in medians.items()
    ]


def in_process(repeats: int, warm_cache: str) -> dict[str, float]:
    import lensfunpy

    from lensaudit.pipeline import run

    times: dict[str, list[float]] = {"liblensfun": [], "cold": [], "first": [], "warm": []}
    os.environ["LENSAUDIT_CACHE_DIR"] = warm_cache
    run(cache=True)
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(prefix="lensaudit-bench-") as fresh:
            os.environ["LENSAUDIT_CACHE_DIR"] = fresh
            start = time.perf_counter()
            run(cache=True)
            times["first"].append(time.perf_counter() - start)
            os.environ["LENSAUDIT_CACHE_DIR"] = warm_cache
        start = time.perf_counter()
        lensfunpy.Database()
        times["liblensfun"].append(time.perf_counter() - start)
        start = time.perf_counter()
        run(cache=False)
        times["cold"].append(time.perf_counter() - start)
        start = time.perf_counter()
        run(cache=True)
        times["warm"].append(time.perf_counter() - start)
    return {k: statistics.median(v) for k, v in times.items()}


def run(quick: bool) -> list[dict]:
    repeats = 5 if quick else 15
    compile_bytecode()
    scratch = Path(tempfile.mkdtemp(prefix="lensaudit-bench-"))
    try:
        env = dict(os.environ)
        runs: Runs = {"liblensfun load (lensfunpy.Database)": (BASELINE, "")}
        for output_format in FORMATS:
            scan = scan_command(output_format)
            warm = scratch / f"warm-{output_format}"
            runs[f"scan -f {output_format}, cold (--no-cache)"] = (scan + ["--no-cache"], "")
            runs[f"scan -f {output_format}, first (empty cache)"] = (scan, None)
            runs[f"scan -f {output_format}, warm (cache)"] = (scan, str(warm))
            measure(scan, dict(env, LENSAUDIT_CACHE_DIR=str(warm)))  # primes its cache
        samples = in_turns(runs, repeats, str(scratch))
        medians = {
            name: [statistics.median(column) for column in zip(*values, strict=True)]
            for name, values in samples.items()
        }
        baseline = medians["liblensfun load (lensfunpy.Database)"][0]
        rows = [
            {
                "run": name,
                "median s": wall,
                "vs liblensfun": wall / baseline,
                "CPU s": cpu,
                "peak MB": peak,
            }
            for name, (wall, cpu, peak) in medians.items()
        ]
        inside = in_process(repeats, str(scratch / "in-process"))
        for name, label in (
            ("liblensfun", "in-process: liblensfun load"),
            ("cold", "in-process: pipeline.run, cold"),
            ("first", "in-process: pipeline.run, first (empty cache)"),
            ("warm", "in-process: pipeline.run, warm"),
        ):
            rows.append(
                {
                    "run": label,
                    "median s": inside[name],
                    "vs liblensfun": inside[name] / inside["liblensfun"],
                    "CPU s": "",
                    "peak MB": "",
                }
            )
        return rows
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
