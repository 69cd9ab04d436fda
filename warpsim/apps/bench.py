"""``warpsim bench``: the throughput of one scene on this machine, as ``mjwarp-testspeed`` is
for MuJoCo models.

``warpsim bench SCENE [-n N] [--frames F] [--device D] [--precision P] [--workers W]
[--broad-phase B] [--motion M] [--json PATH]`` loads a bundled scene by name (or a ``.toml``
file), spawns ``N`` spheres from its emitter, builds the :class:`warpsim.Simulator` (the kernel
build, or its load from Warp's kernel cache, is timed apart), runs one warm-up frame, then times
``F`` frames of :meth:`warpsim.Simulator.step` and prints sphere-frames per second, nanoseconds
per sphere-frame, contacts per sphere-frame, the broad phase and worker count chosen, the device
and the versions. ``--json`` writes the same figures to a file (atomically).

The studies (NumPy baseline, sweep tables, speed figures, accuracy tables, build times) are
scripts in the repository's ``benchmarks/`` folder, not part of the package: see BENCHMARKS.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import warp as wp

from ..export.files import write_json
from ..machine import machine
from .options import add_simulation_options

PROG = "warpsim bench"
DESCRIPTION = ("The throughput of one scene on this machine: kernel build timed apart, one "
               "warm-up frame, then sphere-frames per second over the timed frames.")
EXIT_ERROR = 1
EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line and the usage exit code, as the rest of the CLI
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(EXIT_USAGE)


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The options of ``warpsim bench``."""
    parser = _Parser(prog=PROG, description=DESCRIPTION)
    add_simulation_options(parser, integer=_positive_int,
                           frames_help="timed frames (default: the scene's frames)")
    parser.add_argument("--json", metavar="PATH", help="also write the figures to this JSON file")
    return parser


def _check_json_path(text: str) -> Path:
    """The ``--json`` path, refused before the run when it cannot be written."""
    if not text.strip():
        raise ValueError("--json path is empty")
    path = Path(text)
    if path.is_dir():
        raise ValueError(f"--json {text!r} is a folder, not a file")
    parent = path.parent
    while not parent.exists():  # the first existing folder above must be writable
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK):
        raise ValueError(f"--json {text!r} cannot be written (no writable folder {parent})")
    return path


def _cache_entries() -> set[str]:
    cache = Path(wp.config.kernel_cache_dir or "")
    return {p.name for p in cache.glob("wp_*")} if cache.is_dir() else set()


def measure(scene_name: str, count: int | None = None, frames: int | None = None,
            device=None, precision: str = "float32", workers: int | None = None,
            broad_phase: str = "auto", motion: str | None = None) -> dict:
    """Time one scene: kernel build, one warm-up frame, then ``frames`` timed frames.

    Args:
        scene_name: a bundled scene's name or a ``.toml`` path.
        count: spheres spawned from the scene's emitter (None: its count).
        frames: timed frames (None: the scene's ``frames``).
        device, precision, workers, broad_phase: as for :class:`warpsim.Simulator`.
        motion: the Simulator's ``motion`` keyword, passed only when not None.

    Returns:
        The figures: seconds [s] of the set-up, the build and the timed frames,
        ``sphere_frames_per_s``, ``ns_per_sphere_frame``, ``bounces_per_sphere_frame``,
        ``supports_per_sphere_frame`` (resting contacts) and ``capped`` over the timed
        frames, what the simulator chose, machine and versions.

    Raises:
        ValueError: a bad scene, option or device, in one line.
    """
    from ..scene import Scene
    from ..simulator import Simulator

    scene = Scene.load(scene_name)
    frames = scene.frames if frames is None else frames
    extra = {} if motion is None else {"motion": motion}
    start = time.perf_counter()
    swarm = scene.spawn(n=count)
    sim = Simulator(scene, swarm, device=device, precision=precision, workers=workers,
                    broad_phase=broad_phase, **extra)
    setup_s = time.perf_counter() - start
    before = _cache_entries()
    build_s = sim.build()
    built = bool(_cache_entries() - before)
    start = time.perf_counter()
    sim.step(1)
    warmup_s = time.perf_counter() - start
    first = sim.stats
    start = time.perf_counter()
    sim.step(frames)
    seconds = time.perf_counter() - start
    last = sim.stats
    n = len(swarm)
    sphere_frames = n * frames
    return {
        "scene": scene.name, "source": scene.source, "boxes": len(scene.boxes), "n": n,
        "frames": frames, "dt": sim.dt, "precision": sim.precision,
        "max_bounces": sim.max_bounces, "broad_phase": sim.broad_phase, "workers": sim.workers,
        "motion": sim.motion, "setup_s": setup_s, "build_s": build_s,
        "build_cached": (not built) if sim.device.is_cpu else None, "warmup_s": warmup_s,
        "seconds": seconds, "sphere_frames_per_s": sphere_frames / seconds,
        "ns_per_sphere_frame": seconds / sphere_frames * 1e9,
        "bounces_per_sphere_frame": (last.bounces - first.bounces) / sphere_frames,
        "supports_per_sphere_frame": (last.supports - first.supports) / sphere_frames,
        "capped": last.capped - first.capped,
        "machine": machine(sim.device)}


