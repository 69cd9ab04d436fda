"""Brute force against the BVH, where ``auto`` switches between them: ``benchmarks.speed``'s
grown rooms of K boxes (6 walls around K - 6 plates), each broad phase forced, side by side.

Without a grid, and as the grid's fallback, ``warpsim.broad_phase.exhaustive`` takes the BVH
from ``device.bvh_min_boxes(dtype)`` boxes on (32 in float32, 12 in float64) and tries every
box below. This study measures where the two cross: for each K, precision, motion and emitter
speed, one process a turn for each broad phase (``benchmarks.hot_loop``'s child: the best of 3
timings of F frames in one launch, one core), the turns alternating; the figure is each
side's best turn, with the ratio BVH / brute force and what ``exhaustive`` takes. Both sides
advance the same spheres among the same boxes and must end in the same bits (``identical``).

Run from the repository root: ``python -m benchmarks.bvh_crossover [--k 8,12,16,22,32]
[--cases float32/linear,...] [--speeds 5,60] [--quick]``.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from .common import finish, parser, print_table, start
from .hot_loop import CASES, measure, save_grown_room


def main(argv=None) -> None:
    from warpsim.broad_phase import exhaustive

    p = parser("bvh_crossover", __doc__)
    p.add_argument("--k", default="8,10,12,16,22,28,32",
                   help="comma-separated box counts K of the grown rooms (at least 7)")
    p.add_argument("--cases", default=None,
                   help="comma-separated PRECISION/MOTION pairs (default: all four)")
    p.add_argument("--speeds", default="5,60",
                   help="comma-separated emitter speeds [m/s] (default 5,60)")
    p.add_argument("--turns", type=int, default=None, help="turns per side (default 2)")
    args = p.parse_args(argv)
    ks = [int(k) for k in args.k.split(",")]
    if min(ks) < 7:
        p.error("--k: a grown room has 6 walls and at least one plate (K >= 7)")
    cases = CASES if args.cases is None else [tuple(c.split("/")) for c in args.cases.split(",")]
    speeds = [float(s) for s in args.speeds.split(",")]
    started = time.perf_counter()
    _, info, out = start("bvh_crossover", args)
    n, frames = (5_000, 60) if args.quick else (20_000, 240)
    turns = args.turns or (1 if args.quick else 2)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in ks:
            for speed in speeds:
                scene = save_grown_room(f"grown-{k}", n, speed, Path(tmp))
                for prec, motion in cases:
                    best, hashes = {}, {}
                    for _ in range(turns):
                        for bp in ("brute", "bvh"):
                            r = measure(None, prec, motion, n, frames, 3, scene, None, bp)
                            best[bp] = min(best.get(bp, np.inf), r["seconds"])
                            hashes[bp] = r["hash"]
                    ns = {bp: s / (n * frames) * 1e9 for bp, s in best.items()}
                    dtype = np.float64 if prec == "float64" else np.float32
                    rows.append({"k": k, "speed": speed, "precision": prec, "motion": motion,
                                 "brute_ns": ns["brute"], "bvh_ns": ns["bvh"],
                                 "ratio": ns["bvh"] / ns["brute"],
                                 "exhaustive": exhaustive(k, dtype)[0],
                                 "identical": "yes" if hashes["brute"] == hashes["bvh"]
                                 else "NO"})
                    print(f"  K = {k}, {speed:g} m/s, {prec} {motion}: brute "
                          f"{ns['brute']:.1f} ns, BVH {ns['bvh']:.1f} ns", flush=True)
    print_table(f"Brute force against the BVH, grown rooms, N = {n:,}, F = {frames}, one core, "
                f"best of {turns} x 3", rows,
                [("K", "k", "d"), ("m/s", "speed", "g"), ("precision", "precision", "s"),
                 ("motion", "motion", "s"), ("brute [ns]", "brute_ns", ".1f"),
                 ("BVH [ns]", "bvh_ns", ".1f"), ("BVH / brute", "ratio", ".2f"),
                 ("exhaustive takes", "exhaustive", "s"), ("identical", "identical", "s")])
    finish(out, {"machine": info, "spheres": n, "frames": frames, "turns": turns,
                 "rows": rows}, started)


if __name__ == "__main__":
    main()
