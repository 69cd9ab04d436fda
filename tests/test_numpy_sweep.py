"""The plain NumPy sweep (``benchmarks/numpy_sweep.py``, the sweep study's baseline) against
the float64 references.

The named analytic cases of ``test_reference.py`` run through it in both precisions, then
random segments and groups of boxes against :func:`reference.bounce_reference`. Float64 must
agree to rounding; float32 to its own precision, away from the cases whose verdict rests on
rounding (grazing, starts on the surface, near ties between boxes).
"""

import numpy as np
import pytest
from helpers import exact_entry, far_passes, textbook_entry
from reference import (
    AMBIGUOUS,
    bounce_reference,
    sweep_by_distance,
    sweep_reference_batch,
)
from test_reference import CASES

import warpsim as ws
from benchmarks.numpy_sweep import sweep_boxes_numpy

DTYPES = [np.float64, np.float32]

#: Per precision: ``t`` and contact agreement on a transversal entry, normal agreement (the
#: normal of an edge or corner moves by the position error over R, R >= 0.05 below), and the
#: margin [m] around the surface inside which a float32 verdict may flip (a few hundred ulps
#: of the unit-scale coordinates).
TOL = {
    np.float64: {"t": 1e-10, "pos": 1e-10, "normal": 1e-9, "margin": 1e-9},
    np.float32: {"t": 2e-4, "pos": 2e-4, "normal": 2e-3, "margin": 1e-3},
}


def one_box(center, h, quat, rb) -> ws.RoundedBoxes:
    return ws.RoundedBoxes(center=[center], half_extents=[h], rotation=[quat], radius=[rb])


