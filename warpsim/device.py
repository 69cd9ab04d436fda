"""The host -> device boundary: validated numpy data becomes Warp arrays of one precision."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from . import validation as check
from .kernels.nearest import BOUNDS_PAD_REL, REJECT_SLACK
from .kernels.precision import Precision, precision
from .obstacles import RoundedBoxes

#: ``broad_phase="auto"`` uses the BVH from this many boxes on (else the loop over all boxes).
#: Measured on the CPU (float32, 1e4 spheres at 5 and 60 m/s): in the standard room with its
#: plates made more numerous, the two tie at K = 28 and the BVH wins from K = 32 (1.1-1.2x,
#: 1.6-1.8x at K = 64); in the random-box sweep scene it wins from K = 12 already.
BVH_MIN_BOXES = 32


def resolve_device(device=None) -> wp.context.Device:
    """The Warp device for ``device`` (None: Warp's default, ``cuda:0`` when present)."""
    wp.init()
    try:
        return wp.get_device(device)
    except (RuntimeError, ValueError) as exc:
        raise ValueError(f"device {device!r} is not available: {exc}") from exc


@dataclass
class DeviceBoxes:
    """Obstacles on a device, struct of arrays (the kernels' ``# Model`` data).

    Attributes:
        center: box centres [m], world frame, shape (K,).
        rotation: local -> world rotation matrices, shape (K,).
        half_extents: core half extents [m], local frame, shape (K,).
        radius: rounding radii [m], shape (K,).
        extent: half sizes of the boxes' world-axis-aligned bounding boxes [m], shape (K,),
            for the cheap reject.
        bvh: BVH over the boxes' reject bounds (world frame, float32), or None: not built, or
            no boxes. Owned here so that it lives as long as the arrays.
    """

    center: wp.array
    rotation: wp.array
    half_extents: wp.array
    radius: wp.array
    extent: wp.array
    bvh: wp.Bvh | None = None

    @classmethod
    def upload(cls, boxes: RoundedBoxes, p: Precision, device, bvh: bool = False) -> DeviceBoxes:
        """The boxes as arrays of precision ``p`` on ``device``, with a BVH over them when
        ``bvh`` (and there is at least one box)."""
        dt = p.np_dtype
        center = boxes.center.astype(dt)
        extent = boxes.world_extent().astype(dt)
        tree = None
        if bvh and len(boxes):
            lower, upper = bvh_bounds(center, extent)
            # SAH on every device: the best trees for queries, and its builder caps the depth
            # at the query stack's size (a static scene builds it once)
            tree = wp.Bvh(wp.array(lower, dtype=wp.vec3f, device=device),
                          wp.array(upper, dtype=wp.vec3f, device=device), constructor="sah")
        return cls(
            center=wp.array(center, dtype=p.vec3, device=device),
            rotation=wp.array(boxes.rotation_matrices().astype(dt), dtype=p.mat33, device=device),
            half_extents=wp.array(boxes.half_extents.astype(dt), dtype=p.vec3, device=device),
            radius=wp.array(boxes.radius.astype(dt), dtype=p.scalar, device=device),
            extent=wp.array(extent, dtype=p.vec3, device=device),
            bvh=tree,
        )

    def inputs(self) -> list:
        """The kernels' ``# Model`` box arguments: the five arrays, then the BVH id (0: none)."""
        return [self.center, self.rotation, self.half_extents, self.radius, self.extent,
                wp.uint64(self.bvh.id if self.bvh is not None else 0)]


def bvh_bounds(center: np.ndarray, extent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float32 BVH bounds [m], world frame, (K, 3) each, that contain the per-box reject's.

    The reject (``kernels.nearest.sweep_box_world``) lets a box through when the segment comes
    within ``extent (1 + REJECT_SLACK)`` of its centre (plus the sphere's part); these bounds
    hold that box, padded by ``BOUNDS_PAD_REL`` of the coordinates for the reject's rounding,
    and rounded outward to float32.

    Args:
        center: box centres [m] as the kernels hold them, (K, 3).
        extent: world bounding-box half sizes [m] as the kernels hold them, (K, 3).
    """
    c = center.astype(np.float64)
    e = extent.astype(np.float64) * (1.0 + REJECT_SLACK)
    pad = BOUNDS_PAD_REL * (np.abs(c) + e)
    lower, upper = c - e - pad, c + e + pad
    lower32, upper32 = lower.astype(np.float32), upper.astype(np.float32)
    lower32 = np.where(lower32 > lower, np.nextafter(lower32, np.float32(-np.inf)), lower32)
    upper32 = np.where(upper32 < upper, np.nextafter(upper32, np.float32(np.inf)), upper32)
    return lower32, upper32


def use_bvh(broad_phase: str, box_count: int) -> bool:
    """Whether a scene of ``box_count`` boxes runs the BVH broad phase.

    Args:
        broad_phase: ``"bvh"``, ``"brute"`` (every box tried per sphere), or ``"auto"`` (the BVH
            from ``BVH_MIN_BOXES`` boxes on).

    Raises:
        ValueError: ``broad_phase`` is none of these.
    """
    choice = check.broad_phase(broad_phase)
    return choice == "bvh" or (choice == "auto" and box_count >= BVH_MIN_BOXES)


def to_device(values: np.ndarray, dtype, p: Precision, device) -> wp.array:
    """A Warp array of ``dtype`` from float64 host values, cast to the precision's numpy type."""
    return wp.array(np.ascontiguousarray(values, dtype=p.np_dtype), dtype=dtype, device=device)


__all__ = ["BVH_MIN_BOXES", "DeviceBoxes", "bvh_bounds", "precision", "resolve_device",
           "to_device", "use_bvh"]
