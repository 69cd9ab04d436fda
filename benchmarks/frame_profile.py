"""Where the frame kernel's time goes: a sampling profile mapped onto the Python statements.

Run from the repository root (Linux, with ``perf`` allowed to sample a process of this user):
``python -m benchmarks.frame_profile [--quick] [--cases float32/linear,...] [--speeds 5,60]
[--seconds S] [--top K] [--broad-phase B] [--out PATH]``.

For each case (precision/motion) and speed, a child process builds the standard room's frame
kernel (its emitter's swarm of 20 000 spheres with the speed replaced, ``workers=1``, the broad
phase ``auto`` picks, or ``--broad-phase``) with line tables (the module's
``cpu_compiler_flags`` plus clang's ``-debug-info-kind=line-tables-only``: the same optimised
code, a separate cache entry), says
where Warp loaded the kernel, and advances the swarm for ``S`` seconds while ``perf record -e
cpu-clock`` samples it. Each sample's address, less the kernel's load address, is an offset in
the module's object file; ``addr2line`` gives the innermost line of the generated C++ there, and
the comment Warp writes above each generated statement (``<L n>``) and each function (``//
FILE.py:LINE``) gives the Python statement. The table lists the statements with the largest
share of the kernel's samples, and the share of each Python function.

What a share means: the CPU retires instructions in order, so a statement that waits (on a
load, on a long chain of arithmetic, or for the pipeline to refill after a mispredicted branch)
collects the samples of the wait; a share is where time passes, not how much arithmetic a
statement holds. Samples land within a few instructions of where they are taken, and the
optimiser interleaves statements, so shares of a few percent are approximate.

The child also times its sampled run (the CPU time of its thread, over the spheres and frames it
advanced), so each function's share becomes nanoseconds per sphere-frame. Two comparisons follow
the profiles, function by function, in those nanoseconds: each case's last speed against its
first (where a faster swarm's extra time goes), and at each speed each later case against the
first (``--cases float32/linear,float32/ballistic``: where the ballistic frame's extra time
goes). The timing runs under ``perf`` in one process per case, so it is rough: compare costs
with ``benchmarks.hot_loop``, side by side.
"""

from __future__ import annotations

import bisect
import collections
import dataclasses
import functools
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from warpsim.vocabulary import BroadPhase

from .common import finish, parser, print_table, start

#: clang's (cc1) flags for line tables only: the code is the same optimised code.
LINE_TABLES = " -debug-info-kind=line-tables-only -dwarf-version=4"

#: Samples per second per process.
FREQUENCY = 5000

FULL = {"seconds": 15.0, "n": 20_000, "top": 25}
QUICK = {"seconds": 4.0, "n": 5_000, "top": 12}


@dataclasses.dataclass(frozen=True)
class Statement:
    """One Python statement of the kernel: its file (relative to the repository when inside
    it), its line and its text, and the function it is in (``file:def line``)."""

    file: str
    line: int
    text: str
    function: str


def generated_statements(cpp: str, kernel_file: str) -> list[tuple[int, Statement]]:
    """``(C++ line, Statement)`` for each statement comment (``// TEXT <L n>``) of a module's
    generated C++, in order: the function is the last ``// FILE.py:LINE`` header above it (a
    statement of the kernel itself, below its ``_cpu_kernel_forward`` definition, is in
    ``kernel_file``). C++ lines are counted from 1."""
    out = []
    file, function = kernel_file, f"{kernel_file}:?"
    header = re.compile(r"^// (\S+\.py):(\d+)\s*$")
    stmt = re.compile(r"^\s*// (.*?)\s*<L (\d+)>\s*$")
    for number, line in enumerate(cpp.splitlines(), start=1):
        m = header.match(line)
        if m:
            file, function = m.group(1), f"{m.group(1)}:{m.group(2)}"
            continue
        if "_cpu_kernel_forward(" in line and not line.startswith(" "):
            file, function = kernel_file, f"{kernel_file}:kernel"
            continue
        m = stmt.match(line)
        if m:
            out.append((number, Statement(file, int(m.group(2)), m.group(1), function)))
    return out


