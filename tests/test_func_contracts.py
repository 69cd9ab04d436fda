"""The ``@wp.func`` building blocks' contracts, tested directly through tiny test kernels.

Each table row names a case; segments are built backwards from the answer with fractions exact in
binary, so float64 results are compared exactly or to a few ulps, float32 to its tolerance.
"""

from functools import cache

import numpy as np
import pytest
import warp as wp
from helpers import exact_entry, far_passes

from warpsim.kernels.capsule import capsule_funcs
from warpsim.kernels.precision import precision as types_of
from warpsim.kernels.slab import slab_funcs
from warpsim.kernels.variant import variant_kernel


@cache
def slab_kernel(name: str):
    p = types_of(name)
    segment_slab = slab_funcs(p).segment_slab

    @variant_kernel
    def run(a: wp.array[p.vec3], d: wp.array[p.vec3], g: wp.array[p.vec3],
            hit_out: wp.array[wp.int32], t_enter_out: wp.array[p.scalar],
            t_exit_out: wp.array[p.scalar], axis_out: wp.array[wp.int32]):
        i = wp.tid()
        hit, t_enter, t_exit, axis = segment_slab(a[i], d[i], g[i])
        hit_out[i] = hit
        t_enter_out[i] = t_enter
        t_exit_out[i] = t_exit
        axis_out[i] = axis

    return run


@cache
def capsule_kernel(name: str):
    p = types_of(name)
    funcs = capsule_funcs(p)
    segment_capsule, segment_sphere = funcs.segment_capsule, funcs.segment_sphere

    @variant_kernel
    def run(a: wp.array[p.vec3], d: wp.array[p.vec3], e0: wp.array[p.vec3],
            e1: wp.array[p.vec3], radius: wp.array[p.scalar],
            sphere: wp.array[wp.int32], hit_out: wp.array[wp.int32],
            t_out: wp.array[p.scalar], normal_out: wp.array[p.vec3]):
        i = wp.tid()
        hit = int(0)  # noqa: UP018 (a dynamic Warp variable, not a constant)
        t = p.scalar(0.0)
        n = p.vec3()
        if sphere[i] == 1:
            hit, t, n = segment_sphere(a[i], d[i], e0[i], radius[i])
        else:
            hit, t, n = segment_capsule(a[i], d[i], e0[i], e1[i], radius[i])
        hit_out[i] = hit
        t_out[i] = t
        normal_out[i] = n

    return run


def run_rows(kernel, p, columns: dict, outputs: dict) -> dict:
    """Launch ``kernel`` over table rows; outputs are pre-filled with a sentinel so an unwritten
    one fails the comparison."""
    n = len(next(iter(columns.values()))[0])  # rows of the first column's values
    inputs = []
    for values, dtype in columns.values():
        inputs.append(wp.array(np.asarray(values, dtype=p.np_dtype if dtype is not wp.int32
                                          else np.int32), dtype=dtype, device="cpu"))
    outs = {}
    for name, dtype in outputs.items():
        fill = -7 if dtype is wp.int32 else np.nan
        shape = (n, 3) if dtype is p.vec3 else (n,)
        np_type = np.int32 if dtype is wp.int32 else p.np_dtype
        outs[name] = wp.array(np.full(shape, fill, dtype=np_type), dtype=dtype, device="cpu")
    wp.launch(kernel, dim=n, inputs=inputs + list(outs.values()), device="cpu")
    return {k: v.numpy() for k, v in outs.items()}


# name: (a, d, g, hit, t_enter (None: any < 0), t_exit, axis)
SLAB_CASES = {
    "enter x": ((-2, 0, 0), (4, 0, 0), (1, 1, 1), 1, 0.25, 0.75, 0),
    "enter y from above": ((0.5, 3, 0), (0, -4, 0), (1, 1, 1), 1, 0.5, 1.0, 1),
    "start inside": ((0, 0, 0), (4, 0, 0), (1, 1, 1), 1, None, 0.25, -1),
    "start inside, zero length": ((0, 0.5, 0), (0, 0, 0), (1, 1, 1), 1, None, 1.0, -1),
    "parallel, outside": ((-2, 1.5, 0), (4, 0, 0), (1, 1, 1), 0, None, None, None),
    "parallel, inside slab": ((-2, 0.5, 0), (4, 0, 0), (1, 1, 1), 1, 0.25, 0.75, 0),
    "parallel, on the plane (closed box)": ((-2, 1, 0), (4, 0, 0), (1, 1, 1), 1, 0.25, 0.75, 0),
    "stops short": ((-2, 0, 0), (0.5, 0, 0), (1, 1, 1), 0, None, None, None),
    "moving away": ((2, 0, 0), (1, 0, 0), (1, 1, 1), 0, None, None, None),
    "diagonal, enters through z": ((0.25, 0.25, -3), (0, 0.5, 8), (1, 1, 1), 1, 0.25, 0.5, 2),
    "zero-thickness plate": ((-2, 0, 0), (4, 0, 0), (0, 1, 1), 1, 0.5, 0.5, 0),
}


