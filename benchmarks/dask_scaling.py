"""Sphere-frames per second of a sharded run against the number of Dask processes.

For each process count, a ``LocalCluster`` of that many worker processes (one thread each) is
started and warmed (every process builds or loads the frame kernel once), then the same sharded
run is timed: ``warpsim.distributed.run`` from the first task submitted to the root stage written,
shard layers included. A one-process run of the same shards (``client=None``, one thread)
is the baseline. Figures go to BENCHMARKS.md ("On a Dask cluster").

    python benchmarks/dask_scaling.py [--scene room] [-n 16384] [--frames 300] [--every 30]
                                      [--processes 1,2] [--shards 8] [--json out.json]
"""

from __future__ import annotations

import argparse
import os
import shutil
import tempfile
import time

import warpsim as ws
from warpsim import distributed as wd
from warpsim.export.files import write_json
from warpsim.machine import machine

from .common import RESULTS


def _timed(scene, folder, args, client):
    out = os.path.join(folder, "run.usdc")
    shutil.rmtree(os.path.join(folder, "run.shards"), ignore_errors=True)
    start = time.perf_counter()
    summary = wd.run(scene, out, n=args.n, seed=0, frames=args.frames, every=args.every,
                     client=client, shards=args.shards, threads=1, progress=False)
    seconds = time.perf_counter() - start
    return {"seconds": seconds, "sphere_frames": summary.sphere_frames,
            "sphere_frames_per_second": summary.sphere_frames / seconds,
            "task_seconds": summary.task_seconds, "processes_used": summary.processes_used,
            "shards": summary.shards, "digests": list(summary.digests)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="room")
    p.add_argument("-n", type=int, default=16384)
    p.add_argument("--frames", type=int, default=300)
    p.add_argument("--every", type=int, default=30)
    p.add_argument("--processes", default="1,2",
                   help="Dask process counts to time, comma-separated")
    p.add_argument("--shards", type=int, default=8)
    p.add_argument("--json", default=str(RESULTS / "dask_scaling.json"),
                   help="JSON results (default: benchmarks/results/dask_scaling.json)")
    args = p.parse_args(argv)
    import distributed

    scene = ws.Scene.load(args.scene)
    rows = []
    with tempfile.TemporaryDirectory(prefix="warpsim-dask-") as folder:
        wd.run(scene, os.path.join(folder, "warm.usdc"), n=64, frames=2, block=16,
               progress=False)  # kernel built once in the cache before anything is timed
        here = _timed(scene, folder, args, None)
        rows.append({"processes": 0, **here})
        print(f"in process      : {here['sphere_frames_per_second']:,.0f} sphere-frames/s "
              f"({here['seconds']:.2f} s)")
        for count in [int(w) for w in args.processes.split(",")]:
            with distributed.LocalCluster(n_workers=count, threads_per_worker=1, processes=True,
                                          dashboard_address=None) as cluster, \
                    distributed.Client(cluster) as client:
                wd.run(scene, os.path.join(folder, "warm.usdc"), n=64 * count, frames=2,
                       block=16, shards=2 * count, client=client, progress=False)
                row = {"processes": count, **_timed(scene, folder, args, client)}
            same = row["digests"] == here["digests"]
            rows.append(row)
            print(f"{count} process(es) : {row['sphere_frames_per_second']:,.0f} "
                  f"sphere-frames/s ({row['seconds']:.2f} s, {row['processes_used']} used; "
                  f"bits equal to in-process: {same})")
    result = {"scene": args.scene, "n": args.n, "frames": args.frames, "every": args.every,
              "shards": args.shards, "machine": machine(), "rows": rows}
    write_json(args.json, result)
    print(f"results written to {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
