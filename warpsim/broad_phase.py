"""The broad phase: which boxes a sphere's frame path can reach, and the choice between methods.

Four ways to find a sphere's candidate boxes, all bit-identical to trying every box (ties go to
the lower index, and each skips only boxes the path cannot hit before the first contact):

- ``"brute"``: every box, in index order. Best for a handful of boxes.
- ``"bvh"``: a query of a BVH over the boxes' reject bounds (Warp's ``wp.Bvh``), the boxes
  that span the scene (a room's walls) kept out of its tree and tried before each query
  (:func:`tree_split`). Best for many boxes and fast spheres.
- ``"grid"``: a uniform grid over the scene whose cells list the boxes within ``margin`` of the
  cell. A sphere whose path (grown by its radius) stays within the margin of the cell holding
  the path's midpoint reads that short list only (a path fits when half its extent plus the
  radius is within the margin, so the margin follows half a frame's path: :func:`reach`); any
  other falls back to every box, or to the BVH (``"grid-bvh"``). Best when a frame's path is
  short against the scene: the standard room's spheres see one or two boxes instead of 22.
  Its cells are at least the margin wide, larger where a table of ``CACHE_CELLS`` cells (one
  that stays in cache) costs less than a finer one (:func:`margin_grid`).
- ``"walk"``: a uniform grid whose cells list the boxes within the spheres' radius (plus the
  arc's sagitta) of the cell; a path reads the lists of the cells its chord crosses, in order
  (3D-DDA), tries each box once, and stops at the first cell beyond the nearest contact found.
  Its work follows the path's length in cells, not the speed's share of the scene: fast spheres
  cost little more than slow ones. A path its lists were not made for (a sphere larger than
  the lists' reach, ends far outside the grid) falls back to every box, or to the BVH
  (``"walk-bvh"``).

:func:`choose` turns ``broad_phase="auto"`` into one of them from a cost model measured on this
package's kernels (see BENCHMARKS.md, "Simulator speed" and "The walked grid"): the cheapest of
:func:`estimates`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import validation as check
from .blocks import for_row_blocks
from .device import BVH_MIN_BOXES_FLOAT64, bvh_bounds, bvh_min_boxes
from .energy import lowest_potential
from .kernels.candidates import BOUNDS_PAD_ABS, BOUNDS_PAD_REL, REJECT_SLACK, WALK_PAD_ULPS
from .kernels.data import WALK_FLAG_BITS
from .obstacles import RoundedBoxes

#: The grid's margin is the reach of this share of the spheres' frames (half the path plus the
#: radius, at the speed a sphere can reach: see :func:`reach`): the rest fall back to the slower
#: method.
REACH_QUANTILE = 0.95

#: Margin over the measured reach: collisions turn speed between the axes and bounces turn it
#: upward (a path's extent on one axis is at most its length, which the reach already bounds).
REACH_FACTOR = 1.25

#: A box whose reject bounds span more than this share of the scene's bounds along two axes
#: (a room's floor, ceiling and walls) is kept out of the BVH's tree and tried before each
#: query (:func:`tree_split`).
SPANNING_SHARE = 0.5

#: The most boxes kept out of the tree so (the widest first); the rest stay in it.
SPANNING_MAX = 16

#: Spheres (evenly spaced in the swarm) whose first frame the margin grid's cost is measured on.
COST_SAMPLE = 4096

#: Most cells a grid may have (its cell table is 4 bytes a cell).
MAX_CELLS = 1 << 21

#: Cells of a margin grid whose table (4 bytes a cell) stays in a core's cache: a finer grid
#: pays ``TABLE_PENALTY`` per doubling of its table beyond it, per query, in the cost model (a
#: lookup that misses the cache, the further the larger the table), so ``auto`` and ``"grid"``
#: take the grid of larger cells this many fit unless its lists cost more than that (measured
#: on the CPU: the grown rooms of 262 and 4096 boxes at 5 m/s ran 1.8 to 2 times faster with
#: 20 000 to 27 000 cells than with 0.7 to 2 million, 16 384 boxes 1.15 times at 5 m/s and
#: 1.7 times at 60 m/s, the standard room 3 to 12 % faster with 31 000 than 117 000;
#: BENCHMARKS.md "Fast spheres").
CACHE_CELLS = 1 << 15
TABLE_PENALTY = 2.0

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

#: The BVH's fixed cost in float64, where a box's reject costs more against the BVH's
#: traversal than in float32: set so that the model's BVH ties brute force at
#: ``BVH_MIN_BOXES_FLOAT64`` boxes, where they were measured to tie (BENCHMARKS.md, "float64:
#: brute force's loop in registers").
BVH_FIXED_FLOAT64 = (BRUTE_FIXED + BVH_MIN_BOXES_FLOAT64
                     - BVH_PER_LEVEL * math.log2(BVH_MIN_BOXES_FLOAT64))

#: What building the grids ``auto`` compares costs on the host, in the cost model's unit: a
#: launch of fewer queries than this over the exhaustive method's cost per query takes that
#: method without building them. Measured on the CPU (float32, one frame of the standard room
#: from its emitter through ``collide_boxes``): the grids build in about 12 ms and a query by
#: brute force costs about 6 ns a unit, so brute force was faster up to about 250 000 spheres
#: (0.8 against 13 ms for 10 spheres, 20 against 23 ms for 100 000, 47 against 43 ms for
#: 300 000); 2e6 units is 83 000 such queries. Larger scenes take longer to grid, so the
#: threshold errs towards the exhaustive method there too.
GRID_BUILD = 2.0e6

#: The walk's part of the cost model (same unit): ``WALK_FIXED`` per query (the clip to the grid
#: and the first cell's faces), then per cell crossed ``WALK_PER_CELL`` (the step) plus its list
#: (``WALK_PER_ENTRY`` an entry: the first cell's entries are tested, later ones mostly skipped
#: as tried already, at a fraction of a test). Fitted on the CPU, float32, to the standard room
#: at 5 and 60 m/s, thin-walls and 600 m/s among 256 plates, cell sizes 0.3 to 2.4 m
#: (BENCHMARKS.md, "The walked grid"): a cell crossed costs about two rejects, so the model
#: prefers cells a few times the mean path.
WALK_FIXED = 4.0
WALK_PER_CELL = 2.0
WALK_PER_ENTRY = 0.5

#: A walked path's ends may lie this many of the grid's spans from it (``WalkGrid.scale``);
#: paths reaching farther fall back (their exact sweeps round on a larger scale than the pad).
WALK_SPANS = 4.0

#: Headroom on the walk's reach over the largest sphere radius plus sagitta, so that the kernel's
#: own rounding of a path's growth never sends the largest sphere to the fallback.
WALK_REACH_HEADROOM = 1.0e-3

#: Most bytes the walked grid may take on the device (cell offsets 4 bytes a cell; an entry's
#: box index 4 bytes and its box's bounds six floats): a cell size that needs more is not taken,
#: and where none fits the walk is not built.
MAX_WALK_BYTES = 1 << 26

#: Cell sizes the walk's cost model tries: from the finest allowed on from the span per
#: ``MAX_CELLS_PER_AXIS``, each this much larger than the last, up to one cell.
WALK_CELL_RATIO = 1.25


class CellLists:
    """What both grids share: the cell geometry (``lower``, ``cell``, ``dims``) and the CSR cell
    lists (``cell_start``, ``cell_boxes``), as dataclass fields of the grid."""

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

    def list_lengths(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For each point [m], (S, 3): whether it lies in the grid, and the boxes listed in the
        cell holding it (0 outside), (S,) each."""
        c = np.floor((np.asarray(points) - self.lower) / self.cell).astype(np.int64)
        inside = np.all((c >= 0) & (c < self.dims), axis=1)
        c = np.where(inside[:, None], c, 0)
        cell = c[:, 0] + self.dims[0] * (c[:, 1] + self.dims[1] * c[:, 2])
        return inside, np.where(inside, self.cell_start[cell + 1] - self.cell_start[cell], 0)


