"""Instructions, branches and mispredicted branches per sphere-frame of the frame kernel,
counted by valgrind's callgrind: the same figures on every run, where timings on a shared
machine move by 5 to 10 % (``benchmarks.hot_loop``'s spread column).

Run from the repository root: ``python -m benchmarks.instructions [--against REV] [--cases
float32/linear,...] [--speeds 5,60] [--scene room] [--broad-phase auto] [--memory] [--where N]
[--quick]``. Needs
valgrind (Debian's ``valgrind`` package: ``valgrind`` and ``callgrind_control``).

Each case's kernel is first built outside valgrind (:func:`native_build`), then the case
runs in a fresh process under ``valgrind --tool=callgrind --instr-atstart=no --branch-sim=yes
--toggle-collect=ffi_call*``: it loads that build (the object this machine runs, though
valgrind's CPU shows fewer ISA features than the machine's), advances one frame, then the
parent switches counting on (``callgrind_control -i on``) for ``sim.step(F)`` and off after
it, and within that span only the calls ctypes makes are counted (the kernel, called through
libffi, and Warp's few native calls around it; Python's own work for the launch is not).
The figures are those events divided by ``N F``. The mispredictions are those of
callgrind's simulated predictor (two-bit counters indexed by branch address and recent
history), not of this CPU's: a proxy for the branches that a predictor finds
hard, such as a fast swarm's "does this box pass the reject". Instructions are not time
(stalls, cache misses and this CPU's own predictor are not counted), so this study tells
whether a change removed work or mispredictions, and ``hot_loop`` whether that was time.

``--against REV`` runs the package of git revision ``REV`` (exported as ``hot_loop`` does)
side by side, from the same swarm (the scene's emitter drawn by this checkout and saved as
arrays, with the scene's boxes and physics), and says whether the two final states are the
same bits. With two ``--speeds``, each side's figures at the last speed against the first
are printed too (issue 20: 60 m/s against 5 m/s).

``--memory`` has callgrind simulate the caches too (``--cache-sim=yes``: its model of a
first- and a last-level cache, sized as the CPU reports them) and adds each case's data reads
and writes and the simulated first- and last-level misses per sphere-frame: what a change did
to the frame's memory traffic, such as stores to the stack.

``--where N`` builds the kernel with line tables (``frame_profile``'s, which leave the code
as it was: the totals do not change) and has callgrind keep its counts per instruction; each
instruction of the kernel is mapped onto the Python statement whose generated code it is in,
as ``frame_profile`` maps its samples, and the N statements with the most mispredicted
branches are listed per case and side: where the branches that a fast swarm makes hard are.
With it, the runs of the stack loads that wait for their stores (``benchmarks.store_forwarding``'s
scan of the same object) are counted too, per statement and in all (``split-store loads`` per
sphere-frame).
"""

from __future__ import annotations

import collections
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
from .frame_profile import LINE_TABLES, forward_offset
from .hot_loop import CASES, export_tree, save_arrays
from .store_forwarding import forward_disassembly, split_store_loads, statements_of

#: The events callgrind counts with ``--branch-sim=yes``, in the order of its summary line.
EVENTS = {"Ir": "instructions", "Bc": "branches", "Bcm": "mispredicted",
          "Bi": "indirect", "Bim": "indirect_mispredicted"}

#: The events ``--cache-sim=yes`` adds (``--memory``): data reads and writes, and the misses
#: of callgrind's simulated first-level data cache and last-level cache.
MEMORY_EVENTS = {"Dr": "data_reads", "Dw": "data_writes", "D1mr": "l1_read_misses",
                 "D1mw": "l1_write_misses", "DLmr": "ll_read_misses", "DLmw": "ll_write_misses",
                 "I1mr": "l1_instruction_misses", "ILmr": "ll_instruction_misses"}

