"""The nearest contact of a parabolic arc over a group of rounded boxes, in world coordinates.

The ballistic counterpart of :mod:`nearest`, with the same box arrays (``# Model`` data: centre,
rotation matrix local -> world, core half extents, rounding radius, world-AABB half size) and the
same structure: :func:`sweep_box_world_arc` is the per-candidate step (a cheap reject, then the
exact sweep in the box's frame), :func:`nearest_hit_arc` feeds it every box and
:func:`nearest_hit_arc_bvh` the boxes a BVH query returns; the two are bit-identical.

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
from .nearest import (
    BOUNDS_PAD_ABS,
    BOUNDS_PAD_REL,
    BROAD_PHASES,
    REJECT_SLACK,
    grid_funcs,
    nearest_funcs,
)
from .precision import Precision


@cache
def nearest_arc_funcs(p: Precision) -> SimpleNamespace:
    """Build the group-query ``@wp.func``s for arcs, for one precision.

    Returns:
        Namespace with ``sweep_box_world_arc``, ``nearest_hit_arc``, ``nearest_hit_arc_bvh``
        and ``arc_contact_centre``.
    """
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    arc = arc_funcs(p)
    sweep_rounded_box_arc = arc.sweep_rounded_box_arc
    arc_point = arc.arc_point
    linear = nearest_funcs(p)
    separate = linear.separate
    grid_fits_path = grid_funcs(p).grid_fits_path
    sweep_box_world = linear.sweep_box_world
    nearest_hit = linear.nearest_hit
    nearest_hit_bvh = linear.nearest_hit_bvh
    ZERO = scalar(0.0)
    HALF = scalar(0.5)
    EIGHTH = scalar(0.125)
    SLACK = scalar(1.0 + REJECT_SLACK)
    PAD_REL = scalar(BOUNDS_PAD_REL)
    PAD_ABS = scalar(BOUNDS_PAD_ABS)

    @wp.func
    def is_zero(x: vec3):
        return x[0] == ZERO and x[1] == ZERO and x[2] == ZERO

    @wp.func
    def sagitta(g: vec3, tau: scalar):
        """Per-axis bound [m] on the arc's distance from its chord over ``[0, tau]``."""
        k = EIGHTH * tau * tau
        return vec3(wp.abs(g[0]) * k, wp.abs(g[1]) * k, wp.abs(g[2]) * k)

    @wp.func
    def arc_bounds(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar):
        """What the reject needs of the arc, once per sphere: the chord's midpoint [m], its half
        extent ``|d| / 2`` [m] and the growth ``r + sagitta`` [m] per world axis."""
        d = tau * (v + (HALF * tau) * g)
        sag = sagitta(g, tau)
        half_d = vec3(HALF * wp.abs(d[0]), HALF * wp.abs(d[1]), HALF * wp.abs(d[2]))
        return a + HALF * d, half_d, sag + vec3(r, r, r)

    @wp.func
    def arc_apart(mid: vec3, half_d: vec3, grow: vec3, center: vec3, extent: vec3):
        """The reject: 1 when the arc's bounds and the box's are apart along a world axis."""
        rel = mid - center
        apart = int(0)
        for i in range(3):
            if wp.abs(rel[i]) > (extent[i] + grow[i]) * SLACK + half_d[i]:
                apart = 1
        return apart

    @wp.func
    def sweep_box_local_arc(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, center: vec3,
                            rotation: mat33, half_extents: vec3, box_radius: scalar):
        """The exact sweep of one box in its frame, the normal back in world coordinates."""
        to_local = wp.transpose(rotation)
        hit, s, n_local = sweep_rounded_box_arc(to_local * (a - center), to_local * v,
                                                to_local * g, tau, half_extents,
                                                box_radius + r)
        return hit, s, rotation * n_local

    @wp.func
    def sweep_box_world_arc(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, center: vec3,
                            rotation: mat33, half_extents: vec3, box_radius: scalar,
                            extent: vec3):
        """Sweep of a sphere (centre on the arc from ``a``, radius ``r``) against one box.

        Args:
            a: centre at ``s = 0`` [m], world. v: velocity at ``s = 0`` [m/s]. g: acceleration
            [m/s^2]. tau: time span [s]. r: sphere radius [m]. center, rotation, half_extents,
            box_radius, extent: the box (see :mod:`nearest`).

        A cheap conservative reject first: no hit when the chord's world bounding box, grown by
        the sagitta and ``r``, and the box's are apart along an axis. Otherwise the exact sweep
        in the box's frame. ``g = 0`` is :func:`nearest.sweep_box_world` of the chord, bit for
        bit (``s = t tau``).

        Returns:
            ``(hit, s, normal)`` with the normal in world coordinates (``sweep_rounded_box_arc``).
        """
        hit = int(0)
        s = tau
        normal = vec3(ZERO, ZERO, ZERO)
        if is_zero(g):
            hit_l, t_l, n_l = sweep_box_world(a, v * tau, r, center, rotation, half_extents,
                                              box_radius, extent)
            if hit_l == 1:
                hit = 1
                s = t_l * tau
                normal = n_l
        else:
            mid, half_d, grow = arc_bounds(a, v, g, tau, r)
            if arc_apart(mid, half_d, grow, center, extent) == 0:
                hit, s, normal = sweep_box_local_arc(a, v, g, tau, r, center, rotation,
                                                     half_extents, box_radius)
        return hit, s, normal

    @wp.func
    def nearest_hit_arc(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar,
                        box_center: wp.array(dtype=vec3), box_rotation: wp.array(dtype=mat33),
                        box_half_extents: wp.array(dtype=vec3),
                        box_radius: wp.array(dtype=scalar), box_extent: wp.array(dtype=vec3)):
        """The first contact of the arc over all boxes (smallest ``s``; ties: the lower index).

        Returns:
            ``(box, s, normal)``: ``box`` is -1 when nothing is hit (then ``s = tau``, normal 0).
        """
        best = int(-1)
        best_s = tau
        best_n = vec3(ZERO, ZERO, ZERO)
        if is_zero(g):
            best, t, best_n = nearest_hit(a, v * tau, r, box_center, box_rotation,
                                          box_half_extents, box_radius, box_extent)
            if best >= 0:
                best_s = t * tau
        else:
            mid, half_d, grow = arc_bounds(a, v, g, tau, r)
            for k in range(box_center.shape[0]):
                if arc_apart(mid, half_d, grow, box_center[k], box_extent[k]) == 0:
                    hit, s, normal = sweep_box_local_arc(a, v, g, tau, r, box_center[k],
                                                         box_rotation[k], box_half_extents[k],
                                                         box_radius[k])
                    if hit == 1 and (best < 0 or s < best_s):
                        best = k
                        best_s = s
                        best_n = normal
        return best, best_s, best_n

    @wp.func
    def nearest_hit_arc_bvh(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, bvh_id: wp.uint64,
                            box_center: wp.array(dtype=vec3), box_rotation: wp.array(dtype=mat33),
                            box_half_extents: wp.array(dtype=vec3),
                            box_radius: wp.array(dtype=scalar), box_extent: wp.array(dtype=vec3)):
        """:func:`nearest_hit_arc` over the boxes a BVH query returns (bit-identical to it).

        ``bvh_id`` is the BVH of :func:`nearest.nearest_hit_bvh` (the boxes' reject bounds). The
        query box is the chord's world bounding box grown by ``(r + sagitta) (1 + REJECT_SLACK)``
        per axis and padded as the linear query, in float32 rounded outward: every box the
        per-box reject lets through is a candidate. ``bvh_id = 0`` (no boxes) hits nothing.

        Returns:
            ``(box, s, normal)``: ``box`` is -1 when nothing is hit (then ``s = tau``, normal 0).
        """
        best = int(-1)
        best_s = tau
        best_n = vec3(ZERO, ZERO, ZERO)
        if is_zero(g):
            best, t, best_n = nearest_hit_bvh(a, v * tau, r, bvh_id, box_center, box_rotation,
                                              box_half_extents, box_radius, box_extent)
            if best >= 0:
                best_s = t * tau
        elif bvh_id != wp.uint64(0):
            d = tau * (v + (HALF * tau) * g)
            b = a + d
            sag = sagitta(g, tau)
            lower = wp.vec3f()
            upper = wp.vec3f()
            for i in range(3):
                grow = (r + sag[i]) * SLACK
                lo = wp.min(a[i], b[i]) - grow
                hi = wp.max(a[i], b[i]) + grow
                pad = PAD_REL * wp.max(wp.abs(lo), wp.abs(hi)) + PAD_ABS
                lower[i] = wp.float32(lo - pad)
                upper[i] = wp.float32(hi + pad)
            mid, half_d, grow_r = arc_bounds(a, v, g, tau, r)
            query = wp.bvh_query_aabb(bvh_id, lower, upper)
            k = int(0)
            while wp.bvh_query_next(query, k):
                if arc_apart(mid, half_d, grow_r, box_center[k], box_extent[k]) == 0:
                    hit, s, normal = sweep_box_local_arc(a, v, g, tau, r, box_center[k],
                                                         box_rotation[k], box_half_extents[k],
                                                         box_radius[k])
                    if hit == 1 and (best < 0 or s < best_s or (s == best_s and k < best)):
                        best = k
                        best_s = s
                        best_n = normal
        return best, best_s, best_n

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

    @wp.func
    def arc_grid_fits(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, grid_lower: vec3,
                      grid_cell: vec3, grid_inv_cell: vec3, grid_dims: wp.vec3i,
                      grid_margin: scalar):
        """``(fits, cell)`` for an arc, as ``nearest.grid_funcs``'s ``grid_fits`` for a chord:
        the chord's bounding box grown by ``(r + sagitta) (1 + REJECT_SLACK)`` per axis must lie
        in the grown cell of ``a``; then only the cell's boxes can pass :func:`arc_apart`."""
        sag = sagitta(g, tau)
        grow = vec3((r + sag[0]) * SLACK, (r + sag[1]) * SLACK, (r + sag[2]) * SLACK)
        return grid_fits_path(a, arc_point(a, v, g, tau), grow, grid_lower, grid_cell,
                              grid_inv_cell, grid_dims, grid_margin)

    @wp.func
    def nearest_hit_arc_cell(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, cell: int,
                             grid_cell_start: wp.array(dtype=wp.int32),
                             grid_cell_boxes: wp.array(dtype=wp.int32),
                             box_center: wp.array(dtype=vec3),
                             box_rotation: wp.array(dtype=mat33),
                             box_half_extents: wp.array(dtype=vec3),
                             box_radius: wp.array(dtype=scalar),
                             box_extent: wp.array(dtype=vec3)):
        """:func:`nearest_hit_arc` over the boxes one grid cell lists (ascending: ties keep the
        lower index, so it is bit-identical)."""
        best = int(-1)
        best_s = tau
        best_n = vec3(ZERO, ZERO, ZERO)
        mid, half_d, grow = arc_bounds(a, v, g, tau, r)
        for j in range(grid_cell_start[cell], grid_cell_start[cell + 1]):
            k = grid_cell_boxes[j]
            if arc_apart(mid, half_d, grow, box_center[k], box_extent[k]) == 0:
                hit, s, normal = sweep_box_local_arc(a, v, g, tau, r, box_center[k],
                                                     box_rotation[k], box_half_extents[k],
                                                     box_radius[k])
                if hit == 1 and (best < 0 or s < best_s):
                    best = k
                    best_s = s
                    best_n = normal
        return best, best_s, best_n

    return SimpleNamespace(arc_grid_fits=arc_grid_fits,
                           nearest_hit_arc_cell=nearest_hit_arc_cell,
                           sweep_box_world_arc=sweep_box_world_arc,
                           nearest_hit_arc=nearest_hit_arc,
                           nearest_hit_arc_bvh=nearest_hit_arc_bvh,
                           arc_contact_centre=arc_contact_centre)


