"""Analytic motions of a frictionless sphere supported by a face, a rounded edge or a rounded
corner, for the tests of the reference and of the kernels (imported as ``support_analytic``).

Independent of warpsim: NumPy only, float64. The centre of a sphere of radius ``r`` on a rounded
box of rounding ``rb`` moves on the Minkowski surface of radius ``R = rb + r``: a plane over a
face, a cylinder of radius ``R`` about a core edge, a sphere of radius ``R`` about a core corner.
Frictionless and translation only, the support pushes along the outward normal ``n`` with the
acceleration ``lambda n``, ``lambda = -|v_perp|^2 / R - g . n`` (``v_perp`` the velocity without
its component along a cylinder's axis; all of it on a sphere; ``lambda = -g . n`` on a plane);
the support holds while ``lambda >= 0`` and the sphere flies freely from the instant it is 0.

Closed forms where they exist (parabolas in free flight and on planes, the detachment angles);
elsewhere the time along the surface is the energy integral ``t = int dq / q'(q)`` of one
coordinate ``q`` (the angle from the top on a cylinder, the height on a sphere), computed by
adaptive Gauss-Legendre quadrature to ~1e-15 relative after a substitution ``q = q0 + s^2`` that
removes the square-root singularity of a release from rest, and inverted by safeguarded Newton
iteration. Positions are then exact to ~1e-13 m at metre scale.

Every motion is a :class:`Trajectory`: ``at(times)`` gives positions [m] and velocities [m/s],
world frame, shape (T, 3), at absolute times [s]; ``breaks`` are the instants [s] where one
piece gives way to the next (a detachment, a face exit), ``kinds`` the pieces' names.

Units: SI throughout ([m], [s], [m/s], [m/s^2]).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Relative accuracy asked of each quadrature panel pair: a few float64 rounding units.
QUAD_REL_TOL = 2e-15

#: Bisection depth at which an adaptive quadrature panel is accepted as it is (a guard: smooth
#: integrands settle in under ten).
QUAD_MAX_DEPTH = 40

#: Panels an adaptive quadrature may evaluate before it is refused as not settling (an
#: integrand whose rounding noise lies above ``QUAD_REL_TOL`` would otherwise bisect to
#: ``QUAD_MAX_DEPTH`` everywhere: about 2^40 panels).
QUAD_MAX_PANELS = 20_000

#: Newton iterations allowed to invert t(q) (safeguarded; converges in under ten).
NEWTON_MAX_ITER = 100

#: A speed across the axis below this fraction of the slide's speed scale (``sqrt(G R)`` plus
#: the start's speed) is rounding: a start at rest across the axis.
ROUNDING_SPEED_REL = 1e-14

_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(20)


def _panel(f, a: float, b: float) -> float:
    half, mid = 0.5 * (b - a), 0.5 * (a + b)
    return float(half * np.dot(_GL_WEIGHTS, f(mid + half * _GL_NODES)))


def integrate(f, a: float, b: float) -> float:
    """``int_a^b f`` by adaptive Gauss-Legendre (20 nodes per panel), ``f`` vectorised."""
    if b == a:
        return 0.0
    panels = [0]

    def adapt(lo, hi, whole, depth):
        mid = 0.5 * (lo + hi)
        left, right = _panel(f, lo, mid), _panel(f, mid, hi)
        both = left + right
        panels[0] += 2
        if not np.isfinite(both):
            raise ValueError("the integrand is not finite on the interval")
        if panels[0] > QUAD_MAX_PANELS:
            raise ValueError(f"the quadrature did not settle in {QUAD_MAX_PANELS} panels")
        if abs(both - whole) <= QUAD_REL_TOL * (abs(left) + abs(right)) or depth >= QUAD_MAX_DEPTH:
            return both
        return adapt(lo, mid, left, depth + 1) + adapt(mid, hi, right, depth + 1)

    return adapt(a, b, _panel(f, a, b), 0)


def _invert(time_of, rate_of, t: float, s_hi: float) -> float:
    """The ``s`` in ``[0, s_hi]`` where the increasing ``time_of(s)`` equals ``t``."""
    lo, hi = 0.0, s_hi
    s = 0.5 * (lo + hi)
    for _ in range(NEWTON_MAX_ITER):
        err = time_of(s) - t
        if err > 0.0:
            hi = s
        else:
            lo = s
        rate = rate_of(s)  # dt/ds
        step = s - err / rate if rate > 0.0 else 0.5 * (lo + hi)
        if not lo < step < hi:
            step = 0.5 * (lo + hi)
        if abs(step - s) <= 4.0 * np.finfo(float).eps * max(abs(s), 1e-300) or hi - lo == 0.0:
            return step
        s = step
    return s


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


@dataclass
class Trajectory:
    """A piecewise motion: ``pieces[i]`` holds from ``breaks[i]`` on (``breaks[0]`` the start)."""

    breaks: list[float] = field(default_factory=list)
    pieces: list = field(default_factory=list)
    kinds: list[str] = field(default_factory=list)

    def add(self, t0: float, kind: str, piece) -> None:
        self.breaks.append(float(t0))
        self.kinds.append(kind)
        self.pieces.append(piece)

    def extend(self, other: Trajectory) -> None:
        for t0, kind, piece in zip(other.breaks, other.kinds, other.pieces, strict=True):
            self.add(t0, kind, piece)

    def break_of(self, kind: str) -> float:
        """The start time [s] of the first piece of ``kind`` ("flight", "cylinder", ...)."""
        return self.breaks[self.kinds.index(kind)]

    def at(self, times) -> tuple[np.ndarray, np.ndarray]:
        """Positions [m] and velocities [m/s] at absolute ``times`` [s] (>= the start)."""
        times = np.atleast_1d(np.asarray(times, dtype=np.float64))
        pos, vel = np.empty((len(times), 3)), np.empty((len(times), 3))
        for k, t in enumerate(times):
            i = int(np.searchsorted(self.breaks, t, side="right")) - 1
            pos[k], vel[k] = self.pieces[max(i, 0)](float(t))
        return pos, vel


def _parabola(t0: float, x0, v0, acc):
    x0, v0, acc = (np.array(a, dtype=np.float64) for a in (x0, v0, acc))

    def state(t: float):
        s = t - t0
        return x0 + v0 * s + 0.5 * acc * (s * s), v0 + acc * s

    return state


def free_flight(x0, v0, g, t0: float = 0.0) -> Trajectory:
    """Free flight from ``x0`` [m] with velocity ``v0`` [m/s] at time ``t0`` [s]."""
    out = Trajectory()
    out.add(t0, "flight", _parabola(t0, x0, v0, g))
    return out


def plane_slide(x0, v0, g, normal, t0: float = 0.0) -> Trajectory:
    """A frictionless slide on an unbounded plane of outward unit ``normal`` through ``x0``:
    the velocity ``v0`` [m/s] must lie in the plane and gravity press (``g . n < 0``); the
    acceleration is ``g - (g . n) n``. (The tests end before the contact point leaves the face.)
    """
    n = _unit(normal)
    g = np.asarray(g, dtype=np.float64)
    out = Trajectory()
    out.add(t0, "face", _parabola(t0, x0, v0, g - (g @ n) * n))
    return out


def _crossing_time(c: float, b: float, a: float) -> float:
    """First ``s > 0`` where ``c + b s + 1/2 a s^2`` reaches 0 from below (``c < 0``)."""
    if a == 0.0:
        return -c / b
    disc = b * b - 2.0 * a * c
    if disc < 0.0:
        return np.inf
    q = -(b + np.copysign(np.sqrt(disc), b))
    roots = [r for r in (2.0 * c / q if q != 0.0 else np.inf, q / a) if r > 0.0]
    return min(roots) if roots else np.inf


def cylinder_slide(axis_point, axis, R: float, x0, v0, g, t0: float = 0.0,
                   exit_normal=None) -> Trajectory:
    """A frictionless slide on the cylinder of radius ``R`` [m] about the line through
    ``axis_point`` [m] along ``axis``, then free flight from the detachment.

    Args:
        axis_point, axis: the core edge's line (any point on it, any direction).
        R: the cylinder's radius, ``rb + r`` [m], > 0.
        x0: the centre at ``t0``, on the cylinder [m].
        v0: its velocity [m/s], tangent to the cylinder (no component along the normal).
        g: gravity [m/s^2]; its part across the axis must not vanish.
        t0: start time [s].
        exit_normal: an outward unit normal across the axis where the edge's region ends (the
            adjacent face's normal); when the sphere's normal reaches it before detaching, it
            slides on that face's plane from then on. None: the region never ends.

    The angle ``psi`` from the top (the direction against gravity's part across the axis)
    obeys ``psi'' = (G / R) sin(psi)``, ``G = |g_perp|``, with the energy integral
    ``psi'^2 = w^2 + (2 G / R)(cos psi0 - cos psi)``; the normal force vanishes at
    ``cos psi_d = (2 cos psi0 + R w^2 / G) / 3`` (``w = psi'(t0)``); along the axis the motion
    is the free parabola. A start with ``lambda < 0`` leaves at once. The motion must move
    ``psi`` without turning back (a start moving up towards the top must pass it).

    Returns:
        :class:`Trajectory` with pieces "cylinder" then "flight" (or "face").
    """
    a = _unit(axis)
    c = np.asarray(axis_point, dtype=np.float64)
    x0, v0, g = (np.asarray(v, dtype=np.float64) for v in (x0, v0, g))
    g_axis = float(g @ a)
    g_perp = g - g_axis * a
    G = float(np.linalg.norm(g_perp))
    up = -g_perp / G
    side = np.cross(a, up)  # psi grows from up towards side
    w0 = x0 - c
    s_axis0 = float(w0 @ a)
    radial = w0 - s_axis0 * a
    psi0 = float(np.arctan2(radial @ side, radial @ up))
    v_axis = float(v0 @ a)
    omega = float((v0 - v_axis * a) @ (np.cos(psi0) * side - np.sin(psi0) * up)) / R
    if abs(omega) * R <= ROUNDING_SPEED_REL * (np.sqrt(G * R) + float(np.linalg.norm(v0))):
        omega = 0.0  # a start at rest across the axis, but for rounding: it goes downhill
    sign = 1.0 if omega > 0.0 or (omega == 0.0 and psi0 >= 0.0) else -1.0
    # mirror so that psi increases: q = sign * psi
    q0, w = sign * psi0, abs(omega)
    k = 2.0 * G / R
    if q0 < 0.0 and w * w + k * (np.cos(q0) - 1.0) <= 0.0:
        raise ValueError("the slide turns back before the top: not covered")

    def psi_rate2(s):  # psi'^2 at q = q0 + s^2, without cancellation near the start
        return w * w + 2.0 * k * np.sin(q0 + 0.5 * s * s) * np.sin(0.5 * s * s)

    def time_of(s: float) -> float:
        return integrate(lambda u: 2.0 * u / np.sqrt(psi_rate2(u)), 0.0, s)

    def rate_of(s: float) -> float:
        return 2.0 * s / np.sqrt(psi_rate2(s)) if s > 0.0 else np.inf

    out = Trajectory()
    lam0 = G * np.cos(q0) - R * w * w
    cos_d = (2.0 * np.cos(q0) + R * w * w / G) / 3.0
    q_end = np.arccos(min(1.0, cos_d))
    if lam0 < 0.0 or q_end <= q0:  # the second: lam0 is 0 but for rounding
        out.extend(free_flight(x0, v0, g, t0))
        return out
    end_kind = "flight"
    if exit_normal is not None:
        ne = _unit(exit_normal)
        q_exit = sign * float(np.arctan2(ne @ side, ne @ up))
        q_exit = q_exit + 2.0 * np.pi * np.floor((q0 - q_exit) / (2.0 * np.pi) + 1.0)
        if q_exit < q_end:
            q_end, end_kind = q_exit, "face"
    s_end = np.sqrt(q_end - q0)
    t_end = time_of(s_end)

    def state_at_q(q: float, rate2: float, t: float):
        psi = sign * q
        dpsi = sign * np.sqrt(max(rate2, 0.0))
        n = np.cos(psi) * up + np.sin(psi) * side
        tang = -np.sin(psi) * up + np.cos(psi) * side
        dt = t - t0
        along = s_axis0 + v_axis * dt + 0.5 * g_axis * dt * dt
        return (c + along * a + R * n, (v_axis + g_axis * dt) * a + R * dpsi * tang)

    def state(t: float):
        s = _invert(time_of, rate_of, t - t0, s_end) if t > t0 else 0.0
        return state_at_q(q0 + s * s, psi_rate2(s), t)

    out.add(t0, "cylinder", state)
    x_end, v_end = state_at_q(q_end, psi_rate2(s_end), t0 + t_end)
    if end_kind == "face":
        out.extend(plane_slide(x_end, v_end, g, exit_normal, t0 + t_end))
    else:
        out.extend(free_flight(x_end, v_end, g, t0 + t_end))
    return out


def face_slide_off(x0, v0, g, face_normal, edge_point, edge_axis, R: float,
                   next_normal=None, t0: float = 0.0) -> Trajectory:
    """A frictionless slide on a face plane towards one of its edges, over the edge's cylinder
    (radius ``R = rb + r`` [m]; ``R = r`` for a sharp edge), then free flight (or the next
    face).

    Args:
        x0: the centre on the face's offset plane, ``n . (x0 - edge_point) = R`` [m].
        v0: its velocity in that plane [m/s], carrying it to the edge.
        g: gravity [m/s^2], pressing on the face (``g . n < 0``).
        face_normal: the face's outward unit normal.
        edge_point, edge_axis: the core edge's line.
        R: the edge cylinder's radius [m].
        next_normal: the adjacent face's outward normal (see :func:`cylinder_slide`).
        t0: start time [s].

    The contact point leaves the face when the centre crosses the plane through the edge line
    perpendicular to the face (a root of the face-frame parabola); from there
    :func:`cylinder_slide`.
    """
    n = _unit(face_normal)
    a = _unit(edge_axis)
    g = np.asarray(g, dtype=np.float64)
    x0, v0 = np.asarray(x0, dtype=np.float64), np.asarray(v0, dtype=np.float64)
    off = np.cross(a, n)  # across the edge, in the face plane
    if off @ (x0 - np.asarray(edge_point)) > 0.0:
        off = -off  # now pointing from the face over the edge
    acc = g - (g @ n) * n
    c = float(off @ (x0 - np.asarray(edge_point, dtype=np.float64)))
    t_edge = _crossing_time(c, float(off @ v0), float(off @ acc))
    out = plane_slide(x0, v0, g, n, t0)
    x_e, v_e = out.at([t0 + t_edge])
    out.extend(cylinder_slide(edge_point, a, R, x_e[0], v_e[0], g, t0 + t_edge,
                              exit_normal=next_normal))
    return out


def sphere_slide(center, R: float, x0, v0, g, t0: float = 0.0) -> Trajectory:
    """A frictionless slide on the sphere of radius ``R`` [m] about ``center`` [m] (a rounded
    corner; the inverted spherical pendulum), then free flight from the detachment.

    Args:
        center: the core corner point [m].
        R: ``rb + r`` [m], > 0.
        x0: the centre at ``t0`` on the sphere [m], above its equator (``n . g < 0``).
        v0: its velocity [m/s], tangent to the sphere, not moving up (``v0 . g >= 0``).
        g: gravity [m/s^2], not zero.
        t0: start time [s].

    With ``u = n . up`` (``up = -g / |g|``), energy and the angular momentum about the vertical
    through ``center``, ``L = up . ((x - c) x v)``, give ``R^2 u'^2 = (1 - u^2) |v|^2 - L^2 /
    R^2`` with ``|v|^2 = |v0|^2 + 2 G R (u0 - u)``, and the azimuth ``phi' = L / (R^2 (1 -
    u^2))``. Above the equator ``u`` only decreases; the normal force vanishes at
    ``u_d = (2 u0 + |v0|^2 / (G R)) / 3``. A start with ``lambda < 0`` leaves at once.

    Returns:
        :class:`Trajectory` with pieces "sphere" then "flight".
    """
    c = np.asarray(center, dtype=np.float64)
    x0, v0, g = (np.asarray(v, dtype=np.float64) for v in (x0, v0, g))
    G = float(np.linalg.norm(g))
    up = -g / G
    n0 = (x0 - c) / R
    u0 = float(n0 @ up)
    horiz = n0 - u0 * up
    # the azimuth's origin: the start's horizontal direction (at the top, the velocity's)
    e1 = _unit(horiz if np.linalg.norm(horiz) > 0.0 else v0 - (v0 @ up) * up)
    e2 = np.cross(up, e1)
    L = float(up @ np.cross(x0 - c, v0))
    v2 = float(v0 @ v0)
    du0 = float(v0 @ up) / R  # <= 0
    out = Trajectory()
    u_d = (2.0 * u0 + v2 / (G * R)) / 3.0
    if G * u0 - v2 / R < 0.0 or u_d >= u0:  # the second: lambda is 0 but for rounding
        out.extend(free_flight(x0, v0, g, t0))
        return out
    a0 = 1.0 - u0 * u0

    def rate2(s):  # u'^2 at u = u0 - s^2, as u0'^2 + s^2 Q(s) (no cancellation)
        q = (2.0 * G * R * a0 + (2.0 * u0 - s * s) * (v2 + 2.0 * G * R * s * s)) / (R * R)
        return du0 * du0 + s * s * q

    def dt_ds(s):
        return 2.0 * s / np.sqrt(rate2(s))

    def time_of(s: float) -> float:
        return integrate(dt_ds, 0.0, s)

    def rate_of(s: float) -> float:
        return float(dt_ds(s)) if s > 0.0 else np.inf

    def azimuth_of(s: float) -> float:
        # 1 - u^2 at u = u0 - s^2 as a0 + s^2 (2 u0 - s^2): written as 1 - (u0 - s^2)^2 it
        # cancels near the top (a0 small), and its rounding noise, above the quadrature's
        # tolerance, kept every panel from settling
        return integrate(lambda w: L / (R * R * (a0 + w * w * (2.0 * u0 - w * w))) * dt_ds(w),
                         0.0, s)

    s_end = np.sqrt(u0 - u_d)
    t_end = time_of(s_end)

    def state_at(s: float, t: float):
        u = u0 - s * s
        phi = azimuth_of(s)
        rho = np.sqrt(1.0 - u * u)
        du = -np.sqrt(max(float(rate2(s)), 0.0))
        dphi = L / (R * R * rho * rho)
        radial = np.cos(phi) * e1 + np.sin(phi) * e2
        tang = -np.sin(phi) * e1 + np.cos(phi) * e2
        x = c + R * (u * up + rho * radial)
        v = R * (du * up - u * du / rho * radial + rho * dphi * tang)
        return x, v

    def state(t: float):
        s = _invert(time_of, rate_of, t - t0, s_end) if t > t0 else 0.0
        return state_at(s, t)

    out.add(t0, "sphere", state)
    x_end, v_end = state_at(s_end, t0 + t_end)
    out.extend(free_flight(x_end, v_end, g, t0 + t_end))
    return out
