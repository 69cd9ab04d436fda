"""The batched queries along the exact parabola (``motion="ballistic"``) against analytic
answers and the float64 arc reference of ``tests/arc_reference.py``."""

import math

import numpy as np
import pytest
from arc_reference import arc_contact_by_features

import warpsim as ws
from warpsim.obstacles import quat_to_matrix

G = np.array([0.0, -9.81, 0.0])


def test_floor_contact_time_and_new_state(device, precision):
    """Dropped from h above the contact height: s = sqrt(2 h / g), then the reflected velocity
    and the rest of the frame along the new parabola."""
    h, r, dt = 0.5, 0.1, 0.5
    floor = ws.RoundedBox(center=(0, -0.5, 0), half_extents=(3, 0.5, 3))
    c = ws.collide_box([[0.0, h + r, 0.0]], [[1.0, 0.0, 0.0]], r, floor, dt,
                       precision=precision, motion="ballistic", gravity=G, device=device)
    s = math.sqrt(2 * h / 9.81)
    tol = 1e-5 if precision == "float32" else 1e-12
    assert c.hit[0] and c.box[0] == 0
    assert c.t[0] == pytest.approx(s / dt, abs=tol)
    np.testing.assert_allclose(c.position[0], [s, r, 0], atol=tol * 10)
    np.testing.assert_allclose(c.normal[0], [0, 1, 0], atol=tol)
    np.testing.assert_allclose(c.new_velocity[0], [1.0, 9.81 * s, 0], atol=tol * 10)
    rest = dt - s
    np.testing.assert_allclose(c.new_position[0],
                               [dt, r + 9.81 * s * rest - 0.5 * 9.81 * rest ** 2, 0],
                               atol=tol * 10)


def test_no_contact_is_the_parabola(device, precision):
    box = ws.RoundedBox(center=(10, 0, 0), half_extents=(1, 1, 1))
    c = ws.collide_box([[0.0, 0.0, 0.0]], [[1.0, 2.0, 0.0]], 0.1, box, 0.25,
                       precision=precision, motion="ballistic", gravity=G, device=device)
    assert not c.hit[0] and c.box[0] == -1 and c.t[0] == 1.0
    x = np.array([0.25, 2 * 0.25 - 0.5 * 9.81 * 0.25 ** 2, 0.0])
    np.testing.assert_allclose(c.new_position[0], x, rtol=1e-6)
    np.testing.assert_allclose(c.new_velocity[0], [1.0, 2.0 - 9.81 * 0.25, 0.0], rtol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(4))
def test_random_arcs_against_the_reference(device, seed):
    """Random rounded boxes, plates and sticks, random arcs: contact time and normal as the
    float64 reference finds them (face, edge and corner features alike)."""
    rng = np.random.default_rng(seed)
    n = 200
    rows = []
    for _ in range(n):
        h = rng.uniform(0.0, 0.6, 3) * (rng.random(3) > 0.2)
        rb = rng.choice([0.0, 0.05, 0.2])
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        center = rng.uniform(-1, 1, 3)
        start = center + rng.normal(size=3) * 1.5
        # aimed: the arc passes through a point of the core box at time T < dt (edges and
        # corners get their share through the random offsets and roundings)
        target = center + quat_to_matrix(q) @ (h * rng.uniform(-1, 1, 3))
        flight = rng.uniform(0.05, 0.35)
        v = (target - start - 0.5 * np.array([0.0, -9.81, 0.0]) * flight ** 2) / flight
        r = rng.uniform(0.0, 0.1)
        rows.append((center, h, q, rb, start, v, r))
    dt, g = 0.4, np.array([0.0, -9.81, 0.0])
    for prec, tol in (("float64", 1e-9), ("float32", 2e-4)):
        hits = 0
        for center, h, q, rb, start, v, r in rows:
            box = ws.RoundedBox(center=center, half_extents=h, rotation=q, radius=rb)
            m = quat_to_matrix(q)
            local = m.T @ (start - center)
            if np.linalg.norm(np.maximum(np.abs(local) - h, 0.0)) <= rb + r + 1e-3:
                continue  # starts in or on the box: the contact rules are tested elsewhere
            ref = arc_contact_by_features(local, m.T @ v, m.T @ g, dt, h, rb + r)
            c = ws.collide_box([start], [v], r, box, dt, precision=prec, motion="ballistic",
                               gravity=g, device=device)
            assert bool(c.hit[0]) == bool(ref[0]) or abs(ref[1] - dt) < 1e-6
            if ref[0] and c.hit[0]:
                hits += 1
                assert abs(c.t[0] * dt - ref[1]) <= tol * 10
                np.testing.assert_allclose(c.normal[0], m @ np.asarray(ref[2]), atol=tol * 1e3)
        assert hits >= 100


def test_bounce_between_two_walls_without_and_with_gravity(device, precision):
    """A sphere between walls at x = +-1 (inner faces), 2 m/s along x for 2 s: the sawtooth
    folds x; with gravity the height is the free parabola (the walls are vertical)."""
    walls = ws.RoundedBoxes(center=[[-1.5, 0, 0], [1.5, 0, 0]], half_extents=[[0.5, 50, 5]] * 2)
    r = 0.25
    tol = 1e-4 if precision == "float32" else 1e-10
    b = ws.bounce([[0.0, 0.0, 0.0]], [[2.0, 3.0, 0.0]], r, walls, 2.0, max_bounces=16,
                  precision=precision, motion="ballistic", gravity=G, device=device)
    # x: the sawtooth between -0.75 and 0.75 (period 3 m of travel = 1.5 s at 2 m/s)
    travel = 4.0
    w = (travel + 0.75) % 3.0
    x = w - 0.75 if w <= 1.5 else 2.25 - w
    assert b.bounces[0] == 3
    np.testing.assert_allclose(b.position[0], [x, 3.0 * 2 - 0.5 * 9.81 * 4, 0], atol=tol * 10)
    np.testing.assert_allclose(b.velocity[0], [-2.0, 3.0 - 9.81 * 2, 0], atol=tol * 10)


def test_linear_refuses_gravity_and_bad_motion(device):
    box = ws.RoundedBox()
    with pytest.raises(ValueError, match="gravity applies to motion='ballistic'"):
        ws.collide_box([[0, 3, 0]], [[0, -1, 0]], 0.1, box, 0.1, gravity=G, device=device)
    with pytest.raises(ValueError, match="motion must be one of"):
        ws.bounce([[0, 3, 0]], [[0, -1, 0]], 0.1, box.as_boxes(), 0.1, motion="curved",
                  device=device)
    c = ws.collide_box([[0, 3, 0]], [[0, -1, 0]], 0.1, box, 0.1, gravity=(0, 0, 0), device=device)
    assert c.t[0] == 1
