"""PNG preview of one recorded frame: size, content, camera framing, depth order, errors, atomicity.

Pixels are told apart by colour: spheres are orange/brown (red well above blue), obstacles are
slate blue (blue above red), the background is a near-neutral grey.
"""

import numpy as np
import pytest
from PIL import Image

import warpsim
from warpsim.export import render_preview, write_usd
from warpsim.export.preview import Camera, draw_frame

SMALL = (240, 135)


def sphere_mask(rgb: np.ndarray) -> np.ndarray:
    rgb = rgb.astype(np.int32)
    return rgb[..., 0] - rgb[..., 2] > 20


def obstacle_mask(rgb: np.ndarray) -> np.ndarray:
    rgb = rgb.astype(np.int32)
    return rgb[..., 2] - rgb[..., 0] > 14


def one_frame(position, radius, orientation=None, frame=0):
    position = np.asarray(position, dtype=np.float64).reshape(1, -1, 3)
    n = position.shape[1]
    if orientation is None:
        orientation = np.tile([0.0, 0.0, 0.0, 1.0], (1, n, 1))
    orientation = np.asarray(orientation, dtype=np.float64).reshape(1, n, 4)
    return warpsim.Trajectory(frame=np.array([frame], dtype=np.int64), dt=0.01,
                              position=position, orientation=orientation,
                              radius=np.asarray(radius, dtype=np.float64))


def floor_scene():
    """A 4 m x 4 m floor plate (top at y = 0) and a rounded block on it."""
    boxes = warpsim.RoundedBoxes(center=[[0.0, -0.1, 0.0], [1.0, 0.4, -1.0]],
                                 half_extents=[[2.0, 0.1, 2.0], [0.3, 0.3, 0.3]],
                                 radius=[0.0, 0.1])
    return warpsim.Scene(boxes, name="floor")


@pytest.mark.slow
def test_default_size_picture_shows_obstacles_and_spheres(tmp_path):
    rng = np.random.default_rng(0)
    n = 12
    position = np.c_[rng.uniform(-1.5, 1.5, n), rng.uniform(0.3, 1.5, n), rng.uniform(-1.5, 1.5, n)]
    q = rng.normal(size=(2, n, 4))
    traj = warpsim.Trajectory(frame=np.array([0, 5]), dt=0.01, position=np.stack([position] * 2),
                              orientation=q / np.linalg.norm(q, axis=-1, keepdims=True),
                              radius=np.full(n, 0.2))
    usd = write_usd(tmp_path / "anim.usdc", floor_scene(), traj)
    out = render_preview(usd, 5, tmp_path / "frame.png")
    assert out == tmp_path / "frame.png"
    with Image.open(out) as image:
        assert image.format == "PNG" and image.size == (960, 540)
        rgb = np.asarray(image.convert("RGB"))
    assert obstacle_mask(rgb).mean() > 0.05
    assert sphere_mask(rgb).mean() > 0.01
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.usdc", "frame.png"]


def test_sphere_projects_where_the_camera_says(tmp_path):
    centre, radius = np.array([-0.8, 0.25, 0.9]), 0.25
    usd = write_usd(tmp_path / "anim.usda", floor_scene(), one_frame(centre, [radius]))
    render_preview(usd, 0, tmp_path / "frame.png", size=SMALL)
    rgb = np.asarray(Image.open(tmp_path / "frame.png").convert("RGB"))

    # The camera render_preview used: it frames the floor and the sphere.
    lo = np.array([-2.0, -0.2, -2.0])
    hi = np.array([2.0, 0.8, 2.0])  # the rounded block's top, 0.4 + 0.3 + 0.1
    camera = Camera.framing(lo, hi, *SMALL)
    uv, depth = camera.project(centre[None])
    (u, v), depth = uv[0], depth[0]
    rho = camera.focal * radius / np.sqrt(np.sum((centre - camera.eye) ** 2) - radius**2)

    mask = sphere_mask(rgb)
    ys, xs = np.nonzero(mask)
    assert mask[int(v), int(u)]
    # Pixel centres are at +0.5; the sphere's outline is nearly a circle of radius rho.
    assert abs(xs.mean() + 0.5 - u) < 0.5 and abs(ys.mean() + 0.5 - v) < 0.5
    assert abs(mask.sum() - np.pi * rho**2) < 0.1 * np.pi * rho**2
    assert depth > 0


def test_camera_frames_the_box_tightly_and_centred():
    lo, hi = np.array([-2.0, -0.5, -1.0]), np.array([3.0, 1.5, 1.0])
    width, height = 320, 180
    camera = Camera.framing(lo, hi, width, height)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])])
    uv, depth = camera.project(corners)
    assert (depth > 0).all()
    margin_u = (uv[:, 0].max() - uv[:, 0].min()) / width
    margin_v = (uv[:, 1].max() - uv[:, 1].min()) / height
    # Centred in the picture, and one image axis filled to the framing margin (0.9).
    np.testing.assert_allclose(uv[:, 0].min() + uv[:, 0].max(), width, atol=1e-9)
    np.testing.assert_allclose(uv[:, 1].min() + uv[:, 1].max(), height, atol=1e-9)
    assert max(margin_u, margin_v) == pytest.approx(0.9, abs=1e-9)
    assert margin_u <= 0.9 + 1e-9 and margin_v <= 0.9 + 1e-9
    assert camera.up[1] > 0 and camera.forward[1] < 0  # y up, looking down


