"""The workload every engine runs, and the measures taken on every engine's result.

A closed room (six walls, inner 4 x 3 x 4 m, floor at y = 0) with ``PLATES`` randomly rotated
sharp plates 0.02 m thick inside; spheres of radius 0.01 m, mass 1 kg, spawned clear of every
obstacle, all at one speed (5 or 60 m/s) in uniformly random directions; gravity
(0, -9.81, 0); elastic, frictionless contacts; spheres never touch each other; dt = 1/60 s,
600 frames. The same seed gives every engine the same room and the same spheres.

Measures, computed here from each engine's state the same way for every engine:

- escaped: centre outside the room (beyond the walls' outer faces) or not finite;
- inside: the sphere overlaps an obstacle by more than ``INSIDE_TOLERANCE`` (signed distance
  from :meth:`warpsim.RoundedBoxes.signed_distance`);
- energy drift: relative change of the swarm's total energy (:func:`energy`);
- error: distance from an exact, event-driven reference over the first second
  (:func:`reference_positions`, on a sample of the spheres).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

import warpsim as ws
from warpsim.energy import energy_scale, lowest_potential

ROOM_HALF = np.array([2.0, 1.5, 2.0])
"""Half the inner size of the room [m]; the inner floor is the plane y = 0."""
WALL_THICKNESS = 0.1
"""[m]"""
PLATES = 12
PLATE_HALF = (0.2, 0.6)
"""Range of the plates' half length and half width [m]."""
PLATE_THICKNESS = 0.02
"""[m]: a sphere at 60 m/s moves 1 m in one 1/60 s frame, 50 plate thicknesses."""
PLATE_MARGIN = 0.9
"""Least distance [m] from a plate's centre to a wall: more than the largest plate's half
diagonal (0.85 m), so no plate touches a wall."""
ROOM_SEED = 11
RADIUS = 0.01
"""Sphere radius [m]."""
MASS = 1.0
"""Sphere mass [kg]."""
GRAVITY = (0.0, -9.81, 0.0)
"""[m/s^2]"""
DT = 1.0 / 60.0
"""Frame length [s], the step of every engine."""
FRAMES = 600
"""Frames of a run (10 s)."""
SPEEDS = (5.0, 60.0)
"""Sphere speeds [m/s] of the two workloads."""
SEED = 20261201
SPAWN_GAP = 1e-3
"""Least gap [m] between a new sphere and an obstacle: a float32 copy of the centre must not
start inside one."""
INSIDE_TOLERANCE = 1e-3
"""Overlap [m] with an obstacle above which a sphere counts as inside it: a tenth of the
radius, well above the resting penetration of the soft-contact engines (under 0.1 mm here)
and far below what a sphere stuck in a plate or a wall shows."""
ERROR_HORIZON_FRAMES = 60
"""Frames (1 s) over which positions are compared with the exact reference: trajectories in
a room of plates are chaotic, so later differences measure chaos, not the engine."""


@dataclass(frozen=True)
class Obstacle:
    """One sharp box: centre [m], half extents [m], rotation (x, y, z, w), local -> world."""

    center: tuple[float, float, float]
    half_extents: tuple[float, float, float]
    rotation: tuple[float, float, float, float]


@dataclass
class Workload:
    """The obstacles and the initial spheres of one run, the same for every engine.

    Attributes:
        obstacles: the six walls first, then the plates.
        position: initial centres [m], (N, 3). velocity: initial velocities [m/s], (N, 3).
        speed: the speed of every sphere [m/s]. radius [m], mass [kg], gravity [m/s^2],
        dt [s], frames: as the module constants unless a test shrinks them.
    """

    obstacles: list[Obstacle]
    position: np.ndarray
    velocity: np.ndarray
    speed: float
    radius: float = RADIUS
    mass: float = MASS
    gravity: tuple[float, float, float] = GRAVITY
    dt: float = DT
    frames: int = FRAMES
    boxes: ws.RoundedBoxes = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self.boxes = ws.RoundedBoxes(center=[o.center for o in self.obstacles],
                                     half_extents=[o.half_extents for o in self.obstacles],
                                     rotation=[o.rotation for o in self.obstacles])

    @property
    def n(self) -> int:
        return len(self.position)

    def scene(self) -> ws.Scene:
        """The warpsim scene: these boxes, gravity, elastic and frictionless."""
        return ws.Scene(self.boxes, gravity=self.gravity, friction=0.0, energy_retention=1.0,
                        dt=self.dt, frames=self.frames)

    def swarm(self, rows=slice(None)) -> ws.Swarm:
        """The spheres (or the ``rows`` of them) as a warpsim swarm."""
        return ws.Swarm(self.position[rows], self.velocity[rows], radius=self.radius,
                        mass=self.mass)


