"""The arc's piece walk (``kernels/arc.py``, ``walk_pieces``): face pieces reached over an edge.

An arc that enters the grown box in an edge region is walked piece by piece; when it rises
over the rounded edge and comes down on the face behind it, the contact is the falling root of
the face gap ``q(s) = c0 + c1 s + c2 s^2`` *inside the face piece*. The arcs here are exact in
binary (box ``h = (4, 1, 1)``, ``R = 1/8``, ``g = (0, -8, 0)``): ``y(s) = 19/16 - 4 (s - 1/2)^2``
reaches the top face plane ``y = 9/8`` at ``s = 5/8`` on its way down, ``x(s) = x0 + s / 2``
enters the grown box at ``x = -33/8`` at ``s = 5/16`` (``y = 67/64``: the edge region) and
crosses ``x = -4`` into the face region at ``s = 9/16`` (``y = 75/64``, falling, above the face
plane). The rounded edge is never touched in between (its distance stays above ``R``).

Answers: the closed forms above, or, for an arc that flies past a narrow face, the float64
26-feature reference. Units: [m], [m/s], [m/s^2], [s]; the box's local frame.
"""

import numpy as np
import pytest
from arc_reference import arc_contact_by_features, arc_point, signed_distance
from test_arc_funcs import RB as BOX_R
from test_arc_funcs import H as BOX_H
from test_arc_funcs import run_arcs
from test_arc_sweep import NORMAL_TOL, POSITION_REL

H = np.array([4.0, 1.0, 1.0])
R = 0.125
G = np.array([0.0, -8.0, 0.0])
V = np.array([0.5, 4.0, 0.0])
A = np.array([-4.28125, 0.1875, 0.0])
S_LAND = 0.625  # y(s) = 9/8, falling

#: A face only 2^-7 m half wide in x: the arc crosses it in [9/16, 19/32] and comes down
#: beside its far edge (the face plane's root 5/8 lies beyond the face piece).
NARROW_H = np.array([2.0**-7, 1.0, 1.0])
NARROW_A = np.array([-(2.0**-7) - R - 0.5 * 0.3125, 0.1875, 0.0])


def test_the_construction():
    """Self-check of the arcs above (float64, dense samples): the grown-box entry lies in the
    edge region, the arc stays outside the rounded box until it lands at ``5/8`` on the top
    face's rectangle, and the 26-feature reference agrees."""
    s = np.linspace(0.0, S_LAND, 40001)[:-1]
    x = arc_point(A, V, G, s)
    inside_grown = np.all(np.abs(x) <= H + R, axis=1)
    entry = x[np.argmax(inside_grown)]
    assert np.sum(np.abs(entry) > H) == 2
    assert signed_distance(x, H, R).min() > 0.0
    assert abs(arc_point(A, V, G, S_LAND)[0]) < H[0]
    hit, s_ref, n_ref = arc_contact_by_features(A, V, G, 1.0, H, R)
    assert hit and s_ref == pytest.approx(S_LAND, abs=1e-12)
    np.testing.assert_allclose(n_ref, [0.0, 1.0, 0.0], atol=1e-12)
    hit, s_ref, n_ref = arc_contact_by_features(NARROW_A, V, G, 1.0, NARROW_H, R)
    assert hit and s_ref > S_LAND and n_ref[0] > 0.05  # on the far edge's rounding


