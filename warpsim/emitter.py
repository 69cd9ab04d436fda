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
from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from . import validation as check
from .blocks import for_row_blocks, row_streams, uniform_rows
from .obstacles import RoundedBoxes
from .swarm import Swarm

MAX_PLACEMENT_ROUNDS = 200
"""Draws per sphere before the region is declared too crowded. A sphere fails all of them with
probability ``(1 - f)^200`` where ``f`` is the free fraction of the region: below 1e-9 for
``f >= 10%``, so a failure means the obstacles fill almost all of the region."""

HOPELESS_ROUNDS = 32
"""Stop early, after this many rounds, when not one draw so far was clear and at least
``MAX_PLACEMENT_ROUNDS`` draws were made over all the spheres: that many misses in a row are as
unlikely as one sphere's ``MAX_PLACEMENT_ROUNDS`` misses, and drawing on would only waste time
in a region that is (nearly) all obstacle."""

DEFAULT_CLEARANCE = 1e-3
"""Gap [m] kept between a new sphere and the nearest obstacle surface: a sphere that starts
exactly in contact is legal for the kernels but makes a poor initial state (its first contact
would be at ``t = 0``), and float32 rounding of the stored position must not push it inside."""

HELPER_AXIS_COS = 0.9
"""The cone's frame is built from the cross product with world x, or with world y when the axis
is within ``acos(0.9)`` (26 degrees) of x: the cross product then keeps a length of at least
0.43, far from the cancellation of nearly parallel vectors."""

