"""Independent float64 references for a parabolic arc against a rounded box (test support only).

The kernels find the first contact of ``x(s) = a + v s + 1/2 g s^2`` through the grown box's
windows and a walk over the pieces between slab crossings. The references here take other
routes:

* :func:`arc_contact_by_features` (primary) enumerates **all 26 features** of the Minkowski sum
  in the box's local frame: 6 face rectangles (a quadratic in ``s`` each), 12 edge cylinders and
  8 corner spheres (a quartic each), takes every real root in ``[0, tau]`` from
  ``numpy.roots``, polishes it by Newton on the polynomial, keeps those on the feature's patch
  where the arc goes in, and returns the smallest.
* :func:`arc_contact_by_sampling` (secondary) evaluates only the exact signed distance along the
  arc at dense samples and bisects the first sign change: it can miss a dip thinner than the
  sampling, so it is a cross-check for arcs that pass well clear of grazing.

Contract (as the kernels'): the arc starts outside the rounded box; ``s`` in [0, tau] is the
first time it reaches distance ``R`` of the core box ``[-h, h]`` while moving in; the normal is
the unit outward normal there (local frame). No hit: ``(False, tau, 0)``. Starts in contact are
not handled here (the tests build those analytically).
"""

from __future__ import annotations

import itertools

import numpy as np

#: A root of the feature polynomials counts as real when its imaginary part is below this
#: fraction of the time span (numpy.roots returns a double root as a close complex pair).
IMAG_REL = 1.0e-6

#: Patch membership slack [m] (relative to the local scale): a root on the boundary between two
#: patches belongs to both; this only admits the same contact twice.
PATCH_REL = 1.0e-9

#: A root counts only where its point lies on the rounded box's surface to this fraction of the
#: local scale: a near miss that ``numpy.roots`` returns as a close complex pair (a "double
#: root") is not a contact (an arc at 1e3 m/s passing 2.8 cm from a sharp edge, R = 0, was taken
#: for one).
SURFACE_REL = 1.0e-6

#: Newton iterations polishing a root of ``numpy.roots`` (quadratic convergence from 1e-8).
POLISH_STEPS = 8


def arc_point(a, v, g, s):
    """``a + v s + 1/2 g s^2`` [m] (broadcasts over ``s``)."""
    s = np.asarray(s, float)[..., None]
    return a + v * s + 0.5 * g * s * s


def signed_distance(x, h, radius):
    """Signed distance [m] from local points ``x`` (..., 3) to the rounded box."""
    q = np.abs(x) - h
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
    inside = np.minimum(q.max(axis=-1), 0.0)
    return outside + inside - radius


def _polish(poly: np.ndarray, s: float) -> float:
    d = np.polyder(poly)
    for _ in range(POLISH_STEPS):
        slope = np.polyval(d, s)
        if slope == 0.0:
            break
        s = s - np.polyval(poly, s) / slope
    return s


def _roots_in(poly: np.ndarray, tau: float) -> list[float]:
    """Real roots in [0, tau] of the polynomial (coefficients, highest power first)."""
    coeffs = np.trim_zeros(np.asarray(poly, float), "f")
    if coeffs.size <= 1:
        return []
    out = []
    for z in np.roots(coeffs):
        if abs(z.imag) <= IMAG_REL * max(tau, 1.0):
            s = _polish(coeffs, float(z.real))
            if -1e-12 * tau <= s <= tau * (1.0 + 1e-12):
                out.append(min(max(s, 0.0), tau))
    return out


