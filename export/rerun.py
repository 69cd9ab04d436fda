"""Rerun recordings of warpsim runs (``.rrd``): a timeline to scrub, a camera to turn, spheres to
pick, contacts and energy plots beside the 3D view.

rerun-sdk is the optional ``viewer`` extra (``pip install "warpsim[viewer]"``); it is imported
only when a recording is written or read. :mod:`warpsim.export.rerun_viewer` opens recordings.

Recording layout (application id ``warpsim``; world units are metres, the scene's own axes)::

    world                      ViewCoordinates (static): right-handed, the axis opposite to
                               gravity up (Y when gravity is zero or not along an axis's minus)
    world/obstacles/shape_0000 one entity per distinct obstacle shape (static): Mesh3D in the
                               box's local frame (rounded_box_mesh with 4 segments or box_mesh,
                               triangulated) drawn at every box of that shape by InstancePoses3D
                               (translations = centres, quaternions (x, y, z, w) local -> world);
                               AnyValues ``box`` (scene indices), ``half_extents`` (3 per box,
                               flattened) and ``rounding`` [m] keep the boxes exactly (float64)
    world/spheres              Points3D: ``radii`` [m], ``colors`` (a stable colour per swarm
                               index), ``labels`` ("sphere 17", hidden in the view) and AnyValues
                               ``sphere`` (swarm indices), static; ``positions`` [m] (float32)
                               at every recorded frame
    world/contacts             Points3D at the contact centres of each frame (only that frame's:
                               an empty list at frames without contacts), bounces orange and
                               supports grey, with AnyValues ``sphere``, ``box``,
                               ``contact_time`` [s], ``normal_speed`` [m/s] and ``kind``
                               (ContactKind) per contact;
                               world/contacts/normals: Arrows3D of the unit normals (a tenth of
                               the obstacles' median size long)
    plots/energy_drift, plots/energy, plots/bounces, plots/capped
                               Scalars per recorded frame (see :class:`FrameScalars`)
    description                TextDocument (static): scene, counts, time step

Timelines: ``frame``, a sequence of integer simulation frames (frame ``k`` is the state after
``k`` steps of ``dt``, as in :class:`warpsim.Trajectory`), and ``time``, a duration
(``frame * dt`` seconds, rounded to the nanosecond). Sphere orientations are not recorded
(the points are round).
"""

from __future__ import annotations

import colorsys
import importlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import validation as check
from ..trajectory import Trajectory
from .files import atomic_output, check_writable
from .mesh import box_mesh, rounded_box_mesh
from .usd_layout import OBSTACLE_COLOR  # the USD writer's rules and colour, without pxr
from .usd_layout import SPHERES as USD_SPHERES
from .usd_layout import WORLD as USD_WORLD
from .usd_layout import selected_rows as _selected
from .usd_layout import shapes as _shapes

SUFFIX = ".rrd"
APPLICATION_ID = "warpsim"
FRAME = "frame"  # the sequence timeline: integer simulation frames
TIME = "time"  # the duration timeline: frame * dt [s]
WORLD = "world"
OBSTACLES = "world/obstacles"
SPHERES = "world/spheres"
CONTACTS = "world/contacts"
NORMALS = "world/contacts/normals"
PLOTS = "plots"
DESCRIPTION = "description"
ROUNDED_SEGMENTS = 4  # edges per quarter circle of rounded edges (7 kB a shape; the USD has 8)
GOLDEN = 0.6180339887498949  # hue step between consecutive sphere ids: neighbours differ
SPHERE_SATURATION, SPHERE_VALUE = 0.65, 0.95
BOUNCE_COLOR = (255, 120, 30)
SUPPORT_COLOR = (150, 150, 150)
NORMAL_LENGTH_SHARE = 0.1  # normal arrows: this share of the obstacles' median bounding radius
CAMERA_PERCENTILES = (2.0, 98.0)  # the spheres' region, its outliers left out
CAMERA_HEIGHT = 0.5  # first eye: this share of the region's half height above its centre
CAMERA_MIN_HALF = 1e-3  # [m] half size of the region of a single sphere
CONTACT_RADIUS_UI = -3.0  # contact points 3 UI points wide whatever the zoom (Rerun: r < 0)