def statement_at(statements: list[tuple[int, Statement]], cpp_line: int) -> Statement | None:
    """The statement whose generated C++ holds ``cpp_line``: the last comment at or above it."""
    at = bisect.bisect_right([n for n, _ in statements], cpp_line) - 1
    return statements[at][1] if at >= 0 else None


def innermost_cpp_lines(obj: Path, offsets: list[int]) -> dict[int, int | None]:
    """``{offset: line}``: the innermost line of the generated C++ (``.cpp``) that the object
    file's line table gives for each code offset (``addr2line -i``; None: no such line)."""
    out: dict[int, int | None] = {}
    if not offsets:
        return out
    text = subprocess.run(["addr2line", "-i", "-a", "-e", str(obj), *map(hex, offsets)],
                          capture_output=True, text=True, check=True).stdout
    current = None
    for line in text.splitlines():
        if line.startswith("0x"):
            current = int(line, 16)
            out[current] = None
        elif current is not None and out[current] is None:
            where = line.split(" (")[0]
            if ".cpp:" in where and not where.endswith(":?"):
                try:
                    out[current] = int(where.rsplit(":", 1)[1])
                except ValueError:
                    pass
    return out


def forward_offset(obj: Path) -> int:
    """The offset of the kernel's ``*_cpu_forward`` symbol in its object file."""
    text = subprocess.run(["nm", str(obj)], capture_output=True, text=True, check=True).stdout
    for line in text.splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[2].endswith("_cpu_forward"):
            return int(parts[0], 16)
    raise RuntimeError(f"no *_cpu_forward symbol in {obj}")


@functools.cache
def function_name(function: str) -> str:
    """``NAME (FILE:LINE)`` for a function given as ``FILE:LINE`` (its ``def`` line), read from
    the source; the kernel's own statements (``FILE:kernel``) are ``kernel (FILE)``."""
    file, _, line = function.rpartition(":")
    if line == "kernel":
        return f"kernel ({file})"
    try:  # the line is the decorator's: the def follows it
        text = Path(file).read_text(encoding="utf-8").splitlines()[int(line) - 1:int(line) + 3]
    except (OSError, ValueError):
        return function
    m = re.search(r"def (\w+)", "\n".join(text))
    return f"{m.group(1)} ({function})" if m else function


def attribute(ips: list[int], load_address: int, obj: Path, cpp: Path, kernel_file: str,
              root: Path) -> dict:
    """Count the samples per Python statement and function (see the module docstring)."""
    base = load_address - forward_offset(obj)
    counts = collections.Counter(ip - base for ip in ips if 0 <= ip - base < 1 << 24)
    lines = innermost_cpp_lines(obj, sorted(counts))
    statements = generated_statements(cpp.read_text(encoding="utf-8"), kernel_file)
    by_stmt: collections.Counter = collections.Counter()
    by_func: collections.Counter = collections.Counter()
    for offset, n in counts.items():
        line = lines.get(offset)
        s = statement_at(statements, line) if line is not None else None
        if s is None:
            by_stmt[("?", 0, "(no line)", "?")] += n
            by_func["?"] += n
            continue
        file = os.path.relpath(s.file, root) if s.file.startswith(str(root)) else s.file
        function = function_name(s.function).replace(s.file, file)
        by_stmt[(file, s.line, s.text, function)] += n
        by_func[function] += n
    return {"samples": len(ips), "in_kernel": sum(counts.values()),
            "statements": [{"file": f, "line": ln, "text": t, "function": fn, "samples": n}
                           for (f, ln, t, fn), n in by_stmt.most_common()],
            "functions": [{"function": fn, "samples": n} for fn, n in by_func.most_common()]}


