"""One frame of exact ballistic motion (``kernels.ballistic.ballistic_path``), frame after frame.

A tiny test kernel advances every sphere by one frame with ``ballistic_path`` and nothing else
(no energy reset): positions, velocities and energies are what the motion itself gives. The
answers are closed forms: in a room of axis-aligned walls the motion separates by axis (a
sideways coordinate folds back and forth between two walls at constant speed, the height is a
ball bouncing on the floor with the same period every hop), a slide down a frictionless slope
goes as ``1/2 g sin(theta) t^2``, and energy is conserved by the physics with retention 1.
"""

from functools import cache

import numpy as np
import pytest
import warp as wp
from helpers import closed_room
from hypothesis import example, given, settings
from hypothesis import strategies as st
from test_arc_sweep import device_boxes

import warpsim as ws
from warpsim.kernels.ballistic import ballistic_funcs
from warpsim.kernels.data import BROAD_PHASES, Features, model_structs
from warpsim.kernels.precision import precision as precision_of
from warpsim.model import event_buffer

#: Contacts per frame in the test kernels (the cap test needs more than this in one frame).
MAX_BOUNCES = 4

GRAVITY = 9.81
HALF = 2.0  # the room's inner faces are the planes +-HALF on every axis
R = 0.125  # sphere radius
L = HALF - R  # the centre's reach

#: Closed-form agreement of positions [m] after a few hundred contacts, per precision: float64
#: rounding of the roots (~1e-15 s per contact) grows with the number of contacts; float32 is
#: the rounding of 2 m coordinates (1.2e-7 relative) times the contacts.
POSITION_TOL = {"float32": 1e-4, "float64": 1e-12}

#: Energy drift [J per J of energy scale] allowed over the run, per precision (no correction).
ENERGY_TOL = {"float32": 2e-5, "float64": 1e-12}


@cache
def path_kernel(precision_name: str, lossy: bool, spin: bool):
    """Test kernel: one frame of ``ballistic_path`` per sphere (brute-force boxes)."""
    p = precision_of(precision_name)
    scalar, vec3 = p.scalar, p.vec3
    Boxes, BroadPhase, Physics, EventBuffer = model_structs(p)
    ballistic_path = ballistic_funcs(Features(precision=precision_name, motion="ballistic",
                                              spin=spin, lossy=lossy)).ballistic_path

    @wp.kernel(enable_backward=False, module="unique")
    def ballistic_path_test(
        boxes: Boxes, broad: BroadPhase, physics: Physics,
        radius: wp.array[scalar], mass: wp.array[scalar],
        position_in: wp.array[vec3], velocity_in: wp.array[vec3],
        angular_momentum_in: wp.array[vec3], energy_in: wp.array[scalar],
        position_out: wp.array[vec3], velocity_out: wp.array[vec3],
        angular_momentum_out: wp.array[vec3], energy_out: wp.array[scalar],
        bounce_count: wp.array[wp.int32], capped_count: wp.array[wp.int32],
        supported_count: wp.array[wp.int32], events_out: EventBuffer,
    ):
        i = wp.tid()
        x, v, ang, e, bounces, capped, supported = ballistic_path(
            position_in[i], velocity_in[i], radius[i], mass[i], angular_momentum_in[i],
            energy_in[i], physics, boxes, broad, 0, i, events_out)
        position_out[i] = x
        velocity_out[i] = v
        angular_momentum_out[i] = ang
        energy_out[i] = e
        bounce_count[i] += bounces
        capped_count[i] += capped
        supported_count[i] += supported

    return ballistic_path_test


def physics_struct(p, dt: float, friction: float = 0.0, retention: float = 1.0,
                   max_bounces: int = MAX_BOUNCES):
    """The kernels' ``Physics`` for these tests: gravity ``-GRAVITY`` along y, the potential's
    origin at 0, ``max_rot`` 50 rad/s, the cap on contacts a frame ``max_bounces``."""
    physics = model_structs(p).Physics()
    physics.gravity = p.vec3(0.0, -GRAVITY, 0.0)
    physics.origin = p.vec3(0.0, 0.0, 0.0)
    physics.dt, physics.friction = p.scalar(dt), p.scalar(friction)
    physics.max_rot, physics.retention = p.scalar(50.0), p.scalar(retention)
    physics.max_bounces = max_bounces
    return physics


