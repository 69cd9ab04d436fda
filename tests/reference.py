"""Independent float64 references for a sphere swept against rounded boxes (test support only).

The kernels' method (grown OBB, face Voronoi test of the entry point, then one
or three edge capsules). The references here deliberately take other routes, so that a bug in
that chain shows up as a disagreement:

* :func:`sweep_reference_batch` (primary) enumerates **all 26 features** of the Minkowski sum
  (radius ``R = rb + r``) in the box's local frame: 6 face rectangles, 12 finite edge cylinders
  and 8 corner spheres, and keeps the smallest entering ``t``. The rounded box is the union of
  the 3 boxes ``[-h - R e_i, h + R e_i]``, the 12 cylinders and the 8 balls, and every point of
  the patches tested lies in that union, so the first entry into the union is the smallest
  entry over the patches; no Voronoi classification is needed.
* :func:`sweep_by_distance` (secondary) only evaluates the exact signed distance ``f(t)`` along
  the segment, written independently (quaternion rotation, no matrix). The rounded box is
  convex, so ``f`` is convex in ``t``: a golden-section search finds its minimum, and bisection
  on the decreasing part finds the first root.

Contract shared with the package (see the physics contract):
    * ``t`` in [0, 1] along ``a -> b``; the contact is the sphere centre ``a + t (b - a)``.
    * The normal is the unit outward normal of the rounded box at the contact, world frame.
    * A contact counts only when the motion goes into the surface, ``d . n < 0`` with
      ``d = b - a``; a tangent (grazing) path is no hit; a zero-length segment never hits.
    * A start on or inside the rounded box (signed distance of ``a`` <= 0) is a hit at ``t = 0``
      iff ``d . n < 0``, ``n`` the outward normal at ``a``: outside the core box the direction
      from the nearest core point; inside the core box the normal of the nearest core face
      (ties: the lower axis), with the sign of the local coordinate (a coordinate of 0 picks +).
    * ``R = 0`` (a point against a sharp box): only the closed face rectangles remain. At an edge
      or corner the normal is ambiguous; the reference returns the normal of the face whose
      plane is crossed last (the slab entry axis), and on an exact tie the lower axis.
    * No hit: ``t = 1``, contact ``b``, normal 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from warpsim.obstacles import RoundedBoxes, quat_to_matrix

#: Secondary method: a segment whose minimum signed distance lies within this band [m] of zero
#: only touches (or barely dips into) the surface. Whether it counts as a hit there rests on
#: float64 rounding (of the discriminant in the primary, of the distance in the secondary), so
#: the two methods may legitimately disagree; such segments are reported as ambiguous.
NEAR_GRAZE = 1.0e-9

#: Secondary method: a crossing with ``|f'(t)| / |d|`` below this (a shallow, near-tangent
#: entry) has an ill-conditioned root: an error of one rounding unit in ``f`` moves ``t`` by
#: ``eps / slope``. Such segments are reported as ambiguous too.
SHALLOW_ENTRY = 1.0e-6

#: Primary method, ``R = 0``: face crossings within this many units of ``t`` of the first one
#: reach the same edge or corner point (they differ by rounding only); the last-crossed face of
#: that group gives the normal.
SHARP_TIE_ULPS = 8.0

MISS, HIT, AMBIGUOUS = 0, 1, 2

_EPS = float(np.finfo(np.float64).eps)


@dataclass(frozen=True)
class SweepRef:
    """First contact of one swept sphere with one rounded box.

    Attributes:
        hit: whether the sphere touches the box while moving into it.
        t: fraction of ``a -> b`` at first contact, in [0, 1]; 1 without contact.
        contact: sphere centre at first contact ``a + t (b - a)`` [m], world frame, (3,);
            ``b`` without contact.
        normal: unit outward normal of the rounded box at the contact, world frame, (3,);
            0 without contact.
    """

    hit: bool
    t: float
    contact: np.ndarray
    normal: np.ndarray


@dataclass(frozen=True)
class SweepRefArrays:
    """:class:`SweepRef` for ``N`` segments at once: ``hit`` (N,), ``t`` (N,),
    ``contact`` [m] (N, 3) and ``normal`` (N, 3), world frame."""

    hit: np.ndarray
    t: np.ndarray
    contact: np.ndarray
    normal: np.ndarray


@dataclass(frozen=True)
class DistanceSweep:
    """Result of :func:`sweep_by_distance` for ``N`` segments.

    Attributes:
        status: ``MISS``, ``HIT`` or ``AMBIGUOUS`` (near grazing, shallow entry, or a start whose
            direction of motion sits on a kink of the distance), (N,) int.
        t: first root of the signed distance along the segment (0 for a start in contact,
            1 otherwise when no hit), (N,).
        normal: finite-difference gradient of the signed distance at the contact, world frame,
            (N, 3); 0 without hit.
        min_distance: minimum of the signed distance along the segment [m], (N,).
    """

    status: np.ndarray
    t: np.ndarray
    normal: np.ndarray
    min_distance: np.ndarray


def _rows3(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64).reshape(-1, 3)


def _box_frame(a, b, center, rotation):
    """Segment start and displacement in the box's local frame (local = M^T (world - c))."""
    m = quat_to_matrix(np.asarray(rotation, dtype=np.float64) /
                       np.linalg.norm(np.asarray(rotation, dtype=np.float64)))
    c = np.asarray(center, dtype=np.float64)
    a, b = _rows3(a), _rows3(b)
    return m, (a - c) @ m, (b - a) @ m


