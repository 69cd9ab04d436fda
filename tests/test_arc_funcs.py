"""The arc ``@wp.func``s (``kernels/arc.py``) tested directly, in the box's local frame.

``sweep_rounded_box_arc``, ``quadratic_roots`` and ``box_entry`` run through one tiny test kernel
per precision (a cold build of a few seconds: the mutation check's fast subset for ``arc.py``),
against answers that do not come from the kernels: closed forms (quadratic roots built from
chosen roots, the drop and apex times, arcs built backwards from a chosen contact, the grown-box
windows of quadratic coordinates worked out by hand) and the float64 26-feature reference
(:func:`arc_reference.arc_contact_by_features`) on random arcs and on grazing edge passes.
The piece walk's root polish, dip search and quartic entry (``polish_root``, ``dip_below``,
``quartic_entry``) run through a second tiny kernel, on quartic gaps whose roots and minima come
from NumPy's polynomial roots.

Units: positions and half extents [m], velocities [m/s], accelerations [m/s^2], times [s];
every vector is in the box's local frame (core box ``[-h, h]``, Minkowski radius ``R``).
"""

from functools import cache

import numpy as np
import pytest
import warp as wp
from arc_reference import arc_contact_by_features, arc_point, signed_distance
from helpers import shaped_half_extents
from test_arc_face_after_edge import BIG_R, TAU, falling_root, posed
from test_arc_face_after_edge import CASES as FACE_AFTER_EDGE
from test_arc_sweep import (
    FEATURE_CASES,
    NORMAL_TOL,
    POSITION_REL,
    STEEP,
    as_precision,
    built_backwards,
    check_edge_grazes,
    closest_approach,
    contact_case,
    edge_graze_arcs,
    entering_arc,
    random_case,
    surface_point,
)

from warpsim.kernels.arc import arc_funcs
from warpsim.kernels.precision import precision as types_of
from warpsim.kernels.variant import variant_kernel

#: The box of the named cases: core half extents and Minkowski radius (top face plane y = 1).
H = np.array([1.0, 0.5, 0.25])
RB = 0.5
G = np.array([0.0, -9.81, 0.0])
SQ2 = np.sqrt(0.5)


@cache
def arc_kernel(name: str):
    """Per row: the sweep of the arc, the roots of a quadratic and the grown-box entry."""
    p = types_of(name)
    scalar, vec3 = p.scalar, p.vec3
    funcs = arc_funcs(p)
    sweep, quadratic_roots, box_entry = (funcs.sweep_rounded_box_arc, funcs.quadratic_roots,
                                         funcs.box_entry)

    @variant_kernel
    def run(a: wp.array[vec3], v: wp.array[vec3], g: wp.array[vec3], tau: wp.array[scalar],
            h: wp.array[vec3], radius: wp.array[scalar], quad: wp.array[vec3],
            s_from: wp.array[scalar], contained: wp.array[wp.vec3i],
            hit_out: wp.array[wp.int32], s_out: wp.array[scalar], normal_out: wp.array[vec3],
            count_out: wp.array[wp.int32], r1_out: wp.array[scalar], r2_out: wp.array[scalar],
            found_out: wp.array[wp.int32], entry_out: wp.array[scalar],
            axis_out: wp.array[wp.int32]):
        i = wp.tid()
        hit, s, n = sweep(a[i], v[i], g[i], tau[i], h[i], radius[i])
        hit_out[i] = hit
        s_out[i] = s
        normal_out[i] = n
        q = quad[i]
        count, r1, r2 = quadratic_roots(q[0], q[1], q[2])
        count_out[i] = count
        r1_out[i] = r1
        r2_out[i] = r2
        found, s_e, axis = box_entry(a[i], v[i], g[i], h[i] + vec3(radius[i], radius[i],
                                                                       radius[i]),
                                     s_from[i], tau[i], contained[i])
        found_out[i] = found
        entry_out[i] = s_e
        axis_out[i] = axis

    return run


def run_arcs(precision, a, v, g, tau, h, radius, quad=None, s_from=0.0, contained=(0, 0, 0)):
    """Launch the test kernel over rows (scalars and single vectors broadcast); outputs are
    pre-filled with a sentinel so that an unwritten one fails the comparison."""
    p = types_of(precision)
    n = len(a)

    def rows(x, shape):
        return np.ascontiguousarray(np.broadcast_to(np.asarray(x, np.float64), shape),
                                    dtype=p.np_dtype)

    quad = np.zeros((n, 3)) if quad is None else quad
    inputs = [wp.array(rows(x, (n, 3)), dtype=p.vec3) for x in (a, v, g)]
    inputs.append(wp.array(rows(tau, (n,)), dtype=p.scalar))
    inputs.append(wp.array(rows(h, (n, 3)), dtype=p.vec3))
    inputs.append(wp.array(rows(radius, (n,)), dtype=p.scalar))
    inputs.append(wp.array(rows(quad, (n, 3)), dtype=p.vec3))
    inputs.append(wp.array(rows(s_from, (n,)), dtype=p.scalar))
    inputs.append(wp.array(np.ascontiguousarray(np.broadcast_to(contained, (n, 3)),
                                                dtype=np.int32), dtype=wp.vec3i))
    names = ["hit", "s", "normal", "count", "r1", "r2", "found", "entry", "axis"]
    kinds = [wp.int32, p.scalar, p.vec3, wp.int32, p.scalar, p.scalar, wp.int32, p.scalar,
             wp.int32]
    outs = []
    for kind in kinds:
        if kind is wp.int32:
            outs.append(wp.array(np.full(n, -7, np.int32), dtype=kind))
        else:
            shape = (n, 3) if kind is p.vec3 else (n,)
            outs.append(wp.array(np.full(shape, np.nan, p.np_dtype), dtype=kind))
    wp.launch(arc_kernel(precision), dim=n, inputs=inputs, outputs=outs, device="cpu")
    return {k: o.numpy() for k, o in zip(names, outs, strict=True)}


# --- named arcs against closed forms ----------------------------------------------------------

TOP = 0.5 + RB  # top face plane


