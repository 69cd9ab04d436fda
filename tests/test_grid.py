"""The uniform-grid broad phase gives the same bits as trying every box.

Random scenes from 1 to 10 000 boxes, spheres resting in contact, centres exactly on cell
borders, scenes far from the origin, both precisions; plus the grid's own invariant: a cell
lists every box whose reject bounds meet the cell grown by the margin.
"""

from functools import cache

import numpy as np
import pytest
import warp as wp
from helpers import shaped_half_extents

import warpsim as ws
from benchmarks.common import room_swarm
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
    """``n`` spheres drawn in the scene's cube with speeds in ``speed`` [m/s], less those that
    start inside a box; a tenth of them aimed at a box's centre from within a frame's path
    (``DT``), so that a scene of one small box has contacts too."""
    pos = rng.uniform(-side / 2, side / 2, (n, 3)) + offset
    r = rng.uniform(0.0, 0.05, n)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    s = rng.uniform(*speed, (n, 1))
    v = d * s
    aimed = n // 10
    k = rng.integers(0, len(boxes), aimed)
    pos[:aimed] = boxes.center[k] + d[:aimed] * (s[:aimed] * DT * rng.uniform(0.5, 1.0, (aimed, 1)))
    v[:aimed] = -v[:aimed]  # the path passes through the centre, so it meets the box
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