@dataclass
class Grid(CellLists):
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



def reach(position: np.ndarray, velocity: np.ndarray, radius: np.ndarray, gravity, dt: float,
          lowest: float | None = None) -> float:
    """The margin grid's margin [m]: how far beyond the cell of its midpoint a typical sphere's
    frame path reaches.

    A path's query box (its chord's bounding box grown by the radius) lies within ``|d_i| / 2 +
    r`` of its midpoint along each axis, so it fits the cell of its midpoint grown by that
    much. The chord is at most ``(|v| + |g| dt) dt`` long, with ``|v|`` the highest speed the
    sphere can reach: energy bounds its square by ``|v0|^2 + 2 (-g . x0 - lowest)``, with
    ``lowest`` [J/kg] the lowest potential per unit mass of the scene's region
    (``energy.lowest_potential``, origin 0; None: the start speed), which is what a slow sphere
    falling to the floor gains. The margin is that half path plus the radius at the
    ``REACH_QUANTILE`` of the swarm, times ``REACH_FACTOR``."""
    if len(position) == 0:
        return 0.0
    g = np.asarray(gravity, dtype=np.float64)
    g_len = float(np.linalg.norm(g))
    position = np.asarray(position, dtype=np.float64)
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), position.shape[:1])
    extent = np.empty(position.shape[0])  # half path plus radius, per sphere

    def block(rows: slice) -> None:  # a row's value is its own: blocks on every core
        speed2 = np.einsum("ij,ij->i", velocity[rows], velocity[rows]).astype(np.float64)
        if lowest is not None:
            fall = -(position[rows] @ g) - lowest
            speed2 = speed2 + 2.0 * np.maximum(fall, 0.0)
        extent[rows] = 0.5 * (np.sqrt(speed2) + g_len * dt) * dt + radius[rows]

    for_row_blocks(position.shape[0], block)
    return REACH_FACTOR * float(np.quantile(extent, REACH_QUANTILE))


