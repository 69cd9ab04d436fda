"""The ``warpsim`` command line: run a scene to USD, list scenes, preview a frame or a movie,
benchmark, measure accuracy.

Errors are one line on standard error and a non-zero exit code; ``--debug`` (or the environment
variable ``WARPSIM_DEBUG=1``) shows the traceback instead, and Warp's own start-up messages.
Everything that can be checked before a simulation is checked before it starts: the output
paths can be written, the optional packages are there, the file will not be too large.
"""

from __future__ import annotations

import argparse
import gc
import os
import sys

import numpy as np

from ..vocabulary import BroadPhase
from .options import add_simulation_options
from .startup import check_device, init_warp

EXIT_ERROR = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
USD_SUFFIXES = (".usdc", ".usda")
EVENTS_SUFFIXES = (".parquet",)
#: Default for ``run --velocities``: off. Measured (benchmarks/usd_write.py): velocities add
#: 12 B per sphere-frame in .usdc (24 B with spin) to the 12 B of a non-spinning sphere's
#: position, doubling the per-frame data of most bundled scenes (the default room run, 400
#: spheres x 301 frames: 1.6 MB -> 3.0 MB), a cost only motion-blurred renders need.
VELOCITIES_DEFAULT = False

#: Seconds a kernel build may take before ``run`` says what it is waiting for: a first build
#: (Warp caches it after) takes 3 to 8 s on a CPU and 3 to 16 s for a GPU (BENCHMARKS.md "GPU:
#: an NVIDIA H200"; minutes on a slow or loaded machine, or at Warp's default GPU compiler
#: level, which the package no longer uses).
BUILD_NOTICE_S = 10.0


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
    from ..export.preview import MAX_PIXELS, MAX_SIDE  # the renderer's limit, said once

    if max(w, h) > MAX_SIDE or w * h > MAX_PIXELS:
        raise argparse.ArgumentTypeError(
            f"size must be at most {MAX_SIDE} pixels on a side and {MAX_PIXELS:,} in all "
            f"(4096x4096), got {text!r}")
    return w, h


