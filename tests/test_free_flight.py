"""The frame kernel's free-flight step (``Features.free_flight``: a frame whose path lies beyond
every box's bounds skips the bounce loop).

- Its moves are the bounce loop's own bits: with the energy reset every frame
  (``free_reset_every=1``) the same runs with the step's kernel, with it but the boxes' overall
  bounds made infinite (every frame through the loop) and without it end in the same state, bit
  for bit.
- A run of free frames tests the bounds once for as many frames as it proves clear: the same
  bits as a test every frame (``free_horizon=False``).
- It resets the energy once in ``FREE_RESET_EVERY`` frames of a sphere's age and before a frame
  that is not free: the state is the same whatever the split into launches, the recording
  stride, the threads and the births; over a long flight the motion stays on the parabola and
  the energy at its start, to the rounding of the frames between resets.

The kernels compared are built with every optional feature a run of free frames touches (spin,
losses, births) and with brute force, whatever the scene would choose (:func:`every_feature`):
the step's code is then all there, and the tests share a handful of kernel variants instead of
compiling one per scene. A variant with spin, losses or births on runs a scene without them as
well (no friction, a retention of 1, every sphere born at frame 0); each test compares variants
that differ only in what it tests. The choice of the variant for a scene is tested in
``test_kernel_variants.py``.
"""

import warnings

import numpy as np
import pytest

import warpsim as ws
from warpsim.kernels.data import FREE_RESET_EVERY
from warpsim.kernels.frame_kernel import frame_kernel


def state_bytes(sim: ws.Simulator) -> list[bytes]:
    s = sim.state()
    return [np.ascontiguousarray(a).tobytes() for a in (s.position, s.velocity, s.energy,
                                                         s.angular_momentum, s.orientation)]


def with_features(sim: ws.Simulator, **changes) -> ws.Simulator:
    """``sim`` running the frame kernel built with ``changes`` to its features (the events
    variant follows, as it is built from the same features)."""
    sim._features = sim._features.but(**changes)
    sim._kernel = frame_kernel(sim._features)
    return sim


#: The optional features the kernels of these tests are built with.
EVERY_FEATURE = dict(spin=True, lossy=True, births=True)


def every_feature(scene: ws.Scene, swarm: ws.Swarm, **kw) -> ws.Simulator:
    """A simulator of ``scene`` and ``swarm`` with brute force and the kernel built with
    :data:`EVERY_FEATURE` (and the free-flight step when the swarm starts beyond the boxes'
    bounds, as the scene's own choice)."""
    return with_features(ws.Simulator(scene, swarm, broad_phase="brute", device="cpu", **kw),
                         **EVERY_FEATURE)


def with_step(sim: ws.Simulator, on: bool) -> ws.Simulator:
    """``sim`` running the kernel with (or without) the free-flight step, the step resetting
    the energy every frame as the kernel without it does."""
    return with_features(sim, free_flight=on, free_reset_every=1)


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
    sims = [every_feature(scene, swarm, precision=precision, motion=motion) for _ in range(3)]
    if scene_name == "far":  # spheres start beyond the boxes' bounds: the step is built in
        assert sims[0]._features.free_flight
    with_step(sims[0], True)
    without_free_flight(with_step(sims[1], True))
    with_step(sims[2], False)
    runs = [sim.run(frames, every=frames, events=True) for sim in sims]
    for sim, run in zip(sims[1:], runs[1:], strict=True):
        assert state_bytes(sim) == state_bytes(sims[0])
        np.testing.assert_array_equal(run.events.position, runs[0].events.position)
        a, b = sims[0].stats, sim.stats
        assert (a.bounces, a.supports, a.capped) == (b.bounces, b.supports, b.capped)


def test_a_closed_room_runs_without_the_step():
    scene = ws.Scene.load("room")
    assert not ws.Simulator(scene, scene.spawn(n=50, seed=1), device="cpu")._features.free_flight


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
@pytest.mark.parametrize("births", [False, True])
def test_recorded_frames_of_free_runs_are_the_bounce_loops_bits(precision, motion, births):
    """Runs of free frames go on in a loop of their own: with the reset every frame, the frames
    it records (positions, orientations, velocities, every 3rd frame and the last), the events
    and the counts are those of the kernel without the step, for spheres that leave the boxes'
    bounds, come back and spin (friction), some born late."""
    rng = np.random.default_rng(9)
    n = 120
    scene = ws.Scene(far_boxes(), friction=0.5, energy_retention=0.9)
    birth = rng.integers(0, 40, n) if births else 0
    swarm = ws.Swarm(rng.uniform([-3, 0.2, -1], [3, 4, 1], (n, 3)), rng.uniform(-6, 6, (n, 3)),
                     radius=0.1, birth_frame=birth)
    sims = [every_feature(scene, swarm, precision=precision, motion=motion) for _ in range(2)]
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