def build_grid(boxes: RoundedBoxes, margin: float, dtype=np.float32,
               max_cells: int = MAX_CELLS) -> Grid | None:
    """The grid over ``boxes`` for paths that reach ``margin`` beyond their cell.

    Args:
        boxes: the obstacles.
        margin: [m], > 0.
        dtype: the kernels' float type: the cell geometry is rounded to it first, so that the
            lists are made for exactly the cells the kernel computes.
        max_cells: the most cells (the cells, at least ``margin`` wide, grow by 1.25 until
            they fit).

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
    while np.prod(dims) > min(max_cells, MAX_CELLS):
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
    start, box_ids = cell_lists(c_min, c_max, dims)
    return Grid(lower=lower, cell=cell, dims=dims.astype(np.int32), margin=margin_k,
                kernel_margin=float(np.asarray(kernel_margin, dtype=dtype)),
                cell_start=start, cell_boxes=box_ids)


def cell_lists(c_min: np.ndarray, c_max: np.ndarray, dims: np.ndarray,
               ) -> tuple[np.ndarray, np.ndarray]:
    """The CSR cell lists of boxes listed in the cell ranges ``c_min[b]`` to ``c_max[b]``
    (inclusive, per axis, (K, 3) each) of a grid of ``dims`` cells.

    Returns:
        ``(cell_start, cell_boxes)``, int32: cell ``c`` (x fastest) lists
        ``cell_boxes[cell_start[c]:cell_start[c + 1]]``, ascending.
    """
    counts = np.prod(c_max - c_min + 1, axis=1)
    cells_of = []
    for b in range(len(c_min)):
        ix = np.arange(c_min[b, 0], c_max[b, 0] + 1)
        iy = np.arange(c_min[b, 1], c_max[b, 1] + 1)
        iz = np.arange(c_min[b, 2], c_max[b, 2] + 1)
        cz, cy, cx = np.meshgrid(iz, iy, ix, indexing="ij")
        cells_of.append((cx + dims[0] * (cy + dims[1] * cz)).ravel())
    cell_ids = np.concatenate(cells_of)
    box_ids = np.repeat(np.arange(len(c_min), dtype=np.int64), counts)
    order = np.lexsort((box_ids, cell_ids))  # by cell, then ascending box
    cell_ids, box_ids = cell_ids[order], box_ids[order]
    start = np.zeros(int(np.prod(dims)) + 1, dtype=np.int64)
    np.add.at(start, cell_ids + 1, 1)
    return np.cumsum(start).astype(np.int32), box_ids.astype(np.int32)


@dataclass
class Paths:
    """What the broad phases are sized for: a summary of the spheres' first frame.

    Attributes:
        margin: the margin grid's reach [m] (:func:`reach`).
        reach: the walk's reach [m]: the largest sphere radius plus the sagitta of a frame's
            arc (``|g| dt^2 / 8``), with ``WALK_REACH_HEADROOM``.
        mean_path: the mean of ``|d_i|`` over the swarm per world axis [m], (3,): a frame's
            chord (``(|v| + |g| dt) dt`` along the velocity), for the walk's cost.
        midpoint, half_extent: for the margin grid's cost, a sample of at most
            ``COST_SAMPLE`` spheres' first-frame chords: their midpoints and half extents per
            axis plus the radius [m], (S, 3) each; None: the grid's cost is its mean list.
    """

    margin: float
    reach: float
    mean_path: np.ndarray
    midpoint: np.ndarray | None = None
    half_extent: np.ndarray | None = None


def paths(position: np.ndarray, velocity: np.ndarray, radius: np.ndarray, gravity, dt: float,
          boxes: RoundedBoxes | None = None) -> Paths:
    """The :class:`Paths` of a swarm's frames (``position`` (N, 3) [m], ``velocity`` (N, 3)
    [m/s], ``radius`` (N,) [m], ``gravity`` [m/s^2], ``dt`` [s]); with ``boxes``, the grid's
    margin allows for the speed a sphere gains falling to the lowest point of the boxes and the
    starts (:func:`reach`; without, a single query's first frame)."""
    g = np.asarray(gravity, dtype=np.float64)
    if len(position) == 0:
        return Paths(margin=0.0, reach=0.0, mean_path=np.zeros(3))
    sagitta = float(np.max(np.abs(g))) * dt * dt / 8.0
    step = np.abs(velocity) * dt + np.abs(g) * dt * dt
    lowest = None if boxes is None else lowest_potential(g, boxes, position)
    some = np.linspace(0, len(position) - 1, min(len(position), COST_SAMPLE)).astype(np.int64)
    chord = (velocity[some] + g * (dt / 2)) * dt
    return Paths(margin=reach(position, velocity, radius, g, dt, lowest),
                 reach=(float(np.max(radius)) + sagitta) * (1.0 + WALK_REACH_HEADROOM),
                 mean_path=step.mean(axis=0), midpoint=position[some] + chord / 2,
                 half_extent=np.abs(chord) / 2 + np.asarray(radius)[some, None])


@dataclass
class WalkGrid(CellLists):
    """The walked grid and its cell lists (host arrays, float64 geometry): cell ``c`` lists the
    boxes whose reject bounds, grown by ``reach (1 + REJECT_SLACK) + pad``, meet it.

    Attributes:
        lower, cell, dims: as :class:`Grid`'s.
        reach: the largest growth per axis [m] (radius plus sagitta) of a path the lists are
            made for, as the kernels hold it.
        scale: the largest coordinate [m] a walked path's ends may have, as the kernels hold it.
        pad: the rounding pad [m] the listed bounds carry (``WALK_PAD_ULPS`` of ``scale``).
        cell_start, cell_boxes: the CSR lists, as :class:`Grid`'s.
        box_cell_lo, box_cell_hi: the cell range listing each box, (K, 3) int32 each.
        cost: the cost model's figure for one query (``WALK_*`` units).
    """

    lower: np.ndarray
    cell: np.ndarray
    dims: np.ndarray
    reach: float
    scale: float
    pad: float
    cell_start: np.ndarray
    cell_boxes: np.ndarray
    box_cell_lo: np.ndarray
    box_cell_hi: np.ndarray
    cost: float


    def entries(self) -> np.ndarray:
        """The kernels' ``cell_boxes``: each entry ``box << WALK_FLAG_BITS | flags``, bit ``i``
        set where the entry's cell is the first of the box's range along axis ``i``, bit
        ``3 + i`` where it is the last, int32."""
        cell = np.repeat(np.arange(self.cells, dtype=np.int64), np.diff(self.cell_start))
        index = np.stack([cell % self.dims[0], cell // self.dims[0] % self.dims[1],
                          cell // (self.dims[0] * self.dims[1])], axis=1)
        box = self.cell_boxes.astype(np.int64)
        first = index == self.box_cell_lo[box]
        last = index == self.box_cell_hi[box]
        flags = (first * (1 << np.arange(3))).sum(axis=1) + (last * (8 << np.arange(3))).sum(1)
        return ((box << WALK_FLAG_BITS) | flags).astype(np.int32)

    def nbytes(self, float_bytes: int = 4) -> int:
        """Bytes of the walked grid on the device: the cell offsets, the entries and each
        entry's box bounds (at most ``MAX_WALK_BYTES``)."""
        return int(self.cell_start.nbytes + self.cell_boxes.nbytes
                   + len(self.cell_boxes) * 6 * float_bytes)


def walk_cost(mean_path: np.ndarray, cell: np.ndarray, entries: int, cells: int) -> float:
    """The cost model of one walked query: ``WALK_FIXED`` plus, per cell crossed (one, plus a
    face per cell size along each axis of the mean path), ``WALK_PER_CELL`` and the mean list
    (``entries / cells``) at ``WALK_PER_ENTRY``."""
    crossed = 1.0 + float(np.sum(np.asarray(mean_path) / cell))
    return WALK_FIXED + crossed * (WALK_PER_CELL + WALK_PER_ENTRY * entries / max(cells, 1))


def build_walk_grid(boxes: RoundedBoxes, walk_reach: float, mean_path, dtype=np.float32,
                    cell_size: float | None = None) -> WalkGrid | None:
    """The walked grid over ``boxes`` for paths growing by up to ``walk_reach`` [m].

    Args:
        boxes: the obstacles.
        walk_reach: the largest radius plus sagitta [m] of a path the lists are made for, >= 0.
        mean_path: the mean ``|d_i|`` [m] of a query's chord per axis, (3,): the cost model's
            path, which sets the cell size (the cheapest of cubic cells from the finest allowed
            to one cell, by :func:`walk_cost`).
        dtype: the kernels' float type.
        cell_size: [m], > 0: this cell size instead of the cost model's (tests).

    Returns:
        The :class:`WalkGrid`, or None when the scene has no boxes or no cell size keeps the
        grid within ``MAX_CELLS`` cells and ``MAX_WALK_BYTES``.
    """
    k = len(boxes)
    if (k == 0 or k >= 1 << (31 - WALK_FLAG_BITS) or not walk_reach >= 0.0
            or not math.isfinite(walk_reach)):
        return None
    eps = float(np.finfo(dtype).eps)
    fbytes = np.dtype(dtype).itemsize
    center = boxes.center.astype(dtype)
    extent = boxes.world_extent().astype(dtype)
    lo32, hi32 = bvh_bounds(center, extent)  # the reject bounds, rounded outward
    reach_k = float(np.asarray(walk_reach, dtype=dtype))
    grow = reach_k * (1.0 + REJECT_SLACK)
    box_lo, box_hi = lo32.astype(np.float64) - grow, hi32.astype(np.float64) + grow
    span = box_hi.max(axis=0) - box_lo.min(axis=0)
    largest = float(np.max(np.abs(np.concatenate([box_lo, box_hi]))))
    scale = float(np.asarray(largest + WALK_SPANS * float(span.max()), dtype=dtype))
    pad = WALK_PAD_ULPS * eps * scale + BOUNDS_PAD_ABS
    box_lo, box_hi = box_lo - pad, box_hi + pad
    lower = box_lo.min(axis=0).astype(dtype).astype(np.float64)
    span = box_hi.max(axis=0) - lower
    if cell_size is not None:
        sizes = [float(cell_size)]
    else:
        finest = float(span.max()) / MAX_CELLS_PER_AXIS
        count = int(math.ceil(math.log(MAX_CELLS_PER_AXIS) / math.log(WALK_CELL_RATIO))) + 1
        sizes = [finest * WALK_CELL_RATIO ** i for i in range(count)]
    best = None
    for size in sizes:
        cell = np.full(3, np.asarray(size, dtype=dtype).astype(np.float64))
        dims = np.maximum(1, np.ceil(span / cell)).astype(np.int64)
        if np.prod(dims) > MAX_CELLS or np.any(dims > MAX_CELLS_PER_AXIS):
            continue
        # cell c's domain [lower + c h, lower + (c + 1) h] meets [box_lo, box_hi]
        c_min = np.clip(np.ceil((box_lo - lower) / cell - 1.0).astype(np.int64), 0, dims - 1)
        c_max = np.clip(np.floor((box_hi - lower) / cell).astype(np.int64), 0, dims - 1)
        entries = int(np.prod(c_max - c_min + 1, axis=1).sum())
        if 4 * (np.prod(dims) + 1) + entries * (4 + 6 * fbytes) > MAX_WALK_BYTES:
            continue
        cost = walk_cost(mean_path, cell, entries, int(np.prod(dims)))
        if best is None or cost < best[0]:
            best = (cost, cell, dims, c_min, c_max)
    if best is None:
        return None
    cost, cell, dims, c_min, c_max = best
    start, box_ids = cell_lists(c_min, c_max, dims)
    return WalkGrid(lower=lower, cell=cell, dims=dims.astype(np.int32), reach=reach_k,
                    scale=scale, pad=pad, cell_start=start, cell_boxes=box_ids,
                    box_cell_lo=c_min.astype(np.int32), box_cell_hi=c_max.astype(np.int32),
                    cost=cost)


def tree_split(lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which boxes the BVH's tree holds, and which are tried before each of its queries, where
    the BVH is the broad phase (``"bvh"``; as a grid's fallback its tree holds every box).

    A box whose bounds span more than ``SPANNING_SHARE`` of the scene's along two axes (a
    room's floor, ceiling and walls) meets a large share of the queries wherever it sits in
    the tree, and makes every node above it span the scene as well, so that a query visits
    most of the tree: kept out of the standard room's tree, its six walls leave the forced
    BVH's frame 0.56 to 0.78x the time it took with them in (BENCHMARKS.md, "The BVH
    without the walls"). Those boxes (the ``SPANNING_MAX`` widest at most, by the product
    of their two largest shares) are kept out and tried one by one, each through the same
    reject; the candidates, and so the bits, are those of one tree over every box.

    Args:
        lower, upper: the boxes' BVH bounds [m] (:func:`warpsim.device.bvh_bounds`), (K, 3).

    Returns:
        ``(spanning, tree)``: int32 box indices, ascending: the boxes kept out, and the boxes
        of the tree; the tree is never empty when there are boxes (where every box spans the
        scene, none is kept out). An axis along which the scene has no extent counts as
        spanned.
    """
    lower = np.asarray(lower, dtype=np.float64)
    upper = np.asarray(upper, dtype=np.float64)
    if len(lower) == 0:
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    span = upper.max(axis=0) - lower.min(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(span > 0.0, (upper - lower) / np.where(span > 0.0, span, 1.0), 1.0)
    two = np.sort(share, axis=1)[:, 1:]  # the two largest shares of each box
    wide = np.flatnonzero(two[:, 0] > SPANNING_SHARE)
    if wide.size > SPANNING_MAX:
        order = np.argsort(-(two[wide, 0] * two[wide, 1]), kind="stable")
        wide = np.sort(wide[order[:SPANNING_MAX]])
    if wide.size == len(lower):  # every box spans the scene: one tree over them all
        wide = wide[:0]
    kept = np.ones(len(lower), dtype=bool)
    kept[wide] = False
    return wide.astype(np.int32), np.flatnonzero(kept).astype(np.int32)


def exhaustive(box_count: int, dtype=np.float32) -> tuple[str, float]:
    """The method that tries every candidate without a grid, and its cost by the model, for
    kernels of float type ``dtype``: the BVH from ``device.bvh_min_boxes(dtype)`` boxes on
    (where it was measured to win: 32 in float32, 20 in float64), every box below; the
    BVH's fixed cost is ``BVH_FIXED_FLOAT64`` in float64."""
    if box_count >= bvh_min_boxes(dtype):
        fixed = BVH_FIXED_FLOAT64 if np.dtype(dtype) == np.float64 else BVH_FIXED
        return "bvh", fixed + BVH_PER_LEVEL * math.log2(box_count)
    return "brute", BRUTE_FIXED + box_count


def grid_cost(grid: Grid, frame: Paths, fallback_cost: float) -> float:
    """The cost model of one query through the margin grid: ``GRID_FIXED`` plus the list of the
    cell holding the path's midpoint, or the fallback's cost for a path that does not fit
    (half its extent plus the radius beyond the margin, or outside the grid), averaged over
    the sample of first frames in ``frame`` (without one: the mean list over the cells)."""
    if frame.midpoint is None or not len(frame.midpoint):
        return GRID_FIXED + grid.mean_list_length()
    inside, lengths = grid.list_lengths(frame.midpoint)
    fits = inside & np.all(frame.half_extent * (1.0 + REJECT_SLACK) <= grid.kernel_margin,
                           axis=1)
    return GRID_FIXED + float(np.mean(np.where(fits, lengths, fallback_cost)))


def margin_grid(boxes: RoundedBoxes, frame: Paths, dtype=np.float32,
                ) -> tuple[float, Grid] | None:
    """The margin grid for ``frame`` and its cost by the model (:func:`grid_cost`, plus
    ``TABLE_PENALTY`` per doubling of a table beyond ``CACHE_CELLS``): the finest grid the
    margin allows, or the one of ``CACHE_CELLS`` cells at most when that costs less; None when
    none can be built."""
    fallback_cost = exhaustive(len(boxes), dtype)[1]
    best = None
    for max_cells in (MAX_CELLS, CACHE_CELLS):
        grid = build_grid(boxes, frame.margin, dtype, max_cells)
        if grid is None:
            continue
        cost = grid_cost(grid, frame, fallback_cost)
        cost += TABLE_PENALTY * max(math.log2(grid.cells / CACHE_CELLS), 0.0)
        if best is None or cost < best[0]:
            best = (cost, grid)
        if grid.cells <= CACHE_CELLS:
            break
    return best


def estimates(boxes: RoundedBoxes, frame: Paths, dtype=np.float32) -> dict:
    """Every broad phase the scene can run, with its cost by the model and its grid.

    Returns:
        ``{name: (cost, grid or None)}``: the exhaustive method (:func:`exhaustive`), and
        ``"grid"``/``"grid-bvh"`` and ``"walk"``/``"walk-bvh"`` where their grids can be built
        (a grid falls back to the exhaustive method).
    """
    k = len(boxes)
    fallback, fallback_cost = exhaustive(k, dtype)
    out = {fallback: (fallback_cost, None)}
    if not k:
        return out
    suffix = "-bvh" if fallback == "bvh" else ""
    grid = margin_grid(boxes, frame, dtype)
    if grid is not None:
        out["grid" + suffix] = grid
    walk = build_walk_grid(boxes, frame.reach, frame.mean_path, dtype)
    if walk is not None:
        out["walk" + suffix] = (walk.cost, walk)
    return out


def preferred(options: dict) -> str:
    """The broad phase ``auto`` takes among :func:`estimates`' ``options`` (the exhaustive method
    first): the start-cell grid where the model puts it below the exhaustive method (where it
    pays it was measured the cheapest of all: the standard room at 5 and 60 m/s), else the walk
    where the model puts it below the exhaustive method, else that method."""
    names = list(options)
    floor = options[names[0]][0]
    for prefix in ("grid", "walk"):
        for name in names[1:]:
            if name.startswith(prefix) and options[name][0] < floor:
                return name
    return names[0]


def choose(requested: str, boxes: RoundedBoxes, frame: Paths, dtype=np.float32,
           queries: int | None = None) -> tuple[str, Grid | WalkGrid | None]:
    """The broad phase to compile, and its grid when it has one.

    Args:
        requested: ``"auto"``, ``"brute"``, ``"bvh"``, ``"grid"`` or ``"walk"``. A grid falls
            back to :func:`exhaustive`'s method for the paths it was not made for (``"grid"``
            and ``"walk"`` over every box, ``"grid-bvh"`` and ``"walk-bvh"`` over the BVH), and
            where it cannot be built that method runs instead; ``"auto"`` takes
            :func:`preferred` of :func:`estimates` by the cost model.
        boxes: the obstacles.
        frame: what the spheres' first frame needs (see :func:`paths`).
        dtype: the kernels' float type.
        queries: how many path queries the launch makes, when known (a single frame's
            ``collide_boxes``); None for a run of frames yet unknown. ``auto`` takes the
            exhaustive method without building any grid when these queries cost less than
            the build by the model (``GRID_BUILD``).

    Returns:
        ``(name, grid)`` with ``name`` one of ``kernels.data.BROAD_PHASES``.
    """
    choice = check.broad_phase(requested)
    if choice in ("brute", "bvh"):
        return choice, None
    k = len(boxes)
    method, cost = exhaustive(k, dtype)
    if choice in ("grid", "walk"):
        grid = None
        if k:
            if choice == "grid":
                grid = margin_grid(boxes, frame, dtype)
                grid = None if grid is None else grid[1]
            else:
                grid = build_walk_grid(boxes, frame.reach, frame.mean_path, dtype)
        if grid is None:
            return method, None
        name = choice + ("-bvh" if method == "bvh" else "")
    elif cost <= GRID_FIXED or queries is not None and queries * cost <= GRID_BUILD:
        # no grid can win: by the model a margin grid costs at least GRID_FIXED and a walked
        # one at least WALK_FIXED + WALK_PER_CELL, so a scene of a box or two takes its
        # exhaustive method without building the grids (milliseconds a call for a few
        # spheres); nor where the launch's every query costs less than building them
        name, grid = method, None
    else:
        options = estimates(boxes, frame, dtype)
        name = preferred(options)
        grid = options[name][1]
    return name, grid
