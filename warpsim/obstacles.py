"""Static obstacles: oriented rounded boxes, validated on the host.

A rounded box is the set of points within ``radius`` of the core box ``[-h, h]`` (local frame),
placed in the world by ``rotation`` (quaternion ``(x, y, z, w)``, local -> world) and ``center``.
A plain box has ``radius = 0``. Zero half extents are legal: plates, sticks and points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import validation as check

IDENTITY_QUAT = (0.0, 0.0, 0.0, 1.0)


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
        object.__setattr__(self, "center", check.frozen(check.vec3("center", center)))
        object.__setattr__(self, "half_extents", check.frozen(
            check.nonnegative_vec3("half_extents", half_extents)))
        object.__setattr__(self, "rotation", check.frozen(check.unit_quat("rotation", rotation)))
        object.__setattr__(self, "radius", check.scalar("radius", radius, minimum=0.0))

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
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        local = np.einsum("kji,pkj->pki", self.rotation_matrices(),
                          p[:, None, :] - self.center[None, :, :])
        q = np.abs(local) - self.half_extents[None]
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=2)
        inside = np.minimum(q.max(axis=2), 0.0)
        return outside + inside - self.radius[None]
