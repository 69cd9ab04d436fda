"""The USD file written by a process of its own (``warpsim.export.usd_process``).

Each case runs in a fresh interpreter: a fork is only taken where no other thread runs and pxr
is not loaded yet, which a test process (pytest's, its workers') is not. The files are compared
with those written in one process as text (``Sdf.Layer.ExportToString``: every attribute's
value at every time sample).
"""

import json
import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.slow

#: Shared by the scripts: a run of a bundled scene and its file written in this process.
PRELUDE = """
import json, os, sys
import numpy as np
import warpsim as ws
from warpsim.export import usd_process
from warpsim.distributed.draw import sharded_spawn

def run(name, n, frames, every, velocities=False):
    scene = ws.Scene.load(name)
    sim = ws.Simulator(scene, sharded_spawn(scene, n, 3))
    return scene, sim.run(frames, every=every, velocities=velocities)

def layer_text(path):
    from pxr import Sdf
    return Sdf.Layer.FindOrOpen(str(path)).ExportToString()

def spy_on_forks():
    # the list to which every UsdWriter made from now on appends whether it forked
    forks = []
    real = usd_process.UsdWriter.__init__
    def spy(self, write, **kwargs):
        real(self, write, **kwargs)
        forks.append(self.forked)
    usd_process.UsdWriter.__init__ = spy
    return forks
"""


def script(body: str, tmp_path, **env) -> dict:
    """Run ``PRELUDE + body`` in a fresh interpreter (working folder and ``TMPDIR`` under
    ``tmp_path``); its last line of output is JSON."""
    import os

    work = tmp_path / "work"
    work.mkdir(exist_ok=True)
    environment = dict(os.environ, TMPDIR=str(work), **env)
    out = subprocess.run([sys.executable, "-c", PRELUDE + textwrap.dedent(body)],
                         capture_output=True, text=True, timeout=600, cwd=tmp_path,
                         env=environment)
    assert out.returncode == 0, out.stderr
    assert not list(work.iterdir()), "the handoff's temporary folder was left behind"
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_forked_writer_writes_the_file_this_process_writes(tmp_path):
    # births (nozzle: unborn spheres, NaN rows), spin and velocities (spin), a float64 run
    # far from the origin (origins per frame), .usda and .usdc
    result = script(f"""
        assert usd_process.can_fork()
        cases = []
        for name, n, frames, every, velocities, suffix in (
                ("nozzle", 300, 90, 7, False, ".usdc"), ("spin", 200, 40, 3, True, ".usda"),
                ("room", 500, 30, 10, True, ".usdc")):
            scene, traj = run(name, n, frames, every, velocities)
            forked = "{tmp_path}/" + name + "-forked" + suffix
            here = "{tmp_path}/" + name + "-here" + suffix
            def write(trajectory, out=forked, scene=scene):
                return ws.export.write_usd(out, scene, trajectory, warn=False)
            with usd_process.UsdWriter(write, fork=True) as writer:  # (runs' threads)
                assert writer.forked and "pxr" not in sys.modules
                path = writer.write(traj)
            assert "pxr" not in sys.modules  # the child loaded it, not this process
            assert str(path) == forked
            cases.append((forked, here, scene, traj))
        # and a float64 swarm 10 km from the origin: the positions go through frame origins
        box = ws.Scene(ws.RoundedBoxes(center=[[1e4, 0.0, 0.0]],
                                       half_extents=[[1.0, 0.1, 1.0]]), name="far")
        swarm = ws.Swarm(position=[[1e4, 2.0, 0.0], [1e4 + 0.5, 3.0, 0.2]],
                         velocity=[[0.0, 0.0, 0.0], [0.3, 1.0, 0.0]], radius=[0.1, 0.05])
        far = ws.Simulator(box, swarm, precision="float64").run(30, every=4)
        forked, here = "{tmp_path}/far-forked.usdc", "{tmp_path}/far-here.usdc"
        with usd_process.UsdWriter(lambda t: ws.export.write_usd(forked, box, t),
                                   fork=True) as writer:
            writer.write(far)
        cases.append((forked, here, box, far))
        same = []
        for forked, here, scene, traj in cases:
            ws.export.write_usd(here, scene, traj, warn=False)
            same.append(layer_text(forked) == layer_text(here))
        print(json.dumps({{"same": same}}))
    """, tmp_path)
    assert result["same"] == [True] * 4


