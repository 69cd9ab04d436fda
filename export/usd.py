"""USD animation of a simulation: write it, read it back.

Stage layout (``Y`` up, 1 unit = 1 m, default prim ``/World``)::

    /World                         Xform; warpsim:dt (double, [s]), warpsim:scene (string)
      /Looks                       UsdPreviewSurface materials
      /Obstacles/Box_0000 ...      one prim per box, authored once (no time samples)
      /Spheres                     PointInstancer, one instance per sphere
        /Prototypes/CheckerBall    unit sphere with an octant checker, so spin is visible

Time: a time code is an integer simulation frame index taken from ``Trajectory.frame`` (frame
``k`` is the state after ``k`` steps of ``dt``); ``timeCodesPerSecond`` and ``framesPerSecond``
are both ``1 / dt``, start and end time codes are the first and last recorded frames.

What is stored, and at which precision (``read_usd`` returns exactly this):

- ``positions`` (point3f[], time-sampled): sphere centres [m] in float32. Reading gives
  ``position.astype(float32)`` bit for bit.
- ``orientationsf`` (quatf[], time-sampled): orientations body -> world in float32, read back bit
  for bit as ``orientation.astype(float32)`` in warpsim's ``(x, y, z, w)`` order. USD takes
  ``orientationsf`` over ``orientations`` when both are authored.
- ``orientations`` (quath[], time-sampled): the same quaternions in half precision (11-bit
  significand: rounding error at most 2^-12 ~ 2.4e-4 per component, each rounded once from the
  source values) for readers that predate ``orientationsf``;
  ``read_usd`` uses it only when ``orientationsf`` is missing.
- ``scales`` (float3[]): sphere radius on every axis, float32 (the prototype has radius 1);
  ``warpsim:radius`` (double[]) keeps the radii exactly. ``ids`` (int64[]) are the indices of the
  spheres in the simulated swarm; ``protoIndices`` are all 0. These are authored once.
- Obstacles: sharp boxes (radius 0) are ``Cube`` prims (size 2, scaled by the half extents), rounded
  boxes are ``Mesh`` prims from :func:`warpsim.export.mesh.rounded_box_mesh` (points in float32).
  Both carry ``xformOp:translate`` (double3) and ``xformOp:orient`` (quatd), plus the custom
  attributes ``warpsim:halfExtents`` (double3) and ``warpsim:radius`` (double), so
  :func:`read_usd_boxes` rebuilds the boxes in float64.

Size (measured with usd-core 26.11 on random data, least-squares fit over files from 1 to
10^5 sphere-frames; :func:`estimate_usd_bytes` uses it): per sphere and recorded frame 36.0 bytes
in ``.usdc`` (float32 position 12 B + quatf 16 B + quath 8 B, stored uncompressed) and about
131 bytes in ``.usda`` (decimal text); per sphere (static attributes) 20 B / 68 B; per frame
(time-sample bookkeeping) 56 B / 57 B; fixed (stage, materials, sphere prototype) 14 kB / 64 kB.
Each rounded-box mesh adds about 7 kB (usdc) / 29 kB (usda), a cube about 1 kB.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, Vt

from ..obstacles import RoundedBoxes
from ..trajectory import Trajectory
from .files import atomic_output
from .mesh import checker_sphere_mesh, rounded_box_mesh

WORLD = "/World"
LOOKS = "/World/Looks"
OBSTACLES = "/World/Obstacles"
SPHERES = "/World/Spheres"
PROTOTYPE = "/World/Spheres/Prototypes/CheckerBall"

FORMATS = ("usda", "usdc")
ROUNDED_BOX_SEGMENTS = 8  # edges per quarter circle of a rounded box's edges and corners
SPHERE_LONGITUDES = 32  # prototype tessellation: smooth enough at any zoom a swarm is seen at
SPHERE_LATITUDES = 16

# Colours (linear RGB) shared with the preview so that both look alike.
SPHERE_LIGHT = (0.95, 0.62, 0.18)
SPHERE_DARK = (0.45, 0.12, 0.05)
OBSTACLE_COLOR = (0.42, 0.52, 0.66)

# Size model fitted on measured files (see the module docstring and tests/test_export.py):
# bytes = fixed + per_sphere * N + per_frame * F + per_sphere_frame * N * F.
_SIZE_MODEL = {
    "usda": {"fixed": 64_500, "per_sphere": 68, "per_frame": 57, "per_sphere_frame": 131},
    "usdc": {"fixed": 14_500, "per_sphere": 20, "per_frame": 56, "per_sphere_frame": 36},
}


class LargeOutputWarning(UserWarning):
    """The USD file about to be written is estimated larger than the caller's ``max_bytes``.

    A ``UserWarning`` (not a ``ResourceWarning``, which Python hides by default) so that it shows.
    """


def _format_of(path: Path) -> str:
    fmt = path.suffix[1:]
    if fmt not in FORMATS:
        raise ValueError(f"path must end in .usda (text) or .usdc (binary), got {str(path)!r}")
    return fmt


def estimate_usd_bytes(n_spheres: int, n_frames: int, fmt: str) -> int:
    """Estimated size of a file written by :func:`write_usd` [bytes].

    A linear model fitted on measured files; obstacles add a few kilobytes each and are not
    counted. Use it to pick ``stride`` or a ``spheres`` subset before writing.

    Args:
        n_spheres: spheres written.
        n_frames: recorded frames written (after ``stride``).
        fmt: ``"usda"`` or ``"usdc"`` (a leading dot is accepted).

    Returns:
        The estimate in bytes.

    Raises:
        ValueError: unknown ``fmt`` or negative counts.
    """
    key = str(fmt).lstrip(".")
    if key not in _SIZE_MODEL:
        raise ValueError(f"fmt must be one of {FORMATS}, got {fmt!r}")
    if n_spheres < 0 or n_frames < 0:
        raise ValueError(f"n_spheres and n_frames must be >= 0, got {n_spheres}, {n_frames}")
    m = _SIZE_MODEL[key]
    n, f = int(n_spheres), int(n_frames)
    return int(m["fixed"] + m["per_sphere"] * n + m["per_frame"] * f
               + m["per_sphere_frame"] * n * f)


# --------------------------------------------------------------------------------------------
# Writing


def _selected(trajectory: Trajectory, stride: int, spheres) -> tuple[np.ndarray, np.ndarray]:
    """Validated (frame rows, sphere indices) to write."""
    if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)) or stride < 1:
        raise ValueError(f"stride must be an integer >= 1, got {stride!r}")
    frame = np.asarray(trajectory.frame)
    n_frames, n = len(frame), trajectory.position.shape[1]
    if n_frames == 0:
        raise ValueError("trajectory has no recorded frames")
    if trajectory.position.shape != (n_frames, n, 3):
        raise ValueError(f"trajectory.position must have shape ({n_frames}, N, 3), "
                         f"got {trajectory.position.shape}")
    if trajectory.orientation.shape != (n_frames, n, 4):
        raise ValueError(f"trajectory.orientation must have shape ({n_frames}, {n}, 4), "
                         f"got {trajectory.orientation.shape}")
    if np.shape(trajectory.radius) != (n,):
        raise ValueError(f"trajectory.radius must have shape ({n},), "
                         f"got {np.shape(trajectory.radius)}")
    if not (np.isfinite(trajectory.dt) and trajectory.dt > 0):
        raise ValueError(f"trajectory.dt must be > 0, got {trajectory.dt!r}")
    if (np.diff(frame) <= 0).any():
        raise ValueError("trajectory.frame must be strictly increasing")
    rows = np.arange(0, n_frames, stride)
    if spheres is None:
        return rows, np.arange(n)
    idx = np.asarray(spheres)
    if idx.ndim != 1 or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
        raise ValueError(f"spheres must be a 1-D sequence of sphere indices, got {spheres!r}")
    idx = idx.astype(np.int64)
    bad = (idx < 0) | (idx >= n)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"spheres[{i}] = {idx[i]} is out of range for {n} spheres")
    if np.unique(idx).size != idx.size:
        raise ValueError("spheres must not repeat an index")
    return rows, idx


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


def _author_obstacles(stage: Usd.Stage, boxes: RoundedBoxes, material) -> None:
    UsdGeom.Scope.Define(stage, OBSTACLES)
    width = max(4, len(str(len(boxes) - 1)))
    color = Vt.Vec3fArray([Gf.Vec3f(*OBSTACLE_COLOR)])
    for i in range(len(boxes)):
        path = f"{OBSTACLES}/Box_{i:0{width}d}"
        h = boxes.half_extents[i]
        radius = float(boxes.radius[i])
        if radius == 0.0:
            gprim = UsdGeom.Cube.Define(stage, path)
            gprim.CreateSizeAttr(2.0)
        else:
            gprim = UsdGeom.Mesh.Define(stage, path)
            _author_mesh(gprim, *rounded_box_mesh(h, radius, ROUNDED_BOX_SEGMENTS))
        gprim.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(color)
        x, y, z = boxes.center[i]
        gprim.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(x, y, z))
        qx, qy, qz, qw = boxes.rotation[i]
        gprim.AddOrientOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Quatd(qw, qx, qy, qz))
        if radius == 0.0:  # the size-2 cube spans [-1, 1]: scale it to [-h, h]
            gprim.AddScaleOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(*h))
        prim = gprim.GetPrim()
        prim.CreateAttribute("warpsim:halfExtents", Sdf.ValueTypeNames.Double3,
                             custom=True).Set(Gf.Vec3d(*h))
        prim.CreateAttribute("warpsim:radius", Sdf.ValueTypeNames.Double, custom=True).Set(radius)
        _bind(prim, material)


def _author_spheres(stage: Usd.Stage, trajectory: Trajectory, rows: np.ndarray,
                    idx: np.ndarray) -> None:
    instancer = UsdGeom.PointInstancer.Define(stage, SPHERES)
    instancer.CreatePrototypesRel().SetTargets([Sdf.Path(PROTOTYPE)])
    n = idx.size
    radius = np.asarray(trajectory.radius, dtype=np.float64)[idx]
    instancer.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(np.zeros(n, dtype=np.int32)))
    instancer.CreateIdsAttr(Vt.Int64Array.FromNumpy(idx.astype(np.int64)))
    scales = np.repeat(radius.astype(np.float32)[:, None], 3, axis=1)
    instancer.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(scales))
    instancer.GetPrim().CreateAttribute("warpsim:radius", Sdf.ValueTypeNames.DoubleArray,
                                        custom=True).Set(Vt.DoubleArray.FromNumpy(radius))

    positions = instancer.CreatePositionsAttr()
    orientations_f = instancer.CreateOrientationsfAttr()
    orientations_h = instancer.CreateOrientationsAttr()
    frames = np.asarray(trajectory.frame, dtype=np.int64)
    # Vt quaternion arrays lay out each element as (i, j, k, real): warpsim's (x, y, z, w) order,
    # so the numpy rows go in unchanged (the Gf constructors, by contrast, take the real first).
    for row in rows:
        time = Usd.TimeCode(float(frames[row]))
        p = np.ascontiguousarray(trajectory.position[row][idx], dtype=np.float32)
        q = np.asarray(trajectory.orientation[row][idx])
        positions.Set(Vt.Vec3fArray.FromNumpy(p.reshape(n, 3)), time)
        # Each precision rounded once from the source values (no double rounding via float32).
        orientations_f.Set(Vt.QuatfArray.FromNumpy(
            np.ascontiguousarray(q, dtype=np.float32).reshape(n, 4)), time)
        orientations_h.Set(Vt.QuathArray.FromNumpy(
            np.ascontiguousarray(q, dtype=np.float16).reshape(n, 4)), time)


def _export_layer(layer: Sdf.Layer, path: Path) -> None:
    """Write ``layer`` to ``path``, in the format named by its extension."""
    if not layer.Export(str(path)):
        raise OSError(f"USD could not write {str(path)!r}")


def write_usd(path, scene, trajectory: Trajectory, *, stride: int = 1, spheres=None,
              max_bytes: int = 2_000_000_000, warn: bool = True) -> Path:
    """Write a trajectory and its scene's obstacles as a USD animation, atomically.

    The stage is built in memory, written under a temporary name next to ``path`` (same
    extension), then renamed over ``path``: readers never see a partial file, and on any error
    nothing is left behind and a file already at ``path`` is untouched. See the module docstring
    for the layout and the precision of what is stored.

    Args:
        path: output file; ``.usda`` (text) or ``.usdc`` (binary). Its folder must exist.
        scene: the :class:`warpsim.Scene` simulated (its boxes are written once, never per frame),
            or its :class:`warpsim.RoundedBoxes`, or None to write the spheres alone.
        trajectory: the recorded frames; time codes are its integer ``frame`` indices.
        stride: keep every ``stride``-th recorded frame (rows 0, stride, 2 stride, ...), >= 1.
        spheres: indices of the spheres to write (in that order), or None for all. Their indices
            in the swarm are stored as the instancer's ``ids``.
        max_bytes: size above which a :class:`LargeOutputWarning` is emitted before writing
            (estimate from :func:`estimate_usd_bytes`) [bytes].
        warn: False to silence that warning.

    Returns:
        ``path`` as a :class:`pathlib.Path`.

    Raises:
        ValueError: bad extension, bad ``stride`` or ``spheres``, inconsistent trajectory.
        FileNotFoundError: the output folder does not exist.
        OSError: USD failed to write the file.
    """
    path = Path(path)
    fmt = _format_of(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"folder of {str(path)!r} does not exist")
    rows, idx = _selected(trajectory, stride, spheres)
    frames = np.asarray(trajectory.frame, dtype=np.int64)[rows]
    dt = float(trajectory.dt)

    estimate = estimate_usd_bytes(idx.size, rows.size, fmt)
    if warn and estimate > max_bytes:
        warnings.warn(LargeOutputWarning(
            f"{str(path)!r} is estimated at {estimate / 1e6:,.0f} MB ({idx.size} spheres x "
            f"{rows.size} frames), above max_bytes={max_bytes:,}; pass stride=k to keep every "
            f"k-th frame or spheres=[...] to write a subset (or warn=False)"), stacklevel=2)

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
    obstacle = _preview_material(stage, f"{LOOKS}/Obstacle", OBSTACLE_COLOR)
    if scene is not None:
        boxes = scene if isinstance(scene, RoundedBoxes) else scene.boxes
        _author_obstacles(stage, boxes, obstacle)
    _author_spheres(stage, trajectory, rows, idx)
    _author_sphere_prototype(stage, light, dark)

    with atomic_output(path) as tmp:
        _export_layer(stage.GetRootLayer(), tmp)
    return path


# --------------------------------------------------------------------------------------------
# Reading


def open_stage(path) -> Usd.Stage:
    """Open a USD file fresh from disk (never a cached layer of an older file at that path).

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: USD cannot read it.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no USD file at {str(path)!r}")
    layer = Sdf.Layer.OpenAsAnonymous(str(path))
    if layer is None:
        raise ValueError(f"USD could not read {str(path)!r}")
    return Usd.Stage.Open(layer)


