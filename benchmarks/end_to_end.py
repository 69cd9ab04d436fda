"""End to end: what a ``warpsim run`` spends in each stage, against its simulation.

Run from the repository root:
``python -m benchmarks.end_to_end [--quick] [--repeats R] [--n N] [--against REV] [--out PATH]``.

The command of issue 20, ``warpsim run room -n 200000 --frames 120 --every 10`` (quick: 20 000
spheres), is timed two ways, the two taking turns ``R`` times in fresh processes:

1. the whole command, ``python -m warpsim run ...`` as a user types it (wall time of the process,
   interpreter start-up included);
2. the same stages in one fresh process, each timed apart, in the order the command runs them:
   ``imports`` (``import warpsim``, then the USD writer, which loads ``pxr``), ``scene``
   (``Scene.load``), ``draw`` (the sharded draw of the swarm the command simulates),
   ``set-up`` (``Simulator``: checks, broad phase, upload), ``build`` (the kernel, from Warp's
   cache), ``simulation`` (``Simulator.run``, the recorded frames copied out) and ``output``
   (``export.write_usd``); the garbage collector's objects are frozen after the imports, as
   the command freezes them before it runs (``warpsim.apps.cli.console``). The stages' sum is
   not the command's time: the command loads ``pxr`` in a process of its own while it draws
   and simulates (``warpsim.export.usd_process``), where this process loads it among the
   imports.

Each whole command also prints its own simulation time; the median over the runs of the
command's wall time over that is printed too (the same ratio, without the stages' process).
``--against REV``: the whole command of git revision ``REV``'s package (laid out as
``hot_loop --against`` lays it out) takes turns with this checkout's, a row of its own.

Both run outside the source tree, so that they import the installed package (or the one
``PYTHONPATH`` names: the same benchmark for another checkout). The table gives the median
seconds of each stage (wall time), its share of the stages' sum and
the whole command over its simulation time (issue 20's goal: within 4x). A shared machine
stretches every stage alike, so the ratios are the figures to compare. The children inherit
the environment: with ``PYTHONDONTWRITEBYTECODE`` set, an editable install's modules are
compiled from source at every import (about 0.1 s of ``imports`` here); the results say which.
"""

import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .common import finish, parser, print_table, start

SCENE = "room"
FRAMES = 120
EVERY = 10
STAGES = ("imports", "scene", "draw", "set-up", "build", "simulation", "output")

#: One process's stage times: prints one JSON line.
CHILD = r"""
import json, sys, time
t = {}
t0 = time.perf_counter()
import warpsim as ws
from warpsim.apps.startup import init_warp
init_warp(debug=False)
from warpsim import export
from warpsim.export import usd_write  # noqa: F401 - loads pxr, as the command's output does
t["imports"] = time.perf_counter() - t0
import gc
gc.freeze()  # as the command does before it runs (warpsim.apps.cli.console)
scene_name, out = sys.argv[1], sys.argv[5]
n, frames, every = (int(a) for a in sys.argv[2:5])
t0 = time.perf_counter()
scene = ws.Scene.load(scene_name)
t["scene"] = time.perf_counter() - t0
from warpsim.distributed.draw import DEFAULT_BLOCK, sharded_spawn
t0 = time.perf_counter()
swarm = sharded_spawn(scene, n, None, DEFAULT_BLOCK)
t["draw"] = time.perf_counter() - t0
t0 = time.perf_counter()
sim = ws.Simulator(scene, swarm)
t["set-up"] = time.perf_counter() - t0
t0 = time.perf_counter()
sim.build()
t["build"] = time.perf_counter() - t0
t0 = time.perf_counter()
traj = sim.run(frames, every=every)
t["simulation"] = time.perf_counter() - t0
t0 = time.perf_counter()
export.write_usd(out, scene, traj, warn=False)
t["output"] = time.perf_counter() - t0
print(json.dumps(t))
"""


def stage_times(n: int, out: Path) -> dict:
    result = subprocess.run([sys.executable, "-c", CHILD, SCENE, str(n), str(FRAMES), str(EVERY),
                             str(out)], check=True, capture_output=True, text=True,
                            cwd=tempfile.gettempdir())
    return json.loads(result.stdout.strip().splitlines()[-1])