# Size model fitted on written files (rerun-sdk 0.41, benchmarks/rerun_write.py), bytes: fixed
# (the blueprint, the description) + per_sphere N + F (per_frame + N per_sphere_frame) + per
# distinct obstacle shape (its chunk, and the rounded mesh's extra) + per_box K; with plots
# plots_fixed + per_plot_frame F; with contacts contacts_fixed + per_event E + per_event_frame
# (frames the contacts span: each has a row, empty or not).
_SIZE_MODEL = {"fixed": 50_000, "per_sphere": 17, "per_frame": 18, "per_sphere_frame": 12,
               "per_shape": 7_400, "per_rounded_shape": 4_500, "per_box": 25,
               "plots_fixed": 29_000, "per_plot_frame": 72,
               "contacts_fixed": 6_000, "per_event": 40, "per_event_frame": 40,
               "per_unborn_sphere_frame": 0.5}


def _rerun():
    try:
        return importlib.import_module("rerun")
    except ImportError:
        raise ModuleNotFoundError('rerun-sdk is needed for Rerun recordings: '
                                  'pip install "warpsim[viewer]"') from None


def require_rerun() -> None:
    """Check, before a long run, that recordings can be written here.

    Raises:
        ModuleNotFoundError: rerun-sdk is missing; the message names the ``viewer`` extra.
    """
    _rerun()


def check_rerun_path(path) -> Path:
    """``path`` as a :class:`pathlib.Path` once it is known to end in ``.rrd`` (any case) and
    to be writable (its folder exists).

    Raises:
        ValueError: another extension or an empty path. FileNotFoundError, OSError: the
            folder is missing or cannot be written.
    """
    return check_writable(path, (SUFFIX,), what="Rerun recording")


def check_run_options(args) -> None:
    """The command line's ``--rerun PATH`` and ``--rerun-sample K``, checked before a run: the
    path ends in ``.rrd`` and can be written, rerun-sdk is installed, ``K >= 1``.

    Raises:
        ValueError: naming the option. ModuleNotFoundError: rerun-sdk is missing.
    """
    if args.rerun_sample is not None:
        if args.rerun is None:
            raise ValueError("--rerun-sample needs --rerun")
        check.positive_int("rerun_sample", args.rerun_sample)
    check_rerun_path(args.rerun)
    require_rerun()


def check_recording_size(args, scene, n_spheres: int, n_frames: int, unborn: int = 0) -> int:
    """Refuse, before a run, a recording estimated above ``--max-bytes``
    (:func:`estimate_rerun_bytes` for the spheres and frames written, the scene's obstacles and
    the plots; contacts are not known before the run and not counted).

    Args:
        args: the command's options (``rerun``, ``rerun_sample``, ``max_bytes``).
        scene: the scene run. n_spheres: spheres selected (before ``--rerun-sample``).
        n_frames: recorded frames written.
        unborn: sphere-frames of the written spheres (after ``--rerun-sample``, as
            :func:`sampled_columns` picks them) recorded before their birth.

    Returns:
        The estimate [bytes].

    Raises:
        ValueError: the estimate is above ``args.max_bytes``; the message says what to lower.
    """
    n = n_spheres if args.rerun_sample is None else min(n_spheres, args.rerun_sample)
    estimate = estimate_rerun_bytes(n, n_frames, boxes=scene.boxes, scalars=True, unborn=unborn)
    if estimate > args.max_bytes:
        raise ValueError(f"{str(args.rerun)!r} would be about {estimate / 1e6:,.0f} MB ({n} "
                         f"spheres x {n_frames} frames), above --max-bytes "
                         f"{args.max_bytes:,.0f}: record fewer frames (--every, --start/--end) "
                         f"or spheres (--spheres, --rerun-sample), or raise --max-bytes")
    return estimate