def run(boxes, x, v, frames, dt, precision_name="float64", radius=R, retention=1.0,
        spin=False, friction=0.0, record=False):
    """Advance spheres ``frames`` frames; returns the final state (float64 numpy) and counters."""
    p = precision_of(precision_name)
    dtp = p.np_dtype
    n = len(x)
    device_structs = device_boxes(boxes, p)
    physics = physics_struct(p, dt, friction, retention)
    g = np.array([0.0, -GRAVITY, 0.0])
    mass = np.ones(n)
    r = np.broadcast_to(np.asarray(radius, float), (n,))
    x = np.asarray(x, float).astype(dtp)
    v = np.asarray(v, float).astype(dtp)
    energy = 0.5 * mass * np.einsum("ij,ij->i", v.astype(float), v.astype(float)) \
        - mass * (x.astype(float) @ g)

    def put(a, dtype):
        return wp.array(np.ascontiguousarray(a, dtype=dtp), dtype=dtype)

    state = [put(x, p.vec3), put(v, p.vec3), put(np.zeros((n, 3)), p.vec3), put(energy, p.scalar)]
    spare = [wp.empty_like(a) for a in state]
    counts = [wp.zeros(n, dtype=wp.int32) for _ in range(3)]
    kernel = path_kernel(p.name, retention < 1.0, spin)
    history = []
    for _ in range(frames):
        wp.launch(kernel, dim=n, inputs=[*device_structs[:2], physics, put(r, p.scalar),
                                         put(mass, p.scalar), *state],
                  outputs=[*spare, *counts, event_buffer(p, "cpu", 0)])
        state, spare = spare, state
        if record:
            history.append(state[0].numpy().astype(float))
    out = {"position": state[0].numpy(), "velocity": state[1].numpy(),
           "angular_momentum": state[2].numpy(), "energy": state[3].numpy(),
           "bounces": counts[0].numpy(), "capped": counts[1].numpy(),
           "supported": counts[2].numpy(), "initial_energy": energy}
    if record:
        out["history"] = np.array(history)
    return out


def folded(x0, vx, t):
    """Position and velocity along an axis between walls at +-L (elastic, constant speed)."""
    w = np.mod(x0 + vx * t + L, 4.0 * L)
    forward = w <= 2.0 * L
    return np.where(forward, w - L, 3.0 * L - w), np.where(forward, vx, -vx)


def bouncing(y0, vy0, t):
    """Height and vertical velocity of a ball bouncing elastically on the floor y = -L."""
    g = GRAVITY
    v_floor = np.sqrt(vy0**2 + 2.0 * g * (y0 + L))
    t1 = (vy0 + v_floor) / g
    period = 2.0 * v_floor / g
    phase = np.mod(t - t1, period)
    before = t < t1
    y = np.where(before, y0 + vy0 * t - 0.5 * g * t * t,
                 -L + v_floor * phase - 0.5 * g * phase * phase)
    vy = np.where(before, vy0 - g * t, v_floor - g * phase)
    return y, vy


def room_spheres(rng, n):
    """Spheres inside the room that never reach the ceiling."""
    x = rng.uniform(-L + 0.1, L - 0.1, (n, 3))
    x[:, 1] = rng.uniform(-1.0, 1.0, n)
    v = rng.uniform(-6.0, 6.0, (n, 3))
    v[:, 1] = rng.uniform(-2.0, 2.0, n)
    return x, v


def closed_form(x, v, t):
    xs, vx = folded(x[:, 0], v[:, 0], t)
    ys, vy = bouncing(x[:, 1], v[:, 1], t)
    zs, vz = folded(x[:, 2], v[:, 2], t)
    return np.stack([xs, ys, zs], axis=1), np.stack([vx, vy, vz], axis=1)


