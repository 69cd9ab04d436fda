"""Tests of the float64 sweep references themselves (``reference.py``).

Analytic cases first (exact binary fractions where the geometry allows), then the two
independent methods against each other: the 26-feature enumeration (primary) and the
signed-distance root search (secondary), on random boxes and segments.
"""

import math

import numpy as np
import pytest
from helpers import exact_entry, far_passes, textbook_entry
from hypothesis import given, settings
from hypothesis import strategies as st
from reference import (
    AMBIGUOUS,
    HIT,
    MISS,
    bounce_reference,
    nearest_reference,
    reflect_reference,
    sweep_by_distance,
    sweep_reference,
    sweep_reference_batch,
)

import warpsim as ws

I = (0.0, 0.0, 0.0, 1.0)  # noqa: E741  (identity quaternion)
ORIGIN = (0.0, 0.0, 0.0)
CUBE = (1.0, 1.0, 1.0)
SQ3 = math.sqrt(1.0 / 3.0)

#: Agreement of the two reference methods: contact centres [m] (bisection to ~1e-16 in t,
#: entries no shallower than SHALLOW_ENTRY) and normals (a central difference of step 1e-7
#: across a face/cylinder seam errs by ~step / R, with R >= 0.01 here).
POS_TOL = 1e-8
NORMAL_TOL = 1e-4

