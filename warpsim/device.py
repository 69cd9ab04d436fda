"""The host -> device boundary: validated numpy data becomes Warp arrays of one precision."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from .kernels.precision import Precision, precision
from .obstacles import RoundedBoxes


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
    """

    center: wp.array
    rotation: wp.array
    half_extents: wp.array
    radius: wp.array
    extent: wp.array

    @classmethod
    def upload(cls, boxes: RoundedBoxes, p: Precision, device) -> DeviceBoxes:
        dt = p.np_dtype
        return cls(
            center=wp.array(boxes.center.astype(dt), dtype=p.vec3, device=device),
            rotation=wp.array(boxes.rotation_matrices().astype(dt), dtype=p.mat33, device=device),
            half_extents=wp.array(boxes.half_extents.astype(dt), dtype=p.vec3, device=device),
            radius=wp.array(boxes.radius.astype(dt), dtype=p.scalar, device=device),
            extent=wp.array(boxes.world_extent().astype(dt), dtype=p.vec3, device=device),
        )

    def inputs(self) -> list:
        return [self.center, self.rotation, self.half_extents, self.radius, self.extent]


def to_device(values: np.ndarray, dtype, p: Precision, device) -> wp.array:
    """A Warp array of ``dtype`` from float64 host values, cast to the precision's numpy type."""
    return wp.array(np.ascontiguousarray(values, dtype=p.np_dtype), dtype=dtype, device=device)


__all__ = ["DeviceBoxes", "precision", "resolve_device", "to_device"]
