"""Cold build time of every kernel variant: each built in a fresh process with an empty kernel
cache, so that the figure is what a first run on a new machine (or after a change) pays.

Run from the repository root: ``python -m benchmarks.build_times [--quick] [--out PATH]``.

The variants: the frame kernel over precision x spin x energy correction x lossy x broad phase
(``brute``, ``bvh``, ``grid``, ``grid-bvh``), the collide kernel over precision x broad phase and
the bounce kernel over precision x spin x lossy x broad phase (``max_bounces`` is a launch
value, so no variant per cap), the base frame kernel with the ballistic motion model per
precision and broad phase, and the base frame kernel once more with Warp's adjoint (backward)
code enabled, as every kernel was built before the kernels turned it off. ``--quick`` builds a
representative subset. Each child
process sets ``wp.config.kernel_cache_dir`` to a new temporary folder before ``wp.init()``, times
``wp.load_module`` (code generation and compilation) on the CPU, and reports whether the
generated source holds adjoint functions. Builds run one after another (one core each).
"""

from __future__ import annotations

import argparse
import itertools
import json
import re
import sys
import tempfile
import time
from pathlib import Path

from . import common
from .common import RESULTS, markdown_table

FACTORIES = ("frame", "collide", "bounce")
BROAD_PHASES = ("brute", "bvh", "grid", "grid-bvh")
PRECISIONS = ("float32", "float64")
CHILD_TIMEOUT_S = 600
"""A build that takes longer than this [s] is reported as failed (a cold build takes seconds)."""
ADJOINT_FUNCTION = re.compile(r"static void adj_\w+\(")
"""Warp names every generated adjoint function ``adj_<name>``; without backward code their
bodies are empty stubs (kept for the calls between functions), with it they hold the reverse
pass."""
BACKWARD_ENTRY = "_cpu_kernel_backward"
"""The name suffix of a kernel's generated backward entry point on the CPU."""


def variants(quick: bool) -> list[dict]:
    """The builds to time, each ``{"factory": ..., "args": {...}, "backward": bool}``."""
    frame = [{"factory": "frame", "backward": False,
              "args": {"precision": p, "spin": s, "energy_correction": c, "lossy": lossy,
                       "broad_phase": bp}}
             for p, s, c, lossy, bp in itertools.product(PRECISIONS, (False, True), (True, False),
                                                          (False, True), BROAD_PHASES)]
    collide = [{"factory": "collide", "backward": False,
                "args": {"precision": p, "broad_phase": bp}}
               for p, bp in itertools.product(PRECISIONS, BROAD_PHASES)]
    bounce = [{"factory": "bounce", "backward": False,
               "args": {"precision": p, "spin": s, "lossy": lossy, "broad_phase": bp}}
              for p, s, lossy, bp in itertools.product(PRECISIONS, (False, True), (False, True),
                                                       BROAD_PHASES)]
    base = dict(frame[0], backward=True)  # float32, no spin, correction, elastic, brute
    ballistic = [{"factory": "frame", "backward": False,
                  "args": {**frame[0]["args"], "precision": p, "broad_phase": bp,
                           "motion": "ballistic"}}
                 for p, bp in itertools.product(PRECISIONS, BROAD_PHASES)]
    if not quick:
        return [frame[0], base] + frame[1:] + ballistic + collide + bounce

    def pick(items, **want):
        return next(v for v in items if all(v["args"][k] == x for k, x in want.items()))

    return [frame[0], base,
            pick(frame, precision="float32", spin=False, lossy=False,
                 energy_correction=True, broad_phase="grid"),
            pick(frame, precision="float64", spin=False, lossy=False,
                 energy_correction=True, broad_phase="bvh"),
            pick(frame, precision="float32", spin=True, lossy=False,
                 energy_correction=True, broad_phase="grid"),
            pick(frame, precision="float32", spin=False, lossy=True,
                 energy_correction=False, broad_phase="grid-bvh"),
            pick(ballistic, precision="float32", broad_phase="grid"),
            pick(collide, precision="float32", broad_phase="brute"),
            pick(collide, precision="float64", broad_phase="grid"),
            pick(bounce, precision="float32", spin=False, lossy=False, broad_phase="brute")]


def label(v: dict) -> dict:
    """Table columns of a variant."""
    a = v["args"]
    return {"kernel": v["factory"], "precision": a["precision"],
            "spin": a.get("spin"), "correction": a.get("energy_correction"),
            "lossy": a.get("lossy"), "broad_phase": a["broad_phase"],
            "motion": a.get("motion", "linear" if v["factory"] != "collide" else None),
            "backward": v["backward"]}


def child(spec: dict, cache: str) -> dict:
    """In a fresh process: build one variant into the empty ``cache`` and time it."""
    import warp as wp

    wp.config.kernel_cache_dir = cache  # before wp.init(): every module is built, none loaded
    import warpsim  # noqa: F401  (quiet Warp)
    from warpsim.kernels import variant

    wp.init()
    if spec["backward"]:  # as before the fix: Warp's default, adjoint code generated
        variant.KERNEL_OPTIONS["enable_backward"] = True
    from warpsim.kernels.collide_kernels import bounce_kernel, collide_kernel
    from warpsim.kernels.data import Features
    from warpsim.kernels.frame_kernel import frame_kernel

    factory = {"frame": frame_kernel, "collide": collide_kernel,
               "bounce": bounce_kernel}[spec["factory"]]
    kernel = factory(Features(**spec["args"]))
    start, cpu = time.perf_counter(), time.process_time()
    wp.load_module(kernel.module, device="cpu")
    seconds, cpu_s = time.perf_counter() - start, time.process_time() - cpu
    texts = [p.read_text(errors="replace") for p in Path(cache).rglob("*.cpp")]
    lines = sum(adjoint_lines(t) for t in texts)
    return {"seconds": seconds, "cpu_s": cpu_s, "adjoint_lines": lines,
            "adjoint_code": lines > 0 or any(BACKWARD_ENTRY in t for t in texts),
            "source_lines": sum(t.count("\n") for t in texts)}


