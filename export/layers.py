"""Sharded USD output: one layer per shard of spheres, and a root stage that composes them.

A sharded run (:mod:`warpsim.distributed`) writes::

    RUN.usdc                       root stage: obstacles, materials, the sphere prototype, and
                                   the shard layers as sublayers (``subLayerPaths``)
    RUN.shards/shard_00000.usdc    one layer per shard: the shard's sphere instancer only
    RUN.shards/shard_00001.usdc    ...

Root stage layout (the conventions of :mod:`warpsim.export.usd_write`: ``Y`` up, 1 unit = 1 m,
default prim ``/World``, integer frame indices as time codes, ``timeCodesPerSecond`` =
``framesPerSecond`` = ``1 / dt``)::

    /World                           Xform; warpsim:dt (double, [s]), warpsim:scene (string)
      /Looks                         materials, as write_usd authors them
      /ObstacleShapes, /Obstacles    the obstacles, authored once (write_usd's layout)
      /SphereShapes/CheckerBall      class prim (never drawn): the sphere prototype mesh
      /Spheres                       Scope holding one PointInstancer per shard
        /Shard_00000                 from shard layer 0 (sublayer)
          /Prototypes/CheckerBall    internal reference to /World/SphereShapes/CheckerBall
        /Shard_00001 ...

The root is made from a file written by :func:`warpsim.export.write_usd` for the scene with no
spheres (so obstacles, materials and prototype are exactly what ``write_usd`` writes), with the
prototype moved into a class prim and ``/World/Spheres`` turned into a Scope.

Each shard instancer stores what ``write_usd``'s instancer stores, at the same precision:
``positions`` (point3f[], float32), ``orientationsf`` (quatf[], float32, (x, y, z, w)),
``orientations`` (quath[], from :func:`warpsim.export.half_orientations`), optional
``velocities`` [m/s] and ``angularVelocities`` [deg/s] (vector3f[]), all time-sampled;
``scales`` (float3[], the radius), ``warpsim:radius`` (double[], exact), ``ids`` (int64[]: the
indices of the shard's spheres in the whole swarm) and ``protoIndices`` (all 0), authored once.

Every shard layer carries a manifest in its ``customLayerData`` under ``warpsim:shard``: the
``key`` (a hash of everything that determines the shard's bits: scene, seed, sphere range,
frames, settings), the ``digest`` (SHA-256 of the arrays written) and the shard's range. A layer
is written under a temporary name and renamed, so a file under a shard's final name is always
complete; a layer is reused only when its manifest's key matches the run's (else it is stale).
The root lists every shard's key and digest under ``warpsim:shards``.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np
from pxr import Sdf, Tf, Vt

from ..trajectory import Trajectory
from .compose import in_set_units, set_asset_path
from .files import atomic_output
from .usd_read import (  # the readers live with read_usd, which reads sharded roots too
    SHARD_PREFIX,
    read_sharded_ids,
    read_sharded_usd,
)
from .usd_write import (
    DEGREES_PER_RADIAN,
    PROTOTYPE,
    SPHERES,
    WORLD,
    born_stand_ins,
    export_layer,
    half_orientations,
    hidden_ids,
    write_usd,
)

SPHERE_SHAPES = f"{WORLD}/SphereShapes"
SPHERE_SHAPE = f"{SPHERE_SHAPES}/CheckerBall"
SHARD_WIDTH = 5  # digits of shard numbers in prim and file names (more when needed)
MANIFEST = "warpsim:shard"
ROOT_MANIFEST = "warpsim:shards"
LAYOUT = "warpsim-sharded/1"  # the version of this layout, stored in every manifest


def shard_name(index: int, count: int) -> str:
    """``shard_00003``: the file stem of shard ``index`` of ``count`` (zero padded)."""
    width = max(SHARD_WIDTH, len(str(max(count - 1, 0))))
    return f"shard_{index:0{width}d}"


def shard_prim_path(index: int, count: int) -> str:
    """``/World/Spheres/Shard_00003``: the instancer of shard ``index`` of ``count``."""
    return f"{SPHERES}/{SHARD_PREFIX}{shard_name(index, count)[len('shard_'):]}"


def shard_folder(root) -> Path:
    """The folder of a root stage's shard layers: ``RUN.usdc`` -> ``RUN.shards``."""
    root = Path(root)
    return root.with_name(f"{root.stem}.shards")


