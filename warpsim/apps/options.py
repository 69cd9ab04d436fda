"""The options ``warpsim run`` and ``warpsim bench`` share, declared once."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from ..validation import PRECISIONS
from ..vocabulary import BroadPhase, Motion


def add_simulation_options(parser: argparse.ArgumentParser, integer: Callable = int,
                           frames_help: str = "frames to simulate (default: the scene's)") -> None:
    """The scene, ``-n``, ``--frames``, ``--device``, ``--precision``, ``--workers``,
    ``--broad-phase`` and ``--motion``; ``integer`` parses the counts (``int``: checked later,
    with the field's own message; or a type that refuses bad values as a usage error)."""
    parser.add_argument("scene", help="bundled scene name (see 'warpsim scenes') or a .toml path")
    parser.add_argument("-n", "--count", type=integer,
                        help="number of spheres (default: the scene emitter's count)")
    parser.add_argument("--frames", type=integer, help=frames_help)
    parser.add_argument("--device", help="Warp device, e.g. cpu or cuda:0 (default: Warp's)")
    parser.add_argument("--precision", default="float32", choices=PRECISIONS)
    parser.add_argument("--workers", type=integer,
                        help="CPU threads stepping the swarm (default: every core)")
    parser.add_argument("--broad-phase", default=BroadPhase.AUTO, choices=tuple(BroadPhase),
                        help="candidate boxes per sphere: every box (brute), a BVH (bvh), a "
                             "uniform grid's cell at the path's midpoint (grid), the grid's "
                             "cells along each path (walk), or chosen from a cost model "
                             "(auto); the same results; the summary says which ran")
    parser.add_argument("--motion", choices=tuple(Motion),
                        help="path within a frame: the chord or the exact parabola (default: "
                             "the scene's)")
