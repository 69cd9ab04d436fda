"""Warp's start-up for the applications: initialised quietly (its native code prints start-up
warnings, such as a missing CUDA driver, that a one-line error interface must not show), and a
requested device checked before anything is built."""

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


def init_warp(debug: bool) -> None:
    """Initialise Warp, silently unless ``debug`` (then with its messages and build lines)."""
    import warp as wp

    import warpsim  # noqa: F401  (sets Warp's log level)

    if debug:
        wp.config.log_level = wp.LOG_INFO
    with quiet_stderr(not debug):
        wp.init()


def check_device(name: str | None, debug: bool) -> None:
    """Refuse an unavailable Warp device in one line, before anything is built (Warp's native
    code prints its own CUDA errors while it looks for the device: silenced unless ``debug``).

    Raises:
        ValueError: naming the device.
    """
    if name is None:
        return
    import warp as wp

    try:
        with quiet_stderr(not debug):
            wp.get_device(name)
    except Exception as exc:  # Warp raises RuntimeError or ValueError, with several lines
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"device {name!r} is not available: {first}") from None
