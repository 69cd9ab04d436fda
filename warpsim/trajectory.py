"""Recorded frames of a simulation, as numpy arrays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(repr=False)
class Trajectory:
    """Frames recorded by :meth:`warpsim.Simulator.run` (or read back from USD).

    Attributes:
        frame: simulation frame index of each record, shape (F,), int64. Frame 0 is the initial
            state; frame ``k`` is the state after ``k`` steps of ``dt``.
        dt: simulation time step [s]; the frame rate is ``1 / dt``.
        position: sphere centres [m], shape (F, N, 3).
        orientation: unit quaternions (x, y, z, w), body -> world, shape (F, N, 4).
        radius: sphere radii [m], shape (N,).
        velocity: the true velocity of each sphere at each recorded frame [m/s], shape (F, N, 3)
            (after any bounce in that frame, not a difference of positions), or None when not
            recorded (``Simulator.run(..., velocities=True)`` records it).
        angular_velocity: world-frame angular velocity at each recorded frame [rad/s], shape
            (F, N, 3), or None when not recorded.
        events: the contacts of the run (:class:`warpsim.ContactEvents`), or None when
            not recorded (``Simulator.run(..., events=True)``).
        sphere_ids: the index in the simulated swarm of each of the N spheres, shape (N,),
            int64, or None for ``0 .. N-1`` (a trajectory of the whole swarm); set by
            :meth:`subset` and ``Simulator.run(..., spheres=...)``, written as the USD
            instancer's ``ids``.
        birth_frame: the frame each of the N spheres is born at, shape (N,), int64, or None
            when every sphere exists from frame 0. Before its birth a sphere does not exist:
            its ``position``, ``orientation``, ``velocity`` and ``angular_velocity`` there are
            NaN (:meth:`alive` is the mask), and USD writes it invisible.
    """

    frame: np.ndarray
    dt: float
    position: np.ndarray
    orientation: np.ndarray
    radius: np.ndarray
    velocity: np.ndarray | None = None
    angular_velocity: np.ndarray | None = None
    events: object | None = None
    sphere_ids: np.ndarray | None = None
    birth_frame: np.ndarray | None = None

    def ids(self) -> np.ndarray:
        """:attr:`sphere_ids`, or ``0 .. N-1`` when unset, (N,) int64."""
        if self.sphere_ids is None:
            return np.arange(self.sphere_count, dtype=np.int64)
        return np.asarray(self.sphere_ids, dtype=np.int64)

    def alive(self) -> np.ndarray:
        """Whether each sphere exists at each record (born at or before its frame), (F, N)."""
        if self.birth_frame is None:
            return np.ones((len(self), self.sphere_count), dtype=bool)
        return (np.asarray(self.frame)[:, None]
                >= np.asarray(self.birth_frame, dtype=np.int64)[None, :])

    @property
    def time(self) -> np.ndarray:
        """Time of each record [s], shape (F,), computed from integer frames (no drift)."""
        return self.frame.astype(np.float64) * self.dt

    @property
    def frames_per_second(self) -> float:
        return 1.0 / self.dt

    def __len__(self) -> int:
        return int(self.frame.shape[0])

    @property
    def sphere_count(self) -> int:
        return int(self.position.shape[1])

    def __repr__(self) -> str:
        n_frames = len(self)
        if n_frames:
            span = f"frames {int(self.frame[0])}..{int(self.frame[-1])}"
        else:
            span = "no frames"
        extras = [name for name in ("velocity", "angular_velocity", "events")
                  if getattr(self, name) is not None]
        with_ = f", with {', '.join(extras)}" if extras else ""
        return (f"Trajectory({n_frames} records x {self.sphere_count} spheres, {span}, "
                f"dt={self.dt!r} s, {self.position.dtype}{with_})")

    def subset(self, spheres) -> Trajectory:
        """The same frames for the spheres at the given indices (a copy; events are kept whole,
        their sphere indices stay those of the full swarm; :attr:`sphere_ids` follows)."""
        idx = np.asarray(spheres, dtype=np.int64)

        def pick(values):
            return None if values is None else values[:, idx].copy()

        return Trajectory(frame=self.frame.copy(), dt=self.dt,
                          position=self.position[:, idx].copy(),
                          orientation=self.orientation[:, idx].copy(),
                          radius=self.radius[idx].copy(), velocity=pick(self.velocity),
                          angular_velocity=pick(self.angular_velocity), events=self.events,
                          sphere_ids=self.ids()[idx].copy(),
                          birth_frame=(None if self.birth_frame is None
                                       else np.asarray(self.birth_frame)[idx].copy()))
