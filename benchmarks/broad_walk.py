"""The walked grid against the other broad phases: cost per sphere-frame as spheres get faster.

Run from the repository root:
``python -m benchmarks.broad_walk [--quick] [--device D] [--out PATH] [--only room,thin,plates]``.

Three tables, one core (``workers=1``), float32, many frames per launch (``sim.step(F)``), every
figure of a table from one run with the compared simulators taking turns (``common.
median_times``); the figures are the CPU time of the process per sphere-frame, which other
work on a shared machine stretches less than the wall time (both are in the JSON):

1. The standard room (22 boxes) at 5 and 60 m/s, N = 1e5: each broad phase (``brute``,
   ``bvh``, ``grid``, ``walk``), main's ``auto`` (the cheapest of every box, the BVH and the
   start-cell grid by the cost model: ``before``) and this ``auto`` (the walk included:
   ``after``).
2. The ``thin-walls`` scene (16 boxes, 200 to 400 m/s, 3.5 contacts per sphere-frame), N = 1e5:
   the same columns.
3. A million spheres at 600 m/s (10 m a frame) among plates: the grown room of
   ``benchmarks.speed`` with 256 plates (262 boxes), ``before`` against ``after``.

All simulators of a row start from the same swarm and run the same frames: their final states
must be bit-identical (the ``identical`` column). Columns that run the same broad phase (``auto``
picks one of the others) share one simulator and its figures.
"""

from __future__ import annotations

import dataclasses
from functools import partial

import numpy as np

import warpsim as ws
from warpsim import broad_phase as broad

from .common import (
    ROOM,
    finish,
    identical_states,
    median_times,
    open_study,
    print_table,
    room_swarm,
)
from .speed import SEED, grown_room

BROAD_PHASES = ("brute", "bvh", "grid", "walk")
ROOM_SPEEDS = (5.0, 60.0)
"""[m/s]"""
PLATES_SPEED = 600.0
"""[m/s]: 10 m a frame at 60 Hz."""
PLATES_K = 262
"""6 walls and 256 plates."""

FULL = {"room_n": 100_000, "room_frames": 40, "thin_n": 100_000, "thin_frames": 6,
        "plates_n": 1_000_000, "plates_frames": 2, "repeats": 5}
QUICK = {"room_n": 20_000, "room_frames": 10, "thin_n": 10_000, "thin_frames": 3,
         "plates_n": 50_000, "plates_frames": 2, "repeats": 3}


def main_auto(scene: ws.Scene, swarm: ws.Swarm, dtype=np.float32) -> str:
    """The broad phase main's ``auto`` picks (``broad_phase.preferred`` without the walk), as
    requested of a :class:`warpsim.Simulator`."""
    frame = broad.paths(swarm.position, swarm.velocity, swarm.radius, scene.gravity, scene.dt)
    options = {name: value for name, value in broad.estimates(scene.boxes, frame, dtype).items()
               if not name.startswith("walk")}
    return broad.preferred(options).removesuffix("-bvh")


def timed_row(scene: ws.Scene, swarm: ws.Swarm, frames: int, requests: dict, device,
              repeats: int) -> dict:
    """One row: a simulator per ``{column: broad phase requested}``, timed taking turns. Columns
    that run the same broad phase share one simulator and its figures (a ratio between them is
    1 by construction, not noise)."""
    sims, runs = {}, {}
    for col, bp in requests.items():
        sim = ws.Simulator(scene, swarm, device=device, broad_phase=bp, workers=1)
        runs[col] = str(sim.broad_phase)
        sims.setdefault(runs[col], sim)
    for sim in sims.values():
        sim.build()
    cpu = {}
    times = median_times({bp: partial(sim.step, frames) for bp, sim in sims.items()}, device,
                         repeats, cpu=cpu)
    sphere_frames = frames * len(swarm)
    first = next(iter(sims.values()))
    stats = first.stats
    row = {"scene": scene.name, "n": len(swarm), "frames": frames,
           "repeats": next(iter(times.values()))[1],
           "contacts_per_sphere_frame": stats.bounces / stats.sphere_frames,
           "identical": all(identical_states(first, s) for s in sims.values())}
    for col, bp in runs.items():
        row[f"{col}_runs"] = bp
        row[f"{col}_ns"] = times[bp][0] / sphere_frames * 1e9
        row[f"{col}_cpu_ns"] = cpu[bp] / sphere_frames * 1e9
    row["after_over_before"] = row["after_cpu_ns"] / row["before_cpu_ns"]
    return row


