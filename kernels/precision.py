"""Scalar, vector and matrix types for one floating-point precision, and the named tolerances.

Every ``@wp.func`` in this package is built by a factory that takes a :class:`Precision`, so one
source gives a float32 and a float64 instantiation.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
import warp as wp


@dataclass(frozen=True)
class Precision:
    """Warp types and tolerances for one scalar type.

    Attributes:
        name: ``"float32"`` or ``"float64"``.
        scalar: the Warp scalar type.
        vec3, vec4, mat33, quat: the Warp composite types over ``scalar``.
        np_dtype: the matching numpy dtype.
        eps: machine epsilon of ``scalar`` (relative spacing of floats near 1).
    """

    name: str
    scalar: type
    vec3: type
    vec4: type
    mat33: type
    quat: type
    np_dtype: type
    eps: float

    @property
    def parallel_rel(self) -> float:
        """A direction component at most this fraction of the largest one is treated as zero.

        Below one ulp of the largest component, the motion along that axis over the whole
        segment is lost in rounding of the others anyway, and the flag avoids a 0/0.
        """
        return self.eps

    @property
    def tangent_rel(self) -> float:
        """A start in contact moves *in* only when ``d . n < -tangent_rel |d|``.

        A path leaving a contact along the surface carries rounding of a few ulps in ``d . n``;
        without this margin it would count as a new contact at ``t = 0`` again and again.
        """
        return 64.0 * self.eps

    @property
    def sharp_rel(self) -> float:
        """A Minkowski radius ``R`` below this fraction of the local scale is a sharp box.

        The grown-box entry point then lies within ``R`` of the true surface, below the
        rounding of the local coordinates, and a capsule of that radius is not resolvable.
        """
        return 16.0 * self.eps


@cache
def precision(name: str) -> Precision:
    """The :class:`Precision` for ``"float32"`` or ``"float64"``."""
    if name == "float32":
        return Precision(name, wp.float32, wp.vec3f, wp.vec4f, wp.mat33f, wp.quatf,
                         np.float32, float(np.finfo(np.float32).eps))
    if name == "float64":
        return Precision(name, wp.float64, wp.vec3d, wp.vec4d, wp.mat33d, wp.quatd,
                         np.float64, float(np.finfo(np.float64).eps))
    raise ValueError(f"precision must be 'float32' or 'float64', got {name!r}")
