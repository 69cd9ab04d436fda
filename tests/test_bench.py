"""``warpsim bench``: the throughput measure of one scene, through ``warpsim.apps.bench.main``
and the console script. Figures are checked for consistency and against an analytic bounce
count, never for speed."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import warpsim as ws
from warpsim.apps import bench

#: Two walls with inner faces at x = -1 and x = +1, no gravity, point spheres starting at
#: x = 0.25 at 30 m/s along +x: 0.5 m per frame at dt = 1/60 s, so the centre is at 0.75 after
#: frame 1, meets the wall during frame 2 (back to 0.75), then 0.25, -0.25, -0.75, meets the
#: other wall during frame 6, and so on: one contact every 4 frames, each 0.25 m from any frame
#: boundary (no rounding can move it to another frame).
CORRIDOR = """\
name = "corridor"

[simulation]
dt = 0.016666666666666666
frames = 8

[physics]
gravity = [0.0, 0.0, 0.0]

[[box]]
center = [1.5, 0.0, 0.0]
half_extents = [0.5, 2.0, 2.0]

[[box]]
center = [-1.5, 0.0, 0.0]
half_extents = [0.5, 2.0, 2.0]

[emitter]
count = 7
center = [0.25, 0.0, 0.0]
half_extents = [0.0, 0.0, 0.0]
radius = 0.0
velocity = [30.0, 0.0, 0.0]
"""

KEYS = {"scene", "n", "frames", "dt", "precision", "broad_phase", "workers", "build_s",
        "build_cached", "seconds", "sphere_frames_per_s", "ns_per_sphere_frame",
        "bounces_per_sphere_frame", "capped", "machine"}


def run_main(argv) -> int:
    """``bench.main`` with argparse's exits turned into exit codes."""
    try:
        return bench.main([str(a) for a in argv])
    except SystemExit as exc:
        return exc.code


def check_figures(r: dict, n: int, frames: int) -> None:
    assert KEYS <= set(r)
    assert r["n"] == n and r["frames"] == frames
    assert r["seconds"] > 0 and r["build_s"] >= 0
    assert r["sphere_frames_per_s"] == pytest.approx(n * frames / r["seconds"], rel=1e-12)
    assert r["ns_per_sphere_frame"] == pytest.approx(1e9 / r["sphere_frames_per_s"], rel=1e-12)
    assert r["broad_phase"] in ("brute", "bvh", "grid", "grid-bvh")
    assert r["machine"]["device"] == "cpu"
    assert r["machine"]["warpsim"] == ws.__version__
    assert {"python", "numpy", "warp", "cpu", "cores", "commit", "dirty"} <= set(r["machine"])


def test_main_prints_and_writes_json(tmp_path, capsys):
    out = tmp_path / "deep" / "bench.json"  # missing folders are made
    assert run_main(["room", "-n", 50, "--frames", 3, "--workers", 1, "--json", out]) == 0
    text = capsys.readouterr().out
    assert "sphere-frames/s" in text and "ns per sphere-frame" in text and "broad phase" in text
    r = json.loads(out.read_text())
    check_figures(r, 50, 3)
    assert r["scene"] == "room" and r["workers"] == 1 and r["boxes"] == 22
    assert r["precision"] == "float32"
    assert r["motion"] in (None, "linear")  # the Simulator's default, where it has one
    assert not list(out.parent.glob(".*.tmp"))  # the temporary file was renamed


@pytest.mark.slow
def test_bounce_count_is_exact_on_a_corridor(tmp_path, capsys):
    """Warm-up frame 1, timed frames 2-9: contacts in frames 2 and 6, 2 per sphere in 8 frames."""
    scene = tmp_path / "corridor.toml"
    scene.write_text(CORRIDOR)
    out = tmp_path / "c.json"
    for precision in ("float32", "float64"):
        for bp in ("brute", "grid"):
            assert run_main([scene, "--precision", precision, "--broad-phase", bp,
                             "--json", out]) == 0
            r = json.loads(out.read_text())
            check_figures(r, 7, 8)
            assert r["bounces_per_sphere_frame"] == 0.25
            assert r["capped"] == 0 and r["precision"] == precision
    capsys.readouterr()


def test_motion_is_passed_only_when_given(tmp_path):
    out = tmp_path / "m.json"
    assert run_main(["wedge", "-n", 4, "--frames", 2, "--motion", "ballistic", "--json", out]) == 0
    assert json.loads(out.read_text())["motion"] == "ballistic"
    assert run_main(["wedge", "-n", 4, "--frames", 2, "--json", out]) == 0
    assert json.loads(out.read_text())["motion"] == ws.Scene.load("wedge").motion


@pytest.mark.parametrize("argv, code, words", [
    (["room", "-n", "0"], 2, "-n/--count"),
    (["room", "--frames", "many"], 2, "--frames"),
    (["room", "--workers", "-1"], 2, "--workers"),
    (["room", "--precision", "float16"], 2, "--precision"),
    (["room", "--broad-phase", "octree"], 2, "--broad-phase"),
    (["room", "--motion", "warp-drive"], 2, "--motion"),
    (["no-such-scene"], 1, "unknown scene"),
    (["missing.toml"], 1, "not found"),
    (["room", "-n", "5", "--device", "cuda:97"], 1, "cuda:97"),
    ([], 2, "scene"),
])
def test_bad_options_are_one_line(argv, code, words, capsys):
    assert run_main(argv) == code
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("warpsim bench: error:") and words in lines[0]


def test_unwritable_json_is_refused_before_the_run(tmp_path, capsys):
    folder = tmp_path / "a-folder"
    folder.mkdir()
    assert run_main(["room", "-n", 5, "--frames", 1, "--json", folder]) == 1
    captured = capsys.readouterr()
    assert "is a folder" in captured.err and captured.out == ""  # nothing ran
    assert list(folder.iterdir()) == []


def console(*args):
    """The ``warpsim`` console script of this interpreter's environment (not another one on the
    PATH), or ``python -m warpsim`` where it has none."""
    exe = shutil.which("warpsim", path=str(Path(sys.executable).parent))
    cmd = [exe] if exe else [sys.executable, "-m", "warpsim"]
    return subprocess.run([*cmd, "bench", *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=Path(__file__).resolve().parent)


@pytest.mark.slow
def test_console_script(tmp_path):
    out = tmp_path / "cli.json"
    proc = console("wedge", "-n", 30, "--frames", 4, "--workers", 2, "--json", out)
    assert proc.returncode == 0, proc.stderr
    assert "sphere-frames/s" in proc.stdout
    r = json.loads(out.read_text())
    check_figures(r, 30, 4)
    assert r["scene"] == "wedge" and r["workers"] == 2

    bad = console("wedge", "--frames", "0")
    assert bad.returncode == 2
    lines = bad.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("warpsim bench: error:"), bad.stderr
