"""One frame of exact ballistic motion: the per-sphere loop along parabolas and supports.

From its position the sphere follows ``x(s) = a + v s + 1/2 g s^2`` with its *true* velocity
``v``; at the nearest contact it reflects (``v' = v - 2 (v . n) n`` with the velocity at the
contact) and flies on along the new parabola for the rest of the frame's *time*, until nothing
is hit or ``max_bounces`` contacts were taken (then it stays at its last contact with its
reflected velocity, counted as capped, as in the linear model). The velocity returned is the
true velocity at the frame's end. Spin (``dynamics.friction_spin``) and ``energy_retention``
are applied at each contact exactly as in :mod:`bounce`.

Supports (resting and sliding contacts). A contact is a support when gravity presses the sphere
onto the surface (``g . n < 0``) and its normal speed is at most ``RESTING_SPEED`` (a hop of at
most 1.3 micrometres; the exact reference's rule): the normal part of the velocity is removed
(the energy drops by exactly that kinetic energy), whatever ``dt`` and ``max_bounces``. Then,
frictionless and exact (:mod:`slide`):

- on a face the sphere slides along the face-frame parabola with gravity's tangential part until
  its contact point leaves the face (the first root of that parabola on the face rectangle's
  border); there the edge decides: free flight when ``|v_perp|^2 / R > -g . n``, else a curved
  slide. A sphere at rest stays bit for bit, one on a slope slides;
- on a rounded edge or corner (the rounded box's curved part, radius ``R = rb + r`` about the
  core's edge or corner) it follows the surface until the normal force vanishes (then free
  flight in the same frame), it reaches an adjacent face (a face support when gravity presses)
  or it meets another box; a contact on a curved part with no normal force (an arc tangent to
  it) is free flight;
- a second support on another plane slides along their crease (a curved support by its tangent
  plane), a third stops the sphere for the rest of the frame; these slides end with the frame.

Each support start counts as a contact against ``max_bounces``. A bounce that sends the sphere
off its support gives it back the whole of gravity. Hops below ``RESTING_SPEED`` do not happen,
so a lossy ball comes to rest after finitely many bounces (no Zeno loop); a frame holding more
of its last hops than ``max_bounces`` is capped.
"""

from functools import cache
from types import SimpleNamespace

import warp as wp

from .arc import arc_funcs
from .contact import contact_funcs
from .data import Features, model_structs
from .nearest import nearest_funcs
from .nearest_arc import leaving_funcs, model_nearest_hit_arc, nearest_arc_funcs
from .precision import precision
from .slide import LEG_DETACH, LEG_END, LEG_REGION, SHARP_SLIDE_ULPS, slide_funcs

#: A contact with a normal speed at most this [m/s] while gravity presses the sphere onto the
#: surface is a support: a hop of at most 1.3 micrometres, the exact reference's threshold.
RESTING_SPEED = 5.0e-3

#: Two support normals closer than this (``1 - n1 . n2``) are one plane (coplanar tiles): the
#: new one replaces the old one instead of making a crease.
COPLANAR_REL = 1.0e-6

#: A contact on a curved part that cannot hold the sphere (no normal force) whose normal speed
#: is at most this many square-root ulps of its speed is a tangent touch: the sweep resolves a
#: double root only to ``sqrt(eps)``, so the arc flies on unchanged (a larger one bounces).
TOUCH_SQRT_ULPS = 64.0

#: What a sphere's motion is within the frame: free flight, a slide on a face (its exit
#: tracked), a slide on planes (a crease, a wedge: to the frame's end), a curved slide.
FREE = 0
FACE = 1
PLANE = 2
CURVED = 3