def core_distance_and_normal(p: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance [m] from local points to the core box ``[-h, h]`` and the outward normal.

    Outside the core box the normal points from the nearest core point; inside it (distance
    <= 0) it is the normal of the nearest core face, ties going to the lower axis, with the
    sign of the coordinate (0 counts as +).

    Args:
        p: points in the box's local frame [m], (N, 3).
        h: core half extents [m], (3,).

    Returns:
        ``(distance (N,), normal (N, 3))``.
    """
    q = np.clip(p, -h, h)
    w = p - q
    out = np.linalg.norm(w, axis=1)
    depth = h - np.abs(p)
    k = np.argmin(depth, axis=1)  # first minimum: the lower axis on ties
    rows = np.arange(p.shape[0])
    inside_normal = np.zeros_like(p)
    inside_normal[rows, k] = np.where(p[rows, k] >= 0.0, 1.0, -1.0)
    outside = out > 0.0
    safe = np.where(outside, out, 1.0)
    normal = np.where(outside[:, None], w / safe[:, None], inside_normal)
    distance = np.where(outside, out, -depth[rows, k])
    return distance, normal


class _Best:
    """Running minimum of candidate hits (strict ``<``: the first candidate wins a tie)."""

    def __init__(self, n: int):
        self.t = np.full(n, np.inf)
        self.normal = np.zeros((n, 3))

    def offer(self, t: np.ndarray, normal: np.ndarray, valid: np.ndarray) -> None:
        take = valid & (t < self.t)
        self.t = np.where(take, t, self.t)
        self.normal = np.where(take[:, None], normal, self.normal)


def _face_candidates(a, d, h, big_r):
    """Entering crossings of the 6 face rectangles: ``(t (N, 6), valid (N, 6), axis, sign)``.

    Face ``(i, s)`` is the rectangle ``p_i = s (h_i + R)``, ``|p_j| <= h_j`` (closed), outward
    normal ``s e_i``; it is entered only when ``s d_i < 0``.
    """
    n = a.shape[0]
    ts = np.full((n, 6), np.inf)
    valid = np.zeros((n, 6), dtype=bool)
    axes, signs = [], []
    col = 0
    for i in range(3):
        others = [j for j in range(3) if j != i]
        for s in (1.0, -1.0):
            moving_in = s * d[:, i] < 0.0
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(moving_in, (s * (h[i] + big_r) - a[:, i]) / d[:, i], np.inf)
            p = a + np.where(np.isfinite(t), t, 0.0)[:, None] * d
            in_rect = np.ones(n, dtype=bool)
            for j in others:
                in_rect &= np.abs(p[:, j]) <= h[j]
            ok = moving_in & (t >= 0.0) & (t <= 1.0) & in_rect
            ts[:, col] = t
            valid[:, col] = ok
            axes.append(i)
            signs.append(s)
            col += 1
    return ts, valid, np.array(axes), np.array(signs)


def _entering_root(qa, qb, qc, r2, cross2):
    """Smaller root of ``qa t^2 + 2 qb t + qc`` for a start outside (``qc > 0``) moving in.

    The quadratic is ``|w + t d|^2 - R^2`` (``qa = |d|^2``, ``qb = w . d``, ``qc = |w|^2 - R^2``)
    in the plane across an edge or in space about a corner. Its discriminant comes from
    Lagrange's identity ``(w . d)^2 = |w|^2 |d|^2 - |w x d|^2``: ``qb^2 - qa qc =
    qa R^2 - |w x d|^2`` (``cross2 = |w x d|^2``, ``r2 = R^2``). ``|w x d|`` is ``|d|`` times
    the line's distance from the feature and carries the rounding of ``w`` and ``d`` only, so
    the form holds its digits when the segment starts far away, where ``qb^2 - qa qc``
    subtracts two numbers of size ``|w|^2 |d|^2``. The root is ``qc / (-qb + sqrt(disc))``, a
    sum of two positive terms.

    Returns:
        ``(t, ok)``; ``ok`` requires ``qb < 0`` and a positive discriminant (a double root is a
        tangent touch, not an entry).
    """
    disc = qa * r2 - cross2
    ok = (qc > 0.0) & (qb < 0.0) & (disc > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(ok, qc / (-qb + np.sqrt(np.where(ok, disc, 0.0))), np.inf)
    return t, ok


def _local_sweep(a, d, h, big_r):
    """Primary method in the local frame. ``big_r`` is (N,). Returns ``(t, normal)``, t = inf
    for no hit."""
    n = a.shape[0]
    best = _Best(n)
    rounded = big_r > 0.0

    # Faces. For R = 0, several faces can meet the segment at the same edge or corner point:
    # the one crossed last (largest t of the near-tied group) gives the normal.
    ts, valid, axes, signs = _face_candidates(a, d, h, big_r)
    t_face = np.where(valid, ts, np.inf)
    t_first = t_face.min(axis=1)
    tied = valid & (t_face <= t_first[:, None] + SHARP_TIE_ULPS * _EPS * np.maximum(
        1.0, np.abs(t_first))[:, None])
    sharp_pick = np.argmax(np.where(tied, t_face, -np.inf), axis=1)  # first max: lower axis
    round_pick = np.argmin(t_face, axis=1)
    pick = np.where(rounded, round_pick, sharp_pick)
    rows = np.arange(n)
    face_t = np.where(rounded, t_first, t_face[rows, pick])
    face_n = np.zeros((n, 3))
    face_n[rows, axes[pick]] = signs[pick]
    best.offer(face_t, face_n, valid.any(axis=1))

    # Edge cylinders (radius R, axis along m through (s_i h_i, s_j h_j), |p_m| <= h_m).
    r2 = big_r * big_r
    for m in range(3):
        i, j = [k for k in range(3) if k != m]
        for si in (1.0, -1.0):
            for sj in (1.0, -1.0):
                pi = a[:, i] - si * h[i]
                pj = a[:, j] - sj * h[j]
                qa = d[:, i] ** 2 + d[:, j] ** 2
                qb = pi * d[:, i] + pj * d[:, j]
                qc = pi * pi + pj * pj - r2
                cross = pi * d[:, j] - pj * d[:, i]  # w x d, across the edge
                t, ok = _entering_root(qa, qb, qc, r2, cross * cross)
                tt = np.where(ok, t, 0.0)
                axial = a[:, m] + tt * d[:, m]
                normal = np.zeros((n, 3))
                normal[:, i] = pi + tt * d[:, i]
                normal[:, j] = pj + tt * d[:, j]
                length = np.linalg.norm(normal, axis=1)
                normal /= np.where(length > 0.0, length, 1.0)[:, None]
                ok &= rounded & (t <= 1.0) & (np.abs(axial) <= h[m])
                ok &= np.einsum("ij,ij->i", d, normal) < 0.0
                best.offer(t, normal, ok)

    # Corner spheres (radius R at s * h).
    for sx in (1.0, -1.0):
        for sy in (1.0, -1.0):
            for sz in (1.0, -1.0):
                w = a - np.array([sx, sy, sz]) * h
                qa = np.einsum("ij,ij->i", d, d)
                qb = np.einsum("ij,ij->i", w, d)
                qc = np.einsum("ij,ij->i", w, w) - r2
                cross = np.cross(w, d)
                t, ok = _entering_root(qa, qb, qc, r2, np.einsum("ij,ij->i", cross, cross))
                normal = w + np.where(ok, t, 0.0)[:, None] * d
                length = np.linalg.norm(normal, axis=1)
                normal /= np.where(length > 0.0, length, 1.0)[:, None]
                ok &= rounded & (t <= 1.0)
                ok &= np.einsum("ij,ij->i", d, normal) < 0.0
                best.offer(t, normal, ok)
    return best.t, best.normal


def sweep_reference_batch(a, b, center, half_extents, rotation, box_radius,
                          sphere_radius) -> SweepRefArrays:
    """First contact of ``N`` spheres swept along ``a -> b`` with one rounded box (float64).

    Primary method: every one of the 26 features of the Minkowski sum is intersected and the
    smallest entering ``t`` kept (see the module docstring for the contract).

    Args:
        a: sphere centres at ``t = 0`` [m], world frame, (N, 3) or (3,).
        b: sphere centres at ``t = 1`` [m], world frame, (N, 3) or (3,).
        center: box centre [m], world frame, (3,).
        half_extents: core half extents [m], box frame, (3,), each >= 0.
        rotation: quaternion ``(x, y, z, w)``, box -> world, (4,); normalised here.
        box_radius: rounding radius ``rb`` [m], >= 0.
        sphere_radius: sphere radii ``r`` [m], scalar or (N,), each >= 0.

    Returns:
        :class:`SweepRefArrays`.
    """
    m, a_l, d_l = _box_frame(a, b, center, rotation)
    a_w, b_w = _rows3(a), _rows3(b)
    n = a_l.shape[0]
    h = np.asarray(half_extents, dtype=np.float64)
    big_r = float(box_radius) + np.broadcast_to(np.asarray(sphere_radius, dtype=np.float64),
                                                (n,))
    t, normal_l = _local_sweep(a_l, d_l, h, big_r)

    core, n0 = core_distance_and_normal(a_l, h)
    start = core - big_r <= 0.0
    start_in = start & (np.einsum("ij,ij->i", d_l, n0) < 0.0)
    t = np.where(start, np.where(start_in, 0.0, np.inf), t)
    normal_l = np.where(start[:, None], n0, normal_l)

    hit = np.isfinite(t)
    t = np.where(hit, t, 1.0)
    normal = np.where(hit[:, None], normal_l @ m.T, 0.0)
    contact = np.where(hit[:, None], a_w + t[:, None] * (b_w - a_w), b_w)
    return SweepRefArrays(hit=hit, t=t, contact=contact, normal=normal)


def _entering_root_scalar(qa: float, qb: float, qc: float, r2: float, cross2: float) -> float:
    """Scalar :func:`_entering_root` (the same stable forms): the entering root, or inf when
    there is none."""
    disc = qa * r2 - cross2
    if qc > 0.0 and qb < 0.0 and disc > 0.0:
        return qc / (-qb + math.sqrt(disc))
    return math.inf


def _local_sweep_scalar(a, d, h, big_r):
    """Primary method for one segment, plain floats, local frame: ``(t, normal)``, t = inf
    for no hit. Same features and tie rules as :func:`_local_sweep`."""
    best_t, best_n = math.inf, (0.0, 0.0, 0.0)

    faces = []  # (t, axis, sign) of every entering face-rectangle crossing
    for i in range(3):
        for s in (1.0, -1.0):
            if s * d[i] < 0.0:
                t = (s * (h[i] + big_r) - a[i]) / d[i]
                if 0.0 <= t <= 1.0 and all(abs(a[j] + t * d[j]) <= h[j]
                                           for j in range(3) if j != i):
                    faces.append((t, i, s))
    if faces:
        t_first = min(f[0] for f in faces)
        if big_r > 0.0:
            _, i, s = next(f for f in faces if f[0] == t_first)
            best_t = t_first
        else:  # the last-crossed face of the group meeting at the same edge or corner point
            limit = t_first + SHARP_TIE_ULPS * _EPS * max(1.0, abs(t_first))
            best_t, i, s = max((f for f in faces if f[0] <= limit), key=lambda f: f[0])
        best_n = tuple(s if k == i else 0.0 for k in range(3))
    if big_r <= 0.0:
        return best_t, best_n

    r2 = big_r * big_r
    for m in range(3):
        i, j = (k for k in range(3) if k != m)
        for si in (1.0, -1.0):
            for sj in (1.0, -1.0):
                pi, pj = a[i] - si * h[i], a[j] - sj * h[j]
                t = _entering_root_scalar(d[i] * d[i] + d[j] * d[j], pi * d[i] + pj * d[j],
                                          pi * pi + pj * pj - r2, r2,
                                          (pi * d[j] - pj * d[i]) ** 2)
                if t <= 1.0 and t < best_t and abs(a[m] + t * d[m]) <= h[m]:
                    ni, nj = pi + t * d[i], pj + t * d[j]
                    length = math.hypot(ni, nj)
                    normal = [0.0, 0.0, 0.0]
                    normal[i], normal[j] = ni / length, nj / length
                    if d[i] * normal[i] + d[j] * normal[j] < 0.0:
                        best_t, best_n = t, tuple(normal)
    for sx in (1.0, -1.0):
        for sy in (1.0, -1.0):
            for sz in (1.0, -1.0):
                w = (a[0] - sx * h[0], a[1] - sy * h[1], a[2] - sz * h[2])
                cross = (w[1] * d[2] - w[2] * d[1], w[2] * d[0] - w[0] * d[2],
                         w[0] * d[1] - w[1] * d[0])
                t = _entering_root_scalar(sum(x * x for x in d),
                                          sum(x * y for x, y in zip(w, d, strict=True)),
                                          sum(x * x for x in w) - r2, r2,
                                          sum(x * x for x in cross))
                if t <= 1.0 and t < best_t:
                    p = [x + t * y for x, y in zip(w, d, strict=True)]
                    length = math.sqrt(sum(x * x for x in p))
                    normal = tuple(x / length for x in p)
                    if sum(x * y for x, y in zip(d, normal, strict=True)) < 0.0:
                        best_t, best_n = t, normal
    return best_t, best_n


def sweep_reference(a, b, center, half_extents, rotation, box_radius,
                    sphere_radius) -> SweepRef:
    """First contact of one sphere swept along ``a -> b`` with one rounded box (float64).

    Plain-float version of :func:`sweep_reference_batch` (same method, same contract), fast
    enough for tens of thousands of single calls; prefer the batch form for many segments.

    Args:
        a: sphere centre at ``t = 0`` [m], world frame, (3,).
        b: sphere centre at ``t = 1`` [m], world frame, (3,).
        center: box centre [m], world frame, (3,).
        half_extents: core half extents [m], box frame, (3,), each >= 0.
        rotation: quaternion ``(x, y, z, w)``, box -> world, (4,).
        box_radius: rounding radius ``rb`` [m], >= 0.
        sphere_radius: sphere radius ``r`` [m], >= 0; ``R = rb + r`` may be 0.

    Returns:
        :class:`SweepRef` (see the module docstring for the contract).
    """
    m, a_l, d_l = _box_frame(a, b, center, rotation)
    a_w, b_w = _rows3(a)[0], _rows3(b)[0]
    h = np.asarray(half_extents, dtype=np.float64)
    big_r = float(box_radius) + float(sphere_radius)
    core, n0 = core_distance_and_normal(a_l, h)
    al, dl, hl = a_l[0].tolist(), d_l[0].tolist(), h.tolist()
    if core[0] - big_r <= 0.0:
        t = 0.0 if float(d_l[0] @ n0[0]) < 0.0 else math.inf
        normal_l = n0[0]
    else:
        t, normal_l = _local_sweep_scalar(al, dl, hl, big_r)
    if not math.isfinite(t):
        return SweepRef(hit=False, t=1.0, contact=b_w.copy(), normal=np.zeros(3))
    return SweepRef(hit=True, t=t, contact=a_w + t * (b_w - a_w),
                    normal=m @ np.asarray(normal_l, dtype=np.float64))


def nearest_reference_batch(a, b, boxes: RoundedBoxes, sphere_radius) -> dict:
    """First contact of ``N`` swept spheres over a group of boxes (ties: the lower box index).

    Args:
        a: sphere centres at ``t = 0`` [m], world frame, (N, 3).
        b: sphere centres at ``t = 1`` [m], world frame, (N, 3).
        boxes: the obstacles.
        sphere_radius: sphere radii [m], scalar or (N,).

    Returns:
        Dict of ``hit`` (N,), ``t`` (N,), ``box`` (N,) int (-1 without hit), ``normal`` (N, 3)
        and ``contact`` [m] (N, 3), world frame, with the no-hit values of :class:`SweepRef`.
    """
    a_w, b_w = _rows3(a), _rows3(b)
    n = a_w.shape[0]
    t = np.full(n, np.inf)
    box = np.full(n, -1, dtype=np.int64)
    normal = np.zeros((n, 3))
    for k in range(len(boxes)):
        one = sweep_reference_batch(a_w, b_w, boxes.center[k], boxes.half_extents[k],
                                    boxes.rotation[k], boxes.radius[k], sphere_radius)
        take = one.hit & (one.t < t)
        t = np.where(take, one.t, t)
        box = np.where(take, k, box)
        normal = np.where(take[:, None], one.normal, normal)
    hit = box >= 0
    t = np.where(hit, t, 1.0)
    contact = a_w + t[:, None] * (b_w - a_w)
    return {"hit": hit, "t": t, "box": box, "normal": normal, "contact": contact}


def nearest_reference(a, b, boxes: RoundedBoxes, sphere_radius):
    """First contact of one swept sphere over a group of boxes (ties: the lower box index).

    Returns:
        ``(hit, t, box_index, normal, contact)``: box index -1, ``t = 1``, normal 0 and contact
        ``b`` without hit; normal and contact [m] in the world frame.
    """
    out = nearest_reference_batch(a, b, boxes, sphere_radius)
    return (bool(out["hit"][0]), float(out["t"][0]), int(out["box"][0]), out["normal"][0],
            out["contact"][0])


def reflect_reference(vector, normal) -> np.ndarray:
    """Mirror ``vector`` about the plane of unit ``normal``: ``v - 2 (v . n) n`` (last axis)."""
    v = np.asarray(vector, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    return v - 2.0 * np.sum(v * n, axis=-1, keepdims=True) * n


def bounce_reference(position, velocity, radius, boxes: RoundedBoxes, dt: float) -> dict:
    """The full single-bounce result of the contract for ``N`` spheres (one box, and the first
    contact over many).

    The centre would travel ``a -> b = a + v dt``. With a hit at ``t`` and normal ``n``: the
    contact centre ``a + t (b - a)``, ``v' = v - 2 (v . n) n``, and the new position
    ``contact + (1 - t) reflect(b - a)`` (the rest of the path along ``v'``).

    Args:
        position: centres at the start [m], world frame, (N, 3).
        velocity: velocities [m/s], world frame, (N, 3).
        radius: sphere radii [m], scalar or (N,).
        boxes: the obstacles.
        dt: frame duration [s].

    Returns:
        Dict with ``hit`` (N,), ``t`` (N,), ``box`` (N,) (-1 none), ``position`` (contact
        centre, ``b`` without hit) [m], ``normal`` (0 without hit), ``new_position`` [m] and
        ``new_velocity`` [m/s], each (N, 3), world frame.
    """
    a = _rows3(position)
    v = _rows3(velocity)
    d = v * float(dt)
    b = a + d
    near = nearest_reference_batch(a, b, boxes, radius)
    hit, t, n = near["hit"], near["t"], near["normal"]
    contact = near["contact"]
    new_velocity = np.where(hit[:, None], reflect_reference(v, n), v)
    new_position = np.where(hit[:, None],
                            contact + (1.0 - t)[:, None] * reflect_reference(d, n), b)
    return {"hit": hit, "t": t, "box": near["box"], "position": contact, "normal": n,
            "new_position": new_position, "new_velocity": new_velocity}


# --- Secondary method: the signed distance along the segment --------------------------------


def _rotate_to_local(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate world vectors (N, 3) by the inverse of unit quaternion ``q = (x, y, z, w)``."""
    u = -q[:3]  # conjugate
    w = q[3]
    uv = np.cross(u, v)
    return v + 2.0 * w * uv + 2.0 * np.cross(u, uv)


def rounded_box_sdf(points, center, half_extents, rotation, big_r) -> np.ndarray:
    """Exact signed distance [m] from world points (N, 3) to the rounded box of radius ``big_r``.

    Written apart from the package's own (quaternion rotation, no matrix), for the secondary
    method. ``big_r`` is a scalar or (N,).
    """
    q = np.asarray(rotation, dtype=np.float64)
    q = q / np.linalg.norm(q)
    p = _rotate_to_local(q, _rows3(points) - np.asarray(center, dtype=np.float64))
    e = np.abs(p) - np.asarray(half_extents, dtype=np.float64)
    return (np.linalg.norm(np.maximum(e, 0.0), axis=1) + np.minimum(e.max(axis=1), 0.0)
            - big_r)


def sweep_by_distance(a, b, center, half_extents, rotation, box_radius, sphere_radius,
                      iterations: int = 64) -> DistanceSweep:
    """Secondary reference: first contact found from the signed distance ``f(t)`` alone.

    The rounded box is convex, so ``f(t) = sdf(a + t (b - a))`` is convex in ``t``. Outside at
    ``t = 0``: a golden-section search gives ``min f`` on [0, 1]; a hit when it is below
    ``-NEAR_GRAZE``, and the first root is bisected on ``[0, argmin]`` where ``f`` decreases.
    A start on or inside the surface: hit iff the directional derivative of ``f`` at ``a``
    (central difference) is negative. Cases whose answer rests on rounding (grazing, shallow
    entry, a start on a kink of ``f``) come back ``AMBIGUOUS``.

    Args:
        a, b, center, half_extents, rotation, box_radius, sphere_radius: as
            :func:`sweep_reference_batch`.
        iterations: golden-section and bisection steps.

    Returns:
        :class:`DistanceSweep`.
    """
    a_w, b_w = _rows3(a), _rows3(b)
    n = a_w.shape[0]
    d = b_w - a_w
    big_r = float(box_radius) + np.broadcast_to(np.asarray(sphere_radius, dtype=np.float64),
                                                (n,))

    # The rotation is linear: rotate the start and the displacement once, then f(t) is cheap.
    q = np.asarray(rotation, dtype=np.float64)
    q = q / np.linalg.norm(q)
    a_l = _rotate_to_local(q, a_w - np.asarray(center, dtype=np.float64))
    d_l = _rotate_to_local(q, d)
    h = np.asarray(half_extents, dtype=np.float64)

    def f(t):
        e = np.abs(a_l + t[:, None] * d_l) - h
        return (np.sqrt(np.einsum("ij,ij->i", np.maximum(e, 0.0), np.maximum(e, 0.0)))
                + np.minimum(e.max(axis=1), 0.0) - big_r)

    def gradient(p):
        step = 1.0e-7
        g = np.zeros_like(p)
        for i in range(3):
            e = np.zeros(3)
            e[i] = step
            g[:, i] = (rounded_box_sdf(p + e, center, half_extents, rotation, big_r)
                       - rounded_box_sdf(p - e, center, half_extents, rotation, big_r)) / (
                           2.0 * step)
        return g / np.maximum(np.linalg.norm(g, axis=1), 1e-300)[:, None]

    length = np.linalg.norm(d, axis=1)
    zeros, ones = np.zeros(n), np.ones(n)
    f0 = f(zeros)

    # Golden section for the minimum of the convex f on [0, 1].
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    lo, hi = zeros.copy(), ones.copy()
    x1, x2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    f1, f2 = f(x1), f(x2)
    for _ in range(iterations):
        left = f1 <= f2
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        new_x = np.where(left, hi - ratio * (hi - lo), lo + ratio * (hi - lo))
        new_f = f(new_x)
        x1, x2, f1, f2 = (np.where(left, new_x, x2), np.where(left, x1, new_x),
                          np.where(left, new_f, f2), np.where(left, f1, new_f))
    t_min = np.where(f1 <= f2, x1, x2)
    f_min = np.minimum(f1, f2)
    f_end = f(ones)
    t_min = np.where(f_end < f_min, 1.0, t_min)
    f_min = np.minimum(np.minimum(f_min, f_end), f0)

    # First root on [0, t_min], where f decreases from f0 > 0 to f_min < 0.
    lo, hi = zeros.copy(), t_min.copy()
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        inside = f(mid) <= 0.0
        hi = np.where(inside, mid, hi)
        lo = np.where(inside, lo, mid)
    t_root = hi
    dt_probe = 1.0e-7
    slope = (f(np.minimum(t_root + dt_probe, 1.0)) - f(np.maximum(t_root - dt_probe, 0.0))) / (
        np.minimum(t_root + dt_probe, 1.0) - np.maximum(t_root - dt_probe, 0.0))

    outside = f0 > NEAR_GRAZE
    enters = outside & (f_min < -NEAR_GRAZE)
    shallow = enters & (-slope < SHALLOW_ENTRY * length)
    status = np.where(enters, HIT, MISS)
    status = np.where(outside & (np.abs(f_min) <= NEAR_GRAZE), AMBIGUOUS, status)
    status = np.where(shallow, AMBIGUOUS, status)

    # Start on or inside the surface: the sign of the directional derivative at a.
    probe = 1.0e-7
    ahead = (f(np.full(n, probe)) - f0) / probe
    behind = (f0 - f(np.full(n, -probe))) / probe
    start = ~outside
    start_kink = np.abs(ahead - behind) > SHALLOW_ENTRY * length
    start_flat = np.abs(ahead + behind) < 2.0 * SHALLOW_ENTRY * length
    near_surface_out = (f0 > 0.0) & (f0 <= NEAR_GRAZE)
    start_status = np.where(ahead + behind < 0.0, HIT, MISS)
    start_status = np.where(start_kink | start_flat | near_surface_out, AMBIGUOUS, start_status)
    status = np.where(start, start_status, status)

    t = np.where(status == HIT, np.where(start, 0.0, t_root), 1.0)
    contact = a_w + t[:, None] * d
    normal = np.where((status == HIT)[:, None], gradient(contact), 0.0)
    return DistanceSweep(status=status, t=t, normal=normal, min_distance=f_min)