def test_lands_on_the_face_behind_the_edge(precision):
    """Over the edge and down onto the face: the contact at ``5/8`` with the face normal, also
    when ``tau`` is exactly ``5/8`` (a contact at the end of the span counts); ``tau = 0.6``
    ends with the arc above the face, falling: no hit. Past a narrow face the face plane's
    root lies beyond the face piece: the contact is the far edge's, from the reference."""
    a = np.array([A, A, A, NARROW_A, NARROW_A])
    h = np.array([H, H, H, NARROW_H, NARROW_H])
    tau = np.array([1.0, S_LAND, 0.6, 1.0, 0.5])
    out = run_arcs(precision, a, V, G, tau, h, R)
    s_tol = {"float32": 4e-6, "float64": 1e-14}[precision]
    for k in range(2):
        assert out["hit"][k] == 1, k
        assert out["s"][k] == pytest.approx(S_LAND, abs=s_tol), k
        np.testing.assert_array_equal(out["normal"][k], [0.0, 1.0, 0.0])
    short = np.float32(0.6) if precision == "float32" else 0.6
    assert out["hit"][2] == 0 and out["s"][2] == short
    np.testing.assert_array_equal(out["normal"][2], 0.0)
    _, s_ref, n_ref = arc_contact_by_features(NARROW_A, V, G, 1.0, NARROW_H, R)
    assert out["hit"][3] == 1
    radial = -np.dot(V + G * s_ref, n_ref)
    assert out["s"][3] == pytest.approx(s_ref, abs=1e3 * s_tol / radial)
    np.testing.assert_allclose(out["normal"][3], n_ref, atol=NORMAL_TOL[precision] / radial)
    # and with tau = 0.5 it has not reached the narrow face yet
    assert out["hit"][4] == 0 and out["s"][4] == 0.5


def seam_landings(rng, count, corner):
    """Arcs built backwards onto the seam between two patches of the rounded box (``H``, ``R``
    of ``test_arc_funcs``): a face and an edge cylinder (``corner=False``: the point is on the
    face plane, its coordinate ``j`` on ``+-h_j``) or an edge cylinder and a corner sphere
    (``corner=True``: on the cylinder, its coordinate ``k`` along the edge on ``+-h_k``),
    crossing the seam either way; there the two patches share the point and the normal, and
    the piece walk's boundary falls on the contact, so rounding decides which piece has it.

    Returns:
        ``(a, v, g, normal)`` rows; every arc reaches its seam point at ``s = 3/8`` moving in
        at least 0.3 steeply, from outside the supporting plane (so it is the first contact).
    """
    rows = []
    while len(rows) < count:
        i, j, k = rng.permutation(3)
        si, sj, sk = rng.choice([-1.0, 1.0], 3)
        point = np.empty(3)
        normal = np.zeros(3)
        if corner:
            phi = rng.uniform(0.1, 0.5 * np.pi - 0.1)
            point[i] = si * (BOX_H[i] + BOX_R * np.cos(phi))
            point[j] = sj * (BOX_H[j] + BOX_R * np.sin(phi))
            point[k] = sk * BOX_H[k]
            normal[i], normal[j] = si * np.cos(phi), sj * np.sin(phi)
            across = k
        else:
            point[i] = si * (BOX_H[i] + BOX_R)
            point[j] = sj * BOX_H[j]
            point[k] = rng.uniform(-0.9, 0.9) * BOX_H[k]
            normal[i] = si
            across = j
        u = rng.normal(0.0, 1.0, 3)
        u -= (np.dot(u, normal) + rng.uniform(0.5, 2.0)) * normal
        u[across] = rng.choice([-1.0, 1.0]) * rng.uniform(0.3, 1.5)  # across the seam
        g = rng.normal(0.0, 1.0, 3)
        g *= 9.81 / np.linalg.norm(g)
        un, gn = np.dot(u, normal), np.dot(g, normal)
        if -un < 0.3 * np.linalg.norm(u) or (gn < 0.0 and 0.375 >= 2.0 * abs(un) / abs(gn)):
            continue
        v = u - g * 0.375
        a = point - v * 0.375 - 0.5 * g * 0.375**2
        rows.append((a, v, g, normal))
    return [np.array(c) for c in zip(*rows, strict=True)]


