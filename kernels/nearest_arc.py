"""The nearest contact of a parabolic arc over a group of rounded boxes, in world coordinates.

The ballistic counterpart of :mod:`nearest`, with the same ``Boxes`` and ``BroadPhase``
(``data.model_structs``) and the same loops over the candidates (``candidates.candidate_funcs``),
specialised with the arc's exact sweep in the box's frame (``sweep_arc``); every broad phase gives
bit-identical results.

Over ``[0, tau]`` the arc ``x(s) = a + v s + 1/2 g s^2`` departs from its chord
``a -> a + v tau + 1/2 g tau^2`` by ``1/2 g s (tau - s)``: at most the sagitta
``|g_i| tau^2 / 8`` along each world axis. The reject and the BVH query are the linear ones for
the chord, grown by that per-axis sagitta, so they stay conservative for the arc. With ``g = 0``
every query is the linear one of the chord (``s = t tau``), bit for bit.
"""


from functools import cache
from types import SimpleNamespace

import warp as wp

from .arc import arc_funcs
from .candidates import candidate_funcs, path_funcs, path_struct
from .data import model_structs
from .nearest import model_nearest_hit, nearest_funcs
from .precision import Precision

#: How many times the frame's remaining time an arc bouncing off a box must take to come back
#: to the plane of its contact before the next query leaves that box out
#: (:func:`leaving_funcs`).
RETURN_MARGIN = 2.0


@cache
def nearest_arc_funcs(p: Precision) -> SimpleNamespace:
    """Build the arc's ``@wp.func``s for one precision.

    Returns:
        Namespace with ``arc_path``, ``sweep_arc``, ``sweep_box_world_arc`` and
        ``arc_contact_centre``.
    """
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    Path = path_struct(p)
    make_path = path_funcs(p)
    Boxes = model_structs(p).Boxes
    arc = arc_funcs(p)
    sweep_rounded_box_arc = arc.sweep_rounded_box_arc
    arc_point = arc.arc_point
    linear = nearest_funcs(p)
    separate = linear.separate
    chord_path = linear.chord_path
    chord_candidate = candidate_funcs(p, linear.sweep_chord, "brute").candidate
    ZERO = scalar(0.0)
    HALF = scalar(0.5)
    EIGHTH = scalar(0.125)

    @wp.func
    def sagitta(g: vec3, tau: scalar):
        """Per-axis bound [m] on the arc's distance from its chord over ``[0, tau]``."""
        k = EIGHTH * tau * tau
        return vec3(wp.abs(g[0]) * k, wp.abs(g[1]) * k, wp.abs(g[2]) * k)

    @wp.func(inline=True)
    def arc_path(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar):
        """The ``Path`` of the arc from ``a`` [m] with velocity ``v`` [m/s] and acceleration
        ``g`` [m/s^2] over ``[0, tau]`` [s], of a sphere of radius ``r`` [m]: the chord's
        bounds grown by ``r`` and the per-axis sagitta."""
        d = tau * (v + (HALF * tau) * g)
        return make_path(a, v, g, tau, r, d, sagitta(g, tau) + vec3(r, r, r))

    @wp.func
    def sweep_box_arc(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, center: vec3,
                      rotation: mat33, half_extents: vec3, box_radius: scalar):
        """The exact sweep of the arc ``a + v s + 1/2 g s^2``, ``s`` in ``[0, tau]``, of a
        sphere of radius ``r`` against one box, in the box's frame; out of line and without
        structs, so a call copies no ``Path``.

        Returns:
            ``(hit, s, normal)`` with the normal in world coordinates (``sweep_rounded_box_arc``).
        """
        to_local = wp.transpose(rotation)
        hit, s, n_local = sweep_rounded_box_arc(to_local * (a - center), to_local * v,
                                                to_local * g, tau, half_extents, box_radius + r)
        return hit, s, rotation * n_local

    @wp.func(inline=True)
    def sweep_arc(q: Path, center: vec3, rotation: mat33, half_extents: vec3,
                  box_radius: scalar):
        """The exact sweep of the arc against one box (:func:`sweep_box_arc`)."""
        return sweep_box_arc(q.a, q.v, q.g, q.tau, q.r, center, rotation, half_extents,
                             box_radius)

    arc_candidate = candidate_funcs(p, sweep_arc, "brute").candidate

    @wp.func
    def sweep_box_world_arc(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, boxes: Boxes,
                            k: int):
        """Sweep of a sphere (centre on the arc from ``a``, radius ``r``) against box ``k``.

        Args:
            a: centre at ``s = 0`` [m], world. v: velocity at ``s = 0`` [m/s]. g: acceleration
            [m/s^2]. tau: time span [s]. r: sphere radius [m]. boxes, k: the box.

        The reject first (``candidates.bounds_funcs``' ``apart``), then the exact sweep in the
        box's frame. ``g = 0`` is the chord's sweep, bit for bit (``s = t tau``).

        Returns:
            ``(hit, s, normal)`` with the normal in world coordinates; ``s = tau`` and normal 0
            without a hit.
        """
        zero = vec3(ZERO, ZERO, ZERO)
        hit = int(0)
        s = tau
        normal = zero
        if g[0] == ZERO and g[1] == ZERO and g[2] == ZERO:
            box, t, n = chord_candidate(chord_path(a, v * tau, r), boxes, k, -1, scalar(1.0),
                                        zero)
            if box >= 0:
                hit = 1
                s = t * tau
                normal = n
        else:
            box, s, normal = arc_candidate(arc_path(a, v, g, tau, r), boxes, k, -1, tau, zero)
            if box >= 0:
                hit = 1
        return hit, s, normal

    @wp.func
    def arc_contact_centre(a: vec3, v: vec3, g: vec3, s: scalar, normal: vec3, big_r: scalar,
                           extent: vec3):
        """The centre on the arc at a contact, kept on the side the sphere came from.

        As ``nearest.contact_centre`` (``nearest.separate``, with the displacement from ``a`` as
        the path): moved out along the unit ``normal`` only when the Minkowski radius ``big_r``
        is below the rounding, else ``x(s)`` bit for bit.
        """
        contact = arc_point(a, v, g, s)
        return separate(contact, contact - a, normal, big_r, extent)

    return SimpleNamespace(arc_path=arc_path, sweep_arc=sweep_arc,
                           sweep_box_world_arc=sweep_box_world_arc,
                           arc_contact_centre=arc_contact_centre)


