"""Every check of warpsim's input fields, in one place: types, shapes and bounds.

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

The checks of a whole run rather than one field (what the chosen precision holds, no sphere
inside an obstacle) are :mod:`warpsim.feasibility`.

This module imports nothing else from warpsim but its vocabulary: every other module may
import it.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import numbers
from collections.abc import Mapping, Sequence
from enum import StrEnum

import numpy as np

from .blocks import copy_rows, fill_rows, for_row_blocks
from .vocabulary import BroadPhase, Motion

PRECISIONS = ("float32", "float64")
DTYPES = {"float32": np.float32, "float64": np.float64}

INT_LIMIT = 2**31
"""Integers must be below this: the kernels count spheres, frames and bounces in ``int32``, and
a larger value would wrap around silently (``2**32`` bounces would become 0)."""

MAX_BOUNCES = 1024
"""Largest ``max_bounces`` accepted. The cap is a launch value of the bounce loop (one compiled
kernel serves every cap); a sphere wedged in a corner takes a few contacts per frame, and a cap
this high already means a sphere may spend a thousand sweeps over the obstacles in one frame."""

QUAT_MIN_NORM = 1e-12
"""A quaternion shorter than this has no reliable direction to normalise (its components are
rounding noise): refused as a zero quaternion."""

UNIT_SLACK = 4.0 * np.finfo(np.float64).eps
"""Quaternions whose length is within this of 1 are kept bit for bit, so validating an already
validated quaternion (a box taken out of a group and put back) changes nothing."""


# --- numbers ---------------------------------------------------------------------------------


def _short(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def format_row(row) -> str:
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
    if isinstance(value, np.ndarray) and value.ndim and value.dtype.kind in "iuf":
        # a float64 copy of its own, made in blocks of rows on every core: the same values
        return copy_rows(np.empty(value.shape), value)
    try:
        return np.array(value, dtype=np.float64, copy=True)
    except OverflowError:
        raise ValueError(f"{name} must be a number a float64 can hold, got "
                         f"{_short(value)}") from None
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be a number or a regular array of numbers, got "
                         f"{_short(value)}") from exc


def first_bad_row(mask: np.ndarray) -> int:
    """Index of the first True entry of a 1-D mask (``mask.any()`` must hold)."""
    return int(np.flatnonzero(mask)[0])


def _check_finite_rows(name: str, arr: np.ndarray) -> None:
    """Refuse the first row of ``arr`` (N, ...) holding a nan or an infinity."""
    finite = np.ones(arr.shape[0], dtype=bool)

    def block(rows: slice) -> None:  # blocks of rows on every core: a row's test is its own
        ok = np.isfinite(arr[rows])
        finite[rows] = ok.reshape(ok.shape[0], -1).all(axis=1)

    for_row_blocks(finite.shape[0], block)
    if not finite.all():
        i = first_bad_row(~finite)
        raise ValueError(f"{name}[{i}] must be finite, got {format_row(arr[i])}")


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
    one = arr.ndim == 0  # a scalar is checked once, then broadcast
    if one:
        arr = arr.reshape(1)
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
            i = first_bad_row(bad)
            where = label if label is not None else f"{name}[{i}]"
            raise ValueError(f"{where} {what}, got {arr[i]:g}")
    return np.full(count, float(arr[0])) if one else arr


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
        raise ValueError(f"{name} must be finite, got {format_row(arr)}")
    return arr


def nonnegative_vec3(name: str, value) -> np.ndarray:
    """One finite 3-vector with every component >= 0 (half extents)."""
    arr = vec3(name, value)
    bad = arr < 0.0
    if bad.any():
        j = first_bad_row(bad)
        raise ValueError(f"{name}[{j}] must be >= 0, got {arr[j]:g}")
    return arr


def nonnegative_vec3_array(name: str, value, count: int | None = None) -> np.ndarray:
    """Like :func:`vec3_array`, every component >= 0 (half extents)."""
    arr = vec3_array(name, value, count)
    bad = (arr < 0.0).any(axis=1)
    if bad.any():
        i = first_bad_row(bad)
        raise ValueError(f"{name}[{i}] must be >= 0 in every component, got {format_row(arr[i])}")
    return arr


def _normalised(q: np.ndarray, norm) -> np.ndarray:
    return np.where(np.abs(norm - 1.0) <= UNIT_SLACK, q, q / norm)


def unit_quat_array(name: str, value, count: int) -> np.ndarray:
    """``(count, 4)`` quaternions ``(x, y, z, w)``, finite and non-zero, returned normalised."""
    arr = _as_float_array(name, value)
    if arr.ndim == 1 and arr.shape == (4,):  # one for all: checked once, as a row, then copied
        row = unit_quat_array(name, arr.reshape(1, 4), 1)[0]
        return fill_rows(np.empty((count, 4)), row)
    if arr.shape != (count, 4):
        raise ValueError(f"{name} must have shape ({count}, 4) as (x, y, z, w), got {arr.shape}")
    _check_finite_rows(name, arr)
    norm = np.linalg.norm(arr, axis=1)
    bad = ~(norm > QUAT_MIN_NORM)
    if bad.any():
        i = first_bad_row(bad)
        raise ValueError(f"{name}[{i}] must be a non-zero quaternion, got {format_row(arr[i])}")
    return _normalised(arr, norm[:, None])


def unit_quat(name: str, value) -> np.ndarray:
    """One quaternion ``(x, y, z, w)``, finite and non-zero, returned normalised, shape (4,)."""
    arr = _as_float_array(name, value)
    if arr.shape != (4,):
        raise ValueError(f"{name} must be a quaternion (x, y, z, w), got shape {arr.shape}")
    norm = np.linalg.norm(arr)
    if not np.isfinite(arr).all() or not norm > QUAT_MIN_NORM:
        raise ValueError(f"{name} must be a finite non-zero quaternion (x, y, z, w), got "
                         f"{format_row(arr)}")
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
                        reason="contacts per sphere per frame")


def flag(name: str, value) -> bool:
    """A Python bool (``True``/``False`` or numpy's); 0 and 1 are refused."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be true or false, got {_short(value)}")
    return bool(value)


def _refuse_bools_among_integers(name: str, value) -> None:
    """A list NumPy made integers of may have held booleans (``[0, True]`` becomes ``[0,
    1]``): refused, naming the index (:func:`_refuse_non_numbers`), as a boolean alone is."""
    if isinstance(value, (list, tuple)):
        _refuse_non_numbers(name, value)


def index_list(name: str, value: Sequence[int] | np.ndarray, count: int) -> np.ndarray:
    """Distinct integer indices into ``range(count)``, as int64 (floats and bools refused)."""
    arr = np.asarray(value)
    if arr.size and (arr.dtype.kind not in "iu"):
        raise ValueError(f"{name} must be integer indices, got an array of {arr.dtype}")
    _refuse_bools_among_integers(name, value)
    arr = np.array(arr, dtype=np.int64, copy=True).reshape(-1)
    bad = (arr < 0) | (arr >= count)
    if bad.any():
        i = first_bad_row(bad)
        raise ValueError(f"{name}[{i}] = {arr[i]} is out of range [0, {count})")
    if len(np.unique(arr)) != len(arr):
        raise ValueError(f"{name} must not repeat an index")
    return arr


def frame_array(name: str, value, count: int) -> np.ndarray:
    """Frame numbers: an integer broadcast to ``(count,)``, or ``(count,)`` integers, each in
    ``[0, 2**31)``, as int64 (floats, even ``2.0``, and booleans refused)."""
    arr = np.asarray(value)
    # integers beyond 64 bits come as Python objects: compared as such, never wrapped
    wide = arr.dtype == object and all(
        isinstance(x, (int, np.integer)) and not isinstance(x, (bool, np.bool_))
        for x in arr.reshape(-1))
    if arr.dtype.kind not in "iu" and not wide:
        got = _short(value) if arr.ndim == 0 else f"an array of {arr.dtype}"
        raise ValueError(f"{name} must be integers, got {got}")
    _refuse_bools_among_integers(name, value)
    one = arr.ndim == 0  # a scalar is checked once, then broadcast
    if one:
        arr = arr.reshape(1)
        label = name
    elif arr.shape == (count,):
        label = None
    else:
        raise ValueError(f"{name} must be an integer or have shape ({count},), got {arr.shape}")
    # the bounds in the values' own type (an unsigned 2**63 or more would wrap in int64)
    for bad, what in ((arr < 0, "must be >= 0"), (arr >= INT_LIMIT, "must be below 2**31")):
        if bad.any():
            i = first_bad_row(np.asarray(bad, dtype=bool))
            where = label if label is not None else f"{name}[{i}]"
            raise ValueError(f"{where} {what}, got {arr[i]}")
    arr = arr.astype(np.int64)
    if one:  # zeros: pages the system hands out zeroed, not written here
        return (np.zeros(count, dtype=np.int64) if arr[0] == 0
                else np.full(count, arr[0], dtype=np.int64))
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


def _member(enum: type[StrEnum], name: str, value) -> StrEnum:
    """The member of a string enum named by ``value`` (a member or its string value)."""
    if isinstance(value, str):
        with contextlib.suppress(ValueError):
            return enum(value)
    choices = tuple(m.value for m in enum)
    raise ValueError(f"{name} must be one of {choices}, got {_short(value)}")


def motion(value, name: str = "motion") -> Motion:
    """A :class:`~warpsim.vocabulary.Motion`: ``"linear"`` (the chord of each frame) or
    ``"ballistic"`` (the exact parabola)."""
    return _member(Motion, name, value)


def optional_flag(name: str, value) -> bool | None:
    """None (the default of the model it applies to), or a bool as :func:`flag`."""
    return None if value is None else flag(name, value)


def broad_phase(value) -> BroadPhase:
    """A :class:`~warpsim.vocabulary.BroadPhase`: ``"auto"``, ``"brute"``, ``"bvh"``,
    ``"grid"`` or ``"walk"`` (booleans and other types refused)."""
    return _member(BroadPhase, "broad_phase", value)


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
                             f"{format_row(direction)}")
        direction = _tuple3(direction)
        cone = scalar(name("cone_deg"), 180.0 if values["cone_deg"] is None
                      else values["cone_deg"], minimum=0.0, maximum=180.0)
    count = positive_int(name("count"), values["count"])
    rate, duration = values.get("rate"), values.get("duration")
    if rate is not None:
        rate = scalar(name("rate"), rate, positive=True)
    if duration is not None:
        duration = scalar(name("duration"), duration, positive=True)
    if rate is not None and duration is not None and round(rate * duration) != count:
        raise ValueError(f"{name('rate')} x {name('duration')} = {rate * duration:g} spheres, "
                         f"but {name('count')} is {count}: give one of rate and duration, or "
                         f"both with rate x duration = count")
    return {
        "count": count,
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
        "start": scalar(name("start"), values.get("start", 0.0), minimum=0.0),
        "rate": rate,
        "duration": duration,
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