def grid_matches_brute(scene, swarm, frames, device):
    """Run ``frames`` frames with every box and with the grid: the same bits and contacts.
    Returns the grid's simulator."""
    sims = {bp: ws.Simulator(scene, swarm, broad_phase=bp, device=device)
            for bp in ("brute", "grid")}
    assert sims["grid"].broad_phase == "grid"
    for sim in sims.values():
        sim.step(frames)
    a, b = sims["brute"].state(), sims["grid"].state()
    for f in ("position", "velocity", "energy"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    assert sims["brute"].stats.bounces == sims["grid"].stats.bounces > 0
    return sims["grid"]


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
    grid_matches_brute(scene, swarm, 90, device)


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


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_paths_with_midpoints_on_cell_borders(device, precision, motion):
    """The grid reads the cell of the chord's midpoint: midpoints put exactly on cell borders
    (in the kernels' float type; the kernel's own midpoint rounds to either side), along one,
    two or three axes, give brute force's bits, for the chord and for the arc (whose chord
    ends where the arc does)."""
    rng = np.random.default_rng(11)
    boxes, side = random_scene(60, rng)
    dtype = np.float32 if precision == "float32" else np.float64
    g = np.array([0.0, -9.81 if motion == "ballistic" else 0.0, 0.0])
    n = 3000
    d = rng.normal(size=(n, 3))
    vel = d / np.linalg.norm(d, axis=1)[:, None] * rng.uniform(0.5, 30.0, (n, 1))
    rad = rng.uniform(0.0, 0.05, n)
    # the grid ``ws.bounce`` builds (its margin does not depend on the positions)
    name, grid = broad.choose("grid", boxes, broad.paths(np.zeros((n, 3)), vel, rad, g, DT),
                              dtype)
    assert name.startswith("grid")
    cells = rng.integers(0, grid.dims, (n, 3))
    mid = grid.lower + cells * grid.cell
    on = rng.random((n, 3)) < 0.7  # the other axes anywhere in the cell
    mid = np.where(on, mid, mid + rng.random((n, 3)) * grid.cell).astype(dtype)
    chord = (vel + g * DT / 2) * DT
    pos = mid.astype(np.float64) - chord / 2
    keep = boxes.signed_distance(pos).min(axis=1) > rad + 1e-3
    runs = {bp: ws.bounce(pos[keep], vel[keep], rad[keep], boxes, DT, precision=precision,
                          broad_phase=bp, motion=motion, gravity=g, max_bounces=16,
                          device=device)
            for bp in ("brute", "grid")}
    same(runs["brute"], runs["grid"], FIELDS)
    assert runs["brute"].bounces.sum() > 0


@pytest.mark.parametrize("start", ["room", "drop"])
def test_the_margin_holds_for_the_run(device, start):
    """The margin (``broad_phase.reach``) is made for the speed a sphere can reach, not only
    the first frame's: in the standard room at 5 m/s, and for spheres released at rest under
    the ceiling (whose first frame is almost no path), at least ``REACH_QUANTILE`` of the
    sphere-frames of a 2-second run fit the cell of their midpoint (each frame's displacement,
    at most its chord, within the margin of its midpoint's cell on every axis)."""
    scene = ws.Scene.load("room")
    swarm = scene.spawn(n=1000, seed=4)
    if start == "drop":
        pos = swarm.position.copy()
        pos[:, 1] = 5.5
        swarm = ws.Swarm(pos, np.zeros_like(pos), radius=swarm.radius)
    sim = ws.Simulator(scene, swarm, broad_phase="grid", device=device)
    assert sim.broad_phase == "grid"
    margin = sim._grid.kernel_margin
    path = sim.run(120).position
    half = np.abs(np.diff(path, axis=0)).max(axis=2) / 2
    grow = np.asarray(swarm.radius) * (1.0 + broad.REJECT_SLACK)
    fits = half + grow[None, :] <= margin
    assert fits.mean() >= broad.REACH_QUANTILE, fits.mean()
    if start == "drop":  # the first frame alone would have made a margin far too small
        first = broad.paths(swarm.position, swarm.velocity, swarm.radius, scene.gravity,
                            scene.dt)
        assert (half + grow[None, :] <= first.margin).mean() < 0.5


@cache
def fits_kernel(name: str):
    from warpsim.kernels.candidates import bounds_funcs
    from warpsim.kernels.data import model_structs
    from warpsim.kernels.precision import precision as types_of
    from warpsim.kernels.variant import variant_kernel

    p = types_of(name)
    grid_fits_path = bounds_funcs(p).grid_fits_path
    BroadPhase = model_structs(p).BroadPhase

    @variant_kernel
    def run(broad: BroadPhase, a: wp.array[p.vec3], b: wp.array[p.vec3],
            grow: wp.array[p.vec3], fits_out: wp.array[wp.int32],
            cell_out: wp.array[wp.int32]):
        i = wp.tid()
        fits, cell = grid_fits_path(a[i], b[i], p.scalar(0.5) * (a[i] + b[i]), grow[i], broad)
        fits_out[i] = fits
        cell_out[i] = cell

    return run


def test_a_path_fits_the_cell_of_its_midpoint(precision):
    """``grid_fits_path`` over random paths (short, near the margin, longer than it; midpoints
    on and off cell borders): a path it accepts has every box its query box meets listed in
    the cell it names (float64 check on the host's lists), and every path within the margin of
    its midpoint's cell (half its extent plus its growth at most the margin, less rounding) is
    accepted, wherever in the cell its midpoint lies."""
    from warpsim.kernels.precision import precision as types_of
    from warpsim.model import put_model

    p = types_of(precision)
    rng = np.random.default_rng(5)
    boxes, side = random_scene(40, rng)
    margin = 0.35
    grid = broad.build_grid(boxes, margin, p.np_dtype)
    model = put_model(boxes, p, "cpu", broad_phase="grid", grid=grid, dt=DT)
    n = 20_000
    mid = grid.lower + rng.uniform(0, 1, (n, 3)) * grid.dims * grid.cell
    border = rng.random((n, 3)) < 0.3
    mid = np.where(border, grid.lower + np.round((mid - grid.lower) / grid.cell) * grid.cell,
                   mid).astype(p.np_dtype).astype(np.float64)
    half = rng.uniform(0, 1.3 * margin, (n, 3)) * rng.choice([-1, 1], (n, 3))
    grow = rng.uniform(0, 0.3 * margin, (n, 3))
    a, b = mid - half, mid + half
    arr = {k: wp.array(v.astype(p.np_dtype), dtype=p.vec3, device="cpu")
           for k, v in (("a", a), ("b", b), ("grow", grow))}
    fits = wp.zeros(n, dtype=wp.int32, device="cpu")
    cell = wp.zeros(n, dtype=wp.int32, device="cpu")
    wp.launch(fits_kernel(precision), dim=n, inputs=[model.broad, arr["a"], arr["b"],
              arr["grow"], fits, cell], device="cpu")
    fits, cell = fits.numpy().astype(bool), cell.numpy()
    a, b, grow = (arr[k].numpy().astype(np.float64) for k in ("a", "b", "grow"))
    # accepted: every box the query box meets is in the named cell's list
    lo32, hi32 = bvh_bounds(boxes.center.astype(np.float32),
                            boxes.world_extent().astype(np.float32))
    q_lo, q_hi = np.minimum(a, b) - grow, np.maximum(a, b) + grow
    meets = np.all((q_lo[:, None] <= hi32[None]) & (q_hi[:, None] >= lo32[None]), axis=2)
    for i in np.flatnonzero(fits):
        listed = grid.cell_boxes[grid.cell_start[cell[i]]:grid.cell_start[cell[i] + 1]]
        assert set(np.flatnonzero(meets[i])) <= set(listed), i
    # within the margin of the midpoint's cell: accepted
    reach = (np.abs(b - a) / 2 + grow).max(axis=1)
    at = ((a + b) / 2 - grid.lower) / grid.cell  # in cells; the grid's outer faces round
    inside = np.all((at > 1e-4) & (at < grid.dims - 1e-4), axis=1)
    surely = inside & (reach <= grid.kernel_margin * (1 - 1e-4))
    assert surely.sum() > n // 4 and (~surely).sum() > n // 10
    assert np.all(fits[surely]), np.flatnonzero(surely & ~fits)[:5]


def test_a_sparse_scene_gets_a_table_that_stays_in_cache(device):
    """A walled 40 m room holding only its walls, slow spheres: the finest grid its margin
    allows has millions of empty cells (a lookup that misses the cache every frame); the grid
    the simulator builds keeps its table within ``CACHE_CELLS`` cells, its lists as empty, and
    the bits of every box. A scene whose finest table already fits keeps it."""
    room = ws.Scene.load("room")
    walls = room.boxes[:6]
    scale = np.array([4.0, 4.0, 4.0])
    thin = walls.half_extents.argmin(axis=1)
    half = walls.half_extents * scale
    half[np.arange(6), thin] = 0.05
    center = walls.center * scale
    center[np.arange(6), thin] -= np.sign(center[np.arange(6), thin]) * 0.15
    big = ws.Scene(ws.RoundedBoxes(center, half), gravity=room.gravity)
    rng = np.random.default_rng(2)
    n = 3000
    pos = rng.uniform([-18, 1, -18], [18, 22, 18], (n, 3))
    d = rng.normal(size=(n, 3))
    swarm = ws.Swarm(pos, 5.0 * d / np.linalg.norm(d, axis=1)[:, None], radius=0.05)
    frame = broad.paths(swarm.position, swarm.velocity, swarm.radius, big.gravity, big.dt,
                        big.boxes)
    assert broad.build_grid(big.boxes, frame.margin).cells > 50 * broad.CACHE_CELLS
    grid = grid_matches_brute(big, swarm, 120, device)
    assert grid._grid.cells <= broad.CACHE_CELLS
    # the standard room at 60 m/s: its finest table already fits
    fast = room_swarm(room, 2000, 60.0)
    frame = broad.paths(fast.position, fast.velocity, fast.radius, room.gravity, room.dt,
                        room.boxes)
    finest = broad.build_grid(room.boxes, frame.margin)
    assert finest.cells <= broad.CACHE_CELLS
    assert broad.choose("grid", room.boxes, frame)[1].cells == finest.cells


@cache
def reject_kernel(name: str):
    from warpsim.kernels.candidates import bounds_funcs, path_funcs
    from warpsim.kernels.precision import precision as types_of
    from warpsim.kernels.variant import variant_kernel

    p = types_of(name)
    funcs = bounds_funcs(p)
    per_axis, branch_free = funcs.apart_per_axis, funcs.apart_branch_free
    make_path = path_funcs(p)

    @variant_kernel
    def run(a: wp.array[p.vec3], d: wp.array[p.vec3], grow: wp.array[p.vec3],
            center: wp.array[p.vec3], extent: wp.array[p.vec3], out: wp.array2d[wp.int32]):
        i = wp.tid()
        q = make_path(a[i], d[i], p.vec3(), p.scalar(1.0), p.scalar(0.0), d[i], grow[i])
        out[i, 0] = per_axis(q, center[i], extent[i])
        out[i, 1] = branch_free(q, center[i], extent[i])

    return run


def test_the_reject_without_branches_keeps_every_verdict(precision):
    """The branch-free reject (one comparison of ``max_i (|rel_i| - lim_i)``) against the test
    per axis, and both against the float64 bounds: random paths and boxes at every scale (far
    from the origin, zero extents and zero motion on an axis), and boxes placed exactly on,
    just inside and just beyond the reject's bound along one axis. The two forms agree on
    every case, and neither rejects a box whose bounds the path's bounds meet in float64."""
    from warpsim.kernels.candidates import REJECT_SLACK
    from warpsim.kernels.precision import precision as types_of

    p = types_of(precision)
    rng = np.random.default_rng(11)
    n = 30_000
    scale = 10.0 ** rng.integers(-3, 6, (n, 1))
    a = rng.normal(size=(n, 3)) * scale
    d = rng.normal(size=(n, 3)) * scale * rng.choice([0.0, 0.01, 1.0], (n, 3))
    grow = rng.uniform(0, 1, (n, 3)) * scale * rng.choice([0.0, 1.0], (n, 1))
    extent = rng.uniform(0, 1, (n, 3)) * scale * rng.choice([0.0, 1.0], (n, 3))
    mid = a + 0.5 * d
    lim = (extent + grow) * (1.0 + REJECT_SLACK) + 0.5 * np.abs(d)
    center = mid + rng.uniform(-1.4, 1.4, (n, 3)) * lim
    # on the bound along one axis: exactly, a few ulps either side
    edge = rng.random(n) < 0.5
    axis = rng.integers(0, 3, n)
    rows = np.flatnonzero(edge)
    sign = rng.choice([-1.0, 1.0], rows.size)
    ulps = rng.choice([-4, -1, 0, 0, 1, 4], rows.size)
    eps = np.finfo(p.np_dtype).eps
    center[rows, axis[rows]] = (mid[rows, axis[rows]] + sign * lim[rows, axis[rows]]
                                * (1.0 + ulps * eps))
    arrays = [wp.array(x.astype(p.np_dtype), dtype=p.vec3, device="cpu")
              for x in (a, d, grow, center, extent)]
    out = wp.zeros((n, 2), dtype=wp.int32, device="cpu")
    wp.launch(reject_kernel(precision), dim=n, inputs=[*arrays, out], device="cpu")
    out = out.numpy()
    assert np.array_equal(out[:, 0], out[:, 1]), np.flatnonzero(out[:, 0] != out[:, 1])[:5]
    # float64 on the values the kernel read: bounds that meet are never rejected
    a, d, grow, center, extent = (x.numpy().astype(np.float64) for x in arrays)
    gap = np.abs(a + 0.5 * d - center) - (extent + grow) - 0.5 * np.abs(d)
    meets = np.all(gap <= 0.0, axis=1)
    assert meets.sum() > n // 20 and (~meets).sum() > n // 4
    assert not out[meets, 1].any(), np.flatnonzero(meets & (out[:, 1] == 1))[:5]


@cache
def fit_forms_kernel(name: str):
    from warpsim.kernels.candidates import bounds_funcs
    from warpsim.kernels.data import model_structs
    from warpsim.kernels.precision import precision as types_of
    from warpsim.kernels.variant import variant_kernel

    p = types_of(name)
    funcs = bounds_funcs(p)
    per_axis, branch_free = funcs.grid_fits_per_axis, funcs.grid_fits_branch_free
    BroadPhase = model_structs(p).BroadPhase

    @variant_kernel
    def run(broad: BroadPhase, a: wp.array[p.vec3], b: wp.array[p.vec3],
            mid: wp.array[p.vec3], grow: wp.array[p.vec3], out: wp.array2d[wp.int32]):
        i = wp.tid()
        fits, cell = per_axis(a[i], b[i], mid[i], grow[i], broad)
        out[i, 0] = fits
        out[i, 1] = cell
        fits, cell = branch_free(a[i], b[i], mid[i], grow[i], broad)
        out[i, 2] = fits
        out[i, 3] = cell

    return run


def test_the_fit_without_branches_keeps_every_verdict_and_cell(precision):
    """The branch-free grid fit (one comparison of the largest overhang, the cell clamped
    and the clamp noted) against the test per axis: random paths whose midpoints lie inside
    the grid, on its cell borders, just outside it and far beyond it on one axis or more, of
    every length from a point to several cells, and paths whose ends sit exactly on, a few
    ulps inside and a few ulps beyond their cell's grown bounds along one axis. The two forms
    give the same verdict on every path and the same cell on every path that fits."""
    from warpsim.kernels.precision import precision as types_of
    from warpsim.model import put_model

    p = types_of(precision)
    rng = np.random.default_rng(23)
    boxes, side = random_scene(40, rng)
    grid = broad.build_grid(boxes, 0.35, p.np_dtype)
    model = put_model(boxes, p, "cpu", broad_phase="grid", grid=grid, dt=DT)
    n = 30_000
    span = grid.dims * grid.cell
    mid = grid.lower + rng.uniform(-0.2, 1.2, (n, 3)) * span
    far = rng.random((n, 3)) < 0.05
    mid = np.where(far, grid.lower + rng.choice([-1e3, 1e3], (n, 3)) * span, mid)
    border = rng.random((n, 3)) < 0.3
    mid = np.where(border, grid.lower + np.round((mid - grid.lower) / grid.cell) * grid.cell,
                   mid)
    half = (rng.uniform(0, 1, (n, 3)) * rng.choice([0.0, 0.1, 1.0, 4.0], (n, 1))
            * grid.kernel_margin * rng.choice([-1, 1], (n, 3)))
    grow = rng.uniform(0, 0.5, (n, 3)) * grid.kernel_margin * rng.choice([0.0, 1.0], (n, 1))
    # one end exactly on (or a few ulps either side of) its cell's grown bound on one axis,
    # the path short on the others, its midpoint inside the grid
    dt = p.np_dtype
    edge = np.flatnonzero(rng.random(n) < 0.4)
    mid[edge] = grid.lower + rng.uniform(0.02, 0.98, (edge.size, 3)) * span
    half[edge] *= (0.2 * grid.kernel_margin
                   / np.abs(half[edge]).max(axis=1, keepdims=True).clip(1e-30))
    grow[edge] = rng.uniform(0, 0.1, (edge.size, 3)) * grid.kernel_margin
    a, b = mid - half, mid + half
    axis = rng.integers(0, 3, edge.size)
    m = mid[edge, axis].astype(dt).astype(np.float64)
    lo_g = grid.lower[axis].astype(dt).astype(np.float64)
    cell = grid.cell[axis].astype(dt).astype(np.float64)
    c = np.floor((m - lo_g) / cell)
    cell_lo = lo_g + c * cell
    upper = rng.random(edge.size) < 0.5
    bound = np.where(upper, cell_lo + cell + grid.kernel_margin,
                     cell_lo - grid.kernel_margin)
    ulps = rng.choice([-3, -1, 0, 0, 0, 1, 3], edge.size)
    end = (bound * (1.0 + ulps * np.finfo(dt).eps)
           + np.where(upper, -1.0, 1.0) * grow[edge, axis])
    a[edge, axis] = np.where(upper, 2 * m - end, end)
    b[edge, axis] = np.where(upper, end, 2 * m - end)
    mid[edge, axis] = m
    arrays = [wp.array(x.astype(dt), dtype=p.vec3, device="cpu") for x in (a, b, mid, grow)]
    out = wp.zeros((n, 4), dtype=wp.int32, device="cpu")
    wp.launch(fit_forms_kernel(precision), dim=n, inputs=[model.broad, *arrays, out],
              device="cpu")
    out = out.numpy()
    assert np.array_equal(out[:, 0], out[:, 2]), np.flatnonzero(out[:, 0] != out[:, 2])[:5]
    fits = out[:, 0] == 1
    assert np.array_equal(out[fits, 1], out[fits, 3])
    assert fits.sum() > n // 10 and (~fits).sum() > n // 10
    assert (~fits[edge]).sum() > edge.size // 10 and fits[edge].sum() > edge.size // 10