@pytest.mark.slow
@pytest.mark.parametrize("dt", [1.0 / 30.0, 1.0 / 240.0], ids=["dt30", "dt240"])
def test_room_against_closed_form(dt, precision):
    """Floor and two pairs of walls: after 1 s the state is the closed-form reflection of the
    parabola, at both step sizes (the error does not depend on dt)."""
    rng = np.random.default_rng(1)
    x, v = room_spheres(rng, 64)
    x = x.astype(precision_of(precision).np_dtype).astype(float)
    v = v.astype(precision_of(precision).np_dtype).astype(float)
    frames = int(round(1.0 / dt))
    out = run(closed_room(HALF), x, v, frames, dt, precision)
    assert out["capped"].sum() == 0
    assert out["bounces"].sum() > 100
    x_ref, v_ref = closed_form(x, v, frames * dt)
    np.testing.assert_allclose(out["position"], x_ref, atol=POSITION_TOL[precision])
    np.testing.assert_allclose(out["velocity"], v_ref, atol=POSITION_TOL[precision] * 50)


@pytest.mark.slow
def test_energy_conserved_without_correction(precision):
    """Retention 1, no energy reset: 2000 frames of bouncing keep ``1/2 m v^2 + m g y`` to
    float precision (the physics conserves it; what drifts is rounding)."""
    rng = np.random.default_rng(2)
    x, v = room_spheres(rng, 32)
    out = run(closed_room(HALF), x, v, 2000, 1.0 / 60.0, precision)
    pos, vel = out["position"].astype(float), out["velocity"].astype(float)
    e = 0.5 * np.einsum("ij,ij->i", vel, vel) + GRAVITY * pos[:, 1]
    scale = np.abs(out["initial_energy"]) + GRAVITY * HALF
    assert out["capped"].sum() == 0
    assert np.all(np.abs(e - out["initial_energy"]) <= ENERGY_TOL[precision] * scale)
    assert np.all(np.abs(out["energy"] - out["initial_energy"]) <= ENERGY_TOL[precision] * scale)
    assert np.all(np.abs(pos) <= L + POSITION_TOL[precision])


def test_resting_sphere_stays_bit_for_bit(precision):
    """At rest on the floor (and one in a corner, touching two walls): 200 frames, unchanged."""
    dtp = precision_of(precision).np_dtype
    x = np.array([[0.25, -L, -0.5], [-L, -L, L]], dtp)
    out = run(closed_room(HALF), x, np.zeros((2, 3)), 200, 1.0 / 60.0, precision)
    np.testing.assert_array_equal(out["position"], x)
    np.testing.assert_array_equal(out["velocity"], 0.0)
    assert out["capped"].sum() == 0 and out["supported"].min() == 200


def test_sphere_slides_down_a_slope(precision):
    """A frictionless slope at 30 degrees: from rest on it, ``1/2 g sin(30) t^2`` along it."""
    theta = np.radians(30.0)
    q = (0.0, 0.0, np.sin(theta / 2), np.cos(theta / 2))  # about z: local x tilts up
    slope = ws.RoundedBoxes(center=[(0.0, 0.0, 0.0)], half_extents=[(20.0, 0.5, 2.0)],
                            rotation=[q])
    normal = np.array([-np.sin(theta), np.cos(theta), 0.0])
    down = -np.array([np.cos(theta), np.sin(theta), 0.0])
    x0 = normal * (0.5 + R) + np.array([np.cos(theta), np.sin(theta), 0.0]) * 2.0
    t = 0.5
    out = run(slope, x0[None], np.zeros((1, 3)), 30, t / 30, precision)
    along = 0.5 * GRAVITY * np.sin(theta) * t * t
    tol = 1e-9 if precision == "float64" else 2e-5
    np.testing.assert_allclose(out["position"][0], x0 + along * down, atol=tol)
    np.testing.assert_allclose(out["velocity"][0], GRAVITY * np.sin(theta) * t * down,
                               atol=tol * 10)


#: Capped frames a lossy ball may take while it settles: hops shorter than a frame's share of
#: the cap (``dt / MAX_BOUNCES``, from 20 mm/s at 1/60 s) down to the 5 mm/s of a support are
#: about four bounces at retention 0.5, so a frame or two per settling (a few more on slopes).
SETTLING_CAPPED_FRAMES = 8


