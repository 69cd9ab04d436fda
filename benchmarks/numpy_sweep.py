"""The plain vectorised NumPy sweep: spheres against rounded boxes, the way a Python user would
write it without Warp. It is the side-by-side baseline of ``python -m benchmarks.sweep``.

Same algorithm as the kernels (one sweep per box, the first contact over the boxes),
vectorised over the ``N`` spheres with a Python loop over the ``K`` boxes. Per box, in the box's
local frame (``a_l = M^T (a - c)``, ``d_l = M^T v dt``, ``M`` local -> world) and with the
Minkowski radius ``R = rb + r``:

1. a start on or inside the rounded box is a hit at ``t = 0`` iff it moves in (``d . n < 0``);
2. otherwise the segment against the grown OBB ``[-(h + R), h + R]`` (slab test);
3. the entry point's region picks the answer: a face (the entry is the hit), one edge capsule,
   or the three capsules meeting at a corner (the nearest is kept);
4. a contact counts only when ``d . n < 0``; over the boxes the smallest ``t`` wins (ties: the
   lower index), after a cheap bounding-box reject.
"""

from __future__ import annotations

import numpy as np

from warpsim import validation as check
from warpsim.obstacles import RoundedBox, RoundedBoxes

#: A direction component at most this many machine epsilons of the largest one is parallel to
#: its slab: below one ulp, its motion over the segment is lost in rounding anyway, and the flag
#: avoids a 0/0.
PARALLEL_ULPS = 1.0

#: A Minkowski radius at most this many epsilons of the local scale is a sharp box: the grown
#: OBB entry is then within rounding of the true surface, and such a thin capsule is not
#: resolvable.
SHARP_ULPS = 16.0

#: Relative slack on the bounding-box reject, so rounding in the bounds
#: never rejects a box the segment touches (it only lets a few more boxes to the exact test).
REJECT_SLACK = 1.0e-3


def _dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", x, y)


def _sign(x: np.ndarray) -> np.ndarray:
    """+1 for x >= 0, -1 otherwise (a point on a symmetry plane picks the + side)."""
    return np.where(x >= 0, 1, -1).astype(x.dtype)


def _normalize(x: np.ndarray) -> np.ndarray:
    length = np.sqrt(_dot(x, x))
    return x / np.where(length > 0, length, 1)[:, None]


