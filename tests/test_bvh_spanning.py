"""Boxes that span the scene (a room's walls) kept out of the BVH's tree and tried before each
query where the BVH is the broad phase (``broad_phase.tree_split``): which boxes are kept
out, and the bits of every broad phase that queries a tree (``"bvh"``, and ``"grid-bvh"`` and
``"walk-bvh"``, whose tree holds every box, but whose supports leave through the same loop)
against brute force, ties, batches beyond ``BVH_BATCH`` and the ballistic supports (the
support left is a wall) included."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_broad_phase import (
    CONTACT_FIELDS,
    DT,
    STATE_FIELDS,
    assert_same,
    query_box_counts,
    random_rotations,
)

import warpsim as ws
from warpsim import broad_phase as broad
from warpsim.device import BVH_MIN_BOXES

WALL = 0.05  # half thickness [m]


def shares(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Each box's extent over the scene's, per axis (1 along an axis the scene is flat on)."""
    span = upper.max(axis=0) - lower.min(axis=0)
    out = np.ones_like(lower)
    np.divide(upper - lower, span, out=out, where=span > 0)
    return out


@settings(max_examples=200, deadline=None)
@given(st.integers(0, 40), st.integers(0, 2**32 - 1))
def test_tree_split_keeps_out_the_widest_boxes_and_never_empties_the_tree(k, seed):
    """Over random scenes of slabs, rods and small boxes (some flat on an axis): the two
    lists partition the boxes, ascending; a kept-out box spans over ``SPANNING_SHARE`` of the
    scene along two axes, and a box left in the tree does not, unless ``SPANNING_MAX`` boxes
    wider than it (by the product of their two largest shares) are out already, or every box
    spans (then none is kept out)."""
    rng = np.random.default_rng(seed)
    center = rng.uniform(-5.0, 5.0, size=(k, 3))
    half = rng.choice([0.0, 0.01, 0.5, 3.0, 8.0], size=(k, 3))
    if rng.random() < 0.2:
        half[:, 1] = 0.0
        center[:, 1] = 1.0  # a flat scene: y spanned by every box
    lower, upper = center - half, center + half
    spanning, tree = broad.tree_split(lower, upper)
    assert spanning.dtype == tree.dtype == np.int32
    assert np.array_equal(np.sort(np.concatenate([spanning, tree])), np.arange(k))
    assert np.all(np.diff(spanning) > 0) and np.all(np.diff(tree) > 0)
    if k == 0:
        return
    assert tree.size > 0
    two = np.sort(shares(lower, upper), axis=1)[:, 1:]
    wide = two[:, 0] > broad.SPANNING_SHARE
    assert wide[spanning].all()
    assert spanning.size <= broad.SPANNING_MAX
    left_wide = tree[wide[tree]]
    if left_wide.size and spanning.size:
        width = two[:, 0] * two[:, 1]
        assert spanning.size == broad.SPANNING_MAX
        assert width[left_wide].max() <= width[spanning].min()
    elif left_wide.size:
        assert wide.all()  # every box spans: one tree over them all


def test_tree_split_of_the_standard_room_keeps_out_its_six_walls():
    from warpsim.device import bvh_bounds

    boxes = ws.Scene.load("room").boxes
    lower, upper = bvh_bounds(boxes.center.astype(np.float32),
                              boxes.world_extent().astype(np.float32))
    spanning, tree = broad.tree_split(lower, upper)
    assert spanning.tolist() == list(range(6)) and tree.tolist() == list(range(6, 22))


def walled(boxes: ws.RoundedBoxes, half: float, extra_walls: int = 0) -> ws.RoundedBoxes:
    """``boxes`` inside six walls at ``+-half`` (the walls first), then ``extra_walls`` slabs
    across the room (duplicates of the floor, raised: spanning boxes beyond the six), then
    exact duplicates of the floor and of a side wall (ties with spanning boxes)."""
    h, w = half + WALL, WALL
    walls = ws.RoundedBoxes(
        [(0, -h, 0), (0, h, 0), (-h, 0, 0), (h, 0, 0), (0, 0, -h), (0, 0, h)],
        [(h + w, w, h + w)] * 2 + [(w, h + w, h + w)] * 2 + [(h + w, h + w, w)] * 2)
    y = np.linspace(-0.8 * half, 0.8 * half, extra_walls)
    slabs = ws.RoundedBoxes(np.column_stack([np.zeros(extra_walls), y, np.zeros(extra_walls)]),
                            np.tile((h, 0.0, h), (extra_walls, 1)),
                            radius=np.full(extra_walls, 0.01))
    ties = ws.RoundedBoxes(walls.center[[0, 2]], walls.half_extents[[0, 2]])
    return ws.RoundedBoxes.concatenate([walls, boxes, slabs, ties])


