"""The broad phase: which boxes a sphere's frame path can reach, and the choice between methods.

Three ways to find a sphere's candidate boxes, all bit-identical to trying every box (each only
skips boxes that the per-box reject of ``kernels.candidates`` (``apart``) would refuse, and ties
go to the lower index):

- ``"brute"``: every box, in index order. Best for a handful of boxes.
- ``"bvh"``: a query of a BVH over the boxes' reject bounds (Warp's ``wp.Bvh``). Best for many
  boxes and fast spheres.
- ``"grid"``: a uniform grid over the scene whose cells list the boxes within ``margin`` of the
  cell. A sphere whose path (grown by its radius) stays within its cell's margin reads that
  short list only; any other falls back to every box, or to the BVH (``"grid-bvh"``). Best when
  a frame's path is short against the scene: the standard room's spheres see one or two boxes
  instead of 22.

:func:`choose` turns ``broad_phase="auto"`` into one of them from a cost model measured on this
package's kernels (see BENCHMARKS.md, "Simulator speed" and its table of cost against the
number of boxes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import validation as check
from .device import BVH_MIN_BOXES, bvh_bounds
from .kernels.candidates import BOUNDS_PAD_ABS, BOUNDS_PAD_REL
from .obstacles import RoundedBoxes

#: The grid's margin is the reach of this share of the spheres' first frame (path length plus
#: radius): the rest, and spheres that speed up later, fall back to the slower method.
REACH_QUANTILE = 0.95

#: Margin over the measured reach: speeds change over a run (gravity, bounces).
REACH_FACTOR = 1.5

#: Most cells a grid may have (its cell table is 4 bytes a cell).
MAX_CELLS = 1 << 21

#: Most (cell, box) entries a grid may hold; beyond it the grid is not built.
MAX_ENTRIES = 1 << 24

#: Cells per axis at most (a finer grid buys nothing once a cell is below the margin).
MAX_CELLS_PER_AXIS = 256

#: Relative pad [of the coordinates] by which the host grows each cell's domain when it lists
#: boxes: ten times the kernels' own pad, so that the kernel's float32 view of a cell is always
#: inside the host's float64 one.
HOST_PAD_REL = 10.0 * BOUNDS_PAD_REL

#: Cost model of ``auto``, in units of one per-box reject test (measured on the CPU, float32,
#: standard room and random boxes; BENCHMARKS.md "Simulator speed"): a query costs ``BRUTE_FIXED +
#: K`` by brute force, ``GRID_FIXED + L`` through a grid cell listing ``L`` boxes (plus the
#: fallback for the paths that do not fit), ``BVH_FIXED + BVH_PER_LEVEL log2 K`` through the
#: BVH.
BRUTE_FIXED = 2.0
GRID_FIXED = 4.0
BVH_FIXED = 12.0
BVH_PER_LEVEL = 3.0


@dataclass
class Grid:
    """A uniform grid over the scene and its cell lists (host arrays, float64 geometry).

    Attributes:
        lower: world position of the grid's lowest corner [m], (3,).
        cell: cell size along each axis [m], (3,).
        dims: cells along each axis, (3,) int.
        margin: how far beyond its cell a path may reach and still use the cell's list [m]; the
            lists are made for it.
        kernel_margin: the margin the kernels test against [m]: ``margin`` less twice the
            rounding pad of the grid's largest coordinate (``BOUNDS_PAD_REL``), so that no
            rounding in the kernel accepts a path the lists were not made for.
        cell_start: CSR offsets, (cells + 1,) int32; cell ``c`` (x fastest) lists
            ``cell_boxes[cell_start[c]:cell_start[c + 1]]``.
        cell_boxes: box indices, ascending within each cell, int32.
    """

    lower: np.ndarray
    cell: np.ndarray
    dims: np.ndarray
    margin: float
    kernel_margin: float
    cell_start: np.ndarray
    cell_boxes: np.ndarray

    @property
    def inv_cell(self) -> np.ndarray:
        """``1 / cell`` [1/m], (3,), as the kernels multiply by it."""
        return 1.0 / self.cell

    @property
    def cells(self) -> int:
        return int(np.prod(self.dims))

    def mean_list_length(self) -> float:
        """Boxes listed per cell, averaged over the cells."""
        return float(len(self.cell_boxes)) / max(self.cells, 1)


def reach(position: np.ndarray, velocity: np.ndarray, radius: np.ndarray, gravity, dt: float,
          ) -> float:
    """How far a typical sphere's first frame reaches [m]: path ``(|v| + |g| dt) dt`` plus the
    radius, at the ``REACH_QUANTILE`` of the swarm, times ``REACH_FACTOR``."""
    if len(position) == 0:
        return 0.0
    speed = np.linalg.norm(velocity, axis=1) + float(np.linalg.norm(gravity)) * dt
    path = speed * dt + radius
    return REACH_FACTOR * float(np.quantile(path, REACH_QUANTILE))


def build_grid(boxes: RoundedBoxes, margin: float, dtype=np.float32) -> Grid | None:
    """The grid over ``boxes`` for paths that reach ``margin`` beyond their cell.

    Args:
        boxes: the obstacles.
        margin: [m], > 0.
        dtype: the kernels' float type: the cell geometry is rounded to it first, so that the
            lists are made for exactly the cells the kernel computes.

    Returns:
        The :class:`Grid`, or None when the scene has no boxes or the grid would exceed
        ``MAX_CELLS`` or ``MAX_ENTRIES``.
    """
    k = len(boxes)
    if k == 0 or not margin > 0.0 or not math.isfinite(margin):
        return None
    center = boxes.center.astype(dtype)
    extent = boxes.world_extent().astype(dtype)
    lo32, hi32 = bvh_bounds(center, extent)  # the reject bounds, rounded outward
    box_lo, box_hi = lo32.astype(np.float64), hi32.astype(np.float64)
    scene_lo, scene_hi = box_lo.min(axis=0) - margin, box_hi.max(axis=0) + margin
    span = scene_hi - scene_lo
    cell = np.maximum(np.full(3, margin), span / MAX_CELLS_PER_AXIS)
    dims = np.maximum(1, np.ceil(span / cell)).astype(np.int64)
    while np.prod(dims) > MAX_CELLS:
        cell *= 1.25
        dims = np.maximum(1, np.ceil(span / cell)).astype(np.int64)
    # the geometry as the kernel holds it
    lower = scene_lo.astype(dtype).astype(np.float64)
    cell = cell.astype(dtype).astype(np.float64)
    margin_k = float(np.asarray(margin, dtype=dtype))
    pad = HOST_PAD_REL * (np.abs(scene_lo) + np.abs(scene_hi) + span) + BOUNDS_PAD_ABS
    grow = margin_k + pad
    # cell c's domain [lower + c h - grow, lower + (c + 1) h + grow] meets [box_lo, box_hi]
    c_min = np.ceil((box_lo - grow - lower) / cell - 1.0).astype(np.int64)
    c_max = np.floor((box_hi + grow - lower) / cell).astype(np.int64)
    c_min = np.clip(c_min, 0, dims - 1)
    c_max = np.clip(c_max, 0, dims - 1)
    counts = np.prod(c_max - c_min + 1, axis=1)
    if int(counts.sum()) > MAX_ENTRIES:
        return None
    largest = float(np.max(np.abs(np.concatenate([lower, lower + dims * cell]))) + margin_k)
    kernel_margin = margin_k - 2.0 * (BOUNDS_PAD_REL * largest + BOUNDS_PAD_ABS)
    if not kernel_margin > 0.0:
        return None
    cells_of = []
    for b in range(k):
        ix = np.arange(c_min[b, 0], c_max[b, 0] + 1)
        iy = np.arange(c_min[b, 1], c_max[b, 1] + 1)
        iz = np.arange(c_min[b, 2], c_max[b, 2] + 1)
        cz, cy, cx = np.meshgrid(iz, iy, ix, indexing="ij")
        cells_of.append((cx + dims[0] * (cy + dims[1] * cz)).ravel())
    cell_ids = np.concatenate(cells_of)
    box_ids = np.repeat(np.arange(k, dtype=np.int64), counts)
    order = np.lexsort((box_ids, cell_ids))  # by cell, then ascending box
    cell_ids, box_ids = cell_ids[order], box_ids[order]
    start = np.zeros(int(np.prod(dims)) + 1, dtype=np.int64)
    np.add.at(start, cell_ids + 1, 1)
    start = np.cumsum(start)
    return Grid(lower=lower, cell=cell, dims=dims.astype(np.int32), margin=margin_k,
                kernel_margin=float(np.asarray(kernel_margin, dtype=dtype)),
                cell_start=start.astype(np.int32), cell_boxes=box_ids.astype(np.int32))


def exhaustive(box_count: int) -> tuple[str, float]:
    """The method that tries every candidate without a grid, and its cost by the model: the BVH
    from ``BVH_MIN_BOXES`` boxes on (where it was measured to win), every box below."""
    if box_count >= BVH_MIN_BOXES:
        return "bvh", BVH_FIXED + BVH_PER_LEVEL * math.log2(box_count)
    return "brute", BRUTE_FIXED + box_count


def choose(requested: str, boxes: RoundedBoxes, reach_m: float, dtype=np.float32,
           ) -> tuple[str, Grid | None]:
    """The broad phase to compile, and its grid when it has one.

    Args:
        requested: ``"auto"``, ``"brute"``, ``"bvh"`` or ``"grid"``. A grid falls back to
            :func:`exhaustive`'s method for the paths that leave their cell's margin (``"grid"``
            over every box, ``"grid-bvh"`` over the BVH); ``"auto"`` takes the grid when the
            cost model puts its mean cell list below the exhaustive method's cost, else that
            method.
        boxes: the obstacles.
        reach_m: how far a frame's path reaches [m] (see :func:`reach`).
        dtype: the kernels' float type.

    Returns:
        ``(name, grid)`` with ``name`` one of ``kernels.data.BROAD_PHASES``.
    """
    choice = check.broad_phase(requested)
    if choice in ("brute", "bvh"):
        return choice, None
    k = len(boxes)
    fallback, fallback_cost = exhaustive(k)
    grid = build_grid(boxes, reach_m, dtype) if k else None
    if grid is None or (choice == "auto"
                        and GRID_FIXED + grid.mean_list_length() >= fallback_cost):
        return fallback, None
    return ("grid-bvh" if fallback == "bvh" else "grid"), grid
