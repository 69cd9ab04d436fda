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
from .nearest_arc import model_nearest_hit_arc, nearest_arc_funcs
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
    ``broad_phase`` and ``events`` are read; see ``nearest_arc.model_nearest_hit_arc``). Events
    are written as ``bounce.bounce_funcs`` writes them, the fraction being of the frame's time,
    exact here; a support start (a face slide reaching an edge, a curved slide reaching a face)
    is a row with ``resting`` 1 and normal speed 0.

    Returns:
        Namespace with ``ballistic_path``.
    """
    p = precision(features.precision)
    scalar, vec3 = p.scalar, p.vec3
    Boxes, BroadPhase, Physics, EventBuffer = model_structs(p)
    nearest_hit_arc = model_nearest_hit_arc(p, features.broad_phase)
    arc_contact_centre = nearest_arc_funcs(p).arc_contact_centre
    arc_point = arc_funcs(p).arc_point
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
    COPLANAR = scalar(1.0 - COPLANAR_REL)
    TANGENT_REL = scalar(p.tangent_rel)
    SHARP_SLIDE = scalar(SHARP_SLIDE_ULPS * p.eps)
    TOUCH = scalar(TOUCH_SQRT_ULPS * p.eps ** 0.5)

    @wp.func
    def along_plane(x: vec3, n: vec3):
        """``x`` without its component along the unit ``n``."""
        return x - wp.dot(x, n) * n

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

    @wp.func
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
        """
        g = physics.gravity
        g_len = wp.length(g)
        dt = physics.dt
        max_bounces = physics.max_bounces
        rest = dt  # time left in the frame [s]
        g_eff = g  # gravity the sphere feels: its tangential part on a planar support
        mode = int(FREE)
        supports = int(0)  # planar supports (FACE: 1; PLANE: 1 to 3)
        n1 = vec3(ZERO, ZERO, ZERO)
        n2 = vec3(ZERO, ZERO, ZERO)
        sup_box = int(-1)  # FACE, CURVED: the support's box
        face_axis = int(0)  # FACE: the face's local normal axis and side
        face_side = ONE
        mask = vec3(ZERO, ZERO, ZERO)  # CURVED: the feature (slide.feature_of)
        sig = vec3(ONE, ONE, ONE)
        escape_box = int(-1)  # free flight just off this box's curved part ...
        escape_left = ZERO  # ... which it cannot touch again for this long [s]
        bounces = int(0)
        capped = int(0)
        supported = int(0)
        done = int(0)
        while done == 0:
            have = int(0)  # a contact: box, its normal n, the centre and velocity there
            start = int(0)  # a support may start on sup_box's feature (mask, sig) at a
            box = int(-1)
            n = vec3(ZERO, ZERO, ZERO)
            contact = a
            u = v
            if mode == CURVED:
                kind, s, a, v, mask, sig, hit_box, hit_n, n_sup = curved_leg(
                    a, v, g, rest, r, boxes, broad, sup_box, mask, sig)
                rest = wp.max(rest - s, ZERO)
                if kind == LEG_END:
                    done = 1
                elif kind == LEG_DETACH:
                    mode = FREE
                    g_eff = g
                    xl, vl, gl = box_frame(boxes, sup_box, a, v, g)
                    escape_box = sup_box
                    escape_left = escape_time(xl, vl, gl, rest, boxes.half_extents[sup_box],
                                              boxes.radius[sup_box] + r, mask, sig)
                elif kind == LEG_REGION:
                    start = 1
                else:
                    have = 1
                    box = hit_box
                    n = hit_n
                    contact = a
                    u = v
                    n1 = n_sup  # the curved support's tangent plane, for a crease
            else:
                tau = rest
                skip = int(-1)
                if escape_box >= 0:
                    tau = wp.min(escape_left, rest)
                    skip = escape_box
                    escape_box = -1
                s = tau
                if skip >= 0:
                    box, s, n = nearest_except(a, v, g_eff, tau, r, boxes, broad, skip)
                else:
                    box, s, n = nearest_hit_arc(a, v, g_eff, tau, r, boxes, broad)
                s_exit = tau
                exit_axis = int(-1)
                exit_side = ONE
                if mode == FACE:
                    xl, vl, gl = box_frame(boxes, sup_box, a, v, g_eff)
                    s_exit, exit_axis, exit_side = face_exit(
                        xl, vl, gl, tau, boxes.half_extents[sup_box], face_axis)
                if exit_axis >= 0 and s_exit < s:
                    # the contact point leaves the face: the edge decides what follows
                    a = arc_point(a, v, g_eff, s_exit)
                    v = v + s_exit * g_eff
                    rest = wp.max(rest - s_exit, ZERO)
                    mask = vec3(ZERO, ZERO, ZERO)
                    mask[face_axis] = ONE
                    mask[exit_axis] = ONE
                    sig = vec3(ONE, ONE, ONE)
                    sig[face_axis] = face_side
                    sig[exit_axis] = exit_side
                    start = 1
                elif box < 0:
                    a = arc_point(a, v, g_eff, tau)
                    v = v + tau * g_eff
                    if tau >= rest:
                        done = 1
                    rest = wp.max(rest - tau, ZERO)
                else:
                    have = 1
                    contact = arc_contact_centre(a, v, g_eff, s, n, boxes.radius[box] + r,
                                                 boxes.extent[box])
                    u = v + s * g_eff
                    rest = wp.max(rest - s, ZERO)
            if start == 1:
                # a support starts on the feature the centre reached, if anything presses it
                xl, vl, gl = box_frame(boxes, sup_box, a, v, g)
                h = boxes.half_extents[sup_box]
                big_r = boxes.radius[sup_box] + r
                count = int(mask[0] + mask[1] + mask[2])
                holds = int(0)
                n_w = vec3(ZERO, ZERO, ZERO)
                axis = int(0)
                if count == 1:
                    axis, side = dominant_axis(mask)
                    n_l = vec3(ZERO, ZERO, ZERO)
                    n_l[axis] = sig[axis]
                    n_w = boxes.rotation[sup_box] * n_l
                    if wp.dot(g, n_w) < -TANGENT_REL * g_len:
                        holds = 1
                else:
                    holds = holds_on(xl, vl, gl, h, big_r, mask, sig)
                    cf = wp.cw_mul(mask, wp.cw_mul(sig, h))
                    n_w = boxes.rotation[sup_box] * wp.normalize(wp.cw_mul(mask, xl - cf))
                if holds == 0:
                    mode = FREE
                    g_eff = g
                    supports = 0
                    if count > 1:
                        escape_box = sup_box
                        escape_left = escape_time(xl, vl, gl, rest, h, big_r, mask, sig)
                elif bounces >= max_bounces:
                    capped = 1
                    done = 1
                else:
                    bounces += 1
                    supported += 1
                    on_contact.event(frame, sphere, sup_box, 1, a, n_w, (dt - rest) / dt,
                                     ZERO, events)
                    if count == 1:
                        mode = FACE
                        face_axis = axis
                        face_side = sig[axis]
                        supports = 1
                        n1 = n_w
                        g_eff = along_plane(g, n_w)
                        v_sq = wp.dot(v, v)
                        v = along_plane(v, n_w)
                        energy = energy - HALF * m * (v_sq - wp.dot(v, v))
                    else:
                        mode = CURVED
                        supports = 0
                        g_eff = g
            if have == 1:
                if bounces >= max_bounces:
                    capped = 1  # time left and a contact ahead: stay at the last contact
                    done = 1
                else:
                    bounces += 1
                    L = on_contact.spin(L, u, n, r, m, physics)
                    un = wp.dot(u, n)
                    gn = wp.dot(g, n)
                    keep = on_contact.keep(physics)
                    # a support: gravity presses and the normal speed is at most RESTING_SPEED
                    resting = gn < -TANGENT_REL * g_len and -un <= RESTING
                    kind_flag = int(0)
                    single = int(0)
                    if resting:
                        if mode == CURVED:
                            supports = 1  # its tangent plane (n1) against this new support
                        if supports == 0 or (supports == 1 and wp.dot(n, n1) >= COPLANAR):
                            single = 1
                        elif supports == 1:
                            if wp.dot(along_plane(g, n), n1) >= ZERO and wp.dot(
                                    along_plane(u, n), n1) >= ZERO:
                                single = 1  # sliding off the old plane onto the new one
                    graze = int(0)
                    count = int(0)
                    f_mask = vec3(ZERO, ZERO, ZERO)
                    f_sig = vec3(ONE, ONE, ONE)
                    xl = vec3(ZERO, ZERO, ZERO)
                    vl = vec3(ZERO, ZERO, ZERO)
                    gl = vec3(ZERO, ZERO, ZERO)
                    h = boxes.half_extents[box]
                    big_r = boxes.radius[box] + r
                    if single == 1:
                        xl, vl, gl = box_frame(boxes, box, contact, u, g)
                        f_mask, f_sig, count = feature_of(xl, h, big_r)
                        if count > 1:
                            if holds_on(xl, vl, gl, h, big_r, f_mask, f_sig) == 0:
                                # a curved part that cannot hold it: a tangent touch (within
                                # the sweep's resolution of a double root) flies on, else a
                                # bounce
                                resting = False
                                if -un <= TOUCH * wp.length(u):
                                    graze = 1
                    if graze == 1:
                        mode = FREE
                        supports = 0
                        g_eff = g
                        v = u
                        escape_box = box
                        escape_left = escape_time(xl, vl, gl, rest, h, big_r, f_mask, f_sig)
                    elif resting:
                        u_sq = wp.dot(u, u)
                        u = along_plane(u, n)
                        if single == 1:
                            if count <= 1:
                                kind_flag = 1
                                mode = FACE
                                sup_box = box
                                face_axis, face_side = dominant_axis(
                                    wp.transpose(boxes.rotation[box]) * n)
                                supports = 1
                                n1 = n
                                g_eff = along_plane(g, n)
                            else:
                                kind_flag = 1
                                mode = CURVED
                                sup_box = box
                                mask = f_mask
                                sig = f_sig
                                supports = 0
                                g_eff = g
                        elif supports == 1:  # along the crease of the two planes
                            kind_flag = 1
                            mode = PLANE
                            supports = 2
                            n2 = n
                            crease = wp.normalize(wp.cross(n1, n2))
                            g_eff = wp.dot(g, crease) * crease
                            u = wp.dot(u, crease) * crease
                        else:  # wedged by three supports
                            kind_flag = 1
                            mode = PLANE
                            g_eff = vec3(ZERO, ZERO, ZERO)
                            u = vec3(ZERO, ZERO, ZERO)
                        supported += kind_flag
                        energy = energy - HALF * m * (u_sq - wp.dot(u, u))
                        v = u
                    else:
                        v = u - TWO * un * n
                        if wp.static(features.lossy):
                            energy = on_contact.loss(energy, m, contact, physics)
                            v = v * keep
                        if mode == CURVED:
                            mode = FREE
                            g_eff = g
                        if supports > 0:
                            speed = wp.length(v)
                            leaves = wp.dot(v, n1) > TANGENT_REL * speed
                            if supports == 2:
                                leaves = leaves or wp.dot(v, n2) > TANGENT_REL * speed
                            if leaves:  # off its support: the whole of gravity again
                                supports = 0
                                mode = FREE
                                g_eff = g
                    on_contact.event(frame, sphere, box, kind_flag, contact, n,
                                     (dt - rest) / dt, -un, events)
                    a = contact
        return a, v, L, energy, bounces, capped, supported

    return SimpleNamespace(ballistic_path=ballistic_path)
