"""Reading back what :mod:`warpsim.export.usd_write` wrote: the trajectory (bit for bit as stored,
see the layout and precision there), one frame, the obstacles in float64.

Every reader opens the file fresh from disk (never a cached layer of an older file at that path)
and refuses, in one line naming the file, what is not a warpsim file.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Tf, Usd, UsdGeom

from ..obstacles import RoundedBoxes
from ..trajectory import Trajectory
from .origins import ORIGIN_OP
from .usd_write import DEGREES_PER_RADIAN, OBSTACLES, SPHERES, WORLD, pxr_message

SHARD_PREFIX = "Shard_"
"""Name prefix of the shard instancers under ``/World/Spheres`` of a sharded run's root."""


def _open_layer(path) -> Sdf.Layer:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no USD file at {str(path)!r}")
    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(path))
    except Tf.ErrorException as exc:
        raise ValueError(f"USD could not read {str(path)!r}: {pxr_message(exc)}") from None
    if layer is None:
        raise ValueError(f"USD could not read {str(path)!r}")
    return layer


def _stage_of(layer: Sdf.Layer, path, spheres_only: bool = False) -> Usd.Stage:
    try:
        if layer.subLayerPaths:  # a result composed over a set: its relative sublayer paths
            # resolve against the file, not against an anonymous copy of it
            cached = Sdf.Layer.Find(str(path))
            if cached is not None:
                cached.Reload()
            layer = Sdf.Layer.FindOrOpen(str(path))
        if spheres_only:
            return Usd.Stage.OpenMasked(layer, Usd.StagePopulationMask([SPHERES]))
        return Usd.Stage.Open(layer)
    except Tf.ErrorException as exc:
        raise ValueError(f"USD could not read {str(path)!r}: {pxr_message(exc)}") from None


def open_stage(path, *, spheres_only: bool = False) -> Usd.Stage:
    """Open a USD file fresh from disk (never a cached layer of an older file at that path).

    Args:
        path: the file.
        spheres_only: compose only ``/World/Spheres`` (fast to open whatever the number of
            obstacles).

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: USD cannot read it (corrupt or not USD); one line naming the file.
    """
    return _stage_of(_open_layer(path), path, spheres_only)


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


def _vec3_at(attr: Usd.Attribute, time: Usd.TimeCode, n: int) -> np.ndarray | None:
    if not attr or not attr.HasAuthoredValue():
        return None
    value = attr.Get(time)
    return None if value is None else np.asarray(value, dtype=np.float32).reshape(n, 3)


def instancer_state(instancer: UsdGeom.PointInstancer, frame: int) -> dict[str, np.ndarray]:
    """What is stored at ``frame``: ``position`` (N, 3) float32 [m] (float64 when the file
    stores offsets from a per-frame origin, :mod:`warpsim.export.origins`), ``orientation`` (N, 4)
    float32 (x, y, z, w), and when authored ``velocity`` (N, 3) float32 [m/s] and
    ``angular_velocity`` (N, 3) float64 [rad/s]."""
    time = Usd.TimeCode(float(frame))
    position = np.asarray(instancer.GetPositionsAttr().Get(time), dtype=np.float32).reshape(-1, 3)
    origin = instancer.GetPrim().GetAttribute(ORIGIN_OP)
    if origin and origin.HasAuthoredValue():  # float32 offsets from a float64 origin: exact sum
        position = np.asarray(origin.Get(time), dtype=np.float64) + position.astype(np.float64)
    n = position.shape[0]
    attr = instancer.GetOrientationsfAttr()
    if not attr.HasAuthoredValue():
        attr = instancer.GetOrientationsAttr()  # half precision, from older writers
    value = attr.Get(time) if attr.HasAuthoredValue() else None
    if value is None:
        orientation = np.tile(np.array([0, 0, 0, 1], dtype=np.float32), (n, 1))
    else:  # Vt quaternion arrays are laid out (i, j, k, real) = (x, y, z, w)
        orientation = np.asarray(value, dtype=np.float32).reshape(-1, 4)
    state = {"position": position, "orientation": orientation}
    velocity = _vec3_at(instancer.GetVelocitiesAttr(), time, n)
    if velocity is not None:
        state["velocity"] = velocity
    degrees = _vec3_at(instancer.GetAngularVelocitiesAttr(), time, n)
    if degrees is not None:
        state["angular_velocity"] = degrees.astype(np.float64) / DEGREES_PER_RADIAN
    return state


