"""A parabolic arc against a rounded box: the ballistic sweep, in the box's local frame.

Under constant gravity the sphere's centre follows ``x(s) = a + v s + 1/2 g s^2`` exactly. It
touches the rounded box (core half extents ``h``, Minkowski radius ``R = rb + r``) when it reaches
distance ``R`` of the core box ``[-h, h]``. Each coordinate is a quadratic in ``s``, so:

0. A cheap exact reject: the arc's range along each local axis over ``[0, tau]`` (its ends and
   its vertex) against the grown box; an axis whose range stays inside needs no roots below.
1. The arc against the grown box ``[-(h + R), h + R]`` (the rounded box's OBB) is exact with
   quadratic roots: per axis the set ``|x_i(s)| <= h_i + R`` is at most two closed windows, and
   the first entry is the first ``s`` inside the windows of all three axes. No entry: no hit.
   When the entry point lies in a face's Voronoi region it is the contact (as in the linear
   sweep); a sharp box (``R`` below rounding) takes the entry face.
2. Otherwise the arc is walked through the *pieces* of ``[s, tau]`` between the times where a
   coordinate crosses ``+-h_i`` (at most 12, quadratic roots). On a piece the set of axes the
   point lies outside the core slab of is fixed, and the squared distance to the core box is a
   polynomial: a face plane's distance is a quadratic (closed-form entering root), an edge
   cylinder's or a corner sphere's squared distance ``F(s) = |w(s)|^2 - R^2`` a quartic. The
   quartic's second derivative is a quadratic, whose roots split the piece into at most three
   parts where ``F`` is convex or concave; on each part an entering root exists iff ``F`` changes
   sign between its ends, or, on a convex part, at the minimum (found by safeguarded Newton on
   ``F'``), and is polished by Newton safeguarded by bisection. No root is skipped: a sign change
   is found wherever one exists; only a touch that never goes below zero (tangent) is no hit.

Starts in contact use the same margin as the linear sweep (``TANGENT_REL``); an arc that starts
on the surface moving along it while gravity pulls it in goes in at once (a hit at ``s = 0``), and
one moving away with gravity pulling it back is searched for its return from half the time it
takes to come back to the tangent plane (the convex body lies behind that plane until then),
unless its outward speed could not lift it out of the touch band (rounding of the velocity, or
of the normal far from the origin): that one goes in at once too.
"""


from functools import cache
from types import SimpleNamespace

import warp as wp

from .precision import Precision
from .rounded_box import rounded_box_funcs

#: A start whose signed distance is within this many ulps of the local scale is *on* the surface:
#: the start-contact rules apply to it, and a search from ``s = 0`` always starts with a positive
#: distance (the quartic's squared distance and the signed distance round differently).
TOUCH_ULPS = 16.0

#: Newton / bisection stops when a step moves ``s`` by at most this many ulps of ``tau``: a
#: position error of that many ulps of the frame's displacement, the chord sweep's own rounding.
ROOT_ULPS = 4.0

#: Iterations of safeguarded Newton, enough for bisection alone from ``tau`` down to
#: ``ROOT_ULPS`` ulps in float64 (50 halvings); Newton normally stops after a handful.
MAX_ROOT_ITERATIONS = 64

#: Pieces of the walk: 12 crossings of the core slabs' planes give at most 13 pieces.
#: The walk is a ``while`` loop that stops at its first piece with nothing left to do: Warp
#: copies the body of a ``for`` over a constant range of up to 16 iterations once per
#: iteration, which made the walk alone a fifth of a ballistic frame kernel's C++ and its first
#: build on the CPU 1.4x as long, for no speed (the same bits). The entry passes and the sharp
#: entries below stay ``for`` loops: as ``while`` loops they made the float32 ballistic frame
#: in the room 1.04 to 1.14x slower (BENCHMARKS.md, "The ballistic walk as a while loop").
MAX_PIECES = 13

