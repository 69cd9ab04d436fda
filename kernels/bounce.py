"""Several bounces in one frame (the sheet's method 3): the per-sphere bounce loop.

From its position the sphere follows the chord of its free-flight parabola for the frame, the
displacement ``(u + g dt / 2) dt`` of its mean velocity (``u`` the velocity at the frame's
start; without gravity the straight segment ``u dt``); at the nearest contact it
reflects and goes on with the rest of the path, until nothing is hit or ``max_bounces`` contacts
were taken. The broken line is exactly as long as the straight one (elastic contacts). When the
cap is reached with path still to go, the sphere stays at its last contact (never inside, never
through) with its reflected velocity, and is counted as capped. The velocity at the frame's
end is the (reflected) mean velocity plus the second half kick ``g dt / 2``: in free flight
``u + g dt``, so the chord's ends lie on the exact parabola at every frame.

Resting contacts: a contact whose approach speed (of the mean velocity ``w``) is at most
``RESTING_FRAMES_*`` frames of gravity into the surface (``-w.n <= RESTING_FRAMES max(-g.n, 0)
dt``) is a support, not a bounce: the normal part of the velocity and of the rest of the path is
removed and the sphere slides on; at the frame's end its velocity into the support is removed
too (it ends on the support, as it started: a sphere at rest has velocity 0, one sliding on a
slope gains exactly ``g_t dt``).
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

    The event rows (``contact.contact_funcs``' ``write_event``) give the normal speed of the
    velocity at the contact's time ``tau`` on the chord's parabola, ``-(w + g (tau - dt / 2)).n``
    (``u + g tau`` in free flight), at least 0.
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
        than its energy can take it; the true parabola would not. The highest point the energy
        allows is where all of it but the sideways kinetic energy of ``v`` (which gravity never
        changes) is potential: ``(E - Ep(contact) - 1/2 m |v_side|^2) / (m |g|)`` above the
        contact. A rise beyond it (by more than the rounding of the energies) is cut, only along
        gravity, so the sideways motion is untouched and the cut path ends at that height;
        without gravity nothing is cut.
        """
        out = d
        g_len = wp.length(g)
        if g_len > ZERO:
            down = g / g_len
            rise = -wp.dot(d, down)
            if rise > ZERO:  # else nothing to cut (``allowed`` and the slack are >= 0)
                side = v - wp.dot(v, down) * down
                ep_c = potential(m, g, contact, origin)
                spare = energy - ep_c - HALF * m * wp.dot(side, side)
                allowed = wp.max(spare, ZERO) / (m * g_len)
                slack = RESET_SLACK * (wp.abs(energy) + wp.abs(ep_c)) / (m * g_len)
                if rise - allowed > slack:
                    out = d + (rise - allowed) * down
        return out

    @wp.func
    def bounce_path(a: vec3, v: vec3, r: scalar, m: scalar, L: vec3, energy: scalar,
                    physics: Physics, boxes: Boxes, broad: BroadPhase, frame: int, sphere: int,
                    events: EventBuffer):
        """Move a sphere for one frame among the boxes, bouncing up to ``max_bounces`` times.

        Args:
            a: centre at the start [m]. v: velocity at the frame's start [m/s] (the frame sweeps
            its chord, mean velocity ``v + g dt / 2``). r: radius [m].
            m: mass [kg]. L: angular momentum [kg m^2/s]. energy: total energy [J] (see
            ``dynamics``). physics: the scene's constants (``data.model_structs``): gravity
            (the chord's half kicks, resting contacts, the rise cut and the loss's potential),
            the potential's origin, ``dt``, friction, the ``|Rot|`` clamp, the retention and the
            cap on contacts this frame (a launch value, not compiled in: the loop costs the
            same, and each cap would be a build of its own). boxes, broad: the obstacles and
            the broad phase's data. frame, sphere: what an event row names (frame within the
            launch, sphere index). events: the event buffer (written only when built with
            ``events``).

        Returns:
            ``(position, velocity, L, energy, bounces, capped, supported)``: ``velocity`` is the
            one at the frame's end [m/s] (before any energy reset); ``bounces`` counts
            the contacts taken (resting ones included), ``capped`` is 1 when the cap stopped
            the sphere at its last contact, ``supported`` counts the resting (support)
            contacts among them.
        """
        g = physics.gravity
        dt = physics.dt
        # the chord of the frame's free-flight parabola: its velocity is the frame's mean,
        # u + g dt / 2 (the velocity at the frame's start plus half a kick)
        half_kick = g * (HALF * dt)
        w = v + half_kick
        d = w * dt
        bounces = int(0)
        capped = int(0)
        supported = int(0)
        # the normal of the last resting contact, as three scalars: every vec3 the loop carries
        # is merged at its branches, and in float64 one vec3 more (this one, or ``L``) made
        # clang keep them all in memory, the frame 1.8x slower (BENCHMARKS.md, "float64: the
        # bounce loop's state in registers again")
        s0 = ZERO
        s1 = ZERO
        s2 = ZERO
        if wp.static(features.spin):  # the angular momentum, as scalars too
            l0 = L[0]
            l1 = L[1]
            l2 = L[2]
        done = int(0)
        travelled = ZERO  # fraction of the frame's path behind the sphere
        left = int(-1)  # the box the rest of the path leaves (it cannot meet it again)
        while done == 0:
            box, t, n = nearest_hit(a, d, r, left, boxes, broad)
            if box < 0:
                a = a + d
                done = 1
            elif bounces >= physics.max_bounces:
                capped = 1  # path left and no contact left: stay at the last contact
                done = 1
            else:
                bounces += 1
                contact = contact_centre(a, t, d, n, boxes.radius[box] + r, boxes.extent[box])
                if wp.static(features.spin):  # else L is not the loop's (see s0)
                    spun = on_contact.spin(vec3(l0, l1, l2), w, n, r, m, physics)
                    l0 = spun[0]
                    l1 = spun[1]
                    l2 = spun[2]
                vn = wp.dot(w, n)
                dn = wp.dot(d, n)
                resting = -vn <= REST * wp.max(-wp.dot(g, n), ZERO) * dt
                travelled = travelled + (ONE - travelled) * t
                if wp.static(not lossy):  # elastic: a support touches at the frame's start
                    if resting:
                        gap = t * -dn
                        scale = wp.max(wp.max(wp.abs(a[0]), wp.abs(a[1])), wp.abs(a[2]))
                        resting = gap <= GAP_ULPS * (scale + wp.length(d))
                if wp.static(features.events):
                    # the velocity at the contact's time on the chord's parabola (mean velocity
                    # w, acceleration g), u + g tau: 0 for a sphere at rest on its support
                    speed = -wp.dot(w + g * ((travelled - HALF) * dt), n)
                    on_contact.event(frame, sphere, box, int(resting), contact, n, travelled,
                                     wp.max(speed, ZERO), events)
                if resting:
                    supported += 1
                    s0 = n[0]
                    s1 = n[1]
                    s2 = n[2]
                    w = w - vn * n
                    d = (ONE - t) * (d - dn * n)
                else:
                    w = w - TWO * vn * n
                    d = (ONE - t) * (d - TWO * dn * n)
                    if wp.static(lossy):
                        energy = on_contact.loss(energy, m, contact, physics)
                        keep = on_contact.keep(physics)
                        w = w * keep
                        d = d * keep
                d = clip_rise(contact, d, w, m, g, physics.origin, energy)
                a = contact
                # the rest leaves the box's surface (or runs along it): a straight path from
                # a convex body's surface that does not point into it never enters it, so the
                # next query skips the box; a rest the rise cut turned inward tries it again
                left = int(-1)
                if wp.dot(d, n) >= ZERO:
                    left = box
        # the velocity at the frame's end: the second half kick; a support takes its part into
        # the surface (the sphere ends on it, its normal velocity 0, as at the frame's start)
        v = w + half_kick
        if wp.static(features.spin):
            L = vec3(l0, l1, l2)
        if supported > 0:
            support = vec3(s0, s1, s2)
            into = wp.dot(v, support)
            if into < ZERO:
                v = v - into * support
        return a, v, L, energy, bounces, capped, supported

    return SimpleNamespace(bounce_path=bounce_path)
