"""r_max of every entry of the bundled database, against exact rational arithmetic.

The reference starts from the entry's coefficients as binary64 values taken
exactly, builds D'(r) with rationals (d = 1 - a - b - c included), and finds
its first sign change exactly; lensaudit's floating-point pipeline must agree
on which entries fold and, where they do, on r_max to 1e-12.

The reference of every entry is stored in tests/data/exact_r_max.json, made
offline by scripts/exact_r_max.py with this module's :func:`exact_reference`
(an entry the file lacks, from another Lensfun database, is computed here).
A seeded sample of entries and the hardest ones are computed again here on
every run, so that the file is held to the computation.
"""

from __future__ import annotations

import itertools
import json
import math
import random
from fractions import Fraction
from pathlib import Path

import mpmath
import numpy as np
import pytest

from exact import exact_roots
from lensaudit.pipeline import run

TOLERANCE = 1e-12
#: The stored references, by :func:`key`: [r_max (30 digits, or "inf"), closeness].
STORED_PATH = Path(__file__).parent / "data" / "exact_r_max.json"
#: Significant digits of a stored r_max.
DIGITS = 30
#: Entries recomputed live: a seeded random sample, and the hardest of each kind.
SAMPLE, HARDEST, SEED = 200, 40, 20250101


def key(entry) -> str:
    """An entry's model and coefficients (binary64, round-trip decimals): all
    that its r_max depends on, in Hugin units."""
    names = {"ptlens": ("a", "b", "c"), "poly3": ("k1",), "poly5": ("k1", "k2")}[entry.model]
    return " ".join([entry.model, *(repr(float(getattr(entry, n))) for n in names)])


def exact_reference(entry) -> tuple[mpmath.mpf, mpmath.mpf]:
    """(r_max, closeness): the first positive r where D'(r) changes sign,
    exactly, in Hugin units (mpmath inf where none), and the smallest relative
    distance between two roots of D''s polynomial (complex ones too; 0 for a
    multiple root, inf for fewer than two roots), where an answer in floating
    point is hardest."""
    if entry.model == "ptlens":
        a, b, c = (Fraction(v) for v in (entry.a, entry.b, entry.c))
        d = 1 - a - b - c
        root, roots = exact_roots(2 * c / d, 3 * b / d, 4 * a / d)
    else:
        k1 = Fraction(entry.k1)
        if entry.model == "poly3":
            root, roots = exact_roots(3 * k1 / (1 - k1), 0, 0)
        else:
            root, roots = exact_roots(3 * k1, 5 * Fraction(entry.k2), 0)
        root = mpmath.sqrt(root)
    pairs = [abs(x - y) / max(abs(x), abs(y)) for x, y in itertools.combinations(roots, 2)]
    return root, min(pairs, default=mpmath.inf)


def stored_form(r_max: mpmath.mpf, closeness: mpmath.mpf) -> list[str]:
    """How the file stores a reference."""
    return [mpmath.nstr(r_max, DIGITS), mpmath.nstr(closeness, 3)]


@pytest.fixture(scope="module")
def audited(bundled_db) -> list[tuple]:
    """(entry, lensaudit's r_max) of every audited entry of the bundled database."""
    audit = run(bundled_db)
    rows = zip(audit.entries, audit.metrics.r_max.tolist(), strict=True)
    found = [(entry, r_max) for entry, r_max in rows if entry.status == "ok"]
    assert len(found) == int(np.sum(audit.audited)) > 5000
    return found


@pytest.fixture(scope="module")
def stored() -> dict[str, list[str]]:
    return json.loads(STORED_PATH.read_text(encoding="utf-8"))["references"]


def assert_agrees(entry, r_max: float, expected: mpmath.mpf) -> None:
    where = f"{entry.file}:{entry.line}"
    assert (r_max == math.inf) == (expected == mpmath.inf), where
    if r_max != math.inf:
        assert abs(mpmath.mpf(r_max) - expected) / expected <= TOLERANCE, where


@pytest.mark.exhaustive
def test_every_bundled_entry_has_the_exact_r_max(audited, stored):
    finite = 0
    for entry, r_max in audited:
        reference = stored.get(key(entry))
        expected = mpmath.mpf(reference[0]) if reference else exact_reference(entry)[0]
        assert_agrees(entry, r_max, expected)
        finite += r_max != math.inf
    assert 0 < finite < len(audited)


def test_a_sample_and_the_hardest_entries_are_computed_again_as_stored(audited, stored):
    """A seeded random sample of 200 entries, and the 40 whose D' has the
    closest roots (near-double roots: where the fold decision and r_max are
    hardest in floating point) and the 40 where lensaudit's r_max is farthest
    from the stored one, computed exactly here: each gives what the file
    holds, digit for digit, and lensaudit agrees with it."""
    by_key = {key(entry): (entry, r_max) for entry, r_max in audited}
    held = [k for k in by_key if k in stored]
    assert len(held) > 0.9 * len(by_key)  # the file is this database's

    def distance(k: str) -> float:
        r_max, expected = by_key[k][1], mpmath.mpf(stored[k][0])
        if expected == mpmath.inf or r_max == math.inf:
            return 0.0 if (expected == mpmath.inf) == (r_max == math.inf) else math.inf
        return float(abs(mpmath.mpf(r_max) - expected) / expected)

    closest = sorted(held, key=lambda k: mpmath.mpf(stored[k][1]))[:HARDEST]
    farthest = sorted(held, key=distance)[-HARDEST:]
    sample = random.Random(SEED).sample(sorted(held), SAMPLE)
    for k in dict.fromkeys(closest + farthest + sample):
        entry, r_max = by_key[k]
        reference = exact_reference(entry)
        assert stored_form(*reference) == stored[k], k
        assert_agrees(entry, r_max, reference[0])
