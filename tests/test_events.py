"""Contact events written by the frame kernel, against analytic contact times and normals.

The linear model moves a sphere along the chord of each frame's free-flight parabola, so the
analytic answer is the discrete one: frame ends on the parabola, the contact where the chord
crosses the surface, its normal speed the parabola's at that time, computed in float64 here.
"""

import numpy as np
import pytest

import warpsim as ws

G = 9.81
DT = 1.0 / 60.0


@pytest.mark.slow
def test_drop_on_a_floor_matches_the_scheme(device, precision):
    r, h0 = 0.1, 1.0  # centre starts h0 above the contact height
    floor = ws.RoundedBoxes(center=[[0, -0.5, 0]], half_extents=[[10, 0.5, 10]])
    sim = ws.Simulator(ws.Scene(floor), ws.Swarm([[0.0, r + h0, 0.0]], [[0, 0, 0]], radius=r),
                       dt=DT, precision=precision, device=device)
    traj = sim.run(40, every=40, events=True)
    ev = traj.events
    # frame ends on the parabola y_k = h0 - g (k dt)^2 / 2; the chord crosses 0 in frame k
    k = 0
    while True:
        k += 1
        y_prev, y = h0 - 0.5 * G * ((k - 1) * DT) ** 2, h0 - 0.5 * G * (k * DT) ** 2
        if y <= 0.0:
            break
    fraction = y_prev / (y_prev - y)
    v = -G * (k - 1 + fraction) * DT  # the parabola's velocity at the chord's contact time
    first = np.flatnonzero(ev.sphere == 0)[0]
    tol = 1e-4 if precision == "float32" else 1e-9
    assert ev.frame[first] == k
    assert ev.box[first] == 0
    assert ev.kind[first] == ws.ContactKind.BOUNCE
    assert ev.fraction[first] == pytest.approx(fraction, abs=tol * 100)
    np.testing.assert_allclose(ev.normal[first], [0, 1, 0], atol=tol)
    assert ev.normal_speed[first] == pytest.approx(-v, rel=tol)
    np.testing.assert_allclose(ev.position[first], [0, r, 0], atol=tol * 10)
    assert len(ev) == sim.stats.bounces
    assert ev.dropped == 0


def test_into_a_corner_hits_both_walls_in_order(device, precision):
    """Zero gravity, straight at a vertical corner: wall x first, then wall z, same frame."""
    walls = ws.RoundedBoxes(center=[[1.5, 0, 0], [0, 0, 1.5]],
                            half_extents=[[0.5, 2, 2], [2, 2, 0.5]])
    r = 0.25
    start = np.array([0.0, 0.0, 0.0])
    v = np.array([30.0, 0.0, 15.0])  # reaches x = 0.75 at t = 0.025 s, z = 0.75 at 0.05 s
    sim = ws.Simulator(ws.Scene(walls, gravity=(0, 0, 0)), ws.Swarm([start], [v], radius=r),
                       dt=0.1, precision=precision, device=device)
    ev = sim.run(1, events=True).events
    assert len(ev) == 2 == sim.stats.bounces
    assert ev.box.tolist() == [0, 1]
    tol = 1e-5 if precision == "float32" else 1e-12
    np.testing.assert_allclose(ev.fraction, [0.25, 0.5], atol=tol)
    np.testing.assert_allclose(ev.normal, [[-1, 0, 0], [0, 0, -1]], atol=tol)
    np.testing.assert_allclose(ev.normal_speed, [30.0, 15.0], rtol=tol)
    np.testing.assert_allclose(ev.position, [[0.75, 0, 0.375], [0.0, 0, 0.75]], atol=tol * 10)
    assert ev.frame.tolist() == [1, 1]


@pytest.mark.slow
@pytest.mark.parametrize("scene_name", ["room", "thin-walls", "wedge"])
def test_event_totals_equal_the_counters_and_change_nothing(device, scene_name):
    scene = ws.Scene.load(scene_name)
    swarm = scene.spawn(n=600, seed=9)
    with_events = ws.Simulator(scene, swarm, workers=2, device=device)
    plain = ws.Simulator(scene, swarm, workers=1, device=device)
    traj = with_events.run(30, every=10, events=True)
    plain_traj = plain.run(30, every=10)
    assert np.array_equal(traj.position, plain_traj.position)
    ev = traj.events
    assert len(ev) + ev.dropped == with_events.stats.bounces
    assert ev.dropped == 0
    assert (ev.frame >= 1).all() and (ev.frame <= 30).all()
    assert (np.diff(ev.frame) >= 0).all()
    np.testing.assert_allclose(np.linalg.norm(ev.normal, axis=1), 1.0, atol=1e-5)
    assert (ev.normal_speed >= 0).all()
    assert ((ev.fraction >= 0) & (ev.fraction <= 1)).all()


def test_overflow_is_counted_never_silent(device):
    scene = ws.Scene.load("thin-walls")
    swarm = scene.spawn(n=300, seed=2)
    sim = ws.Simulator(scene, swarm, workers=1, device=device)
    ev = sim.run(10, every=5, events=True, event_capacity=50).events
    assert ev.dropped > 0
    assert len(ev) + ev.dropped == sim.stats.bounces
    assert len(ev) <= 50 * 2  # two launches at most fill their buffers


@pytest.mark.slow
def test_the_kernels_write_the_contact_kinds_of_the_vocabulary(device, precision):
    """A dropped ball's first contact is a BOUNCE; once it lies on the floor every contact is a
    SUPPORT: the kernels' 0/1 in the event buffer are :class:`warpsim.ContactKind`'s values."""
    r = 0.1
    floor = ws.RoundedBoxes(center=[[0, -0.5, 0]], half_extents=[[10, 0.5, 10]])
    scene = ws.Scene(floor, energy_retention=0.5)
    sim = ws.Simulator(scene, ws.Swarm([[0.0, r + 0.2, 0.0]], [[0, 0, 0]], radius=r), dt=DT,
                       precision=precision, device=device)
    ev = sim.run(240, every=240, events=True).events
    assert ev.kind[0] == ws.ContactKind.BOUNCE
    assert ev.kind[-1] == ws.ContactKind.SUPPORT
    assert set(ev.kind.tolist()) == {int(k) for k in ws.ContactKind}
    late = ev.frame > 200  # long at rest: supported, never reflected
    assert late.any() and np.all(ev.kind[late] == ws.ContactKind.SUPPORT)
