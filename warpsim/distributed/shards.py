"""The same run on a Dask cluster: the swarm in shards, one task and one USD layer per shard.

Spheres never interact, so a swarm shards perfectly. :func:`run` splits the swarm into shards of
whole *blocks* of spheres; each shard is one task that draws its own spheres on the worker (from
the scene's emitter, the seed and the block numbers: no per-sphere array goes through the
client), simulates them and writes its own USD layer atomically; the client then writes a small
root stage composing the layers with the obstacles (layout: :mod:`warpsim.export.layers`).

The sharded draw. Sphere ``i`` of a swarm of ``n`` belongs to block ``i // block``; block ``b``
is the emitter's draw ``scene.spawn(n=size_b, seed=block_seed(seed, b))`` (``size_b`` is
``block`` but for a shorter last block). A shard is a run of whole blocks, so any shard draws the
same spheres as a one-process run of the whole swarm: :func:`sharded_spawn` (all blocks) and
:func:`shard_swarm` (some blocks) are the one draw both paths use, and the composed result is
bit-identical whatever the number of workers or shards. Every block is checked clear of the
obstacles, per sphere (the emitter's rejection sampling, then
:func:`warpsim.validation.check_outside`), exactly as :meth:`warpsim.Scene.spawn` checks it.
It is **not** the draw of ``scene.spawn(n, seed)`` (one stream for the whole swarm): a single
stream cannot be split among workers without drawing all of it, so the sharded draw is its own
(equally valid) sample; ``warpsim run`` without ``--dask`` keeps ``scene.spawn``. Changing
``block`` changes the draw; it is stored in every manifest.

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
import functools
import hashlib
import json
import secrets
import sys
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import validation as check
from .scene import Scene
from .swarm import Swarm

DEFAULT_BLOCK = 1024
"""Spheres per block of the sharded draw. Measured on the room scene: drawing a block costs
about 5 ms of fixed overhead plus 5 us per sphere, so 1024-sphere blocks keep the draw within
7 us per sphere (a 300-frame run costs about 45 us per sphere) while a shard can still be as
small as one block."""

MAX_SHARD_BYTES = 1 << 30
"""A shard task holds its recorded frames in memory until its layer is written (28 bytes per
sphere-frame, 52 with velocities): shards are made small enough to stay under 1 GiB each."""

TASKS_PER_THREAD = 4
"""Default shards per worker thread: enough tasks that a slow or lost worker leaves little
idle time at the end, few enough that per-task start-up (a Warp kernel load) stays small."""

PROGRESS_SPHERE_FRAMES = 1 << 22
"""A shard simulates in chunks of about this many sphere-frames (a few tenths of a second on one
core) and reports its progress after each; the result is the same bits as one run."""

CONNECT_TIMEOUT = 10.0
"""Seconds to wait for a Dask scheduler before the error [s]."""

DEFAULT_SCHEDULER_PORT = 8786  # Dask's own default, for an address given without a port
LOCAL = "local"  # the client value (and ``--dask`` without an address) that starts a LocalCluster
DASK_MISSING = 'dask is needed for distributed runs: pip install "warpsim[dask]"'
SEED_LIMIT = 1 << 31  # emitter seeds are integers below 2**31
_BLOCK_TAG = 0x5751_4B42  # domain separation of the block-seed keys from other uses of a seed
_STORED_BYTES = 28  # per sphere-frame: float32 positions (12) and orientations (16)
_VELOCITY_BYTES = 24  # per sphere-frame: float32 velocities and angular velocities


# --------------------------------------------------------------------------------------------
# The sharded draw


def _feistel_round(half: int, key: int) -> int:
    h = (half * 0x9E3779B1 + key) & 0xFFFFFFFF
    h ^= h >> 15
    h = (h * 0x85EBCA6B) & 0xFFFFFFFF
    h ^= h >> 13
    return h & 0xFFFF


@functools.lru_cache(maxsize=64)
def _block_keys(seed: int) -> tuple[int, ...]:
    """The four round keys of a seed's block permutation."""
    return tuple(int(k) for k in np.random.SeedSequence([_BLOCK_TAG, seed]).generate_state(4))