@dataclass(repr=False)
class FrameScalars:
    """Per recorded frame figures of a run, plotted by :func:`write_rerun`.

    Attributes:
        frame: the recorded frames, (R,) int64 (those of the trajectory).
        energy: total energy of the swarm [J], (R,) float64 (:meth:`Simulator.mechanical_energy`).
        energy_drift: the largest per-sphere change of energy since the start, relative to each
            sphere's energy above the scene's lowest point (:func:`warpsim.energy.relative_change`,
            the scale of the run's summary), (R,) float64; 0 at frame 0.
        bounces: contacts taken since the previous recorded frame, all spheres (resting contacts
            included, as :attr:`Stats.bounces` counts them), (R,) int64; 0 at the first.
        capped: sphere-frames stopped by ``max_bounces`` since the previous recorded frame,
            (R,) int64.
    """

    frame: np.ndarray
    energy: np.ndarray
    energy_drift: np.ndarray
    bounces: np.ndarray
    capped: np.ndarray

    def __post_init__(self):
        self.frame = np.asarray(self.frame, dtype=np.int64)
        r = self.frame.shape
        for name, dtype in (("energy", np.float64), ("energy_drift", np.float64),
                            ("bounces", np.int64), ("capped", np.int64)):
            values = np.asarray(getattr(self, name), dtype=dtype)
            if values.shape != r:
                raise ValueError(f"{name} must have shape {r} (one per recorded frame), "
                                 f"got {values.shape}")
            setattr(self, name, values)

    def __len__(self) -> int:
        return int(self.frame.size)

    def __repr__(self) -> str:
        return f"FrameScalars({len(self)} recorded frames)"

    def plots(self) -> dict[str, np.ndarray]:
        """Entity name under ``plots/`` -> values (R,), in the recording's order."""
        return {"energy_drift": self.energy_drift, "energy": self.energy,
                "bounces": self.bounces, "capped": self.capped}


def run_with_scalars(sim, frames: int, every: int = 1, *, progress: bool = False,
                     start=None, **options) -> tuple[Trajectory, FrameScalars]:
    """:meth:`Simulator.run` that also samples :class:`FrameScalars` at each recorded frame.

    The run is made of one ``sim.run`` per recorded interval (``every`` frames, the last one
    shorter), so that the counters and the energy are read between them; results are the same
    bits as one ``sim.run(frames, every)`` (the simulator's launches are bit-identical whatever
    their length), at the price of one launch per recorded frame.

    Args:
        sim: a :class:`warpsim.Simulator`.
        frames: frames to advance, >= 1. every: record one frame in ``every``, >= 1.
        progress: one tqdm progress bar on standard error for the whole run.
        start: the swarm's start positions [m], (N, 3), which set the energy scale of
            ``energy_drift`` (:mod:`warpsim.energy`, the summary's); None: the positions now.
        options: more keywords of ``Simulator.run`` (``velocities``, ``events``,
            ``event_capacity``).

    Returns:
        ``(trajectory, scalars)``: what ``sim.run(frames, every, **options)`` returns, and the
        figures at its recorded frames.
    """
    from tqdm import tqdm

    from ..energy import relative_change
    from ..events import ContactEvents

    frames = check.positive_int("frames", frames)
    every = check.positive_int("every", every)
    start = sim.state().position if start is None else np.asarray(start, dtype=np.float64)

    def sample():
        stats = sim.stats
        energy = sim.mechanical_energy()
        drift = (float(np.max(np.abs(relative_change(sim, start)))) if energy.size else 0.0)
        return float(energy.sum()), drift, stats.bounces, stats.capped

    samples = [sample()]
    pieces, events = [], []
    bar = tqdm(total=frames, unit="frame", disable=not progress, leave=False)
    try:
        done = 0
        while done < frames:
            todo = min(every, frames - done)
            piece = sim.run(todo, every=todo, **options)
            pieces.append(piece)
            if piece.events is not None:
                events.append(piece.events)
            samples.append(sample())
            done += todo
            bar.update(todo)
    finally:
        bar.close()
    first = pieces[0]

    def stacked(name):
        if getattr(first, name) is None:
            return None
        return np.concatenate([getattr(first, name)[:1]]
                              + [getattr(p, name)[1:] for p in pieces])

    traj = Trajectory(frame=stacked("frame"), dt=first.dt, position=stacked("position"),
                      orientation=stacked("orientation"), radius=first.radius,
                      velocity=stacked("velocity"), angular_velocity=stacked("angular_velocity"),
                      events=ContactEvents.concatenate(events) if events else None,
                      sphere_ids=first.sphere_ids, birth_frame=first.birth_frame)
    energy, drift, bounces, capped = (np.array(column) for column in zip(*samples, strict=True))
    scalars = FrameScalars(frame=traj.frame, energy=energy, energy_drift=drift,
                           bounces=np.diff(bounces, prepend=bounces[0]),
                           capped=np.diff(capped, prepend=capped[0]))
    return traj, scalars