def sphere_selection(text: str, count: int) -> np.ndarray:
    """Sphere indices from ``A:B`` / ``A:B:STEP`` (Python slice, ends optional) or ``1,5,9``.

    A bare integer is refused (``-n`` is how many spheres to simulate; ``7:8`` or ``7,`` selects
    sphere 7), so that neither is taken for the other.

    Raises:
        ValueError: a malformed selection, or indices out of ``range(count)``, naming them.
    """
    from .. import validation as check

    text = text.strip()
    try:
        if ":" in text:
            parts = [int(p) if p.strip() else None for p in text.split(":")]
            if len(parts) > 3:
                raise ValueError
            selected = np.arange(count)[slice(*parts)]
            if selected.size == 0:
                raise ValueError(f"--spheres {text!r} selects no sphere of {count}")
            return selected
        if "," in text:
            items = [int(p) for p in text.split(",") if p.strip()]
            return check.index_list("--spheres", items, count)
    except ValueError as exc:
        if str(exc):
            raise
    raise ValueError(f"--spheres takes a range A:B or a list 1,5,9 of sphere indices, got "
                     f"{text!r} (-n sets how many spheres to simulate)")


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = _Parser(prog="warpsim", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"warpsim {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show tracebacks on errors, and Warp's start-up messages")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    run = sub.add_parser("run", help="simulate a scene and write a USD animation")
    add_simulation_options(run)
    run.add_argument("--start", type=int, default=0,
                     help="first frame written (the run still starts at frame 0)")
    run.add_argument("--end", type=int,
                     help="last frame written; the run stops there (default: --frames)")
    run.add_argument("--spheres", help="write only these spheres: A:B, A:B:STEP or 1,5,9")
    run.add_argument("--dt", type=float, help="time step [s] (default: the scene's)")
    run.add_argument("--seed", type=int, help="emitter seed (default: the scene's)")
    run.add_argument("--max-bounces", type=int, help="contacts per sphere per frame")
    run.add_argument("-o", "--output",
                     help="output .usdc or .usda (default: the scene's name + .usdc, here)")
    run.add_argument("--every", type=int, default=1, help="record one frame in EVERY")
    run.add_argument("--velocities", action=argparse.BooleanOptionalAction,
                     default=VELOCITIES_DEFAULT,
                     help="write velocities and angular velocities for motion blur (off by "
                          "default: about doubles the file)")
    run.add_argument("--events", metavar="EVENTS.parquet",
                     help="write one row per contact to a Parquet file (needs pyarrow)")
    run.add_argument("--events-capacity", type=int,
                     help="contacts the event buffer holds per recorded frame")
    run.add_argument("--error-sample", type=int, metavar="K",
                     help="after the run, compare K spheres with the exact reference")
    run.add_argument("--max-bytes", type=float, default=2e9,
                     help="refuse (before simulating) a file estimated larger [bytes]")
    run.add_argument("--max-memory", type=float,
                     help="refuse (before drawing the spheres) a run estimated to hold more "
                          "memory [bytes] (default: 80%% of the machine's)")
    run.add_argument("--rerun", metavar="RUN.rrd",
                     help="also write a Rerun recording: timeline, contacts, energy plots "
                          "(needs warpsim[viewer]; see 'warpsim view')")
    run.add_argument("--rerun-sample", type=int, metavar="K",
                     help="with --rerun: record only K of the written spheres, evenly spread")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    run.add_argument("--dask", nargs="?", const="local", metavar="ADDRESS",
                     help="run in shards on a Dask cluster: a LocalCluster here, or the "
                          "scheduler at ADDRESS (needs warpsim[dask]; README 'On a cluster')")
    run.add_argument("--shards", type=int,
                     help="run in this many shards, one USD layer each: on the Dask cluster "
                          "with --dask (default: 4 per worker), else in this process; at most "
                          "one shard per block of spheres")
    run.add_argument("--block", type=int,
                     help="spheres per block of the draw (default 1024); every run, sharded "
                          "or not, draws the same spheres for the same -n, --seed and --block")

    sub.add_parser("scenes", help="list the bundled scenes")

    prev = sub.add_parser("preview",
                          help="draw a frame of a warpsim USD file to an image, or a movie")
    prev.add_argument("usd", help="a .usdc/.usda written by 'warpsim run'")
    prev.add_argument("--frame", type=int,
                      help="image: the recorded frame; negative counts from the end (default: "
                           "-1, the last); not with --movie")
    prev.add_argument("-o", "--output", help="output image (.png, .jpg, ...)")
    prev.add_argument("--movie", metavar="OUT.mp4", help="write a movie (.mp4 or .gif) instead")
    prev.add_argument("--every", type=int, default=1,
                      help="movie: draw one recorded frame in EVERY")
    prev.add_argument("--size", type=_size, default=(960, 540), help="WIDTHxHEIGHT pixels")
    prev.add_argument("--azimuth", type=float, default=45.0,
                      help="view direction around +y from +z towards +x [deg]")
    prev.add_argument("--elevation", type=float, default=30.0,
                      help="view height above the horizon [deg]")
    prev.add_argument("--no-progress", action="store_true", help="no progress bar (movie)")

    view = sub.add_parser("view", help="open a .rrd, or a warpsim USD file, in the Rerun viewer "
                                       "(needs warpsim[viewer]; analytics off)")
    view.add_argument("file", help="a .rrd recording or a .usdc/.usda written by 'warpsim run'")
    view.add_argument("--web", action="store_true",
                      help="serve Rerun's web viewer on 127.0.0.1 instead of the native one")
    view.add_argument("--port", type=int, default=0,
                      help="with --web: the page's port (default: a free one)")
    view.add_argument("--no-browser", action="store_true",
                      help="with --web: print the address, do not open a browser")
    view.add_argument("--every", type=int, default=1,
                      help="USD files: one recorded frame in EVERY")
    view.add_argument("--sample", type=int, metavar="K",
                      help="USD files: only K spheres, evenly spread")

    sub.add_parser("bench", add_help=False,
                   help="measure throughput (see BENCHMARKS.md; 'warpsim bench --help')")
    sub.add_parser("accuracy", add_help=False,
                   help="the accuracy study ('warpsim accuracy --help')")
    return parser


def _cmd_scenes(_args) -> int:
    from ..scene_files import list_scenes

    scenes = list_scenes()
    width = max(len(name) for name, _ in scenes)
    for name, description in scenes:
        print(f"{name:<{width}}  {description}")
    return 0


def energy_line(sim, swarm, state) -> str:
    """The summary's energy line (:func:`warpsim.energy_figures.line`, on the scale of
    :mod:`warpsim.energy`), the same figures a sharded run adds up."""
    from .. import energy_figures

    return energy_figures.line(energy_figures.figures(sim, swarm.position, state))