def named_arcs():
    """``name: (a, v, g, tau, h, R, hit, s, normal)``, each answer worked out by hand; ``s`` and
    ``normal`` are ``None`` for a miss (``s = tau``, zero normal)."""
    cases = {
        # from rest 2 m above the top face plane, g = -8: 2 = 4 s^2
        "drop onto the top face": ([0.25, 3.0, 0.125], [0, 0, 0], [0, -8, 0], 1.0, H, RB,
                                   1, np.sqrt(0.5), [0, 1, 0]),
        "drop, tau too short": ([0.25, 3.0, 0.125], [0, 0, 0], [0, -8, 0], 0.5, H, RB,
                                0, None, None),
        # g = -16: 2 = 8 s^2 at s = 1/2, the end of the span (a contact at tau counts)
        "drop, lands exactly at tau": ([0.25, 3.0, 0.125], [0, 0, 0], [0, -16, 0], 0.5, H, RB,
                                       1, 0.5, [0, 1, 0]),
        "drop onto a sharp box": ([0.25, 2.0, 0.125], [0, 0, 0], [0, -8, 0], 1.0, H, 0.0,
                                  1, np.sqrt(1.5 / 4.0), [0, 1, 0]),
        # thrown sideways onto the -x face plane x = -1.5 of a sharp box (grown box = core)
        "sharp box, -x face": ([-3.5, 0.25, 0.0], [4, 0.5, 0], [0, -2, 0], 1.0, [1.5, 0.5, 0.25],
                               0.0, 1, 0.5, [-1, 0, 0]),
        # a sharp box is closed: sliding along its top plane y = 0.5 into the -x face plane
        "sharp box, along its top plane into -x": ([-3.5, 0.5, 0.0], [4, 0, 0], [0, 0, -1], 1.0,
                                                   [1.5, 0.5, 0.25], 0.0, 1, 0.5, [-1, 0, 0]),
        # rising under the bottom plane y = -1: apex exactly on it (tangent), 2^-8 m above
        # it (a hit before the apex, at y(s) = -1: s = (1 - sqrt(dip)) / 2), or 2^-8 short
        "apex exactly on the bottom face": ([0.25, -2.0, 0.0], [0.5, 4, 0], [0, -8, 0], 1.0,
                                            H, RB, 0, None, None),
        "apex dips into the bottom face": ([0.25, -2.0 + 2.0**-8, 0.0], [0.5, 4, 0],
                                           [0, -8, 0], 1.0, H, RB,
                                           1, 0.5 * (1 - 2.0**-4), [0, -1, 0]),
        "apex short of the bottom face": ([0.25, -2.0 - 2.0**-8, 0.0], [0.5, 4, 0],
                                          [0, -8, 0], 1.0, H, RB, 0, None, None),
        # thrown up from a sharp box's bottom face plane, the apex on it: tangent, no hit
        "sharp box, apex on the bottom plane": ([0.25, -1.5, 0.0], [0.5, 4, 0], [0, -8, 0],
                                                1.0, H, 0.0, 0, None, None),
        # g = 0: the chord's linear sweep; face entry at x = -1.5, t = 1.5 / 4
        "no gravity, -x face": ([-3.0, 0.125, 0.0], [4, 0, 0], [0, 0, 0], 1.0, H, RB,
                                1, 0.375, [-1, 0, 0]),
        "no gravity, tau 2": ([-3.0, 0.125, 0.0], [2, 0, 0], [0, 0, 0], 2.0, H, RB,
                              1, 0.75, [-1, 0, 0]),
        "no gravity, short": ([-3.0, 0.125, 0.0], [1, 0, 0], [0, 0, 0], 1.0, H, RB,
                              0, None, None),
        "motionless": ([0.0, 3.0, 0.0], [0, 0, 0], [0, 0, 0], 1.0, H, RB, 0, None, None),
        "tau 0": ([0.25, 1.5, 0.0], [0, -4, 0], [0, -8, 0], 0.0, H, RB, 0, None, None),
        "tau < 0": ([0.25, 1.5, 0.0], [0, -4, 0], [0, -8, 0], -1.0, H, RB, 0, None, None),
        # starts on the surface (top face plane y = 1)
        "on the face moving in": ([0.25, TOP, 0.0], [1, -1, 0], G, 1.0, H, RB, 1, 0.0,
                                  [0, 1, 0]),
        "on the face at rest, gravity in": ([0.25, TOP, 0.0], [0, 0, 0], G, 1.0, H, RB, 1, 0.0,
                                            [0, 1, 0]),
        "on the face along, gravity in": ([0.25, TOP, 0.0], [1, 0, 0.5], G, 1.0, H, RB, 1, 0.0,
                                          [0, 1, 0]),
        # leaving at 2 m/s under g = -8: back on the plane at 2 * 2 / 8 = 0.5
        "on the face leaving, comes back": ([0.25, TOP, 0.0], [0.25, 2, 0], [0, -8, 0], 1.0,
                                            H, RB, 1, 0.5, [0, 1, 0]),
        "on the face leaving, tau short": ([0.25, TOP, 0.0], [0.25, 2, 0], [0, -8, 0], 0.25,
                                           H, RB, 0, None, None),
        "on a wall along, gravity along": ([1.0 + RB, 0.0, 0.0], [0, 0.5, 0.1], G, 1.0, H, RB,
                                           0, None, None),
        "under the bottom leaving, gravity away": ([0.25, -TOP, 0.0], [0.5, -1, 0], G, 1.0,
                                                   H, RB, 0, None, None),
        "on an edge along, gravity in": ([1.0 + RB * SQ2, 0.5 + RB * SQ2, 0.0], [0, 0, 1], G,
                                         1.0, H, RB, 1, 0.0, [SQ2, SQ2, 0]),
        # inside the core box moving out, gravity out too: no hit
        "inside, moving out": ([0.0, 0.25, 0.0], [0, 3, 0], [0, 1, 0], 1.0, H, RB,
                               0, None, None),
        # tau 0 never hits, not even from the surface moving in
        "tau 0, on the face moving in": ([0.25, TOP, 0.0], [1, -1, 0], G, 0.0, H, RB,
                                         0, None, None),
        # at rest on the bottom face (v . n = 0 with |v| = 0), gravity pulling away: no hit
        "under the bottom at rest, gravity away": ([0.25, -TOP, 0.0], [0, 0, 0], G, 1.0,
                                                   H, RB, 0, None, None),
        # leaving a wall with gravity along it (g . n = 0): it never comes back
        "on a wall leaving, gravity along": ([1.0 + RB, 0.0, 0.0], [2, 0, 0], G, 1.0, H, RB,
                                             0, None, None),
        # thrown onto the +x face plane x = 1.5 of a sharp box, no gravity along x
        "sharp box, +x face": ([3.5, 0.25, 0.0], [-4, 0.5, 0], [0, -2, 0], 1.0,
                               [1.5, 0.5, 0.25], 0.0, 1, 0.5, [1, 0, 0]),
        # weak gravity (|g| < sqrt 2, where the vertex's s_v^2 g / 2 and s_v / (g / 2) differ
        # in sign): y = -3/2 + 2^-9 + s - s^2 / 2, apex 2^-9 above the bottom plane y = -1 at
        # s = 1, back below it at tau = 2; in at (1 - s)^2 = 2^-8
        "weak gravity, apex dips into the bottom face": ([0.25, -1.5 + 2.0**-9, 0.0],
                                                         [0.5, 1, 0], [0, -1, 0], 2.0, H, RB,
                                                         1, 1.0 - 2.0**-4, [0, -1, 0]),
        # moving straight in at 2^-24 m/s (in at any speed: v . n = -|v|), gravity away
        "on the face creeping in, gravity away": ([0.25, TOP, 0.0], [0, -(2.0**-24), 0],
                                                  [0, 8, 0], 1.0, H, RB, 1, 0.0, [0, 1, 0]),
        # 2^-45 m inside the top face of a box 64 m long (the local scale 64.5 m): on the
        # surface, within 16 ulps of the scale; leaving at 2 m/s under g = -8, back at
        # y = 1: 4 s^2 - 2 s + 2^-45 = 0
        "2^-45 inside a long box's face, leaving, comes back": (
            [0.25, TOP - 2.0**-45, 0.0], [0.25, 2, 0], [0, -8, 0], 1.0, [64.0, 0.5, 0.25], RB,
            1, (2.0 + np.sqrt(4.0 - 2.0**-41)) / 8.0, [0, 1, 0]),
        # 1 ulp inside the top face, "leaving" at 2^-40 m/s (more than the tangent margin),
        # gravity in: it can never rise out of the touch band (vn^2 / 2|g| = 2^-84 m) and has
        # no crossing to come back through: in at once (it fell through a nearly level face)
        "1 ulp inside the face, leaving by rounding": ([0.25, TOP - 2.0**-52, 0.0],
                                                       [1, 2.0**-40, 0], [0, -8, 0], 1.0,
                                                       H, RB, 1, 0.0, [0, 1, 0]),
        # the same on the face's +x border line (x = h exactly: the face, not the edge),
        # sliding onto the face at 3 m/s: held by the face alone (on the edge, 9 / R > 8
        # would let it go)
        "1 ulp inside the face's border, onto it, leaving by rounding": (
            [1.0, TOP - 2.0**-52, 0.0], [-3, 2.0**-40, 0], [0, -8, 0], 1.0, H, RB, 1, 0.0,
            [0, 1, 0]),
        # leaving at 2^-20 m/s rises 2^-44 m, out of the band (16 ulps of 1.5 m): back on the
        # plane at 2 vn / 8 = 2^-22
        "on the face, a hop out of the band": ([0.25, TOP, 0.0], [1, 2.0**-20, 0], [0, -8, 0],
                                               1.0, H, RB, 1, 2.0**-22, [0, 1, 0]),
        # on the +x top edge at 45 degrees, sliding round it (0.25 m/s across its axis, 3 along
        # it) with 2^-44 m/s outwards: the curve holds it (k = -8 sqrt(1/2) + 0.125 / R < 0),
        # so in at once (far from the origin such a start fell through the curve)
        "on an edge leaving by rounding, held": ([1.0 + RB * SQ2, 0.5 + RB * SQ2, 0.0],
                                                 [-0.25 + 2.0**-44, 0.25 + 2.0**-44, 3.0],
                                                 [0, -8, 0], 1.0, H, RB, 1, 0.0,
                                                 [SQ2, SQ2, 0]),
        # the same edge at 2 m/s across its axis, 2^-12 m/s outwards (beyond the tangent
        # margin in both precisions): too fast to hold (8 / R > 8 sqrt(1/2)), it leaves the
        # curve and lands on the top face y = 1 at 4 s^2 - (2 + 2^-12) s + 1/2 - R SQ2 = 0
        "on an edge leaving, too fast to hold": ([1.0 + RB * SQ2, 0.5 + RB * SQ2, 0.0],
                                                 [-2.0 + 2.0**-12, 2.0 + 2.0**-12, 0.0],
                                                 [0, -8, 0], 1.0, H, RB, 1,
                                                 (2.0 + 2.0**-12 + np.sqrt(
                                                     (2.0 + 2.0**-12)**2
                                                     - 16.0 * (0.5 - RB * SQ2))) / 8.0,
                                                 [0, 1, 0]),
    }
    s_star = 0.375
    for name, point, normal, u, g in FEATURE_CASES:
        a, v = built_backwards(point, np.asarray(normal, float), u, s_star, g)
        cases[f"built backwards: {name}"] = (a, v, g, 1.0, H, RB, 1, s_star, normal)
    for perm, side in FACE_AFTER_EDGE:
        h, a, v, g, axis = posed(perm, side)
        normal = np.zeros(3)
        normal[axis] = side
        cases[f"face after the edge {perm}{side:+.0f}"] = (
            a, v, g, TAU, h, BIG_R, 1, falling_root(a, v, g, h, axis, side), normal)
        h, a, v, g, _ = posed(perm, side, gravity_sign=-1.0)
        cases[f"gravity away from the face {perm}{side:+.0f}"] = (
            a, v, g, TAU, h, BIG_R, 0, None, None)
    return cases


