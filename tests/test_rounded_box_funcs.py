"""The rounded-box ``@wp.func``s (``kernels/rounded_box.py``) tested directly, in the box's frame.

``sweep_rounded_box`` and ``rounded_box_distance`` run through one tiny test kernel per
precision (a cold build of a few seconds, so that the mutation check can afford it per mutant),
against answers that do not come from the kernels: the analytic cases of ``test_reference.py``
(built backwards from the contact) and the float64 26-feature reference
(:func:`reference.sweep_reference_batch`) on random boxes and segments, the rows whose verdict
rests on rounding left out as in ``test_sweep_reference.py``.
"""

from functools import cache

import numpy as np
import pytest
import warp as wp
from helpers import TOLERANCES, shaped_half_extents
from reference import core_distance_and_normal, sweep_reference_batch
from test_func_contracts import run_rows
from test_reference import CASES
from test_sweep_reference import BANDS, _decided, _segments

import warpsim as ws
from warpsim.kernels.precision import precision as types_of
from warpsim.kernels.rounded_box import rounded_box_funcs
from warpsim.kernels.variant import variant_kernel

IDENTITY = (0.0, 0.0, 0.0, 1.0)

#: The analytic cases whose box is not rotated: their local frame is the world shifted by the
#: centre, so they run through the local-frame func as they are.
LOCAL_CASES = [c for c in CASES if tuple(c[1][4]) == IDENTITY]


@cache
def rounded_box_kernel(name: str):
    p = types_of(name)
    funcs = rounded_box_funcs(p)
    sweep_rounded_box, rounded_box_distance = funcs.sweep_rounded_box, funcs.rounded_box_distance
    start_contact, closer = funcs.start_contact, funcs.closer

    @variant_kernel
    def run(a: wp.array[p.vec3], d: wp.array[p.vec3], h: wp.array[p.vec3],
            radius: wp.array[p.scalar], hit_a: wp.array[wp.int32], t_a: wp.array[p.scalar],
            hit_b: wp.array[wp.int32], t_b: wp.array[p.scalar], hit_out: wp.array[wp.int32],
            t_out: wp.array[p.scalar], normal_out: wp.array[p.vec3],
            distance_out: wp.array[p.scalar], start_normal_out: wp.array[p.vec3],
            touching_out: wp.array[wp.int32], moving_in_out: wp.array[wp.int32],
            contact_normal_out: wp.array[p.vec3], closer_hit_out: wp.array[wp.int32],
            closer_t_out: wp.array[p.scalar], closer_normal_out: wp.array[p.vec3]):
        i = wp.tid()
        hit, t, n = sweep_rounded_box(a[i], d[i], h[i], radius[i])
        hit_out[i] = hit
        t_out[i] = t
        normal_out[i] = n
        distance, start_normal = rounded_box_distance(a[i], h[i], radius[i])
        distance_out[i] = distance
        start_normal_out[i] = start_normal
        touching, moving_in, contact_normal = start_contact(a[i], d[i], h[i], radius[i])
        touching_out[i] = touching
        moving_in_out[i] = moving_in
        contact_normal_out[i] = contact_normal
        # the first hit's normal is +x, the second's +y: the output normal tells which was kept
        c_hit, c_t, c_n = closer(hit_a[i], t_a[i], p.vec3(1.0, 0.0, 0.0), hit_b[i], t_b[i],
                                 p.vec3(0.0, 1.0, 0.0))
        closer_hit_out[i] = c_hit
        closer_t_out[i] = c_t
        closer_normal_out[i] = c_n

    return run


