"""Instructions, branches and mispredicted branches per sphere-frame of the frame kernel,
counted by valgrind's callgrind: the same figures on every run, where timings on a shared
machine move by 5 to 10 % (``benchmarks.hot_loop``'s spread column).

Run from the repository root: ``python -m benchmarks.instructions [--against REV] [--cases
float32/linear,...] [--speeds 5,60] [--scene room] [--broad-phase auto] [--quick]``. Needs
valgrind (Debian's ``valgrind`` package: ``valgrind`` and ``callgrind_control``).

Each case runs in a fresh process under ``valgrind --tool=callgrind --instr-atstart=no
--branch-sim=yes``: it builds its simulator (the kernel from Warp's cache; the build is not
counted) and advances one frame, then the parent switches counting on (``callgrind_control
-i on``) for ``sim.step(F)`` and off after it. The figures are the process's events in that
span divided by ``N F``: the kernel's work and Warp's launch of it from Python (a few
thousand instructions a launch, nothing against ``N F`` sphere-frames). The mispredictions
are those of callgrind's simulated predictor (two-bit counters indexed by branch address
and recent history), not of this CPU's: a proxy for the branches that a predictor finds
hard, such as a fast swarm's "does this box pass the reject". Instructions are not time
(stalls, cache misses and this CPU's own predictor are not counted), so this study tells
whether a change removed work or mispredictions, and ``hot_loop`` whether that was time.

``--against REV`` runs the package of git revision ``REV`` (exported as ``hot_loop`` does)
side by side, from the same swarm (the scene's emitter drawn by this checkout and saved as
arrays, with the scene's boxes and physics), and says whether the two final states are the
same bits. With two ``--speeds``, each side's figures at the last speed against the first
are printed too (issue 20: 60 m/s against 5 m/s).
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .common import finish, parser, print_table, start
from .hot_loop import CASES, export_tree

#: The events callgrind counts with ``--branch-sim=yes``, in the order of its summary line.
EVENTS = {"Ir": "instructions", "Bc": "branches", "Bcm": "mispredicted",
          "Bi": "indirect", "Bim": "indirect_mispredicted"}

#: The counted process: builds, waits, steps ``F`` frames while counted, then hashes its state.
CHILD = r"""
import hashlib, json, sys
import numpy as np
import warp as wp
wp.config.quiet = True
import warpsim as ws
prec, motion, frames, broad_phase, data = sys.argv[1:6]
frames = int(frames)
d = np.load(data)
scene = ws.Scene(ws.RoundedBoxes(d["center"], d["half_extents"], d["rotation"], d["box_radius"]),
                 **json.loads(str(d["physics"])))
swarm = ws.Swarm(d["position"], d["velocity"], d["radius"], d["mass"])
sim = ws.Simulator(scene, swarm, precision=prec, motion=motion, workers=1, device="cpu",
                   broad_phase=broad_phase)
sim.build()
sim.step(1)
wp.synchronize_device("cpu")
print("ready", flush=True)
sys.stdin.readline()
sim.step(frames)
wp.synchronize_device("cpu")
print("done", flush=True)
sys.stdin.readline()
s = sim.state()
h = hashlib.sha256()
for name in ("position", "velocity", "angular_momentum", "orientation", "energy"):
    h.update(np.ascontiguousarray(getattr(s, name)).tobytes())
print(json.dumps({"hash": h.hexdigest()[:16], "file": ws.__file__,
                  "broad_phase": sim.broad_phase}), flush=True)
"""

#: The scene's physics the saved arrays carry (``warpsim.Scene`` keywords).
PHYSICS = ("gravity", "friction", "energy_retention", "energy_correction", "max_angular_speed",
           "dt", "max_bounces")


def plain(value):
    """A scene attribute as JSON: arrays as lists of floats, NumPy scalars as Python's."""
    if value is None or isinstance(value, bool):
        return value
    if np.ndim(value):
        return [float(x) for x in np.asarray(value).ravel()]
    return value.item() if isinstance(value, np.generic) else value