def valgrind_flags(cpuinfo: str | None = None) -> str:
    """Compiler flags that keep the kernel within the instructions valgrind runs: Warp builds
    CPU kernels with ``-march=native``, and valgrind (3.19 to 3.24) has no AVX-512, so on a
    CPU with it (``avx512f`` among ``/proc/cpuinfo``'s flags) the kernel is built without it
    (clang's front-end form of ``-mno-avx512f``, `` -target-feature -avx512f``, which also
    turns off the extensions built on it): the code this CPU runs less its AVX-512
    instructions, the same on both sides of ``--against``. Empty on a CPU without AVX-512
    (the code is this CPU's).
    ``cpuinfo`` is the text of ``/proc/cpuinfo`` (read when None)."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text(encoding="utf-8")
        except OSError:
            return ""
    flags = next((line.split(":", 1)[1].split() for line in cpuinfo.splitlines()
                  if line.startswith("flags")), [])
    return " -target-feature -avx512f" if "avx512f" in flags else ""


#: The flags every counted kernel is built with (:func:`valgrind_flags`).
VALGRIND_FLAGS = valgrind_flags()

#: The per-sphere-frame figures ``--memory`` adds to each row.
MEMORY_FIGURES = ("data_reads", "data_writes", "l1_read_misses", "l1_write_misses",
                  "ll_read_misses", "ll_write_misses")

#: The counted process: builds, waits, steps ``F`` frames while counted, then hashes its state.
CHILD = r"""
import ctypes, hashlib, inspect, json, sys
import numpy as np
import warp as wp
wp.config.quiet = True
import warpsim as ws
prec, motion, frames, broad_phase, data, flags, isa = sys.argv[1:8]
frames = int(frames)
# Warp keys a CPU object by the ISA features it sees, and valgrind's CPU shows fewer than the
# machine's: given the native build's features, this process loads the object that build made
try:
    from warp._src import context as warp_context
except ImportError:
    warp_context = None
if isa and hasattr(warp_context, "_cpu_feature_set_cache"):
    warp_context._cpu_feature_set_cache = frozenset(isa.split(","))
if flags:  # line tables, for --where
    wp.config.cpu_compiler_flags = (wp.config.cpu_compiler_flags or "") + flags
d = np.load(data)
scene = ws.Scene(ws.RoundedBoxes(d["center"], d["half_extents"], d["rotation"], d["box_radius"]),
                 **json.loads(str(d["physics"])))
swarm = ws.Swarm(d["position"], d["velocity"], d["radius"], d["mass"])
sim = ws.Simulator(scene, swarm, precision=prec, motion=motion, workers=1, device="cpu",
                   broad_phase=broad_phase)
sim.build()
sim.step(1)
wp.synchronize_device("cpu")
where = {}
kernel = getattr(sim, "_kernel", None)
if kernel is not None:  # where the kernel's code is, for --where
    exe = next(iter(kernel.module.execs.values()))
    forward = exe.get_kernel_hooks(kernel).forward
    where = {"address": ctypes.cast(forward, ctypes.c_void_p).value,
             "object": str(exe.binary_path), "kernel_file": inspect.getsourcefile(kernel.func)}
if hasattr(warp_context, "_get_cpu_feature_set"):
    where["isa"] = ",".join(sorted(warp_context._get_cpu_feature_set()))