@pytest.mark.parametrize("extra_walls", [0, 14], ids=["six-walls", "over-the-cap"])
@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_walls_out_of_the_tree_keep_brute_forces_bits(device, precision, motion, extra_walls):
    """A dense cluster of small boxes inside walls (and, over the cap, 14 slabs across the
    room: 22 spanning boxes, 16 kept out and the rest in the tree), duplicated walls for
    ties: the BVH's contacts are brute force's, bit for bit, for queries with fewer, as many
    and more boxes than a batch with the kept-out boxes counted in."""
    from warpsim.kernels.candidates import BVH_BATCH

    rng = np.random.default_rng([7, extra_walls])
    k = 240
    center = rng.uniform(-0.6, 0.6, size=(k, 3))
    half = rng.uniform(0.01, 0.06, size=(k, 3))
    half[::3, 1] = 0.0
    radius = np.where(np.arange(k) % 2 == 0, 0.0, 0.02)
    boxes = walled(ws.RoundedBoxes(center, half, random_rotations(rng, k), radius), 1.0,
                   extra_walls)
    from warpsim.device import bvh_bounds

    lower, upper = bvh_bounds(boxes.center.astype(np.float32),
                              boxes.world_extent().astype(np.float32))
    spanning, _ = broad.tree_split(lower, upper)
    assert spanning.size == min(8 + extra_walls, broad.SPANNING_MAX)
    n = 4000
    pos = rng.uniform(-0.95, 0.95, size=(n, 3))
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    vel = direction * rng.uniform(1.0, 120.0, size=(n, 1))
    rad = rng.uniform(0.0, 0.03, size=n)
    tried = query_box_counts(boxes, pos, vel, rad, DT)  # every box the reject lets through
    assert ((tried > 0) & (tried < BVH_BATCH)).sum() >= 200 and (tried > BVH_BATCH).sum() >= 200
    gravity = (0.0, -9.81, 0.0) if motion == "ballistic" else None
    runs = {bp: ws.collide_boxes(pos, vel, rad, boxes, DT, precision=precision, device=device,
                                 broad_phase=bp, motion=motion, gravity=gravity)
            for bp in ("brute", "bvh")}
    assert_same(runs["brute"], runs["bvh"], CONTACT_FIELDS)
    walls_hit = np.isin(runs["bvh"].box, spanning)
    assert walls_hit.sum() >= 50 and (runs["bvh"].hit & ~walls_hit).sum() >= 200
    assert not np.isin(runs["bvh"].box, len(boxes) - 2 + np.arange(2)).any()  # ties: lower
    if motion == "linear":
        bounced = {bp: ws.bounce(pos, vel, rad, boxes, DT, precision=precision, device=device,
                                 broad_phase=bp) for bp in ("brute", "bvh")}
        assert_same(bounced["brute"], bounced["bvh"], ("hit", "bounces", "capped", "position",
                                                       "velocity", "angular_momentum"))


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_a_walled_room_runs_the_same_bits_through_every_tree_query(device, precision, motion):
    """A room of 42 plates within its six walls (``benchmarks.speed``'s grown room), its
    spheres thrown down so that they bounce off the floor and, ballistic, come to rest and
    slide on it (a support left on a kept-out box): ``"bvh"``, the grid and the walk (each
    falling back to the BVH) advance the swarm to brute force's bits."""
    from benchmarks.speed import grown_room

    scene = grown_room(48, 600, np.random.default_rng(5))
    assert len(scene.boxes) >= BVH_MIN_BOXES
    swarm = scene.spawn()
    swarm = ws.Swarm(swarm.position, swarm.velocity * 3.0 + np.array([0.0, -4.0, 0.0]),
                     swarm.radius, swarm.mass)
    scene = ws.Scene(scene.boxes, energy_retention=0.3, friction=0.05, name="walled")
    sims = {bp: ws.Simulator(scene, swarm, precision=precision, motion=motion, device=device,
                             broad_phase=bp, workers=1) for bp in ("brute", "bvh", "grid", "walk")}
    assert {bp: s.broad_phase for bp, s in sims.items()} == {
        "brute": "brute", "bvh": "bvh", "grid": "grid-bvh", "walk": "walk-bvh"}
    for sim in sims.values():
        sim.step(90)
    for bp in ("bvh", "grid", "walk"):
        assert_same(sims["brute"].state(), sims[bp].state(), STATE_FIELDS)
        assert sims[bp].stats.bounces == sims["brute"].stats.bounces > 0
    if motion == "ballistic":
        assert sims["brute"].stats.supports > 0
