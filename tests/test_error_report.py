"""The error report (``warpsim.analysis.compare``) on tiny runs, checked against analytic
answers: free flight is exact for both motion models from the swarm's velocity (the velocity at
t = 0), and a floor bounce's contact time is known in closed form."""

import json

import numpy as np
import pytest
from helpers import closed_room

import warpsim as ws
from warpsim.analysis import error_report, reference

G = 9.81


def floor_scene(**kw):
    return ws.Scene(ws.RoundedBoxes(center=[[0.0, -1.0, 0.0]], half_extents=[[50.0, 1.0, 50.0]]),
                    **kw)


def test_free_flight_has_no_error_but_rounding(device):
    """From the swarm's velocity at t = 0 the linear model's chords end on the parabola at
    every frame: the report sees rounding only."""
    scene = floor_scene()
    swarm = ws.Swarm(position=[[0.0, 5.0, 0.0], [1.0, 8.0, 0.0]],
                     velocity=[[1.0, 2.0, 0.0], [-0.5, 0.0, 0.3]], radius=0.05)
    sim = ws.Simulator(scene, swarm, dt=1 / 60, precision="float64", device=device)
    sim.run(30)  # 0.5 s: no sphere reaches the floor
    rep = error_report.compare(sim, scene, swarm, sample=2)
    assert rep.horizon == pytest.approx(0.5)
    for key in ("0.1 s", "0.5 s"):
        assert rep.position_error[key]["max_m"] < 1e-13
    assert "1 s" not in rep.position_error  # the run does not reach it
    assert rep.contacts["compared"] == 0
    assert rep.divergence["1 mm"]["diverged"] == 0 and rep.divergence["1 mm"]["median_s"] is None


@pytest.mark.slow
def test_floor_bounce_contact_time_and_error_figures(device):
    """A ball dropped from h: contact at sqrt(2 h / g); the linear model's chord sweep finds it
    within a frame; every figure is present, finite and JSON-ready."""
    h, r = 1.2, 0.05
    scene = floor_scene()
    xs = np.linspace(-1.0, 1.0, 6)
    swarm = ws.Swarm(position=np.stack([xs, np.full(6, h + r), np.zeros(6)], axis=1),
                     velocity=np.zeros((6, 3)), radius=r)
    dt = 1 / 120
    sim = ws.Simulator(scene, swarm, dt=dt, precision="float64", device=device)
    sim.run(round(1.0 / dt))
    rep = error_report.compare(sim, scene, swarm, sample=4, seed=3)
    assert len(rep.sample) == 4 and len(set(rep.sample.tolist())) == 4
    c = rep.contacts
    assert c["compared"] == 4 and c["mismatched_spheres"] == 0
    # the reference's own contact is at the analytic time (released at rest)
    ref = reference.simulate(scene, swarm, 1.0)
    t_hit = np.sqrt(2 * h / G)
    assert abs(ref.events.of_sphere(0).time[0] - t_hit) < 1e-12
    assert c["time_error_max_s"] < dt
    assert c["position_error_max_m"] < G * t_hit * dt
    assert set(rep.position_error) == {"0.1 s", "0.5 s", "1 s"}
    inv = rep.invariants
    assert inv["escaped"] == 0 and inv["inside"] == 0 and inv["capped_spheres"] == 0
    assert inv["energy_drift_max"] < 1e-9
    # both lose energy at the floor's height only (k of the kinetic energy when lossy)
    assert rep.energy["max_relative"] < 1e-9
    text = rep.summary()
    assert "first 5 contacts" in text and "time to 1 mm error" in text
    assert "energy against the reference" in text
    json.dumps(rep.to_dict(), allow_nan=False)


@pytest.mark.slow
def test_lossy_run_is_judged_by_energy_against_the_reference(device):
    h, r = 1.0, 0.05
    scene = floor_scene(energy_retention=0.7)
    swarm = ws.Swarm(position=[[0.0, h + r, 0.0], [0.5, h + r, 0.0]], velocity=np.zeros((2, 3)),
                     radius=r)
    sim = ws.Simulator(scene, swarm, dt=1 / 120, precision="float64", device=device)
    sim.run(120)
    rep = error_report.compare(sim, scene, swarm, sample=2)
    assert rep.invariants["energy_drift_max"] is None  # lost by design: no drift to speak of
    assert rep.energy["max_relative"] < 1e-9
    assert "energy drift" not in rep.summary()


