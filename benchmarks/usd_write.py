"""USD writing: time against the number of obstacles, and the size estimate against real runs.

One command::

    python benchmarks/usd_write.py            # full: up to 1e5 boxes, every bundled scene
    python benchmarks/usd_write.py --quick    # small sizes (development)
    python benchmarks/usd_write.py --only scenes   # one of the two tables

Prints two tables and writes ``benchmarks/results/usd_write.json`` (``--out`` to change it):

1. Writing ``K`` obstacles (a lattice of identical boxes, half of them rounded, and boxes of all
   different shapes) with a small trajectory: seconds to write and to read the boxes back, wall
   and CPU time of this process (on a shared machine the CPU time is the steadier figure),
   microseconds per box, bytes per box. Linear writing shows as a constant time per box.
2. For short runs of the bundled scenes (their own sphere counts and settings), the file size
   :func:`warpsim.export.estimate_usd_bytes` predicts against the size written, with and without
   velocities (``.usdc`` and ``.usda``).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

import warpsim as ws
from warpsim.export import estimate_usd_bytes, read_usd_boxes, write_usd
from warpsim.export.files import write_json
from warpsim.machine import machine

from .common import RESULTS

FULL_BOXES = (1_000, 3_000, 10_000, 30_000, 100_000)
QUICK_BOXES = (1_000, 3_000)
SCENE_FRAMES = 120  # frames simulated per bundled scene for the size table
QUICK_SCENE_FRAMES = 20


def lattice(k: int, distinct: bool, seed: int = 0) -> ws.RoundedBoxes:
    """``k`` boxes on a cubic lattice 1 m apart, randomly turned; half sharp, half rounded.
    ``distinct``: every box has its own half extents (no two share a mesh)."""
    rng = np.random.default_rng(seed)
    side = int(np.ceil(k ** (1.0 / 3.0)))
    idx = np.arange(k)
    center = np.stack([idx % side, (idx // side) % side, idx // (side * side)], axis=1) * 1.0
    q = rng.normal(size=(k, 4))
    half = (rng.uniform(0.1, 0.3, (k, 3)) if distinct else np.tile([0.2, 0.1, 0.3], (k, 1)))
    return ws.RoundedBoxes(center=center, half_extents=half,
                           rotation=q / np.linalg.norm(q, axis=1, keepdims=True),
                           radius=np.where(idx % 2 == 0, 0.0, 0.05))


def small_trajectory(n: int = 10, frames: int = 3) -> ws.Trajectory:
    return ws.Trajectory(frame=np.arange(frames), dt=1 / 60, position=np.zeros((frames, n, 3)),
                         orientation=np.tile([0.0, 0.0, 0.0, 1.0], (frames, n, 1)),
                         radius=np.full(n, 0.1))


def bench_boxes(counts, folder: Path) -> list[dict]:
    rows = []
    for distinct in (False, True):
        for k in counts:
            boxes = lattice(k, distinct)
            path = folder / "boxes.usdc"
            t0, c0 = time.perf_counter(), time.process_time()
            write_usd(path, boxes, small_trajectory(), warn=False)
            t1, c1 = time.perf_counter(), time.process_time()
            back = read_usd_boxes(path)
            t2, c2 = time.perf_counter(), time.process_time()
            assert len(back) == k and np.array_equal(back.center, boxes.center)
            size = path.stat().st_size
            estimate = estimate_usd_bytes(10, 3, "usdc", boxes=boxes, spinning=False)
            rows.append({"boxes": k, "shapes": "distinct" if distinct else "shared",
                         "write_s": t1 - t0, "read_s": t2 - t1, "write_cpu_s": c1 - c0,
                         "read_cpu_s": c2 - c1, "write_us_per_box": 1e6 * (t1 - t0) / k,
                         "write_cpu_us_per_box": 1e6 * (c1 - c0) / k, "bytes": size,
                         "bytes_per_box": size / k, "estimate": estimate})
            print(f"{rows[-1]['shapes']:>8} {k:>8,} boxes: write {t1 - t0:7.2f} s "
                  f"(CPU {c1 - c0:6.2f} s, {1e6 * (c1 - c0) / k:5.0f} us/box), read "
                  f"{t2 - t1:6.2f} s (CPU {c2 - c1:6.2f} s), "
                  f"{size / 1e6:7.2f} MB ({size / k:5.0f} B/box), estimate "
                  f"{estimate / size:4.2f} x", flush=True)
    return rows


def bench_scenes(frames: int, folder: Path) -> list[dict]:
    rows = []
    for name, _ in ws.list_scenes():
        scene = ws.Scene.load(name)
        swarm = scene.spawn()
        sim = ws.Simulator(scene, swarm)
        traj = sim.run(frames, velocities=True)
        spinning = bool(scene.friction > 0.0 or np.any(swarm.angular_momentum != 0.0))
        for fmt in ("usdc", "usda"):
            for velocities in (False, True):
                path = folder / f"{name}.{fmt}"
                write_usd(path, scene, traj, velocities=velocities, warn=False)
                size = path.stat().st_size
                estimate = estimate_usd_bytes(len(swarm), len(traj), fmt, boxes=scene.boxes,
                                              spinning=spinning, velocities=velocities)
                rows.append({"scene": name, "format": fmt, "spheres": len(swarm),
                             "frames": len(traj), "boxes": len(scene.boxes),
                             "spinning": spinning, "velocities": velocities, "bytes": size,
                             "estimate": estimate, "ratio": estimate / size})
                print(f"{name:>10} .{fmt} {len(swarm):>5} spheres x {len(traj)} frames, "
                      f"{len(scene.boxes):>3} boxes, spin {spinning!s:>5}, velocities "
                      f"{velocities!s:>5}: {size / 1e6:6.2f} MB written, estimate "
                      f"{estimate / 1e6:6.2f} MB ({estimate / size:4.2f} x)", flush=True)
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python benchmarks/usd_write.py",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes (development)")
    parser.add_argument("--only", choices=("boxes", "scenes"), help="one of the two tables")
    parser.add_argument("--out", default=None, help="JSON results (default: "
                                                     "benchmarks/results/usd_write.json)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        boxes = scenes = None
        if args.only in (None, "boxes"):
            print("1. Writing obstacles (usdc, 10 spheres x 3 frames)")
            boxes = bench_boxes(QUICK_BOXES if args.quick else FULL_BOXES, folder)
        if args.only in (None, "scenes"):
            print(f"\n2. Size estimate against written files "
                  f"({QUICK_SCENE_FRAMES if args.quick else SCENE_FRAMES} frames per scene)")
            scenes = bench_scenes(QUICK_SCENE_FRAMES if args.quick else SCENE_FRAMES, folder)
    from pxr import Usd

    results = {"machine": dict(machine(), usd=".".join(map(str, Usd.GetVersion()))),
               "quick": args.quick, "boxes": boxes, "scenes": scenes,
               "runtime_s": time.perf_counter() - start}
    out = Path(args.out) if args.out else RESULTS / (
        f"usd_write{'-quick' if args.quick else ''}.json")
    write_json(out, results)
    print(f"\nruntime {results['runtime_s']:.0f} s; results written to {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