def sweep_rows(precision: str, a, d, h, radius, hits=None) -> dict:
    """``sweep_rounded_box``, ``rounded_box_distance`` and ``start_contact`` over rows (local
    frame), and ``closer`` over the rows of ``hits`` (``(hit_a, t_a, hit_b, t_b)``; none by
    default)."""
    p = types_of(precision)
    n = len(a)
    hits = np.zeros((n, 4)) if hits is None else np.asarray(hits, dtype=np.float64)
    return run_rows(rounded_box_kernel(precision), p,
                    {"a": (a, p.vec3), "d": (d, p.vec3),
                     "h": (np.broadcast_to(np.asarray(h, dtype=np.float64), (n, 3)), p.vec3),
                     "radius": (np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,)),
                                p.scalar),
                     "hit_a": (hits[:, 0], wp.int32), "t_a": (hits[:, 1], p.scalar),
                     "hit_b": (hits[:, 2], wp.int32), "t_b": (hits[:, 3], p.scalar)},
                    {"hit": wp.int32, "t": p.scalar, "normal": p.vec3, "distance": p.scalar,
                     "start_normal": p.vec3, "touching": wp.int32, "moving_in": wp.int32,
                     "contact_normal": p.vec3, "closer_hit": wp.int32, "closer_t": p.scalar,
                     "closer_normal": p.vec3})


def test_named_cases(precision, tol):
    """Face, edge, corner, tangents, starts in contact (in, out, along), deep starts and their
    ties, zero-length segments, sharp boxes (edge and corner ties to the last-crossed face),
    plates, sticks and points: the analytic answers, all rows in one launch."""
    a = np.array([np.subtract(c[1][0], c[1][2]) for c in LOCAL_CASES])
    b = np.array([np.subtract(c[1][1], c[1][2]) for c in LOCAL_CASES])
    h = np.array([c[1][3] for c in LOCAL_CASES])
    radius = np.array([c[1][5] + c[1][6] for c in LOCAL_CASES])
    out = sweep_rows(precision, a, b - a, h, radius)
    for k, (name, _, (hit, t, normal)) in enumerate(LOCAL_CASES):
        assert out["hit"][k] == hit, name
        assert out["t"][k] == pytest.approx(t, abs=tol["t_abs"]), name
        np.testing.assert_allclose(out["normal"][k], normal, atol=10 * tol["unit"],
                                   err_msg=name)


#: Points of the local frame against a core box (1, 0.5, 0.25) with R = 0.125, each with the
#: distance and normal worked out by hand: outside a face, an edge and a corner, and inside the
#: core (nearest face, the lower axis on ties, a coordinate of 0 on the + side).
DISTANCE_H = (1.0, 0.5, 0.25)
DISTANCE_CASES = {
    "outside +x face": ((1.5, 0.25, 0.0), 0.5 - 0.125, (1.0, 0.0, 0.0)),
    "outside -y face": ((0.0, -1.0, 0.125), 0.5 - 0.125, (0.0, -1.0, 0.0)),
    "outside an edge": ((1.375, 1.0, 0.0), 0.625 - 0.125, (0.6, 0.8, 0.0)),
    "outside a corner": ((-1.5, 0.5, 0.25 + 0.5), np.sqrt(0.5) - 0.125,
                         (-np.sqrt(0.5), 0.0, np.sqrt(0.5))),
    "inside, nearest -z": ((0.5, 0.125, -0.125), -0.125 - 0.125, (0.0, 0.0, -1.0)),
    "inside, nearest +x": ((0.875, 0.0, 0.0), -0.125 - 0.125, (1.0, 0.0, 0.0)),
    "inside, nearest +y": ((0.25, 0.375, 0.0), -0.125 - 0.125, (0.0, 1.0, 0.0)),
    "inside, x, y and z tie": ((0.75, -0.25, 0.0), -0.25 - 0.125, (1.0, 0.0, 0.0)),
    "centre: z nearest, + side": ((0.0, 0.0, 0.0), -0.25 - 0.125, (0.0, 0.0, 1.0)),
    "on the core face": ((1.0, 0.0, 0.0), -0.125, (1.0, 0.0, 0.0)),
}


def test_rounded_box_distance(precision, tol):
    rows = list(DISTANCE_CASES.values())
    a = np.array([r[0] for r in rows])
    out = sweep_rows(precision, a, np.zeros_like(a), DISTANCE_H, 0.125)
    for k, (name, (_, distance, normal)) in enumerate(DISTANCE_CASES.items()):
        assert out["distance"][k] == pytest.approx(distance, abs=tol["t_abs"]), name
        np.testing.assert_allclose(out["start_normal"][k], normal, atol=10 * tol["unit"],
                                   err_msg=name)


