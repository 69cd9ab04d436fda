"""The ``warpsim`` command end to end, in a subprocess, as a user runs it."""

import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

import warpsim as ws
from warpsim.distributed.draw import sharded_spawn  # the command line's draw


def warpsim(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "warpsim.apps.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


@pytest.mark.slow
def test_scenes_lists_every_bundled_scene():
    out = warpsim("scenes")
    assert out.returncode == 0, out.stderr
    names = [line.split()[0] for line in out.stdout.strip().splitlines()]
    assert names == [name for name, _ in ws.list_scenes()]
    assert {"room", "galton", "staircase", "pinball", "thin-walls", "wedge", "spin",
            "nozzle"} <= set(names)


@pytest.mark.slow
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
    sim = ws.Simulator(scene, sharded_spawn(scene, 24, 5))
    expected = sim.run(12)
    np.testing.assert_array_equal(traj.position, expected.position.astype(np.float32))

    png = tmp_path / "frame.png"
    out = warpsim("preview", usd, "--frame", 7, "-o", png, "--size", "320x180")
    assert out.returncode == 0, out.stderr
    with Image.open(png) as image:
        assert image.size == (320, 180)


@pytest.mark.slow
def test_run_every_and_usda(tmp_path):
    usd = tmp_path / "room.usda"
    out = warpsim("run", "room", "-n", 10, "--frames", 9, "--every", 4, "-o", usd,
                  "--no-progress")
    assert out.returncode == 0, out.stderr
    np.testing.assert_array_equal(ws.export.read_usd(usd).frame, [0, 4, 8, 9])


@pytest.mark.slow
def test_run_default_output_name_in_working_directory(tmp_path):
    out = warpsim("run", "spin", "-n", 4, "--frames", 2, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "spin.usdc").is_file()
    assert "frames" in out.stderr  # the progress bar goes to standard error


@pytest.mark.slow
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
def test_errors_are_one_line_and_nonzero(args, message, tmp_path, capsys, monkeypatch):
    """In this process (the entry point the console script calls), for speed; the subprocess
    tests below check the real standard error, Warp's native output included."""
    from warpsim.apps.cli import main

    monkeypatch.chdir(tmp_path)
    try:
        code = main(list(args))
    except SystemExit as exit_:  # argparse's usage errors
        code = exit_.code
    assert code != 0
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("warpsim: error:") and message in lines[0], lines[0]
    assert "Traceback" not in err
    assert list(tmp_path.iterdir()) == []  # nothing written, no partial file


@pytest.mark.slow
def test_output_under_a_file_is_refused(tmp_path):
    (tmp_path / "plain").write_text("not a directory")
    out = warpsim("run", "wedge", "-n", 4, "--frames", 2, "-o", tmp_path / "plain" / "w.usdc")
    assert out.returncode != 0
    assert "warpsim: error:" in out.stderr and "Traceback" not in out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain"]


@pytest.mark.slow
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


@pytest.mark.slow
def test_debug_shows_the_traceback(tmp_path):
    out = warpsim("--debug", "run", "no-such-scene", cwd=tmp_path)
    assert out.returncode != 0 and "Traceback" in out.stderr


# --------------------------------------------------------------------------------------------
# In-process runs of the same entry point (faster than a subprocess), for the options


def cli(capsys, *args, cwd=None, monkeypatch=None):
    """``warpsim ARGS`` in this process: (exit code, stdout, stderr)."""
    from warpsim.apps.cli import main

    if cwd is not None:
        monkeypatch.chdir(cwd)
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("warpsim: error:") and "Traceback" not in err
    return lines[0]


def test_version(capsys):
    with pytest.raises(SystemExit) as info:
        cli(capsys, "--version")
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"warpsim {ws.__version__}"


def test_output_names_checked_before_simulating(tmp_path, capsys):
    for output, message in (("", "empty"), (tmp_path / "x.obj", "must end in .usdc or .usda"),
                            ("/proc/x.usdc", "cannot write output '/proc/x.usdc'")):
        code, out, err = cli(capsys, "run", "wedge", "-n", 4, "--frames", 2, "-o", output)
        assert code != 0 and message in one_error_line(err)
        assert "simulated" not in out  # refused before the run
    code, out, err = cli(capsys, "run", "wedge", "-n", 4, "--frames", 2, "-o",
                         tmp_path / "w.USDC", "--no-progress")
    assert code == 0, err
    assert [p.name for p in tmp_path.iterdir()] == ["w.USDC"]
    assert (tmp_path / "w.USDC").read_bytes()[:8] == b"PXR-USDC"


def test_size_estimate_checked_before_simulating(tmp_path, capsys):
    code, out, err = cli(capsys, "run", "room", "-n", 50, "--frames", 100, "-o",
                         tmp_path / "r.usdc", "--max-bytes", 1000)
    line = one_error_line(err)
    assert code != 0 and "--max-bytes" in line and "MB" in line
    assert "simulated" not in out and list(tmp_path.iterdir()) == []


def test_frame_range_and_sphere_subset(tmp_path, capsys):
    usd = tmp_path / "w.usda"
    code, out, err = cli(capsys, "run", "wedge", "-n", 20, "--frames", 30, "--seed", 2,
                         "--start", 10, "--end", 20, "--every", 4, "--spheres", "3:9:2",
                         "-o", usd, "--no-progress")
    assert code == 0, err
    traj = ws.export.read_usd(usd)
    np.testing.assert_array_equal(traj.frame, [10, 14, 18, 20])
    scene = ws.Scene.load("wedge")
    expected = ws.Simulator(scene, sharded_spawn(scene, 20, 2)).run(20)
    np.testing.assert_array_equal(traj.position,
                                  expected.position[[10, 14, 18, 20]][:, [3, 5, 7]]
                                  .astype(np.float32))
    assert "simulated 20 frames" in out  # the run stopped at --end
    code, out, err = cli(capsys, "run", "wedge", "-n", 20, "--frames", 3, "--spheres", "0,19,4",
                         "-o", usd, "--no-progress")
    assert code == 0, err
    assert ws.export.read_usd(usd).sphere_count == 3
    for args, message in ((("--spheres", "5"), "range A:B or a list"),
                          (("--spheres", "0,20"), "out of range"),
                          (("--spheres", "30:40"), "selects no sphere"),
                          (("--start", 5, "--end", 5), "before --end"),
                          (("--end", 9, "--frames", 3), "past --frames")):
        code, _, err = cli(capsys, "run", "wedge", "-n", 20, "-o", usd, *args)
        assert code != 0 and message in one_error_line(err)


def test_lossy_scene_reports_energy_lost_not_drift(tmp_path, capsys):
    code, out, err = cli(capsys, "run", "staircase", "-n", 20, "--frames", 60, "-o",
                         tmp_path / "s.usdc", "--no-progress")
    assert code == 0, err
    assert "energy lost at contacts:" in out and "energy drift" not in out
    assert "energy_retention = 0.8" in out


def test_preview_frames_from_the_end_and_image_formats(tmp_path, capsys):
    usd = tmp_path / "w.usdc"
    assert cli(capsys, "run", "wedge", "-n", 6, "--frames", 4, "-o", usd, "--no-progress")[0] == 0
    code, out, err = cli(capsys, "preview", usd, "--frame", -1, "-o", tmp_path / "a.jpg",
                         "--size", "64x48")
    assert code == 0, err
    assert "frame 4" in out
    with Image.open(tmp_path / "a.jpg") as image:
        assert image.format == "JPEG" and image.size == (64, 48)
    code, out, err = cli(capsys, "preview", usd, "--frame", -5, "-o", tmp_path / "b.png",
                         "--size", "64x48", "--azimuth", 120, "--elevation", 10)
    assert code == 0 and "frame 0" in out, err
    for args, message in ((("--frame", -6, "-o", tmp_path / "c.png"), "only 5"),
                          (("--frame", 2, "-o", tmp_path / "c.xyz"), "must end in"),
                          ((), "-o IMAGE or --movie")):
        code, _, err = cli(capsys, "preview", usd, *args)
        assert code != 0 and message in one_error_line(err)


def test_preview_movie(tmp_path, capsys):
    pytest.importorskip("imageio")
    usd = tmp_path / "w.usdc"
    assert cli(capsys, "run", "wedge", "-n", 6, "--frames", 6, "-o", usd, "--no-progress")[0] == 0
    code, out, err = cli(capsys, "preview", usd, "--movie", tmp_path / "w.gif", "--every", 2,
                         "--size", "48x32", "--no-progress")
    assert code == 0, err
    with Image.open(tmp_path / "w.gif") as gif:  # frames 0, 2, 4, 6 of dt = 1/60 s
        assert gif.size == (48, 32)
        total = 0
        for k in range(gif.n_frames):  # Pillow merges identical frames, adding their durations
            gif.seek(k)
            total += gif.info["duration"]
    assert total == pytest.approx(4 * 2 * 1000 / 60, abs=4 * 10)


@pytest.mark.slow
def test_velocities_and_events_options(tmp_path, capsys):
    """Motion data and contact events: the file holds the simulator's own values."""
    usd = tmp_path / "w.usdc"
    code, out, err = cli(capsys, "run", "wedge", "-n", 6, "--frames", 5, "--seed", 3,
                         "-o", usd, "--velocities", "--no-progress")
    assert code == 0, err
    traj = ws.export.read_usd(usd)
    scene = ws.Scene.load("wedge")
    expected = ws.Simulator(scene, sharded_spawn(scene, 6, 3)).run(5, velocities=True)
    # the file holds the simulator's velocities at each recorded frame, to the float32 bit
    np.testing.assert_array_equal(traj.velocity, expected.velocity.astype(np.float32))
    np.testing.assert_allclose(traj.angular_velocity, expected.angular_velocity,
                               rtol=1e-6, atol=1e-30)
    code, _, err = cli(capsys, "run", "wedge", "-o", usd, "--events", tmp_path / "hits.csv")
    assert code != 0 and ".parquet" in one_error_line(err)
    assert "hits.parquet" not in [p.name for p in tmp_path.iterdir()]
    code, _, err = cli(capsys, "run", "wedge", "-o", usd, "--events-capacity", 8)
    assert code != 0 and "--events-capacity needs --events" in one_error_line(err)
    pytest.importorskip("pyarrow")
    events = tmp_path / "hits.parquet"
    code, out, err = cli(capsys, "run", "wedge", "-n", 6, "--frames", 5, "-o", usd,
                         "--events", events, "--no-progress")
    assert code == 0, err
    assert len(ws.ContactEvents.read_parquet(events)) > 0


@pytest.mark.slow
def test_warp_start_up_chatter_is_silenced_and_bad_device_is_one_line(tmp_path):
    out = warpsim("run", "wedge", "-n", 4, "--frames", 2, "-o", tmp_path / "w.usdc",
                  "--no-progress")
    assert out.returncode == 0, out.stderr
    assert "Warp" not in out.stderr, out.stderr
    import warp as wp

    if not wp.is_cuda_available():
        out = warpsim("run", "wedge", "-n", 4, "--device", "cuda", "-o", tmp_path / "x.usdc")
        assert out.returncode != 0
        assert "device 'cuda' is not available" in one_error_line(out.stderr)


@pytest.mark.slow
def test_forwarded_commands_show_their_own_usage():
    out = warpsim("bench", "--help")
    assert out.returncode == 0, out.stderr
    first = out.stdout.splitlines()[0]
    assert first.startswith("usage: warpsim bench")


def test_accuracy_is_forwarded():
    from warpsim.apps.cli import main

    with pytest.raises(SystemExit) as info:
        main(["accuracy", "--help"])
    assert info.value.code == 0


@pytest.mark.slow
def test_python_dash_m_warpsim_is_the_command_line():
    from warpsim import __version__

    out = subprocess.run([sys.executable, "-m", "warpsim", "--version"], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == f"warpsim {__version__}"


CONSOLE = """
import atexit, sys
atexit.register(lambda: print("exit handler ran"))
sys.argv = ["warpsim", *sys.argv[1:]]
from warpsim.apps.cli import console
console()
print("never reached")
"""


@pytest.mark.slow
@pytest.mark.parametrize("args,code", [(["scenes"], 0), (["--version"], 0),
                                       (["run", "no-such-scene"], 1), (["run"], 2),
                                       (["no-such-command"], 2)])
def test_the_command_ends_with_its_code_its_output_and_its_exit_handlers(args, code):
    """The console script ends the process itself, without the interpreter's teardown, once
    :func:`main` returns: with main's exit code (usage errors 2, errors 1), everything it wrote
    on both streams, then what the ``atexit`` handlers print, and nothing after."""
    out = subprocess.run([sys.executable, "-c", CONSOLE, *args], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == code, out.stderr
    assert out.stdout.endswith("exit handler ran\n")
    assert "never reached" not in out.stdout
    if args == ["scenes"]:
        names = [line.split()[0] for line in out.stdout.strip().splitlines()[:-1]]
        assert names == [name for name, _ in ws.list_scenes()]
    if code:
        assert out.stderr.strip(), "an error says why"


@pytest.mark.slow
def test_a_system_exit_with_a_message_is_code_1_and_the_message(monkeypatch, capsys):
    """``SystemExit("message")`` out of :func:`main` (as a study or a library may raise) ends
    the command as Python would: the message on standard error and code 1."""
    from warpsim.apps import cli as cli_module

    ended = []

    def stop(*_):
        raise SystemExit("warpsim: something said why")

    monkeypatch.setattr(cli_module, "main", stop)
    monkeypatch.setattr(cli_module, "fast_exit", ended.append)
    cli_module.console()
    assert ended == [1]
    assert capsys.readouterr().err == "warpsim: something said why\n"


def test_the_command_leaves_what_its_imports_made_out_of_the_collections(monkeypatch):
    """The console script freezes the objects that exist before its command runs, so full
    collections during a run do not walk the imports' objects again; objects made after are
    still collected (a cycle made during the command is freed)."""
    import gc
    import weakref

    from warpsim.apps import cli as cli_module

    class Node:
        pass

    freed = []

    def command():
        assert gc.get_freeze_count() > 0, "frozen before the command runs"
        node = Node()
        node.self = node  # a cycle: only the collector frees it
        weakref.finalize(node, freed.append, True)
        del node
        gc.collect()
        return 0

    monkeypatch.setattr(cli_module, "main", command)
    monkeypatch.setattr(cli_module, "fast_exit", lambda code: None)
    gc.unfreeze()
    try:
        cli_module.console()
    finally:
        gc.unfreeze()  # this test process goes on
    assert freed == [True]


@pytest.mark.parametrize("start", [0, 3])
def test_a_run_with_events_builds_the_plain_kernel_only_to_step_to_its_start(tmp_path, capsys,
                                                                            monkeypatch, start):
    """``--events`` records every simulated frame's contacts, so the command builds the kernel
    with the contact code alone (a first build of one kernel, not two), and the plain one too
    when it steps to ``--start`` first; the events it writes are the library's run's."""
    builds = []
    real_build = ws.Simulator.build

    def spy(self, events=False, plain=True):
        builds.append((events, plain))
        return real_build(self, events=events, plain=plain)

    monkeypatch.setattr(ws.Simulator, "build", spy)
    pytest.importorskip("pyarrow")
    table = tmp_path / "hits.parquet"
    code, _, err = cli(capsys, "run", "wedge", "-n", 40, "--frames", 30, "--start", start,
                       "--seed", 5, "-o", tmp_path / "a.usdc", "--events", table,
                       "--no-progress")
    assert code == 0, err
    assert builds == [(True, start > 0)]
    scene = ws.Scene.load("wedge")
    sim = ws.Simulator(scene, sharded_spawn(scene, 40, 5))
    if start:
        sim.step(start)
    expected = sim.run(30 - start, events=True).events
    written = ws.ContactEvents.read_parquet(table)
    assert len(written) == len(expected) > 0
    np.testing.assert_array_equal(written.frame, expected.frame)
    np.testing.assert_array_equal(written.position, expected.position)


def test_a_long_kernel_build_says_what_the_run_waits_for(tmp_path, capsys, monkeypatch):
    """A build longer than ``BUILD_NOTICE_S`` (a first build on a slow machine) is named
    on standard error while it runs; a quick one says nothing."""
    import time

    from warpsim.apps import cli as cli_module

    real_build = ws.Simulator.build

    def slow_build(self, events=False, plain=True):
        time.sleep(0.3)
        return real_build(self, events=events, plain=plain)

    monkeypatch.setattr(ws.Simulator, "build", slow_build)
    monkeypatch.setattr(cli_module, "BUILD_NOTICE_S", 0.05)
    code, _, err = cli(capsys, "run", "room", "-n", 5, "--frames", 2, "-o",
                       tmp_path / "a.usdc", "--no-progress")
    assert code == 0
    assert "building the frame kernel for cpu (linear, float32): a first build" in err
    monkeypatch.setattr(cli_module, "BUILD_NOTICE_S", 30.0)
    code, _, err = cli(capsys, "run", "room", "-n", 5, "--frames", 2, "-o",
                       tmp_path / "b.usdc", "--no-progress")
    assert code == 0 and "building the frame kernel" not in err
