"""What the studies share: interleaved timing, markdown tables, the standard room's swarms, the
machine description and the JSON output.

Timing: every call runs once as a warm-up, then the calls that are compared take turns for a
number of rounds, each call ended by ``wp.synchronize_device``; the figure is the median. On a
machine shared with other work a change of load then falls on all of them alike, and ratios
between calls of the same round are the figures to quote.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

import warpsim as ws
from warpsim.export.files import write_json
from warpsim.machine import machine

RESULTS = Path(__file__).resolve().parent / "results"
"""Where the studies write their JSON by default (``benchmarks/results/``, where the committed
results are; quick runs as ``NAME-quick.json``, which git ignores)."""

ROOM = "room"
"""The bundled standard room (22 boxes): ``ws.Scene.load(ROOM)``."""

DEFAULT_BUDGET_S = 30.0
"""Timed rounds stop once this much time [s] went into them (the warm-ups are not counted)."""


def median_times(calls: dict, device, repeats: int, budget_s: float = DEFAULT_BUDGET_S,
                 cpu: dict | None = None) -> dict:
    """Median wall time [s] of each call, each call ended by a device sync.

    Every call runs once as a warm-up, then the calls take turns for ``repeats`` rounds (fewer
    when a round is long: at most ``budget_s`` [s] of rounds); when even one round would exceed
    the budget, the warm-ups are the only samples.

    Args:
        cpu: when given, filled with ``{name: median CPU time [s]}`` of the process over each
            call (every thread): for a call on one thread, the time it held a core, which other
            work on a shared machine does not stretch as it stretches the wall time.

    Returns:
        ``{name: (median seconds, samples)}`` for ``calls = {name: call}``.
    """

    def once(call) -> tuple[float, float]:
        start, start_cpu = time.perf_counter(), time.process_time()
        call()
        wp.synchronize_device(device)
        return time.perf_counter() - start, time.process_time() - start_cpu

    first = {name: once(call) for name, call in calls.items()}
    rounds = min(repeats, int(budget_s / max(sum(t for t, _ in first.values()), 1e-9)))
    samples = {name: [] for name in calls}
    if rounds == 0:
        samples = {name: [t] for name, t in first.items()}
    for _ in range(rounds):
        for name, call in calls.items():
            samples[name].append(once(call))
    if cpu is not None:
        cpu.update({name: statistics.median(c for _, c in t) for name, t in samples.items()})
    return {name: (statistics.median(w for w, _ in t), len(t)) for name, t in samples.items()}


def markdown_table(rows: list[dict], columns: list[tuple[str, str, str]]) -> str:
    """``rows`` as a markdown table; ``columns`` are ``(header, key, format spec)``; a missing
    or None value prints as ``-``."""
    def cell(row, key, spec):
        value = row.get(key)
        return "-" if value is None else format(value, spec)

    lines = ["| " + " | ".join(h.replace("|", "\\|") for h, _, _ in columns) + " |",
             "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(cell(r, k, s).replace("|", "\\|") for _, k, s in columns) + " |"
              for r in rows]
    return "\n".join(lines)


def print_table(title: str, rows: list[dict], columns: list[tuple[str, str, str]]) -> None:
    """Print a markdown heading and table, flushed (a long study shows its tables as it goes)."""
    print(f"\n#### {title}\n\n{markdown_table(rows, columns)}")
    sys.stdout.flush()


def room_swarm(scene: ws.Scene, n: int, speed: float, seed: int = 0) -> ws.Swarm:
    """``n`` spheres from the scene's emitter with its speed replaced by ``speed`` [m/s] (every
    direction, as the standard room's emitter), clear of every obstacle."""
    emitter = dataclasses.replace(scene.emitter, count=n, speed=float(speed))
    return emitter.spawn(scene.boxes, seed=seed)


def parser(prog: str, doc: str) -> argparse.ArgumentParser:
    """The options every study takes: ``--quick``, ``--device``, ``--out``."""
    p = argparse.ArgumentParser(prog=prog, description=doc.split("\n\n")[0].replace("\n", " "))
    p.add_argument("--quick", action="store_true",
                   help="small sizes and short timings (noisy; for development)")
    p.add_argument("--device", default="cpu", help="Warp device: cpu or cuda:0 (default cpu)")
    p.add_argument("--out", default=None,
                   help="JSON results (default: benchmarks/results/NAME.json)")
    return p


def open_study(name: str, doc: str, tables: tuple[str, ...], argv: list[str] | None):
    """The start of a study with several tables: its options (:func:`parser` and ``--only``,
    comma-separated among ``tables``; an unknown one or none is a usage error), then
    :func:`start`. Returns ``(args, tables chosen, device, machine dict, out path, start
    time)``."""
    p = parser(f"python -m benchmarks.{name}", doc)
    p.add_argument("--only", default=",".join(tables),
                   help=f"comma-separated tables among {','.join(tables)} (default: all)")
    args = p.parse_args(argv)
    only = [t.strip() for t in args.only.split(",") if t.strip()]
    unknown = sorted(set(only) - set(tables))
    if unknown or not only:
        p.error(f"--only takes tables among {','.join(tables)}, got {unknown or 'none'}")
    started = time.perf_counter()
    device, info, out = start(name, args)
    return args, only, device, info, out, started


def start(name: str, args: argparse.Namespace):
    """Initialise Warp and describe the run. Returns ``(device, machine dict, out path)``."""
    from warpsim.apps.startup import init_warp
    from warpsim.device import resolve_device

    init_warp(debug=False)  # without Warp's start-up lines
    try:
        device = resolve_device(args.device)
    except ValueError as exc:  # one line, as the command-line tool says it, not a traceback
        raise SystemExit(f"python -m benchmarks.{name}: error: {exc}") from None
    info = machine(device)
    print(f"# {name}{' (quick)' if args.quick else ''}\n\n{info['cpu']} ({info['cpu_id']}), "
          f"{info['cores']} cores, "
          f"{info['platform']}, Python {info['python']}, NumPy {info['numpy']}, "
          f"Warp {info['warp']}, warpsim {ws.__version__}, device {info['device']} "
          f"({info['device_name']})")
    out = Path(args.out) if args.out else RESULTS / f"{name}{'-quick' if args.quick else ''}.json"
    return device, info, out


def run_child(module: str, args: list[str], timeout: float) -> dict:
    """``python -m benchmarks.MODULE ARGS`` in a fresh process from the repository root; the
    dict its last line of output holds (JSON), or ``{"error": its last line of errors}``."""
    import json
    import os
    import subprocess

    proc = subprocess.run([sys.executable, "-m", f"benchmarks.{module}", *args],
                          capture_output=True, text=True, timeout=timeout,
                          cwd=Path(__file__).resolve().parents[1], env=dict(os.environ))
    if proc.returncode != 0:
        return {"error": (proc.stderr.strip().splitlines() or ["no output"])[-1]}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def finish(out: Path, results: dict, started: float) -> None:
    """Write the JSON atomically and say where it went."""
    results["runtime_s"] = time.perf_counter() - started
    write_json(out, results)
    print(f"\nruntime {results['runtime_s']:.1f} s; results written to {out}")


def identical_states(a: ws.Simulator, b: ws.Simulator) -> bool:
    """Whether two simulators hold the same state, bit for bit."""
    sa, sb = a.state(), b.state()
    return all(np.array_equal(getattr(sa, f), getattr(sb, f))
               for f in ("position", "velocity", "energy", "angular_momentum", "orientation"))
