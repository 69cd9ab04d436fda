"""A plain NumPy discrete baseline: what a user writes in an afternoon.

Each frame, for all spheres at once (float64): semi-implicit Euler (``v += g dt``, then
``p += v dt``), then one pass over the boxes in order: a sphere that overlaps a box is pushed
out along the box's outward normal at the closest surface point until it just touches, and its
velocity is reflected (``v -= 2 (v.n) n``) when it moves into the box. No sweep: a sphere whose
step carries its centre through a plate or a wall is not seen, which is the point of the
baseline. Elastic and frictionless as the workload says; spheres never interact. Single-threaded
(NumPy's element-wise and ``einsum`` calls here do not use threads).
"""

from __future__ import annotations

import numpy as np

from .workload import Workload


def closest_surface(local: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray]:
    """Signed distance, outward unit normal and closest surface point of a sharp box.

    Args:
        local: points in the box's frame [m], (P, 3). half: its half extents [m], (3,).

    Returns:
        ``(distance (P,) [m], negative inside; normal (P, 3); surface point (P, 3) [m])``, all
        in the box's frame. A point inside (or on the surface) takes the face nearest to it
        (ties to the lower axis), a point outside the closest point of the solid.
    """
    q = np.clip(local, -half, half)
    diff = local - q
    # scaled by the largest component first, so that a tiny offset (1e-161 m) whose square
    # would underflow still gives a unit normal and its exact length
    scale = np.max(np.abs(diff), axis=1)
    outside = scale > 0.0
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = diff / scale[:, None]
    size = np.where(outside, np.linalg.norm(np.where(outside[:, None], unit, 0.0), axis=1), 0.0)
    dist_out = scale * size
    depth = half - np.abs(local)                      # per axis, >= 0 inside
    axis = np.argmin(depth, axis=1)
    rows = np.arange(len(local))
    sign = np.where(local[rows, axis] < 0.0, -1.0, 1.0)
    normal = np.zeros_like(local)
    normal[rows, axis] = sign
    surface = local.copy()
    surface[rows, axis] = sign * half[axis]
    dist = -depth[rows, axis]
    with np.errstate(invalid="ignore", divide="ignore"):
        n_out = unit / size[:, None]
    normal = np.where(outside[:, None], n_out, normal)
    surface = np.where(outside[:, None], q, surface)
    dist = np.where(outside, dist_out, dist)
    return dist, normal, surface


class NumpyDriver:
    """The discrete NumPy baseline (see the module docstring)."""

    key = "numpy-discrete"
    label = "NumPy discrete"

    #: ``state()``'s velocity is semi-implicit Euler's step velocity (the mean over the last step)
    step_velocity = True

    def __init__(self, work: Workload):
        self._work = work
        self._rot = work.boxes.rotation_matrices()       # (K, 3, 3) local -> world
        self._center = work.boxes.center
        self._half = work.boxes.half_extents
        # a cheap first test: centre within the box's bounding sphere grown by the radius
        self._reach = np.linalg.norm(self._half, axis=1) + work.radius
        self._g = np.asarray(work.gravity, dtype=np.float64)
        self.reset()

    def reset(self) -> None:
        self._p = self._work.position.astype(np.float64).copy()
        self._v = self._work.velocity.astype(np.float64).copy()

    def step(self, frames: int) -> None:
        dt, r = self._work.dt, self._work.radius
        p, v = self._p, self._v
        for _ in range(frames):
            v += self._g * dt
            p += v * dt
            for k in range(len(self._center)):
                near = np.flatnonzero(
                    np.einsum("ij,ij->i", p - self._center[k], p - self._center[k])
                    < self._reach[k] ** 2)
                if near.size == 0:
                    continue
                rot = self._rot[k]
                local = (p[near] - self._center[k]) @ rot     # world -> local: R^T x
                dist, n_local, surface = closest_surface(local, self._half[k])
                hit = dist < r
                if not hit.any():
                    continue
                rows = near[hit]
                n = n_local[hit] @ rot.T                       # local -> world: R x
                p[rows] = self._center[k] + (surface[hit] + r * n_local[hit]) @ rot.T
                vn = np.einsum("ij,ij->i", v[rows], n)
                v[rows] -= np.where(vn < 0.0, 2.0 * vn, 0.0)[:, None] * n

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        return self._p.copy(), self._v.copy()

    def settings(self) -> dict:
        return {"dt": self._work.dt, "integrator": "semi-implicit Euler",
                "contact": "push out of overlap, reflect; one pass over the boxes per frame",
                "precision": "float64"}

    def close(self) -> None:
        pass
