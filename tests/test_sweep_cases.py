"""Named cases for the single-box sweep, each with an analytic answer.

Most cases are built backwards (Jolt's habit): pick the contact centre ``P`` on the Minkowski
surface with its outward normal ``n``, a direction ``d`` with ``d . n < 0`` and a fraction ``t``,
and start at ``A = P - t d``. For a convex body the first contact of that segment is ``P`` at
``t``, so the expected answer needs no second implementation. Fractions are exact in binary.
"""

import math

import numpy as np
import pytest
from helpers import TOLERANCES

import warpsim as ws

SQ2 = math.sqrt(0.5)
SQ3 = math.sqrt(1.0 / 3.0)
Q_Z90 = (0.0, 0.0, SQ2, SQ2)  # 90 degrees about z: local x -> world y


def _quat_matrix(q):
    return ws.obstacles.quat_to_matrix(np.array(q, dtype=np.float64))


def backwards(box: ws.RoundedBox, r, local_point, local_normal, d_world, t):
    """Start point so that the segment ``A -> A + d`` first touches at ``t`` (float64)."""
    m = _quat_matrix(box.rotation)
    p = box.center + m @ np.asarray(local_point, float)
    n = m @ np.asarray(local_normal, float)
    n = n / np.linalg.norm(n)
    d = np.asarray(d_world, float)
    assert d @ n < 0
    return p - t * d, d, p, n


BOX = ws.RoundedBox(center=(0.0, 0.0, 0.0), half_extents=(1.0, 0.5, 0.25), radius=0.25)
R = BOX.radius + 0.25  # sphere radius 0.25 below
ROT_BOX = ws.RoundedBox(center=(0.5, -1.0, 2.0), half_extents=(1.0, 0.5, 0.25),
                        rotation=(0.1, 0.7, -0.3, 0.6), radius=0.125)


def _edge_point(box, rr, sx, sy, z):
    h = box.half_extents
    n = np.array([sx * SQ2, sy * SQ2, 0.0])
    return np.array([sx * h[0], sy * h[1], z]) + rr * n, n


def _corner_point(box, rr, s):
    h = box.half_extents
    n = np.asarray(s, float) * SQ3
    return np.asarray(s, float) * h + rr * n, n


# name, box, sphere radius, local contact, local normal, world direction (dt = 1), t
HIT_CASES = []
for name, box in (("axis", BOX), ("rotated", ROT_BOX)):
    rr = box.radius + 0.25
    h = box.half_extents
    m = _quat_matrix(box.rotation)
    HIT_CASES += [
        (f"{name}-face+x", box, 0.25, [h[0] + rr, 0.25, -0.125], [1, 0, 0],
         m @ [-4.0, 0.5, 0.25], 0.5),
        (f"{name}-face-y", box, 0.25, [0.5, -(h[1] + rr), 0.0], [0, -1, 0],
         m @ [0.0, 2.0, 0.0], 0.25),
        (f"{name}-face+z-oblique", box, 0.25, [-0.75, 0.375, h[2] + rr], [0, 0, 1],
         m @ [1.0, -1.0, -3.0], 0.75),
        (f"{name}-edge", box, 0.25, *_edge_point(box, rr, 1, 1, 0.1), m @ [-1.0, -2.0, 0.5],
         0.5),
        (f"{name}-edge-along-its-axis", box, 0.25, *_edge_point(box, rr, -1, 1, 0.2),
         m @ [2.0, -1.0, 0.0], 0.25),
        (f"{name}-corner", box, 0.25, *_corner_point(box, rr, (1, 1, 1)), m @ [-1.0, -1.0, -1.0],
         0.5),
        (f"{name}-corner-oblique", box, 0.25, *_corner_point(box, rr, (-1, 1, -1)),
         m @ [3.0, -1.0, 0.5], 0.75),
    ]

