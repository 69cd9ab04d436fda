"""Sharded runs (warpsim.distributed): the sharded draw, one USD layer per shard composed by a
root stage, bit-identical to one process; on a LocalCluster of two worker processes, a killed
worker, an interrupted run's rerun, and bad scheduler addresses."""

import os
import signal
import socket
import threading
import time

import numpy as np
import pytest

import warpsim as ws
from warpsim import distributed as wd

pxr = pytest.importorskip("pxr")
from pxr import Sdf, Usd, UsdGeom  # noqa: E402

from warpsim.export import layers  # noqa: E402

SCENE = "room"
N, SEED, BLOCK = 80, 7, 16  # 5 blocks: shards of 16 to 80 spheres
FRAMES, EVERY = 24, 5  # records 0, 5, ..., 20, 24: the last interval is partial
DEGREES_PER_RADIAN = 180.0 / np.pi


@pytest.fixture(scope="module")
def scene():
    return ws.Scene.load(SCENE)


@pytest.fixture(scope="module")
def reference(scene):
    """The same spheres run whole in one Simulator: blocks drawn straight from the emitter with
    the documented block seeds, concatenated, no shard code involved."""
    blocks = [scene.spawn(n=min(BLOCK, N - b * BLOCK), seed=wd.block_seed(SEED, b))
              for b in range(-(-N // BLOCK))]
    swarm = ws.Swarm(**{k: np.concatenate([getattr(s, k) for s in blocks])
                        for k in ("position", "velocity", "radius", "mass", "angular_momentum",
                                  "orientation")})
    return swarm, ws.Simulator(scene, swarm).run(FRAMES, every=EVERY, velocities=True)


@pytest.fixture(scope="module")
def client():
    """One LocalCluster of two worker processes (one thread each) for the whole module."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as c:
        yield c


def assert_same_as_reference(trajectory, reference, velocities=False):
    swarm, ref = reference
    np.testing.assert_array_equal(trajectory.frame, ref.frame)
    assert trajectory.position.dtype == np.float32
    assert np.array_equal(trajectory.position, ref.position.astype(np.float32))
    assert np.array_equal(trajectory.orientation, ref.orientation.astype(np.float32))
    assert np.array_equal(trajectory.radius, swarm.radius)
    if velocities:
        assert np.array_equal(trajectory.velocity, ref.velocity.astype(np.float32))
        degrees = (ref.angular_velocity.astype(np.float64) * DEGREES_PER_RADIAN)
        assert np.array_equal(trajectory.angular_velocity,
                              degrees.astype(np.float32).astype(np.float64) / DEGREES_PER_RADIAN)


def run(scene, path, **kw):
    kw = {"n": N, "seed": SEED, "frames": FRAMES, "every": EVERY, "block": BLOCK,
          "progress": False, **kw}
    return wd.run(scene, path, **kw)


# --- the sharded draw ---------------------------------------------------------------------------

@pytest.mark.slow
def test_block_seeds_are_distinct_and_in_range():
    blocks = np.arange(1 << 13)
    for seed in (0, 1, 2**31 - 1):
        seeds = np.array([wd.block_seed(seed, int(b)) for b in blocks])
        assert np.unique(seeds).size == blocks.size
        assert seeds.min() >= 0 and seeds.max() < 2**31
    a = {wd.block_seed(0, b) for b in range(4096)}
    b = {wd.block_seed(1, b) for b in range(4096)}
    assert len(a & b) < 4  # unrelated permutations: ~4096**2 / 2**31 = 0.008 expected in common


def test_any_whole_blocks_draw_the_same_spheres(scene, reference):
    swarm, _ = reference
    for start, stop in [(0, N), (16, 48), (64, 80), (32, 48)]:
        part = wd.shard_swarm(scene, N, SEED, start, stop, BLOCK)
        for name in ("position", "velocity", "radius", "mass", "angular_momentum"):
            assert np.array_equal(getattr(part, name), getattr(swarm, name)[start:stop])
    # each sphere clear of every obstacle by its radius plus the emitter's clearance
    d = scene.boxes.signed_distance(swarm.position).min(axis=1)
    assert np.all(d >= swarm.radius + scene.emitter.clearance)


@pytest.mark.parametrize("start, stop", [(8, 32), (0, 40), (0, 0), (16, N + 1), (-16, 16)])
def test_ranges_that_are_not_whole_blocks_are_refused(scene, start, stop):
    with pytest.raises(ValueError, match="start|stop|whole blocks"):
        wd.shard_swarm(scene, N, SEED, start, stop, BLOCK)


def test_plan_shards_covers_the_swarm_in_whole_blocks():
    for n, shards, block in [(80, 3, 16), (80, 50, 16), (1, 4, 16), (1000, 7, 64)]:
        plan = wd.plan_shards(n, shards, block)
        assert plan[0][0] == 0 and plan[-1][1] == n
        assert all(a % block == 0 and b > a for a, b in plan)
        assert all(plan[k][1] == plan[k + 1][0] for k in range(len(plan) - 1))
        assert len(plan) == min(shards, -(-n // block))


# --- in this process ----------------------------------------------------------------------------

@pytest.mark.slow
def test_in_process_shards_equal_one_simulator(scene, reference, tmp_path):
    out = tmp_path / "run.usda"
    summary = run(scene, out, shards=3, velocities=True)
    assert summary.recomputed == (0, 1, 2) and summary.reused == ()
    assert summary.processes == 0 and summary.processes_used == 1
    assert_same_as_reference(wd.read(out), reference, velocities=True)


def test_scene_without_obstacles_or_emitter_is_refused(scene, tmp_path):
    empty = ws.Scene(ws.RoundedBoxes(center=np.zeros((0, 3)), half_extents=np.zeros((0, 3))),
                     emitter=scene.emitter)
    with pytest.raises(ValueError, match="no obstacles"):
        wd.run(empty, tmp_path / "a.usdc", n=8)
    no_emitter = ws.Scene(scene.boxes)
    with pytest.raises(ValueError, match="no emitter"):
        wd.run(no_emitter, tmp_path / "a.usdc", n=8)


@pytest.mark.parametrize("kw, message", [
    ({"shards": 0}, "shards"), ({"block": 0}, "block"), ({"n": -1}, "n must"),
    ({"every": 0}, "every"), ({"start": 30}, "start"), ({"dt": -1.0}, "dt"),
    ({"max_bounces": 0}, "max_bounces"), ({"processes": 2}, "local"),
])
def test_bad_arguments_fail_before_any_work(scene, tmp_path, kw, message):
    with pytest.raises(ValueError, match=message):
        run(scene, tmp_path / "a.usdc", **kw)
    assert not (tmp_path / "a.usdc").exists()


@pytest.mark.parametrize("call", [
    lambda out: run("room", out, n=8, client="local", workers=2),
    lambda out: wd.sweep(len, ["a"], client="local", workers=2, progress=False),
], ids=["run", "sweep"])
def test_workers_is_not_the_dask_process_count(tmp_path, call):
    """``workers`` counts CPU threads everywhere (Simulator, CLI); the Dask process count is
    ``processes``, and the old keyword is an error naming the new one, raised before a cluster
    starts or a file is made."""
    out = tmp_path / "a.usdc"
    with pytest.raises(TypeError, match=r"processes=.*threads"):
        call(out)
    assert not out.exists() and not (tmp_path / "a.shards").exists()


# --- on a LocalCluster of two processes ---------------------------------------------------------

@pytest.mark.slow
def test_cluster_stage_equals_one_process_bit_for_bit(scene, reference, client, tmp_path):
    out = tmp_path / "run.usdc"
    summary = run(scene, out, client=client, shards=4)
    assert summary.shards == 4 and summary.recomputed == (0, 1, 2, 3)
    assert summary.processes == 2 and 1 <= summary.processes_used <= 2
    stage = Usd.Stage.Open(str(out))
    shards = [UsdGeom.PointInstancer(p) for p in stage.GetPrimAtPath("/World/Spheres")
              .GetChildren()]
    assert len(shards) == 4
    seen = []
    swarm, ref = reference
    for inst in shards:
        ids = np.asarray(inst.GetIdsAttr().Get())
        seen.append(ids)
        last = Usd.TimeCode(float(ref.frame[-1]))
        positions = np.asarray(inst.GetPositionsAttr().Get(last), dtype=np.float32)
        assert np.array_equal(positions, ref.position[-1][ids].astype(np.float32))
        proto = stage.GetPrimAtPath(inst.GetPrototypesRel().GetTargets()[0])
        assert proto.GetTypeName() == "Mesh" and len(proto.GetAttribute("points").Get()) > 0
    assert np.array_equal(np.sort(np.concatenate(seen)), np.arange(N))
    assert_same_as_reference(wd.read(out), reference)
    # the obstacles are authored once, in the root, and read back as written
    root = Sdf.Layer.FindOrOpen(str(out))
    assert root.GetPrimAtPath("/World/Obstacles") is not None
    for path in root.subLayerPaths:
        assert Sdf.Layer.FindOrOpen(str(out.parent / path)).GetPrimAtPath(
            "/World/Obstacles") is None
    boxes = ws.export.read_usd_boxes(out)
    assert np.array_equal(boxes.center, scene.boxes.center)
    assert stage.GetTimeCodesPerSecond() == pytest.approx(1.0 / scene.dt)


@pytest.mark.slow
def test_other_shard_counts_give_the_same_bits(scene, reference, client, tmp_path):
    for shards in (1, 5):
        out = tmp_path / f"run{shards}.usdc"
        assert run(scene, out, client=client, shards=shards).shards == shards
        assert_same_as_reference(wd.read(out), reference)


# --- spheres born over time, and a scene on a USD set ------------------------------------------

NOZZLE_FRAMES = 40  # the nozzle's sphere k is born at frame round(0.6 k): 0 to 47 for N = 80


@pytest.fixture(scope="module")
def nozzle_reference():
    """The sharded draw of the nozzle, births worked out by hand, run whole in one Simulator."""
    scene = ws.Scene.load("nozzle")
    blocks = [scene.spawn(n=min(BLOCK, N - b * BLOCK), seed=wd.block_seed(SEED, b))
              for b in range(-(-N // BLOCK))]
    births = np.rint(np.arange(N) / 200.0 * 120.0).astype(np.int64)  # at k / 200 s, 120 fps
    swarm = ws.Swarm(**{k: np.concatenate([getattr(s, k) for s in blocks])
                        for k in ("position", "velocity", "radius", "mass", "angular_momentum",
                                  "orientation")}, birth_frame=births)
    traj = ws.Simulator(scene, swarm).run(NOZZLE_FRAMES, every=EVERY, velocities=True)
    assert (births > NOZZLE_FRAMES).any() and np.isnan(traj.position[-1]).any()
    return scene, swarm, traj


def assert_births_as_reference(path, nozzle_reference):
    _, swarm, ref = nozzle_reference
    back = wd.read(path)
    assert back.birth_frame.tolist() == swarm.birth_frame.tolist()
    np.testing.assert_array_equal(back.frame, ref.frame)
    for name in ("position", "orientation", "velocity"):
        assert np.array_equal(getattr(back, name), getattr(ref, name).astype(np.float32),
                              equal_nan=True), name
    stage = Usd.Stage.Open(str(path))
    for inst in stage.GetPrimAtPath("/World/Spheres").GetChildren():
        inst = UsdGeom.PointInstancer(inst)
        ids = np.asarray(inst.GetIdsAttr().Get())
        for frame in ref.frame:
            hidden = np.asarray(inst.GetInvisibleIdsAttr().Get(float(frame)), dtype=np.int64)
            assert sorted(hidden.tolist()) == ids[swarm.birth_frame[ids] > frame].tolist()


def open_room():
    """The room without its ceiling, its emitter reaching 0.2 m above the walls' bounds and
    throwing upwards: a few spheres start beyond every box's bounds, in some shards only, and
    the others fly out over the walls later (free frames in every shard)."""
    import dataclasses

    room = ws.Scene.load(SCENE)
    keep = np.arange(len(room.boxes)) != int(np.argmax(room.boxes.center[:, 1]))
    boxes = ws.RoundedBoxes(center=room.boxes.center[keep],
                            half_extents=room.boxes.half_extents[keep],
                            rotation=room.boxes.rotation[keep], radius=room.boxes.radius[keep])
    emitter = dataclasses.replace(room.emitter, center=(0.0, 4.65, 0.0),
                                  half_extents=(4.9, 1.65, 4.9), velocity=(0.0, 8.0, 0.0))
    return ws.Scene(boxes, gravity=room.gravity, emitter=emitter, name="open-room")


@pytest.mark.slow
def test_open_scene_shards_equal_one_process(tmp_path):
    """Shards choose the free-flight kernel for the whole run (``draw.may_start_free``), not
    from their own spheres, whose choices differ here: 3 shards, the plain run of the same
    command and the command line's run, bit for bit (the free frames' energy reset runs once
    in 32 frames, so the two kernels differ by rounding)."""
    from warpsim.distributed.draw import may_start_free
    from warpsim.simulator import _starts_in_free_flight

    scene = open_room()
    own = [_starts_in_free_flight(scene.boxes, wd.shard_swarm(scene, N, SEED, a, b, BLOCK))
           for a, b in wd.plan_shards(N, 3, BLOCK)]
    assert may_start_free(scene) and len(set(own)) == 2  # the shards alone would differ
    frames = 400  # long enough for the two kernels to differ (a sphere at 100 frames, 4 at 400)
    swarm = wd.sharded_spawn(scene, N, SEED, BLOCK)
    whole = ws.Simulator(scene, swarm, free_flight=True).run(frames, every=EVERY,
                                                                velocities=True)
    out = tmp_path / "open.usda"
    run(scene, out, shards=3, frames=frames, velocities=True)
    assert_same_as_reference(wd.read(out), (swarm, whole), velocities=True)


@pytest.mark.slow
def test_births_in_process_shards_equal_one_simulator(nozzle_reference, tmp_path):
    scene = nozzle_reference[0]
    out = tmp_path / "nozzle.usda"
    run(scene, out, shards=3, frames=NOZZLE_FRAMES, velocities=True)
    assert_births_as_reference(out, nozzle_reference)


@pytest.mark.slow
def test_births_and_a_usd_set_on_the_cluster_equal_one_process(nozzle_reference, client,
                                                               tmp_path):
    from test_usd_stage import assert_composed_over_the_set, author_set, write_scene

    scene = nozzle_reference[0]
    out = tmp_path / "nozzle.usdc"
    run(scene, out, client=client, shards=4, frames=NOZZLE_FRAMES, velocities=True)
    assert_births_as_reference(out, nozzle_reference)

    author_set(tmp_path / "set.usda")
    on_set = ws.Scene.load(write_scene(tmp_path))
    composed = tmp_path / "composed.usdc"
    run(on_set, composed, client=client, n=24, frames=12, every=3, block=8, shards=3)
    assert_composed_over_the_set(composed)
    plain = ws.Simulator(on_set, wd.sharded_spawn(on_set, 24, SEED, 8)).run(12, every=3)
    assert np.array_equal(wd.read(composed).position, plain.position.astype(np.float32))


@pytest.mark.slow
def test_rerun_recomputes_only_missing_and_stale_shards(scene, reference, client, tmp_path):
    out = tmp_path / "run.usdc"
    first = run(scene, out, client=client, shards=5)
    folder = layers.shard_folder(out)
    files = sorted(folder.glob("shard_*.usdc"))
    assert len(files) == 5
    kept = {f.name: f.stat().st_mtime_ns for f in files}
    # what an interrupted run leaves: no root, a shard never written, a temporary file from a
    # write cut short; plus a layer of another seed (stale) and a damaged one
    out.unlink()
    files[1].unlink()
    (folder / "shard_00002.tmp-0badf00d.usdc").write_bytes(b"PXR-USDC partial")
    files[3].write_bytes(files[3].read_bytes()[:200])
    stale = tmp_path / "stale.usdc"
    run(scene, stale, client=client, shards=5, seed=SEED + 1)
    layers.shard_folder(stale).joinpath(files[4].name).replace(files[4])
    second = run(scene, out, client=client, shards=5)
    assert second.recomputed == (1, 3, 4) and second.reused == (0, 2)
    assert second.digests == first.digests
    for name in ("shard_00000.usdc", "shard_00002.usdc"):
        assert (folder / name).stat().st_mtime_ns == kept[name]
    assert_same_as_reference(wd.read(out), reference)
    assert "3 of 5 shards recomputed, 2 reused" in str(second)


@pytest.mark.slow
def test_cli_runs_on_a_scheduler_address(client, tmp_path, capsys):
    from warpsim.apps.cli import main

    out = tmp_path / "cli.usdc"
    code = main(["run", SCENE, "-n", "32", "--frames", "6", "--block", "16", "--shards", "2",
                 "--dask", client.scheduler_info()["address"], "-o", str(out), "--no-progress"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "2 of 2 shards recomputed" in captured.out and "of 2 Dask processes" in captured.out
    assert wd.read(out).position.shape == (7, 32, 3)  # frames 0..6


def _mean_radius(name):
    return float(ws.Scene.load(name).spawn(n=16, seed=0).radius.mean())


@pytest.mark.slow
def test_sweep_runs_items_as_tasks_in_order(client):
    names = ["room", "galton", "pinball"]
    assert wd.sweep(_mean_radius, names, client=client, progress=False) == \
        [_mean_radius(n) for n in names]
    with pytest.raises(ValueError, match="sweep item 1"):
        wd.sweep(_mean_radius, ["room", "no-such-scene"], client=client, progress=False)


# --- addresses ----------------------------------------------------------------------------------

@pytest.mark.parametrize("address", ["", "   ", "foo://host:1", "host:port", "tcp://:8786",
                                     "host:0", "host:70000", "tcp://a b:1"])
def test_bad_addresses_are_one_line_errors(scene, tmp_path, address):
    pytest.importorskip("distributed")
    with pytest.raises(ValueError) as info:
        run(scene, tmp_path / "a.usdc", client=address)
    assert "\n" not in str(info.value) and "address" in str(info.value)
    assert list(tmp_path.iterdir()) == []  # nothing made before the error


def test_address_forms():
    assert wd.scheduler_address("10.0.0.5:8786") == "tcp://10.0.0.5:8786"
    assert wd.scheduler_address("scheduler") == "tcp://scheduler:8786"
    assert wd.scheduler_address("tls://h:1") == "tls://h:1"
    assert wd.scheduler_address("[::1]:9000") == "tcp://[::1]:9000"


@pytest.mark.slow
def test_unreachable_scheduler_is_a_one_line_error(scene, tmp_path):
    pytest.importorskip("distributed")
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(OSError) as info:
        run(scene, tmp_path / "a.usdc", client=f"127.0.0.1:{port}", timeout=1.0)
    text = str(info.value)
    assert "\n" not in text and f"no Dask scheduler answered at tcp://127.0.0.1:{port}" in text


def test_missing_dask_names_the_extra(monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(ImportError, match=r'pip install "warpsim\[dask\]"'):
        wd.require_dask()


# --- faults (last: it leaves the cluster a worker short while its nanny restarts it) ---------

@pytest.mark.slow
def test_a_killed_worker_loses_only_its_task(scene, client, tmp_path):
    """Shards long enough (over half a second each) that a worker is killed while running one;
    Dask runs the lost shard again on a live worker, and the output is the same. Last in the
    module: the cluster is not waited for to be whole again."""
    kw = {"n": 64, "frames": 160_000, "every": 40_000, "shards": 4, "threads": 1}
    expected = run(scene, tmp_path / "here.usdc", **kw)  # in this process, no fault
    out = tmp_path / "run.usdc"
    result, killed = {}, {}

    def target():
        try:
            result["summary"] = run(scene, out, client=client, **kw)
        except BaseException as exc:  # reported by the main thread
            result["error"] = exc

    thread = threading.Thread(target=target)
    thread.start()
    deadline = time.monotonic() + 60
    while not killed and time.monotonic() < deadline and thread.is_alive():
        busy = {w: keys for w, keys in client.processing().items()
                if any("warpsim-shard" in str(k) for k in keys)}
        if busy:
            worker, keys = next(iter(busy.items()))
            pid = client.run(os.getpid, workers=[worker])[worker]
            os.kill(pid, signal.SIGKILL)
            killed = {"worker": worker, "shard": int(str(keys[0]).rsplit("-", 1)[1])}
        time.sleep(0.02)
    thread.join(120)
    assert "error" not in result, result.get("error")
    assert killed, "no shard was running to kill"
    summary = result["summary"]
    assert summary.recomputed == (0, 1, 2, 3)
    assert summary.computed_by[killed["shard"]] != killed["worker"]
    assert summary.digests == expected.digests