@pytest.mark.parametrize("kind", ["box", "plate", "stick", "point", "cube"])
def test_random_segments_match_the_reference(kind, precision):
    """Random boxes of each shape (rounded and sharp), segments from all around aimed at and
    beside them (with zero direction components), against the 26-feature float64 reference:
    verdict, contact, and normal (sharp boxes: where the reference hits a face's interior)."""
    band = BANDS[precision]
    rng = np.random.default_rng({"box": 11, "plate": 12, "stick": 13, "point": 14,
                                 "cube": 15}[kind])
    a_rows, d_rows, h_rows, r_rows, refs, decided = [], [], [], [], [], []
    for _ in range(6):
        h = shaped_half_extents(rng, kind, 0.05, 1.5)
        rb = float(rng.choice([0.0, 0.05, 0.3])) if kind in ("box", "cube") \
            else float(rng.choice([0.05, 0.3]))
        r = float(rng.choice([0.0, 0.02, 0.2])) if rb > 0 else 0.0
        box = ws.RoundedBox(center=(0.0, 0.0, 0.0), half_extents=h, radius=rb)
        a, d = _segments(rng, box, r, 300)
        ref = sweep_reference_batch(a, a + d, (0.0, 0.0, 0.0), h, IDENTITY, rb, r)
        a_rows.append(a)
        d_rows.append(d)
        h_rows.append(np.broadcast_to(h, a.shape))
        r_rows.append(np.full(len(a), rb + r))
        refs.append(ref)
        decided.append(_decided(box, r, a, d, ref, band))
    a, d = np.concatenate(a_rows), np.concatenate(d_rows)
    radius = np.concatenate(r_rows)
    out = sweep_rows(precision, a, d, np.concatenate(h_rows), radius)
    ref_hit = np.concatenate([r.hit for r in refs])
    ref_t = np.concatenate([r.t for r in refs])
    ref_normal = np.concatenate([r.normal for r in refs])
    ok = np.concatenate(decided)
    assert ok.mean() > 0.85 and (ok & ref_hit).mean() > 0.2
    np.testing.assert_array_equal(out["hit"][ok], ref_hit[ok])
    both = ok & ref_hit
    length = np.linalg.norm(d, axis=1)
    err = np.abs(out["t"] - ref_t) * length
    assert np.all(err[both] <= band["pos"] * (1 + length[both]) * np.maximum(
        1.0, np.abs(a).max(axis=1))[both]), err[both].max()
    rounded = both & (radius > 0)
    np.testing.assert_allclose(out["normal"][rounded], ref_normal[rounded],
                               atol=band["normal"])
    # no hit: t = 1 and a zero normal, whatever the row
    miss = out["hit"] == 0
    assert np.all(out["t"][miss] == 1.0) and np.all(out["normal"][miss] == 0.0)
    # the start distance against the reference's core distance
    core, _ = core_distance_and_normal(a, np.concatenate(h_rows))
    np.testing.assert_allclose(out["distance"], core - radius,
                               atol=band["pos"] * (1 + np.abs(a).max()))


@pytest.mark.parametrize("slope, moving_in", [(32, False), (128, True)])
def test_start_on_the_surface_moves_in_beyond_the_tangent_margin(slope, moving_in, precision):
    """A start on a face, sliding along it with an inward slope of ``slope`` machine epsilons
    (``d . n = -slope eps |d|`` up to the slope's square): in only beyond the tangent margin of
    64 eps (``TANGENT_REL``), whatever the segment's length (1 and 1024 m here)."""
    eps = float(np.finfo(types_of(precision).np_dtype).eps)
    a = np.array([[1.5, 0.0, 0.0]] * 2)
    d = np.array([[-slope * eps, 1.0, 0.0], [-slope * eps * 1024.0, 1024.0, 0.0]])
    out = sweep_rows(precision, a, d, (1.0, 1.0, 1.0), 0.5)
    np.testing.assert_array_equal(out["hit"], [int(moving_in)] * 2)
    np.testing.assert_array_equal(out["t"], [0.0 if moving_in else 1.0] * 2)
    np.testing.assert_array_equal(out["normal"], [(1.0, 0.0, 0.0) if moving_in else (0, 0, 0)] * 2)