PLATE = ws.RoundedBox(center=(0.0, 0.0, 0.0), half_extents=(1.0, 0.0, 1.0))
STICK = ws.RoundedBox(center=(0.0, 0.0, 0.0), half_extents=(1.0, 0.0, 0.0), radius=0.05)
POINT = ws.RoundedBox(center=(0.0, 0.0, 0.0), half_extents=(0.0, 0.0, 0.0), radius=0.5)
SHARP = ws.RoundedBox(center=(0.0, 0.0, 0.0), half_extents=(1.0, 0.5, 0.25))
HIT_CASES += [
    ("plate-face", PLATE, 0.125, [0.25, 0.125, 0.5], [0, 1, 0], [0.5, -1.0, 0.0], 0.5),
    ("plate-rim", PLATE, 0.125, [1.125, 0.0, 0.0], [1, 0, 0], [-1.0, 0.0, 0.0], 0.5),
    ("stick-side", STICK, 0.125, [0.5, 0.0, 0.175], [0, 0, 1], [0.0, 0.5, -1.0], 0.25),
    ("stick-end", STICK, 0.125, [1.175, 0.0, 0.0], [1, 0, 0], [-2.0, 0.0, 0.0], 0.5),
    ("point", POINT, 0.25, [0.0, 0.75, 0.0], [0, 1, 0], [0.0, -1.0, 0.0], 0.5),
    ("point-oblique", POINT, 0.25, [0.75 * SQ3, 0.75 * SQ3, 0.75 * SQ3], [1, 1, 1],
     [-1.0, -0.5, -0.25], 0.5),
    ("sharp-box-point", SHARP, 0.0, [1.0, 0.25, 0.125], [1, 0, 0], [-1.0, 0.0, 0.0], 0.5),
    ("zero-x-and-z-direction", BOX, 0.25, [0.0, 0.5 + R, 0.0], [0, 1, 0], [0.0, -2.0, 0.0],
     0.5),
]


@pytest.mark.slow
@pytest.mark.parametrize("case", HIT_CASES, ids=[c[0] for c in HIT_CASES])
def test_hit_built_backwards(case, precision, device):
    name, box, r, lp, ln, d, t = case
    tol = TOLERANCES[precision]
    a, d, p, n = backwards(box, r, lp, ln, d, t)
    c = ws.collide_box(a[None], d[None], r, box, 1.0, device=device, precision=precision)
    assert c.hit[0], name
    scale = max(1.0, np.abs(a).max())
    assert abs(c.t[0] - t) <= tol["t_abs"] * scale, (c.t[0], t)
    np.testing.assert_allclose(c.position[0], p, atol=tol["rel"] * scale)
    np.testing.assert_allclose(c.normal[0], n, atol=tol["angle"])
    v_ref = d - 2.0 * (d @ n) * n
    np.testing.assert_allclose(c.new_velocity[0], v_ref, atol=tol["rel"] * 4 * scale)
    np.testing.assert_allclose(c.new_position[0], p + (1.0 - t) * v_ref,
                               atol=tol["rel"] * 4 * scale)
    assert c.box[0] == 0


def _one(a, v, r, box, precision="float32", dt=1.0, device="cpu"):
    c = ws.collide_box(np.array([a], float), np.array([v], float), r, box, dt, device=device,
                       precision=precision)
    return c


@pytest.mark.parametrize("case", [
    # name, start, velocity: no contact expected
    ("leaving-face", [0.0, 0.5 + R, 0.0], [0.0, 1.0, 0.0]),
    ("along-face", [0.0, 0.5 + R, 0.0], [1.0, 0.0, 0.25]),
    ("on-top-plane-past-the-box", [-4.0, 0.5 + R, 0.0], [8.0, 0.0, 0.0]),
    ("zero-velocity-on-surface", [0.0, 0.5 + R, 0.0], [0.0, 0.0, 0.0]),
    ("zero-velocity-far", [5.0, 5.0, 5.0], [0.0, 0.0, 0.0]),
    ("stops-short", [-4.0, 0.0, 0.0], [2.5 - 1e-3, 0.0, 0.0]),
    ("parallel-outside-slab", [-4.0, 0.5 + R + 1e-3, 0.0], [8.0, 0.0, 0.0]),
    ("passes-corner-diagonal", [3.0, 0.0, 3.0], [-3.0, 0.0, 3.0]),
    ("inside-moving-out", [0.0, 0.0, 0.0], [0.0, 3.0, 0.0]),
], ids=lambda c: c[0])
def test_no_hit(case, precision):
    name, a, v = case
    c = _one(a, v, 0.25, BOX, precision)
    assert not c.hit[0], (name, c.t[0], c.normal[0])
    assert c.t[0] == 1.0 and c.box[0] == -1
    np.testing.assert_array_equal(c.normal[0], 0.0)
    np.testing.assert_allclose(c.new_position[0], np.add(a, v), rtol=1e-6)
    np.testing.assert_array_equal(c.new_velocity[0], np.asarray(v, c.t.dtype))


