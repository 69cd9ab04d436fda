"""Whole frames (``ws.Simulator``): physics laws, with tolerances from the integrator's error.

One frame (README "What it models"): the multi-bounce move along the chord of the
free-flight parabola, ``(v + g dt / 2) dt``, ending with ``v + g dt`` (``v`` the velocity at the
frame's start: the swarm's is the velocity at t = 0), the speed reset from the per-sphere energy
``E`` and the orientation step. The energy is that of the state's velocity, which the chord
keeps exactly in free flight. Expected values are analytic or float64 computations in the test.

Scales used in the tolerances:

* ``G_DT2 = g dt^2`` [m]: the displacement gravity adds in one frame. A sampled apex lies
  below the energy height ``E / (m g)`` by at most the last frame's rise, below ``G_DT2``, and
  never above it (``E`` caps ``Ep``). A ball released at rest has the energy height ``h0``.
* Rounding: ``ROUND_ULPS`` ulps of the quantity's scale (the energy ``E`` and ``Ep`` are
  ``O(m g h)``, positions are ``O(scene size + path per frame)``).

Kernel variants compiled here (each costs a compile the first time): float32 with the default
cap, without spin and without loss (most tests); float32 lossy; float32 with spin; float64
without spin and without loss.
"""

import hashlib
import math

import numpy as np
import pytest
from helpers import DEVICES, closed_room
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import warpsim as ws

G = 9.81
DT = 1.0 / 60.0
G_DT2 = G * DT * DT
EPS = {"float32": float(np.finfo(np.float32).eps), "float64": float(np.finfo(np.float64).eps)}

#: Rounding error of an energy, a height or a position, in ulps of its scale (a few roundings of
#: ``E - Ep`` and of the coordinates per frame; nothing accumulates, since ``E`` is kept and the
#: speed is recomputed from it every frame).
ROUND_ULPS = 16.0

#: End-position error per straight piece of a frame's broken line, in ulps of (scene scale +
#: path per frame); the bounce tests measure < 1 ulp per piece.
PIECE_ULPS = 4.0

MAX_BOUNCES = 8




def floor(center=(0.0, 0.0, 0.0), half: float = 50.0) -> ws.RoundedBoxes:
    """A floor slab whose top face is the plane ``y = center.y``, normal +y."""
    c = np.asarray(center, dtype=np.float64) + (0.0, -0.5, 0.0)
    return ws.RoundedBoxes(center=[c], half_extents=[(half, 0.5, half)])


def random_unit_quaternions(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1)[:, None]


def spawn_outside(rng, boxes, half, radius, n, margin=1e-3):
    """``n`` centres uniform in the room ``[-(half - r), half - r]^3`` whose sphere clears
    every box by ``margin``."""
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,))
    out = []
    while len(out) < n:
        r = radius[len(out)]
        p = rng.uniform(-(half - r), half - r, 3)
        if (boxes.signed_distance(p[None])[0] - r).min() > margin:
            out.append(p)
    return np.array(out)


def inside_depth(boxes, positions, radius):
    """Largest penetration ``r - distance`` of any sphere into any box [m] (<= 0: none)."""
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    r = np.broadcast_to(np.asarray(radius, dtype=np.float64), p.shape[:1])
    return float((r - boxes.signed_distance(p).min(axis=1)).max())


def apexes(y):
    """Apex heights of a bouncing ball from its sampled heights ``y`` (one per frame).

    Contacts are the local minima of ``y``. The apex of a flight is the highest sample between
    two contacts; the last flight counts only if it has turned (its highest sample is not the
    last one), so a flight cut short by the end of the run is not mistaken for an apex.
    """
    y = np.asarray(y, dtype=np.float64)
    lows = [k for k in range(1, len(y) - 1) if y[k] < y[k - 1] and y[k] <= y[k + 1]]
    bounds = [0] + lows + [len(y)]
    out = []
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        segment = y[lo:hi]
        if hi < len(y) or np.argmax(segment) < len(segment) - 1:
            out.append(float(segment.max()))
    return out[1:]  # the first "flight" is the drop from the start height


def floor_contacts(y):
    """Frames where a ball sampled at heights ``y`` turned from falling to rising."""
    y = np.asarray(y, dtype=np.float64)
    return [k for k in range(1, len(y) - 1) if y[k] < y[k - 1] and y[k] <= y[k + 1]]


def quat_multiply(a, b):
    """Hamilton product of quaternions ``(x, y, z, w)``."""
    av, aw = np.asarray(a[:3]), a[3]
    bv, bw = np.asarray(b[:3]), b[3]
    return np.append(aw * bv + bw * av + np.cross(av, bv), aw * bw - av @ bv)


def quat_conjugate(q):
    return np.array([-q[0], -q[1], -q[2], q[3]])


def random_scene(rng, half, count):
    """A closed room with ``count`` random rotated rounded boxes (some flat, some sharp)."""
    extents = rng.uniform(0.0, 0.5, (count, 3)) * (rng.random((count, 3)) > 0.2)
    radius = rng.uniform(0.0, 0.2, count) * (rng.random(count) > 0.3)
    obstacles = ws.RoundedBoxes(center=rng.uniform(-1.0, 1.0, (count, 3)), half_extents=extents,
                                rotation=random_unit_quaternions(rng, count), radius=radius)
    return ws.RoundedBoxes.concatenate([closed_room(half), obstacles])


# -- drop tests --------------------------------------------------------------------------------