def _unborn_written(args, scene, n: int, subset, start: int, end: int, every: int) -> int:
    """Sphere-frames a run writes before their sphere's birth (0 without births): of the
    spheres ``subset`` (swarm indices; None: all ``n``), at the records from ``start`` to
    ``end`` every ``every`` frames (and ``end``)."""
    if not getattr(scene.emitter, "emits_over_time", False):
        return 0
    births = scene.emitter.birth_frames(scene.dt if args.dt is None else args.dt, n)
    if subset is not None:
        births = births[subset]
    recorded = np.array(sorted(set(range(start, end + 1, every)) | {end}), dtype=np.int64)
    born = np.searchsorted(np.sort(births), recorded, side="right")  # born by each record
    return int((births.size - born).sum())


def _run_options(args) -> dict:
    """Keywords of :meth:`warpsim.Simulator.run` asked for on the command line, checked before
    anything runs."""
    from .. import validation as check

    options = {}
    if args.velocities:
        options["velocities"] = True
    if args.events is not None:
        options["events"] = True
    if args.events_capacity is not None:
        if args.events is None:
            raise ValueError("--events-capacity needs --events")
        options["event_capacity"] = check.positive_int("events_capacity", args.events_capacity)
    return options


def _simulator_options(args) -> dict:
    """``motion`` and ``workers`` for :class:`warpsim.Simulator`, only when given."""
    return {name: getattr(args, name) for name in ("motion", "workers")
            if getattr(args, name) is not None}


def _frame_range(args, scene_frames: int) -> tuple[int, int]:
    """``(start, end)``: frames written, the run stopping at ``end``."""
    from .. import validation as check

    frames = check.positive_int("frames", scene_frames if args.frames is None else args.frames)
    end = frames if args.end is None else check.positive_int("end", args.end)
    if args.frames is not None and end > frames:
        raise ValueError(f"--end {end} is past --frames {frames}")
    start = check.positive_int("start", args.start, minimum=0)
    if start >= end:
        raise ValueError(f"--start {start} must be before --end {end}")
    return start, end


def check_memory(args, n: int, kept: int, records: int, every: int, frames: int,
                 usd_bytes: float) -> int:
    """Refuse, before anything is drawn, a run whose memory (:mod:`warpsim.footprint`: the
    swarm, the device state, the kept frames, the launch and event buffers, and the USD stage
    being written) is above ``--max-memory``.

    Returns:
        The bytes of the frames the run keeps (``Simulator.run``'s recorded arrays)."""
    from .. import footprint
    from .. import validation as check
    from ..simulator import DEFAULT_EVENT_CAPACITY, LAUNCH_SPHERE_FRAMES
    from ..validation import bounce_cap

    event_rows = 0
    if args.events is not None:
        capacity = (DEFAULT_EVENT_CAPACITY if args.events_capacity is None
                    else args.events_capacity)
        bounces = bounce_cap(8 if args.max_bounces is None else args.max_bounces)
        event_rows = 2 * min(capacity, n * frames * bounces)  # kept rows and a launch's
    run = footprint.run_bytes(n, records, kept=kept,
                              precision_bytes=4 if args.precision == "float32" else 8,
                              velocities=bool(args.velocities),
                              launch_sphere_frames=LAUNCH_SPHERE_FRAMES, every=every,
                              event_rows=event_rows)
    size = footprint.Footprint(swarm=run.swarm, device=run.device,
                               trajectory=run.trajectory + int(usd_bytes), launch=run.launch,
                               events=run.events, broad=run.broad)
    limit = (footprint.default_limit() if args.max_memory is None
             else check.scalar("max_memory", args.max_memory, positive=True))
    footprint.check_fits(size, limit, "--max-memory",
                         "simulate fewer spheres (-n), keep fewer frames (--every, "
                         "--start/--end) or spheres (--spheres)")
    return run.trajectory


