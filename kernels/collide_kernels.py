"""Kernels for the batched single-frame queries (sheet methods 1-3): one thread per sphere."""


from functools import cache

import warp as wp

from .arc import arc_funcs
from .ballistic import ballistic_funcs
from .bounce import bounce_funcs
from .dynamics import dynamics_funcs
from .nearest import model_nearest_hit, nearest_funcs
from .nearest_arc import model_nearest_hit_arc, nearest_arc_funcs
from .precision import precision
from .variant import variant_kernel


@cache
def collide_kernel(precision_name: str, broad_phase: str):
    """The nearest-contact kernel (sheet methods 1 and 2) for one precision and broad phase.

    Per sphere: the centre would move from ``A`` to ``B = A + v dt``; the kernel finds the first
    contact over all boxes and writes the SPEC results. Rows without a contact hold ``box = -1``,
    ``t = 1``, ``position = new_position = B``, ``normal = 0`` and ``new_velocity = v``.
    ``broad_phase`` is one of ``nearest.BROAD_PHASES`` (bit-identical results).
    """
    p = precision(precision_name)
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    nearest_hit = model_nearest_hit(p, broad_phase)
    contact_centre = nearest_funcs(p).contact_centre
    TWO = scalar(2.0)
    ONE = scalar(1.0)

    @variant_kernel
    def collide_boxes_kernel(
        # Model:
        box_center: wp.array(dtype=vec3),
        box_rotation: wp.array(dtype=mat33),
        box_half_extents: wp.array(dtype=vec3),
        box_radius: wp.array(dtype=scalar),
        box_extent: wp.array(dtype=vec3),
        box_bvh: wp.uint64,
        grid_lower: vec3,
        grid_cell: vec3,
        grid_inv_cell: vec3,
        grid_dims: wp.vec3i,
        grid_margin: scalar,
        grid_cell_start: wp.array(dtype=wp.int32),
        grid_cell_boxes: wp.array(dtype=wp.int32),
        dt: scalar,
        # In:
        position_in: wp.array(dtype=vec3),
        velocity_in: wp.array(dtype=vec3),
        radius: wp.array(dtype=scalar),
        # Out:
        box_out: wp.array(dtype=wp.int32),
        t_out: wp.array(dtype=scalar),
        contact_out: wp.array(dtype=vec3),
        normal_out: wp.array(dtype=vec3),
        new_position_out: wp.array(dtype=vec3),
        new_velocity_out: wp.array(dtype=vec3),
    ):
        i = wp.tid()
        a = position_in[i]
        v = velocity_in[i]
        d = v * dt
        box, t, n = nearest_hit(a, d, radius[i], box_center, box_rotation,
                                box_half_extents, box_radius, box_extent, box_bvh,
                                grid_lower, grid_cell, grid_inv_cell, grid_dims, grid_margin,
                                grid_cell_start, grid_cell_boxes)
        contact = a + t * d
        new_v = v
        new_p = contact
        if box >= 0:
            new_v = v - TWO * wp.dot(v, n) * n
            start = contact_centre(a, t, d, n, box_radius[box] + radius[i], box_extent[box])
            new_p = start + (ONE - t) * (d - TWO * wp.dot(d, n) * n)
        else:
            new_p = a + d
            contact = new_p
        box_out[i] = box
        t_out[i] = t
        contact_out[i] = contact
        normal_out[i] = n
        new_position_out[i] = new_p
        new_velocity_out[i] = new_v

    return collide_boxes_kernel


@cache
def collide_arc_kernel(precision_name: str, broad_phase: str):
    """The nearest-contact kernel along the exact parabola (``motion="ballistic"``).

    Per sphere: the centre would follow ``x(s) = A + v s + 1/2 g s^2`` for ``s`` in ``[0, dt]``;
    the kernel finds the first contact over all boxes. ``t`` is the contact time as a fraction
    of ``dt``, ``new_velocity`` the reflected velocity at the contact and ``new_position`` the
    end of the frame along the new parabola. Rows without a contact hold ``box = -1``, ``t = 1``,
    ``position = new_position = x(dt)``, ``normal = 0`` and ``new_velocity = v + g dt``.
    """
    p = precision(precision_name)
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    nearest_hit_arc = model_nearest_hit_arc(p, broad_phase)
    arc = nearest_arc_funcs(p)
    arc_contact_centre = arc.arc_contact_centre
    arc_point = arc_funcs(p).arc_point
    TWO = scalar(2.0)
    ZERO = scalar(0.0)

    @variant_kernel
    def collide_arcs_kernel(
        # Model:
        box_center: wp.array(dtype=vec3),
        box_rotation: wp.array(dtype=mat33),
        box_half_extents: wp.array(dtype=vec3),
        box_radius: wp.array(dtype=scalar),
        box_extent: wp.array(dtype=vec3),
        box_bvh: wp.uint64,
        grid_lower: vec3,
        grid_cell: vec3,
        grid_inv_cell: vec3,
        grid_dims: wp.vec3i,
        grid_margin: scalar,
        grid_cell_start: wp.array(dtype=wp.int32),
        grid_cell_boxes: wp.array(dtype=wp.int32),
        gravity: vec3,
        dt: scalar,
        # In:
        position_in: wp.array(dtype=vec3),
        velocity_in: wp.array(dtype=vec3),
        radius: wp.array(dtype=scalar),
        # Out:
        box_out: wp.array(dtype=wp.int32),
        t_out: wp.array(dtype=scalar),
        contact_out: wp.array(dtype=vec3),
        normal_out: wp.array(dtype=vec3),
        new_position_out: wp.array(dtype=vec3),
        new_velocity_out: wp.array(dtype=vec3),
    ):
        i = wp.tid()
        a = position_in[i]
        v = velocity_in[i]
        box, s, n = nearest_hit_arc(a, v, gravity, dt, radius[i], box_center, box_rotation,
                                    box_half_extents, box_radius, box_extent, box_bvh,
                                    grid_lower, grid_cell, grid_inv_cell, grid_dims,
                                    grid_margin, grid_cell_start, grid_cell_boxes)
        contact = arc_point(a, v, gravity, s)
        new_v = v + gravity * dt
        new_p = contact
        if box >= 0:
            u = v + gravity * s
            new_v = u - TWO * wp.dot(u, n) * n
            start = arc_contact_centre(a, v, gravity, s, n, box_radius[box] + radius[i],
                                       box_extent[box])
            new_p = arc_point(start, new_v, gravity, wp.max(dt - s, ZERO))
        box_out[i] = box
        t_out[i] = s / dt
        contact_out[i] = contact
        normal_out[i] = n
        new_position_out[i] = new_p
        new_velocity_out[i] = new_v

    return collide_arcs_kernel


