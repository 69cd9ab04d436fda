"""A scene: static obstacles plus the physics settings that apply to every sphere."""

from __future__ import annotations

import os

from . import feasibility
from . import validation as check
from .emitter import Emitter
from .obstacles import RoundedBoxes
from .scene_files import SceneFileError, read_scene_file
from .swarm import joined_swarms

DEFAULT_GRAVITY = (0.0, -9.81, 0.0)


class Scene:
    """Obstacles and physics settings (validated on construction; the dynamics of a frame are
    described in :class:`warpsim.Simulator` and the README's "What it models").

    Args:
        boxes: the static obstacles.
        gravity: gravitational acceleration [m/s^2], world frame; None: that of the stage the
            boxes were read from (:func:`warpsim.obstacles_from_usd`), else ``(0, -9.81, 0)``
            (y up).
        friction: friction coefficient ``k_f`` [kg/s] of ``F_f = -k_f v_t,rel``; 0 disables spin.
        energy_retention: fraction ``k`` in (0, 1] of kinetic energy kept at each contact.
        energy_correction: reset the speed from the energy invariant after each frame; when
            False the speed is only lowered to that bound (energy is never gained). None: the
            motion model's default, on for ``"linear"`` and off for ``"ballistic"`` (whose
            motion conserves the energy itself).
        max_angular_speed: clamp on ``|Rot|`` [rad/s], > 0.
        name: short name (bundled scenes use their file stem).
        description: one line for listings.
        emitter: where spheres come from (see :meth:`spawn`), such as a
            :class:`warpsim.Emitter`; None for scenes whose swarms are built in code.
        dt: default time step [s] for this scene, > 0.
        frames: default number of frames to simulate, >= 1.
        max_bounces: default cap of contacts per sphere per frame, in
            ``[1, warpsim.validation.MAX_BOUNCES]``.
        motion: default motion model: ``"linear"`` (each frame's path is the chord
            ``A -> A + v dt``) or ``"ballistic"`` (the exact parabola of each flight).
        source: the file the scene was read from, if any.

    Raises:
        ValueError: naming the bad argument (the checks are :mod:`warpsim.validation`'s).
    """

    def __init__(self, boxes: RoundedBoxes, gravity=None, friction: float = 0.0,
                 energy_retention: float = 1.0, energy_correction: bool | None = None,
                 max_angular_speed: float = 50.0, *, name: str = "scene",
                 description: str = "", emitter=None, dt: float = 1.0 / 60.0,
                 frames: int = 240, max_bounces: int = 8, motion: str = "linear",
                 source: str | None = None):
        if not isinstance(boxes, RoundedBoxes):
            raise ValueError(f"boxes must be a warpsim.RoundedBoxes, got {type(boxes).__name__}")
        if gravity is None:  # a stage's own gravity, in its axes
            gravity = getattr(getattr(boxes, "stage", None), "gravity", DEFAULT_GRAVITY)
        settings = check.scene_settings(dict(
            gravity=gravity, friction=friction, energy_retention=energy_retention,
            energy_correction=energy_correction, max_angular_speed=max_angular_speed, dt=dt,
            frames=frames, max_bounces=max_bounces, motion=motion))
        self.boxes = boxes
        self.gravity = check.frozen(settings["gravity"])
        self.friction = settings["friction"]
        self.energy_retention = settings["energy_retention"]
        self.motion = settings["motion"]
        self.energy_correction = settings["energy_correction"]
        self.max_angular_speed = settings["max_angular_speed"]
        self.name = str(name)
        self.description = str(description)
        self.emitter = emitter
        self.dt = settings["dt"]
        self.frames = settings["frames"]
        self.max_bounces = settings["max_bounces"]
        self.source = source

    @property
    def energy_correction(self) -> bool:
        """Whether the speed is reset from the energy invariant (for :attr:`motion`)."""
        return self.energy_correction_for(self.motion)

    @energy_correction.setter
    def energy_correction(self, value) -> None:
        self._energy_correction = check.optional_flag("energy_correction", value)

    def energy_correction_for(self, motion: str) -> bool:
        """The energy correction a run with ``motion`` uses: the one given, else that model's
        default (on for ``"linear"``, off for ``"ballistic"``)."""
        if self._energy_correction is not None:
            return self._energy_correction
        return check.motion(motion) == "linear"

    @classmethod
    def load(cls, name_or_path) -> Scene:
        """A bundled scene by name (see :func:`warpsim.list_scenes`) or a TOML file by path.

        Raises:
            warpsim.SceneFileError: (a ``ValueError``) naming the file, table, key and index.
        """
        return cls(**read_scene_file(name_or_path))

    def spawn(self, n: int | None = None, seed: int | None = None, dt: float | None = None):
        """The swarm of this scene's emitter: ``n`` spheres (default: the emitter's count).

        ``dt`` [s] (None: the scene's) is the frame duration the birth frames of an emitter
        that emits over time are counted in (``Emitter.birth_frames``).

        Returns:
            A :class:`warpsim.Swarm`; the same ``seed`` gives the same swarm. No sphere starts
            inside an obstacle: a :class:`warpsim.Emitter` keeps only spheres whose signed
            distance is at least their radius plus the clearance (``>= 0``), by the distances
            ``warpsim.feasibility.check_outside`` reads, so that check could never refuse one;
            any other emitter's swarm is checked with it.

        Raises:
            ValueError: when the scene has no emitter, for a bad ``n`` or ``seed``, or when the
                emitter cannot place its spheres; for a scene read from a file, the last is a
                :class:`warpsim.SceneFileError` whose message starts with the file's name.
        """
        if self.emitter is None:
            raise ValueError(f"scene {self.name!r} has no emitter; build a warpsim.Swarm instead")
        if n is not None:
            check.positive_int("n", n)
        if seed is not None:
            check.positive_int("seed", seed, minimum=0)
        try:
            # an emitter of births counts them in frames of dt; any other needs no dt
            timing = ({"dt": self.dt if dt is None else dt}
                      if getattr(self.emitter, "emits_over_time", False) else {})
            swarm = self.emitter.spawn(self.boxes, n=n, seed=seed, **timing)
            if not isinstance(self.emitter, Emitter):  # an emitter of its own: checked here
                feasibility.check_outside(self.boxes, swarm.position, swarm.radius, "float64")
        except ValueError as exc:
            if self.source is None:
                raise
            raise SceneFileError(f"{os.path.basename(self.source)}: {exc}") from exc
        return swarm

    def spawn_many(self, counts, seeds, dt: float | None = None, join: bool = False) -> list:
        """Several swarms of this scene's emitter at once, each as ``spawn(n, seed, dt)`` gives
        it bit for bit (:meth:`warpsim.Emitter.spawn_many`: the clearance of all of them tested
        together); ``counts`` (each >= 1) and ``seeds`` (each >= 0) pair up. ``join``: one
        swarm, those one after the other (:meth:`warpsim.Emitter.spawn_many`'s ``join``).

        Raises:
            ValueError: as :meth:`spawn`.
        """
        if self.emitter is None:
            raise ValueError(f"scene {self.name!r} has no emitter; build a warpsim.Swarm instead")
        counts = [check.positive_int("n", n) for n in counts]
        seeds = [check.positive_int("seed", seed, minimum=0) for seed in seeds]
        if not isinstance(self.emitter, Emitter):
            swarms = [self.spawn(n, seed, dt) for n, seed in zip(counts, seeds, strict=True)]
            return [joined_swarms(swarms)] if join else swarms
        try:
            return self.emitter.spawn_many(
                self.boxes, counts, seeds,
                (self.dt if dt is None else dt) if self.emitter.emits_over_time else None,
                join=join)
        except ValueError as exc:
            if self.source is None:
                raise
            raise SceneFileError(f"{os.path.basename(self.source)}: {exc}") from exc

    def __repr__(self) -> str:
        return f"Scene({self.name!r}, {len(self.boxes)} boxes)"
