"""The walked grid (``broad_phase="walk"``) gives the same bits as trying every box.

The walk tries only the boxes listed in the cells a path's chord crosses, each once, and stops
at the first cell beyond the nearest contact, so every case here compares it with brute force
bit for bit: random scenes near and far from the origin, both precisions, chords and arcs,
radius 0, spheres at rest, paths along cell faces and through cell corners (zero direction
components), paths crossing many cells and longer than the grid, spheres its lists were not
made for (the fallback), whole simulator runs with their contact events, and hypothesis'
paths. The cell size is forced (fine and coarse) where the cost model would pick one cell for
a small scene. Plus the host invariants: which cells list a box, the entries' flags, memory.
"""

from functools import partial

import numpy as np
import pytest
from helpers import examples
from hypothesis import given, settings
from hypothesis import strategies as st
from test_grid import random_scene, same, swarm_inputs

import warpsim as ws
from warpsim import broad_phase as broad
from warpsim.device import bvh_bounds
from warpsim.kernels.data import WALK_FLAG_BITS

DT = 1.0 / 60.0
BOUNCE_FIELDS = ("hit", "bounces", "capped", "position", "velocity", "angular_momentum")
CONTACT_FIELDS = ("hit", "t", "position", "normal", "new_position", "new_velocity", "box")
STATE_FIELDS = ("position", "velocity", "energy", "angular_momentum", "orientation")
BUILD_WALK_GRID = broad.build_walk_grid


@pytest.fixture
def cell_size(monkeypatch):
    """``set(h)``: walked grids built from now on have cubic cells of ``h`` [m]."""

    def set_size(h):
        monkeypatch.setattr(broad, "build_walk_grid", partial(BUILD_WALK_GRID, cell_size=h))

    return set_size


def walked(request_value, fn, *args, **kwargs):
    """``fn(..., broad_phase="brute")`` and ``fn(..., broad_phase="walk")``."""
    return (fn(*args, broad_phase="brute", **kwargs), fn(*args, broad_phase=request_value,
                                                          **kwargs))


@pytest.mark.parametrize("offset", [0.0, 1e4], ids=["origin", "far"])
@pytest.mark.parametrize("k", [7, 60])
@pytest.mark.parametrize("h", [None, 0.3], ids=["model", "fine"])
def test_bounce_walk_is_bit_identical(device, k, offset, h, precision, cell_size):
    """Random rotated boxes, plates and sticks; spheres up to 300 m/s (5 m a frame, many
    cells), a seventh of radius 0."""
    if h is not None:
        cell_size(h)
    rng = np.random.default_rng([k, int(offset)])
    boxes, side = random_scene(k, rng, offset)
    pos, vel, rad = swarm_inputs(3000, side, rng, offset, boxes, speed=(0.5, 300.0))
    rad[::7] = 0.0
    brute, walk = walked("walk", ws.bounce, pos, vel, rad, boxes, DT, precision=precision,
                         max_bounces=16, device=device)
    same(brute, walk, BOUNCE_FIELDS)
    assert brute.bounces.sum() > 20


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_collide_walk_chords_and_arcs(device, precision, motion, cell_size):
    """The first contact of chords and of arcs (gravity 9.81 and a strong 400 m/s^2 whose
    sagitta goes past the lists' reach for slow frames: those fall back), fine cells."""
    cell_size(0.25)
    rng = np.random.default_rng(11)
    boxes, side = random_scene(40, rng)
    pos, vel, rad = swarm_inputs(4000, side, rng, 0.0, boxes, speed=(0.0, 200.0))
    gravities = [None] if motion == "linear" else [(0.0, -9.81, 0.0), (120.0, -400.0, 30.0)]
    for g in gravities:
        brute, walk = walked("walk", ws.collide_boxes, pos, vel, rad, boxes, DT,
                             precision=precision, motion=motion, gravity=g, device=device)
        same(brute, walk, CONTACT_FIELDS)
        assert 0.01 < brute.hit.mean() < 0.95


