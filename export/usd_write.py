"""USD animation of a simulation: writing it (reading it back: :mod:`warpsim.export.usd_read`).

Stage layout (``Y`` up, 1 unit = 1 m, default prim ``/World``)::

    /World                         Xform; warpsim:dt (double, [s]), warpsim:scene (string)
      /Looks                       UsdPreviewSurface materials
      /ObstacleShapes              class prim (abstract, never drawn): one Mesh per distinct shape
        /Shape_0000 ...            points in the box's local frame, displayColor, material bound
      /Obstacles/Box_0000 ...      one Mesh prim per box, referencing its shape; authored once
      /Spheres                     PointInstancer, one instance per sphere
        /Prototypes/CheckerBall    unit sphere with an octant checker, so spin is visible

Time: a time code is an integer simulation frame index taken from ``Trajectory.frame`` (frame
``k`` is the state after ``k`` steps of ``dt``); ``timeCodesPerSecond`` and ``framesPerSecond``
are both ``1 / dt``, start and end time codes are the first and last recorded frames.

What is stored, and at which precision (:func:`warpsim.export.usd_read.read_usd` returns exactly
this):

- ``positions`` (point3f[], time-sampled): sphere centres [m] in float32. Reading gives
  ``position.astype(float32)`` bit for bit. A float64 run far from the origin stores them
  relative to a per-frame double-precision origin instead (the instancer's time-sampled
  ``xformOp:translate:warpsimOrigin``, :mod:`warpsim.export.origins`): each position keeps
  ``2^-16`` of the swarm's extent (rounded up to a power of two, at least 1 m) or better
  wherever the swarm is; reading gives the exact float64 sum.
- ``orientationsf`` (quatf[], time-sampled): orientations body -> world in float32, read back bit
  for bit as ``orientation.astype(float32)`` in warpsim's ``(x, y, z, w)`` order. USD itself
  (usdview, Houdini, Omniverse) takes ``orientationsf`` over ``orientations`` when both are
  authored.
- ``orientations`` (quath[], time-sampled): the same rotations in half precision, for readers
  that only know this attribute (Blender's importer reads it and ignores ``orientationsf``).
  Made as good as half precision allows (:func:`half_orientations`): rounded once from the
  normalised float64 quaternion, choosing among the neighbouring half values of each component
  the combination whose rotation matrix, used as is (unnormalised, as such readers do), is
  nearest the true one; the sign of each quaternion follows the previous written frame, so a
  reader that interpolates component-wise turns the short way. ``read_usd`` uses it only when
  ``orientationsf`` is missing.
- ``velocities`` (vector3f[], time-sampled, when the trajectory has ``velocity`` and the writer
  is asked for it): each sphere's true velocity at the frame [m/s], float32, read back bit for
  bit. ``angularVelocities`` (vector3f[], time-sampled, with ``angular_velocity``): world-frame
  angular velocity in degrees per second, as the USD schema defines it (float32 of the float64
  product ``omega * 180 / pi``). Renderers use both for motion blur; USD also uses them to place
  instances between samples (``position + velocity * delta`` from the earlier sample).
- ``scales`` (float3[]): sphere radius on every axis, float32 (the prototype has radius 1);
  ``warpsim:radius`` (double[]) keeps the radii exactly. ``ids`` (int64[]) are the indices of the
  spheres in the simulated swarm; ``protoIndices`` are all 0. These are authored once.
- Births (a trajectory with ``birth_frame``): ``warpsim:birthFrame`` (int64[], once) holds each
  sphere's birth frame, and ``invisibleIds`` (int64[], time-sampled where it changes, held in
  between) the ids of the spheres not born yet at each written frame, so that every reader
  hides them. Their ``positions`` there are those of their first recorded living frame (their
  state at birth when that frame is recorded), orientations the identity, velocities zero;
  ``read_usd`` gives NaN there, as the simulator does.
- Obstacles: every box is a ``Mesh`` prim with its material bound and ``primvars:displayColor``
  set, so importers that drop the material of other prim types (Blender does for ``Cube``
  prims) keep the look. Sharp boxes (radius 0) are 24-point boxes (:func:`box_mesh`, one quad
  per face, flat shaded by any reader), rounded boxes come from :func:`rounded_box_mesh`; points
  in float32. Boxes of the same shape (half extents and radius equal to the bit) share one
  mesh through an internal reference to ``/World/ObstacleShapes/Shape_*``, so a lattice of
  1e5 identical boxes stores its mesh once. Each box prim carries ``xformOp:translate``
  (double3) and ``xformOp:orient`` (quatd); its shape carries the custom attributes
  ``warpsim:halfExtents`` (double3) and ``warpsim:radius`` (double), which every box composes
  through its reference, from which :func:`read_usd_boxes` rebuilds the boxes in float64.
  Writing is linear in the number of boxes (Sdf specs authored in one change block, no
  per-prim lookups).

Size: :func:`warpsim.export.usd_size.estimate_usd_bytes` (a model fitted on written files, see
its docstring; pxr-free, so the size is checked before pxr loads).
"""

