"""USD export of warpsim results; imported only when used, so ``import warpsim`` never needs pxr.

Import it as ``warpsim.export``. The names below load their module (and pxr, Pillow) on first
use, so ``warpsim.export.files`` (standard library only) never loads pxr.
"""

import importlib

if __name__ != "warpsim.export":  # imported as a bare ``export``: the package would load twice
    raise ImportError("import this package as 'warpsim.export', not as 'export'")

#: public name -> the module defining it
_HOMES = {
    "LargeOutputWarning": "usd_write",
    "check_writable": "files",
    "draw_frame": "preview",
    "estimate_rerun_bytes": "rerun",  # rerun-sdk (the viewer extra) is imported when writing
    "estimate_usd_bytes": "usd_size",
    "half_orientations": "usd_write",
    "obstacles_from_usd": "stage_in",
    "read_usd": "usd_read",
    "read_usd_boxes": "usd_read",
    "read_usd_frame": "usd_read",
    "render_movie": "movie",  # imageio is an optional extra, imported when a movie is made
    "render_preview": "preview",
    "usd_format": "usd_write",
    "usd_to_rerun": "rerun",
    "write_rerun": "rerun",
    "write_usd": "usd_write",
}

__all__ = sorted(_HOMES)


def __getattr__(name):
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module 'warpsim.export' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{home}", __name__), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_HOMES))
