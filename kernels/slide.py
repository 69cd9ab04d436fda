"""Supports that are not a free parabola: how a face slide ends and how a sphere slides on a
curved (edge or corner) support, in the support box's local frame.

A sphere supported on a face slides along the face-frame parabola ``x + v s + 1/2 g_t s^2``
(``g_t`` gravity's part along the face). Its contact point is its centre's in-face coordinates,
so it leaves the face exactly when one of them reaches the face rectangle's border: the first
outward root of a quadratic (:func:`face_exit`).

Past the border the centre is on the rounded box's curved part: at distance ``R = rb + r`` from
the core box's edge (a cylinder) or corner (a sphere). A *feature* is written as a ``mask``
(1 on the local axes where the centre lies outside the core slab, the *constrained* axes) and
the signs ``sig`` of those sides; the feature's point is ``c_f = mask sig h`` and the centre's
offset from it ``w = mask (x - c_f)`` (on an edge the free axis is left out: the cylinder's
axis). Frictionless, the sphere follows the surface with ``x'' = g + lambda n``, ``n = w / R``,
``lambda = -|u|^2 / R - gamma . n`` (``u = mask v``, ``gamma = mask g``): the free axis is an
exact parabola and ``(w, u)`` a pendulum whose energy ``1/2 |u|^2 - gamma . w`` is conserved. It
holds while the normal force ``lambda`` is positive: a contact with ``lambda <= 0`` (an arc
exactly tangent to the surface, or a slide too fast for it) is free flight.

:func:`curved_leg` integrates the pendulum in substeps of the classical fourth-order Runge-Kutta
method, each at most ``SLIDE_ANGLE_STEP`` of the feature's natural angle, re-projected onto the
surface (``|w| = R``, ``u`` tangent, ``|u|`` from the energy: the slide conserves energy to
rounding). It ends at the first of: the frame's end; the detachment (``lambda`` falls to 0);
the centre leaving the feature's region (onto an adjacent face or from an edge to a corner);
a contact with another box, found by the exact arc sweep of the parabola through each
substep's ends. Event times are refined inside their substep (regula falsi with bisection) to
``REFINE_ULPS`` of the leg. The error is that of the substeps: ``(Omega h)^4`` relative per
unit angle, ``Omega`` the feature's natural rate.

The rare paths (a face's exit, a feature, a curved leg, an escape) are compiled out of line
(``inline=False``): inlined, they made the bounce loop around the nearest-hit query twice as
slow for spheres that never slide.

After a curved support ends in free flight the free parabola starts tangent to the box it
leaves; the exact sweep's start rules (made for a plane) would take it as a new contact at
once. :func:`escape_time` gives how long that parabola provably stays off the box (until it
re-enters the feature's cylinder or sphere, a quadratic after dividing out the double root at
0, or leaves the feature's region), and :func:`nearest_except` sweeps the other boxes over that
window.
"""

from functools import cache
from types import SimpleNamespace

import warp as wp

from .arc import TOUCH_ULPS, arc_funcs
from .candidates import candidate_funcs
from .data import model_structs
from .nearest import nearest_funcs
from .nearest_arc import nearest_arc_funcs
from .precision import Precision

#: Largest angle [rad] a curved slide turns per substep at the feature's natural rate
#: ``sqrt(|gamma| / R + |u|^2 / R^2)``: the fourth-order substep's relative error is about
#: ``(0.05)^5 / 120 = 3e-9`` per substep, below 1e-6 m over a slide of a metre.
SLIDE_ANGLE_STEP = 0.05

#: Substeps per curved leg at most, so a tiny radius cannot make a frame's cost unbounded;
#: past it the substeps lengthen evenly over what is left of the leg.
MAX_SLIDE_SUBSTEPS = 64

#: Iterations of the event-time refinement in one substep: regula falsi (Illinois) converges
#: in a handful; bisection alone reaches ``REFINE_ULPS`` from a substep in float64 in ~50.
MAX_REFINE_ITERATIONS = 60

