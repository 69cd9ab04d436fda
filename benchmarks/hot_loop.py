"""The frame kernel's cost at this commit against another one, side by side in one run.

Run from the repository root: ``python -m benchmarks.hot_loop [--against REV] [--quick]
[--repeats R] [--cases float32/linear,...] [--speeds 5,60] [--broad-phase bvh] [--out PATH]``.

A restructuring of the kernels (issue 16: scene data in structs, one candidate loop) must leave
both the results and the hot loop's cost as they were. For each of float32/float64 and the
linear/ballistic motion, the standard room (``warpsim.Scene.load("room")``, or the bundled scene
``--scene`` names; its emitter's swarm,
``workers=1``, the broad phase ``auto`` picks) is advanced ``F`` frames by this checkout's
package and by the package of git revision ``REV`` (exported with ``git archive`` into a
temporary folder), each in its own process, the two taking turns ``R`` times. A process builds
its kernels first (``Simulator.build``), runs one untimed warm-up launch and then takes the best
of several timed ``sim.step(F)`` from the same start state. The time is the CPU time of the
launching thread (``time.thread_time``: with ``workers=1`` the CPU launch runs in it), so the
time a shared machine's other work holds the core is not counted; contention for caches still
is, hence the best of many turns. The table gives the best ns per sphere-frame of each side,
their ratio, the ratio of the two sides' median turns, the spread (the larger side's slowest
turn against its fastest, less one: on this shared 2-core machine 5 to 10 % is common, so a
ratio within a few percent of 1 is not a difference), and whether the final states are
bit-identical (a SHA-256 of the state's bytes). ``--scene grown-K`` advances
``benchmarks.speed``'s grown room of ``K`` boxes: built with its swarm by this checkout and
saved as arrays, which every side loads, so a revision older than the generator or the
benchmarks' helpers (``--against ed0e912``, 1 December) runs the same spheres among the same
boxes. With ``--speeds``, each case runs once per speed, the swarm drawn from the scene's
emitter with its speed replaced (every direction), and each side's cost at the last speed
against the first is printed (issue 20: 60 m/s against 5 m/s over a whole run).
``--broad-phase`` forces both sides' broad phase (the default ``auto`` picks the grid in the
standard room, so a change to the BVH's loop needs ``--broad-phase bvh``, or a grown room whose
paths leave the grid's cells).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .common import finish, parser, print_table, start

#: The packages of a source tree and where each lives in it (as ``pyproject.toml`` maps them).
PACKAGE_DIRS = {"warpsim": "warpsim", "warpsim/kernels": "kernels", "warpsim/export": "export",
                "warpsim/scenes": "scenes"}

CASES = [(prec, motion) for motion in ("linear", "ballistic") for prec in ("float32", "float64")]

#: One process's measurement: prints one JSON line.
CHILD = r"""
import dataclasses, hashlib, json, sys, time
import numpy as np
import warp as wp
wp.config.quiet = True
import warpsim as ws
prec, motion, n, frames, timings = sys.argv[1], sys.argv[2], *map(int, sys.argv[3:6])
if sys.argv[6].endswith(".npz"):  # a grown room and its swarm, saved by the parent as arrays
    d = np.load(sys.argv[6])
    scene = ws.Scene(ws.RoundedBoxes(d["center"], d["half_extents"], d["rotation"],
                                     d["box_radius"]))
    swarm = ws.Swarm(d["position"], d["velocity"], d["radius"], d["mass"])
else:
    scene = ws.Scene.load(sys.argv[6])
    if sys.argv[7]:  # the emitter's speed replaced (every direction, as the standard room's)
        emitter = dataclasses.replace(scene.emitter, count=n, speed=float(sys.argv[7]))
        swarm = emitter.spawn(scene.boxes, seed=20240601)
    else:
        swarm = scene.spawn(n=n, seed=20240601)