def test_depth_order_with_obstacles():
    """A sphere behind a wall is hidden, in front of it is shown, and one resting on a large
    floor is whole (a painter's sort of whole faces would bury it under the floor)."""
    wall = warpsim.RoundedBoxes(center=[[0.0, 0.0, 0.0]], half_extents=[[1.0, 1.0, 1.0]])
    forward = Camera.framing([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], *SMALL).forward  # fixed
    behind = 2.2 * forward  # on the view axis through the cube's centre, past its far corner
    in_front = -2.2 * forward
    for centre, visible in ((behind, False), (in_front, True)):
        image, _ = draw_frame(wall, centre[None], [[0, 0, 0, 1]], [0.15], size=SMALL)
        assert sphere_mask(np.asarray(image)).any() == visible

    floor = warpsim.RoundedBoxes(center=[[0.0, -0.05, 0.0]], half_extents=[[5.0, 0.05, 5.0]])
    resting = np.array([[2.0, 0.3, -2.0], [-2.0, 0.3, 2.0]])  # far and near side of the floor
    image, camera = draw_frame(floor, resting, [[0, 0, 0, 1]] * 2, [0.3, 0.3], size=SMALL)
    mask = sphere_mask(np.asarray(image))
    for centre in resting:
        (u, v), = camera.project(centre[None])[0]
        rho = camera.focal * 0.3 / np.linalg.norm(centre - camera.eye)
        ys, xs = np.nonzero(mask)
        near = (xs + 0.5 - u) ** 2 + (ys + 0.5 - v) ** 2 < (2 * rho) ** 2
        assert near.sum() > 0.8 * np.pi * rho**2


def test_closed_room_is_cut_away_so_the_inside_shows():
    """Six walls enclose a sphere: the walls facing the camera are left out (drawn as outlines),
    the floor and the far walls are drawn, and the sphere inside is visible."""
    t, s = 0.1, 2.0  # wall half thickness, room half size [m]
    walls = warpsim.RoundedBoxes(
        center=[[0, -s, 0], [0, s, 0], [-s, 0, 0], [s, 0, 0], [0, 0, -s], [0, 0, s]],
        half_extents=[[s, t, s], [s, t, s], [t, s, s], [t, s, s], [s, s, t], [s, s, t]])
    centre = np.array([0.0, -1.5, 0.0])
    image, camera = draw_frame(walls, centre[None], [[0, 0, 0, 1]], [0.4], size=SMALL)
    rgb = np.asarray(image)
    rho = camera.focal * 0.4 / np.linalg.norm(centre - camera.eye)
    assert sphere_mask(rgb).sum() > 0.6 * np.pi * rho**2  # an outline may cross it
    assert obstacle_mask(rgb).mean() > 0.2
    from warpsim.export.preview import _cutaway

    # The camera looks from +x, +y, +z: the ceiling and the +x and +z walls are cut.
    assert _cutaway(walls, camera.eye).tolist() == [False, True, False, True, False, True]
    small = warpsim.RoundedBoxes(center=[[0, 0, 0], [1.0, 0.0, 0.0]],
                                 half_extents=[[2, 0.1, 2], [0.01, 0.2, 0.2]])
    assert not _cutaway(small, camera.eye).any()  # a lone floor and a small plate stay


def test_spin_is_visible():
    """The same sphere turned by a quarter turn looks different (octant checker)."""
    s = np.sqrt(0.5)
    a, _ = draw_frame(None, [[0.0, 0.0, 0.0]], [[0, 0, 0, 1]], [1.0], size=SMALL)
    b, _ = draw_frame(None, [[0.0, 0.0, 0.0]], [[s, 0, 0, s]], [1.0], size=SMALL)
    diff = np.abs(np.asarray(a, dtype=np.int32) - np.asarray(b, dtype=np.int32)).sum(axis=2)
    assert (diff > 60).mean() > 0.1


def test_unknown_frame_names_frame_and_range(tmp_path):
    traj = one_frame([0.0, 0.0, 0.0], [0.5])
    traj = warpsim.Trajectory(frame=np.array([10, 12, 14]), dt=0.01,
                              position=np.zeros((3, 1, 3)),
                              orientation=np.tile([0.0, 0.0, 0.0, 1.0], (3, 1, 1)),
                              radius=np.array([0.5]))
    usd = write_usd(tmp_path / "anim.usdc", None, traj)
    for bad in (11, 3, 2.5, "12"):
        with pytest.raises(ValueError, match=r"frame .*10\.\.14"):
            render_preview(usd, bad, tmp_path / "frame.png", size=SMALL)
    render_preview(usd, np.int64(12), tmp_path / "frame.png", size=SMALL)  # numpy ints are fine
    with pytest.raises(ValueError, match="size"):
        render_preview(usd, 10, tmp_path / "frame.png", size=(4, 4))


