"""The exact reference: the same physics without a time step, event by event, in float64.

Between contacts each sphere follows its exact parabola ``x(s) = x0 + u s + 1/2 g s^2`` [m]
(``u`` [m/s] the true velocity, ``s`` [s] the time since the last event). The first contact
with the obstacles is found by *conservative advancement on separating planes*: at the current
point ``x``, each box's nearest core point ``p`` and outward normal ``n`` give the plane
``n . (z - p) = 0`` with the whole core box behind it (it is convex), so the distance from the
centre to the core box is at least ``L(s) = n . (x(s) - p)`` for every ``s``. ``L`` is a
quadratic in ``s``; the sphere cannot reach the rounded box (distance ``R = rb + r``) before
``L(s) = R``, so it is advanced exactly to the first such time over all boxes (the descending
root of the quadratic), and the planes are rebuilt there. The step can never jump over a root
(the true distance is never below ``L``); against a face the plane *is* the surface and one step
lands on the contact, against an edge or a corner the steps converge on it (at least halving the
distance to a grazing point each time). A contact is a landing within ``CONTACT_ZONE_ULPS``
rounding units of the surface (7e-14 m for room-sized coordinates) while the sphere moves into
it: contact times are exact to float64 rounding divided by the normal speed. An arc whose apex
only touches a face is not deflected. For a point sphere (``R = 0``) the target is
``POINT_SKIN_ULPS`` rounding units short of the surface, so that rounding can never put it on
the far side of a zero-thickness plate.

At a contact the velocity reflects, ``u' = u - 2 (u . n) n``, and with
``scene.energy_retention = k < 1`` the whole velocity is scaled by ``sqrt(k)`` (the kinetic
energy at the contact times ``k``). Several simultaneous contacts (a corner between two walls)
reflect one after the other, the most head-on first.

Support (resting and sliding) contacts: a sphere touching a box with a normal speed, into or out
of it, of at most ``RESTING_SPEED`` (5 mm/s, a hop of at most 1.3 micrometres) while gravity
presses it onto that surface does not bounce: the normal part of its velocity is removed (energy
lost: at most ``1/2 m RESTING_SPEED^2``) and it slides, frictionless, with the tangential part
of gravity, ``g - (g . n) n``, along the surface's tangent plane (with two supports, along their
crease, both kept until the slide ends; with three it rests). On a face that is exact: it
slides along the face plane until its contact point leaves the face's rectangle, or it meets
another box. On an edge or a corner (a curved surface) it slides along the tangent plane only
until that plane is ``CURVED_SLIDE_DRIFT`` (0.1 um) above the surface, then falls back onto it:
a sphere slipping off a rounded edge follows the surface within a few times that. A lossy ball
comes to rest after a finite number of bounces (never a Zeno loop of ever smaller hops), and a
ball put on a floor stays there. A sphere that exceeds ``MAX_EVENTS`` contacts is given up
(its remaining samples are NaN and ``incomplete`` says so): in the scenes here that never
happens.

What is not modelled: spin. The model's friction changes only the angular momentum (translation
is not changed by friction: it only turns the spin), and its spin update is defined per frame, so
the reference computes no angular momentum and no orientation. Spheres never interact.

Written independently of the kernels (NumPy only). Units: SI, [m], [s], [m/s].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import validation as check
from ..events import ContactEvents
from ..obstacles import quat_to_matrix
from ..scene import Scene
from ..swarm import Swarm
from ..vocabulary import ContactKind

#: A landing this close to a surface, in units of the float64 rounding of the scene's
#: coordinates, is a contact: far above the rounding of the distance (a few units), far below
#: any physical length (7e-14 m at 5 m from the origin).
CONTACT_ZONE_ULPS = 64.0

#: Where ``R = rb + r`` is below this many rounding units (a point against a plate or a sharp
#: edge), the advancement stops this far short of the surface so that the side it came from is
#: never lost to rounding (3e-13 m at 5 m from the origin).
POINT_SKIN_ULPS = 256.0

#: A contact whose normal speed is at most this [m/s] while gravity presses the sphere onto the
#: surface is a support (the sphere slides or rests), not a bounce: the bounce it replaces
#: would rise at most 1.3 micrometres.
RESTING_SPEED = 5e-3

#: Gravity "presses" a sphere onto a surface when ``g . n`` is below ``-GRAVITY_PRESS_REL |g|``:
#: a wall exactly parallel to gravity (``g . n`` zero but for rounding) supports nothing.
GRAVITY_PRESS_REL = 1e-9

#: On an edge or corner support the sphere slides along the tangent plane until the plane is at
#: most this far [m] above the curved surface, then falls back to it (0.1 um: below any error
#: the study measures, and the fall lands at 1.4 mm/s, below ``RESTING_SPEED``).
CURVED_SLIDE_DRIFT = 1e-7

#: The smallest curvature radius [m] assumed for that slide: a point on a sharp edge (R = 0)
#: still makes progress along its tangent plane.
CURVED_SLIDE_MIN_RADIUS = 1e-3

#: A face support lasts only when the contact point stays on the face for at least this long
#: [s]; a sphere at the face's border moving out slides over the edge as on a curved surface.
FACE_SLIDE_MIN_TIME = 1e-9

#: Contacts (bounces and supports) per sphere before it is given up: a guard, never reached in
#: the bundled scenes (a 5 s room run takes a few dozen).
MAX_EVENTS = 200_000

#: Advancement steps per sphere before it is given up (the same kind of guard).
MAX_STEPS = 5_000_000

#: Contacts resolved at one point before the sphere is given up (a sphere wedged in a corner
#: that reflects back and forth without moving).
MAX_CONTACTS_AT_ONE_POINT = 64

#: Steps in a row that advance time by nothing before the sphere is given up (a guard against
#: a loop that makes no progress; none is known).
MAX_STALLED_STEPS = 1000

@dataclass
class ReferenceRun:
    """The exact motion of a swarm, sampled at given times.

    Attributes:
        times: sample times [s], shape (T,), as given.
        position: sphere centres at those times [m], shape (T, N, 3), float64.
        velocity: true velocities at those times [m/s], shape (T, N, 3), float64.
        events: every sphere's contacts (:class:`warpsim.ContactEvents` without frames: time,
            sphere, box, normal, position, approach speed, :class:`warpsim.ContactKind`), by
            sphere then time; ``events.of_sphere(i)`` holds sphere ``i``'s.
        incomplete: spheres given up (``MAX_EVENTS``, ``MAX_STEPS``), shape (N,); their samples
            after that point are NaN.
        steps: advancement steps taken per sphere, shape (N,) (cost, for information).
        t_end: simulated duration [s].
    """

    times: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    events: ContactEvents
    incomplete: np.ndarray
    steps: np.ndarray
    t_end: float

    def energy(self, scene: Scene, swarm: Swarm) -> np.ndarray:
        """Total energy ``1/2 m |u|^2 - m g . x`` [J] at each sample, shape (T, N)."""
        g = np.asarray(scene.gravity)
        m = np.asarray(swarm.mass)
        return m * (0.5 * np.einsum("tni,tni->tn", self.velocity, self.velocity)
                    - self.position @ g)


def simulate(scene: Scene, swarm: Swarm, t_end: float, times=None) -> ReferenceRun:
    """The exact motion of every sphere of ``swarm`` among ``scene``'s boxes up to ``t_end``.

    Args:
        scene: obstacles, gravity and ``energy_retention`` (friction, spin and the energy
            correction do not change the exact translation).
        swarm: initial state; ``velocity`` is the true velocity at time 0 [m/s].
        t_end: duration [s], > 0.
        times: sample times [s] in ``[0, t_end]``, any order, shape (T,); None for
            ``[0, t_end]``.

    Returns:
        :class:`ReferenceRun`.

    Raises:
        ValueError: a bad argument, or a sphere starting inside an obstacle (naming it).
    """
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a warpsim.Scene, got {type(scene).__name__}")
    if not isinstance(swarm, Swarm):
        raise ValueError(f"swarm must be a warpsim.Swarm, got {type(swarm).__name__}")
    t_end = check.scalar("t_end", t_end, positive=True)
    times = _sample_times(times, t_end)
    world = _World(scene)
    n = len(swarm)
    position = np.full((len(times), n, 3), np.nan)
    velocity = np.full((len(times), n, 3), np.nan)
    events, incomplete, steps = [], np.zeros(n, bool), np.zeros(n, np.int64)
    order = np.argsort(times, kind="stable")
    sorted_times = times[order]
    for i in range(n):
        flight = _Flight(world, swarm.position[i], swarm.velocity[i], float(swarm.radius[i]), i)
        pos, vel = flight.run(t_end, sorted_times)
        position[order, i] = pos
        velocity[order, i] = vel
        events.append(flight.events())
        incomplete[i] = flight.incomplete
        steps[i] = flight.steps
    return ReferenceRun(times=times, position=position, velocity=velocity,
                        events=ContactEvents.concatenate(events),
                        incomplete=incomplete, steps=steps, t_end=t_end)


# -- internals ---------------------------------------------------------------------------------


def _sample_times(times, t_end: float) -> np.ndarray:
    if times is None:
        return np.array([0.0, t_end])
    try:
        arr = np.array(times, dtype=np.float64, copy=True).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"times must be numeric, got {times!r}") from exc
    bad = ~np.isfinite(arr) | (arr < 0.0) | (arr > t_end)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"times[{i}] must be in [0, t_end = {t_end:g}], got {arr[i]:g}")
    return arr


def descending_root(c, b, a) -> np.ndarray:
    """First ``s > 0`` where ``c + b s + 1/2 a s^2`` crosses zero going down (or touches it).

    Elementwise over arrays. Returns ``inf`` where there is none. A quadratic has one descending
    root at most; it is the one where the derivative ``b + a s`` is <= 0. A root at ``s = 0``
    does not count: a contact there has been resolved before the step (a sphere touching a
    surface and moving along it must not stall).
    """
    c, b, a = np.broadcast_arrays(np.asarray(c, float), np.asarray(b, float),
                                  np.asarray(a, float))
    half = 0.5 * a
    out = np.full(c.shape, np.inf)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        disc = b * b - 4.0 * half * c
        real = disc >= 0.0
        sq = np.sqrt(np.where(real, disc, 0.0))
        q = -0.5 * (b + np.where(b >= 0.0, sq, -sq))
        r1 = np.where(q != 0.0, c / q, np.where(c == 0.0, 0.0, np.inf))
        r2 = np.where(half != 0.0, q / half, np.inf)
        for r in (r1, r2):
            ok = real & np.isfinite(r) & (r > 0.0) & (b + a * r <= 0.0)
            out = np.where(ok & (r < out), r, out)
        # linear case (no curvature): b s + c = 0
        lin_root = -c / np.where(b < 0.0, b, -1.0)
        lin = (half == 0.0) & (b < 0.0) & (lin_root > 0.0)
        out = np.where(half == 0.0, np.where(lin, lin_root, np.inf), out)
    return out


def _exit_time(c: float, b: float, a: float) -> float:
    """First ``s >= 0`` where ``c + b s + 1/2 a s^2`` goes below zero: 0 when it is at (or
    below) zero now and going down."""
    if c <= 0.0 and (b < 0.0 or (b == 0.0 and a < 0.0)):
        return 0.0
    return float(descending_root(c, b, a))


class _World:
    """The scene's boxes and constants, float64, world frame."""

    def __init__(self, scene: Scene):
        boxes = scene.boxes
        self.center = np.array(boxes.center, dtype=np.float64)
        self.rotation = quat_to_matrix(boxes.rotation)  # local -> world, (K, 3, 3)
        self.half = np.array(boxes.half_extents, dtype=np.float64)
        self.rounding = np.array(boxes.radius, dtype=np.float64)
        self.gravity = np.array(scene.gravity, dtype=np.float64)
        self.g_norm = float(np.linalg.norm(self.gravity))
        self.keep = float(np.sqrt(scene.energy_retention))
        self.lossy = scene.energy_retention < 1.0
        k = len(boxes)
        self.count = k
        reach = (np.abs(self.center).max(axis=1) + np.linalg.norm(self.half, axis=1)
                 + self.rounding) if k else np.zeros(0)
        self.scale = float(reach.max()) if k else 0.0

    def local(self, x: np.ndarray) -> np.ndarray:
        """World point ``(3,)`` in every box's frame, (K, 3)."""
        return np.einsum("kji,kj->ki", self.rotation, x[None, :] - self.center)

    def to_local_vec(self, v: np.ndarray) -> np.ndarray:
        return np.einsum("kji,j->ki", self.rotation, v)