def block_seed(seed: int, block: int) -> int:
    """The emitter seed of block ``block`` of the sharded draw with seed ``seed``.

    A keyed permutation of ``[0, 2**31)`` (a four-round Feistel network on 32 bits, cycle-walked
    into 31 bits, keyed by ``numpy.random.SeedSequence`` of the seed): the blocks of one run
    always get distinct seeds (so distinct streams), and the block seeds of two different run
    seeds are unrelated.

    Args:
        seed: the run's seed, an integer >= 0.
        block: the block number, in ``[0, 2**31)``.

    Returns:
        An integer in ``[0, 2**31)``.
    """
    seed = check.positive_int("seed", seed, minimum=0)
    block = check.positive_int("block", block, minimum=0)
    keys = _block_keys(seed)
    x = block
    while True:  # cycle walking: a permutation of [0, 2**32) restricted to [0, 2**31)
        left, right = x >> 16, x & 0xFFFF
        for key in keys:
            left, right = right, left ^ _feistel_round(right, key)
        x = (left << 16) | right
        if x < SEED_LIMIT:
            return x


def _check_draw(scene: Scene, n, seed, block) -> tuple[int, int, int]:
    """Validated ``(n, seed, block)`` of the scene's sharded draw (n=None: the emitter's count,
    seed=None: the emitter's seed)."""
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a warpsim.Scene, got {type(scene).__name__}")
    if scene.emitter is None:
        raise ValueError(f"scene {scene.name!r} has no emitter: a sharded run draws its spheres "
                         f"from the scene's emitter")
    n = scene.emitter.count if n is None else check.positive_int("n", n)
    seed = scene.emitter.seed if seed is None else check.positive_int("seed", seed, minimum=0)
    block = check.positive_int("block", block)
    return n, seed, block


