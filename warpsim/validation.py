"""Every check of warpsim's inputs, in one place: types, shapes, bounds and what a precision holds.

The classes (:class:`warpsim.Scene`, :class:`warpsim.Swarm`, :class:`warpsim.RoundedBox`,
:class:`warpsim.RoundedBoxes`, :class:`warpsim.Emitter`), the scene files and the simulator all
call these functions; none of them repeats a check. Each checker returns a new value that the
caller owns (float64 or int numpy arrays, Python floats and ints); what it was given is never
modified. A bad value raises ``ValueError`` naming the field and, for arrays, the index of the
first bad entry, e.g. ``radius[3] must be >= 0, got -0.1``. ``name`` is the field as the user
wrote it: scene files pass ``box[3].half_extents``, so their messages read
``box[3].half_extents[1] must be >= 0, got -0.1``.

Numbers must be numbers: strings, booleans and None are refused where a number is expected
(numpy alone would read ``True`` as 1, ``"0.1"`` as 0.1 and ``None`` as nan). Integers (counts,
frames, seeds, the bounce cap) must be below ``2**31``: the kernels count in 32-bit integers.

Two checks look at a whole run rather than one field: :func:`check_run` (every number against
what the chosen precision can hold; :class:`PrecisionWarning` where float32 loses too much) and
:func:`check_outside` (no sphere may start inside an obstacle).

This module imports nothing else from warpsim: every other module may import it.
"""

from __future__ import annotations

import itertools
import math
import numbers
import warnings
from collections.abc import Mapping, Sequence

import numpy as np

PRECISIONS = ("float32", "float64")
BROAD_PHASES = ("auto", "bvh", "brute", "grid")
MOTIONS = ("linear", "ballistic")
DTYPES = {"float32": np.float32, "float64": np.float64}

INT_LIMIT = 2**31
"""Integers must be below this: the kernels count spheres, frames and bounces in ``int32``, and
a larger value would wrap around silently (``2**32`` bounces would become 0)."""

MAX_BOUNCES = 1024
"""Largest ``max_bounces`` accepted. The cap is compiled into the kernel's bounce loop; a sphere
wedged in a corner takes a few contacts per frame, and a cap this high already means a sphere
may spend a thousand sweeps over the obstacles in one frame."""

QUAT_MIN_NORM = 1e-12
"""A quaternion shorter than this has no reliable direction to normalise (its components are
rounding noise): refused as a zero quaternion."""

UNIT_SLACK = 4.0 * np.finfo(np.float64).eps
"""Quaternions whose length is within this of 1 are kept bit for bit, so validating an already
validated quaternion (a box taken out of a group and put back) changes nothing."""

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


# --- numbers ---------------------------------------------------------------------------------