print(json.dumps(where), flush=True)
sys.stdin.readline()
per = int(sys.argv[8]) or frames  # frames a launch: every step() call is one launch here
for _ in range(frames // per):
    sim.step(per)
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
    side starts from the same spheres; ``grown-K`` is ``benchmarks.speed``'s grown room of
    ``K`` boxes. Returns the file's path."""
    import warpsim as ws

    if scene_name.startswith("grown-"):  # benchmarks.speed's grown room of K boxes
        from .speed import SEED, grown_room

        k = int(scene_name.removeprefix("grown-"))
        scene = grown_room(k, n, np.random.default_rng([SEED, k]))
    else:
        scene = ws.Scene.load(scene_name)
    emitter = scene.emitter
    if speed is not None:
        emitter = dataclasses.replace(emitter, speed=float(speed))
    swarm = dataclasses.replace(emitter, count=n).spawn(scene.boxes, seed=20240601)
    physics = {k: plain(getattr(scene, k)) for k in PHYSICS}
    return save_arrays(folder / f"{scene_name}-{n}-{speed}.npz", scene.boxes, swarm,
                       physics=json.dumps(physics))


def count(site: Path | None, prec: str, motion: str, frames: int, broad_phase: str,
          data: str, where: bool = False, memory: bool = False, per_launch: int = 0) -> dict:
    """One process's counted events (totals) and its state's hash; ``site`` None is this
    checkout's installed package. With ``where``, the kernel is built with line tables and
    ``statements`` holds the events of each Python statement of it (:func:`statement_events`);
    with ``memory``, callgrind also simulates the caches (``MEMORY_EVENTS``), and the
    statements hold their data reads and writes too. ``per_launch`` is the frames of each
    ``sim.step`` call, each one launch (0: all ``frames`` in one).
    """
    env = dict(os.environ)
    if site is not None:
        env["PYTHONPATH"] = str(site)
    flags = VALGRIND_FLAGS + (LINE_TABLES if where else "")
    args = [sys.executable, "-c", CHILD, prec, motion, str(frames), broad_phase, data, flags]
    with tempfile.TemporaryDirectory() as tmp:
        native = native_build([*args, "", str(per_launch)], env, tmp)
        args += [native.get("isa", ""), str(per_launch)]
        dump = ["--dump-instr=yes", "--dump-line=no", "--compress-pos=no",
                "--compress-strings=no"] if where else []
        child = subprocess.Popen(
            ["valgrind", "--tool=callgrind", "--instr-atstart=no", "--branch-sim=yes",
             *(["--cache-sim=yes"] if memory else []), "--toggle-collect=ffi_call*", *dump,
             f"--callgrind-out-file={tmp}/callgrind.out", *args],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env=env, cwd=tmp)
        try:
            # counting on when it has built and taken its first frame, off after the frames
            ready = child.stdout.readline()
            if not ready.startswith("{"):
                child.kill()
                said = [line for line in child.communicate()[1].splitlines()
                        if line and not line.startswith("==")]
                raise RuntimeError("the counted process did not start: "
                                   + (said[-1] if said else "it said nothing"))
            located = json.loads(ready)
            for expected, switch in (("", "on"), ("done", "off")):
                if expected and child.stdout.readline().strip() != expected:
                    raise RuntimeError(f"the counted process did not say {expected!r}")
                subprocess.run(["callgrind_control", "-i", switch, str(child.pid)],
                               check=True, capture_output=True)
                child.stdin.write("go\n")
                child.stdin.flush()
            out, err = child.communicate(timeout=600)
            if where and located:
                text = Path(f"{tmp}/callgrind.out").read_text(encoding="utf-8")
                statements = statement_events(text, located)
        finally:
            if child.poll() is None:
                child.kill()
    counted = summary(err) if child.returncode == 0 else None
    if counted is None:
        raise RuntimeError(f"callgrind gave no counts (exit {child.returncode}): {err[-500:]}")
    result = json.loads(out.strip().splitlines()[-1])
    if site is not None and not result["file"].startswith(str(site)):
        raise RuntimeError(f"the revision's process imported {result['file']}")
    result.update(counted)
    result["native_object"] = bool(native.get("object")) and located.get("object") == native[
        "object"]
    if where:
        result["statements"] = statements if located else []
    return result


def summary(err: str) -> dict | None:
    """The totals of callgrind's closing summary (its ``Events :`` and ``Collected :`` lines, in
    the standard error), named as in ``EVENTS`` and ``MEMORY_EVENTS`` (events of neither are
    left out); None when there is no summary."""
    names = re.search(r"Events\s*:\s*([A-Za-z0-9 ]+)\n", err)
    values = re.search(r"Collected\s*:\s*([\d ]+)\n", err)
    if names is None or values is None:
        return None
    known = {**EVENTS, **MEMORY_EVENTS}
    counted = dict(zip(names.group(1).split(), map(int, values.group(1).split()), strict=True))
    return {known[k]: v for k, v in counted.items() if k in known}


def native_build(args: list[str], env: dict, cwd: str) -> dict:
    """Runs the counted process's script (``args``) outside valgrind up to its first frame,
    which builds the case's kernel into Warp's cache (seconds; inside valgrind the same build
    takes a minute or more), and returns what it says of the kernel: its object and the ISA
    features Warp keyed it by (``{}`` when it said nothing). Given those features
    (the counted process's last argument), it loads that object: the code this machine runs,
    not one built for the fewer features valgrind's CPU shows."""
    child = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                             stderr=subprocess.DEVNULL, text=True, env=env, cwd=cwd)
    try:
        line = child.stdout.readline()
    finally:
        child.kill()
        child.communicate()
    return json.loads(line) if line.startswith("{") else {}