def test_the_child_gets_the_trajectory_bit_for_bit_and_read_only(tmp_path):
    # recorded into the shared memory (no file: np.save would fail), into a reserve too small
    # for them (the frames beyond it through files), without one (files), and the radii of a
    # large swarm (a file) beside small arrays (through the pipe)
    result = script("""
        import hashlib
        def digest(t):
            h = hashlib.sha256()
            for name in usd_process.HANDED_FIELDS:
                value = getattr(t, name)
                h.update(name.encode())
                h.update(np.ascontiguousarray(value).tobytes() if isinstance(value, np.ndarray)
                         else repr(value).encode())
            return h.hexdigest()
        def write(t):
            writable = [name for name in usd_process.HANDED_FIELDS
                        if isinstance(getattr(t, name), np.ndarray)
                        and getattr(t, name).flags.writeable]
            return os.getpid(), digest(t), writable, t.events is None
        scene = ws.Scene.load("nozzle")
        swarm = sharded_spawn(scene, 600, 3)
        expected = ws.Simulator(scene, swarm).run(60, every=6, velocities=True)
        need = sum(getattr(expected, name).nbytes
                   for name in ("position", "orientation", "velocity", "angular_velocity"))
        real_save = np.save
        seen = {}
        for case, share in (("shared", need + 4 * usd_process.SHARED_ALIGN),
                            ("short", need // 3), ("none", 0)):
            saved = []
            def save(path, value):
                if case == "shared":
                    raise OSError("no file expected")
                saved.append(os.path.basename(path))
                real_save(path, value)
            usd_process.np.save = save
            usd_process.PICKLED_MAX_BYTES = 1 << 22 if case == "shared" else 0
            # fork=True: the simulator's idle worker threads of the run before may still be
            # alive, which the command never has at its fork (can_fork)
            with usd_process.UsdWriter(write, fork=True, share_bytes=share) as writer:
                traj = ws.Simulator(scene, swarm).run(60, every=6, velocities=True,
                                                       allocate=writer.empty)
                pid, seen_digest, writable, no_events = writer.write(traj)
            seen[case] = {"child": pid != os.getpid(), "same": seen_digest == digest(expected),
                          "writable": writable, "no_events": no_events,
                          "files": sorted(saved)}
        seen["births"] = expected.birth_frame is not None
        seen["nan"] = bool(np.isnan(expected.position).any())
        print(json.dumps(seen))
    """, tmp_path)
    common = {"child": True, "same": True, "writable": [], "no_events": True}
    assert result["shared"] == {**common, "files": []}
    every = {f"{name}.npy" for name in ("frame", "position", "orientation", "radius",
                                        "velocity", "angular_velocity", "birth_frame")}
    assert result["none"] == {**common, "files": sorted(every)}
    short = set(result["short"].pop("files"))  # the position fits in the reserve, not the rest
    assert result["short"] == common and short == every - {"position.npy"}
    assert result["births"] and result["nan"]