#: The child: builds the kernel with line tables, says where it is, then runs on a signal.
CHILD = r"""
import ctypes, inspect, json, sys, time
import warp as wp
wp.config.quiet = True
wp.config.cpu_compiler_flags = (wp.config.cpu_compiler_flags or "") + sys.argv[5]
import warpsim as ws
from benchmarks.common import ROOM, room_swarm
prec, motion = sys.argv[1], sys.argv[2]
speed, n, seconds = float(sys.argv[3]), int(sys.argv[4]), float(sys.argv[6])
scene = ws.Scene.load(ROOM)
swarm = room_swarm(scene, n, speed, seed=20240601)
sim = ws.Simulator(scene, swarm, precision=prec, motion=motion, workers=1, device="cpu",
                   broad_phase=sys.argv[7])
sim.build()
sim.step(1)
wp.synchronize_device("cpu")
kernel = sim._kernel
exe = next(iter(kernel.module.execs.values()))
hooks = exe.get_kernel_hooks(kernel)
address = ctypes.cast(hooks.forward, ctypes.c_void_p).value
print(json.dumps({"address": address, "object": str(exe.binary_path),
                  "kernel_file": inspect.getsourcefile(kernel.func)}), flush=True)
sys.stdin.readline()
start, cpu, frames = time.time(), time.thread_time(), 0
while time.time() - start < seconds:
    sim.step(60)
    frames += 60
wp.synchronize_device("cpu")
print(json.dumps({"frames": frames, "cpu_s": time.thread_time() - cpu}), flush=True)
"""


