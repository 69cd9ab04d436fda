"""Positions that keep their precision: a double-precision origin per frame under float32 points.

USD stores instancer positions as float32: at x = 1e5 m that is a 7.8 mm grid, so a float64 run
far from the origin would lose its motion in the file. :func:`frame_origins` gives each written
frame an origin (double3, authored as the time-sampled op ``xformOp:translate:warpsimOrigin`` of
the instancer), and the positions are stored relative to it in float32.

The origin of a frame is the centre of its spheres' bounding box rounded to a multiple of the
grid ``G = 2^k``, the smallest power of two not below the box's largest side nor
:data:`MIN_GRID`: every stored offset is then below ``G`` in magnitude and keeps ``2^-24 G``.
A frame gets an origin only where that gains: when its positions reach :data:`FAR` grid steps
from 0 (else its origin is 0, and a file whose origins are all 0 has no origin op: files of
scenes near the origin are laid out as before). So a file keeps every position to ``2^-16 G``
or better wherever the swarm is (0.015 mm for a swarm up to 1 m across), and to ``2^-24 G``
(60 nm for 1 m) once the swarm is far away. Reading adds origin and offset in float64, where the
sum is exact (the origin is a multiple of ``G``). Float32 runs never get an origin (their
positions are float32 already, stored as they are).
"""

from __future__ import annotations

import numpy as np

ORIGIN_OP = "xformOp:translate:warpsimOrigin"

MIN_GRID = 1.0
"""Smallest origin grid [m]: a single sphere, or spheres on one point, still get a grid step;
offsets below it keep 2^-24 m (6e-8 m)."""

FAR = 256.0
"""Positions below this many grid steps from 0 are stored as they are: float32 keeps them to
``2^-24 * 256 G = 2^-16 G``, and files near the origin keep their plain layout."""


def frame_origins(position: np.ndarray, rows: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """The origin [m] of each written frame: ``(len(rows), 3)`` float64, all zero when no frame
    needs one (see the module docstring) or when the positions are float32.

    Args:
        position: the trajectory's positions (F, N, 3) [m].
        rows: the recorded frames written (row indices into ``position``).
        idx: the spheres written (indices into N).
    """
    origins = np.zeros((rows.size, 3))
    if np.asarray(position).dtype == np.float32 or idx.size == 0:
        return origins
    for k, row in enumerate(rows):
        p = np.asarray(position[row], dtype=np.float64)[idx]
        lo, hi = p.min(axis=0), p.max(axis=0)
        grid = 2.0 ** np.ceil(np.log2(max(float((hi - lo).max()), MIN_GRID)))
        if np.abs(p).max() >= FAR * grid:
            origins[k] = np.round((lo + hi) / (2.0 * grid)) * grid
    return origins + 0.0  # no negative zeros
