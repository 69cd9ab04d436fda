"""Obstacles read from an artist's USD stage (a *set*): boxes, cubes and their rounding.

What counts as an obstacle, read at the stage's start time code (a set is static):

- ``Cube`` prims: ``size`` [stage units] and the full local-to-world transform. A non-uniform
  scale gives the half extents; a transform that shears the cube or mirrors it (negative
  determinant) is refused, naming the prim.
- ``Mesh`` prims that are exactly boxes: 8 distinct points joined by 6 quads into a box (edges
  at right angles), in any transform (the same rules as cubes).
- Rounding: the attribute ``warpsim:radius`` (double, [stage units], a length in the stage's
  world, not scaled by the prim's transform) rounds a cube's or box mesh's edges, keeping its
  outer size: the core box is the drawn box shrunk by the radius on every side.
- A ``Cube`` or ``Mesh`` carrying ``warpsim:halfExtents`` (double3, [stage units], in the
  prim's local frame) is that core box, centred on the prim's origin and rounded by
  ``warpsim:radius``, whatever its points: warpsim writes both attributes on its own obstacle
  meshes (:mod:`warpsim.export.usd`), so a warpsim file reads back as a set.
- Colliders: when any prim of the subtree read carries ``UsdPhysics.CollisionAPI``, only those
  prims count (``physics:collisionEnabled = false`` excludes one), as Newton's importer does.
  Prims of a rigid body (``UsdPhysics.RigidBodyAPI`` on them or an ancestor, enabled) move, so
  they are not static obstacles. A ``PointInstancer``'s subtree (its prototypes) is not read.
- Everything else that is geometry (spheres, cylinders, meshes that are not boxes, ...) is
  skipped and counted; :meth:`StageSet.summary` says how many prims of each kind were read and
  skipped.

Units and axes: the boxes are in the stage's own axes (its ``upAxis`` is kept, nothing is
rotated), converted to metres with the stage's ``metersPerUnit``. Gravity
(:attr:`StageSet.gravity`) is the first ``UsdPhysics.Scene``'s (``gravityDirection``, zero
meaning down the up axis, and ``gravityMagnitude`` [stage units/s^2], negative meaning Earth's),
else 9.81 m/s^2 down the up axis, in m/s^2.
"""

from __future__ import annotations

import itertools
import os
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pxr import Sdf, Tf, Usd, UsdGeom, UsdPhysics

from ..obstacles import RoundedBoxes
from .usd_write import pxr_message

RADIUS_ATTR = "warpsim:radius"
HALF_EXTENTS_ATTR = "warpsim:halfExtents"
EARTH_GRAVITY = 9.81  # [m/s^2], what a stage without a physics scene (or with a negative
# gravityMagnitude, UsdPhysics' "use Earth's") gets

ORTHOGONAL_TOL = 1e-5
"""Largest cosine between two box axes (after the transform) still taken as a right angle:
DCC tools store transforms and points in float32 (relative error ~6e-8 per entry, a few of them
chained), while a visible shear is far larger."""

POINT_TOL = 1e-5
"""Largest distance, relative to the box's longest edge, between a mesh point and the corner of
the box its edges span (float32 points, as for ``ORTHOGONAL_TOL``)."""

POINT_ROUNDING = 4.0 * 2.0**-24
"""Mesh points are float32: each coordinate is off by up to ``2^-24`` of the largest one, so a
small box far from its mesh's origin has edges off their right angles by up to about this times
``max |point| / shortest edge``; both tolerances above grow by that much."""

UNIT_SCALE = 8.0 * np.finfo(np.float64).eps
"""A transform's scale within this of 1 is a rigid motion's (a rotation matrix made from a unit
quaternion has column norms 1 to a few ulp): taken as exactly 1, so boxes that warpsim wrote read
back with their half extents to the bit."""

_SIGNS = np.array([[(k >> a) & 1 for a in range(3)] for k in range(8)])  # corner k's bits