@cache
def bounce_kernel(precision_name: str, spin: bool, lossy: bool, broad_phase: str,
                  motion: str = "linear"):
    """The multi-bounce kernel (sheet method 3) for one feature set.

    Per sphere, ``motion="linear"``: the bounce loop over the frame's straight-line displacement
    ``v dt`` (no gravity: the ``gravity`` argument is not read). ``motion="ballistic"``: the
    bounce loop along the parabolas of ``gravity`` for the frame's time; the velocity out is the
    true velocity at the frame's end. Outputs the number of contacts taken, whether the cap
    stopped the sphere, and the new position, velocity and angular momentum (the sheet's third
    prototype, its by-value output fixed). ``broad_phase`` as in :func:`collide_kernel`.
    """
    p = precision(precision_name)
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    if motion == "ballistic":
        path = ballistic_funcs(p, spin, lossy, broad_phase).ballistic_path
    elif motion == "linear":
        path = bounce_funcs(p, spin, lossy, broad_phase).bounce_path
    else:
        raise ValueError(f"motion must be 'linear' or 'ballistic', got {motion!r}")
    dyn = dynamics_funcs(p)
    kinetic_energy, potential = dyn.kinetic_energy, dyn.potential
    ZERO = scalar(0.0)
    BALLISTIC = motion == "ballistic"

    @variant_kernel
    def bounce_spheres_kernel(
        # Model:
        box_center: wp.array(dtype=vec3),
        box_rotation: wp.array(dtype=mat33),
        box_half_extents: wp.array(dtype=vec3),
        box_radius: wp.array(dtype=scalar),
        box_extent: wp.array(dtype=vec3),
        box_bvh: wp.uint64,
        grid_lower: vec3,
        grid_cell: vec3,
        grid_inv_cell: vec3,
        grid_dims: wp.vec3i,
        grid_margin: scalar,
        grid_cell_start: wp.array(dtype=wp.int32),
        grid_cell_boxes: wp.array(dtype=wp.int32),
        gravity: vec3,
        dt: scalar,
        friction: scalar,
        max_rot: scalar,
        retention: scalar,
        max_bounces: int,
        # In:
        position_in: wp.array(dtype=vec3),
        velocity_in: wp.array(dtype=vec3),
        radius: wp.array(dtype=scalar),
        mass: wp.array(dtype=scalar),
        angular_momentum_in: wp.array(dtype=vec3),
        # Out:
        bounces_out: wp.array(dtype=wp.int32),
        capped_out: wp.array(dtype=wp.int32),
        position_out: wp.array(dtype=vec3),
        velocity_out: wp.array(dtype=vec3),
        angular_momentum_out: wp.array(dtype=vec3),
        event_count_out: wp.array(dtype=wp.int32),
        event_index_out: wp.array2d(dtype=wp.int32),
        event_vector_out: wp.array2d(dtype=vec3),
        event_scalar_out: wp.array2d(dtype=scalar),
    ):
        i = wp.tid()
        v = velocity_in[i]
        m = mass[i]
        zero = vec3(ZERO, ZERO, ZERO)
        a = position_in[i]
        g = zero
        if wp.static(BALLISTIC):
            g = gravity
        x, v_new, L, energy, bounces, capped, supported = path(
            a, v, radius[i], m, angular_momentum_in[i],
            kinetic_energy(m, v) + potential(m, g, a, zero), g, zero, dt, friction, max_rot,
            retention, max_bounces,
            box_center, box_rotation, box_half_extents, box_radius, box_extent, box_bvh,
            grid_lower, grid_cell, grid_inv_cell, grid_dims, grid_margin, grid_cell_start,
            grid_cell_boxes, 0, i, event_count_out, event_index_out, event_vector_out,
            event_scalar_out)
        bounces_out[i] = bounces
        capped_out[i] = capped
        position_out[i] = x
        velocity_out[i] = v_new
        angular_momentum_out[i] = L

    return bounce_spheres_kernel