NAMED = named_arcs()


def test_named_arcs_against_closed_forms(precision):
    """Drops, throws and apex touches of faces (rounded and sharp), arcs built backwards onto
    faces, edges and corners, arcs that pass an edge and land on the face behind it (or, with
    gravity reversed, leave), starts on the surface (in, along, leaving, coming back), zero
    gravity, ``tau <= 0``: hit, contact time [s] and outward normal (local frame)."""
    rows = list(NAMED.values())
    # the inputs as the precision holds them (the closed forms are exact for these)
    cols = [np.array([np.asarray(r[k], float) for r in rows]) for k in range(6)]
    out = run_arcs(precision, *cols)
    s_tol = {"float32": 4e-6, "float64": 1e-13}[precision]
    for k, (name, row) in enumerate(NAMED.items()):
        hit, s, normal = row[6:]
        tau = float(as_precision(row[3], precision))
        assert out["hit"][k] == hit, name
        if hit:
            assert out["s"][k] == pytest.approx(s, abs=s_tol * max(1.0, tau)), name
            np.testing.assert_allclose(out["normal"][k], normal, atol=NORMAL_TOL[precision],
                                       err_msg=name)
        else:
            assert out["s"][k] == tau, name
            np.testing.assert_array_equal(out["normal"][k], 0.0, err_msg=name)


def test_built_backwards_cases_are_first_contacts():
    """Self-check of the construction above: the float64 reference finds the contacts that
    the named cases built backwards claim, and nothing earlier."""
    for name, (a, v, g, tau, h, radius, _hit, s, normal) in NAMED.items():
        if not name.startswith(("built backwards", "face after")):
            continue
        ref_hit, ref_s, ref_n = arc_contact_by_features(np.asarray(a, float),
                                                        np.asarray(v, float),
                                                        np.asarray(g, float), tau, h, radius)
        assert ref_hit and ref_s == pytest.approx(s, abs=1e-9), name
        np.testing.assert_allclose(ref_n, normal, atol=1e-9, err_msg=name)