@pytest.mark.parametrize("dtype", DTYPES, ids=["float64", "float32"])
@pytest.mark.parametrize("args, expected", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_named_case(args, expected, dtype):
    """Face, edge, corner, starts in contact, tangents, sharp and degenerate boxes: the
    analytic answers (all exact in float32 too, so the verdicts do not depend on rounding)."""
    a, b, center, h, quat, rb, r = args
    hit, t, normal = expected
    a, b = np.array([a]), np.array([b])
    out = sweep_boxes_numpy(a, b - a, r, one_box(center, h, quat, rb), 1.0, dtype=dtype)
    tol = 1e-15 if dtype == np.float64 else 1e-6
    assert out["hit"][0] == hit
    assert out["box"][0] == (0 if hit else -1)
    assert out["t"][0] == pytest.approx(t, abs=tol)
    np.testing.assert_allclose(out["normal"][0], normal, atol=tol)
    np.testing.assert_allclose(out["position"][0], (a + t * (b - a))[0], atol=4 * tol)
    for key in ("t", "position", "normal", "new_position", "new_velocity"):
        assert out[key].dtype == dtype


@pytest.mark.parametrize("dtype", DTYPES, ids=["float64", "float32"])
def test_edge_hit_built_by_hand(dtype):
    """Edge along z at (1, 1), R = 0.5: contact centre (1.3, 1.4, 0.25) at t = 1/4, normal
    (0.6, 0.8, 0) (see ``test_reference.test_edge_cylinder_by_hand``)."""
    out = sweep_boxes_numpy([(2.3, 2.4, 0.25)], [(-4.0, -4.0, 0.0)], 0.25,
                            one_box((0, 0, 0), (1, 1, 1), (0, 0, 0, 1), 0.25), 1.0, dtype=dtype)
    tol = TOL[dtype]["t"]
    assert out["hit"][0]
    assert out["t"][0] == pytest.approx(0.25, abs=tol)
    np.testing.assert_allclose(out["normal"][0], (0.6, 0.8, 0.0), atol=TOL[dtype]["normal"])


#: Far passes: (dtype, distance [m], Minkowski radius R [m]) where the textbook discriminant
#: has lost every digit of ``R^2 - |p|^2`` (its error, ``eps |w|^2 |d|^2``, is above
#: ``|d|^2 R^2``): float32 from 300 m past 5 cm, float64 from 1000 km past 1 cm.
FAR = [(np.float32, 300.0, 0.05), (np.float64, 1.0e6, 0.01)]


@pytest.mark.parametrize("feature", ["ball", "edge"])
@pytest.mark.parametrize("dtype, distance, big_r", FAR, ids=["float32", "float64"])
def test_far_passes_agree_with_the_exact_root(feature, dtype, distance, big_r):
    """Passes by a ball (a point box) and by a rounded edge from far away, through the
    feature and just beside it: the verdict and ``t`` of the exact rational root of the
    rounded inputs (to a few ulps), on every row, where the textbook ``b^2 - a c`` form gets
    each row wrong (a miss counted as a tangent hit, or a ``t`` off by many ulps)."""
    rows = far_passes(feature, distance, big_r, dtype)
    box = one_box((0.0, 0.0, 0.0), rows[0]["h"], (0, 0, 0, 1), big_r)
    out = sweep_boxes_numpy(np.array([r["a"] for r in rows]), np.array([r["d"] for r in rows]),
                            0.0, box, 1.0, dtype=dtype)
    t_tol = 8 * float(np.finfo(dtype).eps)
    for k, row in enumerate(rows):
        across = row["across"]
        args = (row["a"][across], row["d"][across], row["axis_point"], big_r)
        hit, t = exact_entry(*args)
        assert out["hit"][k] == hit, row["name"]
        assert out["t"][k] == pytest.approx(t, abs=t_tol), row["name"]
        textbook_hit, textbook_t = textbook_entry(*args, dtype)
        assert textbook_hit != hit or abs(textbook_t - t) > 10 * t_tol, row["name"]


@pytest.mark.parametrize("dtype", DTYPES, ids=["float64", "float32"])
def test_parallel_axes(dtype):
    """Direction components at or below one ulp of the largest are parallel to their slab: no
    division, a miss when outside that slab, no constraint inside it."""
    box = one_box((0, 0, 0), (1, 1, 1), (0, 0, 0, 1), 0.0)
    position = [(3.0, 0.5, 0.5), (3.0, 1.5, 0.0), (3.0, 0.5, -0.5), (3.0, 1.5, 0.0)]
    velocity = [(-4.0, 0.0, 0.0), (-4.0, 0.0, 0.0), (-4.0, 1e-30, -1e-30), (-4.0, -1e-30, 0.0)]
    out = sweep_boxes_numpy(position, velocity, 0.25, box, 1.0, dtype=dtype)
    np.testing.assert_array_equal(out["hit"], [True, False, True, False])
    np.testing.assert_allclose(out["t"], [0.4375, 1.0, 0.4375, 1.0])
    np.testing.assert_array_equal(out["normal"][0], (1.0, 0.0, 0.0))
    assert np.isfinite(out["new_position"]).all()


@pytest.mark.parametrize("dtype", DTYPES, ids=["float64", "float32"])
def test_start_in_contact(dtype):
    """On the surface or inside: t = 0 moving in; moving away, along, or not at all: no hit."""
    box = one_box((0, 0, 0), (1, 1, 1), (0, 0, 0, 1), 0.25)
    position = np.array([(1.5, 0.0, 0.0)] * 4 + [(0.5, 0.0, 0.0)] * 2)
    velocity = np.array([(-1.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 0.0),
                         (-1.0, 0.0, 0.0), (1.0, 0.0, 0.0)])
    out = sweep_boxes_numpy(position, velocity, 0.25, box, 0.5, dtype=dtype)
    np.testing.assert_array_equal(out["hit"], [True, False, False, False, True, False])
    np.testing.assert_array_equal(out["t"], [0.0, 1.0, 1.0, 1.0, 0.0, 1.0])
    np.testing.assert_array_equal(out["new_velocity"][0], (1.0, 0.0, 0.0))
    np.testing.assert_array_equal(out["new_position"][0], (2.0, 0.0, 0.0))
    np.testing.assert_array_equal(out["position"][0], (1.5, 0.0, 0.0))


def test_no_hit_rows_ties_and_inputs_untouched():
    boxes = ws.RoundedBoxes(center=[(0, 0, 0), (0, 0, 0), (5, 0, 0)],
                            half_extents=[(1, 1, 1), (1, 1, 1), (1, 1, 1)], radius=0.0)
    position = np.array([[-3.0, 0.0, 0.0], [-3.0, 5.0, 0.0]])
    velocity = np.array([[8.0, 0.0, 0.0], [8.0, 0.0, 0.0]])
    before = position.copy(), velocity.copy()
    out = sweep_boxes_numpy(position, velocity, 0.0, boxes, 0.5, dtype=np.float64)
    np.testing.assert_array_equal(position, before[0])
    np.testing.assert_array_equal(velocity, before[1])
    np.testing.assert_array_equal(out["hit"], [True, False])
    np.testing.assert_array_equal(out["box"], [0, -1])  # boxes 0 and 1 tie: the lower index
    assert out["box"].dtype == np.int32
    np.testing.assert_array_equal(out["t"], [0.5, 1.0])
    np.testing.assert_array_equal(out["position"][1], (1.0, 5.0, 0.0))
    np.testing.assert_array_equal(out["new_position"][1], (1.0, 5.0, 0.0))
    np.testing.assert_array_equal(out["normal"][1], (0.0, 0.0, 0.0))
    np.testing.assert_array_equal(out["new_velocity"][1], velocity[1])
    np.testing.assert_array_equal(out["new_position"][0], (-3.0, 0.0, 0.0))


def test_bad_input_is_refused():
    box = one_box((0, 0, 0), (1, 1, 1), (0, 0, 0, 1), 0.0)
    with pytest.raises(ValueError, match=r"radius\[1\]"):
        sweep_boxes_numpy(np.zeros((2, 3)), np.zeros((2, 3)), [0.1, -0.1], box, 0.1)
    with pytest.raises(ValueError, match="dtype"):
        sweep_boxes_numpy(np.zeros((1, 3)), np.zeros((1, 3)), 0.1, box, 0.1, dtype=np.int32)
    with pytest.raises(ValueError, match="dt"):
        sweep_boxes_numpy(np.zeros((1, 3)), np.zeros((1, 3)), 0.1, box, 0.0)


def _random_box(rng):
    h = rng.uniform(0.0, 1.0, 3) * (rng.uniform(size=3) > 0.25)
    rb = rng.choice([0.0, rng.uniform(0.05, 0.4)])
    return rng.uniform(-1.0, 1.0, 3), h, rng.normal(size=4), rb


def _decided(a, b, center, h, quat, rb, r, margin):
    """Rows whose verdict does not rest on rounding at this precision: the distance search is
    decided, the path's closest approach and its start are more than ``margin`` from the
    surface, and an entry is not shallower than 5 % of the motion."""
    far = sweep_by_distance(a, b, center, h, quat, rb, r)
    start = sweep_by_distance(a, a, center, h, quat, rb, r)
    ok = (far.status != AMBIGUOUS) & (np.abs(far.min_distance) > margin)
    ok &= np.abs(start.min_distance) > margin
    d = b - a
    ref = sweep_reference_batch(a, b, center, h, quat, rb, r)
    steep = -np.einsum("ij,ij->i", d, ref.normal) > 0.05 * np.linalg.norm(d, axis=1)
    return ok & (~ref.hit | steep | (ref.t == 0.0)), ref


@pytest.mark.slow
@pytest.mark.parametrize("dtype", DTYPES, ids=["float64", "float32"])
def test_random_segments_one_box(dtype):
    """20 random boxes (zero extents, sharp or rounded, any rotation) x 200 segments."""
    rng = np.random.default_rng(11)
    tol = TOL[dtype]
    checked = 0
    for _ in range(20):
        center, h, quat, rb = _random_box(rng)
        r = rng.choice([0.0, rng.uniform(0.05, 0.4)])
        a = center + rng.uniform(-3.0, 3.0, (200, 3))
        a[:40] = center + rng.uniform(-1.2, 1.2, (40, 3))
        b = center + rng.uniform(-1.5, 1.5, (200, 3))
        ok, ref = _decided(a, b, center, h, quat, rb, r, tol["margin"])
        out = sweep_boxes_numpy(a, (b - a) * 4.0, r, one_box(center, h, quat, rb), 0.25,
                                dtype=dtype)
        np.testing.assert_array_equal(out["hit"][ok], ref.hit[ok])
        both = ok & ref.hit
        np.testing.assert_allclose(out["t"][both], ref.t[both], atol=tol["t"])
        np.testing.assert_allclose(out["normal"][both], ref.normal[both], atol=tol["normal"])
        np.testing.assert_allclose(out["position"][ok], ref.contact[ok], atol=tol["pos"])
        checked += ok.sum()
    assert checked > 0.9 * 20 * 200


@pytest.mark.slow
@pytest.mark.parametrize("dtype", DTYPES, ids=["float64", "float32"])
def test_random_groups_match_bounce_reference(dtype):
    """Groups of 12 boxes, 300 spheres each: nearest box, contact and reflected outputs."""
    rng = np.random.default_rng(12)
    tol = TOL[dtype]
    for _ in range(3):
        k = 12
        boxes = ws.RoundedBoxes(center=rng.uniform(-3.0, 3.0, (k, 3)),
                                half_extents=rng.uniform(0.0, 0.8, (k, 3)),
                                rotation=rng.normal(size=(k, 4)),
                                radius=rng.choice([0.0, 0.1, 0.2], k))
        n = 300
        position = rng.uniform(-4.0, 4.0, (n, 3))
        dt = 0.5
        # Most spheres aim near a box (so most rows hit something), the rest go anywhere.
        target = boxes.center[rng.integers(k, size=n)] + rng.normal(0.0, 0.5, (n, 3))
        velocity = (target - position) / dt * rng.uniform(0.6, 1.4, n)[:, None]
        velocity[: n // 4] = rng.normal(size=(n // 4, 3)) * 4.0
        radius = rng.uniform(0.05, 0.2, n)
        ref = bounce_reference(position, velocity, radius, boxes, dt)
        out = sweep_boxes_numpy(position, velocity, radius, boxes, dt, dtype=dtype)
        # Rows decided at this precision for every box, and without a near tie between boxes.
        ok = np.ones(n, dtype=bool)
        ts = np.full((k, n), np.inf)
        b = position + velocity * dt
        for i in range(k):
            ok_i, ref_i = _decided(position, b, boxes.center[i], boxes.half_extents[i],
                                   boxes.rotation[i], boxes.radius[i], radius, tol["margin"])
            ok &= ok_i
            ts[i] = np.where(ref_i.hit, ref_i.t, np.inf)
        ts.sort(axis=0)
        gap = np.where(np.isfinite(ts[1]), ts[1] - np.where(np.isfinite(ts[0]), ts[0], 0.0),
                       np.inf)
        ok &= gap >= 1e-3
        assert ok.mean() > 0.8
        assert (ok & ref["hit"]).mean() > 0.25
        for key in ("hit", "box"):
            np.testing.assert_array_equal(out[key][ok], ref[key][ok])
        np.testing.assert_allclose(out["t"][ok], ref["t"][ok], atol=tol["t"])
        np.testing.assert_allclose(out["position"][ok], ref["position"][ok], atol=tol["pos"])
        np.testing.assert_allclose(out["normal"][ok], ref["normal"][ok], atol=tol["normal"])
        # Reflection: an error e in the normal moves v' by up to 2 |v| e (and the rest of the
        # path by 2 |d| e), on top of the contact's own error.
        speed = np.linalg.norm(velocity[ok], axis=1, keepdims=True)
        assert (np.abs(out["new_velocity"][ok] - ref["new_velocity"][ok])
                <= 4.0 * tol["normal"] * speed + tol["pos"]).all()
        assert (np.abs(out["new_position"][ok] - ref["new_position"][ok])
                <= 4.0 * tol["normal"] * speed * dt + 2.0 * tol["pos"]).all()