DROP_HEIGHTS = np.array([0.5, 1.0, 2.0, 3.0])
DROP_R = 0.1


def drop(heights, energy_retention=1.0, precision="float32", device=None, frames=600):
    """Balls dropped from rest (centre at ``heights``) on the floor y = 0; heights per frame."""
    n = len(heights)
    position = np.column_stack([np.arange(n, dtype=np.float64), heights, np.zeros(n)])
    scene = ws.Scene(floor(), energy_retention=energy_retention)
    sim = ws.Simulator(scene, ws.Swarm(position, np.zeros((n, 3)), radius=DROP_R),
                       device=device, precision=precision)
    return sim, sim.run(frames).position[:, :, 1].astype(np.float64)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_drop_comes_back_to_its_height(precision, device):
    """k = 1: every apex is at the energy height H = h0, at most one frame's
    rise below it (``0 <= H - apex <= g dt^2``), never above (the energy caps the height)."""
    sim, y = drop(DROP_HEIGHTS, precision=precision, device=device)
    for i, h0 in enumerate(DROP_HEIGHTS):
        tol = ROUND_ULPS * EPS[precision] * (h0 + 1.0)
        found = apexes(y[:, i])
        assert found, f"sphere {i} never came back up"
        for apex in found:
            assert -tol <= h0 - apex <= G_DT2 + tol, (i, h0, apex)
    assert sim.stats.capped == 0


def test_drop_with_losses_apex_ratio_is_k():
    """k = 1/2: each contact keeps k of the kinetic energy at the contact, so the energy height
    above the contact centre (y = r) is multiplied by k: apex n is r + k^n (H - r) with the
    energy height H = h0 (released at rest), sampled
    at most g dt^2 below. Apexes under the resting threshold (approach speed 2 g dt, i.e.
    2 g dt^2 of height) are supports, not bounces: only apexes above 4 g dt^2 are checked."""
    k = 0.5
    _, y = drop(DROP_HEIGHTS, energy_retention=k)
    for i, h0 in enumerate(DROP_HEIGHTS):
        tol = ROUND_ULPS * EPS["float32"] * (h0 + 1.0)
        found = apexes(y[:, i])
        assert found, f"sphere {i} never came back up"
        for n, apex in enumerate(found, start=1):
            expected = DROP_R + k**n * (h0 - DROP_R)
            if expected - DROP_R < 4.0 * G_DT2:
                break
            assert -tol <= expected - apex <= G_DT2 + tol, (i, n, expected, apex)
        if len(found) >= 2 and found[1] - DROP_R > 4.0 * G_DT2:
            ratio = (found[1] - DROP_R) / (found[0] - DROP_R)
            assert ratio == pytest.approx(k, abs=2.0 * G_DT2 / (found[0] - DROP_R))


def test_dropped_ball_keeps_bouncing():
    """k = 1: a flight from the floor to the apex and back lasts T = 2 sqrt(2 (h0 - r) / g);
    the sampled contacts are at most two frames later than that each time, so in 10 s a ball
    touches the floor at least floor((10 - t1) / (T + 2 dt)) + 1 times (t1: first fall)."""
    frames = 600
    _, y = drop(DROP_HEIGHTS, frames=frames)
    t1 = np.sqrt(2.0 * (DROP_HEIGHTS - DROP_R) / G)
    expected = np.floor((frames * DT - t1) / (2.0 * t1 + 2.0 * DT)) + 1
    got = np.array([len(floor_contacts(y[:, i])) for i in range(len(DROP_HEIGHTS))])
    assert np.all(got >= expected), dict(heights=DROP_HEIGHTS, contacts=got, least=expected)


def test_dropped_ball_with_losses_comes_to_rest_on_the_floor():
    """k = 1/2: flights shrink geometrically (total time t1 + T1 / (1 - sqrt(k)) < 5 s from
    4 m), then the resting contact holds the ball: after 10 s every ball lies on the floor
    (centre at y = r) at rest."""
    heights = np.array([0.5, 1.0, 1.5, 2.0, 3.0, 4.0])
    sim, y = drop(heights, energy_retention=0.5)
    state = sim.state()
    np.testing.assert_allclose(y[-1], DROP_R, rtol=0, atol=ROUND_ULPS * EPS["float32"])
    np.testing.assert_array_equal(state.velocity, 0.0)


def test_free_fall_follows_the_parabola(device):
    """Dropped from rest far above anything: y(t) = h0 - g t^2 / 2 at every frame (the chord's
    ends lie on the parabola), to rounding, for 2 s; the velocity is -g t."""
    frames = 120
    sim = ws.Simulator(ws.Scene(floor((0.0, -100.0, 0.0))),
                       ws.Swarm([(0.0, 10.0, 0.0)], [(0.0, 0.0, 0.0)], radius=DROP_R),
                       device=device)
    traj = sim.run(frames, velocities=True)
    y = traj.position[:, 0, 1].astype(np.float64)
    t = np.arange(frames + 1) * DT
    tol = ROUND_ULPS * EPS["float32"] * 110.0  # heights are O(100 m) from the energy origin
    np.testing.assert_array_less(np.abs(y - (10.0 - 0.5 * G * t * t)), tol)
    np.testing.assert_array_less(np.abs(traj.velocity[:, 0, 1] + G * t), tol)


