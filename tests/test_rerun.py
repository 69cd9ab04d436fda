"""Rerun recordings (the ``viewer`` extra): read back with Rerun's own chunk reader, they hold the
simulated arrays frame by frame, the scene's obstacles, the contacts of the events table and
the run's counters; the viewer is started with its analytics off."""

import os
import sys

import numpy as np
import pytest

import warpsim as ws
from warpsim import ContactEvents, ContactKind
from warpsim.apps import cli
from warpsim.export import read_usd, write_usd

rr = pytest.importorskip("rerun")
from rerun.chunk import RrdReader  # noqa: E402

from warpsim.export import rerun as recording  # noqa: E402
from warpsim.export.rerun import (  # noqa: E402
    estimate_rerun_bytes,
    run_with_scalars,
    usd_to_rerun,
    write_rerun,
)

NANOSECONDS = 1e9
FLOAT32_REL = 4e-7  # float32 rounding of a coordinate, relative to its size (2 ulp)


def columns(path, entity: str) -> dict:
    """Every non-static row of ``entity``, sorted by frame: ``frame`` (R,) and, per component
    column, the list of its R cells (each a numpy array); static cells under ``static``."""
    rows, static = [], {}
    for chunk in RrdReader(path).stream():
        if chunk.entity_path != entity:
            continue
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if not n.startswith("rerun.")]
        if chunk.is_static:
            for name in names:
                static[name] = batch.column(name).to_pylist()[0]
            continue
        frames = batch.column("frame").to_numpy()
        times = batch.column("time").cast("int64").to_numpy()
        for r in range(batch.num_rows):
            rows.append((int(frames[r]), int(times[r]),
                         {n: batch.column(n)[r].as_py() for n in names
                          if n not in ("frame", "time")}))
    rows.sort(key=lambda row: row[0])
    out = {"frame": np.array([r[0] for r in rows], dtype=np.int64),
           "time_ns": np.array([r[1] for r in rows], dtype=np.int64), "static": static}
    for _, _, cells in rows:
        for name, value in cells.items():
            out.setdefault(name, []).append(value)
    return out


def entities(path) -> set[str]:
    return {chunk.entity_path for chunk in RrdReader(path).stream()}


@pytest.fixture(scope="module")
def run():
    """A short room run: 24 spheres, 30 frames recorded every 4th, with contacts."""
    scene = ws.Scene.load("room")
    swarm = scene.spawn(n=24, seed=3)
    sim = ws.Simulator(scene, swarm)
    traj, scalars = run_with_scalars(sim, 30, every=4, events=True)
    return scene, swarm, sim, traj, scalars


def test_sampled_run_is_the_plain_run_and_its_counters(run):
    scene, swarm, sim, traj, scalars = run
    plain = ws.Simulator(scene, swarm).run(30, every=4, events=True)
    np.testing.assert_array_equal(traj.frame, plain.frame)
    np.testing.assert_array_equal(traj.position, plain.position)
    np.testing.assert_array_equal(traj.events.frame, plain.events.frame)
    np.testing.assert_array_equal(traj.events.position, plain.events.position)
    # contacts since the previous record, from the events table, are the counter's increments
    edges = np.r_[traj.frame[0], traj.frame[1:]]
    per_interval = [int(np.count_nonzero((traj.events.frame > a) & (traj.events.frame <= b)))
                    for a, b in zip(np.r_[edges[0], edges[:-1]], edges, strict=True)]
    np.testing.assert_array_equal(scalars.bounces, per_interval)
    assert scalars.bounces.sum() == sim.stats.bounces == len(traj.events)
    assert scalars.capped.sum() == sim.stats.capped
    assert scalars.energy[-1] == pytest.approx(float(sim.mechanical_energy().sum()), rel=1e-12)
    assert scalars.energy_drift[0] == 0.0


