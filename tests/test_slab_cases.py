"""The grown-box (slab) stage of the chord sweep, through ``collide_box``: named cases built so
that each answer is exact in binary (the mutation check's survivors of ``kernels/slab.py``).

Box at the origin, core half extents 0.5, no rounding and a point sphere (``R = 0``: the grown
box is the box, the slab entry is the contact), unless a case says otherwise.
"""

import numpy as np
import pytest

import warpsim as ws

SHARP = ws.RoundedBox(half_extents=(0.5, 0.5, 0.5), radius=0.0)

CASES = [
    # name, start, displacement over the frame, hit, t, normal
    ("along-x", [-2.0, 0.0, 0.0], [4.0, 0.0, 0.0], True, 0.375, [-1, 0, 0]),
    ("along-y", [0.0, 2.0, 0.0], [0.0, -4.0, 0.0], True, 0.375, [0, 1, 0]),
    ("along-z", [0.0, 0.0, -2.0], [0.0, 0.0, 4.0], True, 0.375, [0, 0, -1]),
    # the face plane is reached exactly at the end of the frame: t = 1 is in [0, 1]
    ("touch-at-t=1", [-2.0, 0.0, 0.0], [1.5, 0.0, 0.0], True, 1.0, [-1, 0, 0]),
    # falls short: the plane would be reached at t = 2
    ("short", [-2.0, 0.0, 0.0], [0.75, 0.0, 0.0], False, 1.0, [0, 0, 0]),
    # passes beside the corner: the x window [0.375, 0.625] ends before the y one [0.7, 1.7]
    ("beside-the-corner", [-2.0, 1.2, 0.0], [4.0, -1.0, 0.0], False, 1.0, [0, 0, 0]),
    # crosses both planes of an edge at t = 0.375: the tie goes to the lower axis
    ("edge-tie", [-2.0, -2.0, 0.0], [4.0, 4.0, 0.0], True, 0.375, [-1, 0, 0]),
    # 1 nm in the frame against a box of 0.5 nm: a slow path is not a parallel one (no
    # component is below eps |d|), whatever the units
    ("slow", [-(2.0**-31 + 2.0**-32), 0.0, 0.0], [2.0**-30, 2.0**-34, 0.0], True, 0.5,
     [-1, 0, 0]),
]

TINY = ws.RoundedBox(half_extents=(2.0**-32,) * 3, radius=0.0)


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("name,a,d,hit,t,normal", CASES, ids=[c[0] for c in CASES])
def test_slab_case(name, a, d, hit, t, normal, precision):
    box = TINY if name == "slow" else SHARP
    c = ws.collide_box([a], [d], 0.0, box, 1.0, precision=precision)
    assert c.hit[0] == hit, name
    assert c.t[0] == t, name
    np.testing.assert_array_equal(c.normal[0], normal)
