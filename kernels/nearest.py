"""The nearest hit over a group of rounded boxes (the sheet's method 2), in world coordinates.

Obstacles are passed as struct-of-arrays (``# Model`` data): centre, rotation matrix (local ->
world), core half extents, rounding radius and the half size of the world-axis-aligned bounding
box (precomputed on the host). :func:`sweep_box_world` is the per-candidate step;
:func:`nearest_hit` feeds it every box (brute force, right for small groups) and
:func:`nearest_hit_bvh` feeds it the boxes a BVH query returns (many boxes). Both keep the same
first contact: the BVH only skips boxes the per-box reject would have refused anyway, and the
tie rule (the lower box index) is explicit, so the two are bit-identical.
"""


from functools import cache
from types import SimpleNamespace

import warp as wp

from .precision import Precision
from .rounded_box import rounded_box_funcs

#: Relative slack on the bounding-box reject, so rounding in the bounds can never reject a box
#: the segment touches (it only lets a few more boxes through to the exact test).
REJECT_SLACK = 1.0e-3

#: Relative pad on the BVH's bounds and queries, well above float32's ulp (1.2e-7): rounding in
#: the per-box reject and in the float64 -> float32 bounds can never make the BVH drop a box the
#: reject would let through.
BOUNDS_PAD_REL = 1.0e-6

#: A contact centre ``A + t d`` carries rounding of a few ulps of ``|A|``, ``|d|`` and the box's
#: size. When the Minkowski radius ``R = rb + r`` is below this many of those ulps (a point, or a
#: tiny sphere, against a sharp box or a zero-thickness plate), that rounding can put the centre
#: on the far side of the surface it hit, and the next leg would start behind it; the contact
#: centre is then moved out along the normal by that many ulps, which no rounding undoes.
SEPARATION_ULPS = 16.0

#: Absolute pad [m] on the BVH queries, for coordinates at or near zero, where the relative pad
#: vanishes (above float32's smallest subnormal, so the outward rounding still holds).
BOUNDS_PAD_ABS = 1.0e-30