#: Starts a few ulps outside a sharp box's edge or corner (``R = 8 eps``, below ``SHARP_REL``
#: of the scale): inside the grown box, outside the rounded one. Offsets past the core box per
#: axis in units of eps (0: inside that slab), with signs, and the face the start sticks out of
#: the most (ties: the lower axis), whose normal the hit at ``t = 0`` takes.
SHARP_STARTS = {
    "edge, y sticks out most": ((6, -7, 0), (0.0, -1.0, 0.0)),
    "edge, x and y tie": ((7, 7, 0), (1.0, 0.0, 0.0)),
    "corner, z sticks out most": ((-6, 7, 7.5), (0.0, 0.0, 1.0)),
}


def test_sharp_start_between_the_grown_and_the_rounded_box(precision):
    """A sharp box's start inside the grown box but outside the rounding, moving in: a hit at
    ``t = 0`` whose normal is that of the face the start sticks out of the most."""
    eps = float(np.finfo(types_of(precision).np_dtype).eps)
    h = np.array([1.0, 0.75, 0.5])
    a, normals = [], []
    for offsets, normal in SHARP_STARTS.values():
        sign = np.sign(offsets) + (np.asarray(offsets) == 0)
        a.append(sign * (h * (np.asarray(offsets) != 0) + np.abs(offsets) * eps))
        normals.append(normal)
    a = np.array(a)
    out = sweep_rows(precision, a, -0.25 * np.sign(a), h, 8 * eps)
    for k, name in enumerate(SHARP_STARTS):
        assert out["hit"][k] == 1 and out["t"][k] == 0.0, name
        np.testing.assert_array_equal(out["normal"][k], normals[k], err_msg=name)


#: Starts against the core box (1, 0.5, 0.25) with R = 0.125 (face plane x = 1.125): outside,
#: on the surface and inside, each with a direction, and the expected ``(touching, moving_in)``
#: of ``start_contact`` (in: ``d . n < -TANGENT_REL |d|``).
START_CONTACTS = {
    "outside, moving in": ((1.5, 0.0, 0.0), (-1.0, 0.0, 0.0), (0, 0)),
    "on the +x face, moving in": ((1.125, 0.25, 0.0), (-1.0, 0.5, 0.0), (1, 1)),
    "on the +x face, moving out": ((1.125, 0.25, 0.0), (1.0, 0.0, 0.0), (1, 0)),
    "on the +x face, moving along": ((1.125, 0.25, 0.0), (0.0, 1.0, 0.0), (1, 0)),
    "inside the rounding of an edge, moving in": ((1.0625, 0.5625, 0.0), (-1.0, -1.0, 0.0),
                                                  (1, 1)),
    "inside the core, moving to -z": ((0.5, 0.125, -0.125), (0.0, 0.0, 1.0), (1, 1)),
    "inside the core, moving out through -z": ((0.5, 0.125, -0.125), (0.0, 0.0, -1.0), (1, 0)),
}


def test_start_contact_flags(precision):
    """``start_contact``'s flags, 1 or 0: touching for a start on or inside the rounded box
    (signed distance <= 0), moving in when the direction goes into the surface as well; the
    normal is the outward one at the start (local frame, [m] and [m] of path)."""
    rows = list(START_CONTACTS.values())
    a = np.array([r[0] for r in rows])
    d = np.array([r[1] for r in rows])
    out = sweep_rows(precision, a, d, DISTANCE_H, 0.125)
    for k, (name, (_, _, (touching, moving_in))) in enumerate(START_CONTACTS.items()):
        assert out["touching"][k] == touching, name
        assert out["moving_in"][k] == moving_in, name
    np.testing.assert_allclose(out["contact_normal"][1], (1.0, 0.0, 0.0))
    np.testing.assert_allclose(out["contact_normal"][4], (np.sqrt(0.5), np.sqrt(0.5), 0.0),
                               atol=10 * TOLERANCES[precision]["unit"])


