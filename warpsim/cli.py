"""The ``warpsim`` command line: run a scene to USD, list scenes, preview a frame, benchmark.

Errors are one line on standard error and a non-zero exit code; ``--debug`` (or the environment
variable ``WARPSIM_DEBUG=1``) shows the traceback instead.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

EXIT_ERROR = 1
EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, usage exit code
        sys.stderr.write(f"warpsim: error: {message}\n")
        raise SystemExit(EXIT_USAGE)


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"size must look like 960x540, got {text!r}") from exc
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"size must be at least 16x16, got {text!r}")
    return w, h


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="warpsim", description=__doc__.splitlines()[0])
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = sub.add_parser("run", help="simulate a scene and write a USD animation")
    run.add_argument("scene", help="bundled scene name (see 'warpsim scenes') or a .toml path")
    run.add_argument("-n", "--spheres", type=int, help="number of spheres (default: the scene's)")
    run.add_argument("--frames", type=int, help="frames to simulate (default: the scene's)")
    run.add_argument("--dt", type=float, help="time step [s] (default: the scene's)")
    run.add_argument("--seed", type=int, help="emitter seed (default: the scene's)")
    run.add_argument("--max-bounces", type=int, help="contacts per sphere per frame")
    run.add_argument("--device", help="Warp device, e.g. cpu or cuda:0 (default: Warp's)")
    run.add_argument("--precision", default="float32", choices=("float32", "float64"))
    run.add_argument("--broad-phase", default="auto", choices=("auto", "bvh", "brute"),
                     help="candidate boxes per sphere: a BVH or all boxes (same results)")
    run.add_argument("-o", "--output", help="output .usdc or .usda (default: SCENE.usdc)")
    run.add_argument("--every", type=int, default=1, help="record one frame in EVERY")
    run.add_argument("--max-bytes", type=float, default=2e9,
                     help="warn before writing a file larger than this estimate [bytes]")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")

    sub.add_parser("scenes", help="list the bundled scenes")

    prev = sub.add_parser("preview", help="draw one frame of a warpsim USD file to a PNG")
    prev.add_argument("usd", help="a .usdc/.usda written by 'warpsim run'")
    prev.add_argument("--frame", type=int, default=None, help="frame (default: the last)")
    prev.add_argument("-o", "--output", required=True, help="output .png")
    prev.add_argument("--size", type=_size, default=(960, 540), help="WIDTHxHEIGHT pixels")

    sub.add_parser("bench", add_help=False,
                   help="run the benchmarks (see BENCHMARKS.md; 'warpsim bench --help')")
    return parser


def _cmd_scenes(_args) -> int:
    from .scene_files import list_scenes

    scenes = list_scenes()
    width = max(len(name) for name, _ in scenes)
    for name, description in scenes:
        print(f"{name:<{width}}  {description}")
    return 0


def _energy_drift(sim, state) -> float:
    """Largest per-sphere energy change, relative to that sphere's energy above the lowest
    point of the scene (so a number near 0 means kept, 1 means all of it)."""
    scene = sim.scene
    g = scene.gravity
    if len(scene.boxes):
        corners = scene.boxes.center + scene.boxes.bounding_radius()[:, None] * np.sign(g)
        floor = corners[np.argmin(corners @ -g)] if np.any(g) else sim.energy_origin
    else:
        floor = sim.energy_origin
    mass = sim.mass
    e0 = sim.initial_energy.astype(np.float64)
    floor_potential = -mass * ((floor - sim.energy_origin) @ g)
    scale = np.maximum(e0 - floor_potential, 1e-30)
    return float(np.max(np.abs(sim.mechanical_energy(state) - e0) / scale)) if len(e0) else 0.0


def _cmd_run(args) -> int:
    import warpsim as ws

    from . import validation as check

    scene = ws.Scene.load(args.scene)
    swarm = scene.spawn(n=args.spheres, seed=args.seed)
    frames = check.positive_int("frames", scene.frames if args.frames is None else args.frames)
    check.positive_int("every", args.every)
    out = Path(args.output if args.output else f"{scene.name}.usdc")
    if out.suffix not in (".usdc", ".usda"):
        raise ValueError(f"output must end in .usdc or .usda, got {str(out)!r}")
    if not out.parent.is_dir():
        raise ValueError(f"output directory {str(out.parent)!r} does not exist")
    sim = ws.Simulator(scene, swarm, dt=args.dt, max_bounces=args.max_bounces,
                       device=args.device, precision=args.precision,
                       broad_phase=args.broad_phase)
    from . import export

    estimate = export.estimate_usd_bytes(len(swarm), frames // args.every + 1, out.suffix[1:])
    print(f"{scene.name}: {len(swarm)} spheres, {len(scene.boxes)} obstacles, {frames} frames "
          f"of {sim.dt:g} s on {sim.device} ({args.precision}); about "
          f"{estimate / 1e6:.1f} MB of USD", file=sys.stderr)
    build = sim.build()  # reported apart from the run's speed
    traj = sim.run(frames, every=args.every, progress=not args.no_progress)
    state = sim.state()
    stats = sim.stats
    path = export.write_usd(out, scene, traj, max_bytes=args.max_bytes)
    print(f"simulated {stats.frames} frames x {len(swarm)} spheres in {stats.seconds:.2f} s "
          f"(kernel build {build:.2f} s): "
          f"{stats.sphere_frames_per_second:,.0f} sphere-frames/s")
    print(f"bounces: {stats.bounces:,} ({stats.bounces / max(stats.sphere_frames, 1):.3f} per "
          f"sphere-frame); capped: {stats.capped:,} sphere-frames, {stats.capped_spheres} spheres")
    print(f"energy drift: {_energy_drift(sim, state):.2e} (largest per sphere, relative)")
    print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB, {len(traj)} frames)")
    return 0


def _cmd_preview(args) -> int:
    from . import export

    traj = export.read_usd(args.usd)
    frame = int(traj.frame[-1]) if args.frame is None else args.frame
    path = export.render_preview(args.usd, frame, args.output, size=args.size)
    print(f"wrote {path} (frame {frame}, {args.size[0]}x{args.size[1]})")
    return 0


COMMANDS = {"run": _cmd_run, "scenes": _cmd_scenes, "preview": _cmd_preview}


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``warpsim`` console script; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["bench"]:  # the benchmark parses its own options
        from .benchmark import main as bench_main

        return bench_main(argv[1:]) or 0
    args = build_parser().parse_args(argv)
    debug = args.debug or os.environ.get("WARPSIM_DEBUG") == "1"
    try:
        return COMMANDS[args.command](args)
    except KeyboardInterrupt:
        sys.stderr.write("warpsim: interrupted\n")
        return 130
    except (ValueError, OSError) as exc:
        if debug:
            raise
        sys.stderr.write(f"warpsim: error: {exc}\n")
        return EXIT_ERROR
    except Exception as exc:  # an unexpected failure: still one line unless asked
        if debug:
            raise
        sys.stderr.write(f"warpsim: error: {type(exc).__name__}: {exc} "
                         "(run with --debug for the traceback)\n")
        return EXIT_ERROR


if __name__ == "__main__":
    raise SystemExit(main())