@cache
def nearest_funcs(p: Precision) -> SimpleNamespace:
    """Build the group-query ``@wp.func``s for one precision.

    Returns:
        Namespace with ``sweep_box_world``, ``nearest_hit``, ``nearest_hit_bvh``,
        ``contact_centre`` and ``separate``.
    """
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    sweep_rounded_box = rounded_box_funcs(p).sweep_rounded_box
    ZERO = scalar(0.0)
    ONE = scalar(1.0)
    SLACK = scalar(1.0 + REJECT_SLACK)
    HALF = scalar(0.5)
    PAD_REL = scalar(BOUNDS_PAD_REL)
    PAD_ABS = scalar(BOUNDS_PAD_ABS)
    SEPARATION = scalar(SEPARATION_ULPS * p.eps)

    @wp.func
    def inf_norm(x: vec3):
        return wp.max(wp.max(wp.abs(x[0]), wp.abs(x[1])), wp.abs(x[2]))

    @wp.func
    def separate(contact: vec3, travel: vec3, normal: vec3, big_r: scalar, extent: vec3):
        """``contact`` moved out along the unit ``normal`` by ``SEPARATION_ULPS`` ulps of the
        computation's scale (``|contact|``, the path ``travel`` it came along, the box's size)
        when the Minkowski radius ``big_r`` is below that: else bit for bit."""
        lift = SEPARATION * wp.max(wp.max(inf_norm(contact), inf_norm(travel)), inf_norm(extent))
        out = contact
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

    @wp.func
    def sweep_box_world(a: vec3, d: vec3, r: scalar, center: vec3, rotation: mat33,
                        half_extents: vec3, box_radius: scalar, extent: vec3):
        """Sweep of a sphere (centre ``a`` moving by ``d``, radius ``r``) against one box.

        A cheap conservative reject first: no hit when the segment's world bounding box and the
        box's, grown by ``r``, are apart along an axis. Otherwise the exact sweep in the box's
        frame.

        Returns:
            ``(hit, t, normal)`` with the normal in world coordinates (see ``sweep_rounded_box``).
        """
        hit = int(0)
        t = ONE
        normal = vec3(ZERO, ZERO, ZERO)
        mid = a + HALF * d - center
        apart = int(0)
        for i in range(3):
            if wp.abs(mid[i]) > (extent[i] + r) * SLACK + HALF * wp.abs(d[i]):
                apart = 1
        if apart == 0:
            to_local = wp.transpose(rotation)
            hit, t, n_local = sweep_rounded_box(to_local * (a - center), to_local * d,
                                                half_extents, box_radius + r)
            normal = rotation * n_local
        return hit, t, normal

    @wp.func
    def nearest_hit(a: vec3, d: vec3, r: scalar,
                    box_center: wp.array(dtype=vec3), box_rotation: wp.array(dtype=mat33),
                    box_half_extents: wp.array(dtype=vec3), box_radius: wp.array(dtype=scalar),
                    box_extent: wp.array(dtype=vec3)):
        """The first contact over all boxes (smallest ``t``; ties: the lower box index).

        Returns:
            ``(box, t, normal)``: ``box`` is -1 when nothing is hit (then ``t = 1``, normal 0).
        """
        best = int(-1)
        best_t = ONE
        best_n = vec3(ZERO, ZERO, ZERO)
        for k in range(box_center.shape[0]):
            hit, t, normal = sweep_box_world(a, d, r, box_center[k], box_rotation[k],
                                             box_half_extents[k], box_radius[k], box_extent[k])
            if hit == 1 and (best < 0 or t < best_t):
                best = k
                best_t = t
                best_n = normal
        return best, best_t, best_n

    @wp.func
    def nearest_hit_bvh(a: vec3, d: vec3, r: scalar, bvh_id: wp.uint64,
                        box_center: wp.array(dtype=vec3), box_rotation: wp.array(dtype=mat33),
                        box_half_extents: wp.array(dtype=vec3), box_radius: wp.array(dtype=scalar),
                        box_extent: wp.array(dtype=vec3)):
        """:func:`nearest_hit` over the boxes a BVH query returns.

        ``bvh_id`` is a :class:`warp.Bvh` over the boxes' reject bounds (``center +- extent (1 +
        REJECT_SLACK)``, float32, rounded outward and padded; built by the host). The query box
        is the segment's world bounding box grown by ``r (1 + REJECT_SLACK)`` and padded the
        same way, in float32 rounded outward, so every box the per-box reject would let through
        is a candidate: the result is bit-identical to :func:`nearest_hit`. Candidates come in
        any order, hence the explicit tie rule. ``bvh_id = 0`` (no boxes) hits nothing.

        Returns:
            ``(box, t, normal)``: ``box`` is -1 when nothing is hit (then ``t = 1``, normal 0).
        """
        best = int(-1)
        best_t = ONE
        best_n = vec3(ZERO, ZERO, ZERO)
        if bvh_id != wp.uint64(0):
            b = a + d
            grow = r * SLACK
            lower = wp.vec3f()
            upper = wp.vec3f()
            for i in range(3):
                lo = wp.min(a[i], b[i]) - grow
                hi = wp.max(a[i], b[i]) + grow
                pad = PAD_REL * wp.max(wp.abs(lo), wp.abs(hi)) + PAD_ABS
                lower[i] = wp.float32(lo - pad)
                upper[i] = wp.float32(hi + pad)
            query = wp.bvh_query_aabb(bvh_id, lower, upper)
            k = int(0)
            while wp.bvh_query_next(query, k):
                hit, t, normal = sweep_box_world(a, d, r, box_center[k], box_rotation[k],
                                                 box_half_extents[k], box_radius[k],
                                                 box_extent[k])
                if hit == 1 and (best < 0 or t < best_t or (t == best_t and k < best)):
                    best = k
                    best_t = t
                    best_n = normal
        return best, best_t, best_n

    return SimpleNamespace(sweep_box_world=sweep_box_world, nearest_hit=nearest_hit,
                           nearest_hit_bvh=nearest_hit_bvh, contact_centre=contact_centre,
                           separate=separate)


