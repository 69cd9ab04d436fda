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

#: ``WARPSIM_TEST_SALT=N`` (conftest): every NumPy generator seeded with an integer or a list of
#: integers, the tests' and the package's alike, is seeded with ``N`` mixed in, so the suite's
#: random scenes, swarms and draws are drawn again (a search beyond the fixed seeds, as the
#: ``wide`` profile is for hypothesis's tests). None (unset or empty): the seeds as written.
TEST_SALT = int(os.environ["WARPSIM_TEST_SALT"]) if os.environ.get("WARPSIM_TEST_SALT") else None


#: NumPy's own ``default_rng``, whatever conftest puts in its place under a salt.
NUMPY_DEFAULT_RNG = np.random.default_rng


def salted_default_rng(default_rng, salt: int):
    """``default_rng`` with ``salt`` put in front of an integer seed or a list of them (any
    other seed, None included, passes through unchanged)."""

    def salted(seed=None, *args, **kwargs):
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seed = [salt, int(seed)]
        elif isinstance(seed, (list, tuple)) and seed and all(
                isinstance(k, (int, np.integer)) for k in seed):
            seed = [salt, *map(int, seed)]
        return default_rng(seed, *args, **kwargs)

    return salted


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


def kernel_variant_specs() -> list[tuple[str, object, object]]:
    """``(label, factory, features)`` for every kernel every factory can return, without making
    any: the collide kernel per precision x motion x broad phase, the bounce kernel also over
    ``spin`` x ``lossy``, the frame kernel also over ``energy_correction`` x ``events``, once
    with births (spin and events on) and, ballistic, once under gravity (``falls``). The labels
    read ``factory/precision/motion/broad phase[/spin/lossy[/correction/events]]``
    (``.../births`` and ``.../falls`` for those variants). ``factory(features)`` makes the
    kernel object: it compiles nothing (that happens at its first launch), but Warp hashes the
    kernel's code to name its module, about 0.1 s a variant.
    """
    from warpsim.kernels.collide_kernels import bounce_kernel, collide_kernel
    from warpsim.kernels.data import BROAD_PHASES, MOTIONS, PRECISIONS, Features
    from warpsim.kernels.frame_kernel import frame_kernel

    out = []
    for p, m, b in itertools.product(PRECISIONS, MOTIONS, BROAD_PHASES):
        f = Features(precision=p, motion=m, broad_phase=b)
        out.append((f"collide/{p}/{m}/{b}", collide_kernel, f))
        for spin, lossy in itertools.product(FLAGS, FLAGS):
            out.append((f"bounce/{p}/{m}/{b}/{spin}/{lossy}", bounce_kernel,
                        f.but(spin=spin, lossy=lossy)))
            for corr, events in itertools.product(FLAGS, FLAGS):
                out.append((f"frame/{p}/{m}/{b}/{spin}/{lossy}/{corr}/{events}", frame_kernel,
                            f.but(spin=spin, lossy=lossy, energy_correction=corr,
                                  events=events)))
        out.append((f"frame/{p}/{m}/{b}/births", frame_kernel,
                    f.but(spin=True, events=True, births=True)))
        if m == "ballistic":
            out.append((f"frame/{p}/{m}/{b}/falls", frame_kernel, f.but(falls=True)))
    return out


def every_kernel_variant() -> list[tuple[str, object]]:
    """``(label, kernel)`` for every kernel of :func:`kernel_variant_specs`."""
    return [(label, factory(features)) for label, factory, features in kernel_variant_specs()]


def exact_entry(start, motion, center, radius) -> tuple[bool, float]:
    """The exact first entry of ``start + t motion``, ``t`` in [0, 1], into the ball of
    ``radius`` about ``center`` (or, given the components across a cylinder's axis, into the
    cylinder).

    Every input is taken at its exact value (floats at their binary value, or
    :class:`fractions.Fraction`), so ``|d|^2 t^2 + 2 (w . d) t + |w|^2 - radius^2`` has exact
    rational coefficients and its discriminant an exact sign; the root is taken to 50 digits
    (:mod:`decimal`) and rounded once. An independent answer for the stable-root tests,
    whatever the distance.

    Returns:
        ``(hit, t)``: a hit needs a start outside, motion in, a discriminant > 0 (a tangent
        touch is no entry) and a root <= 1; ``t`` is 1 without a hit.
    """
    from decimal import Decimal, localcontext
    from fractions import Fraction

    def exact(x) -> Fraction:
        return x if isinstance(x, Fraction) else Fraction(float(x))

    w = [exact(x) - exact(c) for x, c in zip(start, center, strict=True)]
    d = [exact(x) for x in motion]
    r = exact(radius)
    qa = sum(x * x for x in d)
    qb = sum(x * y for x, y in zip(w, d, strict=True))
    qc = sum(x * x for x in w) - r * r
    disc = qb * qb - qa * qc
    if not (qc > 0 and qb < 0 and disc > 0):
        return False, 1.0
    with localcontext() as ctx:
        ctx.prec = 50

        def dec(x: Fraction) -> Decimal:
            return Decimal(x.numerator) / Decimal(x.denominator)

        t = (dec(-qb) - dec(disc).sqrt()) / dec(qa)
    return (True, float(t)) if t <= 1 else (False, 1.0)