@cache
def ballistic_funcs(features: Features) -> SimpleNamespace:
    """Build the ballistic loop for one feature set (``precision``, ``spin``, ``lossy``,
    ``broad_phase``, ``events`` and ``falls`` are read; see
    ``nearest_arc.model_nearest_hit_arc``). Events are written as ``bounce.bounce_funcs``
    writes them, the fraction being of the frame's time, exact here; a support start (a face
    slide reaching an edge, a curved slide reaching a face) is a row with ``resting`` 1 and
    normal speed 0.

    Returns:
        Namespace with ``ballistic_path``, and its two halves for a caller with a loop of its
        own: ``free_legs`` and ``held_rest``.
    """
    p = precision(features.precision)
    scalar, vec3 = p.scalar, p.vec3
    Boxes, BroadPhase, Physics, EventBuffer = model_structs(p)
    nearest_hit_arc = model_nearest_hit_arc(p, features.broad_phase)
    # the free legs' query: under gravity (``falls``) the arc's only; it leaves out the box
    # a bounce leaves for the rest of the frame
    nearest_free_leg = model_nearest_hit_arc(p, features.broad_phase, features.falls,
                                             leaves=True)
    leaves_for_the_frame = leaving_funcs(p).leaves_for_the_frame
    arc_contact_centre = nearest_arc_funcs(p).arc_contact_centre
    arc_point = arc_funcs(p).arc_point
    separation_lift = nearest_funcs(p).separation_lift
    separation_bound = nearest_funcs(p).separation_bound
    on_contact = contact_funcs(p, features.spin, features.lossy, features.events)
    slide = slide_funcs(p, features.broad_phase)
    face_exit, feature_of, normal_force = slide.face_exit, slide.feature_of, slide.normal_force
    escape_time, nearest_except, curved_leg = (slide.escape_time, slide.nearest_except,
                                               slide.curved_leg)
    ZERO = scalar(0.0)
    HALF = scalar(0.5)
    ONE = scalar(1.0)
    TWO = scalar(2.0)
    RESTING = scalar(RESTING_SPEED)
    EIGHT = scalar(8.0)
    COPLANAR = scalar(1.0 - COPLANAR_REL)
    TANGENT_REL = scalar(p.tangent_rel)
    SHARP_SLIDE = scalar(SHARP_SLIDE_ULPS * p.eps)
    TOUCH = scalar(TOUCH_SQRT_ULPS * p.eps ** 0.5)

    @wp.func
    def along_plane(x: vec3, n: vec3):
        """``x`` without its component along the unit ``n``."""
        return x - wp.dot(x, n) * n

    @wp.func
    def along_face(x: vec3, boxes: Boxes, k: int, axis: int):
        """``x`` (world) without its component along box ``k``'s local ``axis``, that
        component zeroed in the box's frame: its part along the face normal, seen again from
        the box's frame (as the sweeps see it), is the rounding of ``x`` itself. (``x - (x .
        n) n`` leaves the rounding of the removed part, which for gravity on a nearly level
        face, ``|g . n| >> |g_t|``, was larger than the tangent margin of ``g_t``: a sphere at
        rest there was stopped by its own face at every leg, capped every frame.)"""
        xl = wp.transpose(boxes.rotation[k]) * x
        xl[axis] = ZERO
        return boxes.rotation[k] * xl

    @wp.func
    def box_frame(boxes: Boxes, k: int, x: vec3, v: vec3, g: vec3):
        """Point ``x`` [m], velocity ``v`` and acceleration ``g`` in box ``k``'s frame."""
        to_local = wp.transpose(boxes.rotation[k])
        return to_local * (x - boxes.center[k]), to_local * v, to_local * g

    @wp.func
    def dominant_axis(n: vec3):
        """The local axis of the largest component of the unit ``n``, and its sign."""
        axis = int(0)
        for i in range(1, 3):
            if wp.abs(n[i]) > wp.abs(n[axis]):
                axis = i
        side = ONE
        if n[axis] < ZERO:
            side = -ONE
        return axis, side

    @wp.func
    def resting(g: vec3, n: vec3, un: scalar, a: vec3, leg: vec3, big_r: scalar,
                extent: vec3):
        """Whether a contact (unit normal ``n``, normal speed ``un`` [m/s], from the leg that
        started at ``a`` [m] and moved by ``leg`` [m], Minkowski radius ``big_r`` [m], box
        half extent ``extent`` [m]) is a support: gravity presses the sphere onto the surface
        and its normal speed is at most ``RESTING_SPEED``, or, where the contact centre is
        moved out by the separation lift (``nearest.separation_lift`` of the leg's start, the
        leg and the box: a Minkowski radius below it), at most the speed of a fall from four times
        that lift, ``sqrt(8 |g . n| lift)``: a sphere resting on a sharp face (a point on a
        plate) starts each frame one or two lifts above it, and its fall is no bounce (as a
        bounce each would add a lift of height: a ratchet)."""
        gn = wp.dot(g, n)
        out = int(0)
        if gn < -TANGENT_REL * wp.length(g):
            limit = RESTING
            if big_r < TWO * separation_bound(a, leg, extent):  # else at or above twice the lift
                lift = separation_lift(a, leg, extent)
                if big_r < TWO * lift:
                    limit = wp.max(limit, wp.sqrt(EIGHT * -gn * lift))
            if -un <= limit:
                out = 1
        return out

    @wp.func(inline=False)
    def holds_on(x: vec3, v: vec3, g: vec3, h: vec3, big_r: scalar, mask: vec3, sig: vec3):
        """Whether a sphere on the curved feature ``(mask, sig)`` with velocity ``v`` (all
        local) is pressed onto it: a positive normal force and a resolvable radius."""
        cf = wp.cw_mul(mask, wp.cw_mul(sig, h))
        w = wp.cw_mul(mask, x - cf)
        out = int(0)
        size = wp.length(w)
        if big_r > SHARP_SLIDE * wp.max(wp.max(h[0], h[1]), wp.max(h[2], size)) and size > ZERO:
            n = w / size
            u = wp.cw_mul(mask, v)
            u = u - wp.dot(u, n) * n
            if normal_force(w, u, wp.cw_mul(mask, g), big_r) > ZERO:
                out = 1
        return out

    @wp.struct
    class Support:
        """What holds a sphere within the frame (``ballistic_path``'s loop state)."""

        mode: int
        """``FREE``, ``FACE``, ``PLANE`` or ``CURVED``."""
        supports: int
        """Planar supports: 1 on a face, 1 to 3 on planes (a crease, a wedge)."""
        n1: wp.types.vector(3, scalar)
        """The first planar support's unit normal, world."""
        n2: wp.types.vector(3, scalar)
        """The second's."""
        box: int
        """FACE, CURVED: the support's box."""
        face_axis: int
        """FACE: the face's local normal axis."""
        face_side: scalar
        """FACE: its side, +-1."""
        mask: wp.types.vector(3, scalar)
        """CURVED: the feature's constrained local axes (``slide.feature_of``)."""
        sig: wp.types.vector(3, scalar)
        """CURVED: their sides."""
        escape_box: int
        """Free flight just off this box's curved part (-1: none) ..."""
        escape_left: scalar
        """... which it cannot touch again for this long [s]."""
        g_eff: wp.types.vector(3, scalar)
        """The acceleration of the free or planar legs [m/s^2]: gravity, or its part along
        the support's plane or crease."""

    @wp.func(inline=True)
    def free_support(g: vec3):
        """Nothing holds the sphere: free flight under ``g``."""
        st = Support()
        st.mode = FREE
        st.supports = 0
        st.n1 = vec3(ZERO, ZERO, ZERO)
        st.n2 = vec3(ZERO, ZERO, ZERO)
        st.box = -1
        st.face_axis = 0
        st.face_side = ONE
        st.mask = vec3(ZERO, ZERO, ZERO)
        st.sig = vec3(ONE, ONE, ONE)
        st.escape_box = -1
        st.escape_left = ZERO
        st.g_eff = g
        return st

    @wp.func(inline=False)
    def held_leg(st: Support, a: vec3, v: vec3, g: vec3, rest: scalar, r: scalar, boxes: Boxes,
                 broad: BroadPhase):
        """One leg of a sphere on a face, on a curved part, or just off one (out of line: a
        free sphere never runs it).

        Returns:
            ``(kind, box, n, contact, u, a, v, rest, st)``: ``kind`` 0 the frame is done, 1 a
            contact with ``box`` (normal ``n``, centre ``contact``, velocity ``u`` there), 2 a
            support may start on ``st.box``'s feature ``(st.mask, st.sig)`` at ``a``, 3 go on.
        """
        kind = int(3)
        box = int(-1)
        n = vec3(ZERO, ZERO, ZERO)
        contact = a
        u = v
        if st.mode == CURVED:
            leg, s, a, v, mask, sig, hit_box, hit_n, n_sup = curved_leg(
                a, v, g, rest, r, boxes, broad, st.box, st.mask, st.sig)
            st.mask = mask
            st.sig = sig
            rest = wp.max(rest - s, ZERO)
            if leg == LEG_END:
                kind = 0
            elif leg == LEG_DETACH:
                b = st.box
                st = free_support(g)
                xl, vl, gl = box_frame(boxes, b, a, v, g)
                st.escape_box = b
                st.escape_left = escape_time(xl, vl, gl, rest, boxes.half_extents[b],
                                             boxes.radius[b] + r, mask, sig)
            elif leg == LEG_REGION:
                kind = 2
            else:
                kind = 1
                box = hit_box
                n = hit_n
                contact = a
                u = v
                st.n1 = n_sup  # the curved support's tangent plane, for a crease
        else:
            tau = rest
            skip = st.escape_box
            s = tau
            if skip >= 0:
                tau = wp.min(st.escape_left, rest)
                st.escape_box = -1
                box, s, n = nearest_except(a, v, st.g_eff, tau, r, boxes, broad, skip)
            else:
                box, s, n = nearest_hit_arc(a, v, st.g_eff, tau, r, boxes, broad)
            s_exit = tau
            exit_axis = int(-1)
            exit_side = ONE
            if st.mode == FACE:
                xl, vl, gl = box_frame(boxes, st.box, a, v, st.g_eff)
                s_exit, exit_axis, exit_side = face_exit(
                    xl, vl, gl, tau, boxes.half_extents[st.box], st.face_axis)
            if exit_axis >= 0 and s_exit < s:
                # the contact point leaves the face: the edge decides what follows
                a = arc_point(a, v, st.g_eff, s_exit)
                v = v + s_exit * st.g_eff
                rest = wp.max(rest - s_exit, ZERO)
                mask = vec3(ZERO, ZERO, ZERO)
                mask[st.face_axis] = ONE
                mask[exit_axis] = ONE
                sig = vec3(ONE, ONE, ONE)
                sig[st.face_axis] = st.face_side
                sig[exit_axis] = exit_side
                st.mask = mask
                st.sig = sig
                kind = 2
            elif box < 0:
                a = arc_point(a, v, st.g_eff, tau)
                v = v + tau * st.g_eff
                if tau >= rest:
                    kind = 0
                rest = wp.max(rest - tau, ZERO)
            else:
                kind = 1
                contact = arc_contact_centre(a, v, st.g_eff, s, n, boxes.radius[box] + r,
                                             boxes.extent[box])
                u = v + s * st.g_eff
                rest = wp.max(rest - s, ZERO)
        return kind, box, n, contact, u, a, v, rest, st

    @wp.func(inline=False)
    def start_support(st: Support, a: vec3, v: vec3, g: vec3, rest: scalar, r: scalar,
                      boxes: Boxes):
        """Whether the feature ``(st.mask, st.sig)`` of ``st.box`` that the centre ``a`` just
        reached holds the sphere (velocity ``v``): a face gravity presses on, a curved part
        with a normal force. Out of line.

        Returns:
            ``(holds, st, v, n)``: the support state (free flight, with the escape of a curved
            part, when it does not hold), the velocity along it and its world normal.
        """
        xl, vl, gl = box_frame(boxes, st.box, a, v, g)
        h = boxes.half_extents[st.box]
        big_r = boxes.radius[st.box] + r
        mask = st.mask
        sig = st.sig
        count = int(mask[0] + mask[1] + mask[2])
        holds = int(0)
        n_w = vec3(ZERO, ZERO, ZERO)
        axis = int(0)
        if count == 1:
            axis, side = dominant_axis(mask)
            n_l = vec3(ZERO, ZERO, ZERO)
            n_l[axis] = sig[axis]
            n_w = boxes.rotation[st.box] * n_l
            if wp.dot(g, n_w) < -TANGENT_REL * wp.length(g):
                holds = 1
        else:
            holds = holds_on(xl, vl, gl, h, big_r, mask, sig)
            cf = wp.cw_mul(mask, wp.cw_mul(sig, h))
            n_w = boxes.rotation[st.box] * wp.normalize(wp.cw_mul(mask, xl - cf))
        b = st.box
        if holds == 0:
            st = free_support(g)
            if count > 1:
                st.escape_box = b
                st.escape_left = escape_time(xl, vl, gl, rest, h, big_r, mask, sig)
        elif count == 1:
            st.mode = FACE
            st.face_axis = axis
            st.face_side = sig[axis]
            st.supports = 1
            st.n1 = n_w
            st.g_eff = along_face(g, boxes, st.box, axis)
            v = along_face(v, boxes, st.box, axis)
        else:
            st.mode = CURVED
            st.supports = 0
            st.g_eff = g
        return holds, st, v, n_w

    @wp.func(inline=False)
    def support_contact(st: Support, u: vec3, n: vec3, un: scalar, contact: vec3, box: int,
                        rest: scalar, r: scalar, g: vec3, boxes: Boxes):
        """A contact with gravity pressing and at most ``RESTING_SPEED`` of normal speed: a
        support on a face (a face slide), a curved part (a curved slide), a second plane (the
        crease) or a third (wedged); a curved part with no normal force does not hold it (a
        tangent touch flies on, else it bounces). Out of line.

        Returns:
            ``(held, graze, st, u)``: ``held`` 1 for a support (``u`` along it), ``graze`` 1 for
            a tangent touch (``u`` unchanged); both 0: a bounce (``st`` unchanged).
        """
        held = int(0)
        graze = int(0)
        out = st
        if out.mode == CURVED:
            out.supports = 1  # its tangent plane (n1) against this new support
        single = int(0)
        if out.supports == 0 or (out.supports == 1 and wp.dot(n, out.n1) >= COPLANAR):
            single = 1
        elif out.supports == 1:
            if wp.dot(along_plane(g, n), out.n1) >= ZERO and wp.dot(
                    along_plane(u, n), out.n1) >= ZERO:
                single = 1  # sliding off the old plane onto the new one
        if single == 1:
            xl, vl, gl = box_frame(boxes, box, contact, u, g)
            h = boxes.half_extents[box]
            big_r = boxes.radius[box] + r
            f_mask, f_sig, count = feature_of(xl, h, big_r)
            if count <= 1:
                held = 1
                out.mode = FACE
                out.box = box
                axis, side = dominant_axis(wp.transpose(boxes.rotation[box]) * n)
                out.face_axis = axis
                out.face_side = side
                out.supports = 1
                out.n1 = n
                out.g_eff = along_face(g, boxes, box, axis)
                u = along_face(u, boxes, box, axis)
            elif holds_on(xl, vl, gl, h, big_r, f_mask, f_sig) == 1:
                held = 1
                out.mode = CURVED
                out.box = box
                out.mask = f_mask
                out.sig = f_sig
                out.supports = 0
                out.g_eff = g
                u = along_plane(u, n)
            elif -un <= TOUCH * wp.length(u):
                # tangent to a curved part (within the sweep's resolution of a double root)
                graze = 1
                out = free_support(g)
                out.escape_box = box
                out.escape_left = escape_time(xl, vl, gl, rest, h, big_r, f_mask, f_sig)
            else:
                out = st
        elif out.supports == 1:  # along the crease of the two planes
            held = 1
            out.mode = PLANE
            out.supports = 2
            out.n2 = n
            crease = wp.normalize(wp.cross(out.n1, n))
            out.g_eff = wp.dot(g, crease) * crease
            u = wp.dot(u, crease) * crease
        else:  # wedged by three supports
            held = 1
            out.mode = PLANE
            out.g_eff = vec3(ZERO, ZERO, ZERO)
            u = vec3(ZERO, ZERO, ZERO)
        return held, graze, out, u

    @wp.func(inline=False)
    def general_step(st: Support, a: vec3, v: vec3, L: vec3, energy: scalar, rest: scalar,
                     bounces: int, capped: int, supported: int, r: scalar, m: scalar,
                     physics: Physics, boxes: Boxes, broad: BroadPhase, frame: int,
                     sphere: int, events: EventBuffer, pre_box: int, pre_s: scalar,
                     pre_n: vec3):
        """One pass of :func:`ballistic_path`'s loop for a sphere held by a support or just
        off one, or at a contact that may be a support (``pre_box >= 0``: the free leg's
        contact, ``pre_s`` [s] along it with normal ``pre_n``). Out of line, so the free
        flight's loop stays small.

        Returns:
            ``(a, v, L, energy, rest, bounces, capped, supported, done, st)``.
        """
        g = physics.gravity
        dt = physics.dt
        max_bounces = physics.max_bounces
        done = int(0)
        kind = int(1)  # 0 done, 1 a contact, 2 a support may start, 3 go on
        box = int(-1)
        n = vec3(ZERO, ZERO, ZERO)
        contact = a
        u = v
        if pre_box >= 0 or st.mode == FREE and st.escape_box < 0 or st.mode == PLANE:
            box = pre_box
            s = pre_s
            n = pre_n
            if pre_box < 0:
                box, s, n = nearest_hit_arc(a, v, st.g_eff, rest, r, boxes, broad)
            if box < 0:
                a = arc_point(a, v, st.g_eff, rest)
                v = v + rest * st.g_eff
                kind = 0
            else:
                contact = arc_contact_centre(a, v, st.g_eff, s, n, boxes.radius[box] + r,
                                             boxes.extent[box])
                u = v + s * st.g_eff
                rest = wp.max(rest - s, ZERO)
        else:
            kind, box, n, contact, u, a, v, rest, st = held_leg(st, a, v, g, rest, r,
                                                                boxes, broad)
        if kind == 0:
            done = 1
        elif kind == 2:
            holds, st_new, v_new, n_w = start_support(st, a, v, g, rest, r, boxes)
            if holds == 0:
                st = st_new
            elif bounces >= max_bounces:
                capped = 1
                done = 1
            else:
                bounces += 1
                supported += 1
                on_contact.event(frame, sphere, st.box, 1, a, n_w, (dt - rest) / dt,
                                 ZERO, events)
                st = st_new
                energy = energy - HALF * m * (wp.dot(v, v) - wp.dot(v_new, v_new))
                v = v_new
        elif kind == 1:
            if bounces >= max_bounces:
                capped = 1  # time left and a contact ahead: stay at the last contact
                done = 1
            else:
                bounces += 1
                L = on_contact.spin(L, u, n, r, m, physics)
                un = wp.dot(u, n)
                keep = on_contact.keep(physics)
                held = int(0)
                graze = int(0)
                # a support: gravity presses and the normal speed is at most RESTING_SPEED
                if resting(g, n, un, a, contact - a, boxes.radius[box] + r,
                           boxes.extent[box]) == 1:
                    held, graze, st, u_s = support_contact(st, u, n, un, contact, box,
                                                           rest, r, g, boxes)
                    if held == 1:
                        supported += 1
                        energy = energy - HALF * m * (wp.dot(u, u) - wp.dot(u_s, u_s))
                        v = u_s
                    elif graze == 1:
                        v = u
                if held == 0 and graze == 0:
                    v = u - TWO * un * n
                    if wp.static(features.lossy):
                        energy = on_contact.loss(energy, m, contact, physics)
                        v = v * keep
                    if st.mode == CURVED:
                        st.mode = FREE
                        st.g_eff = g
                    if st.supports > 0:
                        speed = wp.length(v)
                        leaves = wp.dot(v, st.n1) > TANGENT_REL * speed
                        if st.supports == 2:
                            leaves = leaves or wp.dot(v, st.n2) > TANGENT_REL * speed
                        if leaves:  # off its support: the whole of gravity again
                            st = free_support(g)
                on_contact.event(frame, sphere, box, held, contact, n, (dt - rest) / dt,
                                 -un, events)
                a = contact
        return a, v, L, energy, rest, bounces, capped, supported, done, st

    @wp.func(inline=False)
    def held_rest(a: vec3, v: vec3, L: vec3, energy: scalar, rest: scalar, bounces: int,
                  capped: int, supported: int, r: scalar, m: scalar, physics: Physics,
                  boxes: Boxes, broad: BroadPhase, frame: int, sphere: int, events: EventBuffer,
                  box: int, s: scalar, n: vec3):
        """The rest of a frame from a free leg's contact that may be a support (with ``box``,
        ``s`` [s] along the leg, normal ``n``): :func:`general_step` until the frame is done,
        free legs after it included (the same arithmetic as :func:`ballistic_path`'s). Out of
        line, so the free flight's loop carries no support state.

        Returns:
            ``(a, v, L, energy, bounces, capped, supported)`` at the frame's end.
        """
        st = free_support(physics.gravity)
        a, v, L, energy, rest, bounces, capped, supported, done, st = general_step(
            st, a, v, L, energy, rest, bounces, capped, supported, r, m, physics, boxes, broad,
            frame, sphere, events, box, s, n)
        while done == 0:
            a, v, L, energy, rest, bounces, capped, supported, done, st = general_step(
                st, a, v, L, energy, rest, bounces, capped, supported, r, m, physics, boxes,
                broad, frame, sphere, events, -1, ZERO, vec3(ZERO, ZERO, ZERO))
        return a, v, L, energy, bounces, capped, supported

    def path_loop(defer: bool):
        """:func:`ballistic_path`'s loop; with ``defer``, a contact that may be a support ends
        it without the call of :func:`held_rest`, and what that call would take comes back
        (see :func:`free_legs`)."""

        @wp.func(inline=True)
        def loop(a: vec3, v: vec3, r: scalar, m: scalar, L: vec3, energy: scalar,
                 physics: Physics, boxes: Boxes, broad: BroadPhase, frame: int, sphere: int,
                 events: EventBuffer):
            g = physics.gravity
            dt = physics.dt
            max_bounces = physics.max_bounces
            rest = dt  # time left in the frame [s]
            bounces = int(0)
            capped = int(0)
            supported = int(0)
            done = int(0)
            left = int(-1)  # the box the rest of the frame's arc leaves (it cannot meet it again)
            held = int(0)  # deferred: a support contact ends the loop (box, s, n below)
            held_box = int(-1)
            held_s = ZERO
            held_n = vec3(ZERO, ZERO, ZERO)
            # the centre, velocity and angular momentum the loop carries, as three scalars each
            # (p, w and M in a pass): merged at the loop's branches as vec3s, float64 kept them
            # in stack slots, as it had the linear loop's (bounce.py; BENCHMARKS.md, "float64:
            # the ballistic loop's state in registers too")
            a0 = a[0]
            a1 = a[1]
            a2 = a[2]
            v0 = v[0]
            v1 = v[1]
            v2 = v[2]
            l0 = L[0]
            l1 = L[1]
            l2 = L[2]
            while done == 0:
                p = vec3(a0, a1, a2)
                w = vec3(v0, v1, v2)
                M = vec3(l0, l1, l2)
                box, s, n = nearest_free_leg(p, w, g, rest, r, left, boxes, broad)
                if box < 0:
                    p = arc_point(p, w, g, rest)
                    w = w + rest * g
                    done = 1
                elif bounces >= max_bounces:
                    capped = 1  # time left and a contact ahead: stay at the last contact
                    done = 1
                else:
                    u = w + s * g
                    un = wp.dot(u, n)
                    if resting(g, n, un, p, arc_point(p, w, g, s) - p, boxes.radius[box] + r,
                               boxes.extent[box]) == 1:
                        if wp.static(defer):
                            held = 1
                            held_box = box
                            held_s = s
                            held_n = n
                        else:
                            p, w, M, energy, bounces, capped, supported = held_rest(
                                p, w, M, energy, rest, bounces, capped, supported, r, m,
                                physics, boxes, broad, frame, sphere, events, box, s, n)
                        done = 1
                    else:  # a bounce
                        bounces += 1
                        contact = arc_contact_centre(p, w, g, s, n, boxes.radius[box] + r,
                                                     boxes.extent[box])
                        rest = wp.max(rest - s, ZERO)
                        if wp.static(features.spin):
                            M = on_contact.spin(M, u, n, r, m, physics)
                        w = u - TWO * un * n
                        if wp.static(features.lossy):
                            energy = on_contact.loss(energy, m, contact, physics)
                            w = w * on_contact.keep(physics)
                        on_contact.event(frame, sphere, box, 0, contact, n, (dt - rest) / dt,
                                         -un, events)
                        p = contact
                        left = int(-1)
                        if leaves_for_the_frame(w, g, n, rest) == 1:
                            left = box
                a0 = p[0]
                a1 = p[1]
                a2 = p[2]
                v0 = w[0]
                v1 = w[1]
                v2 = w[2]
                l0 = M[0]
                l1 = M[1]
                l2 = M[2]
            return (vec3(a0, a1, a2), vec3(v0, v1, v2), vec3(l0, l1, l2), energy, bounces,
                    capped, supported, held, rest, held_box, held_s, held_n)

        return loop

    whole_loop = path_loop(False)
    deferring_loop = path_loop(True)

    @wp.func(inline=True)
    def free_legs(a: vec3, v: vec3, r: scalar, m: scalar, L: vec3, energy: scalar,
                  physics: Physics, boxes: Boxes, broad: BroadPhase, frame: int, sphere: int,
                  events: EventBuffer):
        """:func:`ballistic_path` up to its first contact that may be a support, without the
        call of :func:`held_rest` (which a caller makes outside its hot loop: an out-of-line
        call in a loop keeps the loop's values in memory across it, every frame; BENCHMARKS.md,
        "The ballistic frame's support path out of its loop").

        Returns:
            ``(position, velocity, L, energy, bounces, capped, supported, held, rest, box, s,
            n)``: with ``held`` 0 the frame's end, as :func:`ballistic_path` returns it; with
            ``held`` 1 the state at the start of the free leg that met ``box`` at ``s`` [s]
            along it (outward normal ``n``), ``rest`` [s] of the frame left: ``held_rest(
            position, velocity, L, energy, rest, bounces, capped, supported, ..., box, s, n)``
            gives the frame's end, the bits of :func:`ballistic_path`.
        """
        return deferring_loop(a, v, r, m, L, energy, physics, boxes, broad, frame, sphere,
                              events)

    @wp.func(inline=True)
    def ballistic_path(a: vec3, v: vec3, r: scalar, m: scalar, L: vec3, energy: scalar,
                       physics: Physics, boxes: Boxes, broad: BroadPhase, frame: int,
                       sphere: int, events: EventBuffer):
        """Move a sphere for one frame along its parabolas and supports, up to ``max_bounces``
        contacts.

        Args:
            a: centre at the frame's start [m]. v: true velocity at the frame's start [m/s].
            r: radius [m]. m: mass [kg]. L: angular momentum [kg m^2/s]. energy: total energy
            [J]. physics: the scene's constants (gravity, the potential's origin, ``dt``,
            friction, the ``|Rot|`` clamp, the retention and the cap on contacts this frame).
            boxes, broad: the obstacles and the broad phase's data. frame, sphere, events: the
            event buffer and what a row names (see ``bounce.bounce_funcs``).

        Returns:
            ``(position, velocity, L, energy, bounces, capped, supported)``: the true velocity
            at the frame's end; ``energy`` lowered by the losses (``retention``) and by the
            normal kinetic energy a support removes; ``bounces`` counts the contacts taken
            (support starts included), ``capped`` is 1 when the cap stopped the sphere,
            ``supported`` counts the support contacts.

        Free flight and plain bounces run here; from the first contact that may be a support
        on, the frame ends in :func:`held_rest`.
        """
        a, v, L, energy, bounces, capped, supported, _held, _rest, _box, _s, _n = whole_loop(
            a, v, r, m, L, energy, physics, boxes, broad, frame, sphere, events)
        return a, v, L, energy, bounces, capped, supported

    return SimpleNamespace(ballistic_path=ballistic_path, free_legs=free_legs,
                           held_rest=held_rest)
