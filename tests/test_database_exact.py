"""r_max of every entry of the bundled database, against exact rational arithmetic.

The reference starts from the entry's coefficients as binary64 values taken
exactly, builds D'(r) with rationals (d = 1 - a - b - c included), and finds
its first sign change exactly; lensaudit's floating-point pipeline must agree
on which entries fold and, where they do, on r_max to 1e-12.
"""

from __future__ import annotations

import math
from fractions import Fraction

import mpmath
import numpy as np

from exact import exact_min_positive_root
from lensaudit.pipeline import run

TOLERANCE = 1e-12


def exact_r_max(entry) -> mpmath.mpf:
    """First positive r where D'(r) changes sign, exactly, in Hugin units."""
    if entry.model == "ptlens":
        a, b, c = (Fraction(v) for v in (entry.a, entry.b, entry.c))
        d = 1 - a - b - c
        return exact_min_positive_root(2 * c / d, 3 * b / d, 4 * a / d)
    k1 = Fraction(entry.k1)
    if entry.model == "poly3":
        w = exact_min_positive_root(3 * k1 / (1 - k1), 0, 0)
    else:
        w = exact_min_positive_root(3 * k1, 5 * Fraction(entry.k2), 0)
    return mpmath.sqrt(w)


def test_every_bundled_entry_has_the_exact_r_max(bundled_db):
    audit = run(bundled_db)
    checked = finite = 0
    for entry, r_max in zip(audit.entries, audit.metrics.r_max.tolist(), strict=True):
        if entry.status != "ok":
            continue
        expected = exact_r_max(entry)
        where = f"{entry.file}:{entry.line}"
        assert (r_max == math.inf) == (expected == mpmath.inf), where
        if r_max != math.inf:
            assert abs(mpmath.mpf(r_max) - expected) / expected <= TOLERANCE, where
            finite += 1
        checked += 1
    assert checked == int(np.sum(audit.audited)) > 5000
    assert 0 < finite < checked
