"""The frame kernel's free-flight step (``Features.free_flight``: a frame whose path lies beyond
every box's bounds skips the bounce loop) gives the bounce loop's own bits: the same runs with
the step's kernel, with it but the boxes' overall bounds made infinite (every frame through the
loop) and without it end in the same state, bit for bit."""

import numpy as np
import pytest

import warpsim as ws
from warpsim.kernels.frame_kernel import frame_kernel


def state_bytes(sim: ws.Simulator) -> list[bytes]:
    s = sim.state()
    return [np.ascontiguousarray(a).tobytes() for a in (s.position, s.velocity, s.energy,
                                                         s.angular_momentum, s.orientation)]


def with_step(sim: ws.Simulator, on: bool) -> ws.Simulator:
    """``sim`` running the kernel with (or without) the free-flight step."""
    sim._features = sim._features.but(free_flight=on)
    sim._kernel = frame_kernel(sim._features)
    return sim


def without_free_flight(sim: ws.Simulator) -> ws.Simulator:
    """``sim`` with the boxes' overall bounds infinite: no path is ever beyond them."""
    inf = np.inf
    sim.model.boxes.lower = sim.model.precision.vec3(-inf, -inf, -inf)
    sim.model.boxes.upper = sim.model.precision.vec3(inf, inf, inf)
    return sim


def far_boxes() -> ws.RoundedBoxes:
    """A floor and a wall far apart: paths leave their bounds, and come back."""
    return ws.RoundedBoxes(center=[[0.0, -0.5, 0.0], [6.0, 1.0, 0.0]],
                           half_extents=[[2.0, 0.5, 2.0], [0.1, 1.5, 2.0]], radius=[0.0, 0.05])


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
@pytest.mark.parametrize("scene_name", ["plates", "galton", "far"])
def test_free_flight_step_is_the_bounce_loops_bits(precision, motion, scene_name):
    if scene_name == "far":
        rng = np.random.default_rng(4)
        n = 200
        scene = ws.Scene(far_boxes(), friction=0.5, energy_retention=0.9)
        swarm = ws.Swarm(rng.uniform([-3, 0.2, -1], [3, 4, 1], (n, 3)),
                         rng.uniform(-6, 6, (n, 3)), radius=0.1)
        frames = 120
    else:
        scene = ws.Scene.load(scene_name)
        swarm = scene.spawn(n=200, seed=11)
        frames = 90
    sims = [ws.Simulator(scene, swarm, precision=precision, motion=motion, device="cpu")
            for _ in range(3)]
    if scene_name == "far":  # spheres start beyond the boxes' bounds: the step is built in
        assert sims[0]._features.free_flight
    with_step(sims[0], True)
    without_free_flight(with_step(sims[1], True))
    with_step(sims[2], False)
    for sim in sims:
        sim.step(frames)
    for sim in sims[1:]:
        assert state_bytes(sim) == state_bytes(sims[0])
        a, b = sims[0].stats, sim.stats
        assert (a.bounces, a.supports, a.capped) == (b.bounces, b.supports, b.capped)


def test_a_closed_room_runs_without_the_step():
    scene = ws.Scene.load("room")
    assert not ws.Simulator(scene, scene.spawn(n=50, seed=1), device="cpu")._features.free_flight


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
@pytest.mark.parametrize("births", [False, True])
def test_recorded_frames_of_free_runs_are_the_bounce_loops_bits(precision, motion, births):
    """Runs of free frames go on in a loop of their own: the frames it records (positions,
    orientations, velocities, every 3rd frame and the last), the events and the counts are
    those of the kernel without the step, for spheres that leave the boxes' bounds, come back
    and spin (friction), some born late."""
    rng = np.random.default_rng(9)
    n = 120
    scene = ws.Scene(far_boxes(), friction=0.5, energy_retention=0.9)
    birth = rng.integers(0, 40, n) if births else 0
    swarm = ws.Swarm(rng.uniform([-3, 0.2, -1], [3, 4, 1], (n, 3)), rng.uniform(-6, 6, (n, 3)),
                     radius=0.1, birth_frame=birth)
    sims = [ws.Simulator(scene, swarm, precision=precision, motion=motion, device="cpu")
            for _ in range(2)]
    assert sims[0]._features.free_flight
    with_step(sims[0], True)
    with_step(sims[1], False)
    runs = [sim.run(100, every=3, velocities=True, events=True) for sim in sims]
    for name in ("position", "orientation", "velocity", "angular_velocity"):
        np.testing.assert_array_equal(getattr(runs[0], name), getattr(runs[1], name), name)
    a, b = runs[0].events, runs[1].events
    assert len(a) == len(b) > 0
    np.testing.assert_array_equal(a.position, b.position)
    assert state_bytes(sims[0]) == state_bytes(sims[1])
    assert (sims[0].stats.bounces, sims[0].stats.supports) == (sims[1].stats.bounces,
                                                               sims[1].stats.supports)
