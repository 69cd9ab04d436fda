"""Batched single-frame sphere sweeps (sheet methods 1 and 2): numpy in, numpy out."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from . import validation as check
from .device import DeviceBoxes, precision, resolve_device, to_device
from .kernels.collide_kernels import collide_kernel
from .obstacles import RoundedBox, RoundedBoxes


@dataclass
class Contacts:
    """First contact of each sphere during one frame (numpy arrays of the chosen precision).

    The centre of sphere ``i`` would move from ``A`` to ``B = A + v dt``.

    Attributes:
        hit: whether the sphere touches an obstacle on the way, (N,) bool.
        t: fraction of ``A -> B`` at first contact, in [0, 1]; 1 without contact, (N,).
        position: centre at first contact ``A + t (B - A)`` [m]; ``B`` without contact, (N, 3).
        normal: unit outward normal of the obstacle at the contact; 0 without contact, (N, 3).
        new_position: centre after the reflected rest of the path, ``(1 - t)|B - A|`` along the
            reflected velocity [m]; ``B`` without contact, (N, 3).
        new_velocity: reflected velocity ``v - 2 (v . n) n`` [m/s]; ``v`` without contact, (N, 3).
        box: index of the obstacle hit (ties: the lower index); -1 without contact, (N,) int32.
    """

    hit: np.ndarray
    t: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    new_position: np.ndarray
    new_velocity: np.ndarray
    box: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])


def collide_boxes(position, velocity, radius, boxes: RoundedBoxes | RoundedBox, dt: float, *,
                  device=None, precision: str = "float32") -> Contacts:
    """First contact of each moving sphere with a group of static rounded boxes.

    Every sphere moves in a straight line for ``dt``; the first contact over all boxes is kept
    (ties: the lower box index). A contact counts only when the sphere moves into the surface;
    a sphere starting in contact and moving in is hit at ``t = 0``. Inputs are never modified.

    Args:
        position: sphere centres at the start of the frame [m], world frame, (N, 3).
        velocity: sphere velocities [m/s], (N, 3).
        radius: sphere radii [m], scalar or (N,), each >= 0.
        boxes: the obstacles.
        dt: frame duration [s], > 0.
        device: Warp device (``"cpu"``, ``"cuda:0"``; None for Warp's default).
        precision: ``"float32"`` or ``"float64"`` kernels.

    Returns:
        :class:`Contacts`, arrays of the chosen precision.

    Raises:
        ValueError: a bad input, naming the field and the index.
    """
    if isinstance(boxes, RoundedBox):
        boxes = boxes.as_boxes()
    if not isinstance(boxes, RoundedBoxes):
        raise ValueError(f"boxes must be a RoundedBoxes or RoundedBox, got {type(boxes).__name__}")
    pos = check.vec3_array("position", position)
    n = pos.shape[0]
    vel = check.vec3_array("velocity", velocity, n)
    rad = check.per_item("radius", radius, n, minimum=0.0)
    dt = check.scalar("dt", dt, positive=True)
    p = precision_of(precision)
    dev = resolve_device(device)

    model = DeviceBoxes.upload(boxes, p, dev)
    out_box = wp.empty(n, dtype=wp.int32, device=dev)
    outs = [wp.empty(n, dtype=p.scalar, device=dev)] + [
        wp.empty(n, dtype=p.vec3, device=dev) for _ in range(4)]
    wp.launch(collide_kernel(p.name), dim=n, device=dev,
              inputs=model.inputs() + [p.scalar(dt),
                                       to_device(pos, p.vec3, p, dev),
                                       to_device(vel, p.vec3, p, dev),
                                       to_device(rad, p.scalar, p, dev)],
              outputs=[out_box] + outs)
    box = out_box.numpy()
    t, contact, normal, new_pos, new_vel = (o.numpy() for o in outs)
    return Contacts(hit=box >= 0, t=t, position=contact, normal=normal, new_position=new_pos,
                    new_velocity=new_vel, box=box)


def collide_box(position, velocity, radius, box: RoundedBox, dt: float, *, device=None,
                precision: str = "float32") -> Contacts:
    """First contact of each moving sphere with one static rounded box (sheet method 1).

    The same contract as :func:`collide_boxes` with a group of one (``box`` is 0 or -1).
    """
    if not isinstance(box, RoundedBox):
        raise ValueError(f"box must be a warpsim.RoundedBox, got {type(box).__name__}")
    return collide_boxes(position, velocity, radius, box.as_boxes(), dt, device=device,
                         precision=precision)


def precision_of(name: str):
    return precision(check.precision(name))
