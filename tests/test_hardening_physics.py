"""Properties a user broke (points through plates, sideways speed lost on a floor, energy gained
near rest and at large steps), each tested over a family of cases in both precisions.

Expected values are geometric or analytic: which side of a plate's plane a point is on, the
initial horizontal velocity, the initial energy (``Simulator.initial_energy``, float64).
"""

import math

import numpy as np
import pytest

import warpsim as ws
from warpsim.obstacles import quat_to_matrix

EPS = {"float32": float(np.finfo(np.float32).eps), "float64": float(np.finfo(np.float64).eps)}

#: Energy comparisons allow this many ulps of the energies' scale (a few roundings per frame of
#: E - Ep, far below any physical gain: the bugs gained 1e-3 to 1e+0 of the scale).
ENERGY_ULPS = 256.0


def random_rotation(rng) -> np.ndarray:
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def plate_side(position, center, rotation, axis=0) -> np.ndarray:
    """Signed offset of world points from a plate's plane (its local ``axis`` is the normal)."""
    normal = quat_to_matrix(rotation)[:, axis]
    return (np.asarray(position, dtype=np.float64) - center) @ normal


# -- 1. a point never crosses a plate ---------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("radius", [0.0, 1e-9, 1e-6])
@pytest.mark.parametrize("offset", [0.0, 1e3])
def test_points_never_cross_a_plate(device, precision, radius, offset):
    """Spheres of radius 0 (and tiny) aimed through the middle of a zero-thickness plate of any
    orientation, at 1 to 1e6 m/s, end every bounce on the side they started from."""
    rng = np.random.default_rng(11)
    n = 400
    centers, rotations, starts, velocities = [], [], [], []
    for _ in range(n):
        c = rng.uniform(-1, 1, 3) + offset
        q = random_rotation(rng)
        m = quat_to_matrix(q)
        normal, u, w = m[:, 0], m[:, 1], m[:, 2]
        side = rng.choice([-1.0, 1.0])
        start = c + side * rng.uniform(0.05, 1.0) * normal + rng.uniform(-0.3, 0.3) * u
        target = c + rng.uniform(-0.5, 0.5) * u + rng.uniform(-0.5, 0.5) * w
        speed = 10.0 ** rng.uniform(0, 6)
        direction = (target - start) / np.linalg.norm(target - start)
        # fast enough to reach the plate within the frame
        speed = max(speed, 2.0 * np.linalg.norm(target - start) * 60.0)
        centers.append(c)
        rotations.append(q)
        starts.append(start)
        velocities.append(speed * direction)
    for i in range(n):
        boxes = ws.RoundedBoxes(center=[centers[i]], half_extents=[[0.0, 1.0, 1.0]],
                                rotation=[rotations[i]])
        before = plate_side(starts[i], centers[i], rotations[i])
        out = ws.bounce([starts[i]], [velocities[i]], radius, boxes, 1 / 60, max_bounces=32,
                        precision=precision, device=device)
        after = plate_side(out.position[0], centers[i], rotations[i])
        assert out.bounces[0] == 1, i  # one plate, convex: one contact, then it moves away
        assert np.sign(after) == np.sign(before), (i, before, after)


def test_the_reported_case_stays_in_front(device):
    plate = ws.RoundedBoxes(center=[[0, 0, 0]], half_extents=[[0, 1, 1]])
    for precision in ("float32", "float64"):
        out = ws.bounce([[-1, 0, 0]], [[120, 0, 0]], 0.0, plate, 1 / 60, precision=precision,
                        device=device)
        assert out.bounces[0] == 1
        assert out.position[0, 0] == pytest.approx(-1.0, abs=1e-5)
        assert out.velocity[0, 0] == -120.0