def block_count(n: int, block: int = DEFAULT_BLOCK) -> int:
    """Blocks of a swarm of ``n`` spheres: ``ceil(n / block)``."""
    return -(-n // block)


def spawn_block(scene: Scene, n: int | None, seed: int | None, index: int,
                block: int = DEFAULT_BLOCK) -> Swarm:
    """Spheres ``index * block`` to ``min((index + 1) * block, n)`` of the sharded draw.

    Args:
        scene: a scene with an emitter and obstacles.
        n: spheres of the whole swarm (None: the emitter's count).
        seed: the run's seed (None: the emitter's).
        index: the block number, in ``[0, ceil(n / block))``.
        block: spheres per block.

    Returns:
        The block's spheres, each clear of every obstacle.

    Raises:
        ValueError: bad arguments (named), or the emitter cannot place the block.
    """
    n, seed, block = _check_draw(scene, n, seed, block)
    blocks = block_count(n, block)
    index = check.positive_int("index", index, minimum=0, maximum=blocks - 1,
                               reason=f"{n} spheres make {blocks} blocks of {block}")
    size = min(block, n - index * block)
    return scene.spawn(n=size, seed=block_seed(seed, index))


def shard_swarm(scene: Scene, n: int | None, seed: int | None, start: int, stop: int,
                block: int = DEFAULT_BLOCK) -> Swarm:
    """Spheres ``start`` to ``stop`` (excluded) of the sharded draw, made of whole blocks.

    Args:
        start: a multiple of ``block``; stop: a multiple of ``block`` or ``n``, > ``start``.

    Raises:
        ValueError: a range that is not whole blocks, or out of ``[0, n]``.
    """
    n, seed, block = _check_draw(scene, n, seed, block)
    start = check.positive_int("start", start, minimum=0, maximum=n - 1)
    stop = check.positive_int("stop", stop, minimum=start + 1, maximum=n)
    if start % block or (stop % block and stop != n):
        raise ValueError(f"spheres {start}..{stop} are not whole blocks of {block} (a shard "
                         f"starts and ends on a multiple of block, or ends at n = {n})")
    parts = [spawn_block(scene, n, seed, b, block) for b in range(start // block,
                                                                   block_count(stop, block))]
    return _joined(parts)


def sharded_spawn(scene: Scene, n: int | None = None, seed: int | None = None,
                  block: int = DEFAULT_BLOCK) -> Swarm:
    """The whole swarm of the sharded draw, in one process: the spheres :func:`run` simulates,
    for a one-process run of the same spheres (``Simulator(scene, sharded_spawn(...))``)."""
    n, seed, block = _check_draw(scene, n, seed, block)
    return shard_swarm(scene, n, seed, 0, n, block)


def _joined(parts: list[Swarm]) -> Swarm:
    if len(parts) == 1:
        return parts[0]
    return Swarm(**{name: np.concatenate([getattr(p, name) for p in parts])
                    for name in ("position", "velocity", "radius", "mass", "angular_momentum",
                                 "orientation")})


def plan_shards(n: int, shards: int, block: int = DEFAULT_BLOCK) -> list[tuple[int, int]]:
    """``shards`` contiguous sphere ranges ``(start, stop)`` of whole blocks, nearly equal.

    At most one shard per block: asking for more shards than blocks gives one per block.
    """
    n = check.positive_int("n", n)
    block = check.positive_int("block", block)
    shards = check.positive_int("shards", shards)
    blocks = block_count(n, block)
    edges = np.linspace(0, blocks, min(shards, blocks) + 1).round().astype(np.int64)
    return [(int(a) * block, min(int(b) * block, n))
            for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]


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
        from .export.layers import shard_name

        return Path(self.folder) / f"{shard_name(index, self.count)}.usdc"

    def shard_key(self, index: int) -> str:
        """Hash of everything that determines shard ``index``'s bits."""
        from . import __version__

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
    from .simulator import Simulator

    return Simulator(scene, swarm, dt=spec.dt, max_bounces=spec.max_bounces, device=spec.device,
                     precision=spec.precision, broad_phase=spec.broad_phase,
                     workers=spec.threads, **dict(spec.options))


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
        ``sphere_frames``, ``bounces``, ``capped``, ``worker`` (its address).
    """
    from .export.layers import write_shard_layer
    from .trajectory import Trajectory

    begin = time.perf_counter()
    start, stop = spec.bounds[index]
    swarm = shard_swarm(scene, spec.n, spec.seed, start, stop, spec.block)
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
    digest = write_shard_layer(spec.layer_path(index), trajectory,
                               np.arange(start, stop, dtype=np.int64), index, spec.count,
                               {"key": key, "start": int(start), "stop": int(stop),
                                "bounces": int(stats.bounces), "capped": int(stats.capped)},
                               velocities=spec.velocities)
    return {"index": int(index), "digest": digest, "key": key,
            "seconds": time.perf_counter() - begin, "sphere_frames": int(stats.sphere_frames),
            "bounces": int(stats.bounces), "capped": int(stats.capped),
            "worker": _worker_name()}


def _without_first(part):
    """A chunk's records but its first (the previous chunk's last)."""
    from .trajectory import Trajectory

    def cut(values):
        return None if values is None else values[1:]

    return Trajectory(frame=part.frame[1:], dt=part.dt, position=part.position[1:],
                      orientation=part.orientation[1:], radius=part.radius,
                      velocity=cut(part.velocity), angular_velocity=cut(part.angular_velocity))


def _concatenated(parts):
    from .trajectory import Trajectory

    if len(parts) == 1:
        return parts[0]

    def joined(name):
        values = [getattr(p, name) for p in parts]
        return None if values[0] is None else np.concatenate(values)

    return Trajectory(frame=joined("frame"), dt=parts[0].dt, position=joined("position"),
                      orientation=joined("orientation"), radius=parts[0].radius,
                      velocity=joined("velocity"), angular_velocity=joined("angular_velocity"))


def _scene_task(scene: Scene) -> Scene:
    """The scene as a task's result, shared by the shard tasks of a Dask run."""
    return scene


def _dask_shard_task(scene: Scene, spec: RunSpec, index: int) -> dict:
    """:func:`simulate_shard` on a Dask worker, reporting progress as events on
    ``spec.topic``."""
    report = None
    if spec.topic:
        from distributed import get_worker

        worker = get_worker()

        def report(i, sphere_frames):
            worker.log_event(spec.topic, {"index": int(i), "done": int(sphere_frames)})

    return simulate_shard(scene, spec, index, report)


# --------------------------------------------------------------------------------------------
# Clients


def require_dask():
    """Import ``distributed``; a missing one is a one-line ImportError naming the extra."""
    try:
        import distributed
    except ImportError:
        raise ImportError(DASK_MISSING) from None
    return distributed