def test_trajectory_input_gives_the_same_position_errors(device):
    scene = ws.Scene(closed_room(1.0))
    rng = np.random.default_rng(1)
    swarm = ws.Swarm(position=rng.uniform(-0.5, 0.5, (8, 3)),
                     velocity=rng.normal(0, 2.0, (8, 3)), radius=0.05)
    sim = ws.Simulator(scene, swarm, dt=1 / 60, precision="float64", device=device)
    traj = sim.run(60)
    from_sim = error_report.compare(sim, scene, swarm, sample=5, seed=2)
    from_traj = error_report.compare(traj, scene, swarm, sample=5, seed=2)
    np.testing.assert_array_equal(from_sim.sample, from_traj.sample)
    for key in from_sim.position_error:
        assert from_traj.position_error[key]["max_m"] == pytest.approx(
            from_sim.position_error[key]["max_m"], rel=1e-9, abs=1e-15)
    assert from_traj.invariants["energy_drift_max"] is None
    assert from_traj.contacts["compared"] >= 1


def test_contacts_from_frames_of_a_linear_bounce():
    """Frames of one exact chord bounce: the estimate recovers the contact time and normal."""
    dt, g = 0.1, np.zeros(3)
    v, tau = np.array([1.0, -2.0, 0.0]), 0.03  # contact 0.03 s into frame 1, floor normal +y
    v_out = v * [1, -1, 1]
    x0 = np.array([0.0, 2.0 * (dt + tau), 0.0])
    contact = x0 + v * (dt + tau)
    frames = [x0, x0 + v * dt, contact + v_out * (dt - tau), contact + v_out * (2 * dt - tau)]
    vel = [v, v, v_out, v_out]
    found = error_report.contacts_from_frames(np.array(frames)[:, None], np.array(vel)[:, None],
                                              dt, g, "linear")
    np.testing.assert_allclose(found.time, [dt + tau], atol=1e-12)
    np.testing.assert_allclose(found.normal, [[0.0, 1.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(found.position, [contact], atol=1e-12)
    assert found.frame.tolist() == [2] and found.sphere.tolist() == [0]
    np.testing.assert_allclose(found.fraction, [tau / dt], atol=1e-12)


@pytest.mark.slow
def test_bad_arguments(device):
    scene = floor_scene()
    swarm = ws.Swarm(position=[[0.0, 1.0, 0.0]], velocity=[[0.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match="sample"):
        error_report.compare(ws.Simulator(scene, swarm, device=device), scene, swarm, sample=0)
    with pytest.raises(ValueError, match="sim_or_trajectory"):
        error_report.compare("run", scene, swarm)
    sim = ws.Simulator(scene, swarm, device=device)
    traj = sim.run(10, every=2)
    with pytest.raises(ValueError, match="every frame"):
        error_report.compare(traj, scene, swarm)


@pytest.mark.slow
def test_ballistic_run_agrees_with_the_reference_at_every_step_size(device):
    """The exact-arc model is the reference's physics per frame: in float64 its positions after
    0.5 s in the standard room agree to far below a micrometre at dt = 1/30 s and 1/240 s
    alike (issue 9's figure), and its contact times to far below a microsecond."""
    scene = ws.Scene.load("room")
    swarm = scene.spawn(n=24, seed=5)
    for dt in (1 / 30, 1 / 240):
        try:
            sim = ws.Simulator(scene, swarm, dt=dt, precision="float64", motion="ballistic",
                               device=device)
        except TypeError:
            pytest.skip("this warpsim.Simulator has no motion='ballistic'")
        sim.run(round(0.5 / dt))
        rep = error_report.compare(sim, scene, swarm, sample=24)
        assert rep.settings["motion"] == "ballistic"
        assert rep.position_error["0.5 s"]["max_m"] < 1e-7
        if rep.contacts["compared"]:
            assert rep.contacts["time_error_max_s"] < 1e-7


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_the_report_compares_a_run_whose_grid_falls_back_to_the_bvh(device, precision):
    """A run whose grid falls back to the BVH (``grid-bvh``: galton's 162 boxes in either
    precision) is compared like any other: the report's own run of its sample asks for the
    grid by name and compiles the same method."""
    scene = ws.Scene.load("galton")
    swarm = scene.spawn(n=64, seed=1)
    sim = ws.Simulator(scene, swarm, precision=precision, device=device)
    assert sim.broad_phase == "grid-bvh"
    sim.run(12)
    assert error_report._like(sim, scene, swarm).broad_phase == "grid-bvh"
    rep = error_report.compare(sim, scene, swarm, sample=2)
    assert rep.horizon == pytest.approx(12 * sim.dt)
    assert rep.position_error["0.1 s"]["max_m"] < 1e-3
