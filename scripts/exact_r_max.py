#!/usr/bin/env python
"""Make tests/data/exact_r_max.json: the exact r_max of every distortion entry
of the bundled Lensfun database (lensfunpy's), for tests/test_database_exact.py.

    python scripts/exact_r_max.py

Each reference is tests/test_database_exact.py's ``exact_reference`` (the
coefficients as rationals, Sturm sequences, mpmath at 60 digits: never
lensaudit's solver, which only lists the entries), keyed by the entry's model
and coefficients. The test holds every entry to the file, and computes a
seeded sample and the hardest entries again on every run. Run this again when
the bundled database gains entries (the test computes those it lacks itself).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "src"), str(ROOT / "tests")]

import lensfunpy  # noqa: E402

from lensaudit.pipeline import run  # noqa: E402
from lensaudit.read.paths import bundled_database_path  # noqa: E402
from test_database_exact import STORED_PATH, exact_reference, key, stored_form  # noqa: E402


def main() -> int:
    """Compute every reference and write the file (sorted, one a line)."""
    references: dict[str, list[str]] = {}
    for entry in run(bundled_database_path()).entries:
        if entry.status == "ok" and key(entry) not in references:
            references[key(entry)] = stored_form(*exact_reference(entry))
    head = {"made_by": "scripts/exact_r_max.py", "database": f"lensfunpy {lensfunpy.__version__}"}
    # One reference a line, so that a change to the file shows entry by entry.
    lines = [f"{json.dumps(k)}: {json.dumps(v)}" for k, v in sorted(references.items())]
    text = json.dumps(head, indent=1)[:-2] + ',\n "references": {\n' + ",\n".join(lines)
    STORED_PATH.parent.mkdir(exist_ok=True)
    STORED_PATH.write_text(text + "\n}}\n", encoding="utf-8")
    print(f"{len(references)} references written to {STORED_PATH.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
