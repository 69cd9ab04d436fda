"""``event_capacity`` is the most contact rows a run keeps: the earliest by frame, then sphere,
the same rows whatever the number of workers and the frames per launch; the rest are counted.

The independent answer is the complete table of the same run (a capacity above every contact),
cut to its first rows; undoing a launch that overflowed must change nothing of the run.
"""

import numpy as np
import pytest

import warpsim as ws
from warpsim import simulator as simulator_module

FRAMES = 12


@pytest.fixture(scope="module")
def thin_walls():
    scene = ws.Scene.load("thin-walls")
    return scene, scene.spawn(n=300, seed=2)


@pytest.fixture(scope="module")
def complete(thin_walls):
    scene, swarm = thin_walls
    sim = ws.Simulator(scene, swarm, workers=1, device="cpu")
    traj = sim.run(FRAMES, every=3, events=True, event_capacity=10**7)
    assert traj.events.dropped == 0
    return traj, sim.stats


def same_rows(kept, full, count):
    for name in ("frame", "sphere", "box", "kind", "fraction", "position", "normal",
                 "normal_speed", "time"):
        assert np.array_equal(getattr(kept, name), getattr(full, name)[:count]), name


@pytest.mark.parametrize("workers", [1, 2, 3])
@pytest.mark.parametrize("launch", [1 << 24, 300 * 3, 300 * 6])  # 1, 4 and 2 launches
@pytest.mark.parametrize("capacity", [1, 37, 50, 500, 1999])
def test_kept_rows_are_the_runs_earliest(thin_walls, complete, monkeypatch, workers, launch,
                                         capacity):
    scene, swarm = thin_walls
    full, stats = complete
    monkeypatch.setattr(simulator_module, "LAUNCH_SPHERE_FRAMES", launch)
    sim = ws.Simulator(scene, swarm, workers=workers, device="cpu")
    traj = sim.run(FRAMES, every=3, events=True, event_capacity=capacity)
    ev, total = traj.events, len(full.events)
    assert total > 1999 or capacity < total  # the sweep covers capacities below the total
    assert len(ev) == min(capacity, total)
    assert ev.dropped == total - len(ev)
    same_rows(ev, full.events, len(ev))
    # an undone launch leaves nothing behind: the same frames and counters as the full run
    assert np.array_equal(traj.position, full.position)
    assert np.array_equal(traj.orientation, full.orientation)
    assert sim.stats.bounces == stats.bounces and sim.stats.capped == stats.capped


def test_no_room_counts_every_contact(thin_walls, complete):
    """Once the capacity is reached, later launches keep nothing and still count."""
    scene, swarm = thin_walls
    full, _ = complete
    sim = ws.Simulator(scene, swarm, workers=2, device="cpu")
    sim.run(FRAMES, every=3, events=True, event_capacity=5)
    again = sim.run(FRAMES, every=3, events=True, event_capacity=5).events
    assert len(again) == 5 and len(again) + again.dropped == sim.stats.bounces - len(full.events)
