"""Static obstacles: oriented rounded boxes, validated on the host.

A rounded box is the set of points within ``radius`` of the core box ``[-h, h]`` (local frame),
placed in the world by ``rotation`` (quaternion ``(x, y, z, w)``, local -> world) and ``center``.
A plain box has ``radius = 0``. Zero half extents are legal: plates, sticks and points.

Every field is checked by :mod:`warpsim.validation` (the same checks the scene files use).
:meth:`RoundedBoxes.nearest` finds each point's nearest box in bounded memory, for the emitter
and for the check that no sphere starts inside an obstacle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import validation as check
from .blocks import for_row_blocks

IDENTITY_QUAT = (0.0, 0.0, 0.0, 1.0)

POINT_BLOCK = 1 << 15
"""Points per block of :meth:`RoundedBoxes.nearest`: the blocks run on the process's cores at
once, so a draw of a few hundred thousand spheres is cut into enough blocks for every core
(measured here, two cores, the standard room's placement of 200 000 spheres: 0.22 to 0.27 s
with blocks of 32 768 points against 0.28 to 0.43 s with one block of 262 144; 2 million
points 0.46 to 0.48 s against 0.56 to 0.63 s)."""

PAIR_CHUNK = 1 << 18
"""Point-box pairs evaluated at once by :meth:`RoundedBoxes.nearest`: about 250 bytes each, so
its memory stays near 65 MB plus ~100 bytes per point, whatever the number of boxes (measured:
140 MB at the peak for a million points among ten thousand boxes)."""

MAX_CELLS_PER_BOX = 64
"""A box whose bounds cover more grid cells than this is left to a coarser grid (or, among the
last few, tested against the points in its bounds): keeps the grid small when a scene mixes a
large floor with many small pegs."""

DIRECT_BOXES = 8
"""With this few boxes left, each is tested against the points inside its bounds directly: a
grid would cost more than it saves."""

GRID_AXIS_CELLS = 1 << 20
"""Most grid cells along one axis, so a cell's key (three 21-bit fields) is an exact int64."""

