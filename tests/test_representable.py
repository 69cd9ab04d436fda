"""Numbers a precision cannot hold are refused before a run; coarse float32 is warned about.

``feasibility.check_run`` is checked against numpy doing the same arithmetic in the chosen
precision: what it accepts stays finite there, and what it refuses as hopeless far from the
origin really rounds a frame's motion away. No Warp kernel runs here.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import warpsim as ws
from warpsim import feasibility
from warpsim.feasibility import PrecisionWarning

DT = 1.0 / 60.0
DTYPE = {"float32": np.float32, "float64": np.float64}
LIMIT = {p: float(np.finfo(d).max) * feasibility.MAGNITUDE_MARGIN for p, d in DTYPE.items()}
SQUARE_LIMIT = {p: LIMIT[p] ** 0.5 for p in DTYPE}
FIX = '; precision="float64" holds it'


def _run(precision="float32", *, dt=DT, max_bounces=8, offset=0.0, velocity=0.0, radius=0.05,
         mass=1.0, gravity=(0.0, -9.81, 0.0), angular_momentum=0.0, box_center=None,
         friction=0.0):
    """check_run on three spheres above a floor, the middle one (index 1) given the values."""
    center = [offset, offset - 0.5, offset] if box_center is None else box_center
    scene = ws.Scene(ws.RoundedBoxes(center=[center], half_extents=[[50.0, 0.5, 50.0]]),
                     gravity=gravity, friction=friction)
    v = np.zeros((3, 3))
    v[1, 0] = velocity
    swarm = ws.Swarm(position=np.full((3, 3), offset) + (0.0, 1.0, 0.0), velocity=v,
                     radius=[0.05, radius, 0.05], mass=[1.0, mass, 1.0],
                     angular_momentum=[[0.0, 0.0, 0.0], [angular_momentum, 0.0, 0.0],
                                       [0.0, 0.0, 0.0]])
    return feasibility.check_run(scene, swarm, dt, precision, max_bounces)


def _refused(message: str, **kwargs) -> None:
    with pytest.raises(ValueError) as info:
        _run(**kwargs)
    assert str(info.value) == message


def test_a_plain_run_passes_silently(precision):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _run(precision) == []


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n, _ in ws.list_scenes()])
def test_every_bundled_scene_passes_silently_in_both_precisions(name, precision):
    scene = ws.Scene.load(name)
    swarm = scene.spawn()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert feasibility.check_run(scene, swarm, scene.dt, precision, scene.max_bounces) == []
    feasibility.check_outside(scene.boxes, swarm.position, swarm.radius, precision)


# --- too small, too large --------------------------------------------------------------------


def test_a_dt_that_underflows_is_refused():
    _refused('dt = 1e-300 s underflows in float32 (smallest normal 1.18e-38 s); '
             'precision="float64" holds it', dt=1e-300)
    _refused("dt = 1e-40 s underflows in float32 (smallest normal 1.18e-38 s)" + FIX, dt=1e-40)
    assert _run("float64", dt=1e-300, gravity=(0.0, 0.0, 0.0)) == []
    _refused("dt = 9.99989e-321 s underflows in float64 (smallest normal 2.23e-308 s)",
             precision="float64", dt=1e-320)


def _too_large(field, shown, quantity, value, unit, precision, squared):
    bound = SQUARE_LIMIT[precision] if squared else LIMIT[precision]
    why = "its square must stay finite" if squared else "sums and products must stay finite"
    fix = FIX if precision == "float32" and value <= (
        SQUARE_LIMIT["float64"] if squared else LIMIT["float64"]) else ""
    return (f"{field}{shown} is too large for {precision}: {quantity} = {value:.3g} {unit}, "
            f"above {bound:.3g} ({why}){fix}")


@pytest.mark.parametrize("factor", [1.5, 1e6])
def test_each_field_is_checked_against_the_precision(precision, factor):
    sq, lim = SQUARE_LIMIT[precision], LIMIT[precision]
    v = factor * sq
    _refused(_too_large("velocity", f"[1] = ({v:g}, 0, 0)", "|v|", v, "m/s", precision, True),
             precision=precision, velocity=v)
    dt = 10.0 * factor
    v = factor * sq / dt  # |v| fits, a frame's path |v| dt does not
    _refused(_too_large("velocity", f"[1] = ({v:g}, 0, 0)", "|v| dt", v * dt, "m", precision,
                        True), precision=precision, velocity=v, dt=dt, gravity=(0, 0, 0))
    g = factor * sq / DT
    _refused(_too_large("gravity", "", "|g| dt", g * DT, "m/s", precision, True),
             precision=precision, gravity=(0.0, -g, 0.0))
    r = factor * sq
    _refused(_too_large("radius", f"[1] = {r:g}", "r", r, "m", precision, True),
             precision=precision, radius=r)
    m = factor * lim
    _refused(_too_large("mass", f"[1] = {m:g}", "m", m, "kg", precision, False),
             precision=precision, mass=m)
    v, m = (20.0 * factor) ** 0.5, 0.1 * lim  # both fine alone, not 1/2 m |v|^2
    _refused(_too_large("velocity", f"[1] = ({v:g}, 0, 0)", "1/2 m |v|^2", 0.5 * m * v * v,
                        "J", precision, False), precision=precision, velocity=v, mass=m)
    L = factor * lim
    _refused(_too_large("angular_momentum", f"[1] = ({L:g}, 0, 0)", "largest |component|", L,
                        "kg m^2/s", precision, False), precision=precision, angular_momentum=L)
    c = factor * sq
    _refused(_too_large("box", f"[0] = ({c:g}, 0, 0)", "|center| + size", c + 50.0, "m",
                        precision, True), precision=precision, box_center=[c, 0.0, 0.0])
    k = factor * lim
    _refused(_too_large("friction", "", "k_f", k, "kg/s", precision, False),
             precision=precision, friction=k)


def test_gravity_and_dt_that_cannot_be_held_are_named():
    _refused(_too_large("gravity", "", "|g|", 1e31, "m/s^2", "float32", False),
             gravity=(0.0, -1e31, 0.0))
    _refused(_too_large("gravity", "", "|g| dt", 9.81e30, "m/s", "float32", True), dt=1e30)
    assert _run("float32", dt=1e30, gravity=(0.0, 0.0, 0.0)) == []
    _refused("gravity * dt = 1e-40 m/s underflows in float32: a frame's gravity would do nothing",
             gravity=(0.0, -1e-30, 0.0), dt=1e-10)
    _refused("mass[1] = 1e-40 kg underflows in float32 (smallest normal 1.18e-38 kg)", mass=1e-40)


def test_the_run_arguments_are_checked_too():
    for kwargs, message in [
        (dict(max_bounces=2**32), "max_bounces must be <= 1024 (contacts per sphere per "
                                  "frame), got 4294967296"),
        (dict(max_bounces=True), "max_bounces must be an integer, got True"),
        (dict(dt="0.1"), "dt must be a number, got '0.1'"),
        (dict(dt=True), "dt must be a number, got True"),
        (dict(precision="float16"), "precision must be one of ('float32', 'float64'), got "
                                    "'float16'"),
    ]:
        _refused(message, **kwargs)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(precision=st.sampled_from(["float32", "float64"]),
       log_v=st.floats(-40.0, 40.0), log_dt=st.floats(-45.0, 35.0),
       log_g=st.floats(-45.0, 45.0), log_m=st.floats(-45.0, 45.0),
       log_x=st.floats(-5.0, 40.0))
def test_what_is_accepted_stays_finite_in_the_precision(precision, log_v, log_dt, log_g, log_m,
                                                        log_x):
    """Whatever passes, the kernels' first products in that precision are finite and dt > 0."""
    v, dt, g, m, x = (10.0 ** e for e in (log_v, log_dt, log_g, log_m, log_x))
    scene = ws.Scene(ws.RoundedBoxes(center=[[x, x, x]], half_extents=[[1.0, 1.0, 1.0]]),
                     gravity=(0.0, -g, 0.0))
    swarm = ws.Swarm(position=[[x, x + 2.0, x]], velocity=[[v, -v, v]], mass=m)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PrecisionWarning)
            feasibility.check_run(scene, swarm, dt, precision, 8)
    except ValueError:
        return
    f = DTYPE[precision]
    p, u, gv = (np.asarray(a, dtype=f) for a in (swarm.position, swarm.velocity, scene.gravity))
    step, mass = f(dt), f(m)
    assert step > 0
    with np.errstate(over="raise", invalid="raise"):
        kicked = u + gv * step
        path = kicked * step
        for value in (np.sum(kicked * kicked), np.sum(path * path), np.sum(p * p),
                      f(0.5) * mass * np.sum(kicked * kicked), mass * gv[1] * p[0, 1],
                      np.sum((p - f(x)) ** 2)):
            assert np.isfinite(value)