@cache
def model_nearest_hit_arc(p: Precision, broad_phase: str, falls: bool = False,
                          leaves: bool = False):
    """The arc's nearest-hit ``@wp.func`` the kernels call.

    Args:
        p: precision.
        broad_phase: one of ``BROAD_PHASES``, compiled in: as for the chord, the grid's cell
            list when the arc's bounds stay in its cell's margin, else every box or the BVH
            query; bit-identical whichever.
        falls: for a ``g`` known not to be zero: the arc's query only, without the chord's
            (the same answer for every ``g != 0``, from less code).
        leaves: the query takes a box to leave out (``left``), one the arc cannot meet (see
            :func:`leaves_for_the_frame`).

    Returns:
        ``nearest_hit_arc(a, v, g, tau, r, boxes, broad) -> (box, s, normal)``, with
        ``leaves`` ``nearest_hit_arc(a, v, g, tau, r, left, boxes, broad)``: the first contact
        along the arc (smallest ``s``; ties: the lower box index) over every box (but
        ``left``; -1: none); ``box`` is -1 when nothing is hit (then ``s = tau``, normal 0).
        ``g = 0`` is the chord's query of ``a -> a + v tau`` (``s = t tau``), bit for bit.
    """
    scalar, vec3 = p.scalar, p.vec3
    Boxes, BroadPhase, _, _ = model_structs(p)
    funcs = nearest_arc_funcs(p)
    arc_path = funcs.arc_path
    nearest = candidate_funcs(p, funcs.sweep_arc, broad_phase, leaves=leaves).nearest
    nearest_chord = model_nearest_hit(p, broad_phase)
    ZERO = scalar(0.0)

    @wp.func(inline=True)
    def nearest_on_arc(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, left: int,
                       boxes: Boxes, broad: BroadPhase):
        """The arc's own query over the boxes but ``left``."""
        q = arc_path(a, v, g, tau, r)
        q.left = left
        return nearest(q, boxes, broad)

    @wp.func(inline=True)
    def nearest_but(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, left: int, boxes: Boxes,
                    broad: BroadPhase):
        """First contact of the sphere's arc over the boxes but ``left``, by the broad phase
        compiled in."""
        box = int(-1)
        s = tau
        normal = vec3(ZERO, ZERO, ZERO)
        if wp.static(falls):
            box, s, normal = nearest_on_arc(a, v, g, tau, r, left, boxes, broad)
        elif g[0] == ZERO and g[1] == ZERO and g[2] == ZERO:  # the chord's own query
            box, t, normal = nearest_chord(a, v * tau, r, left, boxes, broad)
            if box >= 0:
                s = t * tau
        else:
            box, s, normal = nearest_on_arc(a, v, g, tau, r, left, boxes, broad)
        return box, s, normal

    if leaves:
        return nearest_but

    @wp.func(inline=True)
    def nearest_hit_arc(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, boxes: Boxes,
                        broad: BroadPhase):
        """First contact of the sphere's arc over the boxes, by the broad phase compiled in."""
        return nearest_but(a, v, g, tau, r, -1, boxes, broad)

    return nearest_hit_arc


@cache
def leaving_funcs(p: Precision) -> SimpleNamespace:
    """``leaves_for_the_frame(v, g, n, rest) -> int``: whether the arc from a contact, with
    velocity ``v`` [m/s] just after it, acceleration ``g`` [m/s^2] and the contact's outward
    unit normal ``n`` (world frame), stays off the box it bounced off for the ``rest`` [s] of
    the frame, so that the next query may leave that box out.

    A rounded box is convex: it lies behind the plane through the contact normal to ``n``, and
    the arc's height above that plane is ``h(s) = (v . n) s + 1/2 (g . n) s^2``, positive for
    every ``s`` in ``(0, rest]`` when ``v . n > 0`` and, where gravity pulls it back
    (``g . n < 0``), the arc comes back to the plane only at ``s = 2 (v . n) / -(g . n)``,
    after ``rest``. The test asks that return time to be at least ``RETURN_MARGIN`` times
    ``rest``, far beyond any rounding of ``v``, ``n`` and ``rest``. (With ``g = 0`` this is
    the chord's rule, ``bounce.bounce_path``'s ``left``, except that the chord also leaves out
    a rest that runs along the surface, ``d . n = 0``.)
    """
    scalar, vec3 = p.scalar, p.vec3
    ZERO = scalar(0.0)
    MARGIN = scalar(0.5 * RETURN_MARGIN)

    @wp.func(inline=True)
    def leaves_for_the_frame(v: vec3, g: vec3, n: vec3, rest: scalar):
        vn = wp.dot(v, n)
        out = int(0)
        if vn > ZERO and vn >= -wp.dot(g, n) * rest * MARGIN:
            out = 1
        return out

    return SimpleNamespace(leaves_for_the_frame=leaves_for_the_frame)
