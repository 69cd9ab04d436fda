"""Batched single-frame sphere sweeps, numpy in, numpy out: against one rounded box, against a
group of boxes (the first contact), and several bounces in one frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from . import broad_phase as broad
from . import validation as check
from .device import resolve_device
from .kernels import precision as fp
from .kernels.collide_kernels import bounce_kernel, collide_kernel
from .kernels.data import Features
from .model import Spheres, event_buffer, launch, put_model, to_device
from .obstacles import RoundedBox, RoundedBoxes
from .swarm import Swarm


@dataclass
class Contacts:
    """First contact of each sphere during one frame (numpy arrays of the chosen precision).

    The centre of sphere ``i`` would move from ``A`` to ``B = A + v dt``.

    Attributes:
        hit: whether the sphere touches an obstacle on the way, (N,) bool.
        t: fraction of ``A -> B`` at first contact, in [0, 1]; 1 without contact, (N,).
        position: centre at first contact ``A + t (B - A)`` [m]; ``B`` without contact, (N, 3).
        normal: unit outward normal of the obstacle at the contact; 0 without contact, (N, 3).
        new_position: centre after the reflected rest of the path, ``(1 - t)|B - A|`` along the
            reflected velocity [m]; ``B`` without contact, (N, 3).
        new_velocity: reflected velocity ``v - 2 (v . n) n`` [m/s]; ``v`` without contact, (N, 3).
        box: index of the obstacle hit (ties: the lower index); -1 without contact, (N,) int32.
    """

    hit: np.ndarray
    t: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    new_position: np.ndarray
    new_velocity: np.ndarray
    box: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])


def collide_boxes(position, velocity, radius, boxes: RoundedBoxes | RoundedBox, dt: float, *,
                  device=None, precision: str = "float32", broad_phase: str = "auto",
                  motion: str = "linear", gravity=None) -> Contacts:
    """First contact of each moving sphere with a group of static rounded boxes.

    With ``motion="linear"`` every sphere moves in a straight line for ``dt`` (the
    segment ``A -> A + v dt``); with ``motion="ballistic"`` it follows the exact parabola
    ``A + v s + 1/2 g s^2``, ``s`` in ``[0, dt]``. The first contact over all boxes is kept
    (ties: the lower box index). A contact counts only when the sphere moves into the surface;
    a sphere starting in contact and moving in is hit at ``t = 0``. Inputs are never modified.

    Args:
        position: sphere centres at the start of the frame [m], world frame, (N, 3).
        velocity: sphere velocities [m/s], (N, 3).
        radius: sphere radii [m], scalar or (N,), each >= 0.
        boxes: the obstacles.
        dt: frame duration [s], > 0.
        device: Warp device (``"cpu"``, ``"cuda:0"``; None for Warp's default).
        precision: ``"float32"`` or ``"float64"`` kernels.
        broad_phase: how each sphere finds its candidate boxes (see
            :mod:`warpsim.broad_phase`): ``"brute"``, ``"bvh"``, ``"grid"``, ``"walk"`` or
            ``"auto"`` (a grid is built per call, and only where the call's spheres are many
            enough to pay for it: ``broad_phase.GRID_BUILD``). The results are bit-identical;
            only the speed differs.
        motion: ``"linear"`` or ``"ballistic"``. For the ballistic motion ``t`` is the contact
            time as a fraction of ``dt``, ``position`` the centre on the parabola then,
            ``new_velocity`` the reflected velocity at the contact (``v + g dt`` without one)
            and ``new_position`` the frame's end along the new parabola.
        gravity: [m/s^2], world frame, for the ballistic motion (None: zero); the linear
            segment has no gravity, so a non-zero one is refused there.

    Returns:
        :class:`Contacts`, arrays of the chosen precision.

    Raises:
        ValueError: a bad input, naming the field and the index.
    """
    boxes, pos, vel, rad = check.sphere_batch(position, velocity, radius, boxes)
    n = pos.shape[0]
    dt = check.scene_settings({"dt": dt})["dt"]
    motion, g = _motion_and_gravity(motion, gravity)
    p = precision_of(precision)
    dev = resolve_device(device)
    method, grid = broad.choose(broad_phase, boxes, broad.paths(pos, vel, rad, g, dt),
                                p.np_dtype, queries=n)
    model = put_model(boxes, p, dev, broad_phase=method, grid=grid, dt=dt, gravity=g)
    spheres = Spheres(radius=to_device(rad, p.scalar, p, dev), mass=None)
    state = {"position": to_device(pos, p.vec3, p, dev),
             "velocity": to_device(vel, p.vec3, p, dev)}
    out = {"box_out": wp.empty(n, dtype=wp.int32, device=dev),
           "t_out": wp.empty(n, dtype=p.scalar, device=dev)}
    for name in ("contact_out", "normal_out", "new_position_out", "new_velocity_out"):
        out[name] = wp.empty(n, dtype=p.vec3, device=dev)
    kernel = collide_kernel(Features(precision=p.name, motion=motion, broad_phase=method))
    launch(kernel, n, dev, model=model, spheres=spheres, state_in=state, outputs=out)
    box = out["box_out"].numpy()
    return Contacts(hit=box >= 0, t=out["t_out"].numpy(), position=out["contact_out"].numpy(),
                    normal=out["normal_out"].numpy(),
                    new_position=out["new_position_out"].numpy(),
                    new_velocity=out["new_velocity_out"].numpy(), box=box)


def collide_box(position, velocity, radius, box: RoundedBox, dt: float, *, device=None,
                precision: str = "float32", motion: str = "linear", gravity=None) -> Contacts:
    """First contact of each moving sphere with one static rounded box .

    The same contract as :func:`collide_boxes` with a group of one (``box`` is 0 or -1); one
    box needs no broad phase.
    """
    if not isinstance(box, RoundedBox):
        raise ValueError(f"box must be a warpsim.RoundedBox, got {type(box).__name__}")
    return collide_boxes(position, velocity, radius, box.as_boxes(), dt, device=device,
                         precision=precision, broad_phase="brute", motion=motion,
                         gravity=gravity)


def _motion_and_gravity(motion, gravity) -> tuple[str, np.ndarray]:
    """The checked motion model and gravity [m/s^2] of a batched query."""
    motion = check.motion(motion)
    g = np.zeros(3) if gravity is None else check.vec3("gravity", gravity)
    if motion == "linear" and np.any(g != 0.0):
        raise ValueError("gravity applies to motion='ballistic': the linear sweep is the "
                         "straight segment v dt (use motion='ballistic', or a Simulator for "
                         "whole frames with gravity)")
    return motion, g


def precision_of(name: str) -> fp.Precision:
    """The kernel types of a checked precision name."""
    return fp.precision(check.precision(name))


@dataclass
class Bounces:
    """Result of one frame of multi-bounce motion per sphere (numpy, chosen precision).

    Attributes:
        hit: at least one contact was taken, (N,) bool.
        bounces: contacts taken that reflect the sphere, (N,) int32.
        supports: contacts taken that hold it instead (resting or sliding: gravity presses
            it onto the surface and its normal speed is below the resting threshold; a frame
            holds at most ``max_bounces`` contacts of both kinds together), (N,) int32.
        capped: the ``max_bounces`` cap stopped the sphere at its last contact, (N,) bool.
        position: centre at the end of the frame [m], (N, 3).
        velocity: velocity after the last reflection [m/s], (N, 3).
        angular_momentum: after the contacts' friction torque [kg m^2/s], (N, 3).
    """

    hit: np.ndarray
    bounces: np.ndarray
    supports: np.ndarray
    capped: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    angular_momentum: np.ndarray


def bounce(position, velocity, radius, boxes: RoundedBoxes | RoundedBox, dt: float, *,
           max_bounces: int = 8, mass=1.0, angular_momentum=None, friction: float = 0.0,
           max_angular_speed: float = 50.0, energy_retention: float = 1.0, device=None,
           precision: str = "float32", broad_phase: str = "auto", motion: str = "linear",
           gravity=None) -> Bounces:
    """Move each sphere for ``dt``, bouncing off the boxes .

    At each contact the velocity is reflected and the sphere goes on with the rest of its path,
    until nothing is hit or ``max_bounces`` contacts were taken; the broken line is exactly
    ``|v| dt`` long when ``energy_retention = 1``. When the cap is reached with path left, the
    sphere stays at its last contact with its reflected velocity. Each contact applies the
    friction torque to the angular momentum (``friction > 0``) and keeps ``energy_retention``
    of the kinetic energy (the speed and the rest of the path shrink by its square root). The
    linear motion moves in a straight line and has no gravity; the ballistic one
    follows the parabolas of ``gravity`` for the frame's time (``velocity`` out is then the true
    velocity at the frame's end). See :class:`warpsim.Simulator` for whole frames. Inputs are
    never modified.

    Args:
        position: centres [m], (N, 3). velocity: [m/s], (N, 3). radius: [m], scalar or (N,).
        boxes: the obstacles. dt: frame duration [s], > 0.
        max_bounces: cap on contacts per sphere, >= 1.
        mass: [kg], scalar or (N,), > 0 (for the moment of inertia ``2/5 m r^2``).
        angular_momentum: [kg m^2/s], (N, 3); None for zero.
        friction: ``k_f`` [kg/s] of the contact friction, >= 0.
        max_angular_speed: clamp on ``|L| / I`` [rad/s], > 0.
        energy_retention: kept fraction of kinetic energy per contact, in (0, 1].
        device: Warp device. precision: ``"float32"`` or ``"float64"``.
        broad_phase: ``"auto"``, ``"bvh"``, ``"grid"``, ``"walk"`` or ``"brute"``, as in
            :func:`collide_boxes`
            (bit-identical results).
        motion, gravity: as in :func:`collide_boxes`.

    Raises:
        ValueError: a bad input, naming the field and the index.
    """
    motion, g = _motion_and_gravity(motion, gravity)
    boxes, pos, vel, rad = check.sphere_batch(position, velocity, radius, boxes)
    # the same checks as a Swarm's and a Scene's, so the messages are the same too
    swarm = Swarm(pos, vel, radius=rad, mass=mass, angular_momentum=angular_momentum)
    mas, mom, n = swarm.mass, swarm.angular_momentum, len(swarm)
    settings = check.scene_settings({"dt": dt, "max_bounces": max_bounces, "friction": friction,
                                     "max_angular_speed": max_angular_speed,
                                     "energy_retention": energy_retention})
    dt, max_bounces = settings["dt"], settings["max_bounces"]
    friction, max_rot = settings["friction"], settings["max_angular_speed"]
    retention = settings["energy_retention"]
    p = precision_of(precision)
    dev = resolve_device(device)
    # one query a sphere, and one more a contact (not known before the launch)
    method, grid = broad.choose(broad_phase, boxes, broad.paths(pos, vel, rad, g, dt),
                                p.np_dtype, queries=n)
    kernel = bounce_kernel(Features(precision=p.name, motion=motion, broad_phase=method,
                                    spin=friction > 0.0, lossy=retention < 1.0))
    model = put_model(boxes, p, dev, broad_phase=method, grid=grid, dt=dt, gravity=g,
                      friction=friction,
                      max_angular_speed=max_rot, energy_retention=retention,
                      max_bounces=max_bounces)
    spheres = Spheres(radius=to_device(rad, p.scalar, p, dev),
                      mass=to_device(mas, p.scalar, p, dev))
    state = {"position": to_device(pos, p.vec3, p, dev),
             "velocity": to_device(vel, p.vec3, p, dev),
             "angular_momentum": to_device(mom, p.vec3, p, dev)}
    out = {name: wp.empty(n, dtype=wp.int32, device=dev)
           for name in ("bounces_out", "supports_out", "capped_out")}
    for name in ("position_out", "velocity_out", "angular_momentum_out"):
        out[name] = wp.empty(n, dtype=p.vec3, device=dev)
    launch(kernel, n, dev, model=model, spheres=spheres, state_in=state, outputs=out,
           launch_outputs={"events_out": event_buffer(p, dev, 0)})
    outs = [out["position_out"], out["velocity_out"], out["angular_momentum_out"]]
    b, s = out["bounces_out"].numpy(), out["supports_out"].numpy()
    x, v, L = (o.numpy() for o in outs)
    return Bounces(hit=(b + s) > 0, bounces=b, supports=s, capped=out["capped_out"].numpy() > 0,
                   position=x, velocity=v, angular_momentum=L)