@pytest.mark.parametrize("name", list(SLAB_CASES))
def test_segment_slab(name, precision):
    p = types_of(precision)
    a, d, g, hit, t_enter, t_exit, axis = SLAB_CASES[name]
    out = run_rows(slab_kernel(precision), p,
                   {"a": ([a], p.vec3), "d": ([d], p.vec3), "g": ([g], p.vec3)},
                   {"hit": wp.int32, "t_enter": p.scalar, "t_exit": p.scalar, "axis": wp.int32})
    assert out["hit"][0] == hit
    if hit:
        assert out["axis"][0] == axis
        if t_enter is None:
            assert out["t_enter"][0] < 0.0
        else:
            assert out["t_enter"][0] == t_enter  # exact in binary: no rounding on the way
        assert out["t_exit"][0] == t_exit


# name: (a, d, e0, e1, radius, sphere?, hit, t, normal)
CAPSULE_CASES = {
    "sphere: head on": ((-3, 0, 0), (4, 0, 0), (0, 0, 0), (0, 0, 0), 1, 1, 1, 0.5, (-1, 0, 0)),
    "sphere: start inside": ((0.5, 0, 0), (1, 0, 0), (0, 0, 0), (0, 0, 0), 1, 1, 1, 0.0,
                             (1, 0, 0)),
    "sphere: start on surface": ((0, 1, 0), (0, 1, 0), (0, 0, 0), (0, 0, 0), 1, 1, 1, 0.0,
                                 (0, 1, 0)),
    "sphere: moving away": ((2, 0, 0), (1, 0, 0), (0, 0, 0), (0, 0, 0), 1, 1, 0, 1.0, (0, 0, 0)),
    # a tangent line touches (the rounded-box sweep then refuses it: d . n = 0 is no entry)
    "sphere: tangent line": ((-3, 1, 0), (6, 0, 0), (0, 0, 0), (0, 0, 0), 1, 1, 1, 0.5,
                             (0, 1, 0)),
    "sphere: root beyond the end": ((-3, 0, 0), (1, 0, 0), (0, 0, 0), (0, 0, 0), 1, 1, 0, 1.0,
                                    (0, 0, 0)),
    # a root exactly at t = 1 is in range: the segment's end touches (t in [0, 1], closed)
    "sphere: root at the end": ((-3, 0, 0), (2, 0, 0), (0, 0, 0), (0, 0, 0), 1, 1, 1, 1.0,
                                (-1, 0, 0)),
    # radius 0: the contact centre is the sphere's centre, so there is no normal (the
    # rounded-box sweep never asks: a Minkowski radius below SHARP_REL is a sharp box)
    "sphere: radius 0 (a point on the path)": ((-3, 0, 0), (4, 0, 0), (0, 0, 0), (0, 0, 0), 0,
                                               1, 1, 0.75, (0, 0, 0)),
    "capsule: side": ((0.5, 3, 0), (0, -4, 0), (0, 0, 0), (1, 0, 0), 1, 0, 1, 0.5, (0, 1, 0)),
    "capsule: end cap": ((3, 0, 0), (-4, 0, 0), (-1, 0, 0), (1, 0, 0), 1, 0, 1, 0.25, (1, 0, 0)),
    "capsule: along the axis, outside": ((-3, 2, 0), (6, 0, 0), (-1, 0, 0), (1, 0, 0), 1, 0, 0,
                                         1.0, (0, 0, 0)),
    "capsule: start inside the cylinder, heading for an end": ((-3, 0, 0), (4, 0, 0),
                                                               (1, 0, 0), (2, 0, 0), 0.5, 0, 1,
                                                               0.875, (-1, 0, 0)),
    "capsule: zero length is a sphere": ((-3, 0, 0), (4, 0, 0), (0, 0, 0), (0, 0, 0), 1, 0, 1,
                                         0.5, (-1, 0, 0)),
    "capsule: side entry at the end": ((0.5, 3, 0), (0, -2, 0), (0, 0, 0), (1, 0, 0), 1, 0, 1,
                                       1.0, (0, 1, 0)),
    # a start on the side is a start in contact, a hit at t = 0 whatever the motion (the
    # caller decides whether it goes in), as on the ball
    "capsule: start on the side, moving away": ((0.5, 1, 0), (0, 1, 0), (0, 0, 0), (1, 0, 0),
                                                1, 0, 1, 0.0, (0, 1, 0)),
    "capsule: miss beside the end": ((3, 0, 2), (-6, 0, 0), (-1, 0, 0), (1, 0, 0), 1, 0, 0, 1.0,
                                     (0, 0, 0)),
}


