"""No sphere starts inside an obstacle: ``feasibility.check_outside`` and the nearest-box query.

Spheres are built backwards from the contact they should have: a point ``q0`` on the core box
(a face, an edge or a corner), an outward direction ``u`` whose nearest core point is ``q0``,
and the centre ``q0 + (rb + r - depth) u`` in the box's frame, whose surface is then exactly
``depth`` inside the rounded box. No Warp kernel runs here.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import shaped_half_extents

import warpsim as ws
from warpsim import blocks, feasibility, obstacles
from warpsim.obstacles import quat_to_matrix

KINDS = ("box", "plate", "stick", "point", "cube")
FEATURES = ("face", "edge", "corner")
EPS = {"float32": float(np.finfo(np.float32).eps), "float64": float(np.finfo(np.float64).eps)}


def _unit_quaternions(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _contact(rng, h, feature):
    """``(q0, u)``: a point of the core box ``[-h, h]`` and a unit outward direction from it
    whose nearest core point is ``q0``."""
    sign = rng.choice([-1.0, 1.0], 3)
    q0 = rng.uniform(-1.0, 1.0, 3) * h
    u = np.zeros(3)
    axes = rng.permutation(3)
    if feature == "face":
        a = axes[0]
        q0[a], u[a] = sign[a] * h[a], sign[a]
    elif feature == "edge":
        a, b = axes[:2]
        theta = rng.uniform(0.05, np.pi / 2 - 0.05)
        q0[a], q0[b] = sign[a] * h[a], sign[b] * h[b]
        u[a], u[b] = sign[a] * np.cos(theta), sign[b] * np.sin(theta)
    else:
        q0 = sign * h
        u = sign * np.abs(rng.normal(size=3)) + sign * 0.05
        u /= np.linalg.norm(u)
    return q0, u


def _scene(rng, kind, feature, n, depth, offset=0.0):
    """``n`` boxes 10 m apart (one per sphere, rotated, rounded or not) and one sphere touching
    each, its surface ``depth[i]`` inside (``depth`` may be a function of the radii and the box
    centres); returns
    ``(boxes, position, radius, depth)``."""
    centers = offset + 10.0 * np.stack([np.arange(n) % 10, (np.arange(n) // 10) % 10,
                                        np.arange(n) // 100], axis=1).astype(float)
    halves = np.array([shaped_half_extents(rng, kind, 0.1, 1.0) for _ in range(n)])
    rounding = np.where(rng.uniform(size=n) < 0.5, 0.0, rng.uniform(0.01, 0.3, n))
    rotation = _unit_quaternions(rng, n)
    boxes = ws.RoundedBoxes(centers, halves, rotation, rounding)
    radius = rng.uniform(0.05, 0.3, n)
    depth = depth(radius, centers) if callable(depth) else depth
    position = np.empty((n, 3))
    for i in range(n):
        q0, u = _contact(rng, halves[i], feature)
        local = q0 + (rounding[i] + radius[i] - depth[i]) * u
        position[i] = centers[i] + quat_to_matrix(boxes.rotation[i]) @ local
    return boxes, position, radius, depth


@pytest.mark.slow
@pytest.mark.parametrize("feature", FEATURES)
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("offset", [0.0, 1e4])
def test_touching_or_a_few_ulps_in_is_legal(precision, kind, feature, offset):
    rng = np.random.default_rng([KINDS.index(kind), FEATURES.index(feature), int(offset)])
    n = 60

    def depth(radius, centers):  # every other one in contact, the others two ulps in
        ulp = EPS[precision] * np.abs(centers).max(axis=1)
        return np.where(np.arange(n) % 2 == 0, 0.0, 2.0 * ulp)

    boxes, position, radius, _ = _scene(rng, kind, feature, n, depth, offset)
    feasibility.check_outside(boxes, position, radius, precision)
    # and clear of every box is legal, of course
    feasibility.check_outside(boxes, position, radius * 0.5, precision)


@pytest.mark.slow
@pytest.mark.parametrize("feature", FEATURES)
@pytest.mark.parametrize("kind", KINDS)
def test_inside_is_refused_naming_sphere_box_and_depth(precision, kind, feature):
    rng = np.random.default_rng([7, KINDS.index(kind), FEATURES.index(feature)])
    n = 40
    inside = [13, 21, 38]

    def depth(radius, centers):  # half a radius in, far beyond any rounding, for three of them
        out = np.zeros(n)
        out[inside] = 0.5 * radius[inside]
        return out

    boxes, position, radius, depth = _scene(rng, kind, feature, n, depth)
    i = inside[0]
    p = position[i]
    with pytest.raises(ValueError) as info:
        feasibility.check_outside(boxes, position, radius, precision)
    assert str(info.value) == (
        f"sphere {i} starts {depth[i]:.3g} m inside box {i} (position ({p[0]:g}, {p[1]:g}, "
        f"{p[2]:g}), radius {radius[i]:g}): spheres must start outside the obstacles or "
        f"touching them; 3 of {n} spheres start inside")


def test_tolerance_scales_with_the_precision_and_the_coordinates():
    rng = np.random.default_rng(3)
    offset = 1e4
    # four float32 ulps in at 1e4 m: rounding for float32 kernels, a real overlap in float64
    depth = np.full(20, 4.0 * EPS["float32"] * offset)
    boxes, position, radius, _ = _scene(rng, "box", "face", 20, depth, offset)
    feasibility.check_outside(boxes, position, radius, "float32")
    with pytest.raises(ValueError, match=r"^sphere 0 starts 0.00477 m inside box 0 "):
        feasibility.check_outside(boxes, position, radius, "float64")
    # the same depth near the origin is refused in both
    boxes, position, radius, _ = _scene(rng, "box", "face", 20, depth, 0.0)
    for precision in ("float32", "float64"):
        with pytest.raises(ValueError, match=r"^sphere 0 starts 0.00477 m inside box 0 "):
            feasibility.check_outside(boxes, position, radius, precision)


@pytest.mark.parametrize("kind", KINDS)
def test_a_sphere_at_a_box_centre_is_as_deep_as_the_box_is_thin(kind):
    rng = np.random.default_rng(KINDS.index(kind))
    h = shaped_half_extents(rng, kind, 0.2, 1.0)
    box = ws.RoundedBoxes(center=[[1.0, 2.0, 3.0]], half_extents=[h],
                          rotation=_unit_quaternions(rng, 1), radius=[0.1])
    with pytest.raises(ValueError) as info:
        feasibility.check_outside(box, [[0.0, 0.0, 0.0], [1.0, 2.0, 3.0]], [0.0, 0.05], "float32")
    assert str(info.value).startswith(f"sphere 1 starts {h.min() + 0.15:.3g} m inside box 0 ")


def test_points_on_a_surface_are_legal_and_just_inside_are_not():
    plate = ws.RoundedBoxes(center=[[0.0, 0.0, 0.0]], half_extents=[[0.0, 1.0, 1.0]])
    feasibility.check_outside(plate, [[0.0, 0.5, 0.5], [1e-3, 0.0, 0.0]], 0.0, "float64")
    cube = ws.RoundedBoxes(center=[[0.0, 0.0, 0.0]], half_extents=[[1.0, 1.0, 1.0]])
    feasibility.check_outside(cube, [[1.0, 0.0, 0.0], [1.0, 1.0, 1.0]], 0.0, "float64")
    with pytest.raises(ValueError, match=r"^sphere 1 starts 0.001 m inside box 0 "):
        feasibility.check_outside(cube, [[1.0, 0.0, 0.0], [0.999, 0.0, 0.0]], 0.0, "float64")


def test_nothing_to_check_and_the_deepest_box_is_named():
    boxes = ws.RoundedBoxes(center=[[0.0, 0.0, 0.0], [0.5, 0.0, 0.0]],
                            half_extents=[[1.0, 1.0, 1.0], [1.0, 1.0, 1.0]])
    feasibility.check_outside(boxes, np.zeros((0, 3)), 0.1, "float32")
    with pytest.raises(ValueError, match=r"^sphere 0 starts 1 m inside box 1 "):
        feasibility.check_outside(boxes, [[0.6, 0.0, 0.0]], 0.1, "float32")


# --- the nearest-box query ---------------------------------------------------------------------


def _mixed_boxes(rng, k):
    """A floor, long walls, mid-sized blocks and many small pegs, rotated: every grid level."""
    size = np.concatenate([[50.0], rng.uniform(5.0, 20.0, k // 10),
                           rng.uniform(0.5, 2.0, k // 5), rng.uniform(0.01, 0.2, k)])[:k]
    halves = size[:, None] * rng.uniform(0.0, 1.0, (k, 3))
    halves[0] = (50.0, 0.5, 50.0)
    centers = rng.uniform(-30.0, 30.0, (k, 3))
    return ws.RoundedBoxes(centers, halves, _unit_quaternions(rng, k),
                           rng.uniform(0.0, 0.2, k) * (rng.uniform(size=k) < 0.5))


def _brute_nearest(boxes, points, within):
    d = boxes.signed_distance(points)
    best, index = d.min(axis=1), d.argmin(axis=1)
    near = best < within
    return np.where(near, best, np.inf), np.where(near, index, -1)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(6))
def test_nearest_is_the_brute_force_minimum_bit_for_bit(seed, monkeypatch):
    rng = np.random.default_rng(seed)
    if seed % 2:  # small chunks and grids: every boundary of the pair bookkeeping is crossed
        monkeypatch.setattr(obstacles, "PAIR_CHUNK", 7)
        monkeypatch.setattr(obstacles, "DIRECT_BOXES", 1)
    if seed % 3 != 2:  # blocks of points on threads, more threads than cores on a small machine
        monkeypatch.setattr(obstacles, "POINT_BLOCK", int(rng.integers(1, 200)))
        monkeypatch.setattr(blocks, "host_cores", lambda: 3)
    boxes = _mixed_boxes(rng, int(rng.integers(2, 400)))
    points = np.concatenate([rng.uniform(-40.0, 40.0, (600, 3)),
                             boxes.center[rng.integers(0, len(boxes), 50)]])  # at centres
    within = rng.uniform(-0.5, 2.0, points.shape[0])
    within[::5] = 0.0
    distance, index = boxes.nearest(points, within)
    expected_distance, expected_index = _brute_nearest(boxes, points, within)
    np.testing.assert_array_equal(distance, expected_distance)
    np.testing.assert_array_equal(index, expected_index)


@pytest.mark.parametrize("seed", range(8))
def test_candidate_pairs_are_each_point_box_pair_whose_bounds_hold_the_point_once(seed,
                                                                                   monkeypatch):
    """The pairs the nearest-box query evaluates: every (point, box) with the point inside the
    box's bounds, once, and no other (against a test of every pair), through every grid level
    and chunk boundary."""
    rng = np.random.default_rng(100 + seed)
    if seed % 2:
        monkeypatch.setattr(obstacles, "PAIR_CHUNK", int(rng.integers(1, 50)))
        monkeypatch.setattr(obstacles, "DIRECT_BOXES", int(rng.integers(0, 3)))
    boxes = _mixed_boxes(rng, int(rng.integers(1, 300)))
    points = np.concatenate([rng.uniform(-40.0, 40.0, (500, 3)),
                             boxes.center[rng.integers(0, len(boxes), 40)]])
    reach = boxes.world_extent() + rng.uniform(0.0, 2.0)
    lo, hi = boxes.center - reach, boxes.center + reach
    lo[0] = hi[0] = points[0]  # a box whose bounds are one point, and a point on them
    pairs = [np.stack(pair, axis=1) for pair in
             obstacles._candidate_pairs(lo, hi, np.arange(len(boxes)), points)]
    got = np.concatenate(pairs) if pairs else np.zeros((0, 2), dtype=np.int64)
    held = ((points[:, None, :] >= lo[None]) & (points[:, None, :] <= hi[None])).all(axis=2)
    expected = np.argwhere(held)
    assert all(pair.shape[0] <= obstacles.PAIR_CHUNK for pair in pairs)
    assert got.shape == expected.shape  # no pair twice, none missing, none extra
    np.testing.assert_array_equal(got[np.lexsort((got[:, 1], got[:, 0]))], expected)


def test_a_point_whose_cell_lists_more_boxes_than_a_chunk_is_split_across_chunks(monkeypatch):
    """Sixty copies of a box and a few others, seven pairs a chunk: a point among the copies
    has sixty pairs, which span chunks; every chunk holds at most seven, and the pairs and the
    nearest boxes are those of a test of every pair."""
    monkeypatch.setattr(obstacles, "PAIR_CHUNK", 7)
    monkeypatch.setattr(obstacles, "DIRECT_BOXES", 0)
    rng = np.random.default_rng(5)
    centers = np.concatenate([np.zeros((60, 3)), rng.uniform(-5.0, 5.0, (12, 3))])
    boxes = ws.RoundedBoxes(center=centers, half_extents=np.full((72, 3), 0.5), radius=0.1)
    points = np.concatenate([rng.uniform(-0.7, 0.7, (5, 3)), rng.uniform(-6.0, 6.0, (40, 3))])
    reach = boxes.world_extent() + 0.3
    lo, hi = boxes.center - reach, boxes.center + reach
    pairs = [np.stack(pair, axis=1) for pair in
             obstacles._candidate_pairs(lo, hi, np.arange(len(boxes)), points)]
    assert all(pair.shape[0] <= 7 for pair in pairs)
    got = np.concatenate(pairs)
    held = ((points[:, None, :] >= lo[None]) & (points[:, None, :] <= hi[None])).all(axis=2)
    assert held[:5, :60].all()  # the first points have sixty pairs each
    np.testing.assert_array_equal(got[np.lexsort((got[:, 1], got[:, 0]))], np.argwhere(held))
    distance, index = boxes.nearest(points, 0.3)
    expected_distance, expected_index = _brute_nearest(boxes, points, 0.3)
    np.testing.assert_array_equal(distance, expected_distance)
    np.testing.assert_array_equal(index, expected_index)


def test_nearest_ties_take_the_lowest_index_and_copies_are_found():
    boxes = ws.RoundedBoxes(center=[[0.0, 0.0, 0.0]] * 3 + [[5.0, 0.0, 0.0]],
                            half_extents=[[1.0, 1.0, 1.0]] * 4)
    distance, index = boxes.nearest([[0.0, 1.5, 0.0], [5.0, 0.0, 0.0], [20.0, 0.0, 0.0]], 1.0)
    assert distance.tolist() == [0.5, -1.0, np.inf]
    assert index.tolist() == [0, 3, -1]


@pytest.mark.slow
def test_a_million_spheres_among_ten_thousand_boxes_in_bounded_memory():
    rng = np.random.default_rng(11)
    k, n = 10_000, 1_000_000
    centers = np.c_[rng.uniform(-50, 50, k), rng.uniform(0, 10, k), rng.uniform(-50, 50, k)]
    halves = rng.uniform(0.01, 0.3, (k, 3))
    centers[0], halves[0] = (0.0, -0.5, 0.0), (60.0, 0.5, 60.0)  # a floor under all of it
    boxes = ws.RoundedBoxes(centers, halves, _unit_quaternions(rng, k))
    position = np.c_[rng.uniform(-50, 50, n), rng.uniform(0, 10, n), rng.uniform(-50, 50, n)]
    radius = 0.01
    distance, index = boxes.nearest(position, within=radius)
    sample = rng.choice(n, 500, replace=False)
    expected_distance, expected_index = _brute_nearest(boxes, position[sample], radius)
    np.testing.assert_array_equal(distance[sample], expected_distance)
    np.testing.assert_array_equal(index[sample], expected_index)
    clear = ~(distance - radius < 0.0)  # float64's tolerance (1e-13 m here) never matters
    feasibility.check_outside(boxes, position[clear], radius, "float64")
    first = int(np.flatnonzero(~clear)[0])
    with pytest.raises(ValueError, match=rf"^sphere {first} starts .* inside box "
                                         rf"{index[first]} .*; {int((~clear).sum())} of "
                                         rf"{n} spheres start inside$"):
        feasibility.check_outside(boxes, position, radius, "float64")