def scheduler_address(text: str) -> str:
    """A scheduler address in Dask's form (``tcp://HOST:PORT``), checked.

    Accepts ``HOST:PORT``, ``HOST`` (port 8786, Dask's default) and ``SCHEME://HOST:PORT`` for
    the schemes Dask knows (``tcp``, ``tls``, ``inproc``, ``ucx``, ``ws``, ``wss``).

    Raises:
        ValueError: not a string, empty, an unknown scheme, no host, or a bad port.
    """
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"Dask scheduler address must be HOST:PORT or tcp://HOST:PORT, got "
                         f"{text!r}")
    raw = text.strip()
    scheme, sep, rest = raw.partition("://")
    if not sep:
        scheme, rest = "tcp", raw
    known = ("tcp", "tls", "inproc", "ucx", "ws", "wss")
    if scheme not in known:
        raise ValueError(f"Dask scheduler address {text!r}: unknown scheme {scheme!r} (use one "
                         f"of {', '.join(known)})")
    if scheme == "inproc":
        if not rest:
            raise ValueError(f"Dask scheduler address {text!r} has no location")
        return raw
    host, colon, port = rest.rpartition(":")
    if not colon:
        host, port = rest, str(DEFAULT_SCHEDULER_PORT)
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not host or "/" in host or any(c.isspace() for c in host):
        raise ValueError(f"Dask scheduler address {text!r} has no valid host (expected "
                         f"HOST:PORT or tcp://HOST:PORT)")
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"Dask scheduler address {text!r}: port must be an integer in "
                         f"1..65535, got {port!r}")
    shown = f"[{host}]" if ":" in host else host
    return f"{scheme}://{shown}:{int(port)}"


@contextlib.contextmanager
def _client_for(client, workers: int | None, timeout: float):
    """Yield a connected ``distributed.Client`` for ``client`` (LOCAL, an address or a Client);
    what this opened is closed on exit."""
    distributed = require_dask()
    if isinstance(client, distributed.Client):
        yield client
        return
    if client == LOCAL:
        if workers is not None:
            check.positive_int("workers", workers)
        with distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cluster, \
                distributed.Client(cluster) as local:
            yield local
        return
    if not isinstance(client, str):
        raise ValueError(f"client must be None, {LOCAL!r}, a scheduler address or a "
                         f"distributed.Client, got {type(client).__name__}")
    address = scheduler_address(client)
    try:
        remote = distributed.Client(address, timeout=timeout)
    except (OSError, TimeoutError) as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise OSError(f"no Dask scheduler answered at {address} within {timeout:g} s "
                      f"({reason})") from None
    try:
        yield remote
    finally:
        remote.close()


