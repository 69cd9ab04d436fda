"""Accuracy against speed: float32 against float64 sweeps, error against step size, long-run
energy drift.

Run from the repository root:
``python -m benchmarks.accuracy_tables [--quick] [--device D] [--out PATH]``.

- Sweep precision: the float32 and float64 collide kernels on the same random sweeps (the
  sweep study's scene, N = 1e5, K = 16; quick: N = 1e4), at the origin and with every
  coordinate moved by 1e4 m; the float64 kernel is the reference.
- Step size: the standard room (``warpsim.Scene.load("room")``) at 60 m/s, N = 1e4, 1 s of
  simulated time at dt = 1/30 ... 1/240 s, both precisions, energy correction on and off.
- Long run: N = 1e3 for 10 000 frames (quick: 1000) at dt = 1/60 s, 5 and 60 m/s, both
  precisions, correction on and off, the state checked at ten points along the run.

Energies are computed in float64 from the state, with the floor (y = 0) as the reference
height, so that every sphere's energy is positive and relative changes are meaningful.
"""

from __future__ import annotations

import time

import numpy as np

import warpsim as ws
from warpsim.energy import relative_change
from warpsim.kernels.collide_kernels import collide_kernel
from warpsim.kernels.data import Features

from .common import ROOM, finish, median_times, parser, print_table, room_swarm, start
from .sweep import DT, SEED, build_seconds, device_sweep, sweep_inputs

FAR_OFFSET = 1e4
"""Translation [m], added to every coordinate, of the far-from-origin sweep case."""
STEP_SIZES = (1 / 30, 1 / 60, 1 / 120, 1 / 240)
"""Time steps [s] of the error-against-step-size runs (1 s of simulated time each)."""
ROOM_SPEEDS = (5.0, 60.0)
"""[m/s]"""
MAX_BOUNCES = 8
INNER_LOW = np.array([-5.0, 0.0, -5.0])
INNER_HIGH = np.array([5.0, 6.0, 5.0])
"""The standard room's inner faces [m] (``scenes/room.toml``): a centre outside has tunnelled."""

FULL = {"acc_sweep_n": 100_000, "acc_sweep_k": 16, "acc_sim_n": 10_000, "long_n": 1_000,
        "long_frames": 10_000, "repeats": 5}
QUICK = {"acc_sweep_n": 10_000, "acc_sweep_k": 16, "acc_sim_n": 10_000, "long_n": 1_000,
         "long_frames": 1_000, "repeats": 3}


def sweep_accuracy(cfg: dict, device) -> dict:
    """float32 against float64 collide kernels on the same sweeps, at the origin and 1e4 m
    away; their throughput side by side."""
    n, k = cfg["acc_sweep_n"], cfg["acc_sweep_k"]
    boxes, pos, vel, rad = sweep_inputs(n, k, seed=SEED + 1)
    build = {p: build_seconds(collide_kernel(Features(precision=p)), device)
             for p in ("float32", "float64")}
    rows = []
    for offset in (0.0, FAR_OFFSET):
        moved = ws.RoundedBoxes(boxes.center + offset, boxes.half_extents, boxes.rotation,
                                boxes.radius)
        runs = {p: device_sweep(moved, pos + offset, vel, rad, DT, p, device)
                for p in ("float32", "float64")}
        cpu = {}
        times = median_times({p: launch for p, (launch, _) in runs.items()}, device,
                             cfg["repeats"], cpu=cpu)
        secs = {p: t for p, (t, _) in times.items()}
        res = {p: read() for p, (_, read) in runs.items()}
        a, b = res["float32"], res["float64"]
        both = (a["box"] == b["box"]) & (b["box"] >= 0)
        path = np.linalg.norm(vel[both] * DT, axis=1)
        pos_err = np.abs(a["t"][both].astype(np.float64) - b["t"][both]) * path
        n32, n64 = a["normal"][both].astype(np.float64), b["normal"][both]
        angle = np.degrees(np.arctan2(np.linalg.norm(np.cross(n32, n64), axis=1),
                                      np.einsum("ij,ij->i", n32, n64)))
        rows.append({
            "offset": offset, "n": n, "k": k, "hits": int(np.count_nonzero(b["box"] >= 0)),
            "hit_miss_disagree": int(np.count_nonzero((a["box"] >= 0) != (b["box"] >= 0))),
            "box_disagree": int(np.count_nonzero(a["box"] != b["box"])),
            "max_pos_err": float(pos_err.max(initial=0.0)),
            "p99_pos_err": float(np.percentile(pos_err, 99)) if pos_err.size else 0.0,
            "max_normal_deg": float(angle.max(initial=0.0)),
            "f32_ns_per_sphere": secs["float32"] / n * 1e9,
            "f64_ns_per_sphere": secs["float64"] / n * 1e9,
            "f64_over_f32": secs["float64"] / secs["float32"],
            "f64_over_f32_cpu": cpu["float64"] / cpu["float32"]})
    print_table(f"Sweep accuracy, float32 against float64 (N = {n:,}, K = {k})", rows, [
        ("offset m", "offset", "g"), ("hits", "hits", ",d"),
        ("hit/miss diff", "hit_miss_disagree", "d"), ("box diff", "box_disagree", "d"),
        ("max |dt||d| m", "max_pos_err", ".2g"), ("p99 m", "p99_pos_err", ".2g"),
        ("max normal deg", "max_normal_deg", ".2g"),
        ("f32 ns/sph", "f32_ns_per_sphere", ".3g"), ("f64 ns/sph", "f64_ns_per_sphere", ".3g"),
        ("f64/f32", "f64_over_f32", ".2f"), ("f64/f32 CPU", "f64_over_f32_cpu", ".2f")])
    return {"build_s": build, "rows": rows}


