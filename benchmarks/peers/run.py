"""Run every engine on the same workload, interleaved and repeated; write the table and plot.

``python -m benchmarks.peers [--n N] [--repeats R] [--sample K] [--engines a,b] [--out DIR]
[--quick]``, from the repository root. Writes ``DIR/peers.json``, ``DIR/peers.md`` and
``DIR/peers.png`` (default ``DIR``: ``benchmarks/results``), each atomically.

For each speed (5 and 60 m/s) every available engine setting is built (timed: set-up, which
includes compiling kernels for the Warp-based engines), then run once untimed from the start
for the measures: the sampled spheres are recorded every frame of the first second (against
the exact reference), and the final state after all frames gives escaped, inside and the
energy drift. Then the timed runs: ``repeats`` rounds, each resetting and running every
engine's full run in turn (the order rotates from round to round), so that load from other
work on the machine spreads over all engines alike; the table quotes medians, and every ratio
compares medians of the same run. Every engine runs on one core.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from warpsim.export.files import write_bytes, write_json
from warpsim.machine import machine

from . import workload as wl
from .engines import BASELINE, SETTINGS, unavailable, versions

DEFAULT_OUT = str(Path(__file__).resolve().parents[1] / "results")
FULL = {"n": 1000, "repeats": 5, "sample": 32}
QUICK = {"n": 100, "repeats": 1, "sample": 8}


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m benchmarks.peers",
        description="warpsim beside PyBullet, MuJoCo, Newton and a NumPy baseline on one "
                    "workload (see BENCHMARKS.md, 'Against other engines').")
    parser.add_argument("--n", type=int, help=f"spheres per speed (default {FULL['n']}, "
                                              f"--quick {QUICK['n']})")
    parser.add_argument("--repeats", type=int, help="timed rounds (default "
                                                    f"{FULL['repeats']}, --quick 1)")
    parser.add_argument("--sample", type=int, help="spheres compared with the exact reference "
                                                   f"(default {FULL['sample']}, --quick "
                                                   f"{QUICK['sample']})")
    parser.add_argument("--frames", type=int, default=wl.FRAMES,
                        help=f"frames per run (default {wl.FRAMES})")
    parser.add_argument("--engines", help="comma-separated setting keys (default: all): "
                                          + ", ".join(s.key for s in SETTINGS))
    parser.add_argument("--out", default=DEFAULT_OUT, help="output folder (default "
                                                          f"{DEFAULT_OUT})")
    parser.add_argument("--quick", action="store_true", help="small and fast, for trying it")
    args = parser.parse_args(argv)
    base = QUICK if args.quick else FULL
    for name in ("n", "repeats", "sample"):
        if getattr(args, name) is None:
            setattr(args, name, base[name])
    for name in ("n", "repeats", "frames"):
        if getattr(args, name) < 1:
            parser.error(f"--{name} must be >= 1, got {getattr(args, name)}")
    if args.sample < 0:
        parser.error(f"--sample must be >= 0, got {args.sample}")
    args.sample = min(args.sample, args.n)
    keys = [s.key for s in SETTINGS]
    if args.engines:
        chosen = [k.strip() for k in args.engines.split(",") if k.strip()]
        for k in chosen:
            if k not in keys:
                parser.error(f"--engines: unknown setting {k!r}; known: {', '.join(keys)}")
        args.engines = chosen
    else:
        args.engines = keys
    return args


def measure(driver, work: wl.Workload, exact: np.ndarray | None, sample: int) -> dict:
    """The untimed run from the start: the first second recorded for the sampled spheres,
    then the rest; the measures of the final state."""
    driver.reset()
    horizon = min(wl.ERROR_HORIZON_FRAMES, work.frames)
    start = time.perf_counter()
    recorded = [driver.state()[0][:sample]]
    for _ in range(horizon):
        driver.step(1)
        recorded.append(driver.state()[0][:sample])
    if work.frames > horizon:
        driver.step(work.frames - horizon)
    seconds = time.perf_counter() - start
    position, velocity = driver.state()
    out = {"measure_run_s": seconds,
           "escaped": int(wl.escaped(position).sum()),
           "inside": int(wl.inside_obstacle(work, position).sum()),
           "energy_drift": wl.energy_drift(work, position, velocity,
                                           driver.step_velocity),
           "error": None}
    if exact is not None and sample > 0:
        out["error"] = wl.reference_error(np.stack(recorded), exact[: horizon + 1],
                                          work.dt)
    return out


def time_runs(drivers: dict, frames: int, repeats: int) -> dict[str, list[float]]:
    """Seconds of each driver's full run, ``repeats`` rounds, the order rotated each round."""
    keys = list(drivers)
    samples: dict[str, list[float]] = {k: [] for k in keys}
    for r in range(repeats):
        order = keys[r % len(keys):] + keys[: r % len(keys)]
        for k in order:
            drivers[k].reset()
            start = time.perf_counter()
            drivers[k].step(frames)
            samples[k].append(time.perf_counter() - start)
    return samples