def test_free_flight_keeps_horizontal_velocity(device):
    """Gravity is vertical: in free flight the horizontal velocity is constant and
    x(t) = x0 + vx t and y(t) = y0 + vy t - g t^2 / 2 (to rounding)."""
    frames = 60
    sim = ws.Simulator(ws.Scene(floor((0.0, -10.0, 0.0))),
                       ws.Swarm([(0.0, 1.0, 0.0)], [(2.0, 5.0, 0.0)], radius=DROP_R), device=device)
    trajectory = sim.run(frames)
    t = np.arange(frames + 1) * DT
    x, y = trajectory.position[:, 0, 0], trajectory.position[:, 0, 1]
    tol = ROUND_ULPS * EPS["float32"] * 12.0
    np.testing.assert_allclose(sim.state().velocity[0, 0], 2.0, rtol=0, atol=tol)
    np.testing.assert_allclose(x, 2.0 * t, rtol=0, atol=tol * frames)
    assert np.all(np.abs(y - (1.0 + 5.0 * t - 0.5 * G * t * t)) <= tol)


# -- a wall, no gravity ------------------------------------------------------------------------


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_ball_thrown_at_a_wall_mirrors(precision, device):
    """No gravity, wall face x = 1, r = 0.1: from x = 0.05 at v = (2.5, 0.5, -0.25) the centre
    reaches x = 0.9 at t_c = 0.85 / 2.5 = 0.34 s = 20.4 frames: frames 1..20 before, the
    contact inside frame 21. Then x(t) = 0.9 - 2.5 (t - t_c), vx = -2.5; y, z straight on."""
    frames = 40
    scene = ws.Scene(ws.RoundedBoxes(center=[(1.5, 0.0, 0.0)], half_extents=[(0.5, 5.0, 5.0)]),
                     gravity=(0.0, 0.0, 0.0))
    sim = ws.Simulator(scene, ws.Swarm([(0.05, 0.0, 0.0)], [(2.5, 0.5, -0.25)], radius=0.1),
                       device=device, precision=precision)
    velocities = []
    positions = [sim.state().position[0]]
    for _ in range(frames):
        sim.step()
        state = sim.state()
        positions.append(state.position[0])
        velocities.append(state.velocity[0])
    t = np.arange(frames + 1) * DT
    t_c = 0.85 / 2.5
    expected = np.column_stack([0.9 - np.abs(0.9 - (0.05 + 2.5 * t)), 0.5 * t, -0.25 * t])
    # each frame adds one rounding of the coordinates (scale ~1 m)
    tol = PIECE_ULPS * EPS[precision] * 2.0 * (frames + 1)
    np.testing.assert_allclose(np.array(positions), expected, rtol=0, atol=tol)
    vx = np.array(velocities)[:, 0]
    before = t[1:] < t_c
    np.testing.assert_allclose(vx[before], 2.5, rtol=0, atol=tol)
    np.testing.assert_allclose(vx[~before], -2.5, rtol=0, atol=tol)
    assert before.sum() == 20
    np.testing.assert_allclose(np.array(velocities)[:, 1:], np.tile([0.5, -0.25], (frames, 1)),
                               rtol=0, atol=tol)
    assert sim.stats.bounces == 1 and sim.stats.capped == 0


# -- friction spin -----------------------------------------------------------------------------


@pytest.mark.slow
def test_sliding_on_a_floor_spins_up_about_n_cross_v(device):
    """Spheres (r = 0.1, m = 1) sliding along +x on a floor (n = +y), k_f = 2 kg/s, clamp
    5 rad/s. Each frame's support contact applies the friction torque: with Rot = (0, 0, w) and
    OC = -r n = (0, -r, 0), Rot x OC = (w r, 0, 0), so v_t,rel = (vx + w r, 0, 0) and
    dL = dt OC x (-k_f v_t,rel) = (0, 0, -dt r k_f (vx + w r)). From L = 0 the spin grows
    along -z = n x v / |v| (towards rolling), w -> -vx / r geometrically (ratio
    1 - dt k_f / (2/5 m) per frame), unless the clamp |Rot| <= 5 stops it first:
    vx = 0.2 rolls at w = -2 rad/s; vx = 2 would roll at -20 and is held at -5."""
    r, m, k_f, clamp = 0.1, 1.0, 2.0, 5.0
    inertia = 0.4 * m * r * r
    scene = ws.Scene(floor(), friction=k_f, max_angular_speed=clamp)
    swarm = ws.Swarm([(0.0, r, 0.0), (0.0, r, 1.0)], [(0.2, 0.0, 0.0), (2.0, 0.0, 0.0)],
                     radius=r, mass=m)
    sim = ws.Simulator(scene, swarm, device=device)
    assert sim.spin
    w_ref = np.zeros(2)  # float64 iteration of the spin recursion, with the simulated vx
    eps = EPS["float32"]
    orientations = []
    for frame in range(600):
        vx = sim.state().velocity[:, 0].astype(np.float64)
        sim.step()
        state = sim.state()
        orientations.append(state.orientation.astype(np.float64))
        L = state.angular_momentum.astype(np.float64)
        np.testing.assert_array_equal(L[:, :2], 0.0)  # only about z
        assert np.all(L[:, 2] < 0.0)  # along n x v = (0, 1, 0) x (+x) = -z
        assert np.all(np.linalg.norm(L, axis=1) / inertia <= clamp * (1.0 + 4.0 * eps))
        if frame < 20:  # the recursion, step by step, while the spin is still growing
            dL = -DT * r * k_f * (vx + np.clip(w_ref, -clamp, clamp) * r)
            w_ref = np.clip(w_ref + dL / inertia, -clamp, clamp)
            np.testing.assert_allclose(L[:, 2] / inertia, w_ref, rtol=64 * eps, atol=0)
    # slow sphere: rolling; fast one: held at the clamp
    vx_end = sim.state().velocity[0, 0]
    assert L[0, 2] / inertia == pytest.approx(-vx_end / r, rel=64 * eps)
    assert L[1, 2] / inertia == pytest.approx(-clamp, rel=4 * eps)
    # orientation: a constant Rot = (0, 0, -5) turns the fast sphere by 5 dt per frame about -z
    q0, q1 = orientations[299][1], orientations[599][1]
    assert np.linalg.norm(q1) == pytest.approx(1.0, abs=4 * eps)
    relative = quat_multiply(q1, quat_conjugate(q0))
    half = 0.5 * clamp * DT * 300
    expected = np.array([0.0, 0.0, -math.sin(half), math.cos(half)])
    if relative @ expected < 0.0:
        relative = -relative
    # 300 quaternion products, each rounding a unit quaternion by a few ulps
    np.testing.assert_allclose(relative, expected, rtol=0, atol=300 * 4 * eps)