# --------------------------------------------------------------------------------------------
# Sizes


def estimate_rerun_bytes(n_spheres: int, n_frames: int, *, boxes=None, scalars: bool = False,
                         events: int = 0, event_frames: int = 0, unborn: int = 0) -> int:
    """Estimated size of a file written by :func:`write_rerun` [bytes].

    A linear model fitted on written files (``benchmarks/rerun_write.py``: from 4% below to
    18% above the bundled scenes' recordings, the most above for a swarm that comes to rest,
    galton's, whose chunks compress): 12 B per sphere and recorded
    frame (float32 positions, which Rerun stores uncompressed), 0.5 B for one written before
    its sphere's birth (NaN positions, which Rerun's chunk compression all but removes: 0.3 to
    0.5 B measured on the nozzle's births), 17 B per sphere (radius, colour, label, id), 18 B
    per recorded frame (its timelines), 7 kB per distinct obstacle shape (12 kB rounded) and
    25 B per box, 72 B per recorded frame for the four plots, 40 B per contact and 40 B per
    frame the contacts span, and about 50 kB of blueprint and description.

    Args:
        n_spheres: spheres written. n_frames: recorded frames written (after ``stride``).
        boxes: the obstacles (:class:`warpsim.RoundedBoxes` or a :class:`warpsim.Scene`), or None.
        scalars: whether the per-frame plots are written.
        events: contacts written. event_frames: frames the contacts' timeline spans.
        unborn: of the ``n_spheres * n_frames`` sphere-frames written, those before their
            sphere's birth (``~Trajectory.alive()`` of the rows and spheres written; 0 without
            births).

    Raises:
        ValueError: negative counts, or ``unborn`` above ``n_spheres * n_frames``.
    """
    n, f, e, ef, u = (int(v) for v in (n_spheres, n_frames, events, event_frames, unborn))
    if min(n, f, e, ef, u) < 0:
        raise ValueError(f"counts must be >= 0, got n_spheres={n_spheres}, n_frames={n_frames}, "
                         f"events={events}, event_frames={event_frames}, unborn={unborn}")
    if u > n * f:
        raise ValueError(f"unborn must be at most n_spheres * n_frames = {n * f}, got {unborn}")
    m = _SIZE_MODEL
    total = (m["fixed"] + n * m["per_sphere"] + f * (m["per_frame"] + n * m["per_sphere_frame"])
             - u * (m["per_sphere_frame"] - m["per_unborn_sphere_frame"]))
    if scalars:
        total += m["plots_fixed"] + m["per_plot_frame"] * f
    if e:
        total += m["contacts_fixed"] + m["per_event"] * e + m["per_event_frame"] * ef
    boxes = getattr(boxes, "boxes", boxes)
    if boxes is not None and len(boxes):
        _, shapes = _shapes(boxes)
        rounded = int(np.count_nonzero(shapes[:, 3] > 0.0))
        total += (m["per_shape"] * len(shapes) + m["per_rounded_shape"] * rounded
                  + m["per_box"] * len(boxes))
    return int(total)


# --------------------------------------------------------------------------------------------
# Writing


def sphere_colors(ids) -> np.ndarray:
    """A stable colour per swarm index: hues ``frac(id * golden ratio)`` (neighbouring ids
    far apart on the colour wheel), fixed saturation and value; (N, 3) uint8 sRGB."""
    ids = np.asarray(ids, dtype=np.int64)
    hue = np.mod(ids * GOLDEN, 1.0)
    rgb = [colorsys.hsv_to_rgb(h, SPHERE_SATURATION, SPHERE_VALUE) for h in hue]
    return np.round(np.array(rgb, dtype=np.float64).reshape(-1, 3) * 255.0).astype(np.uint8)


def _srgb(linear) -> tuple[int, int, int]:
    """A linear RGB colour in [0, 1] as 8-bit sRGB (IEC 61966-2-1 transfer curve)."""
    c = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1.0 / 2.4) - 0.055)
    return tuple(int(v) for v in np.round(s * 255.0))


