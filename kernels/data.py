"""The scene's device data as Warp structs, and the features record every kernel is built for.

A kernel takes the scene as three ``# Model`` structs, each passed whole from ``@wp.kernel`` to
the ``@wp.func`` that reads it, so no parameter list is written out twice:

- ``Boxes``: the obstacles, struct of arrays, world frame (``K`` boxes);
- ``BroadPhase``: how a sphere finds its candidate boxes (the BVH and the uniform grid);
- ``Physics``: the scene's constants;

and, as an output of a whole launch, ``EventBuffer`` (one row per contact). The host fills
them in ``warpsim.model`` (``put_model``, ``event_buffer``); :func:`model_structs` makes one
set per precision.
"""

from dataclasses import dataclass, replace
from functools import cache
from typing import NamedTuple

import warp as wp

from .precision import Precision

#: The broad phases a kernel can be built with (see ``candidates.candidate_funcs``).
BROAD_PHASES = ("brute", "bvh", "grid", "grid-bvh", "walk", "walk-bvh")

#: Low bits of a walked grid's ``cell_boxes`` entry that say where the box's range of cells
#: starts and ends (``BroadPhase.cell_boxes``): 3 axes, first and last.
WALK_FLAG_BITS = 6

#: The motion models a kernel can be built with.
MOTIONS = ("linear", "ballistic")

PRECISIONS = ("float32", "float64")

#: Frames between energy resets in a run of free frames (``Features.free_reset_every``): the
#: free step keeps the energy to rounding, so the reset there only removes drift, and once in
#: this many frames of a sphere's age (and before a frame that is not free) bounds it while its
#: cost is shared by the run. Free flight against the bare loop (float32, linear, one run):
#: 2.45x at 8, 2.05x at 16, 1.67x at 32, 1.41x at 64: 32 is the smallest period within 2x.
FREE_RESET_EVERY = 32


@dataclass(frozen=True)
class Features:
    """What a kernel variant is built for: the key of every kernel factory's cache.

    A kernel contains the code of the features it is built with and no other (a scene without
    spin runs a kernel without spin code).

    Attributes:
        precision: ``"float32"`` or ``"float64"``.
        motion: ``"linear"`` (the chord per frame) or ``"ballistic"`` (the exact parabola).
        broad_phase: one of ``BROAD_PHASES`` (bit-identical results whichever).
        spin: friction torque on the angular momentum at contacts, and the orientation.
        lossy: ``energy_retention < 1``: the loss at each bounce.
        energy_correction: the frame kernel resets the speed from the energy after the move.
        events: write every contact into the launch's event buffer.
        births: some sphere is born after frame 0: the frame kernel skips each sphere's frames
            before its ``birth_frame`` (no move, no contact, no count).
        free_flight: the frame kernel's free-flight step (a frame whose path lies beyond every
            box's bounds skips the bounce loop, with its move's bits; a run of such frames
            resets the energy once in ``free_reset_every`` frames and before a frame that is not
            free, and tests the bounds once for as many frames as it can prove clear): for
            swarms that fly outside the obstacles' overall bounds; a closed room has no use for
            its test.
        free_reset_every: frames of a sphere's age between energy resets in a run of free
            frames (``FREE_RESET_EVERY``; 1: every frame, the bits of the kernel without the
            step). For tests and measurement; the simulator keeps the default.
        free_horizon: a run of free frames tests the bounds once for the frames up to its next
            reset or record when it can prove them all clear (the same bits as a test every
            frame); False: every frame is tested. For tests and measurement.
        falls: ballistic motion under gravity that is not zero: a frame's free legs query
            along the arc only, without the chord's query that ``g = 0`` takes instead (the
            same bits wherever ``g != 0``; a smaller hot loop). Always False for the linear
            motion.

    ``motion`` and ``broad_phase`` may be any ``str`` (an enumeration of ``str`` included):
    they compare and hash as their text.
    """

    precision: str = "float32"
    motion: str = "linear"
    broad_phase: str = "brute"
    spin: bool = False
    lossy: bool = False
    energy_correction: bool = False
    events: bool = False
    births: bool = False
    free_flight: bool = False
    free_reset_every: int = FREE_RESET_EVERY
    free_horizon: bool = True
    falls: bool = False

    def __post_init__(self):
        for name, allowed in (("precision", PRECISIONS), ("motion", MOTIONS),
                              ("broad_phase", BROAD_PHASES)):
            value = getattr(self, name)
            if not isinstance(value, str) or value not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, got {value!r}")
        for name in ("spin", "lossy", "energy_correction", "events", "births", "free_flight",
                     "free_horizon", "falls"):
            object.__setattr__(self, name, bool(getattr(self, name)))
        if self.motion != "ballistic":  # one linear kernel, not two alike
            object.__setattr__(self, "falls", False)
        every = self.free_reset_every
        if isinstance(every, bool) or int(every) != every or every < 1:
            raise ValueError(f"free_reset_every must be an integer >= 1, got {every!r}")
        object.__setattr__(self, "free_reset_every", int(every))

    def but(self, **changes) -> "Features":
        """This record with some fields changed."""
        return replace(self, **changes)


class ModelStructs(NamedTuple):
    """The struct types of one precision (see :func:`model_structs`)."""

    Boxes: type
    BroadPhase: type
    Physics: type
    EventBuffer: type


