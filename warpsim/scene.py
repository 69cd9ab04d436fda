"""A scene: static obstacles plus the physics settings that apply to every sphere."""

from __future__ import annotations

from . import validation as check
from .obstacles import RoundedBoxes

DEFAULT_GRAVITY = (0.0, -9.81, 0.0)


class Scene:
    """Obstacles and physics settings (validated on construction; see SPEC "Dynamics").

    Args:
        boxes: the static obstacles.
        gravity: gravitational acceleration [m/s^2], world frame (y up).
        friction: friction coefficient ``k_f`` [kg/s] of ``F_f = -k_f v_t,rel``; 0 disables spin.
        energy_retention: fraction ``k`` in (0, 1] of kinetic energy kept at each contact.
        energy_correction: reset the speed from the energy invariant after each frame; when
            False the speed is only lowered to that bound (energy is never gained).
        max_angular_speed: clamp on ``|Rot|`` [rad/s], > 0.
        name: short name (bundled scenes use their file stem).
        description: one line for listings.
        emitter: where spheres come from when the scene is loaded from a file (see
            :meth:`spawn`); None for scenes built in code.
        dt: default time step [s] for this scene, > 0.
        frames: default number of frames to simulate, >= 1.
        max_bounces: default cap of contacts per sphere per frame, >= 1.
        source: the file the scene was read from, if any.
    """

    def __init__(self, boxes: RoundedBoxes, gravity=DEFAULT_GRAVITY, friction: float = 0.0,
                 energy_retention: float = 1.0, energy_correction: bool = True,
                 max_angular_speed: float = 50.0, *, name: str = "scene",
                 description: str = "", emitter=None, dt: float = 1.0 / 60.0,
                 frames: int = 240, max_bounces: int = 8, source: str | None = None):
        if not isinstance(boxes, RoundedBoxes):
            raise ValueError(f"boxes must be a warpsim.RoundedBoxes, got {type(boxes).__name__}")
        self.boxes = boxes
        self.gravity = check.frozen(check.vec3("gravity", gravity))
        self.friction = check.scalar("friction", friction, minimum=0.0)
        self.energy_retention = check.scalar("energy_retention", energy_retention,
                                             positive=True, maximum=1.0)
        if not isinstance(energy_correction, bool):
            raise ValueError(f"energy_correction must be true or false, got {energy_correction!r}")
        self.energy_correction = energy_correction
        self.max_angular_speed = check.scalar("max_angular_speed", max_angular_speed,
                                              positive=True)
        self.name = str(name)
        self.description = str(description)
        self.emitter = emitter
        self.dt = check.scalar("dt", dt, positive=True)
        self.frames = check.positive_int("frames", frames)
        self.max_bounces = check.positive_int("max_bounces", max_bounces)
        self.source = source

    @classmethod
    def load(cls, name_or_path) -> Scene:
        """A bundled scene by name (see :func:`warpsim.list_scenes`) or a TOML file by path."""
        from .scene_files import load_scene

        return load_scene(name_or_path)

    def spawn(self, n: int | None = None, seed: int | None = None):
        """The swarm of this scene's emitter: ``n`` spheres (default: the emitter's count).

        Returns:
            A :class:`warpsim.Swarm`; the same ``seed`` gives the same swarm.

        Raises:
            ValueError: when the scene has no emitter.
        """
        if self.emitter is None:
            raise ValueError(f"scene {self.name!r} has no emitter; build a warpsim.Swarm instead")
        return self.emitter.spawn(self.boxes, n=n, seed=seed)

    def __repr__(self) -> str:
        return f"Scene({self.name!r}, {len(self.boxes)} boxes)"
