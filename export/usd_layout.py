"""The USD file's layout, without pxr: its prim paths, its colours, and which frames, spheres and
shapes it holds.

The USD writer (:mod:`warpsim.export.usd_write`, whose docstring draws the stage), its reader,
the shard layers, the preview and the Rerun writer share these; with pxr out of this module,
the command's checks and the Rerun writer use them without loading pxr (about 0.35 s), which the
command then loads in its writer's own process (:mod:`warpsim.export.usd_process`).
"""

from __future__ import annotations

import numpy as np

from .. import validation as check
from ..trajectory import Trajectory

WORLD = "/World"
LOOKS = "/World/Looks"
SHAPES = "/World/ObstacleShapes"
OBSTACLES = "/World/Obstacles"
SPHERES = "/World/Spheres"
PROTOTYPE = "/World/Spheres/Prototypes/CheckerBall"
OBSTACLE_MATERIAL = f"{LOOKS}/Obstacle"

# Colours (linear RGB) shared by the USD file, the preview and the Rerun recording, so that all
# look alike.
SPHERE_LIGHT = (0.95, 0.62, 0.18)
SPHERE_DARK = (0.45, 0.12, 0.05)
OBSTACLE_COLOR = (0.42, 0.52, 0.66)


def shapes(boxes) -> tuple[np.ndarray, np.ndarray]:
    """Distinct shapes of the boxes, in order of first use: ``(shape of each box (K,) int64,
    shapes (S, 4) = half extents and radius)``. Equal means equal to the bit."""
    key = np.ascontiguousarray(np.column_stack([boxes.half_extents, boxes.radius]))
    _, first, inverse = np.unique(key.view(np.dtype((np.void, key.dtype.itemsize * 4))),
                                  return_index=True, return_inverse=True)
    order = np.argsort(first)  # shapes numbered by their first box
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[inverse.reshape(-1)], key[first[order]]


def selected_rows(trajectory: Trajectory, stride: int, spheres) -> tuple[np.ndarray, np.ndarray]:
    """Validated (frame rows, sphere indices) to write; the last row is always kept."""
    if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)) or stride < 1:
        raise ValueError(f"stride must be an integer >= 1, got {stride!r}")
    frame = np.asarray(trajectory.frame)
    n_frames, n = len(frame), trajectory.position.shape[1]
    if n_frames == 0:
        raise ValueError("trajectory has no recorded frames")
    if trajectory.position.shape != (n_frames, n, 3):
        raise ValueError(f"trajectory.position must have shape ({n_frames}, N, 3), "
                         f"got {trajectory.position.shape}")
    if trajectory.orientation.shape != (n_frames, n, 4):
        raise ValueError(f"trajectory.orientation must have shape ({n_frames}, {n}, 4), "
                         f"got {trajectory.orientation.shape}")
    for name in ("velocity", "angular_velocity"):
        values = getattr(trajectory, name, None)
        if values is not None and np.shape(values) != (n_frames, n, 3):
            raise ValueError(f"trajectory.{name} must have shape ({n_frames}, {n}, 3), "
                             f"got {np.shape(values)}")
    if np.shape(trajectory.radius) != (n,):
        raise ValueError(f"trajectory.radius must have shape ({n},), "
                         f"got {np.shape(trajectory.radius)}")
    if not (np.isfinite(trajectory.dt) and trajectory.dt > 0):
        raise ValueError(f"trajectory.dt must be > 0, got {trajectory.dt!r}")
    if (np.diff(frame) <= 0).any():
        raise ValueError("trajectory.frame must be strictly increasing")
    rows = np.unique(np.r_[np.arange(0, n_frames, stride), n_frames - 1])
    if spheres is None:
        return rows, np.arange(n)
    raw = np.asarray(spheres)
    if raw.ndim != 1 or (raw.size and (raw.dtype == bool
                                       or not np.issubdtype(raw.dtype, np.integer))):
        raise ValueError(f"spheres must be a 1-D sequence of sphere indices, got {spheres!r}")
    return rows, check.index_list("spheres", raw, n)


__all__ = ["LOOKS", "OBSTACLES", "OBSTACLE_COLOR", "OBSTACLE_MATERIAL", "PROTOTYPE", "SHAPES",
           "SPHERES", "SPHERE_DARK", "SPHERE_LIGHT", "WORLD", "selected_rows", "shapes"]