def test_spheres_equal_the_simulated_arrays_frame_by_frame(run, tmp_path):
    scene, _, _, traj, scalars = run
    subset = np.array([3, 0, 17, 9, 22])
    path = write_rerun(tmp_path / "run.rrd", scene, traj, spheres=subset, scalars=scalars)
    got = columns(path, "/world/spheres")
    np.testing.assert_array_equal(got["frame"], traj.frame)
    np.testing.assert_array_equal(got["time_ns"], np.round(traj.frame * traj.dt * NANOSECONDS))
    for k, cell in enumerate(got["Points3D:positions"]):
        np.testing.assert_array_equal(np.array(cell, dtype=np.float32),
                                      traj.position[k][subset].astype(np.float32))
    static = got["static"]
    np.testing.assert_array_equal(static["sphere"], subset)
    np.testing.assert_array_equal(np.array(static["Points3D:radii"], dtype=np.float32),
                                  traj.radius[subset].astype(np.float32))
    assert static["Points3D:labels"] == [f"sphere {i}" for i in subset]
    assert len(set(static["Points3D:colors"])) == subset.size  # a colour of its own each
    # a sphere keeps its colour whatever the subset written
    alone = columns(write_rerun(tmp_path / "one.rrd", scene, traj, spheres=[17]),
                    "/world/spheres")["static"]
    assert alone["Points3D:colors"] == [static["Points3D:colors"][2]]


def test_size_estimate_is_at_most_4_percent_under_the_file(run, tmp_path):
    scene, _, _, traj, scalars = run
    events = traj.events
    path = ws.export.write_rerun(tmp_path / "run.rrd", scene, traj, scalars=scalars)
    span = int(traj.frame[-1] - traj.frame[0] + 1)
    estimate = ws.export.estimate_rerun_bytes(traj.sphere_count, len(traj), boxes=scene,
                                              scalars=True, events=len(events),
                                              event_frames=span)
    assert -0.04 <= estimate / os.path.getsize(path) - 1.0 < 0.15


@pytest.mark.parametrize(("frames", "every"), [(20, 1), (90, 3), (240, 8)])
def test_size_estimate_counts_sphere_frames_before_birth(frames, every, tmp_path):
    """A swarm born over time (the nozzle's 200 spheres a second): the sphere-frames written
    before a sphere's birth (NaN, which Rerun's compression all but removes) are counted as
    such, so the estimate stays within -4 % and +15 % of the file early in the stream, when
    most spheres are unborn, and late; counted as born spheres, it would be far above."""
    scene = ws.Scene.load("nozzle")
    sim = ws.Simulator(scene, scene.spawn())
    sim.build(events=True)
    traj, scalars = run_with_scalars(sim, frames, every=every, events=True)
    events = traj.events
    path = write_rerun(tmp_path / "n.rrd", scene, traj, scalars=scalars)
    span = int(max(traj.frame[-1], events.frame.max(initial=0)) - traj.frame[0] + 1)
    born = np.asarray(traj.frame)[:, None] >= scene.emitter.birth_frames(scene.dt, 400)[None, :]
    unborn = int(born.size - np.count_nonzero(born))
    assert 0 < unborn < born.size
    kwargs = {"boxes": scene, "scalars": True, "events": len(events),
              "event_frames": span if len(events) else 0}
    size = os.path.getsize(path)
    estimate = estimate_rerun_bytes(400, len(traj), unborn=unborn, **kwargs)
    assert -0.04 <= estimate / size - 1.0 < 0.15
    assert estimate_rerun_bytes(400, len(traj), **kwargs) / size - 1.0 > 0.15


def test_size_estimate_refuses_impossible_unborn_counts():
    with pytest.raises(ValueError, match="unborn"):
        estimate_rerun_bytes(3, 4, unborn=-1)
    with pytest.raises(ValueError, match="at most n_spheres"):
        estimate_rerun_bytes(3, 4, unborn=13)
    assert estimate_rerun_bytes(3, 4, unborn=12) < estimate_rerun_bytes(3, 4)