def _run_sharded(args, scene):
    """``warpsim run SCENE --dask [ADDRESS] [--shards N] [--block B]``:
    :func:`warpsim.distributed.run` from the command line's options (``--shards``
    without ``--dask`` shards in this process). ``--workers`` is the threads of each
    shard's simulator.

    Raises:
        ValueError: an option a sharded run does not support, or a bad value (named).
    """
    from .. import distributed
    from .. import validation as check
    from ..export.files import default_name

    for option, value in (("--spheres", args.spheres), ("--events", args.events),
                          ("--events-capacity", args.events_capacity),
                          ("--error-sample", args.error_sample)):
        if value is not None:
            raise ValueError(f"{option} is not supported with --dask/--shards (a sharded run "
                             f"writes every sphere, one layer per shard)")
    if args.frames is not None and args.end is not None and args.end > args.frames:
        raise ValueError(f"--end {args.end} is past --frames {args.frames}")
    end = args.end if args.end is not None else args.frames
    if args.output is not None and not args.output.strip():
        raise ValueError("output path (-o) is empty")
    output = args.output if args.output is not None else default_name(scene.name, ".usdc")
    client = args.dask
    if client not in (None, distributed.LOCAL):
        client = distributed.scheduler_address(client)
    where = ("this process" if client is None
             else "a local Dask cluster" if client == distributed.LOCAL
             else f"the Dask scheduler at {client}")
    n = scene.emitter.count if args.count is None and scene.emitter is not None else args.count
    print(f"{scene.name}: {n} spheres, {len(scene.boxes)} obstacles, sharded on {where}",
          file=sys.stderr)
    block = distributed.DEFAULT_BLOCK if args.block is None else args.block
    if args.shards is not None and n is not None:
        blocks = distributed.block_count(check.positive_int("n", n),
                                         check.positive_int("block", block))
        if check.positive_int("shards", args.shards) > blocks:
            print(f"{blocks} shards, not {args.shards}: {n} spheres make {blocks} blocks of "
                  f"{block} and a shard is whole blocks (--block sets the size)", file=sys.stderr)
    return distributed.run(scene, output, n=args.count, seed=args.seed, frames=end,
                           start=args.start, every=args.every, client=client,
                           shards=args.shards, block=block, threads=args.workers, dt=args.dt,
                           max_bounces=args.max_bounces, device=args.device,
                           precision=args.precision, broad_phase=args.broad_phase,
                           velocities=bool(args.velocities), motion=args.motion,
                           progress=not args.no_progress, max_bytes=args.max_bytes)