def array_digest(frames: np.ndarray, ids: np.ndarray, *arrays) -> str:
    """SHA-256 (hex) of the recorded frames, sphere ids and arrays as written (little endian)."""
    h = hashlib.sha256()
    for a in (np.asarray(frames, dtype="<i8"), np.asarray(ids, dtype="<i8"), *arrays):
        if a is None:
            h.update(b"-")
            continue
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.astype(a.dtype.newbyteorder("<"), copy=False).tobytes())
    return h.hexdigest()


def _stored(trajectory: Trajectory, velocities: bool):
    """The arrays as stored: float32 positions and orientations (and velocities [m/s], angular
    velocities [deg/s] from the float64 product)."""
    position = np.ascontiguousarray(trajectory.position, dtype=np.float32)
    orientation = np.ascontiguousarray(trajectory.orientation, dtype=np.float32)
    velocity = angular = None
    if velocities:
        velocity = np.ascontiguousarray(trajectory.velocity, dtype=np.float32)
        angular = (np.asarray(trajectory.angular_velocity, dtype=np.float64)
                   * DEGREES_PER_RADIAN).astype(np.float32)
    return position, orientation, velocity, angular


def _attribute(prim: Sdf.PrimSpec, name: str, type_name, value=None, *, custom: bool = False,
               uniform: bool = False) -> Sdf.AttributeSpec:
    variability = Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying
    attr = Sdf.AttributeSpec(prim, name, type_name, variability, custom)
    if value is not None:
        attr.default = value
    return attr


def _set_timing(layer: Sdf.Layer, frames: np.ndarray, dt: float) -> None:
    """Time metadata equal to the root's, so that no layer offset rescales a shard's samples."""
    layer.timeCodesPerSecond = 1.0 / dt
    layer.framesPerSecond = 1.0 / dt
    layer.startTimeCode = float(frames[0])
    layer.endTimeCode = float(frames[-1])


