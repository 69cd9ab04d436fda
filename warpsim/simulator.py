"""The simulator: a swarm advanced frame by frame among a scene's obstacles, state on the device."""

from __future__ import annotations

import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields
from functools import partial

import numpy as np
import warp as wp

from . import broad_phase as broad
from . import feasibility
from . import validation as check
from .blocks import any_rows, for_row_blocks, map_row_blocks
from .cores import host_cores
from .device import bvh_bounds, resolve_device
from .kernels import precision as fp
from .kernels.data import Features
from .kernels.frame_kernel import frame_kernel
from .model import (
    event_buffer,
    kernel_arguments,
    parameter_names,
    put_model,
    put_spheres,
    put_state,
    spheres_per_task,
    task_count,
)
from .scene import Scene
from .swarm import Swarm
from .trajectory import Trajectory


@dataclass
class State:
    """A copy of the simulation state (numpy, the simulator's precision).

    Attributes:
        frame: frames advanced since the start.
        position: centres [m], (N, 3).
        velocity: the velocity at the end of the state's frame [m/s], (N, 3), for both motion
            models (at frame 0 the swarm's own): a swarm built from this state moves on as the
            simulator does.
        angular_momentum: [kg m^2/s], (N, 3). orientation: (x, y, z, w), body -> world, (N, 4).
        energy: total energy ``1/2 m |v|^2 - m g . (p - origin)`` [J], (N,): the per-sphere
            invariant (see :attr:`Simulator.energy_origin`), constant but for the contact losses
            and the hops a support removes.
    """

    frame: int
    position: np.ndarray
    velocity: np.ndarray
    angular_momentum: np.ndarray
    orientation: np.ndarray
    energy: np.ndarray


@dataclass
class Stats:
    """Counters since the start of a simulation.

    Attributes:
        frames: frames advanced. sphere_frames: frames simulated, summed over the spheres (a
            sphere born at frame ``b`` counts those after ``b`` only).
        bounces: bounces taken, all spheres (contacts that reflect; resting contacts are in
            ``supports``).
        supports: resting or sliding contacts on a support, all spheres (a sphere at rest on
            a floor makes about one a frame).
        capped: sphere-frames stopped by ``max_bounces``.
        capped_spheres: spheres stopped by the cap at least once.
        seconds: wall time spent in :meth:`Simulator.step` and :meth:`Simulator.run` [s].
        broad_phase: the broad phase that ran (:attr:`Simulator.broad_phase`): a requested
            ``"grid"`` reads ``"brute"`` or ``"bvh"`` where no grid fits (float64 far from the
            origin, too many cells), ``"grid-bvh"`` where the grid falls back to the BVH; a
            requested ``"walk"`` likewise (``"walk-bvh"``).
        requested_broad_phase: the one asked for (``"auto"``, ``"brute"``, ``"bvh"``,
            ``"grid"``, ``"walk"``).
    """

    frames: int
    sphere_frames: int
    bounces: int
    capped: int
    capped_spheres: int
    seconds: float
    broad_phase: str = ""
    requested_broad_phase: str = ""
    supports: int = 0

    @property
    def contacts(self) -> int:
        """Contacts of every kind: ``bounces + supports``."""
        return self.bounces + self.supports

    @property
    def sphere_frames_per_second(self) -> float:
        return self.sphere_frames / self.seconds if self.seconds > 0 else float("nan")


#: A launch advances about this many sphere-frames (split over the workers): about half a second
#: on one CPU core, so that progress is reported and Ctrl-C is honoured promptly, while the
#: launch's cost per sphere (the state read and written once, the frame loop's set-up; about
#: 150 instructions a sphere since a CPU task advances a block of spheres, 380 before) stays
#: small: with 2**22 a million spheres took 4 frames a launch and 47 ns per sphere-frame, with
#: 2**24 16 frames and 36 ns (before the blocks).
LAUNCH_SPHERE_FRAMES = 1 << 24

#: The same on a GPU: about 0.2 s of the standard room's linear frames on an H200 (0.18 ns a
#: sphere-frame), 0.5 s of its ballistic ones. With the CPU's budget a launch of 1e7 spheres
#: held one frame, and every frame paid what a launch of many frames pays once: 0.28 ns a
#: sphere-frame at N = 1e7 and 1e8 against 0.17 at 1e6 (16 to 300 frames a launch).
GPU_LAUNCH_SPHERE_FRAMES = 1 << 30

#: Contact rows a run keeps by default (the earliest by frame, then sphere; about 0.1 GB on the
#: host): room for every contact of the bundled scenes' default runs; more are counted as
#: dropped, never lost silently. The device buffers hold what a launch can produce, at most this.
DEFAULT_EVENT_CAPACITY = 1 << 20

#: Shards smaller than this many spheres are not worth a thread of their own: below it the
#: launch and thread hand-off cost more than the shard's work at one frame per launch.
MIN_SHARD_SPHERES = 256


