"""What no change inside lensaudit can remove, beside liblensfun's own load.

A cold ``check`` or ``scan`` starts an interpreter, imports the libraries it
is built on and has lxml parse every file of the database. Those costs are
timed here alone, as fresh processes in turns with liblensfun's load and the
commands themselves, so that a goal stated as a multiple of liblensfun's load
can be set against what is left of it for lensaudit's own work.

- "import lensfunpy alone": what liblensfun's load spends before it reads a file.
- "imports of a check": click, lxml and numpy (numpy with one BLAS thread, as
  lensaudit asks for it; liblensfun's load imports numpy with lensfunpy, with
  the default thread pool).
- "floor of a check": those imports, then every file of the bundled database
  parsed by lxml and each element's attributes read once from Python, the
  files shared by this process and one forked per other CPU, as ``check``
  shares them (numpy imported here meanwhile). No lens row is made and no
  rule is run.
- "floor of a scan": the same for a cold scan, which imports lxml only.
"""

from __future__ import annotations

import sys
import tempfile

from benchmarks.check import check_command
from benchmarks.scan import BASELINE, Runs, compile_bytecode, in_turns, ratio_rows, scan_command

TITLE = "What no change inside lensaudit removes: start-up, imports, lxml's parse"

#: A process that does only what every cold check or scan must: argv[1] is
#: "imports" (click, lxml, numpy), "check" (those and the parse) or "scan"
#: (lxml and the parse); argv[2] the database directory.
_FLOOR = """
import os, sys
what, directory = sys.argv[1], sys.argv[2]
if what != "scan":
    import click
import lxml.etree as etree
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
if what == "imports":
    import numpy
    raise SystemExit
names = sorted(n for n in os.listdir(directory) if n.endswith(".xml"))
data = []
for name in names:
    with open(os.path.join(directory, name), "rb") as stream:
        data.append(stream.read())
order = sorted(range(len(data)), key=lambda i: -len(data[i]))
count = min(len(os.sched_getaffinity(0)), 8)
share, children = 0, []
for share in range(1, count):
    child = os.fork()
    if child == 0:
        break
    children.append(child)
else:
    share = 0
    if what == "check":
        import numpy
parser = etree.XMLParser(resolve_entities=False, no_network=True)
for index in order[share::count]:
    for element in etree.fromstring(data[index], parser).iter():
        element.items()
if share:
    os._exit(0)
for child in children:
    os.waitpid(child, 0)
"""


def floor_command(what: str, database: str) -> list[str]:
    return [sys.executable, "-c", _FLOOR, what, database]


def run(quick: bool) -> list[dict]:
    from lensaudit.read.paths import bundled_database_path

    turns = 5 if quick else 15
    compile_bytecode()
    database = str(bundled_database_path())
    runs: Runs = {
        "liblensfun load (lensfunpy.Database)": (BASELINE, ""),
        "import lensfunpy alone (numpy with it)": ([sys.executable, "-c", "import lensfunpy"], ""),
        "interpreter alone (python -c pass)": ([sys.executable, "-c", "pass"], ""),
        "imports of a check (click, lxml, numpy)": (floor_command("imports", database), ""),
        "floor of a check: imports, every file parsed": (floor_command("check", database), ""),
        "lensaudit check, cold (--no-cache)": (check_command("--no-cache"), ""),
        "floor of a scan: lxml, every file parsed": (floor_command("scan", database), ""),
        "lensaudit scan -f csv, cold (--no-cache)": (scan_command("csv") + ["--no-cache"], ""),
    }
    with tempfile.TemporaryDirectory(prefix="lensaudit-bench-") as scratch:
        rows = ratio_rows(in_turns(runs, turns, scratch))
    for row in rows:
        del row["peak MB"]
    return rows