@dataclass(frozen=True)
class StageSet:
    """Where a scene's obstacles came from: a USD stage, and what was read from it.

    Attributes:
        path: the stage's file, absolute.
        prim: the subtree read (``"/Set"``), or None for the whole stage.
        up_axis: the stage's ``upAxis``, ``"Y"`` or ``"Z"``.
        meters_per_unit: the stage's ``metersPerUnit`` [m per stage unit].
        gravity: gravitational acceleration [m/s^2] in the stage's axes (see the module
            docstring for where it comes from).
        gravity_source: the ``UsdPhysics.Scene`` prim it came from, or ``""`` (the default).
        read: obstacles read, by prim type (``{"Cube": 4, "Mesh": 1}``).
        skipped: prims skipped, by reason (``{"Sphere not a box": 1, ...}``).
    """

    path: str
    prim: str | None
    up_axis: str
    meters_per_unit: float
    gravity: tuple[float, float, float]
    gravity_source: str = ""
    read: dict[str, int] = field(default_factory=dict)
    skipped: dict[str, int] = field(default_factory=dict)

    def summary(self) -> str:
        """One line: what was read and skipped, the axes, units and gravity."""
        name = os.path.basename(self.path) + (f" {self.prim}" if self.prim else "")
        read = ", ".join(f"{n} {kind}" for kind, n in sorted(self.read.items())) or "none"
        skipped = sum(self.skipped.values())
        why = "".join(f"; {n} {reason}" for reason, n in sorted(self.skipped.items()))
        source = f"from {self.gravity_source}" if self.gravity_source else "by default"
        g = ", ".join(f"{c + 0.0:g}" for c in self.gravity)
        return (f"{name}: read {sum(self.read.values())} obstacles ({read}); skipped "
                f"{skipped} prim{'' if skipped == 1 else 's'}{why}. {self.up_axis} up, "
                f"{self.meters_per_unit:g} m per unit, gravity ({g}) m/s^2 {source}")


class StageObstacles(RoundedBoxes):
    """:class:`warpsim.RoundedBoxes` read from a USD stage, in metres in the stage's axes.

    Attributes:
        stage: the :class:`StageSet` they came from (units, axes, gravity, summary);
            :func:`warpsim.export.write_usd` composes its output over that stage.
    """

    def __init__(self, center, half_extents, rotation, radius, *, stage: StageSet):
        super().__init__(center=center, half_extents=half_extents, rotation=rotation,
                         radius=radius)
        self.stage = stage

    def __repr__(self) -> str:
        return f"StageObstacles({len(self)} boxes from {os.path.basename(self.stage.path)!r})"


def obstacles_from_usd(path, prim: str | None = None) -> StageObstacles:
    """The obstacles of a USD stage (see the module docstring for what is read).

    Args:
        path: a ``.usd``, ``.usda``, ``.usdc`` or ``.usdz`` file.
        prim: the path of one subtree to read (``"/Set"``), or None for the whole stage.

    Returns:
        The boxes [m], in the stage's axes, in traversal order, as :class:`StageObstacles`
        (``.stage`` says what was read and skipped, the units, axes and gravity).

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: USD cannot open it, ``prim`` is not a prim of it, a box's transform shears
            or mirrors it, a rounding radius is larger than the box, or nothing was read; one
            line naming the file and the prim.
    """
    label = str(path)
    stage = _open(path)
    mpu = float(UsdGeom.GetStageMetersPerUnit(stage))
    up = str(UsdGeom.GetStageUpAxis(stage))
    if not (np.isfinite(mpu) and mpu > 0.0):
        raise ValueError(f"{label}: metersPerUnit must be > 0, got {mpu!r}")
    if prim is None:
        root = stage.GetPseudoRoot()
    else:
        if not isinstance(prim, str) or not Sdf.Path.IsValidPathString(prim):
            raise ValueError(f"{label}: prim must be a prim path such as '/Set', got {prim!r}")
        root = stage.GetPrimAtPath(prim)
        if not root or not root.IsActive():
            raise ValueError(f"{label}: no prim {prim!r} in the stage")
    time = (Usd.TimeCode(stage.GetStartTimeCode()) if stage.HasAuthoredTimeCodeRange()
            else Usd.TimeCode.Default())
    candidates, skipped = _candidates(root)
    cache = UsdGeom.XformCache(time)
    read: Counter = Counter()
    boxes = []
    for p in candidates:
        box = _box_of_prim(p, cache, time, label)
        if box is None:
            skipped[f"{p.GetTypeName() or 'untyped'} not a box"] += 1
            continue
        center, axes, half, radius = box
        boxes.append((center * mpu, axes, half * mpu, radius * mpu))
        read[str(p.GetTypeName())] += 1
    gravity, source = _gravity(stage, up, mpu, label)
    info = StageSet(path=str(Path(path).resolve()), prim=prim, up_axis=up,
                    meters_per_unit=mpu, gravity=gravity, gravity_source=source,
                    read=dict(read), skipped=dict(skipped))
    if not boxes:
        raise ValueError(f"{label}: no obstacles read: {info.summary()}")
    center, axes, half, radius = (np.array(column) for column in zip(*boxes, strict=True))
    return StageObstacles(center=center, half_extents=half, rotation=_quaternions(axes),
                          radius=radius, stage=info)


