"""Per-sphere dynamics of one frame: spin from contact friction, energy, orientation.

Conventions (SPEC "Dynamics of one frame"): the moment of inertia of a solid sphere is
``I = 2/5 m r^2``; the rotation vector is ``Rot = L / I`` [rad/s], world frame, with ``|Rot|``
clamped to ``max_angular_speed``; potential energy is ``-m g . (p - origin)`` for a scene-wide
reference point ``origin`` (near the scene, so float32 keeps its digits far from the world
origin); quaternions are ``(x, y, z, w)``.
"""

from functools import cache
from types import SimpleNamespace

import warp as wp

from .precision import Precision

#: Moment of inertia of a solid sphere, as a fraction of ``m r^2``.
SOLID_SPHERE_INERTIA = 0.4

#: A kinetic-energy mismatch within this many ulps of ``|E| + |Ep|`` is rounding of ``E - Ep``, not
#: drift: the reset skips it, so the velocity stays bit for bit (resting spheres stay at zero).
RESET_ULPS = 8.0


@cache
def dynamics_funcs(p: Precision) -> SimpleNamespace:
    """Build the dynamics ``@wp.func``s for one precision.

    Returns:
        Namespace with ``inertia``, ``clamp_momentum``, ``rotation_vector``, ``friction_spin``,
        ``potential``, ``energy_along_gravity``, ``kinetic_energy`` and
        ``integrate_orientation`` (and its parts ``orientation_step``, ``turned``).
    """
    scalar, vec3, quat = p.scalar, p.vec3, p.quat
    ZERO = scalar(0.0)
    ONE = scalar(1.0)
    HALF = scalar(0.5)
    TWO = scalar(2.0)
    INERTIA = scalar(SOLID_SPHERE_INERTIA)
    RESET_SLACK = scalar(RESET_ULPS * p.eps)

    @wp.func
    def inertia(m: scalar, r: scalar):
        """``I = 2/5 m r^2`` [kg m^2]."""
        return INERTIA * m * r * r

    @wp.func
    def clamp_momentum(L: vec3, i_sphere: scalar, max_rot: scalar):
        """``L`` scaled down so that ``|L| / I <= max_rot`` (zero for a sphere without inertia)."""
        out = vec3(ZERO, ZERO, ZERO)
        if i_sphere > ZERO:
            out = L
            limit = max_rot * i_sphere
            size = wp.length(L)
            if size > limit:
                out = L * (limit / size)
        return out

    @wp.func
    def rotation_vector(L: vec3, i_sphere: scalar, max_rot: scalar):
        """``Rot = L / I`` [rad/s] with ``|Rot|`` clamped to ``max_rot``; 0 without inertia."""
        rot = vec3(ZERO, ZERO, ZERO)
        if i_sphere > ZERO:
            rot = clamp_momentum(L, i_sphere, max_rot) / i_sphere
        return rot

    @wp.func
    def friction_spin(L: vec3, v: vec3, n: vec3, r: scalar, m: scalar, dt: scalar,
                      friction: scalar, max_rot: scalar):
        """Angular momentum after one contact with friction (SPEC "Spin").

        ``OC = -r n`` (centre to contact point), ``v_t,rel = v - (v.n) n + Rot x OC``,
        ``F_f = -k_f v_t,rel`` and ``L <- L + dt (OC x F_f)``, then ``|Rot|`` clamped.

        Args:
            L: angular momentum [kg m^2/s]. v: velocity at the contact [m/s]. n: unit outward
            normal of the obstacle. r: radius [m]. m: mass [kg]. dt: frame duration [s].
            friction: ``k_f`` [kg/s]. max_rot: clamp on ``|Rot|`` [rad/s].
        """
        i_sphere = inertia(m, r)
        rot = rotation_vector(L, i_sphere, max_rot)
        oc = -r * n
        v_rel = v - wp.dot(v, n) * n + wp.cross(rot, oc)
        force = -friction * v_rel
        return clamp_momentum(L + dt * wp.cross(oc, force), i_sphere, max_rot)

    @wp.func
    def potential(m: scalar, g: vec3, position: vec3, origin: vec3):
        """Gravitational potential energy ``-m g . (p - origin)`` [J]."""
        return -m * wp.dot(g, position - origin)

    @wp.func(inline=True)
    def energy_mismatch(u: vec3, energy: scalar, m: scalar, g: vec3, position: vec3,
                        origin: vec3, raise_ok: int):
        """``(E - Ep, 1/2 m |u|^2, slack, change)``: the kinetic energy the state should have,
        the one it has, the energies' rounding (``RESET_ULPS``) [J], and 1 when the two differ
        by more than that and the velocity is to change (``raise_ok`` 1, or it is too high)."""
        ep = potential(m, g, position, origin)
        kinetic = energy - ep
        have = HALF * m * wp.dot(u, u)
        slack = RESET_SLACK * (wp.abs(energy) + wp.abs(ep))
        change = int(0)
        if wp.abs(kinetic - have) > slack and (raise_ok == 1 or kinetic < have):
            change = 1
        return kinetic, have, slack, change

    @wp.func
    def energy_along_gravity(u: vec3, energy: scalar, m: scalar, g: vec3, position: vec3,
                             origin: vec3, raise_ok: int):
        """``u`` with its kinetic energy set to ``E - Ep``, through the component along gravity.

        The potential depends on the height only and gravity never changes the horizontal
        velocity, so the energy is restored through ``u . g_hat``, its sign kept: a ball on a
        flat frictionless floor keeps its horizontal speed. When the horizontal part alone holds
        more than ``E - Ep``, the vertical part is dropped and the horizontal part scaled down
        (kept as it is when the excess is within the energies' rounding: a sphere at the top
        of a cut hop keeps its horizontal speed bit for bit).
        Without gravity the whole velocity is scaled. ``E - Ep <= 0`` gives ``u = 0`` (never a
        NaN); a vertical part of exactly 0 is not raised (it has no sign to keep). A mismatch
        within the rounding of the energies (``RESET_ULPS``) leaves ``u`` bit for bit.

        Args:
            u: velocity [m/s]. energy: total energy ``E`` [J]. m: mass [kg]. g: gravity
            [m/s^2]. position: [m]. origin: potential reference [m]. raise_ok: 1 to raise the
            kinetic energy when it is below ``E - Ep`` (the reset), 0 to only ever lower it
            (no energy gain, nothing put back).
        """
        kinetic, have, slack, change = energy_mismatch(u, energy, m, g, position, origin,
                                                       raise_ok)
        out = u
        if change == 1:
            if kinetic <= ZERO:
                out = vec3(ZERO, ZERO, ZERO)
            else:
                g_len = wp.length(g)
                if g_len > ZERO:
                    down = g / g_len
                    u_down = wp.dot(u, down)
                    u_side = u - u_down * down
                    side = HALF * m * wp.dot(u_side, u_side)
                    if kinetic >= side:
                        if u_down != ZERO:
                            size = wp.sqrt(TWO * (kinetic - side) / m)
                            if u_down < ZERO:
                                size = -size
                            out = u_side + size * down
                    elif side - kinetic <= slack:
                        out = u_side  # at its energy height to rounding: the sideways part kept
                    else:
                        out = u_side * wp.sqrt(kinetic / side)
                elif have > ZERO:
                    out = u * wp.sqrt(kinetic / have)
        return out

    @wp.func
    def energy_along_velocity(u: vec3, energy: scalar, m: scalar, g: vec3, position: vec3,
                              origin: vec3, raise_ok: int):
        """``u`` with its kinetic energy set to ``E - Ep`` by scaling its speed, its direction
        kept: for a sphere that may be sliding on a support, whose velocity must stay along
        the surface (a change of the part along gravity would lift it off a tilted face).
        ``E - Ep <= 0`` gives ``u = 0``; a mismatch within the rounding of the energies
        (``RESET_ULPS``) leaves ``u`` bit for bit; ``raise_ok`` as in
        :func:`energy_along_gravity`.
        """
        kinetic, have, _slack, change = energy_mismatch(u, energy, m, g, position, origin,
                                                        raise_ok)
        scale = ONE
        if change == 1:
            scale = ZERO  # no energy left for motion (or no speed to scale)
            if kinetic > ZERO and have > ZERO:
                scale = wp.sqrt(kinetic / have)
        return u * scale

    @wp.func
    def kinetic_energy(m: scalar, v: vec3):
        return HALF * m * wp.dot(v, v)

    @wp.func
    def orientation_step(o: quat, rot: vec3, dt: scalar):
        """The turn of one frame under a constant world-frame ``Rot`` [rad/s]: ``(q, 1)`` with
        ``q = exp(1/2 Rot dt)``, or ``(o, 0)`` when it does not turn (``|Rot| dt = 0``); for a
        run of frames with the same ``Rot``, computed once (:func:`turned`)."""
        angle = wp.length(rot) * dt
        q = o
        turning = int(0)
        if angle > ZERO:
            q = wp.quat_from_axis_angle(wp.normalize(rot), angle)
            turning = 1
        return q, turning

    @wp.func
    def turned(o: quat, q: quat, turning: int):
        """``o`` turned by :func:`orientation_step`'s ``q`` (when ``turning``), renormalised."""
        out = o
        if turning == 1:
            out = q * o
        return wp.normalize(out)

    @wp.func
    def integrate_orientation(o: quat, rot: vec3, dt: scalar):
        """``o <- exp(1/2 Rot dt) (x) o``, renormalised (world-frame ``Rot``, constant over dt)."""
        q, turning = orientation_step(o, rot, dt)
        return turned(o, q, turning)

    return SimpleNamespace(inertia=inertia, clamp_momentum=clamp_momentum,
                           rotation_vector=rotation_vector, friction_spin=friction_spin,
                           potential=potential, energy_along_gravity=energy_along_gravity,
                           energy_along_velocity=energy_along_velocity,
                           kinetic_energy=kinetic_energy,
                           integrate_orientation=integrate_orientation,
                           orientation_step=orientation_step, turned=turned)
