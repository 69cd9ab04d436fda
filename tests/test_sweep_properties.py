"""Properties of the sweep over random rounded boxes and segments (hypothesis).

Each example draws one box and a batch of segments aimed around it, runs the kernels once, and
checks the sweep's invariants with the float64 signed distance of ``RoundedBoxes``, which is an
independent formula (distance to the core box minus the radius), not the kernels' method.
"""

import numpy as np
import pytest
from helpers import DEVICES, TOLERANCES, shaped_half_extents
from hypothesis import given, settings
from hypothesis import strategies as st

import warpsim as ws

BATCH = 256


@st.composite
def boxes_and_segments(draw):
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    kind = draw(st.sampled_from(["box", "plate", "stick", "point", "cube"]))
    h = shaped_half_extents(rng, kind, 0.05, 2.0)
    rb = draw(st.sampled_from([0.0, 0.01, 0.1, 0.5]))
    q = rng.normal(size=4)
    center = rng.uniform(-5, 5, 3)
    box = ws.RoundedBox(center=center, half_extents=h, rotation=q, radius=rb)
    r = draw(st.sampled_from([0.0, 0.02, 0.25]))
    if rb + r == 0.0 and kind in ("stick", "point"):
        r = 0.02  # a segment cannot meet a zero-volume target in general position
    reach = np.linalg.norm(h) + rb + r
    a = center + rng.normal(size=(BATCH, 3)) * 2.0 * reach
    target = center + rng.uniform(-1.2, 1.2, (BATCH, 3)) * (h + rb + r)
    d = (target - a) * rng.uniform(0.5, 2.0, (BATCH, 1))
    zero_axis = rng.random((BATCH, 3)) < 0.15  # zero direction components
    d[zero_axis] = 0.0
    return box, r, a, d


def _sd(box, pts):
    return box.as_boxes().signed_distance(pts)[:, 0]


@pytest.mark.slow
@pytest.mark.parametrize("device", DEVICES)
@settings(max_examples=80, deadline=None)
@given(case=boxes_and_segments(), precision=st.sampled_from(["float32", "float64"]))
def test_sweep_invariants(device, case, precision):
    box, r, a, d = case
    R = box.radius + r
    c = ws.collide_box(a, d, r, box, 1.0, precision=precision, device=device)
    tol = TOLERANCES[precision]
    scale = max(1.0, float(np.abs(a).max()), float(np.abs(a + d).max()))
    surface_tol = 50 * tol["rel"] * scale  # distance error of a computed contact [m]
    hit = c.hit
    for f in ("t", "position", "normal", "new_position", "new_velocity"):
        assert np.isfinite(getattr(c, f)).all(), f
    assert np.all((c.t >= 0.0) & (c.t <= 1.0))
    assert np.all(c.t[~hit] == 1.0)
    if hit.any():
        n = c.normal[hit].astype(np.float64)
        dh = d[hit]
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=tol["unit"] * 8)
        vn = c.new_velocity[hit].astype(np.float64)
        # speed kept by the reflection; the reflected velocity leaves the surface
        np.testing.assert_allclose(np.linalg.norm(vn, axis=1), np.linalg.norm(dh, axis=1),
                                   rtol=tol["rel"] * 4, atol=tol["rel"] * 4)
        assert np.all(np.einsum("ij,ij->i", vn, n) >= 0.0)
        assert np.all(np.einsum("ij,ij->i", dh, n) < 0.0)
        # the contact centre is on the inflated surface (or the start, when in contact)
        p = c.position[hit].astype(np.float64)
        sd = _sd(box, p) - r
        started_inside = _sd(box, a[hit]) - r <= 0.0
        assert np.all(np.abs(sd[~started_inside]) <= surface_tol), np.abs(sd).max()
        # nothing before t is inside: sample the segment up to the contact
        s = np.linspace(0.0, 1.0, 33)[:-1]
        for k in np.flatnonzero(~started_inside):
            pts = a[hit][k] + np.outer(s * c.t[hit][k], dh[k])
            assert (_sd(box, pts) - r).min() >= -surface_tol
        # the new position lies where the reflected rest of the path ends
        expect = p + (1.0 - c.t[hit, None]) * (dh - 2.0 * np.einsum("ij,ij->i", dh, n)[:, None] * n)
        np.testing.assert_allclose(c.new_position[hit], expect, atol=surface_tol * 4)
    # misses: the whole segment stays outside (a start in contact may leave or slide)
    miss = ~hit
    if miss.any():
        s = np.linspace(0.0, 1.0, 65)
        for k in np.flatnonzero(miss)[:64]:
            if R == 0.0:
                continue  # a segment may run along a sharp face without entering
            pts = a[k] + np.outer(s, d[k])
            start = _sd(box, a[k:k + 1])[0] - r
            depth = (_sd(box, pts) - r).min()
            assert depth >= min(start, 0.0) - surface_tol, (depth, start)


@st.composite
def group_scenes(draw):
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    k = draw(st.integers(2, 12))
    h = rng.uniform(0.0, 1.0, (k, 3))
    center = rng.uniform(-2, 2, (k, 3))
    if draw(st.booleans()):  # abutting: a row of boxes face to face, and exact duplicates
        h[:] = 0.5
        center = np.column_stack([np.arange(k) - k / 2.0, np.zeros(k), np.zeros(k)])
        rot = None
        if k > 3:
            center[3] = center[2]
    else:
        rot = rng.normal(size=(k, 4))
    boxes = ws.RoundedBoxes(center=center, half_extents=h, rotation=rot,
                            radius=rng.choice([0.0, 0.05, 0.2], k))
    a = rng.uniform(-6, 6, (BATCH, 3))
    d = rng.uniform(-2, 2, (BATCH, 3)) - a * rng.uniform(0, 1.5, (BATCH, 1))
    return boxes, a, d


@pytest.mark.slow
@pytest.mark.parametrize("device", DEVICES)
@settings(max_examples=40, deadline=None)
@given(scene=group_scenes(), precision=st.sampled_from(["float32", "float64"]))
def test_nearest_of_group_is_min_over_single_boxes(device, scene, precision):
    boxes, a, d = scene
    r = 0.1
    group = ws.collide_boxes(a, d, r, boxes, 1.0, precision=precision, device=device)
    singles = [ws.collide_box(a, d, r, boxes[k], 1.0, precision=precision, device=device)
               for k in range(len(boxes))]
    t_all = np.stack([np.where(s.hit, s.t, np.inf) for s in singles], axis=1)
    any_hit = np.isfinite(t_all).any(axis=1)
    np.testing.assert_array_equal(group.hit, any_hit)
    best = np.argmin(t_all, axis=1)  # argmin returns the lowest index on ties
    np.testing.assert_array_equal(group.box[any_hit], best[any_hit])
    np.testing.assert_array_equal(group.t[any_hit], t_all[any_hit, best[any_hit]])
    rows = np.flatnonzero(any_hit)
    for field in ("position", "normal", "new_position", "new_velocity"):
        ref = np.stack([getattr(singles[b], field)[i] for i, b in zip(rows, best[rows],
                                                                       strict=True)]) \
            if len(rows) else np.zeros((0, 3))
        np.testing.assert_array_equal(getattr(group, field)[any_hit], ref)
