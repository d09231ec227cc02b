#!/usr/bin/env python
"""lensaudit benchmarks: every figure measured side by side in one run.

    python scripts/bench.py            # all sections
    python scripts/bench.py solver     # only the named sections
    python scripts/bench.py --quick    # fewer repetitions

Each section lives in scripts/benchmarks/<name>.py and defines ``TITLE`` and
``run(quick: bool) -> list[dict]``: rows of one table, printed here with the
keys of the first row as the header. Run on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import importlib
import platform
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

#: Sections in the order they are printed; others found on disk follow.
ORDER = (
    "solver",
    "scan",
    "mechanisms",
    "memory",
    "lines",
    "check",
    "report",
    "projection",
    "history",
)


def sections() -> list[str]:
    found = sorted(p.stem for p in (HERE / "benchmarks").glob("*.py") if p.stem != "__init__")
    return [n for n in ORDER if n in found] + [n for n in found if n not in ORDER]


def print_table(rows: list[dict]) -> None:
    if not rows:
        print("  (no rows)")
        return
    header = list(rows[0])
    cells = [header] + [[_cell(row.get(k, "")) for k in header] for row in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    for index, row in enumerate(cells):
        cells_out = (
            c.rjust(w) if j else c.ljust(w)
            for j, (c, w) in enumerate(zip(row, widths, strict=True))
        )
        print("  " + "  ".join(cells_out))
        if index == 0:
            print("  " + "  ".join("-" * w for w in widths))


def _cell(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.3g}" if abs(value) < 1000 else f"{value:,.0f}"
    return str(value)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help=f"sections to run (default: all of {sections()})")
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    args = parser.parse_args()
    names = args.names or sections()
    unknown = [n for n in names if n not in sections()]
    if unknown:
        parser.error(f"unknown sections {unknown}; known: {sections()}")
    print(
        f"lensaudit benchmarks on {platform.machine()}, Python {platform.python_version()}, "
        f"{time.strftime('%Y-%m-%d %H:%M')}"
    )
    for name in names:
        module = importlib.import_module(f"benchmarks.{name}")
        print(f"\n== {module.TITLE}")
        print_table(module.run(args.quick))
    return 0


if __name__ == "__main__":
    sys.exit(main())
