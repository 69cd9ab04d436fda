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
        ``potential``, ``speed_from_energy``, ``limit_speed_to_energy``, ``kinetic_energy`` and
        ``integrate_orientation``.
    """
    scalar, vec3, quat = p.scalar, p.vec3, p.quat
    ZERO = scalar(0.0)
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

    @wp.func
    def speed_from_energy(v: vec3, energy: scalar, m: scalar, g: vec3, position: vec3,
                          origin: vec3):
        """``v`` rescaled to ``|v| = sqrt(2 (E - Ep) / m)``, direction kept.

        A negative kinetic energy (float error near the top of an arc) gives ``v = 0``: never a
        NaN. A zero velocity stays zero (it has no direction to keep). A mismatch within the
        rounding of the energies (``RESET_ULPS``) leaves ``v`` unchanged.
        """
        ep = potential(m, g, position, origin)
        kinetic = energy - ep
        speed = wp.length(v)
        out = v
        if kinetic <= ZERO:
            out = vec3(ZERO, ZERO, ZERO)
        elif speed > ZERO:
            mismatch = wp.abs(kinetic - HALF * m * speed * speed)
            if mismatch > RESET_SLACK * (wp.abs(energy) + wp.abs(ep)):
                out = v * (wp.sqrt(TWO * kinetic / m) / speed)
        return out

    @wp.func
    def limit_speed_to_energy(v: vec3, energy: scalar, m: scalar, g: vec3, position: vec3,
                              origin: vec3):
        """``v`` scaled down, never up, so that ``1/2 m |v|^2 + Ep <= E`` (no energy gain).

        Without the full reset, semi-implicit Euler across a bounce can gain energy of order
        ``m |g| |v| dt`` per contact; this one-sided bound removes the gain and nothing else.
        """
        kinetic = energy - potential(m, g, position, origin)
        out = v
        if kinetic <= ZERO:
            out = vec3(ZERO, ZERO, ZERO)
        else:
            limit = TWO * kinetic / m
            speed_sq = wp.dot(v, v)
            if speed_sq > limit:
                out = v * wp.sqrt(limit / speed_sq)
        return out

    @wp.func
    def kinetic_energy(m: scalar, v: vec3):
        return HALF * m * wp.dot(v, v)

    @wp.func
    def integrate_orientation(o: quat, rot: vec3, dt: scalar):
        """``o <- exp(1/2 Rot dt) (x) o``, renormalised (world-frame ``Rot``, constant over dt)."""
        angle = wp.length(rot) * dt
        out = o
        if angle > ZERO:
            out = wp.quat_from_axis_angle(wp.normalize(rot), angle) * o
        return wp.normalize(out)

    return SimpleNamespace(inertia=inertia, clamp_momentum=clamp_momentum,
                           rotation_vector=rotation_vector, friction_spin=friction_spin,
                           potential=potential, speed_from_energy=speed_from_energy,
                           kinetic_energy=kinetic_energy,
                           limit_speed_to_energy=limit_speed_to_energy,
                           integrate_orientation=integrate_orientation)