def far_swarm(n: int, seed: int, births: bool) -> tuple[ws.Scene, ws.Swarm]:
    """Spheres that leave :func:`far_boxes`' bounds and come back, spinning (friction), some
    born late."""
    rng = np.random.default_rng(seed)
    scene = ws.Scene(far_boxes(), friction=0.5, energy_retention=0.9)
    birth = rng.integers(0, 40, n) if births else 0
    swarm = ws.Swarm(rng.uniform([-3, 0.2, -1], [3, 4, 1], (n, 3)), rng.uniform(-6, 6, (n, 3)),
                     radius=0.1, birth_frame=birth)
    return scene, swarm


def run_bytes(traj) -> list[bytes]:
    return [np.ascontiguousarray(getattr(traj, name)).tobytes()
            for name in ("position", "orientation", "velocity", "angular_velocity")]


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_bounds_tested_once_for_many_frames_are_the_bits_of_a_test_every_frame(precision,
                                                                               motion):
    """A run of free frames proves several frames clear with one test (the parabola's range
    over them, rounding allowed for): the records, events, counts and state are those of the
    kernel that tests every frame, for spheres that leave the bounds, fly up, fall back past
    them and come back in, and spheres lobbed just above the wall's top, the bounds' top, that
    land on it within a reset period (gravity's part of the range)."""
    scene, swarm = far_swarm(150, 13, births=True)
    rng = np.random.default_rng(17)
    lobbed = 60  # just above the wall's top (the bounds' top), landing on it within a period
    start = np.concatenate([swarm.position,
                            rng.uniform([5.92, 2.7, -1.5], [6.08, 2.9, 1.5], (lobbed, 3))])
    speed = np.concatenate([swarm.velocity,
                            rng.uniform([-0.05, 0.0, -0.5], [0.05, 1.0, 0.5], (lobbed, 3))])
    birth = np.concatenate([swarm.birth_frame, rng.integers(0, 40, lobbed)])
    swarm = ws.Swarm(start, speed, radius=0.1, birth_frame=birth)
    sims = [with_features(every_feature(scene, swarm, precision=precision, motion=motion),
                          free_horizon=on) for on in (True, False)]
    runs = [sim.run(150, every=7, velocities=True, events=True) for sim in sims]
    assert run_bytes(runs[0]) == run_bytes(runs[1])
    assert len(runs[0].events) == len(runs[1].events) > 0
    np.testing.assert_array_equal(runs[0].events.position, runs[1].events.position)
    assert state_bytes(sims[0]) == state_bytes(sims[1])
    assert (sims[0].stats.bounces, sims[0].stats.supports) == (sims[1].stats.bounces,
                                                               sims[1].stats.supports)


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_free_runs_split_into_launches_at_odd_frames_are_the_same_bits(monkeypatch, precision,
                                                                       motion):
    """The energy reset of a run of free frames falls on frames of the sphere's age (one in
    ``FREE_RESET_EVERY``) and before a frame that is not free, which the launch's last frame
    tests too: one launch, one launch per frame, launches of odd lengths across the reset
    frames, two threads and another recording stride give the same bits, with births."""
    from warpsim import simulator as simulator_module

    scene, swarm = far_swarm(90, 21, births=True)
    frames = 3 * FREE_RESET_EVERY + 11
    kw = dict(precision=precision, motion=motion, device="cpu")
    whole = ws.Simulator(scene, swarm, workers=1, **kw)
    assert whole._features.free_flight
    ref = whole.run(frames, every=1, velocities=True, events=True)
    per_frame = ws.Simulator(scene, swarm, workers=1, **kw)
    for _ in range(frames):
        per_frame.step(1)
    assert state_bytes(per_frame) == state_bytes(whole)
    monkeypatch.setattr(simulator_module, "LAUNCH_SPHERE_FRAMES", len(swarm) * 5)
    sim = ws.Simulator(scene, swarm, workers=2, **kw)
    first = sim.run(FREE_RESET_EVERY - 3, every=3, velocities=True)
    sim.step(7)
    rest = sim.run(frames - FREE_RESET_EVERY - 4, every=5, velocities=True)
    for part in (first, rest):
        rows = np.searchsorted(ref.frame, part.frame)
        for name in ("position", "orientation", "velocity"):
            assert np.array_equal(getattr(part, name), getattr(ref, name)[rows],
                                  equal_nan=True), name
    assert state_bytes(sim) == state_bytes(whole)
    assert sim.stats.bounces == whole.stats.bounces