#: The broad phases a kernel can be built with (see :func:`model_nearest_hit`).
BROAD_PHASES = ("brute", "bvh", "grid", "grid-bvh")


@cache
def grid_funcs(p: Precision) -> SimpleNamespace:
    """Build the uniform-grid candidate query for one precision.

    The grid covers the scene's bounds with cells of size ``grid_cell``; cell ``c`` lists, in
    ascending order, every box whose reject bounds (as the BVH's: ``center +- extent (1 +
    REJECT_SLACK)``, padded) meet the cell grown by ``grid_margin`` on every side. A segment whose
    query box (its world bounding box grown by ``r (1 + REJECT_SLACK)``, padded as the BVH query)
    lies inside the grown cell of its start point can only pass the per-box reject of a listed
    box, so the list replaces the loop over all boxes; a segment that does not fit (fast, or
    outside the grid) falls back to the broad phase given. Ties go to the lower index as in the
    brute force: the results are bit-identical.

    Returns:
        Namespace with ``grid_fits``, ``grid_fits_path`` and ``nearest_hit_cell``.
    """
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    sweep_box_world = nearest_funcs(p).sweep_box_world
    ZERO = scalar(0.0)
    ONE = scalar(1.0)
    SLACK = scalar(1.0 + REJECT_SLACK)

    @wp.func
    def grid_fits_path(a: vec3, b: vec3, grow: vec3, grid_lower: vec3, grid_cell: vec3,
                       grid_inv_cell: vec3, grid_dims: wp.vec3i, grid_margin: scalar):
        """``(fits, cell)``: whether the box spanned by ``a`` and ``b``, grown by ``grow`` per
        axis, lies in the grown cell of ``a``, and that cell's linear index (x fastest).

        ``grid_margin`` is the margin the host listed the boxes for, less twice the rounding pad
        of any coordinate inside the grid (``BOUNDS_PAD_REL`` of the grid's largest coordinate),
        so no rounding here can accept a path the lists were not made for. Whichever cell the
        rounded ``floor`` picks, the test is against that cell's own bounds.
        """
        fits = int(1)
        index = int(0)
        stride = int(1)
        for i in range(3):
            c = int(wp.floor((a[i] - grid_lower[i]) * grid_inv_cell[i]))
            if c < 0 or c >= grid_dims[i]:
                fits = 0
            else:
                cell_lo = grid_lower[i] + scalar(c) * grid_cell[i]
                if (wp.min(a[i], b[i]) - grow[i] < cell_lo - grid_margin
                        or wp.max(a[i], b[i]) + grow[i] > cell_lo + grid_cell[i] + grid_margin):
                    fits = 0
                index += c * stride
                stride *= grid_dims[i]
        return fits, index

    @wp.func
    def grid_fits(a: vec3, d: vec3, r: scalar, grid_lower: vec3, grid_cell: vec3,
                  grid_inv_cell: vec3, grid_dims: wp.vec3i, grid_margin: scalar):
        """:func:`grid_fits_path` for the segment ``a -> a + d`` of a sphere of radius ``r``:
        its query box is grown by ``r (1 + REJECT_SLACK)``, as the per-box reject's."""
        grow = r * SLACK
        return grid_fits_path(a, a + d, vec3(grow, grow, grow), grid_lower, grid_cell,
                              grid_inv_cell, grid_dims, grid_margin)

    @wp.func
    def nearest_hit_cell(a: vec3, d: vec3, r: scalar, cell: int,
                         grid_cell_start: wp.array(dtype=wp.int32),
                         grid_cell_boxes: wp.array(dtype=wp.int32),
                         box_center: wp.array(dtype=vec3), box_rotation: wp.array(dtype=mat33),
                         box_half_extents: wp.array(dtype=vec3),
                         box_radius: wp.array(dtype=scalar), box_extent: wp.array(dtype=vec3)):
        """:func:`nearest_hit` over the boxes one cell lists (ascending, so ties keep the lower
        index)."""
        best = int(-1)
        best_t = ONE
        best_n = vec3(ZERO, ZERO, ZERO)
        for j in range(grid_cell_start[cell], grid_cell_start[cell + 1]):
            k = grid_cell_boxes[j]
            hit, t, normal = sweep_box_world(a, d, r, box_center[k], box_rotation[k],
                                             box_half_extents[k], box_radius[k], box_extent[k])
            if hit == 1 and (best < 0 or t < best_t):
                best = k
                best_t = t
                best_n = normal
        return best, best_t, best_n

    return SimpleNamespace(grid_fits=grid_fits, grid_fits_path=grid_fits_path,
                           nearest_hit_cell=nearest_hit_cell)