def _entry_root(w: np.ndarray, d: np.ndarray, radius: np.ndarray):
    """First ``t`` in [0, 1] where ``|w + t d|`` (rows; ``|w| > radius`` at ``t = 0``) falls to
    ``radius``: the entering root of ``a2 t^2 + 2 b t + c`` with ``a2 = |d|^2``, ``b = w . d``,
    ``c = |w|^2 - radius^2``.

    Both steps are the cancellation-free forms. The discriminant ``b^2 - a2 c`` is taken as
    ``a2 (radius^2 - |m|^2)``, ``m = w - (b / a2) d`` the offset at the closest approach: the
    textbook difference subtracts two numbers of size ``|w|^2 |d|^2`` and loses the answer
    when the path starts far from the feature (float32: a 5 cm ball 300 m away). The root is
    ``c / (-b + sqrt(disc))`` (``b < 0``), a sum of two positive terms, which never divides by
    ``a2``.

    Returns:
        ``(hit, t)``: no hit when moving away or along (``b >= 0``), when the line passes
        outside (``|m| > radius``), or beyond ``t = 1``; ``t = 1`` then.
    """
    a2 = _dot(d, d)
    b = _dot(w, d)
    c = _dot(w, w) - radius * radius
    moving_in = (b < 0) & (a2 > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        closest = w - np.where(moving_in, b / np.where(moving_in, a2, 1), 0)[:, None] * d
        disc = a2 * (radius * radius - _dot(closest, closest))
        hit = moving_in & (disc >= 0)
        t = np.where(hit, c / (-b + np.sqrt(np.where(hit, disc, 0))), 1)
    hit &= t <= 1
    return hit, np.where(hit, t, 1).astype(w.dtype)


def _segment_sphere(a, d, center, radius):
    """Segment ``a + t d`` against balls of ``radius`` at ``center`` (rows): ``(hit, t, n)``.

    A start on or inside the ball is a hit at ``t = 0`` (the caller checks the direction).
    """
    w = a - center
    hit, t = _entry_root(w, d, radius)
    inside = _dot(w, w) - radius * radius <= 0
    hit |= inside
    t = np.where(inside, 0, t).astype(a.dtype)
    return hit, t, _normalize(w + t[:, None] * d)


def _segment_capsule(a, d, e0, e1, radius):
    """Segment ``a + t d`` against capsules of ``radius`` about ``e0 -> e1`` (rows).

    The infinite cylinder first (a circle problem in the plane perpendicular to the axis); its
    entry is the hit when it falls between the end caps, else the end sphere on that side is the
    answer. A start inside the cylinder goes straight to that end sphere; a capsule of zero
    length is a sphere.

    Returns:
        ``(hit, t, normal)``; ``t = 1`` and any normal without hit.
    """
    axis = e1 - e0
    length = np.sqrt(_dot(axis, axis))
    point = length <= 0
    u = axis / np.where(point, 1, length)[:, None]
    w = a - e0
    w_perp = w - _dot(w, u)[:, None] * u
    d_perp = d - _dot(d, u)[:, None] * u
    in_cylinder, t_cyl = _entry_root(w_perp, d_perp, radius)
    started_in = _dot(w_perp, w_perp) - radius * radius <= 0
    in_cylinder |= started_in
    t_cyl = np.where(started_in, 0, t_cyl).astype(a.dtype)
    y = _dot(w + t_cyl[:, None] * d, u)

    hit0, t0, n0 = _segment_sphere(a, d, e0, radius)
    hit1, t1, n1 = _segment_sphere(a, d, e1, radius)
    below = point | (y < 0)
    above = ~point & (y > length)
    side = ~below & ~above
    hit = np.where(point, hit0, in_cylinder & np.where(below, hit0, np.where(above, hit1, True)))
    t = np.where(below, t0, np.where(above, t1, t_cyl))
    n_cyl = _normalize(w_perp + t_cyl[:, None] * d_perp)
    normal = np.where(below[:, None], n0, np.where(side[:, None], n_cyl, n1))
    return hit, np.where(hit, t, 1).astype(a.dtype), normal


def _start_state(a, h, radius):
    """Signed distance of local points to the rounded box and the outward normal there.

    Outside the core box the normal points from the nearest core point; inside it, it is the
    normal of the nearest core face (ties: the lower axis; a coordinate of 0 picks +).
    """
    w = a - np.clip(a, -h, h)
    dist = np.sqrt(_dot(w, w))
    out = dist > 0
    depth = h - np.abs(a)
    k = np.argmin(depth, axis=1)
    rows = np.arange(a.shape[0])
    n_in = np.zeros_like(a)
    n_in[rows, k] = _sign(a[rows, k])
    normal = np.where(out[:, None], w / np.where(out, dist, 1)[:, None], n_in)
    distance = np.where(out, dist, -depth[rows, k]) - radius
    return distance, normal


def _sweep_local(a, d, h, radius, eps):
    """First contact of segments ``a + t d`` (rows, box frame) with one rounded box.

    Args:
        a: segment starts [m], box frame, (M, 3).
        d: segment displacements [m], box frame, (M, 3).
        h: core half extents [m], (3,).
        radius: Minkowski radii ``R = rb + r`` [m], (M,).
        eps: machine epsilon of the working dtype.

    Returns:
        ``(hit (M,), t (M,), normal (M, 3))``, normal in the box frame.
    """
    dtype = a.dtype
    m_rows = a.shape[0]
    rows = np.arange(m_rows)
    s0, n0 = _start_state(a, h, radius)
    touching = s0 <= 0
    start_hit = touching & (_dot(d, n0) < 0)

    # 2. Slab test against the grown box [-g, g].
    g = h[None, :] + radius[:, None]
    dmax = np.abs(d).max(axis=1)
    parallel = np.abs(d) <= PARALLEL_ULPS * eps * dmax[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-g - a) / d
        t2 = (g - a) / d
    t_near = np.where(parallel, -np.inf, np.minimum(t1, t2))
    t_far = np.where(parallel, np.inf, np.maximum(t1, t2))
    parallel_miss = (parallel & (np.abs(a) > g)).any(axis=1)
    entry = np.maximum(t_near.max(axis=1), -1)  # -1: starts inside the grown box
    axis = np.where(entry >= 0, np.argmax(t_near, axis=1), -1)  # first max: lower axis on ties
    exit_ = np.minimum(t_far.min(axis=1), 1)
    slab_hit = ~parallel_miss & ~(entry > exit_) & ~(entry > 1) & ~(exit_ < 0) & ~touching

    # 3. Region of the entry point; the entry face counts as outside.
    t_entry = np.maximum(entry, 0).astype(dtype)
    p = a + t_entry[:, None] * d
    outside = (np.abs(p) > h) | (np.arange(3)[None, :] == axis[:, None])
    count = outside.sum(axis=1)
    scale = np.maximum(g.max(axis=1), np.sqrt(_dot(a, a)))
    sharp = radius <= SHARP_ULPS * eps * scale

    hit = np.zeros(m_rows, dtype=bool)
    t = np.ones(m_rows, dtype=dtype)
    normal = np.zeros_like(a)

    face = slab_hit & ((count <= 1) | sharp)
    if face.any():
        # The plane facing the motion, or, for a start inside the grown box but outside the
        # rounded one, the face the start sticks out of the most.
        k = np.where(axis >= 0, axis, np.argmax(np.abs(p) - h, axis=1))
        s = np.where(axis >= 0, -_sign(d[rows, k]), _sign(p[rows, k]))
        face_n = np.zeros_like(a)
        face_n[rows, k] = s
        hit = np.where(face, True, hit)
        t = np.where(face, t_entry, t)
        normal = np.where(face[:, None], face_n, normal)

    edge = slab_hit & ~face & (count == 2)
    if edge.any():
        i = np.flatnonzero(edge)
        m = np.argmin(outside[i], axis=1)  # the one inside axis is the edge direction
        e0 = _sign(p[i]) * h
        e1 = e0.copy()
        e0[np.arange(i.size), m] = -h[m]
        e1[np.arange(i.size), m] = h[m]
        hit[i], t[i], normal[i] = _segment_capsule(a[i], d[i], e0, e1, radius[i])

    corner = slab_hit & ~face & (count == 3)
    if corner.any():
        i = np.flatnonzero(corner)
        c0 = _sign(p[i]) * h
        best_hit = np.zeros(i.size, dtype=bool)
        best_t = np.ones(i.size, dtype=dtype)
        best_n = np.zeros((i.size, 3), dtype=dtype)
        for j in range(3):
            c1 = c0.copy()
            c1[:, j] = -c1[:, j]
            hj, tj, nj = _segment_capsule(a[i], d[i], c0, c1, radius[i])
            take = hj & (~best_hit | (tj < best_t))
            best_hit |= take
            best_t = np.where(take, tj, best_t)
            best_n = np.where(take[:, None], nj, best_n)
        hit[i], t[i], normal[i] = best_hit, best_t, best_n

    # 4. Only a motion into the surface is a contact.
    hit &= _dot(d, normal) < 0
    hit = np.where(touching, start_hit, hit)
    t = np.where(touching, 0, t).astype(dtype)
    normal = np.where(touching[:, None], n0, normal)
    return hit, np.where(hit, t, 1).astype(dtype), np.where(hit[:, None], normal, 0)


def sweep_boxes_numpy(position, velocity, radius, boxes: RoundedBoxes | RoundedBox, dt: float,
                      dtype=np.float32) -> dict:
    """First contact of each moving sphere with a group of static rounded boxes, in NumPy.

    Every sphere's centre moves in a straight line from ``a`` to ``b = a + v dt``; the first
    contact over all boxes is kept (ties: the lower box index). A contact counts only when the
    sphere moves into the surface (``v . n < 0``); a sphere starting on or inside a box and
    moving in is hit at ``t = 0``, one moving away or along is not. A zero displacement never
    hits. Inputs are never modified.

    Args:
        position: sphere centres at the start of the frame [m], world frame, (N, 3).
        velocity: sphere velocities [m/s], world frame, (N, 3).
        radius: sphere radii [m], scalar or (N,), each >= 0.
        boxes: the obstacles.
        dt: frame duration [s], > 0.
        dtype: working precision, ``np.float32`` or ``np.float64``.

    Returns:
        Dict of arrays in ``dtype`` (world frame):

        * ``hit``: (N,) bool.
        * ``t``: fraction of ``a -> b`` at first contact, in [0, 1]; 1 without contact, (N,).
        * ``box``: index of the box hit, -1 without contact, (N,) int32.
        * ``position``: centre at first contact ``a + t (b - a)`` [m]; ``b`` without, (N, 3).
        * ``normal``: unit outward normal of the box at the contact; 0 without, (N, 3).
        * ``new_position``: contact centre plus the rest of the path ``(1 - t)(b - a)``
          reflected [m]; ``b`` without contact, (N, 3).
        * ``new_velocity``: ``v - 2 (v . n) n`` [m/s]; ``v`` without contact, (N, 3).

    Raises:
        ValueError: a bad input, naming the field and the index.
    """
    boxes, pos, vel, rad = check.sphere_batch(position, velocity, radius, boxes)
    dtype = np.dtype(dtype)
    if dtype not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(f"dtype must be float32 or float64, got {dtype}")
    n = pos.shape[0]
    vel = vel.astype(dtype)
    rad = rad.astype(dtype)
    step = dtype.type(check.scalar("dt", dt, positive=True))
    eps = dtype.type(np.finfo(dtype).eps)

    a = pos.astype(dtype)
    d = vel * step
    rotations = boxes.rotation_matrices().astype(dtype)
    centers = boxes.center.astype(dtype)
    half_extents = boxes.half_extents.astype(dtype)
    box_radius = boxes.radius.astype(dtype)
    extent = boxes.world_extent().astype(dtype)

    best_t = np.full(n, np.inf, dtype=dtype)
    best_box = np.full(n, -1, dtype=np.int32)
    best_n = np.zeros((n, 3), dtype=dtype)
    for k in range(len(boxes)):
        # Cheap reject: the segment's world bounding box and the box's, grown by r, are apart.
        mid = a + dtype.type(0.5) * d - centers[k]
        reach = (extent[k] + rad[:, None]) * dtype.type(1 + REJECT_SLACK) \
            + dtype.type(0.5) * np.abs(d)
        near = np.flatnonzero((np.abs(mid) <= reach).all(axis=1))
        if near.size == 0:
            continue
        m = rotations[k]
        a_l = (a[near] - centers[k]) @ m  # M^T (a - c), row-wise
        d_l = d[near] @ m
        hit, t, n_l = _sweep_local(a_l, d_l, half_extents[k], box_radius[k] + rad[near], eps)
        take = hit & (t < best_t[near])
        rows = near[take]
        best_t[rows] = t[take]
        best_box[rows] = k
        best_n[rows] = n_l[take] @ m.T

    hit = best_box >= 0
    t = np.where(hit, best_t, 1).astype(dtype)
    contact = a + t[:, None] * d
    v_n = _dot(vel, best_n)[:, None]
    new_velocity = vel - 2 * v_n * best_n
    d_reflected = d - 2 * _dot(d, best_n)[:, None] * best_n
    new_position = np.where(hit[:, None], contact + (1 - t)[:, None] * d_reflected, a + d)
    return {"hit": hit, "t": t, "box": best_box, "position": contact, "normal": best_n,
            "new_position": new_position.astype(dtype), "new_velocity": new_velocity}
