"""One frame of exact ballistic motion: the per-sphere multi-bounce loop along parabolas.

From its position the sphere follows ``x(s) = a + v s + 1/2 g s^2`` with its *true* velocity
``v``; at the nearest contact it reflects (``v' = v - 2 (v . n) n`` with the velocity at the
contact) and flies on along the new parabola for the rest of the frame's *time*, until nothing
is hit or ``max_bounces`` contacts were taken (then it stays at its last contact with its
reflected velocity, counted as capped, as in the linear model). The velocity returned is the
true velocity at the frame's end. Spin (``dynamics.friction_spin``) and ``energy_retention``
are applied at each contact exactly as in :mod:`bounce`.

Resting and sliding contacts (supports). A contact is a support when gravity presses the sphere
onto the surface (``g . n < 0``) and its normal speed is at most ``RESTING_SPEED`` or the hop the
bounce would start is shorter than ``dt / max_bounces`` (one the bounce cap could not follow
through the frame): the normal part of the velocity is removed (the energy drops by exactly that
kinetic energy) and, for the rest of the frame, the sphere moves with the part of gravity along
the surface's tangent plane, ``g - (g . n) n``: exact on a flat face, a sphere at rest stays bit
for bit, one on a slope slides. A second support on another plane slides along their crease; a
third stops the sphere for the rest of the frame. A bounce that sends the sphere off its support
gives it back the whole of gravity. Hops therefore never shrink without end within a frame (no
Zeno loop). Known limit: a sphere sliding off the edge of a face keeps the tangential gravity
until the frame ends (it falls at most ``|g| dt^2 / 2`` late) and slides on a curved (edge or
corner) support along its tangent plane; the next frame's contact puts it back on the surface.
"""

from functools import cache
from types import SimpleNamespace

import warp as wp

from .arc import arc_funcs
from .contact import contact_funcs
from .data import Features, model_structs
from .nearest_arc import model_nearest_hit_arc, nearest_arc_funcs
from .precision import precision

#: A contact with a normal speed at most this [m/s] while gravity presses the sphere onto the
#: surface is a support: a hop of at most 1.3 micrometres, the exact reference's threshold.
RESTING_SPEED = 5.0e-3

#: Two support normals closer than this (``1 - n1 . n2``) are one plane (coplanar tiles): the
#: new one replaces the old one instead of making a crease.
COPLANAR_REL = 1.0e-6


@cache
def ballistic_funcs(features: Features) -> SimpleNamespace:
    """Build the ballistic bounce loop for one feature set (``precision``, ``spin``, ``lossy``,
    ``broad_phase`` and ``events`` are read; see ``nearest_arc.model_nearest_hit_arc``). Events
    are written as ``bounce.bounce_funcs`` writes them, the fraction being of the frame's time,
    exact here.

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
    ZERO = scalar(0.0)
    HALF = scalar(0.5)
    TWO = scalar(2.0)
    RESTING = scalar(RESTING_SPEED)
    COPLANAR = scalar(1.0 - COPLANAR_REL)
    TANGENT_REL = scalar(p.tangent_rel)
    HALF_HOP = scalar(0.5)  # the hop of a bounce lasts 2 |u.n| / |g.n|: half of it per cap

    @wp.func
    def along_plane(x: vec3, n: vec3):
        """``x`` without its component along the unit ``n``."""
        return x - wp.dot(x, n) * n

    @wp.func
    def ballistic_path(a: vec3, v: vec3, r: scalar, m: scalar, L: vec3, energy: scalar,
                       physics: Physics, boxes: Boxes, broad: BroadPhase, frame: int,
                       sphere: int, events: EventBuffer):
        """Move a sphere for one frame along its parabolas, bouncing up to ``max_bounces`` times.

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
            normal kinetic energy a support removes; ``bounces`` counts the contacts taken,
            ``capped`` is 1 when the cap stopped the sphere at its last contact, ``supported``
            is 1 when one of them was a support.
        """
        g = physics.gravity
        dt = physics.dt
        max_bounces = physics.max_bounces
        rest = dt  # time left in the frame [s]
        g_eff = g  # gravity the sphere feels: its tangential part while supported
        supports = int(0)
        n1 = vec3(ZERO, ZERO, ZERO)
        n2 = vec3(ZERO, ZERO, ZERO)
        bounces = int(0)
        capped = int(0)
        supported = int(0)
        done = int(0)
        while done == 0:
            box, s, n = nearest_hit_arc(a, v, g_eff, rest, r, boxes, broad)
            if box < 0:
                a = arc_point(a, v, g_eff, rest)
                v = v + rest * g_eff
                done = 1
            elif bounces >= max_bounces:
                capped = 1  # time left and a contact ahead: stay at the last contact
                done = 1
            else:
                bounces += 1
                contact = arc_contact_centre(a, v, g_eff, s, n, boxes.radius[box] + r,
                                             boxes.extent[box])
                u = v + s * g_eff
                rest = wp.max(rest - s, ZERO)
                L = on_contact.spin(L, u, n, r, m, physics)
                un = wp.dot(u, n)
                gn = wp.dot(g, n)
                keep = on_contact.keep(physics)
                # a support: gravity presses, and the normal speed is below RESTING_SPEED or the
                # hop would last less than dt / max_bounces (2 keep |un| / |gn|)
                resting = gn < -TANGENT_REL * wp.length(g) and (
                    -un <= wp.max(RESTING, -gn * dt * HALF_HOP / (scalar(wp.max(max_bounces, 1))
                                                                * keep)))
                on_contact.event(frame, sphere, box, int(resting), contact, n,
                                 (dt - rest) / dt, -un, events)
                if resting:
                    supported += 1
                    u_sq = wp.dot(u, u)
                    if supports == 0 or (supports == 1 and wp.dot(n, n1) >= COPLANAR):
                        supports = 1
                        n1 = n
                        g_eff = along_plane(g, n)
                        u = along_plane(u, n)
                    elif supports == 1:
                        g_t = along_plane(g, n)
                        u_t = along_plane(u, n)
                        if wp.dot(g_t, n1) >= ZERO and wp.dot(u_t, n1) >= ZERO:
                            n1 = n  # sliding off the old plane onto the new one
                            g_eff = g_t
                            u = u_t
                        else:  # along the crease of the two planes
                            supports = 2
                            n2 = n
                            crease = wp.normalize(wp.cross(n1, n2))
                            g_eff = wp.dot(g, crease) * crease
                            u = wp.dot(u, crease) * crease
                    else:  # wedged by three supports
                        g_eff = vec3(ZERO, ZERO, ZERO)
                        u = vec3(ZERO, ZERO, ZERO)
                    energy = energy - HALF * m * (u_sq - wp.dot(u, u))
                    v = u
                else:
                    v = u - TWO * un * n
                    if wp.static(features.lossy):
                        energy = on_contact.loss(energy, m, contact, physics)
                        v = v * keep
                    if supports > 0:
                        speed = wp.length(v)
                        leaves = wp.dot(v, n1) > TANGENT_REL * speed
                        if supports == 2:
                            leaves = leaves or wp.dot(v, n2) > TANGENT_REL * speed
                        if leaves:  # off its support: the whole of gravity again
                            supports = 0
                            g_eff = g
                a = contact
        return a, v, L, energy, bounces, capped, supported

    return SimpleNamespace(ballistic_path=ballistic_path)