def write_shard_layer(path, trajectory: Trajectory, ids, index: int, count: int,
                      manifest: dict, *, velocities: bool = False) -> str:
    """Write one shard's instancer as a USD layer, atomically (temporary name, then rename).

    Args:
        path: the layer file (``.usdc`` or ``.usda``); its folder must exist.
        trajectory: the shard's recorded frames (time codes are its integer ``frame``).
        ids: indices of the shard's spheres in the whole swarm, (N,) int.
        index: the shard's number; count: the number of shards (for the prim name).
        manifest: string/int/float entries stored under ``warpsim:shard`` (``key`` at least);
            the ``digest`` of the arrays is added.
        velocities: also store ``velocities`` and ``angularVelocities`` (the trajectory must
            have them).

    Returns:
        The digest (SHA-256 hex) of the arrays written.

    Raises:
        ValueError: inconsistent shapes. OSError: the file cannot be written.
    """
    path = Path(path)
    frames = np.asarray(trajectory.frame, dtype=np.int64)
    ids = np.asarray(ids, dtype=np.int64)
    n = ids.size
    if trajectory.position.shape != (frames.size, n, 3):
        raise ValueError(f"trajectory.position must have shape ({frames.size}, {n}, 3), got "
                         f"{trajectory.position.shape}")
    if velocities and (trajectory.velocity is None or trajectory.angular_velocity is None):
        raise ValueError("velocities=True but the trajectory has no velocity")
    births = trajectory.birth_frame
    trajectory = born_stand_ins(trajectory)
    position, orientation, velocity, angular = _stored(trajectory, velocities)
    radius = np.asarray(trajectory.radius, dtype=np.float64)
    digest = array_digest(frames, ids, position, orientation, velocity, angular)

    T = Sdf.ValueTypeNames
    layer = Sdf.Layer.CreateAnonymous(path.suffix.lower())
    _set_timing(layer, frames, float(trajectory.dt))
    layer.customLayerData = {MANIFEST: {**manifest, "digest": digest, "layout": LAYOUT,
                                        "index": int(index), "count": int(count),
                                        "spheres": int(n)}}
    prim_path = Sdf.Path(shard_prim_path(index, count))
    with Sdf.ChangeBlock():
        world = Sdf.PrimSpec(layer, WORLD[1:], Sdf.SpecifierOver)
        spheres = Sdf.PrimSpec(world, SPHERES.rsplit("/", 1)[1], Sdf.SpecifierOver)
        inst = Sdf.PrimSpec(spheres, prim_path.name, Sdf.SpecifierDef, "PointInstancer")
        protos = Sdf.PrimSpec(inst, "Prototypes", Sdf.SpecifierDef, "Xform")
        ball = Sdf.PrimSpec(protos, SPHERE_SHAPE.rsplit("/", 1)[1], Sdf.SpecifierDef)
        ball.referenceList.Prepend(Sdf.Reference(primPath=SPHERE_SHAPE))
        Sdf.RelationshipSpec(inst, "prototypes", False).targetPathList.Append(ball.path)
        _attribute(inst, "protoIndices", T.IntArray,
                   Vt.IntArray.FromNumpy(np.zeros(n, dtype=np.int32)))
        _attribute(inst, "ids", T.Int64Array, Vt.Int64Array.FromNumpy(ids))
        scales = np.repeat(radius.astype(np.float32)[:, None], 3, axis=1)
        _attribute(inst, "scales", T.Float3Array, Vt.Vec3fArray.FromNumpy(scales))
        _attribute(inst, "warpsim:radius", T.DoubleArray, Vt.DoubleArray.FromNumpy(radius),
                   custom=True)
        attrs = {"positions": _attribute(inst, "positions", T.Point3fArray),
                 "orientationsf": _attribute(inst, "orientationsf", T.QuatfArray),
                 "orientations": _attribute(inst, "orientations", T.QuathArray)}
        if births is not None:
            births = np.asarray(births, dtype=np.int64)
            _attribute(inst, "warpsim:birthFrame", T.Int64Array,
                       Vt.Int64Array.FromNumpy(births), custom=True)
            attrs["invisibleIds"] = _attribute(inst, "invisibleIds", T.Int64Array)
        if velocities:
            attrs["velocities"] = _attribute(inst, "velocities", T.Vector3fArray)
            attrs["angularVelocities"] = _attribute(inst, "angularVelocities", T.Vector3fArray)
        paths = {name: attr.path for name, attr in attrs.items()}
        previous = previous_q = None
        hidden_before = None
        for row, frame in enumerate(frames.tolist()):
            time = float(frame)
            if births is not None:
                hidden = hidden_ids(ids, births, frame)
                if hidden_before is None or hidden != hidden_before:
                    layer.SetTimeSample(paths["invisibleIds"], time, hidden)
                hidden_before = hidden
            layer.SetTimeSample(paths["positions"], time, Vt.Vec3fArray.FromNumpy(position[row]))
            # Vt quaternion arrays lay out each element as (i, j, k, real) = (x, y, z, w)
            layer.SetTimeSample(paths["orientationsf"], time,
                                Vt.QuatfArray.FromNumpy(orientation[row]))
            q = trajectory.orientation[row]
            previous, previous_q = half_orientations(q, previous, previous_q), q
            layer.SetTimeSample(paths["orientations"], time, Vt.QuathArray.FromNumpy(previous))
            if velocities:
                layer.SetTimeSample(paths["velocities"], time,
                                    Vt.Vec3fArray.FromNumpy(velocity[row]))
                layer.SetTimeSample(paths["angularVelocities"], time,
                                    Vt.Vec3fArray.FromNumpy(angular[row]))
    with atomic_output(path) as tmp:
        export_layer(layer, tmp)
    return digest


def shard_manifest(path) -> dict | None:
    """The ``warpsim:shard`` manifest of a complete shard layer, or None when there is no
    readable warpsim shard layer at ``path`` (missing, truncated, not USD, no manifest)."""
    path = Path(path)
    if not path.is_file():
        return None
    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(path))
    except Tf.ErrorException:
        return None
    if layer is None:
        return None
    manifest = dict(layer.customLayerData).get(MANIFEST)
    if not isinstance(manifest, dict) or manifest.get("layout") != LAYOUT:
        return None
    return dict(manifest)