_CORNER_SIGNS = np.array([[sx, sy, sz] for sx in (-1.0, 1.0) for sy in (-1.0, 1.0)
                          for sz in (-1.0, 1.0)])


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
        direction: axis of the cone (any non-zero length), shape (3,); only with ``speed``
            (refused without it, where it would do nothing); None there means ``(0, 1, 0)``.
        cone_deg: half angle of the cone [deg], in [0, 180]; only with ``speed``; None there
            means 180 (every direction).
        angular_momentum: initial angular momentum of every sphere [kg m^2/s], shape (3,).
        seed: default seed of :meth:`spawn`, an integer >= 0.
        clearance: minimum gap between a new sphere and any obstacle [m], >= 0.
        start: when the first sphere is born [s], >= 0.
        rate: spheres born per second, > 0, or None; sphere ``k`` is emitted at ``start + k /
            rate`` (:meth:`birth_frames`). With neither ``rate`` nor ``duration`` every sphere
            is born at ``start``.
        duration: the time [s] over which the spheres are emitted, > 0, or None: the rate is
            then ``n / duration`` for ``n`` spheres. Given with ``rate``, ``rate x duration``
            must round to ``count``, and ``rate`` rules for another ``n``.

    A sphere's drawn state is its state at its birth (see :class:`warpsim.Swarm`): it appears
    where it was drawn, with its drawn velocity, at the frame nearest its emission time.

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
    direction: tuple[float, float, float] | None = None
    cone_deg: float | None = None
    angular_momentum: tuple[float, float, float] = (0.0, 0.0, 0.0)
    seed: int = 0
    clearance: float = DEFAULT_CLEARANCE
    start: float = 0.0
    rate: float | None = None
    duration: float | None = None

    def __post_init__(self):
        checked = check.emitter_fields({f.name: getattr(self, f.name) for f in fields(self)})
        for name, value in checked.items():
            object.__setattr__(self, name, value)

    @classmethod
    def from_table(cls, table: Mapping[str, object], where: str = "emitter") -> Emitter:
        """An emitter from a mapping of its fields, such as a scene file's ``[emitter]`` table.

        Args:
            table: field name -> raw value; ``count`` is required, the others default.
            where: the table's name, put before the field names in messages
                (``emitter.radius must be >= 0, got -0.1``).

        Raises:
            ValueError: for an unknown or missing field or a bad value, naming ``where.field``.
        """
        known = {f.name: f.default for f in fields(cls)}
        for key in table:
            if key not in known:
                raise ValueError(f"unknown key {key!r} in [{where}]")
        if "count" not in table:
            raise ValueError(f"{where}.count is required")
        values = {key: table.get(key, default) for key, default in known.items()}
        return cls(**check.emitter_fields(values, where=f"{where}."))

    @property
    def emits_over_time(self) -> bool:
        """Whether some sphere is born after frame 0 (a ``start``, ``rate`` or ``duration``)."""
        return self.start > 0.0 or self.rate is not None or self.duration is not None

    def birth_frames(self, dt: float, n: int | None = None, first: int = 0,
                     size: int | None = None) -> np.ndarray:
        """The birth frame of spheres ``first .. first + size - 1`` of a swarm of ``n``.

        Sphere ``k`` is emitted at ``t_k = start + k / rate`` (``rate = n / duration`` when
        only ``duration`` is given; every ``t_k = start`` with neither) and born at the frame
        nearest ``t_k``: ``round(t_k / dt)``, halves to even.

        Args:
            dt: the run's frame duration [s], > 0.
            n: spheres of the whole swarm; None for :attr:`count`.
            first, size: the spheres wanted (default: all ``n``).

        Returns:
            (size,) int64 frame numbers, non-decreasing.

        Raises:
            ValueError: a bad ``dt``, or a birth frame at or beyond ``2**31``.
        """
        n = self.count if n is None else check.positive_int("n", n)
        dt = check.scalar("dt", dt, positive=True)
        size = n - first if size is None else size
        k = np.arange(first, first + size, dtype=np.float64)
        rate = self.rate if self.rate is not None else (
            n / self.duration if self.duration is not None else None)
        times = np.full(size, self.start) if rate is None else self.start + k / rate
        frames = np.rint(times / dt)
        if frames.size and not frames[-1] < check.INT_LIMIT:
            raise ValueError(f"emitter: the last sphere would be born at frame {frames[-1]:g} "
                             f"(t = {times[-1]:g} s, dt = {dt:g} s): at most 2**31 - 1")
        return frames.astype(np.int64)

    def spawn(self, boxes: RoundedBoxes, n: int | None = None, seed: int | None = None,
              dt: float | None = None) -> Swarm:
        """Draw ``n`` spheres clear of ``boxes``.

        Args:
            boxes: the obstacles no sphere may start inside or touching (never modified).
            n: number of spheres; None for :attr:`count`.
            seed: integer >= 0; None for :attr:`seed`. The same emitter, boxes, ``n`` and
                ``seed`` always give identical arrays.
            dt: the run's frame duration [s]: the swarm's birth frames come from it
                (:meth:`birth_frames`); needed only when the emitter emits over time.

        Returns:
            A :class:`warpsim.Swarm` with identity orientations; every centre ``p`` satisfies
            ``boxes.signed_distance(p) >= radius + clearance``.

        Raises:
            ValueError: on a bad ``n`` or ``seed``; when the largest radius plus the clearance
                fits nowhere in the region (checked first); or when the region is too crowded
                by obstacles to place every sphere in :data:`MAX_PLACEMENT_ROUNDS` draws each
                (the message says how many draws were made).
        """
        if not isinstance(boxes, RoundedBoxes):
            raise ValueError(f"boxes must be a warpsim.RoundedBoxes, got {type(boxes).__name__}")
        n = self.count if n is None else check.positive_int("n", n)
        seed = self.seed if seed is None else check.positive_int("seed", seed, minimum=0)
        return self.spawn_many(boxes, [n], [seed], dt)[0]

    def spawn_many(self, boxes: RoundedBoxes, counts, seeds,
                   dt: float | None = None, join: bool = False) -> list[Swarm]:
        """Draw several swarms at once: ``[spawn(boxes, n, seed, dt) for n, seed in
        zip(counts, seeds)]``, the same arrays bit for bit, with the clearance of every swarm's
        pending spheres tested in one query per round (a sharded draw of many small blocks).

        Args:
            boxes: the obstacles (never modified).
            counts, seeds: one ``n`` (>= 1) and one ``seed`` (>= 0) per swarm, already checked.
            dt: as :meth:`spawn`'s.
            join: return one swarm, those swarms one after the other (the same arrays as
                their concatenation), checked and marked clear of ``boxes`` once instead of
                swarm by swarm (a sharded draw's blocks, about 0.3 ms a block saved).

        Raises:
            ValueError: as :meth:`spawn`, for the first swarm that cannot be placed.
        """
        self._check_radius_fits(boxes)
        cone = self._cone()
        parts = []
        for n, seed in zip(counts, seeds, strict=True):
            # One independent stream per quantity: changing the velocity rule leaves the
            # positions (and radii, masses) of a seed unchanged.
            radius_rng, mass_rng, velocity_rng, position_rng = (
                np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4))
            radius = uniform_rows(radius_rng, *self.radius, n)
            mass = uniform_rows(mass_rng, *self.mass, n)
            velocity = self._velocities(velocity_rng, n, cone)
            births = 0
            if self.emits_over_time:
                if dt is None:
                    raise ValueError("this emitter emits over time (start, rate or duration): "
                                     "spawn it with the run's dt")
                births = self.birth_frames(dt, n)
            parts.append((radius, mass, velocity, births, position_rng))
        positions = self._positions([rng for *_, rng in parts], boxes,
                                    [radius for radius, *_ in parts])
        if join and len(parts) > 1:
            born = [np.broadcast_to(np.asarray(b), r.shape) for r, _, _, b, _ in parts]
            parts = [(np.concatenate([part[0] for part in parts]),
                      np.concatenate([part[1] for part in parts]),
                      np.concatenate([part[2] for part in parts]),
                      np.concatenate(born) if any(np.ndim(b) for *_, b, _ in parts) else 0,
                      None)]
            positions = [np.concatenate(positions)]
        spin = np.asarray(self.angular_momentum, dtype=np.float64)
        still = not spin.any() and not np.signbit(spin).any()  # +0.0 each: the Swarm default
        swarms = [Swarm(position=position, velocity=velocity, radius=radius, mass=mass,
                        angular_momentum=None if still else np.tile(spin, (radius.shape[0], 1)),
                        birth_frame=births)
                  for (radius, mass, velocity, births, _), position
                  in zip(parts, positions, strict=True)]
        for swarm in swarms:  # placed outside these boxes: a simulator need not check again
            swarm._mark_clear_of(boxes)
        return swarms

    def _region(self) -> str:
        return f"center {list(self.center)}, half_extents {list(self.half_extents)}"

    def _check_radius_fits(self, boxes: RoundedBoxes) -> None:
        """Refuse a radius that fits nowhere in the region, before any draw.

        The signed distance from ``p`` to box ``k`` is at most ``|p - c_k| - rb_k`` (the centre
        is in the core box), and over the region ``|p - c_k|`` is largest at a corner: no point
        of the region is farther than ``max_corner |corner - c_k| - rb_k`` from box ``k``.
        """
        if len(boxes) == 0:
            return
        corners = np.asarray(self.center) + _CORNER_SIGNS * np.asarray(self.half_extents)
        farthest = np.linalg.norm(corners[:, None, :] - boxes.center[None], axis=2).max(axis=0)
        bound = farthest - boxes.radius
        k = int(np.argmin(bound))
        if self.radius[1] + self.clearance > bound[k]:
            raise ValueError(
                f"emitter radius up to {self.radius[1]:g} m plus clearance {self.clearance:g} m "
                f"fits nowhere: no point of the region ({self._region()}) is farther than "
                f"{bound[k]:.3g} m from box {k}; use smaller spheres or move the region")

    def _cone(self) -> tuple | None:
        """``(cos(cone), axis, u, w)``: the cone of the speeds' directions and an orthonormal
        frame around its unit axis (None without a speed); the same for every swarm drawn."""
        if self.speed is None:
            return None
        axis = np.asarray(self.direction) / np.linalg.norm(self.direction)
        return (math.cos(math.radians(self.cone_deg)), axis, *_orthonormal_pair(axis))

    def _velocities(self, rng: np.random.Generator, n: int, cone: tuple | None) -> np.ndarray:
        """``n`` velocities [m/s], (n, 3): the base velocity plus the jitter, plus a speed in a
        direction uniform on the cone's cap (``cone``: :meth:`_cone`), in the order of the
        expression ``v0 + j * U + s * (c a + (q cos phi) u + (q sin phi) w)``. The draws are
        those of one serial draw from ``rng`` (U, then s, cos(theta) and phi, ``n`` each), and
        ``rng`` is left where that draw would leave it; the rows are computed in blocks on
        every core (:func:`warpsim.blocks.for_row_blocks`), the arithmetic in place in each
        block."""
        stream, done = row_streams(rng, n)
        jitter = np.asarray(self.velocity_jitter, dtype=np.float64)
        base = np.asarray(self.velocity, dtype=np.float64)
        velocity = np.empty((n, 3))
        if cone is not None:
            cos_cone, axis, u, w = cone

        def block(rows: slice) -> None:
            m = rows.stop - rows.start
            v = velocity[rows]
            v[...] = stream(3 * rows.start).uniform(-1.0, 1.0, size=(m, 3))
            v *= jitter
            np.add(base, v, out=v)
            if cone is None:
                return
            speed = stream(3 * n + rows.start).uniform(*self.speed, size=m)
            # Uniform on the spherical cap: cos(theta) uniform in [cos(cone), 1], azimuth
            # uniform.
            cos_theta = stream(4 * n + rows.start).uniform(cos_cone, 1.0, size=m)
            phi = stream(5 * n + rows.start).uniform(0.0, 2.0 * math.pi, size=m)
            sin_theta = np.multiply(cos_theta, cos_theta)
            np.subtract(1.0, sin_theta, out=sin_theta)
            np.maximum(0.0, sin_theta, out=sin_theta)
            np.sqrt(sin_theta, out=sin_theta)
            d = np.multiply(cos_theta[:, None], axis)
            part = np.empty_like(d)
            along = np.cos(phi)
            along *= sin_theta
            np.multiply(along[:, None], u, out=part)
            d += part
            np.sin(phi, out=along)
            along *= sin_theta
            np.multiply(along[:, None], w, out=part)
            d += part
            d *= speed[:, None]
            v += d

        for_row_blocks(n, block)
        done((3 if cone is None else 6) * n)
        return velocity

    def _positions(self, rngs: list, boxes: RoundedBoxes,
                   radii: list[np.ndarray]) -> list[np.ndarray]:
        """The centres of each swarm (its own stream ``rngs[j]``, radii ``radii[j]``): every
        sphere drawn again until it is clear, the pending spheres of all swarms tested together
        (a point's distance does not depend on the others: each swarm's draws are its own)."""
        center = np.asarray(self.center)
        half = np.asarray(self.half_extents)
        positions = [_uniform_in_box(rng, r.shape[0], center, half)
                     for rng, r in zip(rngs, radii, strict=True)]
        pending = [np.arange(r.shape[0]) for r in radii]
        if len(boxes) == 0:
            return positions
        for rounds in range(1, MAX_PLACEMENT_ROUNDS + 1):
            active = [j for j, p in enumerate(pending) if p.size]
            # the first round tests every sphere: whole arrays, not gathered copies
            need = [radii[j] + self.clearance if rounds == 1
                    else radii[j][pending[j]] + self.clearance for j in active]
            points = [positions[j] if rounds == 1 else positions[j][pending[j]]
                      for j in active]
            distance, _ = boxes.nearest(
                points[0] if len(active) == 1 else np.concatenate(points),
                within=need[0] if len(active) == 1 else np.concatenate(need))
            offset = 0
            for j, need_j in zip(active, need, strict=True):
                n = radii[j].shape[0]
                clear = distance[offset:offset + need_j.size] >= need_j
                offset += need_j.size
                pending[j] = pending[j][~clear]
                if pending[j].size == 0:
                    continue
                if (pending[j].size == n and HOPELESS_ROUNDS <= rounds < MAX_PLACEMENT_ROUNDS
                        and rounds * n >= MAX_PLACEMENT_ROUNDS):
                    raise ValueError(
                        f"emitter region is too crowded: not one of {rounds * n} draws ({rounds} "
                        f"for each of the {n} spheres) was clear of the obstacles (signed "
                        f"distance >= radius + clearance), so spawning stopped early; the "
                        f"obstacles fill (almost) all of the region ({self._region()}): move or "
                        f"enlarge it, or use smaller spheres")
                if rounds < MAX_PLACEMENT_ROUNDS:
                    positions[j][pending[j]] = center + half * rngs[j].uniform(
                        -1.0, 1.0, size=(pending[j].size, 3))
            if not any(p.size for p in pending):
                return positions
        j = next(j for j, p in enumerate(pending) if p.size)
        raise ValueError(
            f"emitter region is too crowded: {pending[j].size} of {radii[j].shape[0]} spheres "
            f"were not clear of the obstacles (signed distance >= radius + clearance) in "
            f"{MAX_PLACEMENT_ROUNDS} draws each; the obstacles fill almost all of the region "
            f"({self._region()}): move or enlarge it, or use smaller spheres")


def _uniform_in_box(rng: np.random.Generator, n: int, center: np.ndarray,
                    half: np.ndarray) -> np.ndarray:
    """``center + half * rng.uniform(-1.0, 1.0, size=(n, 3))`` bit for bit, ``rng`` left where
    that draw leaves it, the rows computed in blocks on every core."""
    stream, done = row_streams(rng, n)
    out = np.empty((n, 3))

    def block(rows: slice) -> None:
        draw = stream(3 * rows.start).uniform(-1.0, 1.0, size=(rows.stop - rows.start, 3))
        draw *= half
        np.add(center, draw, out=out[rows])

    for_row_blocks(n, block)
    done(3 * n)
    return out


def _orthonormal_pair(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing the unit ``axis`` to a right-handed orthonormal basis."""
    helper = (np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < HELPER_AXIS_COS
              else np.array([0.0, 1.0, 0.0]))
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)