@pytest.mark.slow
def test_lossy_ball_comes_to_rest():
    """Retention 0.5 (and spin): hops shrink, then a support (hops below 5 mm/s are not made:
    no Zeno loop); the cap only in the last short hops, never inside the floor, the energy
    never rises and ends at rest on the floor."""
    rng = np.random.default_rng(3)
    x, v = room_spheres(rng, 16)
    out = run(closed_room(HALF), x, v, 600, 1.0 / 60.0, "float64", retention=0.5, spin=True,
              friction=0.2, record=True)
    hist = out["history"]
    assert out["capped"].max() <= SETTLING_CAPPED_FRAMES
    assert hist[:, :, 1].min() >= -L - 1e-12
    np.testing.assert_allclose(out["position"][:, 1], -L, atol=1e-12)
    np.testing.assert_allclose(out["velocity"][:, 1], 0.0, atol=1e-12)
    assert np.all(out["energy"] <= out["initial_energy"])
    assert np.isfinite(out["angular_momentum"]).all()
    assert np.abs(out["angular_momentum"]).max() > 0.0


@pytest.mark.slow
def test_point_never_crosses_a_plate(precision):
    """R = 0 against a zero-thickness plate, elastic: points dropped on it bounce on it forever
    (never below it while over it)."""
    rng = np.random.default_rng(4)
    n = 64
    plate = ws.RoundedBoxes(center=[(0.0, 0.0, 0.0)], half_extents=[(8.0, 0.0, 8.0)])
    x = np.stack([rng.uniform(-1, 1, n), rng.uniform(0.0, 2.0, n), rng.uniform(-1, 1, n)], 1)
    v = rng.normal(0.0, 0.3, (n, 3))
    out = run(plate, x, v, 300, 1.0 / 60.0, precision, radius=0.0, record=True)
    hist = out["history"]
    over = (np.abs(hist[:, :, 0]) < 8.0) & (np.abs(hist[:, :, 2]) < 8.0)
    assert over.all()
    assert hist[:, :, 1].min() >= 0.0
    assert out["bounces"].min() >= 2


def test_cap_stops_at_the_last_contact():
    """Fast along a corridor 0.5 m wide: more than MAX_BOUNCES contacts in one frame; the
    sphere stays at its last contact (a wall plane) with the reflected velocity."""
    walls = ws.RoundedBoxes(center=[(-0.75, 0.0, 0.0), (0.75, 0.0, 0.0)],
                            half_extents=[(0.5, 10.0, 10.0), (0.5, 10.0, 10.0)])
    x = np.array([[0.0, 0.0, 0.0]])
    v = np.array([[10.0, 0.0, 0.0]])
    dt = 0.12  # 1.2 m of travel: contacts after 0.125, 0.375, 0.625, 0.875 and 1.125 m
    out = run(walls, x, v, 1, dt, "float64")
    assert out["capped"][0] == 1 and out["bounces"][0] == MAX_BOUNCES
    # four contacts: +x wall, -x wall, +x, -x; the centre is on the -x wall's plane
    t_last = (0.125 + 3 * 0.25) / 10.0
    expect = np.array([-0.125, -0.5 * GRAVITY * t_last**2, 0.0])
    np.testing.assert_allclose(out["position"][0], expect, atol=1e-12)
    np.testing.assert_allclose(out["velocity"][0], [10.0, -GRAVITY * t_last, 0.0], atol=1e-12)


def tilted_plates():
    """Four tilted rounded plates over a floor (the accuracy study's kind of scene)."""
    angles = np.array([0.3, -0.25, 0.2, -0.35])
    q = np.stack([np.zeros(4), np.zeros(4), np.sin(angles / 2), np.cos(angles / 2)], axis=1)
    plates = ws.RoundedBoxes(center=[(-3, -1, 0), (-1, -0.5, 0), (1, -1.2, 0.2), (3, -0.7, 0)],
                             half_extents=np.tile([0.9, 0.05, 1.0], (4, 1)), rotation=q,
                             radius=np.full(4, 0.1))
    floor = ws.RoundedBoxes(center=[(0.0, -4.0, 0.0)], half_extents=[(10.0, 0.5, 10.0)])
    return ws.RoundedBoxes.concatenate([plates, floor])


