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

from .dynamics import RESET_ULPS, dynamics_funcs
from .nearest import model_nearest_hit, nearest_funcs
from .precision import Precision

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
def bounce_funcs(p: Precision, spin: bool, lossy: bool, broad_phase: str,
                 events: bool = False) -> SimpleNamespace:
    """Build the bounce loop for one precision and one feature set.

    Args:
        p: precision.
        spin: update the angular momentum from contact friction (else ``L`` passes through
            untouched and no spin code is compiled).
        lossy: apply ``energy_retention`` at each bounce (else no loss code is compiled).
        broad_phase: one of ``nearest.BROAD_PHASES`` (bit-identical results).
        events: write one row per contact into the event buffer (else no event code).

    Returns:
        Namespace with ``bounce_path``.

    Event buffer (see :func:`write_event`): ``event_count_out[0]`` counts every contact of the
    launch (the rows past the buffer's capacity are dropped, never written), row ``j`` of
    ``event_index_out`` (C, 4) is ``(frame, sphere, box, resting)``, of ``event_vector_out`` (C,
    2) ``(contact centre [m], normal)``, of ``event_scalar_out`` (C, 2) ``(fraction of the
    frame's path, normal speed before the contact [m/s])``; the normal speed is that of the
    velocity at the contact's time ``tau`` on the chord's parabola, ``-(w + g (tau - dt / 2)).n``
    (``u + g tau`` in free flight), at least 0.
    """
    scalar, vec3 = p.scalar, p.vec3
    nearest_hit = model_nearest_hit(p, broad_phase)
    contact_centre = nearest_funcs(p).contact_centre
    dyn = dynamics_funcs(p)
    friction_spin = dyn.friction_spin
    potential = dyn.potential
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
            side = v - wp.dot(v, down) * down
            ep_c = potential(m, g, contact, origin)
            spare = energy - ep_c - HALF * m * wp.dot(side, side)
            allowed = wp.max(spare, ZERO) / (m * g_len)
            rise = -wp.dot(d, down)
            slack = RESET_SLACK * (wp.abs(energy) + wp.abs(ep_c)) / (m * g_len)
            if rise - allowed > slack:
                out = d + (rise - allowed) * down
        return out

    @wp.func
    def write_event(frame: int, sphere: int, box: int, resting: int, contact: vec3, n: vec3,
                    fraction: scalar, speed: scalar, event_count_out: wp.array(dtype=wp.int32),
                    event_index_out: wp.array2d(dtype=wp.int32),
                    event_vector_out: wp.array2d(dtype=vec3),
                    event_scalar_out: wp.array2d(dtype=scalar)):
        """Append one contact to the launch's event buffer (counted even when it is full)."""
        row = wp.atomic_add(event_count_out, 0, 1)
        if row < event_index_out.shape[0]:
            event_index_out[row, 0] = frame
            event_index_out[row, 1] = sphere
            event_index_out[row, 2] = box
            event_index_out[row, 3] = resting
            event_vector_out[row, 0] = contact
            event_vector_out[row, 1] = n
            event_scalar_out[row, 0] = fraction
            event_scalar_out[row, 1] = speed

    @wp.func
    def bounce_path(a: vec3, v: vec3, r: scalar, m: scalar, L: vec3, energy: scalar,
                    g: vec3, origin: vec3, dt: scalar, friction: scalar, max_rot: scalar,
                    retention: scalar, max_bounces: int,
                    box_center: wp.array(dtype=p.vec3), box_rotation: wp.array(dtype=p.mat33),
                    box_half_extents: wp.array(dtype=p.vec3),
                    box_radius: wp.array(dtype=p.scalar), box_extent: wp.array(dtype=p.vec3),
                    box_bvh: wp.uint64,
                    grid_lower: vec3, grid_cell: vec3, grid_inv_cell: vec3,
                    grid_dims: wp.vec3i, grid_margin: scalar,
                    grid_cell_start: wp.array(dtype=wp.int32),
                    grid_cell_boxes: wp.array(dtype=wp.int32), frame: int, sphere: int,
                    event_count_out: wp.array(dtype=wp.int32),
                    event_index_out: wp.array2d(dtype=wp.int32),
                    event_vector_out: wp.array2d(dtype=vec3),
                    event_scalar_out: wp.array2d(dtype=scalar)):
        """Move a sphere for one frame among the boxes, bouncing up to ``max_bounces`` times.

        Args:
            a: centre at the start [m]. v: velocity at the frame's start [m/s] (the frame sweeps
            its chord, mean velocity ``v + g dt / 2``). r: radius [m].
            m: mass [kg]. L: angular momentum [kg m^2/s]. energy: total energy [J] (see
            ``dynamics``). g: gravity [m/s^2] (the chord's half kicks, resting contacts, the
            rise cut and the loss's potential). origin: potential reference point [m].
            dt: frame duration [s].
            friction: ``k_f`` [kg/s]. max_rot: ``|Rot|`` clamp [rad/s]. retention: kept
            fraction of kinetic energy per bounce. max_bounces: cap on contacts this frame (a
            launch value, not compiled in: the loop costs the same, and each cap would be a
            build of its own). box_*: the obstacles (see ``nearest``);
            ``box_bvh`` and ``grid_*``: the broad phase's data (see ``nearest``). frame,
            sphere: what an event row names (frame within the launch, sphere index).
            event_*: the event buffer (written only when built with ``events``).

        Returns:
            ``(position, velocity, L, energy, bounces, capped, supported)``: ``velocity`` is the
            one at the frame's end [m/s] (before any energy reset); ``bounces`` counts
            the contacts taken, ``capped`` is 1 when the cap stopped the sphere at its last
            contact, ``supported`` is 1 when one of them was a resting contact.
        """
        # the chord of the frame's free-flight parabola: its velocity is the frame's mean,
        # u + g dt / 2 (the velocity at the frame's start plus half a kick)
        half_kick = g * (HALF * dt)
        w = v + half_kick
        d = w * dt
        bounces = int(0)
        capped = int(0)
        supported = int(0)
        support = vec3(ZERO, ZERO, ZERO)  # normal of the last resting contact
        done = int(0)
        travelled = ZERO  # fraction of the frame's path behind the sphere
        while done == 0:
            box, t, n = nearest_hit(a, d, r, box_center, box_rotation, box_half_extents,
                                    box_radius, box_extent, box_bvh, grid_lower, grid_cell,
                                    grid_inv_cell, grid_dims, grid_margin, grid_cell_start,
                                    grid_cell_boxes)
            if box < 0:
                a = a + d
                done = 1
            elif bounces >= max_bounces:
                capped = 1  # path left and no contact left: stay at the last contact
                done = 1
            else:
                bounces += 1
                contact = contact_centre(a, t, d, n, box_radius[box] + r, box_extent[box])
                if wp.static(spin):
                    L = friction_spin(L, w, n, r, m, dt, friction, max_rot)
                vn = wp.dot(w, n)
                dn = wp.dot(d, n)
                resting = -vn <= REST * wp.max(-wp.dot(g, n), ZERO) * dt
                travelled = travelled + (ONE - travelled) * t
                if wp.static(not lossy):  # elastic: a support touches at the frame's start
                    gap = t * -dn
                    scale = wp.max(wp.max(wp.abs(a[0]), wp.abs(a[1])), wp.abs(a[2]))
                    resting = resting and gap <= GAP_ULPS * (scale + wp.length(d))
                if wp.static(events):
                    # the velocity at the contact's time on the chord's parabola (mean velocity
                    # w, acceleration g), u + g tau: 0 for a sphere at rest on its support
                    speed = -wp.dot(w + g * ((travelled - HALF) * dt), n)
                    write_event(frame, sphere, box, int(resting), contact, n, travelled,
                                wp.max(speed, ZERO), event_count_out, event_index_out,
                                event_vector_out, event_scalar_out)
                if resting:
                    supported = 1
                    support = n
                    w = w - vn * n
                    d = (ONE - t) * (d - dn * n)
                else:
                    w = w - TWO * vn * n
                    d = (ONE - t) * (d - TWO * dn * n)
                    if wp.static(lossy):
                        ep = potential(m, g, contact, origin)
                        energy = ep + retention * (energy - ep)
                        keep = wp.sqrt(retention)
                        w = w * keep
                        d = d * keep
                d = clip_rise(contact, d, w, m, g, origin, energy)
                a = contact
        # the velocity at the frame's end: the second half kick; a support takes its part into
        # the surface (the sphere ends on it, its normal velocity 0, as at the frame's start)
        v = w + half_kick
        if supported == 1:
            into = wp.dot(v, support)
            if into < ZERO:
                v = v - into * support
        return a, v, L, energy, bounces, capped, supported

    return SimpleNamespace(bounce_path=bounce_path, write_event=write_event)
