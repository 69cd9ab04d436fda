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
of it, of at most ``RESTING_SPEED`` (5 mm/s, a hop of at most 1.3 micrometres) while the box can
hold it does not bounce: the normal part of its velocity is removed (energy lost: at most
``1/2 m RESTING_SPEED^2``) and it slides, frictionless (translation has no friction in the
model), held by the acceleration ``lambda n`` along the outward normal, ``lambda = -|v_perp|^2 / R
- g . n`` (``v_perp`` the velocity without its component along an edge's axis; all of it on a
corner; ``lambda = -g . n`` on a face). The box holds the sphere while gravity presses it onto the
surface and ``lambda >= 0``. Every support's end is an event, found to float64 resolution:

- on a face the centre follows the face-frame parabola (gravity less its normal part) until the
  contact point leaves the face's rectangle (a root of that parabola);
- on a rounded edge (the cylinder of radius ``R`` about a core edge; ``R = r`` on a sharp edge)
  the centre's offset from the edge line is integrated by a Taylor series of order
  ``ARC_TAYLOR_ORDER`` whose steps keep the truncation below ``ARC_STEP_REL_TOL R``, the offset
  put back on the circle and the energy restored at each step (energy holds to rounding); along
  the axis the motion is the free parabola. On a rounded corner (the sphere of radius ``R`` about
  a core corner) the same series integrates all three offsets (see ``_Arc``);
- a curved slide ends where ``lambda`` reaches 0 (detachment: free flight from there), where the
  contact point leaves the edge's or corner's region (between the adjacent faces' normals;
  onto a face: the face slide, or onto an edge from a corner, or a corner from an edge's end,
  or free flight where the new region cannot hold it), or when the centre meets another box
  (found by the same advancement, with the support's push bounded by ``|g|``). Each end is a
  crossing of the integrated solution (a Taylor polynomial) bisected to float64 resolution,
  and samples inside a slide are the series at those times.
- a sphere reaching an edge with ``|v_perp|^2 / R > -g . n`` (e.g. at 1 m/s over a sharp edge
  with ``r = 0.1``) leaves at once into free flight. Leaving a curve tangentially, the free
  path stays off that curve's surface for a time known in closed form (the parabola of the
  offset against ``R``); the box is not advanced against until then, as the separating planes
  would only creep along the tangent. A slow contact (at most ``RESTING_SPEED``) on a curve
  that cannot hold the sphere is a support that ends at once: its normal speed is removed and
  the sphere leaves tangentially.

Against analytic slides (``tests/test_reference_supports.py``: closed forms and quadrature of the
energy integral) the reference agrees to 1e-15 m near the origin (1e-13 m on turned and tilted
boxes, 1e-12 m from a release 0.1 degree off the top, where the unstable start amplifies
rounding) and 4e-11 m at 1 km: far within the 1e-9 m it claims.

With several supports at once (along their crease, or a rest on three) the sphere slides along the
supports' common tangent space; where a curve is among them it does so until that plane is
``CURVED_SLIDE_DRIFT`` (0.1 um) above the surface, then falls back onto it, and so does a point-
sized sphere (``R`` below ``POINT_SKIN_ULPS``) on an edge. A lossy ball comes to rest after a
finite number of bounces (never a Zeno loop of ever smaller hops), and a ball put on a floor stays
there. A sphere that exceeds ``MAX_EVENTS`` contacts (or another guard, ``MAX_*``) is given up (its
remaining samples are NaN and ``incomplete`` says so): in the scenes here that never happens.

What is not modelled: spin. The model's friction changes only the angular momentum (translation
is not changed by friction: it only turns the spin), and its spin update is defined per frame, so
the reference computes no angular momentum and no orientation. Spheres never interact.

Written independently of the kernels (NumPy only). Units: SI, [m], [s], [m/s].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import polynomial as P

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

#: Where two or more supports act together and one of them is an edge or a corner (a sphere
#: wedged between a rounded edge and another box), the sphere slides along the supports' common
#: tangent space until it is at most this far [m] above the curved surface, then falls back to
#: it (0.1 um; the fall lands at 1.4 mm/s, below ``RESTING_SPEED``). A single curved support is
#: followed exactly (see ``_Arc``).
CURVED_SLIDE_DRIFT = 1e-7

#: The smallest curvature radius [m] assumed for that crease slide: a point on a sharp edge
#: (R = 0) still makes progress along its tangent plane.
CURVED_SLIDE_MIN_RADIUS = 1e-3

