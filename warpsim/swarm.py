"""A swarm of independent spheres: the per-sphere state, validated on the host."""

from __future__ import annotations

import numpy as np

from . import validation as check


class Swarm:
    """Initial state of ``N`` spheres (validated float64 copies, read-only).

    Args:
        position: sphere centres in the world [m], shape (N, 3).
        velocity: linear velocities [m/s], shape (N, 3).
        radius: sphere radii [m], scalar or (N,), each >= 0.
        mass: masses [kg], scalar or (N,), each > 0.
        angular_momentum: about each centre [kg m^2/s], shape (N, 3); None for zero.
        orientation: unit quaternions (x, y, z, w), body -> world, shape (N, 4); None for identity.

    Raises:
        ValueError: naming the field and the index of the first bad entry.
    """

    def __init__(self, position, velocity, radius=0.05, mass=1.0, angular_momentum=None,
                 orientation=None):
        self.position = check.frozen(check.vec3_array("position", position))
        n = self.position.shape[0]
        self.velocity = check.frozen(check.vec3_array("velocity", velocity, n))
        self.radius = check.frozen(check.per_item("radius", radius, n, minimum=0.0))
        self.mass = check.frozen(check.per_item("mass", mass, n, positive=True))
        self.angular_momentum = check.frozen(
            np.zeros((n, 3)) if angular_momentum is None
            else check.vec3_array("angular_momentum", angular_momentum, n))
        self.orientation = check.frozen(check.unit_quat_array(
            "orientation", (0.0, 0.0, 0.0, 1.0) if orientation is None else orientation, n))

    def __len__(self) -> int:
        return self.position.shape[0]

    def __repr__(self) -> str:
        return f"Swarm({len(self)} spheres)"