best = float("inf")
for _ in range(timings):
    sim = ws.Simulator(scene, swarm, precision=prec, motion=motion, workers=1, device="cpu",
                       broad_phase=sys.argv[9])
    sim.build()
    sim.step(1)
    wp.synchronize_device("cpu")
    t0 = time.thread_time()
    per = int(sys.argv[10]) or frames  # frames a launch: every step() call is one launch here
    for _ in range(frames // per):
        sim.step(per)
    wp.synchronize_device("cpu")
    best = min(best, time.thread_time() - t0)
s = sim.state()
h = hashlib.sha256()
for name in ("position", "velocity", "angular_momentum", "orientation", "energy"):
    if hasattr(s, name):  # an older revision's state may lack a field
        h.update(np.ascontiguousarray(getattr(s, name)).tobytes())
print(json.dumps({"seconds": best, "hash": h.hexdigest()[:16], "file": ws.__file__,
                  "broad_phase": sim.broad_phase}))
"""


def export_tree(rev: str, root: Path) -> Path:
    """The package of git revision ``rev`` laid out for import under ``root``."""
    src = root / "src"
    src.mkdir()
    archive = subprocess.run(["git", "archive", rev, *set(PACKAGE_DIRS.values())],
                             check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(src)], input=archive, check=True)
    site = root / "site"
    for package, folder in sorted(PACKAGE_DIRS.items()):  # "warpsim" first
        shutil.copytree(src / folder, site / package)
    return site


def save_grown_room(scene: str, n: int, speed: float | None, folder: Path) -> str:
    """``benchmarks.speed``'s grown room ``grown-K`` and its swarm of ``n`` (the emitter's
    speed replaced by ``speed`` [m/s] when given), built by this checkout and saved as arrays
    in ``folder``, so both sides, whatever their package's version, advance the same spheres
    among the same boxes. Returns the file's path."""
    from .speed import SEED, grown_room

    k = int(scene.removeprefix("grown-"))
    room = grown_room(k, n, np.random.default_rng([SEED, k]))
    if speed is None:
        swarm = room.spawn(n=n, seed=20240601)
    else:
        emitter = dataclasses.replace(room.emitter, count=n, speed=float(speed))
        swarm = emitter.spawn(room.boxes, seed=20240601)
    return save_arrays(folder / f"{scene}-{n}-{speed}.npz", room.boxes, swarm)


def save_arrays(path: Path, boxes, swarm, **extra) -> str:
    """Boxes and swarm as the arrays a child process of any revision rebuilds them from
    (``center``, ``half_extents``, ``rotation``, ``box_radius``; ``position``, ``velocity``,
    ``radius``, ``mass``), with ``extra`` arrays beside them. Returns the file's path."""
    np.savez(path, center=boxes.center, half_extents=boxes.half_extents,
             rotation=boxes.rotation, box_radius=boxes.radius, position=swarm.position,
             velocity=swarm.velocity, radius=swarm.radius, mass=swarm.mass, **extra)
    return str(path)


def measure(site: Path | None, prec: str, motion: str, n: int, frames: int,
            timings: int, scene: str = "room", speed: float | None = None,
            broad_phase: str = "auto", per_launch: int = 0) -> dict:
    """One process's best time; ``site`` None is this checkout's installed package; ``speed``
    [m/s] replaces the emitter's (None: the scene's swarm); ``broad_phase`` the simulator's;
    ``per_launch`` the frames of each ``step`` call (0: all ``frames`` in one)."""
    env = dict(os.environ)
    if site is not None:
        env["PYTHONPATH"] = str(site)
    out = subprocess.run([sys.executable, "-c", CHILD, prec, motion, str(n), str(frames),
                          str(timings), scene, "" if speed is None else repr(float(speed)),
                          str(Path(__file__).resolve().parent.parent), broad_phase,
                          str(per_launch)],
                         check=True, capture_output=True, text=True,
                         env=env, cwd=tempfile.gettempdir())
    result = json.loads(out.stdout.strip().splitlines()[-1])
    if site is not None and not result["file"].startswith(str(site)):
        raise RuntimeError(f"the revision's process imported {result['file']}")
    return result