@pytest.mark.parametrize("count", [0, 1, 2, 7, 50, 401])
def test_sampled_columns_spread_evenly_and_keep_both_ends(count):
    """``sampled_columns`` over every sample size: ascending, distinct, ``min(sample, count)``
    of them, the first and the last selected sphere kept from two on, gaps that differ by at
    most one; the rows ``write_rerun`` writes are those."""
    for sample in [None, *range(1, count + 3)]:
        got = recording.sampled_columns(count, sample)
        want = count if sample is None else min(sample, count)
        assert got.size == want and np.all(np.diff(got) > 0)
        if want:
            assert got[-1] <= count - 1
        if want >= 2:
            assert got[0] == 0 and got[-1] == count - 1
            gaps = np.diff(got)
            assert gaps.max() - gaps.min() <= 1
    with pytest.raises(ValueError, match="sample"):
        recording.sampled_columns(5, 0)


def test_cli_counts_the_written_spheres_unborn_frames_against_max_bytes(tmp_path, capsys):
    """``--rerun`` with ``--max-bytes``: the check counts the sphere-frames before birth of the
    spheres the recording writes (``--spheres``, then ``--rerun-sample`` evenly spread), so a
    nozzle recording exactly at the limit runs and one byte less is refused before running."""
    from warpsim.export import estimate_usd_bytes

    scene = ws.Scene.load("nozzle")
    n, frames, every = 60, 40, 4
    selected = np.arange(n)[1:60:2]  # --spheres 1:60:2
    written = selected[np.round(np.linspace(0, selected.size - 1, 7)).astype(int)]
    records = np.arange(0, frames + 1, every)
    births = scene.emitter.birth_frames(scene.dt, n)[written]
    unborn = int((births[None, :] > records[:, None]).sum())
    assert 0 < unborn < written.size * records.size
    limit = estimate_rerun_bytes(7, records.size, boxes=scene, scalars=True, unborn=unborn)
    assert estimate_usd_bytes(selected.size, records.size, ".usdc", boxes=scene) < limit
    argv = ["run", "nozzle", "-n", str(n), "--frames", str(frames), "--every", str(every),
            "--spheres", "1:60:2", "--rerun-sample", "7", "--no-progress"]
    rrd, usd = tmp_path / "n.rrd", tmp_path / "n.usdc"
    code = cli.main([*argv, "--rerun", str(rrd), "-o", str(usd), "--max-bytes", str(limit - 1)])
    err = capsys.readouterr().err.strip()
    assert code == cli.EXIT_ERROR and "n.rrd" in err and len(err.splitlines()) == 1
    assert not rrd.exists() and not usd.exists()
    assert cli.main([*argv, "--rerun", str(rrd), "-o", str(usd), "--max-bytes", str(limit)]) == 0
    assert rrd.exists() and os.path.getsize(rrd) <= 1.04 * limit  # the model's own bound


def test_stride_and_sample_keep_the_last_frame_and_spread_spheres(run, tmp_path):
    scene, _, _, traj, _ = run
    path = write_rerun(tmp_path / "run.rrd", scene, traj, stride=3, sample=4)
    got = columns(path, "/world/spheres")
    rows = [0, 3, 6, len(traj) - 1]
    np.testing.assert_array_equal(got["frame"], traj.frame[rows])
    np.testing.assert_array_equal(got["static"]["sphere"], [0, 8, 15, 23])  # 24 spheres
    assert os.path.getsize(path) < estimate_rerun_bytes(4, 4, boxes=scene.boxes) * 1.25


