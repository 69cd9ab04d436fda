"""Simulator speed: ns per sphere-frame per broad phase, launch mode, speed and precision; cost
against the number of boxes; speed-up against workers.

Run from the repository root:
``python -m benchmarks.speed [--quick] [--device D] [--out PATH] [--only room,boxes,workers]``.

Three tables, every figure of a table from one run, the compared calls taking turns:

1. The standard room (``warpsim.Scene.load("room")``, 22 boxes; spheres from its emitter with
   the speed set to 5 or 60 m/s) at N = 1e3 ... 1e6 (quick: 1e3 ... 1e5), float32 and float64,
   ``workers=1``: each broad phase (``brute``, ``bvh``, ``grid``), each with one launch per
   frame (``for _ in range(F): sim.step(1)``) and with many frames per launch
   (``sim.step(F)``). All six simulators of a row start from the same swarm and run the same
   frames, so their final states must be bit-identical (the ``identical`` column).
2. Cost against the number of boxes K = 16 ... 16 384 (quick: up to 4096) at fixed N, in a
   *grown room*: the standard room's walls around ``K - 6`` plates drawn like its plates, the
   room enlarged so that the plates keep the standard room's density (37.5 m^3 per plate);
   5 m/s, float32, many frames per launch, ``workers=1``.
3. Speed-up against workers (1, 2) at N = 1e5, the standard room, default settings, over
   ``workers_frames`` frames (320: about a second a call at 5 m/s; a call of a fifth of a
   second, as table 1's 80 frames, read 1.34 to 1.80x between three runs on a shared
   machine, its first frames the least even between the two shards).
"""

from __future__ import annotations

import math
import time
from functools import partial

import numpy as np

import warpsim as ws

from .common import (
    ROOM,
    finish,
    identical_states,
    median_times,
    open_study,
    print_table,
    room_swarm,
)

SEED = 20240601
BROAD_PHASES = ("brute", "bvh", "grid")
MODES = ("per-frame", "many")
"""One launch per frame (``sim.step(1)`` F times) against ``sim.step(F)``."""
SPEEDS = (5.0, 60.0)
"""Sphere speeds [m/s] of the standard-room runs."""
PRECISIONS = ("float32", "float64")
GOAL_NS = 40.0
"""Issue 10's goal [ns per sphere-frame]: the standard room, N >= 1e5, one core, defaults."""

# grown room (table 2)
PLATE_VOLUME = 600.0 / 16
"""Room volume [m^3] per plate: the standard room's 10 x 6 x 10 m holds 16 plates."""
ROOM_SHAPE = np.array([10.0, 6.0, 10.0]) / 600.0 ** (1 / 3)
"""Inner size of a room of unit volume with the standard room's proportions."""
WALL = 0.1
"""Wall thickness [m]."""
PLATE_HALF = (0.3, 1.0)
"""Range of a plate's half sides [m] (zero thickness), as the standard room's."""
PLATE_ROUNDING = 0.02
"""[m]"""
PLATE_MARGIN = 1.5
"""Plate centres keep this far [m] from the walls: more than a plate's bounding radius
(sqrt(2) x 1 m + rounding)."""
ROOM_RADIUS = 0.05
"""Sphere radius [m], as the standard room's emitter."""

FULL = {"room_n": (1_000, 10_000, 100_000, 1_000_000), "sphere_frames": 8_000_000,
        "max_frames": 2000, "min_frames": 16, "k": (16, 64, 256, 1024, 4096, 16384), "k_n": 100_000,
        "k_target_s": 0.4, "workers_n": 100_000, "workers_frames": 320, "repeats": 5}
QUICK = {"room_n": (1_000, 10_000, 100_000), "sphere_frames": 500_000, "max_frames": 500,
         "min_frames": 4,
         "k": (16, 256, 4096), "k_n": 10_000, "k_target_s": 0.15, "workers_n": 100_000,
         "workers_frames": 5, "repeats": 3}


def step_per_frame(sim: ws.Simulator, frames: int) -> None:
    """``frames`` frames, one launch each."""
    for _ in range(frames):
        sim.step(1)


