"""Several bounces in one frame (``ws.bounce``) against analytic answers.

Every expected value here is computed in float64 by the test itself, from geometry that has a
closed form:

* Billiard unfolding: in an axis-aligned room whose walls are at ``+-L``, the centre of a sphere
  of radius ``r`` lives in ``[-a, a]`` per axis (``a = L - r``) and a reflection only flips one
  velocity component. Unfolding the reflections, the end position is the straight end
  ``x0 + v dt`` folded back into ``[-a, a]`` with period ``4a``; the number of folds is the
  number of contacts and its parity the sign of that velocity component. This checks at once
  that the broken line is exactly ``|v| dt`` long and that every contact is at the right place.
* Built backwards: pick the contact centre ``P`` on a plane with normal ``n``, a displacement
  ``d`` with ``d . n < 0`` and a fraction ``t``; start at ``A = P - t d``. The end is
  ``P + (1 - t) (d - 2 (d . n) n)``.
* The friction torque at a contact (README "What it models"), written out in float64
  (:func:`friction_spin_reference`).

Tolerances. A broken line is a chain of straight pieces; each piece rounds a handful of
coordinates (the contact ``a + t d``, the reflected rest ``(1 - t)(d - 2 (d . n) n)``) at the
scale of the scene plus the path, so the end position is within ``PIECE_ULPS`` ulps of that
scale per piece (measured worst case over 20 000 random room paths: 0.6 ulp per piece).
"""

import math

import numpy as np
import pytest
from helpers import DEVICES, closed_room
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import warpsim as ws
from warpsim.kernels.nearest import SEPARATION_ULPS

EPS = {"float32": float(np.finfo(np.float32).eps), "float64": float(np.finfo(np.float64).eps)}

#: End-position error per straight piece, in ulps of (scene scale + path length); see above.
PIECE_ULPS = 4.0

#: Error of a vector computed by a few products and sums (a reflection, a friction torque),
#: in ulps of its inputs' magnitude.
VECTOR_ULPS = 16.0

MAX_BOUNCES = 8  # the default, and the only cap compiled here (each cap is a kernel variant)




def unfold(x, a):
    """Fold unfolded coordinates ``x`` back into ``[-a, a]`` (reflections at ``+-a``).

    Returns:
        ``(position, sign, reflections)``: the folded coordinate, the sign of the velocity
        component after the reflections and how many reflections there were, per coordinate.
    """
    k = np.floor((np.asarray(x, dtype=np.float64) + a) / (2.0 * a))
    y = x - 2.0 * a * k  # in [-a, a)
    sign = np.where(k % 2 == 0, 1.0, -1.0)
    return sign * y, sign, np.abs(k).astype(np.int64)


def rotate(q, v):
    """Rotate ``v`` by the unit quaternion ``q = (x, y, z, w)`` (float64, written out)."""
    q = np.asarray(q, dtype=np.float64)
    u, w = q[:3], q[3]
    v = np.asarray(v, dtype=np.float64)
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def reflect(d, n):
    return d - 2.0 * np.dot(d, n) * n


def friction_spin_reference(L, v, n, r, m, dt, k_f, max_rot):
    """The spin update at one contact, float64: ``I = 2/5 m r^2``, ``Rot = L / I`` clamped,
    ``OC = -r n``, ``v_t,rel = v - (v.n) n + Rot x OC``, ``L += dt OC x (-k_f v_t,rel)``, then
    ``|L| / I`` clamped again."""
    inertia = 0.4 * m * r * r

    def clamp(x):
        size = np.linalg.norm(x)
        limit = max_rot * inertia
        return x * (limit / size) if size > limit else x

    rot = clamp(np.asarray(L, dtype=np.float64)) / inertia
    oc = -r * n
    v_rel = v - np.dot(v, n) * n + np.cross(rot, oc)
    return clamp(L + dt * np.cross(oc, -k_f * v_rel))


def bounce_one(a, v, r, boxes, dt, **kwargs):
    return ws.bounce(np.asarray([a], dtype=np.float64), np.asarray([v], dtype=np.float64), r,
                     boxes, dt, **kwargs)


def wall(center, half_extents):
    return ws.RoundedBoxes(center=[center], half_extents=[half_extents])


# -- path length: the broken line is |v| dt long ---------------------------------------------

