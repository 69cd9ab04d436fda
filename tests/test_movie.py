"""Movie preview: every k-th recorded frame drawn and encoded (imageio, the ``movie`` extra)."""

import importlib.util
import sys

import numpy as np
import pytest
from PIL import Image

import warpsim
from warpsim.export import write_usd

imageio = pytest.importorskip("imageio.v2")

SIZE = (96, 64)


def falling_sphere_file(tmp_path, n_frames=10, dt=0.02):
    """A sphere dropping onto a floor plate, recorded every frame (frames 0..n-1)."""
    boxes = warpsim.RoundedBoxes(center=[[0.0, -0.1, 0.0]], half_extents=[[1.0, 0.1, 1.0]])
    t = np.arange(n_frames) * dt
    position = np.zeros((n_frames, 1, 3))
    position[:, 0, 1] = 1.0 - 0.5 * 9.81 * t**2
    traj = warpsim.Trajectory(frame=np.arange(n_frames), dt=dt, position=position,
                              orientation=np.tile([0.0, 0.0, 0.0, 1.0], (n_frames, 1, 1)),
                              radius=np.array([0.2]))
    return write_usd(tmp_path / "anim.usdc", warpsim.Scene(boxes, name="drop"), traj), traj


@pytest.mark.slow
def test_mp4_has_every_kth_frame_at_the_simulation_rate(tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    from warpsim.export.movie import render_movie

    usd, traj = falling_sphere_file(tmp_path)
    out = render_movie(usd, tmp_path / "drop.mp4", every=3, size=SIZE)
    reader = imageio.get_reader(out)
    frames = [frame for frame in reader]
    meta = reader.get_meta_data()
    reader.close()
    assert len(frames) == 4  # rows 0, 3, 6 and the last, 9
    assert frames[0].shape == (SIZE[1], SIZE[0], 3)
    assert meta["fps"] == pytest.approx(1.0 / (3 * traj.dt), rel=1e-3)
    # the sphere falls: its orange pixels move down the picture from first to last frame
    rows = [np.nonzero((f[..., 0].astype(int) - f[..., 2].astype(int)) > 40)[0].mean()
            for f in frames]
    assert rows[0] < rows[-1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["anim.usdc", "drop.mp4"]


def test_gif_frames_size_and_duration(tmp_path):
    from warpsim.export.movie import render_movie

    usd, traj = falling_sphere_file(tmp_path, n_frames=5, dt=0.05)
    out = render_movie(usd, tmp_path / "drop.GIF", size=SIZE)
    with Image.open(out) as gif:
        assert gif.format == "GIF" and gif.size == SIZE and gif.n_frames == 5
        assert gif.info["duration"] == pytest.approx(1000 * traj.dt, abs=10)


def test_bad_requests_are_refused_before_drawing(tmp_path, monkeypatch):
    from warpsim.export.movie import render_movie

    usd, _ = falling_sphere_file(tmp_path)
    for kwargs, match in (({"every": 0}, "every"), ({"size": (4, 4)}, "size"),
                          ({"elevation": 90.0}, "elevation")):
        with pytest.raises(ValueError, match=match):
            render_movie(usd, tmp_path / "x.gif", **kwargs)
    with pytest.raises(ValueError, match=r"\.mp4 or \.gif"):
        render_movie(usd, tmp_path / "x.avi")
    if importlib.util.find_spec("imageio_ffmpeg") is not None:
        with pytest.raises(ValueError, match="even"):
            render_movie(usd, tmp_path / "x.mp4", size=(95, 64))
    monkeypatch.setitem(sys.modules, "imageio", None)  # as if the extra were not installed
    with pytest.raises(ModuleNotFoundError, match=r"warpsim\[movie\]"):
        render_movie(usd, tmp_path / "x.gif")
    assert [p.name for p in tmp_path.iterdir()] == ["anim.usdc"]