def textbook_entry(start, motion, center, radius, dtype) -> tuple[bool, float]:
    """:func:`exact_entry` computed in ``dtype`` with the textbook discriminant
    ``(w . d)^2 - |d|^2 c``, to show that a stable-root case is one where that form fails; a
    zero discriminant counts as a hit (``>= 0``, as the NumPy sweep had it)."""
    w = np.asarray(start, dtype) - np.asarray(center, dtype)
    d, r = np.asarray(motion, dtype), dtype(radius)
    qa, qb, qc = d @ d, w @ d, w @ w - r * r
    disc = qb * qb - qa * qc
    if not (qc > 0 and qb < 0 and disc >= 0):
        return False, 1.0
    t = float(qc / (-qb + np.sqrt(disc)))
    return (True, t) if t <= 1 else (False, 1.0)


#: Aims of the far passes, as fractions of the Minkowski radius ``R``: three through the
#: feature (from 3 % of ``R`` inside its surface), two beside it. Above ``1 / sqrt(2)`` so that
#: the diagonal pass by an edge enters its cylinder, not the face before it.
FAR_AIMS = (0.75, 0.9, 0.97, 1.03, 1.2)


def far_passes(feature: str, distance: float, big_r: float, dtype) -> list[dict]:
    """Straight passes by a rounded box's feature from ``distance`` [m] on either side, one per
    aim of :data:`FAR_AIMS`, in the box's frame, with the coordinates rounded to ``dtype``.

    ``feature`` "ball": a point box (``h = 0``) at the origin, passed along x at ``y = aim R``.
    ``feature`` "edge": the unit cube's edge along z at ``x = y = 1``, passed at ``z = 0.3``
    along ``(1, -1, 0) / sqrt(2)`` at ``aim R`` from the edge's axis along ``(1, 1, 0) /
    sqrt(2)`` (with ``aim > 1 / sqrt(2)`` the path meets no face's rectangle first).

    Returns:
        One dict per pass: ``name``, ``a`` and ``d`` (3,) in ``dtype``, ``h`` (3,), and
        ``across`` (the coordinates across the feature) and ``axis_point`` (the feature's centre
        in them), the arguments :func:`exact_entry` needs.
    """
    rows = []
    for aim in FAR_AIMS:
        if feature == "ball":
            a = np.array([-distance, aim * big_r, 0.0])
            d = np.array([2.0 * distance, 0.0, 0.0])
            h, across, axis_point = np.zeros(3), [0, 1, 2], (0.0, 0.0, 0.0)
        else:
            normal = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
            along = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0)
            a = np.array([1.0, 1.0, 0.3]) + aim * big_r * normal - distance * along
            d = 2.0 * distance * along
            h, across, axis_point = np.ones(3), [0, 1], (1.0, 1.0)
        rows.append({"name": f"{feature} from {distance:g} m, aim {aim:g} R",
                     "a": a.astype(dtype), "d": d.astype(dtype), "h": h,
                     "across": across, "axis_point": axis_point})
    return rows


def emitter_velocity_formula(emitter, rng: np.random.Generator, n: int) -> np.ndarray:
    """An emitter's ``n`` velocities drawn serially from ``rng``, the formula written out over
    whole arrays: ``v0 + j U + s (cos(theta) a + sin(theta) cos(phi) u + sin(theta) sin(phi)
    w)``, with U, then s, cos(theta) and phi drawn in turn."""
    import math

    from warpsim.emitter import _orthonormal_pair

    expected = (np.asarray(emitter.velocity) + np.asarray(emitter.velocity_jitter)
                * rng.uniform(-1.0, 1.0, size=(n, 3)))
    if emitter.speed is not None:
        speed = rng.uniform(*emitter.speed, size=n)
        cos_theta = rng.uniform(math.cos(math.radians(emitter.cone_deg)), 1.0, size=n)
        phi = rng.uniform(0.0, 2.0 * math.pi, size=n)
        sin_theta = np.sqrt(np.maximum(0.0, 1.0 - cos_theta * cos_theta))
        axis = np.asarray(emitter.direction) / np.linalg.norm(emitter.direction)
        u, w = _orthonormal_pair(axis)
        expected = expected + speed[:, None] * (cos_theta[:, None] * axis
                                                + (sin_theta * np.cos(phi))[:, None] * u
                                                + (sin_theta * np.sin(phi))[:, None] * w)
    return expected
