"""Outputs are byte-identical to the ones made before the one-reader redesign.

tests/golden/capture.py runs scan (csv, json, vignetting, tca), check (json)
and report on the bundled database and on the master of Lensfun's history
bundle, and history over the whole bundle; tests/golden/digests.json holds
what it gave with the code named there. A digest listed under ``changed``
was captured again after a change made on purpose, which it names.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

GOLDEN = Path(__file__).parent / "golden"


@pytest.fixture(scope="module")
def captured(bundled_db: Path, lensfun_head: Path) -> dict:
    clone = lensfun_head.parents[1]  # the session's clone of the history bundle
    result = subprocess.run(
        [sys.executable, str(GOLDEN / "capture.py"), str(bundled_db), str(clone)],
        capture_output=True,
        check=True,
    )
    return json.loads(result.stdout)


EXPECTED = json.loads((GOLDEN / "digests.json").read_text())


@pytest.mark.parametrize("output", sorted(EXPECTED["digests"]))
def test_output_is_unchanged(captured: dict, output: str) -> None:
    assert captured[output] == EXPECTED["digests"][output], (
        f"{output} differs from its golden digest; if on purpose, capture it again and "
        "say why under 'changed' in tests/golden/digests.json"
    )
