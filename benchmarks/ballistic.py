"""The ballistic model's figures: error against the exact motion, energy drift, cost.

Run from the repository root: ``python -m benchmarks.ballistic [--quick] [--out PATH.json]``.
Prints three Markdown tables and writes their rows to JSON (default
``benchmarks/results/ballistic.json``, ``ballistic-quick.json`` with ``--quick``):

1. error against ``warpsim.analysis.reference`` (float64, event-driven, exact) of a swarm dropped
   onto tilted rounded plates (the bundled ``plates`` scene), after 0.5 s, at dt = 1/30 ... 1/240 s,
   both precisions, for the ballistic model and (for scale) the linear one, both started from
   the swarm's velocity (the velocity at t = 0 for both models);
2. energy drift over 10 000 frames without any correction (ballistic, both precisions; the
   linear model without its reset beside it);
3. cost: ns per sphere-frame in the standard room (``room``) at 5 and 60 m/s, linear against
   ballistic at the same dt, default broad phase, one core; CPU time of the process, so other
   work on the machine inflates it less than wall time (ratios are from the same run).
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

import warpsim as ws
from warpsim.analysis import reference
from warpsim.energy import relative_change
from warpsim.export.files import write_json
from warpsim.machine import machine

from .common import RESULTS

STEPS = (1 / 30, 1 / 60, 1 / 120, 1 / 240)
"""Time steps [s] of the accuracy table."""
HORIZON = 0.5
"""Time [s] at which positions are compared with the exact motion."""


def tilted_plates() -> ws.Scene:
    """The bundled ``plates`` scene (a floor, six rounded plates tilted 8 to 30 degrees)."""
    return ws.Scene.load("plates")


def drop_swarm(n: int, seed: int = 1) -> ws.Swarm:
    return tilted_plates().spawn(n=n, seed=seed)


def accuracy_rows(n: int) -> list[dict]:
    scene, swarm = tilted_plates(), drop_swarm(n)
    exact = reference.simulate(scene, swarm, HORIZON, times=[HORIZON])
    ok = ~exact.incomplete
    rows = []
    for motion in ("ballistic", "linear"):
        for precision in ("float64", "float32"):
            for dt in STEPS:
                frames = round(HORIZON / dt)
                sim = ws.Simulator(scene, swarm, dt=dt, precision=precision, motion=motion,
                                   max_bounces=16, device="cpu", workers=1)
                sim.step(frames)
                err = np.linalg.norm(sim.state().position.astype(np.float64)
                                     - exact.position[0], axis=1)[ok]
                rows.append({"motion": motion, "precision": precision, "dt": dt,
                             "median_m": float(np.median(err)), "max_m": float(err.max()),
                             "spheres": int(ok.sum())})
    return rows


def drift_rows(n: int, frames: int) -> list[dict]:
    scene = ws.Scene.load("room")
    swarm = scene.spawn(n=n, seed=2)
    rows = []
    for motion in ("ballistic", "linear"):
        for precision in ("float32", "float64"):
            sim = ws.Simulator(scene, swarm, motion=motion, precision=precision,
                               energy_correction=False, device="cpu", workers=1)
            sim.step(frames)
            drift = relative_change(sim, swarm.position)
            rows.append({"motion": motion, "precision": precision, "frames": frames,
                         "max_gain": float(drift.max()), "max_loss": float(-drift.min()),
                         "median": float(np.median(drift))})
    return rows


def cost_rows(n: int, frames: int, repeats: int) -> list[dict]:
    scene = ws.Scene.load("room")
    rows = []
    for speed in (5.0, 60.0):
        swarm = dataclasses.replace(scene.emitter, speed=speed).spawn(scene.boxes, n=n, seed=3)
        sims = {}
        for motion in ("linear", "ballistic"):
            for precision in ("float32", "float64"):
                sim = ws.Simulator(scene, swarm, motion=motion, precision=precision,
                                   device="cpu", workers=1)
                sim.build()
                sim.step(5)
                sims[(motion, precision)] = sim
        times = {key: [] for key in sims}
        for _ in range(repeats):  # interleaved, so both models see the same machine
            for key, sim in sims.items():
                start = time.process_time()
                sim.step(frames)
                times[key].append(time.process_time() - start)
        for precision in ("float32", "float64"):
            lin = float(np.median(times[("linear", precision)])) / (frames * n) * 1e9
            bal = float(np.median(times[("ballistic", precision)])) / (frames * n) * 1e9
            rows.append({"speed": speed, "precision": precision, "linear_ns": lin,
                         "ballistic_ns": bal, "ratio": bal / lin,
                         "broad_phase": sims[("ballistic", precision)].broad_phase})
    return rows


def table(title: str, header: list[str], rows: list[list]) -> str:
    lines = [f"### {title}", "", "| " + " | ".join(header) + " |",
             "| " + " | ".join("---" for _ in header) + " |"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.ballistic",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes (about a minute)")
    parser.add_argument("--out", default=None, help="JSON output path (default: "
                                                     "benchmarks/results/ballistic.json)")
    args = parser.parse_args(argv)
    quick = args.quick
    acc = accuracy_rows(32 if quick else 96)
    drift = drift_rows(100 if quick else 300, 2000 if quick else 10_000)
    cost = cost_rows(2000 if quick else 20_000, 30 if quick else 100, 3 if quick else 5)
    print(table("Error against the exact motion after 0.5 s (tilted rounded plates)",
                ["motion", "precision", "dt [s]", "median [m]", "max [m]"],
                [[r["motion"], r["precision"], f"1/{round(1 / r['dt'])}", f"{r['median_m']:.1e}",
                  f"{r['max_m']:.1e}"] for r in acc]))
    print(table(f"Energy drift over {drift[0]['frames']} frames, no correction (room)",
                ["motion", "precision", "largest gain", "largest loss", "median"],
                [[r["motion"], r["precision"], f"{r['max_gain']:.1e}", f"{r['max_loss']:.1e}",
                  f"{r['median']:.1e}"] for r in drift]))
    print(table("Cost in the standard room, one core (CPU time)",
                ["speed [m/s]", "precision", "linear [ns]", "ballistic [ns]", "ratio",
                 "broad phase"],
                [[r["speed"], r["precision"], f"{r['linear_ns']:.0f}",
                  f"{r['ballistic_ns']:.0f}", f"{r['ratio']:.2f}", r["broad_phase"]]
                 for r in cost]))
    out = Path(args.out) if args.out else RESULTS / (
        f"ballistic{'-quick' if quick else ''}.json")
    write_json(out, {"machine": machine(), "accuracy": acc, "drift": drift, "cost": cost})
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