@pytest.mark.parametrize("corner", [False, True], ids=["face-edge", "edge-corner"])
def test_landings_on_the_seams_between_patches(corner, precision):
    """Arcs landing exactly on a seam (face and edge, or edge and corner), crossing it either
    way: the contact at ``s = 3/8`` [s] with the shared normal (local frame), whichever of the
    two pieces meeting there rounding hands it to; the float64 reference agrees."""
    rng = np.random.default_rng(61 if corner else 62)
    a, v, g, normal = seam_landings(rng, 48, corner)
    for k in range(0, 48, 8):  # the construction, on a sample
        hit, s_ref, n_ref = arc_contact_by_features(a[k], v[k], g[k], 1.0, BOX_H, BOX_R)
        assert hit and s_ref == pytest.approx(0.375, abs=1e-9)
        np.testing.assert_allclose(n_ref, normal[k], atol=1e-9)
    out = run_arcs(precision, a, v, g, 1.0, BOX_H, BOX_R)
    s_tol = {"float32": 2e-5, "float64": 1e-12}[precision]
    np.testing.assert_array_equal(out["hit"], 1)
    np.testing.assert_allclose(out["s"], 0.375, atol=s_tol)
    np.testing.assert_allclose(out["normal"], normal, atol=NORMAL_TOL[precision])


#: Arcs near the +x+y edge of the ``test_arc_funcs`` box (``H = (1, 0.5, 0.25)``, ``R = 0.5``,
#: ``g = (0, -9.81, 0)``) whose first contact is on the edge cylinder, inside an edge piece
#: where ``F = |w|^2 - R^2`` is concave somewhere and either positive again at the piece's end
#: (the arc clips the rounding and leaves) or changes sign more than once: drawn from random
#: arcs built backwards onto the cylinder, kept where dense float64 samples showed that
#: (``test_clips_of_a_rounded_edge`` checks it again). ``(a, v, tau)``.
CLIPS = [
    ([0.693736, 1.139553, -0.128653], [1.970701, 0.641624, -0.163609], 0.727968),
    ([1.050951, 1.132929, -0.047836], [1.310853, 0.097564, -0.296227], 0.418282),
    ([0.988051, 1.154852, -0.017474], [2.142201, -1.149498, 0.205136], 0.586013),
    ([1.693718, 0.319333, 0.043932], [-1.90896, 3.729134, -0.026413], 0.329822),
    ([1.203813, 1.023746, -0.025648], [1.053213, -0.466148, 0.073756], 0.632284),
    ([1.813317, -0.715478, -0.088775], [-1.116238, 5.832074, -0.157796], 0.670303),
    ([1.807987, -0.172261, 0.109834], [-1.735607, 5.249255, 0.062462], 0.423973),
    ([1.783568, -0.512341, -0.089169], [-1.303267, 5.916065, 0.291324], 0.633093),
    ([1.314956, 1.043127, 0.193312], [0.779507, -1.041982, -0.139787], 0.341719),
    ([1.238653, 1.120567, 0.005371], [0.725614, 0.084071, -0.241808], 0.782741),
    ([1.865751, -0.161291, 0.216081], [-1.978468, 4.966309, -0.192028], 0.478364),
    ([0.635563, 1.148101, -0.189192], [2.104065, 0.622311, -0.016586], 0.770846),
    ([1.040888, 1.157288, -0.114415], [1.703113, -0.669889, 0.015574], 0.477464),
    ([1.031025, 1.08545, -0.129018], [1.411707, 0.047618, 0.173692], 0.494115),
    ([1.717002, -0.526708, 0.182398], [-0.871269, 5.574943, -0.191773], 0.463212),
    ([0.752625, 1.273558, 0.070993], [2.02543, 0.027895, 0.041423], 0.600432),
]


def edge_piece(a, v, g, tau, s_hit, samples=20001):
    """Dense float64 samples of ``F`` over the walk's piece that contains ``s_hit``, and the
    number of core slabs the arc lies outside of there."""
    s = np.linspace(0.0, tau, samples)
    x = arc_point(a, v, g, s)
    outside = np.abs(x) > BOX_H
    k = int(np.searchsorted(s, s_hit))
    same = np.all(outside == outside[k], axis=1)
    lo, hi = k, k
    while lo > 0 and same[lo - 1]:
        lo -= 1
    while hi < samples - 1 and same[hi + 1]:
        hi += 1
    w = np.where(outside[lo:hi + 1], np.abs(x[lo:hi + 1]) - BOX_H, 0.0)
    return (w**2).sum(axis=1) - BOX_R**2, int(outside[k].sum())


