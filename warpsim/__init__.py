"""warpsim: swarms of spheres bouncing among static rounded boxes, with exact continuous
collision detection in NVIDIA Warp kernels, exported as USD animation.

The public surface is the re-exports below; ``warpsim.export`` (USD), ``warpsim.analysis`` (the
exact reference, the error report, the accuracy study) and ``warpsim.distributed`` (Dask) are
imported on first use.
"""

import warp as _wp

if _wp.config.log_level <= _wp.LOG_INFO:  # no banner nor per-module build lines; warnings print
    _wp.config.log_level = _wp.LOG_WARNING

from .collide import Bounces, Contacts, bounce, collide_box, collide_boxes
from .emitter import Emitter
from .events import ContactEvents
from .feasibility import PrecisionWarning
from .obstacles import RoundedBox, RoundedBoxes
from .scene import Scene
from .scene_files import SceneFileError, list_scenes
from .simulator import Simulator, State, Stats
from .swarm import Swarm
from .trajectory import Trajectory
from .vocabulary import BroadPhase, ContactKind, Motion

__all__ = [
    "Bounces",
    "BroadPhase",
    "ContactEvents",
    "ContactKind",
    "Contacts",
    "Emitter",
    "Motion",
    "PrecisionWarning",
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
    if name in ("analysis", "distributed"):  # lazy: the reference, the studies, Dask
        import importlib

        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'warpsim' has no attribute {name!r}")
