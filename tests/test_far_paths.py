"""Paths that start far from the feature they meet: no digits lost on the way (both precisions).

Every case is built backwards from a chosen point ``P`` on the Minkowski surface (a face, an
edge cylinder or a corner sphere of the rounded box of radius ``R = rb + r``) with its outward
normal ``n``, in the box's frame, then placed in the world by a random pose:

* *aimed inside*: the path passes through ``P - f R n``, a point ``f R`` deep inside (the inner
  parallel body of a rounded box is the rounded box of radius ``R - f R``), along a tangent of
  the surface at ``P``: it must hit, and its contact centre must lie on the surface;
* *aimed outside*: through ``P + f R n`` along that tangent: the whole path stays at least
  ``f R`` outside the tangent plane, so outside the convex body: it must miss;
* *entering at P*: the path reaches ``P`` going in (``d . n < 0``); everything before ``P`` lies
  outside the supporting plane at ``P``, so the first contact is exactly ``P`` (analytic).

The start lies ``L`` away, swept log-uniformly over ``1 m .. 1e5 m`` (float32) and further in
float64, as far as the precision represents the path: the rounding of the start, ``eps L`` per
coordinate, must stay a small part (``1 / REPRESENTABLE``) of the aim ``f R``. Contacts are
checked against the float64 signed distance of ``tests/reference.py`` (its own quaternion
rotation), to a few ulps of the coordinates. ``collide_box``, ``collide_boxes`` and ``bounce``
are covered, chords and arcs.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import examples
from hypothesis import given, settings
from hypothesis import strategies as st
from reference import core_distance_and_normal, rounded_box_sdf

import warpsim as ws

#: The aim, as a fraction of the Minkowski radius ``R``: inside or outside by ``F_AIM R``.
F_AIM = 0.25

#: A path is representable when ``REPRESENTABLE * eps * L <= F_AIM * R``: the start's rounding
#: (half an ulp of ``L`` per coordinate) and the sweep's own (a few ulps) are then far below the
#: aim. The cancelling discriminant ``b^2 - a c`` needed ``eps L^2 / R`` below the aim instead.
REPRESENTABLE = 64.0

#: Contact centres lie on the surface to this many ulps of the largest coordinate (the rounding
#: of ``A + t d`` and of ``t``; an arc adds its root tolerance, 4 ulps of the frame's time).
SURFACE_ULPS = {"linear": 8.0, "ballistic": 24.0}

#: Largest start distance [m] swept per precision: float32 to 1e5 m, float64 to 1e9 m.
MAX_DISTANCE = {"float32": 1e5, "float64": 1e9}

G = 9.81  # [m/s^2], the size of the random gravity of the arcs
BATCH = 96


def eps_of(precision: str) -> float:
    return float(np.finfo(np.float32 if precision == "float32" else np.float64).eps)


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors (N, 3) by the unit quaternion ``q = (x, y, z, w)`` (local -> world)."""
    u, w = q[:3], q[3]
    uv = np.cross(u, v)
    return v + 2.0 * w * uv + 2.0 * np.cross(u, uv)


def as_precision(x, precision):
    """``x`` rounded to the precision, back in float64 (the kernel sees exactly these)."""
    dtype = np.float32 if precision == "float32" else np.float64
    return np.asarray(x, np.float64).astype(dtype).astype(np.float64)


def feature_points(rng, h, radius, count):
    """Points on the Minkowski surface (local frame) and their outward normals, a third each on
    faces, edge cylinders and corner spheres, each inside its feature's Voronoi region."""
    points = np.empty((count, 3))
    normals = np.zeros((count, 3))
    for k in range(count):
        signs = rng.choice([-1.0, 1.0], 3)
        core = rng.uniform(-1.0, 1.0, 3) * h
        n = np.zeros(3)
        kind = k % 3
        if kind == 0:  # face
            axis = rng.integers(3)
            n[axis] = signs[axis]
            core[axis] = signs[axis] * h[axis]
        elif kind == 1:  # edge along axis m
            m = rng.integers(3)
            i, j = [x for x in range(3) if x != m]
            angle = rng.uniform(0.05, 0.5 * np.pi - 0.05)
            n[i], n[j] = signs[i] * np.cos(angle), signs[j] * np.sin(angle)
            core[i], core[j] = signs[i] * h[i], signs[j] * h[j]
        else:  # corner
            n = signs * rng.uniform(0.1, 1.0, 3)
            n /= np.linalg.norm(n)
            core = signs * h
        points[k] = core + radius * n
        normals[k] = n
    return points, normals


