"""Devices and the broad-phase choice: which Warp device, whether to build a BVH, its bounds."""

from __future__ import annotations

import numpy as np
import warp as wp

from .kernels.candidates import BOUNDS_PAD_REL, REJECT_SLACK

#: Without a grid, the BVH is used from this many boxes on in float32, every box below
#: (``warpsim.broad_phase.exhaustive``: the fallback of the grid, and ``"auto"``'s choice when
#: the grid does not pay).
#: Measured on the CPU (float32, 1e4 spheres at 5 and 60 m/s): in the standard room with its
#: plates made more numerous, the two tie at K = 28 and the BVH wins from K = 32 (1.1-1.2x,
#: 1.6-1.8x at K = 64); in the random-box sweep scene it wins from K = 12 already. Measured
#: again since the BVH keeps a room's walls out of its tree (2e4 spheres, 240 frames, family
#: 26 CPU; ``benchmarks.bvh_crossover``): at K = 32 the BVH takes 0.73 to 0.76x brute force's
#: time at 5 m/s and 0.97 to 1.02x at 60 m/s, at K = 28 0.76 to 1.06x.
BVH_MIN_BOXES = 32

#: The same in float64 (BENCHMARKS.md, "float64: brute force's loop in registers"): in the
#: same grown rooms, both motions at 5 and 60 m/s, the BVH takes 0.83 to 1.20x brute force's
#: time at K = 16 (1.05x on average over the four cases) and 0.66 to 1.02x at K = 22 (0.87x):
#: they tie near 20 boxes, where float32's tie near 28.
BVH_MIN_BOXES_FLOAT64 = 20


def bvh_min_boxes(dtype=np.float32) -> int:
    """Boxes from which the BVH replaces brute force for kernels of float type ``dtype``
    (``BVH_MIN_BOXES``, ``BVH_MIN_BOXES_FLOAT64``)."""
    return BVH_MIN_BOXES_FLOAT64 if np.dtype(dtype) == np.float64 else BVH_MIN_BOXES


def resolve_device(device=None) -> wp.context.Device:
    """The Warp device for ``device`` (None: Warp's default, ``cuda:0`` when present)."""
    wp.init()
    try:
        return wp.get_device(device)
    except (RuntimeError, ValueError) as exc:
        raise ValueError(f"device {device!r} is not available: {exc}") from exc


def bvh_bounds(center: np.ndarray, extent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float32 BVH bounds [m], world frame, (K, 3) each, that contain the per-box reject's.

    The reject (``kernels.candidates``' ``apart``) lets a box through when the segment comes
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


__all__ = ["BVH_MIN_BOXES", "BVH_MIN_BOXES_FLOAT64", "bvh_bounds", "bvh_min_boxes",
           "resolve_device"]
