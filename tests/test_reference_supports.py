"""The exact reference's supports (``warpsim.analysis.reference``) against analytic slides.

A frictionless sphere sliding off a face over a sharp or rounded edge, released on a rounded
edge (with motion and gravity along the edge's axis, on rotated boxes, far from the origin, a
point sphere), passing over an edge onto the next face, and sliding on a rounded corner: every
expected motion comes from ``support_analytic`` (closed forms and quadrature of the energy
integral, independent of warpsim), never from the code under test; that quadrature is checked
first against a closed form.
"""

import numpy as np
import pytest
import support_analytic as sa
from helpers import examples
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

import warpsim as ws
from warpsim.analysis import reference

G = 9.81

#: The accuracy the reference claims on supports [m] (the issue's contract): the analytic
#: answers are good to ~1e-13 m, the reference's events to float64 rounding.
POS_TOL = 1e-9

#: Velocities [m/s]: the same claim over the slides' time scale (~0.1 s).
VEL_TOL = 1e-8

#: Energy along a curved slide, relative: the slide resets the energy at each Taylor step, so
#: only a few roundings of it remain.
ENERGY_REL_TOL = 1e-12

#: Distance [m] of the centre from the Minkowski surface while it slides: the slide puts it
#: back on the surface at each step; what is left is the rounding of the distance at unit scale.
SURFACE_TOL = 1e-13

#: Off the surface [m]: a gap above this is a flight (a hundred times SURFACE_TOL and more).
LIFT_GAP = 1e-11

#: Float64 rounding of the set-up's own constructions (rotations, angles), unit scale.
ROUNDING = 1e-12

#: Angular margin [rad] that keeps a drawn start off the border of the edge's region.
REGION_MARGIN = 1e-3

#: Sample times per run: enough to see every piece of the motion (slide, detachment, flight).
SAMPLES = 61


# -- the analytic answers' own quadrature ---------------------------------------------------------


@pytest.mark.parametrize("c", [1.0, 1e-6, 1e-120, 0.0])
def test_quadrature_of_the_release_integrand_against_its_closed_form(c):
    """``int_0^1 2 s / sqrt(s^2 + c) ds = 2 (sqrt(1 + c) - sqrt(c))``: the shape of every
    time integral after the substitution ``q = q0 + s^2`` (``c``: the start's rate squared; a
    start at rest is 0, one all but at rest 1e-120), to a few rounding units."""
    got = sa.integrate(lambda s: 2.0 * s / np.sqrt(s * s + c), 0.0, 1.0)
    want = 2.0 * (np.sqrt(1.0 + c) - np.sqrt(c))
    assert abs(got - want) <= 1e-14 * want


def test_quadrature_refuses_an_integrand_that_never_settles():
    """An integrand whose noise lies above the quadrature's tolerance (here a wiggle of 1e-12
    on 1, where the tolerance is 2e-15) is refused after ``QUAD_MAX_PANELS`` panels instead of
    bisecting every panel to the depth guard (2^40 panels: the test would hang)."""
    with pytest.raises(ValueError, match="did not settle"):
        sa.integrate(lambda u: 1.0 + 1e-12 * np.sin(1e9 * u), 0.0, 1.0)