#: A long free flight: frames, and the spheres' start (metres, metres per second).
LONG_FRAMES = 10_000


def parabola_bounds(traj, x0, u0, g, dt, eps):
    """The analytic parabola at the recorded frames and how far rounding may take the floats
    from it: each frame rounds the velocity at most twice and the position at most four times
    (half an ulp each, the ballistic arc's point the most), so after ``k`` frames the velocity
    is within ``k eps V`` and the position within ``sum_j (dt j eps V + 2 eps (X + D))``, ``V``
    the largest speed, ``X`` the largest coordinate and ``D`` the largest step so far. A reset
    only moves the velocity to the energy's, which the same roundings bound."""
    k = traj.frame.astype(np.float64)[:, None, None]
    t = k * dt
    x = x0[None] + u0[None] * t + 0.5 * g * t ** 2
    v = u0[None] + g * t
    speed = np.maximum.accumulate(np.abs(v).max(axis=(1, 2)))[:, None, None]
    coord = np.maximum.accumulate(np.abs(x).max(axis=(1, 2)))[:, None, None]
    step = speed * dt
    v_tol = k * eps * speed
    x_tol = 0.5 * k * (k + 1) * eps * speed * dt + 2.0 * k * eps * (coord + step)
    return x, v, x_tol, v_tol


@pytest.mark.parametrize("motion,correction", [("linear", False), ("ballistic", False),
                                               ("linear", True)])
def test_a_long_free_flight_stays_on_its_parabola_and_never_gains_energy(precision, motion,
                                                                         correction):
    """10 000 frames (167 s, a fall of 136 km) with the reset once in ``FREE_RESET_EVERY``
    frames: the positions and velocities against the analytic parabola within the rounding of
    the frames (:func:`parabola_bounds`), and the energy (evaluated in float64 from the
    state) never above its start by more than the reset's own allowance (``RESET_ULPS``) and the
    rounding of the frames since the last reset: each frame moves ``1/2 m v_y^2`` by at most
    two roundings of ``v_y`` (``2 eps KE``) and the potential by at most two roundings of the
    height (``eps m |g| (|y| + |d_y|)``). Below its start it drifts by no more than those
    roundings over the whole flight (without the correction nothing raises it back); with the
    correction it is held within the same allowance on both sides."""
    from warpsim.kernels.dynamics import RESET_ULPS

    rng = np.random.default_rng(5)
    n = 48
    p0, v0 = rng.uniform(-1, 1, (n, 3)), rng.uniform(-8, 8, (n, 3))
    scene = ws.Scene(ws.RoundedBoxes(center=[[0.0, 100.0, 0.0]], half_extents=[[1, 1, 1]]),
                     energy_correction=correction)
    with warnings.catch_warnings():  # float32 at 136 km: the far box only, never reached
        warnings.simplefilter("ignore", ws.PrecisionWarning)
        sim = every_feature(scene, ws.Swarm(p0, v0), precision=precision, motion=motion)
    assert sim._features.free_flight and sim._features.free_reset_every == FREE_RESET_EVERY
    dtype = sim.model.precision.np_dtype
    eps = float(np.finfo(dtype).eps)
    traj = sim.run(LONG_FRAMES, every=1, velocities=True)
    g = np.asarray(scene.gravity, dtype=np.float64)
    x0 = p0.astype(dtype).astype(np.float64)
    u0 = v0.astype(dtype).astype(np.float64)
    x, v, x_tol, v_tol = parabola_bounds(traj, x0, u0, g, sim.dt, eps)
    assert np.all(np.abs(traj.position - x) <= x_tol)
    assert np.all(np.abs(traj.velocity - v) <= v_tol)

    m = sim.mass[:, None]
    height = (traj.position - sim.energy_origin) @ g  # -(potential) / m
    kinetic = 0.5 * m.T * (traj.velocity ** 2).sum(axis=-1)
    potential = np.abs(m.T * height)
    energy = kinetic - m.T * height
    gain = energy - energy[0]
    y = np.abs(traj.position[..., 1])
    step_y = np.abs(traj.velocity[..., 1]) * sim.dt
    per_frame = eps * (2.0 * kinetic + m.T * np.linalg.norm(g) * (y + step_y))
    per_frame = np.maximum.accumulate(per_frame, axis=0)
    evaluation = 4.0 * eps * (np.abs(energy) + kinetic + potential)  # this test's float64 sum
    allowed = (RESET_ULPS * eps * (np.abs(energy[0]) + potential)
               + FREE_RESET_EVERY * per_frame + evaluation)
    assert np.all(gain <= allowed)
    lost = allowed if correction else traj.frame[:, None] * per_frame + allowed
    assert np.all(-gain <= lost)
