"""The compiler's optimisation level of the frame kernel: its cold build time and its speed at
each level, side by side.

Run from the repository root:
``python -m benchmarks.opt_level [--quick] [--device D] [--levels default,2] [--out PATH]``.

Warp builds every module at an optimisation level, the module option ``optimization_level``:
Warp's own default is 3 for a GPU and 2 for the CPU; this package builds its kernels at
``warpsim.kernels.variant.OPTIMIZATION_LEVEL`` (2) on both. On an H200 the ballistic frame
kernel's first build took 246 s at Warp's default and 2.9 s at level 2, at the same speed and
with the same bits (``benchmarks/results/opt_level-cuda.json``, BENCHMARKS.md "GPU: an NVIDIA
H200"): this study is what chose the level, for the linear and the ballistic models of the
standard room (float32, spheres at 5 m/s).

Each measurement runs in a fresh process with a kernel cache of its own per motion and level (a
temporary folder): the first round's process builds the kernel there (its cold build time), the
later rounds' processes load it. Each process sets the level on the simulator's kernel module
before its first build (``default`` is Warp's own choice, the module option ``None``),
advances ``--frames`` frames once to warm up, then times ``step(frames)`` (the median of
``--repeats``). The levels of a motion take turns within each round, so that a change of load
falls on all of them alike; the figure is the median over the rounds, and ``identical`` says
whether the final state is the first level's, bit for bit.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

from .common import finish, parser, print_table, run_child, start

MOTIONS = ("linear", "ballistic")
SPEED = 5.0
"""Sphere speed [m/s]: the standard room's own."""
SEED = 20261204
CHILD_TIMEOUT_S = 900
"""A process that takes longer [s] is reported as failed (a cold ballistic build for a GPU at
level 3 takes about 3 minutes)."""
SIZES = {"cpu": (20_000, 120), "cuda": (1_000_000, 300)}
"""Default ``(N, frames)`` per device kind: a few tenths of a second of timed frames."""
QUICK_SIZES = {"cpu": (4_000, 40), "cuda": (100_000, 100)}


def child(spec: dict) -> dict:
    """In a fresh process: build the kernel at the level into ``spec["cache"]`` and time it."""
    import warp as wp

    wp.config.kernel_cache_dir = spec["cache"]  # before wp.init()
    import warpsim as ws
    from benchmarks.common import room_swarm
    from warpsim.apps.startup import init_warp

    init_warp(debug=False)
    scene = ws.Scene.load("room")
    swarm = room_swarm(scene, spec["n"], SPEED, seed=SEED)
    sim = ws.Simulator(scene, swarm, device=spec["device"], motion=spec["motion"], workers=1)
    sim._kernel.module.options["optimization_level"] = (
        None if spec["level"] == "default" else int(spec["level"]))
    build_s = sim.build()
    sim.step(spec["frames"])
    times = []
    for _ in range(spec["repeats"]):
        begin = time.perf_counter()
        sim.step(spec["frames"])  # ends with a device sync
        times.append(time.perf_counter() - begin)
    state = sim.state()
    digest = hashlib.sha256(b"".join(a.tobytes() for a in (
        state.position, state.velocity, state.energy))).hexdigest()
    return {"build_s": build_s, "ns": statistics.median(times) / (spec["n"] * spec["frames"])
            * 1e9, "digest": digest}


def main(argv: list[str] | None = None) -> int:
    p = parser("python -m benchmarks.opt_level", __doc__)
    p.add_argument("--levels", default="default,2",
                   help="comma-separated levels: default (Warp's) or 0 to 3 (default: default,2)")
    p.add_argument("--rounds", type=int, default=3, help="rounds of turns (default 3)")
    p.add_argument("--repeats", type=int, default=5, help="timed steps per process (default 5)")
    p.add_argument("--child", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child is not None:
        print(json.dumps(child(json.loads(args.child))))
        return 0
    levels = [v.strip() for v in args.levels.split(",") if v.strip()]
    bad = [v for v in levels if v != "default" and v not in ("0", "1", "2", "3")]
    if bad or not levels:
        p.error(f"--levels takes default or 0 to 3, got {bad or 'none'}")
    started = time.perf_counter()
    device, info, out = start("opt_level", args)
    kind = "cpu" if device.is_cpu else "cuda"
    n, frames = (QUICK_SIZES if args.quick else SIZES)[kind]
    rounds = 1 if args.quick else max(1, args.rounds)
    samples = {(m, v): [] for m in MOTIONS for v in levels}
    with tempfile.TemporaryDirectory(prefix="warpsim-opt-") as root:
        for _ in range(rounds):
            for motion in MOTIONS:
                for level in levels:
                    spec = {"cache": str(Path(root) / f"{motion}-{level}"), "n": n,
                            "frames": frames, "repeats": max(1, args.repeats),
                            "device": str(device), "motion": motion, "level": level}
                    samples[(motion, level)].append(
                        run_child("opt_level", ["--child", json.dumps(spec)], CHILD_TIMEOUT_S))
    rows = []
    for motion in MOTIONS:
        base = samples[(motion, levels[0])]
        for level in levels:
            got = samples[(motion, level)]
            ok = [s for s in got if "error" not in s]
            row = {"motion": motion, "level": level, "n": n, "frames": frames,
                   "runs": len(ok), "errors": [s["error"] for s in got if "error" in s]}
            if ok:
                row["cold_build_s"] = got[0].get("build_s")
                row["ns"] = statistics.median(s["ns"] for s in ok)
                row["identical"] = all(s["digest"] == b.get("digest")
                                       for s, b in zip(got, base, strict=True) if "error" not in s)
            rows.append(row)
    for row in rows:
        first = next(r for r in rows if r["motion"] == row["motion"])
        if "ns" in row and "ns" in first:
            row["ratio"] = row["ns"] / first["ns"]
    print_table(f"Frame kernel at each optimisation level: the standard room, float32, "
                f"{SPEED:g} m/s, N = {n:,}, {frames} frames a step, median of {rounds} rounds",
                rows, [("motion", "motion", ""), ("level", "level", ""),
                       ("cold build [s]", "cold_build_s", ".3g"), ("ns/sphere-frame", "ns", ".3g"),
                       (f"against {levels[0]}", "ratio", ".3f"), ("identical", "identical", ""),
                       ("runs", "runs", "d")])
    for row in rows:
        for error in row["errors"]:
            print(f"- {row['motion']} at level {row['level']}: {error}")
    finish(out, {"machine": info, "quick": args.quick, "levels": levels, "n": n,
                 "frames": frames, "rounds": rounds, "rows": rows}, started)
    return 0


if __name__ == "__main__":
    sys.exit(main())
