"""The peer comparison (``benchmarks/peers``): its workload, its measures and every driver.

Each driver runs on a tiny configuration when its engine is installed (skipped otherwise; the
warpsim and NumPy drivers always run). What is checked against analytic answers:

* free flight: away from every obstacle, every peer integrates gravity by semi-implicit
  Euler, so after ``k`` frames a centre is exactly
  ``x0 + k dt v0 + g dt^2 k (k + 1) / 2`` and the step velocity ``v0 + k g dt``; warpsim
  (both motion models) moves on the exact parabola, ``x0 + k dt v0 + g (k dt)^2 / 2``, with
  the velocity ``v0 + k g dt`` (this checks each driver's units, axes, gravity, time step,
  initial state and velocity convention);
* the measures (escaped, inside, energy, error) on hand-made states with known answers;
* the NumPy baseline's box distance and normal against ``RoundedBoxes.signed_distance`` (an
  independent implementation) and its finite-difference gradient;
* warpsim on the real workload: no sphere escapes or ends inside an obstacle, and the energy
  is kept to float rounding.

No timing is asserted. The Newton driver compiles Newton's kernels on its first use (about a
minute, then cached by Warp).
"""

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root: benchmarks

from benchmarks.peers import workload as wl  # noqa: E402
from benchmarks.peers.engines import SETTINGS, unavailable  # noqa: E402
from benchmarks.peers.numpy_driver import closest_surface  # noqa: E402

FREE_FLIGHT_FRAMES = 12
#: Free-flight position error [m] allowed: float32 engines (warpsim float32, Newton) round a
#: ~2 m coordinate to ~1.2e-7 m each frame; 12 frames stay below 2e-6 m.
FREE_FLIGHT_TOL = 1e-5
#: Velocity error [m/s] allowed in free flight: float32 rounding of ~|v0| + k g dt per frame.
VELOCITY_TOL = 1e-4
#: Energy drift allowed for warpsim float32 over the tiny run: a few ulps of the per-sphere
#: energy per frame at most (the energy is reset from a kept invariant every frame).
WARPSIM_ENERGY_TOL = {"warpsim-float32": 1e-5, "warpsim-float64": 1e-12,
                      "warpsim-ballistic-float32": 1e-5, "warpsim-ballistic-float64": 1e-12}


def free_flight_workload() -> wl.Workload:
    """Three spheres in the empty room (walls only), far from every wall for 12 frames."""
    position = np.array([[0.0, 1.5, 0.0], [1.0, 2.0, -0.5], [-1.2, 0.8, 1.1]])
    velocity = np.array([[1.0, 0.5, -0.3], [-2.0, 0.0, 1.5], [0.0, 3.0, 0.0]])
    return wl.Workload(wl.room_walls(), position, velocity, speed=3.0,
                       frames=FREE_FLIGHT_FRAMES)


def available_settings():
    out = []
    for s in SETTINGS:
        why = unavailable(s)
        marks = [pytest.mark.skip(reason=why)] if why else []
        out.append(pytest.param(s, id=s.key, marks=marks))
    return out


# -- the workload ---------------------------------------------------------------------------------

def test_workload_is_reproducible_and_clear_of_obstacles():
    a = wl.make_workload(200, 60.0)
    b = wl.make_workload(200, 60.0)
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.velocity, b.velocity)
    assert len(a.obstacles) == 6 + wl.PLATES
    gap = a.boxes.signed_distance(a.position).min(axis=1) - a.radius
    assert gap.min() >= wl.SPAWN_GAP
    np.testing.assert_allclose(np.linalg.norm(a.velocity, axis=1), 60.0, rtol=1e-12)
    assert not wl.escaped(a.position).any()
    assert not wl.inside_obstacle(a, a.position).any()


def test_plates_are_inside_the_room_and_thin():
    for p in wl.room_plates():
        assert p.half_extents[1] == pytest.approx(wl.PLATE_THICKNESS / 2)
        reach = np.linalg.norm(p.half_extents)
        c = np.array(p.center)
        assert np.all(np.abs(c[[0, 2]]) + reach < wl.ROOM_HALF[[0, 2]])
        assert reach < c[1] < 2 * wl.ROOM_HALF[1] - reach


@pytest.mark.parametrize("kwargs, field", [({"n": 0, "speed": 5.0}, "n"),
                                           ({"n": 3, "speed": -1.0}, "speed"),
                                           ({"n": 3, "speed": float("nan")}, "speed"),
                                           ({"n": 3, "speed": 5.0, "frames": 0}, "frames")])
def test_workload_refuses_bad_input(kwargs, field):
    with pytest.raises(ValueError, match=f"^{field} must"):
        wl.make_workload(**kwargs)


# -- the measures ---------------------------------------------------------------------------------

