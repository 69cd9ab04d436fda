"""Where a figure was measured: the one machine description of every benchmark and study
(``warpsim bench``, ``warpsim accuracy``, the scripts of ``benchmarks/``)."""

from __future__ import annotations

import os
import platform
import subprocess
from pathlib import Path

SOURCE = Path(__file__).resolve().parent
"""The package's source folder: the git commit is read from the repository holding it."""


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo`` where there is one, else what Python knows)."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def cpu_id() -> str | None:
    """The CPU's vendor, family, model and stepping from ``/proc/cpuinfo`` (``"AuthenticAMD
    family 23 model 1 stepping 2"``), None where there is none. Two machines with the same
    model name can be different generations, and the kernels' costs differ between them (a
    code form faster on one measured 1.4x slower on another: BENCHMARKS.md, "The grid lookup:
    the branch-free form on another CPU")."""
    fields = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if not line.strip():
                    break  # the first processor's block
                key, _, value = line.partition(":")
                fields[key.strip()] = value.strip()
    except OSError:
        return None
    if "cpu family" not in fields:
        return None
    return (f"{fields.get('vendor_id', '?')} family {fields['cpu family']} "
            f"model {fields.get('model', '?')} stepping {fields.get('stepping', '?')}")


def git_commit(folder: Path = SOURCE) -> dict:
    """``{"commit": hex or None, "dirty": bool or None}`` of the git checkout holding
    ``folder`` (None where it is not one, or git is missing); ``dirty``: tracked files differ
    from the commit."""
    def git(*args) -> str | None:
        try:
            done = subprocess.run(["git", *args], cwd=folder, capture_output=True, text=True,
                                  timeout=10, check=False)
        except (OSError, subprocess.SubprocessError):
            return None
        return done.stdout.strip() if done.returncode == 0 else None

    commit = git("rev-parse", "HEAD")
    if commit is None:
        return {"commit": None, "dirty": None}
    status = git("status", "--porcelain", "--untracked-files=no")
    return {"commit": commit, "dirty": None if status is None else bool(status)}


def machine(device=None) -> dict:
    """Platform, CPU model (and its family, model and stepping, ``cpu_id``), core count, the
    versions (Python, NumPy, Warp, warpsim), the git commit of the source (with ``dirty``),
    and the Warp device when given (a Warp device, or None for none)."""
    import numpy as np
    import warp as wp

    from . import __version__

    info = {"platform": platform.platform(), "cpu": cpu_model(),
            "cpu_id": cpu_id(), "cores": os.cpu_count(),
            "python": platform.python_version(), "numpy": np.__version__,
            "warp": wp.__version__, "warpsim": __version__, **git_commit()}
    if device is not None:
        info.update(device=device.alias, device_name=device.name)
    return info


__all__ = ["cpu_id", "cpu_model", "git_commit", "machine"]
