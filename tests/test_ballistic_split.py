"""The ballistic frame in two halves: ``free_legs``, then ``held_rest`` for a held frame.

The frame kernel runs a ballistic frame's free legs in its loop of frames and finishes a frame
held at a contact that may be a support (``held_rest``, out of line) outside that loop
(``kernels.frame_kernel``). The two halves must give the bits of the whole frame,
``ballistic_path``: one test kernel runs both on the same state, frame after frame along the
whole frame's trajectory, over families of scenes where spheres bounce, come to rest, slide on
faces and off edges (lossy and elastic, with and without spin, both precisions), and every
output is compared bit for bit. The families are checked to reach the held half often.
"""

from functools import cache

import numpy as np
import pytest
import warp as wp
from test_arc_sweep import device_boxes
from test_ballistic_path import GRAVITY, physics_struct

import warpsim as ws
from warpsim.kernels.ballistic import ballistic_funcs
from warpsim.kernels.data import Features, model_structs
from warpsim.kernels.precision import precision as precision_of
from warpsim.model import event_buffer

DT = 1.0 / 60.0
MAX_BOUNCES = 8


@cache
def split_kernel(precision_name: str, lossy: bool, spin: bool):
    """One frame per sphere by ``ballistic_path`` (the ``whole_*`` outputs) and by its two
    halves (``split_*``), from the same state; ``held_out`` 1 where the halves held the frame."""
    p = precision_of(precision_name)
    scalar, vec3 = p.scalar, p.vec3
    Boxes, BroadPhase, Physics, EventBuffer = model_structs(p)
    funcs = ballistic_funcs(Features(precision=precision_name, motion="ballistic", spin=spin,
                                     lossy=lossy))
    whole, free_legs, held_rest = funcs.ballistic_path, funcs.free_legs, funcs.held_rest

    @wp.kernel(enable_backward=False, module="unique")
    def split_test(boxes: Boxes, broad: BroadPhase, physics: Physics,
                   radius: wp.array[scalar], mass: wp.array[scalar],
                   position: wp.array[vec3], velocity: wp.array[vec3],
                   angular_momentum: wp.array[vec3], energy: wp.array[scalar],
                   whole_state: wp.array2d[scalar], split_state: wp.array2d[scalar],
                   whole_counts: wp.array2d[wp.int32], split_counts: wp.array2d[wp.int32],
                   held_out: wp.array[wp.int32], events: EventBuffer):
        i = wp.tid()
        r = radius[i]
        m = mass[i]
        x0, v0, l0, e0, b0, c0, s0 = whole(position[i], velocity[i], r, m, angular_momentum[i],
                                           energy[i], physics, boxes, broad, 1, i, events)
        x1, v1, l1, e1, b1, c1, s1, held, rest, box, s, n = free_legs(
            position[i], velocity[i], r, m, angular_momentum[i], energy[i], physics, boxes,
            broad, 1, i, events)
        if held == 1:
            x1, v1, l1, e1, b1, c1, s1 = held_rest(x1, v1, l1, e1, rest, b1, c1, s1, r, m,
                                                   physics, boxes, broad, 1, i, events, box, s,
                                                   n)
        held_out[i] = held
        for k in range(3):
            whole_state[i, k] = x0[k]
            whole_state[i, 3 + k] = v0[k]
            whole_state[i, 6 + k] = l0[k]
            split_state[i, k] = x1[k]
            split_state[i, 3 + k] = v1[k]
            split_state[i, 6 + k] = l1[k]
        whole_state[i, 9] = e0
        split_state[i, 9] = e1
        whole_counts[i, 0] = b0
        whole_counts[i, 1] = c0
        whole_counts[i, 2] = s0
        split_counts[i, 0] = b1
        split_counts[i, 1] = c1
        split_counts[i, 2] = s1

    return split_test