#: Passes of the grown-box entry search: each pass but the last moves to the start of a new
#: window, and the three axes have at most two windows each.
MAX_ENTRY_PASSES = 8

#: Attempts at a sharp box's entry: a tangent touch of a face plane is skipped and the search
#: resumes just after it.
MAX_SHARP_ENTRIES = 3


@cache
def arc_funcs(p: Precision) -> SimpleNamespace:
    """Build the arc ``@wp.func``s for one precision.

    Returns:
        Namespace with ``arc_point``, ``quadratic_roots``, ``box_entry`` and
        ``sweep_rounded_box_arc``.
    """
    scalar, vec3, vec4 = p.scalar, p.vec3, p.vec4
    rb = rounded_box_funcs(p)
    rounded_box_distance = rb.rounded_box_distance
    sweep_rounded_box = rb.sweep_rounded_box
    ZERO = scalar(0.0)
    HALF = scalar(0.5)
    ONE = scalar(1.0)
    TWO = scalar(2.0)
    FOUR = scalar(4.0)
    SIX = scalar(6.0)
    NONE = scalar(1.0e30)  # "no such time": far beyond any frame
    TANGENT_REL = scalar(p.tangent_rel)
    SHARP_REL = scalar(p.sharp_rel)
    TOUCH_REL = scalar(TOUCH_ULPS * p.eps)
    ROOT_TOL = scalar(ROOT_ULPS * p.eps)

    @wp.func
    def arc_point(a: vec3, v: vec3, g: vec3, s: scalar):
        """``a + v s + 1/2 g s^2`` [m]."""
        return a + s * (v + (HALF * s) * g)

    @wp.func
    def sign_of(x: scalar):
        """+1 for x >= 0, -1 otherwise."""
        out = ONE
        if x < ZERO:
            out = -ONE
        return out

    @wp.func
    def quadratic_roots(qa: scalar, qb: scalar, qc: scalar):
        """Real roots of ``qa s^2 + qb s + qc = 0`` (stable form, no cancellation).

        Returns:
            ``(count, r1, r2)`` with ``r1 <= r2``: count 2 (a double root gives ``r1 = r2``),
            1 for a linear equation (``r1 = r2``), 0 when there is none.
        """
        count = int(0)
        r1 = NONE
        r2 = NONE
        if qa == ZERO:
            if qb != ZERO:
                count = 1
                r1 = -qc / qb
                r2 = r1
        else:
            disc = qb * qb - FOUR * qa * qc
            if disc >= ZERO:
                count = 2
                q = -HALF * (qb + sign_of(qb) * wp.sqrt(disc))
                if q == ZERO:  # qb = 0 and qc = 0: the double root 0
                    r1 = ZERO
                    r2 = ZERO
                else:
                    x1 = q / qa
                    x2 = qc / q
                    r1 = wp.min(x1, x2)
                    r2 = wp.max(x1, x2)
        return count, r1, r2

    @wp.func
    def axis_windows(c: scalar, b: scalar, qa: scalar, bound: scalar):
        """The times where ``|c + b s + qa s^2| <= bound``, as two closed windows.

        Returns:
            ``vec4(start1, end1, start2, end2)``; an empty window has ``start > end``.
        """
        if qa < ZERO:  # the same set for the negated coordinate, which is convex
            c = -c
            b = -b
            qa = -qa
        w = vec4(NONE, -NONE, NONE, -NONE)
        if qa == ZERO:
            if b == ZERO:
                if wp.abs(c) <= bound:
                    w = vec4(-NONE, NONE, NONE, -NONE)
            else:
                s1 = (bound - c) / b
                s2 = (-bound - c) / b
                w = vec4(wp.min(s1, s2), wp.max(s1, s2), NONE, -NONE)
        else:
            n_hi, p1, p2 = quadratic_roots(qa, b, c - bound)
            if n_hi > 0:
                n_lo, q1, q2 = quadratic_roots(qa, b, c + bound)
                if n_lo > 0 and q1 < q2:
                    w = vec4(p1, q1, q2, p2)
                else:
                    w = vec4(p1, p2, NONE, -NONE)
        return w

    @wp.func
    def window_from(w: vec4, s: scalar):
        """The first time ``>= s`` inside the windows ``w`` (``NONE`` if there is none)."""
        out = NONE
        if w[0] <= w[1] and s <= w[1]:
            out = wp.max(s, w[0])
        elif w[2] <= w[3] and s <= w[3]:
            out = wp.max(s, w[2])
        return out

    @wp.func
    def all_times():
        """The windows of an axis whose coordinate never leaves the bound."""
        return vec4(-NONE, NONE, NONE, -NONE)

    @wp.func
    def box_entry(a: vec3, v: vec3, g: vec3, bound: vec3, s_from: scalar, tau: scalar,
                  contained: wp.vec3i):
        """First time in ``[s_from, tau]`` where the arc is in the closed box ``[-bound, bound]``.

        Exact up to the rounding of the quadratic roots; a zero ``bound`` (a plate) gives
        windows of a single instant, never lost to rounding of a re-evaluation.

        ``contained[i] = 1`` says the coordinate ``i`` stays within its bound over the whole
        span (its windows are then not computed).

        Returns:
            ``(found, s, axis)``: ``axis`` is the slab entered last (-1 when the arc is inside
            at ``s_from``).
        """
        w0 = all_times()
        w1 = all_times()
        w2 = all_times()
        if contained[0] == 0:
            w0 = axis_windows(a[0], v[0], HALF * g[0], bound[0])
        if contained[1] == 0:
            w1 = axis_windows(a[1], v[1], HALF * g[1], bound[1])
        if contained[2] == 0:
            w2 = axis_windows(a[2], v[2], HALF * g[2], bound[2])
        s = s_from
        axis = int(-1)
        found = int(0)
        for _pass in range(MAX_ENTRY_PASSES):
            if found == 0 and s <= tau:
                s_before = s
                s0 = window_from(w0, s)
                if s0 > s:
                    s = s0
                    axis = 0
                s1 = window_from(w1, s)
                if s1 > s:
                    s = s1
                    axis = 1
                s2 = window_from(w2, s)
                if s2 > s:
                    s = s2
                    axis = 2
                if s == s_before and s <= tau:
                    found = 1
        return found, s, axis

    @wp.func
    def slab_crossings(c: scalar, b: scalar, qa: scalar, h: scalar):
        """The times where the coordinate ``c + b s + qa s^2`` equals ``+h`` or ``-h``."""
        out = vec4(NONE, NONE, NONE, NONE)
        n, r1, r2 = quadratic_roots(qa, b, c - h)
        if n > 0:
            out[0] = r1
            out[1] = r2
        n, r1, r2 = quadratic_roots(qa, b, c + h)
        if n > 0:
            out[2] = r1
            out[3] = r2
        return out

    @wp.func
    def next_after(w: vec4, s: scalar, r: scalar):
        """The smallest entry of ``w`` in ``(s, r)``, else ``r``."""
        out = r
        for j in range(4):
            if w[j] > s and w[j] < out:
                out = w[j]
        return out

    @wp.func
    def gap_sq(c0: vec3, c1: vec3, c2: vec3, radius: scalar, s: scalar):
        """``F(s) = |w(s)|^2 - R^2`` and ``F'(s)``, ``w = c0 + c1 s + c2 s^2`` (core offset)."""
        w = c0 + s * (c1 + s * c2)
        dw = c1 + (TWO * s) * c2
        return wp.dot(w, w) - radius * radius, TWO * wp.dot(w, dw)

    @wp.func
    def gap_sq_slope(c0: vec3, c1: vec3, c2: vec3, s: scalar):
        """``F'(s)`` and ``F''(s)`` of :func:`gap_sq`."""
        w = c0 + s * (c1 + s * c2)
        dw = c1 + (TWO * s) * c2
        return TWO * wp.dot(w, dw), TWO * (wp.dot(dw, dw) + TWO * wp.dot(w, c2))

    @wp.func
    def polish_root(c0: vec3, c1: vec3, c2: vec3, radius: scalar, lo: scalar, hi: scalar,
                    tol: scalar):
        """The root of ``F`` in ``[lo, hi]`` given ``F(lo) > 0 >= F(hi)`` and one sign change.

        Newton, safeguarded by bisection: a Newton step that leaves the bracket, or goes the
        wrong way (``F' >= 0``), is replaced by the midpoint; the bracket shrinks every step.
        """
        s = HALF * (lo + hi)
        for _it in range(MAX_ROOT_ITERATIONS):
            f, df = gap_sq(c0, c1, c2, radius, s)
            if f > ZERO:
                lo = s
            else:
                hi = s
            s_next = HALF * (lo + hi)
            if df < ZERO:
                s_newton = s - f / df
                if s_newton > lo and s_newton < hi:
                    s_next = s_newton
            step = wp.abs(s_next - s)
            s = s_next
            if step <= tol or hi <= lo:
                break
        return s

    @wp.func
    def dip_below(c0: vec3, c1: vec3, c2: vec3, radius: scalar, lo: scalar, hi: scalar,
                  tol: scalar):
        """On a part where ``F`` is convex, positive at both ends, falling then rising: a time
        where ``F <= 0``, if any.

        First the convex lower bound (the two end tangents); then Newton on ``F'`` (increasing
        here) safeguarded by bisection towards the minimum, stopping at the first ``F <= 0``.

        Returns:
            ``(found, s)``: ``found`` 1 with ``F(s) <= 0``, else 0.
        """
        found = int(0)
        s_in = hi
        f_lo, d_lo = gap_sq(c0, c1, c2, radius, lo)
        f_hi, d_hi = gap_sq(c0, c1, c2, radius, hi)
        # convex: F >= both tangents; their crossing bounds the minimum from below
        s_x = (f_hi - f_lo + d_lo * lo - d_hi * hi) / (d_lo - d_hi)
        bound = f_lo + d_lo * (s_x - lo)
        if bound <= ZERO:
            s = wp.min(wp.max(s_x, lo), hi)
            for _it in range(MAX_ROOT_ITERATIONS):
                if found == 0:
                    f, df = gap_sq(c0, c1, c2, radius, s)
                    if f <= ZERO:
                        found = 1
                        s_in = s
                    else:
                        if df < ZERO:
                            lo = s
                        else:
                            hi = s
                        df2, ddf = gap_sq_slope(c0, c1, c2, s)
                        s_next = HALF * (lo + hi)
                        if ddf > ZERO:
                            s_newton = s - df2 / ddf
                            if s_newton > lo and s_newton < hi:
                                s_next = s_newton
                        step = wp.abs(s_next - s)
                        s = s_next
                        if step <= tol or hi <= lo:
                            f_end, df_end = gap_sq(c0, c1, c2, radius, s)
                            if f_end <= ZERO:
                                found = 1
                                s_in = s
                            break
        return found, s_in

    @wp.func
    def quartic_entry(c0: vec3, c1: vec3, c2: vec3, radius: scalar, left: scalar, right: scalar,
                      tol: scalar):
        """First entering root of ``F`` in ``[left, right]`` (an edge or corner piece).

        ``F''/2 = 6|c2|^2 s^2 + 6 (c1.c2) s + |c1|^2 + 2 c0.c2`` is an upward parabola in ``s``:
        ``F`` is convex outside its roots and concave between them. A start with ``F(left) <= 0``
        (only within rounding of a piece boundary) is a hit at ``left`` when ``F`` falls there.

        The time origin moves to ``left`` first (``w(left + u) = w_l + u_l u + c2 u^2``): the
        piece starts near the feature, so the coefficients are small there, while ``c0`` and
        ``c1`` of a start far away would cancel in ``|c1|^2 + 2 c0.c2`` and misplace the convex
        parts by ``eps |c0| / |c2|``.

        Returns:
            ``(found, s)``; a root where ``F`` does not fall (a tangent touch) is skipped.
        """
        w_l = c0 + left * (c1 + left * c2)
        u_l = c1 + (TWO * left) * c2
        span = right - left
        n, z1, z2 = quadratic_roots(SIX * wp.dot(c2, c2), SIX * wp.dot(u_l, c2),
                                    wp.dot(u_l, u_l) + TWO * wp.dot(w_l, c2))
        b1 = span
        b2 = span
        if n == 2 and z1 < z2:
            b1 = wp.min(wp.max(z1, ZERO), span)
            b2 = wp.min(wp.max(z2, ZERO), span)
        found = int(0)
        s_hit = span
        lo = ZERO
        for part in range(3):
            hi = span
            if part == 0:
                hi = b1
            elif part == 1:
                hi = b2
            if found == 0 and hi >= lo:
                f_lo, d_lo = gap_sq(w_l, u_l, c2, radius, lo)
                if f_lo <= ZERO:
                    if d_lo < ZERO:
                        found = 1
                        s_hit = lo
                elif hi > lo:
                    f_hi, d_hi = gap_sq(w_l, u_l, c2, radius, hi)
                    bracket = int(0)
                    b_hi = hi
                    if f_hi <= ZERO:
                        bracket = 1
                    elif part != 1 and d_lo < ZERO and d_hi > ZERO:
                        bracket, b_hi = dip_below(w_l, u_l, c2, radius, lo, hi, tol)
                    if bracket == 1:
                        s_root = polish_root(w_l, u_l, c2, radius, lo, b_hi, tol)
                        f_root, d_root = gap_sq(w_l, u_l, c2, radius, s_root)
                        if d_root < ZERO:
                            found = 1
                            s_hit = s_root
            lo = hi
        return found, left + s_hit

    @wp.func
    def face_entry(c0: scalar, c1: scalar, c2: scalar, left: scalar, right: scalar):
        """First entering root in ``[left, right]`` of the face gap ``q = c0 + c1 s + c2 s^2``.

        The entering root is the one where ``q`` falls: the smaller of two for ``c2 > 0``, the
        larger for ``c2 < 0``; a double root is a tangent touch (no hit). A start with
        ``q(left) <= 0`` (rounding at a piece boundary) is a hit at ``left`` when ``q`` falls there.
        The roots are those of ``q(left + u) = q_l + dq_l u + c2 u^2``, small coefficients near
        the face (as in :func:`quartic_entry`).
        """
        found = int(0)
        s_hit = right
        q_l = c0 + left * (c1 + left * c2)
        dq_l = c1 + TWO * c2 * left
        if q_l <= ZERO and dq_l < ZERO:
            found = 1
            s_hit = left
        else:
            e = NONE
            if c2 == ZERO:
                if dq_l < ZERO:
                    e = -q_l / dq_l
            else:
                n, r1, r2 = quadratic_roots(c2, dq_l, q_l)
                if n == 2 and r1 < r2:
                    if c2 > ZERO:
                        e = r1
                    else:
                        e = r2
            if e >= ZERO and e <= right - left:
                found = 1
                s_hit = left + e
        return found, s_hit

    @wp.func
    def walk_pieces(a: vec3, v: vec3, g: vec3, tau: scalar, h: vec3, radius: scalar,
                    s_start: scalar, tol: scalar):
        """First entering contact in ``[s_start, tau]`` by the piece walk (module docstring).

        Returns:
            ``(hit, s, normal)`` in the local frame; no hit: ``s = tau``, normal 0.
        """
        x0 = slab_crossings(a[0], v[0], HALF * g[0], h[0])
        x1 = slab_crossings(a[1], v[1], HALF * g[1], h[1])
        x2 = slab_crossings(a[2], v[2], HALF * g[2], h[2])
        hit = int(0)
        s_hit = tau
        normal = vec3(ZERO, ZERO, ZERO)
        s = s_start
        piece = int(0)
        while piece < MAX_PIECES and hit == 0 and s < tau:
            r = next_after(x0, s, tau)
            r = next_after(x1, s, r)
            r = next_after(x2, s, r)
            xm = arc_point(a, v, g, HALF * (s + r))
            c0 = vec3(ZERO, ZERO, ZERO)
            c1 = vec3(ZERO, ZERO, ZERO)
            c2 = vec3(ZERO, ZERO, ZERO)
            sig = vec3(ZERO, ZERO, ZERO)
            outside = int(0)
            face = int(0)
            for i in range(3):
                if wp.abs(xm[i]) > h[i]:
                    si = sign_of(xm[i])
                    sig[i] = si
                    c0[i] = si * a[i] - h[i]
                    c1[i] = si * v[i]
                    c2[i] = HALF * si * g[i]
                    outside += 1
                    face = i
            if outside == 0:
                # inside the core slab box: reached only through rounding at a boundary
                x = arc_point(a, v, g, s)
                dist, n_in = rounded_box_distance(x, h, radius)
                if wp.dot(v + s * g, n_in) < ZERO:
                    hit = 1
                    s_hit = s
                    normal = n_in
            elif outside == 1:
                found, s_f = face_entry(c0[face] - radius, c1[face], c2[face], s, r)
                if found == 1:
                    hit = 1
                    s_hit = s_f
                    normal = vec3(ZERO, ZERO, ZERO)
                    normal[face] = sig[face]
            else:
                found, s_q = quartic_entry(c0, c1, c2, radius, s, r, tol)
                if found == 1:
                    w = c0 + s_q * (c1 + s_q * c2)
                    size = wp.length(w)
                    if size > ZERO:
                        hit = 1
                        s_hit = s_q
                        normal = wp.cw_mul(sig, w) / size
            s = r
            piece += 1
        return hit, s_hit, normal

    @wp.func
    def local_scale(a: vec3, bound: vec3):
        """The scale [m] of a sweep's local computation: the largest of the grown box's half
        extents ``bound`` and of the start's coordinates ``a`` (its touch band is ``TOUCH_ULPS``
        of it)."""
        return wp.max(wp.max(wp.max(bound[0], bound[1]), bound[2]),
                      wp.max(wp.max(wp.abs(a[0]), wp.abs(a[1])), wp.abs(a[2])))

    @wp.func
    def held_within_rounding(a: vec3, v: vec3, h: vec3, radius: scalar, dist0: scalar,
                             vn: scalar, gn: scalar, slack: scalar):
        """1 when a start within the touch band of the surface (signed distance ``dist0`` [m],
        ``|dist0| <= slack``) that moves away from it (normal speed ``vn > 0`` [m/s]) with
        gravity pressing (``gn < 0`` [m/s^2]) cannot rise above the band, so that its outward
        speed is the rounding of the velocity or of the normal, not a hop.

        Relative to the surface the centre's height is ``dist0 + vn s + 1/2 k s^2``: on a face
        ``k = gn``; on an edge's or a corner's curved part (``a`` outside two or three core
        slabs), which falls away under the tangential motion, ``k = gn + |v_t|^2 / R`` (``v_t``
        the velocity across the edge's axis less its normal part; all of it on a corner).
        When ``k < 0`` its highest point is ``dist0 + vn^2 / (2 |k|)``; at most ``slack``
        above the surface, the arc never leaves the band and goes into the body at once
        (a start just inside, rising too slowly to get out, has no crossing to return
        through: a sphere slowly sliding on a nearly level face, or on a curve far from the
        origin, where a position's rounding turns the normal by ``ulp / R``).
        """
        out = int(0)
        count = int(0)
        v_perp = v
        for i in range(3):
            if wp.abs(a[i]) > h[i]:
                count += 1
            else:
                v_perp[i] = ZERO
        k = gn
        if count >= 2:
            k = ONE  # a point's edge or corner (R = 0): no curvature to hold it
            if radius > ZERO:
                k = gn + wp.max(wp.dot(v_perp, v_perp) - vn * vn, ZERO) / radius
        if k < ZERO and dist0 + vn * vn / (-TWO * k) <= slack:
            out = 1
        return out

    @wp.func
    def sweep_rounded_box_arc(a: vec3, v: vec3, g: vec3, tau: scalar, h: vec3, radius: scalar):
        """First contact of the arc ``x(s) = a + v s + 1/2 g s^2``, ``s`` in [0, tau], with a
        rounded box.

        Local frame of the box. ``h`` are the core half extents (zeros allowed), ``radius`` the
        Minkowski radius ``R = rb + r`` (0 allowed), ``tau`` the time span [s], ``v`` [m/s] and
        ``g`` [m/s^2] the velocity at ``s = 0`` and the acceleration.

        Contract (the linear sweep's, for the arc):
            * A contact counts only while the arc goes into the surface (``x'(s) . n < 0``); a
              tangent touch (an apex exactly on a face, a grazing pass) is no hit.
            * A start on or inside the surface (signed distance within ``TOUCH_ULPS`` of the
              local scale) is a hit at ``s = 0`` with the normal at ``a`` when it moves in
              (``v . n < -TANGENT_REL |v|``), or when it moves along (``|v . n| <= TANGENT_REL
              |v|``) while gravity pulls it in (``g . n < -TANGENT_REL |g|``): the arc then goes
              in at once. Moving away from the surface with gravity pulling it back, the return
              is searched for, except when it could not rise out of the touch band
              (``held_within_rounding``: an outward speed that is rounding): a hit at ``s =
              0``. Otherwise (or from inside the body moving out) no hit.
            * ``g = 0``: the linear sweep of the chord ``a -> a + v tau`` (``s = t tau``).
            * ``tau <= 0`` or a motionless arc never hits.
            * A Minkowski radius below ``SHARP_REL`` of the local scale is a sharp box: the
              grown-box entry is the hit and the normal that of the entry face.

        Returns:
            ``(hit, s, normal)``: ``hit`` 1 or 0, ``s`` in [0, tau] (``tau`` when no hit) and the
            unit outward normal at the contact, local frame (zero when no hit).
        """
        hit = int(0)
        s_hit = tau
        normal = vec3(ZERO, ZERO, ZERO)
        if g[0] == ZERO and g[1] == ZERO and g[2] == ZERO:
            hit_l, t_l, n_l = sweep_rounded_box(a, v * tau, h, radius)
            if hit_l == 1:
                hit = 1
                s_hit = t_l * tau
                normal = n_l
        elif tau > ZERO:
            bound = h + vec3(radius, radius, radius)
            scale = local_scale(a, bound)
            slack = TOUCH_REL * scale
            tol = ROOT_TOL * tau
            # cheap exact reject: the arc's range along each local axis against the grown box
            search = int(1)
            inside_start = int(1)
            contained = wp.vec3i(0, 0, 0)
            for i in range(3):
                qa = HALF * g[i]
                x_end = a[i] + tau * (v[i] + tau * qa)
                lo = wp.min(a[i], x_end)
                hi = wp.max(a[i], x_end)
                if qa != ZERO:
                    s_v = -v[i] / (TWO * qa)
                    if s_v > ZERO and s_v < tau:
                        x_v = a[i] + s_v * (v[i] + s_v * qa)
                        lo = wp.min(lo, x_v)
                        hi = wp.max(hi, x_v)
                if lo > bound[i] + slack or hi < -bound[i] - slack:
                    search = 0
                if lo > -bound[i] and hi < bound[i]:
                    contained[i] = 1
                if wp.abs(a[i]) > bound[i] + slack:
                    inside_start = 0
            s_from = ZERO
            dist0 = scale
            n0 = vec3(ZERO, ZERO, ZERO)
            if search == 1 and inside_start == 1:
                # only a start inside the grown box can be on or in the rounded box
                dist0, n0 = rounded_box_distance(a, h, radius)
            if search == 1 and dist0 <= slack:
                search = 0
                vn = wp.dot(v, n0)
                gn = wp.dot(g, n0)
                speed = wp.length(v)
                if speed == ZERO:
                    vn = ZERO  # |v|^2 underflowed (a speed near 1e-154 m/s or below): no motion
                if vn < -TANGENT_REL * speed:
                    hit = 1
                    s_hit = ZERO
                    normal = n0
                elif vn <= TANGENT_REL * speed:
                    if gn < -TANGENT_REL * wp.length(g):
                        hit = 1
                        s_hit = ZERO
                        normal = n0
                elif gn < ZERO and dist0 >= -TOUCH_REL * scale:
                    if held_within_rounding(a, v, h, radius, dist0, vn, gn, slack) == 1:
                        # "moving away" only by rounding: it never rises out of the touch
                        # band, and goes in at once
                        hit = 1
                        s_hit = ZERO
                        normal = n0
                    else:
                        # on the surface moving away: the convex body stays behind the tangent
                        # plane until the arc comes back to it, at -2 vn / gn
                        s_from = -vn / gn
                        if s_from < tau:
                            search = 1
            if search == 1:
                sharp = radius <= SHARP_REL * scale
                for _attempt in range(MAX_SHARP_ENTRIES):
                    if search == 1:
                        search = 0
                        found, s_e, axis = box_entry(a, v, g, bound, s_from, tau,
                                                          contained)
                        if found == 1:
                            x_e = arc_point(a, v, g, s_e)
                            u_e = v + s_e * g
                            if axis < 0:
                                # inside the grown box at the search's start
                                if sharp:
                                    dist_e, n_e = rounded_box_distance(x_e, h, radius)
                                    if wp.dot(u_e, n_e) < ZERO:
                                        hit = 1
                                        s_hit = s_e
                                        normal = n_e
                                else:
                                    hit, s_hit, normal = walk_pieces(a, v, g, tau, h, radius,
                                                                     s_e, tol)
                            elif sharp:
                                if u_e[axis] != ZERO:
                                    hit = 1
                                    s_hit = s_e
                                    normal[axis] = -sign_of(u_e[axis])
                                else:  # a tangent touch of the face plane: look past it
                                    s_from = s_e + tol
                                    search = 1
                            else:
                                in_face = int(1)
                                for i in range(3):
                                    if i != axis and wp.abs(x_e[i]) > h[i]:
                                        in_face = 0
                                side = sign_of(x_e[axis])
                                if in_face == 1 and side * u_e[axis] < ZERO:
                                    hit = 1
                                    s_hit = s_e
                                    normal[axis] = side
                                else:
                                    hit, s_hit, normal = walk_pieces(a, v, g, tau, h, radius,
                                                                     s_e, tol)
            if hit == 1 and s_hit > ZERO and wp.dot(v + s_hit * g, normal) >= ZERO:
                hit = 0
            if hit == 0:
                s_hit = tau
                normal = vec3(ZERO, ZERO, ZERO)
        return hit, s_hit, normal

    return SimpleNamespace(arc_point=arc_point, quadratic_roots=quadratic_roots,
                           local_scale=local_scale,
                           box_entry=box_entry, sweep_rounded_box_arc=sweep_rounded_box_arc)