def _cluster_threads(client) -> tuple[int, int]:
    """(workers, threads) of the cluster now."""
    workers = client.scheduler_info().get("workers", {})
    return len(workers), sum(int(w.get("nthreads", 1)) for w in workers.values())


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
        workers: workers of the cluster (0 in process). workers_used: distinct workers (or
            this process) that computed a shard.
        spheres, frames: the swarm and the frames simulated (``start`` included).
        sphere_frames: of the recomputed shards. seconds: wall time of the whole run [s].
        task_seconds: sum of the recomputed tasks' wall times [s].
        bounces, capped: contact and cap counters of all shards (reused ones included).
    """

    path: Path
    shards: int
    recomputed: tuple[int, ...]
    reused: tuple[int, ...]
    workers: int
    workers_used: int
    spheres: int
    frames: int
    sphere_frames: int
    seconds: float
    task_seconds: float
    bounces: int
    capped: int
    digests: tuple[str, ...] = field(default=(), repr=False)
    computed_by: dict[int, str] = field(default_factory=dict, repr=False)
    """Shard -> the worker (address) that computed it, for the recomputed shards."""

    @property
    def sphere_frames_per_second(self) -> float:
        """Recomputed sphere-frames per wall second of the run."""
        return self.sphere_frames / self.seconds if self.seconds > 0 else float("nan")

    def lines(self) -> list[str]:
        per_sphere_frame = max(self.spheres * self.frames, 1)
        where = (f"{self.workers_used} of {self.workers} workers" if self.workers
                 else "this process")
        recomputed = (f"{len(self.recomputed)} of {self.shards} shards recomputed"
                      + (f", {len(self.reused)} reused" if self.reused else ""))
        return [f"simulated {self.frames} frames x {self.spheres:,} spheres in {self.shards} "
                f"shards on {where}: {recomputed}; {self.seconds:.2f} s, "
                f"{self.sphere_frames_per_second:,.0f} sphere-frames/s",
                f"bounces: {self.bounces:,} ({self.bounces / per_sphere_frame:.3f} per "
                f"sphere-frame); capped: {self.capped:,} sphere-frames",
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
        shards: int | None = None, block: int = DEFAULT_BLOCK, workers: int | None = None,
        threads: int | None = None, dt: float | None = None, max_bounces: int | None = None,
        device: str | None = None, precision: str = "float32", broad_phase: str = "auto",
        velocities: bool = False, motion: str | None = None, progress: bool = True,
        timeout: float = CONNECT_TIMEOUT, max_bytes: float | None = None) -> RunSummary:
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
            reference run); ``"local"`` starts a ``LocalCluster`` of ``workers`` processes (one
            thread each) for this run; a scheduler address (``tcp://HOST:PORT``) or a
            ``distributed.Client`` uses that cluster.
        shards: number of shards (default: 4 per worker thread, more when a shard's records
            would pass 1 GiB; never more than the blocks).
        block: spheres per block of the draw (changing it changes the spheres).
        workers: processes of a ``"local"`` cluster (default: one per core).
        threads: CPU threads each shard's simulator launches from (default: 1 per Dask task,
            every core in process).
        dt, max_bounces, device, precision, broad_phase, motion: as :class:`warpsim.Simulator`
            (``motion`` only when given).
        velocities: also store velocities and angular velocities.
        progress: one tqdm bar over all shards' sphere-frames on standard error.
        timeout: seconds to wait for a scheduler at an address [s].
        max_bytes: refuse the run when the estimated output is larger [bytes] (None: no limit).

    Returns:
        A :class:`RunSummary` (printable).

    Raises:
        ValueError: a bad argument (named), found before anything runs; a failed shard (named,
            with its spheres).
        OSError: the output cannot be written; no scheduler at the address.
        ImportError: a client is asked for and dask is not installed (names the extra).
    """
    from .export.files import check_writable
    from .export.layers import shard_folder, shard_manifest, write_root_stage

    began = time.perf_counter()
    if not isinstance(scene, Scene):
        scene = Scene.load(scene)
    n, seed, block = _check_draw(scene, n, seed, block)
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
    if client is None and workers is not None:
        raise ValueError("workers is the size of a 'local' cluster: it needs client='local'")
    if isinstance(client, str) and client != LOCAL:
        client = scheduler_address(client)  # a bad address fails before any file is made
    out = check_writable(output, (".usdc", ".usda"), what="output")
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
    probe = _simulator(scene, spawn_block(scene, n, seed, 0, block), spec)
    spec = _replace(spec, dt=float(probe.dt), max_bounces=int(probe.max_bounces))
    records = spec.recorded_frames()
    if max_bytes is not None:
        from .export import estimate_usd_bytes

        estimate = estimate_usd_bytes(n, records.size, "usdc", velocities=velocities)
        if estimate > max_bytes:
            raise ValueError(f"{str(out)!r} and its shards would be about {estimate / 1e6:,.0f}"
                             f" MB ({n} spheres x {records.size} frames), above max_bytes "
                             f"{max_bytes:,.0f}: record fewer frames (every, start) or spheres")
    if client is None:
        plan = plan_shards(n, shards or _default_shards(n, block, records.size, velocities, 1),
                           block)
        spec = _replace(spec, bounds=tuple(plan))
        done, computed, cluster_workers = _run_here(scene, spec, progress)
    else:
        require_dask()
        with _client_for(client, workers, timeout) as dask_client:
            cluster_workers, cluster_threads = _cluster_threads(dask_client)
            count = shards or _default_shards(n, block, records.size, velocities,
                                              TASKS_PER_THREAD * max(cluster_threads, 1))
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
    recomputed = tuple(sorted(computed))
    return RunSummary(
        path=out, shards=spec.count, recomputed=recomputed,
        reused=tuple(i for i in range(spec.count) if i not in computed),
        workers=cluster_workers,
        workers_used=len({done[i]["worker"] for i in computed}), spheres=n, frames=end,
        sphere_frames=sum(done[i]["sphere_frames"] for i in computed),
        seconds=time.perf_counter() - began,
        task_seconds=sum(done[i]["seconds"] for i in computed),
        bounces=sum(r["bounces"] for r in results), capped=sum(r["capped"] for r in results),
        digests=tuple(r["digest"] for r in results),
        computed_by={i: done[i]["worker"] for i in recomputed})