def test_paths_on_cell_faces_and_through_corners(device, precision, cell_size):
    """Starts exactly on cell faces, edges and corners (in the kernels' precision), moving
    along the axes (two or three zero direction components), along face diagonals and through
    cell corners (equal crossing parameters on two or three axes), at rest, and radius 0."""
    h = 0.5
    cell_size(h)
    boxes = ws.RoundedBoxes(
        center=[[0.0, -0.5, 0.0], [1.0, 0.5, 0.0], [-1.0, 1.0, 0.5], [0.25, 1.5, -1.0],
                [0.0, 1.0, 1.5]],
        half_extents=[[4.0, 0.5, 4.0], [0.25, 0.5, 0.5], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5],
                      [1.0, 0.25, 0.0]],
        rotation=[[0, 0, 0, 1], [0, 0, 0, 1], [0, 0, 0, 1], [0.1, 0.2, 0.0, 1.0],
                  [0, 0, 0, 1]], radius=[0.0, 0.05, 0.0, 0.02, 0.0])
    dtype = np.float32 if precision == "float32" else np.float64
    grid = broad.build_walk_grid(boxes, 0.1, np.zeros(3), dtype)
    rng = np.random.default_rng(5)
    n = 4000
    cells = rng.integers(0, grid.dims, (n, 3))
    pos = (grid.lower + cells * grid.cell).astype(dtype).astype(np.float64)
    pos[:, 1] = np.clip(pos[:, 1], 0.15, None)  # above the floor
    dirs = np.array([[1, 0, 0], [0, -1, 0], [0, 0, 1], [1, 1, 0], [0, -1, -1], [1, 1, 1],
                     [-1, -1, 1], [1, -1, -1], [0, 0, 0]], dtype=np.float64)
    direction = dirs[rng.integers(0, len(dirs), n)]
    # whole numbers of cells a frame: the chord ends on faces, edges and corners too
    vel = direction * (h * rng.integers(1, 9, (n, 1)) / DT)
    rad = rng.choice([0.0, 0.05, 0.1], n)
    keep = boxes.signed_distance(pos).min(axis=1) > rad
    pos, vel, rad = pos[keep], vel[keep], rad[keep]
    brute, walk = walked("walk", ws.collide_boxes, pos, vel, rad, boxes, DT,
                         precision=precision, device=device)
    same(brute, walk, CONTACT_FIELDS)
    assert brute.hit.sum() > 100
    brute, walk = walked("walk", ws.bounce, pos, vel, rad, boxes, DT, precision=precision,
                         max_bounces=16, device=device)
    same(brute, walk, BOUNCE_FIELDS)


@pytest.mark.parametrize("offset", [0.0, 1e4], ids=["origin", "far"])
def test_very_fast_spheres_and_the_fallback(device, precision, offset, cell_size,
                                            monkeypatch):
    """Paths of 2 to 2000 m a frame (many cells, longer than the grid, ends beyond the walk's
    scale: those fall back), and lists made for a smaller reach than the spheres' (every
    sphere of a larger radius falls back)."""
    cell_size(0.4)
    rng = np.random.default_rng(7 + int(offset))
    boxes, side = random_scene(30, rng, offset)
    pos, vel, rad = swarm_inputs(3000, side, rng, offset, boxes, speed=(100.0, 120_000.0))
    brute, walk = walked("walk", ws.bounce, pos, vel, rad, boxes, DT, precision=precision,
                         max_bounces=8, device=device)
    same(brute, walk, BOUNCE_FIELDS)
    monkeypatch.setattr(broad, "build_walk_grid",
                        lambda boxes, reach, path, dtype: BUILD_WALK_GRID(boxes, 0.02, path,
                                                                           dtype, 0.4))
    brute, walk = walked("walk", ws.bounce, pos, vel, rad, boxes, DT, precision=precision,
                         max_bounces=8, device=device)
    same(brute, walk, BOUNCE_FIELDS)


@st.composite
def path_batches(draw):
    """64 paths: starts in and around a 6 m scene, directions with zero components, lengths
    from 0 to 40 m, radii from 0 to 0.1 m."""
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    n = 64
    pos = rng.uniform(-4.0, 4.0, (n, 3))
    d = rng.normal(size=(n, 3))
    d[rng.random((n, 3)) < 0.2] = 0.0
    length = draw(st.sampled_from([0.0, 0.05, 1.0, 5.0, 40.0]))
    vel = d * (rng.uniform(0.0, 1.0, (n, 1)) * length / DT)
    rad = np.where(rng.random(n) < 0.2, 0.0, rng.uniform(0.0, 0.1, n))
    h = draw(st.sampled_from([0.2, 0.7, 3.0]))
    return pos, vel, rad, h


HYPOTHESIS_BOXES = random_scene(25, np.random.default_rng(99))[0]


@settings(max_examples=examples(15))
@given(batch=path_batches())
def test_walk_matches_brute_on_any_path(batch):
    pos, vel, rad, h = batch
    keep = HYPOTHESIS_BOXES.signed_distance(pos).min(axis=1) > rad
    pos, vel, rad = pos[keep], vel[keep], rad[keep]
    grid = partial(BUILD_WALK_GRID, cell_size=h)
    original = broad.build_walk_grid
    broad.build_walk_grid = grid  # hypothesis and function-scoped fixtures do not mix
    try:
        brute, walk = walked("walk", ws.collide_boxes, pos, vel, rad, HYPOTHESIS_BOXES, DT,
                             device="cpu")
    finally:
        broad.build_walk_grid = original
    same(brute, walk, CONTACT_FIELDS)