def uses_bvh(broad_phase) -> bool:
    """Whether ``broad_phase`` falls back to (or is) the BVH query: ``True``, ``"bvh"`` or
    ``"grid-bvh"``; ``False``, ``"brute"`` or ``"grid"`` are not.

    Raises:
        ValueError: anything else.
    """
    if broad_phase is True or broad_phase in ("bvh", "grid-bvh"):
        return True
    if broad_phase is False or broad_phase in ("brute", "grid"):
        return False
    raise ValueError(f"broad_phase for arcs must be one of {BROAD_PHASES}, got {broad_phase!r}")


def model_nearest_hit_arc(p: Precision, broad_phase):
    """The arc's nearest-hit ``@wp.func`` the kernels call, with the kernels' ``# Model`` arguments.

    Args:
        p: precision.
        broad_phase: one of ``nearest.BROAD_PHASES`` (``True``/``False`` are ``"bvh"`` and
            ``"brute"``): as for the chord, the grid's cell list when the arc's bounds stay in
            its cell's margin, else every box or the BVH query; bit-identical whichever.

    Returns:
        ``nearest_hit_arc_model(a, v, g, tau, r, box_center, box_rotation, box_half_extents,
        box_radius, box_extent, box_bvh, grid_lower, grid_cell, grid_inv_cell, grid_dims,
        grid_margin, grid_cell_start, grid_cell_boxes) -> (box, s, normal)``.
    """
    name = {True: "bvh", False: "brute"}.get(broad_phase, broad_phase)
    uses_bvh(name)
    return _model_nearest_hit_arc(p, name)