def test_errors_come_back_as_raised_and_a_lost_child_is_replaced_by_this_process(tmp_path):
    result = script("""
        scene, traj = run("room", 50, 10, 5)
        seen = {}
        def failing(t):
            raise ValueError("spheres[3]: not a sphere")
        try:
            with usd_process.UsdWriter(failing) as writer:
                writer.write(traj)
        except ValueError as exc:
            seen["value_error"] = str(exc)
        def odd(t):
            class Odd(Exception):  # a class local to a function: it does not pickle
                pass
            raise Odd("bad")
        try:
            with usd_process.UsdWriter(odd) as writer:
                writer.write(traj)
        except RuntimeError as exc:
            seen["unpicklable"] = str(exc).startswith("Odd: bad")
        # the child killed before the handoff: this process writes it
        with usd_process.UsdWriter(lambda t: os.getpid()) as writer:
            writer._process.kill()
            writer._process.join()
            seen["lost"] = writer.write(traj) == os.getpid()
        # above the handoff's size outside the shared memory: written here, the child ended
        usd_process.HANDOFF_MAX_BYTES = 0
        usd_process.PICKLED_MAX_BYTES = 0
        with usd_process.UsdWriter(lambda t: os.getpid()) as writer:
            child = writer._process
            seen["large"] = writer.write(traj) == os.getpid() and not child.is_alive()
        usd_process.HANDOFF_MAX_BYTES = 1 << 30
        usd_process.PICKLED_MAX_BYTES = 1 << 22
        # shared memory refused (a mapping larger than the machine allows): files instead
        import mmap
        real_mmap = mmap.mmap
        def no_room(*args, **kwargs):
            raise OSError(12, "Cannot allocate memory")
        mmap.mmap = no_room
        with usd_process.UsdWriter(lambda t: (os.getpid(), t.position.tolist()),
                                   share_bytes=1 << 20) as writer:
            position = writer.empty(traj.position.shape, traj.position.dtype)
            position[...] = traj.position
            pid, got = writer.write(ws.Trajectory(**{**traj.__dict__, "position": position}))
            seen["no_room"] = (writer._shared is None and pid != os.getpid()
                               and got == traj.position.tolist())
        mmap.mmap = real_mmap
        # interrupted while the child writes: it stops, its partial file removed, at once
        import signal, time
        from warpsim.export.files import atomic_output
        def slow(t):
            with atomic_output("slow.usdc") as tmp:
                tmp.write_bytes(b"partial")
                time.sleep(60)
        def interrupt(*_):
            raise KeyboardInterrupt
        signal.signal(signal.SIGALRM, interrupt)
        began = time.perf_counter()
        try:
            with usd_process.UsdWriter(slow) as writer:
                child = writer._process
                signal.alarm(2)
                writer.write(traj)
        except KeyboardInterrupt:
            seen["interrupted"] = (time.perf_counter() - began < 10.0
                                   and child.exitcode not in (0, None)
                                   and sorted(os.listdir(".")) == ["work"])
        # a child that is never asked ends when closed
        writer = usd_process.UsdWriter(lambda t: 0)
        child = writer._process
        writer.close()
        seen["closed"] = not child.is_alive() and child.exitcode == 0 and not writer.forked
        # where pxr is loaded already, or another thread runs, no fork is taken
        import threading
        event = threading.Event()
        thread = threading.Thread(target=event.wait)
        thread.start()
        seen["thread"] = usd_process.can_fork()
        event.set()
        thread.join()
        import pxr  # noqa: F401
        seen["pxr"] = usd_process.can_fork()
        with usd_process.UsdWriter(lambda t: os.getpid()) as writer:
            seen["here"] = (not writer.forked) and writer.write(traj) == os.getpid()
        print(json.dumps(seen))
    """, tmp_path)
    assert result == {"value_error": "spheres[3]: not a sphere", "unpicklable": True,
                      "lost": True, "large": True, "no_room": True, "interrupted": True,
                      "closed": True,
                      "thread": False, "pxr": False, "here": True}


