"""The simulator: a swarm advanced frame by frame among a scene's obstacles, state on the device."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass

import numpy as np
import warp as wp

from . import validation as check
from .device import resolve_device, use_bvh
from .kernels import precision as fp
from .kernels.frame_kernel import frame_kernel
from .model import DeviceState, kernel_arguments, put_model, put_spheres, put_state
from .scene import Scene
from .swarm import Swarm
from .trajectory import Trajectory


@dataclass
class State:
    """A copy of the simulation state (numpy, the simulator's precision).

    Attributes:
        frame: frames advanced since the start.
        position: centres [m], (N, 3).
        velocity: semi-implicit Euler's step velocity [m/s], (N, 3): the one the last frame
            moved with (its mean velocity), and the one the next frame's gravity kick adds to.
            The velocity at the frame's end is ``velocity + g dt / 2``.
        angular_momentum: [kg m^2/s], (N, 3). orientation: (x, y, z, w), body -> world, (N, 4).
        energy: total energy ``1/2 m |v + g dt/2|^2 - m g . (p - origin)`` [J], (N,), the
            per-sphere invariant the speed is reset from (see :attr:`Simulator.energy_origin`);
            constant but for the contact losses.
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
        frames: frames advanced. sphere_frames: frames times spheres.
        bounces: contacts taken, all spheres (resting contacts on a support included).
        capped: sphere-frames stopped by ``max_bounces``.
        capped_spheres: spheres stopped by the cap at least once.
        seconds: wall time spent in :meth:`Simulator.step` and :meth:`Simulator.run` [s].
    """

    frames: int
    sphere_frames: int
    bounces: int
    capped: int
    capped_spheres: int
    seconds: float

    @property
    def sphere_frames_per_second(self) -> float:
        return self.sphere_frames / self.seconds if self.seconds > 0 else float("nan")


class Simulator:
    """Advances a swarm among a scene's static obstacles, one kernel launch per frame.

    Each frame, per sphere: ``v += g dt`` (semi-implicit Euler), the multi-bounce move of
    ``v dt`` (contacts reflect; friction spins; ``energy_retention`` losses), the speed reset
    from the energy invariant (``scene.energy_correction``), and the orientation step from the
    rotation vector. The kernel is built for what the scene needs: no spin code when friction is
    0 and no sphere spins, no loss code when ``energy_retention = 1``, no reset when the
    correction is off. State stays on the device between frames; :meth:`run` copies out only the
    frames it records. Results are bit-identical run after run on the same device.

    Args:
        scene: obstacles and physics settings.
        swarm: initial state of the spheres.
        dt: time step [s], > 0 (default: ``scene.dt``).
        max_bounces: contacts per sphere per frame, >= 1 (default: ``scene.max_bounces``).
        device: Warp device (None: Warp's default).
        precision: ``"float32"`` or ``"float64"`` kernels.
        broad_phase: how each sphere finds its candidate boxes: ``"brute"`` tries every box,
            ``"bvh"`` queries a BVH over the boxes' bounds (built once, here), ``"auto"`` takes
            the BVH from ``warpsim.device.BVH_MIN_BOXES`` boxes on. Bit-identical results;
            :attr:`broad_phase` says which one runs.

    Attributes:
        broad_phase: ``"bvh"`` or ``"brute"``, the broad phase compiled into the kernel.

    Raises:
        ValueError: a bad argument, naming it.
    """

    def __init__(self, scene: Scene, swarm: Swarm, dt: float | None = None,
                 max_bounces: int | None = None, device=None, precision: str = "float32",
                 broad_phase: str = "auto"):
        if not isinstance(scene, Scene):
            raise ValueError(f"scene must be a warpsim.Scene, got {type(scene).__name__}")
        if not isinstance(swarm, Swarm):
            raise ValueError(f"swarm must be a warpsim.Swarm, got {type(swarm).__name__}")
        self.scene = scene
        self.dt = check.scalar("dt", scene.dt if dt is None else dt, positive=True)
        self.max_bounces = check.positive_int(
            "max_bounces", scene.max_bounces if max_bounces is None else max_bounces)
        self.precision = check.precision(precision)
        self.broad_phase = "bvh" if use_bvh(broad_phase, len(scene.boxes)) else "brute"
        self.device = resolve_device(device)
        self.spin = bool(scene.friction > 0.0 or np.any(swarm.angular_momentum != 0.0))
        self.energy_origin = _energy_origin(scene, swarm)
        self.frame = 0
        self._n = len(swarm)
        self._radius_host = swarm.radius.copy()
        self.mass = swarm.mass.copy()
        """Sphere masses [kg], (N,), float64."""
        self._seconds = 0.0
        self._kernel = frame_kernel(self.precision, self.max_bounces, self.spin,
                                    scene.energy_correction, scene.energy_retention < 1.0,
                                    self.broad_phase == "bvh")
        self._upload(swarm)

    # -- set-up -------------------------------------------------------------------------------

    def _upload(self, swarm: Swarm) -> None:
        p = fp.precision(self.precision)
        dev = self.device
        scene = self.scene
        # the energy of the state the device holds: positions and velocities rounded to the
        # kernels' precision first, so that E and Ep agree to rounding from the first frame
        energy = self._energy_of(swarm.position.astype(p.np_dtype).astype(np.float64),
                                 swarm.velocity.astype(p.np_dtype).astype(np.float64))
        self._p = p
        self.model = put_model(scene.boxes, p, dev, bvh=self.broad_phase == "bvh", dt=self.dt,
                               gravity=scene.gravity, origin=self.energy_origin,
                               friction=scene.friction,
                               max_angular_speed=scene.max_angular_speed,
                               energy_retention=scene.energy_retention)
        """The scene on the device (:class:`warpsim.model.Model`)."""
        self.spheres = put_spheres(swarm.radius, swarm.mass, p, dev)
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
                         "capped_count_out": wp.zeros(self._n, dtype=wp.int32, device=dev)}
        """Per-sphere counters the kernel adds to (contacts taken, sphere-frames capped)."""
        self._initial_energy = energy
        # the two argument lists (state_0 -> state_1 and back), built once by name
        self._launch_args = [self._arguments(self.state_0, self.state_1),
                             self._arguments(self.state_1, self.state_0)]

    def _arguments(self, state_in: DeviceState, state_out: DeviceState) -> list:
        return kernel_arguments(self._kernel, model=self.model, spheres=self.spheres,
                                state_in=state_in, state_out=state_out, outputs=self.counters)

    # -- stepping -----------------------------------------------------------------------------

    def build(self) -> float:
        """Build (or load from Warp's cache) this simulator's kernel now; returns seconds.

        :meth:`step` does it on first use anyway; calling it first keeps the build time out of
        a timed run.
        """
        start = time.perf_counter()
        wp.load_module(self._kernel.module, device=self.device)
        return time.perf_counter() - start

    def _launch(self) -> None:
        wp.launch(self._kernel, dim=self._n, device=self.device, inputs=self._launch_args[0])
        self.state_0, self.state_1 = self.state_1, self.state_0
        self._launch_args.reverse()
        self.frame += 1

    def step(self, frames: int = 1) -> None:
        """Advance ``frames`` frames on the device (no copy to the host)."""
        frames = check.positive_int("frames", frames)
        start = time.perf_counter()
        for _ in range(frames):
            self._launch()
        wp.synchronize_device(self.device)
        self._seconds += time.perf_counter() - start

    def run(self, frames: int, every: int = 1, progress: bool = False) -> Trajectory:
        """Advance ``frames`` frames, recording the current state and every ``every``-th frame.

        Args:
            frames: frames to advance, >= 1.
            every: record one frame in ``every``, >= 1 (the last frame is always recorded).
            progress: draw a progress bar on standard error.

        Returns:
            :class:`Trajectory` with the frame numbers since the start of the simulation.
        """
        frames = check.positive_int("frames", frames)
        every = check.positive_int("every", every)
        stops = sorted(set(range(every, frames + 1, every)) | {frames})
        records = [self._record()]
        bar = _ProgressBar(frames) if progress else None
        done = 0
        for stop in stops:
            self.step(stop - done)
            done = stop
            records.append(self._record())
            if bar:
                bar.update(done)
        if bar:
            bar.close()
        return Trajectory(frame=np.array([r[0] for r in records], dtype=np.int64), dt=self.dt,
                          position=np.stack([r[1] for r in records]),
                          orientation=np.stack([r[2] for r in records]),
                          radius=self._radius_host.copy())

    def _record(self):
        return (self.frame, self.state_0.position.numpy().copy(),
                self.state_0.orientation.numpy().copy())

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

        ``1/2 m |u|^2 - m g . (p - origin)`` with ``u = v + g dt / 2``, the velocity at the
        frame's end (see :class:`State`); compare with :attr:`initial_energy`.
        """
        s = self.state() if state is None else state
        return self._energy_of(s.position.astype(np.float64), s.velocity.astype(np.float64))

    def _energy_of(self, position: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        g = self.scene.gravity
        u = velocity + 0.5 * self.dt * g
        return (0.5 * self.mass * np.einsum("ij,ij->i", u, u)
                - self.mass * ((position - self.energy_origin) @ g))

    @property
    def stats(self) -> Stats:
        """Bounce and cap counters since the start, and the time spent stepping."""
        capped = self.counters["capped_count_out"].numpy()
        bounces = self.counters["bounce_count_out"].numpy()
        return Stats(frames=self.frame, sphere_frames=self.frame * self._n,
                     bounces=int(bounces.astype(np.int64).sum()),
                     capped=int(capped.astype(np.int64).sum()),
                     capped_spheres=int(np.count_nonzero(capped)), seconds=self._seconds)

    def __len__(self) -> int:
        return self._n


def _energy_origin(scene: Scene, swarm: Swarm) -> np.ndarray:
    """Reference point of the potential energy: the middle of the obstacles' centres (or of the
    swarm when there are none), so energies keep their digits in float32 far from the origin."""
    pts = scene.boxes.center if len(scene.boxes) else swarm.position
    if len(pts) == 0:
        return np.zeros(3)
    return 0.5 * (pts.min(axis=0) + pts.max(axis=0))


class _ProgressBar:
    """A one-line text progress bar on standard error."""

    #: Seconds between redraws: a bar drawn every frame would cost more than small frames.
    REDRAW_S = 0.1

    def __init__(self, total: int, width: int = 30):
        self.total = total
        self.width = width
        self.start = time.perf_counter()
        self.drawn = -1.0

    def update(self, done: int) -> None:
        now = time.perf_counter()
        if done < self.total and now - self.drawn < self.REDRAW_S:
            return
        self.drawn = now
        filled = int(self.width * done / self.total)
        elapsed = time.perf_counter() - self.start
        rate = done / elapsed if elapsed > 0 else 0.0
        sys.stderr.write(f"\r[{'#' * filled}{'.' * (self.width - filled)}] "
                         f"{done}/{self.total} frames  {rate:,.0f} frames/s")
        sys.stderr.flush()

    def close(self) -> None:
        sys.stderr.write("\n")
        sys.stderr.flush()