def _cmd_run(args) -> int:
    import warpsim as ws

    from .. import validation as check
    from ..export.files import check_writable, default_name
    from ..export.usd_process import SHARED_ALIGN, UsdWriter

    scene = ws.Scene.load(args.scene)
    stage_set = getattr(scene.boxes, "stage", None)  # obstacles read from a USD stage
    if stage_set is not None:
        print(stage_set.summary(), file=sys.stderr)
    sharded = args.dask is not None or args.shards is not None
    if sharded and stage_set is not None:
        raise ValueError("--dask: a scene whose obstacles come from a USD stage runs unsharded "
                         "(its result composes over the stage)")
    if sharded and args.rerun is not None:
        raise ValueError("--rerun does not run with --dask: open the sharded USD with "
                         "'warpsim view OUT.usdc' (it converts it)")
    if sharded:
        print(_run_sharded(args, scene))  # sharded: the spheres are drawn on the workers
        return 0
    start, end = _frame_range(args, scene.frames)
    every = check.positive_int("every", args.every)
    if args.output is not None and not args.output.strip():
        raise ValueError("output path (-o) is empty")
    out = check_writable(args.output if args.output is not None
                         else default_name(scene.name, ".usdc"), USD_SUFFIXES)
    if stage_set is not None:
        from ..export.compose import check_output

        check_output(stage_set, out)
    if args.events is not None:
        from ..events import require_parquet

        check_writable(args.events, EVENTS_SUFFIXES, what="events file")
        require_parquet()
    if args.error_sample is not None:
        check.positive_int("error_sample", args.error_sample)
    if args.rerun is not None or args.rerun_sample is not None:
        from ..export.rerun import check_run_options

        check_run_options(args)
    options = _run_options(args)
    # sizes first: the file and the memory the run will hold, before any sphere is drawn
    if scene.emitter is None:
        raise ValueError(f"scene {scene.name!r} has no emitter")
    n = check.positive_int("n", scene.emitter.count if args.count is None else args.count)
    subset = None if args.spheres is None else sphere_selection(args.spheres, n)
    n_written = n if subset is None else subset.size
    n_records = len(sorted(set(range(start, end + 1, every)) | {end}))
    from .. import export

    spinning = bool(scene.friction > 0.0
                    or np.any(np.asarray(scene.emitter.angular_momentum) != 0.0))
    estimate = export.estimate_usd_bytes(n_written, n_records, out.suffix, boxes=scene.boxes,
                                         spinning=spinning, velocities=args.velocities,
                                         unborn=_unborn_written(args, scene, n, subset, start,
                                                                end, every))
    if estimate > args.max_bytes:
        raise ValueError(f"{str(out)!r} would be about {estimate / 1e6:,.0f} MB "
                         f"({n_written} spheres x {n_records} frames), above --max-bytes "
                         f"{args.max_bytes:,.0f}: record fewer frames (--every, --start/--end) "
                         f"or spheres (--spheres), or raise --max-bytes")
    if args.rerun is not None:
        from ..export.rerun import check_recording_size, sampled_columns

        recorded = np.arange(n) if subset is None else subset
        recorded = recorded[sampled_columns(recorded.size, args.rerun_sample)]
        check_recording_size(args, scene, n_written, n_records,
                             unborn=_unborn_written(args, scene, n, recorded, start, end, every))
    recorded_bytes = check_memory(args, n, n_written, n_records, every, end - start, estimate)
    check_device(args.device, args.debug_mode)

    def write_file(trajectory):
        return export.write_usd(out, scene, trajectory, velocities=args.velocities, warn=False)

    # the file's writer, forked now where it may be: it loads pxr while this process draws and
    # simulates, and reads the recorded frames from the memory they are recorded in
    # (export/usd_process.py); with --debug the file is written here, tracebacks whole
    with UsdWriter(write_file, fork=False if args.debug_mode else None,
                   share_bytes=recorded_bytes + 4 * SHARED_ALIGN) as usd_writer:
        # the block draw of a sharded run, so that the same command with --shards or --dask
        # simulates the same spheres, bit for bit
        from ..distributed.draw import DEFAULT_BLOCK, may_start_free, sharded_spawn

        swarm = sharded_spawn(scene, n, args.seed, DEFAULT_BLOCK if args.block is None
                              else check.positive_int("block", args.block), dt=args.dt)
        extra = _simulator_options(args)
        sim = ws.Simulator(scene, swarm, dt=args.dt, max_bounces=args.max_bounces,
                           device=args.device, precision=args.precision,
                           broad_phase=args.broad_phase, free_flight=may_start_free(scene),
                           **extra)
        if subset is not None:
            options["spheres"] = subset
        print(f"{scene.name}: {len(swarm)} spheres, {len(scene.boxes)} obstacles, {end} frames "
              f"of {sim.dt:g} s on {sim.device} ({args.precision}); about "
              f"{estimate / 1e6:.1f} MB of USD", file=sys.stderr)
        # reported apart from the run's speed; with --events every recorded frame is run by the
        # kernel with the contact code, and the plain one only steps to --start
        build = _build_with_notice(sim, bool(args.events), plain=not args.events or start > 0)
        if start:
            sim.step(start)
        if args.rerun is not None:  # also samples the energy and the counters at each record
            from ..export.rerun import run_with_scalars

            traj, scalars = run_with_scalars(sim, end - start, every=every,
                                             progress=not args.no_progress,
                                             start=swarm.position, **options)
        else:
            traj = sim.run(end - start, every=every, progress=not args.no_progress,
                           allocate=usd_writer.empty, **options)
        state = sim.state()
        stats = sim.stats
        print(f"simulated {stats.frames} frames x {len(swarm)} spheres in {stats.seconds:.2f} s "
              f"(kernel build {build:.2f} s): "
              f"{stats.sphere_frames_per_second:,.0f} sphere-frames/s")
        print(bounce_line(stats))
        print(energy_line(sim, swarm, state))
        print("broad phase: "
              f"{describe_broad_phase(stats.broad_phase, stats.requested_broad_phase)}")

        def write_scene():
            path = usd_writer.write(traj)
            print(f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB, {len(traj)} frames "
                  f"{int(traj.frame[0])}..{int(traj.frame[-1])}, {n_written} spheres)")

        def write_events():
            events = traj.events
            events_path = events.write_parquet(args.events)
            lost = (f"; {events.dropped:,} dropped: the buffer was full, raise --events-capacity"
                    if events.dropped else "")
            print(f"wrote {events_path} ({len(events):,} contacts{lost})")

        def write_recording():
            rrd = export.write_rerun(args.rerun, scene, traj, ids=traj.ids(),
                                     sample=args.rerun_sample, scalars=scalars)
            print(f"wrote {rrd} ({rrd.stat().st_size / 1e6:.1f} MB Rerun recording; "
                  f"'warpsim view {rrd}' opens it)")

        def compare():
            from ..analysis import error_report

            report = error_report.compare(sim, scene, swarm, sample=args.error_sample)
            print(report.summary())

        # each output on its own: one that fails never loses the others (nor the run's figures)
        outputs = [("USD file", write_scene)]
        if args.events is not None:
            outputs.append(("events file", write_events))
        if args.rerun is not None:
            outputs.append(("Rerun recording", write_recording))
        if args.error_sample is not None:
            outputs.append(("error sample", compare))
        return finish_outputs(outputs, args.debug_mode)


