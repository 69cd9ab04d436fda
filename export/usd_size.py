"""The size of a USD file before it is written: pxr is not loaded here.

:func:`estimate_usd_bytes` is what the command checks against ``--max-bytes`` before any sphere
is drawn; with pxr out of this module, that check does not load pxr (about 0.35 s), which the
command then loads in a process of its own while it simulates
(:mod:`warpsim.export.usd_process`).
"""

from __future__ import annotations

import numpy as np

from .usd_layout import shapes

FORMATS = ("usda", "usdc")
SUFFIXES = (".usdc", ".usda")

# Size model fitted on written files (usd-core 26.11, benchmarks/usd_write.py): bytes = fixed +
# per_frame F + N (per_sphere + F per_sphere_frame) + per_box K + per_shape S (+ the rounded
# shapes' extra). Pairs are (not spinning, spinning): .usdc stores a time sample equal to an
# earlier one once (constant orientations, zero angular velocities), .usda writes every sample.
_SIZE_MODEL = {
    "usdc": {"fixed": 15_200, "per_sphere": 20, "per_frame": 56, "position": 12,
             "orientation": (0, 24), "velocity": 12, "angular_velocity": (0, 12),
             "per_box": 70, "per_shape": 430, "per_rounded_shape": 5_550, "unborn": 1},
    "usda": {"fixed": 64_500, "per_sphere": 68, "per_frame": 57, "position": 40,
             "orientation": (24, 91), "velocity": 36, "angular_velocity": (11, 35),
             "per_box": 400, "per_shape": 1_700, "per_rounded_shape": 28_300, "unborn": 5},
}


def estimate_usd_bytes(n_spheres: int, n_frames: int, fmt: str, *, boxes=None,
                       spinning: bool = True, velocities: bool = False,
                       angular_velocities: bool | None = None, unborn: int = 0) -> int:
    """Estimated size of a file written by :func:`warpsim.export.write_usd` [bytes].

    A linear model fitted on written files (``benchmarks/usd_write.py``, within a few percent
    of the bundled scenes' runs in ``.usdc`` whose spheres do not spin; above the others, by a
    quarter for ``spin``, whose spheres start without spin and so store their first
    orientations once). The ``.usdc`` writer stores a time sample equal
    to an earlier one only once, so what does not change costs nothing per frame: orientations
    of spheres that never spin (no friction, no initial spin) and zero angular velocities. Per
    sphere and frame, ``.usdc``: 12 B of position, 24 B of orientations (quatf + quath) when
    spinning, 12 B each for velocities and angular velocities; ``.usda`` writes every sample as
    text (40 B of position, 24 to 91 B of orientations, about 36 B per velocity). Per box a
    small prim (70 B in ``.usdc``), per distinct shape its mesh (500 B sharp, 6 kB rounded).

    Args:
        n_spheres: spheres written.
        n_frames: recorded frames written (after ``stride``).
        fmt: ``"usda"`` or ``"usdc"`` (a leading dot and any case are accepted).
        boxes: the obstacles written (:class:`warpsim.RoundedBoxes`, a :class:`warpsim.Scene`),
            or None.
        spinning: whether orientations change over time (False: they are stored once).
        velocities: whether ``velocities`` are written.
        angular_velocities: whether ``angularVelocities`` are written (default: with
            ``velocities``).
        unborn: sphere-frames written before their sphere's birth. A file holds every
            sphere at every frame (the unborn at a stand-in position), so they cost what the
            living do, plus their id in ``invisibleIds``: under 1 B in ``.usdc`` (compressed;
            0.3 B measured on the ``nozzle`` scene), 5 B of text in ``.usda``.

    Returns:
        The estimate in bytes.

    Raises:
        ValueError: unknown ``fmt`` or negative counts.
    """
    key = str(fmt).lstrip(".").lower()
    if key not in _SIZE_MODEL:
        raise ValueError(f"fmt must be one of {FORMATS}, got {fmt!r}")
    n, f = int(n_spheres), int(n_frames)
    if n < 0 or f < 0:
        raise ValueError(f"n_spheres and n_frames must be >= 0, got {n_spheres}, {n_frames}")
    if angular_velocities is None:
        angular_velocities = velocities
    m = _SIZE_MODEL[key]
    spin = 1 if spinning else 0
    per_sphere_frame = (m["position"] + m["orientation"][spin]
                        + (m["velocity"] if velocities else 0)
                        + (m["angular_velocity"][spin] if angular_velocities else 0))
    total = (m["fixed"] + m["per_frame"] * f + n * (m["per_sphere"] + f * per_sphere_frame)
             + m["unborn"] * max(int(unborn), 0))
    boxes = getattr(boxes, "boxes", boxes)
    if boxes is not None and len(boxes):
        _, unique = shapes(boxes)
        rounded = int(np.count_nonzero(unique[:, 3] > 0.0))
        total += (m["per_box"] * len(boxes) + m["per_shape"] * len(unique)
                  + m["per_rounded_shape"] * rounded)
    return int(total)


__all__ = ["FORMATS", "SUFFIXES", "estimate_usd_bytes"]