def triangulated(points, counts, indices) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A polygon mesh as triangles with vertex normals, for Rerun's Mesh3D.

    Each polygon is fanned from its first vertex (counter-clockwise kept). Vertex normals are
    the area-weighted mean of the normals of the triangles around the vertex; a vertex only on
    zero-area faces (a plate's edges) gets the unit direction from the origin to it (the box's
    local centre), or +Y at the origin.

    Returns:
        ``(points (P, 3) float32, triangles (T, 3) uint32, normals (P, 3) float32)``.
    """
    points = np.asarray(points, dtype=np.float64)
    counts = np.asarray(counts, dtype=np.int64)
    indices = np.asarray(indices, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    tris = [np.stack([indices[starts[counts > j]], indices[starts[counts > j] + j],
                      indices[starts[counts > j] + j + 1]], axis=1)
            for j in range(1, int(counts.max()) - 1)] if counts.size else []
    triangles = np.concatenate(tris) if tris else np.zeros((0, 3), dtype=np.int64)
    a, b, c = (points[triangles[:, k]] for k in range(3))
    face = np.cross(b - a, c - a)  # length = twice the area: area weighting
    normals = np.zeros_like(points)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face)
    size = np.linalg.norm(normals, axis=1, keepdims=True)
    reach = np.linalg.norm(points, axis=1, keepdims=True)
    fallback = np.where(reach > 0.0, points / np.where(reach > 0.0, reach, 1.0), (0.0, 1.0, 0.0))
    normals = np.where(size > 0.0, normals / np.where(size > 0.0, size, 1.0), fallback)
    return points.astype(np.float32), triangles.astype(np.uint32), normals.astype(np.float32)


def _up_axis(rr, gravity):
    g = np.asarray(gravity, dtype=np.float64)
    axis = int(np.argmax(np.abs(g)))
    if not np.any(g) or g[axis] >= 0.0:
        return rr.ViewCoordinates.RIGHT_HAND_Y_UP
    return (rr.ViewCoordinates.RIGHT_HAND_X_UP, rr.ViewCoordinates.RIGHT_HAND_Y_UP,
            rr.ViewCoordinates.RIGHT_HAND_Z_UP)[axis]


def _camera(gravity, position: np.ndarray, boxes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(eye, target, up) of the 3D view's first camera: at the upper corner of the region the
    spheres fill at the first written frame (:data:`CAMERA_PERCENTILES`, so inside a closed
    room), looking at its centre; the obstacles' bounds when there are no spheres (or none is
    born yet)."""
    up = -np.asarray(gravity, dtype=np.float64)
    up = up / np.linalg.norm(up) if np.any(up) else np.array([0.0, 1.0, 0.0])
    position = position.reshape(-1, 3)
    position = position[np.isfinite(position).all(axis=1)]  # the unborn are NaN
    if position.size:
        lo, hi = np.percentile(position, CAMERA_PERCENTILES, axis=0)
    elif boxes is not None and len(boxes):
        reach = boxes.bounding_radius()[:, None]
        lo, hi = (boxes.center - reach).min(axis=0), (boxes.center + reach).max(axis=0)
    else:
        lo, hi = -np.ones(3), np.ones(3)
    center, half = (lo + hi) / 2.0, np.maximum((hi - lo) / 2.0, CAMERA_MIN_HALF)
    axis = int(np.argmax(np.abs(up)))
    offset = half.copy()
    offset[axis] = half[axis] * CAMERA_HEIGHT * np.sign(up[axis])
    return center + offset, center, up


def _blueprint(eye, target, up, plots: list[str]):
    import rerun.blueprint as rrb

    side = [rrb.TimeSeriesView(origin=f"{PLOTS}/{name}", name=name.replace("_", " "))
            for name in plots]
    side.append(rrb.TextDocumentView(origin=DESCRIPTION, name="run"))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin=WORLD, name="spheres and obstacles",
                              eye_controls=rrb.EyeControls3D(position=eye, look_target=target,
                                                             eye_up=up)),
            rrb.Vertical(*side), column_shares=[3, 1]),
        rrb.TimePanel(timeline=FRAME))