def room_walls() -> list[Obstacle]:
    """Six walls ``WALL_THICKNESS`` thick around the inner space; they overlap at the edges,
    so no corner has a gap."""
    hx, hy, hz = ROOM_HALF
    w = WALL_THICKNESS / 2
    identity = (0.0, 0.0, 0.0, 1.0)
    centers = [(0.0, -w, 0.0), (0.0, 2 * hy + w, 0.0), (-hx - w, hy, 0.0), (hx + w, hy, 0.0),
               (0.0, hy, -hz - w), (0.0, hy, hz + w)]
    halves = ([(hx + 2 * w, w, hz + 2 * w)] * 2 + [(w, hy + 2 * w, hz + 2 * w)] * 2
              + [(hx + 2 * w, hy + 2 * w, w)] * 2)
    return [Obstacle(c, h, identity) for c, h in zip(centers, halves, strict=True)]


def room_plates(count: int = PLATES, seed: int = ROOM_SEED) -> list[Obstacle]:
    """``count`` plates ``PLATE_THICKNESS`` thick (local y), uniformly random rotations,
    centres at least ``PLATE_MARGIN`` from every wall."""
    rng = np.random.default_rng(seed)
    low = np.array([-ROOM_HALF[0], 0.0, -ROOM_HALF[2]]) + PLATE_MARGIN
    high = np.array([ROOM_HALF[0], 2 * ROOM_HALF[1], ROOM_HALF[2]]) - PLATE_MARGIN
    center = rng.uniform(low, high, size=(count, 3))
    half = np.column_stack([rng.uniform(*PLATE_HALF, count), np.full(count, PLATE_THICKNESS / 2),
                            rng.uniform(*PLATE_HALF, count)])
    q = rng.normal(size=(count, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return [Obstacle(tuple(map(float, c)), tuple(map(float, h)), tuple(map(float, r)))
            for c, h, r in zip(center, half, q, strict=True)]


def make_workload(n: int, speed: float, seed: int = SEED, frames: int = FRAMES) -> Workload:
    """``n`` spheres at ``speed`` [m/s] in the room with its plates.

    Centres are uniform in the inner space, kept only when at least ``RADIUS + SPAWN_GAP`` from
    every obstacle; directions are uniform on the sphere. The same arguments give the same
    workload.

    Raises:
        ValueError: ``n`` < 1, ``speed`` < 0 or ``frames`` < 1.
    """
    if int(n) != n or n < 1:
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    if not np.isfinite(speed) or speed < 0:
        raise ValueError(f"speed must be finite and >= 0, got {speed!r}")
    if int(frames) != frames or frames < 1:
        raise ValueError(f"frames must be an integer >= 1, got {frames!r}")
    obstacles = room_walls() + room_plates()
    boxes = ws.RoundedBoxes(center=[o.center for o in obstacles],
                            half_extents=[o.half_extents for o in obstacles],
                            rotation=[o.rotation for o in obstacles])
    rng = np.random.default_rng([seed, int(n), int(round(speed * 1000))])
    inner = ROOM_HALF - RADIUS - SPAWN_GAP
    low = np.array([-inner[0], ROOM_HALF[1] - inner[1], -inner[2]])
    high = np.array([inner[0], ROOM_HALF[1] + inner[1], inner[2]])
    kept: list[np.ndarray] = []
    count = 0
    while count < n:
        cand = rng.uniform(low, high, size=(2 * (n - count) + 16, 3))
        clear = boxes.signed_distance(cand).min(axis=1) >= RADIUS + SPAWN_GAP
        cand = cand[clear][: n - count]
        kept.append(cand)
        count += len(cand)
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return Workload(obstacles, np.concatenate(kept), speed * direction, float(speed),
                    frames=int(frames))


# -- measures -----------------------------------------------------------------------------------

def escaped(position: np.ndarray) -> np.ndarray:
    """Spheres (bool, (N,)) that left the room: centre beyond the walls' outer faces, or not
    finite. (A centre inside a wall is not escaped but inside an obstacle: discrete engines
    leave spheres part-way into a wall between steps.)"""
    p = np.asarray(position, dtype=np.float64)
    outer = ROOM_HALF + WALL_THICKNESS
    low = np.array([-outer[0], -WALL_THICKNESS, -outer[2]])
    high = np.array([outer[0], 2 * ROOM_HALF[1] + WALL_THICKNESS, outer[2]])
    with np.errstate(invalid="ignore"):
        within = np.all((p >= low) & (p <= high), axis=1)
    return ~within


def inside_obstacle(work: Workload, position: np.ndarray) -> np.ndarray:
    """Spheres (bool, (N,)) overlapping some obstacle by more than ``INSIDE_TOLERANCE`` [m];
    a sphere whose centre is not finite is not counted here (it counts as escaped)."""
    p = np.asarray(position, dtype=np.float64)
    finite = np.all(np.isfinite(p), axis=1)
    out = np.zeros(len(p), dtype=bool)
    if finite.any():
        depth = work.radius - work.boxes.signed_distance(p[finite]).min(axis=1)
        out[finite] = depth > INSIDE_TOLERANCE
    return out


def energy(work: Workload, position: np.ndarray, velocity: np.ndarray,
           step_velocity: bool = True) -> np.ndarray:
    """Per-sphere total energy [J], (N,), with the floor (y = 0) as the zero of height.

    ``1/2 m |u|^2 - m g . p`` with ``u`` the velocity at the step's end. The peers integrate
    gravity by semi-implicit Euler and report the step's velocity ``v`` (the one the last step
    moved with, ``step_velocity``), whose step ends with ``u = v + g dt / 2``; warpsim reports
    ``u`` itself. With ``u`` this energy is exactly constant in free flight, so its drift
    measures the contacts only (with ``v`` itself a ball in free flight would lose
    ``m g^2 dt^2 / 2`` every step).
    """
    g = np.asarray(work.gravity)
    u = np.asarray(velocity, dtype=np.float64) + (0.5 * work.dt if step_velocity else 0.0) * g
    return (0.5 * work.mass * np.einsum("ij,ij->i", u, u)
            - work.mass * (np.asarray(position, dtype=np.float64) @ g))


def energy_drift(work: Workload, position: np.ndarray, velocity: np.ndarray,
                 step_velocity: bool = True) -> dict:
    """Relative change of the total energy from the start, and the worst single sphere's, on
    the scale of :mod:`warpsim.energy` (each sphere's energy above the scene's lowest point);
    ``step_velocity`` as in :func:`energy`, for the start as for the end: each engine is given
    the workload's velocity in its own convention.

    Spheres whose state is not finite are left out of both (they count as escaped).
    """
    e0 = energy(work, work.position, work.velocity, step_velocity)
    e1 = energy(work, position, velocity, step_velocity)
    ok = np.isfinite(e1)
    if not ok.any():
        return {"total": None, "worst_sphere": None}
    lowest = lowest_potential(work.gravity, work.boxes, work.position)
    scale = energy_scale(e0, work.mass, lowest)[ok]
    return {"total": float((e1[ok].sum() - e0[ok].sum()) / scale.sum()),
            "worst_sphere": float(np.max(np.abs(e1[ok] - e0[ok]) / scale))}


def reference_positions(work: Workload, sample: int, frames: int = ERROR_HORIZON_FRAMES):
    """Exact positions [m] of the first ``sample`` spheres at frames 0..``frames``.

    Uses ``warpsim.analysis.reference.simulate`` (float64, event-driven, exact parabolas between
    contacts). Returns ``(positions (frames + 1, sample, 3), seconds, None)``, or
    ``(None, 0.0, reason)`` when this warpsim has no reference yet.
    """
    try:
        from warpsim.analysis import reference
    except ImportError as exc:
        return None, 0.0, f"warpsim.analysis.reference is not available ({exc})"
    times = np.arange(frames + 1) * work.dt
    start = time.perf_counter()
    ref = reference.simulate(work.scene(), work.swarm(slice(0, sample)), float(times[-1]), times)
    return np.asarray(ref.position, dtype=np.float64), time.perf_counter() - start, None


def reference_error(recorded: np.ndarray, exact: np.ndarray, dt: float = DT) -> dict:
    """Distances [m] of the sampled spheres from their exact paths.

    Args:
        recorded: an engine's positions at frames 0..F, (F + 1, S, 3). exact: the reference's
            at the same frames. dt: the frame length [s].

    Returns:
        ``median_at`` (median over the sample at 0.1 s and 0.5 s, the frames that exist),
        ``median`` and ``worst`` of each sphere's largest distance over all compared frames,
        ``share_over_0.1m`` of the sample, ``sample`` (spheres compared) and ``left_out``
        (spheres the reference gave up on: their exact path is not finite). An engine's
        position that is not finite counts as infinitely far.
    """
    exact = np.asarray(exact, dtype=np.float64)
    known = np.all(np.isfinite(exact), axis=(0, 2))
    d = np.linalg.norm(np.asarray(recorded, dtype=np.float64)[:, known] - exact[:, known],
                       axis=2)
    d = np.where(np.isfinite(d), d, np.inf)
    if d.shape[1] == 0:
        return {"median_at": {}, "median": None, "worst": None, "share_over_0.1m": None,
                "sample": 0, "left_out": int(known.size)}
    at = {f"{t:g}": float(np.median(d[round(t / dt)])) for t in (0.1, 0.5)
          if round(t / dt) < len(d)}
    largest = d.max(axis=0)
    return {"median_at": at, "median": float(np.median(largest)),
            "worst": float(largest.max()), "share_over_0.1m": float(np.mean(largest > 0.1)),
            "sample": int(largest.size), "left_out": int(np.count_nonzero(~known))}


# -- the interface every driver has -------------------------------------------------------------

class Driver(Protocol):
    """What every engine driver provides (each driver module documents its set-up).

    Construction builds the engine's model for a :class:`Workload` (timed by the caller as
    set-up; drivers whose engine compiles kernels on first use run one step and reset there, so
    that compiling is part of the set-up and not of a timed run).

    Attributes:
        key: short unique name of the setting (used in the JSON).
        label: what the table shows.
    """

    key: str
    label: str

    def reset(self) -> None:
        """Back to the workload's initial state, without rebuilding."""

    def step(self, frames: int) -> None:
        """Advance ``frames`` frames of ``dt``."""

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """Current centres [m] and velocities [m/s], float64 copies, (N, 3) each."""

    def settings(self) -> dict:
        """The engine's settings as the engine reports them (for the JSON)."""

    def close(self) -> None:
        """Release the engine's resources."""