def test_the_command_writes_its_file_in_a_child_and_never_loads_pxr(tmp_path):
    # the command as a program calls it: the first run forks (no pxr in this process after
    # it), the second is told to write here; the same file
    result = script(f"""
        from warpsim.apps import cli
        forks = spy_on_forks()
        shared = []
        real_write = usd_process.UsdWriter.write
        def spy_write(self, trajectory):
            shared.append([self._in_shared(getattr(trajectory, name)) is not None
                           for name in ("position", "orientation", "velocity",
                                        "angular_velocity")])
            return real_write(self, trajectory)
        usd_process.UsdWriter.write = spy_write
        args = ["run", "nozzle", "-n", "400", "--frames", "60", "--every", "5",
                "--no-progress", "--velocities", "--spheres", "3:300"]
        first = cli.main(args + ["-o", "{tmp_path}/a.usdc"])
        pxr_after = "pxr" in sys.modules
        usd_process.can_fork = lambda: False
        second = cli.main(args + ["-o", "{tmp_path}/b.usdc"])
        print(json.dumps({{"codes": [first, second], "forks": forks, "pxr": pxr_after,
                          "shared": shared, "same": layer_text("{tmp_path}/a.usdc")
                          == layer_text("{tmp_path}/b.usdc")}}))
    """, tmp_path)
    # the forked run recorded every frame in the shared memory the child reads
    assert result == {"codes": [0, 0], "forks": [True, False], "pxr": False, "same": True,
                      "shared": [[True] * 4, [False] * 4]}


def test_a_failed_write_in_the_child_is_the_commands_one_line_error(tmp_path):
    # the writer raises in the child (patched before the fork, so the child has it too)
    result = script(f"""
        from warpsim.apps import cli
        forks = spy_on_forks()
        def failing(path, *args, **kwargs):
            raise OSError(f"USD could not write {{str(path)!r}}: disk full")
        ws.export.write_usd = failing
        import contextlib, io
        err, out = io.StringIO(), io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            code = cli.main(["run", "room", "-n", "50", "--frames", "5", "--no-progress",
                             "-o", "{tmp_path}/full.usdc"])
        lines = [line for line in err.getvalue().splitlines() if line.startswith("warpsim")]
        print(json.dumps({{"code": code, "forks": forks, "errors": lines,
                          "simulated": "simulated" in out.getvalue(),
                          "files": sorted(os.listdir("{tmp_path}"))}}))
    """, tmp_path)
    assert result["code"] == 1 and result["forks"] == [True] and result["simulated"]
    assert result["errors"] == [f"warpsim: error: USD file: USD could not write "
                                f"'{tmp_path}/full.usdc': disk full"]
    assert "full.usdc" not in result["files"]


def test_a_run_with_a_rerun_recording_forks_too(tmp_path):
    pytest.importorskip("rerun", reason="the viewer extra (rerun-sdk) is not installed")
    result = script(f"""
        from warpsim.apps import cli
        forks = spy_on_forks()
        args = ["run", "room", "-n", "300", "--frames", "30", "--every", "3", "--no-progress",
                "--rerun", "{tmp_path}/run.rrd"]
        first = cli.main(args + ["-o", "{tmp_path}/a.usdc"])
        pxr_after = "pxr" in sys.modules
        usd_process.can_fork = lambda: False
        second = cli.main(args + ["-o", "{tmp_path}/b.usdc"])
        print(json.dumps({{"codes": [first, second], "forks": forks, "pxr": pxr_after,
                          "rrd": os.path.getsize("{tmp_path}/run.rrd") > 0,
                          "same": layer_text("{tmp_path}/a.usdc")
                          == layer_text("{tmp_path}/b.usdc")}}))
    """, tmp_path)
    assert result == {"codes": [0, 0], "forks": [True, False], "pxr": False, "rrd": True,
                      "same": True}


def test_the_modules_the_command_checks_with_never_load_pxr(tmp_path):
    result = script("""
        import importlib
        loaded = {}
        for name in ("usd_size", "usd_layout", "usd_process", "rerun", "files"):
            importlib.import_module(f"warpsim.export.{name}")
            loaded[name] = "pxr" in sys.modules
        scene = ws.Scene.load("room")
        ws.export.estimate_usd_bytes(10, 3, ".usdc", boxes=scene)
        loaded["estimate"] = "pxr" in sys.modules
        print(json.dumps(loaded))
    """, tmp_path)
    assert result == dict.fromkeys(("usd_size", "usd_layout", "usd_process", "rerun", "files",
                                    "estimate"), False)
