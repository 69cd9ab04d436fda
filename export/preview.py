"""Pictures of spheres among boxes, drawn with Pillow and numpy from arrays (no GPU, no USD).

:func:`draw_frame` draws one state; :class:`Renderer` keeps a fixed camera and the obstacles
drawn once, for a sequence of frames (a movie); :func:`render_preview` reads a frame of a
warpsim USD file and saves it as an image.

The camera is placed automatically: a three-quarter view (by default looking down at 30
degrees, from the +x/+z diagonal, y up) as near as it can be while the given bounds (by default
the obstacles and the spheres) are in view, centred in the picture.

Obstacles are drawn from the same tessellation as the USD meshes, flat shaded, back faces culled.
Spheres are ray-cast per pixel with their octant checker (the look of the USD prototype, so spin
shows). Visibility between objects is resolved per pixel by depth: each box's front faces are
filled by Pillow into a face-id image (a convex solid's front faces never overlap, so their order
does not matter) and the depth of each covered pixel comes from the face's plane, so a sphere
resting on a large floor or half hidden behind a wall is drawn right where a painter's sort of
whole faces would fail. The picture is rendered at twice the size and box-filtered down, which
smooths edges.

Closed scenes (a room, a cabinet under glass) would show only their outside, so the walls of
the enclosure that face the camera are cut away and drawn as thin outlines: large plates on the
side of the obstacles' bounding box nearest the camera, seen from outside (see ``_cutaway``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from ..obstacles import RoundedBoxes, quat_to_matrix
from .files import atomic_output
from .mesh import rounded_box_mesh
from .usd_layout import OBSTACLE_COLOR, SPHERE_DARK, SPHERE_LIGHT
from .usd_read import read_usd_boxes, read_usd_frame

SUPERSAMPLING = 2  # rendered at this many times the size per axis, then averaged down
#: Largest picture drawn [pixels]: rendered at SUPERSAMPLING^2 times that with colour and depth
#: (32 B per rendered pixel) and batch temporaries, 4096x4096 holds about 2.5 GB; larger is
#: refused before any buffer is made.
MAX_PIXELS = 4096 * 4096
MAX_SIDE = 16384
PIXELS_PER_BATCH = 1 << 20  # sphere pixels ray-cast together: bounds the temporary memory
PREVIEW_SEGMENTS = 6  # edges per quarter circle of a rounded box in the picture
AZIMUTH_DEG = 45.0  # default view direction around +y, from +z towards +x [deg]
ELEVATION_DEG = 30.0  # default camera height above the horizon, seen from the target [deg]
MAX_ELEVATION_DEG = 89.0  # straight down or up leaves no image "right" direction: refused
VERTICAL_FOV = np.radians(40.0)
FRAME_MARGIN = 0.9  # the bounding box fills at most this fraction of the half field of view
CENTRING_STEPS = 64  # bisection steps centring the picture: down to float64 resolution
NEAR_FRACTION = 0.05  # nearest geometry at least this fraction of the box size from the eye
DEGENERATE_AREA = 1e-12  # faces smaller than this fraction of the squared box size are skipped
AMBIENT = 0.35  # share of a colour lit regardless of the light direction
SPECULAR = 0.25  # strength of the spheres' highlight
SHININESS = 40.0
PLATE_ASPECT = 4.0  # a box this many times thinner than its middle extent is a plate
WALL_FRACTION = 0.3  # a plate at least this long (share of the obstacles' diagonal) may be a wall
WALL_TOLERANCE = 0.04  # how near the obstacles' bounding box a wall lies (share of the diagonal)
OUTLINE_COLOR = (120, 130, 145)  # the edges of left-out walls
BACKGROUND_TOP = np.array([0.80, 0.83, 0.86])
BACKGROUND_BOTTOM = np.array([0.95, 0.95, 0.95])


@dataclass(frozen=True)
class Camera:
    """A pinhole camera, y-up world; image ``u`` to the right, ``v`` down, in pixels.

    Continuous image coordinates: pixel ``(i, j)`` covers ``[i, i + 1) x [j, j + 1)``, so the
    principal point ``(width / 2, height / 2)`` is the image centre.

    Attributes:
        eye: camera position [m], shape (3,).
        forward: unit viewing direction (world), shape (3,).
        right: unit image-right direction (world), shape (3,).
        up: unit image-up direction (world), shape (3,).
        focal: focal length [px].
        width: image width [px].
        height: image height [px].
    """

    eye: np.ndarray
    forward: np.ndarray
    right: np.ndarray
    up: np.ndarray
    focal: float
    width: int
    height: int

    @classmethod
    def framing(cls, lo, hi, width: int, height: int, *, azimuth: float = AZIMUTH_DEG,
                elevation: float = ELEVATION_DEG) -> Camera:
        """The camera looking from ``azimuth``/``elevation`` that frames ``[lo, hi]`` tightly.

        The view direction comes from the two angles [deg] (azimuth around +y from +z towards
        +x, elevation above the horizon); the eye position is the one, among those seeing every
        corner of the box ``[lo, hi]`` (world, [m]) within :data:`FRAME_MARGIN` of the half
        field of view, nearest to the box, with the box's picture centred. Each frustum side is a
        linear constraint on the eye, so the distance is found in closed form per image axis;
        the centring is a bisection per axis.

        Raises:
            ValueError: an angle that is not finite, or an elevation beyond
                :data:`MAX_ELEVATION_DEG`.
        """
        az, el = _view_angles(azimuth, elevation)
        lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        size = max(float(np.linalg.norm(hi - lo)), 1e-6)
        back = np.array([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])
        forward = -back
        right = np.cross(forward, [0.0, 1.0, 0.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        tan_y = np.tan(0.5 * VERTICAL_FOV)
        tan_x = tan_y * width / height
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                            for z in (lo[2], hi[2])])
        depth = corners @ forward
        # Along one image axis a (unit vector, half-angle tangent tan_a, k = margin * tan_a) a
        # point p is in view from eye e when |p.a - e.a| <= k (p.f - e.f). Both sides hold for
        # every corner when e.a - k e.f >= max(p.a - k p.f) =: A and e.a + k e.f <= min(p.a +
        # k p.f) =: B; the nearest such eye has e.f = (B - A) / 2k. The eye backs off to the
        # smallest e.f over both axes (and the near limit).
        eye_depth = []
        for axis, tan_a in ((right, tan_x), (up, tan_y)):
            k = FRAME_MARGIN * tan_a
            across = corners @ axis
            a, b = np.max(across - k * depth), np.min(across + k * depth)
            eye_depth.append((b - a) / (2.0 * k))
        eye_f = min(*eye_depth, float(depth.min()) - NEAR_FRACTION * size)
        # Then each image axis is centred: the most positive and most negative slopes
        # (p.a - e.a) / (p.f - e.f) over the corners cancel; their sum decreases with e.a.
        z = depth - eye_f
        eye_along = []
        for axis in (right, up):
            across = corners @ axis
            low, high = float(across.min()), float(across.max())
            for _ in range(CENTRING_STEPS):
                mid = 0.5 * (low + high)
                slope = (across - mid) / z
                low, high = (mid, high) if slope.max() + slope.min() > 0.0 else (low, mid)
            eye_along.append(0.5 * (low + high))
        eye = eye_along[0] * right + eye_along[1] * up + eye_f * forward
        return cls(eye=eye, forward=forward, right=right, up=up,
                   focal=0.5 * height / tan_y, width=int(width), height=int(height))

    def scaled(self, factor: int) -> Camera:
        """The same view on an image ``factor`` times larger per axis."""
        return Camera(self.eye, self.forward, self.right, self.up, self.focal * factor,
                      self.width * factor, self.height * factor)

    def to_camera(self, points) -> np.ndarray:
        """World points (P, 3) [m] -> camera coordinates (P, 3): right, up, depth [m]."""
        rel = np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.eye
        return np.stack([rel @ self.right, rel @ self.up, rel @ self.forward], axis=1)

    def project(self, points) -> tuple[np.ndarray, np.ndarray]:
        """World points (P, 3) [m] -> continuous image coordinates (P, 2) [px], depth (P,) [m].

        Points at depth <= 0 (behind the eye) get non-finite coordinates.
        """
        cam = self.to_camera(points)
        with np.errstate(divide="ignore", invalid="ignore"):
            u = 0.5 * self.width + self.focal * cam[:, 0] / cam[:, 2]
            v = 0.5 * self.height - self.focal * cam[:, 1] / cam[:, 2]
        return np.stack([u, v], axis=1), cam[:, 2]

    def rays(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """Unit world directions through the centres of pixels ``[x0, x1) x [y0, y1)``.

        Returns:
            Shape ``(y1 - y0, x1 - x0, 3)``.
        """
        u = (np.arange(x0, x1) + 0.5 - 0.5 * self.width) / self.focal
        v = (0.5 * self.height - (np.arange(y0, y1) + 0.5)) / self.focal
        d = (u[None, :, None] * self.right + v[:, None, None] * self.up + self.forward)
        return d / np.linalg.norm(d, axis=2, keepdims=True)


def _view_angles(azimuth, elevation) -> tuple[float, float]:
    """Validated view angles in radians from degrees."""
    try:
        az, el = float(azimuth), float(elevation)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"azimuth and elevation must be numbers [deg], got {azimuth!r}, "
                         f"{elevation!r}") from exc
    if not (np.isfinite(az) and np.isfinite(el)):
        raise ValueError(f"azimuth and elevation must be finite, got {azimuth!r}, {elevation!r}")
    if abs(el) > MAX_ELEVATION_DEG:
        raise ValueError(f"elevation must be within +-{MAX_ELEVATION_DEG:g} deg, got {el:g}")
    return np.radians(az), np.radians(el)


def _light_direction(camera: Camera) -> np.ndarray:
    """Unit direction towards the light: from above, a little left of and behind the camera."""
    d = -0.35 * camera.right + 0.9 * np.array([0.0, 1.0, 0.0]) - 0.45 * camera.forward
    return d / np.linalg.norm(d)


def _box_faces(boxes: RoundedBoxes, i: int, scale: float):
    """World polygons of box ``i``: vertices (P, 3), a (F, 4) index table, and unit normals."""
    points, _, indices = rounded_box_mesh(boxes.half_extents[i], boxes.radius[i],
                                          PREVIEW_SEGMENTS)
    rot = quat_to_matrix(boxes.rotation[i])
    world = points @ rot.T + boxes.center[i]
    quads = indices.reshape(-1, 4)
    corner = world[quads]
    # Newell's normal: exact for planar quads, robust when two corners coincide.
    nxt = np.roll(corner, -1, axis=1)
    normal = 0.5 * np.cross(corner, nxt).sum(axis=1)
    area = np.linalg.norm(normal, axis=1)
    keep = area > DEGENERATE_AREA * scale * scale
    return world, quads[keep], normal[keep] / area[keep, None]


def _shade(color, lit) -> np.ndarray:
    """Colours (F, 3) of faces of one ``color`` lit by ``lit`` = n . light, (F,)."""
    intensity = AMBIENT + (1.0 - AMBIENT) * np.clip(lit, 0.0, 1.0)
    return np.asarray(color)[None, :] * intensity[:, None]


def _draw_box(rgb, depth, camera: Camera, world, quads, normal, light) -> None:
    """Z-buffer the front faces of one convex box into ``rgb`` (H, W, 3) and ``depth`` (H, W)."""
    uv, z = camera.project(world)
    centre_view = world[quads].mean(axis=1) - camera.eye
    front = (np.einsum("ij,ij->i", normal, centre_view) < 0.0) & (z[quads] > 0.0).all(axis=1)
    quads, normal = quads[front], normal[front]
    if quads.shape[0] == 0:
        return
    pts = uv[quads]  # (F, 4, 2)
    x0 = max(int(np.floor(pts[..., 0].min())) - 1, 0)
    y0 = max(int(np.floor(pts[..., 1].min())) - 1, 0)
    x1 = min(int(np.ceil(pts[..., 0].max())) + 1, camera.width)
    y1 = min(int(np.ceil(pts[..., 1].max())) + 1, camera.height)
    if x1 <= x0 or y1 <= y0:
        return
    ids = Image.new("I", (x1 - x0, y1 - y0), 0)
    draw = ImageDraw.Draw(ids)
    for k, quad in enumerate(pts):
        # Pillow puts integer coordinates at pixel centres, ours at pixel corners.
        draw.polygon([(float(x) - x0 - 0.5, float(y) - y0 - 0.5) for x, y in quad], fill=k + 1)
    face = np.asarray(ids, dtype=np.int64) - 1
    ys, xs = np.nonzero(face >= 0)
    if ys.size == 0:
        return
    f = face[ys, xs]
    ray = camera.rays(x0, y0, x1, y1)[ys, xs]
    plane_point = world[quads[f, 0]]
    n = normal[f]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.einsum("ij,ij->i", n, plane_point - camera.eye) / np.einsum("ij,ij->i", n, ray)
    t = np.where(np.isfinite(t) & (t > 0.0), t, np.inf)
    gy, gx = ys + y0, xs + x0
    nearer = t < depth[gy, gx]
    colors = _shade(OBSTACLE_COLOR, normal @ light)
    rgb[gy[nearer], gx[nearer]] = colors[f[nearer]]
    depth[gy[nearer], gx[nearer]] = t[nearer]


def _shade_spheres(ray, normal, rotation, light) -> np.ndarray:
    """Colours (P, 3) of sphere pixels: octant checker in the body frame, Lambert + highlight.

    Args:
        ray: unit view rays (P, 3); normal: unit world normals (P, 3); rotation: the sphere's
            body -> world matrix per pixel (P, 3, 3); light: unit direction to the light (3,).
    """
    body = np.einsum("pji,pj->pi", rotation, normal)  # R^T n: the normal in the body frame
    base = np.where((body.prod(axis=1) > 0.0)[:, None], SPHERE_LIGHT, SPHERE_DARK)
    diffuse = AMBIENT + (1.0 - AMBIENT) * np.clip(normal @ light, 0.0, 1.0)
    half = light[None, :] - ray
    half /= np.linalg.norm(half, axis=1, keepdims=True)
    spec = SPECULAR * np.clip(np.einsum("ij,ij->i", normal, half), 0.0, 1.0) ** SHININESS
    return np.clip(base * diffuse[:, None] + spec[:, None], 0.0, 1.0)


def _draw_spheres(rgb, depth, camera: Camera, center, radius, rotation, light) -> None:
    """Ray-cast checkered spheres into ``rgb`` (H, W, 3) and ``depth`` (H, W), z-buffered.

    Every sphere tests the pixels of the square around its silhouette; the pixels of many spheres
    are processed together (at most :data:`PIXELS_PER_BATCH` at a time), the nearest hit per pixel
    wins, and only hits nearer than what ``depth`` holds are written.

    Args:
        center: sphere centres (N, 3) [m]; radius: (N,) [m]; rotation: body -> world (N, 3, 3).
    """
    oc = center - camera.eye
    dist2 = np.einsum("ij,ij->i", oc, oc)
    silhouette2 = dist2 - radius * radius
    uv, z = camera.project(center)
    ok = (radius > 0.0) & (silhouette2 > 0.0) & (z > 0.0)
    rho = np.zeros_like(radius)
    rho[ok] = camera.focal * radius[ok] / np.sqrt(silhouette2[ok]) + 2.0  # outline + margin
    with np.errstate(invalid="ignore"):
        x0 = np.clip(np.floor(uv[:, 0] - rho), 0, camera.width)
        x1 = np.clip(np.ceil(uv[:, 0] + rho) + 1, 0, camera.width)
        y0 = np.clip(np.floor(uv[:, 1] - rho), 0, camera.height)
        y1 = np.clip(np.ceil(uv[:, 1] + rho) + 1, 0, camera.height)
    ok &= (x1 > x0) & (y1 > y0)
    idx = np.flatnonzero(ok)
    x0, y0 = x0[idx].astype(np.int64), y0[idx].astype(np.int64)
    w, h = x1[idx].astype(np.int64) - x0, y1[idx].astype(np.int64) - y0
    area = w * h
    start = 0
    while start < len(idx):
        stop = start + max(1, int(np.searchsorted(np.cumsum(area[start:]), PIXELS_PER_BATCH)))
        sl = slice(start, stop)
        start = stop
        k = np.repeat(np.arange(sl.start, sl.stop), area[sl])  # batch-local sphere per pixel
        first = np.repeat(np.cumsum(area[sl]) - area[sl], area[sl])
        offset = np.arange(k.size) - first
        px, py = x0[k] + offset % w[k], y0[k] + offset // w[k]
        ray = (((px + 0.5 - 0.5 * camera.width) / camera.focal)[:, None] * camera.right
               + ((0.5 * camera.height - (py + 0.5)) / camera.focal)[:, None] * camera.up
               + camera.forward)
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        sphere = idx[k]
        b = np.einsum("ij,ij->i", ray, oc[sphere])
        disc = b * b - silhouette2[sphere]
        t = b - np.sqrt(np.maximum(disc, 0.0))
        hit = (disc >= 0.0) & (t > 0.0) & (t < depth[py, px])
        if not hit.any():
            continue
        px, py, t, ray, sphere = px[hit], py[hit], t[hit], ray[hit], sphere[hit]
        # Nearest hit per pixel: sort by pixel, then depth, and keep each pixel's first entry.
        pixel = py * camera.width + px
        order = np.lexsort((t, pixel))
        keep = order[np.r_[True, pixel[order][1:] != pixel[order][:-1]]]
        px, py, t, ray, sphere = px[keep], py[keep], t[keep], ray[keep], sphere[keep]
        normal = (ray * t[:, None] - oc[sphere]) / radius[sphere, None]
        rgb[py, px] = _shade_spheres(ray, normal, rotation[sphere], light)
        depth[py, px] = t


def _box_bounds(boxes: RoundedBoxes) -> tuple[np.ndarray, np.ndarray]:
    """World axis-aligned bounds of each rounded box, ``(lo, hi)`` each (K, 3) [m]."""
    reach = boxes.world_extent()
    return boxes.center - reach, boxes.center + reach


def _cutaway(boxes: RoundedBoxes, eye) -> np.ndarray:
    """Which boxes to leave out so that the camera sees into a closed room: (K,) bool.

    A box is left out when it is a wall of the scene's enclosure seen from outside: a plate
    (thinnest extent at most 1 / :data:`PLATE_ASPECT` of the middle one), long (at least
    :data:`WALL_FRACTION` of the obstacles' bounding-box diagonal), lying on the bounding box's
    side that faces the camera (within :data:`WALL_TOLERANCE` of the diagonal), with the eye
    outside its slab and the centre of the obstacles on the other side of it.
    """
    lo, hi = _box_bounds(boxes)
    scene_lo, scene_hi = lo.min(axis=0), hi.max(axis=0)
    diag = max(float(np.linalg.norm(scene_hi - scene_lo)), 1e-12)
    centre = 0.5 * (scene_lo + scene_hi)
    extent = boxes.half_extents + boxes.radius[:, None]
    rot = boxes.rotation_matrices()
    hide = np.zeros(len(boxes), dtype=bool)
    for k in range(len(boxes)):
        thin_axis = int(np.argmin(extent[k]))
        half, middle, longest = np.sort(extent[k])
        if half * PLATE_ASPECT > middle or 2.0 * longest < WALL_FRACTION * diag:
            continue
        normal = rot[k][:, thin_axis]
        eye_side = float((eye - boxes.center[k]) @ normal)
        centre_side = float((centre - boxes.center[k]) @ normal)
        if abs(eye_side) <= half or abs(centre_side) <= half or eye_side * centre_side > 0.0:
            continue  # eye or scene centre in the slab, or both on one side: a floor, say
        outward = np.sign(eye_side) * normal
        j = int(np.argmax(np.abs(outward)))
        tol = WALL_TOLERANCE * diag
        hide[k] = (hi[k, j] >= scene_hi[j] - tol if outward[j] > 0.0
                   else lo[k, j] <= scene_lo[j] + tol)
    return hide


def _draw_outline(image: Image.Image, camera: Camera, boxes: RoundedBoxes, k: int) -> None:
    """Thin lines along the edges of box ``k`` (grown by its radius): where a cut wall was."""
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    corners = (signs * (boxes.half_extents[k] + boxes.radius[k])) @ quat_to_matrix(
        boxes.rotation[k]).T + boxes.center[k]
    uv, z = camera.project(corners)
    if (z <= 0.0).any():
        return
    draw = ImageDraw.Draw(image)
    for a in range(8):
        for b in range(a + 1, 8):
            if np.abs(signs[a] - signs[b]).sum() == 2:  # corners one edge apart
                draw.line([tuple(uv[a] - 0.5), tuple(uv[b] - 0.5)], fill=OUTLINE_COLOR,
                          width=SUPERSAMPLING)


def scene_bounds(boxes: RoundedBoxes | None, position, radius) -> tuple[np.ndarray, np.ndarray]:
    """World bounds ``(lo, hi)`` (3,) [m] of the obstacles and the spheres.

    Args:
        boxes: the obstacles, or None. position: sphere centres [m], (N, 3) or (F, N, 3) for
            the bounds over several frames. radius: (N,) [m].
    """
    position = np.asarray(position, dtype=np.float64)
    radius = np.asarray(radius, dtype=np.float64).reshape(-1)
    los, his = [], []
    if boxes is not None and len(boxes):
        lo, hi = _box_bounds(boxes)
        los.append(lo.min(axis=0))
        his.append(hi.max(axis=0))
    if position.size:
        p = position.reshape(-1, radius.size, 3)
        finite = np.isfinite(p).all(axis=2)
        if finite.any():
            r = np.broadcast_to(radius, finite.shape)[finite]
            los.append((p[finite] - r[:, None]).min(axis=0))
            his.append((p[finite] + r[:, None]).max(axis=0))
    if not los:
        return -np.ones(3), np.ones(3)
    return np.min(los, axis=0), np.max(his, axis=0)


class Renderer:
    """A fixed camera and the obstacles drawn once: draws any number of sphere states fast.

    Args:
        boxes: the obstacles, or None.
        lo, hi: world bounds the camera frames ([m], (3,) each), e.g. from :func:`scene_bounds`.
        size: ``(width, height)`` of the pictures [px], each >= 8.
        azimuth, elevation: view direction [deg] (see :meth:`Camera.framing`).

    Attributes:
        camera: the camera, at the pictures' size.
    """

    def __init__(self, boxes: RoundedBoxes | None, lo, hi, *, size=(960, 540),
                 azimuth: float = AZIMUTH_DEG, elevation: float = ELEVATION_DEG):
        width, height = _size(size)
        lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        self.camera = Camera.framing(lo, hi, width, height, azimuth=azimuth,
                                     elevation=elevation)
        self._big = self.camera.scaled(SUPERSAMPLING)
        self._light = _light_direction(self.camera)
        big = self._big
        fade = np.linspace(0.0, 1.0, big.height)[:, None, None]
        self._rgb = np.broadcast_to(BACKGROUND_TOP * (1 - fade) + BACKGROUND_BOTTOM * fade,
                                    (big.height, big.width, 3)).copy()
        self._depth = np.full((big.height, big.width), np.inf)
        scale = max(float(np.linalg.norm(hi - lo)), 1e-6)
        has_boxes = boxes is not None and len(boxes) > 0
        cut = _cutaway(boxes, self.camera.eye) if has_boxes else np.zeros(0, dtype=bool)
        for k in np.flatnonzero(~cut):
            _draw_box(self._rgb, self._depth, big, *_box_faces(boxes, k, scale), self._light)
        self._boxes, self._cut = boxes, np.flatnonzero(cut)

    def draw(self, position, orientation, radius) -> Image.Image:
        """The picture of spheres (world frame) among the obstacles.

        Args:
            position: sphere centres [m], shape (N, 3); a sphere whose centre is NaN (not
                born yet) is not drawn.
            orientation: sphere orientations (x, y, z, w), body -> world, shape (N, 4).
            radius: sphere radii [m], shape (N,).
        """
        position = np.asarray(position, dtype=np.float64).reshape(-1, 3)
        born = np.isfinite(position).all(axis=1)
        position = position[born]
        radius = np.broadcast_to(np.asarray(radius, dtype=np.float64).reshape(-1),
                                 born.shape)[born]
        rotation = quat_to_matrix(np.asarray(orientation, dtype=np.float64).reshape(-1, 4)[born])
        rgb, depth = self._rgb.copy(), self._depth.copy()
        _draw_spheres(rgb, depth, self._big, position, radius, rotation, self._light)
        image = Image.fromarray(np.round(rgb * 255.0).astype(np.uint8), "RGB")
        for k in self._cut:
            _draw_outline(image, self._big, self._boxes, k)
        return image.resize((self.camera.width, self.camera.height), Image.Resampling.BOX)


def draw_frame(boxes: RoundedBoxes | None, position, orientation, radius, *,
               size=(960, 540), azimuth: float = AZIMUTH_DEG, elevation: float = ELEVATION_DEG,
               bounds=None) -> tuple[Image.Image, Camera]:
    """Draw obstacles and spheres (world frame) from an automatic three-quarter view.

    Args:
        boxes: the obstacles, or None.
        position: sphere centres [m], shape (N, 3).
        orientation: sphere orientations (x, y, z, w), body -> world, shape (N, 4).
        radius: sphere radii [m], shape (N,).
        size: ``(width, height)`` of the picture [px].
        azimuth, elevation: view direction [deg] (see :meth:`Camera.framing`).
        bounds: ``(lo, hi)`` world box the camera frames [m]; default: the obstacles and these
            spheres (:func:`scene_bounds`).

    Returns:
        The RGB picture and the camera it was seen from (at the picture's size).
    """
    position = np.asarray(position, dtype=np.float64).reshape(-1, 3)
    radius = np.asarray(radius, dtype=np.float64).reshape(-1)
    lo, hi = scene_bounds(boxes, position, radius) if bounds is None else bounds
    renderer = Renderer(boxes, lo, hi, size=size, azimuth=azimuth, elevation=elevation)
    return renderer.draw(position, orientation, radius), renderer.camera


def _size(size) -> tuple[int, int]:
    try:
        width, height = (int(s) for s in size)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"size must be (width, height) in pixels, got {size!r}") from exc
    if width < 8 or height < 8 or (width, height) != tuple(size):
        raise ValueError(f"size must be two integers >= 8, got {size!r}")
    if max(width, height) > MAX_SIDE or width * height > MAX_PIXELS:
        raise ValueError(f"size must be at most {MAX_SIDE} pixels on a side and {MAX_PIXELS:,} "
                         f"in all (4096x4096), got {width}x{height}")
    return width, height


def image_format(path) -> str:
    """The Pillow format name that saves a picture at ``path``, from its extension (any case).

    Raises:
        ValueError: an extension Pillow cannot save (the message lists the common ones).
    """
    suffix = Path(path).suffix.lower()
    Image.init()
    fmt = Image.registered_extensions().get(suffix)
    if fmt is None or fmt not in Image.SAVE:
        raise ValueError(f"image must end in .png, .jpg, .webp, .bmp or .tif (a format Pillow "
                         f"can write), got {str(path)!r}")
    return fmt


def save_image(image: Image.Image, path) -> Path:
    """Save ``image`` atomically in the format its extension names (``.jpg`` -> JPEG).

    Raises:
        ValueError: an unknown extension. FileNotFoundError: the folder does not exist.
    """
    path = Path(path)
    fmt = image_format(path)
    if not path.parent.is_dir():
        raise FileNotFoundError(f"folder of {str(path)!r} does not exist")
    with atomic_output(path) as tmp:
        image.save(tmp, format=fmt)
    return path


def render_preview(usd_path, frame: int, image_path, *, size=(960, 540),
                   azimuth: float = AZIMUTH_DEG, elevation: float = ELEVATION_DEG) -> Path:
    """Draw one recorded frame of a warpsim USD file to an image (CPU only).

    See the module docstring for the camera and the drawing (walls of a closed scene that face
    the camera are cut away and outlined, so the inside shows). The image is written atomically
    (temporary name next to ``image_path``, then a rename): on error nothing is left behind and a
    file already at ``image_path`` is untouched.

    Args:
        usd_path: a file written by :func:`warpsim.export.write_usd`.
        frame: a recorded frame index (time code), e.g. ``trajectory.frame[k]``, or a negative
            number counting recorded frames from the end (-1: the last).
        image_path: output file; its extension picks the format (``.png``, ``.jpg``, ...). Its
            folder must exist.
        size: ``(width, height)`` of the picture [px], each >= 8.
        azimuth, elevation: view direction [deg] (see :meth:`Camera.framing`).

    Returns:
        ``image_path`` as a :class:`pathlib.Path`.

    Raises:
        ValueError: ``frame`` is not a recorded frame (the message gives the available range),
            bad ``size``, angles or image extension, or the file was not written by warpsim.
        FileNotFoundError: no file at ``usd_path``, or the output folder does not exist.
    """
    image_path = Path(image_path)
    image_format(image_path)
    _size(size)
    _view_angles(azimuth, elevation)
    if not image_path.parent.is_dir():
        raise FileNotFoundError(f"folder of {str(image_path)!r} does not exist")
    state = read_usd_frame(usd_path, frame)
    image, _ = draw_frame(read_usd_boxes(usd_path), state.position[0], state.orientation[0],
                          state.radius, size=size, azimuth=azimuth, elevation=elevation)
    return save_image(image, image_path)
