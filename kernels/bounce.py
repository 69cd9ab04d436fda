"""Several bounces in one frame (the sheet's method 3): the per-sphere bounce loop.

From its position the sphere follows its displacement for the frame; at the nearest contact it
reflects and goes on with the rest of the path, until nothing is hit or ``max_bounces`` contacts
were taken. The broken line is exactly as long as the straight one (elastic contacts). When the
cap is reached with path still to go, the sphere stays at its last contact (never inside, never
through) with its reflected velocity, and is counted as capped.

Resting contacts: a contact whose approach speed is at most ``RESTING_FRAMES_*`` frames of
gravity into the surface (``-v.n <= RESTING_FRAMES max(-g.n, 0) dt``) is a support, not a
bounce: the normal part of the velocity and of the rest of the path is removed and the sphere
slides on.
This is what keeps a sphere at rest on a floor without jitter or sinking; a bounce that small
would rise less than ``2 g dt^2`` (5 mm at 60 Hz). A resting contact is inelastic: the frame
kernel then takes the energy of the state it ends in (never more than before) instead of
resetting the speed.
"""

from functools import cache
from types import SimpleNamespace

import warp as wp

from .contact import contact_funcs
from .data import Features, model_structs
from .dynamics import RESET_ULPS, dynamics_funcs
from .nearest import model_nearest_hit, nearest_funcs
from .precision import precision

#: With contact losses, approach speeds up to this many frames of gravity make a resting
#: (sliding) contact: below that a lossy ball would only decay through sub-frame hops.
RESTING_FRAMES_LOSSY = 2.0

#: With elastic contacts, a support is a sphere already touching at the frame's start
#: whose approach this frame's gravity explains (to this many frames of gravity): a sphere at
#: rest or sliding. An elastic ball that still has a hop in it, however small, keeps it; the
#: slack above 1 covers rounding and removes at most ``1/2 m (1e-3 g dt)^2`` of energy.
RESTING_FRAMES_ELASTIC = 1.001

#: "Touching at the start" for an elastic support: a gap along the normal of at most this many
#: ulps of the coordinates (a sphere put on a floor far from the origin sits a few ulps off it).
RESTING_GAP_ULPS = 16.0


