"""The nearest hit of a chord over a group of rounded boxes (the sheet's method 2), world frame.

The obstacles are a ``data.model_structs`` ``Boxes`` (struct of arrays: centre, rotation matrix
local -> world, core half extents, rounding radius and the half size of the world-axis-aligned
bounding box, precomputed on the host) and the broad phase's ``BroadPhase``. The loops over the
candidates are ``candidates.candidate_funcs``'s, specialised here with the chord's exact sweep
(:func:`nearest_funcs`' ``sweep_chord``): every broad phase keeps the same first contact, bit for
bit (the tie rule, the lower box index, is explicit).
"""

from functools import cache
from types import SimpleNamespace

import warp as wp

from .candidates import (  # noqa: F401 (the constants of the reject and the BVH, named here too)
    BOUNDS_PAD_ABS,
    BOUNDS_PAD_REL,
    REJECT_SLACK,
    candidate_funcs,
    path_funcs,
    path_struct,
)
from .data import BROAD_PHASES, model_structs  # noqa: F401 (BROAD_PHASES: named here too)
from .precision import Precision
from .rounded_box import rounded_box_funcs

#: A contact centre ``A + t d`` carries rounding of a few ulps of ``|A|``, ``|d|`` and the box's
#: size. When the Minkowski radius ``R = rb + r`` is below this many of those ulps (a point, or a
#: tiny sphere, against a sharp box or a zero-thickness plate), that rounding can put the centre
#: on the far side of the surface it hit, and the next leg would start behind it; the contact
#: centre is then moved out along the normal by that many ulps, which no rounding undoes.
SEPARATION_ULPS = 16.0