def room_rows(cfg: dict, device) -> list[dict]:
    """Table 1: one row per precision, speed and N; a column per broad phase and launch mode."""
    scene = ws.Scene.load(ROOM)
    rows = []
    for prec in PRECISIONS:
        for speed in SPEEDS:
            for n in cfg["room_n"]:
                swarm = room_swarm(scene, n, speed, seed=SEED)
                sims = {(bp, mode): ws.Simulator(scene, swarm, device=device, precision=prec,
                                                 broad_phase=bp, workers=1)
                        for bp in BROAD_PHASES for mode in MODES}
                auto = ws.Simulator(scene, swarm, device=device, precision=prec, workers=1)
                for sim in sims.values():
                    sim.build()
                frames = max(cfg["min_frames"],
                             min(cfg["max_frames"], math.ceil(cfg["sphere_frames"] / n)))
                calls = {key: partial(step_per_frame if key[1] == "per-frame" else
                                      ws.Simulator.step, sim, frames)
                         for key, sim in sims.items()}
                cpu = {}
                times = median_times(calls, device, cfg["repeats"], cpu=cpu)
                ref = sims[("brute", "per-frame")]
                stats = ref.stats
                row = {"precision": prec, "speed": speed, "n": n, "frames": frames,
                       "repeats": times[("brute", "per-frame")][1],
                       "grid": sims[("grid", "many")].broad_phase, "auto": auto.broad_phase,
                       "bounces_per_sphere_frame": stats.bounces / stats.sphere_frames,
                       "capped": stats.capped,
                       "identical": all(identical_states(ref, s) for s in sims.values())}
                for (bp, mode), (seconds, _) in times.items():
                    row[f"{bp}_{mode}_s"] = seconds
                    row[f"{bp}_{mode}_ns"] = seconds / (frames * n) * 1e9
                    row[f"{bp}_{mode}_cpu_ns"] = cpu[(bp, mode)] / (frames * n) * 1e9
                rows.append(row)
                del sims, auto
    head = [("precision", "precision", ""), ("m/s", "speed", "g"), ("N", "n", ",d"),
            ("frames", "frames", "d")]
    for kind, title in (("ns", "wall time"), ("cpu_ns", "CPU time of the process")):
        columns = list(head)
        for bp in BROAD_PHASES:
            for mode, label in zip(MODES, ("1/frame", "many"), strict=True):
                columns.append((f"{bp} {label}", f"{bp}_{mode}_{kind}", ".3g"))
        columns += [("auto picks", "auto", ""),
                    ("bounces/sph-frame", "bounces_per_sphere_frame", ".3f"),
                    ("identical", "identical", "")]
        print_table(f"Standard room, ns per sphere-frame ({title}), one core (workers=1): "
                    f"broad phase x one launch per frame ('1/frame') or one launch for all F "
                    f"frames ('many')", rows, columns)
    return rows


