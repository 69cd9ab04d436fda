"""Scene files (TOML): reading bundled and user scenes into :class:`warpsim.Scene`.

The format is documented in the README ("Scene files"). In short: top-level ``name`` and
``description``, optional ``[simulation]`` and ``[physics]`` tables, obstacles as ``[[box]]`` and
``[[box_grid]]`` tables or an ``[obstacles]`` table naming a USD stage (``usd = "set.usda"``,
relative to the scene file, and optionally ``prim = "/Set"``; read by
:func:`warpsim.obstacles_from_usd`), and one ``[emitter]`` table (see
:class:`warpsim.emitter.Emitter`).
The raw values go to the same checks as the classes' arguments (:mod:`warpsim.validation`), named
as the file names them. ``warpsim.Scene.load`` turns what :func:`read_scene_file` returns into a
scene; this module does not import :mod:`warpsim.scene`.

Every error is a :class:`SceneFileError` (a ``ValueError``) whose message starts with the file and
names the table, key and index, e.g. ``room.toml: box[3].half_extents[1] must be >= 0, got -0.1``.
Indices count from 0 in file order: ``box[3]`` is the fourth ``[[box]]`` table.
"""

from __future__ import annotations

import difflib
import importlib.resources
import math
import os
import tomllib
from dataclasses import fields
from pathlib import Path

import numpy as np

from . import validation as check
from .emitter import Emitter
from .obstacles import IDENTITY_QUAT, RoundedBoxes

BUNDLED_PACKAGE = "warpsim.scenes"
SUFFIX = ".toml"

MAX_GRID_BOXES = 100_000
"""Largest ``[[box_grid]]`` expansion accepted: far above any sensible scene, it turns a typo
such as ``count = [1000, 1000, 1]`` into an error instead of an out-of-memory."""

TOP_KEYS = ("name", "description", "simulation", "physics", "box", "box_grid", "obstacles",
            "emitter")
SIMULATION_KEYS = ("dt", "frames", "max_bounces", "motion")
PHYSICS_KEYS = ("gravity", "friction", "energy_retention", "energy_correction",
                "max_angular_speed")
BOX_KEYS = ("center", "half_extents", "rotation", "rotation_deg", "radius")
BOX_GRID_KEYS = ("origin", "count", "spacing", "half_extents", "rotation", "rotation_deg",
                 "radius", "stagger", "stagger_axis")
OBSTACLES_KEYS = ("usd", "prim")
EMITTER_KEYS = tuple(f.name for f in fields(Emitter))
AXES = ("x", "y", "z")
TOP_LEVEL = "the top level"  # how messages name the file's root table


class SceneFileError(ValueError):
    """A scene file that cannot be used; the message starts with the file's name."""


def list_scenes() -> list[tuple[str, str]]:
    """The bundled scenes, sorted by name.

    Returns:
        ``(name, description)`` pairs; ``name`` is what ``warpsim.Scene.load`` accepts.
    """
    scenes = []
    for name, resource in sorted(_bundled().items()):
        data = _parse_toml(f"{name}{SUFFIX}", resource.read_text(encoding="utf-8"))
        description = data.get("description", "")
        scenes.append((name, description if isinstance(description, str) else ""))
    return scenes


def read_scene_file(name_or_path: str | os.PathLike) -> dict:
    """Read and check a scene file: a bundled one by name (see :func:`list_scenes`) or a path.

    A string is taken as a path when it ends in ``.toml`` or contains a path separator;
    otherwise it is a bundled scene's name. ``warpsim.Scene.load`` makes the scene.

    Args:
        name_or_path: e.g. ``"room"``, ``"thin-walls"``, ``"my/scene.toml"`` or a ``Path``.

    Returns:
        The keyword arguments of :class:`warpsim.Scene`, every value checked: ``boxes``,
        ``emitter`` (a :class:`warpsim.Emitter`), ``name``, ``description``, ``source`` (the
        file read) and the settings the file gives.

    Raises:
        SceneFileError: (a ``ValueError``) for an unknown name, a missing file, a TOML syntax
            error (with its line) or a bad value; the message names the file, table, key and
            index.
    """
    label, stem, source, text = _locate(name_or_path)
    data = _parse_toml(label, text)
    try:
        return _scene_arguments(data, stem=stem, source=source)
    except ValueError as exc:
        raise SceneFileError(f"{label}: {exc}") from exc


