"""Polygon meshes for export and preview: sharp and rounded boxes, the checkered sphere prototype.

Meshes are returned in USD's layout: ``points`` (P, 3) float64 [m] in the shape's local frame,
``face_vertex_counts`` (F,) int32 and ``face_vertex_indices`` (sum of counts,) int32. Faces are
wound counter-clockwise seen from outside (USD's default ``rightHanded`` orientation), so the
right-hand-rule normal of every face points out of the solid. No module here imports pxr.
"""

from __future__ import annotations

import functools

import numpy as np

QUARTER_TURN = 0.25 * np.pi  # [rad] half of a face's angular span on the cube sphere


def _axis_grid(segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis samples of the cube-sphere grid used by :func:`rounded_box_mesh`.

    Along one axis the grid has ``segments + 2`` entries: the negative side from the cube edge
    (direction component -1) in to the face centre (-0), then the positive side from +0 out to +1.
    The zero is listed twice, once per side, so that offsetting each side by ``-h`` or ``+h``
    opens the flat faces of the box between the two copies.

    Returns:
        ``(side, direction)``: side sign (-1 or +1) and direction component in [-1, 1] of each
        entry, both shape (segments + 2,). The directions are tangents of equally spaced angles,
        so the arcs of the rounding are split evenly.
    """
    half = segments // 2
    tangents = np.tan(np.linspace(0.0, QUARTER_TURN, half + 1))
    tangents[-1] = 1.0  # tan(pi/4) is 0.9999999999999999 in float64: keep the cube edge exact
    direction = np.concatenate([-tangents[::-1], tangents])
    side = np.concatenate([-np.ones(half + 1), np.ones(half + 1)])
    return side, direction


def rounded_box_mesh(half_extents, radius: float, segments: int = 8
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed quad mesh of a rounded box: every point within ``radius`` of the core box ``[-h, h]``.

    The mesh is a subdivided cube ("cube sphere") whose vertices are pushed onto the rounded
    surface: a vertex with outward direction ``n`` (unit) on the side ``s`` (a sign per axis) is
    placed at ``s * h + radius * n``. Each coordinate then lies outside the core slab on its own
    side, so the nearest core point is ``s * h`` and every vertex is at distance exactly
    ``radius`` from the core box (up to float64 rounding). Flat faces are single quads, edges are
    strips of quads, corners are patches of the sphere.

    The topology depends only on ``segments``: it is always a closed, consistently oriented
    2-manifold of genus 0 (every edge shared by exactly two faces, in opposite directions). With
    ``radius = 0`` or a zero half extent some quads have zero area; they are kept so that the
    mesh stays watertight.

    Args:
        half_extents: core half sizes along the local axes [m], shape (3,), each >= 0.
        radius: rounding radius [m], >= 0.
        segments: number of edges along each quarter circle of the rounding; even, >= 2.

    Returns:
        ``(points, face_vertex_counts, face_vertex_indices)``: points (P, 3) float64 [m] in the
        box's local frame with ``P = (segments + 2)**3 - segments**3``, counts (F,) int32 (all 4)
        with ``F = 6 * (segments + 1)**2``, indices (4 F,) int32, faces counter-clockwise seen
        from outside.

    Raises:
        ValueError: bad half extents, radius or segments.
    """
    h = np.asarray(half_extents, dtype=np.float64)
    if h.shape != (3,) or not np.isfinite(h).all() or (h < 0).any():
        raise ValueError(f"half_extents must be 3 finite values >= 0, got {half_extents!r}")
    radius = float(radius)
    if not np.isfinite(radius) or radius < 0:
        raise ValueError(f"radius must be finite and >= 0, got {radius!r}")
    if int(segments) != segments or segments < 2 or segments % 2:
        raise ValueError(f"segments must be an even integer >= 2, got {segments!r}")
    segments = int(segments)

    side, unit, counts, indices = _rounded_box_topology(segments)
    return side * h + radius * unit, counts.copy(), indices.copy()


@functools.lru_cache(maxsize=8)
def _rounded_box_topology(segments: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What a rounded box's mesh shares with every other of the same ``segments``: per vertex
    the side signs (P, 3) and the unit outward direction (P, 3), and the faces (counts,
    indices); the points are then ``side * h + radius * unit``. Read-only arrays (cached)."""
    side, direction = _axis_grid(segments)
    n = segments + 2  # grid entries per axis
    last = n - 1
    ix, iy, iz = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    on_surface = ((ix == 0) | (ix == last) | (iy == 0) | (iy == last)
                  | (iz == 0) | (iz == last))
    vertex_id = np.full((n, n, n), -1, dtype=np.int64)
    vertex_id[on_surface] = np.arange(int(on_surface.sum()))

    grid = np.stack([ix[on_surface], iy[on_surface], iz[on_surface]], axis=1)
    d = direction[grid]
    unit = d / np.linalg.norm(d, axis=1, keepdims=True)

    faces = []
    j, k = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    j, k = j.ravel(), k.ravel()
    for axis in range(3):
        b, c = (axis + 1) % 3, (axis + 2) % 3  # (b, c, axis) right-handed: b x c = +axis
        for sign, fixed in ((1, last), (-1, 0)):
            corners = [(j, k), (j + 1, k), (j + 1, k + 1), (j, k + 1)]
            if sign < 0:
                corners = corners[::-1]
            quad = []
            for cj, ck in corners:
                idx = [None, None, None]
                idx[axis], idx[b], idx[c] = np.full_like(cj, fixed), cj, ck
                quad.append(vertex_id[idx[0], idx[1], idx[2]])
            faces.append(np.stack(quad, axis=1))
    indices = np.concatenate(faces).astype(np.int32).ravel()
    counts = np.full(indices.size // 4, 4, dtype=np.int32)
    out = (side[grid], unit, counts, indices)
    for arr in out:
        arr.setflags(write=False)
    return out


def box_mesh(half_extents) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Closed quad mesh of a sharp box ``[-h, h]``: six faces with four vertices each.

    Each face has its own four vertices (24 in all, none shared between faces), so a reader
    that computes smooth vertex normals still shades every face flat, as a box should look.
    Zero half extents are legal (a plate's two faces coincide, back to back).

    Args:
        half_extents: half sizes along the local axes [m], shape (3,), each >= 0.

    Returns:
        ``(points, face_vertex_counts, face_vertex_indices)``: points (24, 3) float64 [m] in the
        box's local frame, counts (6,) int32 (all 4), indices (24,) int32, counter-clockwise seen
        from outside.

    Raises:
        ValueError: bad half extents.
    """
    h = np.asarray(half_extents, dtype=np.float64)
    if h.shape != (3,) or not np.isfinite(h).all() or (h < 0).any():
        raise ValueError(f"half_extents must be 3 finite values >= 0, got {half_extents!r}")
    faces = []
    for axis in range(3):
        b, c = (axis + 1) % 3, (axis + 2) % 3  # (b, c, axis) right-handed: b x c = +axis
        for sign in (1.0, -1.0):
            corners = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
            if sign < 0:
                corners = corners[::-1]
            for sb, sc in corners:
                point = np.zeros(3)
                point[axis], point[b], point[c] = sign, sb, sc
                faces.append(point)
    points = np.array(faces) * h
    return (points, np.full(6, 4, dtype=np.int32), np.arange(24, dtype=np.int32))


def checker_sphere_mesh(longitudes: int = 16, latitudes: int = 8
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Unit UV sphere about the origin, poles on the local y axis, with an octant checker.

    Each face lies in a single octant (the meridians at 0, 90, 180, 270 degrees and the equator
    are mesh edges), and faces are labelled by the sign of ``x * y * z`` of their centre: the
    eight octants alternate like a checkerboard, which makes a rotation about any axis visible.

    Args:
        longitudes: faces around the pole axis; a multiple of 4, >= 4.
        latitudes: faces from pole to pole; even, >= 2.

    Returns:
        ``(points, face_vertex_counts, face_vertex_indices, light)``: points (P, 3) float64 on the
        unit sphere (also its vertex normals), counts (F,) int32 (3 at the poles, 4 elsewhere),
        indices int32 counter-clockwise seen from outside, and ``light`` (F,) bool, True for the
        faces of the octants where ``x * y * z > 0``.

    Raises:
        ValueError: bad ``longitudes`` or ``latitudes``.
    """
    if int(longitudes) != longitudes or longitudes < 4 or longitudes % 4:
        raise ValueError(f"longitudes must be a multiple of 4, >= 4, got {longitudes!r}")
    if int(latitudes) != latitudes or latitudes < 2 or latitudes % 2:
        raise ValueError(f"latitudes must be an even integer >= 2, got {latitudes!r}")
    longitudes, latitudes = int(longitudes), int(latitudes)

    polar = np.linspace(0.0, np.pi, latitudes + 1)[1:-1]  # ring angles from +y
    azimuth = np.linspace(0.0, 2.0 * np.pi, longitudes, endpoint=False)
    sin_p, cos_p = np.sin(polar)[:, None], np.cos(polar)[:, None]
    rings = np.stack([sin_p * np.cos(azimuth), np.broadcast_to(cos_p, (polar.size, longitudes)),
                      -sin_p * np.sin(azimuth)], axis=-1).reshape(-1, 3)
    points = np.concatenate([[[0.0, 1.0, 0.0]], rings, [[0.0, -1.0, 0.0]]])
    south = points.shape[0] - 1

    def ring(i, a):  # vertex id of ring i (0 = nearest +y), azimuth step a (wraps)
        return 1 + i * longitudes + (a % longitudes)

    # Azimuth increases counter-clockwise seen from +y (x towards -z), so walking a ring forward
    # at the top and backward at the bottom keeps faces counter-clockwise seen from outside.
    a = np.arange(longitudes)
    counts, faces = [], []
    faces += [np.stack([np.zeros_like(a), ring(0, a), ring(0, a + 1)], axis=1)]
    counts += [np.full(longitudes, 3)]
    for i in range(latitudes - 2):
        faces += [np.stack([ring(i, a), ring(i + 1, a), ring(i + 1, a + 1), ring(i, a + 1)],
                           axis=1)]
        counts += [np.full(longitudes, 4)]
    last = latitudes - 2
    faces += [np.stack([ring(last, a), np.full_like(a, south), ring(last, a + 1)], axis=1)]
    counts += [np.full(longitudes, 3)]

    face_list = [row for block in faces for row in block]
    centres = np.array([points[f].mean(axis=0) for f in face_list])
    light = centres.prod(axis=1) > 0.0
    indices = np.concatenate(face_list).astype(np.int32)
    return points, np.concatenate(counts).astype(np.int32), indices, light