def tangents(rng, normals):
    """Random unit vectors perpendicular to each normal."""
    t = rng.normal(size=normals.shape)
    t -= np.einsum("ij,ij->i", t, normals)[:, None] * normals
    return t / np.linalg.norm(t, axis=1)[:, None]


@st.composite
def far_scenes(draw):
    """One posed rounded box, a sphere radius, a precision and a batch of feature points."""
    precision = draw(st.sampled_from(["float32", "float64"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    h = rng.uniform(0.0, 2.0, 3) * (rng.random(3) > 0.2)  # some zero extents: plates, sticks
    rb = float(draw(st.sampled_from([0.0, 0.02, 0.3])))
    r = float(draw(st.sampled_from([0.01, 0.06, 1.0, 4.0])))
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    center = as_precision(rng.uniform(-20.0, 20.0, 3), precision)
    box = ws.RoundedBox(center=center, half_extents=as_precision(h, precision), rotation=q,
                        radius=float(as_precision(rb, precision)))
    big_r = box.radius + float(as_precision(r, precision))
    # the start distances: log-uniform up to what the precision represents for this R
    top = min(MAX_DISTANCE[precision], F_AIM * big_r / (REPRESENTABLE * eps_of(precision)))
    distance = 10.0 ** rng.uniform(0.0, np.log10(top), BATCH)
    p_local, n_local = feature_points(rng, box.half_extents, big_r, BATCH)
    t_local = tangents(rng, n_local)
    world = {"P": center + rotate(q, p_local), "n": rotate(q, n_local), "t": rotate(q, t_local)}
    return precision, box, float(as_precision(r, precision)), distance, world, rng


def surface_distance(box, big_r, x):
    """Float64 signed distance of world points to the Minkowski surface [m]."""
    return rounded_box_sdf(x, box.center, box.half_extents, box.rotation, big_r)


def world_normal(box, x):
    """Float64 outward normal of the rounded box at world points ``x`` (N, 3)."""
    local = rotate(box.rotation * np.array([-1.0, -1.0, -1.0, 1.0]), x - box.center)
    return rotate(box.rotation, core_distance_and_normal(local, box.half_extents)[1])


def ulps(precision, *coords):
    """One ulp [m] of the largest coordinate among ``coords`` (arrays (N, 3)), per row."""
    size = np.max([np.abs(c).max(axis=1) for c in coords], axis=0)
    return eps_of(precision) * np.maximum(size, 1.0)


# --- chords ----------------------------------------------------------------------------------

@settings(max_examples=examples(30), deadline=None)
@given(scene=far_scenes())
def test_chords_aimed_inside_hit_and_outside_miss(scene):
    """Through ``P -+ f R n`` along a tangent, from ``L`` away to ``L`` beyond: every inside
    path hits before it passes ``P`` with its contact centre on the surface and the normal of
    the surface there; every outside path misses."""
    precision, box, r, distance, w, _ = scene
    big_r = box.radius + r
    depth = F_AIM * big_r
    for sign, expect_hit in ((-1.0, True), (1.0, False)):
        mid = w["P"] + sign * depth * w["n"]
        a = as_precision(mid - distance[:, None] * w["t"], precision)
        v = as_precision(2.0 * distance[:, None] * w["t"], precision)
        keep = surface_distance(box, big_r, a) > 0.0  # short paths along a big face start in it
        a, v = a[keep], v[keep]
        c = ws.collide_box(a, v, r, box, 1.0, precision=precision)
        assert np.all(c.hit == expect_hit), (precision, distance[keep][c.hit != expect_hit])
        if not expect_hit:
            assert np.all(c.t == 1.0)
            continue
        x = c.position.astype(np.float64)
        ulp = ulps(precision, a, a + v)
        assert np.all(np.abs(surface_distance(box, big_r, x)) <= SURFACE_ULPS["linear"] * ulp)
        # on the path, before its deepest point (t = 1/2)
        t = c.t.astype(np.float64)
        np.testing.assert_array_less(t, 0.5)
        off_path = np.linalg.norm(x - (a + t[:, None] * v), axis=1)
        assert np.all(off_path <= SURFACE_ULPS["linear"] * ulp)
        # the normal of the surface at the contact centre; near the seam of two features (a
        # cylinder and its end sphere, a face and its edge) a contact within ``delta`` of the
        # surface may take the other feature's normal, up to ``sqrt(2 delta / R)`` apart
        n_ref = world_normal(box, x)
        angle = np.linalg.norm(c.normal - n_ref, axis=1)
        assert np.all(angle <= 2e-3 + np.sqrt(2.0 * SURFACE_ULPS["linear"] * ulp / big_r))
        assert np.all(np.einsum("ij,ij->i", v, c.normal) < 0.0)


def entering_directions(rng, w):
    """Unit directions entering at ``P``: ``d . n = -cos`` with ``cos`` in [0.2, 1]."""
    cos = rng.uniform(0.2, 1.0, len(w["n"]))
    d = -cos[:, None] * w["n"] + np.sqrt(1.0 - cos * cos)[:, None] * w["t"]
    return d, cos


@settings(max_examples=examples(30), deadline=None)
@given(scene=far_scenes())
def test_chords_entering_at_a_chosen_contact(scene):
    """``A = P - L d``, ``B = P + R d / 2`` with ``d . n < 0``: the contact is ``P`` at
    ``t = L / (L + R/2)`` (convexity), to the rounding of the start over the entry's steepness."""
    precision, box, r, distance, w, rng = scene
    big_r = box.radius + r
    d, cos = entering_directions(rng, w)
    a = as_precision(w["P"] - distance[:, None] * d, precision)
    v = as_precision((distance + 0.5 * big_r)[:, None] * d, precision)
    c = ws.collide_box(a, v, r, box, 1.0, precision=precision)
    assert c.hit.all()
    ulp = ulps(precision, a, a + v)
    error = np.linalg.norm(c.position - w["P"], axis=1)
    assert np.all(error <= SURFACE_ULPS["linear"] * ulp / cos)
    assert np.all(np.abs(surface_distance(box, big_r, c.position.astype(np.float64)))
                  <= SURFACE_ULPS["linear"] * ulp)
    # bounce: the rest of the path, R/2, leaves along the reflection (no second contact on a
    # convex body)
    b = ws.bounce(a, v, r, box, 1.0, precision=precision)
    assert np.all(b.bounces == 1)
    reflected = d - 2.0 * np.einsum("ij,ij->i", d, w["n"])[:, None] * w["n"]
    end = w["P"] + 0.5 * big_r * reflected
    np.testing.assert_array_less(np.linalg.norm(b.position - end, axis=1),
                                 bounce_tolerance(SURFACE_ULPS["linear"] * ulp / cos, big_r))


def bounce_tolerance(delta, big_r):
    """Error bound [m] of the end of a bounce whose contact is ``delta`` [m] off, with ``R / 2``
    of path left: ``delta``, plus twice the normal's error times ``R / 2``, the normal's error
    being ``sqrt(2 delta / R)`` (a contact near the seam of two features may take the other
    one's normal, see the chord test above), plus the float32 rounding of the reflection."""
    return 2.0 * delta + big_r * np.sqrt(2.0 * delta / big_r) + 1e-6 * big_r


# --- arcs ------------------------------------------------------------------------------------

def gravity_away(rng, normals, sign):
    """Gravity [m/s^2] of size ``G`` with ``sign * (g . n) >= 0`` (away from the body for +1)."""
    g = rng.normal(size=normals.shape)
    along = np.einsum("ij,ij->i", g, normals)
    g -= (along - sign * np.abs(along))[:, None] * normals
    return G * g / np.linalg.norm(g, axis=1)[:, None]


def run_arcs(a, v, g, r, box, tau, precision, query):
    """``collide_box`` or ``bounce`` of arcs under one gravity ``g`` for ``tau`` seconds."""
    return query(a, v, r, box, tau, precision=precision, motion="ballistic", gravity=g)


@settings(max_examples=examples(30), deadline=None)
@given(scene=far_scenes())
def test_arcs_aimed_inside_hit_and_outside_miss(scene):
    """Arcs through ``P -+ f R n`` at ``s = 1`` with a tangent velocity of ``L`` m/s, for two
    seconds: inside ones hit with the contact on the surface, before ``s = 1``; outside ones,
    where gravity points away from the body (``g . n >= 0``), stay ``f R`` clear and miss."""
    precision, box, r, distance, w, rng = scene
    big_r = box.radius + r
    depth = F_AIM * big_r
    g = as_precision(G * tangents(rng, rng.normal(size=(1, 3)))[0], precision)
    u = distance[:, None] * w["t"]
    for sign, expect_hit in ((-1.0, True), (1.0, False)):
        mid = w["P"] + sign * depth * w["n"]
        a = as_precision(mid - u + 0.5 * g, precision)  # x(s) = a + v s + g s^2 / 2
        v = as_precision(u - g, precision)
        keep = surface_distance(box, big_r, a) > 0.0  # a start outside the body
        if not expect_hit:
            keep &= w["n"] @ g >= 0.0
        a, v = a[keep], v[keep]
        c = run_arcs(a, v, g, r, box, 2.0, precision, ws.collide_box)
        assert np.all(c.hit == expect_hit), (precision, distance[keep][c.hit != expect_hit])
        if not expect_hit:
            continue
        s = 2.0 * c.t.astype(np.float64)
        x = c.position.astype(np.float64)
        on_arc = a + v * s[:, None] + 0.5 * g * (s * s)[:, None]
        ulp = ulps(precision, a, v, on_arc)
        assert np.all(np.abs(surface_distance(box, big_r, x)) <= SURFACE_ULPS["ballistic"] * ulp)
        assert np.all(np.linalg.norm(x - on_arc, axis=1) <= SURFACE_ULPS["ballistic"] * ulp)
        np.testing.assert_array_less(s, 1.0)


@settings(max_examples=examples(30), deadline=None)
@given(scene=far_scenes())
def test_arcs_entering_at_a_chosen_contact(scene):
    """Arcs reaching ``P`` at ``s* = 1`` with velocity ``u = L d`` (``d . n < 0``), for
    ``tau = 1 + R / 2 L_max``. Before ``s*`` the height over the supporting plane at ``P`` is
    ``sigma (|u . n| + sigma g . n / 2)``, ``sigma = 1 - s``: positive when ``g . n >= 0`` or
    ``|u . n| > |g . n|`` (the cases kept), so ``P`` is the first contact; ``bounce`` then
    leaves along the reflected velocity (the normal's error over ``R``, times ``R / 2``)."""
    precision, box, r, distance, w, rng = scene
    big_r = box.radius + r
    d, cos = entering_directions(rng, w)
    u = distance[:, None] * d
    g = as_precision(G * tangents(rng, rng.normal(size=(1, 3)))[0], precision)
    un, gn = np.einsum("ij,ij->i", u, w["n"]), w["n"] @ g
    keep = (gn >= 0.0) | (np.abs(un) > np.abs(gn))
    # one duration per launch: R / 2L past the contact at the batch's largest L (at least
    # 2 REPRESENTABLE / F_AIM ulps of 1 s: far from rounding)
    tau = 1.0 + 0.5 * big_r / distance[keep].max()
    a = as_precision((w["P"] - u + 0.5 * g)[keep], precision)
    v = as_precision((u - g)[keep], precision)
    p_star, cos, n_star = w["P"][keep], cos[keep], w["n"][keep]
    c = run_arcs(a, v, g, r, box, tau, precision, ws.collide_box)
    assert c.hit.all(), (precision, distance[keep][~c.hit])
    ulp = ulps(precision, a, v)
    error = np.linalg.norm(c.position - p_star, axis=1)
    assert np.all(error <= SURFACE_ULPS["ballistic"] * ulp / cos)
    b = run_arcs(a, v, g, r, box, tau, precision, ws.bounce)
    assert np.all(b.bounces == 1)
    rest = tau - 1.0
    u_star = v + g
    u_out = u_star - 2.0 * np.einsum("ij,ij->i", u_star, n_star)[:, None] * n_star
    end = p_star + u_out * rest + 0.5 * g * rest * rest
    np.testing.assert_array_less(np.linalg.norm(b.position - end, axis=1),
                                 bounce_tolerance(SURFACE_ULPS["ballistic"] * ulp / cos, big_r))


# --- the reported cases and a sweep over the distance -----------------------------------------

@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_point_sized_box_from_300_m(precision):
    """A path 3 cm from a point box of radius 5 cm, from 300 m: enters 4 cm before the centre's
    abscissa, ``t = (300 - 0.04) / 600`` (the chord of the circle)."""
    c = ws.collide_box([[-300.0, 0.03, 0.0]], [[600.0, 0.0, 0.0]], 0.0,
                       ws.RoundedBox(half_extents=(0, 0, 0), radius=0.05), 1.0,
                       precision=precision)
    assert c.hit[0]
    assert c.t[0] == pytest.approx((300.0 - 0.04) / 600.0, abs=4 * eps_of(precision))


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_edge_passes_over_a_sweep_of_distances(precision, motion):
    """A 6 cm sphere past a 2 cm rounded edge (``R`` = 8 cm), aimed 9 mm inside and outside its
    cylinder, from 1 m to as far as the precision represents a 9 mm aim, chords and arcs
    (gravity along the edge, so the path across it stays straight), through ``collide_boxes``
    over a row of boxes (both broad phases) and ``bounce``. The inside path enters the circle
    ``k = sqrt(R^2 - p^2)`` before its closest point (``p = R - 9 mm``); the bounce reflects it
    in the radius there."""
    h, rb, r = np.array([1.0, 1.0, 1.0]), 0.02, 0.06
    big_r = rb + r
    target = ws.RoundedBox(half_extents=h, radius=rb)
    boxes = ws.RoundedBoxes(center=[[0, 0, 0], [0, 0, 50], [0, 0, -50], [0, 0, 100]],
                            half_extents=[h] * 4, radius=[rb] * 4)
    aim = 0.009
    top = min(MAX_DISTANCE[precision], aim / (REPRESENTABLE * eps_of(precision)))
    distance = 10.0 ** np.arange(0.0, np.log10(top), 0.25)
    normal = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    edge = np.array([1.0, 1.0, 0.3])  # on the edge's axis (x = y = 1)
    along = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
    g = np.array([0.0, 0.0, 0.0 if motion == "linear" else -G])
    gravity = None if motion == "linear" else g
    for offset, expect in ((big_r - aim, True), (big_r + aim, False)):
        mid = edge + offset * normal
        # x(1/2) = mid with speed 2 L across the edge: the start takes up the fall
        a = as_precision(mid - distance[:, None] * along - 0.125 * g, precision)
        v = as_precision(2.0 * distance[:, None] * along, precision)
        for method in ("brute", "bvh"):
            c = ws.collide_boxes(a, v, r, boxes, 1.0, precision=precision,
                                 broad_phase=method, motion=motion, gravity=gravity)
            assert np.all(c.hit == expect), (method, offset, distance[c.hit != expect])
            if expect:
                assert np.all(c.box == 0)
                ulp = ulps(precision, a, a + v)
                assert np.all(np.abs(surface_distance(target, big_r, c.position))
                              <= SURFACE_ULPS[motion] * ulp)
        b = ws.bounce(a, v, r, boxes, 1.0, precision=precision, motion=motion,
                      gravity=gravity)
        assert np.all(b.bounces == (1 if expect else 0))
        if not expect:
            continue
        k = np.sqrt(big_r**2 - offset**2)
        s_hit = 0.5 - k / (2.0 * distance)
        n_hit = (offset * normal - k * along) / big_r
        u_hit = v + g * s_hit[:, None]
        u_out = u_hit - 2.0 * (u_hit @ n_hit)[:, None] * n_hit
        v_end = u_out + g * (1.0 - s_hit)[:, None]
        # the normal is the contact's direction from the axis: its error is the contact's
        # (a few ulps of L) over R, and the velocity's is that times its size
        ulp = ulps(precision, a, a + v)
        error = np.linalg.norm(b.velocity - v_end, axis=1) / np.linalg.norm(v, axis=1)
        assert np.all(error <= 4.0 * SURFACE_ULPS[motion] * ulp / big_r + 1e-6)