def _short(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _fmt(row) -> str:
    row = np.asarray(row)
    if row.ndim == 0:
        return f"{float(row):g}"
    return "(" + ", ".join(f"{float(x):g}" for x in row) + ")"


def _is_scalar_number(x) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


def _first_non_number(item):
    """``(True, leaf)`` for the first leaf of a nested item that is not a number, else
    ``(False, None)``."""
    if _is_scalar_number(item):
        return False, None
    if isinstance(item, (list, tuple)):
        for x in item:
            found = _first_non_number(x)
            if found[0]:
                return found
        return False, None
    if isinstance(item, np.ndarray):
        if item.dtype.kind in "iuf":
            return False, None
        if item.dtype.kind == "O":
            return _first_non_number(item.tolist())
    return True, item


def _only_numbers(value: list | tuple) -> bool:
    """Whether a nested list holds numbers only: the fast path of :func:`_refuse_non_numbers`,
    looking at the set of leaf types one nesting level at a time (a million rows in ~0.2 s)."""
    level = value
    types = set(map(type, level))
    while types & {list, tuple}:
        if not types <= {list, tuple}:
            return False  # lists mixed with leaves: let the walk find what is there
        level = list(itertools.chain.from_iterable(level))
        types = set(map(type, level))
    return all(issubclass(t, numbers.Real) and not issubclass(t, (bool, np.bool_))
               for t in types)


def _refuse_non_numbers(name: str, value) -> None:
    """Refuse None, strings, booleans (also inside lists and numpy arrays) and complex numbers."""
    if value is None or isinstance(value, (str, bytes, bool, np.bool_)):
        raise ValueError(f"{name} must be a number, got {_short(value)}")
    if isinstance(value, (list, tuple)):
        if _only_numbers(value):
            return
        for i, item in enumerate(value):
            bad, leaf = _first_non_number(item)
            if bad:
                raise ValueError(f"{name}[{i}] must be a number, got {_short(leaf)}")
        return
    if _is_scalar_number(value):
        return
    kind = np.asarray(value).dtype.kind
    if kind == "O":
        items = np.asarray(value).tolist()
        if not isinstance(items, list):  # a lone object: a dict, a set, a class...
            raise ValueError(f"{name} must be a number, got {_short(value)}")
        _refuse_non_numbers(name, items)
    elif kind not in "iuf":
        raise ValueError(f"{name} must hold numbers, got an array of "
                         f"{np.asarray(value).dtype}")


def _as_float_array(name: str, value) -> np.ndarray:
    _refuse_non_numbers(name, value)
    try:
        return np.array(value, dtype=np.float64, copy=True)
    except OverflowError:
        raise ValueError(f"{name} must be a number a float64 can hold, got "
                         f"{_short(value)}") from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a number or a regular array of numbers, got "
                         f"{_short(value)}") from exc


def _first_bad_row(mask: np.ndarray) -> int:
    """Index of the first True entry of a 1-D mask (``mask.any()`` must hold)."""
    return int(np.flatnonzero(mask)[0])


def _check_finite_rows(name: str, arr: np.ndarray) -> None:
    bad = ~np.isfinite(arr)
    if bad.ndim > 1:
        bad = bad.reshape(bad.shape[0], -1).any(axis=1) if bad.size else np.zeros(0, bool)
    if bad.any():
        i = _first_bad_row(bad)
        raise ValueError(f"{name}[{i}] must be finite, got {_fmt(arr[i])}")


def scalar(name: str, value, *, minimum: float | None = None, positive: bool = False,
           maximum: float | None = None) -> float:
    """A finite Python float with optional bounds (``positive`` means strictly > 0).

    Raises:
        ValueError: for a non-number (``"0.1"``, ``True``, ``None``), an array, nan or inf, or a
            value out of bounds, naming ``name``.
    """
    arr = _as_float_array(name, value)
    if arr.ndim != 0:
        raise ValueError(f"{name} must be a scalar, got shape {arr.shape}")
    x = float(arr)
    if not math.isfinite(x):
        raise ValueError(f"{name} must be finite, got {x}")
    if positive and not x > 0.0:
        raise ValueError(f"{name} must be > 0, got {x:g}")
    if minimum is not None and x < minimum:
        raise ValueError(f"{name} must be >= {minimum:g}, got {x:g}")
    if maximum is not None and x > maximum:
        raise ValueError(f"{name} must be <= {maximum:g}, got {x:g}")
    return x


def per_item(name: str, value, count: int, *, positive: bool = False,
             minimum: float | None = None) -> np.ndarray:
    """A scalar broadcast to ``(count,)``, or a ``(count,)`` array; finite, bounded."""
    arr = _as_float_array(name, value)
    if arr.ndim == 0:
        arr = np.full(count, float(arr))
        label = name
    elif arr.shape == (count,):
        label = None
    else:
        raise ValueError(f"{name} must be a scalar or have shape ({count},), got {arr.shape}")
    for bad, what in (
        (~np.isfinite(arr), "must be finite"),
        (~(arr > 0.0) if positive else None, "must be > 0"),
        (arr < minimum if minimum is not None else None,
         f"must be >= {minimum:g}" if minimum is not None else ""),
    ):
        if bad is not None and bad.any():
            i = _first_bad_row(bad)
            where = label if label is not None else f"{name}[{i}]"
            raise ValueError(f"{where} {what}, got {arr[i]:g}")
    return arr