def _log_obstacles(rr, rec, boxes) -> None:
    color = _srgb(OBSTACLE_COLOR)
    shape_of, shapes = _shapes(boxes)
    for s, shape in enumerate(shapes):
        members = np.flatnonzero(shape_of == s)
        h, rounding = shape[:3], float(shape[3])
        mesh = (rounded_box_mesh(h, rounding, ROUNDED_SEGMENTS) if rounding > 0.0
                else box_mesh(h))
        points, triangles, normals = triangulated(*mesh)
        path = f"{OBSTACLES}/shape_{s:04d}"
        rec.log(path, rr.Mesh3D(vertex_positions=points, triangle_indices=triangles,
                                vertex_normals=normals, albedo_factor=color),
                rr.InstancePoses3D(translations=boxes.center[members],
                                   quaternions=boxes.rotation[members]),
                rr.AnyValues(box=members.astype(np.int64), half_extents=np.tile(h, members.size),
                             rounding=np.full(members.size, rounding)), static=True)


def _timelines(rr, frames: np.ndarray, dt: float) -> list:
    nanoseconds = np.round(frames.astype(np.float64) * dt * 1e9).astype(np.int64)
    return [rr.TimeColumn(FRAME, sequence=frames),
            rr.TimeColumn(TIME, duration=nanoseconds.astype("timedelta64[ns]"))]


def _log_contacts(rr, rec, events, ids: np.ndarray, frames: np.ndarray, dt: float,
                  length: float) -> int:
    """Contacts of the written spheres, each at its own frame; returns how many."""
    from ..vocabulary import ContactKind

    frame = contact_frames(events, dt)
    rows = np.flatnonzero(np.isin(events.sphere, ids) & (frame >= frames[0]))
    rows = rows[np.argsort(frame[rows], kind="stable")]
    if rows.size == 0:
        return 0
    first = int(frames[0])
    span = np.arange(first, max(int(frames[-1]), int(frame[rows].max())) + 1)
    lengths = np.bincount(frame[rows] - first, minlength=span.size)
    support = events.kind[rows] == ContactKind.SUPPORT
    colors = np.where(support[:, None], np.array(SUPPORT_COLOR, dtype=np.uint8),
                      np.array(BOUNCE_COLOR, dtype=np.uint8))
    position = events.position[rows].astype(np.float32)
    indexes = _timelines(rr, span, dt)
    rec.send_columns(CONTACTS, indexes=indexes, columns=[
        *rr.Points3D.columns(positions=position, colors=colors,
                             radii=np.full(rows.size, CONTACT_RADIUS_UI, dtype=np.float32)
                             ).partition(lengths),
        *rr.AnyValues.columns(sphere=events.sphere[rows], box=events.box[rows].astype(np.int64),
                              contact_time=events.time[rows],
                              normal_speed=events.normal_speed[rows],
                              kind=events.kind[rows].astype(np.int64)).partition(lengths)])
    rec.send_columns(NORMALS, indexes=indexes, columns=rr.Arrows3D.columns(
        origins=position, vectors=(events.normal[rows] * length).astype(np.float32),
        colors=colors).partition(lengths))
    return int(rows.size)


def contact_frames(events, dt: float) -> np.ndarray:
    """The frame of each contact, (E,) int64: the table's ``frame``, or for a table in
    continuous time the frame whose step holds ``time`` (``floor(time / dt) + 1``)."""
    if events.frame is not None:
        return np.asarray(events.frame, dtype=np.int64)
    return np.floor(np.asarray(events.time) / dt).astype(np.int64) + 1


def _sphere_rows(trajectory: Trajectory, stride: int, spheres, sample):
    """Validated (frame rows, columns of the trajectory) to write, as the USD writer selects
    them (the last row always kept), then ``sample`` of the columns evenly spread."""
    rows, columns = _selected(trajectory, stride, spheres)
    return rows, columns[sampled_columns(columns.size, sample)]


def sampled_columns(count: int, sample: int | None) -> np.ndarray:
    """Which of ``count`` selected spheres a recording of at most ``sample`` writes: their
    positions in the selection, evenly spread, the first and the last kept; all of them when
    ``sample`` is None or not below ``count``.

    Raises:
        ValueError: ``sample`` is not an integer >= 1.
    """
    if sample is None:
        return np.arange(count, dtype=np.int64)
    sample = check.positive_int("sample", sample)
    if sample >= count:
        return np.arange(count, dtype=np.int64)
    return np.unique(np.round(np.linspace(0, count - 1, sample)).astype(np.int64))


