"""Checks at the API boundary: every host array is copied, shaped, and checked here.

Each checker returns a new float64 (or int) numpy array that the caller owns; the value it was
given is never modified. A bad value raises ``ValueError`` naming the field and, for arrays, the
index of the first bad row, e.g. ``radius[3] must be >= 0, got -0.1``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

PRECISIONS = ("float32", "float64")
BROAD_PHASES = ("auto", "bvh", "brute")


def _as_float_array(name: str, value) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be numeric, got {value!r}") from exc
    return arr


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


def _fmt(row) -> str:
    row = np.asarray(row)
    if row.ndim == 0:
        return f"{float(row):g}"
    return "(" + ", ".join(f"{float(x):g}" for x in row) + ")"


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


def scalar(name: str, value, *, minimum: float | None = None, positive: bool = False,
           maximum: float | None = None) -> float:
    """A finite Python float with optional bounds (``positive`` means strictly > 0)."""
    arr = _as_float_array(name, value)
    if arr.ndim != 0:
        raise ValueError(f"{name} must be a scalar, got shape {arr.shape}")
    x = float(arr)
    if not np.isfinite(x):
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


def nonnegative_vec3_array(name: str, value, count: int | None = None) -> np.ndarray:
    """Like :func:`vec3_array`, every component >= 0 (half extents)."""
    arr = vec3_array(name, value, count)
    bad = (arr < 0.0).any(axis=1)
    if bad.any():
        i = _first_bad_row(bad)
        raise ValueError(f"{name}[{i}] must be >= 0 in every component, got {_fmt(arr[i])}")
    return arr


def unit_quat_array(name: str, value, count: int) -> np.ndarray:
    """``(count, 4)`` quaternions ``(x, y, z, w)``, finite and non-zero, returned normalised."""
    arr = _as_float_array(name, value)
    if arr.ndim == 1 and arr.shape == (4,):
        arr = np.tile(arr, (count, 1))
    if arr.shape != (count, 4):
        raise ValueError(f"{name} must have shape ({count}, 4) as (x, y, z, w), got {arr.shape}")
    _check_finite_rows(name, arr)
    norm = np.linalg.norm(arr, axis=1)
    bad = ~(norm > 1e-12)
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
    if not np.isfinite(arr).all() or not norm > 1e-12:
        raise ValueError(f"{name} must be a finite non-zero quaternion, got {_fmt(arr)}")
    return _normalised(arr, norm)


#: Quaternions whose length is within this of 1 are kept bit for bit, so validating an already
#: validated quaternion (a box taken out of a group and put back) changes nothing.
UNIT_SLACK = 4.0 * np.finfo(np.float64).eps


def _normalised(q: np.ndarray, norm) -> np.ndarray:
    return np.where(np.abs(norm - 1.0) <= UNIT_SLACK, q, q / norm)


def nonnegative_vec3(name: str, value) -> np.ndarray:
    """One finite 3-vector with every component >= 0 (half extents)."""
    arr = vec3(name, value)
    if (arr < 0.0).any():
        raise ValueError(f"{name} must be >= 0 in every component, got {_fmt(arr)}")
    return arr


def precision(value: str) -> str:
    """``"float32"`` or ``"float64"``."""
    if value not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {value!r}")
    return value


def broad_phase(value: str) -> str:
    """``"auto"``, ``"bvh"`` or ``"brute"``."""
    if not isinstance(value, str) or value not in BROAD_PHASES:
        raise ValueError(f"broad_phase must be one of {BROAD_PHASES}, got {value!r}")
    return value


def positive_int(name: str, value, *, minimum: int = 1) -> int:
    """An integer >= ``minimum`` (bools refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")
    return int(value)


def index_list(name: str, value: Sequence[int] | np.ndarray, count: int) -> np.ndarray:
    """Distinct indices into ``range(count)``, as int64."""
    arr = np.array(value, dtype=np.int64, copy=True).reshape(-1)
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


def sphere_batch(position, velocity, radius, boxes):
    """The common inputs of the batched queries, checked: ``(boxes, position, velocity, radius)``.

    Args:
        position: (N, 3) centres [m]. velocity: (N, 3) [m/s]. radius: scalar or (N,) [m], >= 0.
        boxes: a :class:`warpsim.RoundedBoxes`, or one :class:`warpsim.RoundedBox`.

    Returns:
        The boxes as a group, and float64 copies of position (N, 3), velocity (N, 3), radius (N,).
    """
    from .obstacles import RoundedBox, RoundedBoxes

    if isinstance(boxes, RoundedBox):
        boxes = boxes.as_boxes()
    if not isinstance(boxes, RoundedBoxes):
        raise ValueError(f"boxes must be a RoundedBoxes or RoundedBox, got {type(boxes).__name__}")
    pos = vec3_array("position", position)
    n = pos.shape[0]
    return (boxes, pos, vec3_array("velocity", velocity, n),
            per_item("radius", radius, n, minimum=0.0))

