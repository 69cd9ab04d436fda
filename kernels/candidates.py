"""The nearest hit over the candidate boxes, written once for every path and every broad phase.

A sphere's path over one leg is a :func:`path_struct` ``Path``: its start, its bounds (the
chord's midpoint, half extent and the growth per world axis that covers the sphere and, for an
arc, the sagitta) and the no-hit value of the path parameter (``t = 1`` for a chord, ``s = tau``
for an arc). Every per-box step is the same: the cheap conservative reject (:func:`apart`: the
path's world bounding box and the box's, grown, apart along an axis), then the exact sweep in the
box's frame, then keep the closer contact (ties: the lower box index). Only the exact sweep
depends on the path, and :func:`candidate_funcs` captures it: ``nearest.chord_funcs`` and
``nearest_arc.nearest_arc_funcs`` specialise the loops with the chord's or the arc's.

The candidates come from every box (brute force), from the grid cell of the chord's midpoint
(when the path's query box fits in the cell's margin: a path reaching ``|d_i| / 2 + r`` from its
midpoint fits wherever the midpoint lies, so the margin, and the lists, need only half the
path), from the cells the path's chord crosses, walked
in order (:func:`candidate_funcs`' ``nearest_walk``), or from a BVH query (any order: hence the
explicit tie rule). Brute force, the cell and the BVH only skip boxes the reject would refuse
anyway; the walk skips boxes the path cannot touch before the nearest hit it has found (see
``nearest_walk``), so all of them give bit-identical results.
"""

from functools import cache
from types import SimpleNamespace

import warp as wp

from .data import BROAD_PHASES, WALK_FLAG_BITS, model_structs
from .precision import Precision

#: Relative slack on the bounding-box reject, so rounding in the bounds can never reject a box
#: the segment touches (it only lets a few more boxes through to the exact test).
REJECT_SLACK = 1.0e-3

#: Relative pad on the BVH's bounds and queries, well above float32's ulp (1.2e-7): rounding in
#: the per-box reject and in the float64 -> float32 bounds can never make the BVH drop a box the
#: reject would let through.
BOUNDS_PAD_REL = 1.0e-6

#: A walked chord moving less than this [m] along an axis counts as parallel to that axis's cell
#: faces: its reciprocal stays finite in float32 (below 1e30), and so little motion never leaves
#: the rounding pad of the walked grid's lists (``broad_phase.WALK_PAD_ULPS``).
WALK_PARALLEL = 1.0e-30

#: The walked grid's rounding pad [ulps of the kernels' float type, of the walk's scale
#: (``BroadPhase.scale``)]: the lists grow every box's bounds by it besides the path's reach, and
#: the walk's chord-against-bounds test by it too; far above the rounding of a chord's cell
#: crossings, of the kernel's view of the cell faces, of that test and of a contact's position
#: (a few ulps each), so no rounding can hide a box a contact is found on.
WALK_PAD_ULPS = 64.0

#: Boxes of a BVH query gathered before any is tried (``candidate_funcs``' ``nearest_bvh``);
#: a query returning more runs again, trying each box as it comes.
BVH_BATCH = 16

#: Absolute pad [m] on the BVH queries, for coordinates at or near zero, where the relative pad
#: vanishes (above float32's smallest subnormal, so the outward rounding still holds).
BOUNDS_PAD_ABS = 1.0e-30


@cache
def path_struct(p: Precision):
    """The ``Path`` struct of one precision: one leg of a sphere's motion, world frame."""
    scalar, vec3 = p.scalar, p.vec3

    @wp.struct
    class Path:
        """A chord ``a -> a + v`` (``g = 0``, ``tau = 1``) or an arc ``a + v s + 1/2 g s^2``,
        ``s`` in ``[0, tau]``, of a sphere of radius ``r``."""

        a: vec3
        """Centre at the start [m]."""
        v: vec3
        """Chord: the displacement [m]; arc: the velocity at the start [m/s]."""
        g: vec3
        """Arc: the acceleration [m/s^2]; chord: 0."""
        tau: scalar
        """Arc: the time span [s]; chord: 1. The path parameter of "no hit"."""
        r: scalar
        """Sphere radius [m]."""
        mid: vec3
        """Midpoint of the chord [m]."""
        reach: vec3
        """How far the chord reaches from its midpoint per world axis [m], ``|d_i| / 2``,
        padded by ``BOUNDS_PAD_REL (|mid_i| + |d_i| / 2)`` for the rounding of ``mid``: the
        reject (``bounds_funcs``' ``apart``) then never refuses a box the chord's bounds meet,
        even where nothing else grows them (a point against a sharp plate, ``r = 0`` and no
        thickness along the axis)."""
        grow: vec3
        """What the chord's bounding box grows by per world axis [m]: ``r`` (+ the sagitta)."""
        end: vec3
        """End of the path [m]."""
        left: int
        """A box the path cannot meet, not tried (-1: none): the one a chord has just bounced
        off, its rest leaving the surface (the rounded box is convex, so a straight path from
        its surface outward never enters it again), or the one an arc has just bounced off
        and does not come back to in the frame (``nearest_arc.leaving_funcs``). Only loops
        built with :func:`candidate_funcs` ``leaves`` read it."""

    return Path