def _commit(m: dict) -> str:
    if m["commit"] is None:
        return "unknown (not a git checkout)"
    return m["commit"][:12] + (" with local changes" if m["dirty"] else "")


def report(r: dict) -> str:
    """The figures of :func:`measure` as a few lines of text."""
    m = r["machine"]
    cache = {True: " (loaded from Warp's kernel cache)", False: " (compiled)", None: ""}
    motion = f", motion {r['motion']}" if r["motion"] is not None else ""
    return "\n".join([
        f"{r['scene']}: {r['n']:,} spheres, {r['boxes']} boxes, dt = {r['dt']:.6g} s, "
        f"{r['precision']}, max_bounces {r['max_bounces']}{motion}",
        f"device {m['device']} ({m['device_name']}), broad phase {r['broad_phase']}, "
        f"{r['workers']} worker{'s' if r['workers'] != 1 else ''}",
        f"set-up {r['setup_s']:.3f} s, kernel build {r['build_s']:.3f} s"
        f"{cache[r['build_cached']]}, warm-up frame {r['warmup_s'] * 1e3:.2f} ms",
        f"{r['frames']:,} frames in {r['seconds']:.4g} s: "
        f"{r['sphere_frames_per_s']:.4g} sphere-frames/s, "
        f"{r['ns_per_sphere_frame']:.4g} ns per sphere-frame",
        f"{r['bounces_per_sphere_frame']:.4f} bounces per sphere-frame, "
        f"{r['capped']} sphere-frames capped",
        f"warpsim {m['warpsim']}, warp {m['warp']}, numpy {m['numpy']}, python {m['python']}; "
        f"{m['cpu']}, {m['cores']} cores, {m['platform']}; commit {_commit(m)}"])


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``warpsim bench``; returns the exit code (0, 1 on an error, 2 on bad
    usage), errors in one line on standard error."""
    args = build_parser().parse_args(argv)
    from .startup import init_warp

    init_warp(debug=False)  # without Warp's start-up lines (a machine without CUDA has some)
    try:
        out = None if args.json is None else _check_json_path(args.json)
        result = measure(args.scene, count=args.count, frames=args.frames, device=args.device,
                         precision=args.precision, workers=args.workers,
                         broad_phase=args.broad_phase, motion=args.motion)
        print(report(result))
        if out is not None:
            write_json(out, result)
            print(f"figures written to {out}")
    except (ValueError, OSError) as exc:
        sys.stderr.write(f"{PROG}: error: {exc}\n")
        return EXIT_ERROR
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
