"""Warp started quietly: its native code prints start-up warnings (a missing CUDA driver, say)
with C ``fprintf``, which a one-line interface, or a Dask worker's log, must not show."""

from __future__ import annotations

import contextlib
import os
import sys


@contextlib.contextmanager
def quiet_stderr(enabled: bool):
    """Send file descriptor 2 to the null device: Warp's native code prints its start-up
    warnings (no CUDA driver, say) with C ``fprintf``, which Python cannot intercept."""
    if not enabled:
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(null)


def init_quietly() -> None:
    """``wp.init()`` with standard error silenced (a no-op once Warp is initialised)."""
    import warp as wp

    with quiet_stderr(True):
        wp.init()


__all__ = ["init_quietly", "quiet_stderr"]