def test_obstacles_match_the_scene(run, tmp_path):
    scene, _, _, traj, _ = run
    path = write_rerun(tmp_path / "run.rrd", scene, traj)
    boxes = scene.boxes
    seen = []
    shapes = sorted(e for e in entities(path) if e.startswith("/world/obstacles/"))
    assert shapes
    for entity in shapes:
        static = columns(path, entity)["static"]
        members = np.array(static["box"], dtype=np.int64)
        seen += members.tolist()
        np.testing.assert_array_equal(np.array(static["half_extents"]).reshape(-1, 3),
                                      boxes.half_extents[members])
        np.testing.assert_array_equal(static["rounding"], boxes.radius[members])
        translation = np.array(static["InstancePoses3D:translations"], dtype=np.float64)
        quaternion = np.array(static["InstancePoses3D:quaternions"], dtype=np.float64)
        np.testing.assert_array_equal(translation, boxes.center[members].astype(np.float32))
        np.testing.assert_array_equal(quaternion, boxes.rotation[members].astype(np.float32))
        # every vertex of the mesh, placed by each pose, lies on that box's surface
        local = np.array(static["Mesh3D:vertex_positions"], dtype=np.float64)
        for i, box in enumerate(members):
            matrix = ws.obstacles.quat_to_matrix(quaternion[i])
            world = local @ matrix.T + translation[i]
            distance = boxes[int(box)].as_boxes().signed_distance(world)
            scale = float(np.abs(boxes.center[box]).max() + boxes.bounding_radius()[box])
            assert np.abs(distance).max() <= 8 * FLOAT32_REL * scale
        triangles = np.array(static["Mesh3D:triangle_indices"])
        assert triangles.max() < local.shape[0]
    assert sorted(seen) == list(range(len(boxes)))  # each box exactly once
    # gravity along -y: x right, y up, z back (Rerun's ViewDir codes 3, 1, 6)
    assert columns(path, "/world")["static"]["ViewCoordinates:xyz"] == [[3, 1, 6]]


def test_contacts_on_the_timeline_match_the_events_table(run, tmp_path):
    scene, _, _, traj, _ = run
    events = traj.events
    subset = np.unique(events.sphere)[:5]
    path = write_rerun(tmp_path / "run.rrd", scene, traj, spheres=subset)
    got = columns(path, "/world/contacts")
    keep = np.isin(events.sphere, subset)
    assert keep.any() and not keep.all()
    np.testing.assert_array_equal(got["frame"], np.arange(traj.frame[0], traj.frame[-1] + 1))
    for k, frame in enumerate(got["frame"]):
        rows = np.flatnonzero(keep & (events.frame == frame))
        np.testing.assert_array_equal(np.array(got["Points3D:positions"][k],
                                               dtype=np.float32).reshape(-1, 3),
                                      events.position[rows].astype(np.float32))
        np.testing.assert_array_equal(got["sphere"][k], events.sphere[rows])
        np.testing.assert_array_equal(got["box"][k], events.box[rows])
        np.testing.assert_array_equal(got["contact_time"][k], events.time[rows])
        np.testing.assert_array_equal(got["normal_speed"][k], events.normal_speed[rows])
        np.testing.assert_array_equal(got["kind"][k], events.kind[rows])
    normals = columns(path, "/world/contacts/normals")
    lengths = [np.linalg.norm(np.array(v, dtype=np.float64).reshape(-1, 3), axis=1)
               for v in normals["Arrows3D:vectors"] if len(v)]
    assert np.ptp(np.concatenate(lengths)) < 1e-5 * np.concatenate(lengths).max()


def test_plots_hold_the_run_counters_at_the_written_frames(run, tmp_path):
    scene, _, _, traj, scalars = run
    path = write_rerun(tmp_path / "run.rrd", scene, traj, stride=2, scalars=scalars)
    rows = np.unique(np.r_[np.arange(0, len(traj), 2), len(traj) - 1])
    for name, values in scalars.plots().items():
        got = columns(path, f"/plots/{name}")
        np.testing.assert_array_equal(got["frame"], traj.frame[rows])
        np.testing.assert_array_equal(np.concatenate(got["Scalars:scalars"]),
                                      values[rows].astype(np.float64))


