"""Kernels for the batched single-frame queries (sheet methods 1-3): each task takes a block of
``spheres_per_task`` spheres in turn (on the CPU many, ``warpsim.model.CPU_SPHERES_PER_TASK``;
on a GPU one a thread), the same bits whatever the block (see ``frame_kernel``)."""


from functools import cache

import warp as wp

from .arc import arc_funcs
from .ballistic import ballistic_funcs
from .bounce import bounce_funcs
from .data import Features, model_structs
from .dynamics import dynamics_funcs
from .nearest import model_nearest_hit, nearest_funcs
from .nearest_arc import model_nearest_hit_arc, nearest_arc_funcs
from .precision import precision
from .variant import variant_kernel


@cache
def collide_kernel(features: Features):
    """The nearest-contact kernel for one precision, broad phase and motion (the features read).

    ``motion="linear"`` (sheet methods 1 and 2): per sphere, the centre would move from ``A`` to
    ``B = A + v dt``; the kernel finds the first contact over all boxes and writes the SPEC
    results. Rows without a contact hold ``box = -1``, ``t = 1``, ``position = new_position =
    B``, ``normal = 0`` and ``new_velocity = v``.

    ``motion="ballistic"``: the centre would follow ``x(s) = A + v s + 1/2 g s^2`` for ``s`` in
    ``[0, dt]``. ``t`` is the contact time as a fraction of ``dt``, ``new_velocity`` the
    reflected velocity at the contact and ``new_position`` the end of the frame along the new
    parabola. Rows without a contact hold ``box = -1``, ``t = 1``, ``position = new_position =
    x(dt)``, ``normal = 0`` and ``new_velocity = v + g dt``.

    Every broad phase gives bit-identical results.
    """
    p = precision(features.precision)
    scalar, vec3 = p.scalar, p.vec3
    Boxes, BroadPhase, Physics, _ = model_structs(p)
    ballistic = features.motion == "ballistic"
    nearest_hit = model_nearest_hit(p, features.broad_phase)
    contact_centre = nearest_funcs(p).contact_centre
    nearest_hit_arc = model_nearest_hit_arc(p, features.broad_phase)
    arc_contact_centre = nearest_arc_funcs(p).arc_contact_centre
    arc_point = arc_funcs(p).arc_point
    TWO = scalar(2.0)
    ONE = scalar(1.0)
    ZERO = scalar(0.0)

    @wp.func
    def chord_contact(a: vec3, v: vec3, r: scalar, physics: Physics, boxes: Boxes,
                      broad: BroadPhase):
        """``(box, t, contact, normal, new_position, new_velocity)`` of the segment."""
        d = v * physics.dt
        box, t, n = nearest_hit(a, d, r, -1, boxes, broad)
        contact = a + t * d
        new_v = v
        new_p = contact
        if box >= 0:
            new_v = v - TWO * wp.dot(v, n) * n
            start = contact_centre(a, t, d, n, boxes.radius[box] + r, boxes.extent[box])
            new_p = start + (ONE - t) * (d - TWO * wp.dot(d, n) * n)
        else:
            new_p = a + d
            contact = new_p
        return box, t, contact, n, new_p, new_v

    @wp.func
    def arc_contact(a: vec3, v: vec3, r: scalar, physics: Physics, boxes: Boxes,
                    broad: BroadPhase):
        """``(box, t, contact, normal, new_position, new_velocity)`` of the parabola."""
        gravity = physics.gravity
        dt = physics.dt
        box, s, n = nearest_hit_arc(a, v, gravity, dt, r, boxes, broad)
        contact = arc_point(a, v, gravity, s)
        new_v = v + gravity * dt
        new_p = contact
        if box >= 0:
            u = v + gravity * s
            new_v = u - TWO * wp.dot(u, n) * n
            start = arc_contact_centre(a, v, gravity, s, n, boxes.radius[box] + r,
                                       boxes.extent[box])
            new_p = arc_point(start, new_v, gravity, wp.max(dt - s, ZERO))
        return box, s / dt, contact, n, new_p, new_v

    first_contact = arc_contact if ballistic else chord_contact

    @variant_kernel
    def collide_spheres(
        # Model:
        boxes: Boxes, broad: BroadPhase, physics: Physics,
        # In:
        position_in: wp.array[vec3], velocity_in: wp.array[vec3], radius: wp.array[scalar],
        # Out:
        box_out: wp.array[wp.int32], t_out: wp.array[scalar], contact_out: wp.array[vec3],
        normal_out: wp.array[vec3], new_position_out: wp.array[vec3],
        new_velocity_out: wp.array[vec3],
        # Launch:
        spheres_per_task: int,
    ):
        # a block of spheres a task (a CPU task first copies the launch's arguments)
        i = wp.tid() * spheres_per_task
        last = wp.min(i + spheres_per_task, position_in.shape[0])
        while i < last:
            box, t, contact, n, new_p, new_v = first_contact(position_in[i], velocity_in[i],
                                                             radius[i], physics, boxes, broad)
            box_out[i] = box
            t_out[i] = t
            contact_out[i] = contact
            normal_out[i] = n
            new_position_out[i] = new_p
            new_velocity_out[i] = new_v
            i += 1

    return collide_spheres