def euler_deg_to_quat(angles_deg) -> np.ndarray:
    """The quaternion of ``rotation_deg = [rx, ry, rz]`` (the scene files' Euler convention).

    The rotation turns about the fixed world axes x, then y, then z (extrinsic x-y-z, the same
    as intrinsic z-y'-x''): ``R = Rz(rz) @ Ry(ry) @ Rx(rx)``, right-handed, angles in degrees.
    ``[0, 0, 90]`` maps the local x axis onto world y.

    Args:
        angles_deg: ``[rx, ry, rz]`` [deg].

    Returns:
        Unit quaternion ``(x, y, z, w)``, local -> world, shape (4,), float64.
    """
    rx, ry, rz = np.radians(check.vec3("rotation_deg", angles_deg)) / 2.0
    cx, sx = math.cos(rx), math.sin(rx)
    cy, sy = math.cos(ry), math.sin(ry)
    cz, sz = math.cos(rz), math.sin(rz)
    # Hamilton product qz * qy * qx, written out.
    return np.array([
        sx * cy * cz - cx * sy * sz,
        cx * sy * cz + sx * cy * sz,
        cx * cy * sz - sx * sy * cz,
        cx * cy * cz + sx * sy * sz,
    ])


# --- finding and parsing files ---------------------------------------------------------------


def _bundled() -> dict:
    """Bundled scene files by name (file stem)."""
    root = importlib.resources.files(BUNDLED_PACKAGE)
    return {r.name[:-len(SUFFIX)]: r for r in root.iterdir()
            if r.name.endswith(SUFFIX) and r.is_file()}