#: Order of the Taylor series that integrates a slide on a rounded edge or corner: high enough
#: that a step covers a good part of the slide (a few hundredths of a second at R ~ 0.1 m).
ARC_TAYLOR_ORDER = 30

#: Truncation error allowed per Taylor step, relative to R: far below the float64 rounding of
#: the position, so the slide is exact to rounding.
ARC_STEP_REL_TOL = 1e-18

#: Sample points per Taylor step at which an event function (normal force, region border) is
#: tested for a sign change before the crossing is bisected to float64 resolution.
ARC_EVENT_SAMPLES = 48

#: Taylor steps of one slide before the sphere is given up (a guard: a slide takes tens).
MAX_ARC_STEPS = 100_000

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


def _first_crossing(coeffs: np.ndarray, h: float, rising: bool) -> float:
    """First ``tau`` in ``(0, h]`` where the polynomial ``sum coeffs[k] tau^k`` goes above 0
    (``rising``) or to 0 and below (not ``rising``), bisected to float64 resolution; ``inf``
    when the samples show none (a touch between two samples is not a crossing)."""
    taus = np.linspace(0.0, h, ARC_EVENT_SAMPLES + 1)
    f = P.polyval(taus, coeffs)
    past = f > 0.0 if rising else f <= 0.0
    if past[0]:
        if rising or P.polyval(0.0, P.polyder(coeffs)) <= 0.0:
            return 0.0
        # an offset that starts on its border moving out: the crossing is its next one
        inside = np.flatnonzero(~past)
        if not len(inside):
            return np.inf
        past[:inside[0]] = False
    hits = np.flatnonzero(past)
    if not len(hits):
        return np.inf
    lo, hi = taus[hits[0] - 1], taus[hits[0]]
    while True:
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            return hi
        value = P.polyval(mid, coeffs)
        if (value > 0.0) if rising else (value <= 0.0):
            hi = mid
        else:
            lo = mid


class _Feature:
    """Where on box ``j`` a sphere centre is, seen from the box's frame: the core edge or
    corner it is nearest to (``out``: the local axes along which it is beyond the core box,
    with their ``sign``), its offset ``w`` [m] from that edge line or corner point along those
    axes (signed outward), and the rates of ``w``. A centre within ``tol`` [m] of a region's
    border counts on the side it moves to (its velocity, then gravity, decide)."""

    def __init__(self, world: _World, j: int, x, u, tol: float):
        rot = world.rotation[j]
        self.rot, self.center, self.half = rot, world.center[j], world.half[j]
        self.y, self.vy, self.gy = rot.T @ (x - self.center), rot.T @ u, rot.T @ world.gravity
        lead = np.where(self.y != 0.0, self.y, np.where(self.vy != 0.0, self.vy, self.gy))
        self.sign = np.where(lead >= 0.0, 1.0, -1.0)
        o = np.abs(self.y) - self.half
        moving_out = np.where(self.vy != 0.0, self.sign * self.vy, self.sign * self.gy) > 0.0
        self.out = np.flatnonzero((o > tol) | ((np.abs(o) <= tol) & moving_out))
        self.w = self.sign[self.out] * self.y[self.out] - self.half[self.out]
        self.dw = self.sign[self.out] * self.vy[self.out]
        self.g = self.sign[self.out] * self.gy[self.out]

    @property
    def curved(self) -> bool:
        return len(self.out) >= 2

    def normal_force(self, radius: float) -> float:
        """``lambda = -|v_perp|^2 / R - g . n`` [m/s^2] of the curved support there."""
        n = self.w / max(float(np.linalg.norm(self.w)), np.finfo(float).tiny)
        dw = self.dw - (self.dw @ n) * n
        if radius <= 0.0:
            return -np.inf if dw @ dw > 0.0 else -float(self.g @ n)
        return -float(dw @ dw) / radius - float(self.g @ n)

    def clearance(self, radius: float) -> float:
        """How long [s] free flight from here stays off this feature's surface: until the
        free parabola of ``w`` (a lower bound of the distance to the core box while every
        offset stays positive) comes back to ``|w| = R``, or an offset reaches zero (the path
        enters another region, where the box's planes take over). The start is on the surface
        with a tangent velocity and a normal force <= 0, so ``|w(s)|^2 - R^2 = s^2 (c2 + c3 s +
        c4 s^2)`` with ``c2 >= 0``."""
        w, dw, g = self.w, self.dw, self.g
        n = w / max(float(np.linalg.norm(w)), np.finfo(float).tiny)
        dw = dw - (dw @ n) * n
        c2 = max(float(dw @ dw + (radius * n) @ g), 0.0)
        back = float(descending_root(c2, float(dw @ g), 0.5 * float(g @ g)))
        exits = descending_root(w, dw, g)
        return min(back, float(exits.min()))