#: name, boxes, radius, start, velocity (dt = 1), expected end, expected velocity, contacts.
#: Values are exact in binary; each row's expected answer is worked out in its comment.
PATH_CASES = [
    # Face at x = 1, centre stops at x = 0.75 after 0.75 of the 2 m in x; 1.25 m back: -0.5.
    ("one-wall", wall((1.5, 0.0, 0.0), (0.5, 10.0, 10.0)), 0.25, (0.0, 0.0, 0.0),
     (2.0, 0.5, 0.0), (-0.5, 0.5, 0.0), (-2.0, 0.5, 0.0), 1),
    # Faces at x = +-1: contacts at 0.75 (0.5 m), -0.75 (2 m), 0.75 (3.5 m), 0.5 m back: 0.25.
    ("parallel-walls", ws.RoundedBoxes.concatenate([
        wall((1.5, 0.0, 0.0), (0.5, 10.0, 10.0)), wall((-1.5, 0.0, 0.0), (0.5, 10.0, 10.0))]),
     0.25, (0.25, 0.0, 0.0), (4.0, 0.0, 0.0), (0.25, 0.0, 0.0), (-4.0, 0.0, 0.0), 3),
    # Floor and ceiling at y = +-1 along x: y contacts at 0.75 (0.75 m), -0.75 (2.25 m), then
    # 0.25 m up: -0.5; x and z go straight.
    ("corridor", ws.RoundedBoxes.concatenate([
        wall((0.0, 1.5, 0.0), (10.0, 0.5, 10.0)), wall((0.0, -1.5, 0.0), (10.0, 0.5, 10.0))]),
     0.25, (0.0, 0.0, 0.0), (3.0, 2.5, 0.5), (3.0, -0.5, 0.5), (3.0, 2.5, 0.5), 2),
    # Room [-1, 1]^3: the centre reaches the corner (0.75, 0.75, 0.75) at t = 1/4, touching
    # three walls at once (three contacts, the last two at t = 0), and comes back 0.75 per axis.
    ("room-corner", closed_room(1.0), 0.25, (0.5, 0.5, 0.5), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0),
     (-1.0, -1.0, -1.0), 3),
    # Room [-1, 1]^3, per axis: x 0.25 + 2.5 = 2.75, contacts at 0.75 and -0.75, 0.5 m left:
    # -0.25; y 0.125 - 1.5 = -1.375, contact at -0.75, 0.625 m left: -0.125; z -0.5 + 0.75
    # = 0.25, no contact.
    ("room-oblique", closed_room(1.0), 0.25, (0.25, 0.125, -0.5), (2.5, -1.5, 0.75),
     (-0.25, -0.125, 0.25), (2.5, 1.5, 0.75), 3),
]


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("case", PATH_CASES, ids=[c[0] for c in PATH_CASES])
def test_path_in_simple_scenes(case, precision, device):
    name, boxes, r, a, v, end, v_end, contacts = case
    b = bounce_one(a, v, r, boxes, 1.0, device=device, precision=precision)
    scale = 1.0 + np.linalg.norm(v)
    tol = PIECE_ULPS * EPS[precision] * scale * (contacts + 1)
    assert b.bounces[0] == contacts and b.hit[0] and not b.capped[0], name
    np.testing.assert_allclose(b.position[0], end, rtol=0, atol=tol)
    np.testing.assert_allclose(b.velocity[0], v_end, rtol=0, atol=tol)
    assert b.position.dtype == np.dtype(precision)


@pytest.mark.slow
@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("precision", ["float32", "float64"])
@settings(max_examples=150, deadline=None)
@given(start=st.tuples(*[st.floats(-0.9, 0.9)] * 3),
       direction=st.tuples(*[st.floats(-1.0, 1.0)] * 3),
       speed=st.one_of(st.just(0.0), st.floats(1e-3, 12.0)),
       radius=st.sampled_from([0.0, 0.05, 0.25]))
def test_room_end_position_is_the_unfolded_one(device, precision, start, direction, speed,
                                               radius):
    """Closed room ``[-1, 1]^3``: end inside, speed kept, end and velocity = unfolding."""
    half = 1.0
    a = half - radius
    direction = np.asarray(direction)
    assume(np.linalg.norm(direction) > 1e-3)
    v = speed * direction / np.linalg.norm(direction)
    x0 = np.asarray(start) * a
    end, sign, folds = unfold(x0 + v, a)
    assume(folds.sum() <= MAX_BOUNCES)  # the cap is tested on its own below
    # An end within rounding of a wall may or may not count the contact at t = 1.
    assume(np.all(a - np.abs(end) > 1e-6 * (1.0 + speed)))
    b = bounce_one(x0, v, radius, closed_room(half), 1.0, device=device, precision=precision)
    eps = EPS[precision]
    tol = PIECE_ULPS * eps * (half + speed) * (folds.sum() + 1)
    if radius == 0.0:  # a point is lifted off each wall by SEPARATION_ULPS of the wall's scale
        tol += SEPARATION_ULPS * eps * max(2.0 * half, speed) * folds.sum()
    assert not b.capped[0]
    assert b.bounces[0] == folds.sum()
    assert np.all(np.abs(b.position[0]) <= a + tol)
    np.testing.assert_allclose(b.position[0], end, rtol=0, atol=tol)
    np.testing.assert_allclose(b.velocity[0], sign * v, rtol=0, atol=VECTOR_ULPS * eps * speed)
    assert abs(np.linalg.norm(b.velocity[0].astype(np.float64)) - speed) <= 4 * eps * speed