#: An event time is refined until its bracket is this many ulps of the leg's time: the
#: position error of that many ulps of the leg's travel, as the sweeps' own roots.
REFINE_ULPS = 4.0

#: A contact point within this many ulps of the local scale of a face rectangle's border is on
#: the face: coplanar tiles meet at their borders, and a slide crossing one stays a face slide.
FACE_BORDER_ULPS = 64.0

#: A Minkowski radius below this many ulps of the local scale is a sharp edge for a point:
#: its curvature is unresolvable, so leaving a face there is free flight.
SHARP_SLIDE_ULPS = 16.0

#: How a curved leg ended (:func:`curved_leg`).
LEG_END = 0
LEG_DETACH = 1
LEG_REGION = 2
LEG_HIT = 3


@cache
def slide_funcs(p: Precision, broad_phase: str) -> SimpleNamespace:
    """Build the slide ``@wp.func``s for one precision and broad phase.

    Returns:
        Namespace with ``first_crossing``, ``face_exit``, ``feature_of``, ``normal_force``,
        ``escape_time``, ``nearest_except`` and ``curved_leg``.
    """
    scalar, vec3 = p.scalar, p.vec3
    Boxes, BroadPhase, _, _ = model_structs(p)
    arc = arc_funcs(p)
    quadratic_roots = arc.quadratic_roots
    local_scale = arc.local_scale
    arc_path = nearest_arc_funcs(p).arc_path
    # every box's loop, or the BVH's (its kept-out boxes, then the query's), never trying
    # the path's ``left``
    nearest_brute = candidate_funcs(p, nearest_arc_funcs(p).sweep_arc, "brute", leaves=True
                                    ).nearest_brute
    nearest_bvh = candidate_funcs(p, nearest_arc_funcs(p).sweep_arc, "bvh", leaves=True
                                  ).nearest_bvh
    use_bvh = broad_phase in ("bvh", "grid-bvh")
    ZERO = scalar(0.0)
    HALF = scalar(0.5)
    ONE = scalar(1.0)
    TWO = scalar(2.0)
    SIXTH = scalar(1.0 / 6.0)
    NONE = scalar(1.0e30)  # "no such time"
    ANGLE = scalar(SLIDE_ANGLE_STEP)
    REFINE_TOL = scalar(REFINE_ULPS * p.eps)
    BORDER_REL = scalar(FACE_BORDER_ULPS * p.eps)
    TOUCH_REL = scalar(TOUCH_ULPS * p.eps)
    mat33 = p.mat33
    separation_lift = nearest_funcs(p).separation_lift

    @wp.func
    def first_crossing(c0: scalar, c1: scalar, c2: scalar, bound: scalar, tau: scalar):
        """The first time in ``[0, tau]`` [s] where ``c0 + c1 s + c2 s^2`` rises through
        ``bound`` (``NONE`` if it does not); a start beyond ``bound`` still rising is 0.

        A double root (touching ``bound`` without crossing) is no crossing.
        """
        out = NONE
        if c0 > bound and (c1 > ZERO or (c1 == ZERO and c2 > ZERO)):
            out = ZERO
        else:
            n, r1, r2 = quadratic_roots(c2, c1, c0 - bound)
            if n > 0:
                if r1 >= ZERO and r1 <= tau and c1 + TWO * c2 * r1 > ZERO:
                    out = r1
                elif r2 >= ZERO and r2 <= tau and c1 + TWO * c2 * r2 > ZERO:
                    out = r2
        return out

    @wp.func(inline=False)
    def face_exit(x: vec3, v: vec3, g: vec3, tau: scalar, h: vec3, axis: int):
        """When the contact point of a face slide leaves the face, box frame.

        Args:
            x: centre [m], v: velocity [m/s], g: the slide's acceleration [m/s^2], all local;
            tau: the time span [s]; h: core half extents [m]; axis: the face's normal axis.

        Returns:
            ``(s, exit_axis, side)``: the first time in ``[0, tau]`` an in-face coordinate
            reaches ``side * h[exit_axis]`` moving out; ``s = NONE`` and axis -1 if none.
        """
        s = NONE
        exit_axis = int(-1)
        side = ONE
        for i in range(3):
            if i != axis:
                up = first_crossing(x[i], v[i], HALF * g[i], h[i], tau)
                down = first_crossing(-x[i], -v[i], -HALF * g[i], h[i], tau)
                if up < s:
                    s = up
                    exit_axis = i
                    side = ONE
                if down < s:
                    s = down
                    exit_axis = i
                    side = -ONE
        return s, exit_axis, side

    @wp.func(inline=False)
    def feature_of(x: vec3, h: vec3, radius: scalar):
        """The feature of a point on a rounded box's surface, box frame: ``(mask, sig,
        count)``, the constrained axes (outside the core slab by more than ``FACE_BORDER_ULPS``
        of the local scale, so a face's border belongs to the face) and their sides."""
        scale = wp.max(wp.max(wp.max(h[0], h[1]), wp.max(h[2], radius)),
                       wp.max(wp.max(wp.abs(x[0]), wp.abs(x[1])), wp.abs(x[2])))
        slack = BORDER_REL * scale
        mask = vec3(ZERO, ZERO, ZERO)
        sig = vec3(ONE, ONE, ONE)
        count = int(0)
        for i in range(3):
            if wp.abs(x[i]) > h[i] + slack:
                mask[i] = ONE
                if x[i] < ZERO:
                    sig[i] = -ONE
                count += 1
        return mask, sig, count

    @wp.func
    def normal_force(w: vec3, u: vec3, gam: vec3, radius: scalar):
        """``lambda`` [m/s^2]: the surface's push per unit mass keeping the centre on the
        feature (offset ``w``, perpendicular velocity ``u``, gravity's part ``gam``)."""
        return -wp.dot(u, u) / radius - wp.dot(gam, w) / wp.length(w)

    @wp.func
    def surface_accel(w: vec3, u: vec3, gam: vec3, radius: scalar):
        """``gamma + lambda n`` [m/s^2], the perpendicular acceleration on the feature."""
        n = w / wp.length(w)
        return gam + (-wp.dot(u, u) / radius - wp.dot(gam, n)) * n

    @wp.func
    def curved_step(w: vec3, u: vec3, gam: vec3, radius: scalar, e_perp: scalar, h: scalar):
        """One fourth-order Runge-Kutta substep of ``h`` [s] on the feature, re-projected:
        ``|w| = R``, ``u`` tangent, ``1/2 |u|^2 = e_perp + gam . w`` (the energy).

        Returns:
            ``(w, u)`` at the substep's end.
        """
        hh = HALF * h
        a1 = surface_accel(w, u, gam, radius)
        w2 = w + hh * u
        u2 = u + hh * a1
        a2 = surface_accel(w2, u2, gam, radius)
        w3 = w + hh * u2
        u3 = u + hh * a2
        a3 = surface_accel(w3, u3, gam, radius)
        w4 = w + h * u3
        u4 = u + h * a3
        a4 = surface_accel(w4, u4, gam, radius)
        w_n = w + (SIXTH * h) * (u + TWO * (u2 + u3) + u4)
        u_n = u + (SIXTH * h) * (a1 + TWO * (a2 + a3) + a4)
        n = wp.normalize(w_n)
        w_n = radius * n
        u_n = u_n - wp.dot(u_n, n) * n
        kinetic2 = TWO * (e_perp + wp.dot(gam, w_n))
        speed = wp.length(u_n)
        if kinetic2 <= ZERO:
            u_n = vec3(ZERO, ZERO, ZERO)
        elif speed > ZERO:
            u_n = u_n * (wp.sqrt(kinetic2) / speed)
        return w_n, u_n

    @wp.func
    def event_value(w: vec3, u: vec3, gam: vec3, radius: scalar, sig: vec3, which: int):
        """The quantity whose sign change is an event: ``which`` -1 the normal force, 0..2
        how far the centre is outside the core slab of that axis (``sig_j w_j``)."""
        out = ZERO
        if which < 0:
            out = normal_force(w, u, gam, radius)
        else:
            out = sig[which] * w[which]
        return out

    @wp.func
    def refine_event(w: vec3, u: vec3, gam: vec3, radius: scalar, e_perp: scalar, sig: vec3,
                     which: int, h: scalar, f_hi: scalar, tol: scalar):
        """The time in ``[0, h]`` [s] where :func:`event_value` falls to 0, given it is
        ``>= 0`` at 0 and ``f_hi < 0`` at ``h``: regula falsi (Illinois) safeguarded by
        bisection; the bracket's lower end is returned (the event's value still ``>= 0``)."""
        lo = ZERO
        hi = h
        f_lo = event_value(w, u, gam, radius, sig, which)
        side = int(0)
        for _it in range(MAX_REFINE_ITERATIONS):
            if hi - lo > tol:
                s = HALF * (lo + hi)
                if f_lo != f_hi:
                    s_f = hi - f_hi * (hi - lo) / (f_hi - f_lo)
                    if s_f > lo and s_f < hi:
                        s = s_f
                w_s, u_s = curved_step(w, u, gam, radius, e_perp, s)
                f_s = event_value(w_s, u_s, gam, radius, sig, which)
                if f_s >= ZERO:
                    lo = s
                    f_lo = f_s
                    if side == 1:
                        f_hi = HALF * f_hi
                    side = 1
                else:
                    hi = s
                    f_hi = f_s
                    if side == -1:
                        f_lo = HALF * f_lo
                    side = -1
        return lo

    @wp.func(inline=False)
    def escape_time(x: vec3, v: vec3, g: vec3, tau: scalar, h: vec3, radius: scalar,
                    mask: vec3, sig: vec3):
        """How long [s] the free parabola from a tangential start on a curved feature stays
        off the box, box frame: all of ``tau`` when the safe window is longer, else half of it.

        The window ends when the parabola re-enters the feature's cylinder or sphere: ``|w(s)|^2
        - R^2`` is ``s^2 q(s)`` with ``q = |gam|^2/4 s^2 + (u . gam) s + |u|^2 + gam . w``
        (positive at 0 when ``lambda < 0``), entered at ``q``'s first falling root; or when the
        centre leaves the feature's region (a constrained coordinate back inside its slab, or a
        free one out of it). Until then the box's surface is the feature's, so no contact.
        """
        cf = wp.cw_mul(mask, wp.cw_mul(sig, h))
        w = wp.cw_mul(mask, x - cf)
        u = wp.cw_mul(mask, v)
        gam = wp.cw_mul(mask, g)
        window = NONE
        n, r1, r2 = quadratic_roots(HALF * HALF * wp.dot(gam, gam), wp.dot(u, gam),
                                    wp.dot(u, u) + wp.dot(gam, w))
        if n == 2 and r1 < r2 and r1 > ZERO:
            window = r1
        for i in range(3):
            if mask[i] > ZERO:
                window = wp.min(window, first_crossing(-sig[i] * x[i], -sig[i] * v[i],
                                                       -HALF * sig[i] * g[i], -h[i], tau))
            else:
                window = wp.min(window, first_crossing(x[i], v[i], HALF * g[i], h[i], tau))
                window = wp.min(window, first_crossing(-x[i], -v[i], -HALF * g[i], h[i], tau))
        out = tau
        if window < tau:
            out = HALF * window
        return out

    @wp.func(inline=False)
    def nearest_except(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, boxes: Boxes,
                       broad: BroadPhase, skip: int):
        """First contact of the arc ``a + v s + 1/2 g s^2``, ``s`` in ``[0, tau]``, over every
        box but ``skip`` (the support being left), world frame: the boxes kept out of the BVH's
        tree and its query when the broad phase has one, else every box; ``(box, s,
        normal)`` as ``nearest_hit_arc``."""
        q = arc_path(a, v, g, tau, r)
        q.left = skip
        best = int(-1)
        best_s = tau
        best_n = vec3(ZERO, ZERO, ZERO)
        if wp.static(use_bvh):
            best, best_s, best_n = nearest_bvh(q, boxes, broad)
        else:
            best, best_s, best_n = nearest_brute(q, boxes)
        return best, best_s, best_n

    @wp.func
    def kept_on_the_curve(a: vec3, center: vec3, to_local: mat33, rotation: mat33, h: vec3,
                          radius: scalar, cf: vec3, mask: vec3):
        """The end ``a`` [m, world] of a curved leg, put back out of the curve when the world
        coordinates' rounding left it inside by more than the sweeps' touch band.

        The leg ends on the surface in the box's frame; far from the origin the world centre
        ``center + rotation x`` rounds to ulps of its coordinates, which can be far more than
        the band the arc sweep's start rules take as *on* the surface (``arc.TOUCH_ULPS`` of
        ``arc.local_scale``; at 3 km, 1e-13 m against 4e-15 m), and a start deeper than that
        moving out by rounding would be taken as leaving from inside. Such an end is moved out
        along the normal to ``SEPARATION_ULPS`` of its coordinates above the surface
        (``nearest.separation_lift``; the next sweep finds the entry just after); within the
        band (always, near the origin) it stays bit for bit.
        """
        x = to_local * (a - center)
        w = wp.cw_mul(mask, x - cf)
        size = wp.length(w)
        scale = local_scale(x, h + vec3(radius, radius, radius))
        depth = radius - size
        out = a
        if size > ZERO and depth > TOUCH_REL * scale:
            lift = separation_lift(a, vec3(ZERO, ZERO, ZERO), h)
            out = a + (depth + lift) * (rotation * (w / size))
        return out

    @wp.func(inline=False)
    def curved_leg(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, boxes: Boxes,
                   broad: BroadPhase, box: int, mask: vec3, sig: vec3):
        """Slide on the curved feature ``(mask, sig)`` of ``box`` for at most ``tau`` [s].

        Args:
            a: centre [m] on the feature, v: velocity [m/s], g: gravity [m/s^2], world frame;
            r: sphere radius [m]; boxes, broad: the obstacles; box: the support.

        Returns:
            ``(kind, s, a, v, mask, sig, hit_box, hit_normal, normal)``: how it ended (``LEG_*``)
            after ``s`` [s], the centre and velocity there (world), the feature the centre is on
            then (for ``LEG_REGION``: the new one), the box and world normal of a
            ``LEG_HIT``, and the support's world normal at the end.
        """
        center = boxes.center[box]
        rotation = boxes.rotation[box]
        h = boxes.half_extents[box]
        radius = boxes.radius[box] + r
        to_local = wp.transpose(rotation)
        x = to_local * (a - center)
        vl = to_local * v
        gl = to_local * g
        free = vec3(ONE, ONE, ONE) - mask
        cf = wp.cw_mul(mask, wp.cw_mul(sig, h))
        w = radius * wp.normalize(wp.cw_mul(mask, x - cf))
        n = w / radius
        u = wp.cw_mul(mask, vl)
        u = u - wp.dot(u, n) * n
        gam = wp.cw_mul(mask, gl)
        e_perp = HALF * wp.dot(u, u) - wp.dot(gam, w)
        xf0 = wp.cw_mul(free, x)
        vf0 = wp.cw_mul(free, vl)
        gf = wp.cw_mul(free, gl)
        tol = REFINE_TOL * tau
        kind = int(LEG_END)
        elapsed = ZERO
        hit_box = int(-1)
        hit_n = vec3(ZERO, ZERO, ZERO)
        new_mask = mask
        new_sig = sig
        omega_sq0 = wp.length(gam) / radius
        for step in range(MAX_SLIDE_SUBSTEPS):
            if kind == LEG_END and elapsed < tau:
                left = tau - elapsed
                omega = wp.sqrt(omega_sq0 + wp.dot(u, u) / (radius * radius))
                h_step = left
                if omega * left > ANGLE:
                    h_step = ANGLE / omega
                h_step = wp.max(h_step, left / scalar(MAX_SLIDE_SUBSTEPS - step))
                w1, u1 = curved_step(w, u, gam, radius, e_perp, h_step)
                s_ev = h_step
                ev = int(LEG_END)
                ev_which = int(-2)
                # the free coordinate (an exact parabola) leaving its slab: onto a corner
                xf = xf0 + elapsed * (vf0 + (HALF * elapsed) * gf)
                vf = vf0 + elapsed * gf
                for i in range(3):
                    if free[i] > ZERO:
                        up = first_crossing(xf[i], vf[i], HALF * gf[i], h[i], h_step)
                        down = first_crossing(-xf[i], -vf[i], -HALF * gf[i], h[i], h_step)
                        if up < s_ev:
                            s_ev = up
                            ev = LEG_REGION
                            ev_which = i + 3
                        if down < s_ev:
                            s_ev = down
                            ev = LEG_REGION
                            ev_which = i + 6
                # the normal force vanishing, and a constrained coordinate back in its slab
                for k in range(4):
                    which = k - 1
                    tracked = int(1)
                    if which >= 0:
                        if mask[which] == ZERO:
                            tracked = 0
                    if tracked == 1:
                        f1 = event_value(w1, u1, gam, radius, sig, which)
                        if f1 < ZERO:
                            s_w = refine_event(w, u, gam, radius, e_perp, sig, which, h_step,
                                               f1, tol)
                            if s_w < s_ev:
                                s_ev = s_w
                                ev = LEG_REGION
                                ev_which = which
                                if which < 0:
                                    ev = LEG_DETACH
                # another box, along the parabola through the substep's ends
                x1 = cf + w1 + xf + h_step * (vf + (HALF * h_step) * gf)
                a1 = center + rotation * x1
                g_fit = (TWO / (h_step * h_step)) * (a1 - a - h_step * v)
                hb, s_b, n_b = nearest_except(a, v, g_fit, h_step, r, boxes, broad, box)
                if hb >= 0 and s_b < s_ev:
                    s_ev = s_b
                    ev = LEG_HIT
                    hit_box = hb
                    hit_n = n_b
                if ev != LEG_END:
                    w1, u1 = curved_step(w, u, gam, radius, e_perp, s_ev)
                    h_step = s_ev
                    kind = ev
                    if ev == LEG_REGION:
                        if ev_which >= 3:
                            axis = (ev_which - 3) % 3
                            new_mask[axis] = ONE
                            if ev_which >= 6:
                                new_sig[axis] = -ONE
                            else:
                                new_sig[axis] = ONE
                        else:
                            new_mask[ev_which] = ZERO
                w = w1
                u = u1
                elapsed = elapsed + h_step
                xf_end = xf0 + elapsed * (vf0 + (HALF * elapsed) * gf)
                vf_end = vf0 + elapsed * gf
                a = center + rotation * (cf + w + xf_end)
                v = rotation * (u + vf_end)
        n_out = rotation * (w / radius)
        a = kept_on_the_curve(a, center, to_local, rotation, h, radius, cf, mask)
        return kind, elapsed, a, v, new_mask, new_sig, hit_box, hit_n, n_out

    return SimpleNamespace(first_crossing=first_crossing, face_exit=face_exit,
                           feature_of=feature_of, normal_force=normal_force,
                           escape_time=escape_time, nearest_except=nearest_except,
                           curved_leg=curved_leg)