def compare_halves(boxes: ws.RoundedBoxes, x, v, frames: int, precision_name: str,
                   retention: float, spin: bool, radius: float = 0.1) -> int:
    """Advance the spheres ``frames`` frames along the whole frame's trajectory, asserting at
    every frame that the halves give its bits; returns the frames the halves held."""
    p = precision_of(precision_name)
    dtp = p.np_dtype
    n = len(x)
    structs = device_boxes(boxes, p)
    physics = physics_struct(p, DT, 0.4 if spin else 0.0, retention, MAX_BOUNCES)
    mass = np.ones(n)
    x = np.asarray(x, float)
    v = np.asarray(v, float)
    spin_l = np.zeros((n, 3))
    if spin:
        spin_l = np.random.default_rng(7).normal(size=(n, 3)) * 0.01
    energy = 0.5 * np.einsum("ij,ij->i", v, v) + GRAVITY * x[:, 1]

    def put(a, dtype):
        return wp.array(np.ascontiguousarray(a, dtype=dtp), dtype=dtype)

    kernel = split_kernel(p.name, retention < 1.0, spin)
    held_frames = 0
    for frame in range(frames):
        outs = [wp.zeros((n, 10), dtype=p.scalar), wp.zeros((n, 10), dtype=p.scalar),
                wp.zeros((n, 3), dtype=wp.int32), wp.zeros((n, 3), dtype=wp.int32),
                wp.zeros(n, dtype=wp.int32)]
        wp.launch(kernel, dim=n, inputs=[*structs[:2], physics,
                                         put(np.full(n, radius), p.scalar), put(mass, p.scalar),
                                         put(x, p.vec3), put(v, p.vec3), put(spin_l, p.vec3),
                                         put(energy, p.scalar)],
                  outputs=[*outs, event_buffer(p, "cpu", 0)])
        whole, split, whole_counts, split_counts, held = (a.numpy() for a in outs)
        assert whole.tobytes() == split.tobytes(), f"frame {frame}: the states differ"
        np.testing.assert_array_equal(whole_counts, split_counts)
        held_frames += int(held.sum())
        x, v, spin_l = (whole[:, k:k + 3].astype(float) for k in (0, 3, 6))
        energy = whole[:, 9].astype(float)
    return held_frames


def plates_drop(rng, n):
    """Spheres released slowly above the bundled ``plates`` scene (tilted rounded plates)."""
    scene = ws.Scene.load("plates")
    swarm = scene.spawn(n=n, seed=int(rng.integers(1 << 30)))
    return scene.boxes, swarm.position, swarm.velocity * 0.2


def wedge_drop(rng, n):
    """Spheres released into the bundled ``wedge`` scene (a crease of two faces)."""
    scene = ws.Scene.load("wedge")
    swarm = scene.spawn(n=n, seed=int(rng.integers(1 << 30)))
    return scene.boxes, swarm.position, swarm.velocity * 0.5


def rotated_box_slides(rng, n):
    """Spheres put on or just above the faces, edges and corners of a tilted rounded box,
    moving slowly in random directions: rest, slides off faces and over rounded edges."""
    box = ws.RoundedBoxes(center=[(0.0, 0.0, 0.0)], half_extents=[(1.0, 0.3, 0.7)],
                          rotation=[(0.05, 0.0, 0.12, 0.99)], radius=[0.05])
    rot = box.rotation_matrices()[0]
    local = rng.uniform(-1.0, 1.0, size=(n, 3)) * np.array([1.2, 0.0, 0.9])
    # on the top face (its core's half height, the rounding, the sphere's radius), half of
    # them touching it and moving along it, the others just above it
    local[:, 1] = 0.3 + 0.05 + 0.1 + np.where(np.arange(n) % 2 == 0, 0.0,
                                              rng.uniform(0.0, 0.02, size=n))
    v_local = rng.normal(size=(n, 3)) * 0.3
    v_local[::2, 1] = 0.0
    return box, local @ rot.T, v_local @ rot.T


FAMILIES = {"plates": plates_drop, "wedge": wedge_drop, "rotated box": rotated_box_slides}


#: (precision, retention, spin): each a test kernel of its own (a first build of some seconds),
#: so elastic and lossy, with and without spin, and both precisions, in four of them.
VARIANTS = [("float32", 1.0, False), ("float64", 0.5, False), ("float32", 0.5, True),
            ("float64", 0.5, True)]


@pytest.mark.parametrize("precision_name, retention, spin", VARIANTS)
@pytest.mark.parametrize("family", sorted(FAMILIES))
def test_the_two_halves_give_the_whole_frames_bits(family, retention, spin, precision_name):
    rng = np.random.default_rng([len(family), int(retention * 10), spin])
    boxes, x, v = FAMILIES[family](rng, 48)
    held = compare_halves(boxes, x, v, 90, precision_name, retention, spin)
    if retention < 1.0 or family == "rotated box":
        assert held > 0, "the family never reached the held half"