def command_time(n: int, out: Path, site: Path | None = None) -> tuple[float, float]:
    """The whole command's wall time and the simulation time it printed [s]; ``site``:
    another revision's package (``hot_loop.export_tree``), else this checkout's installed
    one."""
    env = dict(os.environ)
    if site is not None:
        env["PYTHONPATH"] = str(site)
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "warpsim", "run", SCENE, "-n", str(n),
                           "--frames", str(FRAMES), "--every", str(EVERY), "-o", str(out),
                           "--no-progress"], check=True, capture_output=True, text=True,
                          cwd=tempfile.gettempdir(), env=env)
    wall = time.perf_counter() - t0
    simulated = re.search(r"^simulated .* in ([0-9.]+) s", done.stdout, flags=re.M)
    return wall, float(simulated.group(1))


def main(argv=None) -> None:
    p = parser("end_to_end", __doc__)
    p.add_argument("--repeats", type=int, default=None, help="turns (default 3)")
    p.add_argument("--n", type=int, default=None, help="spheres (default 200 000)")
    p.add_argument("--against", default=None,
                   help="git revision whose whole command takes turns with this one's")
    args = p.parse_args(argv)
    started = time.perf_counter()
    _, info, out = start("end_to_end", args)
    n = args.n or (20_000 if args.quick else 200_000)
    repeats = args.repeats or (1 if args.quick else 3)
    samples = {stage: [] for stage in STAGES}
    whole_runs = []  # (wall, printed simulation) [s] of each whole command, this checkout's
    base_runs = []  # and REV's
    rev = None
    with tempfile.TemporaryDirectory() as tmp:
        usd = Path(tmp) / "room.usdc"
        site = None
        if args.against is not None:
            from .hot_loop import export_tree

            rev = subprocess.run(["git", "rev-parse", "--short", args.against], check=True,
                                 capture_output=True, text=True).stdout.strip()
            site = export_tree(rev, Path(tmp))
            command_time(n, usd, site)
        command_time(n, usd)  # warm-up: the kernel cache, the file system
        for turn in range(repeats):
            for stage, seconds in stage_times(n, usd).items():
                samples[stage].append(seconds)
            sides = [None] if site is None else [None, site] if turn % 2 == 0 else [site, None]
            for side in sides:
                (whole_runs if side is None else base_runs).append(
                    command_time(n, usd, side))
    own = statistics.median(wall / sim for wall, sim in whole_runs)
    own_base = statistics.median(wall / sim for wall, sim in base_runs) if base_runs else None
    whole = [wall for wall, _ in whole_runs]
    base = [wall for wall, _ in base_runs]
    median = {stage: statistics.median(values) for stage, values in samples.items()}
    total = sum(median.values())
    command = statistics.median(whole)
    rows = [{"stage": stage, "seconds": median[stage], "share": 100.0 * median[stage] / total,
             "per_simulation": median[stage] / median["simulation"]} for stage in STAGES]
    rows.append({"stage": "sum of the stages", "seconds": total, "share": 100.0,
                 "per_simulation": total / median["simulation"]})
    rows.append({"stage": "whole command", "seconds": command, "share": None,
                 "per_simulation": command / median["simulation"]})
    if base:
        rows.append({"stage": f"whole command, {rev}", "seconds": statistics.median(base),
                     "share": None,
                     "per_simulation": statistics.median(base) / median["simulation"]})
    print_table(f"warpsim run {SCENE} -n {n} --frames {FRAMES} --every {EVERY}, default "
                f"settings, median of {repeats} (wall time)",
                rows, [("stage", "stage", "s"), ("seconds", "seconds", ".2f"),
                       ("share [%]", "share", ".0f"), ("x simulation", "per_simulation", ".2f")])
    # with PYTHONDONTWRITEBYTECODE set (as on some shared machines) every import of an
    # editable checkout compiles its modules from source: 0.1 s more of warpsim's own import
    bytecode = "not written (PYTHONDONTWRITEBYTECODE)" if sys.flags.dont_write_bytecode \
        else "written"
    print(f"compiled bytecode of the package's modules: {bytecode}")
    print(f"whole command over the simulation it printed, median of the runs' ratios: {own:.2f}x"
          + (f"; {rev}: {own_base:.2f}x" if base else ""))
    finish(out, {"machine": info, "spheres": n, "frames": FRAMES, "every": EVERY,
                 "repeats": repeats, "bytecode": bytecode, "stages": samples,
                 "command": whole, "against": rev, "command_against": base,
                 "command_runs": whole_runs, "command_against_runs": base_runs,
                 "own_ratio": own, "own_ratio_against": own_base, "rows": rows},
           started)


if __name__ == "__main__":
    main()