def adjoint_lines(text: str) -> int:
    """Lines of code inside the generated adjoint functions' bodies (0: stubs only)."""
    total = 0
    for match in ADJOINT_FUNCTION.finditer(text):
        start = text.find("{", match.end())
        depth, end = 0, start
        while end < len(text):
            depth += {"{": 1, "}": -1}.get(text[end], 0)
            if depth == 0:
                break
            end += 1
        body = [ln.strip() for ln in text[start + 1:end].splitlines()]
        total += sum(1 for ln in body if ln and not ln.startswith("//"))
    return total


def run_child(spec: dict) -> dict:
    """One variant in a subprocess with its own empty cache folder (removed afterwards)."""
    with tempfile.TemporaryDirectory(prefix="warpsim-build-") as cache:
        start = time.perf_counter()
        args = ["--child", json.dumps(spec), "--cache", cache]
        result = common.run_child("build_times", args, CHILD_TIMEOUT_S)
        wall = time.perf_counter() - start
    return {**result, "process_s": wall}


def summary(rows: list[dict]) -> list[str]:
    """Per kernel: fewest, median and most seconds (wall and CPU), and the adjoint comparison.
    On a machine shared with other work the CPU seconds are what a build costs on its own
    core; the wall seconds include the waits for a core."""
    import statistics

    def spread(values) -> str:
        v = sorted(values)
        return f"{v[0]:.2f} to {v[-1]:.2f} s (median {statistics.median(v):.2f} s)"

    lines = []
    groups = [("frame", "linear"), ("frame", "ballistic"), ("collide", None), ("bounce", "linear")]
    for factory, motion in groups:
        done = [r for r in rows if r["kernel"] == factory and r["motion"] == motion
                and not r["backward"] and "seconds" in r]
        name = factory if motion in (None, "linear") else f"{factory} ({motion})"
        if done:
            lines.append(f"{name} kernel, {len(done)} variants: CPU "
                         f"{spread(r['cpu_s'] for r in done)}, wall "
                         f"{spread(r['seconds'] for r in done)}; adjoint code in "
                         f"{sum(r['adjoint_code'] for r in done)}")
    without = rows[0]  # the base frame kernel, first in every list
    with_adjoint = next((r for r in rows if r["backward"]), None)
    if with_adjoint is not None and "seconds" in without and "seconds" in with_adjoint:
        a, b = without["cpu_s"], with_adjoint["cpu_s"]
        lines.append(f"base frame kernel: {a:.2f} CPU s without adjoint code, {b:.2f} with it "
                     f"({b / a:.2f}x; wall {without['seconds']:.2f} and "
                     f"{with_adjoint['seconds']:.2f} s; {with_adjoint['adjoint_lines']:,} "
                     f"adjoint lines)")
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.build_times",
                                description=__doc__.split("\n\n")[0].replace("\n", " "))
    p.add_argument("--quick", action="store_true", help="a representative subset (10 builds)")
    p.add_argument("--out", default=None, help="JSON results (default: benchmarks/results/"
                                                "build_times.json)")
    p.add_argument("--child", help=argparse.SUPPRESS)
    p.add_argument("--cache", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child is not None:
        print(json.dumps(child(json.loads(args.child), args.cache)))
        return 0
    from warpsim.export.files import write_json
    from warpsim.machine import machine

    started = time.perf_counter()
    info = machine()
    print(f"# build_times{' (quick)' if args.quick else ''}\n\n{info['cpu']}, {info['cores']} "
          f"cores, {info['platform']}, Python {info['python']}, Warp {info['warp']}")
    rows = []
    todo = variants(args.quick)
    for i, spec in enumerate(todo, 1):
        row = {**label(spec), **run_child(spec)}
        rows.append(row)
        done = (f"{row['seconds']:.2f} s ({row['cpu_s']:.2f} CPU s)" if "seconds" in row
                else f"failed: {row['error']}")
        print(f"[{i}/{len(todo)}] {spec['factory']} {json.dumps(spec['args'])}"
              f"{' backward' if spec['backward'] else ''}: {done}", file=sys.stderr, flush=True)
    print("\n#### Cold build time per kernel variant (empty kernel cache, CPU, one process "
          "each)\n")
    print(markdown_table(rows, [
        ("kernel", "kernel", ""), ("precision", "precision", ""), ("spin", "spin", ""),
        ("correction", "correction", ""), ("lossy", "lossy", ""),
        ("broad phase", "broad_phase", ""), ("motion", "motion", ""),
        ("backward", "backward", ""),
        ("build s", "seconds", ".2f"), ("CPU s", "cpu_s", ".2f"),
        ("adjoint code", "adjoint_code", ""), ("adjoint lines", "adjoint_lines", ",d"),
        ("C++ lines", "source_lines", ",d"), ("process s", "process_s", ".2f")]))
    lines = summary(rows)
    print("\n" + "\n".join(f"- {line}" for line in lines))
    out = Path(args.out) if args.out else RESULTS / (
        f"build_times{'-quick' if args.quick else ''}.json")
    results = {"machine": info, "quick": args.quick, "rows": rows, "summary": lines,
               "runtime_s": time.perf_counter() - started}
    write_json(out, results)
    print(f"\nruntime {results['runtime_s']:.1f} s; results written to {out}")
    return 0 if all("seconds" in r for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
