"""The BVH broad phase against brute force: bit-identical results, the same tie rule.

Both broad phases feed the same per-box step (``sweep_box_world``) and keep the smallest ``t``
with ties to the lower box index, and the BVH's bounds contain the per-box reject's, so every
output must be equal bit for bit, not merely close. The scenes are built to stress that:
overlapping and abutting rotated rounded boxes, zero-extent plates, exact duplicates (equal
``t`` on two boxes: the lower index must win in both), spheres starting inside boxes, and the
same scene 1e4 m from the origin (float32 bounds a few ulps from the reject's).

Kernel variants compiled here (most are shared with other tests): the collide kernel for
float32 and float64, brute and BVH; the default bounce kernel, brute and BVH; the galton
scene's frame kernel (float32, lossy), brute and BVH, also used for the K = 0 checks.
"""

import numpy as np
import pytest

import warpsim as ws
from warpsim.device import BVH_MIN_BOXES, BVH_MIN_BOXES_FLOAT64, bvh_bounds, bvh_min_boxes
from warpsim.kernels.nearest import REJECT_SLACK

DT = 1.0 / 60.0
CONTACT_FIELDS = ("hit", "t", "position", "normal", "new_position", "new_velocity", "box")
STATE_FIELDS = ("position", "velocity", "energy", "angular_momentum", "orientation")


