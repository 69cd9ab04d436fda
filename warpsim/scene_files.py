"""Scene files (TOML): reading bundled and user scenes into :class:`warpsim.Scene`."""

from __future__ import annotations


def list_scenes():
    raise NotImplementedError("scene files are not implemented yet")


def load_scene(name_or_path):
    raise NotImplementedError("scene files are not implemented yet")
