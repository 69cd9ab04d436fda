"""Whether a run is feasible as a whole, before anything is uploaded: every number against what
the chosen precision can hold (:func:`check_run`; a :class:`PrecisionWarning` where float32 loses
too much) and no sphere starting inside an obstacle (:func:`check_outside`).

The fields themselves are checked by :mod:`warpsim.validation`, which these checks call; this
module imports nothing else from warpsim.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from .blocks import for_row_blocks
from .validation import bounce_cap, first_bad_row, float_dtype, format_row, scalar

MAGNITUDE_MARGIN = 1e-8
"""Largest magnitude of a stored number, as a fraction of the precision's largest finite value
(float32: 3.4e30, float64: 1.8e300): the kernels add and multiply a few such values (a dot
product, ``m g h``, ``m |v|^2``), which must stay finite."""

START_INSIDE_ULPS = 16.0
"""A sphere may start this many ulps of its coordinates inside an obstacle (and is then taken as
in contact): a sphere put exactly on a surface sits a few ulps off it once its position and the
box are rounded to the kernels' precision (the kernels' resting gap uses the same count)."""

MOTION_RESOLUTION = 1e-2
"""Warn when the precision's spacing at the scene's coordinates exceeds this fraction of a
frame's motion: each frame's move is then rounded by more than 1 %."""

RADIUS_RESOLUTION = 1e-2
"""Warn when the precision's spacing at the scene's coordinates exceeds this fraction of the
smallest non-zero sphere radius: contacts are then placed to worse than 1 % of a radius."""

MOTION_HOPELESS = 2.0
"""Refuse when the spacing is at least this many times a frame's largest motion: a move below
half the spacing rounds away entirely, so every sphere would freeze."""


class PrecisionWarning(UserWarning):
    """The chosen precision represents the run's numbers, but coarsely (see :func:`check_run`)."""


def _limits(dtype: np.dtype) -> tuple[float, float]:
    """``(largest magnitude, largest magnitude of a squared quantity)`` stored in ``dtype``."""
    limit = float(np.finfo(dtype).max) * MAGNITUDE_MARGIN
    return limit, math.sqrt(limit)


def _fits_float64(value: float, squared: bool) -> str:
    limit, square_limit = _limits(np.dtype(np.float64))
    return '; precision="float64" holds it' if value <= (square_limit if squared
                                                             else limit) else ""


def _refuse_large(field: str, magnitude, rows, quantity: str, unit: str, dtype: np.dtype,
                  squared: bool) -> None:
    """Raise when a magnitude exceeds the precision's limit (``squared``: its square must fit).

    Args:
        field: the field's name; with ``rows`` (the field's value per index) the message names
            the first bad index and shows its row.
        magnitude: the checked quantity, a scalar or one per row. quantity: how it is computed.
    """
    limit, square_limit = _limits(dtype)
    bound = square_limit if squared else limit
    magnitude = np.atleast_1d(np.asarray(magnitude, dtype=np.float64))
    bad = ~(magnitude <= bound)
    if not bad.any():
        return
    i = first_bad_row(bad)
    shown = f"[{i}] = {format_row(rows[i])}" if rows is not None else ""
    why = "its square must stay finite" if squared else "sums and products must stay finite"
    hint = "" if dtype == np.float64 else _fits_float64(float(magnitude[i]), squared)
    raise ValueError(f"{field}{shown} is too large for {dtype.name}: {quantity} = "
                     f"{magnitude[i]:.3g} {unit}, above {bound:.3g} ({why}){hint}")


def _norms(rows: np.ndarray) -> np.ndarray:
    """Euclidean norms of ``(N, 3)`` rows without overflow in the squares (float64 holds
    ``|v| = 1e200``, not ``|v|^2``)."""
    norms = np.empty(rows.shape[0])

    def block(part: slice) -> None:  # a row's norm is its own: blocks on every core
        scale = np.abs(rows[part]).max(axis=1, initial=0.0)
        safe = np.where(scale > 0.0, scale, 1.0)
        norms[part] = scale * np.linalg.norm(rows[part] / safe[:, None], axis=1)

    for_row_blocks(rows.shape[0], block)
    return norms


def _row_abs_max(rows: np.ndarray) -> np.ndarray:
    """The largest ``|component|`` of each of the ``(N, 3)`` rows (0 for none), in blocks of
    rows on every core."""
    out = np.empty(rows.shape[0])

    def block(part: slice) -> None:
        out[part] = np.abs(rows[part]).max(axis=1, initial=0.0)

    for_row_blocks(rows.shape[0], block)
    return out