# -- energy ------------------------------------------------------------------------------------


def closed_room_swarm(n, seed, half=1.0, r=0.05):
    rng = np.random.default_rng(seed)
    position = rng.uniform(-(half - r), half - r, (n, 3))
    velocity = rng.normal(size=(n, 3))
    velocity *= rng.uniform(0.5, 5.0, (n, 1)) / np.linalg.norm(velocity, axis=1)[:, None]
    mass = rng.uniform(0.5, 2.0, n)
    return ws.Swarm(position, velocity, radius=r, mass=mass), mass


@pytest.mark.slow
@pytest.mark.parametrize("precision,frames", [("float32", 10_000), ("float64", 2_000)])
def test_energy_kept_in_a_closed_room(device, precision, frames):
    """Closed room, k = 1, correction on: the per-sphere energy is a constant of the motion
    (README "What it models"), and the mechanical energy 1/2 m |v|^2 - m g . (p - origin) of
    the state equals it to rounding at every checkpoint: within ROUND_ULPS ulps of the energy scale
    1/2 m v_max^2 + m g (room height), never more (no gain), whatever the number of frames."""
    half = 1.0
    swarm, mass = closed_room_swarm(64, seed=3, half=half)
    sim = ws.Simulator(ws.Scene(closed_room(half)), swarm, precision=precision, device=device)
    e0 = sim.initial_energy.astype(np.float64)
    tol = ROUND_ULPS * EPS[precision] * (0.5 * mass * 5.0**2 + mass * G * 2.0 * half)
    p_tol = PIECE_ULPS * EPS[precision] * (2.0 * half + 5.0 * DT) * (MAX_BOUNCES + 1)
    for _ in range(frames // 250):
        sim.step(250)
        state = sim.state()
        np.testing.assert_array_equal(state.energy, e0.astype(precision))
        assert np.all(np.abs(sim.mechanical_energy(state) - e0) <= tol)
        assert np.all(np.abs(state.position) <= half - 0.05 + p_tol)
    assert sim.stats.capped == 0


# -- resting and starting in contact ------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("offset", [0.0, 1.0e3])
def test_spheres_at_rest_on_a_floor_stay_put(device, offset, precision):
    """Spheres of radius 0.01 to 1 m resting on a floor (centre at y = r), at the origin and
    1 km away: at every one of 10 000 frames none has moved (< 1e-6 m, no jitter), none sank
    (distance to the floor >= r - one ulp of the coordinates, the rounding of the input
    itself); speed 0 at the end."""
    rng = np.random.default_rng(0)
    n = 16
    center = np.array([offset, offset, -offset])
    r = rng.choice([0.01, 0.05, 0.25, 1.0], n)
    xz = rng.uniform(-10.0, 10.0, (n, 2))
    position = center + np.column_stack([xz[:, 0], r, xz[:, 1]])
    boxes = floor(center, half=20.0)
    sim = ws.Simulator(ws.Scene(boxes), ws.Swarm(position, np.zeros((n, 3)), radius=r),
                       precision=precision, device=device)
    positions = sim.run(10_000).position.astype(np.float64)  # every frame
    assert np.abs(positions - positions[0]).max() < 1e-6
    ulp = EPS[precision] * (np.abs(center).max() + 20.0)
    assert inside_depth(boxes, positions, np.tile(r, len(positions))) <= ulp
    np.testing.assert_array_equal(sim.state().velocity, 0.0)


#: name, velocity, expected position after one frame (from (r, 1, 0)), contacts
WALL_CONTACT_CASES = [
    ("moving-away", (1.0, 0.0, 0.0), (0.25 + DT, 1.0 - G_DT2 / 2, 0.0), 0),
    ("moving-along", (0.0, 0.0, 1.0), (0.25, 1.0 - G_DT2 / 2, DT), 0),
    ("moving-along-down", (0.0, -1.0, 1.0), (0.25, 1.0 - DT - G_DT2 / 2, DT), 0),
    ("moving-into", (-1.0, 0.0, 0.0), (0.25 + DT, 1.0 - G_DT2 / 2, 0.0), 1),
]


@pytest.mark.parametrize("case", WALL_CONTACT_CASES, ids=[c[0] for c in WALL_CONTACT_CASES])
def test_sphere_starting_in_contact_with_a_wall(device, case):
    """A sphere (r = 1/4) touching the wall x = 0 (normal +x), gravity along the wall: moving
    away or along it is no contact (the chord v dt + g dt^2 / 2 of the free flight);
    moving into it is a contact at t = 0 and the whole path is reflected. After 60 frames it is
    still outside the wall."""
    name, velocity, expected, contacts = case
    boxes = ws.RoundedBoxes(center=[(-0.5, 0.0, 0.0)], half_extents=[(0.5, 10.0, 10.0)])
    sim = ws.Simulator(ws.Scene(boxes), ws.Swarm([(0.25, 1.0, 0.0)], [velocity], radius=0.25),
                       device=device)
    sim.step()
    state = sim.state()
    tol = PIECE_ULPS * EPS["float32"] * 2.0 * 2
    np.testing.assert_allclose(state.position[0], expected, rtol=0, atol=tol)
    assert sim.stats.bounces == contacts, name
    sim.step(59)
    assert inside_depth(boxes, sim.state().position, 0.25) <= tol


# -- hard scenes -------------------------------------------------------------------------------


def plates_in_a_room(rng, half, half_thickness, count=6):
    plates = ws.RoundedBoxes(center=rng.uniform(-0.5 * half, 0.5 * half, (count, 3)),
                             half_extents=np.tile([0.4 * half, half_thickness, 0.4 * half],
                                                  (count, 1)),
                             rotation=random_unit_quaternions(rng, count))
    return ws.RoundedBoxes.concatenate([closed_room(half), plates])


@pytest.mark.slow
@pytest.mark.parametrize("half_thickness", [0.0, 1e-3])
@pytest.mark.parametrize("speed", [60.0, 600.0])
def test_fast_spheres_among_thin_rotated_plates(device, speed, half_thickness):
    """256 spheres at 60 m/s (1 m per frame) or 600 m/s (10 m per frame, several times the room)
    among six rotated plates in a closed 4 m room, 300 frames: no NaN, nobody escapes, nobody
    inside a box. Tolerance: PIECE_ULPS ulps of (room + path per frame) per piece, for the
    MAX_BOUNCES + 1 pieces of a frame."""
    rng = np.random.default_rng(int(speed) + int(half_thickness * 1e3))
    half, r, n = 2.0, 0.02, 256
    boxes = plates_in_a_room(rng, half, half_thickness)
    position = spawn_outside(rng, boxes, half, r, n)
    velocity = rng.normal(size=(n, 3))
    velocity *= speed / np.linalg.norm(velocity, axis=1)[:, None]
    sim = ws.Simulator(ws.Scene(boxes), ws.Swarm(position, velocity, radius=r), device=device)
    trajectory = sim.run(300)
    p = trajectory.position.reshape(-1, 3)
    tol = PIECE_ULPS * EPS["float32"] * (2.0 * half + speed * DT) * (MAX_BOUNCES + 1)
    assert np.isfinite(p).all()
    assert np.abs(p).max() <= half - r + tol
    assert inside_depth(boxes, p, r) <= tol
    assert np.isfinite(sim.state().velocity).all()


@pytest.mark.slow
def test_narrow_wedge_caps_and_never_lets_a_sphere_in(device):
    """Two zero-thickness plates 2 m long meeting at the origin, each 5 degrees from the
    vertical (a V); spheres (r = 5 cm) dropped in from 1.5 m. Deep in the V the gap between the
    plates closes to the sphere's diameter: contacts alternate faster and faster and the cap
    stops the sphere at its last contact. Nobody ever inside a plate, no NaN."""
    tilt = math.radians(5.0)

    def about_z(angle):
        return (0.0, 0.0, math.sin(angle / 2.0), math.cos(angle / 2.0))

    # local x of each plate along its length: rotate x to (+-sin tilt, cos tilt)
    plates = ws.RoundedBoxes(
        center=[(math.sin(tilt), math.cos(tilt), 0.0), (-math.sin(tilt), math.cos(tilt), 0.0)],
        half_extents=[(1.0, 0.0, 0.5)] * 2,
        rotation=[about_z(math.pi / 2 - tilt), about_z(math.pi / 2 + tilt)])
    boxes = ws.RoundedBoxes.concatenate([plates, closed_room(3.0)])
    rng = np.random.default_rng(0)
    n, r = 64, 0.05
    x = rng.uniform(-0.05, 0.05, n)
    x[0] = 0.0
    position = np.column_stack([x, np.full(n, 1.5), rng.uniform(-0.3, 0.3, n)])
    sim = ws.Simulator(ws.Scene(boxes), ws.Swarm(position, np.zeros((n, 3)), radius=r),
                       device=device)
    trajectory = sim.run(600)
    tol = PIECE_ULPS * EPS["float32"] * (3.0 + 10.0 * DT) * (MAX_BOUNCES + 1)
    assert np.isfinite(trajectory.position).all()
    assert sim.stats.capped > 0
    assert inside_depth(boxes, trajectory.position, r) <= tol
    # the energy is a per-sphere constant: the cap never adds any
    np.testing.assert_array_equal(sim.state().energy, sim.initial_energy.astype(np.float32))
    assert np.all(sim.mechanical_energy() <= sim.initial_energy + energy_gain_tolerance(
        1.0, 0.0, 3.0, "float32"))


@pytest.mark.slow
def test_random_scenes_with_losses_settle_without_entering_boxes(device):
    """Random rounded boxes in a room, k = 1/2, 1200 frames: spheres come to rest on faces,
    edges and in creases. At every checkpoint: no NaN, nobody inside, and the per-sphere
    energy never grows (contacts only remove energy)."""
    rng = np.random.default_rng(23)
    half, n = 1.5, 64
    boxes = random_scene(rng, half, 4)
    r = rng.uniform(0.01, 0.1, n)
    position = spawn_outside(rng, boxes, half, r, n)
    velocity = rng.normal(size=(n, 3)) * 3.0
    sim = ws.Simulator(ws.Scene(boxes, energy_retention=0.5),
                       ws.Swarm(position, velocity, radius=r), device=device)
    energy = sim.initial_energy.astype(np.float64)
    tol = PIECE_ULPS * EPS["float32"] * (2.0 * half + 1.0) * (MAX_BOUNCES + 1)
    e_tol = ROUND_ULPS * EPS["float32"] * (0.5 * 10.0**2 + G * 2.0 * half)
    for _ in range(60):
        trajectory = sim.run(20)
        assert np.isfinite(trajectory.position).all()
        assert inside_depth(boxes, trajectory.position[1:], np.tile(r, 20)) <= tol
        state = sim.state()
        assert np.all(state.energy <= energy + e_tol)
        energy = state.energy.astype(np.float64)
    assert energy.sum() < 0.9 * sim.initial_energy.sum()  # the losses did act


# -- invariants over random scenes ----------------------------------------------------------------


def energy_gain_tolerance(mass, speed, height, precision):
    """How far the mechanical energy of a state may exceed the sphere's energy ``E`` [J].

    Rounding (ROUND_ULPS ulps of 1/2 m v^2 + m g h), plus the one overshoot the model allows:
    a frame's path is at most ``(v + g dt) dt`` long; if contacts turn it upward the sphere
    can end higher than ``E`` allows, by at most max over v of ``m g (v + g dt) dt - m v^2 / 2``
    = ``1.5 m g (g dt^2)`` (at v = g dt), and the reset then sets its speed to 0. ``E`` itself
    never changes (k = 1).
    """
    rounding = ROUND_ULPS * EPS[precision] * mass * (0.5 * speed**2 + G * height)
    return rounding + 1.5 * mass * G * G_DT2


@pytest.mark.slow
@pytest.mark.parametrize("device", DEVICES)
@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), count=st.integers(1, 5),
       speed=st.floats(0.0, 20.0), radius=st.floats(0.005, 0.15))
