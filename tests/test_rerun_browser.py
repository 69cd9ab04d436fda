"""The web viewer in a real browser: ``warpsim view --web``'s servers on the loopback address,
opened in headless Chromium (the system's package), load the recording without console errors
or exceptions, the 3D view draws the spheres, and the page never asks for another address.

Skipped, with the reason, where Chromium is not installed or cannot start. Bounded in time:
the page gets :data:`LOAD_DEADLINE_S` to draw the spheres, and every process is killed at the
end. Only 127.0.0.1 is contacted (see ``headless_chromium``).
"""

import time

import numpy as np
import pytest
from PIL import Image

import warpsim as ws

pytest.importorskip("rerun")

from headless_chromium import Browser, chromium_path, is_loopback  # noqa: E402

from warpsim.export.rerun import sphere_colors, write_rerun  # noqa: E402
from warpsim.export.rerun_viewer import WebViewer, viewer_environment  # noqa: E402

LOAD_DEADLINE_S = 240.0  # the wasm viewer on a software rasteriser: 40 s here, more when busy
POLL_S = 5.0
SIZE = (1280, 800)
#: The 3D view of the recording's layout: the left three quarters, below the top bar and above
#: the time panel (fractions of the page's width and height).
VIEW_BOX = (0.18, 0.12, 0.58, 0.6)
SPHERE_PIXELS = 0.02  # share of the view's pixels that must show a sphere's hue


def big_spheres_recording(path):
    """Nine large spheres over a floor, for 20 frames: they fill much of the view."""
    boxes = ws.RoundedBoxes(center=[[0.0, -0.1, 0.0]], half_extents=[[3.0, 0.1, 3.0]],
                            radius=0.05)
    grid = np.stack(np.meshgrid([-1.6, 0.0, 1.6], [-1.6, 0.0, 1.6]), -1).reshape(-1, 2)
    frames = np.arange(0, 20)
    position = np.zeros((frames.size, 9, 3))
    position[:, :, 0], position[:, :, 2] = grid[:, 0], grid[:, 1]
    position[:, :, 1] = 1.0 + 0.02 * frames[:, None]
    traj = ws.Trajectory(frame=frames, dt=0.05, position=position,
                         orientation=np.tile([0.0, 0.0, 0.0, 1.0], (frames.size, 9, 1)),
                         radius=np.full(9, 0.7))
    return write_rerun(path, ws.Scene(boxes, name="big"), traj)


def hue_share(image: Image.Image, colors: np.ndarray) -> float:
    """Share of the 3D view's pixels whose hue is within 0.03 of a sphere colour's hue and
    that are saturated (the viewer's own chrome is grey, white and one accent)."""
    w, h = image.size
    x0, y0, x1, y1 = (int(VIEW_BOX[0] * w), int(VIEW_BOX[1] * h), int(VIEW_BOX[2] * w),
                      int(VIEW_BOX[3] * h))
    hsv = np.asarray(image.convert("RGB").crop((x0, y0, x1, y1)).convert("HSV"),
                     dtype=np.float64) / 255.0
    wanted = np.asarray(Image.fromarray(colors[None].astype(np.uint8)).convert("HSV"),
                        dtype=np.float64)[0, :, 0] / 255.0
    distance = np.abs(hsv[..., 0, None] - wanted)
    near = np.minimum(distance, 1.0 - distance).min(axis=-1) < 0.03
    return float(np.mean(near & (hsv[..., 1] > 0.35) & (hsv[..., 2] > 0.25)))


@pytest.mark.slow
def test_web_viewer_loads_the_recording_in_headless_chromium(tmp_path):
    executable = chromium_path()
    if executable is None:
        pytest.skip("no chromium executable (.ci/run installs the system's chromium package)")
    recording = big_spheres_recording(tmp_path / "big.rrd")
    colors = sphere_colors(np.arange(9))
    with viewer_environment() as (env, folder):
        with WebViewer(recording, env=env, log=folder / "viewer.log") as viewer:
            assert viewer.url.startswith("http://127.0.0.1:")
            try:
                browser = Browser(executable, size=SIZE)
            except OSError as exc:
                pytest.skip(f"chromium cannot start here: {exc}")
            with browser:
                try:
                    browser.open(viewer.url)
                except (RuntimeError, TimeoutError) as exc:
                    pytest.skip(f"chromium cannot run here: {exc}")
                deadline = time.monotonic() + LOAD_DEADLINE_S
                share, shot = 0.0, tmp_path / "page.png"
                while time.monotonic() < deadline:
                    browser.pump(POLL_S)
                    browser.screenshot(shot)
                    share = hue_share(Image.open(shot), colors)
                    if share >= SPHERE_PIXELS:
                        break
                browser.pump(POLL_S)  # late errors of the first frames drawn
                errors = [text for level, text in browser.console
                          if level in ("error", "assert")]
                requested = list(browser.requested)
    image = np.asarray(Image.open(shot).convert("L"), dtype=np.float64)
    assert image.std() > 10.0, "the page is blank"
    assert share >= SPHERE_PIXELS, (f"the spheres were not drawn within {LOAD_DEADLINE_S} s "
                                    f"({share:.3%} of the view); screenshot {shot}")
    assert not errors, errors
    assert not browser.exceptions, browser.exceptions
    assert any(f":{viewer.grpc_port}/" in url for url in requested)  # it read the recording
    assert all(is_loopback(url) for url in requested), [u for u in requested
                                                        if not is_loopback(u)]