def arc_contact_by_features(a, v, g, tau, h, radius):
    """First entering contact of the arc with the rounded box, over all 26 features.

    Args:
        a, v, g: start [m], velocity [m/s] and acceleration [m/s^2], local frame, (3,).
        tau: time span [s]. h: core half extents [m]. radius: Minkowski radius ``R`` [m].

    Returns:
        ``(hit, s, normal)``.
    """
    a, v, g, h = (np.asarray(x, float) for x in (a, v, g, h))
    coord = [np.array([0.5 * g[i], v[i], a[i]]) for i in range(3)]
    sq = np.convolve  # polynomial product, no trimming of leading zeros
    scale = max(1.0, np.abs(a).max(), h.max() + radius)
    slack = PATCH_REL * scale
    best = (False, tau, np.zeros(3))

    def consider(s, normal_fn, on_patch):
        nonlocal best
        x = arc_point(a, v, g, s)
        if not on_patch(x) or abs(signed_distance(x, h, radius)) > SURFACE_REL * scale:
            return
        n = normal_fn(x)
        if np.dot(v + g * s, n) >= 0.0:
            return
        if not best[0] or s < best[1]:
            best = (True, s, n)

    for i, side in itertools.product(range(3), (-1.0, 1.0)):
        plane = side * coord[i] - np.array([0.0, 0.0, h[i] + radius])
        others = [j for j in range(3) if j != i]
        normal = np.zeros(3)
        normal[i] = side
        for s in _roots_in(plane, tau):
            consider(s, lambda x, n=normal: n,
                     lambda x, o=others: all(abs(x[j]) <= h[j] + slack for j in o))
    for k in range(3):
        i, j = (m for m in range(3) if m != k)
        for si, sj in itertools.product((-1.0, 1.0), repeat=2):
            wi = si * coord[i] - np.array([0.0, 0.0, h[i]])
            wj = sj * coord[j] - np.array([0.0, 0.0, h[j]])
            poly = sq(wi, wi) + sq(wj, wj) - np.array([0.0, 0.0, 0.0, 0.0, radius * radius])

            def normal_fn(x, i=i, j=j, si=si, sj=sj):
                n = np.zeros(3)
                n[i] = si * x[i] - h[i]
                n[j] = sj * x[j] - h[j]
                n[i] *= si
                n[j] *= sj
                return n / np.linalg.norm(n)

            def on_patch(x, i=i, j=j, k=k, si=si, sj=sj):
                return (abs(x[k]) <= h[k] + slack and si * x[i] >= h[i] - slack
                        and sj * x[j] >= h[j] - slack)

            for s in _roots_in(poly, tau):
                consider(s, normal_fn, on_patch)
    for signs in itertools.product((-1.0, 1.0), repeat=3):
        ws = [signs[i] * coord[i] - np.array([0.0, 0.0, h[i]]) for i in range(3)]
        poly = (sq(ws[0], ws[0]) + sq(ws[1], ws[1]) + sq(ws[2], ws[2])
                - np.array([0.0, 0.0, 0.0, 0.0, radius * radius]))

        def normal_fn(x, signs=signs):
            n = np.array([signs[i] * (signs[i] * x[i] - h[i]) for i in range(3)])
            return n / np.linalg.norm(n)

        def on_patch(x, signs=signs):
            return all(signs[i] * x[i] >= h[i] - slack for i in range(3))

        for s in _roots_in(poly, tau):
            consider(s, normal_fn, on_patch)
    return best


def arc_contact_by_sampling(a, v, g, tau, h, radius, samples: int = 4097):
    """First sign change of the exact signed distance along the arc (dense samples, bisection).

    Returns:
        ``(hit, s, min_distance)``: ``min_distance`` [m] is the smallest sampled distance, to
        tell clear misses (and clear hits) from grazing arcs.
    """
    a, v, g, h = (np.asarray(x, float) for x in (a, v, g, h))
    s = np.linspace(0.0, tau, samples)
    f = signed_distance(arc_point(a, v, g, s), h, radius)
    inside = np.flatnonzero(f <= 0.0)
    if inside.size == 0:
        return False, tau, float(f.min())
    k = inside[0]
    if k == 0:
        return True, 0.0, float(f.min())
    lo, hi = s[k - 1], s[k]
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if signed_distance(arc_point(a, v, g, mid), h, radius) > 0.0:
            lo = mid
        else:
            hi = mid
    return True, hi, float(f.min())