def run_command(args, scene: Scene) -> RunSummary:
    """``warpsim run SCENE --dask [ADDRESS] [--shards N] [--block B]``: :func:`run` from the
    command line's options (``--shards`` or ``--block`` without ``--dask`` shard in this
    process). ``--workers`` is the threads of each shard's simulator.

    Raises:
        ValueError: an option a sharded run does not support, or a bad value (named).
    """
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
    output = args.output if args.output is not None else f"{scene.name}.usdc"
    client = args.dask
    if client not in (None, LOCAL):
        client = scheduler_address(client)
    where = ("this process" if client is None else "a local Dask cluster" if client == LOCAL
             else f"the Dask scheduler at {client}")
    n = scene.emitter.count if args.count is None and scene.emitter is not None else args.count
    print(f"{scene.name}: {n} spheres, {len(scene.boxes)} obstacles, sharded on {where}",
          file=sys.stderr)
    return run(scene, output, n=args.count, seed=args.seed, frames=end, start=args.start,
               every=args.every, client=client, shards=args.shards,
               block=DEFAULT_BLOCK if args.block is None else args.block, threads=args.workers,
               dt=args.dt, max_bounces=args.max_bounces, device=args.device,
               precision=args.precision, broad_phase=args.broad_phase,
               velocities=bool(args.velocities), motion=args.motion,
               progress=not args.no_progress, max_bytes=args.max_bytes)


def _replace(spec: RunSpec, **changes) -> RunSpec:
    from dataclasses import replace

    return replace(spec, **changes)


def _reusable(spec: RunSpec) -> dict[int, dict]:
    """The shards whose layer is complete and current: index -> what the manifest says."""
    from .export.layers import shard_manifest

    found = {}
    for i in range(spec.count):
        manifest = shard_manifest(spec.layer_path(i))
        if manifest is not None and manifest.get("key") == spec.shard_key(i):
            found[i] = {"index": i, "key": manifest["key"], "digest": manifest["digest"],
                        "bounces": int(manifest.get("bounces", 0)),
                        "capped": int(manifest.get("capped", 0))}
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


# --------------------------------------------------------------------------------------------
# Sweeps


def sweep(function: Callable, items: Iterable, *, client=None, workers: int | None = None,
          progress: bool = True, timeout: float = CONNECT_TIMEOUT) -> list:
    """``[function(item) for item in items]``, one Dask task per item, results in order.

    For many scenes or settings at once, such as the accuracy study of several scenes
    (``sweep(warpsim.accuracy.main, [["room", "--out", "acc/room"], ...], client=...)``).
    ``function`` must be importable or picklable by cloudpickle on the workers.

    Args:
        function: called once per item, on a worker.
        items: the arguments, one per task.
        client: as in :func:`run`: None in this process, ``"local"``, an address or a
            ``distributed.Client``.
        workers: processes of a ``"local"`` cluster.
        progress: a tqdm bar over the items.
        timeout: seconds to wait for a scheduler at an address [s].

    Returns:
        The results, in the order of ``items``.

    Raises:
        ValueError: an item's task failed (the message names the item's position).
    """
    items = list(items)
    if not callable(function):
        raise ValueError(f"function must be callable, got {type(function).__name__}")
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(items), unit="task", file=sys.stderr, dynamic_ncols=True)
    try:
        if client is None:
            results = []
            for k, item in enumerate(items):
                try:
                    results.append(function(item))
                except Exception as exc:
                    raise ValueError(f"sweep item {k} ({item!r}) failed: "
                                     f"{' '.join(str(exc).split())}") from exc
                if bar is not None:
                    bar.update(1)
            return results
        require_dask()
        from distributed import as_completed

        with _client_for(client, workers, check.scalar("timeout", timeout, positive=True)) as c:
            futures = c.map(function, items, pure=False)
            index = {f.key: k for k, f in enumerate(futures)}
            results = [None] * len(items)
            try:
                for future in as_completed(futures):
                    k = index[future.key]
                    try:
                        results[k] = future.result()
                    except Exception as exc:
                        raise ValueError(f"sweep item {k} ({items[k]!r}) failed: "
                                         f"{' '.join(str(exc).split())}") from exc
                    if bar is not None:
                        bar.update(1)
            finally:
                for future in futures:
                    future.cancel()
            return results
    finally:
        if bar is not None:
            bar.close()


def read(path):
    """The composed result of :func:`run`, as one :class:`warpsim.Trajectory` (spheres in swarm
    order; see :func:`warpsim.export.layers.read_sharded_usd`)."""
    from .export.layers import read_sharded_usd

    return read_sharded_usd(path)


__all__ = ["DEFAULT_BLOCK", "LOCAL", "RunSpec", "RunSummary", "block_count", "block_seed",
           "plan_shards", "read", "run", "scene_key", "scheduler_address", "shard_swarm",
           "sharded_spawn", "simulate_shard", "spawn_block", "sweep"]