def all_phases(scene: ws.Scene, swarm: ws.Swarm) -> dict:
    requests = {bp: bp for bp in BROAD_PHASES}
    requests.update(before=main_auto(scene, swarm), after="auto")
    return requests


def room_rows(cfg: dict, device) -> list[dict]:
    scene = ws.Scene.load(ROOM)
    rows = []
    for speed in ROOM_SPEEDS:
        swarm = room_swarm(scene, cfg["room_n"], speed, seed=SEED)
        row = timed_row(scene, swarm, cfg["room_frames"], all_phases(scene, swarm), device,
                        cfg["repeats"])
        rows.append({"speed": speed, **row})
    slow = rows[0]
    for row in rows:
        for col in (*BROAD_PHASES, "before", "after"):
            row[f"{col}_over_5"] = row[f"{col}_cpu_ns"] / slow[f"{col}_cpu_ns"]
    return rows


def thin_rows(cfg: dict, device) -> list[dict]:
    scene = ws.Scene.load("thin-walls")
    emitter = dataclasses.replace(scene.emitter, count=cfg["thin_n"])
    swarm = emitter.spawn(scene.boxes, seed=SEED)
    row = timed_row(scene, swarm, cfg["thin_frames"], all_phases(scene, swarm), device,
                    cfg["repeats"])
    return [{"speed": "200-400", **row}]


def plates_rows(cfg: dict, device) -> list[dict]:
    n = cfg["plates_n"]
    scene = grown_room(PLATES_K, n, np.random.default_rng([SEED, PLATES_K]))
    emitter = dataclasses.replace(scene.emitter, speed=PLATES_SPEED)
    swarm = emitter.spawn(scene.boxes, seed=SEED)
    requests = {"before": main_auto(scene, swarm), "after": "auto"}
    row = timed_row(scene, swarm, cfg["plates_frames"], requests, device, cfg["repeats"])
    return [{"speed": PLATES_SPEED, **row}]


def columns(with_phases: bool) -> list[tuple[str, str, str]]:
    cols = [("scene", "scene", ""), ("m/s", "speed", ""), ("N", "n", ",d"),
            ("frames", "frames", "d"),
            ("contacts/sph-frame", "contacts_per_sphere_frame", ".3f")]
    if with_phases:
        cols += [(f"{bp} ns", f"{bp}_cpu_ns", ".3g") for bp in BROAD_PHASES]
    cols += [("before: main's auto", "before_runs", ""), ("before ns", "before_cpu_ns", ".3g"),
             ("after: auto", "after_runs", ""), ("after ns", "after_cpu_ns", ".3g"),
             ("after / before", "after_over_before", ".2f"), ("identical", "identical", "")]
    return cols


TABLES = ("room", "thin", "plates")


def main(argv: list[str] | None = None) -> int:
    args, only, device, info, out, started = open_study("broad_walk", __doc__, TABLES, argv)
    cfg = QUICK if args.quick else FULL
    results = {"machine": info, "quick": args.quick, "settings": cfg, "tables": only}
    title = "ns per sphere-frame (CPU time), one core, float32, many frames per launch"
    if "room" in only:
        results["room"] = room_rows(cfg, device)
        print_table(f"Standard room: {title}", results["room"], columns(True) + [
            (f"{c} / 5 m/s", f"{c}_over_5", ".2f") for c in ("grid", "walk", "before", "after")])
    if "thin" in only:
        results["thin_walls"] = thin_rows(cfg, device)
        print_table(f"thin-walls: {title}", results["thin_walls"], columns(True))
    if "plates" in only:
        results["plates"] = plates_rows(cfg, device)
        print_table(f"{PLATES_SPEED:g} m/s among {PLATES_K - 6} plates: {title}",
                    results["plates"], columns(False))
    finish(out, results, started)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