def statement_events(text: str, located: dict) -> list[dict]:
    """The events of a callgrind dump (``--dump-instr=yes``, uncompressed) at the kernel's
    instructions, summed per Python statement of the kernel (``frame_profile``'s mapping:
    the object's line tables, then the generated C++'s statement comments); the events of a
    call site's callee (the line after ``calls=``) are the callee's, not counted there. The
    data reads and writes are 0 unless callgrind simulated the caches (``--memory``)."""
    obj = Path(located["object"])
    base = located["address"] - forward_offset(obj)
    kept = ("Ir", "Bc", "Bcm", "Dr", "Dw")
    names, after_call = [], False
    per_offset = collections.defaultdict(lambda: [0] * len(kept))
    for line in text.splitlines():
        if line.startswith("events:"):
            names = line.split()[1:]
        elif line.startswith("calls="):
            after_call = True
        elif line.startswith("0x"):
            if after_call:
                after_call = False
                continue
            addr, *values = line.split()
            offset = int(addr, 16) - base
            if 0 <= offset < 1 << 24:
                got = dict(zip(names, map(int, values), strict=False))
                cost = per_offset[offset]
                for i, key in enumerate(kept):
                    cost[i] += got.get(key, 0)
    where = statements_of(obj, list(per_offset), located["kernel_file"])
    split = split_store_loads(forward_disassembly(obj))
    by: dict[tuple, list[int]] = collections.defaultdict(lambda: [0] * (len(kept) + 1))
    for offset, cost in per_offset.items():
        key = where[offset]
        for i in range(len(kept)):
            by[key][i] += cost[i]
        if offset in split:  # a load that waits for its stores: its runs
            by[key][len(kept)] += cost[0]
    return [{"file": f, "line": ln, "text": t, "instructions": c[0], "branches": c[1],
             "mispredicted": c[2], "data_reads": c[3], "data_writes": c[4],
             "split_loads": c[5]}
            for (f, ln, t), c in sorted(by.items(), key=lambda kv: -kv[1][2])]