from __future__ import annotations

import re
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdShade, Vt

from ..obstacles import RoundedBoxes
from ..trajectory import Trajectory
from .files import atomic_output
from .mesh import box_mesh, checker_sphere_mesh, rounded_box_mesh
from .origins import ORIGIN_OP, frame_origins
from .usd_layout import (  # noqa: F401 - the layout's names are the writer's too
    LOOKS,
    OBSTACLE_COLOR,
    OBSTACLE_MATERIAL,
    OBSTACLES,
    PROTOTYPE,
    SHAPES,
    SPHERE_DARK,
    SPHERE_LIGHT,
    SPHERES,
    WORLD,
)
from .usd_layout import selected_rows as _selected
from .usd_layout import shapes as _shapes
from .usd_size import FORMATS, SUFFIXES, estimate_usd_bytes  # noqa: F401 - its names too

ROUNDED_BOX_SEGMENTS = 8  # edges per quarter circle of a rounded box's edges and corners
SPHERE_LONGITUDES = 32  # prototype tessellation: smooth enough at any zoom a swarm is seen at
SPHERE_LATITUDES = 16
HALF_CHUNK = 1 << 16  # quaternions rounded to half together: bounds the temporary memory
DEGREES_PER_RADIAN = 180.0 / np.pi

class LargeOutputWarning(UserWarning):
    """The USD file about to be written is estimated larger than the caller's ``max_bytes``.

    A ``UserWarning`` (not a ``ResourceWarning``, which Python hides by default) so that it shows.
    """


def usd_format(path) -> str:
    """``"usdc"`` or ``"usda"`` from a path's extension (any case: ``a.USDC`` is binary).

    Raises:
        ValueError: another extension, or an empty path.
    """
    text = str(path)
    suffix = Path(text).suffix.lower()
    if not text.strip() or suffix not in SUFFIXES:
        raise ValueError(f"path must end in .usda (text) or .usdc (binary), got {text!r}")
    return suffix[1:]


def pxr_message(exc: Exception) -> str:
    """The first message of a pxr error, without its C++ location: one line."""
    found = re.findall(r" : '(.*?)'\s*(?:\n|$)", str(exc), flags=re.S)
    text = found[0] if found else str(exc)
    return " ".join(text.split())


# --------------------------------------------------------------------------------------------
# Writing


def born_stand_ins(trajectory: Trajectory) -> Trajectory:
    """A copy of a trajectory with births whose unborn values (NaN) are what a file stores
    there (module docstring): a sphere's first living position, the identity orientation, zero
    velocities; the trajectory itself when it has no births."""
    births = getattr(trajectory, "birth_frame", None)
    if births is None:
        return trajectory
    unborn = ~trajectory.alive()
    first = np.minimum(np.searchsorted(np.asarray(trajectory.frame), births), len(trajectory) - 1)
    n = trajectory.sphere_count
    position = np.array(trajectory.position, copy=True)
    stand_in = np.nan_to_num(position[first, np.arange(n)])
    position[unborn] = np.broadcast_to(stand_in, position.shape)[unborn]
    orientation = np.array(trajectory.orientation, copy=True)
    orientation[unborn] = (0.0, 0.0, 0.0, 1.0)

    def still(values):
        if values is None:
            return None
        values = np.array(values, copy=True)
        values[unborn] = 0.0
        return values

    return replace(trajectory, position=position, orientation=orientation,
                   velocity=still(trajectory.velocity),
                   angular_velocity=still(trajectory.angular_velocity))


