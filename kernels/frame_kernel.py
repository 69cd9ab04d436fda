"""The frame kernel: one thread per sphere advances it by one time step.

Per sphere (SPEC "Dynamics of one frame"): gravity by semi-implicit Euler (``v += g dt``), the
move by the bounce loop, the speed reset from the energy invariant, and the orientation from the
rotation vector. Variants come from :func:`frame_kernel`, keyed by what the scene needs, so a
scene without spin runs a kernel with no spin code in it.
"""

from functools import cache

import warp as wp

from .bounce import bounce_funcs
from .dynamics import dynamics_funcs
from .precision import precision

wp.set_module_options({"enable_backward": False})


@cache
def frame_kernel(precision_name: str, max_bounces: int, spin: bool, energy_correction: bool,
                 lossy: bool):
    """Build the frame kernel for one feature set.

    Args:
        precision_name: ``"float32"`` or ``"float64"``.
        max_bounces: contacts per sphere per frame, compiled in.
        spin: friction torque on ``L`` at contacts and orientation integration; without it the
            angular momentum and orientation arrays are neither read nor written.
        energy_correction: reset ``|v|`` from the energy after the move; without it the speed
            is only ever lowered to the energy bound, so energy is never gained either way.
        lossy: ``energy_retention < 1``.
    """
    p = precision(precision_name)
    scalar, vec3, mat33, quat = p.scalar, p.vec3, p.mat33, p.quat
    bounce_path = bounce_funcs(p, max_bounces, spin, lossy).bounce_path
    dyn = dynamics_funcs(p)
    speed_from_energy = dyn.speed_from_energy
    limit_speed_to_energy = dyn.limit_speed_to_energy
    rotation_vector = dyn.rotation_vector
    inertia = dyn.inertia
    integrate_orientation = dyn.integrate_orientation

    @wp.kernel(module="unique")
    def advance_frame(
        # Model:
        box_center: wp.array(dtype=vec3),
        box_rotation: wp.array(dtype=mat33),
        box_half_extents: wp.array(dtype=vec3),
        box_radius: wp.array(dtype=scalar),
        box_bound: wp.array(dtype=scalar),
        gravity: vec3,
        origin: vec3,
        dt: scalar,
        friction: scalar,
        max_rot: scalar,
        retention: scalar,
        radius: wp.array(dtype=scalar),
        mass: wp.array(dtype=scalar),
        # In:
        position_in: wp.array(dtype=vec3),
        velocity_in: wp.array(dtype=vec3),
        energy_in: wp.array(dtype=scalar),
        angular_momentum_in: wp.array(dtype=vec3),
        orientation_in: wp.array(dtype=quat),
        # Out:
        position_out: wp.array(dtype=vec3),
        velocity_out: wp.array(dtype=vec3),
        energy_out: wp.array(dtype=scalar),
        angular_momentum_out: wp.array(dtype=vec3),
        orientation_out: wp.array(dtype=quat),
        bounce_count: wp.array(dtype=wp.int32),
        capped_count: wp.array(dtype=wp.int32),
    ):
        i = wp.tid()
        r = radius[i]
        m = mass[i]
        energy = energy_in[i]
        L = vec3()
        if wp.static(spin):
            L = angular_momentum_in[i]
        v = velocity_in[i] + gravity * dt
        x, v, L, energy, bounces, capped = bounce_path(
            position_in[i], v, r, m, L, energy, gravity, origin, dt, friction, max_rot,
            retention, box_center, box_rotation, box_half_extents, box_radius, box_bound)
        if wp.static(energy_correction):
            v = speed_from_energy(v, energy, m, gravity, x, origin)
        else:
            v = limit_speed_to_energy(v, energy, m, gravity, x, origin)
        position_out[i] = x
        velocity_out[i] = v
        energy_out[i] = energy
        if wp.static(spin):
            angular_momentum_out[i] = L
            rot = rotation_vector(L, inertia(m, r), max_rot)
            orientation_out[i] = integrate_orientation(orientation_in[i], rot, dt)
        bounce_count[i] += bounces
        capped_count[i] += capped

    return advance_frame