def sphere_radii(instancer: UsdGeom.PointInstancer) -> np.ndarray:
    """Sphere radii [m], (N,) float64: exact from ``warpsim:radius``, else from ``scales``."""
    attr = instancer.GetPrim().GetAttribute("warpsim:radius")
    if attr and attr.HasAuthoredValue():
        return np.array(attr.Get(), dtype=np.float64)
    scales = instancer.GetScalesAttr().Get()
    return np.array(scales, dtype=np.float64).reshape(-1, 3)[:, 0]


def birth_frames(instancer: UsdGeom.PointInstancer) -> np.ndarray | None:
    """Each sphere's birth frame, (N,) int64, from ``warpsim:birthFrame``; None when the file
    has none (every sphere there from its first frame)."""
    attr = instancer.GetPrim().GetAttribute("warpsim:birthFrame")
    if not (attr and attr.HasAuthoredValue()):
        return None
    return np.array(attr.Get(), dtype=np.int64)


def unborn_as_nan(trajectory: Trajectory) -> Trajectory:
    """``trajectory`` with every value of a sphere before its birth set to NaN (in place)."""
    if trajectory.birth_frame is None:
        return trajectory
    unborn = ~trajectory.alive()
    for name in ("position", "orientation", "velocity", "angular_velocity"):
        values = getattr(trajectory, name)
        if values is not None:
            values[unborn] = np.nan
    return trajectory


def _stage_dt(stage: Usd.Stage) -> float:
    world = stage.GetPrimAtPath(WORLD)
    dt_attr = world.GetAttribute("warpsim:dt") if world else None
    return float(dt_attr.Get()) if dt_attr else 1.0 / stage.GetTimeCodesPerSecond()


def _trajectory(stage: Usd.Stage, instancer, frames: np.ndarray) -> Trajectory:
    states = [instancer_state(instancer, f) for f in frames]
    radius = sphere_radii(instancer)
    n, f = radius.size, frames.size

    def stacked(key, width):
        if any(key not in s for s in states):
            return None
        return np.stack([s[key] for s in states]).reshape(f, n, width)

    return unborn_as_nan(Trajectory(
        frame=frames, dt=_stage_dt(stage), position=stacked("position", 3),
        orientation=stacked("orientation", 4), radius=radius, velocity=stacked("velocity", 3),
        angular_velocity=stacked("angular_velocity", 3), birth_frame=birth_frames(instancer)))


def shard_instancers(stage: Usd.Stage) -> list[UsdGeom.PointInstancer]:
    """The shard instancers under ``/World/Spheres`` of a composed root stage, in shard order."""
    root = stage.GetPrimAtPath(SPHERES)
    if not root:
        return []
    prims = sorted((p for p in root.GetChildren()
                    if p.GetName().startswith(SHARD_PREFIX) and p.IsA(UsdGeom.PointInstancer)),
                   key=lambda p: p.GetName())
    return [UsdGeom.PointInstancer(p) for p in prims]


