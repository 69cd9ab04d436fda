"""Segment against an axis-aligned box centred at the origin (the slab test), in that box's frame.

This is the first stage of the rounded-box sweep: the segment against the box grown by the
Minkowski radius on every face (the rounded box's OBB).
"""


from functools import cache
from types import SimpleNamespace

import warp as wp

from .precision import Precision


@cache
def slab_funcs(p: Precision) -> SimpleNamespace:
    """Build the slab-test ``@wp.func``s for one precision.

    Returns:
        Namespace with ``segment_slab``.
    """
    scalar, vec3 = p.scalar, p.vec3
    PARALLEL_REL = scalar(p.parallel_rel)
    NO_ENTRY = scalar(-1.0)  # any t_enter < 0 means "starts inside the slab intersection"

    @wp.func
    def segment_slab(a: vec3, d: vec3, g: vec3):
        """Segment ``a + t d``, ``t`` in [0, 1], against the box ``[-g, g]`` (local frame).

        A direction component with ``|d_i| <= PARALLEL_REL * max|d|`` is parallel to slab ``i``:
        it never divides; the segment misses when ``|a_i| > g_i`` and slab ``i`` puts no
        bound on ``t`` otherwise. A point on a slab plane counts as inside (closed box).

        Returns:
            ``(hit, t_enter, t_exit, axis)``: ``hit`` is 1 when the closed box and the segment
            meet; ``t_enter`` is the first parameter inside the box, negative when ``a`` is
            inside, and ``axis`` the slab whose plane is crossed there (-1 when ``a`` is inside).
        """
        dmax = wp.max(wp.max(wp.abs(d[0]), wp.abs(d[1])), wp.abs(d[2]))
        t_enter = NO_ENTRY
        t_exit = scalar(1.0)
        axis = int(-1)
        hit = int(1)
        for i in range(3):
            if wp.abs(d[i]) <= PARALLEL_REL * dmax:
                if wp.abs(a[i]) > g[i]:
                    hit = 0
            else:
                t1 = (-g[i] - a[i]) / d[i]
                t2 = (g[i] - a[i]) / d[i]
                t_near = wp.min(t1, t2)
                t_far = wp.max(t1, t2)
                if t_near > t_enter:
                    t_enter = t_near
                    axis = i
                t_exit = wp.min(t_exit, t_far)
        if t_enter > t_exit or t_enter > scalar(1.0) or t_exit < scalar(0.0):
            hit = 0
        if t_enter < scalar(0.0):
            axis = -1
        return hit, t_enter, t_exit, axis

    return SimpleNamespace(segment_slab=segment_slab)
