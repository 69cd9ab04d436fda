"""USD export of warpsim results; imported only when used, so ``import warpsim`` never needs pxr.

Import it as ``warpsim.export``.
"""

if __name__ != "warpsim.export":  # imported as a bare ``export``: the package would load twice
    raise ImportError("import this package as 'warpsim.export', not as 'export'")

# The guard must run first, so these imports come after it on purpose.
from .preview import render_preview  # noqa: E402
from .usd import (  # noqa: E402
    LargeOutputWarning,
    estimate_usd_bytes,
    read_usd,
    read_usd_boxes,
    write_usd,
)

__all__ = [
    "LargeOutputWarning",
    "estimate_usd_bytes",
    "read_usd",
    "read_usd_boxes",
    "render_preview",
    "write_usd",
]