def grown_room(k: int, n: int, rng: np.random.Generator) -> ws.Scene:
    """A closed room of ``k`` boxes: 6 walls around ``k - 6`` plates, sized so that the plates
    keep the standard room's density, with an emitter of ``n`` spheres at 5 m/s filling it."""
    plates = k - 6
    inner = ROOM_SHAPE * (plates * PLATE_VOLUME) ** (1 / 3)
    hx, hy, hz = inner / 2
    w = WALL / 2  # walls overlap at the edges: no gap at any corner
    walls = ws.RoundedBoxes(
        [(0, -w, 0), (0, 2 * hy + w, 0), (-hx - w, hy, 0), (hx + w, hy, 0), (0, hy, -hz - w),
         (0, hy, hz + w)],
        [(hx + 2 * w, w, hz + 2 * w)] * 2 + [(w, hy + 2 * w, hz + 2 * w)] * 2
        + [(hx + 2 * w, hy + 2 * w, w)] * 2)
    low = np.array([-hx, 0.0, -hz]) + PLATE_MARGIN
    high = np.array([hx, 2 * hy, hz]) - PLATE_MARGIN
    center = rng.uniform(low, np.maximum(high, low), size=(plates, 3))
    half = np.column_stack([rng.uniform(*PLATE_HALF, plates), np.zeros(plates),
                            rng.uniform(*PLATE_HALF, plates)])
    q = rng.normal(size=(plates, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    boxes = ws.RoundedBoxes.concatenate(
        [walls, ws.RoundedBoxes(center, half, q, PLATE_ROUNDING)])
    clear = ROOM_RADIUS + 2 * 1e-3  # the emitter region keeps clear of the walls
    emitter = ws.Emitter(count=n, center=(0.0, hy, 0.0),
                         half_extents=(hx - clear, hy - clear, hz - clear), radius=ROOM_RADIUS,
                         speed=5.0, seed=SEED)
    return ws.Scene(boxes, name=f"grown-room-{k}", emitter=emitter)


def box_count_rows(cfg: dict, device) -> list[dict]:
    """Table 2: cost per sphere-frame against K, per broad phase."""
    n = cfg["k_n"]
    rows = []
    for k in cfg["k"]:
        scene = grown_room(k, n, np.random.default_rng([SEED, k]))
        swarm = scene.spawn()
        sims = {bp: ws.Simulator(scene, swarm, device=device, broad_phase=bp, workers=1)
                for bp in BROAD_PHASES}
        auto = ws.Simulator(scene, swarm, device=device, workers=1)
        frames = {}
        for bp, sim in sims.items():
            sim.build()
            t0 = time.perf_counter()
            sim.step(1)
            one = time.perf_counter() - t0
            frames[bp] = max(1, min(cfg["max_frames"], math.ceil(cfg["k_target_s"] / one)))
        cpu = {}
        times = median_times({bp: partial(sim.step, frames[bp]) for bp, sim in sims.items()},
                             device, cfg["repeats"], cpu=cpu)
        stats = sims["grid"].stats
        row = {"k": k, "n": n, "auto": auto.broad_phase, "grid": sims["grid"].broad_phase,
               "bounces_per_sphere_frame": stats.bounces / stats.sphere_frames,
               "repeats": times["grid"][1]}
        for bp in BROAD_PHASES:
            row[f"{bp}_frames"] = frames[bp]
            row[f"{bp}_ns"] = times[bp][0] / (frames[bp] * n) * 1e9
            row[f"{bp}_cpu_ns"] = cpu[bp] / (frames[bp] * n) * 1e9
        rows.append(row)
        del sims, auto
    base = rows[0]
    for row in rows:
        for bp in BROAD_PHASES:
            row[f"{bp}_growth"] = row[f"{bp}_cpu_ns"] / base[f"{bp}_cpu_ns"]
        row["log_growth"] = math.log2(row["k"]) / math.log2(base["k"])
    print_table(f"Cost against the number of boxes: grown room, N = {n:,}, 5 m/s, float32, "
                f"many frames per launch, one core", rows, [
                    ("K", "k", ",d"), ("brute ns", "brute_ns", ".3g"),
                    ("BVH ns", "bvh_ns", ".3g"), ("grid ns", "grid_ns", ".3g"),
                    ("brute CPU ns", "brute_cpu_ns", ".3g"), ("BVH CPU ns", "bvh_cpu_ns", ".3g"),
                    ("grid CPU ns", "grid_cpu_ns", ".3g"),
                    ("grid runs", "grid", ""), ("auto picks", "auto", ""),
                    ("brute CPU / K=16", "brute_growth", ".2f"),
                    ("BVH CPU / K=16", "bvh_growth", ".2f"),
                    ("grid CPU / K=16", "grid_growth", ".2f"),
                    ("log K / log 16", "log_growth", ".2f"),
                    ("bounces/sph-frame", "bounces_per_sphere_frame", ".3f")])
    return rows


def worker_rows(cfg: dict, device) -> list[dict]:
    """Table 3: workers 1 and 2 taking turns, default settings otherwise."""
    scene = ws.Scene.load(ROOM)
    n = cfg["workers_n"]
    rows = []
    for speed in SPEEDS:
        swarm = room_swarm(scene, n, speed, seed=SEED)
        sims = {w: ws.Simulator(scene, swarm, device=device, workers=w) for w in (1, 2)}
        for sim in sims.values():
            sim.build()
        frames = cfg["workers_frames"]
        cpu = {}
        times = median_times({w: partial(sim.step, frames) for w, sim in sims.items()}, device,
                             cfg["repeats"], cpu=cpu)
        one, two = times[1][0], times[2][0]
        rows.append({"speed": speed, "n": n, "frames": frames, "repeats": times[1][1],
                     "broad_phase": sims[1].broad_phase,
                     "ns_1": one / (frames * n) * 1e9, "ns_2": two / (frames * n) * 1e9,
                     "cpu_ns_1": cpu[1] / (frames * n) * 1e9,
                     "cpu_ns_2": cpu[2] / (frames * n) * 1e9,
                     "speedup": one / two, "identical": identical_states(sims[1], sims[2])})
        del sims
    print_table(f"Workers: standard room, N = {n:,}, float32, default settings", rows, [
        ("m/s", "speed", "g"), ("N", "n", ",d"), ("frames", "frames", "d"),
        ("broad phase", "broad_phase", ""), ("1 worker ns", "ns_1", ".3g"),
        ("2 workers ns", "ns_2", ".3g"), ("speed-up", "speedup", ".2f"),
        ("1 worker CPU ns", "cpu_ns_1", ".3g"), ("2 workers CPU ns", "cpu_ns_2", ".3g"),
        ("identical", "identical", "")])
    return rows


def goal_lines(room: list[dict]) -> list[str]:
    """Where the defaults (``auto``, float32, many frames per launch, one core) stand against
    the goal at N >= 1e5."""
    lines = []
    for r in room:
        if r["precision"] == "float32" and r["n"] >= 100_000:
            picked = r["auto"].split("-")[0]
            ns = r.get(f"{picked}_many_ns", float("nan"))
            cpu = r.get(f"{picked}_many_cpu_ns", float("nan"))
            lines.append(f"defaults at {r['speed']:g} m/s, N = {r['n']:,}: auto runs {r['auto']}, "
                         f"{ns:.3g} ns per sphere-frame wall, {cpu:.3g} CPU (goal {GOAL_NS:g}: "
                         f"{'met' if cpu <= GOAL_NS else f'{cpu / GOAL_NS:.1f}x above'} on CPU "
                         f"time)")
    return lines


TABLES = ("room", "boxes", "workers")


def main(argv: list[str] | None = None) -> int:
    args, only, device, info, out, started = open_study("speed", __doc__, TABLES, argv)
    cfg = QUICK if args.quick else FULL
    results = {"machine": info, "quick": args.quick, "settings": cfg, "tables": only}
    if "room" in only:
        results["room"] = room_rows(cfg, device)
        results["goal"] = goal_lines(results["room"])
        print("\n" + "\n".join(f"- {line}" for line in results["goal"]))
    if "boxes" in only:
        results["box_count"] = box_count_rows(cfg, device)
    if "workers" in only:
        results["workers"] = worker_rows(cfg, device)
    finish(out, results, started)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