def main(argv=None) -> None:
    p = parser("hot_loop", __doc__)
    p.add_argument("--against", default="main", help="git revision to compare with (main)")
    p.add_argument("--repeats", type=int, default=None, help="turns per side (default 5)")
    p.add_argument("--scene", default="room",
                   help="bundled scene to advance (default room; plates is the ballistic one), "
                        "or grown-K: benchmarks.speed's grown room of K boxes")
    p.add_argument("--cases", default=None,
                   help="comma-separated PRECISION/MOTION pairs (default: all four)")
    p.add_argument("--speeds", default=None,
                   help="comma-separated emitter speeds [m/s] replacing the scene's, each a row "
                        "(default: the scene's own swarm); with two, each side's cost at the "
                        "last against the first is printed too")
    p.add_argument("--broad-phase", default="auto",
                   help="the simulators' broad_phase (default auto; bvh, brute, grid, walk)")
    p.add_argument("--spheres", type=int, default=None,
                   help="spheres N (default 20000; 5000 with --quick)")
    p.add_argument("--frames", type=int, default=None,
                   help="frames F timed (default 240; 60 with --quick)")
    p.add_argument("--per-launch", type=int, default=0,
                   help="frames each sim.step call advances, a divisor of F (default: all F in "
                        "one call); 1 times a launch per frame, as a caller stepping frame by "
                        "frame pays it")
    args = p.parse_args(argv)
    cases = CASES if args.cases is None else [tuple(c.split("/")) for c in args.cases.split(",")]
    speeds = [None] if args.speeds is None else [float(s) for s in args.speeds.split(",")]
    cases = [(prec, motion, speed) for prec, motion in cases for speed in speeds]
    started = time.perf_counter()
    _, info, out = start("hot_loop", args)
    n, frames = (5_000, 60) if args.quick else (20_000, 240)
    n, frames = args.spheres or n, args.frames or frames
    if args.per_launch < 0 or (args.per_launch and frames % args.per_launch):
        p.error(f"--per-launch must divide the {frames} frames")
    repeats = args.repeats or (2 if args.quick else 5)
    rev = subprocess.run(["git", "rev-parse", "--short", args.against], check=True,
                         capture_output=True, text=True).stdout.strip()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        site = export_tree(rev, Path(tmp))
        for prec, motion, speed in cases:
            turns = {"base": [], "this": []}  # each turn's best of 3 [s]
            hashes = {}
            scene = args.scene
            if scene.startswith("grown-"):
                scene = save_grown_room(scene, n, speed, Path(tmp))
            for _ in range(repeats):
                for side, where in (("base", site), ("this", None)):
                    r = measure(where, prec, motion, n, frames, 3, scene, speed,
                                args.broad_phase, args.per_launch)
                    turns[side].append(r["seconds"])
                    hashes[side] = r["hash"]
            best = {k: min(v) for k, v in turns.items()}
            ns = {k: v / (n * frames) * 1e9 for k, v in best.items()}
            median = {k: float(np.median(v)) for k, v in turns.items()}
            rows.append({"precision": prec, "motion": motion, "speed": speed or "scene",
                         "broad_phase": r["broad_phase"],
                         "base_ns": ns["base"], "this_ns": ns["this"],
                         "ratio": ns["this"] / ns["base"],
                         "median_ratio": median["this"] / median["base"],
                         "spread": max(max(v) / min(v) - 1.0 for v in turns.values()),
                         "identical": "yes" if hashes["this"] == hashes["base"] else "NO",
                         "base_s": best["base"], "this_s": best["this"],
                         "base_turns_s": turns["base"], "this_turns_s": turns["this"]})
            print(f"  {prec} {motion} {speed or ''}: {ns['base']:.2f} -> {ns['this']:.2f} ns",
                  flush=True)
    print_table(f"Frame kernel, scene {args.scene}, N = {n:,}, F = {frames}, one core, best of "
                f"{repeats} x 3"
                + (f", {args.per_launch} frames a launch" if args.per_launch else "")
                + f": {rev} against this checkout",
                rows, [("precision", "precision", "s"), ("motion", "motion", "s"),
                       ("m/s", "speed", ""), ("broad phase", "broad_phase", "s"),
                       (f"{rev} [ns]", "base_ns", ".2f"), ("this [ns]", "this_ns", ".2f"),
                       ("ratio", "ratio", ".3f"), ("ratio of medians", "median_ratio", ".3f"),
                       ("spread", "spread", ".1%"), ("identical", "identical", "s")])
    speed_ratios = {}
    if len(speeds) > 1:
        for prec, motion in {(row["precision"], row["motion"]) for row in rows}:
            by = {row["speed"]: row for row in rows
                  if (row["precision"], row["motion"]) == (prec, motion)}
            first, last = by[speeds[0]], by[speeds[-1]]
            for side in ("base", "this"):
                key = f"{prec}/{motion}/{side}"
                speed_ratios[key] = last[f"{side}_ns"] / first[f"{side}_ns"]
                print(f"{prec} {motion}, {rev if side == 'base' else 'this'}: "
                      f"{speeds[-1]:g} m/s costs {speed_ratios[key]:.2f}x {speeds[0]:g} m/s")
    finish(out, {"machine": info, "against": rev, "scene": args.scene,
                 "broad_phase": args.broad_phase, "per_launch": args.per_launch, "spheres": n,
                 "frames": frames, "repeats": repeats, "rows": rows,
                 "speed_ratios": speed_ratios}, started)


if __name__ == "__main__":
    main()