def hidden_ids(ids: np.ndarray, births: np.ndarray, frame: int) -> Vt.Int64Array:
    """The ``invisibleIds`` of a frame: the ids of the spheres born after it."""
    return Vt.Int64Array.FromNumpy(np.asarray(ids, dtype=np.int64)[births > frame])


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two arrays hold the same values to the bit (``-0.0`` is not ``0.0``, a NaN is
    the same NaN), with the same type and shape."""
    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    return bool(np.array_equal(np.ascontiguousarray(a).view(np.uint8),
                               np.ascontiguousarray(b).view(np.uint8)))


def half_orientations(q, previous=None, previous_q=None) -> np.ndarray:
    """Quaternions (x, y, z, w) in half precision, as good as half precision allows.

    The quaternions are normalised in float64, then each component is taken from the two half
    values around it (below and above): of the 16 combinations, the one whose rotation matrix,
    computed from the half values as they are (readers of ``orientations`` do not renormalise),
    is nearest the true rotation in the largest entry. ``q`` and ``-q`` are the same rotation
    and round alike; the sign is chosen so that each quaternion lies in the hemisphere of
    ``previous`` (the half values written for the frame before), so interpolating readers turn
    the short way.

    Args:
        q: quaternions, shape (N, 4), any non-zero length.
        previous: half quaternions (N, 4) of the previous frame, or None.
        previous_q: the quaternions (N, 4) that ``previous`` was made from, or None. A row of
            ``q`` equal to its row there keeps its ``previous`` value unchanged: the choice is
            per row and ``previous`` already lies in its own hemisphere, so this is exactly what
            the whole computation gives, and a frame where nothing turned costs a comparison.

    Returns:
        (N, 4) float16.
    """
    if previous is not None and previous_q is not None:
        q = np.asarray(q).reshape(-1, 4)
        moved = np.any(q != np.asarray(previous_q).reshape(-1, 4), axis=1)
        out = np.array(previous, dtype=np.float16).reshape(-1, 4)
        if moved.any():
            out[moved] = half_orientations(q[moved], out[moved])
        return out
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    out = np.empty(q.shape, dtype=np.float16)
    combos = (np.arange(16)[:, None] >> np.arange(4)[None, :]) & 1  # (16, 4): 0 below, 1 above
    unit = q / np.linalg.norm(q, axis=1, keepdims=True)
    near = unit.astype(np.float16)
    # a row whose components are all half values (the identity of a swarm that never turned)
    # has one candidate only, 16 times: it is its own best, no matrix needed
    exact = np.all(near.astype(np.float64) == unit, axis=1)
    out[exact] = near[exact]
    rows = np.flatnonzero(~exact)
    for start in range(0, rows.size, HALF_CHUNK):
        chunk = rows[start:start + HALF_CHUNK]
        unit_c = unit[chunk]
        near_c = near[chunk]
        near64 = near_c.astype(np.float64)
        below = np.where(near64 > unit_c, np.nextafter(near_c, np.float16(-np.inf)), near_c)
        above = np.where(near64 < unit_c, np.nextafter(near_c, np.float16(np.inf)), near_c)
        candidates = np.where(combos[None] == 1, above[:, None, :], below[:, None, :])
        error = np.abs(_rotation_entries(candidates.astype(np.float64))
                       - _rotation_entries(unit_c)[:, None, :]).max(axis=2)
        out[chunk] = candidates[np.arange(chunk.size), np.argmin(error, axis=1)]
    if previous is not None:
        flip = (out.astype(np.float64) * np.asarray(previous, dtype=np.float64)).sum(axis=1) < 0
        out[flip] = -out[flip]
    return out


def _rotation_entries(p: np.ndarray) -> np.ndarray:
    """The nine entries of the rotation matrix of unit quaternions (x, y, z, w), applied to
    ``p`` as it is (..., 4) -> (..., 9)."""
    x, y, z, w = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    return np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
                     2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                     2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1)


def _preview_material(stage: Usd.Stage, path: str, color) -> UsdShade.Material:
    material = UsdShade.Material.Define(stage, path)
    shader = UsdShade.Shader.Define(stage, f"{path}/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color))
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.6)
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    return material


def _bind(prim: Usd.Prim, material: UsdShade.Material) -> None:
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)


def _author_mesh(mesh: UsdGeom.Mesh, points: np.ndarray, counts: np.ndarray,
                 indices: np.ndarray) -> None:
    pts = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, dtype=np.float32))
    mesh.CreatePointsAttr(pts)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(counts.astype(np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(indices.astype(np.int32)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)  # polygons as given, not a limit surface
    mesh.CreateExtentAttr(UsdGeom.Mesh.ComputeExtent(pts))


def _author_sphere_prototype(stage: Usd.Stage, light, dark) -> None:
    points, counts, indices, is_light = checker_sphere_mesh(SPHERE_LONGITUDES, SPHERE_LATITUDES)
    UsdGeom.Xform.Define(stage, PROTOTYPE.rsplit("/", 1)[0])
    mesh = UsdGeom.Mesh.Define(stage, PROTOTYPE)
    _author_mesh(mesh, points, counts, indices)
    mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))  # unit sphere
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    colors = np.where(is_light[:, None], SPHERE_LIGHT, SPHERE_DARK).astype(np.float32)
    mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.uniform).Set(Vt.Vec3fArray.FromNumpy(colors))
    binding = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
    for name, faces, material in (("light", np.flatnonzero(is_light), light),
                                  ("dark", np.flatnonzero(~is_light), dark)):
        subset = binding.CreateMaterialBindSubset(
            name, Vt.IntArray.FromNumpy(faces.astype(np.int32)), UsdGeom.Tokens.face)
        _bind(subset.GetPrim(), material)
    binding.SetMaterialBindSubsetsFamilyType(UsdGeom.Tokens.partition)


def _spec_attribute(prim: Sdf.PrimSpec, name: str, type_name, value, *, custom: bool = False,
                    uniform: bool = False) -> Sdf.AttributeSpec:
    variability = Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying
    attr = Sdf.AttributeSpec(prim, name, type_name, variability, custom)
    attr.default = value
    return attr


def _author_obstacles(layer: Sdf.Layer, boxes: RoundedBoxes) -> None:
    """Author the shapes and one Mesh prim per box, in one Sdf change block (linear in K)."""
    T = Sdf.ValueTypeNames
    shape_of, shapes = _shapes(boxes)
    width = max(4, len(str(len(boxes) - 1)))
    shape_width = max(4, len(str(len(shapes) - 1)))
    color = Vt.Vec3fArray([Gf.Vec3f(*OBSTACLE_COLOR)])
    order = Vt.TokenArray(["xformOp:translate", "xformOp:orient"])
    binding_schema = Sdf.TokenListOp.Create(prependedItems=["MaterialBindingAPI"])
    with Sdf.ChangeBlock():
        world = layer.GetPrimAtPath(WORLD)
        shapes_root = Sdf.PrimSpec(world, SHAPES.rsplit("/", 1)[1], Sdf.SpecifierClass)
        shape_paths = []
        faces = {}  # faces of every sharp (True) / rounded (False) shape: one Vt array each
        for j, (hx, hy, hz, radius) in enumerate(shapes):
            h = np.array([hx, hy, hz])
            sharp = bool(radius == 0.0)
            points, counts, indices = (box_mesh(h) if sharp else
                                       rounded_box_mesh(h, radius, ROUNDED_BOX_SEGMENTS))
            if sharp not in faces:
                faces[sharp] = (Vt.IntArray.FromNumpy(counts), Vt.IntArray.FromNumpy(indices))
            mesh = Sdf.PrimSpec(shapes_root, f"Shape_{j:0{shape_width}d}", Sdf.SpecifierDef,
                                "Mesh")
            pts = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(points, dtype=np.float32))
            _spec_attribute(mesh, "points", T.Point3fArray, pts)
            _spec_attribute(mesh, "faceVertexCounts", T.IntArray, faces[sharp][0])
            _spec_attribute(mesh, "faceVertexIndices", T.IntArray, faces[sharp][1])
            _spec_attribute(mesh, "subdivisionScheme", T.Token, UsdGeom.Tokens.none,
                            uniform=True)
            _spec_attribute(mesh, "extent", T.Float3Array, UsdGeom.Mesh.ComputeExtent(pts))
            _spec_attribute(mesh, "primvars:displayColor", T.Color3fArray, color).SetInfo(
                "interpolation", UsdGeom.Tokens.constant)
            mesh.SetInfo("apiSchemas", binding_schema)
            _spec_attribute(mesh, "warpsim:halfExtents", T.Double3, Gf.Vec3d(hx, hy, hz),
                            custom=True)
            _spec_attribute(mesh, "warpsim:radius", T.Double, float(radius), custom=True)
            Sdf.RelationshipSpec(mesh, "material:binding", False).targetPathList.Append(
                Sdf.Path(OBSTACLE_MATERIAL))
            shape_paths.append(mesh.path)

        root = Sdf.PrimSpec(world, OBSTACLES.rsplit("/", 1)[1], Sdf.SpecifierDef, "Scope")
        centers, rotations = boxes.center.tolist(), boxes.rotation.tolist()
        for i, ((x, y, z), (qx, qy, qz, qw)) in enumerate(zip(centers, rotations, strict=True)):
            prim = Sdf.PrimSpec(root, f"Box_{i:0{width}d}", Sdf.SpecifierDef, "Mesh")
            prim.referenceList.Prepend(Sdf.Reference(primPath=shape_paths[shape_of[i]]))
            _spec_attribute(prim, "xformOp:translate", T.Double3, Gf.Vec3d(x, y, z))
            _spec_attribute(prim, "xformOp:orient", T.Quatd, Gf.Quatd(qw, qx, qy, qz))
            _spec_attribute(prim, "xformOpOrder", T.TokenArray, order, uniform=True)


def _author_spheres(stage: Usd.Stage, trajectory: Trajectory, rows: np.ndarray,
                    idx: np.ndarray, velocities: bool) -> None:
    instancer = UsdGeom.PointInstancer.Define(stage, SPHERES)
    instancer.CreatePrototypesRel().SetTargets([Sdf.Path(PROTOTYPE)])
    n = idx.size
    radius = np.asarray(trajectory.radius, dtype=np.float64)[idx]
    instancer.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(np.zeros(n, dtype=np.int32)))
    ids = trajectory.ids() if hasattr(trajectory, "ids") else np.arange(
        np.shape(trajectory.radius)[0], dtype=np.int64)
    instancer.CreateIdsAttr(Vt.Int64Array.FromNumpy(ids[idx].astype(np.int64)))
    scales = np.repeat(radius.astype(np.float32)[:, None], 3, axis=1)
    instancer.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(scales))
    instancer.GetPrim().CreateAttribute("warpsim:radius", Sdf.ValueTypeNames.DoubleArray,
                                        custom=True).Set(Vt.DoubleArray.FromNumpy(radius))
    attrs = {"positions": instancer.CreatePositionsAttr(),
             "orientationsf": instancer.CreateOrientationsfAttr(),
             "orientations": instancer.CreateOrientationsAttr()}
    trajectory = born_stand_ins(trajectory)
    velocity = trajectory.velocity if velocities else None
    angular = trajectory.angular_velocity if velocities else None
    if velocity is not None:
        attrs["velocities"] = instancer.CreateVelocitiesAttr()
    if angular is not None:
        attrs["angularVelocities"] = instancer.CreateAngularVelocitiesAttr()
    births = getattr(trajectory, "birth_frame", None)
    if births is not None:
        births = np.asarray(births, dtype=np.int64)[idx]
        instancer.GetPrim().CreateAttribute("warpsim:birthFrame", Sdf.ValueTypeNames.Int64Array,
                                            custom=True).Set(Vt.Int64Array.FromNumpy(births))
        attrs["invisibleIds"] = instancer.CreateInvisibleIdsAttr()
    origins = frame_origins(trajectory.position, rows, idx)  # [m], far from 0 (origins.py)
    if origins.any():
        attrs["origin"] = instancer.GetPrim().CreateAttribute(ORIGIN_OP,
                                                              Sdf.ValueTypeNames.Double3)
        instancer.CreateXformOpOrderAttr(Vt.TokenArray([ORIGIN_OP]))
    paths = {name: attr.GetPath() for name, attr in attrs.items()}
    layer = stage.GetRootLayer()
    frames = np.asarray(trajectory.frame, dtype=np.int64)

    def vec3(values):
        return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(values, dtype=np.float32)
                                       .reshape(n, 3))

    # every sphere in order: a frame's rows as they are, without a gathered copy
    everyone = idx.size == trajectory.position.shape[1] and bool(
        np.array_equal(idx, np.arange(idx.size)))

    def chosen(values):
        return values if everyone else values[idx]

    # Vt quaternion arrays lay out each element as (i, j, k, real): warpsim's (x, y, z, w) order,
    # so the numpy rows go in unchanged (the Gf constructors, by contrast, take the real first).
    previous = previous_q = None
    turned = None  # the frame's quaternions as the trajectory holds them, for the next frame
    hidden_before = None
    with Sdf.ChangeBlock():
        for row, origin in zip(rows, origins, strict=True):
            time = float(frames[row])
            if "origin" in paths:
                layer.SetTimeSample(paths["origin"], time, Gf.Vec3d(*origin.tolist()))
            if births is not None:
                hidden = hidden_ids(ids[idx], births, frames[row])
                if hidden_before is None or hidden != hidden_before:
                    layer.SetTimeSample(paths["invisibleIds"], time, hidden)
                hidden_before = hidden
            position = chosen(trajectory.position[row])  # [m], as the trajectory holds it
            if "origin" in paths:  # no float64 copy to take 0 off every coordinate
                position = position - origin
            layer.SetTimeSample(paths["positions"], time, vec3(position))
            raw = np.asarray(trajectory.orientation[row])
            if turned is None or not same_bits(raw, turned):
                # Each precision rounded from the source values (no double rounding via
                # float32); a frame whose quaternions are the previous frame's to the bit (a
                # swarm that does not spin) writes the previous frame's arrays again
                q = chosen(raw)
                quat_f = Vt.QuatfArray.FromNumpy(np.ascontiguousarray(q, dtype=np.float32)
                                                 .reshape(n, 4))
                previous, previous_q = half_orientations(q, previous, previous_q), q
                quat_h = Vt.QuathArray.FromNumpy(previous)
            turned = raw
            layer.SetTimeSample(paths["orientationsf"], time, quat_f)
            layer.SetTimeSample(paths["orientations"], time, quat_h)
            if velocity is not None:
                layer.SetTimeSample(paths["velocities"], time, vec3(chosen(velocity[row])))
            if angular is not None:
                degrees = chosen(np.asarray(angular[row], dtype=np.float64)) * DEGREES_PER_RADIAN
                layer.SetTimeSample(paths["angularVelocities"], time, vec3(degrees))


def export_layer(layer: Sdf.Layer, path: Path) -> None:
    """Write ``layer`` to ``path``, in the format named by its extension."""
    try:
        ok = layer.Export(str(path))
    except Tf.ErrorException as exc:
        raise OSError(f"USD could not write {str(path)!r}: {pxr_message(exc)}") from None
    if not ok:
        raise OSError(f"USD could not write {str(path)!r}")


def write_usd(path, scene, trajectory: Trajectory, *, stride: int = 1, spheres=None,
              velocities: bool | None = None, max_bytes: int = 2_000_000_000,
              warn: bool = True) -> Path:
    """Write a trajectory and its scene's obstacles as a USD animation, atomically.

    The stage is built in memory, written under a temporary name next to ``path`` (same
    extension), then renamed over ``path``: readers never see a partial file, and on any error
    nothing is left behind and a file already at ``path`` is untouched. See the module docstring
    for the layout and the precision of what is stored.

    Args:
        path: output file; ``.usda`` (text) or ``.usdc`` (binary), any case. Its folder must
            exist.
        scene: the :class:`warpsim.Scene` simulated (its boxes are written once, never per frame),
            or its :class:`warpsim.RoundedBoxes`, or None to write the spheres alone. Boxes read
            from a USD stage are not written: the result composes over that stage
            (:mod:`warpsim.export.compose`).
        trajectory: the recorded frames; time codes are its integer ``frame`` indices.
        stride: keep every ``stride``-th recorded frame (rows 0, stride, 2 stride, ...) and the
            last one, as ``Simulator.run(every=...)`` does; >= 1.
        spheres: indices of the spheres to write (in that order, distinct), or None for all.
            Their indices in the swarm (``trajectory.sphere_ids``, for a trajectory of a
            subset) are stored as the instancer's ``ids``.
        velocities: write ``velocities`` and ``angularVelocities`` (True), or not (False);
            None writes whichever the trajectory has.
        max_bytes: size above which a :class:`LargeOutputWarning` is emitted before writing
            (estimate from :func:`estimate_usd_bytes`) [bytes].
        warn: False to silence that warning.

    Returns:
        ``path`` as a :class:`pathlib.Path`.

    Raises:
        ValueError: bad extension, bad ``stride`` or ``spheres``, inconsistent trajectory,
            ``velocities=True`` for a trajectory without velocities.
        FileNotFoundError: the output folder does not exist.
        OSError: the file cannot be written (the message names it).
    """
    fmt = usd_format(path)
    path = Path(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"folder of {str(path)!r} does not exist")
    rows, idx = _selected(trajectory, stride, spheres)
    has_velocity = getattr(trajectory, "velocity", None) is not None
    if velocities and not has_velocity:
        raise ValueError("velocities=True but the trajectory has no velocity: record it with "
                         "Simulator.run(..., velocities=True)")
    velocities = has_velocity if velocities is None else bool(velocities)
    frames = np.asarray(trajectory.frame, dtype=np.int64)[rows]
    dt = float(trajectory.dt)
    boxes = None if scene is None else (scene if isinstance(scene, RoundedBoxes) else scene.boxes)
    over = getattr(boxes, "stage", None)  # boxes read from a USD stage: compose over it
    if over is not None:  # (export/compose.py), the set drawing them
        boxes = None

    if warn:
        q = np.asarray(trajectory.orientation)
        spinning = bool(rows.size > 1 and (q[rows[1:]] != q[rows[0]]).any())
        estimate = estimate_usd_bytes(idx.size, rows.size, fmt, boxes=boxes,
                                      spinning=spinning, velocities=velocities)
        if estimate > max_bytes:
            warnings.warn(LargeOutputWarning(
                f"{str(path)!r} is estimated at {estimate / 1e6:,.0f} MB ({idx.size} spheres x "
                f"{rows.size} frames), above max_bytes={max_bytes:,}; pass stride=k to keep "
                f"every k-th frame or spheres=[...] to write a subset (or warn=False)"),
                stacklevel=2)

    stage = Usd.Stage.CreateInMemory(f"warpsim.{fmt}")
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(1.0 / dt)
    stage.SetFramesPerSecond(1.0 / dt)
    stage.SetStartTimeCode(float(frames[0]))
    stage.SetEndTimeCode(float(frames[-1]))
    world = UsdGeom.Xform.Define(stage, WORLD).GetPrim()
    stage.SetDefaultPrim(world)
    world.CreateAttribute("warpsim:dt", Sdf.ValueTypeNames.Double, custom=True).Set(dt)
    name = getattr(scene, "name", "")
    world.CreateAttribute("warpsim:scene", Sdf.ValueTypeNames.String, custom=True).Set(name)
    stage.GetRootLayer().documentation = (
        f"warpsim animation of scene {name!r}: {idx.size} spheres, {rows.size} frames, "
        f"dt = {dt!r} s. {getattr(scene, 'description', '')}".strip())

    UsdGeom.Scope.Define(stage, LOOKS)
    light = _preview_material(stage, f"{LOOKS}/SphereLight", SPHERE_LIGHT)
    dark = _preview_material(stage, f"{LOOKS}/SphereDark", SPHERE_DARK)
    _preview_material(stage, OBSTACLE_MATERIAL, OBSTACLE_COLOR)
    if boxes is not None and len(boxes):
        _author_obstacles(stage.GetRootLayer(), boxes)
    _author_spheres(stage, trajectory, rows, idx, velocities)
    _author_sphere_prototype(stage, light, dark)

    layer = stage.GetRootLayer()
    if over is not None:
        from .compose import over_set

        layer = over_set(layer, over, path, SPHERES)
    with atomic_output(path) as tmp:
        export_layer(layer, tmp)
    return path


__all__ = ["LargeOutputWarning", "estimate_usd_bytes", "half_orientations", "usd_format",
           "write_usd"]