def test_escaped_counts_only_spheres_beyond_the_walls():
    hx, hy, hz = wl.ROOM_HALF
    t = wl.WALL_THICKNESS
    p = np.array([[0.0, 1.0, 0.0],                 # in the room
                  [hx + 0.5 * t, 1.0, 0.0],        # centre inside the +x wall: not escaped
                  [hx + t + 1e-9, 1.0, 0.0],       # just beyond its outer face
                  [0.0, -t - 1e-9, 0.0],           # below the floor slab
                  [0.0, 2 * hy + t + 1e-9, 0.0],   # above the ceiling slab
                  [0.0, 1.0, -hz - t - 1.0],       # far beyond the -z wall
                  [np.nan, 1.0, 0.0]])             # not finite
    np.testing.assert_array_equal(wl.escaped(p), [False, False, True, True, True, True, True])


def test_inside_obstacle_uses_the_overlap_depth():
    work = wl.make_workload(1, 5.0)
    plate = work.obstacles[6]
    rot = work.boxes.rotation_matrices()[6]
    c = np.array(plate.center)
    normal = rot[:, 1]                              # the plate's thin axis, world frame
    face = plate.half_extents[1]
    r, tol = work.radius, wl.INSIDE_TOLERANCE
    p = np.array([c,                                            # centre in the plate
                  c + normal * (face + r - 0.5 * tol),          # overlap below the tolerance
                  c + normal * (face + r - 2.0 * tol),          # overlap above it
                  c + normal * (face + r + 1e-3),               # clear
                  [np.nan, 0.0, 0.0]])
    np.testing.assert_array_equal(wl.inside_obstacle(work, p), [True, False, True, False, False])


def test_energy_is_constant_along_semi_implicit_free_flight():
    work = free_flight_workload()
    g = np.array(work.gravity)
    x, v = work.position.copy(), work.velocity.copy()
    e0 = wl.energy(work, x, v)
    for _ in range(50):
        v = v + g * work.dt
        x = x + v * work.dt
    np.testing.assert_allclose(wl.energy(work, x, v), e0, rtol=1e-12)
    drift = wl.energy_drift(work, x, v)
    assert abs(drift["total"]) < 1e-12 and drift["worst_sphere"] < 1e-12
    # 1/2 m |u|^2 + m g y by hand for the first sphere at the start
    u = work.velocity[0] + 0.5 * work.dt * g
    assert e0[0] == pytest.approx(0.5 * u @ u + 9.81 * 1.5, rel=1e-14)


def test_energy_drift_leaves_out_spheres_that_are_not_finite():
    work = free_flight_workload()
    v = work.velocity.copy()
    v[1] = np.nan
    v[0] *= 2.0
    e0 = wl.energy(work, work.position, work.velocity)
    e1 = wl.energy(work, work.position, v)
    drift = wl.energy_drift(work, work.position, v)
    # the scale: each sphere's energy above the lowest point of the obstacles and start positions
    assert work.gravity[0] == work.gravity[2] == 0.0
    bottom = min((work.boxes.center[:, 1] - work.boxes.world_extent()[:, 1]).min(),
                 work.position[:, 1].min())
    scale = e0 - work.mass * (-work.gravity[1]) * bottom
    expected = (e1[[0, 2]].sum() - e0[[0, 2]].sum()) / scale[[0, 2]].sum()
    assert drift["total"] == pytest.approx(expected, rel=1e-12)
    worst = np.max(np.abs(e1[[0, 2]] - e0[[0, 2]]) / scale[[0, 2]])
    assert drift["worst_sphere"] == pytest.approx(worst, rel=1e-12)


def test_reference_error_summaries():
    exact = np.zeros((61, 4, 3))
    recorded = exact.copy()
    recorded[:, 0, 0] = np.linspace(0.0, 0.6, 61)   # drifts to 0.6 m at frame 60
    recorded[6, 1, 1] = 0.05                         # one excursion at 0.1 s
    recorded[10, 2, 2] = np.inf                      # the engine lost it
    exact[:, 3] = np.nan                             # the reference gave this one up
    e = wl.reference_error(recorded, exact, 1 / 60)
    assert e["sample"] == 3 and e["left_out"] == 1
    assert e["worst"] == np.inf
    assert e["median"] == pytest.approx(0.6)
    assert e["median_at"]["0.1"] == pytest.approx(0.05)   # 0.06 (sphere 0), 0.05, 0
    assert e["median_at"]["0.5"] == pytest.approx(0.0)
    assert e["share_over_0.1m"] == pytest.approx(2 / 3)


# -- the NumPy baseline's geometry ----------------------------------------------------------------

coord = st.floats(-2.0, 2.0, allow_nan=False)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(st.tuples(coord, coord, coord),
       st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(0.0, 1.0)))
def test_closest_surface_matches_signed_distance(point, half):
    import warpsim as ws

    half = np.array(half)
    p = np.array([point])
    dist, normal, surface = closest_surface(p, half)
    box = ws.RoundedBoxes(center=[(0.0, 0.0, 0.0)], half_extents=[half])
    assert dist[0] == pytest.approx(box.signed_distance(p)[0, 0], abs=1e-12)
    assert np.linalg.norm(normal[0]) == pytest.approx(1.0, abs=1e-12)
    # the point is the surface point moved along the normal by the signed distance
    np.testing.assert_allclose(surface[0] + dist[0] * normal[0], p[0], atol=1e-12)
    assert np.all(np.abs(surface[0]) <= half + 1e-12)


