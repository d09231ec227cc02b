"""Points per second for ``project`` beside plain numpy without the validity check.

For each model, four ways to project the same camera-frame points (5%
behind the camera, more beyond r_max), timed in turns (rotating the order),
best of the repetitions:

* plain numpy: the textbook whole-array expression, no validity check;
* project(): lensaudit, with the check and NaN pixels for invalid points;
* project(nan_for_invalid=False): the check only;
* kernel, no check: lensaudit's own blocked kernel with the check left out,
  which isolates what the check itself costs.

"vs plain" is the throughput relative to plain numpy; "check cost" is the
share of throughput the check takes from lensaudit's own kernel.
"""

from __future__ import annotations

import time

import numpy as np

from lensaudit.projection import (
    LensfunCalibration,
    RadialCamera,
    _project_blocks,
    brown_conrady_camera,
    lensfun_camera,
    project,
)

TITLE = "projection: points per second (project vs plain numpy without validity check)"


def _plain(points: np.ndarray, camera: RadialCamera) -> np.ndarray:
    """What one writes without thinking of r_max: distort and project, nothing else."""
    x = points[:, 0] / points[:, 2]
    y = points[:, 1] / points[:, 2]
    w = x * x + y * y
    if camera.power == 1:
        w = np.sqrt(w)
    factor = np.zeros_like(w)
    for coefficient in camera.distortion[::-1]:
        factor = factor * w + coefficient
    return np.stack(
        [camera.fx * x * factor + camera.cx, camera.fy * y * factor + camera.cy], axis=1
    )


def _kernel_without_check(points: np.ndarray, camera: RadialCamera) -> np.ndarray:
    pixels = np.empty((points.shape[0], 2))
    valid = np.empty(points.shape[0], dtype=bool)
    _project_blocks(camera, points, pixels, valid, check=False)
    return pixels


def _points(camera: RadialCamera, count: int, rng: np.random.Generator) -> np.ndarray:
    """Points inside 1.1 r_max (or a 70 degree cone), 5% of them behind the camera."""
    limit = min(camera.r_max * 1.1, np.tan(np.radians(70)))
    radius = limit * np.sqrt(rng.uniform(0, 1, count))
    angle = rng.uniform(0, 2 * np.pi, count)
    depth = rng.uniform(0.5, 50, count)
    depth[rng.uniform(0, 1, count) < 0.05] *= -1
    return np.stack([radius * np.cos(angle) * depth, radius * np.sin(angle) * depth, depth], axis=1)


def run(quick: bool) -> list[dict]:
    count = 200_000 if quick else 2_000_000
    repeats = 4 if quick else 12
    rng = np.random.default_rng(0)
    cameras = {
        "Brown-Conrady (k1 k2 k3)": brown_conrady_camera(
            1400, 1400, 959.5, 539.5, -0.3, 0.1, -0.01, 1920, 1080
        ),
        "Lensfun ptlens": lensfun_camera(
            LensfunCalibration("ptlens", focal=11.0, a=0.0365, b=-0.1264, c=0.0781), 6000, 4000
        ),
        "Lensfun poly3": lensfun_camera(
            LensfunCalibration(
                "poly3", focal=14.0, k1=-0.0343, crop_factor=2.0, aspect_ratio=4 / 3
            ),
            4608,
            3456,
        ),
    }
    rows = []
    for name, camera in cameras.items():
        points = _points(camera, count, rng)
        ways = {
            "plain numpy, no check": lambda p, c=camera: _plain(p, c),
            "project()": lambda p, c=camera: project(p, c),
            "project(nan_for_invalid=False)": lambda p, c=camera: project(
                p, c, nan_for_invalid=False
            ),
            "kernel, no check": lambda p, c=camera: _kernel_without_check(p, c),
        }
        best = dict.fromkeys(ways, np.inf)
        labels = list(ways)
        for repeat in range(repeats):
            # Rotate the order: a run right after plain numpy's big temporaries pays for
            # fresh memory pages, and that must not always fall on the same way.
            for label in labels[repeat % len(labels) :] + labels[: repeat % len(labels)]:
                start = time.perf_counter()
                ways[label](points)
                best[label] = min(best[label], time.perf_counter() - start)
        invalid = 1 - project(points, camera)[1].mean()
        for label in ways:
            rate = count / best[label]
            rows.append(
                {
                    "model": name,
                    "implementation": label,
                    "points": count,
                    "invalid": f"{invalid:.1%}",
                    "M points/s": rate / 1e6,
                    "vs plain": f"{best['plain numpy, no check'] / best[label]:.2f}x",
                    "check cost": (
                        f"{1 - best['kernel, no check'] / best[label]:.1%}"
                        if label.startswith("project")
                        else ""
                    ),
                }
            )
    return rows