def run(args: argparse.Namespace) -> dict:
    """The whole comparison (see the module docstring); returns what goes into the JSON."""
    began = time.perf_counter()
    settings, left_out = [], {}
    for s in SETTINGS:
        if s.key not in args.engines:
            continue
        why = unavailable(s)
        if why:
            left_out[s.key] = why
        else:
            settings.append(s)
    for key, why in left_out.items():
        print(f"left out {key}: {why}")
    if not any(s.key == BASELINE for s in settings):
        print(f"note: {BASELINE} is not in the run, so there is no 'x warpsim' column")
    rows, reference_notes = [], {}
    for speed in wl.SPEEDS:
        work = wl.make_workload(args.n, speed, frames=args.frames)
        exact, ref_s, why = (wl.reference_positions(work, args.sample,
                                                    min(wl.ERROR_HORIZON_FRAMES, work.frames))
                             if args.sample else (None, 0.0, "--sample 0"))
        reference_notes[f"{speed:g}"] = why or f"reference computed in {ref_s:.3g} s"
        print(f"{speed:g} m/s: {work.n} spheres, {len(work.obstacles)} boxes; "
              + reference_notes[f"{speed:g}"])
        drivers, speed_rows = {}, {}
        for s in settings:
            start = time.perf_counter()
            try:
                driver = s.make(work)
            except Exception as exc:  # an engine release the driver does not know: go on
                left_out[f"{s.key} at {speed:g} m/s"] = f"failed to build: {exc}"
                print(f"  {s.key}: failed to build ({exc}); left out")
                continue
            setup = time.perf_counter() - start
            m = measure(driver, work, exact, args.sample)
            drivers[s.key] = driver
            speed_rows[s.key] = {"setting": s.key, "label": driver.label, "speed": speed,
                                 "n": work.n, "frames": work.frames, "setup_s": setup, **m}
            print(f"  {driver.label}: set-up {setup:.3g} s, escaped {m['escaped']}, inside "
                  f"{m['inside']}, energy {m['energy_drift']['total']}")
            sys.stdout.flush()
        samples = time_runs(drivers, work.frames, args.repeats)
        base = statistics.median(samples[BASELINE]) if BASELINE in samples else None
        for key, row in speed_rows.items():
            t = statistics.median(samples[key])
            row.update({"samples_s": samples[key], "run_s": t,
                        "ns_per_sphere_frame": t / (work.n * work.frames) * 1e9,
                        "best_ns_per_sphere_frame":
                            min(samples[key]) / (work.n * work.frames) * 1e9,
                        "over_baseline": t / base if base else None,
                        "engine_settings": drivers[key].settings()})
            rows.append(row)
        for d in drivers.values():
            d.close()
    return {"machine": machine(), "versions": versions(),
            "workload": {"room_inner_m": (2 * wl.ROOM_HALF).tolist(),
                         "wall_m": wl.WALL_THICKNESS, "plates": wl.PLATES,
                         "plate_thickness_m": wl.PLATE_THICKNESS, "radius_m": wl.RADIUS,
                         "mass_kg": wl.MASS, "gravity": list(wl.GRAVITY), "dt_s": wl.DT,
                         "frames": args.frames, "speeds": list(wl.SPEEDS), "n": args.n,
                         "seed": wl.SEED, "room_seed": wl.ROOM_SEED,
                         "inside_tolerance_m": wl.INSIDE_TOLERANCE,
                         "error_horizon_frames": wl.ERROR_HORIZON_FRAMES},
            "options": {"n": args.n, "repeats": args.repeats, "sample": args.sample,
                        "frames": args.frames, "quick": args.quick},
            "baseline": BASELINE, "left_out": left_out, "reference": reference_notes,
            "rows": rows, "runtime_s": time.perf_counter() - began}


def main(argv: list[str] | None = None) -> int:
    from .report import markdown, plot

    args = parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    try:  # before the long run: the plot needs matplotlib
        import matplotlib  # noqa: F401
    except ImportError:
        print('matplotlib is needed for the plot: pip install "warpsim[peers]"', file=sys.stderr)
        return 2
    results = run(args)
    table = markdown(results)
    write_json(out / "peers.json", results)
    write_bytes(out / "peers.md", table.encode())
    plot(results, out / "peers.png")
    print("\n" + table)
    print(f"\nruntime {results['runtime_s']:.0f} s; wrote {out / 'peers.json'}, "
          f"{out / 'peers.md'}, {out / 'peers.png'}")
    return 0
