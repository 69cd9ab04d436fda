"""The user's velocity is the velocity: exact free flight, restarts, and hops on a flat floor.

README "What it models": a swarm's velocity is the velocity at t = 0 and a state's the
velocity at the end of its frame, for both motion models. The linear model moves each frame
along the chord of the exact free-flight parabola, so without contacts every frame lies on
``p0 + v0 t + g t^2 / 2`` and its velocity is ``v0 + g t``: both computed here in float64.

On a flat frictionless floor gravity and the contacts never change the horizontal velocity, and
a sphere released at height ``h`` never rises above ``h``. When the chord's rise after a contact
is longer than the energy allows (a hop shorter than a frame), the cut rise ends exactly at
that height: released at rest at ``h < g dt^2 / 4`` above the floor (every frame's chord then
reaches the floor and its reflected rest is longer than ``h``), a sphere ends every frame at
height ``h`` with no vertical velocity.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import warpsim as ws

G = 9.81
EPS = {"float32": float(np.finfo(np.float32).eps), "float64": float(np.finfo(np.float64).eps)}

#: Roundings per frame of a position or a velocity: the chord's sum ``p + (v + g dt/2) dt``
#: and the kick ``v + g dt`` round a few times each, and the errors add up over the frames.
FRAME_ULPS = 4.0

#: Rounding of an energy, a height or a speed derived from it, in ulps of its scale: ``E - Ep``
#: and ``sqrt`` round a few times per frame, the reset recomputes the speed from ``E`` so
#: nothing accumulates.
ENERGY_ULPS = 64.0

#: Fixed hypothesis profile: the same examples every run (CI is reproducible).
PROFILE = settings(max_examples=12, deadline=None, derandomize=True, database=None)

R = 0.05


def thin_floor() -> ws.RoundedBoxes:
    """A floor whose top face is ``y = 0`` and whose centre (the potential's origin) is 5 mm
    below it, so the energies are of the motion's size, not of the slab's."""
    return ws.RoundedBoxes(center=[[0.0, -0.005, 0.0]], half_extents=[[20.0, 0.005, 20.0]])


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
@pytest.mark.parametrize("dt", [1 / 24, 1 / 60, 1 / 240, 0.1])
def test_free_flight_is_the_parabola_from_the_users_velocity(device, precision, motion, dt):
    rng = np.random.default_rng(int(1 / dt))
    n, frames = 16, 48
    p0 = rng.uniform(-50.0, 50.0, (n, 3))
    v0 = rng.uniform(-20.0, 20.0, (n, 3))
    far = ws.RoundedBoxes(center=[[0.0, -1e5, 0.0]], half_extents=[[1.0, 1.0, 1.0]])
    sim = ws.Simulator(ws.Scene(far, motion=motion), ws.Swarm(p0, v0, radius=0.1), dt=dt,
                       precision=precision, device=device)
    traj = sim.run(frames, velocities=True)
    g = np.array([0.0, -G, 0.0])
    t = np.arange(frames + 1)[:, None, None] * dt
    want_p = p0 + v0 * t + 0.5 * g * t * t
    want_v = v0 + g * t
    k = np.arange(frames + 1)[:, None, None]
    eps = EPS[precision]
    p_scale = np.abs(p0) + np.abs(v0) * t + G * t * t + 1.0
    v_scale = np.abs(v0) + G * t + 1.0
    np.testing.assert_array_less(np.abs(traj.position - want_p), FRAME_ULPS * eps * (k + 1)
                                 * p_scale)
    np.testing.assert_array_less(np.abs(traj.velocity - want_v), FRAME_ULPS * eps * (k + 1)
                                 * v_scale)
    s = sim.state()
    np.testing.assert_array_equal(s.velocity, traj.velocity[-1])
    np.testing.assert_array_equal(traj.velocity[0], v0.astype(s.velocity.dtype))
    if precision == "float64":  # 1e-15 m at 10 m scale: the chord ends on the arc
        assert np.abs(traj.position - want_p).max() < 1e-12


def test_the_thrown_ball_of_the_readme():
    """Thrown from 10 m at (1, 3, 0) m/s with the default settings (linear, 1/60 s) in float64:
    after 1 s it is at (1, 10 + 3 - g / 2, 0) = (1, 8.095, 0) m to a few 1e-15 m, with the
    velocity (1, 3 - g, 0) to the rounding of 120 half kicks."""
    far = ws.RoundedBoxes(center=[[0.0, -100.0, 0.0]], half_extents=[[1.0, 1.0, 1.0]])
    sim = ws.Simulator(ws.Scene(far), ws.Swarm([[0.0, 10.0, 0.0]], [[1.0, 3.0, 0.0]]),
                       precision="float64")
    sim.step(60)
    s = sim.state()
    assert np.abs(s.position[0] - [1.0, 13.0 - G / 2, 0.0]).max() < 5e-15
    assert np.abs(s.velocity[0] - [1.0, 3.0 - G, 0.0]).max() < 120 * EPS["float64"] * G


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_restart_from_a_state_continues_bit_for_bit(device, precision, motion):
    """A run stopped, its state set on a new simulator and continued, ends in the same bits
    as the run that never stopped (contacts, resets and supports included)."""
    scene = ws.Scene.load("room")
    swarm = scene.spawn(n=64, seed=5)
    kw = dict(dt=1 / 60, precision=precision, device=device, motion=motion)
    straight = ws.Simulator(scene, swarm, **kw)
    straight.step(120)
    first = ws.Simulator(scene, swarm, **kw)
    first.step(50)
    again = ws.Simulator(scene, swarm, **kw)
    again.set_state(first.state())
    again.step(70)
    a, b = straight.state(), again.state()
    assert b.frame == a.frame == 120
    for name in ("position", "velocity", "energy", "angular_momentum", "orientation"):
        np.testing.assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)


def test_swarm_from_a_state_continues_free_flight_bit_for_bit(precision):
    """Without contacts a swarm made of a state's position and velocity is the same motion,
    bit for bit: the velocity is the velocity, no half kick to add or remove. (The swarm starts
    a new run, its spheres' age 0: made of a state whose age is a multiple of
    ``FREE_RESET_EVERY``, its free flight resets the energy on the same frames.)"""
    from warpsim.kernels.data import FREE_RESET_EVERY

    rng = np.random.default_rng(3)
    p0, v0 = rng.uniform(-5, 5, (8, 3)), rng.uniform(-5, 5, (8, 3))
    scene = ws.Scene(ws.RoundedBoxes(center=[[0.0, -1e4, 0.0]], half_extents=[[1, 1, 1]]))
    straight = ws.Simulator(scene, ws.Swarm(p0, v0), precision=precision)
    straight.step(FREE_RESET_EVERY + 25)
    first = ws.Simulator(scene, ws.Swarm(p0, v0), precision=precision)
    first.step(FREE_RESET_EVERY)
    s = first.state()
    again = ws.Simulator(scene, ws.Swarm(s.position, s.velocity), precision=precision)
    again.step(25)
    np.testing.assert_array_equal(again.state().position, straight.state().position)
    np.testing.assert_array_equal(again.state().velocity, straight.state().velocity)


def test_set_state_refuses_a_bad_state():
    sim = ws.Simulator(ws.Scene(thin_floor()), ws.Swarm([[0, 1, 0]], [[0, 0, 0]]))
    s = sim.state()
    s.velocity = np.array([[0.0, np.nan, 0.0]])
    with pytest.raises(ValueError, match=r"state\.velocity\[0\]"):
        sim.set_state(s)
    with pytest.raises(ValueError, match="state must be a warpsim.State"):
        sim.set_state("state")


def floor_run(precision, dt, heights, speeds, retention, frames):
    """Spheres released at rest vertically ``heights`` above a flat floor, sliding along
    directions spread over the floor at ``speeds``; returns the simulator, the start velocities
    and the recorded heights above the floor and velocities, frame 0 first."""
    n = len(heights)
    angle = np.linspace(0.0, 2.0 * math.pi, n, endpoint=False)
    v0 = np.stack([speeds * np.cos(angle), np.zeros(n), speeds * np.sin(angle)], axis=1)
    p0 = np.stack([np.zeros(n), R + heights, np.arange(n) * 1.0], axis=1)
    scene = ws.Scene(thin_floor(), energy_retention=retention)
    sim = ws.Simulator(scene, ws.Swarm(p0, v0, radius=R), dt=dt, precision=precision)
    traj = sim.run(frames, velocities=True)
    return sim, v0, traj.position[:, :, 1].astype(np.float64) - R, traj.velocity


def height_rounding(sim, precision, speeds):
    """Rounding of a height got from the energy [m]: ulps of (E + Ep) / (m g)."""
    scale = 0.5 * speeds ** 2 / G + 0.1  # kinetic and potential (origin 5 mm below) heights
    return ENERGY_ULPS * EPS[precision] * scale


@PROFILE
@given(precision=st.sampled_from(["float32", "float64"]),
       dt=st.floats(1 / 240, 1 / 10),
       heights=st.lists(st.floats(1e-6, 1e-2), min_size=4, max_size=4),
       speeds=st.lists(st.floats(0.0, 5.0), min_size=4, max_size=4),
       lossy=st.booleans())
def test_a_hop_never_eats_horizontal_speed_nor_grows(precision, dt, heights, speeds, lossy):
    """Released 1 um to 1 cm above a flat frictionless floor while sliding: the horizontal
    velocity is kept to rounding and the height never exceeds the release height, elastic or
    lossy, at any step."""
    heights, speeds = np.array(heights), np.array(speeds)
    frames = int(min(2.0 / dt, 240))
    sim, v0, y, v = floor_run(precision, dt, heights, speeds, 0.7 if lossy else 1.0, frames)
    eps = EPS[precision]
    side = v[:, :, [0, 2]].astype(np.float64)
    drift = np.abs(side - v0[None, :, [0, 2]]).max(axis=(0, 2))
    assert (drift <= ENERGY_ULPS * eps * (speeds + 1e-3)).all(), (drift, speeds)
    top = y.max(axis=0)
    assert (top <= heights + height_rounding(sim, precision, speeds)).all(), (top, heights)


@pytest.mark.parametrize("dt", [1 / 30, 1 / 10])
def test_a_cut_rise_reaches_the_height_its_energy_allows(precision, dt):
    """Released at rest at ``h < g dt^2 / 4``: every frame's chord reaches the floor and its
    reflected rest (``g dt^2 / 2 - h``) is longer than ``h``, so every rise is cut, and a cut
    rise ends at the energy height ``h`` itself with no vertical velocity; the horizontal
    velocity stays what it was. (Cutting below it, e.g. by counting the vertical kinetic energy
    as spent, would leave the sphere lower and its energy to the reset.)"""
    heights = np.array([1e-4, 1e-3, 0.2 * G * dt * dt]) if dt > 0.05 else np.array(
        [1e-5, 1e-4, 1e-3])
    assert (heights < G * dt * dt / 4).all()
    speeds = np.array([0.0, 0.7, 3.0])
    sim, v0, y, v = floor_run(precision, dt, heights, speeds, 1.0, 60)
    tol = height_rounding(sim, precision, speeds)
    off = np.abs(y[1:] - heights).max(axis=0)
    assert (off <= tol).all(), (off, tol)
    v_tol = math.sqrt(2.0 * G * tol.max()) + ENERGY_ULPS * EPS[precision]
    assert np.abs(v[1:, :, 1]).max() <= v_tol
    np.testing.assert_allclose(v[1:, :, [0, 2]], np.broadcast_to(v0[:, [0, 2]], (60, 3, 2)),
                               rtol=ENERGY_ULPS * EPS[precision], atol=0)