def finish_outputs(outputs, debug: bool) -> int:
    """Run each ``(what, write)`` of ``outputs`` in turn, whatever the others do; the failures
    are reported together at the end, one line each, and make the exit code non-zero.
    ``debug`` raises the first failure instead (its traceback)."""
    failed = []
    for what, write in outputs:
        try:
            write()
        except Exception as exc:  # noqa: BLE001 - reported below, with the output it hit
            if debug:
                raise
            failed.append(f"{what}: {exc}" if isinstance(exc, (ValueError, OSError,
                                                               ImportError))
                          else f"{what}: {type(exc).__name__}: {exc}")
    for line in failed:
        sys.stderr.write(f"warpsim: error: {line}\n")
    return EXIT_ERROR if failed else 0


def bounce_line(stats) -> str:
    """The summary's contact line: the bounces and the resting (supporting) contacts, each
    counted by the kernel."""
    per = stats.bounces / max(stats.sphere_frames, 1)
    per_support = stats.supports / max(stats.sphere_frames, 1)
    return (f"contacts: {stats.bounces:,} bounces ({per:.3f} per sphere-frame), "
            f"{stats.supports:,} resting or sliding ({per_support:.3f} per sphere-frame); "
            f"capped: {stats.capped:,} sphere-frames, {stats.capped_spheres} spheres")


def describe_broad_phase(ran: str, requested: str) -> str:
    """What broad phase ran, and why when it is not the one asked for."""
    if requested in (BroadPhase.AUTO, ran):
        return f"{ran}" + (" (chosen by the cost model)" if requested == BroadPhase.AUTO else "")
    if requested == BroadPhase.GRID and ran == "grid-bvh":
        return "grid, falling back to the BVH for paths that leave their cell"
    if requested == BroadPhase.WALK and ran == "walk-bvh":
        return "walk, falling back to the BVH for paths its lists were not made for"
    return (f"{ran} ({requested} asked: no grid fits this scene at this precision, "
            f"so every sphere uses the {ran})")


def _cmd_preview(args) -> int:
    from .. import export

    if (args.output is None) == (args.movie is None):
        raise ValueError("preview needs -o IMAGE or --movie MOVIE (one of them)")
    angles = {"azimuth": args.azimuth, "elevation": args.elevation}
    if args.movie is not None:
        from ..export.files import check_writable
        from ..export.movie import check_movie_support, render_movie

        if args.frame is not None:
            raise ValueError("--frame picks the frame of an image (-o); a movie (--movie) "
                             "draws every recorded frame (--every to thin them)")

        check_movie_support(args.movie)
        check_writable(args.movie, what="movie")
        path = render_movie(args.usd, args.movie, every=args.every, size=args.size,
                            progress=not args.no_progress, **angles)
        print(f"wrote {path} ({args.size[0]}x{args.size[1]}, one recorded frame in "
              f"{args.every})")
        return 0
    from ..export.files import check_writable
    from ..export.preview import image_format

    image_format(args.output)
    check_writable(args.output, what="image")
    frame = export.read_usd_frame(args.usd, -1 if args.frame is None else args.frame).frame[0]
    path = export.render_preview(args.usd, int(frame), args.output, size=args.size, **angles)
    print(f"wrote {path} (frame {frame}, {args.size[0]}x{args.size[1]})")
    return 0


def _build_with_notice(sim, events: bool, plain: bool = True) -> float:
    """``sim.build(events, plain)``, saying on standard error what the command waits for when
    the build takes more than ``BUILD_NOTICE_S`` seconds; returns the build's seconds."""
    import threading

    def notice():
        print(f"building the frame kernel for {sim.device} ({sim.motion}, {sim.precision}): "
              f"a first build, kept in Warp's kernel cache for the next runs",
              file=sys.stderr, flush=True)

    timer = threading.Timer(BUILD_NOTICE_S, notice)
    timer.daemon = True
    timer.start()
    try:
        return sim.build(events=events, plain=plain)
    finally:
        timer.cancel()


