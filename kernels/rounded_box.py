"""Segment against a rounded box: the sheet's method 1, in the box's local frame.

The swept sphere touches the rounded box (core half extents ``h``, rounding ``rb``) when its
centre reaches the Minkowski sum: the rounded box of radius ``R = rb + r``. The sweep follows the
sheet: the segment against the grown OBB (``[-(h + R), h + R]``); when the entry point lies in a
face's Voronoi region (inside that face's rectangle) it is the hit; otherwise the one edge
capsule (edge region) or the three capsules meeting at the corner (corner region) that the entry
point selects are swept and the nearest hit is kept.
"""


from functools import cache
from types import SimpleNamespace

import warp as wp

from .capsule import capsule_funcs
from .precision import Precision
from .slab import slab_funcs


@cache
def rounded_box_funcs(p: Precision) -> SimpleNamespace:
    """Build the rounded-box ``@wp.func``s for one precision.

    Returns:
        Namespace with ``start_contact``, ``sweep_rounded_box`` and ``rounded_box_distance``.
    """
    scalar, vec3 = p.scalar, p.vec3
    segment_slab = slab_funcs(p).segment_slab
    segment_capsule = capsule_funcs(p).segment_capsule
    ZERO = scalar(0.0)
    ONE = scalar(1.0)
    SHARP_REL = scalar(p.sharp_rel)
    TANGENT_REL = scalar(p.tangent_rel)

    @wp.func
    def with_axis_selected(v: vec3, i: int, x: scalar):
        """``v`` with its component ``i`` (a run-time axis) replaced by ``x``, a select per
        component: in registers."""
        return vec3(wp.where(i == 0, x, v[0]), wp.where(i == 1, x, v[1]),
                    wp.where(i == 2, x, v[2]))

    @wp.func
    def with_axis_indexed(v: vec3, i: int, x: scalar):
        """:func:`with_axis_selected` by a write at the index: through memory."""
        out = v
        out[i] = x
        return out

    # The same vector either way. In float64 the write at a run-time index went through the
    # stack and the vector was read back whole, waiting for that write (a store-forwarding
    # stall: benchmarks.store_forwarding): the selects took 0.94 to 0.99x the float64 linear
    # frame. In float32 clang read it back without the wait, and the selects added 1.8 to
    # 2.4 % to the linear frame's instructions (BENCHMARKS.md, "Loads that wait for stores").
    with_axis = with_axis_selected if p.name == "float64" else with_axis_indexed

    @wp.func
    def unit_axis(i: int, sign: scalar):
        """``sign`` times the unit vector of axis ``i``."""
        return with_axis(vec3(ZERO, ZERO, ZERO), i, sign)

    @wp.func
    def sign_of(x: scalar):
        """+1 for x >= 0, -1 otherwise (a point on a symmetry plane picks the + side)."""
        s = ONE
        if x < ZERO:
            s = -ONE
        return s

    @wp.func
    def rounded_box_distance(a: vec3, h: vec3, radius: scalar):
        """Signed distance [m] from local point ``a`` to the rounded box, and the outward normal.

        Outside the core box the normal is the direction from the nearest core point; inside the
        core box it is the normal of the nearest core face (ties: the lower axis; a coordinate
        of 0 picks the + side).

        Returns:
            ``(distance, normal)``; the distance is negative inside.
        """
        q = wp.min(wp.max(a, -h), h)
        w = a - q
        dist = wp.length(w)
        distance = ZERO
        normal = vec3(ZERO, ZERO, ZERO)
        if dist > ZERO:
            distance = dist - radius
            normal = w / dist
        else:
            k = int(0)
            depth = h[0] - wp.abs(a[0])
            for i in range(1, 3):
                di = h[i] - wp.abs(a[i])
                if di < depth:
                    depth = di
                    k = i
            distance = -depth - radius
            normal = unit_axis(k, sign_of(a[k]))
        return distance, normal

    @wp.func
    def start_contact(a: vec3, d: vec3, h: vec3, radius: scalar):
        """Contact state of a segment that starts on or inside the rounded box.

        Returns:
            ``(touching, moving_in, normal)``: ``touching`` is 1 when ``a`` is on or inside the
            surface (signed distance <= 0); ``moving_in`` is 1 when, in addition, ``d`` goes into
            the surface (``d . n < -TANGENT_REL |d|``): that is a hit at ``t = 0``. Moving away
            or along it (within rounding) is not.
        """
        distance, normal = rounded_box_distance(a, h, radius)
        touching = int(0)
        moving_in = int(0)
        if distance <= ZERO:
            touching = 1
            if wp.dot(d, normal) < -TANGENT_REL * wp.length(d):
                moving_in = 1
        return touching, moving_in, normal

    @wp.func
    def closer(hit: int, t: scalar, normal: vec3, hit_b: int, t_b: scalar, normal_b: vec3):
        """The nearer of two hits (the first on ties)."""
        out_hit = hit
        out_t = t
        out_n = normal
        if hit_b == 1 and (hit == 0 or t_b < t):
            out_hit = 1
            out_t = t_b
            out_n = normal_b
        return out_hit, out_t, out_n

    @wp.func
    def sweep_rounded_box(a: vec3, d: vec3, h: vec3, radius: scalar):
        """First contact of the segment ``a + t d``, ``t`` in [0, 1], with a rounded box.

        Local frame of the box. ``h`` are the core half extents (zeros allowed), ``radius`` the
        Minkowski radius ``R = rb + r`` (0 allowed: a point against a sharp box).

        Contract:
            * A contact counts only when the motion goes into the surface (``d . n < 0``); a
              tangent or grazing path, or one leaving the surface, is no hit.
            * A start on or inside the surface moving in is a hit at ``t = 0`` with the normal
              at ``a``; moving away or along it is no hit.
            * A zero-length segment never hits.
            * A Minkowski radius below ``SHARP_REL`` of the local scale is a sharp box: the
              grown-OBB entry is the hit and the normal that of the entry face.

        Returns:
            ``(hit, t, normal)``: ``hit`` 1 or 0, ``t`` in [0, 1] (1 when no hit) and the unit
            outward normal at the contact (zero when no hit).
        """
        hit = int(0)
        t = ONE
        normal = vec3(ZERO, ZERO, ZERO)
        g = h + vec3(radius, radius, radius)
        slab_hit, t_enter, t_exit, axis = segment_slab(a, d, g)
        touching = int(0)
        if slab_hit == 1 and t_enter <= ZERO:
            # only a start inside the grown box can be on or in the rounded box
            touching, moving_in, n0 = start_contact(a, d, h, radius)
            if moving_in == 1:
                hit = 1
                t = ZERO
                normal = n0
        if slab_hit == 1 and touching == 0:
            t_entry = wp.max(t_enter, ZERO)
            pe = a + t_entry * d
            # Region of the entry point: which core slabs it lies outside of. The entry
            # face counts as outside (its coordinate is h + R, or h when R = 0).
            outside = int(0)
            out_axis = int(0)
            for i in range(3):
                if i == axis or wp.abs(pe[i]) > h[i]:
                    outside += 1
                else:
                    out_axis = i  # with 2 outside, the one inside is the edge direction
            scale = wp.max(wp.max(g[0], g[1]), wp.max(g[2], wp.length(a)))
            if outside <= 1 or radius <= SHARP_REL * scale:
                # Face region (or sharp box): the grown-OBB entry is the contact.
                k = axis
                s = ONE
                if k >= 0:
                    s = -sign_of(d[k])  # crossing the plane facing the motion
                else:
                    # starts inside the grown box but outside the rounded one (rounding):
                    # the face it sticks out of the most.
                    k = int(0)
                    best = wp.abs(pe[0]) - h[0]
                    for i in range(1, 3):
                        if wp.abs(pe[i]) - h[i] > best:
                            best = wp.abs(pe[i]) - h[i]
                            k = i
                    s = sign_of(pe[k])
                hit = 1
                t = t_entry
                normal = unit_axis(k, s)
            elif outside == 2:
                corner = vec3(ZERO, ZERO, ZERO)
                for i in range(3):
                    if i != out_axis:
                        corner[i] = sign_of(pe[i]) * h[i]
                e = h[out_axis]
                hit, t, normal = segment_capsule(a, d, with_axis(corner, out_axis, -e),
                                                 with_axis(corner, out_axis, e), radius)
            else:
                corner = vec3(sign_of(pe[0]) * h[0], sign_of(pe[1]) * h[1],
                              sign_of(pe[2]) * h[2])
                for i in range(3):
                    other = corner
                    other[i] = -corner[i]
                    hit_i, t_i, n_i = segment_capsule(a, d, corner, other, radius)
                    hit, t, normal = closer(hit, t, normal, hit_i, t_i, n_i)
            if hit == 1 and wp.dot(d, normal) >= ZERO:
                hit = 0
            if hit == 0:
                t = ONE
                normal = vec3(ZERO, ZERO, ZERO)
        return hit, t, normal

    return SimpleNamespace(rounded_box_distance=rounded_box_distance,
                           start_contact=start_contact,
                           sweep_rounded_box=sweep_rounded_box,
                           closer=closer)