@cache
def nearest_funcs(p: Precision) -> SimpleNamespace:
    """Build the chord's ``@wp.func``s for one precision.

    Returns:
        Namespace with ``chord_path``, ``sweep_chord``, ``contact_centre``, ``separate``,
        ``separation_lift`` and ``separation_bound``.
    """
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    Path = path_struct(p)
    make_path = path_funcs(p)
    sweep_rounded_box = rounded_box_funcs(p).sweep_rounded_box
    ZERO = scalar(0.0)
    ONE = scalar(1.0)
    SEPARATION = scalar(SEPARATION_ULPS * p.eps)

    @wp.func
    def inf_norm(x: vec3):
        return wp.max(wp.max(wp.abs(x[0]), wp.abs(x[1])), wp.abs(x[2]))

    @wp.func
    def separation_lift(x: vec3, travel: vec3, extent: vec3):
        """``SEPARATION_ULPS`` ulps [m] of the scale of a contact's computation: the point
        ``x`` [m], the path ``travel`` [m] it came along, the box's half extent [m]."""
        return SEPARATION * wp.max(wp.max(inf_norm(x), inf_norm(travel)), inf_norm(extent))

    @wp.func
    def magnitude_sum(x: vec3):
        """``|x_0| + |x_1| + |x_2|``, rounded: at least the largest of them (a sum of terms
        >= 0 rounded to nearest is never below one of its terms)."""
        return wp.abs(x[0]) + wp.abs(x[1]) + wp.abs(x[2])

    @wp.func
    def separation_bound(x: vec3, travel: vec3, extent: vec3):
        """An upper bound [m] of :func:`separation_lift` without its branches: ``SEPARATION``
        times the sum of the nine magnitudes, at least their largest (:func:`magnitude_sum`;
        the rounded product is monotone in its factor). Which magnitude is the largest is a
        coin toss that a branch mispredicts, so a radius is tested against this first."""
        return SEPARATION * (magnitude_sum(x) + magnitude_sum(travel) + magnitude_sum(extent))

    @wp.func
    def separate(contact: vec3, travel: vec3, normal: vec3, big_r: scalar, extent: vec3):
        """``contact`` moved out along the unit ``normal`` by :func:`separation_lift` when the
        Minkowski radius ``big_r`` is below it: else bit for bit. A radius at or above
        :func:`separation_bound` is not below the lift, so the lift is computed only under
        the bound."""
        out = contact
        if big_r < separation_bound(contact, travel, extent):
            lift = separation_lift(contact, travel, extent)
            if big_r < lift:
                out = contact + lift * normal
        return out

    @wp.func
    def contact_centre(a: vec3, t: scalar, d: vec3, normal: vec3, big_r: scalar, extent: vec3):
        """The centre ``a + t d`` at a contact, kept strictly on the side the sphere came from.

        When the Minkowski radius ``big_r`` is below ``SEPARATION_ULPS`` ulps of the scale of the
        computation (``|a + t d|``, ``|d|``, the box's size), rounding could put the centre behind
        a sharp surface, so it is moved out along the unit ``normal`` by that many ulps; any larger
        radius leaves it bit for bit.
        """
        return separate(a + t * d, d, normal, big_r, extent)

    @wp.func(inline=True)
    def chord_path(a: vec3, d: vec3, r: scalar):
        """The ``Path`` of a sphere of radius ``r`` [m] whose centre moves from ``a`` by ``d``
        [m]: its bounds grow by ``r`` on every axis, ``t`` runs over ``[0, 1]``."""
        return make_path(a, d, vec3(ZERO, ZERO, ZERO), ONE, r, d, vec3(r, r, r))

    @wp.func
    def sweep_box(a: vec3, d: vec3, r: scalar, center: vec3, rotation: mat33,
                  half_extents: vec3, box_radius: scalar):
        """The exact sweep of a sphere (centre ``a`` moving by ``d``, radius ``r``) against one
        box, in the box's frame; out of line and without structs, so a call copies no ``Path``.

        Returns:
            ``(hit, t, normal)`` with the normal in world coordinates (see ``sweep_rounded_box``).
        """
        to_local = wp.transpose(rotation)
        hit, t, n_local = sweep_rounded_box(to_local * (a - center), to_local * d,
                                            half_extents, box_radius + r)
        return hit, t, rotation * n_local

    @wp.func(inline=True)
    def sweep_chord(q: Path, center: vec3, rotation: mat33, half_extents: vec3,
                    box_radius: scalar):
        """The exact sweep of the chord against one box (:func:`sweep_box`)."""
        return sweep_box(q.a, q.v, q.r, center, rotation, half_extents, box_radius)

    return SimpleNamespace(chord_path=chord_path, sweep_chord=sweep_chord,
                           separation_lift=separation_lift, separation_bound=separation_bound,
                           contact_centre=contact_centre, separate=separate)


@cache
def model_nearest_hit(p: Precision, broad_phase: str):
    """The chord's nearest-hit ``@wp.func`` the kernels call.

    Args:
        p: precision.
        broad_phase: one of ``BROAD_PHASES``, compiled in (see ``candidates.candidate_funcs``);
            every one gives bit-identical results.

    Returns:
        ``nearest_hit(a, d, r, left, boxes, broad) -> (box, t, normal)``: the first contact of
        the sphere of radius ``r`` moving from ``a`` by ``d`` (smallest ``t``; ties: the lower
        box index) over every box but ``left`` (the box the chord has just bounced off and
        leaves, which it cannot meet again; -1: none); ``box`` is -1 when nothing is hit (then
        ``t = 1``, normal 0).
    """
    scalar, vec3 = p.scalar, p.vec3
    Boxes, BroadPhase, _, _ = model_structs(p)
    funcs = nearest_funcs(p)
    chord_path = funcs.chord_path
    nearest = candidate_funcs(p, funcs.sweep_chord, broad_phase, leaves=True).nearest

    @wp.func(inline=True)
    def nearest_hit(a: vec3, d: vec3, r: scalar, left: int, boxes: Boxes, broad: BroadPhase):
        """First contact of the sphere over the boxes but ``left``, by the broad phase compiled
        in."""
        q = chord_path(a, d, r)
        q.left = left
        return nearest(q, boxes, broad)

    return nearest_hit
