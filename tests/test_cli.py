"""The ``warpsim`` command end to end, in a subprocess, as a user runs it."""

import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

import warpsim as ws


def warpsim(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "warpsim.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def test_scenes_lists_every_bundled_scene():
    out = warpsim("scenes")
    assert out.returncode == 0, out.stderr
    names = [line.split()[0] for line in out.stdout.strip().splitlines()]
    assert names == [name for name, _ in ws.list_scenes()]
    assert {"room", "galton", "staircase", "pinball", "thin-walls", "wedge", "spin"} <= set(names)


def test_run_writes_usd_and_preview_draws_a_frame(tmp_path):
    usd = tmp_path / "wedge.usdc"
    out = warpsim("run", "wedge", "-n", 24, "--frames", 12, "--seed", 5, "-o", usd,
                  "--no-progress")
    assert out.returncode == 0, out.stderr
    assert "sphere-frames/s" in out.stdout and "capped" in out.stdout
    assert "energy drift" in out.stdout and str(usd) in out.stdout
    traj = ws.export.read_usd(usd)
    np.testing.assert_array_equal(traj.frame, np.arange(13))  # the start and 12 frames
    assert traj.position.shape == (13, 24, 3)
    # the file holds what the simulator computes for the same scene, seed and count
    scene = ws.Scene.load("wedge")
    sim = ws.Simulator(scene, scene.spawn(n=24, seed=5))
    expected = sim.run(12)
    np.testing.assert_array_equal(traj.position, expected.position.astype(np.float32))

    png = tmp_path / "frame.png"
    out = warpsim("preview", usd, "--frame", 7, "-o", png, "--size", "320x180")
    assert out.returncode == 0, out.stderr
    with Image.open(png) as image:
        assert image.size == (320, 180)


def test_run_every_and_usda(tmp_path):
    usd = tmp_path / "room.usda"
    out = warpsim("run", "room", "-n", 10, "--frames", 9, "--every", 4, "-o", usd,
                  "--no-progress")
    assert out.returncode == 0, out.stderr
    np.testing.assert_array_equal(ws.export.read_usd(usd).frame, [0, 4, 8, 9])


def test_run_default_output_name_in_working_directory(tmp_path):
    out = warpsim("run", "spin", "-n", 4, "--frames", 2, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "spin.usdc").is_file()
    assert "frames" in out.stderr  # the progress bar goes to standard error


@pytest.mark.parametrize("args,message", [
    (("run", "no-such-scene"), "unknown scene 'no-such-scene'"),
    (("run", "room", "-n", "-3"), "n must be >= 1"),
    (("run", "room", "--dt", "0"), "dt must be > 0"),
    (("run", "room", "--frames", "0"), "frames must be >= 1"),
    (("run", "room", "-o", "/no/such/dir/out.usdc"), "does not exist"),
    (("run", "room", "-o", "out.obj"), "must end in .usdc or .usda"),
    (("run", "room", "--precision", "float16"), "invalid choice"),
    (("preview", "missing.usdc", "-o", "x.png"), "missing.usdc"),
    (("frobnicate",), "invalid choice"),
])
def test_errors_are_one_line_and_nonzero(args, message, tmp_path):
    out = warpsim(*args, cwd=tmp_path)
    assert out.returncode != 0
    lines = [line for line in out.stderr.splitlines() if not line.startswith("Warp CUDA")]
    assert len(lines) == 1, out.stderr
    assert lines[0].startswith("warpsim: error:") and message in lines[0], lines[0]
    assert "Traceback" not in out.stderr
    assert list(tmp_path.iterdir()) == []  # nothing written, no partial file


def test_output_under_a_file_is_refused(tmp_path):
    (tmp_path / "plain").write_text("not a directory")
    out = warpsim("run", "wedge", "-n", 4, "--frames", 2, "-o", tmp_path / "plain" / "w.usdc")
    assert out.returncode != 0
    assert "warpsim: error:" in out.stderr and "Traceback" not in out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain"]


def test_unwritable_output_leaves_nothing(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        out = warpsim("run", "wedge", "-n", 4, "--frames", 2, "-o", locked / "w.usdc")
        if out.returncode == 0:  # running as a user that ignores permissions
            pytest.skip("this user can write into a read-only directory")
        assert "warpsim: error:" in out.stderr and "Traceback" not in out.stderr
        assert list(locked.iterdir()) == []
    finally:
        locked.chmod(0o700)


def test_debug_shows_the_traceback(tmp_path):
    out = warpsim("--debug", "run", "no-such-scene", cwd=tmp_path)
    assert out.returncode != 0 and "Traceback" in out.stderr