def read_sharded_usd(path) -> Trajectory:
    """Read a root stage and all its shards back as one trajectory, spheres in swarm order.

    The stage is opened and composed (``Usd.Stage.Open``); every shard instancer is read as
    :func:`warpsim.export.read_usd` reads ``write_usd``'s one instancer (same dtypes and exact
    values), and the shards' spheres are put in the order of their ``ids``.

    Returns:
        A :class:`warpsim.Trajectory`: ``frame`` (F,), ``position`` (F, N, 3) float32 [m],
        ``orientation`` (F, N, 4) float32, ``radius`` (N,) float64 [m], ``velocity`` and
        ``angular_velocity`` when stored; N is the spheres of all shards.

    Raises:
        FileNotFoundError: no file at ``path``. ValueError: no shard instancer, the shards do
        not share their recorded frames, or two shards hold the same sphere.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no USD file at {str(path)!r}")
    try:
        stage = Usd.Stage.Open(str(path), load=Usd.Stage.LoadAll)
    except Tf.ErrorException as exc:
        raise ValueError(f"USD could not read {str(path)!r}: {pxr_message(exc)}") from None
    instancers = shard_instancers(stage)
    if not instancers:
        raise ValueError(f"{str(path)!r} has no shard instancers under {SPHERES}")
    frames = recorded_frames(instancers[0])
    parts = {key: [] for key in ("position", "orientation", "velocity", "angular_velocity")}
    ids, radii, births = [], [], []
    for inst in instancers:
        if not np.array_equal(recorded_frames(inst), frames):
            raise ValueError(f"{str(path)!r}: {inst.GetPath()} has other recorded frames than "
                             f"{instancers[0].GetPath()}")
        states = [instancer_state(inst, int(f)) for f in frames]
        for key, values in parts.items():
            values.append(np.stack([s[key] for s in states]) if key in states[0] else None)
        ids.append(np.asarray(inst.GetIdsAttr().Get(), dtype=np.int64))
        radii.append(sphere_radii(inst))
        births.append(birth_frames(inst))
    all_ids = np.concatenate(ids)
    order = np.argsort(all_ids, kind="stable")
    if np.unique(all_ids).size != all_ids.size:
        raise ValueError(f"{str(path)!r}: two shards hold the same sphere id")

    def joined(key):
        values = parts[key]
        if any(v is None for v in values):
            return None
        return np.concatenate(values, axis=1)[:, order]

    world = stage.GetPrimAtPath(WORLD)
    dt_attr = world.GetAttribute("warpsim:dt") if world else None
    dt = float(dt_attr.Get()) if dt_attr else 1.0 / stage.GetTimeCodesPerSecond()
    born = None
    if any(b is not None for b in births):
        born = np.concatenate([np.zeros(r.size, dtype=np.int64) if b is None else b
                               for b, r in zip(births, radii, strict=True)])[order]
    return unborn_as_nan(Trajectory(frame=frames, dt=dt, position=joined("position"),
                                    orientation=joined("orientation"),
                                    radius=np.concatenate(radii)[order],
                                    velocity=joined("velocity"),
                                    angular_velocity=joined("angular_velocity"),
                                    birth_frame=born))


def read_sharded_ids(path) -> np.ndarray:
    """The swarm indices of the spheres of a root stage, in the order :func:`read_sharded_usd`
    returns them (sorted)."""
    stage = Usd.Stage.Open(str(path))
    ids = [np.asarray(i.GetIdsAttr().Get(), dtype=np.int64) for i in shard_instancers(stage)]
    return np.sort(np.concatenate(ids)) if ids else np.zeros(0, dtype=np.int64)



def read_usd(path) -> Trajectory:
    """Read back the trajectory of a file written by :func:`write_usd`.

    Returns exactly what is stored (module docstring): ``frame`` (F,) int64 are the time codes
    of the written frames (after ``stride``), ``position`` (F, N, 3) float32 [m],
    ``orientation`` (F, N, 4) float32 (x, y, z, w) from ``orientationsf`` (half precision from
    ``orientations`` if a file lacks it), ``radius`` (N,) float64 [m] and ``dt`` [s] exact;
    ``velocity`` (F, N, 3) float32 [m/s] and ``angular_velocity`` (F, N, 3) float64 [rad/s]
    when the file has them, else None. With a ``spheres`` subset, N is the subset in the order
    written (its swarm indices are the instancer's ``ids``).

    The root stage of a sharded run (``warpsim run --shards``/``--dask``) is read whole, its
    spheres in swarm order (:func:`read_sharded_usd`).

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: not a USD file, or not one written by warpsim.
    """
    stage = open_stage(path, spheres_only=True)
    if _is_sharded_root(stage):
        return read_sharded_usd(path)
    instancer = sphere_instancer(stage, path)
    frames = recorded_frames(instancer)
    if frames.size == 0:
        raise ValueError(f"{str(path)!r} has no time-sampled sphere positions")
    return _trajectory(stage, instancer, frames)


def _is_sharded_root(stage: Usd.Stage) -> bool:
    """Whether ``/World/Spheres`` is a sharded run's Scope of shard instancers."""
    prim = stage.GetPrimAtPath(SPHERES)
    return bool(prim) and not prim.IsA(UsdGeom.PointInstancer) and bool(shard_instancers(stage))


def frame_label(frames: np.ndarray) -> str:
    """``"recorded frames are 0..300 (301 frames)"``, with ``every K`` when regular."""
    steps = np.unique(np.diff(frames))
    regular = f", every {steps[0]}" if steps.size == 1 and steps[0] > 1 else ""
    return f"recorded frames are {frames[0]}..{frames[-1]} ({frames.size} frames{regular})"


def resolve_frame(frames: np.ndarray, frame, path="") -> int:
    """The recorded frame meant by ``frame``: a recorded frame index (time code), or a negative
    number counting recorded frames from the end (-1 is the last, as in Python).

    Raises:
        ValueError: not an integer, or no such recorded frame (the message gives the range).
    """
    if frames.size == 0:
        raise ValueError(f"frame {frame!r}: {str(path)!r} has no recorded frames")
    available = frame_label(frames)
    if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)):
        raise ValueError(f"frame must be an integer frame index, got {frame!r}; {available}")
    frame = int(frame)
    if frame < 0:
        if -frame > frames.size:
            raise ValueError(f"frame {frame}: {str(path)!r} has only {frames.size} recorded "
                             f"frames; {available}")
        return int(frames[frame])
    if frame not in set(frames.tolist()):
        raise ValueError(f"frame {frame!r} is not a recorded frame of {str(path)!r}: "
                         f"{available}")
    return frame