def sphere_instancer(stage: Usd.Stage, path="") -> UsdGeom.PointInstancer:
    """The warpsim sphere instancer of ``stage`` (``/World/Spheres``).

    Raises:
        ValueError: the stage has none (not a warpsim file); ``path`` names the file.
    """
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath(SPHERES))
    if not instancer:
        raise ValueError(f"{str(path)!r} has no PointInstancer at {SPHERES}: "
                         f"not written by warpsim")
    return instancer


def recorded_frames(instancer: UsdGeom.PointInstancer) -> np.ndarray:
    """Frame indices (time codes of ``positions``) of a warpsim instancer, (F,) int64."""
    times = np.asarray(instancer.GetPositionsAttr().GetTimeSamples(), dtype=np.float64)
    return np.rint(times).astype(np.int64)


def instancer_state(instancer: UsdGeom.PointInstancer, frame: int
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Positions (N, 3) float32 [m] and orientations (N, 4) float32 (x, y, z, w) at ``frame``."""
    time = Usd.TimeCode(float(frame))
    position = np.asarray(instancer.GetPositionsAttr().Get(time), dtype=np.float32).reshape(-1, 3)
    n = position.shape[0]
    attr = instancer.GetOrientationsfAttr()
    if not attr.HasAuthoredValue():
        attr = instancer.GetOrientationsAttr()  # half precision, from older writers
    value = attr.Get(time) if attr.HasAuthoredValue() else None
    if value is None:
        orientation = np.tile(np.array([0, 0, 0, 1], dtype=np.float32), (n, 1))
    else:  # Vt quaternion arrays are laid out (i, j, k, real) = (x, y, z, w)
        orientation = np.asarray(value, dtype=np.float32).reshape(-1, 4)
    return position, orientation


def sphere_radii(instancer: UsdGeom.PointInstancer) -> np.ndarray:
    """Sphere radii [m], (N,) float64: exact from ``warpsim:radius``, else from ``scales``."""
    attr = instancer.GetPrim().GetAttribute("warpsim:radius")
    if attr and attr.HasAuthoredValue():
        return np.array(attr.Get(), dtype=np.float64)
    scales = instancer.GetScalesAttr().Get()
    return np.array(scales, dtype=np.float64).reshape(-1, 3)[:, 0]


def read_usd(path) -> Trajectory:
    """Read back the trajectory of a file written by :func:`write_usd`.

    Returns exactly what is stored (module docstring): ``frame`` (F,) int64 are the time codes
    of the written frames (after ``stride``), ``position`` (F, N, 3) float32 [m],
    ``orientation`` (F, N, 4) float32 (x, y, z, w) from ``orientationsf`` (half precision from
    ``orientations`` if a file lacks it), ``radius`` (N,) float64 [m] and ``dt`` [s] exact. With a
    ``spheres`` subset, N is the subset in the order written (its swarm indices are the
    instancer's ``ids``).

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: not a USD file, or not one written by warpsim.
    """
    stage = open_stage(path)
    instancer = sphere_instancer(stage, path)
    frames = recorded_frames(instancer)
    if frames.size == 0:
        raise ValueError(f"{str(path)!r} has no time-sampled sphere positions")
    states = [instancer_state(instancer, f) for f in frames]
    radius = sphere_radii(instancer)
    n = radius.size
    world = stage.GetPrimAtPath(WORLD)
    dt_attr = world.GetAttribute("warpsim:dt") if world else None
    dt = float(dt_attr.Get()) if dt_attr else 1.0 / stage.GetTimeCodesPerSecond()
    return Trajectory(frame=frames, dt=dt,
                      position=np.stack([s[0] for s in states]).reshape(frames.size, n, 3),
                      orientation=np.stack([s[1] for s in states]).reshape(frames.size, n, 4),
                      radius=radius)


def read_usd_boxes(path) -> RoundedBoxes | None:
    """The obstacles of a file written by :func:`write_usd`, in the order written.

    Centres, rotations, half extents and radii come from the double-precision transform ops and
    ``warpsim:`` attributes: float64, equal to the written boxes up to the re-normalisation of
    the rotation that :class:`warpsim.RoundedBoxes` applies (a few ulp).

    Returns:
        The boxes, or None when the file has no obstacles.

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: an obstacle prim lacks the warpsim attributes.
    """
    stage = open_stage(path)
    return boxes_of_stage(stage, path)


def boxes_of_stage(stage: Usd.Stage, path="") -> RoundedBoxes | None:
    """The obstacles under ``/World/Obstacles`` of an open stage (see :func:`read_usd_boxes`)."""
    root = stage.GetPrimAtPath(OBSTACLES)
    if not root:
        return None
    center, rotation, half, radius = [], [], [], []
    for prim in root.GetChildren():
        h_attr, r_attr = prim.GetAttribute("warpsim:halfExtents"), prim.GetAttribute(
            "warpsim:radius")
        if not (h_attr and r_attr):
            raise ValueError(f"{str(path)!r}: obstacle {prim.GetPath()} lacks warpsim:halfExtents "
                             f"or warpsim:radius")
        ops = {op.GetOpType(): op.Get() for op in UsdGeom.Xformable(prim).GetOrderedXformOps()}
        t = ops.get(UsdGeom.XformOp.TypeTranslate, Gf.Vec3d(0.0))
        q = ops.get(UsdGeom.XformOp.TypeOrient, Gf.Quatd(1.0))
        center.append(tuple(t))
        rotation.append((*q.GetImaginary(), q.GetReal()))
        half.append(tuple(h_attr.Get()))
        radius.append(float(r_attr.Get()))
    if not center:
        return None
    return RoundedBoxes(center=center, half_extents=half, rotation=rotation, radius=radius)


__all__ = ["LargeOutputWarning", "estimate_usd_bytes", "read_usd", "read_usd_boxes", "write_usd"]