# --- quadratic roots --------------------------------------------------------------------------

#: ``(qa, qb, qc)`` of ``qa s^2 + qb s + qc`` built from chosen roots, and the answer:
#: ``(count, r1, r2)`` with ``r1 <= r2`` (no root: the "no such time" 1e30).
NONE = 1.0e30
QUADRATICS = {
    "two roots, 1 and 2": ((1.0, -3.0, 2.0), (2, 1.0, 2.0)),
    "two negative roots": ((1.0, 3.0, 2.0), (2, -2.0, -1.0)),
    "symmetric, qb = 0": ((2.0, 0.0, -8.0), (2, -2.0, 2.0)),
    "downward parabola": ((-1.0, 0.0, 4.0), (2, -2.0, 2.0)),
    "downward, both positive": ((-2.0, 6.0, -4.0), (2, 1.0, 2.0)),
    "double root 1": ((1.0, -2.0, 1.0), (2, 1.0, 1.0)),
    "double root 0": ((1.0, 0.0, 0.0), (2, 0.0, 0.0)),
    "root 0 and 4": ((0.5, -2.0, 0.0), (2, 0.0, 4.0)),
    "no real root": ((1.0, 0.0, 1.0), (0, NONE, NONE)),
    "no real root, qb > 0": ((1.0, 1.0, 1.0), (0, NONE, NONE)),
    "linear": ((0.0, 2.0, -1.0), (1, 0.5, 0.5)),
    "linear, negative slope": ((0.0, -4.0, 1.0), (1, 0.25, 0.25)),
    "constant": ((0.0, 0.0, 1.0), (0, NONE, NONE)),
    # (s - 2^-20)(s - 2^20): the small root by cancellation in the naive form
    "far-apart roots": ((1.0, -(2.0**20 + 2.0**-20), 1.0), (2, 2.0**-20, 2.0**20)),
    "far-apart roots, negative": ((1.0, 2.0**20 + 2.0**-20, 1.0), (2, -(2.0**20), -(2.0**-20))),
}


def test_quadratic_roots_against_chosen_roots(precision):
    """The real roots of quadratics built from chosen roots (exact in binary), ordered, with
    the count: two (a double root twice), one for a linear equation, none; the far-apart pair
    to a few ulps each (no cancellation)."""
    rows = list(QUADRATICS.values())
    n = len(rows)
    zeros = np.zeros((n, 3))
    out = run_arcs(precision, zeros, zeros, zeros, 1.0, np.ones(3), 0.0,
                   quad=np.array([q for q, _ in rows]))
    eps = float(np.finfo(types_of(precision).np_dtype).eps)
    for k, (name, (_, (count, r1, r2))) in enumerate(QUADRATICS.items()):
        assert out["count"][k] == count, name
        for got, want in ((out["r1"][k], r1), (out["r2"][k], r2)):
            if want == NONE:
                assert got == np.float32(NONE) if precision == "float32" else got == NONE, name
            else:
                assert got == pytest.approx(want, rel=8 * eps, abs=8 * eps * (want == 0)), name


# --- the grown-box entry ----------------------------------------------------------------------

#: ``(a, v, g, tau, bound, s_from, contained, (found, s, axis))``: arcs whose per-axis windows
#: ``|x_i(s)| <= bound_i`` are worked out by hand (``bound`` is passed as ``h`` with ``R = 0``).
ROOT3 = np.sqrt(0.75)
ENTRIES = {
    # x = -3 + 4 s reaches -1 at s = 0.5
    "straight, through -x": ([-3, 0, 0], [4, 0, 0], [0, 0, 0], 1.0, [1, 1, 1], 0.0, (0, 0, 0),
                             (1, 0.5, 0)),
    "straight, too short": ([-3, 0, 0], [4, 0, 0], [0, 0, 0], 0.25, [1, 1, 1], 0.0, (0, 0, 0),
                            (0, None, None)),
    # x = 3 - 4 s reaches +1 at s = 0.5
    "straight, through +x": ([3, 0, 0], [-4, 0, 0], [0, 0, 0], 1.0, [1, 1, 1], 0.0, (0, 0, 0),
                             (1, 0.5, 0)),
    # y = 3 - 8 s^2 reaches 1 at s = 1/2 = tau
    "drop, entry exactly at tau": ([0, 3, 0], [0, 0, 0], [0, -16, 0], 0.5, [1, 1, 1], 0.0,
                                   (0, 0, 0), (1, 0.5, 1)),
    # y = 3 - 4 s^2 reaches 1 at sqrt(0.5)
    "drop through +y": ([0, 3, 0], [0, 0, 0], [0, -8, 0], 1.0, [1, 1, 1], 0.0, (0, 0, 0),
                        (1, np.sqrt(0.5), 1)),
    "drop, x and z flagged contained": ([0, 3, 0], [0, 0, 0], [0, -8, 0], 1.0,
                                                 [1, 1, 1], 0.0, (1, 0, 1),
                                                 (1, np.sqrt(0.5), 1)),
    # rising through -z: z = -2 + 2 s + 2 s^2 = -0.5 at s = 0.5 (and y, x inside)
    "rising through -z": ([0, 0, -2], [0, 0, 2], [0, 0, 4], 1.0, [1, 1, 0.5], 0.0, (0, 0, 0),
                          (1, 0.5, 2)),
    "start inside": ([0.5, 0, 0], [1, 0, 0], [0, -1, 0], 1.0, [1, 1, 1], 0.0, (0, 0, 0),
                     (1, 0.0, -1)),
    "start inside, from s = 0.25": ([0.25, 0, 0], [1, 0, 0], [0, -1, 0], 1.0, [1, 1, 1], 0.25,
                                    (0, 0, 0), (1, 0.25, -1)),
    # x = 4 (s - 1)^2 - 2 is inside [-1, 1] on [1 - sqrt(3/4), 1/2] and [3/2, 1 + sqrt(3/4)];
    # y = 1.7 - s comes inside at 0.7: the first window is missed, the second is the entry
    "second window of x": ([2, 1.7, 0], [-8, -1, 0], [8, 0, 0], 2.0, [1, 1, 1], 0.0,
                           (0, 0, 0), (1, 1.5, 0)),
    "first window of x": ([2, 0.7, 0], [-8, -1, 0], [8, 0, 0], 2.0, [1, 1, 1], 0.0,
                          (0, 0, 0), (1, 1.0 - ROOT3, 0)),
    "between the windows of x": ([2, 1.7, 0], [-8, -1, 0], [8, 0, 0], 1.25, [1, 1, 1], 0.0,
                                 (0, 0, 0), (0, None, None)),
    # x = -0.5 throughout, y = -1.7 + s enters at 0.7, z = 1.6 - s at 0.6: y enters last
    "y enters last": ([-0.5, -1.7, 1.6], [0, 1, -1], [0, 0, 0], 2.0, [1, 1, 1], 0.0,
                      (0, 0, 0), (1, 0.7, 1)),
    # a plate (bound 0 in y): y = 1 - 2 s is inside at the single instant 0.5
    "plate, single instant": ([0.25, 1, 0], [0, -2, 0], [0, 0, 0], 1.0, [1, 0, 1], 0.0,
                              (0, 0, 0), (1, 0.5, 1)),
    # beside the box in z the whole time: no entry
    "beside the box": ([-3, 0, 2], [4, 0, 0], [0, -1, 0], 1.0, [1, 1, 1], 0.0, (0, 0, 0),
                       (0, None, None)),
}


