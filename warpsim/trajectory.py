"""Recorded frames of a simulation, as numpy arrays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Trajectory:
    """Frames recorded by :meth:`warpsim.Simulator.run` (or read back from USD).

    Attributes:
        frame: simulation frame index of each record, shape (F,), int64. Frame 0 is the initial
            state; frame ``k`` is the state after ``k`` steps of ``dt``.
        dt: simulation time step [s]; the frame rate is ``1 / dt``.
        position: sphere centres [m], shape (F, N, 3).
        orientation: unit quaternions (x, y, z, w), body -> world, shape (F, N, 4).
        radius: sphere radii [m], shape (N,).
    """

    frame: np.ndarray
    dt: float
    position: np.ndarray
    orientation: np.ndarray
    radius: np.ndarray

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

    def subset(self, spheres) -> Trajectory:
        """The same frames for the spheres at the given indices (a copy)."""
        idx = np.asarray(spheres, dtype=np.int64)
        return Trajectory(frame=self.frame.copy(), dt=self.dt,
                          position=self.position[:, idx].copy(),
                          orientation=self.orientation[:, idx].copy(),
                          radius=self.radius[idx].copy())