@pytest.mark.parametrize("start,velocity,normal", [
    ([0.0, 0.5 + R, 0.0], [0.5, -1.0, 0.0], [0, 1, 0]),  # on the top face, moving in
    ([1.0 + R * SQ2, 0.5 + R * SQ2, 0.0], [-1.0, -1.0, 0.0], [SQ2, SQ2, 0]),  # on an edge
    ([0.0, 0.25, 0.0], [0.0, -1.0, 0.0], [0, 1, 0]),  # inside the core, moving deeper
], ids=["on-face", "on-edge", "inside"])
def test_start_in_contact_moving_in_is_hit_at_zero(start, velocity, normal, precision):
    c = _one(start, velocity, 0.25, BOX, precision)
    assert c.hit[0] and c.t[0] == 0.0
    np.testing.assert_allclose(c.normal[0], normal, atol=TOLERANCES[precision]["angle"])
    np.testing.assert_allclose(c.position[0], start, atol=1e-6)


def test_sharp_box_edge_sliding_path_is_a_face_hit():
    """A path on the top plane of a sharp box crosses the -x face plane at its top edge: the
    closed box is touched there, the motion goes into that face, so it is a hit (the
    OBB entry) with the face normal."""
    c = _one([-4.0, 0.5, 0.0], [4.0, 0.0, 0.0], 0.0, SHARP)
    assert c.hit[0] and c.t[0] == pytest.approx(0.75)
    np.testing.assert_array_equal(c.normal[0], [-1.0, 0.0, 0.0])


def test_reflected_velocity_never_points_in_near_grazing(device):
    """Paths that pass an edge at distance R (1 +- 1e-k): consistent hit or miss, finite, the
    reflected velocity leaves the surface and hits stay on the near side."""
    rng = np.random.default_rng(7)
    n = 2000
    offsets = R * (1.0 + rng.choice([-1, 1], n) * 10.0 ** -rng.uniform(1, 7, n))
    # lines along z passing the edge x = 1, y = 0.5 (core) at the offset, in the xy diagonal
    a = np.stack([1.0 + offsets * SQ2, 0.5 + offsets * SQ2, np.full(n, -3.0)], axis=1)
    a[:, :2] += rng.normal(0.0, 1e-3, (n, 2)) * (offsets < R)[:, None]
    v = np.stack([-rng.uniform(0, 1e-2, n), -rng.uniform(0, 1e-2, n), np.full(n, 6.0)], axis=1)
    for precision in ("float32", "float64"):
        c = ws.collide_box(a, v, 0.25, BOX, 1.0, precision=precision, device=device)
        for f in ("t", "position", "normal", "new_position", "new_velocity"):
            assert np.isfinite(getattr(c, f)).all(), f
        hit = c.hit
        assert np.all(np.einsum("ij,ij->i", c.new_velocity[hit], c.normal[hit]) > 0.0)
        assert np.all(np.einsum("ij,ij->i", v[hit], c.normal[hit]) < 0.0)


def test_far_from_origin_gives_same_answer(device):
    """The same scene translated by 1e4 m (exact in float32) gives the same t and normal."""
    rng = np.random.default_rng(3)
    n = 500
    # 1/64 steps: exact at 1e4 in float32; aimed near the box so that most hit
    a = ROT_BOX.center + np.round(rng.uniform(-3, 3, (n, 3)) * 64) / 64
    v = np.round(((ROT_BOX.center - a) * 0.75 + rng.normal(0, 0.5, (n, 3))) * 64) / 64
    shift = np.array([1.0e4, -1.0e4, 1.0e4])
    box_far = ws.RoundedBox(center=ROT_BOX.center + shift, half_extents=ROT_BOX.half_extents,
                            rotation=ROT_BOX.rotation, radius=ROT_BOX.radius)
    near = ws.collide_box(a, v, 0.25, ROT_BOX, 1.0, device=device)
    far = ws.collide_box(a + shift, v, 0.25, box_far, 1.0, device=device)
    np.testing.assert_array_equal(near.hit, far.hit)
    assert near.hit.sum() > 50
    np.testing.assert_array_equal(near.t, far.t)
    np.testing.assert_array_equal(near.normal, far.normal)
    # positions agree to float32 resolution at 1e4 (one ulp is ~1e-3 m there)
    np.testing.assert_allclose(far.position - shift, near.position, atol=2e-3)