def test_box_entry_against_hand_windows(precision):
    """The first time in ``[s_from, tau]`` inside the closed box ``[-bound, bound]`` and the
    axis entered last (-1: inside at ``s_from``): straight and parabolic coordinates, two
    windows of one axis, a plate's single instant, no entry; positions [m], times [s]."""
    rows = list(ENTRIES.values())
    cols = [np.array([np.asarray(r[k], float) for r in rows]) for k in range(5)]
    out = run_arcs(precision, *cols[:4], cols[4], 0.0,
                   s_from=np.array([r[5] for r in rows]),
                   contained=np.array([r[6] for r in rows]))
    s_tol = {"float32": 4e-7, "float64": 1e-15}[precision]
    for k, (name, row) in enumerate(ENTRIES.items()):
        found, s, axis = row[7]
        assert out["found"][k] == found, name
        if found:
            assert out["entry"][k] == pytest.approx(s, abs=s_tol * 4), name
            assert out["axis"][k] == axis, name


# --- against the float64 reference ------------------------------------------------------------

def random_arcs(precision, count=150, seed=7):
    """Random boxes (boxes, plates, sticks, points, cubes; sharp and rounded), starts outside,
    any gravity direction; two in three built backwards from a chosen contact."""
    rng = np.random.default_rng(seed)
    kinds = ["box", "plate", "stick", "point", "cube"]
    cases = []
    while len(cases) < count:
        kind = kinds[len(cases) % len(kinds)]
        case = random_case(rng, kind) if len(cases) % 3 == 2 else contact_case(rng, kind)
        if case is None:
            continue
        h, radius, a, v, g, tau = case
        a, v, g, h = (as_precision(x, precision) for x in (a, v, g, h))
        radius = float(as_precision(radius, precision))
        if signed_distance(a, h, radius) > 0.05:
            cases.append((a, v, g, tau, h, radius))
    return cases


def test_random_arcs_match_the_reference(precision):
    """The kernel against the 26-feature float64 reference on random arcs: the verdict where
    it is clear, the contact point [m] (to a few hundred ulps of the local scale over the
    entry's steepness) and the normal; misses end at ``tau`` with a zero normal."""
    cases = random_arcs(precision)
    cols = [np.array([np.asarray(c[k], float) for c in cases]) for k in range(6)]
    out = run_arcs(precision, *cols)
    hits = misses = 0
    for k, (a, v, g, tau, h, radius) in enumerate(cases):
        ref_hit, ref_s, ref_n = arc_contact_by_features(a, v, g, tau, h, radius)
        scale = max(np.abs(a).max(), h.max() + radius)
        if ref_hit:
            u = v + g * ref_s
            steep = -np.dot(u, ref_n) / np.linalg.norm(u)
            if steep < STEEP:
                continue
            assert out["hit"][k] == 1, k
            np.testing.assert_allclose(arc_point(a, v, g, out["s"][k]),
                                       arc_point(a, v, g, ref_s),
                                       atol=POSITION_REL[precision] * scale / steep)
            if radius > 0.0:
                np.testing.assert_allclose(out["normal"][k], ref_n,
                                           atol=NORMAL_TOL[precision] / steep)
            hits += 1
        elif closest_approach(a, v, g, tau, h, radius) > 1e-3 * scale:
            assert out["hit"][k] == 0, k
            assert out["s"][k] == float(as_precision(tau, precision)), k
            np.testing.assert_array_equal(out["normal"][k], 0.0)
            misses += 1
    assert hits >= 80 and misses >= 10


def test_grazing_edge_passes(precision):
    """Arcs whose apex is at ``R (1 + eps)`` from the +x+y edge cylinder (gravity out along
    the edge's diagonal normal; ``test_arc_sweep.edge_graze_arcs``), through the funcs' kernel:
    clear misses miss, clear dips hit where the float64 reference enters, with its normal, to
    the position error over the radial speed [m/s]; every hit moves in, before the apex."""
    a, v, g, eps = edge_graze_arcs(200, precision)
    out = run_arcs(precision, a, v, g, 0.5, H, RB)
    checked = check_edge_grazes(precision, a, v, g, eps, out["hit"], out["s"], out["normal"],
                                check_normal=True)
    assert checked >= 25


# --- the quartic piece's root polish and dip search, called directly ---------------------------

def inner_func(outer, name):
    """The ``@wp.func`` ``name`` that ``outer`` calls (read from its Python closure): the piece
    walk's helpers are not in the namespace of :func:`arc_funcs`."""
    code, cells = outer.func.__code__, outer.func.__closure__
    return dict(zip(code.co_freevars, (c.cell_contents for c in cells), strict=True))[name]


@cache
def search_kernel(name: str):
    """Per row: ``dip_below``, ``polish_root`` and ``quartic_entry`` on the gap
    ``F(s) = |w(s)|^2 - R^2`` over ``[lo, hi]``."""
    p = types_of(name)
    scalar, vec3 = p.scalar, p.vec3
    quartic_entry = inner_func(inner_func(arc_funcs(p).sweep_rounded_box_arc, "walk_pieces"),
                               "quartic_entry")
    dip_below, polish_root = (inner_func(quartic_entry, "dip_below"),
                              inner_func(quartic_entry, "polish_root"))

    @variant_kernel
    def run(c0: wp.array[vec3], c1: wp.array[vec3], c2: wp.array[vec3],
            radius: wp.array[scalar], lo: wp.array[scalar], hi: wp.array[scalar],
            tol: wp.array[scalar], found_out: wp.array[wp.int32], dip_out: wp.array[scalar],
            root_out: wp.array[scalar], entered_out: wp.array[wp.int32],
            entry_out: wp.array[scalar]):
        i = wp.tid()
        found, s = dip_below(c0[i], c1[i], c2[i], radius[i], lo[i], hi[i], tol[i])
        found_out[i] = found
        dip_out[i] = s
        root_out[i] = polish_root(c0[i], c1[i], c2[i], radius[i], lo[i], hi[i], tol[i])
        entered, s_entry = quartic_entry(c0[i], c1[i], c2[i], radius[i], lo[i], hi[i], tol[i])
        entered_out[i] = entered
        entry_out[i] = s_entry

    return run