def test_room_batch_far_from_origin_matches_unfolding(device):
    """The same unfolding for a batch of 2000 spheres in a room centred at 1e3 m (float64,
    where 1e3 m costs 10 bits; float32 far from the origin is the sweep tests' business)."""
    rng = np.random.default_rng(5)
    n, half, r = 2000, 1.0, 0.125
    a = half - r
    center = np.array([1.0e3, -1.0e3, 1.0e3])
    x0 = rng.uniform(-0.9 * a, 0.9 * a, (n, 3))
    v = rng.normal(size=(n, 3))
    v *= rng.uniform(0.0, 6.0, (n, 1)) / np.linalg.norm(v, axis=1)[:, None]
    end, sign, folds = unfold(x0 + v, a)
    assert folds.sum(axis=1).max() <= MAX_BOUNCES  # below the cap by construction
    b = ws.bounce(center + x0, v, r, closed_room(half, center=center), 1.0, precision="float64",
                  device=device)
    tol = PIECE_ULPS * EPS["float64"] * (np.abs(center).max() + 7.0) * (MAX_BOUNCES + 1)
    np.testing.assert_array_equal(b.bounces, folds.sum(axis=1))
    np.testing.assert_allclose(b.position - center, end, rtol=0, atol=tol)
    np.testing.assert_allclose(b.velocity, sign * v, rtol=0,
                               atol=VECTOR_ULPS * EPS["float64"] * 6.0)


# -- the cap -----------------------------------------------------------------------------------

#: Two plates with inner faces at x = +-GAP_FACE; a sphere of radius GAP_R has its centre free
#: in [-GAP_A, GAP_A] (all exact in binary).
GAP_R = 0.0625
GAP_A = 2.0 ** -6
GAP_FACE = GAP_R + GAP_A
GAP_PLATES = ws.RoundedBoxes(center=[(GAP_FACE + 0.5, 0.0, 0.0), (-GAP_FACE - 0.5, 0.0, 0.0)],
                             half_extents=[(0.5, 10.0, 10.0)] * 2)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_cap_stops_at_the_last_contact(precision, device):
    """From x = 0 at 128 m/s for 1/64 s (2 m, ~64 contacts needed): contacts alternate at +a,
    -a, ...; the 8th is at x = -a after a + 7 (2a) = 15a of x travel, i.e. at time
    15 a / vx, where y = vy 15 a / vx. The sphere stays there with the velocity reflected
    8 times (x back to +vx)."""
    vx, vy, dt = 128.0, 2.0, 1.0 / 64.0
    b = bounce_one((0.0, 0.0, 0.0), (vx, vy, 0.0), GAP_R, GAP_PLATES, dt, device=device,
                   precision=precision)
    path = math.hypot(vx, vy) * dt
    tol = PIECE_ULPS * EPS[precision] * (1.0 + path) * (MAX_BOUNCES + 1)
    assert b.bounces[0] == MAX_BOUNCES and b.capped[0] and b.hit[0]
    expected = np.array([-GAP_A, vy * 15.0 * GAP_A / vx, 0.0])
    np.testing.assert_allclose(b.position[0], expected, rtol=0, atol=tol)
    np.testing.assert_allclose(b.velocity[0], (vx, vy, 0.0), rtol=0,
                               atol=VECTOR_ULPS * EPS[precision] * vx)
    # at the last contact: touching the left plate, never inside either
    distance = GAP_PLATES.signed_distance(b.position.astype(np.float64))[0] - GAP_R
    assert abs(distance[1]) <= tol
    assert distance.min() >= -tol


