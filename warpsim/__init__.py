"""warpsim: swarms of spheres bouncing among static rounded boxes, with exact continuous
collision detection in NVIDIA Warp kernels, exported as USD animation.

The public surface is the re-exports below; ``warpsim.export`` (USD) is imported on first use.
"""

import warp as _wp

if _wp.config.log_level <= _wp.LOG_INFO:  # no banner nor per-module build lines; warnings print
    _wp.config.log_level = _wp.LOG_WARNING

from .collide import Bounces, Contacts, bounce, collide_box, collide_boxes
from .emitter import Emitter
from .obstacles import RoundedBox, RoundedBoxes
from .scene import Scene
from .scene_files import SceneFileError, list_scenes
from .simulator import Simulator, State, Stats
from .swarm import Swarm
from .trajectory import Trajectory

__all__ = [
    "Bounces",
    "Contacts",
    "Emitter",
    "bounce",
    "collide_box",
    "collide_boxes",
    "RoundedBox",
    "RoundedBoxes",
    "Scene",
    "SceneFileError",
    "Simulator",
    "State",
    "Stats",
    "Swarm",
    "Trajectory",
    "list_scenes",
    "obstacles_from_usd",
]

__version__ = "0.1.0"


def __getattr__(name):
    if name == "export":  # lazy: only users of USD need pxr
        import importlib

        return importlib.import_module(".export", __name__)
    if name == "obstacles_from_usd":  # lazy: reading a stage needs pxr
        from .export.stage_in import obstacles_from_usd

        return obstacles_from_usd
    if name in ("reference", "error_report", "accuracy", "distributed"):  # lazy: optional parts
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'warpsim' has no attribute {name!r}")
