"""Arcs that enter the grown box through an edge region, pass the rounded edge and land on a face.

The ballistic sweep walks such an arc piece by piece (``kernels/arc.py``): an edge piece (a
quartic, no root: the arc passes the rounded edge) and then a face piece, where the face gap
``q(s) = c0 + c1 s + c2 s^2`` has two roots and the *falling* one is the contact. Every case is
one base arc (box ``h = (5, 1, 1)``, ``R = 0.1``, start ``(-5.2, 1, 0)``, ``v = (5, 5, 0)``, for
1.2 s) under all six permutations of the axes and both sides of the face, so every face of the
box is reached, from every neighbouring edge.

The answer is analytic: the contact is the larger root of ``q`` (gravity towards the face makes
``c2 < 0``; the smaller root is where the arc rose through the face's plane, over the edge).
With gravity pointing away from the face (``c2 > 0``) the arc cannot come back to a face it
passed over: it must miss. (A falling root with ``c2 > 0`` cannot follow an edge region at all:
at the grown-box entry every face gap is <= 0, so a gap that later rises above 0 and falls again
is concave.)
"""

from itertools import permutations

import numpy as np
import pytest
from arc_reference import arc_point, signed_distance

import warpsim as ws

H = np.array([5.0, 1.0, 1.0])
RB, R_SPHERE = 0.04, 0.06  # Minkowski radius 0.1
BIG_R = RB + R_SPHERE
A = np.array([-5.2, 1.0, 0.0])
V = np.array([5.0, 5.0, 0.0])
GRAVITY = np.array([0.0, -9.81, 0.0])
TAU = 1.2
FACE = 1  # the base arc lands on the +y face

#: Contact time agreement per precision: a few ulps of the frame (the root is closed-form).
S_TOL = {"float32": 2e-6, "float64": 1e-13}

CASES = [(perm, side) for perm in permutations(range(3)) for side in (1.0, -1.0)]


def posed(perm, side, gravity_sign=1.0):
    """The base arc with its axes permuted (new axis ``perm[i]`` carries old axis ``i``) and
    the face axis mirrored by ``side``; ``gravity_sign = -1`` turns gravity away from the face.

    Returns:
        ``(h, a, v, g, axis)``: the box, the arc and the axis of the face it reaches.
    """
    axis = perm[FACE]

    def move(x, mirror=True):
        out = np.empty(3)
        out[list(perm)] = x
        if mirror:
            out[axis] *= side
        return out

    return move(H, mirror=False), move(A), move(V), gravity_sign * move(GRAVITY), axis


def falling_root(a, v, g, h, axis, side):
    """The later root of ``side x_axis(s) = h_axis + R`` (float64, cancellation-free form)."""
    c0 = side * a[axis] - h[axis] - BIG_R
    c1 = side * v[axis]
    c2 = 0.5 * side * g[axis]
    disc = c1 * c1 - 4.0 * c2 * c0
    q = -0.5 * (c1 + np.copysign(np.sqrt(disc), c1))
    return max(q / c2, c0 / q)


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("perm,side", CASES, ids=[f"{p}{'+-'[s < 0]}" for p, s in CASES])
def test_lands_on_the_face_after_the_edge(perm, side, precision):
    h, a, v, g, axis = posed(perm, side)
    box = ws.RoundedBox(half_extents=h, radius=RB)
    s_star = falling_root(a, v, g, h, axis, side)
    # the construction: the grown-box entry is in an edge region, the arc stays outside the
    # rounded box until s_star (dense float64 samples), and lands on the face's rectangle
    s = np.linspace(0.0, s_star, 20001)[:-1]
    x = arc_point(a, v, g, s)
    inside_grown = np.all(np.abs(x) <= h + BIG_R, axis=1)
    entry = x[np.argmax(inside_grown)]
    assert inside_grown.any() and np.sum(np.abs(entry) > h) == 2
    assert signed_distance(x, h, BIG_R).min() > 0.0
    contact = arc_point(a, v, g, s_star)
    assert np.all(np.abs(np.delete(contact, axis)) < np.delete(h, axis))

    c = ws.collide_box([a], [v], R_SPHERE, box, TAU, precision=precision, motion="ballistic",
                       gravity=g)
    assert c.hit[0]
    assert c.t[0] * TAU == pytest.approx(s_star, abs=S_TOL[precision])
    expected_normal = np.zeros(3)
    expected_normal[axis] = side
    np.testing.assert_array_equal(c.normal[0], expected_normal)
    np.testing.assert_allclose(c.position[0], contact, atol=10 * S_TOL[precision])


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("perm,side", CASES, ids=[f"{p}{'+-'[s < 0]}" for p, s in CASES])
def test_gravity_away_from_the_face_misses(perm, side, precision):
    """The same arcs with gravity reversed (``c2 > 0`` on that face): they pass the edge and
    leave; the face gap's roots both lie before the face piece, so neither is a contact."""
    h, a, v, g, axis = posed(perm, side, gravity_sign=-1.0)
    s = np.linspace(0.0, TAU, 20001)
    assert signed_distance(arc_point(a, v, g, s), h, BIG_R).min() > 0.0
    c = ws.collide_box([a], [v], R_SPHERE, ws.RoundedBox(half_extents=h, radius=RB), TAU,
                       precision=precision, motion="ballistic", gravity=g)
    assert not c.hit[0] and c.t[0] == 1.0