def test_cap_not_reached_when_the_path_ends_before_another_contact():
    """x travel a + 7 (2a) + a: the 8th contact (at -a) is the last one needed and the sphere
    ends at x = 0 after it; that is 8 contacts, not capped."""
    x_travel = 16.0 * GAP_A
    b = bounce_one((0.0, 0.0, 0.0), (x_travel, 0.0, 0.0), GAP_R, GAP_PLATES, 1.0)
    assert b.bounces[0] == MAX_BOUNCES and not b.capped[0]
    tol = PIECE_ULPS * EPS["float32"] * 1.0 * (MAX_BOUNCES + 1)
    np.testing.assert_allclose(b.position[0], (0.0, 0.0, 0.0), rtol=0, atol=tol)
    np.testing.assert_allclose(b.velocity[0], (x_travel, 0.0, 0.0), rtol=0, atol=0)


# -- spin from friction --------------------------------------------------------------------------

FLOOR = wall((0.0, -0.5, 0.0), (10.0, 0.5, 10.0))  # top face y = 0, normal +y


def test_spin_grazing_a_floor_by_hand():
    """Sphere r = 1/4, m = 1 grazing the floor: v = (4, -1, 0), dt = 1/2, from y = 1/2 (contact
    at t = 1/2). With L0 = 0: Rot = 0, OC = -r n = (0, -1/4, 0), v_t,rel = (4, 0, 0),
    F = -k_f (4, 0, 0) and dL = dt OC x F = 1/2 (0, -1/4, 0) x (-4 k_f, 0, 0)
    = 1/2 (0, 0, -k_f) = (0, 0, -k_f / 2). For k_f = 1/10: L = (0, 0, -0.05), along
    n x v = (0, 1, 0) x (4, -1, 0) = (0, 0, -4): the friction spins the sphere towards rolling
    (rolling in +x about -z). |Rot| = 0.05 / I = 0.05 / (0.4 / 16) = 2 rad/s < 50: no clamp."""
    b = bounce_one((0.0, 0.5, 0.0), (4.0, -1.0, 0.0), 0.25, FLOOR, 0.5, friction=0.1)
    assert b.bounces[0] == 1
    np.testing.assert_allclose(b.angular_momentum[0], (0.0, 0.0, -0.05), rtol=0,
                               atol=VECTOR_ULPS * EPS["float32"] * 0.05)
    n_cross_v = np.cross((0.0, 1.0, 0.0), (4.0, -1.0, 0.0))
    assert np.dot(b.angular_momentum[0], n_cross_v) > 0.0
    # friction does not touch the translation
    np.testing.assert_allclose(b.position[0], (2.0, 0.5, 0.0), rtol=0, atol=1e-6)
    np.testing.assert_allclose(b.velocity[0], (4.0, 1.0, 0.0), rtol=0, atol=0)


def test_spin_clamped_to_max_angular_speed():
    """The same contact with k_f = 1000: dL = (0, 0, -500), |Rot| = 500 / I = 20 000 rad/s,
    clamped to max_angular_speed = 50: L = (0, 0, -50 I) = (0, 0, -1.25)."""
    b = bounce_one((0.0, 0.5, 0.0), (4.0, -1.0, 0.0), 0.25, FLOOR, 0.5, friction=1000.0)
    inertia = 0.4 * 1.0 * 0.25**2
    np.testing.assert_allclose(b.angular_momentum[0], (0.0, 0.0, -50.0 * inertia), rtol=0,
                               atol=VECTOR_ULPS * EPS["float32"] * 1.25)
    assert np.linalg.norm(b.angular_momentum[0]) / inertia <= 50.0 * (1.0 + 4 * EPS["float32"])


def test_spin_two_contacts_in_one_frame():
    """Floor (n = +y) then wall x = 1 (n = -x) in one frame: the torque of each contact uses the
    velocity at that contact (the second one after the floor's reflection) and the L left by
    the first. r = 1/4, m = 2, v = (1, -1, 1/2), dt = 1, start (0, 1/2, 0): floor at t = 1/4,
    wall (centre x = 3/4) at t = 3/4."""
    boxes = ws.RoundedBoxes.concatenate([FLOOR, wall((1.5, 0.0, 0.0), (0.5, 10.0, 10.0))])
    r, m, dt, k_f, max_rot = 0.25, 2.0, 1.0, 0.5, 50.0
    L0 = np.array([0.01, -0.02, 0.03])
    v = np.array([1.0, -1.0, 0.5])
    b = bounce_one((0.0, 0.5, 0.0), v, r, boxes, dt, mass=m, angular_momentum=[L0],
                   friction=k_f, max_angular_speed=max_rot)
    floor_n, wall_n = np.array([0.0, 1.0, 0.0]), np.array([-1.0, 0.0, 0.0])
    L1 = friction_spin_reference(L0, v, floor_n, r, m, dt, k_f, max_rot)
    L2 = friction_spin_reference(L1, reflect(v, floor_n), wall_n, r, m, dt, k_f, max_rot)
    assert b.bounces[0] == 2
    np.testing.assert_allclose(b.angular_momentum[0], L2, rtol=0,
                               atol=VECTOR_ULPS * EPS["float32"] * np.abs(L2).max())
    # positions: floor at (1/4, 1/4, 1/8), wall at (3/4, 3/4, 3/8), then 1/4 of the path
    np.testing.assert_allclose(b.position[0], (0.5, 1.0, 0.5), rtol=0, atol=1e-6)


