"""The energy figures of a run's summary: the largest drift of an elastic run, or what the
contacts took from a lossy one, as numbers that add up over shards of a swarm."""

from __future__ import annotations

import numpy as np

#: Energy floors below this [J] are treated as zero when scaling relative energy figures.
ENERGY_SCALE_FLOOR = 1e-30


def energy_scale(sim) -> tuple[np.ndarray, np.ndarray]:
    """Initial energies (N,) and each sphere's energy above the lowest point of the scene (N,),
    the scale of relative energy figures (near 0: kept; 1: all of it) [J]."""
    scene = sim.scene
    g = scene.gravity
    if len(scene.boxes) and np.any(g):
        corners = scene.boxes.center + scene.boxes.bounding_radius()[:, None] * np.sign(g)
        floor = corners[np.argmin(corners @ -g)]
    else:
        floor = sim.energy_origin
    e0 = np.asarray(sim.initial_energy, dtype=np.float64)
    floor_potential = -sim.mass * ((floor - sim.energy_origin) @ g)
    return e0, np.maximum(e0 - floor_potential, ENERGY_SCALE_FLOOR)


def figures(sim, state=None) -> dict:
    """``{"spheres", "drift", "lost", "scale", "gained", "retention"}`` of a simulator's state:
    the largest relative drift and gain per sphere, the energy lost and the energy above the
    lowest obstacle (sums [J]); :func:`combine` merges shards', :func:`line` says them."""
    e0, scale = energy_scale(sim)
    if not len(e0):
        return {"spheres": 0, "drift": 0.0, "lost": 0.0, "scale": 0.0, "gained": 0.0,
                "retention": float(sim.scene.energy_retention)}
    energy = sim.mechanical_energy(state)
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
        text = (f"energy lost at contacts: {100.0 * lost:.1f}% of the energy above the lowest "
                f"obstacle (energy_retention = {fig['retention']:g})")
        return text + (f"; largest gain {fig['gained']:.2e} (relative)"
                       if fig["gained"] > 0.0 else "")
    return f"energy drift: {fig['drift']:.2e} (largest per sphere, relative)"


__all__ = ["combine", "energy_scale", "figures", "line"]