def main(argv=None) -> None:
    p = parser("instructions", __doc__)
    p.add_argument("--against", default=None,
                   help="git revision to count side by side (default: this checkout only)")
    p.add_argument("--scene", default="room",
                   help="bundled scene (default room), or grown-K: benchmarks.speed's grown "
                        "room of K boxes")
    p.add_argument("--cases", default=None,
                   help="comma-separated PRECISION/MOTION pairs (default: all four)")
    p.add_argument("--speeds", default="5,60",
                   help="comma-separated emitter speeds [m/s] (default 5,60); 'scene' keeps "
                        "the scene's own")
    p.add_argument("--broad-phase", default="auto",
                   help="the simulators' broad_phase (default auto; bvh, brute, grid, walk)")
    p.add_argument("--where", type=int, default=0, metavar="N",
                   help="also list, per case and side, the N statements of the kernel with "
                        "the most mispredicted branches (built with line tables)")
    p.add_argument("--memory", action="store_true",
                   help="also simulate the caches: data reads and writes and the first- and "
                        "last-level misses per sphere-frame (with --where, per statement too)")
    p.add_argument("--per-launch", type=int, default=0,
                   help="frames each sim.step call advances, a divisor of F (default: all F in "
                        "one launch); 1 counts a launch per frame, its cost per sphere included")
    args = p.parse_args(argv)
    if args.device != "cpu":
        sys.exit("benchmarks.instructions counts the CPU kernel: --device must be cpu")
    need_valgrind()
    cases = CASES if args.cases is None else [tuple(c.split("/")) for c in args.cases.split(",")]
    speeds = [None if s == "scene" else float(s) for s in args.speeds.split(",")]
    started = time.perf_counter()
    _, info, out = start("instructions", args)
    n, frames = (500, 20) if args.quick else (2_000, 60)
    if args.per_launch < 0 or (args.per_launch and frames % args.per_launch):
        p.error(f"--per-launch must divide the {frames} frames")
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
                    r = count(where, prec, motion, frames, args.broad_phase, data,
                              where=args.where > 0, memory=args.memory,
                              per_launch=args.per_launch)
                    hashes[side] = r["hash"]
                    if args.where:
                        row[f"{side}_statements"] = [
                            {**st, **{k: st[k] / (n * frames)
                                      for k in ("instructions", "branches", "mispredicted",
                                                "data_reads", "data_writes", "split_loads")}}
                            for st in r["statements"]]
                        row[f"{side}_split_loads"] = sum(
                            st["split_loads"] for st in row[f"{side}_statements"])
                    row["broad_phase"] = r["broad_phase"]
                    for key in ("instructions", "branches", "mispredicted",
                                *(MEMORY_FIGURES if args.memory else ())):
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
        if args.where:
            columns += [(f"{name} split-store loads", f"{side}_split_loads", ".3f")]
        if args.memory:
            columns += [(f"{name} data reads", f"{side}_data_reads", ".1f"),
                        (f"{name} data writes", f"{side}_data_writes", ".1f"),
                        (f"{name} L1 read misses", f"{side}_l1_read_misses", ".3f"),
                        (f"{name} L1 write misses", f"{side}_l1_write_misses", ".3f"),
                        (f"{name} LL read misses", f"{side}_ll_read_misses", ".3f"),
                        (f"{name} LL write misses", f"{side}_ll_write_misses", ".3f")]
    if rev:
        columns += [("ratio", "ratio", ".3f"), ("identical", "identical", "s")]
    print_table(f"Frame kernel under callgrind, scene {args.scene}, N = {n:,}, F = {frames}"
                + (f", {args.per_launch} frames a launch" if args.per_launch else "")
                + ", per sphere-frame" + (f": {rev} against this checkout" if rev else ""),
                rows, columns)
    for row in rows if args.where else []:
        for side, _ in sides:
            name = rev if side == "base" else "this"
            print_table(f"{name}, {row['precision']} {row['motion']}, {row['speed']} m/s: the "
                        f"{args.where} statements with the most mispredicted branches, per "
                        "sphere-frame", row[f"{side}_statements"][:args.where],
                        [("mispredicted", "mispredicted", ".3f"),
                         ("branches", "branches", ".2f"),
                         ("instructions", "instructions", ".1f"),
                         *([("data writes", "data_writes", ".2f")] if args.memory else []),
                         ("split-store loads", "split_loads", ".3f"),
                         ("file", "file", "s"), ("line", "line", ""), ("statement", "text", "s")])
            split = [st for st in row[f"{side}_statements"] if st["split_loads"] > 0]
            if split:
                print_table(f"{name}, {row['precision']} {row['motion']}, {row['speed']} m/s: "
                            "the statements whose stack loads wait for their stores "
                            "(benchmarks.store_forwarding), runs per sphere-frame",
                            sorted(split, key=lambda st: -st["split_loads"])[:args.where],
                            [("split-store loads", "split_loads", ".3f"),
                             ("file", "file", "s"), ("line", "line", ""),
                             ("statement", "text", "s")])
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
                 "broad_phase": args.broad_phase, "per_launch": args.per_launch, "spheres": n,
                 "frames": frames,
                 "rows": rows, "speed_ratios": speed_ratios}, started)


if __name__ == "__main__":
    main()