def _cmd_bench(argv: list[str]) -> int:
    from . import bench

    return bench.main(argv) or 0


def _cmd_accuracy(argv: list[str]) -> int:
    from ..analysis import accuracy

    return accuracy.main(argv) or 0


def _cmd_view(args) -> int:
    from ..export.rerun_viewer import view

    return view(args.file, web=args.web, port=args.port, open_browser=not args.no_browser,
                stride=args.every, sample=args.sample)


COMMANDS = {"run": _cmd_run, "scenes": _cmd_scenes, "preview": _cmd_preview, "view": _cmd_view}
FORWARDED = {"bench": _cmd_bench, "accuracy": _cmd_accuracy}  # parse their own options


def _report(exc: BaseException, debug: bool) -> int:
    if debug:
        raise exc
    if isinstance(exc, (ValueError, OSError, ImportError)):
        sys.stderr.write(f"warpsim: error: {exc}\n")
    else:  # an unexpected failure: still one line unless asked
        sys.stderr.write(f"warpsim: error: {type(exc).__name__}: {exc} "
                         "(run with --debug for the traceback)\n")
    return EXIT_ERROR


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``warpsim`` console script; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    debug = os.environ.get("WARPSIM_DEBUG") == "1"
    head = 0
    while head < len(argv) and argv[head] == "--debug":  # global flag before a forwarded one
        debug, head = True, head + 1
    if argv[head:head + 1] and argv[head] in FORWARDED:
        command, rest = argv[head], argv[head + 1:]
        try:
            init_warp(debug)
            return FORWARDED[command](rest)
        except KeyboardInterrupt:
            sys.stderr.write("warpsim: interrupted\n")
            return EXIT_INTERRUPTED
        except Exception as exc:
            return _report(exc, debug)
    args = build_parser().parse_args(argv)
    debug = debug or args.debug
    args.debug_mode = debug
    try:
        init_warp(debug)
        return COMMANDS[args.command](args)
    except KeyboardInterrupt:
        sys.stderr.write("warpsim: interrupted\n")
        return EXIT_INTERRUPTED
    except Exception as exc:
        return _report(exc, debug)


def console() -> None:
    """The ``warpsim`` command: :func:`main`, then the end of the process without the
    interpreter's teardown.

    Once the command is done there is nothing left to do but that teardown, and a process
    that has loaded Warp spends about 0.4 s in it (freeing Warp's tables of builtins object
    by object: ``python -c "import warp"`` takes 1.3 s, 0.9 s when it ends with ``os._exit``).
    So the command flushes its output, runs the exit handlers (``atexit``: temporary folders,
    the libraries' own) and ends with ``os._exit`` and :func:`main`'s code. A command's files
    are written and closed, its Dask cluster shut down and its simulator's threads idle
    before :func:`main` returns. :func:`main` itself returns as any function does (the tests
    and programs that call it keep their process).

    Before the command runs, the objects its imports made (Warp's tables and functions, the
    modules: about 140 000) are moved out of the garbage collector's generations
    (``gc.freeze``): they live as long as the process, and each full collection would walk
    them again. Measured here, ``warpsim run room -n 200000``: 0.09 to 0.11 s of collection
    against 0.23 to 0.28 s, most of it one full collection while the kernel's functions are
    made. Objects made later are collected as before."""
    gc.freeze()
    try:
        code = main()
    except SystemExit as stop:  # argparse's usage errors, --help and --version
        code = stop.code
    if code is None:
        code = 0
    elif not isinstance(code, int):  # SystemExit("message"): Python prints it, exit code 1
        sys.stderr.write(f"{code}\n")
        code = EXIT_ERROR
    fast_exit(code)


def fast_exit(code: int) -> None:
    """End the process with ``code`` after flushing the standard streams and running the
    ``atexit`` handlers, without the interpreter's teardown (see :func:`console`)."""
    import atexit

    def flush() -> None:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # a closed pipe (``| head``) or a closed stream
                pass

    flush()
    atexit._run_exitfuncs()
    flush()  # what the handlers wrote
    os._exit(code)


if __name__ == "__main__":
    console()