@cache
def path_funcs(p: Precision):
    """``make_path(a, v, g, tau, r, d, grow) -> Path``: the path from ``a`` [m] along ``v``, ``g``
    over ``[0, tau]`` whose chord is ``d`` [m] and whose bounds grow by ``grow`` [m] per axis."""
    scalar, vec3 = p.scalar, p.vec3
    Path = path_struct(p)
    HALF = scalar(0.5)
    PAD_REL = scalar(BOUNDS_PAD_REL)
    HALF_PADDED = scalar(0.5 * (1.0 + BOUNDS_PAD_REL))  # |d| / 2 and its pad, one product

    @wp.func(inline=True)
    def make_path(a: vec3, v: vec3, g: vec3, tau: scalar, r: scalar, d: vec3, grow: vec3):
        q = Path()
        q.a = a
        q.v = v
        q.g = g
        q.tau = tau
        q.r = r
        q.mid = a + HALF * d
        q.reach = (HALF_PADDED * vec3(wp.abs(d[0]), wp.abs(d[1]), wp.abs(d[2]))
                   + PAD_REL * vec3(wp.abs(q.mid[0]), wp.abs(q.mid[1]), wp.abs(q.mid[2])))
        q.grow = grow
        q.end = a + d
        q.left = -1
        return q

    return make_path


