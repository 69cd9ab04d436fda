"""A swarm of independent spheres: the per-sphere state, validated on the host."""

from __future__ import annotations

import numpy as np

from . import validation as check
from .blocks import any_rows, digest


class Swarm:
    """Initial state of ``N`` spheres (validated float64 copies, read-only).

    Births: a sphere with ``birth_frame = b`` does not exist before frame ``b`` (it is not
    simulated, has no contacts, counts in no statistics and is not drawn). Its ``position``,
    ``velocity``, ``angular_momentum`` and ``orientation`` here are its state *at* frame ``b``
    (time ``b dt``, recorded as frame ``b``), and the step from frame ``b`` to ``b + 1`` is its
    first: from then on it moves bit for bit as the only sphere of a run started with that state
    would, its frame ``k`` being frame ``b + k`` here. A birth after a run's last frame is
    allowed: that sphere simply never appears.

    Args:
        position: sphere centres in the world [m], shape (N, 3).
        velocity: linear velocities [m/s], shape (N, 3).
        radius: sphere radii [m], scalar or (N,), each >= 0.
        mass: masses [kg], scalar or (N,), each > 0.
        angular_momentum: about each centre [kg m^2/s], shape (N, 3); None for zero.
        orientation: unit quaternions (x, y, z, w), body -> world, shape (N, 4); None for identity.
        birth_frame: the frame each sphere appears at, an integer or (N,) integers, each in
            ``[0, 2**31)``; 0 (every sphere there from the start) by default.

    Raises:
        ValueError: naming the field and the index of the first bad entry.
    """

    def __init__(self, position, velocity, radius=0.05, mass=1.0, angular_momentum=None,
                 orientation=None, birth_frame=0):
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
        self.birth_frame = check.frozen(check.frame_array("birth_frame", birth_frame, n))
        self._clear_of = None  # a placement's digest: see _known_clear_of

    def _mark_clear_of(self, boxes) -> None:
        """Record that every sphere was placed outside ``boxes`` (a
        :class:`warpsim.RoundedBoxes`): its signed distance to each box at least its radius,
        by the distances ``feasibility.check_outside`` reads (an emitter's placement, or a
        join of such swarms), so that check could never refuse one."""
        self._clear_of = _placement_digest(self, boxes)

    def _known_clear_of(self, boxes) -> bool:
        """Whether :meth:`_mark_clear_of` recorded the spheres and boxes as they are now: the
        digest of the spheres' centres and radii and of the boxes' arrays
        (:func:`blocks.digest`), so that any change since (an array replaced, or written
        after being made writable again; other boxes) is checked again. Equal boxes in
        another object are the same obstacles."""
        return self._clear_of is not None and self._clear_of == _placement_digest(self, boxes)

    @property
    def has_births(self) -> bool:
        """Whether some sphere is born after frame 0."""
        return any_rows(len(self), lambda rows: self.birth_frame[rows] > 0)

    def __len__(self) -> int:
        return self.position.shape[0]

    def __repr__(self) -> str:
        return f"Swarm({len(self)} spheres)"


#: The arrays a swarm holds, by its constructor's argument names.
FIELDS = ("position", "velocity", "radius", "mass", "angular_momentum", "orientation",
          "birth_frame")


def joined_swarms(swarms: list[Swarm]) -> Swarm:
    """The swarms one after the other, in one swarm (not marked clear of any boxes: see
    :meth:`Swarm._mark_clear_of`)."""
    if len(swarms) == 1:
        return swarms[0]
    return Swarm(**{name: np.concatenate([getattr(s, name) for s in swarms])
                    for name in FIELDS})


def _placement_digest(swarm: Swarm, boxes) -> bytes:
    """The digest of what whether a sphere starts inside a box depends on: the spheres'
    centres and radii, the boxes' centres, half extents, rotations and radii."""
    return digest(swarm.position, swarm.radius, boxes.center, boxes.half_extents,
                  boxes.rotation, boxes.radius)