def test_recording_without_scene_events_or_plots(tmp_path):
    traj = ws.Trajectory(frame=np.array([0, 5]), dt=0.1, position=np.zeros((2, 1, 3)),
                         orientation=np.tile([0.0, 0.0, 0.0, 1.0], (2, 1, 1)),
                         radius=np.array([0.5]))
    path = write_rerun(tmp_path / "bare.rrd", None, traj)
    assert "/world/spheres" in entities(path)
    assert not any(e.startswith(("/world/obstacles", "/world/contacts", "/plots"))
                   for e in entities(path))


@pytest.mark.parametrize("kw, message", [
    ({"stride": 0}, "stride"), ({"spheres": [30]}, "spheres"), ({"sample": 0}, "sample"),
    ({"ids": [1, 2]}, "ids")])
def test_bad_arguments_name_the_field(run, tmp_path, kw, message):
    scene, _, _, traj, _ = run
    with pytest.raises(ValueError, match=message):
        write_rerun(tmp_path / "bad.rrd", scene, traj, **kw)
    with pytest.raises(ValueError, match=r"\.rrd"):
        write_rerun(tmp_path / "bad.usdc", scene, traj)
    assert not list(tmp_path.iterdir())


def test_usd_file_converts_with_its_sphere_ids(run, tmp_path):
    scene, _, _, traj, _ = run
    subset = np.array([5, 1, 20])
    usd = write_usd(tmp_path / "run.usdc", scene, traj, spheres=subset)
    path = usd_to_rerun(usd, tmp_path / "run.rrd")
    got = columns(path, "/world/spheres")
    np.testing.assert_array_equal(got["static"]["sphere"], subset)
    stored = read_usd(usd)
    for k, cell in enumerate(got["Points3D:positions"]):
        np.testing.assert_array_equal(np.array(cell, dtype=np.float32), stored.position[k])
    assert len([e for e in entities(path) if e.startswith("/world/obstacles/")]) > 0


def test_sharded_root_converts_in_swarm_order(run, tmp_path):
    from warpsim.export.layers import write_root_stage, write_shard_layer

    scene, _, _, traj, _ = run
    folder = tmp_path / "run.shards"
    folder.mkdir()
    layers = []
    for index, ids in enumerate((np.arange(12, 24), np.arange(0, 12))):
        layer = folder / f"shard_{index}.usdc"
        write_shard_layer(layer, traj.subset(ids), ids, index, 2, {"key": f"k{index}"})
        layers.append(layer)
    root = write_root_stage(tmp_path / "run.usdc", scene, traj.frame, traj.dt, layers,
                            {"keys": ["k0", "k1"]})
    got = columns(usd_to_rerun(root, tmp_path / "run.rrd"), "/world/spheres")
    np.testing.assert_array_equal(got["static"]["sphere"], np.arange(24))
    np.testing.assert_array_equal(np.array(got["Points3D:positions"][-1], dtype=np.float32),
                                  traj.position[-1].astype(np.float32))


def test_cli_writes_the_recording_beside_the_usd(tmp_path, capsys):
    rrd, usd = tmp_path / "room.rrd", tmp_path / "room.usdc"
    code = cli.main(["run", "room", "-n", "20", "--frames", "12", "--every", "3",
                     "--spheres", "2:8", "--rerun-sample", "3", "--rerun", str(rrd),
                     "-o", str(usd), "--no-progress"])
    assert code == 0
    assert f"wrote {rrd}" in capsys.readouterr().out
    got = columns(rrd, "/world/spheres")
    np.testing.assert_array_equal(got["frame"], [0, 3, 6, 9, 12])
    np.testing.assert_array_equal(got["static"]["sphere"], [2, 4, 7])
    np.testing.assert_array_equal(np.array(got["Points3D:positions"][-1], dtype=np.float32),
                                  read_usd(usd).position[-1][[0, 2, 5]])
    assert columns(rrd, "/plots/bounces")["frame"].tolist() == [0, 3, 6, 9, 12]