def profile_case(prec: str, motion: str, speed: float, n: int, seconds: float,
                 root: Path, broad_phase: str = "auto") -> dict:
    """One case's profile (see the module docstring)."""
    with tempfile.TemporaryDirectory() as tmp:
        child = subprocess.Popen(
            [sys.executable, "-c", CHILD, prec, motion, str(speed), str(n), LINE_TABLES,
             str(seconds), broad_phase], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL, text=True, cwd=root)
        where = json.loads(child.stdout.readline() or "{}")
        if "address" not in where:
            child.kill()
            return {"error": "the child process did not build its kernel"}
        data = Path(tmp) / "perf.data"
        perf = subprocess.Popen(["perf", "record", "-q", "-e", "cpu-clock", "-F", str(FREQUENCY),
                                 "-p", str(child.pid), "-o", str(data)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(0.5)  # perf attached before the run starts
        child.stdin.write("go\n")
        child.stdin.flush()
        ran = json.loads(child.stdout.readline() or "{}")
        child.wait()
        perf.wait(timeout=60)
        script = subprocess.run(["perf", "script", "-i", str(data), "-F", "ip"],
                                capture_output=True, text=True)
        ips = [int(x, 16) for x in script.stdout.split()]
    if not ips:
        return {"error": "perf recorded no samples (is perf allowed to sample this user's "
                         "processes? /proc/sys/kernel/perf_event_paranoid)"}
    obj = Path(where["object"])
    cpp = next(obj.parent.glob("*.cpp"))
    result = attribute(ips, where["address"], obj, cpp, where["kernel_file"], root)
    result.update(precision=prec, motion=motion, speed=speed, n=n, seconds=seconds,
                  broad_phase=broad_phase)
    if ran.get("frames"):
        result["ns_per_sphere_frame"] = 1e9 * ran["cpu_s"] / (n * ran["frames"])
    return result


def run_title(run: dict) -> str:
    """``precision motion speed m/s``."""
    return f"{run['precision']} {run['motion']} {run['speed']:g} m/s"


def function_ns(run: dict) -> dict[str, float]:
    """Each function's share of the run's kernel samples times the run's cost [ns per
    sphere-frame]: the nanoseconds per sphere-frame that pass in it."""
    total = max(run["in_kernel"], 1)
    return {f["function"]: run["ns_per_sphere_frame"] * f["samples"] / total
            for f in run["functions"]}


def compare(base: dict, other: dict, top: int) -> list[dict]:
    """The functions whose nanoseconds per sphere-frame (:func:`function_ns`) differ the most
    between two runs, the largest increase first, and a last row with the sum over every
    function (the two runs' whole difference)."""
    a, b = function_ns(base), function_ns(other)
    rows = [{"function": fn, "base": a.get(fn, 0.0), "other": b.get(fn, 0.0),
             "difference": b.get(fn, 0.0) - a.get(fn, 0.0)} for fn in set(a) | set(b)]
    rows.sort(key=lambda r: (-r["difference"], r["function"]))
    whole = {"function": "(every function)", "base": sum(a.values()),
             "other": sum(b.values()), "difference": sum(b.values()) - sum(a.values())}
    return rows[:top] + [whole]


def comparisons(runs: list[dict]) -> list[tuple[dict, dict]]:
    """The pairs of runs worth comparing: each case's last speed against its first, and at
    each speed each later case against the first case (runs with an error or no timing are
    left out)."""
    ok = [r for r in runs if "error" not in r and "ns_per_sphere_frame" in r]
    pairs = []
    cases = list(dict.fromkeys((r["precision"], r["motion"]) for r in ok))
    speeds = list(dict.fromkeys(r["speed"] for r in ok))
    by = {(r["precision"], r["motion"], r["speed"]): r for r in ok}
    for case in cases:
        have = [by[(*case, s)] for s in speeds if (*case, s) in by]
        if len(have) > 1:
            pairs.append((have[0], have[-1]))
    for s in speeds:
        have = [by[(*c, s)] for c in cases if (*c, s) in by]
        pairs.extend((have[0], other) for other in have[1:])
    return pairs


def main(argv: list[str] | None = None) -> None:
    p = parser("python -m benchmarks.frame_profile", __doc__)
    p.add_argument("--cases", default="float32/linear",
                   help="comma-separated precision/motion pairs (default float32/linear)")
    p.add_argument("--speeds", default="5,60", help="comma-separated speeds [m/s] (5,60)")
    p.add_argument("--seconds", type=float, default=None, help="sampled run per case [s]")
    p.add_argument("--top", type=int, default=None, help="statements listed per case")
    p.add_argument("--broad-phase", default="auto",
                   choices=[b.value for b in BroadPhase],
                   help="the simulator's broad_phase (default auto)")
    args = p.parse_args(argv)
    if args.device != "cpu":
        p.error("--device: the profile maps samples of the CPU kernel; only cpu is supported")
    for tool in ("perf", "addr2line", "nm"):
        if shutil.which(tool) is None:
            sys.exit(f"frame_profile: {tool!r} is not installed (perf: linux-perf; "
                     "addr2line, nm: binutils)")
    sizes = QUICK if args.quick else FULL
    seconds = args.seconds or sizes["seconds"]
    top = args.top or sizes["top"]
    started = time.perf_counter()
    _, info, out = start("frame_profile", args)
    root = Path(__file__).resolve().parents[1]
    cases = [c.strip().split("/") for c in args.cases.split(",") if c.strip()]
    speeds = [float(s) for s in args.speeds.split(",") if s.strip()]
    runs = []
    for prec, motion in cases:
        for speed in speeds:
            run = profile_case(prec, motion, speed, sizes["n"], seconds, root,
                               args.broad_phase)
            runs.append(run)
            if "error" in run:
                print(f"\n{prec} {motion} {speed:g} m/s: {run['error']}")
                continue
            total = max(run["in_kernel"], 1)
            rows = [{"share": 100.0 * s["samples"] / total, "where": f"{s['file']}:{s['line']}",
                     "statement": s["text"][:80]}
                    for s in run["statements"][:top]]
            print_table(f"{prec} {motion}, {speed:g} m/s: {run['in_kernel']} samples in the "
                        f"kernel of {run['samples']}", rows,
                        [("share [%]", "share", ".1f"), ("where", "where", ""),
                         ("statement", "statement", "")])
            rows = [{"share": 100.0 * f["samples"] / total, "function": f["function"]}
                    for f in run["functions"][:12]]
            cost = run.get("ns_per_sphere_frame")
            cost_text = f", {cost:.2f} ns per sphere-frame" if cost else ""
            print_table(f"{prec} {motion}, {speed:g} m/s: by function (file:def line)"
                        f"{cost_text}", rows,
                        [("share [%]", "share", ".1f"), ("function", "function", "")])
    compared = []
    for base, other in comparisons(runs):
        rows = compare(base, other, top)
        print_table(f"{run_title(other)} against {run_title(base)}: ns per sphere-frame by "
                    "function (share x the run's cost)", rows,
                    [("function", "function", ""), (run_title(base), "base", ".2f"),
                     (run_title(other), "other", ".2f"), ("difference", "difference", "+.2f")])
        compared.append({"base": run_title(base), "other": run_title(other), "rows": rows})
    finish(out, {"machine": info, "quick": args.quick, "seconds": seconds, "runs": runs,
                 "compared": compared}, started)


if __name__ == "__main__":
    main()