@pytest.mark.slow
@pytest.mark.parametrize("radius", [0.0, 1e-9])
@pytest.mark.parametrize("speed", [5.0, 1e3, 1e6])
def test_closed_room_of_plates_holds_every_point(device, precision, radius, speed):
    """Six zero-thickness plates around a cube, and two zero-thickness dividers across it: no
    point leaves its cell, whatever its speed (no gravity)."""
    h = 2.0
    centers = [[-h, 0, 0], [h, 0, 0], [0, -h, 0], [0, h, 0], [0, 0, -h], [0, 0, h],
               [0, 0, 0], [0, 0, 0]]
    halves = [[0, h, h], [0, h, h], [h, 0, h], [h, 0, h], [h, h, 0], [h, h, 0],
              [0, h, h], [h, 0, h]]
    scene = ws.Scene(ws.RoundedBoxes(center=centers, half_extents=halves), gravity=(0, 0, 0))
    rng = np.random.default_rng(5)
    n = 300
    position = rng.uniform(-1.9, 1.9, (n, 3))
    position[:, :2] = np.where(np.abs(position[:, :2]) < 0.05, 0.5, position[:, :2])
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    swarm = ws.Swarm(position, speed * direction, radius=radius)
    sim = ws.Simulator(scene, swarm, precision=precision, max_bounces=64, device=device)
    frames = 20 if speed >= 1e6 else 60
    for _ in range(frames // 10):
        sim.step(10)
        p = sim.state().position.astype(np.float64)
        assert np.isfinite(p).all()
        assert (np.abs(p) <= h).all(), "a point left the room"
        assert (np.sign(p[:, :2]) == np.sign(position[:, :2])).all(), "a point changed cell"


def test_thin_walls_with_points_keep_their_cells(device, precision):
    scene = ws.Scene.load("thin-walls")
    base = scene.spawn(n=400, seed=2)
    swarm = ws.Swarm(base.position, base.velocity, radius=0.0, mass=base.mass)
    sim = ws.Simulator(scene, swarm, precision=precision, device=device)
    start = np.sign(swarm.position[:, :2])
    for _ in range(6):
        sim.step(10)
        p = sim.state().position
        assert (np.sign(p[:, :2]) == start).all()


# -- 2. sideways speed on a flat frictionless floor --------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("correction", [True, False])
@pytest.mark.parametrize("height,vx", [(0.5, 1.0), (0.01, 0.5)])
def test_floor_keeps_horizontal_speed_and_bounce_height(device, precision, correction, height, vx):
    """A ball bouncing on a flat frictionless floor (rotated about the vertical, anywhere in the
    world) keeps its horizontal velocity to float precision, and its apexes stay at its release
    height: never above it (the energy caps it) and, sampled every frame, at most one frame's
    rise (``g dt^2``) below it (no hop decays, none is paid for by the horizontal speed)."""
    dt = 1 / 60
    g = 9.81
    rng = np.random.default_rng(1 if correction else 2)
    for where in ([0.0, 0.0, 0.0], [300.0, 0.0, -700.0]):
        angle = rng.uniform(0, 2 * math.pi)
        q = [0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2)]
        floor = ws.RoundedBoxes(center=[np.add(where, [0, -0.5, 0])],
                                half_extents=[[2000.0, 0.5, 2000.0]], rotation=[q])
        scene = ws.Scene(floor, energy_correction=correction)
        r = 0.05
        start = np.add(where, [0.0, r + height, 0.0])
        v0 = np.array([vx * math.cos(angle), 0.0, vx * math.sin(angle)])
        sim = ws.Simulator(scene, ws.Swarm([start], [v0], radius=r), dt=dt, precision=precision,
                           device=device)
        frames = 1800  # 30 s
        y = sim.run(frames).position[:, 0, 1].astype(np.float64) - where[1] - r
        flights = y[120:]  # after the first two seconds
        u = sim.state().velocity[0]
        tol = 64 * EPS[precision] * vx
        assert abs(u[0] - v0[0]) <= tol and abs(u[2] - v0[2]) <= tol, (u, v0)
        top, low = flights.max(), flights.min()
        h_tol = 1e-6 + 64 * EPS[precision] * (1.0 + height)
        assert height - g * dt * dt - h_tol <= top <= height + h_tol, (top, height)
        # and it did come down to the floor between the apexes (to within a frame's fall)
        assert -h_tol <= low <= math.sqrt(2.0 * g * height) * dt + g * dt * dt


# -- 3. energy is never gained -------------------------------------------------------------

def energy_slack(sim: ws.Simulator) -> np.ndarray:
    e0 = sim.initial_energy
    g = np.linalg.norm(sim.scene.gravity)
    return ENERGY_ULPS * EPS[sim.precision] * (np.abs(e0) + sim.mass * g * 10.0)


