"""The device side of a simulation: one model, one state, one way to launch a kernel.

Three bundles of Warp arrays, each made at one validating boundary:

- :class:`Model` (:func:`put_model`): the static scene as the kernels' three ``# Model`` structs
  (``kernels.data.model_structs``): the obstacles ``boxes``, the broad phase's ``broad`` and the
  constants ``physics``. Its field names *are* the kernels' parameter names.
- :class:`Spheres` (:func:`put_spheres`): the per-sphere constants (``radius``, ``mass``,
  ``birth_frame``).
- :class:`DeviceState` (:func:`put_state`): the per-sphere state that a frame changes. A kernel
  reads it through parameters named ``<field>_in`` and writes a second one through
  ``<field>_out``; the simulator swaps ``state_0`` and ``state_1`` after each launch.

:func:`kernel_arguments` builds a launch's argument list from these bundles *by parameter name*
(``position_in`` is ``state_in.position``, ``boxes`` is ``model.boxes``, any other ``*_out`` comes
from ``outputs``), so a reordering of a kernel's parameters can never silently swap two arrays,
and every launch of the package goes through :func:`launch`. Inside a struct the fields are
named too (``model.boxes.radius``), so nothing is ever bound by position.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import warp as wp

from .blocks import copy_rows
from .broad_phase import Grid, WalkGrid, tree_split
from .device import bvh_bounds
from .kernels.data import model_structs
from .kernels.precision import Precision
from .obstacles import RoundedBoxes

IN_SUFFIX = "_in"
OUT_SUFFIX = "_out"


@dataclass
class Model:
    """A scene's obstacles and physics constants on one device, in one precision.

    Field names are the kernels' parameter names; each struct's fields are documented with
    their units and shapes in ``kernels.data.model_structs``.

    Attributes:
        boxes: the obstacles (``Boxes``: centres, rotations local -> world, core half extents,
            rounding radii, world bounding-box half sizes, and the box holding all their reject
            bounds; ``K`` boxes, world frame).
        broad: the broad phase's data (``BroadPhase``: the BVH's id, 0 when none was built,
            and the uniform grid of :class:`warpsim.broad_phase.Grid`, a single empty cell when
            the scene runs without one; kernels built without them never read them).
        physics: the constants (``Physics``: gravity, the potential's origin, ``dt``, friction,
            the ``|Rot|`` clamp, the retention, the cap on contacts per sphere per frame).
        precision: the :class:`~warpsim.kernels.precision.Precision` of every array and value.
        device: the Warp device holding the arrays.
        bvh: the :class:`warp.Bvh` behind ``broad.bvh`` (kept here so that it lives as long as
            the model), or None.
    """

    boxes: object
    broad: object
    physics: object
    precision: Precision
    device: object
    bvh: wp.Bvh | None = None


@dataclass
class Spheres:
    """Per-sphere constants on the device (``N`` spheres).

    Attributes:
        radius: sphere radii [m], shape (N,).
        mass: sphere masses [kg], shape (N,).
        birth_frame: the frame each sphere is born at (int32), shape (N,); read only by
            kernels built with births (``kernels.data.Features.births``).
    """

    radius: wp.array
    mass: wp.array
    birth_frame: wp.array | None = None

    def __len__(self) -> int:
        return int(self.radius.shape[0])


@dataclass
class DeviceState:
    """The per-sphere state one frame changes, on the device (``N`` spheres).

    Attributes:
        position: centres [m], world frame, shape (N,) of vec3.
        velocity: velocities at the end of the state's frame [m/s], shape (N,) of vec3 (see
            ``kernels.frame_kernel``).
        energy: total energy [J], shape (N,) (see ``kernels.frame_kernel``).
        angular_momentum: [kg m^2/s], world frame, shape (N,) of vec3.
        orientation: unit quaternions (x, y, z, w), body -> world, shape (N,) of quat.
    """

    position: wp.array
    velocity: wp.array
    energy: wp.array
    angular_momentum: wp.array
    orientation: wp.array

    def empty_like(self, share: tuple[str, ...] = ()) -> DeviceState:
        """A state of the same shapes to write into; the fields in ``share`` are the same arrays
        (state a kernel variant never writes needs no second copy)."""
        return DeviceState(**{f.name: getattr(self, f.name) if f.name in share
                              else wp.empty_like(getattr(self, f.name)) for f in fields(self)})


def to_device(values: np.ndarray, dtype, p: Precision, device) -> wp.array:
    """A Warp array of ``dtype`` from float64 host values ``(N, ...)``, cast to the precision's
    numpy type (``p``'s; ``dtype`` is the Warp type of one row). The cast is written in blocks
    of rows on every core straight into a Warp array on the host: on the CPU device that array
    is the result; for a GPU it is copied over."""
    values = np.asarray(values)
    host = wp.empty(values.shape[0], dtype=dtype, device="cpu")
    copy_rows(host.numpy(), values)
    device = wp.get_device(device)
    return host if device.is_cpu else host.to(device)


def put_model(boxes: RoundedBoxes, p: Precision, device, *, broad_phase: str, dt: float,
              grid: Grid | WalkGrid | None = None, gravity=(0.0, 0.0, 0.0), origin=(0.0, 0.0, 0.0),
              friction: float = 0.0, max_angular_speed: float = 50.0,
              energy_retention: float = 1.0, max_bounces: int = 8) -> Model:
    """The obstacles and physics constants as a :class:`Model` on ``device``.

    The values must already be validated (``warpsim.validation``; :class:`warpsim.Scene` and
    :class:`warpsim.RoundedBoxes` are); here they are only converted, once.

    Args:
        boxes: the obstacles (float64, world frame).
        p: precision of the arrays and scalars.
        device: Warp device.
        broad_phase: the kernels' broad phase (``kernels.data.BROAD_PHASES``): ``"bvh"`` and
            ``"grid-bvh"`` build a BVH over the boxes (``box_bvh``; none without boxes).
        grid: the grid of ``"grid"`` and ``"grid-bvh"`` (a ``Grid``), or of ``"walk"`` and
            ``"walk-bvh"`` (a ``WalkGrid``) (:func:`warpsim.broad_phase.choose`).
        dt: frame duration [s]. gravity: [m/s^2]. origin: potential reference point [m].
        friction: ``k_f`` [kg/s]. max_angular_speed: ``|Rot|`` clamp [rad/s].
        energy_retention: kept fraction of kinetic energy per contact.
        max_bounces: cap on contacts per sphere per frame.
    """
    dtype = p.np_dtype
    structs = model_structs(p)
    center = boxes.center.astype(dtype)
    extent = boxes.world_extent().astype(dtype)
    kind = {"grid": Grid, "grid-bvh": Grid, "walk": WalkGrid, "walk-bvh": WalkGrid}.get(
        broad_phase)
    if kind is not None and not isinstance(grid, kind):
        raise ValueError(f"broad_phase {broad_phase!r} needs its grid (a {kind.__name__})")
    tree = None
    # every box's reject bounds, padded and rounded outward to float32 (either precision holds
    # them): the BVH's leaves, and their union for the frame kernel's free-flight step
    lower, upper = bvh_bounds(center, extent) if len(boxes) else (None, None)
    spanning = np.zeros(0, np.int32)
    if broad_phase in ("bvh", "grid-bvh", "walk-bvh") and len(boxes):
        # with the BVH as the method, the boxes that span the scene (a room's walls) are tried
        # before each query, out of the tree (broad_phase.tree_split, which never empties
        # it); as a grid's fallback the tree holds every box (the kernels' fallback loop
        # reads no kept-out boxes)
        if broad_phase == "bvh":
            spanning = tree_split(lower, upper)[0]
        # SAH on every device: the best trees for queries, and its builder caps the depth at
        # the query stack's size (a static scene builds it once); the boxes kept out hold
        # empty bounds (lower above upper: no query meets them, no node grows)
        tree_lower, tree_upper = lower.copy(), upper.copy()
        tree_lower[spanning] = np.finfo(np.float32).max
        tree_upper[spanning] = -np.finfo(np.float32).max
        tree = wp.Bvh(wp.array(tree_lower, dtype=wp.vec3f, device=device),
                      wp.array(tree_upper, dtype=wp.vec3f, device=device), constructor="sah")
    device_boxes = structs.Boxes()
    device_boxes.center = wp.array(center, dtype=p.vec3, device=device)
    device_boxes.rotation = wp.array(boxes.rotation_matrices().astype(dtype), dtype=p.mat33,
                                     device=device)
    device_boxes.half_extents = wp.array(boxes.half_extents.astype(dtype), dtype=p.vec3,
                                         device=device)
    device_boxes.radius = wp.array(boxes.radius.astype(dtype), dtype=p.scalar, device=device)
    device_boxes.extent = wp.array(extent, dtype=p.vec3, device=device)
    # the box holding every box's reject bounds, for the frame kernel's free-flight step
    if len(boxes):
        device_boxes.lower = p.vec3(*lower.min(axis=0).astype(np.float64))
        device_boxes.upper = p.vec3(*upper.max(axis=0).astype(np.float64))
    else:  # empty: every path lies beyond it
        device_boxes.lower = p.vec3(np.inf, np.inf, np.inf)
        device_boxes.upper = p.vec3(-np.inf, -np.inf, -np.inf)
    broad = _broad_phase(structs.BroadPhase(), grid if kind is not None else None, p, device,
                         spanning)
    if isinstance(grid, WalkGrid) and len(grid.cell_boxes):
        bounds = np.stack([center[grid.cell_boxes], extent[grid.cell_boxes]], axis=1)
    else:
        bounds = np.zeros((1, 2, 3), dtype)
    broad.entry_bounds = wp.array(bounds.reshape(-1, 3), dtype=p.vec3, device=device)
    broad.bvh = wp.uint64(tree.id if tree is not None else 0)
    physics = structs.Physics()
    physics.gravity = p.vec3(*np.asarray(gravity, dtype=np.float64))
    physics.origin = p.vec3(*np.asarray(origin, dtype=np.float64))
    physics.dt = p.scalar(dt)
    physics.friction = p.scalar(friction)
    physics.max_rot = p.scalar(max_angular_speed)
    physics.retention = p.scalar(energy_retention)
    physics.max_bounces = int(max_bounces)
    return Model(boxes=device_boxes, broad=broad, physics=physics, precision=p, device=device,
                 bvh=tree)


def _broad_phase(broad, grid: Grid | WalkGrid | None, p: Precision, device,
                 spanning: np.ndarray):
    """``broad`` (a ``BroadPhase``) with the grid's fields set (one empty cell without a grid;
    the walk's fields empty without a walked grid) and the boxes kept out of the BVH's tree
    (``spanning``, box indices) after the grid's entries and a placeholder."""
    walk = grid if isinstance(grid, WalkGrid) else None
    broad.reach = p.scalar(walk.reach if walk is not None else 0.0)
    broad.scale = p.scalar(walk.scale if walk is not None else 0.0)
    if grid is None:
        broad.lower = p.vec3(0.0, 0.0, 0.0)
        broad.cell = p.vec3(1.0, 1.0, 1.0)
        broad.inv_cell = p.vec3(1.0, 1.0, 1.0)
        broad.dims = wp.vec3i(0, 0, 0)
        broad.margin = p.scalar(0.0)
        broad.cell_start = wp.zeros(2, dtype=wp.int32, device=device)
        entries = np.zeros(0, np.int32)
    else:
        broad.lower = p.vec3(*grid.lower)
        broad.cell = p.vec3(*grid.cell)
        broad.inv_cell = p.vec3(*grid.inv_cell)
        broad.dims = wp.vec3i(*(int(x) for x in grid.dims))
        broad.margin = p.scalar(grid.kernel_margin if walk is None else 0.0)
        broad.cell_start = wp.array(grid.cell_start, dtype=wp.int32, device=device)
        entries = grid.entries() if walk is not None else grid.cell_boxes
    broad.spanning_start = int(len(entries) + 1)
    broad.spanning_count = int(len(spanning))
    broad.cell_boxes = wp.array(np.concatenate([entries, [0], spanning]).astype(np.int32),
                                dtype=wp.int32, device=device)
    return broad


def put_spheres(radius: np.ndarray, mass: np.ndarray, p: Precision, device,
                birth_frame: np.ndarray | None = None) -> Spheres:
    """Validated per-sphere constants (float64 radius and mass, integer birth frames, (N,)
    each; None for births all at 0) as :class:`Spheres` on ``device``."""
    births = (np.zeros(len(radius), dtype=np.int32) if birth_frame is None
              else np.ascontiguousarray(birth_frame, dtype=np.int32))
    return Spheres(radius=to_device(radius, p.scalar, p, device),
                   mass=to_device(mass, p.scalar, p, device),
                   birth_frame=wp.array(births, dtype=wp.int32, device=device))


def put_state(p: Precision, device, *, position, velocity, energy, angular_momentum,
              orientation) -> DeviceState:
    """Validated per-sphere state (float64 host arrays) as a :class:`DeviceState`."""
    return DeviceState(position=to_device(position, p.vec3, p, device),
                       velocity=to_device(velocity, p.vec3, p, device),
                       energy=to_device(energy, p.scalar, p, device),
                       angular_momentum=to_device(angular_momentum, p.vec3, p, device),
                       orientation=to_device(orientation, p.quat, p, device))


def event_buffer(p: Precision, device, capacity: int):
    """An empty event buffer of ``capacity`` rows for one launch: a ``kernels.data``
    ``EventBuffer``, the kernels' ``events_out``; capacity 0 is the buffer of launches without
    events (never written)."""
    buffer = model_structs(p).EventBuffer()
    buffer.count = wp.zeros(1, dtype=wp.int32, device=device)
    buffer.index = wp.empty((capacity, 4), dtype=wp.int32, device=device)
    buffer.vector = wp.empty((capacity, 2), dtype=p.vec3, device=device)
    buffer.value = wp.empty((capacity, 2), dtype=p.scalar, device=device)
    return buffer


def parameter_names(kernel) -> list[str]:
    """The parameter names of a Warp kernel, in order."""
    return [arg.label for arg in kernel.adj.args]


def _field(source, name: str):
    """``source[name]`` or ``source.name``; None when the source or the entry is missing."""
    if source is None:
        return None
    if isinstance(source, dict):
        return source.get(name)
    return getattr(source, name, None)


def kernel_arguments(kernel, *, model: Model | None = None, spheres: Spheres | None = None,
                     state_in: DeviceState | None = None, state_out: DeviceState | None = None,
                     outputs=None, launch_outputs=None, values: dict | None = None,
                     rows: slice | None = None) -> list:
    """A launch's arguments for ``kernel``, each looked up by its parameter's name.

    Rules, per parameter ``name``:

    - ``<field>_in``: ``state_in.<field>``;
    - ``<field>_out``: ``state_out.<field>`` when the state has that field, else
      ``outputs[name]`` (a dict or an object with that attribute: per-sphere counters, query
      results), else ``launch_outputs[name]`` (outputs of the whole launch, never sliced: the
      event buffer ``events_out``);
    - any other name: ``model.<name>``, else ``spheres.<name>``, else ``values[name]`` (plain
      per-launch values such as a frame count).

    Args:
        kernel: a Warp kernel of this package.
        model, spheres, state_in, state_out, outputs, launch_outputs, values: the sources
            above.
        rows: a slice of the spheres: every per-sphere array (of ``spheres``, the states and
            ``outputs``) is passed as that slice (a view, no copy); a 2-D per-sphere output
            (frames, N) is sliced along its second axis. The model's structs are passed whole.

    Returns:
        The argument list in parameter order, for ``wp.launch(kernel, inputs=...)``.

    Raises:
        KeyError: a parameter that no source provides, or that two sources both provide (the
            ambiguity would make the launch depend on lookup order).
    """
    args = []
    for name in parameter_names(kernel):
        per_sphere = True
        if name.endswith(IN_SUFFIX):
            value = _field(state_in, name[:-len(IN_SUFFIX)])
            where = "state_in"
        elif name.endswith(OUT_SUFFIX):
            value = _field(state_out, name[:-len(OUT_SUFFIX)])
            where = "state_out"
            if value is None:
                value = _field(outputs, name)
                where = "outputs"
            if value is None:
                value = _field(launch_outputs, name)
                per_sphere = False
        else:
            found = [(src, v) for src, v in (("model", _field(model, name)),
                                             ("spheres", _field(spheres, name)),
                                             ("values", _field(values, name))) if v is not None]
            if len(found) > 1:
                raise KeyError(f"kernel {kernel.key}: parameter {name!r} is provided by both "
                               f"{found[0][0]} and {found[1][0]}")
            where, value = found[0] if found else ("", None)
            per_sphere = where == "spheres"
        if value is None:
            raise KeyError(f"kernel {kernel.key}: no source provides parameter {name!r}")
        if rows is not None and per_sphere and isinstance(value, wp.array):
            if value.ndim == 1:
                value = value[rows]
            elif value.shape[0] > 0:  # an empty (0, N) output is never indexed: pass it whole
                value = value[:, rows]
        args.append(value)
    return args


#: Spheres each task of a CPU launch advances, one after another (a GPU thread takes one). A CPU
#: task first copies the launch's arguments, which the compiler cannot keep across tasks (a
#: store to an output array might change them): about 230 instructions a task for the frame
#: kernel, which a task of one sphere paid once per sphere and launch (BENCHMARKS.md, "A
#: launch's cost per sphere").
CPU_SPHERES_PER_TASK = 64


def spheres_per_task(device) -> int:
    """The spheres each task of a launch on ``device`` advances (the kernels' launch value
    ``spheres_per_task``): ``CPU_SPHERES_PER_TASK`` on the CPU, one on a GPU."""
    return CPU_SPHERES_PER_TASK if wp.get_device(device).is_cpu else 1


def task_count(spheres: int, per_task: int) -> int:
    """The launch size for ``spheres`` spheres, ``per_task`` a task: ``ceil(spheres /
    per_task)``."""
    return -(-spheres // per_task)


def launch(kernel, count: int, device, **sources) -> None:
    """Launch ``kernel`` over ``count`` spheres with the arguments of :func:`kernel_arguments`,
    ``spheres_per_task`` (:func:`spheres_per_task`) added to its ``values``: :func:`task_count`
    tasks."""
    per_task = spheres_per_task(device)
    values = {**(sources.pop("values", None) or {}), "spheres_per_task": per_task}
    wp.launch(kernel, dim=task_count(count, per_task), device=device,
              inputs=kernel_arguments(kernel, values=values, **sources))


__all__ = ["CPU_SPHERES_PER_TASK", "DeviceState", "Model", "Spheres", "event_buffer",
           "kernel_arguments", "launch", "parameter_names", "put_model", "put_spheres",
           "put_state", "spheres_per_task", "task_count", "to_device"]