def read_usd_frame(path, frame: int) -> Trajectory:
    """One recorded frame of a file written by :func:`write_usd`, as a one-record trajectory.

    Args:
        path: the file.
        frame: a recorded frame index (time code), e.g. ``trajectory.frame[k]``, or a negative
            number counting recorded frames from the end (-1: the last).

    Returns:
        A :class:`warpsim.Trajectory` with ``frame`` of shape (1,) and arrays of shape (1, N, .),
        as :func:`read_usd` returns them.

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: no such recorded frame (the message gives the available range), or not a
            warpsim file.
    """
    stage = open_stage(path, spheres_only=True)
    if _is_sharded_root(stage):  # every shard's frames, then the one asked for
        whole = read_sharded_usd(path)
        k = int(np.searchsorted(whole.frame, resolve_frame(whole.frame, frame, path)))

        def one(values):
            return None if values is None else values[k:k + 1]

        return replace(whole, frame=whole.frame[k:k + 1], position=one(whole.position),
                       orientation=one(whole.orientation), velocity=one(whole.velocity),
                       angular_velocity=one(whole.angular_velocity))
    instancer = sphere_instancer(stage, path)
    chosen = resolve_frame(recorded_frames(instancer), frame, path)
    return _trajectory(stage, instancer, np.array([chosen], dtype=np.int64))


def read_usd_boxes(path) -> RoundedBoxes | None:
    """The obstacles of a file written by :func:`write_usd`, in the order written.

    Centres, rotations, half extents and radii come from the double-precision transform ops and
    ``warpsim:`` attributes: float64, equal to the written boxes up to the re-normalisation of
    the rotation that :class:`warpsim.RoundedBoxes` applies (a few ulp).

    A result composed over a USD set (:mod:`warpsim.export.compose`) has no obstacles of its
    own: its boxes are the set's, read as :func:`warpsim.obstacles_from_usd` reads them (in
    metres, in the axes the run used, the trajectory's frame).

    Returns:
        The boxes, or None when the file has no obstacles.

    Raises:
        FileNotFoundError: no file at ``path``.
        ValueError: not a USD file, or an obstacle prim lacks the warpsim attributes.
    """
    layer = _open_layer(path)
    plain = _boxes_of_layer(layer, path)
    if plain is not _COMPOSE:
        return plain
    boxes = boxes_of_stage(_stage_of(layer, path), path)
    if boxes is None and layer.subLayerPaths:  # a result composed over a set: the set's boxes,
        from .stage_in import obstacles_from_usd  # in metres in the axes the run used

        boxes = obstacles_from_usd(path)
        return boxes if len(boxes) else None
    return boxes