def test_clips_of_a_rounded_edge(precision):
    """Arcs whose edge piece holds a concave part of ``F`` and more than one crossing of the
    surface, or a clip (in and out again): the first contact where the float64 26-feature
    reference has it (time [s], position over the entry's steepness, normal), in one launch;
    the split of the piece into convex and concave parts decides these."""
    g = np.array([0.0, -9.81, 0.0])
    a = np.array([c[0] for c in CLIPS])
    v = np.array([c[1] for c in CLIPS])
    tau = np.array([c[2] for c in CLIPS])
    out = run_arcs(precision, a, v, g, tau, BOX_H, BOX_R)
    scale = 2.0
    for k, (a_k, v_k, tau_k) in enumerate(CLIPS):
        a_k, v_k = np.asarray(a_k), np.asarray(v_k)
        hit, s_ref, n_ref = arc_contact_by_features(a_k, v_k, g, tau_k, BOX_H, BOX_R)
        f, outside = edge_piece(a_k, v_k, g, tau_k, s_ref)
        assert hit and outside == 2 and np.diff(f, 2).min() < 0.0, k
        assert f[-1] > 0.0 or np.sum(np.diff(np.sign(f)) != 0) >= 2, k
        u = v_k + g * s_ref
        steep = -np.dot(u, n_ref) / np.linalg.norm(u)
        assert out["hit"][k] == 1, k
        np.testing.assert_allclose(arc_point(a_k, v_k, g, out["s"][k]),
                                   arc_point(a_k, v_k, g, s_ref),
                                   atol=POSITION_REL[precision] * scale / steep, err_msg=str(k))
        np.testing.assert_allclose(out["normal"][k], n_ref, atol=NORMAL_TOL[precision] / steep,
                                   err_msg=str(k))


def test_leaving_an_edge_or_a_corner_and_coming_back(precision):
    """Starts on the rounding of an edge or a corner moving straight out along the normal
    ``n`` at ``vn`` [m/s], gravity ``-gamma n``: the arc runs along the normal line, out and
    back, and lands where it started at ``s = 2 vn / gamma`` [s] with the normal ``n``. Slow
    starts whose whole excursion stays inside the grown box, and faster ones that leave it."""
    rows = []
    for phi in (0.3, np.pi / 4, 1.2):
        n = np.array([np.cos(phi), np.sin(phi), 0.0])
        rows.append((np.array([BOX_H[0], BOX_H[1], 0.125]) + BOX_R * n, n))
    n = np.ones(3) / np.sqrt(3.0)
    rows.append((BOX_H + BOX_R * n, n))
    n = np.array([-1.0, 1.0, -1.0]) / np.sqrt(3.0)
    rows.append((np.array([-1.0, 1.0, -1.0]) * BOX_H + BOX_R * n, n))
    a, v, g, s_back, normal = [], [], [], [], []
    for point, n in rows:
        for vn, gamma in ((0.5, 8.0), (0.25, 4.0), (2.0, 8.0)):
            a.append(point)
            v.append(vn * n)
            g.append(-gamma * n)
            s_back.append(2.0 * vn / gamma)
            normal.append(n)
    out = run_arcs(precision, np.array(a), np.array(v), np.array(g), 1.0, BOX_H, BOX_R)
    np.testing.assert_array_equal(out["hit"], 1)
    s_tol = {"float32": 1e-5, "float64": 1e-12}[precision]
    np.testing.assert_allclose(out["s"], s_back, atol=s_tol)
    np.testing.assert_allclose(out["normal"], normal, atol=NORMAL_TOL[precision])

