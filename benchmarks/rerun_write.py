"""Rerun recordings: the size estimate against written files, and the cost of writing them.

One command::

    python -m benchmarks.rerun_write            # every bundled scene, 120 frames each
    python -m benchmarks.rerun_write --quick    # 20 frames each (development)

For each bundled scene (its own sphere count and settings), simulates with contacts recorded
and the per-frame figures sampled (:func:`warpsim.export.rerun.run_with_scalars`), writes the
recording, and prints its size against :func:`warpsim.export.estimate_rerun_bytes`, the
seconds to write it, and the simulation's wall time with the figures sampled against one plain
``Simulator.run`` (the sampling costs one launch per recorded frame). Writes
``benchmarks/results/rerun_write.json`` (``rerun_write-quick.json`` with ``--quick``). Needs the
``viewer`` extra.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

import warpsim as ws
from warpsim.export import estimate_rerun_bytes, write_rerun
from warpsim.export.files import write_json
from warpsim.export.rerun import run_with_scalars
from warpsim.machine import machine

from .common import RESULTS

FRAMES = 120
QUICK_FRAMES = 20


def measure(name: str, frames: int, folder: Path) -> dict:
    scene = ws.Scene.load(name)
    swarm = scene.spawn()
    plain = ws.Simulator(scene, swarm)
    plain.build(events=True)
    start = time.perf_counter()
    plain.run(frames, events=True)
    plain_s = time.perf_counter() - start
    sim = ws.Simulator(scene, swarm)
    sim.build(events=True)
    start = time.perf_counter()
    traj, scalars = run_with_scalars(sim, frames, events=True)
    sampled_s = time.perf_counter() - start
    events = traj.events
    start = time.perf_counter()
    path = write_rerun(folder / f"{name}.rrd", scene, traj, scalars=scalars)
    write_s = time.perf_counter() - start
    span = int(max(traj.frame[-1], events.frame.max(initial=0)) - traj.frame[0] + 1)
    estimate = estimate_rerun_bytes(len(swarm), len(traj), boxes=scene.boxes, scalars=True,
                                    events=len(events), event_frames=span if len(events) else 0,
                                    unborn=int(np.count_nonzero(~traj.alive())))
    size = path.stat().st_size
    return {"scene": name, "spheres": len(swarm), "frames": len(traj), "boxes": len(scene.boxes),
            "contacts": len(events), "bytes": size, "estimate": estimate,
            "error": estimate / size - 1.0, "write_s": write_s, "run_s": plain_s,
            "run_sampled_s": sampled_s}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="20 frames per scene")
    parser.add_argument("--out", help="JSON path (default: benchmarks/results/rerun_write.json, "
                                       "or rerun_write-quick.json)")
    args = parser.parse_args(argv)
    frames = QUICK_FRAMES if args.quick else FRAMES
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for name, _ in ws.list_scenes():
            rows.append(measure(name, frames, Path(folder)))
            r = rows[-1]
            print(f"{r['scene']:<11} {r['spheres']:>6} spheres {r['frames']:>4} frames "
                  f"{r['contacts']:>7} contacts: {r['bytes'] / 1e6:7.2f} MB, estimate "
                  f"{r['error']:+6.1%}; write {r['write_s']:.2f} s; run {r['run_s']:.2f} s, "
                  f"sampled {r['run_sampled_s']:.2f} s")
    worst = float(np.max(np.abs([r["error"] for r in rows])))
    print(f"largest estimate error: {worst:.1%}")
    out = Path(args.out) if args.out else RESULTS / (
        f"rerun_write{'-quick' if args.quick else ''}.json")
    write_json(out, {"machine": machine(), "frames": frames, "rows": rows})
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
