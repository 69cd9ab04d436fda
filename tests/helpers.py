"""Shared helpers of the tests (imported as ``helpers``): the devices to test on, a tolerance
table per precision, scenes built by hand, and every kernel variant the factories make."""

import itertools
import os

import numpy as np
import warp as wp

import warpsim  # noqa: F401  (sets Warp's log level before anything initialises it)

wp.init()

DEVICES = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])

#: The hypothesis profile conftest loads: ``ci`` (default, fixed examples) or ``wide``.
HYPOTHESIS_PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "ci")

#: How many times more examples the ``wide`` profile draws than ``ci``.
WIDE_FACTOR = 10


def examples(count: int) -> int:
    """``count`` hypothesis examples under the ``ci`` profile, ``WIDE_FACTOR`` times more under
    ``wide`` (for a test's ``@settings(max_examples=...)``)."""
    return count * (WIDE_FACTOR if HYPOTHESIS_PROFILE == "wide" else 1)

#: Tolerances per precision. ``rel``: relative error of a computed length against a float64
#: reference at unit scale (a few hundred ulps: the sweep chains ~20 roundings through a square
#: root); ``t_abs``: absolute error of a contact fraction ``t``; ``unit``: deviation of a unit
#: vector's length; ``angle``: normal direction error [rad].
TOLERANCES = {
    "float32": {"rel": 2e-5, "t_abs": 2e-5, "unit": 1e-6, "angle": 2e-3},
    "float64": {"rel": 1e-11, "t_abs": 1e-11, "unit": 1e-13, "angle": 1e-7},
}


def closed_room(half: float, thickness: float = 0.5, center=(0.0, 0.0, 0.0)):
    """Six sharp walls whose inner faces are the planes ``center +- half`` on each axis.

    Each wall overhangs the room by ``thickness`` on its four sides, so everywhere a sphere
    inside can touch it is the middle of a face (no edge, no corner of a wall is reachable).
    """
    import warpsim as ws

    centers, halves = [], []
    for axis in range(3):
        for side in (-1.0, 1.0):
            c = np.array(center, dtype=np.float64)
            c[axis] += side * (half + thickness)
            h = np.full(3, half + 2.0 * thickness)
            h[axis] = thickness
            centers.append(c)
            halves.append(h)
    return ws.RoundedBoxes(center=centers, half_extents=halves)


def shaped_half_extents(rng, kind: str, low: float, high: float) -> np.ndarray:
    """Random core half extents in [low, high] for a box ``kind``: "box" (all > 0), "plate"
    (one zero), "stick" (two zeros), "point" (all zero) or "cube" (all equal)."""
    h = rng.uniform(low, high, 3)
    if kind == "plate":
        h[rng.integers(3)] = 0.0
    elif kind == "stick":
        h[rng.choice(3, 2, replace=False)] = 0.0
    elif kind == "point":
        h[:] = 0.0
    elif kind == "cube":
        h[:] = h[0]
    return h


#: Both values of each boolean feature flag.
FLAGS = (False, True)


def every_kernel_variant() -> list[tuple[str, object]]:
    """``(label, kernel)`` for every kernel every factory can return: the collide kernel per
    precision x motion x broad phase, the bounce kernel also over ``spin`` x ``lossy``, the
    frame kernel also over ``energy_correction`` x ``events``. Making a kernel object compiles
    nothing (that happens at its first launch), so the whole product is cheap to enumerate.
    The labels read ``factory/precision/motion/broad phase[/spin/lossy[/correction/events]]``.
    """
    from warpsim.kernels.collide_kernels import bounce_kernel, collide_kernel
    from warpsim.kernels.data import BROAD_PHASES, MOTIONS, PRECISIONS, Features
    from warpsim.kernels.frame_kernel import frame_kernel

    out = []
    for p, m, b in itertools.product(PRECISIONS, MOTIONS, BROAD_PHASES):
        f = Features(precision=p, motion=m, broad_phase=b)
        out.append((f"collide/{p}/{m}/{b}", collide_kernel(f)))
        for spin, lossy in itertools.product(FLAGS, FLAGS):
            out.append((f"bounce/{p}/{m}/{b}/{spin}/{lossy}",
                        bounce_kernel(f.but(spin=spin, lossy=lossy))))
            for corr, events in itertools.product(FLAGS, FLAGS):
                out.append((f"frame/{p}/{m}/{b}/{spin}/{lossy}/{corr}/{events}",
                            frame_kernel(f.but(spin=spin, lossy=lossy, energy_correction=corr,
                                               events=events))))
    return out