def _locate(name_or_path) -> tuple[str, str, str, str]:
    """``(label for messages, stem, source path, text)`` of a bundled name or a file path."""
    if isinstance(name_or_path, os.PathLike) or (
            isinstance(name_or_path, str) and (name_or_path.endswith(SUFFIX)
                                               or "/" in name_or_path or os.sep in name_or_path)):
        path = Path(name_or_path)
        label = str(name_or_path)
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise SceneFileError(f"{label}: scene file not found") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise SceneFileError(f"{label}: cannot read scene file: {exc}") from exc
        return label, path.stem, str(path), text
    if not isinstance(name_or_path, str):
        raise SceneFileError(f"a scene is a bundled name or a path to a {SUFFIX} file, got "
                             f"{name_or_path!r}")
    bundled = _bundled()
    if name_or_path not in bundled:
        close = difflib.get_close_matches(name_or_path, bundled, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise SceneFileError(f"unknown scene {name_or_path!r}; {hint}bundled scenes: "
                             f"{', '.join(sorted(bundled))} (or give a path to a {SUFFIX} file)")
    resource = bundled[name_or_path]
    return (f"{name_or_path}{SUFFIX}", name_or_path, str(resource),
            resource.read_text(encoding="utf-8"))


def _parse_toml(label: str, text: str) -> dict:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:  # its message ends with "(at line L, column C)"
        raise SceneFileError(f"{label}: invalid TOML: {exc}") from exc


# --- building the scene ----------------------------------------------------------------------


def _scene_arguments(data: dict, *, stem: str, source: str) -> dict:
    """The keyword arguments of :class:`warpsim.Scene`, every value checked, from parsed TOML."""
    _known_keys(data, TOP_KEYS, TOP_LEVEL)
    name = _string(data, "name", stem)
    description = _string(data, "description", "")
    if "\n" in description:
        raise ValueError("description must be a single line")
    settings = check.scene_settings(_table(data, "simulation", SIMULATION_KEYS),
                                    where="simulation.")
    settings.update(check.scene_settings(_table(data, "physics", PHYSICS_KEYS),
                                         where="physics."))
    boxes = _stage_boxes(data, source) if "obstacles" in data else _boxes(data)
    if "emitter" not in data:
        raise ValueError("missing [emitter] table (its count is required)")
    emitter = Emitter.from_table(_table(data, "emitter", EMITTER_KEYS), where="emitter")
    return dict(boxes=boxes, name=name, description=description, emitter=emitter,
                source=source, **settings)


def _boxes(data: dict) -> RoundedBoxes:
    """``[[box]]`` tables in file order, then every ``[[box_grid]]`` expanded in file order."""
    parts = []  # (center (M,3), half_extents (M,3), rotation (M,4), radius (M,))
    for i, table in enumerate(_array_of_tables(data, "box")):
        where = f"box[{i}]"
        _known_keys(table, BOX_KEYS, where)
        center, half, rotation, radius = _shape(table, where, _require(table, where, "center"))
        parts.append((center[None], half[None], rotation[None], np.array([radius])))
    for i, table in enumerate(_array_of_tables(data, "box_grid")):
        parts.append(_grid(table, f"box_grid[{i}]"))
    if not parts:
        raise ValueError("no obstacles: add at least one [[box]] or [[box_grid]] table")
    center, half, rotation, radius = (np.concatenate(column) for column in zip(*parts,
                                                                                strict=True))
    return RoundedBoxes(center=center, half_extents=half, rotation=rotation, radius=radius)


def _stage_boxes(data: dict, source: str) -> RoundedBoxes:
    """The obstacles of the stage that ``[obstacles] usd`` names (relative to the scene file);
    a stage scene's boxes are all the stage's, so ``[[box]]`` tables are refused beside it."""
    table = _table(data, "obstacles", OBSTACLES_KEYS)
    usd, prim = _require(table, "obstacles", "usd"), table.get("prim")
    if not isinstance(usd, str) or not usd.strip():
        raise ValueError(f"obstacles.usd must be the path of a USD file, got {usd!r}")
    if prim is not None and not isinstance(prim, str):
        raise ValueError(f"obstacles.prim must be a prim path such as '/Set', got {prim!r}")
    if "box" in data or "box_grid" in data:
        raise ValueError("[[box]] and [[box_grid]] tables cannot be mixed with [obstacles] usd: "
                         "the obstacles are the stage's (add the boxes to the stage)")
    from .export.stage_in import obstacles_from_usd  # pxr only for scenes that read a stage

    try:
        return obstacles_from_usd(Path(source).parent / usd, prim)
    except (ValueError, FileNotFoundError) as exc:
        raise ValueError(f"obstacles.usd: {exc}") from None


def _shape(table: dict, where: str, center) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """One box's checked ``(center, half_extents, rotation, radius)``, shared by ``[[box]]``
    and grids; the rotation from ``rotation`` (a quaternion) or ``rotation_deg``."""
    if "rotation" in table and "rotation_deg" in table:
        raise ValueError(f"{where}: give either rotation (quaternion) or rotation_deg (Euler "
                         f"angles), not both")
    rotation = table.get("rotation", IDENTITY_QUAT)
    if "rotation_deg" in table:
        rotation = euler_deg_to_quat(check.vec3(f"{where}.rotation_deg", table["rotation_deg"]))
    return check.rounded_box(center, _require(table, where, "half_extents"), rotation,
                             table.get("radius", 0.0), where=f"{where}.")


def _grid(table: dict, where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The boxes of one ``[[box_grid]]``, x index fastest, then y, then z."""
    _known_keys(table, BOX_GRID_KEYS, where)
    origin = check.vec3(f"{where}.origin", _require(table, where, "origin"))
    counts = _require(table, where, "count")
    if not isinstance(counts, list) or len(counts) != 3:
        raise ValueError(f"{where}.count must be [nx, ny, nz], got {counts!r}")
    nx, ny, nz = (check.positive_int(f"{where}.count[{a}]", c) for a, c in enumerate(counts))
    if nx * ny * nz > MAX_GRID_BOXES:
        raise ValueError(f"{where}.count {counts} makes {nx * ny * nz} boxes, more than "
                         f"{MAX_GRID_BOXES}")
    spacing = check.vec3(f"{where}.spacing", _require(table, where, "spacing"))
    stagger = check.vec3(f"{where}.stagger", table.get("stagger", (0.0, 0.0, 0.0)))
    axis = table.get("stagger_axis", "y")
    if axis not in AXES:
        raise ValueError(f"{where}.stagger_axis must be one of 'x', 'y', 'z', got {axis!r}")
    _, half, rotation, radius = _shape(table, where, origin)

    iz, iy, ix = (a.reshape(-1) for a in np.indices((nz, ny, nx)))
    index = np.stack([ix, iy, iz], axis=1)
    odd = (index[:, AXES.index(axis)] % 2 == 1)[:, None]
    center = origin + index * spacing + odd * stagger
    m = center.shape[0]
    return center, np.tile(half, (m, 1)), np.tile(rotation, (m, 1)), np.full(m, radius)


# --- small readers ---------------------------------------------------------------------------


def _known_keys(table: dict, allowed: tuple[str, ...], where: str) -> None:
    """Refuse keys outside ``allowed``, suggesting the likely intended one."""
    for key in table:
        if key in allowed:
            continue
        home = [name for name, keys in (("simulation", SIMULATION_KEYS),
                                        ("physics", PHYSICS_KEYS)) if key in keys]
        close = difflib.get_close_matches(key, allowed, n=1)
        if where == TOP_LEVEL and home:
            hint = f"it belongs in the [{home[0]}] table"
        elif close:
            hint = f"did you mean {close[0]!r}?"
        else:
            hint = f"expected one of: {', '.join(allowed)}"
        raise ValueError(f"unknown key {key!r} in {where}; {hint}")


def _table(data: dict, key: str, allowed: tuple[str, ...]) -> dict:
    """The optional table ``[key]`` (empty when absent), its keys checked."""
    table = data.get(key, {})
    if not isinstance(table, dict):
        raise ValueError(f"{key} must be a table [{key}], got {table!r}")
    _known_keys(table, allowed, f"[{key}]")
    return table


def _array_of_tables(data: dict, key: str) -> list[dict]:
    tables = data.get(key, [])
    if isinstance(tables, dict):
        raise ValueError(f"{key} must be written [[{key}]] (an array of tables), not [{key}]")
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise ValueError(f"{key} must be [[{key}]] tables, got {tables!r}")
    return tables


def _string(data: dict, key: str, default: str) -> str:
    value = data.get(key, default)
    if not isinstance(value, str):
        raise ValueError(f"{key} must be a string, got {value!r}")
    return value


def _require(table: dict, where: str, key: str):
    if key not in table:
        raise ValueError(f"{where}.{key} is required")
    return table[key]


