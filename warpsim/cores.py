"""The CPU cores this process may use: how many threads the host-side work (the simulator's
shards, the nearest-box query's blocks) spreads over."""

from __future__ import annotations

import os


def host_cores() -> int:
    """The cores this process may run on (its affinity mask where the platform has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on every platform
        return os.cpu_count() or 1
