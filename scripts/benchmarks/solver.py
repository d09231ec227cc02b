"""Cubics per second: lensaudit's solver beside the paper's Algorithm 1 and numpy.roots.

Two kinds of cubics, a million of each: those of the bundled Lensfun database,
per model, repeated to the array size; and random cubics whose coefficients
have exponents spread uniformly over the whole binary64 range (subnormals
included, one in ten exactly zero, either sign). lensaudit and the vectorized
Algorithm 1 run on the same arrays in turns, and the table gives the median
of each; numpy.roots takes one polynomial at a time, so it is timed on a
sample and scaled. The last columns say which path of the solver the cubics
took: the certified fast path, and the exact (integer arithmetic) fallback.
"""

from __future__ import annotations

import time

import numpy as np

from lensaudit import normalizer
from lensaudit.read import read as load
from lensaudit.read.paths import bundled_database_path
from lensaudit.solver import (
    PATHS,
    min_positive_root,
    min_positive_root_paper_vectorized,
    min_positive_root_paths,
)

TITLE = "Solver throughput (cubics per second, one core)"


def database_cubics() -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    entries = [e for e in load(bundled_database_path()).entries() if e.status == "ok"]
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


def whole_range_cubics(size: int, seed: int = 2022) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coefficients sign * [1, 2) * 2^e, e uniform in [-1074, 1023]; 10% exact zeros."""
    rng = np.random.default_rng(seed)

    def coefficient() -> np.ndarray:
        mantissa = rng.uniform(1.0, 2.0, size) * rng.choice([-1.0, 1.0], size)
        values = np.ldexp(mantissa, rng.integers(-1074, 1024, size))
        values[rng.random(size) < 0.1] = 0.0
        return values

    return coefficient(), coefficient(), coefficient()


def median_times(functions: dict[str, object], repeats: int) -> dict[str, float]:
    """Median seconds of each function, run in turns so that drifts hit all alike."""
    times: dict[str, list[float]] = {name: [] for name in functions}
    for _ in range(repeats):
        for name, function in functions.items():
            start = time.perf_counter()
            function()
            times[name].append(time.perf_counter() - start)
    return {name: float(np.median(values)) for name, values in times.items()}


def numpy_roots_time(a: np.ndarray, b: np.ndarray, c: np.ndarray, sample: int) -> float:
    """Seconds per cubic for numpy.roots, plus picking the smallest positive real root.

    Over the whole range numpy.roots often fails (its companion matrix
    overflows); those attempts are timed too.
    """
    start = time.perf_counter()
    for x, y, z in zip(a[:sample], b[:sample], c[:sample], strict=True):
        try:
            roots = np.roots([z, y, x, 1.0])
        except np.linalg.LinAlgError:
            continue
        real = roots.real[(np.abs(roots.imag) < 1e-12) & (roots.real > 0)]
        _ = real.min() if real.size else np.inf
    return (time.perf_counter() - start) / sample


def run(quick: bool) -> list[dict]:
    size = 200_000 if quick else 1_000_000
    repeats = 3 if quick else 7
    sets = {}
    for model, (a, b, c) in database_cubics().items():
        reps = -(-size // a.size)
        sets[f"Lensfun {model}"] = tuple(np.tile(v, reps)[:size] for v in (a, b, c))
    sets["whole binary64 range"] = whole_range_cubics(size)
    rows = []
    for name, (a, b, c) in sets.items():
        with np.errstate(all="ignore"):  # the paper's formula overflows on the whole range
            seconds = median_times(
                {
                    "lensaudit": lambda a=a, b=b, c=c: min_positive_root(a, b, c),
                    "paper": lambda a=a, b=b, c=c: min_positive_root_paper_vectorized(a, b, c),
                },
                repeats,
            )
            per_roots = numpy_roots_time(a, b, c, 500 if quick else 2000)
        paths = np.bincount(min_positive_root_paths(a, b, c)[1], minlength=len(PATHS)) / size
        rows.append(
            {
                "cubics": name,
                "lensaudit": size / seconds["lensaudit"],
                "paper Algorithm 1": size / seconds["paper"],
                "time vs paper": seconds["lensaudit"] / seconds["paper"],
                "numpy.roots": 1 / per_roots,
                "fast path": f"{paths[PATHS.index('fast')]:.2%}",
                "exact fallback": f"{paths[PATHS.index('exact')]:.4%}",
            }
        )
    return rows