def write_rerun(path, scene, trajectory: Trajectory, *, stride: int = 1, spheres=None,
                sample: int | None = None, ids=None, events=None,
                scalars: FrameScalars | None = None) -> Path:
    """Write a trajectory, its scene's obstacles, its contacts and its per-frame figures as a
    Rerun recording (layout in the module docstring), atomically.

    The recording is written under a temporary name next to ``path`` and renamed over it: on
    any error nothing is left behind and a file already at ``path`` is untouched.

    Args:
        path: output file ending in ``.rrd`` (any case); its folder must exist.
        scene: the :class:`warpsim.Scene` simulated, its :class:`warpsim.RoundedBoxes`, or None
            for the spheres alone (then Y is up).
        trajectory: the recorded frames; the ``frame`` timeline takes its integer ``frame``.
        stride: keep every ``stride``-th recorded frame (and the last), >= 1.
        spheres: indices (columns of the trajectory) of the spheres to write, or None for all.
        sample: write at most this many of them, evenly spread over the selection (first and
            last kept), >= 1; None for all.
        ids: the swarm index of each sphere of the trajectory, (N,) (a trajectory read from a
            file with a subset); None: ``0 .. N - 1``. Colours and labels follow them.
        events: a :class:`warpsim.ContactEvents` (its ``sphere`` are swarm indices; a table in
            continuous time goes to the frame whose step holds each contact); None takes
            ``trajectory.events``. Only the written spheres' contacts are written.
        scalars: :class:`FrameScalars` of the run (their frames must be recorded frames of the
            trajectory), plotted at the written frames; None for no plots.

    Returns:
        ``path`` as a :class:`pathlib.Path`.

    Raises:
        ValueError: bad extension, ``stride``, ``spheres``, ``sample``, ``ids`` or ``scalars``,
            or an inconsistent trajectory. ModuleNotFoundError: rerun-sdk is missing (the
            ``viewer`` extra). FileNotFoundError, OSError: the file cannot be written.
    """
    path = check_rerun_path(path)
    rows, columns = _sphere_rows(trajectory, stride, spheres, sample)
    n = trajectory.position.shape[1]
    all_ids = np.arange(n, dtype=np.int64) if ids is None else np.asarray(ids)
    if all_ids.shape != (n,) or (all_ids.size and not np.issubdtype(all_ids.dtype, np.integer)):
        raise ValueError(f"ids must be {n} integer swarm indices, got shape {all_ids.shape}")
    written_ids = all_ids.astype(np.int64)[columns]
    frames = np.asarray(trajectory.frame, dtype=np.int64)[rows]
    dt = float(trajectory.dt)
    if scalars is not None:
        where = {int(f): i for i, f in enumerate(scalars.frame)}
        missing = [int(f) for f in frames if int(f) not in where]
        if missing:
            raise ValueError(f"scalars have no value at recorded frame {missing[0]}")
        scalar_rows = np.array([where[int(f)] for f in frames], dtype=np.int64)
    events = trajectory.events if events is None else events
    boxes = None if scene is None else getattr(scene, "boxes", scene)
    rr = _rerun()

    gravity = getattr(scene, "gravity", (0.0, 0.0, 0.0))
    position = np.asarray(trajectory.position)[rows][:, columns].astype(np.float32)
    blueprint = _blueprint(*_camera(gravity, position[0], boxes),
                           [] if scalars is None else list(scalars.plots()))
    name = getattr(scene, "name", "")
    rec = rr.RecordingStream(APPLICATION_ID, send_properties=False)
    with atomic_output(path) as tmp:
        rec.save(tmp, default_blueprint=blueprint)
        rec.send_recording_name(name or APPLICATION_ID)
        rec.log(WORLD, _up_axis(rr, gravity), static=True)
        rec.log(DESCRIPTION, rr.TextDocument(
            f"warpsim run of scene {name!r}: {columns.size} spheres, {frames.size} recorded "
            f"frames {frames[0]}..{frames[-1]}, dt = {dt!r} s, "
            f"{0 if boxes is None else len(boxes)} obstacles. "
            f"{getattr(scene, 'description', '')}".strip()), static=True)
        if boxes is not None and len(boxes):
            _log_obstacles(rr, rec, boxes)
        radius = np.asarray(trajectory.radius, dtype=np.float64)[columns]
        rec.log(SPHERES, rr.Points3D.from_fields(
            radii=radius.astype(np.float32), colors=sphere_colors(written_ids),
            labels=[f"sphere {i}" for i in written_ids], show_labels=False), static=True)
        rec.log(SPHERES, rr.AnyValues(sphere=written_ids), static=True)
        if columns.size:
            rec.send_columns(SPHERES, indexes=_timelines(rr, frames, dt),
                             columns=rr.Points3D.columns(positions=position.reshape(-1, 3))
                             .partition(np.full(frames.size, columns.size)))
        if events is not None and len(events):
            size = (float(np.median(boxes.bounding_radius())) if boxes is not None and len(boxes)
                    else float(np.max(radius, initial=0.0)) * 4.0)
            _log_contacts(rr, rec, events, written_ids, frames, dt,
                          max(size, 1e-6) * NORMAL_LENGTH_SHARE)
        if scalars is not None:
            for name, values in scalars.plots().items():
                rec.send_columns(f"{PLOTS}/{name}", indexes=_timelines(rr, frames, dt),
                                 columns=rr.Scalars.columns(
                                     scalars=values[scalar_rows].astype(np.float64)))
        rec.flush()
        rec.disconnect()
    return path