@cache
def bounce_kernel(features: Features):
    """The multi-bounce kernel (sheet method 3) for one feature set (all but
    ``energy_correction`` and ``events`` read).

    Per sphere, ``motion="linear"``: the bounce loop over the frame's straight-line displacement
    ``v dt`` (no gravity: the model's gravity is not read). ``motion="ballistic"``: the bounce
    loop along the parabolas of gravity for the frame's time; the velocity out is the true
    velocity at the frame's end. Outputs the number of contacts taken, whether the cap stopped
    the sphere, and the new position, velocity and angular momentum (the sheet's third
    prototype, its by-value output fixed). The potential's origin is the world origin.
    """
    p = precision(features.precision)
    scalar, vec3 = p.scalar, p.vec3
    Boxes, BroadPhase, Physics, EventBuffer = model_structs(p)
    features = features.but(energy_correction=False, events=False)
    if features.motion == "ballistic":
        path = ballistic_funcs(features).ballistic_path
    else:
        path = bounce_funcs(features).bounce_path
    dyn = dynamics_funcs(p)
    kinetic_energy, potential = dyn.kinetic_energy, dyn.potential
    ZERO = scalar(0.0)
    BALLISTIC = features.motion == "ballistic"

    @wp.func(inline=True)
    def query_physics(physics: Physics):
        """The model's constants as this query sees them: no gravity for the linear motion,
        the potential's origin at the world origin."""
        out = physics
        zero = vec3(ZERO, ZERO, ZERO)
        if wp.static(not BALLISTIC):
            out.gravity = zero
        out.origin = zero
        return out

    @variant_kernel
    def bounce_spheres(
        # Model:
        boxes: Boxes, broad: BroadPhase, physics: Physics,
        # In:
        position_in: wp.array[vec3], velocity_in: wp.array[vec3], radius: wp.array[scalar],
        mass: wp.array[scalar], angular_momentum_in: wp.array[vec3],
        # Out:
        bounces_out: wp.array[wp.int32], supports_out: wp.array[wp.int32],
        capped_out: wp.array[wp.int32], position_out: wp.array[vec3], velocity_out: wp.array[vec3],
        angular_momentum_out: wp.array[vec3], events_out: EventBuffer,
        # Launch:
        spheres_per_task: int,
    ):
        # a block of spheres a task (a CPU task first copies the launch's arguments)
        i = wp.tid() * spheres_per_task
        last = wp.min(i + spheres_per_task, position_in.shape[0])
        ph = query_physics(physics)
        while i < last:
            v = velocity_in[i]
            m = mass[i]
            a = position_in[i]
            energy = kinetic_energy(m, v) + potential(m, ph.gravity, a, ph.origin)
            x, v_new, L, energy, bounces, capped, supported = path(
                a, v, radius[i], m, angular_momentum_in[i], energy, ph, boxes, broad, 0, i,
                events_out)
            bounces_out[i] = bounces - supported
            supports_out[i] = supported
            capped_out[i] = capped
            position_out[i] = x
            velocity_out[i] = v_new
            angular_momentum_out[i] = L
            i += 1

    return bounce_spheres