def _share(ratio: float) -> str:
    """``"4.5 % of"`` or ``"380 times"``: how a ratio reads in a message."""
    return f"{100.0 * ratio:.2g} % of" if ratio < 1.0 else f"{ratio:.2g} times"


def scene_extent(boxes, position) -> float:
    """Largest coordinate magnitude [m] of the scene: the spheres' centres and the boxes'
    world bounds (0 for an empty scene)."""
    reach = [0.0]
    if len(position):
        reach.append(float(np.abs(position).max()))
    if len(boxes):
        reach.append(float((np.abs(boxes.center) + boxes.world_extent()).max()))
    return max(reach)


def check_run(scene, swarm, dt, precision, max_bounces) -> list[str]:
    """Check once, before anything is uploaded, that a run's numbers fit its precision.

    Every number is checked against what ``precision`` can hold, with margin (see
    :data:`MAGNITUDE_MARGIN`): ``dt`` must not underflow; gravity, ``|g| dt`` (a frame's velocity
    kick), ``|g| dt^2``, the speeds, ``|v| dt`` (a frame's path), the positions, the spheres'
    radii and kinetic energies, and the boxes' world bounds must stay finite, the squared ones
    too. Then float32's coarseness far from the origin: where the spacing of the numbers at the
    scene's coordinates (:func:`scene_extent`) is at least :data:`MOTION_HOPELESS` times a
    frame's largest motion (the larger of ``|g| dt^2`` and the largest ``|v| dt``) every sphere
    would freeze: refused; above :data:`MOTION_RESOLUTION` of that motion or
    :data:`RADIUS_RESOLUTION` of the smallest non-zero radius: a :class:`PrecisionWarning`.

    Args:
        scene: a :class:`warpsim.Scene` (its gravity, friction, angular speed cap and boxes).
        swarm: a :class:`warpsim.Swarm`.
        dt: time step [s]. precision: ``"float32"`` or ``"float64"``. max_bounces: the cap.

    Returns:
        The texts of the warnings given (each also issued with ``warnings.warn``).

    Raises:
        ValueError: one line naming the field (and the sphere or box index) that does not fit.
    """
    dtype = float_dtype(precision)
    dt = scalar("dt", dt, positive=True)
    bounce_cap(max_bounces)
    info = np.finfo(dtype)
    name = dtype.name

    if not dtype.type(dt) >= info.tiny:
        hint = "" if dtype == np.float64 else '; precision="float64" holds it'
        raise ValueError(f"dt = {dt:g} s underflows in {name} (smallest normal "
                         f"{float(info.tiny):.3g} s){hint}")
    _refuse_large("dt", dt, None, "dt", "s", dtype, squared=False)

    g = np.asarray(scene.gravity, dtype=np.float64)
    g_norm = float(_norms(g[None])[0])
    _refuse_large("gravity", g_norm, None, "|g|", "m/s^2", dtype, squared=False)
    _refuse_large("gravity", g_norm * dt, None, "|g| dt", "m/s", dtype, squared=True)
    _refuse_large("gravity", g_norm * dt * dt, None, "|g| dt^2", "m", dtype, squared=True)
    if g_norm > 0.0 and not dtype.type(g_norm * dt) >= info.tiny:
        raise ValueError(f"gravity * dt = {g_norm * dt:.3g} m/s underflows in {name}: a frame's "
                         f"gravity would do nothing")
    _refuse_large("friction", float(scene.friction), None, "k_f", "kg/s", dtype, squared=False)
    _refuse_large("max_angular_speed", float(scene.max_angular_speed), None, "|Rot|", "rad/s",
                  dtype, squared=False)

    position = np.asarray(swarm.position, dtype=np.float64)
    velocity = np.asarray(swarm.velocity, dtype=np.float64)
    radius = np.asarray(swarm.radius, dtype=np.float64)
    mass = np.asarray(swarm.mass, dtype=np.float64)
    angular = np.asarray(swarm.angular_momentum, dtype=np.float64)
    speed = _norms(velocity)
    _refuse_large("position", _row_abs_max(position), position,
                  "largest |coordinate|", "m", dtype, squared=True)
    _refuse_large("velocity", speed, velocity, "|v|", "m/s", dtype, squared=True)
    _refuse_large("velocity", speed * dt, velocity, "|v| dt", "m", dtype, squared=True)
    _refuse_large("radius", radius, radius, "r", "m", dtype, squared=True)
    _refuse_large("mass", mass, mass, "m", "kg", dtype, squared=False)
    tiny_mass = ~(mass.astype(dtype) >= info.tiny)
    if tiny_mass.any():
        i = first_bad_row(tiny_mass)
        raise ValueError(f"mass[{i}] = {mass[i]:g} kg underflows in {name} (smallest normal "
                         f"{float(info.tiny):.3g} kg)")
    _refuse_large("velocity", 0.5 * mass * speed * speed, velocity, "1/2 m |v|^2", "J", dtype,
                  squared=False)
    _refuse_large("angular_momentum", _row_abs_max(angular), angular,
                  "largest |component|", "kg m^2/s", dtype, squared=False)
    boxes = scene.boxes
    if len(boxes):
        reach = (np.abs(boxes.center) + boxes.world_extent()).max(axis=1)
        _refuse_large("box", reach, boxes.center, "|center| + size", "m", dtype, squared=True)

    extent = scene_extent(boxes, position)
    _refuse_large("the potential energy", extent * g_norm * mass.max(initial=0.0), None,
                  "m |g| |coordinate|", "J", dtype, squared=False)
    spacing = float(np.spacing(dtype.type(extent)))
    motion = max(g_norm * dt * dt, float(speed.max(initial=0.0)) * dt)
    where = (f"{name}'s spacing at the scene's coordinates (up to {extent:.3g} m) is "
             f"{spacing:.3g} m")
    fix = ('precision="float64" fixes it' if dtype == np.float32
           else "move the scene nearer the origin")
    if motion > 0.0 and spacing >= MOTION_HOPELESS * motion:
        raise ValueError(f"{where}, at least {MOTION_HOPELESS:g} times a frame's largest motion "
                         f"({motion:.3g} m): every sphere would freeze; {fix}")
    texts = []
    if motion > 0.0 and spacing > MOTION_RESOLUTION * motion:
        texts.append(f"{where}, {_share(spacing / motion)} a frame's largest motion "
                     f"({motion:.3g} m): every move is rounded that coarsely; {fix}")
    nonzero = radius[radius > 0.0]
    if nonzero.size and spacing > RADIUS_RESOLUTION * nonzero.min():
        texts.append(f"{where}, {_share(spacing / nonzero.min())} the smallest sphere "
                     f"radius ({nonzero.min():.3g} m): contacts are placed that coarsely; {fix}")
    for text in texts:
        warnings.warn(text, PrecisionWarning, stacklevel=3)
    return texts