@pytest.mark.slow
def test_error_does_not_depend_on_dt(precision):
    """Dropped onto tilted rounded plates (faces, rounded edges): the state after 1 s is the
    same at four step sizes (float64 to 1e-9 m; float32 to its rounding as each sphere's
    contacts amplify it), and nobody is ever inside a box."""
    rng = np.random.default_rng(7)
    boxes = tilted_plates()
    n = 128
    x = np.stack([rng.uniform(-4, 4, n), rng.uniform(0.5, 2, n), rng.uniform(-1, 1, n)], axis=1)
    v = rng.normal(0.0, 1.0, (n, 3))
    finals = []
    for dt in (1 / 30, 1 / 60, 1 / 120, 1 / 240):
        out = run(boxes, x, v, int(round(1.0 / dt)), dt, precision, radius=0.1)
        assert out["capped"].sum() == 0 and out["bounces"].sum() > 100
        assert boxes.signed_distance(out["position"].astype(float)).min() >= 0.1 - 1e-6
        finals.append(out["position"].astype(float))
    err = np.abs(np.array(finals[:-1]) - finals[-1]).max(axis=2)
    if precision == "float64":
        assert err.max() <= 1e-9
    else:
        # float32: the rounding of 4 m coordinates (spacing 4.8e-7 m; 240 frames of half a
        # spacing, 6e-5 m, taken as 1e-4 m), amplified by the contacts. How much depends on
        # the sphere: one that meets rounded edges several times can move its end by 1 mm for
        # a start moved 1e-7 m (a seed of this test drew one whose float32 runs ended 4 cm
        # apart). Each sphere's bound is 5 mm plus that rounding times its own amplification,
        # measured on the float64 model (which agrees with itself to 1e-9 at every step size)
        # from a start moved 1e-7 m in a random direction.
        base = run(boxes, x, v, 240, 1 / 240, "float64", radius=0.1)["position"]
        d = np.random.default_rng(1).normal(size=x.shape)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        moved = run(boxes, x + 1e-7 * d, v, 240, 1 / 240, "float64", radius=0.1)["position"]
        amplification = np.linalg.norm(moved - base, axis=1) / 1e-7
        assert np.median(err) <= 5e-5
        assert np.all(err.max(axis=0) <= 5e-3 + 1e-4 * amplification), (
            err.max(axis=0).max(), amplification[np.argmax(err.max(axis=0))])


@pytest.mark.slow
def test_lossy_ball_settles_in_a_valley():
    """Two slopes meeting in a crease, retention 0.5: the second support makes the sphere slide
    along the crease (here level), so it comes to rest there; the cap only while it settles,
    never inside."""
    th = np.radians(25.0)
    down_left = np.array([np.sin(th), np.cos(th), 0.0])
    down_right = np.array([-np.sin(th), np.cos(th), 0.0])
    centers = [np.array([-2 * np.cos(th), 2 * np.sin(th), 0.0]) - 0.5 * down_left,
               np.array([2 * np.cos(th), 2 * np.sin(th), 0.0]) - 0.5 * down_right]
    valley = ws.RoundedBoxes(center=centers, half_extents=[(2, 0.5, 2), (2, 0.5, 2)],
                             rotation=[(0, 0, np.sin(-th / 2), np.cos(th / 2)),
                                       (0, 0, np.sin(th / 2), np.cos(th / 2))])
    x = np.array([[0.7, 1.5, 0.0], [-0.3, 1.0, 0.3], [0.05, 0.8, 0.0]])
    out = run(valley, x, np.zeros((3, 3)), 600, 1 / 60, "float64", radius=0.1, retention=0.5,
              record=True)
    assert out["capped"].max() <= SETTLING_CAPPED_FRAMES
    gap = valley.signed_distance(out["history"].reshape(-1, 3)).min(axis=1) - 0.1
    assert gap.min() >= -1e-12
    crease_y = 0.1 / np.cos(th)  # centre height touching both slopes at x = 0
    np.testing.assert_allclose(out["position"][:, :2], [[0.0, crease_y]] * 3, atol=1e-9)
    np.testing.assert_array_equal(out["velocity"], 0.0)


@pytest.mark.slow
@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), retention=st.sampled_from([1.0, 0.5]),
       dt=st.sampled_from([1 / 30, 1 / 60, 1 / 240]))
