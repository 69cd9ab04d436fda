"""warpsim through its public API only: ``ws.RoundedBoxes``, ``ws.Scene``, ``ws.Swarm``,
``ws.Simulator``.

Faithful to the workload as stated: the boxes are the workload's sharp boxes, contacts are
elastic (``energy_retention = 1``) and frictionless (``friction = 0``, so no spin code is
compiled), gravity as given, one frame of ``dt`` per step with exact continuous collision
detection (up to ``max_bounces`` contacts per sphere per frame, warpsim's default). Everything
else is warpsim's default (energy correction on, the linear motion model, broad phase "auto").
Device ``cpu``: one Warp CPU launch runs on one core.
"""

from __future__ import annotations

import numpy as np

import warpsim as ws

from .workload import Workload


class WarpsimDriver:
    """warpsim ``Simulator`` on the CPU.

    Args:
        work: the workload.
        precision: ``"float32"`` or ``"float64"`` kernels.
        device: Warp device (``"cpu"`` for the single-core comparison).
    """

    def __init__(self, work: Workload, precision: str = "float32", device: str = "cpu"):
        self.key = f"warpsim-{precision}"
        self.label = f"warpsim {precision}"
        self._scene = work.scene()
        self._swarm = work.swarm()
        self._options = {"dt": work.dt, "device": device, "precision": precision}
        self.reset()
        self._sim.build()

    def reset(self) -> None:
        self._sim = ws.Simulator(self._scene, self._swarm, **self._options)

    def step(self, frames: int) -> None:
        self._sim.step(frames)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        s = self._sim.state()
        return s.position.astype(np.float64), s.velocity.astype(np.float64)

    def settings(self) -> dict:
        stats = self._sim.stats
        return {**self._options,
                "max_bounces": self._sim.max_bounces, "broad_phase": self._sim.broad_phase,
                "energy_correction": self._scene.energy_correction,
                "bounces": stats.bounces, "capped": stats.capped, "frames": stats.frames}

    def close(self) -> None:
        self._sim = None