_COMPOSE = object()  # the layer holds more than warpsim writes: read through composition
_LAYOUT_FIELDS = frozenset({"specifier", "typeName", "references"})  # a box prim's metadata
_BOX_PROPERTIES = frozenset({"xformOp:translate", "xformOp:orient", "xformOpOrder"})


def _boxes_of_layer(layer: Sdf.Layer, path) -> RoundedBoxes | None | object:
    """The boxes read straight from the layer's specs, as :func:`write_usd` lays them out (a
    box prim with its transform, an internal reference to its shape carrying the warpsim
    attributes): the same values composition gives, without composing 1e5 prims. Returns
    ``_COMPOSE`` for anything else (sublayers, overrides, other arcs, edited files)."""
    if layer.subLayerPaths:
        return _COMPOSE
    root = layer.GetPrimAtPath(OBSTACLES)
    if root is None:
        return None
    children = list(root.nameChildren)
    if not children:
        return None
    shapes: dict[str, tuple] = {}
    center, rotation, half, radius = [], [], [], []
    for prim in children:
        refs = prim.referenceList.prependedItems
        if (len(refs) != 1 or refs[0].assetPath or not _LAYOUT_FIELDS.issuperset(
                prim.ListInfoKeys()) or not _BOX_PROPERTIES.issuperset(prim.properties.keys())):
            return _COMPOSE  # other arcs or metadata, or properties of its own (overrides)
        target = str(refs[0].primPath)
        if target not in shapes:
            shape = layer.GetPrimAtPath(target)
            attrs = shape.attributes if shape is not None else {}
            if "warpsim:halfExtents" not in attrs or "warpsim:radius" not in attrs:
                return _COMPOSE
            h, r = attrs["warpsim:halfExtents"].default, attrs["warpsim:radius"].default
            if h is None or r is None:
                return _COMPOSE
            shapes[target] = (tuple(h), float(r))
        attrs = prim.attributes
        t, q = attrs["xformOp:translate"].default, attrs["xformOp:orient"].default
        if t is None or q is None:
            return _COMPOSE
        center.append(tuple(t))
        rotation.append((*q.GetImaginary(), q.GetReal()))
        h, r = shapes[target]
        half.append(h)
        radius.append(r)
    return RoundedBoxes(center=np.array(center, dtype=np.float64),
                        half_extents=np.array(half, dtype=np.float64),
                        rotation=np.array(rotation, dtype=np.float64),
                        radius=np.array(radius, dtype=np.float64))


def boxes_of_stage(stage: Usd.Stage, path="") -> RoundedBoxes | None:
    """The obstacles under ``/World/Obstacles`` of an open stage (see :func:`read_usd_boxes`)."""
    root = stage.GetPrimAtPath(OBSTACLES)
    if not root:
        return None
    center, rotation, half, radius = [], [], [], []
    for prim in root.GetChildren():
        h_attr = prim.GetAttribute("warpsim:halfExtents")
        r_attr = prim.GetAttribute("warpsim:radius")
        if not (h_attr and r_attr):
            raise ValueError(f"{str(path)!r}: obstacle {prim.GetPath()} lacks warpsim:halfExtents "
                             f"or warpsim:radius")
        t = prim.GetAttribute("xformOp:translate").Get()
        q = prim.GetAttribute("xformOp:orient").Get()
        t = Gf.Vec3d(0.0) if t is None else t
        q = Gf.Quatd(1.0) if q is None else q
        center.append(tuple(t))
        rotation.append((*q.GetImaginary(), q.GetReal()))
        half.append(tuple(h_attr.Get()))
        radius.append(float(r_attr.Get()))
    if not center:
        return None
    return RoundedBoxes(center=np.array(center, dtype=np.float64),
                        half_extents=np.array(half, dtype=np.float64),
                        rotation=np.array(rotation, dtype=np.float64),
                        radius=np.array(radius, dtype=np.float64))


__all__ = ["boxes_of_stage", "open_stage", "read_usd", "read_usd_boxes", "read_usd_frame",
           "recorded_frames", "sphere_instancer"]
