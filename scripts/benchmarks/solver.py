"""Cubics per second: lensaudit's solver beside numpy.roots and the paper's Algorithm 1.

The cubics are those of the bundled Lensfun database, per model, repeated to
the array size; all methods run on the same arrays in one process. numpy.roots
takes one polynomial at a time, so it is timed on a sample and scaled.
"""

from __future__ import annotations

import time

import numpy as np

from lensaudit import normalizer
from lensaudit.database import bundled_database_path
from lensaudit.loader import load
from lensaudit.solver import min_positive_root, min_positive_root_paper_vectorized

TITLE = "Solver throughput (cubics per second, one core)"


def database_cubics() -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    entries = [e for e in load(bundled_database_path()).entries if e.status == "ok"]
    by_model: dict[str, list] = {}
    for e in entries:
        by_model.setdefault(e.model, []).append(e)
    cubics = {}
    for model, rows in by_model.items():
        if model == "ptlens":
            cubic = normalizer.ptlens(*(np.array([getattr(e, n) for e in rows]) for n in "abc"))
        elif model == "poly3":
            cubic = normalizer.poly3(np.array([e.k1 for e in rows]))
        else:
            cubic = normalizer.poly5(np.array([e.k1 for e in rows]), np.array([e.k2 for e in rows]))
        cubics[model] = (cubic.a, cubic.b, cubic.c)
    return cubics


def best_time(function, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best


def numpy_roots_time(a: np.ndarray, b: np.ndarray, c: np.ndarray, sample: int) -> float:
    """Seconds per cubic for numpy.roots, plus picking the smallest positive real root."""
    start = time.perf_counter()
    for x, y, z in zip(a[:sample], b[:sample], c[:sample], strict=True):
        roots = np.roots([z, y, x, 1.0])
        real = roots.real[(np.abs(roots.imag) < 1e-12) & (roots.real > 0)]
        _ = real.min() if real.size else np.inf
    return (time.perf_counter() - start) / sample


def run(quick: bool) -> list[dict]:
    size = 200_000 if quick else 1_000_000
    repeats = 3 if quick else 7
    rows = []
    for model, (a, b, c) in database_cubics().items():
        reps = -(-size // a.size)
        a, b, c = (np.tile(v, reps)[:size] for v in (a, b, c))
        ours = best_time(lambda a=a, b=b, c=c: min_positive_root(a, b, c), repeats)
        paper = best_time(
            lambda a=a, b=b, c=c: min_positive_root_paper_vectorized(a, b, c), repeats
        )
        per_roots = numpy_roots_time(a, b, c, 500 if quick else 2000)
        for method, seconds_per_cubic in (
            ("lensaudit min_positive_root", ours / size),
            ("paper Algorithm 1, vectorized", paper / size),
            ("numpy.roots, one by one", per_roots),
        ):
            rows.append(
                {
                    "model": model,
                    "method": method,
                    "cubics/s": 1 / seconds_per_cubic,
                    "vs lensaudit": (ours / size) / seconds_per_cubic,
                }
            )
    return rows
