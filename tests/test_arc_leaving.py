"""An arc that bounces off a box leaves that box out of its next query only when it cannot meet
it again in the frame (``nearest_arc.leaving_funcs``' ``leaves_for_the_frame``).

- Against the float64 reference: over rotated, rounded, flat and sharp boxes, contacts on
  faces, edges and corners, gravity along, against and across the normal (and none), outgoing
  normal speeds around the return-time margin, zero and inward: whenever the rule leaves the
  box out, the rest of the arc stays outside it (the reference finds no contact from just
  after the bounce to the frame's end, and its signed distance stays positive at dense
  samples), and the rule never leaves out an arc moving into the box or along it.
- In a simulation: balls hopping on a floor, under a ceiling and along a wall, several hops a
  frame, their return times on both sides of the margin, end where the analytic hops put them
  (a box left out wrongly lets a ball through the floor).
"""

from functools import cache

import numpy as np
import pytest
import warp as wp
from arc_reference import arc_contact_by_features, arc_point, signed_distance

import warpsim as ws
from warpsim.kernels.nearest_arc import RETURN_MARGIN, leaving_funcs
from warpsim.kernels.precision import precision as types_of
from warpsim.kernels.variant import variant_kernel

G = 9.81


@cache
def leaving_kernel(name: str):
    p = types_of(name)
    scalar, vec3 = p.scalar, p.vec3
    leaves_for_the_frame = leaving_funcs(p).leaves_for_the_frame

    @variant_kernel
    def run(v: wp.array[vec3], g: wp.array[vec3], n: wp.array[vec3], rest: wp.array[scalar],
            out: wp.array[wp.int32]):
        i = wp.tid()
        out[i] = leaves_for_the_frame(v[i], g[i], n[i], rest[i])

    return run


def leaves(precision, v, g, n, rest) -> np.ndarray:
    """The kernel's verdicts, and the inputs as the kernel read them (float64)."""
    p = types_of(precision)
    rows = [np.ascontiguousarray(x, dtype=p.np_dtype) for x in (v, g, n, rest)]
    arrays = [wp.array(x, dtype=p.vec3 if x.ndim == 2 else p.scalar, device="cpu")
              for x in rows]
    out = wp.full(len(rest), -1, dtype=wp.int32, device="cpu")
    wp.launch(leaving_kernel(precision), dim=len(rest), inputs=[*arrays, out], device="cpu")
    return out.numpy(), [x.astype(np.float64) for x in rows]


def rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def contacts(rng, count: int):
    """Contacts on rounded boxes in their local frames: ``(h, radius, point, normal)`` with
    the point on the Minkowski surface and its outward unit normal, on faces, edges and
    corners (the nearest core point of a far point), of boxes sharp (radius 0) and flat (a
    zero half extent) among them."""
    out = []
    for _ in range(count):
        h = rng.uniform(0.05, 2.0, 3)
        if rng.random() < 0.2:
            h[rng.integers(3)] = 0.0
        radius = 0.0 if rng.random() < 0.3 else rng.uniform(0.01, 0.5)
        far = rng.normal(size=3)
        kind = rng.integers(3)  # face, edge or corner: how many axes stick out
        far = np.sign(far) * (h + rng.uniform(0.1, 1.0, 3))
        inside = rng.permutation(3)[:2 - kind]
        far[inside] = rng.uniform(-1.0, 1.0, len(inside)) * h[inside]
        core = np.clip(far, -h, h)
        normal = (far - core) / np.linalg.norm(far - core)
        out.append((h, radius, core + radius * normal, normal))
    return out


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_an_arc_left_out_never_meets_its_box_again_in_the_frame(precision):
    rng = np.random.default_rng(41)
    count = 1500
    cases = contacts(rng, count)
    rot = [rotation(rng) for _ in range(count)]
    n_world = np.array([r @ c[3] for r, c in zip(rot, cases, strict=True)])
    rest = 10.0 ** rng.uniform(-4, -0.5, count)
    # gravity: along the normal, against it, across it or none, of any strength
    g = rng.normal(size=(count, 3)) * 10.0 ** rng.uniform(-1, 1.5, (count, 1))
    which = rng.integers(4, size=count)
    g[which == 0] = 0.0
    g[which == 1] = -np.abs(rng.normal(size=(np.sum(which == 1), 1))) * 9.81 * n_world[which == 1]
    gn = np.einsum("ij,ij->i", g, n_world)
    # outgoing normal speed: around the margin's return time, and zero or inward now and then
    pull = np.maximum(-gn, 0.0) * rest
    vn = pull * rng.uniform(0.2, 2.5, count) + (pull == 0) * rng.uniform(0.0, 2.0, count)
    vn[rng.random(count) < 0.05] = 0.0
    inward = rng.random(count) < 0.05
    vn[inward] = -rng.uniform(1e-6, 1.0, np.sum(inward))
    tangent = rng.normal(size=(count, 3)) * rng.uniform(0.0, 5.0, (count, 1))
    tangent -= np.einsum("ij,ij->i", tangent, n_world)[:, None] * n_world
    v = tangent + vn[:, None] * n_world
    out, (v32, g32, n32, rest32) = leaves(precision, v, g, n_world, rest)
    assert set(np.unique(out)) <= {0, 1}
    speed = np.linalg.norm(v32, axis=1)
    vn_read = np.einsum("ij,ij->i", v32, n32)  # the normal speed of the values read
    grazing = np.abs(vn_read) <= 1e-6 * speed  # along the surface, to the inputs' rounding
    assert np.all(out[inward & ~grazing] == 0)  # into the box: never left out
    left = np.flatnonzero(out == 1)
    assert 0.3 * count < len(left) < 0.95 * count  # both verdicts are tested
    eps = np.finfo(types_of(precision).np_dtype).eps
    for i in left:
        h, radius, point, _ = cases[i]
        to_local = rot[i].T
        vl, gl, tau = to_local @ v32[i], to_local @ g32[i], float(rest32[i])
        samples = np.linspace(0.0, tau, 513)[1:]
        x = arc_point(point, vl, gl, samples)
        gap = signed_distance(x, h, radius)
        if grazing[i]:  # along the surface: off it to the rounding of the normal speed
            scale = np.abs(x).max() + speed[i] * tau
            assert np.all(gap > -16 * eps * scale), (i, gap.min())
            continue
        assert np.all(gap > 0.0), (i, gap.min())
        # the reference starts outside: just after the bounce, the rest of the frame from there
        s0 = 1e-6 * tau
        start = arc_point(point, vl, gl, s0)
        hit, s, _ = arc_contact_by_features(start, vl + gl * s0, gl, tau - s0, h, radius)
        assert not hit, (i, s)
    # where the rule keeps the box, the return time is within the margin (or the arc does not
    # move out): it never keeps a box the margin leaves out by far
    far_enough = (vn > 1e-3 * speed) & (vn >= 0.5 * RETURN_MARGIN * pull * (1 + 1e-2))
    assert not np.any((out == 0) & far_enough)