@pytest.mark.parametrize("scene_name", ["room", "plates"])
def test_simulator_walk_events_match_brute(device, scene_name):
    """Whole runs, the linear room and the ballistic plates, with resting contacts: states,
    counters and every contact event identical."""
    scene = ws.Scene.load(scene_name)
    swarm = scene.spawn(n=300, seed=3)
    sims = {bp: ws.Simulator(scene, swarm, broad_phase=bp, device=device)
            for bp in ("brute", "walk")}
    assert sims["walk"].broad_phase == "walk"
    runs = {bp: sim.run(40, events=True) for bp, sim in sims.items()}
    same(sims["brute"].state(), sims["walk"].state(), STATE_FIELDS)
    assert sims["brute"].stats.bounces == sims["walk"].stats.bounces > 0
    a, b = runs["brute"].events.columns(), runs["walk"].events.columns()
    assert len(a["frame"]) == len(b["frame"]) > 0
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


@pytest.mark.parametrize("k", [3, 40])
def test_walk_cells_list_every_box_near_them(k):
    """The host invariant: a cell lists box b exactly when b's reject bounds, grown by the
    reach and the pad, meet it; the ranges and the entries' flags agree with the lists."""
    boxes, _ = random_scene(k, np.random.default_rng(k))
    grid = broad.build_walk_grid(boxes, 0.05, np.full(3, 0.3))
    lo32, hi32 = bvh_bounds(boxes.center.astype(np.float32),
                            boxes.world_extent().astype(np.float32))
    grow = grid.reach * (1.0 + ws.kernels.candidates.REJECT_SLACK) + grid.pad
    iz, iy, ix = np.indices(grid.dims[::-1]).reshape(3, -1)
    idx = np.stack([ix, iy, iz], axis=1)
    cell_lo = grid.lower + idx * grid.cell
    cell_hi = cell_lo + grid.cell
    entry_cell = np.repeat(np.arange(grid.cells), np.diff(grid.cell_start))
    listed = np.zeros((grid.cells, k), bool)
    listed[entry_cell, grid.cell_boxes] = True
    for b in range(k):
        meets = np.all((cell_lo <= hi32[b] + grow) & (cell_hi >= lo32[b] - grow), axis=1)
        assert not np.any(meets & ~listed[:, b]), b
        in_range = np.all((idx >= grid.box_cell_lo[b]) & (idx <= grid.box_cell_hi[b]), axis=1)
        np.testing.assert_array_equal(in_range, listed[:, b])
    entries = grid.entries()
    np.testing.assert_array_equal(entries >> WALK_FLAG_BITS, grid.cell_boxes)
    first_x = (entries & 1) != 0
    np.testing.assert_array_equal(first_x, idx[entry_cell, 0] == grid.box_cell_lo[
        grid.cell_boxes, 0])
    assert grid.nbytes() <= broad.MAX_WALK_BYTES


def test_walk_memory_is_bounded(monkeypatch):
    """No cell size within the byte budget: no walked grid, and a requested walk runs the
    exhaustive method instead."""
    boxes, _ = random_scene(200, np.random.default_rng(1))
    assert broad.build_walk_grid(boxes, 0.05, np.full(3, 0.3)) is not None
    monkeypatch.setattr(broad, "MAX_WALK_BYTES", 1000)
    assert broad.build_walk_grid(boxes, 0.05, np.full(3, 0.3)) is None
    frame = broad.Paths(margin=0.2, reach=0.05, mean_path=np.full(3, 0.3))
    assert broad.choose("walk", boxes, frame) == ("bvh", None)


def test_auto_walks_fast_spheres_among_many_plates():
    """The cost model: long paths among many boxes take the walk, the standard room's slow
    spheres keep the cheaper start cell."""
    from benchmarks.speed import grown_room

    scene = grown_room(262, 10, np.random.default_rng(3))
    fast = broad.Paths(margin=15.0, reach=0.05, mean_path=np.full(3, 5.0))
    assert broad.choose("auto", scene.boxes, fast)[0] == "walk-bvh"
    room = ws.Scene.load("room")
    slow = broad.Paths(margin=0.2, reach=0.05, mean_path=np.full(3, 0.04))
    assert broad.choose("auto", room.boxes, slow)[0] == "grid"


def test_the_run_footprint_bounds_the_broad_phase():
    """What ``--max-memory`` is checked against holds the largest grid either broad phase
    may build."""
    from warpsim import footprint

    margin_grid = 4 * (broad.MAX_CELLS + 1) + 4 * broad.MAX_ENTRIES
    assert max(margin_grid, broad.MAX_WALK_BYTES) <= footprint.BROAD_PHASE_BYTES
    assert footprint.run_bytes(10, 2).broad == footprint.BROAD_PHASE_BYTES