def run_searches(precision, rows):
    """Launch :func:`search_kernel` over rows ``(c0, c1, c2, R, lo, hi, tol)``: the dip
    search's ``found`` and time, the polished root, the quartic entry's ``found`` and time."""
    p = types_of(precision)
    cols = [np.array([np.asarray(r[k], np.float64) for r in rows]) for k in range(7)]
    inputs = [wp.array(c.astype(p.np_dtype), dtype=p.vec3) for c in cols[:3]]
    inputs += [wp.array(c.astype(p.np_dtype), dtype=p.scalar) for c in cols[3:]]
    n = len(rows)
    outs = [wp.array(np.full(n, -7, np.int32), dtype=wp.int32),
            wp.array(np.full(n, np.nan, p.np_dtype), dtype=p.scalar),
            wp.array(np.full(n, np.nan, p.np_dtype), dtype=p.scalar),
            wp.array(np.full(n, -7, np.int32), dtype=wp.int32),
            wp.array(np.full(n, np.nan, p.np_dtype), dtype=p.scalar)]
    wp.launch(search_kernel(precision), dim=n, inputs=inputs, outputs=outs, device="cpu")
    return [o.numpy() for o in outs]


def gap_polynomial(c0, c1, c2, radius):
    """``F(s) = |c0 + c1 s + c2 s^2|^2 - R^2`` as a float64 NumPy polynomial [m^2]."""
    parts = [np.polynomial.Polynomial([c0[i], c1[i], c2[i]]) for i in range(3)]
    return sum(q * q for q in parts) - radius * radius


#: Convex parts of ``F`` (``F > 0`` and falling at ``lo``, rising at ``hi``), the core offset's
#: coefficients ``c0`` [m], ``c1`` [m/s], ``c2`` [m/s^2] in the box's local frame with the time
#: origin at the piece's start, ``R`` [m], ``lo``, ``hi`` and the stopping step ``tol`` [s].
#: ``4 ulps`` is the sweep's own ``ROOT_ULPS`` of the span; the coarse one stops at the first
#: small Newton step, so that only the check after the stop sees ``F <= 0``.
ULPS = 4.0 * np.finfo(np.float64).eps
DIPS = {
    # a part after a concave one (F'' = 0 at 6.684 s): the first guess, the tangents' crossing,
    # lies above F's minimum (-2.5e-6 R^2 at 10.58 s), which Newton on F' must reach
    "late in a part after a concave one": (
        [0.8911669542823284, 0.3208483045665637, -0.818230227390307],
        [0.06534884780575859, -0.044787022711091064, 0.0785238216493645],
        [-0.008550176076538457, 0.00729515525172918, -0.00016005605865926267],
        0.9119302031831882, 6.976514288186557, 10.817404675247317, ULPS * 10.817404675247317),
    # F convex throughout, a minimum of -7.4e-8 R^2 at 3.69 s of a 6.7 s part from lo = 0
    "shallow, from the piece's start": (
        [-1.8890132459676727, -0.17477209205516195, -0.42219041157635356],
        [0.008424529948517372, 0.008569600397883933, 0.08351219664091397],
        [-0.001729127141338856, -0.0005871536651419724, 0.0031763901795499364],
        1.888858591137986, 0.0, 6.705100641952094, ULPS * 6.705100641952094),
    # the tangents' bound is below 0 but F stays above 0.024 R^2: no dip, and F <= 0 outside
    # the part (before 39.8 s) must not be reported
    "no dip, the bound below zero": (
        [-2.728670128606971, -0.009672544916135537, -0.9487755307207126],
        [-0.05647730314094708, 0.01981280986342682, 0.01906005049792493],
        [0.00129553615866038, -0.00010930894424654364, -0.0008857809646640805],
        3.2359857837443875, 39.80136492814271, 105.52083631579939,
        ULPS * 105.52083631579939),
    # a minimum of -3.2e-8 R^2, found after a stop with a coarse tol (1e-3 of the part)
    "found at the check after the stop": (
        [0.5889689337804737, -0.8407215900583078, -0.5060254839367364],
        [-1.080492991440681, 1.651237242261867, -1.257984452981859],
        [2.6770347484992096, -1.7006651730908706, -8.137292302310689],
        1.1029519914026764, 0.0, 0.7318419276335691, 7.318419276335691e-4),
    # parts where Newton on F' (from F' and F'' at the iterate) must be right: a wrong step
    # lands within tol of the iterate and stops the search at F > 0, or keeps landing near
    # one end of the bracket, which then shrinks too slowly for the iterations
    "an edge piece's part, a minimum of -0.044 R^2 at 2.10 s": (
        [0.5065200160043164, 0.0, 2.674197713287978],
        [-0.15536769049989885, 0.0, -1.1798828524606435],
        [0.0060002527140121525, 0.0, -0.04850971523460604],
        0.21217821016104596, 0.9471641579767756, 3.9535294386478013, ULPS * 3.9535294386478013),
    "just after a concave part, a minimum of -1.7e-4 R^2 at 2.72 s": (
        [-0.35045104032469937, 2.4254363868640287, -0.5906723242759668],
        [0.9194378793619966, -3.6201369354566366, -2.6977321706046395],
        [-0.24361793815757543, 0.988976388637287, 1.0830254529786274],
        0.37271349501989837, 2.6521899524528645, 4.501562142568854, ULPS * 4.501562142568854),
    "a part 0.08 s long, a minimum of -4.9e-6 R^2 at 0.070 s": (
        [-0.06666041280375261, 0.03324192266491149, 0.07168785424706935],
        [0.46083137842023003, 0.06758583236767537, 0.13328611819481406],
        [1.9908256802551227, 0.16017301136303325, 0.34383114122860015],
        0.0946007146262507, 0.03074304714314094, 0.10724170051300888,
        ULPS * 0.10724170051300888),
    "a corner 60 m away, a minimum of -4.3e-4 R^2 at 27.0 s": (
        [38.00190117532917, 46.655979725667, 8.676909123794362],
        [-2.809307603216552, -3.3287798651714375, -0.566525036209237],
        [0.051991948273888526, 0.0593215377989621, 0.009014843366864311],
        0.07491048925377704, 15.534507791055558, 33.01276529884191, ULPS * 33.01276529884191),
}