def hop_scene(normal_axis: int, sign: float, dt: float):
    """A slab whose face, normal to ``normal_axis`` and facing ``sign``, is the plane at 0."""
    center = np.zeros(3)
    center[normal_axis] = -sign * 0.5
    half = np.full(3, 50.0)
    half[normal_axis] = 0.5
    return ws.Scene(ws.RoundedBoxes(center=[center], half_extents=[half]), motion="ballistic",
                    energy_correction=False, dt=dt)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_balls_hopping_several_times_a_frame_follow_their_hops(precision):
    """Elastic balls of radius r hopping on a floor (gravity pulls them back), with their hop
    periods from a fifth to five times a frame: each hop ends on the floor and the next starts
    there, so after T seconds the height is that of the hop's phase, ``vn tau - g tau^2 / 2``
    with ``tau = T mod (2 vn / g)``."""
    dt = 0.1
    r = 0.05
    rng = np.random.default_rng(8)
    n = 64
    period = dt * np.geomspace(0.2, 5.0, n)
    vn = 0.5 * G * period
    x = np.column_stack([rng.uniform(-10, 10, n), np.full(n, r), rng.uniform(-10, 10, n)])
    u = np.column_stack([rng.uniform(-1, 1, n), vn, rng.uniform(-1, 1, n)])
    sim = ws.Simulator(hop_scene(1, 1.0, dt), ws.Swarm(x, u, radius=r), precision=precision,
                       device="cpu")
    frames = 30
    sim.step(frames)
    t = frames * dt
    phase = np.mod(t, period)
    y = r + vn * phase - 0.5 * G * phase ** 2
    state = sim.state()
    tol = 2e-3 if precision == "float32" else 1e-7
    np.testing.assert_allclose(state.position[:, 1], y, atol=tol)
    np.testing.assert_allclose(state.position[:, [0, 2]], x[:, [0, 2]] + u[:, [0, 2]] * t,
                               atol=tol)
    assert sim.stats.bounces == int(np.sum(np.floor(t / period + 1e-9)))


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_balls_bouncing_off_a_ceiling_and_along_a_wall_never_come_back_in_the_frame(
        precision):
    """Off a ceiling (gravity pulls away from it) and off a wall (gravity along it) the arc
    never returns to the box: one bounce each, then free flight, at any speed."""
    dt = 0.1
    r = 0.05
    rng = np.random.default_rng(9)
    n = 40
    speed = np.geomspace(0.05, 50.0, n)
    # a ceiling: the slab above y = 0, facing down; balls just under it moving up
    x = np.column_stack([rng.uniform(-5, 5, n), np.full(n, -r - 1e-6), rng.uniform(-5, 5, n)])
    u = np.column_stack([np.zeros(n), speed, np.zeros(n)])
    sim = ws.Simulator(hop_scene(1, -1.0, dt), ws.Swarm(x, u, radius=r), precision=precision,
                       device="cpu")
    sim.step(10)
    state = sim.state()
    assert np.all(state.position[:, 1] < -r + 1e-6)
    assert sim.stats.bounces == n
    # a wall: the slab beyond x = 0, facing -x; balls moving into it
    x = np.column_stack([np.full(n, -r - 1e-6), rng.uniform(0, 5, n), rng.uniform(-5, 5, n)])
    u = np.column_stack([speed, np.zeros(n), np.zeros(n)])
    sim = ws.Simulator(hop_scene(0, -1.0, dt), ws.Swarm(x, u, radius=r), precision=precision,
                       device="cpu")
    sim.step(10)
    state = sim.state()
    assert np.all(state.position[:, 0] < -r + 1e-6)
    np.testing.assert_allclose(state.velocity[:, 0], -speed, rtol=1e-5)