def write_root_stage(path, scene, frames, dt: float, layers, manifest: dict) -> Path:
    """Write the root stage that composes the shard layers with the scene's obstacles.

    Args:
        path: the root file (``.usdc`` or ``.usda``); its folder must exist.
        scene: the :class:`warpsim.Scene` (its obstacles are authored once, here).
        frames: the recorded frame indices (time codes), (F,) int.
        dt: time step [s].
        layers: the shard layer files in shard order (stored relative to the root's folder).
        manifest: entries stored under ``warpsim:shards`` in the root's ``customLayerData``
            (lists of strings or numbers, strings, numbers).

    Returns:
        ``path`` as a :class:`pathlib.Path`.
    """
    path = Path(path)
    frames = np.asarray(frames, dtype=np.int64)
    empty = Trajectory(frame=frames, dt=float(dt),
                       position=np.zeros((frames.size, 0, 3), dtype=np.float32),
                       orientation=np.zeros((frames.size, 0, 4), dtype=np.float32),
                       radius=np.zeros(0))
    with tempfile.TemporaryDirectory(prefix="warpsim-root-") as folder:
        base = write_usd(Path(folder) / f"base{path.suffix.lower()}", scene, empty, warn=False)
        layer = Sdf.Layer.OpenAsAnonymous(str(base))
    world = layer.GetPrimAtPath(WORLD)
    with Sdf.ChangeBlock():
        Sdf.PrimSpec(world, SPHERE_SHAPES.rsplit("/", 1)[1], Sdf.SpecifierClass)
    if not Sdf.CopySpec(layer, PROTOTYPE, layer, SPHERE_SHAPE):
        raise OSError(f"USD could not copy the sphere prototype for {str(path)!r}")
    over = getattr(getattr(scene, "boxes", None), "stage", None)  # boxes from a USD set
    with Sdf.ChangeBlock():
        del world.nameChildren[SPHERES.rsplit("/", 1)[1]]
        # over a set, an Xform that scales the shards' metres to the set's units
        spheres = Sdf.PrimSpec(world, SPHERES.rsplit("/", 1)[1], Sdf.SpecifierDef,
                               "Scope" if over is None else "Xform")
        if over is not None:
            in_set_units(spheres, over)
    folder = path.parent.resolve()
    layer.subLayerPaths = [Path(os.path.relpath(Path(p).resolve(), folder)).as_posix()
                           for p in layers] + ([] if over is None
                                               else [set_asset_path(over.path, path)])
    layer.customLayerData = {ROOT_MANIFEST: _dictionary({**manifest, "layout": LAYOUT})}
    layer.documentation = (
        f"warpsim animation of scene {getattr(scene, 'name', '')!r}: {frames.size} frames, "
        f"dt = {float(dt)!r} s, spheres in {len(layers)} shard layers composed as sublayers "
        f"(warpsim.distributed).")
    with atomic_output(path) as tmp:
        export_layer(layer, tmp)
    return path


def _dictionary(values: dict) -> dict:
    """``values`` as USD dictionary entries: lists become typed Vt arrays (strings, int64 or
    double), which the text format can write back."""
    out = {}
    for name, value in values.items():
        if isinstance(value, (list, tuple)):
            if all(isinstance(v, str) for v in value):
                value = Vt.StringArray(list(value))
            elif all(isinstance(v, (int, np.integer)) for v in value):
                value = Vt.Int64Array([int(v) for v in value])
            else:
                value = Vt.DoubleArray([float(v) for v in value])
        out[name] = value
    return out


def root_manifest(path) -> dict | None:
    """The ``warpsim:shards`` manifest of a root stage, or None when it has none."""
    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(path))
    except Tf.ErrorException:
        return None
    value = None if layer is None else dict(layer.customLayerData).get(ROOT_MANIFEST)
    if not isinstance(value, dict):
        return None
    return {k: list(v) if isinstance(v, (Vt.StringArray, Vt.Int64Array, Vt.DoubleArray))
            else v for k, v in value.items()}


__all__ = ["read_sharded_ids", "read_sharded_usd", "root_manifest", "shard_folder",
           "shard_manifest", "shard_name", "write_root_stage", "write_shard_layer"]