@cache
def model_structs(p: Precision) -> ModelStructs:
    """The device structs for one precision: ``Boxes, BroadPhase, Physics, EventBuffer``."""
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33

    @wp.struct
    class Boxes:
        """The obstacles (``K`` rounded boxes), world frame."""

        center: wp.array[vec3]
        """Box centres [m], shape (K,)."""
        rotation: wp.array[mat33]
        """Local -> world rotation matrices, shape (K,)."""
        half_extents: wp.array[vec3]
        """Core half extents [m], local frame, shape (K,)."""
        radius: wp.array[scalar]
        """Rounding radii [m], shape (K,)."""
        extent: wp.array[vec3]
        """Half sizes of each rounded box's world-axis-aligned bounding box [m], shape (K,), for
        the cheap per-box reject."""
        lower: vec3
        """Lowest corner [m] of a world box holding every box's reject bounds (``center -
        extent (1 + REJECT_SLACK)``), rounded outward; without boxes above ``upper`` (empty)."""
        upper: vec3
        """Highest corner [m] of that box: a path whose bounds lie beyond it on one axis meets
        no box (the frame kernel's free-flight step)."""

    @wp.struct
    class BroadPhase:
        """The candidate lookup: a BVH over the boxes' reject bounds and a uniform grid.

        The grid is either the margin grid of ``"grid"`` (a path reads the list of the cell
        holding its chord's midpoint when it stays within ``margin`` of that cell) or the
        walked grid of ``"walk"`` (a path reads the lists of the cells its chord crosses, in
        order; ``reach``, ``scale`` and the per-box cell ranges are its). A kernel built
        without one of them never reads it (a single empty cell, a BVH id 0).
        """

        bvh: wp.uint64
        """Id of a ``warp.Bvh`` over the reject bounds (float32, rounded outward), item ``k``
        box ``k``; the boxes kept out of it (``spanning_start``, ``spanning_count``) hold empty
        bounds there (no query returns them);
        0: none."""
        spanning_start: int
        """Where in ``cell_boxes`` the boxes kept out of the BVH's tree begin: with the BVH as
        the broad phase (``"bvh"``), those whose bounds span most of the scene along two axes
        (``broad_phase.tree_split``), tried before each of its queries; none as a grid's
        fallback. They share the grid's array, after its entries, so that this
        struct, which the frame passes by value, grows by two integers only (an array more made
        the float32 frame copy it with a loop: BENCHMARKS.md, "The BVH without the walls")."""
        spanning_count: int
        """How many boxes are kept out of the tree (0: none)."""
        lower: vec3
        """The grid's lowest corner [m]."""
        cell: vec3
        """Cell size [m] per axis."""
        inv_cell: vec3
        """``1 / cell`` [1/m]."""
        dims: wp.vec3i
        """Cells per axis."""
        margin: scalar
        """The margin [m] a path may leave its cell by (``broad_phase.Grid.kernel_margin``)."""
        cell_start: wp.array[wp.int32]
        """CSR offsets into ``cell_boxes``, shape (cells + 1,); cell index x fastest."""
        cell_boxes: wp.array[wp.int32]
        """Box indices of each cell, ascending within a cell. Walk: each entry is
        ``box << WALK_FLAG_BITS | flags``: bit ``i`` set when the cell is the first along axis
        ``i`` of the box's range of cells, bit ``3 + i`` when it is the last (``broad_phase.
        WalkGrid.entries``). Then a placeholder entry, then, from ``spanning_start``, the
        boxes kept out of the BVH's tree (plain box indices)."""
        reach: scalar
        """Walk: the largest growth per axis [m] (sphere radius plus the arc's sagitta) of a
        path the lists were made for (``broad_phase.WalkGrid.reach``)."""
        scale: scalar
        """Walk: the largest coordinate [m] (any axis) a walked path's ends may have; the lists'
        rounding pad is sized for it."""
        entry_bounds: wp.array[vec3]
        """Walk: per entry ``j`` of ``cell_boxes``, its box's centre at ``2 j`` and world
        bounding-box half size at ``2 j + 1`` [m] (``Boxes.center``, ``Boxes.extent``), so the
        reject reads a cell's entries in order, shape (2 entries,)."""

    @wp.struct
    class Physics:
        """The scene's constants."""

        gravity: vec3
        """[m/s^2], world frame."""
        origin: vec3
        """Reference point of the potential energy [m]."""
        dt: scalar
        """Frame duration [s]."""
        friction: scalar
        """``k_f`` [kg/s]."""
        max_rot: scalar
        """Clamp on ``|Rot|`` [rad/s]."""
        retention: scalar
        """Fraction of the kinetic energy kept at each bounce."""
        max_bounces: int
        """Cap on contacts per sphere per frame (a launch value, not compiled in)."""

    @wp.struct
    class EventBuffer:
        """One row per contact of a launch (``C`` rows of room); rows past ``C`` are counted,
        never written."""

        count: wp.array[wp.int32]
        """``count[0]``: contacts of the launch, written or not, shape (1,)."""
        index: wp.array2d[wp.int32]
        """``(frame within the launch from 1, sphere, box, resting)``, shape (C, 4)."""
        vector: wp.array2d[vec3]
        """``(contact centre [m], unit normal)``, shape (C, 2)."""
        value: wp.array2d[scalar]
        """``(fraction of the frame, normal speed before the contact [m/s])``, shape (C, 2)."""

    return ModelStructs(Boxes, BroadPhase, Physics, EventBuffer)
