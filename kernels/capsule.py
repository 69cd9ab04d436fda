"""Segment against a sphere and against a capsule (a segment swept by a sphere).

These are the edge and corner parts of the rounded-box sweep. The entering root of
``|w + t d|^2 = R^2`` (``a t^2 + 2 b t + c = 0`` with ``a = |d|^2``, ``b = w . d``,
``c = |w|^2 - R^2``) is written so that it loses no digits far from the feature:

* the discriminant comes from the perpendicular offset of the line at its closest approach,
  ``b^2 - a c = a (R^2 - |p|^2)`` with ``p = w - (b / a) d``. The textbook ``b^2 - a c``
  subtracts two numbers of size ``|w|^2 |d|^2``; its error, ``eps |w|^2 / R`` on the path's
  distance from the feature, hid a ball of 5 cm from a float32 path 300 m away. The form from
  ``p`` errs by ``eps |w|`` there: the rounding of the start point itself.
* the root is ``t = c / (-b + sqrt(disc))`` (``b < 0``), the cancellation-free member of the
  pair ``q / a``, ``c / q`` with ``q = -(b + sign(b) sqrt(disc))``: it never divides by ``a``
  (near zero for a direction along the capsule axis) and the sum has no cancellation.
"""


from functools import cache
from types import SimpleNamespace

import warp as wp

from .precision import Precision


@cache
def capsule_funcs(p: Precision) -> SimpleNamespace:
    """Build the sphere and capsule ``@wp.func``s for one precision.

    Returns:
        Namespace with ``segment_sphere`` and ``segment_capsule``.
    """
    scalar, vec3 = p.scalar, p.vec3
    ZERO = scalar(0.0)
    ONE = scalar(1.0)

    @wp.func
    def entry_root(w: vec3, d: vec3, radius: scalar):
        """First ``t`` in [0, 1] where ``|w + t d|`` falls to ``radius``, from ``|w| > radius``.

        ``w`` is the start's offset from the centre (or from the axis, both projected on the
        plane across it), ``d`` the motion (projected alike). Stable forms: module docstring.

        Returns:
            ``(hit, t)``; no hit when moving away or tangent (``w . d >= 0``), when the line
            passes outside (the closest approach ``|p| > radius``) or when the root lies beyond
            ``t = 1``.
        """
        hit = int(0)
        t = ONE
        b = wp.dot(w, d)
        a2 = wp.dot(d, d)
        if b < ZERO and a2 > ZERO:
            p = w - (b / a2) * d  # the offset at the closest approach
            disc = a2 * (radius * radius - wp.dot(p, p))
            if disc >= ZERO:
                root = (wp.dot(w, w) - radius * radius) / (-b + wp.sqrt(disc))
                if root <= ONE:
                    hit = 1
                    t = root
        return hit, t

    @wp.func
    def segment_sphere(a: vec3, d: vec3, center: vec3, radius: scalar):
        """Segment ``a + t d``, ``t`` in [0, 1], against the ball of ``radius`` at ``center``.

        Returns:
            ``(hit, t, normal)`` with the unit outward normal at the contact. A start on or
            inside the ball is a hit at ``t = 0`` (the caller decides whether the motion goes
            in); no hit leaves ``t = 1`` and a zero normal.
        """
        w = a - center
        c = wp.dot(w, w) - radius * radius
        hit = int(0)
        t = ONE
        if c <= ZERO:
            hit = 1
            t = ZERO
        else:
            hit, t = entry_root(w, d, radius)
        normal = vec3(ZERO, ZERO, ZERO)
        if hit == 1:
            normal = wp.normalize(w + t * d)
        return hit, t, normal

    @wp.func
    def segment_capsule(a: vec3, d: vec3, e0: vec3, e1: vec3, radius: scalar):
        """Segment ``a + t d``, ``t`` in [0, 1], against the capsule of ``radius`` about ``e0-e1``.

        The infinite cylinder first (the problem in the plane perpendicular to the axis); its
        entry is the hit when it falls between the end caps, else the end sphere on that side
        is the answer. A direction along the axis never enters the cylinder from outside, and a
        start inside the cylinder goes straight to the end sphere it is heading for. A capsule
        of zero length is a sphere.

        Returns:
            ``(hit, t, normal)`` as :func:`segment_sphere`.
        """
        axis = e1 - e0
        length = wp.length(axis)
        hit = int(0)
        t = ONE
        normal = vec3(ZERO, ZERO, ZERO)
        if length <= ZERO:
            hit, t, normal = segment_sphere(a, d, e0, radius)
        else:
            u = axis / length
            w = a - e0
            w_perp = w - wp.dot(w, u) * u
            d_perp = d - wp.dot(d, u) * u
            c = wp.dot(w_perp, w_perp) - radius * radius
            t_cyl = ZERO
            in_cylinder = 1
            if c > ZERO:
                in_cylinder, t_cyl = entry_root(w_perp, d_perp, radius)
            if in_cylinder == 1:
                y = wp.dot(w + t_cyl * d, u)
                if y < ZERO:
                    hit, t, normal = segment_sphere(a, d, e0, radius)
                elif y > length:
                    hit, t, normal = segment_sphere(a, d, e1, radius)
                else:
                    hit = 1
                    t = t_cyl
                    normal = wp.normalize(w_perp + t_cyl * d_perp)
        return hit, t, normal

    return SimpleNamespace(segment_sphere=segment_sphere, segment_capsule=segment_capsule)