# --- the stage and its prims -----------------------------------------------------------------


def _open(path) -> Usd.Stage:
    """The stage at ``path``, read fresh from disk (a layer already open is reloaded)."""
    text = os.fspath(path)
    if not Path(text).is_file():
        raise FileNotFoundError(f"no USD file at {text!r}")
    try:
        layer = Sdf.Layer.Find(text)
        if layer is not None:
            layer.Reload()
        stage = Usd.Stage.Open(text, Usd.Stage.LoadAll)
    except Tf.ErrorException as exc:
        raise ValueError(f"USD could not read {text!r}: {pxr_message(exc)}") from None
    if stage is None:
        raise ValueError(f"USD could not read {text!r}")
    return stage


def _rigid_body(prim: Usd.Prim) -> bool:
    """Whether ``prim`` or an ancestor is an enabled rigid body (it moves: not static)."""
    while prim and not prim.IsPseudoRoot():
        if prim.HasAPI(UsdPhysics.RigidBodyAPI):
            enabled = UsdPhysics.RigidBodyAPI(prim).GetRigidBodyEnabledAttr().Get()
            if enabled is None or enabled:
                return True
        prim = prim.GetParent()
    return False


def _candidates(root: Usd.Prim) -> tuple[list[Usd.Prim], Counter]:
    """The geometry prims that may be obstacles, and the skipped ones counted by reason."""
    skipped: Counter = Counter()
    geometry = []
    rng = iter(Usd.PrimRange(root, Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
    for prim in rng:
        if prim.IsA(UsdGeom.PointInstancer):
            skipped["PointInstancer"] += 1
            rng.PruneChildren()  # its prototypes are drawn only where it places them
            continue
        if prim.IsA(UsdGeom.Gprim) or prim.HasAPI(UsdPhysics.CollisionAPI):
            geometry.append(prim)
    colliders = [p for p in geometry if p.HasAPI(UsdPhysics.CollisionAPI)]
    if not colliders:
        chosen = geometry
    else:
        skipped["not a collider"] += len(geometry) - len(colliders)
        chosen = []
        for p in colliders:
            if UsdPhysics.CollisionAPI(p).GetCollisionEnabledAttr().Get() is False:
                skipped["disabled collider"] += 1
            else:
                chosen.append(p)
    static = []
    for p in chosen:
        if _rigid_body(p):
            skipped["rigid body"] += 1
        else:
            static.append(p)
    return static, skipped


def _attribute(prim: Usd.Prim, name: str, time: Usd.TimeCode):
    attr = prim.GetAttribute(name)
    return attr.Get(time) if attr and attr.HasAuthoredValue() else None


def _box_of_prim(prim: Usd.Prim, cache: UsdGeom.XformCache, time: Usd.TimeCode, label: str):
    """``(center (3,), axes (3, 3) columns, half extents (3,), radius)`` in stage units, the
    world box of a cube or box mesh; None when the prim is not a box."""
    where = f"{label}: {prim.GetPath()}"
    radius = _attribute(prim, RADIUS_ATTR, time)
    radius = 0.0 if radius is None else float(radius)
    if not (np.isfinite(radius) and radius >= 0.0):
        raise ValueError(f"{where}: {RADIUS_ATTR} must be >= 0, got {radius!r}")
    core = _attribute(prim, HALF_EXTENTS_ATTR, time)
    if core is not None and (prim.IsA(UsdGeom.Cube) or prim.IsA(UsdGeom.Mesh)):
        local = (np.zeros(3), np.eye(3), np.array(core, dtype=np.float64))
        if not (np.isfinite(local[2]).all() and (local[2] >= 0.0).all()):
            raise ValueError(f"{where}: {HALF_EXTENTS_ATTR} must be >= 0, got {tuple(core)}")
    elif prim.IsA(UsdGeom.Cube):
        size = UsdGeom.Cube(prim).GetSizeAttr().Get(time)
        size = float(size)
        if not (np.isfinite(size) and size >= 0.0):
            raise ValueError(f"{where}: size must be >= 0, got {size!r}")
        local = (np.zeros(3), np.eye(3), np.full(3, size / 2.0))
    elif prim.IsA(UsdGeom.Mesh):
        local = _box_of_mesh(UsdGeom.Mesh(prim), time)
        if local is None:
            return None
    else:
        return None
    center, axes, half = _world_box(np.array(cache.GetLocalToWorldTransform(prim)), *local,
                                    where)
    if core is None:  # the drawn box is the outer surface: its core is shrunk by the radius
        half = half - radius
        if (half < 0.0).any():
            raise ValueError(f"{where}: {RADIUS_ATTR} = {radius:g} is more than half the box's "
                             f"size ({2.0 * (half + radius).min():g}) in stage units")
    return center, axes, half, radius


def _box_of_mesh(mesh: UsdGeom.Mesh, time: Usd.TimeCode):
    """``(center, axes (3, 3) columns, half extents)`` of a mesh that is exactly a box (8
    distinct points, 6 quads, 12 edges at right angles), in its local frame; else None."""
    points = mesh.GetPointsAttr().Get(time)
    counts = mesh.GetFaceVertexCountsAttr().Get(time)
    indices = mesh.GetFaceVertexIndicesAttr().Get(time)
    if points is None or counts is None or indices is None or len(points) != 8:
        return None
    p = np.array(points, dtype=np.float64).reshape(8, 3)
    faces = np.array(indices, dtype=np.int64)
    if list(counts) != [4] * 6 or faces.size != 24 or sorted(set(faces.tolist())) != list(
            range(8)):
        return None
    faces = faces.reshape(6, 4)
    edges = {tuple(sorted((int(a), int(b)))) for face in faces
             for a, b in zip(face, np.roll(face, -1), strict=True)}
    neighbours = [[b if a == k else a for a, b in edges if k in (a, b)] for k in range(8)]
    if len(edges) != 12 or any(len(n) != 3 for n in neighbours):
        return None
    if not np.isfinite(p).all():
        return None
    e = p[neighbours[0]] - p[0]  # (3, 3) rows: the box's edges from corner 0
    gap = np.linalg.norm((p[0] + _SIGNS @ e)[:, None, :] - p[None, :, :], axis=2)
    match = gap.argmin(axis=1)  # the point nearest each corner those edges span
    if sorted(match.tolist()) != list(range(8)):
        return None
    bits = _SIGNS[np.argsort(match)]  # each point's corner bits
    if any(np.abs(bits[a] - bits[b]).sum() != 1 for a, b in edges):
        return None  # an edge across a face or through the box
    sides = set()
    for face in faces:  # a face of the box: its four corners share one bit
        shared = [(a, int(bits[face[0], a])) for a in range(3) if len(set(bits[face, a])) == 1]
        if len(shared) != 1:
            return None
        sides.add(shared[0])
    if len(sides) != 6:
        return None
    # Fit the box to all 8 points: each axis is the mean of its 4 parallel edges, made
    # orthonormal from the longest axis down (a long edge's direction is the best known).
    edge = np.array([p[bits[:, a] == 1].mean(axis=0) - p[bits[:, a] == 0].mean(axis=0)
                     for a in range(3)])
    length = np.linalg.norm(edge, axis=1)
    if (length <= 0.0).any():
        return None
    rounding = POINT_ROUNDING * np.abs(p).max()  # [stage units]
    cosines = np.abs(np.triu((edge / length[:, None]) @ (edge / length[:, None]).T, 1))
    if cosines.max() > ORTHOGONAL_TOL + rounding / length.min():
        return None
    unit = np.empty((3, 3))
    for rank, a in enumerate(np.argsort(-length)):  # Gram-Schmidt, longest first
        v = edge[a] - sum((edge[a] @ unit[b]) * unit[b] for b in np.argsort(-length)[:rank])
        unit[a] = v / np.linalg.norm(v)
    center = p.mean(axis=0)
    half = np.abs((p - center) @ unit.T).mean(axis=0)
    fitted = center + ((2 * bits - 1) * half) @ unit
    if np.linalg.norm(fitted - p, axis=1).max() > POINT_TOL * length.max() + 4.0 * rounding:
        return None
    order = _nearest_axes(unit)  # the axis nearest local x first, then y, then z
    return center, unit[order].T, half[order]


def _nearest_axes(edges: np.ndarray) -> list[int]:
    """The order of three edges that best lines them up with the local x, y and z axes (the
    permutation with the largest sum of ``|cos|``), so an axis-aligned box keeps its axes."""
    cos = np.abs(edges) / np.linalg.norm(edges, axis=1, keepdims=True)
    return list(max(itertools.permutations(range(3)),
                    key=lambda order: sum(cos[order[a], a] for a in range(3))))


def _world_box(matrix: np.ndarray, center: np.ndarray, axes: np.ndarray, half: np.ndarray,
               where: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The world box of a local box under a USD transform (row vectors: ``p_world = [p, 1] @
    matrix``): ``(center, unit axes (3, 3) columns, proper rotation, half extents)``.

    Raises:
        ValueError: the transform shears the box, mirrors it, or flattens it on two axes.
    """
    if not np.isfinite(matrix).all():
        raise ValueError(f"{where}: the transform is not finite")
    if np.abs(matrix[:3, 3]).max() > 0.0 or matrix[3, 3] != 1.0:
        raise ValueError(f"{where}: the transform is projective, not a rigid motion with scale")
    linear = matrix[:3, :3].T  # column vectors: world = linear @ local + translation
    frame = linear @ axes  # images of the box's axes
    scale = np.linalg.norm(frame, axis=0)
    scale[np.abs(scale - 1.0) <= UNIT_SCALE] = 1.0
    flat = scale <= ORTHOGONAL_TOL * scale.max()
    if flat.sum() > 1:
        raise ValueError(f"{where}: the transform flattens the box on {flat.sum()} axes")
    unit = np.where(flat, 0.0, frame / np.where(flat, 1.0, scale))
    cosines = np.abs(np.triu(unit.T @ unit, 1)).max()
    if cosines > ORTHOGONAL_TOL:
        angle = np.degrees(np.arccos(min(cosines, 1.0)))
        raise ValueError(f"{where}: the transform shears the box (axes {angle:.4f} deg "
                         f"apart, not 90); a box must stay a box")
    if flat.any():  # a plate: its normal is the cross product of the two other axes
        i = int(np.flatnonzero(flat)[0])
        unit[:, i] = np.cross(unit[:, (i + 1) % 3], unit[:, (i + 2) % 3])
    else:
        if np.linalg.det(linear) < 0.0:
            raise ValueError(f"{where}: the transform mirrors the box (negative scale); use a "
                             f"rotation instead")
        if np.linalg.det(axes) < 0.0:  # a left-handed local frame (mesh corners): same box
            unit[:, 2] = -unit[:, 2]
    u, _, vt = np.linalg.svd(unit)  # the nearest rotation, exact to float64
    return center @ matrix[:3, :3] + matrix[3, :3], u @ vt, half * scale


def _quaternions(axes: np.ndarray) -> np.ndarray:
    """Unit quaternions ``(x, y, z, w)`` of rotation matrices ``(K, 3, 3)`` (columns: the local
    axes in the world), by Shepperd's method (the largest of the four squares first)."""
    out = np.empty((axes.shape[0], 4))
    for k, m in enumerate(axes):
        trace = np.trace(m)
        squares = [1.0 + 2.0 * m[0, 0] - trace, 1.0 + 2.0 * m[1, 1] - trace,
                   1.0 + 2.0 * m[2, 2] - trace, 1.0 + trace]  # 4 x^2, 4 y^2, 4 z^2, 4 w^2
        i = int(np.argmax(squares))
        s = 2.0 * np.sqrt(squares[i])  # 4 |q_i|
        if i == 3:
            q = [m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1], s * s / 4.0]
        elif i == 0:
            q = [s * s / 4.0, m[0, 1] + m[1, 0], m[0, 2] + m[2, 0], m[2, 1] - m[1, 2]]
        elif i == 1:
            q = [m[0, 1] + m[1, 0], s * s / 4.0, m[1, 2] + m[2, 1], m[0, 2] - m[2, 0]]
        else:
            q = [m[0, 2] + m[2, 0], m[1, 2] + m[2, 1], s * s / 4.0, m[1, 0] - m[0, 1]]
        out[k] = np.array(q) / s
    return out


def _gravity(stage: Usd.Stage, up: str, mpu: float, label: str):
    """``(gravity [m/s^2] in the stage's axes, the physics scene prim or "")``."""
    down = -np.eye(3)[1 if up == "Y" else 2]
    for prim in stage.Traverse():
        if not prim.IsA(UsdPhysics.Scene):
            continue
        scene = UsdPhysics.Scene(prim)
        direction = np.array(scene.GetGravityDirectionAttr().Get() or (0.0, 0.0, 0.0),
                             dtype=np.float64)
        magnitude = scene.GetGravityMagnitudeAttr().Get()
        magnitude = -np.inf if magnitude is None else float(magnitude)
        if not np.isfinite(direction).all() or np.isnan(magnitude) or magnitude == np.inf:
            raise ValueError(f"{label}: {prim.GetPath()}: gravity must be finite")
        norm = np.linalg.norm(direction)
        unit = down if norm == 0.0 else direction / norm
        g = EARTH_GRAVITY if magnitude < 0.0 else magnitude * mpu
        return tuple(float(c) for c in unit * g), str(prim.GetPath())
    return tuple(float(c) for c in down * EARTH_GRAVITY), ""