@cache
def bounds_funcs(p: Precision) -> SimpleNamespace:
    """The path bounds shared by every loop: the reject, the grid fit and the BVH query box.

    Returns:
        Namespace with ``apart`` (and its two forms, ``apart_per_axis`` and
        ``apart_branch_free``), ``grid_fits_path`` (and its two forms, ``grid_fits_per_axis``
        and ``grid_fits_branch_free``), ``grid_fits`` and ``bvh_box``.
    """
    scalar, vec3 = p.scalar, p.vec3
    Path = path_struct(p)
    BroadPhase = model_structs(p).BroadPhase
    SLACK = scalar(1.0 + REJECT_SLACK)
    PAD_REL = scalar(BOUNDS_PAD_REL)
    PAD_ABS = scalar(BOUNDS_PAD_ABS)
    ZERO = scalar(0.0)

    @wp.func(inline=True)
    def apart_per_axis(q: Path, center: vec3, extent: vec3):
        """The reject, a test per axis: 1 when the path's bounds and the box's (``center +-
        extent``) are apart along a world axis, both grown (``grow``, ``REJECT_SLACK``):
        ``|rel_i| > (extent_i + grow_i) (1 + REJECT_SLACK) + reach_i`` on some axis ``i``
        (``Path.reach``: half the chord, padded for the rounding of its midpoint)."""
        rel = q.mid - center
        out = int(0)
        for i in range(3):
            if wp.abs(rel[i]) > (extent[i] + q.grow[i]) * SLACK + q.reach[i]:
                out = 1
        return out

    @wp.func(inline=True)
    def apart_branch_free(q: Path, center: vec3, extent: vec3):
        """:func:`apart_per_axis` with one comparison: of the axis where the bounds are the
        most apart, ``max_i (|rel_i| - lim_i) > 0`` (``x - y > 0`` exactly when ``x > y``: no
        rounding of a difference changes its sign, so the verdicts are those of the test per
        axis)."""
        rel = q.mid - center
        lim = wp.cw_mul(extent + q.grow, vec3(SLACK, SLACK, SLACK)) + q.reach
        o0 = wp.abs(rel[0]) - lim[0]
        o1 = wp.abs(rel[1]) - lim[1]
        o2 = wp.abs(rel[2]) - lim[2]
        o01 = wp.where(o0 > o1, o0, o1)
        out = int(0)
        if wp.where(o01 > o2, o01, o2) > ZERO:
            out = 1
        return out

    # The reject the loops use, the same verdicts either way. In a fast swarm whether a box
    # passes is a coin toss, and a branch per axis mispredicts: the branch-free form takes 0.78
    # to 0.89x the float32 frame at 60 m/s in the standard room; in float64 it measured no gain
    # at 60 m/s and 1.10x the frame at 5 m/s (BENCHMARKS.md, "Fast spheres: a reject without
    # branches"). Brute force, which rejects most of a scene's boxes every query, takes the
    # branch-free form in float64 too (``candidate_funcs``).
    apart = apart_branch_free if p.name == "float32" else apart_per_axis

    @wp.func
    def grid_fits_per_axis(a: vec3, b: vec3, mid: vec3, grow: vec3, broad: BroadPhase):
        """``(fits, cell)``: whether the box spanned by ``a`` and ``b``, grown by ``grow`` per
        axis, lies in the grown cell of ``mid`` (their midpoint [m], as the ``Path`` holds it),
        and that cell's linear index (x fastest). Any cell would do (the test is against the
        cell's own bounds); the midpoint's is the one a path fits best: wherever the midpoint
        lies in it, a path fits when ``|b_i - a_i| / 2 + grow_i <= margin``.

        ``broad.margin`` is the margin the host listed the boxes for, less twice the rounding
        pad of any coordinate inside the grid (``BOUNDS_PAD_REL`` of the grid's largest
        coordinate), so no rounding here can accept a path the lists were not made for.
        Whichever cell the rounded ``floor`` picks, the test is against that cell's own bounds.

        The cell's lower face takes the ``floor`` itself (an integer below ``dims``, so
        ``scalar(c)`` is the same value) and the path's extremes are plain comparisons
        (``wp.min``/``wp.max`` also order NaNs: the positions are finite), so the float-int-float
        round trip and the NaN blends are off the lookup's chain: 0.88 to 0.93x the linear
        frame at 5 m/s, the same verdicts and bits
        (BENCHMARKS.md, "The grid lookup's chain").
        """
        fits = int(1)
        index = int(0)
        stride = int(1)
        for i in range(3):
            fc = wp.floor((mid[i] - broad.lower[i]) * broad.inv_cell[i])
            c = int(fc)
            if c < 0 or c >= broad.dims[i]:
                fits = 0
            else:
                cell_lo = broad.lower[i] + fc * broad.cell[i]
                ai = a[i]
                bi = b[i]
                if (wp.where(ai < bi, ai, bi) - grow[i] < cell_lo - broad.margin
                        or wp.where(ai > bi, ai, bi) + grow[i]
                        > cell_lo + broad.cell[i] + broad.margin):
                    fits = 0
                index += c * stride
                stride *= broad.dims[i]
        return fits, index

    @wp.func
    def grid_fits_branch_free(a: vec3, b: vec3, mid: vec3, grow: vec3, broad: BroadPhase):
        """:func:`grid_fits_per_axis` with one comparison for the fit: the largest of the
        overhangs ``(cell_lo - margin) - (lo - grow)`` and ``(hi + grow) - (cell_hi +
        margin)`` over the axes against 0 (``x - y > 0`` exactly when ``x > y``, so the
        verdicts are those of the test per axis), the cell's index clamped into the grid and
        the clamp noted. The same ``(fits, cell)`` wherever it fits."""
        index = int(0)
        stride = int(1)
        outside = int(0)
        over = ZERO  # the largest overhang, when above 0
        for i in range(3):
            c = int(wp.floor((mid[i] - broad.lower[i]) * broad.inv_cell[i]))
            cc = wp.clamp(c, 0, broad.dims[i] - 1)
            outside = outside + wp.where(c != cc, 1, 0)
            cell_lo = broad.lower[i] + scalar(cc) * broad.cell[i]
            ai = a[i]
            bi = b[i]
            lo = wp.where(ai < bi, ai, bi) - grow[i]
            hi = wp.where(ai > bi, ai, bi) + grow[i]
            below = (cell_lo - broad.margin) - lo
            above = hi - (cell_lo + broad.cell[i] + broad.margin)
            o = wp.where(below > above, below, above)
            over = wp.where(o > over, o, over)
            index += cc * stride
            stride *= broad.dims[i]
        fits = int(1)
        if outside > 0 or over > ZERO:
            fits = 0
        return fits, index

    # The fit test the loops use, the same verdicts and cells either way: the test per axis,
    # in both precisions. The branch-free form took 0.95 to 0.98x the float32 frame on the
    # CPU it was written on, and 1.3 to 1.4x on another (AMD family 23, where clang's
    # two-lane vector form of it is slow); so it is kept, tested equal, but not compiled in
    # (BENCHMARKS.md, "Fast spheres: a grid lookup without branches" and "The grid lookup:
    # the branch-free form on another CPU").
    grid_fits_path = grid_fits_per_axis

    @wp.func(inline=True)
    def grid_fits(q: Path, broad: BroadPhase):
        """:func:`grid_fits_path` for the path's query box (its chord's bounding box grown by
        ``grow (1 + REJECT_SLACK)``) in the cell of the chord's midpoint: then only the cell's
        boxes can pass :func:`apart`."""
        return grid_fits_path(q.a, q.end, q.mid, q.grow * SLACK, broad)

    @wp.func(inline=True)
    def bvh_box(q: Path):
        """The BVH query box of the path: the chord's bounding box grown by ``grow (1 +
        REJECT_SLACK)`` and padded (``BOUNDS_PAD_*``), in float32 rounded outward, so every box
        :func:`apart` lets through is a candidate."""
        # whole vectors, not a component at a time: the query then stores each bound as the
        # comparisons of its traversal load it (a bound stored a component at a time and read
        # two components at once waits for both stores: the forced BVH's float32 frame took
        # 1.07 to 1.10x the time so; BENCHMARKS.md, "Loads that wait for stores")
        grow = q.grow * SLACK
        lo = wp.min(q.a, q.end) - grow
        hi = wp.max(q.a, q.end) + grow
        pad = PAD_REL * wp.max(wp.abs(lo), wp.abs(hi)) + vec3(PAD_ABS, PAD_ABS, PAD_ABS)
        return wp.vec3f(lo - pad), wp.vec3f(hi + pad)

    return SimpleNamespace(apart=apart, apart_per_axis=apart_per_axis,
                           apart_branch_free=apart_branch_free, grid_fits_path=grid_fits_path,
                           grid_fits_per_axis=grid_fits_per_axis,
                           grid_fits_branch_free=grid_fits_branch_free, grid_fits=grid_fits,
                           bvh_box=bvh_box)


