"""USD export of warpsim results; imported only when used, so ``import warpsim`` never needs pxr.

Import it as ``warpsim.export``.
"""

if __name__ != "warpsim.export":  # imported as a bare ``export``: the package would load twice
    raise ImportError("import this package as 'warpsim.export', not as 'export'")

# The guard must run first, so these imports come after it on purpose.
from .files import check_writable  # noqa: E402
from .preview import draw_frame, render_preview  # noqa: E402
from .usd import (  # noqa: E402
    LargeOutputWarning,
    estimate_usd_bytes,
    half_orientations,
    read_usd,
    read_usd_boxes,
    read_usd_frame,
    usd_format,
    write_usd,
)

__all__ = [
    "LargeOutputWarning",
    "check_writable",
    "draw_frame",
    "estimate_rerun_bytes",
    "estimate_usd_bytes",
    "half_orientations",
    "read_usd",
    "read_usd_boxes",
    "read_usd_frame",
    "render_movie",
    "render_preview",
    "usd_format",
    "usd_to_rerun",
    "write_rerun",
    "write_usd",
]


def __getattr__(name):
    if name == "render_movie":  # imageio is an optional extra: loaded on first use
        from .movie import render_movie

        return render_movie
    if name in ("write_rerun", "usd_to_rerun", "estimate_rerun_bytes"):  # rerun-sdk: on use
        from . import rerun

        return getattr(rerun, name)
    raise AttributeError(f"module 'warpsim.export' has no attribute {name!r}")