def room_check(sim: ws.Simulator, swarm: ws.Swarm) -> dict:
    """Energy drift and largest gain over the spheres (the scale of :mod:`warpsim.energy`), the
    smallest clearance [m] to an obstacle (< 0: a sphere inside one) and the tunnelled count."""
    s = sim.state()
    change = relative_change(sim, swarm.position, s)
    position = s.position.astype(np.float64)
    clearance = sim.scene.boxes.signed_distance(position).min(axis=1) - swarm.radius
    inside = np.all((position >= INNER_LOW) & (position <= INNER_HIGH), axis=1)
    return {"max_drift": float(np.max(np.abs(change))), "max_gain": float(np.max(change)),
            "min_clearance": float(clearance.min()),
            "outside": int(np.count_nonzero(~inside))}


def step_size_error(cfg: dict, device) -> list[dict]:
    """The standard room at 60 m/s for 1 s of simulated time, per step size, precision and
    energy correction (without it the integrator's own energy error shows)."""
    room = ws.Scene.load(ROOM)
    swarm = room_swarm(room, cfg["acc_sim_n"], 60.0, seed=SEED + 2)
    rows = []
    for correction in (True, False):
        scene = ws.Scene(room.boxes, energy_correction=correction)
        for prec in ("float32", "float64"):
            for dt in STEP_SIZES:
                sim = ws.Simulator(scene, swarm, dt=dt, max_bounces=MAX_BOUNCES, device=device,
                                   precision=prec, workers=1)
                sim.build()
                sim.step(round(1.0 / dt))
                stats = sim.stats
                rows.append({"correction": correction, "precision": prec, "dt": dt,
                             "frames": stats.frames,
                             "sim_s_per_wall_s": stats.frames * dt / stats.seconds,
                             "capped": stats.capped, **room_check(sim, swarm)})
    print_table(f"Step size against error: standard room, 60 m/s, 1 s simulated, "
                f"N = {len(swarm):,}", rows, [
                    ("correction", "correction", ""), ("precision", "precision", ""),
                    ("frames", "frames", "d"), ("sim s / wall s", "sim_s_per_wall_s", ".3g"),
                    ("max drift", "max_drift", ".2g"), ("max gain", "max_gain", ".2g"),
                    ("min clearance m", "min_clearance", ".2g"), ("capped", "capped", "d"),
                    ("outside", "outside", "d")])
    return rows


def long_run_drift(cfg: dict, device) -> list[dict]:
    """Energy drift over a long run (dt = 1/60 s) per room speed, energy correction and
    precision; the state is checked at ten points along the run."""
    room = ws.Scene.load(ROOM)
    n, frames = cfg["long_n"], cfg["long_frames"]
    rows = []
    for speed in ROOM_SPEEDS:
        swarm = room_swarm(room, n, speed, seed=SEED + 3)
        for correction in (True, False):
            scene = ws.Scene(room.boxes, energy_correction=correction)
            for prec in ("float32", "float64"):
                sim = ws.Simulator(scene, swarm, dt=DT, max_bounces=MAX_BOUNCES, device=device,
                                   precision=prec, workers=1)
                sim.build()
                checks = []
                for _ in range(10):
                    sim.step(max(1, frames // 10))
                    checks.append(room_check(sim, swarm))
                stats = sim.stats
                rows.append({"speed": speed, "correction": correction, "precision": prec,
                             "frames": sim.frame,
                             "max_drift": max(c["max_drift"] for c in checks),
                             "final_drift": checks[-1]["max_drift"],
                             "max_gain": max(c["max_gain"] for c in checks),
                             "min_clearance": min(c["min_clearance"] for c in checks),
                             "outside": checks[-1]["outside"],
                             "ns_per_sphere_frame": stats.seconds / stats.sphere_frames * 1e9})
    print_table(f"Long run: energy drift, N = {n:,}, dt = 1/60 s", rows, [
        ("m/s", "speed", "g"), ("correction", "correction", ""), ("precision", "precision", ""),
        ("frames", "frames", ",d"), ("max drift", "max_drift", ".2g"),
        ("final", "final_drift", ".2g"), ("max gain", "max_gain", ".2g"),
        ("min clearance m", "min_clearance", ".2g"),
        ("outside", "outside", "d"), ("ns/sph-frame", "ns_per_sphere_frame", ".3g")])
    return rows


def main(argv: list[str] | None = None) -> int:
    args = parser("python -m benchmarks.accuracy_tables", __doc__).parse_args(argv)
    started = time.perf_counter()
    device, info, out = start("accuracy_tables", args)
    cfg = QUICK if args.quick else FULL
    results = {"machine": info, "quick": args.quick, "settings": cfg,
               "sweep": sweep_accuracy(cfg, device), "step_size": step_size_error(cfg, device),
               "long_run": long_run_drift(cfg, device)}
    finish(out, results, started)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