class _Arc:
    """A frictionless slide on the cylinder of a core edge or the sphere of a core corner.

    The offset ``w`` [m] of the centre from the edge line (2 components, the edge's axes) or
    corner point (3 components), in the box frame and signed outward, obeys
    ``w'' = g_w - mu w`` with ``mu = (|w'|^2 + w . g_w) / R^2``: the support's acceleration
    ``lambda n`` with ``lambda = -R mu`` keeps ``|w| = R`` (it is the motion on the surface,
    ``lambda = -|v_perp|^2 / R - g . n``). That system is polynomial, so its Taylor series is
    built term by term (order ``ARC_TAYLOR_ORDER``) and each step is as long as the series
    stays below ``ARC_STEP_REL_TOL`` R; at each step's start ``w`` is put back on the surface,
    ``w'`` made tangent and its size set from the energy ``1/2 |w'|^2 - g_w . w`` of the start:
    the energy holds to float64 rounding. Along an edge's axis the motion is the free parabola.
    The slide ends at the first of: the normal force reaching 0 (``mu`` rising through 0:
    detachment), an offset reaching 0 (the contact point enters a face's region, or an edge's
    from a corner), the contact point passing an end of the edge (a corner's region), or the
    horizon. Each is a crossing of a Taylor polynomial (or the axial parabola) bisected to
    float64 resolution. ``state(tau)`` is the motion ``tau`` [s] after the start, from the
    series (dense output).
    """

    def __init__(self, feature: _Feature, radius: float, horizon: float):
        f = feature
        self.f, self.radius = f, radius
        self.axial = [a for a in range(3) if a not in f.out]
        r2 = radius * radius
        n = f.w / np.linalg.norm(f.w)
        dw = f.dw - (f.dw @ n) * n
        energy = 0.5 * float(dw @ dw) - float(f.g @ f.w)
        w = radius * n
        self.starts, self.series = [], []
        tau, self.end, self.reason = 0.0, horizon, "horizon"
        order = ARC_TAYLOR_ORDER
        for a in self.axial:  # the contact point passing an end of the edge: a corner
            h, y, v, g = f.half[a], f.y[a], f.vy[a], f.gy[a]
            t_axis = min(_exit_time(h - y, -v, -g), _exit_time(h + y, v, g))
            if t_axis < self.end:
                self.end, self.reason = t_axis, "exit"
        while tau < self.end:
            if len(self.starts) > MAX_ARC_STEPS:
                raise _GiveUp
            coeffs, mu = self._taylor(w, dw, f.g, r2, order)
            size = np.abs(coeffs[order - 1:]).max(axis=1)
            powers = 1.0 / np.arange(order - 1, order + 1)
            with np.errstate(divide="ignore"):
                reach = (ARC_STEP_REL_TOL * radius / size) ** powers
            h = min(float(reach.min()), self.end - tau)
            self.starts.append(tau)
            self.series.append(coeffs)
            end = _first_crossing(mu, h, rising=True)
            reason = "detach"
            for b in range(len(w)):
                t_b = _first_crossing(coeffs[:, b], h, rising=False)
                if t_b < end:
                    end, reason = t_b, "exit"
            if end <= h and tau + end < self.end:
                self.end, self.reason = tau + end, reason
                break
            tau += h
            w, dw = P.polyval(h, coeffs), P.polyval(h, P.polyder(coeffs))
            size = np.linalg.norm(w)
            w = radius * w / size
            dw = dw - (dw @ w) * w / r2
            speed2 = 2.0 * (energy + float(f.g @ w))
            norm = float(np.linalg.norm(dw))
            if norm > 0.0:
                dw = dw * (np.sqrt(max(speed2, 0.0)) / norm)
        self.starts = np.array(self.starts)

    @staticmethod
    def _taylor(w, dw, g, r2: float, order: int):
        """Taylor coefficients of ``w`` (order + 1, d) and of ``mu`` (order - 1,)."""
        coeffs = np.zeros((order + 1, len(w)))
        mu = np.zeros(order - 1)
        coeffs[0], coeffs[1] = w, dw
        for k in range(order - 1):
            rate = coeffs[1:k + 2] * np.arange(1, k + 2)[:, None]
            mu[k] = (np.sum(rate * rate[::-1]) + coeffs[k] @ g) / r2
            pull = mu[:k + 1] @ coeffs[k::-1]
            coeffs[k + 2] = ((g if k == 0 else 0.0) - pull) / ((k + 1) * (k + 2))
        return coeffs, mu

    def state(self, tau: float):
        """World position [m] and velocity [m/s] ``tau`` [s] after the start."""
        f = self.f
        i = max(int(np.searchsorted(self.starts, tau, side="right")) - 1, 0)
        coeffs = self.series[i]
        s = tau - self.starts[i]
        w, dw = P.polyval(s, coeffs), P.polyval(s, P.polyder(coeffs))
        y, vy = np.empty(3), np.empty(3)
        y[f.out] = f.sign[f.out] * (f.half[f.out] + w)
        vy[f.out] = f.sign[f.out] * dw
        for a in self.axial:
            y[a] = f.y[a] + f.vy[a] * tau + 0.5 * f.gy[a] * tau * tau
            vy[a] = f.vy[a] + f.gy[a] * tau
        return f.center + f.rot @ y, f.rot @ vy


