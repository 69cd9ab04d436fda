"""The uniform-grid broad phase gives the same bits as trying every box.

Random scenes from 1 to 10 000 boxes, spheres resting in contact, centres exactly on cell
borders, scenes far from the origin, both precisions; plus the grid's own invariant: a cell
lists every box whose reject bounds meet the cell grown by the margin.
"""

import numpy as np
import pytest
from helpers import shaped_half_extents

import warpsim as ws
from warpsim import broad_phase as broad
from warpsim.device import bvh_bounds

DT = 1.0 / 60.0
FIELDS = ("hit", "bounces", "capped", "position", "velocity", "angular_momentum")


def random_scene(k: int, rng, offset: float = 0.0):
    side = max(4.0, (k * 3.0) ** (1 / 3) * 2.0)
    center = rng.uniform(-side / 2, side / 2, (k, 3)) + offset
    kinds = rng.choice(["box", "plate", "stick", "cube"], size=k)
    half = np.stack([shaped_half_extents(rng, kind, 0.05, 0.6) for kind in kinds])
    q = rng.normal(size=(k, 4))
    radius = rng.choice([0.0, 0.02, 0.1], size=k)
    return ws.RoundedBoxes(center=center, half_extents=half, rotation=q, radius=radius), side


def swarm_inputs(n, side, rng, offset, boxes, speed=(0.5, 20.0)):
    pos = rng.uniform(-side / 2, side / 2, (n, 3)) + offset
    r = rng.uniform(0.0, 0.05, n)
    d = rng.normal(size=(n, 3))
    v = d / np.linalg.norm(d, axis=1)[:, None] * rng.uniform(*speed, (n, 1))
    clear = boxes.signed_distance(pos).min(axis=1) > r + 1e-3
    return pos[clear], v[clear], r[clear]


def same(a, b, fields):
    for f in fields:
        x, y = getattr(a, f), getattr(b, f)
        assert np.array_equal(np.asarray(x).view(np.uint8), np.asarray(y).view(np.uint8)), f


@pytest.mark.slow
@pytest.mark.parametrize("k", [1, 7, 60, 500, 10_000])
@pytest.mark.parametrize("offset", [0.0, 1e4])
def test_bounce_grid_is_bit_identical(device, k, offset, precision):
    rng = np.random.default_rng(k + int(offset))
    boxes, side = random_scene(k, rng, offset)
    pos, vel, rad = swarm_inputs(3000 if k < 10_000 else 400, side, rng, offset, boxes)
    brute = ws.bounce(pos, vel, rad, boxes, DT, precision=precision, broad_phase="brute",
                      max_bounces=16, device=device)
    grid = ws.bounce(pos, vel, rad, boxes, DT, precision=precision, broad_phase="grid",
                     max_bounces=16, device=device)
    same(brute, grid, FIELDS)
    assert brute.bounces.sum() > 0


def test_spheres_on_cell_borders_and_resting(device):
    """Centres put exactly on cell borders (in the kernels' float32), and spheres resting on
    a floor and on box tops: the grid keeps every contact brute force finds."""
    floor = ws.RoundedBoxes(center=[[0, -0.5, 0], [1.0, 0.25, 0.3], [-1.2, 0.1, -0.7]],
                            half_extents=[[5, 0.5, 5], [0.3, 0.25, 0.3], [0.2, 0.1, 0.4]],
                            radius=[0.0, 0.05, 0.0])
    scene = ws.Scene(floor)
    grid = broad.build_grid(floor, 0.3)
    assert grid is not None
    rng = np.random.default_rng(3)
    n = 2000
    r = 0.05
    cells = rng.integers(0, grid.dims, (n, 3))
    pos = (grid.lower + cells * grid.cell).astype(np.float32).astype(np.float64)
    pos[:, 1] = np.abs(pos[:, 1]) % 1.5 + r + 0.01
    # a third rest exactly on the floor, on borders in x and z
    pos[: n // 3, 1] = r
    vel = rng.normal(size=(n, 3))
    vel[: n // 3] = 0.0
    keep = floor.signed_distance(pos).min(axis=1) >= r
    swarm = ws.Swarm(pos[keep], vel[keep], radius=r)
    sims = {bp: ws.Simulator(scene, swarm, broad_phase=bp, device=device) for bp in
            ("brute", "grid")}
    assert sims["grid"].broad_phase == "grid"
    for sim in sims.values():
        sim.step(90)
    a, b = sims["brute"].state(), sims["grid"].state()
    for f in ("position", "velocity", "energy"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    assert sims["brute"].stats.bounces == sims["grid"].stats.bounces > 0


@pytest.mark.slow
def test_simulator_grid_matches_brute_in_bundled_scenes(device, precision):
    for name in ("room", "galton", "staircase", "pinball"):
        scene = ws.Scene.load(name)
        swarm = scene.spawn(n=400, seed=5)
        brute = ws.Simulator(scene, swarm, broad_phase="brute", precision=precision,
                             device=device)
        grid = ws.Simulator(scene, swarm, broad_phase="grid", precision=precision,
                            device=device)
        assert grid.broad_phase in ("grid", "grid-bvh")
        brute.step(60)
        grid.step(60)
        assert np.array_equal(brute.state().position, grid.state().position), name
        assert brute.stats.bounces == grid.stats.bounces


@pytest.mark.slow
@pytest.mark.parametrize("k", [3, 40, 300])
def test_cells_list_every_box_near_them(k):
    """The host invariant: cell c lists box b exactly when b's reject bounds meet c's domain
    grown by the margin (checked by brute force over all cells and boxes, float64)."""
    rng = np.random.default_rng(k)
    boxes, _ = random_scene(k, rng)
    margin = 0.4
    grid = broad.build_grid(boxes, margin)
    lo32, hi32 = bvh_bounds(boxes.center.astype(np.float32),
                            boxes.world_extent().astype(np.float32))
    iz, iy, ix = np.indices(grid.dims[::-1]).reshape(3, -1)
    idx = np.stack([ix, iy, iz], axis=1)
    cell_lo = grid.lower + idx * grid.cell - margin
    cell_hi = cell_lo + grid.cell + 2 * margin
    entry_cell = np.repeat(np.arange(grid.cells), np.diff(grid.cell_start))
    listed = np.zeros((grid.cells, k), bool)
    listed[entry_cell, grid.cell_boxes] = True
    for b in range(k):
        meets = np.all((cell_lo <= hi32[b]) & (cell_hi >= lo32[b]), axis=1)
        # every cell that meets the box lists it (the host may list a few more: its pad)
        assert not np.any(meets & ~listed[:, b]), b
    # lists ascend within each cell
    same_cell = entry_cell[1:] == entry_cell[:-1]
    assert np.all(np.diff(grid.cell_boxes)[same_cell] > 0)


def test_auto_picks_the_grid_for_the_standard_room(device):
    scene = ws.Scene.load("room")
    sim = ws.Simulator(scene, scene.spawn(n=100, seed=0), device=device)
    assert sim.broad_phase == "grid"