@pytest.mark.slow
@settings(max_examples=60, deadline=None)
@given(q=st.tuples(*[st.floats(-1.0, 1.0)] * 4),
       local_d=st.tuples(st.floats(-2.0, 2.0), st.floats(0.1, 2.0), st.floats(-2.0, 2.0)),
       L0=st.tuples(*[st.floats(-0.05, 0.05)] * 3),
       k_f=st.floats(0.01, 20.0), mass=st.floats(0.5, 4.0), t=st.sampled_from([0.25, 0.5]))
def test_spin_on_a_rotated_plate_matches_the_formula(q, local_d, L0, k_f, mass, t):
    """Built backwards on a rotated zero-thickness plate: one contact, L from the torque formula
    (float64 reference), and the clamp holds."""
    q = np.asarray(q)
    assume(np.linalg.norm(q) > 0.1)
    q = q / np.linalg.norm(q)
    r, dt, max_rot = 0.25, 0.5, 50.0
    plate = ws.RoundedBoxes(center=[(0.5, -1.0, 2.0)], half_extents=[(10.0, 0.0, 10.0)],
                            rotation=[q])
    n = rotate(q, (0.0, 1.0, 0.0))
    contact = plate.center[0] + rotate(q, (0.25, r, -0.5))
    d = rotate(q, (local_d[0], -local_d[1], local_d[2]))
    a = contact - t * d
    v = d / dt
    b = bounce_one(a, v, r, plate, dt, mass=mass, angular_momentum=[L0], friction=k_f,
                   max_angular_speed=max_rot)
    expected = friction_spin_reference(np.asarray(L0), v, n, r, mass, dt, k_f, max_rot)
    inertia = 0.4 * mass * r * r
    # the torque's inputs: L0, and dt r k_f (|v| + r |Rot|)
    scale = np.linalg.norm(L0) + dt * r * k_f * (np.linalg.norm(v) + r * max_rot)
    assert b.bounces[0] == 1
    np.testing.assert_allclose(b.angular_momentum[0], expected, rtol=0,
                               atol=VECTOR_ULPS * EPS["float32"] * scale)
    assert np.linalg.norm(b.angular_momentum[0]) <= max_rot * inertia * (1 + 4 * EPS["float32"])
    np.testing.assert_allclose(b.position[0], contact + (1.0 - t) * reflect(d, n), rtol=0,
                               atol=PIECE_ULPS * EPS["float32"] * 10.0 * 2)


def test_no_friction_leaves_angular_momentum_untouched(device):
    L0 = np.array([[0.3, -0.2, 0.1], [1e-3, 5.0, -7.0]])
    b = ws.bounce([(0.0, 0.5, 0.0), (1.0, 0.5, 0.0)], [(4.0, -1.0, 0.0), (-4.0, -1.0, 2.0)],
                  0.25, FLOOR, 0.5, angular_momentum=L0, friction=0.0, device=device)
    assert b.bounces.tolist() == [1, 1]
    np.testing.assert_array_equal(b.angular_momentum, L0.astype(np.float32))


# -- energy retention ------------------------------------------------------------------------------


@pytest.mark.parametrize("k", [0.25, 0.5, 0.81])
def test_energy_retention_scales_speed_and_rest_of_path(k):
    """One floor contact at t = 1/2 with v = (1, -2, 0), dt = 1/2, from y = 3/4 (r = 1/4):
    kinetic energy times k, so |v'| = sqrt(k) |v| and the rest of the path, (1 - t) d
    reflected, shrinks by sqrt(k) too."""
    v = np.array([1.0, -2.0, 0.0])
    dt, t = 0.5, 0.5
    b = bounce_one((0.0, 0.75, 0.0), v, 0.25, FLOOR, dt, energy_retention=k)
    n = np.array([0.0, 1.0, 0.0])
    contact = np.array([0.0, 0.75, 0.0]) + t * dt * v
    tol = VECTOR_ULPS * EPS["float32"] * np.linalg.norm(v)
    assert b.bounces[0] == 1
    np.testing.assert_allclose(b.velocity[0], math.sqrt(k) * reflect(v, n), rtol=0, atol=tol)
    assert abs(np.linalg.norm(b.velocity[0]) - math.sqrt(k) * np.linalg.norm(v)) <= tol
    np.testing.assert_allclose(b.position[0],
                               contact + (1.0 - t) * math.sqrt(k) * reflect(v * dt, n),
                               rtol=0, atol=PIECE_ULPS * EPS["float32"] * 2.0 * 2)


