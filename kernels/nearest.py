"""The nearest hit over a group of rounded boxes (the sheet's method 2), in world coordinates.

Obstacles are passed as struct-of-arrays (``# Model`` data): centre, rotation matrix (local ->
world), core half extents, rounding radius and the half size of the world-axis-aligned bounding
box (precomputed on the host). :func:`sweep_box_world` is the per-candidate step;
:func:`nearest_hit` feeds it every box (brute force, right for small groups), and another
candidate source (a BVH query) can feed the same step.
"""


from functools import cache
from types import SimpleNamespace

import warp as wp

from .precision import Precision
from .rounded_box import rounded_box_funcs

wp.set_module_options({"enable_backward": False})

#: Relative slack on the bounding-box reject, so rounding in the bounds can never reject a box
#: the segment touches (it only lets a few more boxes through to the exact test).
REJECT_SLACK = 1.0e-3


@cache
def nearest_funcs(p: Precision) -> SimpleNamespace:
    """Build the group-query ``@wp.func``s for one precision.

    Returns:
        Namespace with ``sweep_box_world`` and ``nearest_hit``.
    """
    scalar, vec3, mat33 = p.scalar, p.vec3, p.mat33
    sweep_rounded_box = rounded_box_funcs(p).sweep_rounded_box
    ZERO = scalar(0.0)
    ONE = scalar(1.0)
    SLACK = scalar(1.0 + REJECT_SLACK)
    HALF = scalar(0.5)

    @wp.func
    def sweep_box_world(a: vec3, d: vec3, r: scalar, center: vec3, rotation: mat33,
                        half_extents: vec3, box_radius: scalar, extent: vec3):
        """Sweep of a sphere (centre ``a`` moving by ``d``, radius ``r``) against one box.

        A cheap conservative reject first: no hit when the segment's world bounding box and the
        box's, grown by ``r``, are apart along an axis. Otherwise the exact sweep in the box's
        frame.

        Returns:
            ``(hit, t, normal)`` with the normal in world coordinates (see ``sweep_rounded_box``).
        """
        hit = int(0)
        t = ONE
        normal = vec3(ZERO, ZERO, ZERO)
        mid = a + HALF * d - center
        apart = int(0)
        for i in range(3):
            if wp.abs(mid[i]) > (extent[i] + r) * SLACK + HALF * wp.abs(d[i]):
                apart = 1
        if apart == 0:
            to_local = wp.transpose(rotation)
            hit, t, n_local = sweep_rounded_box(to_local * (a - center), to_local * d,
                                                half_extents, box_radius + r)
            normal = rotation * n_local
        return hit, t, normal

    @wp.func
    def nearest_hit(a: vec3, d: vec3, r: scalar,
                    box_center: wp.array(dtype=vec3), box_rotation: wp.array(dtype=mat33),
                    box_half_extents: wp.array(dtype=vec3), box_radius: wp.array(dtype=scalar),
                    box_extent: wp.array(dtype=vec3)):
        """The first contact over all boxes (smallest ``t``; ties: the lower box index).

        Returns:
            ``(box, t, normal)``: ``box`` is -1 when nothing is hit (then ``t = 1``, normal 0).
        """
        best = int(-1)
        best_t = ONE
        best_n = vec3(ZERO, ZERO, ZERO)
        for k in range(box_center.shape[0]):
            hit, t, normal = sweep_box_world(a, d, r, box_center[k], box_rotation[k],
                                             box_half_extents[k], box_radius[k], box_extent[k])
            if hit == 1 and (best < 0 or t < best_t):
                best = k
                best_t = t
                best_n = normal
        return best, best_t, best_n

    return SimpleNamespace(sweep_box_world=sweep_box_world, nearest_hit=nearest_hit)