def rotation_about(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate([axis * np.sin(angle / 2), [np.cos(angle / 2)]])


def quat_product(a, b):
    """``a * b`` for quaternions ``(x, y, z, w)``."""
    av, aw, bv, bw = np.asarray(a[:3]), a[3], np.asarray(b[:3]), b[3]
    return np.concatenate([aw * bv + bw * av + np.cross(av, bv), [aw * bw - av @ bv]])


def run_against(box, x0, v0, r, expected, t_end, gravity=(0.0, -G, 0.0)):
    """The reference from ``x0``, ``v0`` against ``expected`` at SAMPLES times up to ``t_end``:
    its worst position and velocity errors, after checking them and the run's health."""
    scene = ws.Scene(box, gravity=gravity)
    times = np.linspace(0.0, t_end, SAMPLES)
    run = reference.simulate(scene, ws.Swarm(position=[x0], velocity=[v0], radius=r), t_end,
                             times)
    assert not run.incomplete.any()
    assert not len(run.events.of_sphere(0).bounces())
    x, v = expected.at(times)
    pos_err = float(np.linalg.norm(run.position[:, 0] - x, axis=1).max())
    vel_err = float(np.linalg.norm(run.velocity[:, 0] - v, axis=1).max())
    assert pos_err < POS_TOL, pos_err
    assert vel_err < VEL_TOL, vel_err
    return run, pos_err


def stays_outside(box, expected, r, t_end) -> bool:
    """Whether the analytic motion's last piece (a flight or a face slide; the slides before it
    are on the surface by construction) stays off the box: the motion has no bounce in it."""
    x, _ = expected.at(np.linspace(expected.breaks[-1], t_end, 400))
    return bool(box.signed_distance(x)[:, 0].min() - r > -POS_TOL)


# -- a face slide off an edge ------------------------------------------------------------------


@pytest.mark.parametrize("far", [0.0, 1e3], ids=["origin", "far"])
@pytest.mark.parametrize("speed", [0.3, 0.8, 0.98, 1.0, 1.5])
@pytest.mark.parametrize("rb", [0.0, 0.15], ids=["sharp", "rounded"])
def test_face_slide_off_an_edge(rb, speed, far):
    """On top of a box at ``speed`` towards its +x edge: the contact point leaves the face at
    the root of the face parabola, then the sphere rides the edge's cylinder (R = rb + r) to
    the detachment, or leaves at once when ``speed^2 / R > g`` (a sharp box's 1 m/s case with
    r = 0.1: 10 > 9.81)."""
    r = 0.1
    R = rb + r
    center = np.array([far, -0.5 - far / 3, 0.2 * far])
    h = np.array([0.5, 0.5, 0.6])
    box = ws.RoundedBoxes(center=[center], half_extents=[h], radius=[rb])
    top = center + [0.0, h[1], 0.0]
    x0 = top + [0.1, R, 0.05]
    v0 = np.array([speed, 0.0, 0.2])
    edge = center + [h[0], h[1], 0.0]
    expected = sa.face_slide_off(x0, v0, (0.0, -G, 0.0), (0.0, 1.0, 0.0), edge, (0.0, 0.0, 1.0),
                                 R)
    t_edge = expected.breaks[1]  # the contact point leaves the face
    run_against(box, x0, v0, r, expected, t_edge + 0.3)
    at_once = speed * speed / R > G
    assert expected.kinds[1] == ("flight" if at_once else "cylinder")


# -- a release on a rounded edge ----------------------------------------------------------------


@settings(max_examples=examples(40))
@given(angle=st.floats(0.5, 85.0), spin=st.floats(0.0, 1.4), axial=st.floats(-1.0, 1.0),
       tilt=st.floats(-0.6, 0.6), turn=st.floats(0.0, 2 * np.pi),
       far=st.sampled_from([0.0, 1e3]), r=st.sampled_from([0.0, 0.05]))
# spin 1: the normal force is 0 at the start, up to rounding either way (it leaves at once)
@example(angle=53.46989266177574, spin=1.0, axial=0.0, tilt=0.0, turn=1.0, far=0.0, r=0.0)
@example(angle=20.0, spin=1.0, axial=0.3, tilt=0.2, turn=0.5, far=1e3, r=0.05)
def test_slide_on_a_rounded_edge(angle, spin, axial, tilt, turn, far, r):
    """A sphere put on a rounded edge (rb = 0.15) ``angle`` degrees from the top, with an
    angular speed ``spin`` times the one that detaches it at once and a speed ``axial`` [m/s]
    along the edge, on a box turned by ``turn`` about the vertical and tilted by ``tilt``
    about a horizontal axis across the edge (gravity then has a part along the axis), at the
    origin or 1 km away; a point sphere (r = 0) too. Against the analytic slide on the
    cylinder, then the free flight (or the slide on the next face)."""
    rb = 0.15
    R = rb + r
    h = np.array([0.6, 0.5, 0.9])
    q = quat_product(rotation_about([0.0, 1.0, 0.0], turn), rotation_about([1.0, 0.0, 0.0], tilt))
    m = ws.obstacles.quat_to_matrix(q)
    center = np.array([0.3 * far, -far, 0.7 * far]) + [0.2, -0.5, 0.1]
    box = ws.RoundedBoxes(center=[center], half_extents=[h], rotation=[q], radius=[rb])
    g = np.array([0.0, -G, 0.0])
    axis = m[:, 2]
    up = -(g - (g @ axis) * axis)
    up /= np.linalg.norm(up)
    # the edge along local z at (+hx, +hy); local +y is the top face (the tilt keeps it
    # within 0.6 rad of up), so the edge's region spans psi from the top face's normal on
    edge = center + m @ [h[0], h[1], 0.0]
    side = np.cross(axis, up)
    if side @ m[:, 0] < 0.0:
        side = -side
    psi_top_face = np.arctan2(m[:, 1] @ side, m[:, 1] @ up)
    psi_side_face = np.arctan2(m[:, 0] @ side, m[:, 0] @ up)
    psi = max(np.radians(angle), psi_top_face + REGION_MARGIN)
    assume(psi < psi_side_face - REGION_MARGIN)
    n = np.cos(psi) * up + np.sin(psi) * side
    tangent = -np.sin(psi) * up + np.cos(psi) * side
    g_perp = float(np.linalg.norm(g - (g @ axis) * axis))
    omega_at_once = np.sqrt(g_perp * np.cos(psi) / R)
    x0 = edge + R * n
    v0 = spin * omega_at_once * R * tangent + axial * axis
    expected = sa.cylinder_slide(edge, axis, R, x0, v0, g, exit_normal=m[:, 0])
    t_end = expected.breaks[-1] + 0.05
    assume(stays_outside(box, expected, r, t_end))
    # the contact point stays on the edge (its axial position within the core's length)
    axial_end, _ = expected.at([t_end])
    assume(abs(m[:, 2] @ (axial_end[0] - center)) < h[2])
    run_against(box, x0, v0, r, expected, t_end)


@pytest.mark.parametrize("far", [0.0, 1e3], ids=["origin", "far"])
@pytest.mark.parametrize("angle", [0.1, 1.0, 20.0, 40.0, 60.0, 80.0])
def test_release_from_rest_on_a_rounded_edge_detaches_at_the_analytic_angle(angle, far):
    """Released at rest on a horizontal rounded edge (rb = 0.15, r = 0.05): the sphere leaves
    where ``cos(theta_d) = (2/3) cos(theta_0)``, at the analytic instant, then flies freely."""
    rb, r = 0.15, 0.05
    R = rb + r
    center = np.array([far, -0.5, -far])
    h = np.array([0.5, 0.5, 0.5])
    box = ws.RoundedBoxes(center=[center], half_extents=[h], radius=[rb])
    edge = center + [h[0], h[1], 0.0]
    t0 = np.radians(angle)
    x0 = edge + R * np.array([np.sin(t0), np.cos(t0), 0.0])
    expected = sa.cylinder_slide(edge, (0.0, 0.0, 1.0), R, x0, np.zeros(3), (0.0, -G, 0.0))
    t_d = expected.break_of("flight")
    x_d, _ = expected.at([t_d])
    off = x_d[0] - edge
    np.testing.assert_allclose(off[1] / R, 2.0 / 3.0 * np.cos(t0), atol=ROUNDING)
    run, _ = run_against(box, x0, np.zeros(3), r, expected, t_d + 0.2)
    gap = box.signed_distance(run.position[:, 0])[:, 0] - r
    assert gap.min() > -SURFACE_TOL


def test_slide_over_an_edge_lands_on_the_next_face():
    """A box turned 45 degrees about z (a ridge): released at rest 5 degrees past the ridge, the
    sphere slides over the rounded edge (it would leave at 48.4 degrees) and reaches the next
    face at 45 degrees, then slides down that face's plane."""
    rb, r = 0.1, 0.1
    R = rb + r
    q = rotation_about([0.0, 0.0, 1.0], np.pi / 4)
    m = ws.obstacles.quat_to_matrix(q)
    h = np.array([1.5, 1.5, 0.5])
    center = np.array([0.0, -2.0, 0.0])
    box = ws.RoundedBoxes(center=[center], half_extents=[h], rotation=[q], radius=[rb])
    ridge = center + m @ [h[0], h[1], 0.0]
    assert abs(ridge[0]) < ROUNDING  # the edge along z at the top
    t0 = np.radians(5.0)
    x0 = ridge + R * np.array([-np.sin(t0), np.cos(t0), 0.0])  # towards the -x side
    v0 = np.array([0.0, 0.0, 0.3])
    next_face = m @ [0.0, 1.0, 0.0]
    assert next_face[0] < 0.0
    expected = sa.cylinder_slide(ridge, (0.0, 0.0, 1.0), R, x0, v0, (0.0, -G, 0.0),
                                 exit_normal=next_face)
    assert expected.kinds == ["cylinder", "face"]
    run, _ = run_against(box, x0, v0, r, expected, expected.break_of("face") + 0.3)
    assert np.all(run.events.of_sphere(0).kind == ws.ContactKind.SUPPORT)


# -- a rounded corner ---------------------------------------------------------------------------


@settings(max_examples=examples(25))
@given(height=st.floats(0.35, 0.999), azimuth=st.floats(0.0, 2 * np.pi),
       speed=st.floats(0.0, 1.2), heading=st.floats(0.0, np.pi / 2),
       far=st.sampled_from([0.0, 1e3]))
# speed 1: the normal force is 0 at the start, up to rounding either way (it leaves at once)
@example(height=0.40788944723618087, azimuth=0.0, speed=1.0, heading=0.0, far=0.0)
@example(height=0.6683919597989949, azimuth=1.0, speed=1.0, heading=0.5, far=1e3)
# near the top, all but at rest: the azimuth's integrand must not cancel (1 - u^2 small)
@example(height=0.999, azimuth=1.8125184146203626, speed=1e-53, heading=6e-8, far=1e3)
def test_slide_on_a_ball(height, azimuth, speed, heading, far):
    """A box of zero extents (its rounded corner is the whole surface: a ball, rb = 0.4): a
    sphere put on it at height ``height`` R above its centre, moving at ``speed`` times the
    speed that detaches it at once, horizontally (``heading`` 0) or downhill, follows the
    inverted spherical pendulum to ``|v|^2 / R = -g . n``, then flies."""
    rb, r = 0.4, 0.1
    R = rb + r
    center = np.array([far, 0.5 * far, -far])
    box = ws.RoundedBoxes(center=[center], half_extents=[[0.0, 0.0, 0.0]], radius=[rb])
    rho = np.sqrt(1.0 - height * height)
    n = np.array([rho * np.cos(azimuth), height, rho * np.sin(azimuth)])
    east = np.array([-np.sin(azimuth), 0.0, np.cos(azimuth)])
    down = np.cross(n, east)  # tangent, pointing down the slope
    v_once = np.sqrt(G * height * R)
    v0 = speed * v_once * (np.cos(heading) * east + np.sin(heading) * down)
    x0 = center + R * n
    expected = sa.sphere_slide(center, R, x0, v0, (0.0, -G, 0.0))
    run_against(box, x0, v0, r, expected, expected.breaks[-1] + 0.2)


@pytest.mark.parametrize("angle", [5.0, 15.0, 25.0])
def test_slide_on_a_box_corner(angle):
    """A cube turned so that its +++ corner points up: released at rest ``angle`` degrees from
    the top towards the +x face's normal, the sphere stays in the corner's region (on its
    symmetry plane) and leaves where the spherical pendulum says (48.2 degrees and more, below
    the 54.7 degrees of the face normal), the flight soon landing on that face."""
    rb, r = 0.2, 0.05
    R = rb + r
    diag = np.ones(3) / np.sqrt(3.0)
    axis = np.cross(diag, [0.0, 1.0, 0.0])
    q = rotation_about(axis, np.arccos(diag[1]))
    m = ws.obstacles.quat_to_matrix(q)
    h = np.array([0.4, 0.4, 0.4])
    box = ws.RoundedBoxes(center=[[0.0, 0.0, 0.0]], half_extents=[h], rotation=[q], radius=[rb])
    corner = m @ h
    np.testing.assert_allclose(m @ diag, [0.0, 1.0, 0.0], atol=ROUNDING)
    face = m @ [1.0, 0.0, 0.0]
    toward = face - face[1] * np.array([0.0, 1.0, 0.0])
    toward /= np.linalg.norm(toward)
    a = np.radians(angle)
    x0 = corner + R * (np.cos(a) * np.array([0.0, 1.0, 0.0]) + np.sin(a) * toward)
    expected = sa.sphere_slide(corner, R, x0, np.zeros(3), (0.0, -G, 0.0))
    t_end = expected.breaks[-1] + 0.003  # the flight soon lands on the +x face
    assert stays_outside(box, expected, r, t_end)
    run_against(box, x0, np.zeros(3), r, expected, t_end)


# -- energy -------------------------------------------------------------------------------------


@pytest.mark.parametrize("shape", ["edge", "ball"])
def test_energy_is_conserved_on_curved_slides(shape):
    """Along the slide (200 samples, with motion along the axis on the edge) the total energy
    holds to ENERGY_REL_TOL."""
    rb, r = 0.15, 0.05
    R = rb + r
    if shape == "edge":
        box = ws.RoundedBoxes(center=[[0.0, -0.5, 0.0]], half_extents=[[0.5, 0.5, 2.0]],
                              radius=[rb])
        x0 = np.array([0.5, 0.0, 0.0]) + R * np.array([np.sin(0.2), np.cos(0.2), 0.0])
        v0 = np.array([0.3 * np.cos(0.2), -0.3 * np.sin(0.2), 0.7])
        t_d = sa.cylinder_slide((0.5, 0.0, 0.0), (0.0, 0.0, 1.0), R, x0, v0,
                                (0.0, -G, 0.0)).break_of("flight")
    else:
        box = ws.RoundedBoxes(center=[[0.0, 0.0, 0.0]], half_extents=[[0.0, 0.0, 0.0]],
                              radius=[rb])
        n = np.array([0.2, 1.0, 0.1]) / np.linalg.norm([0.2, 1.0, 0.1])
        x0 = R * n
        v0 = 0.2 * np.cross(n, [0.0, 1.0, 0.0]) / np.linalg.norm(np.cross(n, [0.0, 1.0, 0.0]))
        t_d = sa.sphere_slide((0.0, 0.0, 0.0), R, x0, v0, (0.0, -G, 0.0)).break_of("flight")
    scene = ws.Scene(box)
    swarm = ws.Swarm(position=[x0], velocity=[v0], radius=r)
    times = np.linspace(0.0, t_d, 200)
    run = reference.simulate(scene, swarm, t_d, times)
    e = run.energy(scene, swarm)[:, 0]
    assert np.abs(e - e[0]).max() < ENERGY_REL_TOL * abs(e[0])
    gap = box.signed_distance(run.position[:, 0])[:, 0] - r
    np.testing.assert_allclose(gap, 0.0, atol=SURFACE_TOL)  # on the surface all along


# -- the slide's other ends ---------------------------------------------------------------------


def test_slide_on_an_edge_meets_another_box_where_the_surfaces_cross():
    """Sliding from rest down a rounded edge (rb = 0.15, r = 0.05) towards a wall whose face
    the centre reaches at 25 degrees: the first bounce is on the wall at the point of the
    cylinder at that angle, at the analytic instant."""
    rb, r = 0.15, 0.05
    R = rb + r
    stop = np.radians(25.0)
    wall_x = 0.5 + R * np.sin(stop) + r
    boxes = ws.RoundedBoxes(center=[[0.0, -0.5, 0.0], [wall_x + 0.5, 0.6, 0.0]],
                            half_extents=[[0.5, 0.5, 0.3], [0.5, 0.5, 0.5]], radius=[rb, 0.0])
    edge = np.array([0.5, 0.0, 0.0])
    t0 = np.radians(10.0)
    x0 = edge + R * np.array([np.sin(t0), np.cos(t0), 0.0])
    run = reference.simulate(ws.Scene(boxes), ws.Swarm(position=[x0], velocity=[[0, 0, 0]],
                                                       radius=r), 0.3)
    first = run.events.of_sphere(0).bounces()
    assert first.box[0] == 1
    contact = edge + R * np.array([np.sin(stop), np.cos(stop), 0.0])
    np.testing.assert_allclose(first.position[0], contact, atol=POS_TOL)
    expected = sa.cylinder_slide(edge, (0.0, 0.0, 1.0), R, x0, np.zeros(3), (0.0, -G, 0.0))
    x, _ = expected.at([first.time[0]])
    np.testing.assert_allclose(x[0], contact, atol=POS_TOL)


def test_slide_along_an_edge_onto_its_corner():
    """Released on a rounded edge moving at 1 m/s along it, the sphere passes the edge's end
    onto the corner's sphere before it leaves: energy and the surface hold through the change
    of region, and it leaves the surface beyond the edge's end."""
    rb, r = 0.15, 0.05
    R = rb + r
    h = np.array([0.5, 0.5, 0.3])
    box = ws.RoundedBoxes(center=[[0.0, -0.5, 0.0]], half_extents=[h], radius=[rb])
    t0 = np.radians(10.0)
    x0 = np.array([0.5, 0.0, 0.1]) + R * np.array([np.sin(t0), np.cos(t0), 0.0])
    scene = ws.Scene(box)
    swarm = ws.Swarm(position=[x0], velocity=[[0.0, 0.0, 1.0]], radius=r)
    times = np.linspace(0.0, 0.6, 601)
    run = reference.simulate(scene, swarm, 0.6, times)
    assert not run.incomplete.any() and not len(run.events.of_sphere(0).bounces())
    e = run.energy(scene, swarm)[:, 0]
    assert np.abs(e - e[0]).max() < ENERGY_REL_TOL * abs(e[0])
    gap = box.signed_distance(run.position[:, 0])[:, 0] - r
    off = np.flatnonzero(gap > LIFT_GAP)[0]
    assert np.abs(gap[:off]).max() < SURFACE_TOL  # on the surface until it leaves
    assert run.position[off, 0, 2] > h[2]  # on the corner by then