def need_valgrind() -> None:
    """Stop with one line when valgrind's tools are not installed."""
    missing = [tool for tool in ("valgrind", "callgrind_control") if shutil.which(tool) is None]
    if missing:
        sys.exit(f"benchmarks.instructions needs {' and '.join(missing)}: install Debian's "
                 "valgrind package (apt-get install valgrind)")


def save_case(scene_name: str, n: int, speed: float | None, folder: Path) -> str:
    """The scene's boxes, physics and swarm (its emitter's, the speed replaced by ``speed``
    [m/s] when given, seed 20240601), drawn by this checkout and saved as arrays, so every
    side starts from the same spheres. Returns the file's path."""
    import warpsim as ws

    scene = ws.Scene.load(scene_name)
    emitter = scene.emitter
    if speed is not None:
        emitter = dataclasses.replace(emitter, speed=float(speed))
    swarm = dataclasses.replace(emitter, count=n).spawn(scene.boxes, seed=20240601)
    physics = {k: plain(getattr(scene, k)) for k in PHYSICS}
    b = scene.boxes
    path = folder / f"{scene_name}-{n}-{speed}.npz"
    np.savez(path, center=b.center, half_extents=b.half_extents, rotation=b.rotation,
             box_radius=b.radius, position=swarm.position, velocity=swarm.velocity,
             radius=swarm.radius, mass=swarm.mass, physics=json.dumps(physics))
    return str(path)


def count(site: Path | None, prec: str, motion: str, frames: int, broad_phase: str,
          data: str) -> dict:
    """One process's counted events (totals) and its state's hash; ``site`` None is this
    checkout's installed package."""
    env = dict(os.environ)
    if site is not None:
        env["PYTHONPATH"] = str(site)
    with tempfile.TemporaryDirectory() as tmp:
        child = subprocess.Popen(
            ["valgrind", "--tool=callgrind", "--instr-atstart=no", "--branch-sim=yes",
             "--toggle-collect=ffi_call*",
             f"--callgrind-out-file={tmp}/callgrind.out", sys.executable, "-c", CHILD, prec,
             motion, str(frames), broad_phase, data],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env=env, cwd=tmp)
        try:
            # counting on when it has built and taken its first frame, off after the frames
            for expected, switch in (("ready", "on"), ("done", "off")):
                if child.stdout.readline().strip() != expected:
                    raise RuntimeError(f"the counted process did not say {expected!r}")
                subprocess.run(["callgrind_control", "-i", switch, str(child.pid)],
                               check=True, capture_output=True)
                child.stdin.write("go\n")
                child.stdin.flush()
            out, err = child.communicate(timeout=600)
        finally:
            if child.poll() is None:
                child.kill()
    names = re.search(r"Events\s*:\s*([A-Za-z ]+)\n", err)
    values = re.search(r"Collected\s*:\s*([\d ]+)\n", err)
    if child.returncode != 0 or names is None or values is None:
        raise RuntimeError(f"callgrind gave no counts (exit {child.returncode}): {err[-500:]}")
    counted = dict(zip(names.group(1).split(), map(int, values.group(1).split()), strict=True))
    result = json.loads(out.strip().splitlines()[-1])
    if site is not None and not result["file"].startswith(str(site)):
        raise RuntimeError(f"the revision's process imported {result['file']}")
    result.update({EVENTS[k]: v for k, v in counted.items() if k in EVENTS})
    return result