def test_cli_refuses_a_recording_above_max_bytes_before_running(tmp_path, capsys):
    from warpsim.export import estimate_usd_bytes

    scene = ws.Scene.load("room")
    usd_size = estimate_usd_bytes(20, 11, ".usdc", boxes=scene, spinning=False)
    rrd_size = estimate_rerun_bytes(20, 11, boxes=scene, scalars=True)
    assert rrd_size > usd_size
    rrd, usd = tmp_path / "room.rrd", tmp_path / "room.usdc"
    code = cli.main(["run", "room", "-n", "20", "--frames", "10", "--rerun", str(rrd),
                     "-o", str(usd), "--max-bytes", str((usd_size + rrd_size) // 2)])
    err = capsys.readouterr().err.strip()
    assert code == cli.EXIT_ERROR and len(err.splitlines()) == 1
    assert "room.rrd" in err and "--rerun-sample" in err
    assert not rrd.exists() and not usd.exists()


def test_cli_option_errors_are_one_line(tmp_path, capsys):
    for argv, message in ((["--rerun", str(tmp_path / "x.txt")], ".rrd"),
                          (["--rerun-sample", "3"], "--rerun-sample needs --rerun"),
                          (["--rerun", str(tmp_path / "x.rrd"), "--rerun-sample", "0"],
                           "rerun_sample"),
                          (["--dask", "--rerun", str(tmp_path / "x.rrd")], "--dask")):
        assert cli.main(["run", "room", "-n", "5", "--frames", "2", *argv]) == cli.EXIT_ERROR
        err = capsys.readouterr().err.strip()
        assert message in err and len(err.splitlines()) == 1
    assert cli.main(["view", str(tmp_path / "x.parquet")]) == cli.EXIT_ERROR
    assert ".rrd" in capsys.readouterr().err


def test_viewer_environment_turns_analytics_off_and_leaves_the_user_settings(
        monkeypatch, tmp_path):
    from warpsim.export.rerun_viewer import _analytics_config, viewer_environment

    if not sys.platform.startswith("linux"):
        pytest.skip("the private analytics settings use the XDG folders of Linux")
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    for name in ("XDG_CONFIG_HOME", "XDG_DATA_HOME"):
        monkeypatch.delenv(name, raising=False)
    with viewer_environment() as (env, folder):
        config = _analytics_config(env)
        assert config["analytics_enabled"] is False
        assert str(config["config_file_path"]).startswith(str(folder))
    assert not folder.exists()
    assert not any(home.rglob("*"))  # nothing written to the user's own Rerun settings


def test_page_guard_drops_web_fonts_and_runs_first():
    from warpsim.export.rerun_viewer import FETCH_GUARD, content_policy, guarded_page

    page = (b'<html><head>\n<link rel="preconnect" href="https://fonts.googleapis.com" />'
            b'<link\n href="https://fonts.googleapis.com/css2?family=Inter" rel="stylesheet"/>'
            b'<script src="re_viewer.js"></script></head></html>')
    out = guarded_page(page)
    assert b"fonts.g" not in out and b"re_viewer.js" in out
    assert out.index(FETCH_GUARD) < out.index(b"re_viewer.js")
    policy = content_policy(4321)
    assert "connect-src 'self' http://127.0.0.1:4321" in policy
    assert "https:" not in policy and "*" not in policy


def test_scalars_must_cover_the_written_frames(run, tmp_path):
    scene, _, _, traj, scalars = run
    short = recording.FrameScalars(scalars.frame[:2], scalars.energy[:2],
                                   scalars.energy_drift[:2], scalars.bounces[:2],
                                   scalars.capped[:2])
    with pytest.raises(ValueError, match="scalars"):
        write_rerun(tmp_path / "x.rrd", scene, traj, scalars=short)
    with pytest.raises(ValueError, match="energy"):
        recording.FrameScalars([0, 1], [1.0], [0.0, 0.0], [0, 0], [0, 0])


def test_events_of_other_spheres_are_left_out(tmp_path):
    traj = ws.Trajectory(frame=np.array([0, 1, 2]), dt=0.5, position=np.zeros((3, 2, 3)),
                         orientation=np.tile([0.0, 0.0, 0.0, 1.0], (3, 2, 1)),
                         radius=np.array([0.1, 0.1]))
    columns_ = {"sphere": [0, 1], "box": [0, 0], "position": [[0, 0, 0], [1, 1, 1]],
                "normal": [[0, 1, 0], [0, 1, 0]], "normal_speed": [1.0, 2.0],
                "kind": [ContactKind.BOUNCE, ContactKind.SUPPORT]}
    events = ContactEvents.of_frames(0.5, [1, 2], [0.5, 0.25], **columns_)
    got = columns(write_rerun(tmp_path / "x.rrd", None, traj, spheres=[1], events=events),
                  "/world/contacts")
    np.testing.assert_array_equal(got["frame"], [0, 1, 2])
    assert [len(s) for s in got["sphere"]] == [0, 0, 1] and got["sphere"][2] == [1]
    # the same contacts in continuous time land on the frames whose steps hold them
    timed = ContactEvents(time=events.time, **columns_)
    again = columns(write_rerun(tmp_path / "y.rrd", None, traj, spheres=[1], events=timed),
                    "/world/contacts")
    assert again["sphere"] == got["sphere"] and again["contact_time"] == got["contact_time"]


def test_viewer_requests_to_other_hosts_go_to_a_closed_loopback_port(run, tmp_path):
    """The native viewer's version check (GitHub) is sent to the proxy warpsim names: the
    closed port refuses it on the machine. Shown here with a listening stand-in for it."""
    import socket
    import subprocess

    from warpsim.export.rerun_viewer import PROXY_VARIABLES, rerun_executable, viewer_environment

    scene, _, _, traj, _ = run
    rrd = write_rerun(tmp_path / "run.rrd", scene, traj)
    with viewer_environment() as (env, _), \
            socket.socket(socket.AF_INET, socket.SOCK_STREAM) as stand_in:
        closed = env["HTTPS_PROXY"]
        assert closed.startswith("http://127.0.0.1:") and "127.0.0.1" in env["NO_PROXY"]
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            assert probe.connect_ex(("127.0.0.1", int(closed.rsplit(":", 1)[1]))) != 0
        stand_in.bind(("127.0.0.1", 0))
        stand_in.listen(4)
        stand_in.settimeout(30.0)
        address = f"http://127.0.0.1:{stand_in.getsockname()[1]}"
        trial = dict(env, **{n: address for n in PROXY_VARIABLES},
                     **{n.lower(): address for n in PROXY_VARIABLES})
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as spare:
            spare.bind(("127.0.0.1", 0))
            grpc = str(spare.getsockname()[1])
        viewer = subprocess.Popen([rerun_executable(), str(rrd), "--headless", "--bind",
                                   "127.0.0.1", "--port", grpc], env=trial,
                                  stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL)
        try:
            connection, _ = stand_in.accept()
            with connection:
                connection.settimeout(10.0)
                request = connection.recv(4096).split(b"\r\n", 1)[0]
        except TimeoutError:
            pytest.skip("the headless viewer made no request within 30 s here")
        finally:
            viewer.kill()
            viewer.wait()
    assert request.startswith(b"CONNECT ") and b"127.0.0.1" not in request, request


def test_view_web_serves_the_guarded_page_of_a_usd_file(run, tmp_path, monkeypatch, capsys):
    import urllib.request

    from warpsim.export.rerun_viewer import FETCH_GUARD, WebViewer

    scene, _, _, traj, _ = run
    usd = write_usd(tmp_path / "run.usdc", scene, traj)
    pages = []

    def fetch_instead_of_waiting(self):  # what a browser gets, then Ctrl-C
        opener = urllib.request.build_opener(urllib.request.ProxyHandler({}))
        with opener.open(self.url, timeout=30) as response:
            pages.append((response.headers["Content-Security-Policy"], response.read()))
        return 0

    monkeypatch.setattr(WebViewer, "wait", fetch_instead_of_waiting)
    assert cli.main(["view", str(usd), "--web", "--no-browser"]) == 0
    out = capsys.readouterr().out
    assert "http://127.0.0.1:" in out
    policy, page = pages[0]
    assert FETCH_GUARD in page and b"fonts.googleapis" not in page
    assert "connect-src 'self' http://127.0.0.1:" in policy


@pytest.mark.slow
def test_readme_viewer_commands_run(tmp_path, monkeypatch, capsys):
    """The README's viewer commands, as printed: the run writes both files; ``view --web``
    serves them (the browser it would open and the wait for Ctrl-C are stood in for)."""
    import re
    import shlex
    import webbrowser
    from pathlib import Path

    from warpsim.export.rerun_viewer import WebViewer

    readme = Path(__file__).resolve().parents[1] / "README.md"
    if not readme.is_file():
        pytest.skip("README.md not present (installed package)")
    section = readme.read_text(encoding="utf-8").split("## Interactive viewer", 1)[1]
    block = re.search(r"```bash\n(.*?)```", section, flags=re.S).group(1)
    commands = [shlex.split(line.split("#", 1)[0]) for line in block.strip().splitlines()]
    assert [c[:2] for c in commands] == [["warpsim", "run"], ["warpsim", "view"],
                                          ["warpsim", "view"]]
    monkeypatch.chdir(tmp_path)
    opened = []
    monkeypatch.setattr(webbrowser, "open", opened.append)
    monkeypatch.setattr(WebViewer, "wait", lambda self: 0)
    assert cli.main(commands[0][1:] + ["--no-progress"]) == 0
    assert (tmp_path / "room.rrd").is_file() and (tmp_path / "room.usdc").is_file()
    assert (tmp_path / "hits.parquet").is_file()
    assert cli.main(commands[2][1:]) == 0
    assert opened and opened[0].startswith("http://127.0.0.1:")
    assert opened[0] in capsys.readouterr().out


def test_mesh_normals_point_out_of_the_box():
    """Triangulated obstacle meshes: a sharp box's vertex normals are its face axes; a rounded
    box's are near the exact outward normal ``(p - clamp(p, -h, h)) / r``, and every triangle
    turns counter-clockwise seen from outside."""
    from warpsim.export.mesh import box_mesh, rounded_box_mesh
    from warpsim.export.rerun import triangulated

    h = np.array([0.4, 0.1, 0.25])
    points, triangles, normals = triangulated(*box_mesh(h))
    assert triangles.shape == (12, 3)
    np.testing.assert_allclose(np.abs(normals).max(axis=1), 1.0, atol=1e-6)  # a face axis each
    np.testing.assert_allclose(np.sign(points * normals).max(axis=1), 1.0)  # pointing out
    r = 0.05
    points, triangles, normals = triangulated(*rounded_box_mesh(h, r, 4))
    exact = (points - np.clip(points, -h, h)) / r
    cosine = np.einsum("ij,ij->i", normals, exact / np.linalg.norm(exact, axis=1)[:, None])
    assert cosine.min() > np.cos(np.radians(25.0))  # within a facet's angle (90 / 4 degrees)
    a, b, c = (points[triangles[:, k]].astype(np.float64) for k in range(3))
    centre = (a + b + c) / 3.0
    assert (np.einsum("ij,ij->i", np.cross(b - a, c - a), centre) > 0.0).all()