def test_closest_surface_normal_is_the_distance_gradient():
    rng = np.random.default_rng(3)
    half = np.array([0.6, 0.01, 0.3])
    p = rng.uniform(-1.0, 1.0, size=(500, 3))
    dist, normal, _ = closest_surface(p, half)
    h = 1e-6
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = h
        grad = (closest_surface(p + step, half)[0] - closest_surface(p - step, half)[0]) / (2 * h)
        # away from the creases where the nearest face changes, the gradient is the normal
        smooth = np.abs(grad - normal[:, axis]) < 1e-3
        assert smooth.mean() > 0.98


# -- every driver ---------------------------------------------------------------------------------

@pytest.mark.parametrize("setting", available_settings())
def test_driver_free_flight_in_its_velocity_convention(setting):
    work = free_flight_workload()
    driver = setting.make(work)
    try:
        driver.step(FREE_FLIGHT_FRAMES)
        position, velocity = driver.state()
        k = FREE_FLIGHT_FRAMES
        g, dt = np.array(work.gravity), work.dt
        kicks = k * (k + 1) / 2 if driver.step_velocity else k * k / 2
        exact_x = work.position + k * dt * work.velocity + g * dt * dt * kicks
        np.testing.assert_allclose(position, exact_x, atol=FREE_FLIGHT_TOL, rtol=0)
        np.testing.assert_allclose(velocity, work.velocity + k * g * dt, atol=VELOCITY_TOL,
                                   rtol=0)
        # reset goes back to the start, and the run repeats exactly
        driver.reset()
        again = driver.state()
        np.testing.assert_allclose(again[0], work.position, atol=1e-6, rtol=0)
        driver.step(FREE_FLIGHT_FRAMES)
        np.testing.assert_array_equal(driver.state()[0], position)
    finally:
        driver.close()


@pytest.mark.parametrize("setting", available_settings())
def test_driver_runs_the_workload(setting):
    work = wl.make_workload(6, 60.0, frames=20)
    driver = setting.make(work)
    try:
        driver.step(work.frames)
        position, velocity = driver.state()
        assert position.shape == velocity.shape == (work.n, 3)
        assert position.dtype == velocity.dtype == np.float64
        json.dumps(driver.settings(), default=float)   # the JSON report can hold them
        assert driver.key == setting.key
    finally:
        driver.close()


@pytest.mark.parametrize("key", sorted(WARPSIM_ENERGY_TOL))
@pytest.mark.parametrize("speed", wl.SPEEDS)
def test_warpsim_keeps_every_sphere_in_the_room(key, speed):
    setting = next(s for s in SETTINGS if s.key == key)
    work = wl.make_workload(32, speed, frames=90)
    driver = setting.make(work)
    driver.step(work.frames)
    position, velocity = driver.state()
    assert not wl.escaped(position).any()
    assert not wl.inside_obstacle(work, position).any()
    drift = wl.energy_drift(work, position, velocity, driver.step_velocity)
    assert abs(drift["total"]) < WARPSIM_ENERGY_TOL[key]


# -- the command ----------------------------------------------------------------------------------

@pytest.mark.slow
def test_command_writes_table_json_and_plot(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from benchmarks.peers.run import main

    out = tmp_path / "res"
    assert main(["--n", "4", "--frames", "12", "--repeats", "2", "--sample", "3",
                 "--engines", "warpsim-float32,numpy-discrete", "--out", str(out)]) == 0
    results = json.loads((out / "peers.json").read_text())
    rows = results["rows"]
    assert [(r["setting"], r["speed"]) for r in rows] == [
        ("warpsim-float32", 5.0), ("numpy-discrete", 5.0),
        ("warpsim-float32", 60.0), ("numpy-discrete", 60.0)]
    for r in rows:
        assert len(r["samples_s"]) == 2 and r["ns_per_sphere_frame"] > 0
        assert r["over_baseline"] == pytest.approx(
            np.median(r["samples_s"]) / np.median(rows[0 if r["speed"] == 5.0 else 2]
                                                  ["samples_s"]))
    table = (out / "peers.md").read_text()
    assert table.count("\n| warpsim float32 |") == 2 and "NumPy discrete" in table
    assert (out / "peers.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(out.glob("*.tmp*"))
    if results["reference"]["5"].startswith("reference computed"):
        assert rows[0]["error"]["sample"] == 3
        # 12 frames of free flight or bounces: the frame-0 positions are the reference's
        assert rows[0]["error"]["median_at"]["0.1"] < 0.05


@pytest.mark.parametrize("argv, message", [(["--n", "0"], "--n must be >= 1"),
                                           (["--repeats", "0"], "--repeats must be >= 1"),
                                           (["--engines", "warpsim,bogus"], "unknown setting")])
def test_command_refuses_bad_options(argv, message, capsys):
    from benchmarks.peers.run import parse_args

    with pytest.raises(SystemExit):
        parse_args(argv)
    assert message in capsys.readouterr().err