@cache
def bounce_funcs(features: Features) -> SimpleNamespace:
    """Build the bounce loop for one feature set (``precision``, ``spin``, ``lossy``,
    ``broad_phase`` and ``events`` are read).

    Returns:
        Namespace with ``bounce_path``.
    """
    p = precision(features.precision)
    scalar, vec3 = p.scalar, p.vec3
    Boxes, BroadPhase, Physics, EventBuffer = model_structs(p)
    lossy = features.lossy
    nearest_hit = model_nearest_hit(p, features.broad_phase)
    contact_centre = nearest_funcs(p).contact_centre
    on_contact = contact_funcs(p, features.spin, lossy, features.events)
    potential = dynamics_funcs(p).potential
    ZERO = scalar(0.0)
    ONE = scalar(1.0)
    TWO = scalar(2.0)
    HALF = scalar(0.5)
    REST = scalar(RESTING_FRAMES_LOSSY if lossy else RESTING_FRAMES_ELASTIC)
    GAP_ULPS = scalar(RESTING_GAP_ULPS * p.eps)
    RESET_SLACK = scalar(RESET_ULPS * p.eps)

    @wp.func
    def clip_rise(contact: vec3, d: vec3, v: vec3, m: scalar, g: vec3, origin: vec3,
                  energy: scalar):
        """The rest of the path ``d`` after a contact, its rise cut to what ``energy`` allows.

        The chord model reflects the whole rest of the frame's path, so a sub-frame hop (a
        sphere released just above a floor, or any bounce at a large ``dt``) would climb higher
        than its energy can take it; the true parabola would not. Only the part of ``d`` against
        gravity is cut, so the sideways motion is untouched, and the rise allowed leaves the
        sideways kinetic energy of ``v`` (which gravity never changes) in place; without
        gravity nothing is cut.
        """
        out = d
        g_len = wp.length(g)
        if g_len > ZERO:
            ep_c = potential(m, g, contact, origin)
            ep_end = potential(m, g, contact + d, origin)
            if ep_end - energy > RESET_SLACK * (wp.abs(energy) + wp.abs(ep_end)):
                down = g / g_len
                side = v - wp.dot(v, down) * down
                spare = energy - ep_c - HALF * m * wp.dot(side, side)
                allowed = wp.max(spare, ZERO) / (m * g_len)
                rise = -wp.dot(d, down)
                if rise > allowed:
                    out = d + (rise - allowed) * down
        return out

    @wp.func
    def bounce_path(a: vec3, v: vec3, r: scalar, m: scalar, L: vec3, energy: scalar,
                    physics: Physics, boxes: Boxes, broad: BroadPhase, frame: int, sphere: int,
                    events: EventBuffer):
        """Move a sphere for one frame among the boxes, bouncing up to ``max_bounces`` times.

        Args:
            a: centre at the start [m]. v: velocity for the frame [m/s]. r: radius [m].
            m: mass [kg]. L: angular momentum [kg m^2/s]. energy: total energy [J] (see
            ``dynamics``). physics: the scene's constants (``data.model_structs``): gravity
            (only for resting contacts and the loss's potential), the potential's origin,
            ``dt``, friction, the ``|Rot|`` clamp, the retention and the cap on contacts this
            frame (a launch value, not compiled in: the loop costs the same, and each cap would
            be a build of its own). boxes, broad: the obstacles and the broad phase's data.
            frame, sphere: what an event row names (frame within the launch, sphere index).
            events: the event buffer (written only when built with ``events``).

        Returns:
            ``(position, velocity, L, energy, bounces, capped, supported)``: ``bounces`` counts
            the contacts taken, ``capped`` is 1 when the cap stopped the sphere at its last
            contact, ``supported`` is 1 when one of them was a resting contact.
        """
        g = physics.gravity
        dt = physics.dt
        d = v * dt
        bounces = int(0)
        capped = int(0)
        supported = int(0)
        done = int(0)
        travelled = ZERO  # fraction of the frame's path behind the sphere
        while done == 0:
            box, t, n = nearest_hit(a, d, r, boxes, broad)
            if box < 0:
                a = a + d
                done = 1
            elif bounces >= physics.max_bounces:
                capped = 1  # path left and no contact left: stay at the last contact
                done = 1
            else:
                bounces += 1
                contact = contact_centre(a, t, d, n, boxes.radius[box] + r, boxes.extent[box])
                L = on_contact.spin(L, v, n, r, m, physics)
                vn = wp.dot(v, n)
                dn = wp.dot(d, n)
                resting = -vn <= REST * wp.max(-wp.dot(g, n), ZERO) * dt
                travelled = travelled + (ONE - travelled) * t
                if wp.static(not lossy):  # elastic: a support touches at the frame's start
                    gap = t * -dn
                    scale = wp.max(wp.max(wp.abs(a[0]), wp.abs(a[1])), wp.abs(a[2]))
                    resting = resting and gap <= GAP_ULPS * (scale + wp.length(d))
                on_contact.event(frame, sphere, box, int(resting), contact, n, travelled, -vn,
                                 events)
                if resting:
                    supported = 1
                    v = v - vn * n
                    d = (ONE - t) * (d - dn * n)
                else:
                    v = v - TWO * vn * n
                    d = (ONE - t) * (d - TWO * dn * n)
                    if wp.static(lossy):
                        energy = on_contact.loss(energy, m, contact, physics)
                        keep = on_contact.keep(physics)
                        v = v * keep
                        d = d * keep
                d = clip_rise(contact, d, v, m, g, physics.origin, energy)
                a = contact
        return a, v, L, energy, bounces, capped, supported

    return SimpleNamespace(bounce_path=bounce_path)