def test_energy_retention_compounds_over_contacts():
    """The 'parallel-walls' row with k = 1/2: contact 1 at x = 0.75 after 0.5 m (1/8 s at
    4 m/s); then 4 sqrt(k) m/s over the 1.5 m to x = -0.75 (contact 2); then 4 k = 2 m/s for
    the time left, which is not enough for a third contact."""
    k = 0.5
    boxes = PATH_CASES[1][1]
    b = bounce_one((0.25, 0.0, 0.0), (4.0, 0.0, 0.0), 0.25, boxes, 1.0, energy_retention=k)
    speed1, speed2 = 4.0 * math.sqrt(k), 4.0 * k
    t2 = 0.5 / 4.0 + 1.5 / speed1
    tol = PIECE_ULPS * EPS["float32"] * (1.0 + 4.0) * 3
    assert b.bounces[0] == 2
    np.testing.assert_allclose(b.velocity[0], (speed2, 0.0, 0.0), rtol=0, atol=tol)
    np.testing.assert_allclose(b.position[0], (-0.75 + speed2 * (1.0 - t2), 0.0, 0.0), rtol=0,
                               atol=tol)


# -- thin plates at high speed ------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("half_thickness", [0.0, 1e-3])
@pytest.mark.parametrize("speed", [600.0, 5000.0])
def test_thin_plate_at_high_speed_is_never_crossed(device, speed, half_thickness):
    """A large rotated plate; spheres from both sides, built backwards to hit its face at a
    random fraction of a 10 m (600 m/s) or 83 m (5000 m/s) frame path. Each ends on its own
    side at the reflected position, one contact.

    Tolerance: coordinates up to ~150 m from the plate centre plus the path, PIECE_ULPS per
    piece, two pieces."""
    rng = np.random.default_rng(int(speed) + int(half_thickness * 1e3))
    n_spheres, r, dt = 256, 0.02, 1.0 / 60.0
    q = np.array([0.3, -0.5, 0.2, 0.8])
    q /= np.linalg.norm(q)
    center = np.array([3.0, -2.0, 1.0])
    plate = ws.RoundedBoxes(center=[center], half_extents=[(200.0, half_thickness, 200.0)],
                            rotation=[q])
    normal = rotate(q, (0.0, 1.0, 0.0))
    side = rng.choice([-1.0, 1.0], n_spheres)
    u = rng.uniform(-50.0, 50.0, (n_spheres, 2))
    local_contact = np.column_stack([u[:, 0], side * (half_thickness + r), u[:, 1]])
    direction = rng.normal(size=(n_spheres, 3))
    direction[:, 1] = -side * (0.05 + np.abs(direction[:, 1]))  # into the face it faces
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    d = np.array([rotate(q, x) for x in direction]) * speed * dt
    contact = center + np.array([rotate(q, x) for x in local_contact])
    t = rng.uniform(0.0, 1.0, n_spheres)
    start = contact - t[:, None] * d
    b = ws.bounce(start, d / dt, r, plate, dt, device=device)
    n_world = side[:, None] * normal
    reflected = d - 2.0 * np.einsum("ij,ij->i", d, n_world)[:, None] * n_world
    expected = contact + (1.0 - t)[:, None] * reflected
    scale = np.abs(start).max() + speed * dt
    tol = PIECE_ULPS * EPS["float32"] * scale * 2
    assert np.all(b.bounces == 1)
    np.testing.assert_allclose(b.position, expected, rtol=0, atol=tol)
    height = side * ((b.position.astype(np.float64) - center) @ normal)
    assert np.all(height >= half_thickness + r - tol)  # on its own side, never through


# -- inputs ------------------------------------------------------------------------------------