#: ``closer``'s rows: ``(hit_a, t_a, hit_b, t_b)`` and the one it keeps ("a", "b" or None for
#: no hit); a tie keeps the first.
CLOSER_CASES = {
    "b nearer": ((1, 0.5, 1, 0.25), "b"),
    "a nearer": ((1, 0.25, 1, 0.5), "a"),
    "tie keeps the first": ((1, 0.5, 1, 0.5), "a"),
    "only b hits": ((0, 1.0, 1, 0.75), "b"),
    "only a hits": ((1, 0.75, 0, 0.25), "a"),
    "neither hits": ((0, 1.0, 0, 0.25), None),
}


def test_closer_keeps_the_nearer_hit_and_the_first_on_ties(precision):
    """``closer`` of two hits (times in [0, 1] of the segment): the one with the smaller
    ``t``, the first one on a tie, the one that hits when only one does."""
    rows = [r for r, _ in CLOSER_CASES.values()]
    a = np.full((len(rows), 3), 5.0)
    out = sweep_rows(precision, a, np.zeros_like(a), DISTANCE_H, 0.125, hits=rows)
    for k, (name, (row, keep)) in enumerate(CLOSER_CASES.items()):
        hit_a, t_a, hit_b, t_b = row
        if keep is None:
            assert out["closer_hit"][k] == 0, name
            continue
        assert out["closer_hit"][k] == 1, name
        assert out["closer_t"][k] == (t_a if keep == "a" else t_b), name
        np.testing.assert_array_equal(out["closer_normal"][k],
                                      (1.0, 0.0, 0.0) if keep == "a" else (0.0, 1.0, 0.0),
                                      err_msg=name)


def test_sharpness_threshold_against_the_local_scale(precision):
    """A box is sharp when ``R <= SHARP_REL * scale``, the scale being the largest of the
    grown half extents and ``|a|``: such a box's entry through an edge region is the grown box
    entry, with the normal of the face crossed last (a rounded one would sweep the edge's
    capsule and tilt the normal). ``R`` exactly at the threshold (``|a| = 1.25`` exactly, the
    scale), and boxes 8 m long along each axis entered beside an edge along that axis, with
    ``R`` = 64 eps, sharp only through the long half extent. Positions [m], local frame."""
    eps = float(np.finfo(types_of(precision).np_dtype).eps)
    rows = [  # (a, d, h, R, t, normal)
        # R = 16 eps * 1.25; z enters 10 eps after y (h_z lowered by 10 eps), y still outside
        ((0.0, 0.75, 1.0), (0.0, -1.0, -1.0), (0.5, 0.25, 0.5 - 10 * eps), 20 * eps,
         0.5 - 10 * eps, (0.0, 0.0, 1.0)),
    ]
    for long_axis in range(3):
        h = np.full(3, 0.125)
        h[long_axis] = 8.0
        a = np.ones(3)
        a[long_axis] = 0.0
        last = 2 if long_axis != 2 else 0  # the face crossed last: 32 eps further to go
        a[last] += 32 * eps
        d = -2.0 * (a != 0)
        normal = np.zeros(3)
        normal[last] = 1.0
        rows.append((a, d, h, 64 * eps, (0.875 + 32 * eps - 64 * eps) / 2.0, normal))
    out = sweep_rows(precision, np.array([r[0] for r in rows], dtype=float),
                     np.array([r[1] for r in rows], dtype=float),
                     np.array([r[2] for r in rows], dtype=float),
                     np.array([r[3] for r in rows]))
    for k, (_, _, _, _, t, normal) in enumerate(rows):
        assert out["hit"][k] == 1, k
        assert out["t"][k] == pytest.approx(t, abs=4 * eps), k
        np.testing.assert_array_equal(out["normal"][k], normal, err_msg=str(k))
