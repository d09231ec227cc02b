"""r_max of the Brown-Conrady model over a (k1, k2) grid, for several k3 (paper Figure 3).

Radii are in normalized camera coordinates (x/z, y/z), OpenCV's convention
for k1, k2, k3. Computed in one vectorized call of the solver.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import metrics, normalizer

DEFAULT_K3 = (-0.5, 0.0, 0.5, 1.0)
DEFAULT_RANGE = (-1.0, 1.0)
DEFAULT_RESOLUTION = 301


@dataclass(frozen=True)
class RMaxMap:
    """``r_max[i, j, l]`` at ``k2[j]`` (rows), ``k1[l]`` (columns), ``k3[i]``.

    ``inf`` where the model is a bijection on (0, inf).
    """

    k1: NDArray[np.float64]
    k2: NDArray[np.float64]
    k3: tuple[float, ...]
    r_max: NDArray[np.float64]


def rmax_map(
    k3: tuple[float, ...] = DEFAULT_K3,
    k_range: tuple[float, float] = DEFAULT_RANGE,
    resolution: int = DEFAULT_RESOLUTION,
) -> RMaxMap:
    """Brown-Conrady r_max on a ``resolution`` x ``resolution`` grid of (k1, k2) per k3."""
    if resolution < 2:
        raise ValueError("resolution must be at least 2")
    axis = np.linspace(k_range[0], k_range[1], resolution)
    k3_grid, k2_grid, k1_grid = np.meshgrid(
        np.asarray(k3, dtype=np.float64), axis, axis, indexing="ij"
    )
    cubic = normalizer.brown_conrady(k1_grid, k2_grid, k3_grid)
    r_max = metrics.cubic_r_max(cubic)
    return RMaxMap(axis, axis.copy(), tuple(float(k) for k in k3), np.asarray(r_max))
