"""The energy figures of a run's summary: the largest drift of an elastic run, or what the
contacts took from a lossy one, as numbers that add up over shards of a swarm."""

from __future__ import annotations

import numpy as np


def lowest(sim, start) -> float:
    """The lowest potential per unit mass of :func:`warpsim.energy.lowest_potential` over the
    obstacles, the ``start`` positions and the corners of the scene's emitter region (where
    every start lies): the same for a whole swarm and for any shard of it."""
    from .energy import lowest_potential

    points = np.asarray(start, dtype=np.float64).reshape(-1, 3)
    emitter = getattr(sim.scene, "emitter", None)
    if emitter is not None:
        c = np.asarray(emitter.center, dtype=np.float64)
        h = np.asarray(emitter.half_extents, dtype=np.float64)
        points = np.concatenate([points, [c - h, c + h]])
    return lowest_potential(sim.scene.gravity, sim.scene.boxes, points, sim.energy_origin)


def figures(sim, start, state=None) -> dict:
    """``{"spheres", "drift", "lost", "scale", "gained", "retention"}`` of a simulator's state:
    the largest relative drift and gain per sphere, the energy lost and the energy above the
    lowest point (sums [J]), on the scale of :mod:`warpsim.energy`; ``start``: the swarm's
    start positions [m]; :func:`combine` merges shards', :func:`line` says them. Only the
    spheres born by the state's frame count."""
    from .energy import energy_scale

    frame = sim.frame if state is None else state.frame
    born = np.asarray(getattr(sim, "birth_frame", np.zeros(len(sim), dtype=np.int64))) <= frame
    e0 = np.asarray(sim.initial_energy, dtype=np.float64)[born]
    if not len(e0):
        return {"spheres": 0, "drift": 0.0, "lost": 0.0, "scale": 0.0, "gained": 0.0,
                "retention": float(sim.scene.energy_retention)}
    scale = energy_scale(e0, sim.mass[born], lowest(sim, start))
    energy = np.asarray(sim.mechanical_energy(state), dtype=np.float64)[born]
    return {"spheres": int(len(e0)), "drift": float(np.max(np.abs(energy - e0) / scale)),
            "lost": float(np.sum(e0 - energy)), "scale": float(np.sum(scale)),
            "gained": float(np.max((energy - e0) / scale)),
            "retention": float(sim.scene.energy_retention)}


def combine(parts: list[dict]) -> dict:
    """The figures of a whole swarm from its shards' (maxima and sums)."""
    if not parts:
        return {"spheres": 0, "drift": 0.0, "lost": 0.0, "scale": 0.0, "gained": 0.0,
                "retention": 1.0}
    return {"spheres": sum(p["spheres"] for p in parts),
            "drift": max(p["drift"] for p in parts), "lost": sum(p["lost"] for p in parts),
            "scale": sum(p["scale"] for p in parts), "gained": max(p["gained"] for p in parts),
            "retention": parts[0]["retention"]}


def line(fig: dict) -> str:
    """The summary's energy line: the largest drift (elastic scenes), or what the contacts took
    (``energy_retention < 1``: losing energy is the model, not an error)."""
    if not fig["spheres"]:
        return "energy: no spheres"
    if fig["retention"] < 1.0:
        lost = fig["lost"] / fig["scale"] if fig["scale"] > 0 else 0.0
        text = (f"energy lost at contacts: {100.0 * lost:.1f}% of the energy above the scene's "
                f"lowest point (energy_retention = {fig['retention']:g})")
        return text + (f"; largest gain {fig['gained']:.2e} (relative)"
                       if fig["gained"] > 0.0 else "")
    return f"energy drift: {fig['drift']:.2e} (largest per sphere, relative)"


__all__ = ["combine", "figures", "line", "lowest"]