def test_inputs_not_modified(device):
    a = np.array([[0.0, 0.5, 0.0], [0.25, 0.5, 0.0]])
    v = np.array([[4.0, -1.0, 0.0], [-4.0, -1.0, 2.0]])
    L0 = np.array([[0.3, -0.2, 0.1], [0.0, 0.0, 0.0]])
    radius, mass = np.array([0.25, 0.125]), np.array([1.0, 2.0])
    before = [x.copy() for x in (a, v, L0, radius, mass)]
    ws.bounce(a, v, radius, FLOOR, 0.5, mass=mass, angular_momentum=L0, friction=0.5, device=device)
    for x, y in zip((a, v, L0, radius, mass), before, strict=True):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("kwargs,message", [
    (dict(position=[[0, 0, 0], [0, 0, 0], [0, 0, 0], [np.nan, 0, 0]]),
     r"position\[3\] must be finite"),
    (dict(velocity=[[0, 0, 0], [np.inf, 0, 0], [0, 0, 0], [0, 0, 0]]),
     r"velocity\[1\] must be finite"),
    (dict(radius=[0.1, 0.1, -0.1, 0.1]), r"radius\[2\] must be >= 0"),
    (dict(mass=0.0), r"mass must be > 0"),
    (dict(mass=[1.0, -1.0, 1.0, 1.0]), r"mass\[1\] must be > 0"),
    (dict(dt=0.0), r"dt must be > 0"),
    (dict(max_bounces=0), r"max_bounces must be >= 1"),
    (dict(energy_retention=1.5), r"energy_retention must be <= 1"),
    (dict(friction=-1.0), r"friction must be >= 0"),
    (dict(angular_momentum=[[0, 0, 0]]), r"angular_momentum must have shape \(4, 3\)"),
    (dict(precision="half"), r"precision must be one of"),
])
def test_bad_input_names_the_field(device, kwargs, message):
    args = dict(position=np.zeros((4, 3)), velocity=np.ones((4, 3)), radius=0.1, dt=0.1)
    args.update(kwargs)
    position, velocity, radius, dt = (args.pop(k) for k in ("position", "velocity", "radius",
                                                            "dt"))
    with pytest.raises(ValueError, match=message):
        ws.bounce(position, velocity, radius, FLOOR, dt, **args, device=device)



@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("impact_speed", [0.0, 1.0e-3, 4.0e-3, 0.02, 0.5, 3.0])
def test_bounces_and_supports_are_counted_apart(precision, impact_speed):
    """``ws.bounce(motion="ballistic")``: a sphere dropped from rest onto a floor meets it at
    ``sqrt(2 g h)``; at most ``RESTING_SPEED`` (5 mm/s) of normal speed it is a support (held,
    counted in ``supports``), above it a bounce (counted in ``bounces``), never both; the frame
    lasts until the apex of the bounce, so it holds exactly one contact. ``impact_speed = 0``:
    a sphere starting at rest on the floor."""
    from warpsim.kernels.ballistic import RESTING_SPEED

    g, r = 9.81, 0.1
    h = impact_speed ** 2 / (2.0 * g)  # drop height [m] above the floor's contact height
    t_fall = impact_speed / g
    dt = max(2.0 * t_fall, 1.0e-3)  # to the apex of the bounce (a resting sphere: 1 ms)
    floor = ws.RoundedBox(center=(0.0, -0.5, 0.0), half_extents=(5.0, 0.5, 5.0))
    b = ws.bounce([[0.0, r + h, 0.0]], [[0.0, 0.0, 0.0]], r, floor, dt, motion="ballistic",
                  gravity=(0.0, -g, 0.0), precision=precision, device="cpu")
    support = impact_speed <= RESTING_SPEED
    assert b.hit[0] and not b.capped[0]
    assert (b.bounces[0], b.supports[0]) == ((0, 1) if support else (1, 0))
    # the analytic end: at rest on the floor, or at the bounce's apex (back at the start)
    np.testing.assert_allclose(b.position[0], [0.0, r if support else r + h, 0.0],
                               atol=5e-5 if precision == "float32" else 1e-12)


def test_a_straight_hit_is_a_bounce_not_a_support():
    """The linear query has no gravity: every contact it takes reflects."""
    wall = ws.RoundedBox(center=(1.0, 0.0, 0.0), half_extents=(0.1, 1.0, 1.0))
    b = ws.bounce([[0.0, 0.0, 0.0]], [[1.0, 0.0, 0.0]], 0.1, wall, 1.0, device="cpu")
    assert (b.hit[0], b.bounces[0], b.supports[0]) == (True, 1, 0)