BOUNDS_PAD_REL = 1e-9
"""World bounds are grown by this fraction of their coordinates: far above float64's rounding of
the bounds and of the distances (~1e-16 relative), so no point nearer than asked is missed."""


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (local -> world) of unit quaternions ``(..., 4)`` in ``(x, y, z, w)``.

    Returns:
        ``(..., 3, 3)`` float64 array.
    """
    q = np.asarray(q, dtype=np.float64)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - z * w)
    m[..., 0, 2] = 2 * (x * z + y * w)
    m[..., 1, 0] = 2 * (x * y + z * w)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - x * w)
    m[..., 2, 0] = 2 * (x * z - y * w)
    m[..., 2, 1] = 2 * (y * z + x * w)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


@dataclass(frozen=True)
class RoundedBox:
    """One oriented rounded box (validated, float64).

    Attributes:
        center: world position of the box centre [m], shape (3,).
        half_extents: half sizes of the core box along its local axes [m], shape (3,), each >= 0.
        rotation: unit quaternion (x, y, z, w), local -> world, shape (4,).
        radius: rounding radius [m], >= 0; 0 is a sharp box.
    """

    center: np.ndarray
    half_extents: np.ndarray
    rotation: np.ndarray
    radius: float

    def __init__(self, center=(0.0, 0.0, 0.0), half_extents=(0.5, 0.5, 0.5),
                 rotation=IDENTITY_QUAT, radius: float = 0.0):
        center, half_extents, rotation, radius = check.rounded_box(center, half_extents,
                                                                   rotation, radius)
        object.__setattr__(self, "center", check.frozen(center))
        object.__setattr__(self, "half_extents", check.frozen(half_extents))
        object.__setattr__(self, "rotation", check.frozen(rotation))
        object.__setattr__(self, "radius", radius)

    @classmethod
    def _trusted(cls, center, half_extents, rotation, radius) -> RoundedBox:
        self = object.__new__(cls)
        object.__setattr__(self, "center", check.frozen(np.array(center, dtype=np.float64)))
        object.__setattr__(self, "half_extents",
                           check.frozen(np.array(half_extents, dtype=np.float64)))
        object.__setattr__(self, "rotation", check.frozen(np.array(rotation, dtype=np.float64)))
        object.__setattr__(self, "radius", float(radius))
        return self

    def as_boxes(self) -> RoundedBoxes:
        """This box as a group of one."""
        return RoundedBoxes(center=[self.center], half_extents=[self.half_extents],
                            rotation=[self.rotation], radius=[self.radius])

    def __eq__(self, other) -> bool:
        if not isinstance(other, RoundedBox):
            return NotImplemented
        return (np.array_equal(self.center, other.center)
                and np.array_equal(self.half_extents, other.half_extents)
                and np.array_equal(self.rotation, other.rotation)
                and self.radius == other.radius)

    __hash__ = None  # mutable-looking numpy fields: not hashable

    def __repr__(self) -> str:
        return (f"RoundedBox(center={self.center.tolist()}, half_extents="
                f"{self.half_extents.tolist()}, rotation={self.rotation.tolist()}, "
                f"radius={self.radius:g})")


class RoundedBoxes:
    """A group of ``K`` oriented rounded boxes, struct of arrays (validated, float64, read-only).

    Args:
        center: box centres in the world [m], shape (K, 3).
        half_extents: core half sizes along local axes [m], shape (K, 3), each >= 0.
        rotation: unit quaternions (x, y, z, w), local -> world, shape (K, 4); None for identity.
            Normalised on input; a zero quaternion is refused.
        radius: rounding radii [m], scalar or shape (K,), each >= 0; None for sharp boxes.

    Raises:
        ValueError: naming the field and the index of the first bad entry.
    """

    def __init__(self, center, half_extents, rotation=None, radius=None):
        self.center = check.frozen(check.vec3_array("center", center))
        k = self.center.shape[0]
        self.half_extents = check.frozen(
            check.nonnegative_vec3_array("half_extents", half_extents, k))
        self.rotation = check.frozen(check.unit_quat_array(
            "rotation", IDENTITY_QUAT if rotation is None else rotation, k))
        self.radius = check.frozen(
            check.per_item("radius", 0.0 if radius is None else radius, k, minimum=0.0))

    @classmethod
    def concatenate(cls, groups: list[RoundedBoxes | RoundedBox]) -> RoundedBoxes:
        """One group holding the boxes of ``groups`` in order."""
        parts = [g.as_boxes() if isinstance(g, RoundedBox) else g for g in groups]
        if not parts:
            raise ValueError("concatenate needs at least one group of boxes")
        return cls(center=np.concatenate([p.center for p in parts]),
                   half_extents=np.concatenate([p.half_extents for p in parts]),
                   rotation=np.concatenate([p.rotation for p in parts]),
                   radius=np.concatenate([p.radius for p in parts]))

    def as_boxes(self) -> RoundedBoxes:
        """This group itself (so a box and a group can be passed alike)."""
        return self

    def __len__(self) -> int:
        return self.center.shape[0]

    def __getitem__(self, i) -> RoundedBox | RoundedBoxes:
        if isinstance(i, (int, np.integer)):
            k = len(self)
            if not -k <= i < k:
                raise IndexError(f"box index {i} out of range for {k} boxes")
            return RoundedBox._trusted(self.center[i], self.half_extents[i],
                                       self.rotation[i], self.radius[i])
        return RoundedBoxes(center=self.center[i], half_extents=self.half_extents[i],
                            rotation=self.rotation[i], radius=self.radius[i])

    def __iter__(self):
        return (self[i] for i in range(len(self)))

    def __eq__(self, other) -> bool:
        if not isinstance(other, RoundedBoxes):
            return NotImplemented
        return all(np.array_equal(getattr(self, f), getattr(other, f))
                   for f in ("center", "half_extents", "rotation", "radius"))

    __hash__ = None

    def __repr__(self) -> str:
        return f"RoundedBoxes({len(self)} boxes)"

    def rotation_matrices(self) -> np.ndarray:
        """Local -> world rotation matrices, shape (K, 3, 3)."""
        return quat_to_matrix(self.rotation)

    def bounding_radius(self) -> np.ndarray:
        """Radius of the sphere about each centre that holds the whole rounded box [m], (K,)."""
        return np.linalg.norm(self.half_extents, axis=1) + self.radius

    def world_extent(self) -> np.ndarray:
        """Half sizes of each rounded box's world-axis-aligned bounding box [m], (K, 3)."""
        return (np.einsum("kij,kj->ki", np.abs(self.rotation_matrices()), self.half_extents)
                + self.radius[:, None])

    def signed_distance(self, points) -> np.ndarray:
        """Signed distance [m] from world points ``(P, 3)`` to every box, shape (P, K).

        Negative inside. Exact for rounded boxes (distance to the core box minus the radius).
        Memory is ``P K``: for many points and boxes use :meth:`nearest`.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return _signed_distance(p[:, None, :] - self.center[None, :, :],
                                self.rotation_matrices()[None], self.half_extents[None],
                                self.radius[None])

    def nearest(self, points, within) -> tuple[np.ndarray, np.ndarray]:
        """The nearest box to each point, for the points nearer than ``within`` to some box.

        Candidates come from a grid over the boxes' world bounds (grown by ``within``), boxes
        too large for it from coarser grids, so memory stays bounded (:data:`PAIR_CHUNK` pairs
        at a time) for a million points among ten thousand boxes.

        Args:
            points: world points [m], shape (P, 3).
            within: distance [m], a scalar or (P,), finite: only boxes whose signed distance
                from the point is below it count.

        Returns:
            ``(distance, index)``, both (P,): the smallest signed distance [m] over the boxes and
            the box that has it (the lowest index on ties), bit for bit what
            ``signed_distance(points)`` gives, wherever it is below ``within``; ``inf`` and -1
            for the points with no box that near.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        within = np.broadcast_to(np.asarray(within, dtype=np.float64), p.shape[:1])
        if not np.isfinite(within).all():
            raise ValueError("within must be finite")
        if len(self) == 0 or p.shape[0] == 0:
            return np.full(p.shape[0], np.inf), np.full(p.shape[0], -1, dtype=np.int64)
        distance = np.empty(p.shape[0])  # every block writes all of its own rows
        index = np.empty(p.shape[0], dtype=np.int64)
        matrices = self.rotation_matrices()
        grow = max(float(within.max()), 0.0)
        reach = self.world_extent() + grow
        pad = BOUNDS_PAD_REL * (np.abs(self.center) + reach)
        lo, hi = self.center - reach - pad, self.center + reach + pad

        def block(part: slice) -> None:  # a point's answer depends on that point alone
            distance[part], index[part] = self._nearest_among(p[part], within[part], lo, hi,
                                                              matrices)

        for_row_blocks(p.shape[0], block, POINT_BLOCK)  # blocks of points on every core
        return distance, index

    def _nearest_among(self, p, within, lo, hi, matrices) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`nearest` for one block of points, the boxes' grown bounds ``[lo, hi]``."""
        distance = np.full(p.shape[0], np.inf)
        index = np.full(p.shape[0], -1, dtype=np.int64)
        for pi, bk in _candidate_pairs(lo, hi, np.arange(len(self)), p):
            d = _signed_distance(p[pi] - self.center[bk], matrices[bk], self.half_extents[bk],
                                 self.radius[bk])
            near = d < within[pi]
            pi, bk, d = pi[near], bk[near], d[near]
            order = np.lexsort((bk, d, pi))  # per point: nearest first, lowest index on ties
            pi, bk, d = pi[order], bk[order], d[order]
            first = np.ones(pi.shape[0], dtype=bool)
            first[1:] = pi[1:] != pi[:-1]
            pi, bk, d = pi[first], bk[first], d[first]
            better = (d < distance[pi]) | ((d == distance[pi]) & (bk < index[pi]))
            distance[pi[better]] = d[better]
            index[pi[better]] = bk[better]
        return distance, index