@pytest.mark.parametrize("name", list(CAPSULE_CASES))
def test_segment_sphere_and_capsule(name, precision, tol):
    p = types_of(precision)
    a, d, e0, e1, radius, sphere, hit, t, normal = CAPSULE_CASES[name]
    out = run_rows(capsule_kernel(precision), p,
                   {"a": ([a], p.vec3), "d": ([d], p.vec3), "e0": ([e0], p.vec3),
                    "e1": ([e1], p.vec3), "radius": ([radius], p.scalar),
                    "sphere": ([sphere], wp.int32)},
                   {"hit": wp.int32, "t": p.scalar, "normal": p.vec3})
    assert out["hit"][0] == hit
    np.testing.assert_allclose(out["t"][0], t, rtol=0, atol=tol["t_abs"])
    np.testing.assert_allclose(out["normal"][0], normal, rtol=0, atol=tol["unit"] * 10)


#: Far passes per precision: (distance [m], radius [m]) where the textbook discriminant has
#: lost every digit (float32: 5 cm from 300 m; float64: 1 cm from 1000 km).
FAR = {"float32": (300.0, 0.05), "float64": (1.0e6, 0.01)}


@pytest.mark.parametrize("feature", ["ball", "edge"])
def test_far_passes_agree_with_the_exact_root(feature, precision):
    """Passes by a ball (``segment_sphere``) and by a capsule's side (``segment_capsule``, the
    unit cube's z edge) from far away, through it and just beside it: the verdict, ``t`` (to a
    few ulps) and normal (to the start's rounding over the radius) of the exact rational root
    of the rounded inputs (``helpers.exact_entry``)."""
    from fractions import Fraction

    p = types_of(precision)
    distance, radius = FAR[precision]
    rows = far_passes(feature, distance, radius, p.np_dtype)
    ends = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)) if feature == "ball" else \
        ((1.0, 1.0, -1.0), (1.0, 1.0, 1.0))
    n = len(rows)
    out = run_rows(capsule_kernel(precision), p,
                   {"a": ([r["a"] for r in rows], p.vec3), "d": ([r["d"] for r in rows], p.vec3),
                    "e0": ([ends[0]] * n, p.vec3), "e1": ([ends[1]] * n, p.vec3),
                    "radius": ([radius] * n, p.scalar),
                    "sphere": ([int(feature == "ball")] * n, wp.int32)},
                   {"hit": wp.int32, "t": p.scalar, "normal": p.vec3})
    eps = float(np.finfo(p.np_dtype).eps)
    for k, row in enumerate(rows):
        across = row["across"]
        hit, t = exact_entry(row["a"][across], row["d"][across], row["axis_point"], radius)
        assert out["hit"][k] == hit, row["name"]
        assert out["t"][k] == pytest.approx(t, abs=8 * eps), row["name"]
        normal = np.zeros(3)
        if hit:
            contact = [Fraction(float(row["a"][i])) - Fraction(c) + Fraction(t)
                       * Fraction(float(row["d"][i])) for i, c in zip(across, row["axis_point"],
                                                                    strict=True)]
            normal[across] = np.array([float(x) for x in contact]) / radius
        np.testing.assert_allclose(out["normal"][k], normal, rtol=0,
                                   atol=8 * eps * distance / radius, err_msg=row["name"])