@pytest.mark.parametrize("speed", [600.0, 5000.0])
def test_thin_plate_at_high_speed_never_tunnels(device, speed, precision):
    """A plate of zero thickness stops every sphere aimed at it, whatever the speed."""
    n = 256
    rng = np.random.default_rng(11)
    r = 0.01
    a = np.column_stack([rng.uniform(-0.9, 0.9, n), np.full(n, 10.0), rng.uniform(-0.9, 0.9, n)])
    v = np.column_stack([rng.uniform(-1, 1, n), np.full(n, -speed), rng.uniform(-1, 1, n)])
    dt = 1.0 / 60.0
    c = ws.collide_box(a, v, r, PLATE, dt, precision=precision, device=device)
    assert c.hit.all()
    t_exact = (10.0 - r) / (speed * dt)
    np.testing.assert_allclose(c.t, t_exact, rtol=TOLERANCES[precision]["rel"] * 10)
    assert np.all(c.new_position[:, 1] >= r - 1e-4)
    np.testing.assert_allclose(c.normal, np.tile([0.0, 1.0, 0.0], (n, 1)), atol=1e-6)


def test_inputs_not_modified_and_results_are_copies(device):
    a = np.array([[-4.0, 0.0, 0.0]])
    v = np.array([[4.0, 0.0, 0.0]])
    r = np.array([0.25])
    before = (a.copy(), v.copy(), r.copy())
    ws.collide_box(a, v, r, BOX, 1.0, device=device)
    for x, y in zip((a, v, r), before, strict=True):
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("kwargs,message", [
    (dict(position=[[0, 0, 0], [np.nan, 0, 0]]), r"position\[1\] must be finite"),
    (dict(velocity=[[0, 0, 0], [0, np.inf, 0]]), r"velocity\[1\] must be finite"),
    (dict(radius=[0.1, -0.1]), r"radius\[1\] must be >= 0"),
    (dict(dt=0.0), r"dt must be > 0"),
    (dict(dt=-1.0), r"dt must be > 0"),
    (dict(position=[[0, 0]]), r"position must have shape \(N, 3\)"),
    (dict(velocity=[[0, 0, 0]]), r"velocity must have shape \(2, 3\)"),
    (dict(precision="float16"), r"precision must be one of"),
])
def test_bad_input_names_field_and_index(device, kwargs, message):
    args = dict(position=[[0, 0, 0], [1, 1, 1]], velocity=[[1, 0, 0], [1, 0, 0]], radius=0.1,
                dt=0.1)
    args.update(kwargs)
    precision = args.pop("precision", "float32")
    with pytest.raises(ValueError, match=message):
        ws.collide_box(args["position"], args["velocity"], args["radius"], BOX, args["dt"],
                       precision=precision, device=device)


@pytest.mark.parametrize("kwargs,message", [
    (dict(half_extents=(1, -0.5, 1)), r"half_extents\[1\] must be >= 0, got -0.5"),
    (dict(rotation=(0, 0, 0, 0)), r"rotation must be a finite non-zero quaternion"),
    (dict(radius=-0.1), r"radius must be >= 0"),
    (dict(center=(0, np.nan, 0)), r"center must be finite"),
])
def test_bad_box_names_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ws.RoundedBox(**kwargs)


def test_boxes_group_errors_name_index():
    with pytest.raises(ValueError, match=r"half_extents\[2\]"):
        ws.RoundedBoxes(center=np.zeros((3, 3)), half_extents=[[1, 1, 1], [1, 1, 1], [1, -1, 1]])
    with pytest.raises(ValueError, match=r"radius\[1\] must be >= 0"):
        ws.RoundedBoxes(center=np.zeros((2, 3)), half_extents=np.ones((2, 3)), radius=[0, -1])
    with pytest.raises(ValueError, match=r"rotation\[1\] must be a non-zero quaternion"):
        ws.RoundedBoxes(center=np.zeros((2, 3)), half_extents=np.ones((2, 3)),
                        rotation=[[0, 0, 0, 1], [0, 0, 0, 0]])