def test_failed_png_write_keeps_the_existing_file(tmp_path, monkeypatch):
    usd = write_usd(tmp_path / "anim.usdc", floor_scene(), one_frame([0.0, 0.5, 0.0], [0.2]))
    png = tmp_path / "frame.png"
    png.write_bytes(b"old picture")

    def partial_save(self, fp, format=None, **params):
        with open(fp, "wb") as f:
            f.write(b"\x89PNG half")
        raise OSError("disk full")

    monkeypatch.setattr(Image.Image, "save", partial_save)
    with pytest.raises(OSError, match="disk full"):
        render_preview(usd, 0, png, size=SMALL)
    assert png.read_bytes() == b"old picture"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.usdc", "frame.png"]


def test_image_format_follows_the_extension(tmp_path):
    """``.jpg`` writes a JPEG, ``.PNG`` a PNG; an extension Pillow cannot write is refused
    before anything is drawn, and nothing is left behind."""
    usd = write_usd(tmp_path / "anim.usdc", floor_scene(), one_frame([0.0, 0.5, 0.0], [0.2]))
    for name, fmt in (("frame.jpg", "JPEG"), ("frame.jpeg", "JPEG"), ("frame.PNG", "PNG"),
                      ("frame.webp", "WEBP")):
        out = render_preview(usd, 0, tmp_path / name, size=SMALL)
        with Image.open(out) as image:
            assert image.format == fmt and image.size == SMALL
    for bad in ("frame.xyz", "frame", "frame.usdc"):
        with pytest.raises(ValueError, match="must end in"):
            render_preview(usd, 0, tmp_path / bad, size=SMALL)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "anim.usdc", "frame.PNG", "frame.jpeg", "frame.jpg", "frame.webp"]


def test_negative_frame_counts_from_the_end(tmp_path):
    traj = warpsim.Trajectory(frame=np.array([10, 12, 14]), dt=0.01,
                              position=np.array([[[-1.0, 0.5, 0.0]], [[0.0, 0.5, 0.0]],
                                                 [[1.0, 0.5, 0.0]]]),
                              orientation=np.tile([0.0, 0.0, 0.0, 1.0], (3, 1, 1)),
                              radius=np.array([0.3]))
    usd = write_usd(tmp_path / "anim.usdc", floor_scene(), traj)
    render_preview(usd, -1, tmp_path / "last.png", size=SMALL)
    render_preview(usd, 14, tmp_path / "fourteen.png", size=SMALL)
    render_preview(usd, -3, tmp_path / "first.png", size=SMALL)
    last = np.asarray(Image.open(tmp_path / "last.png"))
    assert np.array_equal(last, np.asarray(Image.open(tmp_path / "fourteen.png")))
    assert not np.array_equal(last, np.asarray(Image.open(tmp_path / "first.png")))
    with pytest.raises(ValueError, match="only 3"):
        render_preview(usd, -4, tmp_path / "x.png", size=SMALL)


def test_view_angles_move_the_camera():
    lo, hi = np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0])
    side = Camera.framing(lo, hi, *SMALL, azimuth=90.0, elevation=0.0)
    np.testing.assert_allclose(side.forward, [-1.0, 0.0, 0.0], atol=1e-12)  # from +x
    top = Camera.framing(lo, hi, *SMALL, azimuth=0.0, elevation=80.0)
    assert top.forward[1] < -0.98
    for azimuth, elevation in ((0.0, 90.0), (float("nan"), 0.0), ("a", 0.0)):
        with pytest.raises(ValueError, match="azimuth|elevation"):
            Camera.framing(lo, hi, *SMALL, azimuth=azimuth, elevation=elevation)


def test_renderer_draws_what_draw_frame_draws():
    """The renderer keeps the obstacles drawn once; each frame equals a fresh drawing with the
    same camera bounds."""
    from warpsim.export.preview import Renderer, scene_bounds

    boxes = floor_scene().boxes
    frames = [np.array([[0.0, 0.4, 0.0]]), np.array([[1.0, 1.2, 0.5]])]
    lo, hi = scene_bounds(boxes, np.stack(frames), [0.2])
    renderer = Renderer(boxes, lo, hi, size=SMALL)
    for position in frames:
        image = renderer.draw(position, [[0, 0, 0, 1]], [0.2])
        fresh, _ = draw_frame(boxes, position, [[0, 0, 0, 1]], [0.2], size=SMALL,
                              bounds=(lo, hi))
        assert np.array_equal(np.asarray(image), np.asarray(fresh))
