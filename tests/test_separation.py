"""The separation of a contact centre (``kernels/nearest.py``): the lift, its branch-free bound
and the decision to move a centre out, against a NumPy reference in the kernel's precision.

``separate`` tests the Minkowski radius against ``separation_bound`` before it computes the
lift, so it must move a centre exactly when ``R < SEPARATION * max |.|`` over the nine
magnitudes (the reference), whatever the magnitudes: zeros, subnormals, the largest finite
values, and radii a few ulps either side of the lift.
"""

from functools import cache

import numpy as np
import pytest
import warp as wp
from helpers import examples
from hypothesis import given, settings
from hypothesis import strategies as st

from warpsim.kernels.nearest import SEPARATION_ULPS, nearest_funcs
from warpsim.kernels.precision import precision as types_of
from warpsim.kernels.variant import variant_kernel

PRECISIONS = ["float32", "float64"]


@cache
def separation_kernel(name: str):
    p = types_of(name)
    funcs = nearest_funcs(p)
    lift_of, bound_of, separate = funcs.separation_lift, funcs.separation_bound, funcs.separate

    @variant_kernel
    def run(x: wp.array[p.vec3], travel: wp.array[p.vec3], extent: wp.array[p.vec3],
            normal: wp.array[p.vec3], big_r: wp.array[p.scalar], lift: wp.array[p.scalar],
            bound: wp.array[p.scalar], moved: wp.array[wp.int32]):
        i = wp.tid()
        lift[i] = lift_of(x[i], travel[i], extent[i])
        bound[i] = bound_of(x[i], travel[i], extent[i])
        out = separate(x[i], travel[i], normal[i], big_r[i], extent[i])
        moved[i] = 0
        if out[0] != x[i][0] or out[1] != x[i][1] or out[2] != x[i][2]:
            moved[i] = 1

    return run


def separation(name: str, x, travel, extent, big_r):
    """``(lift, bound, moved)`` of the kernel for rows of ``x``, ``travel``, ``extent`` and
    ``big_r``; the normal is +z."""
    p = types_of(name)
    n = len(big_r)
    arrays = [wp.array(np.asarray(v, dtype=name), dtype=p.vec3, device="cpu")
              for v in (x, travel, extent)]
    normal = wp.array(np.tile(np.array([0.0, 0.0, 1.0], dtype=name), (n, 1)), dtype=p.vec3,
                      device="cpu")
    radius = wp.array(np.asarray(big_r, dtype=name), dtype=p.scalar, device="cpu")
    lift = wp.zeros(n, dtype=p.scalar, device="cpu")
    bound = wp.zeros(n, dtype=p.scalar, device="cpu")
    moved = wp.zeros(n, dtype=wp.int32, device="cpu")
    wp.launch(separation_kernel(name), dim=n, inputs=[*arrays, normal, radius, lift, bound,
                                                     moved], device="cpu")
    return lift.numpy(), bound.numpy(), moved.numpy()


def reference_lift(name: str, x, travel, extent):
    """``SEPARATION_ULPS eps max |.|`` over the nine magnitudes, rounded once in ``name``."""
    dtype = np.dtype(name)
    nine = np.abs(np.concatenate([np.asarray(v, dtype=dtype) for v in (x, travel, extent)],
                                 axis=1))
    return dtype.type(SEPARATION_ULPS * np.finfo(dtype).eps) * nine.max(axis=1)


def magnitudes(name: str, rng, n: int):
    """``(n, 3)`` values of every scale the precision holds: zeros, subnormals, ordinary and
    near the largest finite, of both signs; the first tenth of the rows near the origin."""
    info = np.finfo(np.dtype(name))
    exponents = rng.uniform(np.log10(float(info.smallest_subnormal)) + 1,
                            np.log10(float(info.max)) - 2, (n, 3))
    v = np.sign(rng.uniform(-1, 1, (n, 3))) * 10.0 ** exponents
    v[rng.random((n, 3)) < 0.1] = 0.0
    v[rng.random((n, 3)) < 0.02] = float(info.max) / 4
    v[: n // 10] = rng.uniform(-3, 3, (n // 10, 3))  # near the origin, the common case
    return v.astype(name)


@pytest.mark.parametrize("name", PRECISIONS)
def test_bound_is_never_below_the_lift_and_the_decision_is_the_references(name):
    rng = np.random.default_rng(20261206)
    n = 4000
    x, travel, extent = (magnitudes(name, rng, n) for _ in range(3))
    ref = reference_lift(name, x, travel, extent)
    # radii at the lift, a few ulps either side of it, and far either side
    dtype = np.dtype(name)
    steps = rng.integers(-3, 4, n)
    big_r = ref.copy()
    for k in range(n):
        for _ in range(abs(int(steps[k]))):
            big_r[k] = np.nextafter(big_r[k], dtype.type(np.inf if steps[k] > 0
                                                          else 0.0), dtype=dtype)
    far = rng.random(n) < 0.3
    big_r[far] = (ref[far] * rng.choice([1e-3, 1e3], far.sum())).astype(dtype)
    lift, bound, moved = separation(name, x, travel, extent, big_r)
    np.testing.assert_array_equal(lift, ref)
    finite = np.isfinite(lift)
    assert (bound[finite] >= lift[finite]).all()
    # moved exactly when R < lift, and then the centre changed (the normal is +z)
    expect = big_r < ref
    wrong = np.flatnonzero(expect != moved.astype(bool))
    # only a move too small to change z, x_z + lift rounding back to x_z (the normal is +z),
    # may leave x as it was
    tiny = (x[wrong, 2] + ref[wrong]).astype(dtype) == x[wrong, 2]
    assert tiny.all(), f"row {wrong[~tiny][:3]}: moved {moved[wrong[~tiny][:3]]}"


@pytest.mark.parametrize("name", PRECISIONS)
@settings(max_examples=examples(40), deadline=None)
@given(data=st.data())
def test_radius_at_or_above_the_bound_leaves_the_centre(name, data):
    """The branch-free bound decides alone only where the lift would not move the centre."""
    floats = st.floats(-1e6, 1e6, allow_nan=False, width=32 if name == "float32" else 64)
    rows = [[data.draw(floats) for _ in range(3)] for _ in range(3)]
    x, travel, extent = ([row] for row in rows)
    _, bound, _ = separation(name, x, travel, extent, [0.0])
    lift, _, moved = separation(name, x, travel, extent, bound)
    assert bound[0] >= lift[0]
    assert moved[0] == 0