@pytest.mark.parametrize("precision", ["float64"])
def test_dip_search_on_shallow_convex_parts(precision):
    """``dip_below`` on convex parts whose dip (if any) is too shallow for the first guess:
    found exactly when F's float64 minimum on ``[lo, hi]`` (from the real roots of ``F'``) is
    below zero, and then at a time inside the part where F <= 0 (to rounding, 1e-12 R^2).
    Float64 only: most dips are 1e-6 to 1e-8 of R^2 deep, below float32's resolution of F."""
    rows = list(DIPS.values())
    found, s, *_ = run_searches(precision, rows)
    for k, (name, (c0, c1, c2, radius, lo, hi, _tol)) in enumerate(DIPS.items()):
        f = gap_polynomial(c0, c1, c2, radius)
        assert np.all(f.deriv(2)(np.linspace(lo, hi, 2001)) > 0.0), name  # convex part
        assert f(lo) > 0.0 and f(hi) > 0.0 and f.deriv()(lo) < 0.0 < f.deriv()(hi), name
        crit = [r.real for r in f.deriv().roots() if abs(r.imag) < 1e-12 and lo < r.real < hi]
        depth = min(f(t) for t in [lo, hi, *crit]) / radius**2
        assert abs(depth) > 1e-9, name  # clear of a tangent touch
        assert found[k] == int(depth < 0.0), name
        if depth < 0.0:
            assert lo <= s[k] <= hi, name
            assert f(s[k]) <= 1e-12 * radius**2, name


#: Parts with one root of F in ``[lo, hi]``, ``F(lo) > 0 >= F(hi)``, where a Newton step from
#: the midpoint leaves the bracket (units as in :data:`DIPS`; ``tol`` 4 ulps of 0.31 s).
ROOTS = {
    "steep near the root, flat at the midpoint": (
        [1.3551605045124333, 0.9666960256554462, 1.3010442986255635],
        [2.037028632107496, 3.946431907397624, 1.9375375876223802],
        [-6.850895075610787, -15.135120751811126, -14.631526789476732],
        2.0777532358301296, 0.0, 0.22629161909665277, ULPS * 0.31),
    "a second root beyond the bracket": (
        [0.3160481273078601, -0.23779689710483434, -1.8960106100940826],
        [4.6515751075047485, -0.02803024263352401, -1.0824765355817787],
        [-9.648123046245633, -9.690477407424607, 9.96247041605571],
        1.9354830445337592, 0.0, 0.307068407148792, ULPS * 0.31),
}


def test_edge_starts_leaving_by_rounding_held_or_not_float64():
    """float64: on the +x top edge at 45 degrees (``R = 1/2``, ``g . n = -8 sqrt(1/2)``), a
    start moving round the edge at ``u`` across its axis and outwards at ``2^-40`` m/s (beyond
    the tangent margin, far inside the touch band's rise): the curve holds it when ``u^2 / R <
    -g . n`` (in at once, ``s = 0``); faster it leaves the curve, and the next contact is a
    return to the edge or the landing on the top face (``4 s^2 - u sqrt(1/2) s + 1/2 - R
    sqrt(1/2) = 0``), never ``s = 0``. (``arc.held_within_rounding``: the curvature term, its
    sign and the edge/face count; float32 cannot hold the 2^-40.)"""
    point = np.array([1.0 + RB * SQ2, 0.5 + RB * SQ2, 0.0])
    out_v = 2.0**-40 * np.array([1.0, 1.0, 0.0])
    rows = [(0.5, 0.0), (np.sqrt(3.2), None), (np.sqrt(8.0), "top")]  # u^2 = 1/4, 3.2, 8
    a = np.array([point] * len(rows))
    v = np.array([u * SQ2 * np.array([-1.0, 1.0, 0.0]) + out_v for u, _ in rows])
    out = run_arcs("float64", a, v, [0.0, -8.0, 0.0], 1.0, H, RB)
    assert np.all(out["hit"] == 1)
    for k, (u, want) in enumerate(rows):
        if want == 0.0:
            assert out["s"][k] == 0.0
        elif want == "top":
            up = u * SQ2  # the vertical part of the speed round the edge
            s_top = (up + np.sqrt(up * up - 16.0 * (0.5 - RB * SQ2))) / 8.0
            assert out["s"][k] == pytest.approx(s_top, abs=1e-11)
        else:
            assert out["s"][k] > 0.01


@pytest.mark.parametrize("precision", ["float64"])
def test_root_polish_stays_in_its_bracket(precision):
    """``polish_root``: the root of F in ``[lo, hi]`` [s], against the float64 NumPy roots of
    the quartic, to 1e-12 of the bracket (the kernel stops at 4 ulps). Float64 only, as the
    dip search above (one kernel for both)."""
    rows = list(ROOTS.values())
    _, _, root, *_ = run_searches(precision, rows)
    for k, (name, (c0, c1, c2, radius, lo, hi, _tol)) in enumerate(ROOTS.items()):
        f = gap_polynomial(c0, c1, c2, radius)
        assert f(lo) > 0.0 >= f(hi), name
        real = [r.real for r in f.roots() if abs(r.imag) < 1e-9 and lo <= r.real <= hi]
        assert len(real) == 1, name
        assert root[k] == pytest.approx(real[0], abs=1e-12 * (hi - lo)), name


#: Corner pieces ``[lo, hi]`` (units as in :data:`DIPS`, the time origin at the piece's start)
#: whose entering root lies in a dip just past the concave part of F: ``F'' < 0`` from 1.459
#: to 2.153 s, and the convex part after it falls to -1.0e-4 R^2 at 2.422 s, below zero from
#: 2.4146 to 2.4300 s. A split moved by a wrong ``F''`` leaves that dip in the part taken for
#: concave, where no dip is searched (``F > 0`` at both its ends).
PIECES = {
    "a dip just past the concave part": (
        [-1.7930190099816006, 0.8570593814879615, 0.22279608143175034],
        [2.0857661155819724, -0.5857688308454208, -0.9108988148188545],
        [-0.5810355638456228, 0.15062571235590275, 0.2507360492900225],
        0.6235339536923699, 0.0, 2.6397706355848864, ULPS * 2.6397706355848864),
}


@pytest.mark.parametrize("precision", ["float64"])
def test_quartic_entry_on_a_dip_beside_the_concave_part(precision):
    """``quartic_entry``: the first entering root of F in ``[lo, hi]`` [s], against the float64
    NumPy roots of the quartic, to 1e-12 of the piece; the construction checked first (the
    root's dip lies in the convex part that starts where the concave part ends, the roots of
    ``F''``). Float64 only, as the searches above (one kernel for all three)."""
    rows = list(PIECES.values())
    *_, entered, entry = run_searches(precision, rows)
    for k, (name, (c0, c1, c2, radius, lo, hi, _tol)) in enumerate(PIECES.items()):
        f = gap_polynomial(c0, c1, c2, radius)
        split = sorted(r.real for r in f.deriv(2).roots() if abs(r.imag) < 1e-12)
        real = sorted(r.real for r in f.roots() if abs(r.imag) < 1e-9 and lo <= r.real <= hi)
        assert f(lo) > 0.0 and f(hi) > 0.0 and len(split) == 2 and len(real) == 2, name
        assert split[1] < real[0] and f.deriv()(real[0]) < 0.0 < f.deriv()(real[1]), name
        assert entered[k] == 1, name
        assert entry[k] == pytest.approx(real[0], abs=1e-12 * (hi - lo)), name


