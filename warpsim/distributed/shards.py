"""The same run on a Dask cluster: the swarm in shards, one task and one USD layer per shard.

Spheres never interact, so a swarm shards perfectly. :func:`run` splits the swarm into shards of
whole *blocks* of spheres; each shard is one task that draws its own spheres on the worker (from
the scene's emitter, the seed and the block numbers: no per-sphere array goes through the
client), simulates them and writes its own USD layer atomically; the client then writes a small
root stage composing the layers with the obstacles (layout: :mod:`warpsim.export.layers`).
The spheres are the sharded draw of :mod:`warpsim.distributed.draw`.

Faults. A worker that dies loses only the tasks it was running, which Dask runs again
elsewhere. Layers are written under a temporary name and renamed: a file under a shard's name is
complete. Each layer's manifest holds a key hashing everything that determines its bits (scene,
emitter, seed, block, the shard's spheres, frames, settings, device, warpsim version): a rerun
reuses every layer whose key matches and computes only the missing or stale shards.

The output folder must be reachable under the same path by the client and every worker (a
shared file system on a real cluster; any folder with a ``LocalCluster``), and every worker
needs warpsim installed.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import re
import secrets
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import validation as check
from ..scene import Scene
from ..swarm import Swarm
from .cluster import (
    CONNECT_TIMEOUT,
    LOCAL,
    WORKERS_RENAMED,
    client_for,
    cluster_threads,
    require_dask,
    scheduler_address,
)
from .draw import DEFAULT_BLOCK, block_count, check_draw, plan_shards, shard_swarm, spawn_block

MAX_SHARD_BYTES = 1 << 30
"""A shard task holds its recorded frames in memory until its layer is written (28 bytes per
sphere-frame, 52 with velocities): shards are made small enough to stay under 1 GiB each."""

TASKS_PER_THREAD = 4
"""Default shards per worker thread: enough tasks that a slow or lost worker leaves little
idle time at the end, few enough that per-task start-up (a Warp kernel load) stays small."""

PROGRESS_SPHERE_FRAMES = 1 << 22
"""A shard simulates in chunks of about this many sphere-frames (a few tenths of a second on one
core) and reports its progress after each; the result is the same bits as one run."""

_STORED_BYTES = 28  # per sphere-frame: float32 positions (12) and orientations (16)
_VELOCITY_BYTES = 24  # per sphere-frame: float32 velocities and angular velocities


# --------------------------------------------------------------------------------------------
# What a shard task needs


@dataclass(frozen=True)
class RunSpec:
    """Everything a shard task needs besides the scene (small: no per-sphere data).

    Attributes:
        n, seed, block: the sharded draw. bounds: each shard's ``(start, stop)`` spheres.
        frames: frames recorded after ``start`` frames stepped unrecorded; every: one record
            in ``every``. dt [s], max_bounces, precision, broad_phase, device, options (extra
            :class:`warpsim.Simulator` keywords such as ``motion``): the simulator's settings.
        velocities: store velocities too. threads: CPU threads per shard task (None: all).
        folder: the shard layers' folder. scene_key: hash of the scene (:func:`scene_key`).
        topic: the Dask event topic progress is reported on ("" for none).
    """

    n: int
    seed: int
    block: int
    bounds: tuple[tuple[int, int], ...]
    frames: int
    start: int
    every: int
    dt: float
    max_bounces: int
    precision: str
    broad_phase: str
    device: str | None
    options: tuple[tuple[str, object], ...]
    velocities: bool
    threads: int | None
    folder: str
    scene_key: str
    topic: str = ""

    @property
    def count(self) -> int:
        return len(self.bounds)

    def layer_path(self, index: int) -> Path:
        from ..export.layers import shard_name

        return Path(self.folder) / f"{shard_name(index, self.count)}.usdc"

    def shard_key(self, index: int) -> str:
        """Hash of everything that determines shard ``index``'s bits."""
        from .. import __version__

        start, stop = self.bounds[index]
        fields_ = {"version": __version__, "scene": self.scene_key, "n": self.n,
                   "seed": self.seed, "block": self.block, "spheres": [start, stop],
                   "frames": self.frames, "start": self.start, "every": self.every,
                   "dt": repr(float(self.dt)), "max_bounces": self.max_bounces,
                   "precision": self.precision, "broad_phase": self.broad_phase,
                   "device": self.device or "default", "options": repr(self.options),
                   "velocities": self.velocities}
        text = json.dumps(fields_, sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()

    def recorded_frames(self) -> np.ndarray:
        """The frame indices a shard records (as ``Simulator.run`` records them)."""
        stops = list(range(self.every, self.frames + 1, self.every))
        if not stops or stops[-1] != self.frames:
            stops.append(self.frames)
        return np.array([self.start] + [self.start + k for k in stops], dtype=np.int64)


def scene_key(scene: Scene) -> str:
    """SHA-256 (hex) of what a scene's runs depend on: its boxes (float64 bits), physics
    settings and emitter."""
    h = hashlib.sha256()
    boxes = scene.boxes
    for name in ("center", "half_extents", "rotation", "radius"):
        h.update(np.ascontiguousarray(getattr(boxes, name), dtype="<f8").tobytes())
    settings = [scene.gravity.tolist(), scene.friction, scene.energy_retention,
                scene.energy_correction, scene.max_angular_speed, repr(scene.emitter)]
    h.update(repr(settings).encode())
    return h.hexdigest()


def _simulator(scene: Scene, swarm: Swarm, spec: RunSpec):
    from ..simulator import Simulator
    from .draw import may_start_free

    return Simulator(scene, swarm, dt=spec.dt, max_bounces=spec.max_bounces, device=spec.device,
                     precision=spec.precision, broad_phase=spec.broad_phase,
                     workers=spec.threads, free_flight=may_start_free(scene),
                     **dict(spec.options))


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return get_worker().address
    except (ImportError, ValueError):
        return "this process"


def simulate_shard(scene: Scene, spec: RunSpec, index: int,
                   report: Callable[[int, int], None] | None = None) -> dict:
    """Draw, simulate and write shard ``index``: the task one worker runs.

    Args:
        scene: the scene.
        spec: the run (:class:`RunSpec`).
        index: the shard.
        report: called as ``report(index, sphere_frames_done)`` after each chunk.

    Returns:
        ``index``, ``digest`` of the layer's arrays, ``seconds`` (wall, the whole task),
        ``sphere_frames``, ``bounces``, ``supports``, ``capped``, ``worker`` (its address).
    """
    from ..export.layers import write_shard_layer
    from ..trajectory import Trajectory

    begin = time.perf_counter()
    start, stop = spec.bounds[index]
    swarm = shard_swarm(scene, spec.n, spec.seed, start, stop, spec.block, spec.dt)
    sim = _simulator(scene, swarm, spec)
    size = stop - start
    if spec.start:
        sim.step(spec.start)
        if report is not None:
            report(index, spec.start * size)
    # Chunks of whole recording intervals record the same frames as one run, and the kernels
    # give the same bits whatever the frames per launch: the chunks only pace the progress.
    chunk = max(spec.every, PROGRESS_SPHERE_FRAMES // size // spec.every * spec.every)
    parts: list[Trajectory] = []
    done = 0
    while done < spec.frames:
        todo = min(chunk, spec.frames - done)
        part = sim.run(todo, every=spec.every, velocities=spec.velocities)
        parts.append(part if not parts else _without_first(part))
        done += todo
        if report is not None:
            report(index, (spec.start + done) * size)
    trajectory = _concatenated(parts)
    stats = sim.stats
    key = spec.shard_key(index)
    from .. import energy_figures

    energy = energy_figures.figures(sim, swarm.position)
    digest = write_shard_layer(spec.layer_path(index), trajectory,
                               np.arange(start, stop, dtype=np.int64), index, spec.count,
                               {"key": key, "start": int(start), "stop": int(stop),
                                "bounces": int(stats.bounces),
                                "supports": int(stats.supports), "capped": int(stats.capped),
                                "capped_spheres": int(stats.capped_spheres),
                                "energy": energy},
                               velocities=spec.velocities)
    return {"index": int(index), "digest": digest, "key": key,
            "seconds": time.perf_counter() - begin, "sphere_frames": int(stats.sphere_frames),
            "bounces": int(stats.bounces), "supports": int(stats.supports),
            "capped": int(stats.capped),
            "capped_spheres": int(stats.capped_spheres), "energy": energy,
            "worker": _worker_name()}


def _without_first(part):
    """A chunk's records but its first (the previous chunk's last)."""
    from ..trajectory import Trajectory

    def cut(values):
        return None if values is None else values[1:]

    return Trajectory(frame=part.frame[1:], dt=part.dt, position=part.position[1:],
                      orientation=part.orientation[1:], radius=part.radius,
                      velocity=cut(part.velocity), angular_velocity=cut(part.angular_velocity),
                      birth_frame=part.birth_frame)


def _concatenated(parts):
    from ..trajectory import Trajectory

    if len(parts) == 1:
        return parts[0]

    def joined(name):
        values = [getattr(p, name) for p in parts]
        return None if values[0] is None else np.concatenate(values)

    return Trajectory(frame=joined("frame"), dt=parts[0].dt, position=joined("position"),
                      orientation=joined("orientation"), radius=parts[0].radius,
                      velocity=joined("velocity"), angular_velocity=joined("angular_velocity"),
                      birth_frame=parts[0].birth_frame)


def _scene_task(scene: Scene) -> Scene:
    """The scene as a task's result, shared by the shard tasks of a Dask run."""
    return scene


def _dask_shard_task(scene: Scene, spec: RunSpec, index: int) -> dict:
    """:func:`simulate_shard` on a Dask worker, reporting progress as events on
    ``spec.topic``; Warp starts quietly there (no CUDA warning in the worker's log)."""
    from ..warp_start import init_quietly

    init_quietly()
    report = None
    if spec.topic:
        from distributed import get_worker

        worker = get_worker()

        def report(i, sphere_frames):
            worker.log_event(spec.topic, {"index": int(i), "done": int(sphere_frames)})

    return simulate_shard(scene, spec, index, report)


# --------------------------------------------------------------------------------------------
# Progress


class _Progress:
    """One tqdm bar over every shard's sphere-frames (thread-safe: Dask events arrive on the
    client's event-loop thread). A shard whose task is re-run after a lost worker reports from
    zero again; the bar only moves forward."""

    def __init__(self, sizes: list[int], total_frames: int, enabled: bool):
        self._lock = threading.Lock()
        self._done = [0] * len(sizes)
        self._full = [s * total_frames for s in sizes]
        self._finished = 0
        self._bar = None
        if enabled:
            from tqdm.auto import tqdm

            self._bar = tqdm(total=sum(self._full), unit="sphere-frame", unit_scale=True,
                             file=sys.stderr, dynamic_ncols=True, mininterval=0.2)
            self._bar.set_postfix_str(f"shards 0/{len(sizes)}")

    def advance(self, index: int, done: int) -> None:
        with self._lock:
            done = min(int(done), self._full[index])
            step = done - self._done[index]
            if step > 0:
                self._done[index] = done
                if self._bar is not None:
                    self._bar.update(step)

    def finish(self, index: int) -> None:
        self.advance(index, self._full[index])
        with self._lock:
            self._finished += 1
            if self._bar is not None:
                self._bar.set_postfix_str(f"shards {self._finished}/{len(self._full)}")

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


# --------------------------------------------------------------------------------------------
# The run


@dataclass
class RunSummary:
    """What :func:`run` did.

    Attributes:
        path: the root stage. shards: shard layers composed. recomputed: the shards computed
            by this run; reused: the complete layers kept from an earlier run.
        processes: Dask worker processes of the cluster (0 in process). processes_used:
            distinct worker processes (or this process) that computed a shard.
        spheres, frames: the swarm and the frames simulated (``start`` included).
        sphere_frames: of the recomputed shards. seconds: wall time of the whole run [s].
        task_seconds: sum of the recomputed tasks' wall times [s].
        bounces, capped: bounce and cap counters of all shards (reused ones included).
        supports: resting or sliding contacts of all shards, or None when a reused shard's
            layer, from an earlier version, does not say (its ``bounces`` then count both).
        capped_spheres: spheres stopped by the cap at least once (None when a reused shard's
            layer, from an earlier version, does not say).
        energy: the energy figures of the whole swarm (:func:`warpsim.energy_figures.combine`
            of the shards'), or None when a reused layer does not hold them.
    """

    path: Path
    shards: int
    recomputed: tuple[int, ...]
    reused: tuple[int, ...]
    processes: int
    processes_used: int
    spheres: int
    frames: int
    sphere_frames: int
    seconds: float
    task_seconds: float
    bounces: int
    capped: int
    capped_spheres: int | None = None
    energy: dict | None = None
    supports: int | None = None
    digests: tuple[str, ...] = field(default=(), repr=False)
    computed_by: dict[int, str] = field(default_factory=dict, repr=False)
    """Shard -> the worker (address) that computed it, for the recomputed shards."""

    @property
    def sphere_frames_per_second(self) -> float:
        """Recomputed sphere-frames per wall second of the run."""
        return self.sphere_frames / self.seconds if self.seconds > 0 else float("nan")

    def lines(self) -> list[str]:
        per_sphere_frame = max(self.spheres * self.frames, 1)
        where = (f"{self.processes_used} of {self.processes} Dask processes" if self.processes
                 else "this process")
        recomputed = (f"{len(self.recomputed)} of {self.shards} shards recomputed"
                      + (f", {len(self.reused)} reused" if self.reused else ""))
        speed = (f"{self.sphere_frames_per_second:,.0f} sphere-frames/s" if self.recomputed
                 else "nothing simulated: every shard was current")
        return [f"simulated {self.frames} frames x {self.spheres:,} spheres in {self.shards} "
                f"shards on {where}: {recomputed}; {self.seconds:.2f} s, {speed}",
                (f"contacts: {self.bounces:,} (bounces and resting contacts together: a "
                 f"reused shard layer does not tell them apart; "
                 if self.supports is None else
                 f"contacts: {self.bounces:,} bounces, {self.supports:,} resting or sliding ("
                 ) + f"{self.bounces / per_sphere_frame:.3f} bounces per sphere-frame); capped: "
                f"{self.capped:,} sphere-frames"
                + ("" if self.capped_spheres is None else f", {self.capped_spheres} spheres"),
                _energy_text(self.energy),
                f"wrote {self.path} ({self.shards} shard layers in {self.path.stem}.shards/)"]

    def __str__(self) -> str:
        return "\n".join(self.lines())


def _default_shards(n: int, block: int, records: int, velocities: bool, tasks: int) -> int:
    """At least ``tasks`` shards, and enough that no shard's records pass
    :data:`MAX_SHARD_BYTES`; at most one per block."""
    per_sphere = records * (_STORED_BYTES + (_VELOCITY_BYTES if velocities else 0))
    by_memory = -(-n * per_sphere // MAX_SHARD_BYTES)
    return max(1, min(block_count(n, block), max(tasks, by_memory)))


def run(scene, output, *, n: int | None = None, seed: int | None = None,
        frames: int | None = None, start: int = 0, every: int = 1, client=None,
        shards: int | None = None, block: int = DEFAULT_BLOCK, processes: int | None = None,
        threads: int | None = None, dt: float | None = None, max_bounces: int | None = None,
        device: str | None = None, precision: str = "float32", broad_phase: str = "auto",
        velocities: bool = False, motion: str | None = None, progress: bool = True,
        timeout: float = CONNECT_TIMEOUT, max_bytes: float | None = None,
        workers=None) -> RunSummary:
    """Simulate a scene's sharded swarm, one task and one USD layer per shard, and compose them.

    Args:
        scene: a :class:`warpsim.Scene` (with an emitter and obstacles), a bundled scene's name
            or a ``.toml`` path.
        output: the root stage (``.usdc`` or ``.usda``); the shard layers go in the folder
            ``<output stem>.shards`` next to it (see :mod:`warpsim.export.layers`).
        n: spheres (default: the emitter's count). seed: the draw's seed (default: the
            emitter's); the draw is :func:`sharded_spawn`'s, not ``scene.spawn``'s.
        frames: last frame simulated (default ``scene.frames``); frames ``start`` to
            ``frames`` are recorded, one in ``every`` (the last always).
        client: None runs the shards one after the other in this process (no Dask needed; the
            reference run); ``"local"`` starts a ``LocalCluster`` of ``processes`` (one
            thread each) for this run; a scheduler address (``tcp://HOST:PORT``) or a
            ``distributed.Client`` uses that cluster.
        shards: number of shards (default: 4 per worker thread, more when a shard's records
            would pass 1 GiB; never more than the blocks).
        block: spheres per block of the draw (changing it changes the spheres).
        processes: Dask worker processes of a ``"local"`` cluster (default: one per core).
        threads: CPU threads each shard's simulator launches from (its ``workers``; default:
            1 per Dask task, every core in process).
        dt, max_bounces, device, precision, broad_phase, motion: as :class:`warpsim.Simulator`
            (``motion`` only when given).
        velocities: also store velocities and angular velocities.
        progress: one tqdm bar over all shards' sphere-frames on standard error.
        timeout: seconds to wait for a scheduler at an address [s].
        max_bytes: refuse the run when the estimated output is larger [bytes] (None: no limit).
        workers: removed (it was ``processes``); passing it is an error that says so.

    Returns:
        A :class:`RunSummary` (printable).

    Raises:
        ValueError: a bad argument (named), found before anything runs; a failed shard (named,
            with its spheres).
        OSError: the output cannot be written; no scheduler at the address.
        ImportError: a client is asked for and dask is not installed (names the extra).
        TypeError: ``workers`` given (renamed ``processes``).
    """
    if workers is not None:
        raise TypeError(WORKERS_RENAMED.format(what="run"))
    from ..export.files import check_writable
    from ..export.layers import shard_folder, shard_manifest, write_root_stage

    began = time.perf_counter()
    if not isinstance(scene, Scene):
        scene = Scene.load(scene)
    n, seed, block = check_draw(scene, n, seed, block)
    if len(scene.boxes) == 0:
        raise ValueError(f"scene {scene.name!r} has no obstacles: the simulator then takes its "
                         f"energy origin from the swarm, which a shard does not see whole, so "
                         f"shards could not give the bits of a one-process run")
    end = check.positive_int("frames", scene.frames if frames is None else frames)
    start = check.positive_int("start", start, minimum=0)
    if start >= end:
        raise ValueError(f"start {start} must be before frames {end}")
    every = check.positive_int("every", every)
    if shards is not None:
        shards = check.positive_int("shards", shards)
    if threads is not None:
        threads = check.positive_int("threads", threads)
    velocities = check.flag("velocities", velocities)
    timeout = check.scalar("timeout", timeout, positive=True)
    if client is None and processes is not None:
        raise ValueError("processes is the size of a 'local' cluster: it needs client='local'")
    if isinstance(client, str) and client != LOCAL:
        client = scheduler_address(client)  # a bad address fails before any file is made
    out = check_writable(output, (".usdc", ".usda"), what="output")
    stage_set = getattr(scene.boxes, "stage", None)  # a result composed over that set
    if stage_set is not None:
        from ..export.compose import check_output

        check_output(stage_set, out)
    folder = shard_folder(out)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"shard folder {str(folder)!r} exists and is not a folder")
    folder.mkdir(exist_ok=True)
    options = (("motion", motion),) if motion is not None else ()
    spec = RunSpec(n=n, seed=seed, block=block, bounds=((0, min(block, n)),), frames=end - start,
                   start=start, every=every, dt=scene.dt if dt is None else dt,
                   max_bounces=scene.max_bounces if max_bounces is None else max_bounces,
                   precision=precision, broad_phase=broad_phase, device=device, options=options,
                   velocities=velocities, threads=threads, folder=str(folder),
                   scene_key=scene_key(scene))
    # Every setting is checked here, on one block, before a cluster starts: a bad dt, cap,
    # precision, broad phase, device or motion fails now, not in every task.
    probe = _simulator(scene, spawn_block(scene, n, seed, 0, block, spec.dt), spec)
    spec = _replace(spec, dt=float(probe.dt), max_bounces=int(probe.max_bounces))
    records = spec.recorded_frames()
    if max_bytes is not None:
        from ..export import estimate_usd_bytes

        estimate = estimate_usd_bytes(n, records.size, "usdc", velocities=velocities)
        if estimate > max_bytes:
            raise ValueError(f"{str(out)!r} and its shards would be about {estimate / 1e6:,.0f}"
                             f" MB ({n} spheres x {records.size} frames), above max_bytes "
                             f"{max_bytes:,.0f}: record fewer frames (every, start) or spheres")
    if client is None:
        plan = plan_shards(n, shards or _default_shards(n, block, records.size, velocities, 1),
                           block)
        spec = _replace(spec, bounds=tuple(plan))
        done, computed, cluster_processes = _run_here(scene, spec, progress)
    else:
        require_dask()
        with client_for(client, processes, timeout) as dask_client:
            cluster_processes, threads_now = cluster_threads(dask_client)
            count = shards or _default_shards(n, block, records.size, velocities,
                                              TASKS_PER_THREAD * max(threads_now, 1))
            spec = _replace(spec, bounds=tuple(plan_shards(n, count, block)),
                            threads=1 if threads is None else threads,
                            topic=f"warpsim-progress-{secrets.token_hex(6)}")
            done, computed = _run_on(dask_client, scene, spec, progress)
    results = [done[i] for i in range(spec.count)]
    layers = [spec.layer_path(i) for i in range(spec.count)]
    for i, path in enumerate(layers):  # every layer composed must be the one just checked
        manifest = shard_manifest(path)
        if manifest is None or manifest.get("key") != results[i]["key"]:
            raise OSError(f"shard layer {str(path)!r} changed while the run was writing the "
                          f"root (another run on the same output?)")
    write_root_stage(out, scene, records, spec.dt, layers, {
        "keys": [r["key"] for r in results], "digests": [r["digest"] for r in results],
        "starts": [b[0] for b in spec.bounds], "stops": [b[1] for b in spec.bounds],
        "n": n, "seed": seed, "block": block, "frames": end, "every": every})
    _remove_stale_layers(folder, layers)
    recomputed = tuple(sorted(computed))
    together = any(r.get("supports") is None for r in results)
    return RunSummary(
        path=out, shards=spec.count, recomputed=recomputed,
        reused=tuple(i for i in range(spec.count) if i not in computed),
        processes=cluster_processes,
        processes_used=len({done[i]["worker"] for i in computed}), spheres=n, frames=end,
        sphere_frames=sum(done[i]["sphere_frames"] for i in computed),
        seconds=time.perf_counter() - began,
        task_seconds=sum(done[i]["seconds"] for i in computed),
        # a layer of an earlier version counts its resting contacts among its bounces: then
        # the summary gives every contact together
        bounces=sum(r["bounces"] for r in results) + (
            sum(int(r.get("supports") or 0) for r in results) if together else 0),
        capped=sum(r["capped"] for r in results),
        supports=None if together else sum(int(r["supports"]) for r in results),
        capped_spheres=(None if any(r.get("capped_spheres") is None for r in results)
                        else sum(int(r["capped_spheres"]) for r in results)),
        energy=(None if any(not isinstance(r.get("energy"), dict) for r in results)
                else _combined_energy([r["energy"] for r in results])),
        digests=tuple(r["digest"] for r in results),
        computed_by={i: done[i]["worker"] for i in recomputed})

def _combined_energy(parts: list[dict]) -> dict:
    from ..energy_figures import combine

    return combine(parts)


def _energy_text(energy: dict | None) -> str:
    from ..energy_figures import line

    if energy is None:
        return "energy: not known (a reused shard layer from an earlier version lacks it)"
    return line(energy)


def _remove_stale_layers(folder: Path, layers: list[Path]) -> list[Path]:
    """Remove the shard layers of an earlier run with other shards (``shard_<digits>.usdc``
    or ``.usda`` files the new root does not compose); returns what was removed. Nothing else
    in the folder is touched."""
    keep = {Path(p).name for p in layers}
    removed = []
    for path in sorted(Path(folder).glob("shard_*.usd[ac]")):
        if path.name not in keep and re.fullmatch(r"shard_\d+\.usd[ac]", path.name):
            path.unlink()
            removed.append(path)
    return removed


def _replace(spec: RunSpec, **changes) -> RunSpec:
    from dataclasses import replace

    return replace(spec, **changes)


def _reusable(spec: RunSpec) -> dict[int, dict]:
    """The shards whose layer is complete and current: index -> what the manifest says."""
    from ..export.layers import shard_manifest

    found = {}
    for i in range(spec.count):
        manifest = shard_manifest(spec.layer_path(i))
        if manifest is not None and manifest.get("key") == spec.shard_key(i):
            found[i] = {"index": i, "key": manifest["key"], "digest": manifest["digest"],
                        "bounces": int(manifest.get("bounces", 0)),
                        "supports": manifest.get("supports"),
                        "capped": int(manifest.get("capped", 0)),
                        "capped_spheres": manifest.get("capped_spheres"),
                        "energy": manifest.get("energy")}
    return found


def _shard_error(spec: RunSpec, index: int, exc: BaseException) -> Exception:
    start, stop = spec.bounds[index]
    text = " ".join(str(exc).split()) or type(exc).__name__
    message = f"shard {index} (spheres {start}..{stop - 1}) failed: {text}"
    if type(exc).__name__ == "KilledWorker":
        message = (f"shard {index} (spheres {start}..{stop - 1}) was lost with every worker "
                   f"that ran it (Dask gives up after distributed.scheduler.allowed-failures "
                   f"deaths; out of memory?): {text}")
        return RuntimeError(message)
    return (OSError if isinstance(exc, OSError) else ValueError)(message)


def _run_here(scene: Scene, spec: RunSpec, progress: bool):
    done = _reusable(spec)
    todo = [i for i in range(spec.count) if i not in done]
    bar = _Progress([b - a for a, b in spec.bounds], spec.start + spec.frames, progress)
    try:
        for i in done:
            bar.finish(i)
        for i in todo:
            try:
                done[i] = simulate_shard(scene, spec, i, bar.advance)
            except (ValueError, OSError) as exc:
                raise _shard_error(spec, i, exc) from exc
            bar.finish(i)
    finally:
        bar.close()
    return done, set(todo), 0


def _run_on(client, scene: Scene, spec: RunSpec, progress: bool):
    from distributed import as_completed

    done = _reusable(spec)
    todo = [i for i in range(spec.count) if i not in done]
    bar = _Progress([b - a for a, b in spec.bounds], spec.start + spec.frames, progress)

    def on_event(event):
        _, message = event
        bar.advance(int(message["index"]), int(message["done"]))

    for i in done:
        bar.finish(i)
    futures = {}
    client.subscribe_topic(spec.topic, on_event)
    try:
        if todo:
            token = secrets.token_hex(4)
            # A task, not scattered data: Dask recomputes a task's result lost with a worker,
            # while scattered data lost with its worker is gone for good.
            scene_future = client.submit(_scene_task, scene, key=f"warpsim-scene-{token}",
                                         pure=False)
            futures = {client.submit(_dask_shard_task, scene_future, spec, i,
                                     key=f"warpsim-shard-{token}-{i}", pure=False): i
                       for i in todo}
            for future in as_completed(list(futures)):
                i = futures[future]
                try:
                    done[i] = future.result()
                except Exception as exc:
                    raise _shard_error(spec, i, exc) from exc
                bar.finish(i)
    finally:
        with contextlib.suppress(Exception):
            client.unsubscribe_topic(spec.topic)
        for future in futures:
            future.cancel()
        bar.close()
    return done, set(todo)


def read(path):
    """The composed result of :func:`run`, as one :class:`warpsim.Trajectory` (spheres in swarm
    order; see :func:`warpsim.export.layers.read_sharded_usd`)."""
    from ..export.layers import read_sharded_usd

    return read_sharded_usd(path)
