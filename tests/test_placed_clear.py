"""A swarm an emitter placed outside a scene's obstacles is not checked again by a simulator of
that scene (``feasibility.check_outside``, a nearest-box query of every sphere: a fifth of the
set-up of a large swarm); anything that could have put a sphere inside a box since is.

The skip is sound only if the placement really is outside: that is tested here against the
signed distances of the boxes (``RoundedBoxes.signed_distance``, float64), for every bundled
scene with an emitter and for the sharded draw."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import warpsim as ws
from warpsim import feasibility
from warpsim.distributed import draw
from warpsim.validation import frozen

EMITTING = ("room", "plates", "pinball", "thin-walls", "nozzle", "staircase")


@pytest.fixture
def checks(monkeypatch):
    """The calls of ``feasibility.check_outside`` (each still runs)."""
    calls = []
    real = feasibility.check_outside

    def counted(*args, **kwargs):
        calls.append(args)
        return real(*args, **kwargs)

    monkeypatch.setattr(feasibility, "check_outside", counted)
    return calls


def _outside(boxes, swarm) -> bool:
    """Every sphere's signed distance to every box at least its radius (float64)."""
    distance = boxes.signed_distance(swarm.position)  # (N, K)
    return bool(np.all(distance >= swarm.radius[:, None]))


@pytest.mark.parametrize("name", EMITTING)
def test_an_emitters_swarm_is_outside_and_not_checked_again(name, checks):
    scene = ws.Scene.load(name)
    swarms = [scene.spawn(n=300, seed=3),
              *scene.spawn_many([40, 7], [1, 2]),
              draw.sharded_spawn(scene, n=700, seed=5, block=128),
              draw.shard_swarm(scene, 700, 5, 256, 700, block=128)]
    for swarm in swarms:
        assert _outside(scene.boxes, swarm)
        before = len(checks)
        ws.Simulator(scene, swarm, device="cpu")
        assert len(checks) == before


def test_another_scene_with_equal_boxes_needs_no_check(checks):
    """Equal values in another ``RoundedBoxes`` object: the same obstacles, not checked."""
    scene = ws.Scene.load("room")
    swarm = scene.spawn(n=200, seed=1)
    again = ws.Scene.load("room")
    ws.Simulator(again, swarm, device="cpu")
    assert not checks


def test_a_box_over_a_sphere_in_another_scene_is_refused(checks):
    scene = ws.Scene.load("room")
    swarm = scene.spawn(n=200, seed=1)
    over = ws.RoundedBoxes(swarm.position[17:18], [[0.3, 0.3, 0.3]])
    crowded = ws.Scene(ws.RoundedBoxes.concatenate([scene.boxes, over]),
                       gravity=scene.gravity)
    with pytest.raises(ValueError, match=r"^sphere 17 starts .* inside box 22"):
        ws.Simulator(crowded, swarm, device="cpu")


def test_a_sphere_moved_in_place_into_a_box_is_refused(checks):
    """The position array made writable again and one sphere moved into a box: the digest no
    longer matches, so the simulator checks and names that sphere, read-only again or not."""
    scene = ws.Scene.load("room")
    swarm = scene.spawn(n=200, seed=1)
    swarm.position.setflags(write=True)
    swarm.position[42] = scene.boxes.center[7]
    with pytest.raises(ValueError, match=r"^sphere 42 starts .* inside box 7"):
        ws.Simulator(scene, swarm, device="cpu")
    swarm.position.setflags(write=False)
    with pytest.raises(ValueError, match=r"^sphere 42 starts"):
        ws.Simulator(scene, swarm, device="cpu")


@pytest.mark.parametrize("field", ["position", "radius"])
def test_replaced_spheres_are_checked(field, checks):
    scene = ws.Scene.load("room")
    swarm = scene.spawn(n=200, seed=1)
    grown = (np.full(len(swarm), 5.0) if field == "radius"
             else np.repeat(scene.boxes.center[3:4], len(swarm), axis=0))
    setattr(swarm, field, frozen(grown))
    with pytest.raises(ValueError, match=r"^sphere 0 starts"):
        ws.Simulator(scene, swarm, device="cpu")