def main(argv=None) -> None:
    p = parser("instructions", __doc__)
    p.add_argument("--against", default=None,
                   help="git revision to count side by side (default: this checkout only)")
    p.add_argument("--scene", default="room", help="bundled scene (default room)")
    p.add_argument("--cases", default=None,
                   help="comma-separated PRECISION/MOTION pairs (default: all four)")
    p.add_argument("--speeds", default="5,60",
                   help="comma-separated emitter speeds [m/s] (default 5,60); 'scene' keeps "
                        "the scene's own")
    p.add_argument("--broad-phase", default="auto",
                   help="the simulators' broad_phase (default auto; bvh, brute, grid, walk)")
    args = p.parse_args(argv)
    if args.device != "cpu":
        sys.exit("benchmarks.instructions counts the CPU kernel: --device must be cpu")
    need_valgrind()
    cases = CASES if args.cases is None else [tuple(c.split("/")) for c in args.cases.split(",")]
    speeds = [None if s == "scene" else float(s) for s in args.speeds.split(",")]
    started = time.perf_counter()
    _, info, out = start("instructions", args)
    n, frames = (500, 20) if args.quick else (2_000, 60)
    rev = None
    if args.against:
        rev = subprocess.run(["git", "rev-parse", "--short", args.against], check=True,
                             capture_output=True, text=True).stdout.strip()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        site = export_tree(rev, Path(tmp)) if rev else None
        sides = [("base", site)] * bool(rev) + [("this", None)]
        for speed in speeds:
            data = save_case(args.scene, n, speed, Path(tmp))
            for prec, motion in cases:
                row = {"precision": prec, "motion": motion, "speed": speed or "scene"}
                hashes = {}
                for side, where in sides:
                    r = count(where, prec, motion, frames, args.broad_phase, data)
                    hashes[side] = r["hash"]
                    row["broad_phase"] = r["broad_phase"]
                    for key in ("instructions", "branches", "mispredicted"):
                        row[f"{side}_{key}"] = r[key] / (n * frames)
                if rev:
                    row["ratio"] = row["this_instructions"] / row["base_instructions"]
                    row["identical"] = "yes" if hashes["this"] == hashes["base"] else "NO"
                rows.append(row)
                print(f"  {prec} {motion} {speed or ''}: "
                      + ", ".join(f"{side} {row[f'{side}_instructions']:.1f} instructions"
                                  for side, _ in sides), flush=True)
    columns = [("precision", "precision", "s"), ("motion", "motion", "s"),
               ("m/s", "speed", ""), ("broad phase", "broad_phase", "s")]
    for side, _ in sides:
        name = rev if side == "base" else "this"
        columns += [(f"{name} instructions", f"{side}_instructions", ".1f"),
                    (f"{name} branches", f"{side}_branches", ".2f"),
                    (f"{name} mispredicted", f"{side}_mispredicted", ".3f")]
    if rev:
        columns += [("ratio", "ratio", ".3f"), ("identical", "identical", "s")]
    print_table(f"Frame kernel under callgrind, scene {args.scene}, N = {n:,}, F = {frames}, "
                "per sphere-frame" + (f": {rev} against this checkout" if rev else ""),
                rows, columns)
    speed_ratios = {}
    if len(speeds) > 1:
        for prec, motion in cases:
            by = {row["speed"]: row for row in rows
                  if (row["precision"], row["motion"]) == (prec, motion)}
            first, last = by[speeds[0] or "scene"], by[speeds[-1] or "scene"]
            for side, _ in sides:
                key = f"{prec}/{motion}/{side}"
                speed_ratios[key] = {
                    k: last[f"{side}_{k}"] / first[f"{side}_{k}"]
                    for k in ("instructions", "branches", "mispredicted")}
                r = speed_ratios[key]
                print(f"{prec} {motion}, {rev if side == 'base' else 'this'}: "
                      f"{speeds[-1]:g} m/s against {speeds[0]:g} m/s: "
                      f"{r['instructions']:.2f}x the instructions, {r['branches']:.2f}x the "
                      f"branches, {r['mispredicted']:.2f}x the mispredicted ones")
    finish(out, {"machine": info, "against": rev, "scene": args.scene,
                 "broad_phase": args.broad_phase, "spheres": n, "frames": frames,
                 "rows": rows, "speed_ratios": speed_ratios}, started)


if __name__ == "__main__":
    main()