class Simulator:
    """Advances a swarm among a scene's static obstacles, many frames per kernel launch.

    Each frame, per sphere (linear model): the multi-bounce move along the chord of the
    free-flight parabola, ``(v + g dt / 2) dt`` (contacts reflect; friction spins;
    ``energy_retention`` losses), ending with the velocity ``v + g dt`` in free flight (``v``
    the velocity at the frame's start: the swarm's is the velocity at t = 0), the speed reset
    from the energy invariant (``scene.energy_correction``), and the orientation step from the
    rotation vector. The kernel is built for what the scene needs: no spin code when friction is
    0 and no sphere spins, no loss code when ``energy_retention = 1``, no reset when the
    correction is off. A launch advances each sphere through many frames with its state in
    registers (spheres never interact), writing the recorded frames straight from the kernel;
    the state stays on the device between launches. Results are bit-identical run after run on
    the same device, whatever the frames per launch and the number of workers.

    Args:
        scene: obstacles and physics settings.
        swarm: initial state of the spheres.
        dt: time step [s], > 0 (default: ``scene.dt``).
        max_bounces: contacts per sphere per frame, >= 1 (default: ``scene.max_bounces``).
        device: Warp device (None: Warp's default).
        precision: ``"float32"`` or ``"float64"`` kernels.
        broad_phase: how each sphere finds its candidate boxes (see
            :mod:`warpsim.broad_phase`): ``"brute"`` tries every box, ``"bvh"`` queries a BVH
            over the boxes' bounds, ``"grid"`` reads the list of a uniform grid's cell when the
            frame's path stays near that cell (else every box, or the BVH for many boxes),
            ``"walk"`` reads the lists of the grid cells each path crosses, in order, up to its
            first contact, ``"auto"`` picks by a measured cost model. Bit-identical results;
            :attr:`broad_phase` says which one runs.
        workers: on the CPU device, the swarm is split into this many contiguous shards, each
            launched from its own thread (Warp runs one CPU launch on one core and releases the
            GIL during it); None uses every core of the machine, 1 one core. Results are
            bit-identical whatever the number. On a CUDA device one launch covers the swarm.
            (``warpsim.distributed.run`` calls these ``threads``: its ``workers`` are Dask
            processes.)
        motion: ``"linear"`` (the chord of each frame) or ``"ballistic"`` (the exact parabola);
            None takes ``scene.motion``.
        energy_correction: reset each sphere's speed from its energy after each frame; None
            takes the scene's setting for the motion (``scene.energy_correction_for``: on for
            the linear model, off for the ballistic one, unless the scene says).
        free_flight: build the kernel with the free-flight step (frames beyond every box's
            bounds skip the broad phase; their energy reset runs once in
            ``FREE_RESET_EVERY`` frames, which changes their bits by rounding); None chooses
            it from the swarm (some sphere starts beyond those bounds). Give it for every part
            of a run simulated in parts, so that all parts run the same kernel.

    Attributes:
        broad_phase: the broad phase compiled into the kernel: ``"brute"``, ``"bvh"``,
            ``"grid"``, ``"grid-bvh"`` (a grid falling back to the BVH), ``"walk"`` or
            ``"walk-bvh"``.

    Raises:
        ValueError: a bad argument, naming it.
    """

    def __init__(self, scene: Scene, swarm: Swarm, dt: float | None = None,
                 max_bounces: int | None = None, device=None, precision: str = "float32",
                 broad_phase: str = "auto", workers: int | None = None,
                 motion: str | None = None, energy_correction: bool | None = None,
                 free_flight: bool | None = None):
        if not isinstance(scene, Scene):
            raise ValueError(f"scene must be a warpsim.Scene, got {type(scene).__name__}")
        if not isinstance(swarm, Swarm):
            raise ValueError(f"swarm must be a warpsim.Swarm, got {type(swarm).__name__}")
        self.scene = scene
        self.dt = check.scalar("dt", scene.dt if dt is None else dt, positive=True)
        self.max_bounces = check.bounce_cap(
            scene.max_bounces if max_bounces is None else max_bounces)
        self.precision = check.precision(precision)
        self.motion = check.motion(scene.motion if motion is None else motion)
        """``"linear"`` or ``"ballistic"``: the motion model compiled into the kernel."""
        self.energy_correction = (scene.energy_correction_for(self.motion)
                                  if energy_correction is None
                                  else check.flag("energy_correction", energy_correction))
        """Whether the speed is reset from the energy after each frame."""
        # everything a run needs, checked before anything is uploaded or compiled
        self.warnings = feasibility.check_run(scene, swarm, self.dt, self.precision,
                                        self.max_bounces)
        """Texts of the :class:`warpsim.PrecisionWarning` s this set-up raised."""
        if not swarm._known_clear_of(scene.boxes):  # an emitter's swarm was placed outside
            feasibility.check_outside(scene.boxes, swarm.position, swarm.radius,
                                      self.precision)
        frame = broad.paths(swarm.position, swarm.velocity, swarm.radius, scene.gravity, self.dt,
                            scene.boxes)
        dtype = fp.precision(self.precision).np_dtype
        self.requested_broad_phase = str(check.broad_phase(broad_phase))
        """The broad phase asked for; :attr:`broad_phase` is the one that runs."""
        self.broad_phase, self._grid = broad.choose(broad_phase, scene.boxes, frame, dtype)
        self.device = resolve_device(device)
        self.workers = _workers(workers, self.device, len(swarm))
        """Threads that launch the frame kernel, each on a contiguous shard of the swarm."""
        self.spin = bool(scene.friction > 0.0 or any_rows(
            len(swarm), lambda rows: swarm.angular_momentum[rows] != 0.0))
        self.energy_origin = _energy_origin(scene, swarm)
        self.frame = 0
        self._n = len(swarm)
        # the swarm's own arrays, read-only (a Swarm owns and freezes what it holds): shared,
        # not copied
        self.birth_frame = swarm.birth_frame
        """The frame each sphere is born at, (N,), int64, read-only (see
        :class:`warpsim.Swarm`)."""
        self._radius_host = swarm.radius
        self.mass = swarm.mass
        """Sphere masses [kg], (N,), float64, read-only."""
        self._seconds = 0.0
        # what the kernel is built for (the factory's cache key)
        self._features = Features(precision=self.precision, motion=self.motion,
                                  broad_phase=self.broad_phase, spin=self.spin,
                                  lossy=scene.energy_retention < 1.0,
                                  energy_correction=self.energy_correction,
                                  births=swarm.has_births,
                                  free_flight=(_starts_in_free_flight(scene.boxes, swarm)
                                               if free_flight is None
                                               else check.flag("free_flight", free_flight)),
                                  falls=bool(np.any(np.asarray(scene.gravity) != 0.0)))
        self._kernel = frame_kernel(self._features)
        self._per_task = spheres_per_task(self.device)
        """Spheres each task of the frame kernel advances, one after another."""
        self._upload(swarm)
        self._shards = _shards(self._n, self.workers)
        self._executor = None
        self._no_records = self._records(0, False)
        self._no_events = event_buffer(self._p, self.device, 0)
        self._step_launches = {}
        """Recorded launches of :meth:`step` (``wp.Launch``, one per shard), by the arrays of
        the two states they read and write: :func:`_state_key`."""
        names = parameter_names(self._kernel)
        self._step_params = (names.index("frame_count"), names.index("first_frame"))
        """The indices of the launch values :meth:`step` sets on its recorded launches."""

    # -- set-up -------------------------------------------------------------------------------

    def _upload(self, swarm: Swarm) -> None:
        p = fp.precision(self.precision)
        dev = self.device
        scene = self.scene
        # the energy of the state the device holds: positions and velocities rounded to the
        # kernels' precision first, so that E and Ep agree to rounding from the first frame
        energy = self._energy_of(swarm.position, swarm.velocity, rounded_to=p.np_dtype)
        self._p = p
        self.model = put_model(scene.boxes, p, dev, broad_phase=self.broad_phase,
                               grid=self._grid, dt=self.dt,
                               gravity=scene.gravity, origin=self.energy_origin,
                               friction=scene.friction,
                               max_angular_speed=scene.max_angular_speed,
                               energy_retention=scene.energy_retention,
                               max_bounces=self.max_bounces)
        """The scene on the device (:class:`warpsim.model.Model`)."""
        self.spheres = put_spheres(swarm.radius, swarm.mass, p, dev, swarm.birth_frame)
        """The per-sphere constants on the device (:class:`warpsim.model.Spheres`)."""
        self.state_0 = put_state(p, dev, position=swarm.position, velocity=swarm.velocity,
                                 energy=energy, angular_momentum=swarm.angular_momentum,
                                 orientation=swarm.orientation)
        """The current state on the device (:class:`warpsim.model.DeviceState`)."""
        # a kernel without spin code neither reads nor writes L and the orientation
        unwritten = () if self.spin else ("angular_momentum", "orientation")
        self.state_1 = self.state_0.empty_like(share=unwritten)
        """The state the next launch writes; swapped with :attr:`state_0` after it."""
        self.counters = {"bounce_count_out": wp.zeros(self._n, dtype=wp.int32, device=dev),
                         "support_count_out": wp.zeros(self._n, dtype=wp.int32, device=dev),
                         "capped_count_out": wp.zeros(self._n, dtype=wp.int32, device=dev)}
        """Per-sphere counters the kernel adds to (bounces, resting contacts, sphere-frames
        capped)."""
        self._initial_energy = energy

    def _arguments(self, kernel, rows: slice | None, values: dict, records: dict,
                   events) -> list:
        offset = 0 if rows is None else rows.start
        return kernel_arguments(kernel, model=self.model, spheres=self.spheres,
                                state_in=self.state_0, state_out=self.state_1,
                                outputs={**self.counters, **records},
                                launch_outputs={"events_out": events},
                                values={**values, "sphere_offset": offset,
                                        "spheres_per_task": self._per_task}, rows=rows)

    def _records(self, rows: int, motion: bool) -> dict:
        """Device arrays the kernel writes ``rows`` recorded frames into, (rows, N) each; the
        velocity pair has no rows unless ``motion``."""
        p, dev, n = self._p, self.device, self._n
        motion_rows = rows if motion else 0
        return {"record_position_out": wp.empty((rows, n), dtype=p.vec3, device=dev),
                "record_orientation_out": wp.empty((rows, n), dtype=p.quat, device=dev),
                "record_velocity_out": wp.empty((motion_rows, n), dtype=p.vec3, device=dev),
                "record_angular_velocity_out": wp.empty((motion_rows, n), dtype=p.vec3,
                                                        device=dev)}

    # -- stepping -----------------------------------------------------------------------------

    def build(self, events: bool = False, plain: bool = True) -> float:
        """Build (or load from Warp's cache) this simulator's kernels now; returns seconds.

        :meth:`step` and :meth:`run` do it on first use anyway; calling it first keeps the build
        time out of a timed run.

        Args:
            events: also build the variant that records contacts (what ``run(events=True)``
                launches).
            plain: build the kernel without the contact code (what :meth:`step` and
                :meth:`run` without events launch). ``build(events=True, plain=False)`` builds
                the variant with events alone, for a program whose every frame records its
                contacts: a first build then compiles one kernel, not two.

        Raises:
            ValueError: ``events`` and ``plain`` both false (nothing to build).
        """
        events = check.flag("events", events)
        plain = check.flag("plain", plain)
        if not (events or plain):
            raise ValueError("build: events and plain are both false, so there is nothing to "
                             "build")
        start = time.perf_counter()
        if plain:
            wp.load_module(self._kernel.module, device=self.device)
        if events:
            kernel = frame_kernel(self._features.but(events=True))
            wp.load_module(kernel.module, device=self.device)
        return time.perf_counter() - start

    def _launch(self, frames: int, every: int = 0, records: dict | None = None,
                events: list[dict] | None = None) -> None:
        """Advance ``frames`` frames in one launch per shard (all shards at once); with
        ``every > 0`` the kernel writes its recorded frames into ``records``; with ``events``
        (one event buffer per shard, :func:`warpsim.model.event_buffer`) it writes the contacts
        there, with a kernel variant that has the event code."""
        if records is None and events is None:
            self._run_launches(self._kernel, self._plain_launches(frames))
        else:
            if records is None:
                records = self._no_records
            kernel = (self._kernel if events is None
                      else frame_kernel(self._features.but(events=True)))
            values = {"frame_count": int(frames), "record_every": int(every),
                      "first_frame": int(self.frame)}
            shards = self._launch_rows()
            buffers = events if events is not None else [self._no_events] * len(shards)
            self._run_launches(kernel, [
                partial(wp.launch, kernel, dim=self._task_count(rows), device=self.device,
                        inputs=self._arguments(kernel, rows, values, records, buffer))
                for rows, buffer in zip(shards, buffers, strict=True)])
        self.state_0, self.state_1 = self.state_1, self.state_0
        self.frame += frames

    def _plain_launches(self, frames: int) -> list:
        """The launches (one per shard) of ``frames`` frames without records or events from the
        current states: recorded launches (``wp.Launch``) whose arguments are packed once per
        pair of states (a step's host time was mostly that packing: 70 microseconds a
        ``step(1)`` here), only the frame count and first frame set each time. A state or
        state array replaced since is a new key, so a launch never reads an array the
        simulator no longer holds."""
        key = _state_key(self.state_0, self.state_1)
        launches = self._step_launches.get(key)
        if launches is None:
            if len(self._step_launches) >= 2:  # the two parities of the current states only
                self._step_launches.clear()
            values = {"frame_count": 0, "record_every": 0, "first_frame": 0}
            launches = [wp.launch(self._kernel, dim=self._task_count(rows), device=self.device,
                                  inputs=self._arguments(self._kernel, rows, values,
                                                         self._no_records, self._no_events),
                                  record_cmd=True)
                        for rows in self._launch_rows()]
            self._step_launches[key] = launches
        count, first = self._step_params
        for launch in launches:
            launch.set_param_at_index(count, int(frames))
            launch.set_param_at_index(first, int(self.frame))
        return [launch.launch for launch in launches]

    def _launch_rows(self) -> list:
        """The spheres of each launch: ``[None]`` (the whole swarm) or a slice per shard."""
        return self._shards if len(self._shards) > 1 else [None]

    def _rows_count(self, rows: slice | None) -> int:
        return self._n if rows is None else rows.stop - rows.start

    def _task_count(self, rows: slice | None) -> int:
        """The frame kernel's launch size for ``rows``: one task a block of
        ``_per_task`` spheres."""
        return task_count(self._rows_count(rows), self._per_task)

    def _run_launches(self, kernel, calls: list) -> None:
        """Make the calls that launch ``kernel`` on each shard, all shards at once on the
        pool's threads."""
        if len(calls) == 1:
            calls[0]()
            return
        # built (or loaded) here first: every thread's launch would otherwise build the same
        # module at once on its first use, each on a core of its own
        wp.load_module(kernel.module, device=self.device)
        pool = self._pool()
        for future in [pool.submit(call) for call in calls]:
            future.result()

    def _pool(self) -> ThreadPoolExecutor:
        if self._executor is None:
            self._executor = ThreadPoolExecutor(max_workers=len(self._shards),
                                                thread_name_prefix="warpsim-shard")
        return self._executor

    def _frames_per_launch(self, every: int = 1, records: bool = False) -> int:
        """Frames of one launch: about ``LAUNCH_SPHERE_FRAMES`` sphere-frames on a CPU,
        ``GPU_LAUNCH_SPHERE_FRAMES`` on a GPU, so that a long run still reports progress and
        stops promptly on Ctrl-C; a multiple of ``every``. A launch that records frames
        (``records``) keeps the CPU's budget on every device: its record buffers on the device
        and their copy on the host are sized by it (``footprint.run_bytes``)."""
        gpu = not (records or self.device.is_cpu)
        budget = GPU_LAUNCH_SPHERE_FRAMES if gpu else LAUNCH_SPHERE_FRAMES
        per_launch = max(1, budget // max(self._n, 1))
        return max(every, per_launch // every * every)

    def step(self, frames: int = 1) -> None:
        """Advance ``frames`` frames on the device (no copy to the host)."""
        frames = check.positive_int("frames", frames)
        start = time.perf_counter()
        done = 0
        chunk = self._frames_per_launch()
        while done < frames:
            todo = min(chunk, frames - done)
            self._launch(todo)
            done += todo
        wp.synchronize_device(self.device)
        self._seconds += time.perf_counter() - start

    def run(self, frames: int, every: int = 1, progress: bool = False,
            velocities: bool = False, events: bool = False,
            event_capacity: int = DEFAULT_EVENT_CAPACITY, spheres=None,
            allocate=None) -> Trajectory:
        """Advance ``frames`` frames, recording the current state and every ``every``-th frame.

        The kernel writes the recorded frames itself; one launch covers many of them.

        Args:
            frames: frames to advance, >= 1.
            every: record one frame in ``every``, >= 1 (the last frame is always recorded).
            progress: draw a progress bar (tqdm) on standard error.
            velocities: also record each sphere's true velocity [m/s] and angular velocity
                [rad/s] at the recorded frames (``Trajectory.velocity`` and
                ``angular_velocity``).
            events: also record every contact (``Trajectory.events``, a
                :class:`warpsim.ContactEvents`), written by the kernel into a bounded
                buffer per shard and copied out after each launch. The results are the same
                bits with or without.
            event_capacity: most contact rows the run keeps: the earliest ``event_capacity``
                by frame, then sphere (a sphere's contacts in a frame in their order), the
                same rows whatever the workers and launches; the others are counted in
                ``ContactEvents.dropped``, never lost silently.
            spheres: indices of the spheres whose frames are kept (distinct, any order), or
                None for all: the trajectory then holds only those (its ``sphere_ids``), so
                a run that writes a few spheres of a large swarm keeps a few in memory. Every
                sphere is still simulated; events and stats cover them all.
            allocate: makes each recorded array (``position``, ``orientation``, and with
                ``velocities`` ``velocity`` and ``angular_velocity``): ``allocate(shape,
                dtype)`` returns a writable array of that shape and type, which the run fills
                and the trajectory holds (None: ``numpy.empty``). For arrays in memory another
                process reads without a copy, as the command's USD writer does
                (:mod:`warpsim.export.usd_process`).

        Returns:
            :class:`Trajectory` with the frame numbers since the start of the simulation.

        Raises:
            ValueError: a bad argument, or ``allocate`` returning anything but a writable
                array of the shape and type asked for (the message names the array).
        """
        frames = check.positive_int("frames", frames)
        every = check.positive_int("every", every)
        velocities = check.flag("velocities", velocities)
        events = check.flag("events", events)
        if events:
            event_capacity = check.positive_int("event_capacity", event_capacity)
        keep = (None if spheres is None
                else np.asarray(check.index_list("spheres", spheres, self._n), dtype=np.int64))
        gathered = []
        dropped = 0
        stops = list(range(every, frames + 1, every))
        if not stops or stops[-1] != frames:
            stops.append(frames)
        n, count = (self._n if keep is None else keep.size), len(stops) + 1
        pick = (lambda a: a) if keep is None else (lambda a: a[..., keep, :])
        first = self.frame
        empty = _allocator(allocate, self._p.np_dtype)
        position = empty("position", (count, n, 3))
        orientation = empty("orientation", (count, n, 4))
        velocity = empty("velocity", (count, n, 3)) if velocities else None
        angular = empty("angular_velocity", (count, n, 3)) if velocities else None
        position[0] = pick(self.state_0.position.numpy())
        orientation[0] = pick(self.state_0.orientation.numpy())
        if velocities:
            velocity[0], angular[0] = (pick(a) for a in self._motion_now())
        bar = _progress_bar(frames, progress)
        start = time.perf_counter()
        row = 1
        try:
            per_launch = self._frames_per_launch(every, records=True)
            done = 0
            kept = 0  # contact rows kept so far (the run's first ones: none lost before)
            while done < frames:
                todo = min(per_launch, frames - done)
                if events:
                    todo, records, parts, lost = self._launch_recording_events(
                        todo, every, velocities, max(event_capacity - kept, 0))
                    gathered.extend(parts)
                    kept += sum(len(part["frame"]) for part in parts)
                    dropped += lost
                else:
                    records = self._records(-(-todo // every), velocities)
                    self._launch(todo, every, records)
                rows = -(-todo // every)  # every full interval, and a last partial one
                done += todo
                position[row:row + rows] = pick(_host(records["record_position_out"]))
                orientation[row:row + rows] = pick(_host(records["record_orientation_out"]))
                if velocities:
                    velocity[row:row + rows] = pick(_host(records["record_velocity_out"]))
                    angular[row:row + rows] = pick(_host(records["record_angular_velocity_out"]))
                row += rows
                bar.update(todo)
        finally:
            bar.close()
            self._seconds += time.perf_counter() - start
        frame_numbers = np.array([first] + [first + k for k in stops], dtype=np.int64)
        births = None
        if self._features.births:
            births = (self.birth_frame if keep is None else self.birth_frame[keep]).copy()
            unborn = frame_numbers[:, None] < births[None, :]
            for values in (position, orientation, velocity, angular):
                if values is not None:
                    values[unborn] = np.nan
        return Trajectory(frame=frame_numbers,
                          dt=self.dt, position=position, orientation=orientation,
                          radius=(self._radius_host if keep is None
                                  else self._radius_host[keep]).copy(),
                          velocity=velocity, sphere_ids=None if keep is None else keep.copy(),
                          angular_velocity=angular, birth_frame=births,
                          events=(_contact_events(gathered, dropped, self.dt, self.settings(),
                                                  event_capacity) if events else None))

    def _launch_recording_events(self, todo: int, every: int, velocities: bool, room: int,
                                 ) -> tuple[int, dict, list[dict], int]:
        """One launch of up to ``todo`` frames that records contacts, keeping every one while
        ``room`` rows are left, so that the rows a run keeps are its earliest whatever the
        shards and launches: a shard's buffer holds what its launch can produce, at most
        ``room`` rows; when one overflows (the kernel still counts every contact), the launch
        is undone (the state it read is intact, the counters restored) and run again with
        buffers of the exact counts, or over half the frames when those would hold more than
        twice ``room`` rows. With no room left the buffers have no rows and count only.

        Returns:
            ``(frames advanced, records, event columns per shard, contacts not kept)``.
        """
        shards = self._shards if len(self._shards) > 1 else [slice(0, self._n)]
        exact = None
        saved = ({k: wp.clone(v) for k, v in self.counters.items()} if room > 0 else None)
        while True:
            records = self._records(-(-todo // every), velocities)
            if exact is not None:
                sizes = exact
            elif room > 0:
                sizes = [min(room, (r.stop - r.start) * todo * self.max_bounces) for r in shards]
            else:
                sizes = [0] * len(shards)
            buffers = [event_buffer(self._p, self.device, size) for size in sizes]
            base = self.frame
            self._launch(todo, every, records, buffers)
            counts = [int(b.count.numpy()[0]) for b in buffers]
            if room == 0 or all(c <= size for c, size in zip(counts, sizes, strict=True)):
                break
            # overflow: undo the launch (the kernel never writes the state it reads)
            self.state_0, self.state_1 = self.state_1, self.state_0
            self.frame -= todo
            for name, array in self.counters.items():
                wp.copy(array, saved[name])
            if sum(counts) <= 2 * room or todo <= every:
                exact = counts
            else:
                todo = max(every, todo // 2 // every * every)
        parts, lost = [], 0
        for buffer in buffers:
            columns, missed = _read_events(buffer, base)
            parts.append(columns)
            lost += missed
        return todo, records, parts, lost

    def settings(self) -> dict[str, str]:
        """The run's settings as text (what an events file stores with its rows): ``scene``,
        ``dt`` [s], ``precision``, ``motion``, ``max_bounces``, ``broad_phase``,
        ``energy_correction``."""
        return {"scene": self.scene.name, "dt": repr(float(self.dt)),
                "precision": self.precision, "motion": str(self.motion),
                "max_bounces": str(self.max_bounces), "broad_phase": str(self.broad_phase),
                "energy_correction": str(bool(self.energy_correction)).lower()}

    def _motion_now(self) -> tuple[np.ndarray, np.ndarray]:
        """Velocity [m/s] and world angular velocity [rad/s] of the current state."""
        s = self.state()
        inertia = 0.4 * self.mass * self._radius_host ** 2
        rot = np.zeros_like(s.angular_momentum)
        if self.spin:
            ok = inertia > 0.0
            rot[ok] = s.angular_momentum[ok] / inertia[ok, None]
            size = np.linalg.norm(rot, axis=1)
            limit = self.scene.max_angular_speed
            over = size > limit
            rot[over] *= (limit / size[over])[:, None]
        return s.velocity, rot.astype(s.angular_momentum.dtype)

    def set_state(self, state: State) -> None:
        """Continue from ``state`` (one of :meth:`state`'s, of this simulator or of one built
        alike): the run then goes on bit for bit as if it had never stopped.

        A new simulator built from a :class:`Swarm` of the state's position and velocity moves
        on the same way but for the energy invariant, which it computes again from the state
        (equal to the carried one to rounding, less what losses and supports removed); this
        method carries it, with the frame count.

        Raises:
            ValueError: a field of the wrong shape or not finite, naming it.
        """
        if not isinstance(state, State):
            raise ValueError(f"state must be a warpsim.State, got {type(state).__name__}")
        n = self._n
        values = {"position": check.vec3_array("state.position", state.position, n),
                  "velocity": check.vec3_array("state.velocity", state.velocity, n),
                  "energy": check.per_item("state.energy", state.energy, n),
                  "angular_momentum": check.vec3_array("state.angular_momentum",
                                                       state.angular_momentum, n),
                  # checked, but uploaded as given: normalising again would move its last bits
                  "orientation": np.asarray(state.orientation, dtype=np.float64)}
        check.unit_quat_array("state.orientation", state.orientation, n)
        frame = check.positive_int("state.frame", state.frame, minimum=0)
        self._step_launches.clear()  # they hold the states replaced here
        self.state_0 = put_state(self._p, self.device, **values)
        unwritten = () if self.spin else ("angular_momentum", "orientation")
        self.state_1 = self.state_0.empty_like(share=unwritten)
        self.frame = frame

    # -- read-out -----------------------------------------------------------------------------

    def state(self) -> State:
        """A numpy copy of the current state."""
        s = self.state_0
        return State(frame=self.frame,
                     position=s.position.numpy().copy(),
                     velocity=s.velocity.numpy().copy(),
                     angular_momentum=s.angular_momentum.numpy().copy(),
                     orientation=s.orientation.numpy().copy(),
                     energy=s.energy.numpy().copy())

    @property
    def initial_energy(self) -> np.ndarray:
        """Per-sphere total energy at the start [J], (N,), float64 (see :class:`State`); the
        device holds it rounded to the kernels' precision."""
        return self._initial_energy.copy()

    def mechanical_energy(self, state: State | None = None) -> np.ndarray:
        """Total energy of a state [J], (N,), computed in float64 from its position and velocity.

        ``1/2 m |v|^2 - m g . (p - origin)`` (see :class:`State`); compare with
        :attr:`initial_energy`.
        """
        s = self.state() if state is None else state
        return self._energy_of(s.position.astype(np.float64), s.velocity.astype(np.float64))

    def _energy_of(self, position: np.ndarray, velocity: np.ndarray,
                   rounded_to: np.dtype | None = None) -> np.ndarray:
        """``1/2 m |v|^2 - m g . (p - origin)`` [J] per sphere, float64, of ``position`` and
        ``velocity`` (N, 3) rounded to ``rounded_to`` first when given; in blocks of rows on
        every core (each row's value is its own)."""
        g = np.asarray(self.scene.gravity, dtype=np.float64)
        energy = np.empty(position.shape[0])

        def block(rows: slice) -> None:
            p, v, m = position[rows], velocity[rows], self.mass[rows]
            if rounded_to is not None:
                p = p.astype(rounded_to).astype(np.float64)
                v = v.astype(rounded_to).astype(np.float64)
            energy[rows] = (0.5 * m * np.einsum("ij,ij->i", v, v)
                            - m * ((p - self.energy_origin) @ g))

        for_row_blocks(position.shape[0], block)
        return energy

    @property
    def stats(self) -> Stats:
        """Bounce, support and cap counters since the start, and the time spent stepping."""
        capped = self.counters["capped_count_out"].numpy()
        bounces = self.counters["bounce_count_out"].numpy()
        supports = self.counters["support_count_out"].numpy()
        lived = np.clip(self.frame - self.birth_frame, 0, None)
        return Stats(frames=self.frame, sphere_frames=int(lived.sum()),
                     bounces=int(bounces.astype(np.int64).sum()),
                     supports=int(supports.astype(np.int64).sum()),
                     capped=int(capped.astype(np.int64).sum()),
                     capped_spheres=int(np.count_nonzero(capped)), seconds=self._seconds,
                     broad_phase=self.broad_phase,
                     requested_broad_phase=self.requested_broad_phase)

    def __len__(self) -> int:
        return self._n


def _energy_origin(scene: Scene, swarm: Swarm) -> np.ndarray:
    """Reference point of the potential energy: the middle of the obstacles' centres (or of the
    swarm when there are none), so energies keep their digits in float32 far from the origin."""
    pts = scene.boxes.center if len(scene.boxes) else swarm.position
    if len(pts) == 0:
        return np.zeros(3)
    return 0.5 * (pts.min(axis=0) + pts.max(axis=0))


def _starts_in_free_flight(boxes, swarm: Swarm) -> bool:
    """Whether some sphere starts beyond the box holding every obstacle's reject bounds (the
    device model's ``Boxes.lower`` / ``upper``): then the kernel is built with the free-flight
    step (the same moves; its runs of free frames reset the energy once in
    ``FREE_RESET_EVERY`` frames instead of every frame, which changes their bits by rounding).
    Spheres that start inside it, as in a closed room, stay near the boxes, and the step's test
    would only cost them time. The choice depends on the swarm, so two parts of one swarm
    simulated apart could choose differently and differ by rounding: a run split into parts
    passes ``Simulator(free_flight=...)`` chosen for the whole run (the sharded runs and the
    command line take ``distributed.draw.may_start_free`` of the scene's emitter)."""
    if len(swarm) == 0 or len(boxes) == 0:
        return False

    def block(rows: slice) -> tuple[np.ndarray, np.ndarray]:
        """Per axis, the highest of the block's spheres' lowest points and the lowest of their
        highest points [m]."""
        r = swarm.radius[rows, None]
        return ((swarm.position[rows] - r).max(axis=0),
                (swarm.position[rows] + r).min(axis=0))

    lowest_top, highest_bottom = (np.array(v) for v in zip(*map_row_blocks(len(swarm), block),
                                                            strict=True))
    return reaches_beyond_bounds(boxes, lowest_top.max(axis=0), highest_bottom.min(axis=0))


def reaches_beyond_bounds(boxes, low_end, high_end) -> bool:
    """Whether some sphere lies wholly beyond the box holding every obstacle's reject bounds
    on some axis: its lowest point ``low_end`` [m] above that box, or its highest point
    ``high_end`` [m] below it (arrays of shape (..., 3)); False without obstacles."""
    if len(boxes) == 0:
        return False
    lower, upper = bvh_bounds(boxes.center, boxes.world_extent())
    return bool(np.any(np.asarray(low_end) > upper.max(axis=0))
                or np.any(np.asarray(high_end) < lower.min(axis=0)))


def _host(array: wp.array) -> np.ndarray:
    """A device array's values on the host: a view on the CPU device; from a GPU through a
    pinned (page-locked) host buffer, which copies at full bus speed."""
    if array.device.is_cpu:
        return array.numpy()
    pinned = wp.empty(array.shape, dtype=array.dtype, device="cpu", pinned=True)
    wp.copy(pinned, array)
    wp.synchronize_device(array.device)
    return pinned.numpy()


def _read_events(buffer, frame_base: int) -> tuple[dict, int]:
    """The rows one launch wrote into an event buffer (:func:`warpsim.model.event_buffer`), as
    float64/int64 numpy columns (frames made absolute), and the number of contacts the buffer
    had no room for."""
    count = int(buffer.count.numpy()[0])
    capacity = buffer.index.shape[0]
    rows = min(count, capacity)
    index = buffer.index.numpy()[:rows].astype(np.int64)
    vector = buffer.vector.numpy()[:rows].astype(np.float64)
    scalar = buffer.value.numpy()[:rows].astype(np.float64)
    columns = {"frame": index[:, 0] + frame_base, "sphere": index[:, 1], "box": index[:, 2],
               "kind": index[:, 3], "position": vector[:, 0], "normal": vector[:, 1],
               "fraction": scalar[:, 0], "normal_speed": scalar[:, 1]}
    return columns, count - rows


def _contact_events(parts: list[dict], dropped: int, dt: float, settings: dict,
                    capacity: int):
    """One :class:`warpsim.ContactEvents` from the launches' rows, ordered by frame, then
    sphere, then the order the contacts happened in (a stable sort keeps it: one thread writes a
    sphere's contacts in sequence); the first ``capacity`` rows of that order are kept, the
    others added to ``dropped``."""
    from .events import ContactEvents
    from .vocabulary import ContactKind

    if not parts:
        empty = ContactEvents.empty(dropped=dropped)
        empty.settings = dict(settings)
        return empty
    merged = {key: np.concatenate([part[key] for part in parts]) for key in parts[0]}
    order = np.lexsort((merged["sphere"], merged["frame"]))
    dropped += max(0, order.size - capacity)
    order = order[:capacity]
    merged = {key: value[order] for key, value in merged.items()}
    merged["box"] = merged["box"].astype(np.int32)
    merged["fraction"] = np.clip(merged["fraction"], 0.0, 1.0)
    # a bounce moves into the surface: a speed rounding made negative (a resting contact's
    # few nm/s) is zero; a support's speed keeps its sign (it may slide onto the surface)
    bounce = merged["kind"] == ContactKind.BOUNCE
    merged["normal_speed"] = np.where(bounce, np.maximum(merged["normal_speed"], 0.0),
                                      merged["normal_speed"])
    return ContactEvents.of_frames(dt, dropped=dropped, settings=settings, **merged)


def _state_key(state_0, state_1) -> tuple:
    """The identities of the arrays of two device states (a recorded launch's key)."""
    return tuple(id(getattr(state, f.name)) for state in (state_0, state_1)
                 for f in fields(state))


def _workers(workers, device, n: int) -> int:
    """The number of CPU threads to launch from (1 on a CUDA device).

    An explicit number is kept (at most one sphere per shard); None takes every core the
    process may use, but no shard below ``MIN_SHARD_SPHERES`` spheres.
    """
    if workers is not None:
        workers = check.positive_int("workers", workers)
    if not device.is_cpu:
        return 1
    if workers is not None:
        return max(1, min(workers, n))
    return max(1, min(host_cores(), n // MIN_SHARD_SPHERES))


def _shards(n: int, workers: int) -> list[slice]:
    """``workers`` contiguous, nearly equal slices of ``range(n)``."""
    bounds = np.linspace(0, n, workers + 1).round().astype(int)
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True) if b > a]


def _allocator(allocate, dtype):
    """``empty(name, shape)``: the recorded array ``name`` from ``allocate(shape, dtype)``
    (``numpy.empty`` when None), checked to be a writable array of that shape and type."""
    if allocate is None:
        return lambda _name, shape: np.empty(shape, dtype=dtype)
    if not callable(allocate):
        raise ValueError(f"allocate must be a function (shape, dtype) -> array or None, got "
                         f"{type(allocate).__name__}")

    def empty(name, shape):
        out = allocate(shape, np.dtype(dtype))
        if (not isinstance(out, np.ndarray) or out.shape != tuple(shape)
                or out.dtype != dtype or not out.flags.writeable):
            got = (f"a {'read-only ' if not out.flags.writeable else ''}{out.dtype} array of "
                   f"shape {out.shape}" if isinstance(out, np.ndarray)
                   else type(out).__name__)
            raise ValueError(f"allocate returned {got} for {name}, expected a writable "
                             f"{np.dtype(dtype)} array of shape {tuple(shape)}")
        return out

    return empty


def _progress_bar(frames: int, enabled: bool):
    """A tqdm bar over frames on standard error (a no-op object when disabled)."""
    if not enabled:
        return _NoBar()
    from tqdm.auto import tqdm

    return tqdm(total=frames, unit="frame", file=sys.stderr, dynamic_ncols=True,
                mininterval=0.1)


class _NoBar:
    def update(self, _n: int) -> None:
        pass

    def close(self) -> None:
        pass