def scalar_or_range(name: str, value, *, minimum: float | None = None,
                    positive: bool = False) -> tuple[float, float]:
    """A scalar ``x`` as ``(x, x)``, or a ``[min, max]`` pair with ``min <= max``; bounded."""
    if not isinstance(value, (list, tuple, np.ndarray)):
        x = scalar(name, value, minimum=minimum, positive=positive)
        return (x, x)
    pair = _as_float_array(name, value)
    if pair.shape != (2,):
        raise ValueError(f"{name} must be a scalar or [min, max], got shape {pair.shape}")
    lo, hi = per_item(name, pair, 2, minimum=minimum, positive=positive)
    if lo > hi:
        raise ValueError(f"{name} must be a scalar or [min, max] with min <= max, "
                         f"got [{lo:g}, {hi:g}]")
    return (float(lo), float(hi))


def vec3_array(name: str, value, count: int | None = None) -> np.ndarray:
    """A finite ``(N, 3)`` array; a single ``(3,)`` vector is accepted when ``count`` is None.

    Args:
        name: field name used in error messages.
        value: array-like of shape ``(N, 3)`` (or ``(3,)``).
        count: required ``N``, or None for any.
    """
    arr = _as_float_array(name, value)
    if arr.ndim == 1 and arr.shape == (3,) and count is None:
        arr = arr.reshape(1, 3)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {arr.shape}")
    if count is not None and arr.shape[0] != count:
        raise ValueError(f"{name} must have shape ({count}, 3), got {arr.shape}")
    if arr.shape[0] >= INT_LIMIT:
        raise ValueError(f"{name} has {arr.shape[0]} rows, at most {INT_LIMIT - 1} are allowed")
    _check_finite_rows(name, arr)
    return arr


def vec3(name: str, value) -> np.ndarray:
    """A single finite 3-vector, as a ``(3,)`` float64 array."""
    arr = _as_float_array(name, value)
    if arr.shape != (3,):
        raise ValueError(f"{name} must be a 3-vector, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} must be finite, got {_fmt(arr)}")
    return arr


def nonnegative_vec3(name: str, value) -> np.ndarray:
    """One finite 3-vector with every component >= 0 (half extents)."""
    arr = vec3(name, value)
    bad = arr < 0.0
    if bad.any():
        j = _first_bad_row(bad)
        raise ValueError(f"{name}[{j}] must be >= 0, got {arr[j]:g}")
    return arr


def nonnegative_vec3_array(name: str, value, count: int | None = None) -> np.ndarray:
    """Like :func:`vec3_array`, every component >= 0 (half extents)."""
    arr = vec3_array(name, value, count)
    bad = (arr < 0.0).any(axis=1)
    if bad.any():
        i = _first_bad_row(bad)
        raise ValueError(f"{name}[{i}] must be >= 0 in every component, got {_fmt(arr[i])}")
    return arr


def _normalised(q: np.ndarray, norm) -> np.ndarray:
    return np.where(np.abs(norm - 1.0) <= UNIT_SLACK, q, q / norm)


def unit_quat_array(name: str, value, count: int) -> np.ndarray:
    """``(count, 4)`` quaternions ``(x, y, z, w)``, finite and non-zero, returned normalised."""
    arr = _as_float_array(name, value)
    if arr.ndim == 1 and arr.shape == (4,):
        arr = np.tile(arr, (count, 1))
    if arr.shape != (count, 4):
        raise ValueError(f"{name} must have shape ({count}, 4) as (x, y, z, w), got {arr.shape}")
    _check_finite_rows(name, arr)
    norm = np.linalg.norm(arr, axis=1)
    bad = ~(norm > QUAT_MIN_NORM)
    if bad.any():
        i = _first_bad_row(bad)
        raise ValueError(f"{name}[{i}] must be a non-zero quaternion, got {_fmt(arr[i])}")
    return _normalised(arr, norm[:, None])