# name, (a, b, center, half_extents, rotation, rb, r), (hit, t, normal)
CASES = [
    ("face", ((3.0, 0.0, 0.0), (-1.0, 0.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (True, 0.375, (1.0, 0.0, 0.0))),
    ("face-offset", ((0.75, -0.5, 3.0), (0.75, -0.5, -1.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (True, 0.375, (0.0, 0.0, 1.0))),
    ("face-from-below", ((0.0, -3.0, 0.0), (0.0, 1.0, 0.0), ORIGIN, CUBE, I, 0.5, 0.0),
     (True, 0.375, (0.0, -1.0, 0.0))),
    # Corner sphere at (1, 1, 1) on the diagonal: contact where |p - corner| = R.
    ("corner", ((3.0, 3.0, 3.0), (-1.0, -1.0, -1.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (True, 0.5 - 0.5 / (4.0 * math.sqrt(3.0)), (SQ3, SQ3, SQ3))),
    ("miss-beside", ((3.0, 2.0, 0.0), (-3.0, 2.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (False, 1.0, (0.0, 0.0, 0.0))),
    ("short-of-box", ((3.0, 0.0, 0.0), (2.0, 0.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (False, 1.0, (0.0, 0.0, 0.0))),
    ("moving-away", ((3.0, 0.0, 0.0), (5.0, 0.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (False, 1.0, (0.0, 0.0, 0.0))),
    ("translated", ((13.0, -2.0, 5.0), (9.0, -2.0, 5.0), (10.0, -2.0, 5.0), CUBE, I, 0.25, 0.25),
     (True, 0.375, (1.0, 0.0, 0.0))),
    # Tangent paths touch without going in: no hit.
    ("tangent-face", ((3.0, 1.5, 0.0), (-3.0, 1.5, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (False, 1.0, (0.0, 0.0, 0.0))),
    ("tangent-ball", ((-2.0, 0.5, 0.0), (2.0, 0.5, 0.0), ORIGIN, ORIGIN, I, 0.5, 0.0),
     (False, 1.0, (0.0, 0.0, 0.0))),
    # Start on or inside: a hit at t = 0 only when moving in (normal at the start).
    ("start-shell-in", ((1.25, 0.0, 0.0), (0.25, 0.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (True, 0.0, (1.0, 0.0, 0.0))),
    ("start-shell-out", ((1.25, 0.0, 0.0), (2.25, 0.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (False, 1.0, (0.0, 0.0, 0.0))),
    ("start-shell-along", ((1.25, 0.0, 0.0), (1.25, 1.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (False, 1.0, (0.0, 0.0, 0.0))),
    ("start-on-surface-in", ((1.5, 0.0, 0.0), (0.5, 0.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (True, 0.0, (1.0, 0.0, 0.0))),
    # Start in the edge shell: the normal points from the core edge.
    ("start-edge-shell-in", ((1.25, 1.25, 0.0), (0.25, 0.25, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (True, 0.0, (math.sqrt(0.5), math.sqrt(0.5), 0.0))),
    # Deep inside the core: the nearest core face (x at depth 0.5) gives the normal.
    ("start-deep-deeper", ((0.5, 0.125, 0.0), (0.25, 0.125, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (True, 0.0, (1.0, 0.0, 0.0))),
    ("start-deep-out", ((0.5, 0.125, 0.0), (0.75, 0.125, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (False, 1.0, (0.0, 0.0, 0.0))),
    # At the centre every face is nearest: the lower axis, + side.
    ("start-centre-tie", (ORIGIN, (-1.0, 0.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (True, 0.0, (1.0, 0.0, 0.0))),
    ("start-centre-tie-out", (ORIGIN, (0.0, -1.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (False, 1.0, (0.0, 0.0, 0.0))),
    ("zero-length-inside", ((0.5, 0.0, 0.0), (0.5, 0.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (False, 1.0, (0.0, 0.0, 0.0))),
    ("zero-length-outside", ((3.0, 0.0, 0.0), (3.0, 0.0, 0.0), ORIGIN, CUBE, I, 0.25, 0.25),
     (False, 1.0, (0.0, 0.0, 0.0))),
    # R = 0: a point against a sharp box; closed face rectangles only.
    ("sharp-face", ((0.0, 2.0, 0.0), (0.0, -2.0, 0.0), ORIGIN, (1.0, 0.5, 0.25), I, 0.0, 0.0),
     (True, 0.375, (0.0, 1.0, 0.0))),
    # Edge and corner of a sharp box: the planes meet there at the same t; exact tie -> lower axis.
    ("sharp-edge", ((3.0, 2.0, 0.0), (-1.0, 0.0, 0.0), ORIGIN, CUBE, I, 0.0, 0.0),
     (True, 0.5, (1.0, 0.0, 0.0))),
    ("sharp-edge-yz", ((0.0, 3.0, 2.0), (0.0, -1.0, 0.0), ORIGIN, CUBE, I, 0.0, 0.0),
     (True, 0.5, (0.0, 1.0, 0.0))),
    ("sharp-corner", ((2.0, 2.0, 2.0), ORIGIN, ORIGIN, CUBE, I, 0.0, 0.0),
     (True, 0.5, (1.0, 0.0, 0.0))),
    # Sliding in the plane of the top face onto the box: the closed side face is entered at
    # the edge (the top face is only grazed).
    ("sharp-slide-onto-edge", ((3.0, 1.0, 0.0), (-3.0, 1.0, 0.0), ORIGIN, CUBE, I, 0.0, 0.0),
     (True, 1.0 / 3.0, (1.0, 0.0, 0.0))),
    ("sharp-start-on-face-along", ((0.0, 1.0, 0.0), (0.5, 1.0, 0.0), ORIGIN, CUBE, I, 0.0, 0.0),
     (False, 1.0, (0.0, 0.0, 0.0))),
    ("sharp-start-on-face-in", ((0.0, 1.0, 0.0), (0.0, 0.5, 0.0), ORIGIN, CUBE, I, 0.0, 0.0),
     (True, 0.0, (0.0, 1.0, 0.0))),
    # Degenerate boxes: zero half extents are plates, sticks and points.
    ("ball", ((2.0, 0.3, 0.0), (-2.0, 0.3, 0.0), ORIGIN, ORIGIN, I, 0.25, 0.25),
     (True, 0.4, (0.8, 0.6, 0.0))),
    ("plate-down", ((0.5, 1.0, 0.25), (0.5, -1.0, 0.25), ORIGIN, (1.0, 0.0, 1.0), I, 0.0, 0.0),
     (True, 0.5, (0.0, 1.0, 0.0))),
    ("plate-up", ((0.5, -1.0, 0.25), (0.5, 1.0, 0.25), ORIGIN, (1.0, 0.0, 1.0), I, 0.0, 0.0),
     (True, 0.5, (0.0, -1.0, 0.0))),
    ("plate-x-from-below", ((-1.0, 0.25, 0.5), (1.0, 0.25, 0.5), ORIGIN, (0.0, 1.0, 1.0), I,
                            0.0, 0.0), (True, 0.5, (-1.0, 0.0, 0.0))),
    ("plate-rim", ((3.0, 0.0, 0.5), (-1.0, 0.0, 0.5), ORIGIN, (1.0, 0.0, 1.0), I, 0.0, 0.0),
     (True, 0.5, (1.0, 0.0, 0.0))),
    ("plate-miss-beside", ((1.5, 1.0, 0.0), (1.5, -1.0, 0.0), ORIGIN, (1.0, 0.0, 1.0), I,
                           0.0, 0.0), (False, 1.0, (0.0, 0.0, 0.0))),
    ("rounded-plate", ((0.5, 1.0, 0.25), (0.5, -1.0, 0.25), ORIGIN, (1.0, 0.0, 1.0), I,
                       0.125, 0.125), (True, 0.375, (0.0, 1.0, 0.0))),
    ("stick-side", ((1.0, 0.0, 0.5), (-1.0, 0.0, 0.5), ORIGIN, (0.0, 0.0, 1.0), I, 0.0, 0.25),
     (True, 0.375, (1.0, 0.0, 0.0))),
    ("stick-end", ((0.0, 0.0, 2.0), ORIGIN, ORIGIN, (0.0, 0.0, 1.0), I, 0.125, 0.125),
     (True, 0.375, (0.0, 0.0, 1.0))),
    ("point-through", ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), ORIGIN, ORIGIN, I, 0.0, 0.0),
     (True, 0.5, (1.0, 0.0, 0.0))),
    ("point-beside", ((1.0, 0.25, 0.0), (-1.0, 0.25, 0.0), ORIGIN, ORIGIN, I, 0.0, 0.0),
     (False, 1.0, (0.0, 0.0, 0.0))),
]


@pytest.mark.parametrize("args, expected", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_named_case(args, expected):
    hit, t, normal = expected
    got = sweep_reference(*args)
    assert got.hit == hit
    assert got.t == pytest.approx(t, abs=1e-15)
    np.testing.assert_allclose(got.normal, normal, atol=1e-15)
    a, b = np.asarray(args[0]), np.asarray(args[1])
    np.testing.assert_allclose(got.contact, a + t * (b - a) if hit else b, atol=1e-15)
    batch = sweep_reference_batch(*args)
    assert batch.hit[0] == hit
    np.testing.assert_allclose(batch.t[0], t, atol=1e-15)
    np.testing.assert_allclose(batch.normal[0], normal, atol=1e-15)


def test_edge_cylinder_by_hand():
    """Edge along z at (1, 1) of the unit cube, R = 0.5. Built backwards: contact centre
    (1, 1, 0.25) + 0.5 (0.6, 0.8, 0) at t = 1/4 for d = (-4, -4, 0). In the plane
    |(1.3, 1.4) + t (-4, -4)|^2 = 0.25 gives 32 t^2 - 21.6 t + 3.4 = 0, roots 1/4 and 0.425;
    the x face plane (x = 1.5) is crossed earlier at t = 0.2 with y = 1.6 > 1: outside its
    rectangle."""
    a = (2.3, 2.4, 0.25)
    got = sweep_reference(a, (-1.7, -1.6, 0.25), ORIGIN, CUBE, I, 0.25, 0.25)
    assert got.hit
    assert got.t == pytest.approx(0.25, abs=1e-14)
    np.testing.assert_allclose(got.normal, (0.6, 0.8, 0.0), atol=1e-14)
    np.testing.assert_allclose(got.contact, (1.3, 1.4, 0.25), atol=1e-14)


def test_rotated_box_face():
    """A box turned 45 degrees about z, placed off the origin: the segment along its local -x
    axis meets the local +x face (sharp box: plane at h_x = 1) half way."""
    s, c = math.sin(math.pi / 8), math.cos(math.pi / 8)
    q = (0.0, 0.0, s, c)
    u = np.array([math.sqrt(0.5), math.sqrt(0.5), 0.0])  # local x in the world
    center = np.array([10.0, -2.0, 3.0])
    got = sweep_reference(center + 3.0 * u, center - u, center, (1.0, 0.5, 0.5), q, 0.0, 0.0)
    assert got.hit
    assert got.t == pytest.approx(0.5, abs=1e-14)
    np.testing.assert_allclose(got.normal, u, atol=1e-14)
    np.testing.assert_allclose(got.contact, center + u, atol=1e-13)


@pytest.mark.parametrize("feature", ["ball", "edge"])
@pytest.mark.parametrize("distance, big_r", [(1.0e6, 0.01), (1.0e7, 0.1)])
def test_far_passes_agree_with_the_exact_root(feature, distance, big_r):
    """Passes by a corner ball (a point box) and by an edge cylinder from 1000 and 10 000 km,
    through the feature (from 3 % of ``R`` inside) and just beside it, the box at the origin
    and at 1e4: both forms of the reference give the verdict and ``t`` of the exact rational
    root to a few ulps, where the textbook ``b^2 - a c`` discriminant, whose error ``eps |w|^2
    |d|^2`` is above ``|d|^2 R^2`` here, gets each row wrong."""
    from fractions import Fraction

    t_tol = 16 * float(np.finfo(np.float64).eps)
    for shift in (0.0, 1.0e4):
        for row in far_passes(feature, distance, big_r, np.float64):
            center = np.full(3, shift)
            a = row["a"] + center
            b = a + row["d"]
            across = row["across"]
            motion = [Fraction(float(b[i])) - Fraction(float(a[i])) for i in across]
            start = [Fraction(float(a[i])) - Fraction(shift) for i in across]
            hit, t = exact_entry(start, motion, row["axis_point"], big_r)
            for got in (sweep_reference(a, b, center, row["h"], I, big_r, 0.0),
                        sweep_reference(a, b, center, row["h"], I, 0.5 * big_r, 0.5 * big_r)):
                assert got.hit == hit, row["name"]
                assert got.t == pytest.approx(t, abs=t_tol), row["name"]
            batch = sweep_reference_batch(a, b, center, row["h"], I, big_r, 0.0)
            assert batch.hit[0] == hit and batch.t[0] == pytest.approx(t, abs=t_tol)
            textbook_hit, textbook_t = textbook_entry(row["a"][across], row["d"][across],
                                                      row["axis_point"], big_r, np.float64)
            assert textbook_hit != hit or abs(textbook_t - t) > 10 * t_tol, row["name"]


#: Cases decided on an exact tie or an exact tangency: once rotated, rounding of the local
#: coordinates decides them (either answer is right), so they stay out of the rigid-motion test.
ROUNDING_DECIDED = {"tangent-face", "tangent-ball", "start-shell-along", "start-centre-tie",
                    "start-centre-tie-out", "sharp-edge", "sharp-edge-yz", "sharp-corner",
                    "sharp-slide-onto-edge", "sharp-start-on-face-along", "plate-rim",
                    "point-through"}


@pytest.mark.slow
@settings(max_examples=100, deadline=None)
@given(quat=st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(lambda q: np.linalg.norm(q) > 0.1),
       shift=st.tuples(*[st.floats(-50.0, 50.0)] * 3),
       case=st.sampled_from([c for c in CASES if c[0] not in ROUNDING_DECIDED]))
def test_rigid_motion_moves_the_answer(quat, shift, case):
    """Rotating and translating box and segment together keeps t and rotates the normal."""
    a, b, center, h, _, rb, r = case[1]
    hit, t, normal = case[2]
    m = ws.obstacles.quat_to_matrix(np.asarray(quat) / np.linalg.norm(quat))
    shift = np.asarray(shift)
    got = sweep_reference(m @ a + shift, m @ b + shift, m @ center + shift, h, quat, rb, r)
    scale = 1.0 + np.abs(shift).max()
    assert got.hit == hit
    assert got.t == pytest.approx(t, abs=1e-13 * scale)
    np.testing.assert_allclose(got.normal, m @ np.asarray(normal), atol=1e-12 * scale)


def test_nearest_over_boxes_and_ties():
    boxes = ws.RoundedBoxes(center=[(5.0, 0.0, 0.0), (-5.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                    (0.0, 0.0, 0.0)],
                            half_extents=[CUBE, CUBE, (0.5, 0.5, 0.5), (0.5, 0.5, 0.5)],
                            radius=[0.0, 0.0, 0.0, 0.0])
    # Box 0's face plane x = 6.5 is reached first (t = 1.5 / 16), before boxes 2, 3 and 1.
    hit, t, k, n, contact = nearest_reference((8.0, 0.0, 0.0), (-8.0, 0.0, 0.0), boxes, 0.5)
    assert (hit, t, k) == (True, 0.09375, 0)
    np.testing.assert_array_equal(n, (1.0, 0.0, 0.0))
    np.testing.assert_array_equal(contact, (6.5, 0.0, 0.0))
    # Boxes 2 and 3 are identical: the tie goes to the lower index.
    hit, t, k, n, _ = nearest_reference((0.0, 4.0, 0.0), (0.0, 0.0, 0.0), boxes, 0.5)
    assert (hit, t, k) == (True, 0.75, 2)
    np.testing.assert_array_equal(n, (0.0, 1.0, 0.0))
    hit, t, k, n, contact = nearest_reference((0.0, 4.0, 0.0), (0.0, 3.0, 0.0), boxes, 0.5)
    assert (hit, t, k) == (False, 1.0, -1)
    np.testing.assert_array_equal(n, (0.0, 0.0, 0.0))
    np.testing.assert_array_equal(contact, (0.0, 3.0, 0.0))


def test_bounce_reference_reflects_and_keeps_the_path_length():
    boxes = ws.RoundedBoxes(center=[ORIGIN], half_extents=[CUBE], radius=[0.25])
    position = np.array([[3.0, 0.0, 0.0], [3.0, 5.0, 0.0]])
    velocity = np.array([[-4.0, 2.0, 0.0], [-4.0, 0.0, 0.0]])
    out = bounce_reference(position, velocity, 0.25, boxes, 1.0)
    np.testing.assert_array_equal(out["hit"], [True, False])
    np.testing.assert_array_equal(out["box"], [0, -1])
    np.testing.assert_array_equal(out["t"], [0.375, 1.0])
    np.testing.assert_array_equal(out["position"], [[1.5, 0.75, 0.0], [-1.0, 5.0, 0.0]])
    np.testing.assert_array_equal(out["normal"], [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_array_equal(out["new_velocity"], [[4.0, 2.0, 0.0], [-4.0, 0.0, 0.0]])
    np.testing.assert_array_equal(out["new_position"], [[4.0, 2.0, 0.0], [-1.0, 5.0, 0.0]])
    travelled = (np.linalg.norm(out["position"][0] - position[0])
                 + np.linalg.norm(out["new_position"][0] - out["position"][0]))
    assert travelled == pytest.approx(np.linalg.norm(velocity[0]))
    np.testing.assert_array_equal(reflect_reference((1.0, -2.0, 3.0), (0.0, 1.0, 0.0)),
                                  (1.0, 2.0, 3.0))


# --- The two methods against each other -----------------------------------------------------

half = st.one_of(st.just(0.0), st.floats(0.05, 1.0))
rounding = st.one_of(st.just(0.0), st.floats(0.01, 0.5))
coord = st.floats(-3.0, 3.0)


point = st.tuples(coord, coord, coord)


@pytest.mark.slow
@settings(max_examples=120, deadline=None)
@given(h=st.tuples(half, half, half),
       quat=st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(lambda q: np.linalg.norm(q) > 0.1),
       center=st.tuples(*[st.floats(-2.0, 2.0)] * 3),
       rb=rounding, r=rounding,
       segments=st.lists(st.tuples(point, point), min_size=1, max_size=16))
def test_feature_enumeration_agrees_with_distance_search(h, quat, center, rb, r, segments):
    """Primary and secondary agree wherever the secondary is decided.

    Left out (``AMBIGUOUS``): paths whose minimum signed distance lies within NEAR_GRAZE of 0
    (a tangent touch is no hit for the primary by the sign of a discriminant or of ``d . n``,
    while the distance search sees ``f = 0`` up to rounding: the verdict rests on the last ulp;
    this includes every hit on a sharp plate or stick, whose solid has no interior), entries
    shallower than SHALLOW_ENTRY (the root moves by ``eps / slope``), and starts whose
    direction sits on a kink of the distance (the contract's tie rules pick a side there).
    """
    a = np.asarray(center) + np.array([s[0] for s in segments])
    b = np.asarray(center) + np.array([s[1] for s in segments])
    primary = sweep_reference_batch(a, b, center, h, quat, rb, r)
    secondary = sweep_by_distance(a, b, center, h, quat, rb, r)
    decided = secondary.status != AMBIGUOUS
    np.testing.assert_array_equal(primary.hit[decided], secondary.status[decided] == HIT)
    np.testing.assert_array_equal(~primary.hit[decided], secondary.status[decided] == MISS)
    both = decided & primary.hit
    contact = a + secondary.t[:, None] * (b - a)
    np.testing.assert_allclose(primary.contact[both], contact[both], atol=POS_TOL)
    np.testing.assert_allclose(primary.normal[both], secondary.normal[both], atol=NORMAL_TOL)


@pytest.mark.slow
def test_methods_agree_on_random_batches():
    """Seeded batches: 40 random boxes (zero extents, sharp and rounded, any rotation), 1000
    segments each, a fifth of them starting near or inside the box."""
    rng = np.random.default_rng(20240601)
    decided_total = hits_total = 0
    for _ in range(40):
        h = rng.uniform(0.0, 1.0, 3) * (rng.uniform(size=3) > 0.25)
        quat = rng.normal(size=4)
        center = rng.uniform(-2.0, 2.0, 3)
        rb = rng.choice([0.0, 0.2, rng.uniform(0.01, 0.5)])
        r = rng.choice([0.0, 0.3, rng.uniform(0.01, 0.5)])
        n = 1000
        a = center + rng.uniform(-3.0, 3.0, (n, 3))
        a[:200] = center + rng.uniform(-1.2, 1.2, (200, 3))
        b = center + rng.uniform(-1.5, 1.5, (n, 3))
        primary = sweep_reference_batch(a, b, center, h, quat, rb, r)
        secondary = sweep_by_distance(a, b, center, h, quat, rb, r)
        decided = secondary.status != AMBIGUOUS
        np.testing.assert_array_equal(primary.hit[decided], secondary.status[decided] == HIT)
        both = decided & primary.hit
        contact = a + secondary.t[:, None] * (b - a)
        np.testing.assert_allclose(primary.contact[both], contact[both], atol=POS_TOL)
        np.testing.assert_allclose(primary.normal[both], secondary.normal[both],
                                   atol=NORMAL_TOL)
        decided_total += decided.sum()
        hits_total += both.sum()
    assert decided_total > 0.98 * 40 * 1000  # the filter leaves out only the rare cases
    # and the test is not about misses only: a fifth at least (9853 hits of 40 000 with the
    # seed salted by 1111, about a quarter as a rule)
    assert hits_total > 0.2 * 40 * 1000


@pytest.mark.slow
def test_scalar_and_batch_forms_agree():
    rng = np.random.default_rng(7)
    for _ in range(10):
        h = rng.uniform(0.0, 1.0, 3) * (rng.uniform(size=3) > 0.25)
        quat, center = rng.normal(size=4), rng.uniform(-1.0, 1.0, 3)
        rb, r = rng.choice([0.0, 0.2]), rng.choice([0.0, 0.3])
        a = center + rng.uniform(-3.0, 3.0, (100, 3))
        b = center + rng.uniform(-1.5, 1.5, (100, 3))
        batch = sweep_reference_batch(a, b, center, h, quat, rb, r)
        for k in range(100):
            one = sweep_reference(a[k], b[k], center, h, quat, rb, r)
            assert one.hit == batch.hit[k]
            assert one.t == pytest.approx(batch.t[k], abs=1e-12)
            np.testing.assert_allclose(one.normal, batch.normal[k], atol=1e-12)