def _signed_distance(offset, matrices, half_extents, radius) -> np.ndarray:
    """Signed distance [m] of points at ``offset`` from box centres (world frame), broadcast
    over leading axes: ``offset`` (..., 3), ``matrices`` (..., 3, 3) local -> world,
    ``half_extents`` (..., 3), ``radius`` (...). The one formula both queries use."""
    local = (matrices[..., 0, :] * offset[..., 0, None]
             + matrices[..., 1, :] * offset[..., 1, None]
             + matrices[..., 2, :] * offset[..., 2, None])  # R^T offset
    q = np.abs(local) - half_extents
    out = np.maximum(q, 0.0)
    outside = np.sqrt(out[..., 0] * out[..., 0] + out[..., 1] * out[..., 1]
                      + out[..., 2] * out[..., 2])
    inside = np.minimum(np.maximum(np.maximum(q[..., 0], q[..., 1]), q[..., 2]), 0.0)
    return outside + inside - radius


def _chunks(pi: np.ndarray, bk: np.ndarray):
    for start in range(0, pi.shape[0], PAIR_CHUNK):
        yield pi[start:start + PAIR_CHUNK], bk[start:start + PAIR_CHUNK]


def _candidate_pairs(lo: np.ndarray, hi: np.ndarray, ids: np.ndarray, points: np.ndarray):
    """Yield ``(point index, box index)`` arrays, at most :data:`PAIR_CHUNK` long, holding once
    every pair of a point and a box of ``ids`` whose bounds ``[lo, hi]`` hold the point.

    A uniform grid of cells the size of the median box holds the boxes covering at most
    :data:`MAX_CELLS_PER_BOX` cells; each point looks up its own cell. The larger boxes go to
    the next, coarser level; the last :data:`DIRECT_BOXES` are tested directly.
    """
    if ids.size == 0:
        return
    if ids.size <= DIRECT_BOXES:
        for k in ids:
            inside = np.flatnonzero(((points >= lo[k]) & (points <= hi[k])).all(axis=1))
            yield from _chunks(inside, np.full(inside.shape[0], k, dtype=np.int64))
        return
    box_lo, box_hi = lo[ids], hi[ids]
    origin, top = box_lo.min(axis=0), box_hi.max(axis=0)
    cell = max(float(np.median((box_hi - box_lo).max(axis=1))),
               float((top - origin).max()) / (GRID_AXIS_CELLS - 1))
    if not cell > 0.0:  # every box is a point at the same place
        cell = 1.0
    first = np.minimum(np.floor((box_lo - origin) / cell).astype(np.int64), GRID_AXIS_CELLS - 1)
    last = np.minimum(np.floor((box_hi - origin) / cell).astype(np.int64), GRID_AXIS_CELLS - 1)
    span = last - first + 1
    cells = span.prod(axis=1)
    small = cells <= MAX_CELLS_PER_BOX
    if not small.any():  # cannot happen (half the boxes are at most the median), but be safe
        small[np.argmin(cells)] = True

    # Every (cell key, box) of the small boxes, sorted by key.
    first_s, span_s, cells_s = first[small], span[small], cells[small]
    owner = np.repeat(np.arange(first_s.shape[0]), cells_s)
    offset = np.arange(owner.shape[0]) - np.repeat(np.cumsum(cells_s) - cells_s, cells_s)
    sx, sy = span_s[owner, 0], span_s[owner, 1]
    cell_index = first_s[owner] + np.stack([offset % sx, (offset // sx) % sy,
                                            offset // (sx * sy)], axis=1)
    keys = _cell_key(cell_index)
    order = np.argsort(keys, kind="stable")
    keys, members = keys[order], ids[small][owner[order]]

    # Each point's cell, for the points inside the grid.
    inside = np.flatnonzero(((points >= origin) & (points <= top)).all(axis=1))
    point_cell = np.minimum(np.floor((points[inside] - origin) / cell).astype(np.int64),
                            GRID_AXIS_CELLS - 1)
    point_keys = _cell_key(point_cell)
    begin = np.searchsorted(keys, point_keys, side="left")
    count = np.searchsorted(keys, point_keys, side="right") - begin
    has = count > 0
    inside, begin, count = inside[has], begin[has], count[has]
    # the pairs in order (point by point, each point's cell list in order), numbered from 0,
    # PAIR_CHUNK at a time: a point whose cell lists more boxes than that spans chunks
    total = np.cumsum(count)
    pairs = int(total[-1]) if total.size else 0
    for start in range(0, pairs, PAIR_CHUNK):
        flat = np.arange(start, min(start + PAIR_CHUNK, pairs))
        owner = np.searchsorted(total, flat, side="right")  # its point, among ``inside``
        pi = inside[owner]
        bk = members[begin[owner] + flat - (total[owner] - count[owner])]
        q = points[pi]  # the cell's boxes, kept where their bounds hold the point
        held = ((q >= lo[bk]) & (q <= hi[bk])).all(axis=1)
        yield pi[held], bk[held]
    yield from _candidate_pairs(lo, hi, ids[~small], points)


def _cell_key(cell_index: np.ndarray) -> np.ndarray:
    """One int64 per cell ``(ix, iy, iz)``, each in ``[0, GRID_AXIS_CELLS)``."""
    return (cell_index[:, 0] + cell_index[:, 1] * GRID_AXIS_CELLS
            + cell_index[:, 2] * (GRID_AXIS_CELLS * GRID_AXIS_CELLS))