def assert_no_gain(sim: ws.Simulator, frames: int, chunk: int = 10):
    worst = -np.inf
    slack = energy_slack(sim)
    for _ in range(frames // chunk):
        sim.step(chunk)
        gain = sim.mechanical_energy() - sim.initial_energy
        worst = max(worst, float(np.max(gain / slack)))
        assert (gain <= slack).all(), f"energy gained: {gain.max():.3g} J > {slack.max():.3g}"
    return worst


def floor_scene(**kw) -> ws.Scene:
    return ws.Scene(ws.RoundedBoxes(center=[[0, -0.5, 0]], half_extents=[[50, 0.5, 50]]), **kw)


@pytest.mark.parametrize("dt", [1 / 240, 1 / 60, 1 / 10])
def test_no_energy_gain_released_near_a_floor(device, precision, dt):
    """Spheres released at rest from 1 um to 0.3 mm above a floor (and from 1 cm)."""
    gaps = np.array([1e-6, 3e-6, 1e-5, 3e-5, 1e-4, 3e-4, 1e-2])
    r = 0.05
    position = np.stack([np.linspace(-5, 5, len(gaps)), r + gaps, np.zeros(len(gaps))], axis=1)
    sim = ws.Simulator(floor_scene(), ws.Swarm(position, np.zeros_like(position), radius=r),
                       dt=dt, precision=precision, device=device)
    assert_no_gain(sim, 300)
    assert (sim.state().position[:, 1] <= r + gaps + 9.81 * dt * dt).all()


@pytest.mark.slow
@pytest.mark.parametrize("dt", [1 / 60, 0.1, 1.0])
def test_no_energy_gain_at_large_steps(device, precision, dt):
    """A ball dropped from 1 m (sliding at 0.3 m/s) never climbs above its energy height, 1 m
    (its energy less its horizontal kinetic energy, over m g), at any step; it climbs back to
    within one frame's rise of it."""
    r = 0.1
    sim = ws.Simulator(floor_scene(), ws.Swarm([[0, 1.0 + r, 0]], [[0.3, 0, 0]], radius=r),
                       dt=dt, precision=precision, device=device)
    top = -np.inf
    slack = energy_slack(sim)
    for _ in range(100):
        sim.step(1)
        top = max(top, sim.state().position[0, 1] - r)
        assert sim.mechanical_energy()[0] - sim.initial_energy[0] <= slack[0]
    m, g = sim.mass[0], 9.81
    energy_height = ((sim.initial_energy[0] - 0.5 * m * 0.3 ** 2) / (m * g)
                     + sim.energy_origin[1] - r)
    h_tol = 64 * EPS[precision] * (2.0 + 0.3 ** 2 / g)
    assert abs(energy_height - 1.0) <= h_tol
    assert energy_height - g * dt * dt - h_tol <= top <= energy_height + h_tol, (
        top, energy_height)


def test_no_energy_gain_sliding_down_a_slope(device, precision):
    """Frictionless spheres sliding 10 s down a long 20-degree slope."""
    angle = math.radians(20.0)
    q = [0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2)]  # tilt about z
    slope = ws.RoundedBoxes(center=[[0, 0, 0]], half_extents=[[400, 0.5, 5]], rotation=[q])
    normal = quat_to_matrix(np.array(q))[:, 1]
    tangent = quat_to_matrix(np.array(q))[:, 0]
    r = 0.05
    s = np.array([60.0, 100.0, 140.0])
    position = s[:, None] * tangent + (0.5 + r) * normal
    sim = ws.Simulator(ws.Scene(slope), ws.Swarm(position, np.zeros((3, 3)), radius=r),
                       precision=precision, device=device)
    assert_no_gain(sim, 600, chunk=60)
    # and they did slide down: at least half the frictionless distance 1/2 g sin(a) t^2
    moved = (position - sim.state().position) @ tangent
    assert (moved > 0.5 * 0.5 * 9.81 * math.sin(angle) * 100.0).all()


@pytest.mark.parametrize("seed", range(3))
def test_no_energy_gain_bouncing_in_the_room(device, precision, seed):
    scene = ws.Scene.load("room")
    sim = ws.Simulator(scene, scene.spawn(n=200, seed=seed), precision=precision, device=device)
    assert_no_gain(sim, 240, chunk=40)