def random_rotations(rng: np.random.Generator, k: int) -> np.ndarray:
    q = rng.normal(size=(k, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def crowded_scene(k: int, rng: np.random.Generator, offset: float = 0.0):
    """``k`` boxes packed so they overlap and abut: rotated rounded boxes, zero-thickness
    plates (sharp and rounded), a row of axis-aligned boxes sharing faces, and exact
    duplicates of earlier boxes at the end.

    Returns:
        ``(boxes, region half size [m], indices of the duplicates, their originals)``.
    """
    n_dup = k // 10
    n_row = k // 10
    n_free = k - n_dup - n_row
    half_region = 0.5 * (0.5 * k) ** (1 / 3)  # one box per 0.5 m^3: they overlap
    center = rng.uniform(-half_region, half_region, size=(n_free, 3))
    half = rng.uniform(0.05, 0.5, size=(n_free, 3))
    kind = np.arange(n_free) % 4
    half[kind == 2, 1] = 0.0  # sharp plates
    half[kind == 3] *= np.array([1.0, 0.0, 0.0])  # rounded sticks
    radius = np.where(kind == 0, 0.0, np.where(kind == 1, rng.uniform(0.01, 0.2, n_free),
                                               np.where(kind == 2, 0.0, 0.05)))
    rotation = random_rotations(rng, n_free)
    # abutting: face to face along x, 0.4 m cubes from the region's corner
    row_center = np.column_stack([-half_region + 0.2 + 0.4 * np.arange(n_row),
                                  np.zeros(n_row), np.zeros(n_row)])
    row_half = np.full((n_row, 3), 0.2)
    base = ws.RoundedBoxes.concatenate([
        ws.RoundedBoxes(center, half, rotation, radius),
        ws.RoundedBoxes(row_center, row_half)])
    original = rng.choice(len(base), size=n_dup, replace=False)
    dup = ws.RoundedBoxes(base.center[original], base.half_extents[original],
                          base.rotation[original], base.radius[original])
    boxes = ws.RoundedBoxes.concatenate([base, dup])
    moved = ws.RoundedBoxes(boxes.center + offset, boxes.half_extents, boxes.rotation,
                            boxes.radius)
    return moved, half_region, len(base) + np.arange(n_dup), original


def swarm_inputs(n: int, half_region: float, rng: np.random.Generator, offset: float = 0.0):
    """Spheres anywhere in the region (some start inside boxes), paths up to 1.5 m a frame,
    radii from 0; the last one is far from every box."""
    position = rng.uniform(-half_region - 0.5, half_region + 0.5, size=(n, 3))
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    velocity = direction * rng.uniform(0.5, 90.0, size=(n, 1))
    radius = rng.uniform(0.0, 0.1, size=n)
    radius[::7] = 0.0
    position[-1] = 1e3
    return position + offset, velocity, radius


def assert_same(a, b, fields):
    for name in fields:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("offset", [0.0, 1e4], ids=["origin", "far"])
@pytest.mark.parametrize("k", [50, 300])
def test_collide_boxes_bvh_is_bit_identical(device, k, offset, precision):
    rng = np.random.default_rng([k, int(offset)])
    boxes, half_region, dup, original = crowded_scene(k, rng, offset)
    pos, vel, rad = swarm_inputs(3000, half_region, rng, offset)
    brute = ws.collide_boxes(pos, vel, rad, boxes, DT, precision=precision, device=device,
                             broad_phase="brute")
    bvh = ws.collide_boxes(pos, vel, rad, boxes, DT, precision=precision, device=device,
                           broad_phase="bvh")
    assert_same(brute, bvh, CONTACT_FIELDS)
    assert 0.1 < brute.hit.mean() < 0.95  # a crowded scene, not a trivial one
    assert bvh.box[-1] == -1  # the far sphere
    # ties: a duplicate has the same t as its original, lower index, so it never wins
    assert not np.isin(bvh.box, dup).any()
    assert np.isin(bvh.box, original).sum() > 10
    auto = ws.collide_boxes(pos, vel, rad, boxes, DT, precision=precision, device=device)
    assert_same(brute, auto, CONTACT_FIELDS)


def test_bounce_bvh_is_bit_identical(device):
    rng = np.random.default_rng(3)
    boxes, half_region, _, _ = crowded_scene(120, rng)
    pos, vel, rad = swarm_inputs(2000, half_region, rng)
    brute = ws.bounce(pos, vel, rad, boxes, DT, device=device, broad_phase="brute")
    bvh = ws.bounce(pos, vel, rad, boxes, DT, device=device, broad_phase="bvh")
    assert_same(brute, bvh, ("hit", "bounces", "capped", "position", "velocity",
                             "angular_momentum"))
    assert brute.bounces.max() >= 2


@pytest.mark.slow
def test_simulator_galton_bvh_is_bit_identical(device):
    scene = ws.Scene.load("galton")
    assert len(scene.boxes) >= BVH_MIN_BOXES
    swarm = scene.spawn(n=1000, seed=1)
    sims = {bp: ws.Simulator(scene, swarm, device=device, broad_phase=bp)
            for bp in ("brute", "bvh", "grid", "auto")}
    assert {bp: s.broad_phase for bp, s in sims.items() if bp != "auto"} == {
        "brute": "brute", "bvh": "bvh", "grid": "grid-bvh"}
    for sim in sims.values():
        sim.step(30)
    brute, bvh = sims["brute"], sims["bvh"]
    assert_same(brute.state(), bvh.state(), STATE_FIELDS)
    assert_same(brute.state(), sims["grid"].state(), STATE_FIELDS)
    assert_same(brute.state(), sims["auto"].state(), STATE_FIELDS)
    assert brute.stats.bounces == bvh.stats.bounces > 0
    assert brute.stats.capped == bvh.stats.capped


def test_auto_keeps_brute_force_for_few_boxes(device):
    """Boxes piled in one place: a grid cell near them lists them all, so it buys nothing."""
    boxes = ws.RoundedBoxes(np.zeros((3, 3)), np.full((3, 3), 0.1))
    swarm = ws.Swarm([[0.0, 1.0, 0.0]], [[0.0, 0.0, 0.0]], 0.05)
    assert ws.Simulator(ws.Scene(boxes), swarm, device=device).broad_phase == "brute"


def test_exhaustive_takes_the_bvh_from_each_precisions_measured_count():
    """Without a grid the BVH replaces brute force from 32 boxes in float32 and from 20 in
    float64 (where a box's reject costs more against the BVH's traversal), for every box
    count; in float64 the model's BVH costs no more than brute force exactly from 20 boxes
    on (its fixed cost is set so), so the model and the switch agree there, and each
    method's cost grows with the boxes."""
    from warpsim import broad_phase as broad

    assert (BVH_MIN_BOXES, BVH_MIN_BOXES_FLOAT64) == (32, 20)
    assert bvh_min_boxes(np.float32) == bvh_min_boxes("float32") == BVH_MIN_BOXES
    assert bvh_min_boxes(np.float64) == bvh_min_boxes("float64") == BVH_MIN_BOXES_FLOAT64
    for dtype, edge in ((np.float32, 32), (np.float64, 20)):
        costs = []
        for k in range(0, 200):
            method, cost = broad.exhaustive(k, dtype)
            assert method == ("bvh" if k >= edge else "brute"), (dtype, k)
            assert cost > 0.0
            costs.append((method, cost))
        for (m0, c0), (m1, c1) in zip(costs[:-1], costs[1:], strict=True):
            if m0 == m1:
                assert c1 > c0
    assert broad.exhaustive(40) == broad.exhaustive(40, np.float32)
    brute = [broad.BRUTE_FIXED + k for k in range(1, 200)]
    tree = [broad.BVH_FIXED_FLOAT64 + broad.BVH_PER_LEVEL * np.log2(k) for k in range(1, 200)]
    cheaper = [k for k, (b, t) in enumerate(zip(brute, tree, strict=True), start=1)
               if t <= b + 1e-12]
    assert cheaper == list(range(BVH_MIN_BOXES_FLOAT64, 200))


@pytest.mark.parametrize("k", [19, 20, 31, 32])
def test_the_grids_fallback_follows_the_precision(k):
    """``"grid"`` falls back to the exhaustive method of the kernels' precision: the BVH
    (``grid-bvh``) from 20 boxes in float64 and from 32 in float32."""
    from warpsim import broad_phase as broad

    rng = np.random.default_rng(k)
    boxes = ws.RoundedBoxes(rng.uniform(-30.0, 30.0, (k, 3)), rng.uniform(0.1, 1.0, (k, 3)),
                            rotation=random_rotations(rng, k))
    position = rng.uniform(-30.0, 30.0, (200, 3))
    frame = broad.paths(position, rng.normal(size=(200, 3)), np.full(200, 0.05),
                        (0.0, -9.81, 0.0), DT, boxes)
    for dtype in (np.float32, np.float64):
        name, grid = broad.choose("grid", boxes, frame, dtype)
        assert grid is not None
        assert name == ("grid-bvh" if k >= bvh_min_boxes(dtype) else "grid"), (k, dtype)
        assert broad.choose("auto", boxes, frame, dtype, queries=1) == (
            broad.exhaustive(k, dtype)[0], None)


def test_the_bundled_scenes_take_the_measured_method_per_precision():
    """``auto``'s choices where the precision changes them: the standard room (22 boxes)
    takes the grid with brute force as its fallback in float32 and with the BVH in float64;
    ``thin-walls`` (16 boxes, 200 to 400 m/s) keeps brute force in both (BENCHMARKS.md,
    "float64: brute force's loop in registers")."""
    for name, want in (("room", {"float32": "grid", "float64": "grid-bvh"}),
                       ("thin-walls", {"float32": "brute", "float64": "brute"})):
        scene = ws.Scene.load(name)
        swarm = scene.spawn(n=500, seed=4)
        got = {precision: ws.Simulator(scene, swarm, precision=precision,
                                       device="cpu").broad_phase
               for precision in ("float32", "float64")}
        assert got == want, name


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_float64_brute_force_keeps_the_bvhs_bits_among_thin_walls(device, motion):
    """Brute force's float64 loop (the branch-free reject, the normal in registers) against
    the BVH among ``thin-walls``' zero-thickness plates at 200 to 400 m/s: the same bits and
    bounce counts, and no sphere leaves its cell."""
    scene = ws.Scene.load("thin-walls")
    swarm = scene.spawn(n=300, seed=4)
    sims = {bp: ws.Simulator(scene, swarm, precision="float64", motion=motion, device=device,
                             broad_phase=bp) for bp in ("brute", "bvh")}
    for sim in sims.values():
        sim.step(20)
    brute, bvh = sims["brute"], sims["bvh"]
    assert_same(brute.state(), bvh.state(), STATE_FIELDS)
    assert brute.stats.bounces == bvh.stats.bounces > 1000
    start, end = np.sign(swarm.position[:, :2]), np.sign(brute.state().position[:, :2])
    assert np.array_equal(start, end)


@pytest.mark.parametrize("k", [0, 1, 2, 3])
@pytest.mark.parametrize("seed", range(4))
def test_auto_takes_the_models_choice_without_grids_where_none_can_win(k, seed, monkeypatch):
    """``auto`` picks what the cost model picks over every option (``preferred`` of
    ``estimates``); for a box or two no grid can cost less than the exhaustive method by the
    model's floors, and none is built (a call for a few spheres then costs no grid)."""
    from warpsim import broad_phase as broad

    assert broad.GRID_FIXED <= broad.WALK_FIXED + broad.WALK_PER_CELL  # the floors compared
    rng = np.random.default_rng(seed)
    if seed < 2:  # boxes piled near the spheres, at any speed
        boxes = ws.RoundedBoxes(rng.uniform(-2.0, 2.0, (k, 3)), rng.uniform(0.0, 0.5, (k, 3)),
                                rotation=random_rotations(rng, k),
                                radius=rng.uniform(0.0, 0.1, k))
        position = rng.uniform(-3.0, 3.0, (50, 3)) + [0.0, 5.0, 0.0]
        velocity = rng.normal(size=(50, 3)) * 10.0 ** rng.uniform(-1.0, 2.0)
    else:  # boxes 40 m apart in a row, slow spheres between them: a grid pays from 3 boxes
        centers = np.array([[-40.0, 0.0, 0.0], [0.0, 0.0, 0.0], [40.0, 0.0, 0.0]])[:k]
        boxes = ws.RoundedBoxes(centers + rng.uniform(-1.0, 1.0, (k, 3)),
                                np.tile([0.5, 2.0, 2.0], (k, 1)))
        position = np.column_stack([rng.uniform(-38.0, 38.0, 50),
                                    rng.uniform(-1.5, 1.5, (50, 2))])
        position[np.abs(position[:, 0]) < 2.0, 0] += 10.0
        velocity = rng.normal(size=(50, 3)) * 0.5
    frame = broad.paths(position, velocity, np.full(50, 0.05), (0.0, -9.81, 0.0), DT, boxes)
    expected = broad.preferred(broad.estimates(boxes, frame))
    if k <= 2:
        def refused(*args, **kwargs):
            raise AssertionError("a grid was built")

        monkeypatch.setattr(broad, "build_grid", refused)
        monkeypatch.setattr(broad, "build_walk_grid", refused)
    name, grid = broad.choose("auto", boxes, frame)
    assert name == expected
    if k == 3 and seed >= 2:
        assert name == "grid"  # the case where the model's grid wins
    assert (grid is None) == (name in ("brute", "bvh"))


@pytest.mark.parametrize("k", [22, 300])
def test_auto_builds_no_grid_for_a_launch_cheaper_than_building_one(k, monkeypatch):
    """Given the launch's number of queries, ``auto`` takes the exhaustive method without
    building a grid exactly when those queries cost at most ``GRID_BUILD`` by the model, and
    the cost model's choice otherwise (as without a count); ``collide_boxes`` and ``bounce``
    pass their sphere count, and give the exhaustive method's results bit for bit."""
    from warpsim import broad_phase as broad

    rng = np.random.default_rng(k)
    boxes = ws.RoundedBoxes(rng.uniform(-20.0, 20.0, (k, 3)), rng.uniform(0.1, 1.0, (k, 3)),
                            rotation=random_rotations(rng, k))
    n = 200
    position = rng.uniform(-20.0, 20.0, (n, 3))
    velocity = rng.normal(size=(n, 3))
    frame = broad.paths(position, velocity, np.full(n, 0.05), (0.0, 0.0, 0.0), DT, boxes)
    method, cost = broad.exhaustive(k)
    expected = broad.preferred(broad.estimates(boxes, frame))
    assert expected != method  # spread boxes, slow spheres: a grid pays per query
    edge = int(broad.GRID_BUILD // cost)
    for queries in (None, edge + 1, 10 * edge):
        assert broad.choose("auto", boxes, frame, queries=queries)[0] == expected

    def refused(*args, **kwargs):
        raise AssertionError("a grid was built")

    monkeypatch.setattr(broad, "build_grid", refused)
    monkeypatch.setattr(broad, "build_walk_grid", refused)
    for queries in (1, n, edge):
        assert broad.choose("auto", boxes, frame, queries=queries) == (method, None)
    with pytest.raises(AssertionError, match="a grid was built"):
        broad.choose("auto", boxes, frame)
    got = ws.collide_boxes(position, velocity, 0.05, boxes, DT, device="cpu")
    want = ws.collide_boxes(position, velocity, 0.05, boxes, DT, device="cpu",
                            broad_phase=method)
    for field in ("box", "t", "position", "normal", "new_position", "new_velocity"):
        assert getattr(got, field).tobytes() == getattr(want, field).tobytes(), field
    ws.bounce(position, velocity, 0.05, boxes, DT, device="cpu")


@pytest.mark.parametrize("broad_phase", ["brute", "bvh", "auto"])
def test_no_boxes(device, broad_phase):
    empty = ws.RoundedBoxes(np.zeros((0, 3)), np.zeros((0, 3)))
    pos = np.array([[0.0, 1.0, 0.0], [2.0, 0.0, -1.0]])
    vel = np.array([[1.0, 0.0, 0.0], [0.0, -3.0, 0.0]])
    c = ws.collide_boxes(pos, vel, 0.1, empty, DT, device=device, broad_phase=broad_phase)
    assert (c.box == -1).all() and (c.t == 1.0).all()
    lossy = ws.Scene(empty, energy_retention=0.5)  # the galton test's kernels: no new builds
    sim = ws.Simulator(lossy, ws.Swarm(pos, vel, 0.1), device=device, broad_phase=broad_phase)
    sim.step(2)
    assert np.isfinite(sim.state().position).all()


def test_bad_broad_phase_is_refused(device):
    box = ws.RoundedBox()
    swarm = ws.Swarm([[0.0, 2.0, 0.0]], [[0.0, 0.0, 0.0]], 0.05)
    with pytest.raises(ValueError, match="broad_phase"):
        ws.collide_boxes([[0.0, 2.0, 0.0]], [[0.0, -1.0, 0.0]], 0.1, box, DT, broad_phase="bhv",
                         device=device)
    with pytest.raises(ValueError, match="broad_phase"):
        ws.bounce([[0.0, 2.0, 0.0]], [[0.0, -1.0, 0.0]], 0.1, box, DT, broad_phase=None,
                  device=device)
    with pytest.raises(ValueError, match="broad_phase"):
        ws.Simulator(ws.Scene(box.as_boxes()), swarm, device=device, broad_phase="octree")


@pytest.mark.parametrize("scale", [1.0, 1e4, 1e-3])
def test_bvh_bounds_hold_the_reject_bounds(scale):
    """float32 bounds contain ``center +- extent (1 + REJECT_SLACK)``, exactly (no rounding in)."""
    rng = np.random.default_rng(5)
    center = rng.normal(size=(500, 3)) * scale
    extent = rng.uniform(0.0, 1.0, size=(500, 3)) * scale
    extent[::5] = 0.0
    for dtype in (np.float32, np.float64):
        c, e = center.astype(dtype), extent.astype(dtype)
        lower, upper = bvh_bounds(c, e)
        assert lower.dtype == upper.dtype == np.float32
        reach = e.astype(np.float64) * (1.0 + REJECT_SLACK)
        assert (lower.astype(np.float64) < c.astype(np.float64) - reach).all()
        assert (upper.astype(np.float64) > c.astype(np.float64) + reach).all()


def query_box_counts(boxes: ws.RoundedBoxes, pos, vel, rad, dt: float) -> np.ndarray:
    """How many boxes' BVH bounds a straight path's query box overlaps (float64, the query
    box of ``candidates.bvh_box`` without its rounding pad): what one query returns."""
    lower, upper = bvh_bounds(boxes.center, boxes.world_extent())
    end = pos + vel * dt
    grow = (rad * (1.0 + REJECT_SLACK))[:, None]
    lo, hi = np.minimum(pos, end) - grow, np.maximum(pos, end) + grow
    overlap = ((lo[:, None, :] <= upper[None]) & (hi[:, None, :] >= lower[None])).all(axis=2)
    return overlap.sum(axis=1)


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_bvh_queries_beyond_one_batch_are_bit_identical(device, motion):
    """A BVH query's boxes are gathered in batches of ``BVH_BATCH`` before they are tried; a
    query returning more runs again. Paths through a dense cluster of small boxes return
    fewer, exactly as many and more boxes than a batch: every one keeps brute force's
    contact, bit for bit, ties included (duplicated boxes)."""
    from warpsim.kernels.candidates import BVH_BATCH

    rng = np.random.default_rng(11)
    k = 240
    center = rng.uniform(-0.6, 0.6, size=(k, 3))
    half = rng.uniform(0.01, 0.06, size=(k, 3))
    half[::3, 1] = 0.0  # sharp plates among them
    radius = np.where(np.arange(k) % 2 == 0, 0.0, 0.02)
    base = ws.RoundedBoxes(center, half, random_rotations(rng, k), radius)
    original = rng.choice(k, size=20, replace=False)
    boxes = ws.RoundedBoxes.concatenate([base, ws.RoundedBoxes(
        center[original], half[original], base.rotation[original], radius[original])])
    n = 4000
    pos = rng.uniform(-1.0, 1.0, size=(n, 3))
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    vel = direction * rng.uniform(1.0, 120.0, size=(n, 1))  # paths of 1.7 cm to 2 m
    rad = rng.uniform(0.0, 0.03, size=n)
    counts = query_box_counts(boxes, pos, vel, rad, DT)
    assert (counts == BVH_BATCH).sum() >= 5
    assert ((counts > 0) & (counts < BVH_BATCH)).sum() >= 200
    assert (counts > BVH_BATCH).sum() >= 200
    gravity = (0.0, -9.81, 0.0) if motion == "ballistic" else None
    brute = ws.collide_boxes(pos, vel, rad, boxes, DT, device=device, broad_phase="brute",
                             motion=motion, gravity=gravity)
    bvh = ws.collide_boxes(pos, vel, rad, boxes, DT, device=device, broad_phase="bvh",
                           motion=motion, gravity=gravity)
    assert_same(brute, bvh, CONTACT_FIELDS)
    for few in (counts < BVH_BATCH, counts > BVH_BATCH):  # contacts on both sides of a batch
        assert brute.hit[few].sum() >= 100
    assert not np.isin(bvh.box, k + np.arange(len(original))).any()  # ties: the lower index
    if motion == "linear":
        bounced = ws.bounce(pos, vel, rad, boxes, DT, device=device, broad_phase="bvh")
        exhaustive = ws.bounce(pos, vel, rad, boxes, DT, device=device, broad_phase="brute")
        assert_same(exhaustive, bounced, ("hit", "bounces", "capped", "position",
                                          "velocity", "angular_momentum"))
        assert exhaustive.bounces.max() >= 2