def test_a_box_moved_in_place_is_checked(checks):
    """The scene's own boxes changed after the draw (an array made writable, or replaced):
    checked, and the sphere now inside is named."""
    scene = ws.Scene.load("room")
    swarm = scene.spawn(n=200, seed=1)
    scene.boxes.center.setflags(write=True)
    scene.boxes.center[7] = swarm.position[9]
    scene.boxes.center.setflags(write=False)
    with pytest.raises(ValueError, match=r"^sphere 9 starts .* inside box 7"):
        ws.Simulator(scene, swarm, device="cpu")
    fresh = ws.Scene.load("room")
    swarm = fresh.spawn(n=200, seed=1)
    half = fresh.boxes.half_extents.copy()
    half[7] = 50.0
    fresh.boxes.half_extents = frozen(half)
    with pytest.raises(ValueError, match=r"^sphere 0 starts .* inside box 7"):
        ws.Simulator(fresh, swarm, device="cpu")


def test_a_hand_made_swarm_is_checked(checks):
    scene = ws.Scene.load("room")
    placed = scene.spawn(n=50, seed=1)
    swarm = ws.Swarm(placed.position, placed.velocity, radius=placed.radius)
    ws.Simulator(scene, swarm, device="cpu")
    assert len(checks) == 1


def test_two_spheres_swapped_are_checked(checks):
    """Two spheres' centres swapped in place: every centre is still one the emitter placed,
    but a centre with another sphere's radius is not what the placement vouched for (a
    larger radius may reach into a box), so the order of the rows counts: checked."""
    scene = ws.Scene.load("room")
    emitter = dataclasses.replace(scene.emitter, radius=(0.01, 0.08))
    swarm = emitter.spawn(scene.boxes, n=200, seed=1)
    small, big = int(np.argmin(swarm.radius)), int(np.argmax(swarm.radius))
    assert swarm.radius[small] < swarm.radius[big]
    ws.Simulator(scene, swarm, device="cpu")
    assert not checks
    swarm.position.setflags(write=True)
    swarm.position[[small, big]] = swarm.position[[big, small]]
    swarm.position.setflags(write=False)
    ws.Simulator(scene, swarm, device="cpu")
    assert len(checks) == 1


@pytest.mark.parametrize("name", ["room", "nozzle", "pinball"])
def test_a_joined_draw_is_the_swarms_one_after_the_other(name, checks):
    """``spawn_many(join=True)`` (a sharded draw's blocks) is the concatenation of the swarms
    drawn one by one, bit for bit, births included, placed outside the boxes and marked so
    once for the whole."""
    scene = ws.Scene.load(name)
    counts, seeds = [128, 128, 37], [4, 9, 2]
    apart = scene.spawn_many(counts, seeds)
    (joined,) = scene.spawn_many(counts, seeds, join=True)
    for field in ("position", "velocity", "radius", "mass", "angular_momentum", "orientation",
                  "birth_frame"):
        want = np.concatenate([getattr(s, field) for s in apart])
        assert getattr(joined, field).tobytes() == want.tobytes(), field
    assert _outside(scene.boxes, joined)
    before = len(checks)
    ws.Simulator(scene, joined, device="cpu")
    assert len(checks) == before


class ListedEmitter:
    """An emitter of its own (not a ``warpsim.Emitter``): its spheres are checked by the
    scene, and a swarm joined from them is checked again by a simulator."""

    def spawn(self, boxes, n=None, seed=None):
        rng = np.random.default_rng(seed)
        return ws.Swarm(rng.uniform([-1, 1, -1], [1, 2, 1], (n, 3)), np.zeros((n, 3)),
                        radius=0.05)


def test_a_joined_draw_of_another_emitter_is_checked_by_the_simulator(checks):
    room = ws.Scene.load("room")
    scene = ws.Scene(room.boxes, emitter=ListedEmitter(), name="listed")
    apart = scene.spawn_many([20, 30], [1, 2])
    (joined,) = scene.spawn_many([20, 30], [1, 2], join=True)
    assert joined.position.tobytes() == np.concatenate([s.position for s in apart]).tobytes()
    before = len(checks)
    ws.Simulator(scene, joined, device="cpu")
    assert len(checks) == before + 1