def axis_gravity_case(rng, kind):
    """An arc built backwards from a chosen contact on a rounded box (as ``contact_case``),
    with gravity along one local axis, as for a box not rotated against gravity: the other two
    coordinates are linear in ``s``, and their slab crossings are the linear roots."""
    h = shaped_half_extents(rng, kind, 0.1, 1.0)
    radius = rng.choice([0.05, 0.3]) if kind != "point" else rng.uniform(0.1, 0.5)
    g = np.zeros(3)
    g[rng.integers(3)] = rng.choice([-9.81, 9.81])
    drawn = surface_point(rng, h, radius)
    if drawn is None:
        return None
    point, normal, _ = drawn
    tau = rng.uniform(0.5, 1.0)
    s_star = tau * rng.uniform(0.2, 0.6)
    arc = entering_arc(rng, point, normal, g, s_star)
    return None if arc is None else (h, radius, *arc, g, tau)


def test_arcs_with_gravity_along_an_axis_match_the_reference(precision):
    """Arcs under gravity along one local axis (two coordinates moving linearly, each crossing
    its core slab's planes once at most) onto faces, edges and corners of rounded boxes: the
    contact point [m] and normal of the float64 26-feature reference."""
    rng = np.random.default_rng(23)
    kinds = ["box", "plate", "stick", "point", "cube"]
    cases = []
    while len(cases) < 100:
        case = axis_gravity_case(rng, kinds[len(cases) % len(kinds)])
        if case is None:
            continue
        h, radius, a, v, g, tau = case
        a, v, h = (as_precision(x, precision) for x in (a, v, h))
        radius = float(as_precision(radius, precision))
        if signed_distance(a, h, radius) > 0.05:
            cases.append((a, v, g, tau, h, radius))
    cols = [np.array([np.asarray(c[k], float) for c in cases]) for k in range(6)]
    out = run_arcs(precision, *cols)
    checked = 0
    for k, (a, v, g, tau, h, radius) in enumerate(cases):
        ref_hit, ref_s, ref_n = arc_contact_by_features(a, v, g, tau, h, radius)
        assert ref_hit, k
        u = v + g * ref_s
        steep = -np.dot(u, ref_n) / np.linalg.norm(u)
        if steep < STEEP:
            continue
        scale = max(np.abs(a).max(), h.max() + radius)
        assert out["hit"][k] == 1, k
        np.testing.assert_allclose(arc_point(a, v, g, out["s"][k]), arc_point(a, v, g, ref_s),
                                   atol=POSITION_REL[precision] * scale / steep)
        np.testing.assert_allclose(out["normal"][k], ref_n, atol=NORMAL_TOL[precision] / steep)
        checked += 1
    assert checked >= 80


@pytest.mark.parametrize("length, time", [(2.0**-10, 1.0), (2.0**10, 1.0), (1.0, 2.0**-6),
                                          (1.0, 2.0**6), (2.0**10, 2.0**-6)],
                         ids=["mm", "km", "short time", "long time", "km, short time"])
def test_named_arcs_at_other_scales(precision, length, time):
    """The named arcs with lengths scaled by ``length`` (positions, half extents, radii [m])
    and times by ``time`` (``tau`` and contact times [s]; velocities by ``length / time``,
    accelerations by ``length / time^2``): powers of two, so every input and closed form
    scales exactly, and the answers scale with them (the normals unchanged). The sweep's
    margins (touch, root, tangent, gravity, sharpness) are relative to the local scale, the
    span and the speeds, so nothing else may change."""
    rows = list(NAMED.values())
    cols = [np.array([np.asarray(r[k], float) for r in rows]) for k in range(6)]
    a, v, g, tau, h, radius = cols
    out = run_arcs(precision, a * length, v * (length / time), g * (length / time**2),
                   tau * time, h * length, radius * length)
    s_tol = {"float32": 4e-6, "float64": 1e-13}[precision]
    for k, (name, row) in enumerate(NAMED.items()):
        hit, s, normal = row[6:]
        span = float(as_precision(row[3] * time, precision))
        assert out["hit"][k] == hit, name
        if hit:
            assert out["s"][k] == pytest.approx(s * time, abs=s_tol * max(time, span)), name
            np.testing.assert_allclose(out["normal"][k], normal, atol=NORMAL_TOL[precision],
                                       err_msg=name)
        else:
            assert out["s"][k] == span, name


def test_sharpness_threshold_against_the_local_scale(precision):
    """A box is sharp when ``R <= SHARP_REL * scale``, the scale being the largest of the
    grown half extents and ``|a|``: its entry through an edge region is the grown-box entry,
    with the normal of the face crossed last (a rounded one walks on to the edge's capsule, a
    tilted normal). ``R = 64 eps``, boxes ``1/8`` m half wide, the
    arcs entering beside an edge, 16 eps of time between the two faces' planes: sharp only
    through one half extent 8 m long, or through a start 7.125 m out along one axis (that
    axis's face crossed last, at 16 m/s); the scale without that component is about 1 m.
    Gravity 1 m/s^2 along the axis that stays inside its slab. Positions [m], times [s]."""
    eps = float(np.finfo(types_of(precision).np_dtype).eps)
    rows = []  # (a, v, g, h, normal); every entry at s = 7/16 - 16 eps
    for axis in range(3):
        first, last = [k for k in range(3) if k != axis]
        a, v, g, h = np.zeros(3), np.zeros(3), np.zeros(3), np.full(3, 0.125)
        h[axis] = 8.0
        a[[first, last]] = 1.0, 1.0 + 32 * eps
        v[[first, last]] = -2.0
        g[axis] = -1.0
        rows.append((a, v, g, h, np.eye(3)[last]))
        first, still = (axis + 1) % 3, (axis + 2) % 3
        a, v, g, h = np.zeros(3), np.zeros(3), np.zeros(3), np.full(3, 0.125)
        a[[axis, first]] = 7.125 - 192 * eps, 1.0
        v[[axis, first]] = -16.0, -2.0
        g[still] = -1.0
        rows.append((a, v, g, h, np.eye(3)[axis]))
    a, v, g, h, normals = (np.array([r[k] for r in rows]) for k in range(5))
    out = run_arcs(precision, a, v, g, 1.0, h, 64 * eps)
    for k, normal in enumerate(normals):
        assert out["hit"][k] == 1, k
        assert out["s"][k] == pytest.approx(0.4375 - 16 * eps, abs=4 * eps), k
        np.testing.assert_array_equal(out["normal"][k], normal, err_msg=str(k))