def check_outside(boxes, position, radius, precision) -> None:
    """Refuse spheres that start inside an obstacle.

    A sphere starts inside when the signed distance of its surface to some box,
    ``boxes.signed_distance(p) - r``, is below minus a rounding tolerance:
    :data:`START_INSIDE_ULPS` ulps of ``precision`` at the pair's coordinates (the larger of the
    centre's, the sphere radius, the box centre's and its size). Exactly in contact, or a few ulps
    in, is legal. Memory stays bounded for any counts (see ``RoundedBoxes.nearest``).

    Args:
        boxes: a :class:`warpsim.RoundedBoxes`.
        position: sphere centres [m], (N, 3). radius: scalar or (N,) [m].
        precision: ``"float32"`` or ``"float64"``, the kernels' precision.

    Raises:
        ValueError: one line naming the first sphere inside (lowest index), the box it is
            deepest in, how deep, and how many spheres start inside.
    """
    eps = float(np.finfo(float_dtype(precision)).eps)
    position = np.asarray(position, dtype=np.float64).reshape(-1, 3)
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), position.shape[:1])
    if len(boxes) == 0 or len(position) == 0:
        return
    distance, index = boxes.nearest(position, within=radius)
    hit = index >= 0
    k = index[hit]
    scale = np.maximum.reduce([np.abs(position[hit]).max(axis=1), radius[hit],
                               np.abs(boxes.center[k]).max(axis=1),
                               boxes.half_extents[k].max(axis=1) + boxes.radius[k]])
    depth = radius[hit] - distance[hit]
    inside = depth > START_INSIDE_ULPS * eps * scale
    if not inside.any():
        return
    first = first_bad_row(inside)
    i, box = int(np.flatnonzero(hit)[first]), int(k[first])
    count = int(inside.sum())
    also = f"; {count} of {len(position)} spheres start inside" if count > 1 else ""
    raise ValueError(f"sphere {i} starts {depth[first]:.3g} m inside box {box} (position "
                     f"{format_row(position[i])}, radius {radius[i]:g}): spheres must start "
                     f"outside the obstacles or touching them{also}")