def unit_quat(name: str, value) -> np.ndarray:
    """One quaternion ``(x, y, z, w)``, finite and non-zero, returned normalised, shape (4,)."""
    arr = _as_float_array(name, value)
    if arr.shape != (4,):
        raise ValueError(f"{name} must be a quaternion (x, y, z, w), got shape {arr.shape}")
    norm = np.linalg.norm(arr)
    if not np.isfinite(arr).all() or not norm > QUAT_MIN_NORM:
        raise ValueError(f"{name} must be a finite non-zero quaternion (x, y, z, w), got "
                         f"{_fmt(arr)}")
    return _normalised(arr, norm)


def positive_int(name: str, value, *, minimum: int = 1, maximum: int = INT_LIMIT - 1,
                 reason: str = "") -> int:
    """A Python int in ``[minimum, maximum]``; booleans and floats (even ``2.0``) are refused.

    Args:
        reason: why ``maximum``, said in the message; by default the 32-bit limit's reason.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {_short(value)}")
    value = int(value)
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    if value > maximum:
        why = reason or ("integers must be below 2**31" if maximum == INT_LIMIT - 1 else "")
        raise ValueError(f"{name} must be <= {maximum}{f' ({why})' if why else ''}, got "
                         f"{_short(value)}")
    return value


def bounce_cap(value, name: str = "max_bounces") -> int:
    """The bounce cap: an integer in ``[1, MAX_BOUNCES]``."""
    return positive_int(name, value, maximum=MAX_BOUNCES,
                        reason="the cap is compiled into the kernel's bounce loop")


def flag(name: str, value) -> bool:
    """A Python bool (``True``/``False`` or numpy's); 0 and 1 are refused."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be true or false, got {_short(value)}")
    return bool(value)


def index_list(name: str, value: Sequence[int] | np.ndarray, count: int) -> np.ndarray:
    """Distinct integer indices into ``range(count)``, as int64 (floats and bools refused)."""
    arr = np.asarray(value)
    if arr.size and (arr.dtype.kind not in "iu"):
        raise ValueError(f"{name} must be integer indices, got an array of {arr.dtype}")
    arr = np.array(arr, dtype=np.int64, copy=True).reshape(-1)
    bad = (arr < 0) | (arr >= count)
    if bad.any():
        i = _first_bad_row(bad)
        raise ValueError(f"{name}[{i}] = {arr[i]} is out of range [0, {count})")
    if len(np.unique(arr)) != len(arr):
        raise ValueError(f"{name} must not repeat an index")
    return arr


def frozen(arr: np.ndarray) -> np.ndarray:
    """Mark an owned array read-only, so validated data cannot drift after the check."""
    arr.setflags(write=False)
    return arr


def precision(value: str) -> str:
    """``"float32"`` or ``"float64"``."""
    if not isinstance(value, str) or value not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {_short(value)}")
    return value


def float_dtype(name: str) -> np.dtype:
    """The numpy dtype of a precision name (``"float32"`` or ``"float64"``), checked."""
    return np.dtype(DTYPES[precision(name)])


def motion(value: str, name: str = "motion") -> str:
    """``"linear"`` (the sheet's chord per frame) or ``"ballistic"`` (the exact parabola)."""
    if not isinstance(value, str) or value not in MOTIONS:
        raise ValueError(f"{name} must be one of {MOTIONS}, got {_short(value)}")
    return value


def optional_flag(name: str, value) -> bool | None:
    """None (the default of the model it applies to), or a bool as :func:`flag`."""
    return None if value is None else flag(name, value)


def broad_phase(value: str) -> str:
    """``"auto"``, ``"bvh"``, ``"brute"`` or ``"grid"``."""
    if not isinstance(value, str) or value not in BROAD_PHASES:
        raise ValueError(f"broad_phase must be one of {BROAD_PHASES}, got {_short(value)}")
    return value


# --- the fields of the classes, shared with the scene files ----------------------------------


def rounded_box(center, half_extents, rotation, radius, where: str = ""
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """One rounded box's fields, checked: ``(center, half_extents, rotation, radius)``.

    Args:
        where: prefix of the field names in messages (``"box[3]."`` in a scene file).

    Returns:
        float64 ``center`` (3,), ``half_extents`` (3,) each >= 0, unit ``rotation`` (4,) and a
        ``radius`` >= 0.
    """
    return (vec3(f"{where}center", center),
            nonnegative_vec3(f"{where}half_extents", half_extents),
            unit_quat(f"{where}rotation", rotation),
            scalar(f"{where}radius", radius, minimum=0.0))


SCENE_SETTINGS = {
    "dt": lambda name, v: scalar(name, v, positive=True),
    "frames": lambda name, v: positive_int(name, v),
    "max_bounces": lambda name, v: bounce_cap(v, name),
    "gravity": lambda name, v: vec3(name, v),
    "friction": lambda name, v: scalar(name, v, minimum=0.0),
    "energy_retention": lambda name, v: scalar(name, v, positive=True, maximum=1.0),
    "energy_correction": lambda name, v: optional_flag(name, v),
    "motion": lambda name, v: motion(v, name),
    "max_angular_speed": lambda name, v: scalar(name, v, positive=True),
}
"""The check of each physics and simulation setting of a :class:`warpsim.Scene`."""


def scene_settings(values: Mapping[str, object], where: str = "") -> dict[str, object]:
    """Checked copies of :class:`warpsim.Scene` settings (keys of :data:`SCENE_SETTINGS`).

    Args:
        values: setting name -> raw value.
        where: prefix of the names in messages (``"simulation."`` in a scene file).
    """
    checked = {}
    for key, value in values.items():
        if key not in SCENE_SETTINGS:
            raise ValueError(f"unknown scene setting {where}{key}")
        checked[key] = SCENE_SETTINGS[key](f"{where}{key}", value)
    return checked


def _tuple3(arr: np.ndarray) -> tuple[float, float, float]:
    return (float(arr[0]), float(arr[1]), float(arr[2]))


def emitter_fields(values: Mapping[str, object], where: str = "") -> dict[str, object]:
    """Checked fields of a :class:`warpsim.Emitter` (every field given, as the dataclass has).

    ``direction`` and ``cone_deg`` shape the ``speed`` term only: given without ``speed`` they
    would do nothing, so they are refused; with ``speed`` they default to ``(0, 1, 0)`` and 180.

    Args:
        values: field name -> raw value; ``speed``, ``direction``, ``cone_deg`` may be None.
        where: prefix of the names in messages (``"emitter."`` in a scene file).

    Returns:
        Plain Python values: ints, floats, and tuples for vectors and ``(min, max)`` ranges.
    """
    def name(key: str) -> str:
        return f"{where}{key}"

    speed = values["speed"]
    for key in ("direction", "cone_deg"):
        if values[key] is not None and speed is None:
            raise ValueError(f"{name(key)} only shapes the speed term: give {name('speed')} "
                             f"too, or leave {key} out")
    direction = cone = None
    if speed is not None:
        speed = scalar_or_range(name("speed"), speed, minimum=0.0)
        direction = vec3(name("direction"), (0.0, 1.0, 0.0) if values["direction"] is None
                         else values["direction"])
        if not np.linalg.norm(direction) > 0.0:
            raise ValueError(f"{name('direction')} must be a non-zero vector, got "
                             f"{_fmt(direction)}")
        direction = _tuple3(direction)
        cone = scalar(name("cone_deg"), 180.0 if values["cone_deg"] is None
                      else values["cone_deg"], minimum=0.0, maximum=180.0)
    return {
        "count": positive_int(name("count"), values["count"]),
        "center": _tuple3(vec3(name("center"), values["center"])),
        "half_extents": _tuple3(nonnegative_vec3(name("half_extents"), values["half_extents"])),
        "radius": scalar_or_range(name("radius"), values["radius"], minimum=0.0),
        "mass": scalar_or_range(name("mass"), values["mass"], positive=True),
        "velocity": _tuple3(vec3(name("velocity"), values["velocity"])),
        "velocity_jitter": _tuple3(nonnegative_vec3(name("velocity_jitter"),
                                                    values["velocity_jitter"])),
        "speed": speed,
        "direction": direction,
        "cone_deg": cone,
        "angular_momentum": _tuple3(vec3(name("angular_momentum"), values["angular_momentum"])),
        "seed": positive_int(name("seed"), values["seed"], minimum=0),
        "clearance": scalar(name("clearance"), values["clearance"], minimum=0.0),
    }


def sphere_batch(position, velocity, radius, boxes):
    """The common inputs of the batched queries, checked: ``(boxes, position, velocity, radius)``.

    Args:
        position: (N, 3) centres [m]. velocity: (N, 3) [m/s]. radius: scalar or (N,) [m], >= 0.
        boxes: a :class:`warpsim.RoundedBoxes`, or one :class:`warpsim.RoundedBox` (anything
            with ``as_boxes()``, which both have).

    Returns:
        The boxes as a group, and float64 copies of position (N, 3), velocity (N, 3), radius (N,).
    """
    as_boxes = getattr(boxes, "as_boxes", None)
    if not callable(as_boxes):
        raise ValueError(f"boxes must be a RoundedBoxes or RoundedBox, got {type(boxes).__name__}")
    pos = vec3_array("position", position)
    n = pos.shape[0]
    return (as_boxes(), pos, vec3_array("velocity", velocity, n),
            per_item("radius", radius, n, minimum=0.0))


# --- a whole run against its precision -------------------------------------------------------


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
    i = _first_bad_row(bad)
    shown = f"[{i}] = {_fmt(rows[i])}" if rows is not None else ""
    why = "its square must stay finite" if squared else "sums and products must stay finite"
    hint = "" if dtype == np.float64 else _fits_float64(float(magnitude[i]), squared)
    raise ValueError(f"{field}{shown} is too large for {dtype.name}: {quantity} = "
                     f"{magnitude[i]:.3g} {unit}, above {bound:.3g} ({why}){hint}")


def _norms(rows: np.ndarray) -> np.ndarray:
    """Euclidean norms of ``(N, 3)`` rows without overflow in the squares (float64 holds
    ``|v| = 1e200``, not ``|v|^2``)."""
    scale = np.abs(rows).max(axis=1, initial=0.0)
    safe = np.where(scale > 0.0, scale, 1.0)
    return scale * np.linalg.norm(rows / safe[:, None], axis=1)


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
    _refuse_large("position", np.abs(position).max(axis=1, initial=0.0), position,
                  "largest |coordinate|", "m", dtype, squared=True)
    _refuse_large("velocity", speed, velocity, "|v|", "m/s", dtype, squared=True)
    _refuse_large("velocity", speed * dt, velocity, "|v| dt", "m", dtype, squared=True)
    _refuse_large("radius", radius, radius, "r", "m", dtype, squared=True)
    _refuse_large("mass", mass, mass, "m", "kg", dtype, squared=False)
    tiny_mass = ~(mass.astype(dtype) >= info.tiny)
    if tiny_mass.any():
        i = _first_bad_row(tiny_mass)
        raise ValueError(f"mass[{i}] = {mass[i]:g} kg underflows in {name} (smallest normal "
                         f"{float(info.tiny):.3g} kg)")
    _refuse_large("velocity", 0.5 * mass * speed * speed, velocity, "1/2 m |v|^2", "J", dtype,
                  squared=False)
    _refuse_large("angular_momentum", np.abs(angular).max(axis=1, initial=0.0), angular,
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
    first = _first_bad_row(inside)
    i, box = int(np.flatnonzero(hit)[first]), int(k[first])
    count = int(inside.sum())
    also = f"; {count} of {len(position)} spheres start inside" if count > 1 else ""
    raise ValueError(f"sphere {i} starts {depth[first]:.3g} m inside box {box} (position "
                     f"{_fmt(position[i])}, radius {radius[i]:g}): spheres must start outside "
                     f"the obstacles or touching them{also}")
