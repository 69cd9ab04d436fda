"""The engine settings the comparison runs, and which of them this machine can run."""

from __future__ import annotations

import importlib.metadata
import importlib.util
from collections.abc import Callable
from dataclasses import dataclass

from .workload import Workload


@dataclass(frozen=True)
class Setting:
    """One row family of the table: an engine with its options.

    Attributes:
        key: unique name (JSON, ``--engines``). engine: the package it needs (None: only
        warpsim and NumPy). make: builds the driver for a workload.
    """

    key: str
    engine: str | None
    make: Callable[[Workload], object]


def _warpsim(precision: str, motion: str = "linear"):
    def make(work: Workload):
        from .warpsim_driver import WarpsimDriver

        return WarpsimDriver(work, precision=precision, motion=motion)
    return make


def _numpy(work: Workload):
    from .numpy_driver import NumpyDriver

    return NumpyDriver(work)


def _pybullet(ccd: bool):
    def make(work: Workload):
        from .pybullet_driver import PybulletDriver

        return PybulletDriver(work, ccd=ccd)
    return make


def _mujoco(speculative: bool):
    def make(work: Workload):
        from .mujoco_driver import MujocoDriver

        return MujocoDriver(work, speculative=speculative)
    return make


def _newton(speculative: bool):
    def make(work: Workload):
        from .newton_driver import NewtonDriver

        return NewtonDriver(work, speculative=speculative)
    return make


SETTINGS = (
    Setting("warpsim-float32", None, _warpsim("float32")),
    Setting("warpsim-float64", None, _warpsim("float64")),
    Setting("warpsim-ballistic-float32", None, _warpsim("float32", "ballistic")),
    Setting("warpsim-ballistic-float64", None, _warpsim("float64", "ballistic")),
    Setting("numpy-discrete", None, _numpy),
    Setting("pybullet", "pybullet", _pybullet(False)),
    Setting("pybullet-ccd", "pybullet", _pybullet(True)),
    Setting("mujoco", "mujoco", _mujoco(False)),
    Setting("mujoco-speculative", "mujoco", _mujoco(True)),
    Setting("newton-xpbd", "newton", _newton(False)),
    Setting("newton-xpbd-speculative", "newton", _newton(True)),
)
BASELINE = "warpsim-float32"
"""The setting every time is divided by."""

PACKAGES = {"pybullet": "pybullet", "mujoco": "mujoco", "newton": "newton"}
"""Engine -> distribution name, for the versions in the report."""


def unavailable(setting: Setting) -> str | None:
    """Why ``setting`` cannot run here (one line), or None when it can."""
    if setting.engine is None:
        return None
    if importlib.util.find_spec(setting.engine) is None:
        return f'{setting.engine} is not installed (pip install "warpsim[peers]")'
    if setting.key == "mujoco-speculative":
        from .mujoco_driver import speculative_available

        if not speculative_available():
            return "this MuJoCo has no speculative contacts (new in 4.0)"
    return None


def versions() -> dict:
    """Installed versions of warpsim, Warp, NumPy and the peer engines (None: missing)."""
    out = {}
    for name in ("warpsim", "warp-lang", "numpy", *PACKAGES.values(), "matplotlib"):
        try:
            out[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            out[name] = None
    return out
