"""What a run will hold in memory, estimated before anything is drawn or allocated.

A run holds the swarm (its draw included), the device state, the frames it keeps on the host,
the launch's frame buffers and the contact buffers. :func:`run_bytes` adds them up from the
sizes alone, so that ``warpsim run`` refuses a run that cannot fit in one line, before the
spheres are drawn, instead of dying of a ``MemoryError`` (or being killed) later.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

SPAWN_BYTES = 560
"""Host bytes per sphere for drawing the swarm: the emitter's draws and their rejection test
(measured peak: 535 B per sphere for the room, tracemalloc), the swarm's arrays included."""
SIMULATOR_HOST_BYTES = 200
"""Host bytes per sphere the simulator keeps beside the device (masses, radii, energies, the
energy figures of the summary): measured 170 B per sphere."""
DEVICE_SCALARS = 2 * 14 + 2
"""Device scalars per sphere: two states (position, velocity, angular momentum: 3 each;
orientation 4; energy 1), radius and mass."""
COUNTER_BYTES = 8
"""Device bytes per sphere of the per-sphere counters (contacts, capped frames: int32 each)."""
EVENT_DEVICE_SCALARS = 8
"""Scalars of one contact row on the device: 2 vec3 (position, normal) and 2 scalars."""
EVENT_DEVICE_FIXED = 16
"""Bytes of one contact row's integers on the device: frame, sphere, box, kind (int32)."""
EVENT_HOST_BYTES = 3 * 100
"""Host bytes of one contact row: read out as float64/int64 columns (about 100 B), the table's
columns, and a copy while it is sorted."""
DEFAULT_MEMORY_FRACTION = 0.8
"""Fraction of the machine's memory a run may plan to hold by default."""


@dataclass(frozen=True)
class Footprint:
    """Estimated bytes of a run, by part (each an upper estimate, in bytes)."""

    swarm: int
    device: int
    trajectory: int
    launch: int
    events: int

    @property
    def total(self) -> int:
        return self.swarm + self.device + self.trajectory + self.launch + self.events

    def describe(self) -> str:
        parts = [("swarm", self.swarm), ("device state", self.device),
                 ("recorded frames", self.trajectory), ("launch buffers", self.launch),
                 ("events", self.events)]
        return ", ".join(f"{name} {value / 1e9:.2f} GB" for name, value in parts if value)


def run_bytes(n: int, records: int, *, kept: int | None = None, precision_bytes: int = 4,
              velocities: bool = False, launch_sphere_frames: int = 1 << 24, every: int = 1,
              event_rows: int = 0) -> Footprint:
    """What a run of ``n`` spheres keeping ``records`` frames of ``kept`` spheres holds.

    Args:
        n: spheres simulated, those born later too (every sphere has its state on the device
            and its slot in every record from the start). records: frames kept on the host
            (the first state included).
        kept: spheres whose frames are kept (``Simulator.run(spheres=...)``); None: all.
        precision_bytes: 4 (float32) or 8 (float64).
        velocities: velocities and angular velocities are recorded too.
        launch_sphere_frames: sphere-frames of one launch (``simulator.LAUNCH_SPHERE_FRAMES``).
        every: one frame in ``every`` is recorded (the launch buffers hold that many fewer).
        event_rows: contact rows the run may keep (its events capacity; 0 without events).
    """
    n, records = int(n), int(records)
    kept = n if kept is None else int(kept)
    ps = int(precision_bytes)
    per_record = (7 + (6 if velocities else 0)) * ps  # position 3, orientation 4 (+ 2 vec3)
    launch_rows = max(1, launch_sphere_frames // max(n, 1) // max(every, 1))
    return Footprint(swarm=n * (SPAWN_BYTES + SIMULATOR_HOST_BYTES),
                     device=n * (DEVICE_SCALARS * ps + COUNTER_BYTES),
                     trajectory=records * kept * per_record,
                     launch=2 * launch_rows * n * per_record,  # device rows and their copy
                     events=int(event_rows) * (EVENT_DEVICE_FIXED + EVENT_DEVICE_SCALARS * ps
                                               + EVENT_HOST_BYTES))


def machine_bytes() -> int | None:
    """The machine's physical memory [bytes], or None where the system does not say."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


def default_limit() -> float:
    """The memory a run may plan to hold unless told otherwise: ``DEFAULT_MEMORY_FRACTION`` of
    the machine's memory (no limit where the system does not say) [bytes]."""
    total = machine_bytes()
    return float("inf") if total is None else DEFAULT_MEMORY_FRACTION * total


def check_fits(footprint: Footprint, limit: float, option: str = "--max-memory",
               remedy: str = "") -> None:
    """Refuse a run whose footprint is above ``limit`` bytes, in one line that gives the
    figure, its parts, and ``option`` (the setting that raises the limit).

    Raises:
        ValueError: the run would not fit.
    """
    if footprint.total > limit:
        hint = f"{remedy}, or raise {option}" if remedy else f"raise {option}"
        raise ValueError(f"the run would hold about {footprint.total / 1e9:,.1f} GB in memory "
                         f"({footprint.describe()}), above {option} {limit / 1e9:,.1f} GB: "
                         f"{hint}")


__all__ = ["Footprint", "check_fits", "default_limit", "machine_bytes", "run_bytes"]