@cache
def _model_nearest_hit_arc(p: Precision, broad_phase: str):
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    funcs = nearest_arc_funcs(p)
    nearest_hit_arc, nearest_hit_arc_bvh = funcs.nearest_hit_arc, funcs.nearest_hit_arc_bvh
    arc_grid_fits, nearest_hit_arc_cell = funcs.arc_grid_fits, funcs.nearest_hit_arc_cell
    use_grid = broad_phase in ("grid", "grid-bvh")
    fallback_bvh = uses_bvh(broad_phase)
    ZERO = scalar(0.0)

    @wp.func
    def nearest_hit_arc_model(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar,
                              box_center: wp.array(dtype=vec3),
                              box_rotation: wp.array(dtype=mat33),
                              box_half_extents: wp.array(dtype=vec3),
                              box_radius: wp.array(dtype=scalar),
                              box_extent: wp.array(dtype=vec3), box_bvh: wp.uint64,
                              grid_lower: vec3, grid_cell: vec3, grid_inv_cell: vec3,
                              grid_dims: wp.vec3i, grid_margin: scalar,
                              grid_cell_start: wp.array(dtype=wp.int32),
                              grid_cell_boxes: wp.array(dtype=wp.int32)):
        """First contact of the sphere's arc over the boxes, by the broad phase compiled in."""
        box = int(-1)
        s = tau
        normal = vec3(ZERO, ZERO, ZERO)
        fits = int(0)
        if wp.static(use_grid):
            if g[0] != ZERO or g[1] != ZERO or g[2] != ZERO:  # g = 0: the chord's own path
                fits, cell = arc_grid_fits(a, v, g, tau, r, grid_lower, grid_cell,
                                           grid_inv_cell, grid_dims, grid_margin)
                if fits == 1:
                    box, s, normal = nearest_hit_arc_cell(a, v, g, tau, r, cell,
                                                          grid_cell_start, grid_cell_boxes,
                                                          box_center, box_rotation,
                                                          box_half_extents, box_radius,
                                                          box_extent)
        if fits == 0:
            if wp.static(fallback_bvh):
                box, s, normal = nearest_hit_arc_bvh(a, v, g, tau, r, box_bvh, box_center,
                                                     box_rotation, box_half_extents,
                                                     box_radius, box_extent)
            else:
                box, s, normal = nearest_hit_arc(a, v, g, tau, r, box_center, box_rotation,
                                                 box_half_extents, box_radius, box_extent)
        return box, s, normal

    return nearest_hit_arc_model
