"""The closed sets of warpsim, each named once: the motion models, the broad phases a user may
ask for, and the kinds of contact the event tables record.

The string enums compare equal to their values (``Motion.LINEAR == "linear"``), so a user may
pass either; :mod:`warpsim.validation` turns what was given into a member or refuses it in one
line. This module imports nothing from warpsim.
"""

from __future__ import annotations

from enum import IntEnum, StrEnum


class Motion(StrEnum):
    """The path of a sphere within one frame."""

    LINEAR = "linear"
    """The chord from the frame's start to its end (semi-implicit Euler, contacts on it)."""
    BALLISTIC = "ballistic"
    """The exact parabola under gravity (contacts on the arc)."""


class BroadPhase(StrEnum):
    """How each sphere finds its candidate boxes; every choice gives the same bits."""

    AUTO = "auto"
    """One of the others, chosen from a cost model (:func:`warpsim.broad_phase.choose`)."""
    BRUTE = "brute"
    """Every box."""
    BVH = "bvh"
    """A bounding-volume hierarchy of the boxes."""
    GRID = "grid"
    """A uniform grid of the boxes: the list of the cell holding the path's midpoint, for paths
    that stay near that cell (falling back to the BVH or every box for the others)."""
    WALK = "walk"
    """A uniform grid walked along each path: the lists of the cells the path crosses, in
    order, up to the first contact (its cost follows the path, not the speed)."""


class ContactKind(IntEnum):
    """What a contact of an event table is. The values are those the kernels write in the
    event buffer's ``resting`` column (0 for a bounce, 1 for a resting contact)."""

    BOUNCE = 0
    """A reflection (elastic, or lossy with ``energy_retention < 1``)."""
    SUPPORT = 1
    """A resting or sliding contact: the sphere is supported by the surface, not reflected."""


__all__ = ["BroadPhase", "ContactKind", "Motion"]