class _GiveUp(Exception):
    """A guard (``MAX_ARC_STEPS``) was reached: the sphere is given up."""


class _Flight:
    """One sphere's event loop (state: time, position, velocity, supports, the slide on a
    curved support ``arc`` and the box it has just left ``skip``)."""

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
        self.arc: _Arc | None = None  # the slide on a single curved support
        self.arc_t0 = 0.0  # its start time [s]
        self.skip: tuple[int, float] | None = None  # (box, until [s]): just left its curve
        self.t_end = np.inf
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
        self.t_end = t_end
        stalled = 0
        while True:
            if self.skip is not None and self.t >= self.skip[1]:
                self.skip = None
            gap, normal, face = self._geometry(self.x)
            try:
                resolved = self._resolve_contacts(gap, normal, face)
            except _GiveUp:
                resolved, self.incomplete = False, True
            if not resolved:
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
                try:
                    self._end_slide()
                except _GiveUp:
                    self.incomplete = True
                    break
            stalled = stalled + 1 if s <= 0.0 else 0
            if self.steps > MAX_STEPS or stalled > MAX_STALLED_STEPS:
                self.incomplete = True
                break
        return pos, vel

    def _at(self, s: float):
        """Position and velocity ``s`` [s] after the current time."""
        if self.arc is not None:
            return self.arc.state(self.t - self.arc_t0 + s)
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

    def _in_contact(self, gap) -> np.ndarray:
        """Boxes within the contact zone, without the supports and the curve just left."""
        contact = gap <= self.tol
        if self.supports:
            contact[self.supports] = False
        if self.skip is not None:
            contact[self.skip[0]] = False
        return contact

    def _holds(self, j: int, normal: np.ndarray) -> bool | None:
        """Whether box ``j`` can support the sphere where it is: gravity presses, and on an
        edge or a corner the normal force ``lambda`` is >= 0 too. None: a curve that cannot
        hold it (it leaves the surface at once)."""
        if not self._presses(normal):
            return False
        if self.target[j] > 0.0:  # point-sized R: the crease rule of _start_slide
            return True
        feature = _Feature(self.w, j, self.x, self.u, float(self.tol[j]))
        if feature.curved and feature.normal_force(float(self.reach[j])) < 0.0:
            return None
        return True

    def _leave(self, j: int, normal: np.ndarray) -> None:
        """Leave the curve of box ``j`` tangentially: free flight, box ``j`` ignored while the
        free path provably stays off its surface (``_Feature.clearance``)."""
        self.u = self.u - (self.u @ normal) * normal
        feature = _Feature(self.w, j, self.x, self.u, float(self.tol[j]))
        self.skip = (j, self.t + feature.clearance(float(self.reach[j])))

    def _resolve_contacts(self, gap, normal, face) -> bool:
        """Reflect off, or rest on, every box in contact that the sphere moves into.

        Returns False when the sphere is given up.
        """
        if self.w.count == 0:
            return True
        contact = self._in_contact(gap)
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
            holds = self._holds(j, normal[j]) if speed <= RESTING_SPEED else False
            if holds or holds is None:
                # a slow contact: the sphere rests or slides on the box, or, on a curve that
                # cannot hold it, loses its normal speed and leaves tangentially
                contact[j] = False
                if not self._event(j, normal[j], speed, ContactKind.SUPPORT):
                    return False
                if holds:
                    self.supports.append(j)
                    changed_supports = True
                else:
                    self._leave(j, normal[j])
            else:
                self.u = self.u - 2.0 * un[j] * normal[j]
                if self.w.lossy:
                    self.u = self.u * self.w.keep
                if not self._event(j, normal[j], speed, ContactKind.BOUNCE):
                    return False
                if self.supports:  # a bounce ends a slide; supports are found again below
                    self.supports = []
                    changed_supports = True
                    contact = self._in_contact(gap)
        else:
            self.incomplete = True
            return False
        # slow departures and spheres already on a surface (a ball put on a floor) are supports
        un = normal @ self.u
        for j in np.flatnonzero(contact & (np.abs(un) <= RESTING_SPEED)):
            if j in self.supports:
                continue
            holds = self._holds(int(j), normal[j])
            if holds:
                self.supports.append(int(j))
                changed_supports = True
                if not self._event(int(j), normal[j], -float(un[j]), ContactKind.SUPPORT):
                    return False
            elif holds is None:
                self._leave(int(j), normal[j])
        if changed_supports:
            self._start_slide(gap, normal, face)
        return True

    def _start_slide(self, gap, normal, face) -> None:
        """Start the slide on the supports: on one box (not point-sized) exactly, in its face,
        edge or corner (``_follow``); on several, along their common tangent space, until a
        face exit or, with a curve among them, ``CURVED_SLIDE_DRIFT``."""
        g = self.w.gravity
        self.arc = None
        self.acc = g.copy()
        self.support_end = np.inf
        if not self.supports:
            return
        if len(self.supports) == 1 and self.target[self.supports[0]] == 0.0:
            self._follow(self.supports[0])
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
            if t_face > 0.0:
                end = min(end, t_face)
            else:  # curved support: slide along the tangent plane while it stays within drift
                radius = max(float(self.reach[j]), CURVED_SLIDE_MIN_RADIUS)
                reach = np.sqrt(2.0 * radius * CURVED_SLIDE_DRIFT)
                end = min(end, float(descending_root(reach, -np.linalg.norm(u),
                                                     -np.linalg.norm(acc))))
        self.support_end = end

    def _follow(self, j: int) -> None:
        """Slide on box ``j`` alone from here, in the region the centre is in (moves to): on a
        face along the face-frame parabola until the contact point leaves the face, on an edge
        or a corner along the exact curved slide (``_Arc``); or, where the box no longer holds
        the sphere (gravity does not press a face, the normal force of a curve is < 0), free
        flight."""
        g = self.w.gravity
        radius = float(self.reach[j])
        f = _Feature(self.w, j, self.x, self.u, float(self.tol[j]))
        if not f.curved:
            axis = int(f.out[0])
            normal = f.rot[:, axis] * f.sign[axis]
            if not self._presses(normal):
                self.supports = []
                return
            self.u = self.u - (self.u @ normal) * normal
            self.acc = g - (g @ normal) * normal
            self.support_end = self._face_exit(j, normal)
            return
        normal = f.rot[:, f.out] @ (f.sign[f.out] * f.w)
        normal = normal / np.linalg.norm(normal)
        if f.normal_force(radius) < 0.0:
            self.supports = []
            self._leave(j, normal)
            return
        self.arc = _Arc(f, radius, self.t_end - self.t)
        self.arc_t0 = self.t
        self.x, self.u = self.arc.state(0.0)
        self.support_end = self.arc.end

    def _end_slide(self) -> None:
        """The slide's end: a detachment (free flight, leaving the curve), the contact point
        entering another region of the same box (the slide goes on there), or the crease
        rule's end (supports found again)."""
        arc, self.arc = self.arc, None
        self.acc = self.w.gravity.copy()
        self.support_end = np.inf
        single = len(self.supports) == 1 and self.target[self.supports[0]] == 0.0
        if not single or (arc is not None and arc.reason == "horizon"):
            self.supports = []
            return
        j = self.supports[0]
        if arc is not None and arc.reason == "detach":
            self.supports = []
            _, normal, _ = self._geometry(self.x)
            self._leave(j, normal[j])
            return
        self._follow(j)

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
            if self.arc is None:
                acc = normal @ self.acc
            else:  # the support pushes along its normal with 0 <= lambda <= |g|
                acc = normal @ self.acc - self.w.g_norm
            roots = descending_root(gap - self.target, normal @ self.u, acc)
            if self.supports:
                roots[self.supports] = np.inf
            if self.skip is not None:
                roots[self.skip[0]] = np.inf
                step = min(step, self.skip[1] - self.t)
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
