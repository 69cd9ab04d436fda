"""warpsim through its public API only: ``ws.RoundedBoxes``, ``ws.Scene``, ``ws.Swarm``,
``ws.Simulator``.

Faithful to the workload as stated: the boxes are the workload's sharp boxes, contacts are
elastic (``energy_retention = 1``) and frictionless (``friction = 0``, so no spin code is
compiled), gravity as given, one frame of ``dt`` per step with exact continuous collision
detection (up to ``max_bounces`` contacts per sphere per frame, warpsim's default), in either
motion model. Everything else is warpsim's default (the energy correction of the model, broad
phase "auto"). Its state's velocity is the velocity at the frame's end (``step_velocity`` is
False), so its free flight is the exact parabola from the workload's velocity.
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
        motion: ``"linear"`` (the default model) or ``"ballistic"``.
    """

    #: ``state()``'s velocity is the velocity at the frame's end, not a step velocity
    step_velocity = False

    def __init__(self, work: Workload, precision: str = "float32", device: str = "cpu",
                 motion: str = "linear"):
        model = "" if motion == "linear" else f"{motion}-"
        self.key = f"warpsim-{model}{precision}"
        self.label = f"warpsim {model.replace('-', ' ')}{precision}"
        self._scene = work.scene()
        self._swarm = work.swarm()
        self._options = {"dt": work.dt, "device": device, "precision": precision,
                         "motion": motion}
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
                "energy_correction": self._sim.energy_correction,
                "bounces": stats.bounces, "capped": stats.capped, "frames": stats.frames}

    def close(self) -> None:
        self._sim = None