@cache
def model_nearest_hit(p: Precision, broad_phase: str):
    """The nearest-hit ``@wp.func`` the kernels call, with the kernels' ``# Model`` arguments.

    Args:
        p: precision.
        broad_phase: how candidates are found, compiled in (one of ``BROAD_PHASES``):
            ``"brute"`` every box (:func:`nearest_hit`); ``"bvh"`` the BVH query
            (:func:`nearest_hit_bvh`, ``box_bvh`` read); ``"grid"`` the uniform grid's cell list
            with every box as the fallback; ``"grid-bvh"`` the grid with the BVH as the
            fallback. Arrays a variant does not use are passed but never read. Every variant
            gives bit-identical results.

    Returns:
        ``nearest_hit_model(a, d, r, box_center, box_rotation, box_half_extents, box_radius,
        box_extent, box_bvh, grid_lower, grid_cell, grid_inv_cell, grid_dims, grid_margin,
        grid_cell_start, grid_cell_boxes) -> (box, t, normal)``, the contract of
        :func:`nearest_hit`.
    """
    if broad_phase not in BROAD_PHASES:
        raise ValueError(f"broad_phase must be one of {BROAD_PHASES}, got {broad_phase!r}")
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    funcs = nearest_funcs(p)
    nearest_hit, nearest_hit_bvh = funcs.nearest_hit, funcs.nearest_hit_bvh
    grid = grid_funcs(p)
    grid_fits, nearest_hit_cell = grid.grid_fits, grid.nearest_hit_cell
    use_grid = broad_phase in ("grid", "grid-bvh")
    fallback_bvh = broad_phase in ("bvh", "grid-bvh")

    @wp.func
    def nearest_hit_model(a: vec3, d: vec3, r: scalar,
                          box_center: wp.array(dtype=vec3), box_rotation: wp.array(dtype=mat33),
                          box_half_extents: wp.array(dtype=vec3),
                          box_radius: wp.array(dtype=scalar), box_extent: wp.array(dtype=vec3),
                          box_bvh: wp.uint64, grid_lower: vec3, grid_cell: vec3,
                          grid_inv_cell: vec3, grid_dims: wp.vec3i, grid_margin: scalar,
                          grid_cell_start: wp.array(dtype=wp.int32),
                          grid_cell_boxes: wp.array(dtype=wp.int32)):
        """First contact of the sphere over the boxes, by the broad phase compiled in."""
        box = int(-1)
        t = scalar(1.0)
        normal = vec3()
        fits = int(0)
        if wp.static(use_grid):
            fits, cell = grid_fits(a, d, r, grid_lower, grid_cell, grid_inv_cell, grid_dims,
                                   grid_margin)
            if fits == 1:
                box, t, normal = nearest_hit_cell(a, d, r, cell, grid_cell_start,
                                                  grid_cell_boxes, box_center, box_rotation,
                                                  box_half_extents, box_radius, box_extent)
        if fits == 0:
            if wp.static(fallback_bvh):
                box, t, normal = nearest_hit_bvh(a, d, r, box_bvh, box_center, box_rotation,
                                                 box_half_extents, box_radius, box_extent)
            else:
                box, t, normal = nearest_hit(a, d, r, box_center, box_rotation,
                                             box_half_extents, box_radius, box_extent)
        return box, t, normal

    return nearest_hit_model