# --- far from the origin ---------------------------------------------------------------------


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(log_offset=st.floats(0.0, 12.0), precision=st.sampled_from(["float32", "float64"]),
       speed=st.sampled_from([0.0, 1.0, 30.0]))
def test_refused_far_out_exactly_where_a_frame_motion_rounds_away(log_offset, precision, speed):
    offset = 10.0 ** log_offset
    f = DTYPE[precision]
    extent = offset + 50.0  # the floor's far edge
    motion = max(9.81 * DT * DT, speed * DT)
    spacing = float(np.spacing(f(extent)))
    if abs(spacing / (2.0 * motion) - 1.0) < 0.05:
        return  # at the threshold itself rounding ties decide; not a property to pin
    moved = f(extent) + f(motion) != f(extent)  # numpy's own float arithmetic, no warpsim
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PrecisionWarning)
            _run(precision, offset=offset, velocity=speed)
    except ValueError as exc:
        assert not moved
        assert "every sphere would freeze" in str(exc)
    else:
        assert moved


def test_far_out_warns_then_refuses_and_names_the_fix():
    with pytest.warns(PrecisionWarning) as record:
        texts = _run("float32", offset=1e4)
    assert [str(w.message) for w in record] == texts
    assert texts == [
        "float32's spacing at the scene's coordinates (up to 1e+04 m) is 0.000977 m, 36 % of a "
        "frame's largest motion (0.00272 m): every move is rounded that coarsely; "
        'precision="float64" fixes it',
        "float32's spacing at the scene's coordinates (up to 1e+04 m) is 0.000977 m, 2 % of the "
        "smallest sphere radius (0.05 m): contacts are placed that coarsely; "
        'precision="float64" fixes it']
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _run("float64", offset=1e4) == []
        assert _run("float64", offset=1e8) == []
    _refused("float32's spacing at the scene's coordinates (up to 1e+08 m) is 8 m, at least 2 "
             "times a frame's largest motion (0.00272 m): every sphere would freeze; "
             'precision="float64" fixes it', offset=1e8)
    _refused("float64's spacing at the scene's coordinates (up to 1e+16 m) is 2 m, at least 2 "
             "times a frame's largest motion (0.00272 m): every sphere would freeze; move the "
             "scene nearer the origin", precision="float64", offset=1e16)


def test_the_documented_distance_where_resting_float32_spheres_freeze():
    """README: spheres at rest at 60 Hz freeze in float32 from 65 km off the origin."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PrecisionWarning)
        _run("float32", offset=64_000.0)
    with pytest.raises(ValueError, match="every sphere would freeze"):
        _run("float32", offset=65_536.0)


def test_tiny_radii_warn_in_float32_only():
    with pytest.warns(PrecisionWarning, match=r"3\.8e\+04 times the smallest sphere radius "
                                              r"\(1e-10 m\)"):
        _run("float32", radius=1e-10)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _run("float64", radius=1e-10) == []
        assert _run("float32", radius=0.0) == []  # points are points: nothing to resolve
