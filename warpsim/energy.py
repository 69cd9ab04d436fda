"""The energy scale of every report: what "energy drift" means in ``warpsim run``'s summary,
the error report, the accuracy study and the benchmarks.

A sphere's energy ``E`` is ``1/2 m |u|^2 - m g . (p - origin)`` [J] (see
:meth:`warpsim.Simulator.mechanical_energy`). Its scale is its energy above the lowest point of
the scene's region (:func:`region_bounds`: the obstacles' world bounds and the spheres' start
positions), i.e. the largest kinetic energy it could ever have: ``E0 - m min(-g . (x -
origin))`` over the region's corners, at least :data:`ENERGY_FLOOR`. The **energy drift** of a
sphere is ``|E - E0| / scale``, its relative change ``(E - E0) / scale``: 0 kept, -1 all of it
lost. The scale does not depend on where the origin of heights is, unlike ``|E - E0| / E0``.
"""

from __future__ import annotations

import numpy as np

from .blocks import map_row_blocks

ENERGY_FLOOR = 1e-12
"""Smallest energy scale [J]: a sphere at rest on the lowest point has nothing to lose."""


def region_bounds(boxes, position) -> tuple[np.ndarray, np.ndarray]:
    """World axis-aligned bounds [m], (3,) each, of the obstacles' world extents and the sphere
    centres ``position`` (N, 3) together (only the centres when there is no obstacle)."""
    p = np.asarray(position, dtype=np.float64).reshape(-1, 3)
    lows, highs = [], []
    if len(boxes):
        extent = boxes.world_extent()
        lows.append((boxes.center - extent).min(axis=0))
        highs.append((boxes.center + extent).max(axis=0))
    if len(p):  # per block of rows on every core, then over the blocks: the same extremes
        ends = map_row_blocks(len(p), lambda rows: (p[rows].min(axis=0), p[rows].max(axis=0)))
        lows.append(np.min([low for low, _ in ends], axis=0))
        highs.append(np.max([high for _, high in ends], axis=0))
    if not lows:
        return np.zeros(3), np.zeros(3)
    return np.min(lows, axis=0), np.max(highs, axis=0)


def lowest_potential(gravity, boxes, start, origin=(0.0, 0.0, 0.0)) -> float:
    """The lowest potential energy per unit mass ``-g . (x - origin)`` [J/kg] over the corners
    of :func:`region_bounds` of ``boxes`` and the ``start`` positions [m]."""
    g = np.asarray(gravity, dtype=np.float64)
    low, high = region_bounds(boxes, start)
    corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1])
                        for z in (low[2], high[2])])
    return float((-(corners - np.asarray(origin, dtype=np.float64)) @ g).min())


def energy_scale(e0, mass, lowest: float) -> np.ndarray:
    """Each sphere's energy above the lowest point [J], (N,): ``max(E0 - m lowest,
    ENERGY_FLOOR)`` with ``lowest`` from :func:`lowest_potential` (same origin as ``E0``)."""
    e0 = np.asarray(e0, dtype=np.float64)
    return np.maximum(e0 - np.asarray(mass, dtype=np.float64) * lowest, ENERGY_FLOOR)


def relative_change(sim, start, state=None) -> np.ndarray:
    """``(E - E0) / scale`` per sphere, (N,) float64, of a :class:`warpsim.Simulator` now (or at
    ``state``); ``start``: the swarm's start positions [m], (N, 3)."""
    e0 = np.asarray(sim.initial_energy, dtype=np.float64)
    energy = np.asarray(sim.mechanical_energy(state), dtype=np.float64)
    lowest = lowest_potential(sim.scene.gravity, sim.scene.boxes, start, sim.energy_origin)
    return (energy - e0) / energy_scale(e0, sim.mass, lowest)


__all__ = ["ENERGY_FLOOR", "energy_scale", "lowest_potential", "region_bounds",
           "relative_change"]
