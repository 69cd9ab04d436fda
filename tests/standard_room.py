"""The standard room rebuilt from its recipe: an independent reference for ``scenes/room.toml``.

The bundled file lists the room's boxes in full precision; this draws them again from the seed
they came from, so a test can check that the file still holds exactly that room.
"""

import numpy as np

import warpsim as ws

ROOM_HALF = np.array([5.0, 3.0, 5.0])
"""Inner half size of the room [m]; its inner floor is at y = 0."""
WALL_THICKNESS = 0.1
"""[m]"""
ROOM_PLATES = 16
PLATE_ROUNDING = 0.02
"""Rounding radius [m] of the plates (their core has zero thickness)."""
ROOM_SEED = 7
PLATE_MARGIN = 1.5
"""[m] > sqrt(2) x 1 m + rounding: the plates stay clear of the walls."""


def random_rotations(rng: np.random.Generator, k: int) -> np.ndarray:
    """``k`` uniformly random unit quaternions (x, y, z, w)."""
    q = rng.normal(size=(k, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def standard_room() -> ws.RoundedBoxes:
    """6 walls around an inner 10 x 6 x 10 m space (floor at y = 0) and 16 randomly rotated
    rounded plates (half sides 0.3 to 1 m) from a fixed seed."""
    hx, hy, hz = ROOM_HALF
    w = WALL_THICKNESS / 2  # walls overlap at the edges: no gap at any corner
    center = [(0, -w, 0), (0, 2 * hy + w, 0), (-hx - w, hy, 0), (hx + w, hy, 0),
              (0, hy, -hz - w), (0, hy, hz + w)]
    half = ([(hx + 2 * w, w, hz + 2 * w)] * 2 + [(w, hy + 2 * w, hz + 2 * w)] * 2
            + [(hx + 2 * w, hy + 2 * w, w)] * 2)
    walls = ws.RoundedBoxes(center, half)
    rng = np.random.default_rng(ROOM_SEED)
    m = PLATE_MARGIN
    plate_center = rng.uniform((-hx + m, m, -hz + m), (hx - m, 2 * hy - m, hz - m),
                               size=(ROOM_PLATES, 3))
    plate_half = np.column_stack([rng.uniform(0.3, 1.0, ROOM_PLATES), np.zeros(ROOM_PLATES),
                                  rng.uniform(0.3, 1.0, ROOM_PLATES)])
    plates = ws.RoundedBoxes(plate_center, plate_half, random_rotations(rng, ROOM_PLATES),
                             PLATE_ROUNDING)
    return ws.RoundedBoxes.concatenate([walls, plates])