@cache
def candidate_funcs(p: Precision, exact, broad_phase: str, leaves: bool = False,
                    ) -> SimpleNamespace:
    """The nearest-hit loops over candidate boxes, for one path kind and one broad phase.

    Args:
        p: precision.
        exact: the exact sweep of one box, ``@wp.func exact(q: Path, center, rotation,
            half_extents, box_radius) -> (hit, param, normal)`` with the normal in world
            coordinates and ``param`` in ``[0, q.tau]`` (captured, so one source gives the
            chord's and the arc's loops).
        broad_phase: one of ``BROAD_PHASES``, compiled into ``nearest``: ``"brute"`` every box;
            ``"bvh"`` the BVH query; ``"grid"`` the grid cell's list, every box as the fallback;
            ``"grid-bvh"`` the grid, the BVH as the fallback; ``"walk"`` the cells the path
            crosses, every box as the fallback (for a path :func:`walkable` refuses);
            ``"walk-bvh"`` the walk, the BVH as the fallback. Bit-identical whichever.
        leaves: skip the box a path has left (``Path.left``): a chord cannot enter the
            convex box it leaves again; an arc can come back to it, so its caller leaves a box
            out only where it cannot (``nearest_arc.leaving_funcs``).

    Returns:
        Namespace with ``candidate``, ``nearest_brute``, ``nearest_cell``, ``nearest_bvh``,
        ``nearest_walk``, ``walkable`` and ``nearest``; each loop returns ``(box, param,
        normal)``: ``box`` is -1 when nothing is hit (then ``param = q.tau`` and the normal
        is 0).
    """
    if broad_phase not in BROAD_PHASES:
        raise ValueError(f"broad_phase must be one of {BROAD_PHASES}, got {broad_phase!r}")
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    Path = path_struct(p)
    Boxes, BroadPhase, _, _ = model_structs(p)
    bounds = bounds_funcs(p)
    apart, grid_fits, bvh_box = bounds.apart, bounds.grid_fits, bounds.bvh_box
    # brute force's reject: branch-free in both precisions where it is the method, over a
    # scene's every box (the float64 frame 0.74 to 0.91x with it); as a grid's fallback it
    # keeps ``apart``, so the grid's frames keep their code (with it there the float64
    # ballistic frame took 1.01x the instructions), and the BVH's loop keeps it too (1.02 to
    # 1.04x the float64 frame with it; BENCHMARKS.md, "float64: brute force's loop in
    # registers")
    apart_every = bounds.apart_branch_free if broad_phase == "brute" else apart
    normal_scalars = p.name == "float64"  # brute force's loop (see ``nearest_brute``)
    use_grid = broad_phase in ("grid", "grid-bvh")
    use_walk = broad_phase in ("walk", "walk-bvh")
    fallback_bvh = broad_phase in ("bvh", "grid-bvh", "walk-bvh")
    ZERO = scalar(0.0)
    ONE = scalar(1.0)
    PAST_END = scalar(2.0)  # the crossing "parameter" of an axis the chord never crosses
    PARALLEL = scalar(WALK_PARALLEL)
    FLAG_BITS = WALK_FLAG_BITS
    SLACK = scalar(1.0 + REJECT_SLACK)
    PAD_ULPS = scalar(WALK_PAD_ULPS * p.eps)
    BvhBatch = wp.types.vector(BVH_BATCH, wp.int32)
    # nearest_bvh gathers a query's boxes first in float32 where the BVH is the method; as a
    # fallback (grid-bvh, walk-bvh) the gathering's code made the grid's frame 1.8x slower
    batched = p.name == "float32" and broad_phase == "bvh"
    # the boxes that span the scene kept out of the tree where the BVH is the method; as the
    # grids' fallback the tree holds every box (its loop then kept the frames' code as it was:
    # the kept-out boxes' loop there made the float64 frames 1.04 to 2.6x slower, for paths
    # the grid seldom gives the BVH; BENCHMARKS.md, "The BVH without the walls")
    kept_out = broad_phase == "bvh"

    @wp.func(inline=True)
    def candidate(q: Path, boxes: Boxes, k: int, best: int, best_t: scalar, best_n: vec3):
        """Box ``k`` against the best so far: the reject, the exact sweep, and the closer of the
        two contacts kept (ties: the lower box index); with ``leaves``, never the box the
        path has left."""
        other = int(1)
        if wp.static(leaves):
            if k == q.left:
                other = 0
        if other == 1:
            center = boxes.center[k]
            if apart(q, center, boxes.extent[k]) == 0:
                hit, t, normal = exact(q, center, boxes.rotation[k], boxes.half_extents[k],
                                       boxes.radius[k])
                if hit == 1 and (best < 0 or t < best_t or (t == best_t and k < best)):
                    best = k
                    best_t = t
                    best_n = normal
        return best, best_t, best_n

    @wp.func(inline=True)
    def considered(q: Path, center: vec3, extent: vec3, k: int):
        """1 when box ``k`` (centre ``center`` [m], world half-extent ``extent`` [m]) passes
        the reject and, with ``leaves``, is not the box the path has left."""
        out = int(0)
        if apart_every(q, center, extent) == 0:
            out = 1
            if wp.static(leaves):
                if k == q.left:
                    out = 0
        return out

    @wp.func(inline=True)
    def closer(q: Path, center: vec3, rotation: mat33, half_extents: vec3, box_radius: scalar,
               k: int, best: int, best_t: scalar, best_n: vec3):
        """The exact sweep of box ``k`` and the closer of its contact and the best so far
        (ties: the lower box index)."""
        hit, t, normal = exact(q, center, rotation, half_extents, box_radius)
        if hit == 1 and (best < 0 or t < best_t or (t == best_t and k < best)):
            best = k
            best_t = t
            best_n = normal
        return best, best_t, best_n

    @wp.func(inline=True)
    def nearest_brute(q: Path, boxes: Boxes):
        """The first contact over every box."""
        best = int(-1)
        best_t = q.tau
        best_n = vec3(ZERO, ZERO, ZERO)
        # the box's work written out here, not through :func:`candidate`, which takes the
        # ``Boxes`` struct by value (Warp's C++ passes structs so): through it the float32
        # frame cost 1.25 to 1.29x in a room of 16 boxes, the same bits (BENCHMARKS.md, "Brute
        # force: the loop without the struct's copy"); the grid's and the BVH's loops written
        # so measured no gain, and keep it
        k = int(0)
        count = boxes.center.shape[0]
        if wp.static(normal_scalars):
            # the normal carried as three scalars in float64: carried as a ``vec3``, clang
            # kept it in memory and copied it onto itself every turn, a chain through memory
            # that made the float64 frame 1.5 to 1.8x slower (BENCHMARKS.md, "float64: brute
            # force's loop in registers"); in float32 it measured no gain, and carried so
            # through :func:`candidate` (the grid's, the walk's and the BVH's step) it took
            # 1.02 to 1.06x the float32 grid frame's instructions, so they keep the ``vec3``
            n0, n1, n2 = scalar(0.0), scalar(0.0), scalar(0.0)
            while k < count:
                center = boxes.center[k]
                if considered(q, center, boxes.extent[k], k) == 1:
                    hit, t, normal = exact(q, center, boxes.rotation[k],
                                           boxes.half_extents[k], boxes.radius[k])
                    if hit == 1 and (best < 0 or t < best_t or (t == best_t and k < best)):
                        best = k
                        best_t = t
                        n0, n1, n2 = normal[0], normal[1], normal[2]
                k += 1
            best_n = vec3(n0, n1, n2)
        else:
            while k < count:
                center = boxes.center[k]
                if considered(q, center, boxes.extent[k], k) == 1:
                    best, best_t, best_n = closer(q, center, boxes.rotation[k],
                                                  boxes.half_extents[k], boxes.radius[k], k,
                                                  best, best_t, best_n)
                k += 1
        return best, best_t, best_n

    @wp.func(inline=True)
    def nearest_cell(q: Path, boxes: Boxes, broad: BroadPhase, cell: int):
        """The first contact over the boxes grid cell ``cell`` lists."""
        best = int(-1)
        best_t = q.tau
        best_n = vec3(ZERO, ZERO, ZERO)
        # a ``while`` loop, not ``for j in range(...)``: over a run-time range Warp's loop
        # tests its step's sign every turn, two branches more (the loops over boxes here and
        # in the walk, brute force and the BVH's batch are written so too: 0.92 to 0.94x the
        # frame's instructions, brute force's 0.70x; BENCHMARKS.md, "Loops over a run-time
        # range as `while` loops")
        j = broad.cell_start[cell]
        end = broad.cell_start[cell + 1]
        while j < end:
            best, best_t, best_n = candidate(q, boxes, broad.cell_boxes[j], best, best_t,
                                             best_n)
            j += 1
        return best, best_t, best_n

    @wp.func(inline=True)
    def nearest_bvh(q: Path, boxes: Boxes, broad: BroadPhase):
        """The first contact over the boxes kept out of the BVH's tree (``broad.spanning_*``,
        tried first) and those a query of the tree returns (``broad.bvh = 0``: no tree).

        Boxes are kept out where the BVH is the broad phase (``"bvh"``): those that span the
        scene, such as a room's walls (``broad_phase.tree_split``), which made a query visit
        most of the tree (BENCHMARKS.md, "The BVH without the walls"); as a grid's fallback
        the tree holds every box and its loop is the query's alone.

        With the BVH as the broad phase (``"bvh"``) in float32, the query's boxes are
        gathered first (up to ``BVH_BATCH``) and tried after the traversal, in the order it
        returned them; a query returning more is run a second time, each box tried as it
        comes. Trying each box inside the traversal's loop cost 1.25x that frame with 256
        boxes; in float64 the gathering cost 1.10x, and as the grid's fallback
        (``"grid-bvh"``) it made the grid's own frame 1.8x slower, so there each box is tried
        as it comes (BENCHMARKS.md, "The BVH's query: its boxes gathered first"). The boxes,
        their order and so the bits are the same either way."""
        best = int(-1)
        best_t = q.tau
        best_n = vec3(ZERO, ZERO, ZERO)
        if broad.bvh != wp.uint64(0):  # a tree whenever there are boxes
            lower, upper = bvh_box(q)
            query = wp.bvh_query_aabb(broad.bvh, lower, upper)
            j = broad.spanning_start  # the boxes kept out of the tree, first ("bvh" only)
            end = broad.spanning_start + broad.spanning_count
            k = int(0)
            more = int(0)  # 1: the kept-out boxes, then the query's, each tried as it comes
            if wp.static(batched):
                found = BvhBatch()
                count = int(0)
                while j < end:
                    if count < BVH_BATCH:
                        found[count] = broad.cell_boxes[j]
                    count += 1
                    j += 1
                while wp.bvh_query_next(query, k):
                    if count < BVH_BATCH:
                        found[count] = k
                    count += 1
                if count <= BVH_BATCH:
                    i = int(0)
                    while i < count:
                        best, best_t, best_n = candidate(q, boxes, found[i], best, best_t,
                                                         best_n)
                        i += 1
                else:  # more than a batch: the same boxes in the same order, as they come
                    query = wp.bvh_query_aabb(broad.bvh, lower, upper)
                    j = broad.spanning_start
                    more = int(1)
            elif wp.static(kept_out):
                more = int(1)
            else:  # the grid's fallback: a tree over every box, each tried as it comes
                while wp.bvh_query_next(query, k):
                    best, best_t, best_n = candidate(q, boxes, k, best, best_t, best_n)
            if wp.static(batched or kept_out):
                # one loop for both (one copy of the box's work: a third copy left the
                # float32 frame too large to inline whole, 1.027x its instructions)
                while more == 1:
                    if j < end:
                        k = broad.cell_boxes[j]
                        j += 1
                    elif not wp.bvh_query_next(query, k):
                        more = int(0)
                    if more == 1:
                        best, best_t, best_n = candidate(q, boxes, k, best, best_t, best_n)
        return best, best_t, best_n

    @wp.func(inline=True)
    def walkable(q: Path, broad: BroadPhase):
        """1 when the walked grid's lists were made for the path: its growth (radius, sagitta)
        within ``broad.reach`` and its ends within ``broad.scale`` of the origin on every axis
        (the lists' rounding pad is sized for that scale); else the fallback answers it."""
        ok = int(1)
        for i in range(3):
            if (q.grow[i] > broad.reach or wp.abs(q.a[i]) > broad.scale
                    or wp.abs(q.end[i]) > broad.scale):
                ok = 0
        return ok

    @wp.func(inline=True)
    def crossing(lower: scalar, cell: scalar, a: scalar, inv_d: scalar, c: int, step: int):
        """The chord's parameter where it leaves cell ``c`` along one axis, moving by ``step``
        (+1, -1; 0: it does not move along it, ``PAST_END``): computed afresh from the cell's
        face each time (grid ``lower`` [m], ``cell`` [m], start ``a`` [m], ``1 / d`` [1/m]), so
        no rounding accumulates along a long walk."""
        out = PAST_END
        if step != 0:
            face = c
            if step > 0:
                face = c + 1
            out = (lower + scalar(face) * cell - a) * inv_d
        return out

    @wp.func(inline=True)
    def advance(lower: scalar, cell: scalar, a: scalar, inv_d: scalar, c: int, step: int,
                dims: int, axis: int):
        """One step of the walk across a face of axis ``axis``: ``(c, t, fresh_bit, inside)``,
        the new cell index along it, where the chord leaves that cell (:func:`crossing`), the
        entry flag that marks a box fresh there (first along the axis, walking down: last) and
        whether the cell is in the grid (``dims`` cells along the axis)."""
        c = c + step
        fresh_bit = int(1) << axis
        if step < 0:
            fresh_bit = int(1) << (axis + 3)
        inside = int(1)
        if c < 0 or c >= dims:
            inside = 0
        return c, crossing(lower, cell, a, inv_d, c, step), fresh_bit, inside

    @wp.func(inline=True)
    def crosses(q: Path, inv_d: vec3, center: vec3, extent: vec3, pad: scalar,
                best_t: scalar):
        """1 unless the chord misses the box's bounds (``center +- extent``) grown as the
        reject grows them, and by ``pad`` [m], or enters them only past ``best_t``: the slab
        test of the chord (``inv_d``: ``1 / d`` per axis, 0 on a parallel axis). A contact puts
        the centre inside those bounds (on the chord, within the sagitta of the arc; the pad
        holds the rounding), so a box it refuses cannot be hit before ``best_t``."""
        lo = ZERO
        hi = ONE
        for i in range(3):
            w = (extent[i] + q.grow[i]) * SLACK + pad
            rel = center[i] - q.a[i]
            if inv_d[i] == ZERO:
                if wp.abs(rel) > w:
                    hi = -ONE
            else:
                ta = (rel - w) * inv_d[i]
                tb = (rel + w) * inv_d[i]
                lo = wp.max(lo, wp.min(ta, tb))
                hi = wp.min(hi, wp.max(ta, tb))
        out = int(0)
        if lo <= hi and lo * q.tau <= best_t:
            out = 1
        return out

    @wp.func(inline=True)
    def nearest_walk(q: Path, boxes: Boxes, broad: BroadPhase):
        """The first contact over the boxes listed in the cells the path's chord crosses.

        The chord ``q.a -> q.end`` is clipped to the grid and its cells are walked in order
        (3D-DDA: each step crosses the nearest cell face, its parameter computed afresh from
        the face). Each box is tried once per walk: in the first cell along the walk that lists
        it. A cell lists a box when the box's reject bounds grown by ``broad.reach`` and the
        rounding pad meet it, so the cells listing a box form an axis-aligned range; the walk's
        cells are monotone along each axis, so a box listed in the cell just entered was listed
        in an earlier one exactly when it is listed in the cell just left, i.e. unless the range
        starts (or, walking down, ends) at the entered cell along the axis just crossed: the
        entry's flags (``BroadPhase.cell_boxes``).

        The walk stops at the first cell entered beyond the nearest hit found so far: a hit at
        ``t`` puts the centre (on the chord, the arc within its sagitta of it) within ``reach``
        of the box's bounds, in a cell entered at or before ``t``, which lists the box. Ties
        keep the lower index (``candidate``), so the answer is brute force's, bit for bit. An
        axis along which the chord moves less than ``WALK_PARALLEL`` [m] counts as parallel
        (an explicit flag, no division by zero): so little motion stays inside the pad.

        Contract: ``(box, param, normal)`` as ``nearest_brute``; -1, ``q.tau``, 0 without a
        hit. Only for a path :func:`walkable` accepts.
        """
        best = int(-1)
        best_t = q.tau
        best_n = vec3(ZERO, ZERO, ZERO)
        d = q.end - q.a
        pad = PAD_ULPS * broad.scale
        # the chord's part inside the grid, [f0, f1]; no box's lists reach outside it
        f0 = ZERO
        f1 = ONE
        step = wp.vec3i(0, 0, 0)
        inv_d = vec3(ZERO, ZERO, ZERO)
        for i in range(3):
            lo = broad.lower[i]
            hi = lo + scalar(broad.dims[i]) * broad.cell[i]
            if wp.abs(d[i]) < PARALLEL:
                if q.a[i] < lo or q.a[i] > hi:
                    f1 = -ONE
            else:
                inv_d[i] = ONE / d[i]
                ta = (lo - q.a[i]) * inv_d[i]
                tb = (hi - q.a[i]) * inv_d[i]
                f0 = wp.max(f0, wp.min(ta, tb))
                f1 = wp.min(f1, wp.max(ta, tb))
                if d[i] > ZERO:
                    step[i] = 1
                else:
                    step[i] = -1
        if f0 <= f1:
            # the walk in scalars (a vector indexed by a run-time axis goes through memory)
            start = q.a + f0 * d
            lo0, lo1, lo2 = broad.lower[0], broad.lower[1], broad.lower[2]
            h0, h1, h2 = broad.cell[0], broad.cell[1], broad.cell[2]
            n0, n1, n2 = broad.dims[0], broad.dims[1], broad.dims[2]
            s0, s1, s2 = step[0], step[1], step[2]
            i0, i1, i2 = inv_d[0], inv_d[1], inv_d[2]
            c0 = wp.clamp(int(wp.floor((start[0] - lo0) * broad.inv_cell[0])), 0, n0 - 1)
            c1 = wp.clamp(int(wp.floor((start[1] - lo1) * broad.inv_cell[1])), 0, n1 - 1)
            c2 = wp.clamp(int(wp.floor((start[2] - lo2) * broad.inv_cell[2])), 0, n2 - 1)
            t0 = crossing(lo0, h0, q.a[0], i0, c0, s0)
            t1 = crossing(lo1, h1, q.a[1], i1, c1, s1)
            t2 = crossing(lo2, h2, q.a[2], i2, c2, s2)
            # a box is fresh in a cell unless it was listed in the cell just left too: its
            # entry's flag of "first along the axis crossed" (walking down: "last") says so
            fresh_bit = int(0)  # the first cell: every box
            walking = int(1)
            while walking == 1:
                cell = c0 + n0 * (c1 + n1 * c2)
                j = broad.cell_start[cell]
                end = broad.cell_start[cell + 1]
                while j < end:
                    entry = broad.cell_boxes[j]
                    if fresh_bit == 0 or (entry & fresh_bit) != 0:
                        # the chord against the box's bounds first, on the entry's own copy of
                        # them (read in order, no indirection)
                        if crosses(q, inv_d, broad.entry_bounds[2 * j],
                                   broad.entry_bounds[2 * j + 1], pad, best_t) == 1:
                            best, best_t, best_n = candidate(q, boxes, entry >> FLAG_BITS, best,
                                                             best_t, best_n)
                    j += 1
                # the next cell: across the nearest face
                enter = wp.min(wp.min(t0, t1), t2)
                if enter > f1 or enter * q.tau > best_t:
                    walking = 0
                elif enter == t0:
                    c0, t0, fresh_bit, walking = advance(lo0, h0, q.a[0], i0, c0, s0, n0, 0)
                elif enter == t1:
                    c1, t1, fresh_bit, walking = advance(lo1, h1, q.a[1], i1, c1, s1, n1, 1)
                else:
                    c2, t2, fresh_bit, walking = advance(lo2, h2, q.a[2], i2, c2, s2, n2, 2)
        return best, best_t, best_n

    @wp.func(inline=True)
    def nearest(q: Path, boxes: Boxes, broad: BroadPhase):
        """The first contact of the path over the boxes, by the broad phase compiled in."""
        box = int(-1)
        t = q.tau
        normal = vec3(ZERO, ZERO, ZERO)
        fits = int(0)
        if wp.static(use_grid):
            fits, cell = grid_fits(q, broad)
            if fits == 1:
                box, t, normal = nearest_cell(q, boxes, broad, cell)
        if wp.static(use_walk):
            fits = walkable(q, broad)
            if fits == 1:
                box, t, normal = nearest_walk(q, boxes, broad)
        if fits == 0:
            if wp.static(fallback_bvh):
                box, t, normal = nearest_bvh(q, boxes, broad)
            else:
                box, t, normal = nearest_brute(q, boxes)
        return box, t, normal

    return SimpleNamespace(candidate=candidate, nearest_brute=nearest_brute,
                           nearest_cell=nearest_cell, nearest_bvh=nearest_bvh,
                           nearest_walk=nearest_walk, walkable=walkable, nearest=nearest)