# a lossy sphere whose last hops hold more than the cap of four in a frame of 1/30 s
@example(seed=3, retention=0.5, dt=1 / 30)
def test_invariants(seed, retention, dt):
    """Random swarms in the plates scene: no NaN, nobody inside a box, energy never gained
    (tracked and of the state), the cap never reached by an elastic sphere (float64). A lossy
    one's last hops, shorter and shorter down to ``RESTING_SPEED``, can hold more contacts
    than the cap in a frame (``kernels/ballistic.py``): it stays at its last contact, a few
    frames at most."""
    rng = np.random.default_rng(seed)
    boxes = tilted_plates()
    n = 32
    x = np.stack([rng.uniform(-4, 4, n), rng.uniform(-0.3, 2, n), rng.uniform(-1, 1, n)], 1)
    x = x[boxes.signed_distance(x).min(axis=1) > 0.15]
    v = rng.normal(0.0, 3.0, (len(x), 3))
    out = run(boxes, x, v, 30, dt, "float64", radius=0.1, retention=retention)
    pos, vel = out["position"], out["velocity"]
    assert np.isfinite(pos).all() and np.isfinite(vel).all()
    assert boxes.signed_distance(pos).min() >= 0.1 - 1e-9
    e0 = out["initial_energy"]
    state = 0.5 * np.einsum("ij,ij->i", vel, vel) + GRAVITY * pos[:, 1]
    slack = 1e-12 * (np.abs(e0) + GRAVITY * 5.0)
    assert np.all(out["energy"] <= e0 + slack)
    assert np.all(state <= e0 + slack)
    if retention == 1.0:
        assert out["capped"].sum() == 0
    else:
        assert out["capped"].max() <= SETTLING_CAPPED_FRAMES


def test_broad_phase_names():
    """The arcs take every broad phase of the chords by name; others (a flag included) are
    refused by the features record, naming the field."""
    for name in BROAD_PHASES:
        assert Features(motion="ballistic", broad_phase=name).broad_phase == name
    for bad in ("octree", True, False):
        with pytest.raises(ValueError, match="broad_phase"):
            Features(motion="ballistic", broad_phase=bad)


def test_far_from_origin():
    """The room and its spheres translated by 1e4 m (1/64 m steps: exact): float64 follows the
    same paths to rounding of 1e4 m coordinates, and a sphere at rest there stays bit for bit."""
    shift = np.array([1.0e4, 1.0e4, -1.0e4])
    rng = np.random.default_rng(5)
    x, v = room_spheres(rng, 16)
    x, v = np.round(x * 64) / 64, np.round(v * 64) / 64
    near = run(closed_room(HALF), x, v, 60, 1 / 64, "float64")
    far = run(closed_room(HALF, center=shift), x + shift, v, 60, 1 / 64, "float64")
    assert far["capped"].sum() == 0 and far["bounces"].sum() > 16
    np.testing.assert_allclose(far["position"] - shift, near["position"], atol=1e-9)
    rest = np.array([[0.25, -L, -0.5]]) + shift
    out = run(closed_room(HALF, center=shift), rest, np.zeros((1, 3)), 60, 1 / 60, "float64")
    np.testing.assert_array_equal(out["position"], rest)


@pytest.mark.parametrize("name", ["plates", "room"])
@pytest.mark.parametrize("prec", ["float32", "float64"])
def test_the_falling_kernel_keeps_the_bits(name, prec):
    """Under gravity the frame's free legs query along the arc only (``Features.falls``): the
    same bits as the kernel that chooses between the chord's and the arc's query at every leg,
    over 90 frames of bundled scenes (bounces, supports and slides included); a scene without
    gravity keeps the choice."""
    from warpsim.kernels.frame_kernel import frame_kernel

    scene = ws.Scene.load(name)
    swarm = scene.spawn(n=300, seed=8)
    sims = [ws.Simulator(scene, swarm, precision=prec, motion="ballistic", device="cpu")
            for _ in range(2)]
    assert sims[0]._features.falls
    sims[1]._kernel = frame_kernel(sims[1]._features.but(falls=False))
    for sim in sims:
        sim.step(90)
    a, b = sims[0].state(), sims[1].state()
    for f in ("position", "velocity", "energy"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    assert sims[0].stats.bounces == sims[1].stats.bounces > 0
    floating = ws.Scene.load("thin-walls")
    sim = ws.Simulator(floating, floating.spawn(n=10, seed=1), motion="ballistic", device="cpu")
    assert not sim._features.falls