def _usd_ids(path) -> tuple[np.ndarray | None, bool]:
    """(swarm ids of a single-instancer file's spheres, sharded?) from the stage itself."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path), load=Usd.Stage.LoadNone)
    prim = stage.GetPrimAtPath(USD_SPHERES)
    instancer = UsdGeom.PointInstancer(prim)
    if not instancer:  # a sharded root's Scope of instancers; no prim: read_usd says why
        return None, bool(prim)
    ids = instancer.GetIdsAttr().Get()
    return (None if ids is None else np.asarray(ids, dtype=np.int64)), False


def usd_to_rerun(usd_path, rrd_path, *, stride: int = 1, sample: int | None = None) -> Path:
    """Convert a warpsim USD file (one written by ``write_usd``, or the root of a sharded run)
    into a Rerun recording: the obstacles, the spheres with their swarm ids, the timelines.

    A USD file holds neither contacts nor per-frame figures, so the recording has none.

    Args:
        usd_path: a ``.usdc``/``.usda`` written by warpsim. rrd_path: the ``.rrd`` to write.
        stride, sample: as :func:`write_rerun`'s.

    Raises:
        FileNotFoundError: no file. ValueError: not a warpsim file, or a bad argument.
        ModuleNotFoundError: rerun-sdk is missing.
    """
    from pxr import Usd

    from .usd_read import read_usd, read_usd_boxes

    usd_path = Path(usd_path)
    if not usd_path.is_file():
        raise FileNotFoundError(f"no USD file at {str(usd_path)!r}")
    check_rerun_path(rrd_path)
    require_rerun()
    try:
        ids, sharded = _usd_ids(usd_path)
    except Exception as exc:  # pxr raises Tf.ErrorException with a multi-line message
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise ValueError(f"USD could not read {str(usd_path)!r}: {first}") from None
    if sharded:
        from .layers import read_sharded_ids, read_sharded_usd

        traj, ids = read_sharded_usd(usd_path), read_sharded_ids(usd_path)
    else:
        traj = read_usd(usd_path)
    boxes = read_usd_boxes(usd_path)
    world = Usd.Stage.Open(str(usd_path), load=Usd.Stage.LoadNone).GetPrimAtPath(USD_WORLD)
    name_attr = world.GetAttribute("warpsim:scene") if world else None
    scene = _NamedBoxes(boxes, name_attr.Get() if name_attr else usd_path.stem)
    return write_rerun(rrd_path, scene, traj, stride=stride, sample=sample, ids=ids)


@dataclass
class _NamedBoxes:
    """What :func:`write_rerun` reads of a scene, for a file's obstacles: USD files are Y up."""

    boxes: object
    name: str
    gravity: tuple = (0.0, -1.0, 0.0)
    description: str = ""


__all__ = ["FrameScalars", "check_recording_size", "check_rerun_path", "check_run_options",
           "contact_frames", "estimate_rerun_bytes", "require_rerun", "run_with_scalars",
           "sampled_columns", "sphere_colors", "triangulated", "usd_to_rerun", "write_rerun"]