class _Flight:
    """One sphere's event loop (state: time, position, velocity, supports)."""

    def __init__(self, world: _World, x0, u0, radius: float, index: int):
        self.w = world
        self.x = np.array(x0, dtype=np.float64)
        self.u = np.array(u0, dtype=np.float64)
        self.t = 0.0
        self.reach = world.rounding + radius  # R per box
        scale = max(1.0, world.scale, float(np.abs(self.x).max()))
        ulp = np.finfo(np.float64).eps * scale
        skin = POINT_SKIN_ULPS * ulp
        self.target = np.where(self.reach < skin, skin, 0.0)  # gap aimed at, per box [m]
        self.tol = self.target + CONTACT_ZONE_ULPS * ulp  # a landing within it is a contact
        self.index = index
        self.supports: list[int] = []
        self.support_end = np.inf  # time [s] since the segment start when the slide ends
        self.acc = world.gravity.copy()
        self.incomplete = False
        self.steps = 0
        self._ev: list[tuple] = []
        gap, _, _ = self._geometry(self.x)
        if world.count and np.any(gap < -CONTACT_ZONE_ULPS * ulp):
            k = int(np.argmin(gap))
            raise ValueError(f"sphere {index} starts inside box {k} (gap {gap[k]:.3g} m)")

    # geometry of every box at a point -----------------------------------------------------------

    def _geometry(self, x: np.ndarray):
        """Gap [m] to every rounded box, outward unit normals (world), face flags; (K,)..."""
        w = self.w
        if w.count == 0:
            return np.zeros(0), np.zeros((0, 3)), np.zeros(0, bool)
        y = w.local(x)
        q = np.abs(y) - w.half
        out = np.maximum(q, 0.0)
        n_out = (q > 0.0).sum(axis=1)
        d_out = np.linalg.norm(out, axis=1)
        core = np.where(n_out > 0, d_out, q.max(axis=1))
        sign = np.where(y >= 0.0, 1.0, -1.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            n_local = np.where(d_out[:, None] > 0.0, sign * out / d_out[:, None], 0.0)
        # on or inside the core box (radius-0 spheres on a plate): the least deep axis's face,
        # facing the motion
        flat = d_out <= 0.0
        if flat.any():
            u_local = w.to_local_vec(self.u)
            for k in np.flatnonzero(flat):
                a = int(np.argmax(q[k]))
                s = sign[k, a] if y[k, a] != 0.0 else (-1.0 if u_local[k, a] > 0.0 else 1.0)
                n_local[k] = 0.0
                n_local[k, a] = s
        normal = np.einsum("kij,kj->ki", w.rotation, n_local)
        return core - self.reach, normal, n_out <= 1

    # the loop ---------------------------------------------------------------------------------

    def run(self, t_end: float, times: np.ndarray):
        """Advance to ``t_end``; positions and velocities at the sorted ``times``."""
        pos = np.full((len(times), 3), np.nan)
        vel = np.full((len(times), 3), np.nan)
        self._pos, self._vel, self._times, self._next = pos, vel, times, 0
        g = self.w.gravity
        stalled = 0
        while True:
            gap, normal, face = self._geometry(self.x)
            if not self._resolve_contacts(gap, normal, face):
                break
            s = self._next_step(gap, normal)
            if self.t + s >= t_end:
                self._sample_until(t_end, inclusive=True)
                self.x, self.u = self._at(t_end - self.t)
                self.t = t_end
                break
            self._sample_until(self.t + s, inclusive=False)
            ended_slide = self.supports and s >= self.support_end
            self.x, self.u = self._at(s)
            self.t += s
            self.support_end -= s
            self.steps += 1
            if ended_slide:
                self.supports = []
                self.acc = g.copy()
                self.support_end = np.inf
            stalled = stalled + 1 if s <= 0.0 else 0
            if self.steps > MAX_STEPS or stalled > MAX_STALLED_STEPS:
                self.incomplete = True
                break
        return pos, vel

    def _at(self, s: float):
        return self.x + self.u * s + 0.5 * self.acc * (s * s), self.u + self.acc * s

    def _sample_until(self, t_stop: float, inclusive: bool) -> None:
        times = self._times
        j = self._next
        while j < len(times) and (times[j] < t_stop or (inclusive and times[j] <= t_stop)):
            x, u = self._at(times[j] - self.t)
            self._pos[j], self._vel[j] = x, u
            j += 1
        self._next = j

    def _event(self, box: int, normal: np.ndarray, speed: float, kind: ContactKind) -> bool:
        self._ev.append((self.t, box, normal.copy(), self.x.copy(), speed, kind))
        if len(self._ev) > MAX_EVENTS:
            self.incomplete = True
            return False
        return True

    def _presses(self, normal: np.ndarray) -> bool:
        return float(self.w.gravity @ normal) < -GRAVITY_PRESS_REL * self.w.g_norm

    def _resolve_contacts(self, gap, normal, face) -> bool:
        """Reflect off, or rest on, every box in contact that the sphere moves into.

        Returns False when the sphere is given up.
        """
        if self.w.count == 0:
            return True
        contact = gap <= self.tol
        if self.supports:
            contact[self.supports] = False
        if not contact.any():
            return True
        changed_supports = False
        for _ in range(MAX_CONTACTS_AT_ONE_POINT):
            un = normal @ self.u
            approaching = contact & (un < 0.0)
            if not approaching.any():
                break
            j = int(np.flatnonzero(approaching)[np.argmin(un[approaching])])
            speed = -float(un[j])
            if speed <= RESTING_SPEED and self._presses(normal[j]):
                self.supports.append(j)
                contact[j] = False
                changed_supports = True
                if not self._event(j, normal[j], speed, ContactKind.SUPPORT):
                    return False
            else:
                self.u = self.u - 2.0 * un[j] * normal[j]
                if self.w.lossy:
                    self.u = self.u * self.w.keep
                if not self._event(j, normal[j], speed, ContactKind.BOUNCE):
                    return False
                if self.supports:  # a bounce ends a slide; supports are found again below
                    self.supports = []
                    changed_supports = True
                    contact = gap <= self.tol
        else:
            self.incomplete = True
            return False
        # slow departures and spheres already on a surface (a ball put on a floor) are supports
        un = normal @ self.u
        for j in np.flatnonzero(contact & (np.abs(un) <= RESTING_SPEED)):
            if j not in self.supports and self._presses(normal[j]):
                self.supports.append(int(j))
                changed_supports = True
                if not self._event(int(j), normal[j], -float(un[j]), ContactKind.SUPPORT):
                    return False
        if changed_supports:
            self._start_slide(gap, normal, face)
        return True

    def _start_slide(self, gap, normal, face) -> None:
        """Project velocity and gravity onto the supports' tangent space; when the slide ends."""
        g = self.w.gravity
        if not self.supports:
            self.acc = g.copy()
            self.support_end = np.inf
            return
        basis = []
        for j in self.supports:  # Gram-Schmidt over the support normals
            v = normal[j].copy()
            for b in basis:
                v -= (v @ b) * b
            size = np.linalg.norm(v)
            if size > 1e-9:  # a repeated normal adds no constraint
                basis.append(v / size)
        u, acc = self.u.copy(), g.copy()
        for b in basis:
            u -= (u @ b) * b
            acc -= (acc @ b) * b
        self.u, self.acc = u, acc
        end = np.inf
        for j in self.supports:
            t_face = self._face_exit(j, normal[j]) if face[j] else 0.0
            if t_face > FACE_SLIDE_MIN_TIME:
                end = min(end, t_face)
            else:  # curved support: slide along the tangent plane while it stays within drift
                radius = max(float(self.reach[j]), CURVED_SLIDE_MIN_RADIUS)
                reach = np.sqrt(2.0 * radius * CURVED_SLIDE_DRIFT)
                end = min(end, float(descending_root(reach, -np.linalg.norm(u),
                                                     -np.linalg.norm(acc))))
        self.support_end = end

    def _face_exit(self, j: int, normal: np.ndarray) -> float:
        """Time [s] until the contact point sliding on face ``j`` leaves its rectangle."""
        w = self.w
        rot = w.rotation[j]
        y = rot.T @ (self.x - w.center[j])
        vel = rot.T @ self.u
        acc = rot.T @ self.acc
        axis = int(np.argmax(np.abs(rot.T @ normal)))
        end = np.inf
        for b in range(3):
            if b == axis:
                continue
            h = w.half[j, b]
            end = min(end, _exit_time(h - y[b], -vel[b], -acc[b]),
                      _exit_time(h + y[b], vel[b], acc[b]))
        return end

    def _next_step(self, gap, normal) -> float:
        """Time [s] to the next point where a separating plane reaches its target gap."""
        step = self.support_end
        if self.w.count:
            roots = descending_root(gap - self.target, normal @ self.u, normal @ self.acc)
            if self.supports:
                roots[self.supports] = np.inf
            step = min(step, float(roots.min()))
        return step

    def events(self) -> ContactEvents:
        """This sphere's contacts, in time order."""
        ev = self._ev
        if not ev:
            return ContactEvents.empty(frames=False)
        return ContactEvents(time=np.array([e[0] for e in ev]),
                             sphere=np.full(len(ev), self.index, dtype=np.int64),
                             box=np.array([e[1] for e in ev], dtype=np.int32),
                             normal=np.array([e[2] for e in ev]),
                             position=np.array([e[3] for e in ev]),
                             normal_speed=np.array([e[4] for e in ev]),
                             kind=np.array([e[5] for e in ev], dtype=np.int8))