def test_invariants_over_random_scenes(device, seed, count, speed, radius):
    """No NaN, nobody inside a box (or out of the room), no energy gain: the per-sphere energy
    is constant (k = 1) and the state's mechanical energy never exceeds it by more than
    :func:`energy_gain_tolerance`."""
    rng = np.random.default_rng(seed)
    half, n, frames = 1.5, 32, 120
    boxes = random_scene(rng, half, count)
    position = spawn_outside(rng, boxes, half, radius, n)
    velocity = rng.normal(size=(n, 3))
    velocity *= speed * rng.random((n, 1)) / np.linalg.norm(velocity, axis=1)[:, None]
    mass = rng.uniform(0.5, 2.0, n)
    sim = ws.Simulator(ws.Scene(boxes), ws.Swarm(position, velocity, radius=radius, mass=mass),
                       device=device)
    e0 = sim.initial_energy.astype(np.float64)
    tol = PIECE_ULPS * EPS["float32"] * (2.0 * half + speed * DT) * (MAX_BOUNCES + 1)
    e_tol = energy_gain_tolerance(mass, speed, 2.0 * half, "float32")
    for _ in range(frames // 20):
        trajectory = sim.run(20)
        p = trajectory.position[1:]
        assert np.isfinite(p).all()
        assert np.abs(p).max() <= half - radius + tol
        assert inside_depth(boxes, p, radius) <= tol
        state = sim.state()
        np.testing.assert_array_equal(state.energy, e0.astype(np.float32))
        assert np.all(sim.mechanical_energy(state) <= e0 + e_tol)


# -- determinism -------------------------------------------------------------------------------


def state_digest(state) -> str:
    h = hashlib.sha256()
    for a in (state.position, state.velocity, state.angular_momentum, state.orientation,
              state.energy):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


@pytest.mark.slow
@pytest.mark.parametrize("friction", [0.0, 0.5], ids=["no-spin", "spin"])
def test_same_inputs_give_bit_identical_states(friction, device):
    """Two simulators built from the same inputs: bit-identical states after 200 frames of a
    hard scene (fast spheres among thin plates, cap reached), and equal state hashes; a third
    run stepped in uneven chunks gives the same bits."""
    rng = np.random.default_rng(99)
    half, r, n = 2.0, 0.02, 128
    boxes = plates_in_a_room(rng, half, 0.0)
    position = spawn_outside(rng, boxes, half, r, n)
    velocity = rng.normal(size=(n, 3)) * 100.0

    def simulate(chunks):
        sim = ws.Simulator(ws.Scene(boxes, friction=friction),
                           ws.Swarm(position, velocity, radius=r), device=device)
        for c in chunks:
            sim.step(c)
        return sim

    a, b, c = simulate([200]), simulate([200]), simulate([1, 99, 37, 63])
    assert a.stats.capped > 0
    sa, sb, sc = a.state(), b.state(), c.state()
    for field in ("position", "velocity", "angular_momentum", "orientation", "energy"):
        np.testing.assert_array_equal(getattr(sa, field), getattr(sb, field))
        np.testing.assert_array_equal(getattr(sa, field), getattr(sc, field))
    assert state_digest(sa) == state_digest(sb) == state_digest(sc)
    assert (a.stats.bounces, a.stats.capped) == (b.stats.bounces, b.stats.capped)


# -- bad input -----------------------------------------------------------------------------------

GOOD_SWARM = dict(position=np.zeros((5, 3)) + (0.0, 1.0, 0.0), velocity=np.zeros((5, 3)))


@pytest.mark.parametrize("kwargs,message", [
    (dict(position=np.array([[0, 1, 0]] * 3 + [[np.nan, 1, 0]] + [[0, 1, 0]], float)),
     r"position\[3\] must be finite"),
    (dict(position=np.array([[0, 1, 0]] * 3 + [[np.inf, 1, 0]] + [[0, 1, 0]], float)),
     r"position\[3\] must be finite"),
    (dict(velocity=np.array([[0, 0, 0], [0, -np.inf, 0]] + [[0, 0, 0]] * 3, float)),
     r"velocity\[1\] must be finite"),
    (dict(radius=-0.1), r"radius must be >= 0"),
    (dict(radius=[0.1, 0.1, -0.1, 0.1, 0.1]), r"radius\[2\] must be >= 0"),
    (dict(mass=0.0), r"mass must be > 0"),
    (dict(mass=[1.0, 1.0, 1.0, 1.0, -2.0]), r"mass\[4\] must be > 0"),
    (dict(orientation=[[0, 0, 0, 1]] * 2 + [[0, 0, 0, 0]] + [[0, 0, 0, 1]] * 2),
     r"orientation\[2\] must be a non-zero quaternion"),
    (dict(orientation=[0, 0, 0, 0]), r"orientation\[0\] must be a non-zero quaternion"),
    (dict(angular_momentum=[[0, 0, 0]] * 4 + [[0, np.nan, 0]]),
     r"angular_momentum\[4\] must be finite"),
    (dict(position=np.zeros((5, 2))), r"position must have shape \(N, 3\)"),
    (dict(velocity=np.zeros((4, 3))), r"velocity must have shape \(5, 3\)"),
    (dict(radius=[0.1, 0.1]), r"radius must be a scalar or have shape \(5,\)"),
    (dict(orientation=np.zeros((5, 3))), r"orientation must have shape \(5, 4\)"),
])
def test_bad_swarm_refused_naming_the_field(kwargs, message):
    args = dict(GOOD_SWARM)
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        ws.Swarm(**args)


@pytest.mark.parametrize("kwargs,message", [
    (dict(dt=0.0), r"dt must be > 0"),
    (dict(dt=-DT), r"dt must be > 0"),
    (dict(dt=float("nan")), r"dt must be finite"),
    (dict(max_bounces=0), r"max_bounces must be >= 1"),
    (dict(max_bounces=2.5), r"max_bounces must be an integer"),
    (dict(precision="float16"), r"precision must be one of"),
    (dict(precision="double"), r"precision must be one of"),
])
def test_bad_simulator_arguments_refused(device, kwargs, message):
    with pytest.raises(ValueError, match=message):
        ws.Simulator(ws.Scene(floor()), ws.Swarm(**GOOD_SWARM), **kwargs, device=device)


@pytest.mark.parametrize("kwargs,message", [
    (dict(gravity=(0.0, np.nan, 0.0)), r"gravity must be finite"),
    (dict(friction=-1.0), r"friction must be >= 0"),
    (dict(energy_retention=0.0), r"energy_retention must be > 0"),
    (dict(energy_retention=1.5), r"energy_retention must be <= 1"),
    (dict(max_angular_speed=0.0), r"max_angular_speed must be > 0"),
])
def test_bad_scene_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ws.Scene(floor(), **kwargs)


def test_bad_frames_refused(device):
    sim = ws.Simulator(ws.Scene(floor()), ws.Swarm(**GOOD_SWARM), device=device)
    for call in (lambda: sim.step(0), lambda: sim.run(0), lambda: sim.run(5, every=0)):
        with pytest.raises(ValueError, match=r"(frames|every) must be >= 1"):
            call()
    assert sim.frame == 0


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("scene_name, velocities, spheres", [
    ("room", False, None), ("nozzle", True, None), ("spin", True, [5, 0, 17])])
def test_recorded_arrays_made_by_allocate_hold_the_same_frames(precision, scene_name,
                                                              velocities, spheres):
    """``Simulator.run(allocate=...)``: views of one buffer, strided ones included, hold the
    same bits as the default arrays (births' NaN rows, velocities, a subset of spheres)."""
    scene = ws.Scene.load(scene_name)
    swarm = scene.spawn(n=40, seed=2)
    asked = []
    pool = np.full(1 << 20, 7.0)  # float64 storage, so a float32 array can be a strided view

    def allocate(shape, dtype):
        asked.append((tuple(shape), np.dtype(dtype)))
        size = int(np.prod(shape))
        start = sum(int(np.prod(a)) for a, _ in asked[:-1]) * 2
        if dtype == np.float64:
            return pool[start:start + size].reshape(shape)
        return pool[start:start + size].view(np.float32)[::2].reshape(shape)  # strided

    runs = []
    for allocate_with in (None, allocate):
        sim = ws.Simulator(scene, swarm, precision=precision)
        runs.append(sim.run(25, every=4, velocities=velocities, spheres=spheres,
                            allocate=allocate_with))
    plain, made = runs
    names = ["position", "orientation"] + (["velocity", "angular_velocity"] if velocities
                                           else [])
    assert [shape for shape, _ in asked] == [getattr(plain, name).shape for name in names]
    assert all(dtype == np.dtype(precision) for _, dtype in asked)
    for name in names:
        assert np.shares_memory(getattr(made, name), pool)
        np.testing.assert_array_equal(getattr(made, name), getattr(plain, name))
    if scene_name == "nozzle":
        assert np.isnan(made.position).any()


@pytest.mark.parametrize("allocate, message", [
    ("np.empty", r"allocate must be a function \(shape, dtype\) -> array or None, got str"),
    (lambda shape, dtype: np.empty(shape[:-1], dtype),
     r"allocate returned a float32 array of shape \(4, 5\) for position, expected a writable "
     r"float32 array of shape \(4, 5, 3\)"),
    (lambda shape, dtype: np.empty(shape, np.float64),
     r"returned a float64 array of shape \(4, 5, 3\) for position"),
    (lambda shape, dtype: np.empty(shape, dtype).tolist(), r"returned list for position"),
    (lambda shape, dtype: np.broadcast_to(np.empty(1, dtype), shape),
     r"returned a read-only float32 array of shape \(4, 5, 3\) for position"),
])
def test_bad_allocate_refused_before_any_frame(allocate, message):
    sim = ws.Simulator(ws.Scene(floor()), ws.Swarm(**GOOD_SWARM))
    with pytest.raises(ValueError, match=message):
        sim.run(3, allocate=allocate)
    assert sim.frame == 0


def test_inputs_never_mutated_and_swarm_holds_copies(device):
    rng = np.random.default_rng(4)
    n = 8
    arrays = dict(position=rng.uniform(0.2, 1.0, (n, 3)), velocity=rng.normal(size=(n, 3)),
                  radius=np.full(n, 0.1), mass=rng.uniform(1.0, 2.0, n),
                  angular_momentum=rng.normal(size=(n, 3)) * 1e-3,
                  orientation=random_unit_quaternions(rng, n) * 3.0)  # not unit: normalised
    before = {k: v.copy() for k, v in arrays.items()}
    swarm = ws.Swarm(**arrays)
    for name, value in arrays.items():
        np.testing.assert_array_equal(value, before[name])
        assert not np.shares_memory(getattr(swarm, name), value), name
    snapshot = {k: getattr(swarm, k).copy() for k in arrays}
    arrays["position"][0] = 99.0  # the caller's arrays are theirs to change
    np.testing.assert_array_equal(swarm.position, snapshot["position"])
    sim = ws.Simulator(ws.Scene(floor(), friction=0.5), swarm, device=device)
    sim.step(30)
    state = sim.state()
    for name in snapshot:
        np.testing.assert_array_equal(getattr(swarm, name), snapshot[name])
    state.position[:] = 0.0  # a state is a copy too
    assert not np.array_equal(sim.state().position, state.position)


# -- kernel variants -----------------------------------------------------------------------------


def test_no_spin_variant_leaves_orientation_and_angular_momentum_as_given(device):
    """Friction 0 and no initial spin: the kernel without spin code is used and the orientation
    stays exactly the given (normalised) quaternion, the angular momentum exactly zero, while
    the spheres bounce around a room."""
    rng = np.random.default_rng(8)
    n = 32
    swarm, _ = closed_room_swarm(n, seed=8)
    orientation = random_unit_quaternions(rng, n)
    swarm = ws.Swarm(swarm.position, swarm.velocity, radius=0.05, orientation=orientation)
    sim = ws.Simulator(ws.Scene(closed_room(1.0)), swarm, device=device)
    assert sim.spin is False
    sim.step(300)
    state = sim.state()
    assert sim.stats.bounces > 0
    np.testing.assert_array_equal(state.orientation, swarm.orientation.astype(np.float32))
    np.testing.assert_array_equal(state.angular_momentum, 0.0)


def test_initial_spin_without_friction_turns_at_constant_rate(device):
    """Friction 0 but a sphere spinning from the start: the spin variant runs, L stays as given
    (no friction torque) and the orientation turns by |Rot| dt per frame about Rot = L / I:
    after k frames o = exp(1/2 Rot k dt) o0 (constant Rot, so the frame steps compose)."""
    r, m = 0.5, 2.0
    inertia = 0.4 * m * r * r
    rot = np.array([0.0, 3.0, 4.0])  # |Rot| = 5 rad/s < the clamp
    L = rot * inertia
    q0 = np.array([0.0, 0.0, math.sin(0.3), math.cos(0.3)])
    swarm = ws.Swarm([(0.0, 2.0, 0.0)], [(0.0, 0.0, 0.0)], radius=r, mass=m,
                     angular_momentum=[L], orientation=[q0])
    sim = ws.Simulator(ws.Scene(floor((0.0, -100.0, 0.0)), gravity=(0.0, 0.0, 0.0)), swarm,
                       device=device)
    assert sim.spin is True
    frames = 120
    sim.step(frames)
    state = sim.state()
    np.testing.assert_allclose(state.angular_momentum[0], L, rtol=4 * EPS["float32"])
    angle = 5.0 * DT * frames
    axis = rot / 5.0
    turn = np.append(math.sin(angle / 2) * axis, math.cos(angle / 2))
    expected = quat_multiply(turn, q0)
    got = state.orientation[0].astype(np.float64)
    if got @ expected < 0.0:
        got = -got
    np.testing.assert_allclose(got, expected, rtol=0, atol=frames * 4 * EPS["float32"])