@settings(max_examples=40, deadline=None)
@given(tilt=st.floats(3.0, 60.0), turn=st.floats(0.0, 360.0),
       rounding=st.sampled_from([0.0, 0.05]), height=st.floats(0.0, 0.03),
       side_speed=st.floats(0.0, 3.0), heading=st.floats(-90.0, 90.0),
       dt=st.sampled_from([1 / 240, 1 / 60, 0.1, 0.25]), retention=st.sampled_from([1.0, 0.6]),
       precision=st.sampled_from(["float32", "float64"]))
def test_low_hops_on_a_ramp_never_end_inside(tilt, turn, rounding, height, side_speed, heading,
                                             dt, retention, precision):
    """Hops too low for the chord's rest of the path (the rise cut turns it back toward the
    ramp), mostly uphill, on a tilted, turned box: every frame's centre stays outside the ramp
    by the radius (to rounding), against the host's float64 distance. The next query after a
    bounce skips the box the rest leaves only when the rest does not point into it."""
    a, b = math.radians(tilt), math.radians(turn)
    axis = np.array([math.cos(b), 0.0, math.sin(b)])
    q = np.array([*(math.sin(a / 2) * axis), math.cos(a / 2)])  # (x, y, z, w)
    ramp = ws.RoundedBoxes(center=[[0.0, 0.0, 0.0]], half_extents=[[1.5, 0.1, 1.5]],
                           rotation=[q], radius=[rounding])
    normal = ramp.rotation_matrices()[0] @ np.array([0.0, 1.0, 0.0])
    r = 0.05
    top = normal * (0.1 + rounding + r + height)
    uphill = np.array([0.0, 1.0, 0.0]) - normal[1] * normal  # up the slope, in its plane
    uphill /= np.linalg.norm(uphill)
    across = np.cross(normal, uphill)
    h = math.radians(heading)
    swarm = ws.Swarm([top], [side_speed * (math.cos(h) * uphill + math.sin(h) * across)],
                     radius=r)
    scene = ws.Scene(ramp, dt=dt, energy_retention=retention)
    sim = ws.Simulator(scene, swarm, precision=precision, device="cpu")
    path = sim.run(int(min(60, 1.2 / dt))).position[:, 0]
    assert normal[1] > 0.4  # the top face, facing up
    tol = 2e-5 if precision == "float32" else 1e-10
    on_ramp = np.all(np.abs(np.linalg.solve(ramp.rotation_matrices()[0], path.T).T)[:, [0, 2]]
                     < 1.5, axis=1)
    gap = ramp.signed_distance(path)[:, 0] - r
    assert np.all(gap[on_ramp] >= -tol), gap.min()


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
@pytest.mark.parametrize("broad_phase", ["brute", "grid"])
def test_a_point_on_a_sharp_plate_moving_in_bounces_whatever_the_rounding(
        precision, motion, broad_phase):
    """Points (``r = 0``) that start on a sharp, zero-thickness plate (``rb = 0``, no extent
    along its normal) far from the origin and move into it: the plate's bounds and the path's
    touch only at the path's start, with nothing growing either along the normal, so the
    reject has no slack there but its rounding pad; each must bounce at ``t = 0`` and end on
    the side it came from, for plates normal to each axis. (Without the pad on the chord's
    midpoint about half of them went through in both precisions.)

    Gravity lies in the plate's plane, so the arc's bounds have no sagitta along the normal
    either (with ``g = 0`` the ballistic kernel takes the chord's query, the linear rows')."""
    rng = np.random.default_rng(7)
    n = 1500
    for axis in range(3):
        at = float(np.float32(rng.uniform(100.0, 1000.0)))
        center = np.zeros(3)
        center[axis] = at
        half = np.full(3, 1.0e4)
        half[axis] = 0.0
        boxes = ws.RoundedBoxes(center=[center], half_extents=[half], radius=0.0)
        gravity = np.zeros(3)
        gravity[(axis + 1) % 3] = -9.81
        scene = ws.Scene(boxes, gravity=tuple(gravity), dt=1.0 / 60.0)
        x = rng.uniform(-100.0, 100.0, (n, 3))
        x[:, axis] = at
        v = rng.normal(size=(n, 3)) * 3.0
        v[:, axis] = -np.abs(v[:, axis]) - 0.01
        sim = ws.Simulator(scene, ws.Swarm(x, v, radius=0.0), precision=precision,
                           motion=motion, broad_phase=broad_phase, free_flight=False,
                           device="cpu")
        sim.step(1)
        state = sim.state()
        assert np.all(state.position[:, axis] >= at), (axis, np.flatnonzero(
            state.position[:, axis] < at)[:5])
        assert np.all(state.velocity[:, axis] > 0.0), axis
