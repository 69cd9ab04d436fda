"""Emitters: where a scene's spheres start, sampled reproducibly and clear of every obstacle.

An :class:`Emitter` describes a distribution (a box-shaped region, radius and mass ranges, a
velocity rule); :meth:`Emitter.spawn` draws a :class:`warpsim.Swarm` from it. Sampling is
vectorised and seeded: the same emitter, obstacles, ``n`` and ``seed`` give bit-identical arrays.
Spheres may overlap each other (they never interact) but never an obstacle: a candidate centre is
kept only when its signed distance to every box is at least the sphere's radius plus
``clearance``; the rejected ones are drawn again, a bounded number of times.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import validation as check
from .obstacles import RoundedBoxes
from .swarm import Swarm

MAX_PLACEMENT_ROUNDS = 200
"""Draws per sphere before the region is declared too crowded. A sphere fails all of them with
probability ``(1 - f)^200`` where ``f`` is the free fraction of the region: below 1e-9 for
``f >= 10%``, so a failure means the obstacles fill almost all of the region."""

HOPELESS_ROUNDS = 32
"""Give up early when not a single candidate was accepted in this many rounds: the region is
(nearly) all obstacle, and drawing the remaining rounds would only waste time."""

DEFAULT_CLEARANCE = 1e-3
"""Gap [m] kept between a new sphere and the nearest obstacle surface: a sphere that starts
exactly in contact is legal for the kernels but makes a poor initial state (its first contact
would be at ``t = 0``), and float32 rounding of the stored position must not push it inside."""


def _pair(name: str, value, *, minimum: float | None = None,
          positive: bool = False) -> tuple[float, float]:
    """A scalar ``x`` as ``(x, x)`` or a ``[min, max]`` pair, bounded, with ``min <= max``."""
    arr = np.asarray(value, dtype=object)
    if arr.ndim == 0:
        x = check.scalar(name, value, minimum=minimum, positive=positive)
        return (x, x)
    lo, hi = check.per_item(name, value, 2, minimum=minimum, positive=positive)
    if lo > hi:
        raise ValueError(f"{name} must be a scalar or [min, max] with min <= max, "
                         f"got [{lo:g}, {hi:g}]")
    return (float(lo), float(hi))


def _vec3(name: str, value, *, nonnegative: bool = False) -> tuple[float, float, float]:
    arr = check.vec3(name, value)
    if nonnegative:
        check.per_item(name, arr, 3, minimum=0.0)
    return (float(arr[0]), float(arr[1]), float(arr[2]))


@dataclass(frozen=True)
class Emitter:
    """A reproducible source of spheres (validated on construction; fields are plain tuples).

    The initial velocity of each sphere is the sum of three terms:
    ``velocity + velocity_jitter * U(-1, 1)^3 + s * d``, where the last term exists only when
    ``speed`` is given: ``s`` uniform in the speed range and ``d`` a unit direction uniform over
    the cone of half angle ``cone_deg`` about ``direction`` (180 degrees: every direction).

    Attributes:
        count: number of spheres spawned by default, >= 1.
        center: centre of the box-shaped emission region [m], world frame, shape (3,).
        half_extents: half sizes of the region along the world axes [m], each >= 0 (0 along an
            axis emits in a plane).
        radius: sphere radius [m], a scalar or a ``(min, max)`` range sampled uniformly; >= 0.
        mass: sphere mass [kg], a scalar or a ``(min, max)`` range sampled uniformly; > 0.
        velocity: mean initial velocity [m/s], shape (3,).
        velocity_jitter: half width of the uniform jitter of each velocity component [m/s],
            each >= 0.
        speed: None, or the speed [m/s] of the cone term: a scalar or a ``(min, max)`` range;
            >= 0.
        direction: axis of the cone (any non-zero length), shape (3,).
        cone_deg: half angle of the cone [deg], in [0, 180].
        angular_momentum: initial angular momentum of every sphere [kg m^2/s], shape (3,).
        seed: default seed of :meth:`spawn`, an integer >= 0.
        clearance: minimum gap between a new sphere and any obstacle [m], >= 0.

    Raises:
        ValueError: on a bad field, naming it (and the index for vectors and ranges).
    """

    count: int
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    half_extents: tuple[float, float, float] = (0.5, 0.5, 0.5)
    radius: float | tuple[float, float] = 0.05
    mass: float | tuple[float, float] = 1.0
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity_jitter: tuple[float, float, float] = (0.0, 0.0, 0.0)
    speed: float | tuple[float, float] | None = None
    direction: tuple[float, float, float] = (0.0, 1.0, 0.0)
    cone_deg: float = 180.0
    angular_momentum: tuple[float, float, float] = (0.0, 0.0, 0.0)
    seed: int = 0
    clearance: float = DEFAULT_CLEARANCE

    def __post_init__(self):
        fields = {
            "count": check.positive_int("count", self.count),
            "center": _vec3("center", self.center),
            "half_extents": _vec3("half_extents", self.half_extents, nonnegative=True),
            "radius": _pair("radius", self.radius, minimum=0.0),
            "mass": _pair("mass", self.mass, positive=True),
            "velocity": _vec3("velocity", self.velocity),
            "velocity_jitter": _vec3("velocity_jitter", self.velocity_jitter, nonnegative=True),
            "speed": None if self.speed is None else _pair("speed", self.speed, minimum=0.0),
            "direction": _vec3("direction", self.direction),
            "cone_deg": check.scalar("cone_deg", self.cone_deg, minimum=0.0, maximum=180.0),
            "angular_momentum": _vec3("angular_momentum", self.angular_momentum),
            "seed": check.positive_int("seed", self.seed, minimum=0),
            "clearance": check.scalar("clearance", self.clearance, minimum=0.0),
        }
        if not np.linalg.norm(fields["direction"]) > 0.0:
            raise ValueError(f"direction must be a non-zero vector, got {fields['direction']}")
        for name, value in fields.items():
            object.__setattr__(self, name, value)

    def spawn(self, boxes: RoundedBoxes, n: int | None = None, seed: int | None = None) -> Swarm:
        """Draw ``n`` spheres clear of ``boxes``.

        Args:
            boxes: the obstacles no sphere may start inside or touching (never modified).
            n: number of spheres; None for :attr:`count`.
            seed: integer >= 0; None for :attr:`seed`. The same emitter, boxes, ``n`` and
                ``seed`` always give identical arrays.

        Returns:
            A :class:`warpsim.Swarm` with identity orientations; every centre ``p`` satisfies
            ``boxes.signed_distance(p) >= radius + clearance``.

        Raises:
            ValueError: on a bad ``n`` or ``seed``, or when the region is too crowded by
                obstacles to place every sphere within the bounded number of draws.
        """
        if not isinstance(boxes, RoundedBoxes):
            raise ValueError(f"boxes must be a warpsim.RoundedBoxes, got {type(boxes).__name__}")
        n = self.count if n is None else check.positive_int("n", n)
        seed = self.seed if seed is None else check.positive_int("seed", seed, minimum=0)
        # One independent stream per quantity: changing the velocity rule leaves the positions
        # (and radii, masses) of a seed unchanged.
        radius_rng, mass_rng, velocity_rng, position_rng = (
            np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4))
        radius = radius_rng.uniform(*self.radius, size=n)
        mass = mass_rng.uniform(*self.mass, size=n)
        velocity = self._velocities(velocity_rng, n)
        position = self._positions(position_rng, boxes, radius)
        return Swarm(position=position, velocity=velocity, radius=radius, mass=mass,
                     angular_momentum=np.tile(np.asarray(self.angular_momentum), (n, 1)))

    def _velocities(self, rng: np.random.Generator, n: int) -> np.ndarray:
        velocity = np.asarray(self.velocity) + np.asarray(self.velocity_jitter) * rng.uniform(
            -1.0, 1.0, size=(n, 3))
        if self.speed is None:
            return velocity
        speed = rng.uniform(*self.speed, size=n)
        # Uniform on the spherical cap: cos(theta) uniform in [cos(cone), 1], azimuth uniform.
        cos_theta = rng.uniform(math.cos(math.radians(self.cone_deg)), 1.0, size=n)
        phi = rng.uniform(0.0, 2.0 * math.pi, size=n)
        sin_theta = np.sqrt(np.maximum(0.0, 1.0 - cos_theta * cos_theta))
        axis = np.asarray(self.direction) / np.linalg.norm(self.direction)
        u, w = _orthonormal_pair(axis)
        d = (cos_theta[:, None] * axis
             + (sin_theta * np.cos(phi))[:, None] * u
             + (sin_theta * np.sin(phi))[:, None] * w)
        return velocity + speed[:, None] * d

    def _positions(self, rng: np.random.Generator, boxes: RoundedBoxes,
                   radius: np.ndarray) -> np.ndarray:
        n = radius.shape[0]
        center = np.asarray(self.center)
        half = np.asarray(self.half_extents)
        position = center + half * rng.uniform(-1.0, 1.0, size=(n, 3))
        pending = np.arange(n)
        if len(boxes) == 0:
            return position
        for round_index in range(MAX_PLACEMENT_ROUNDS):
            clear = (boxes.signed_distance(position[pending]).min(axis=1)
                     >= radius[pending] + self.clearance)
            pending = pending[~clear]
            if pending.size == 0:
                return position
            if round_index + 1 == HOPELESS_ROUNDS and pending.size == n:
                break
            position[pending] = center + half * rng.uniform(-1.0, 1.0, size=(pending.size, 3))
        raise ValueError(
            f"emitter region is too crowded: {pending.size} of {n} spheres could not be placed "
            f"clear of the obstacles (signed distance >= radius + clearance) after "
            f"{round_index + 1} draws each; the obstacles fill (almost) all of the region "
            f"center {list(self.center)}, half_extents {list(self.half_extents)}: move or "
            f"enlarge the region, or use smaller spheres")


def _orthonormal_pair(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing the unit ``axis`` to a right-handed orthonormal basis."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)
