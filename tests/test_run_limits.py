"""What a demanding user runs into: outputs that must survive each other's failures, default
names that stay in the working folder, limits and sizes checked before anything is drawn."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import warpsim as ws
from warpsim import ContactEvents, footprint
from warpsim.apps.cli import describe_broad_phase, main
from warpsim.export.files import default_name
from warpsim.scene_files import MAX_BOXES, SceneFileError


def cli(capsys, *args):
    code = main([str(a) for a in args])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def error_lines(err: str) -> list[str]:
    lines = [line for line in err.strip().splitlines() if "warpsim: error:" in line
             or "Traceback" in line]
    assert lines and all(line.startswith("warpsim: error:") for line in lines), err
    assert "Traceback" not in err
    return lines


# --- rounding never fails a table --------------------------------------------------------------


@given(st.lists(st.tuples(st.floats(-1e-6, 1e-6), st.booleans(), st.sampled_from([0.0, -0.0])),
                min_size=1, max_size=40))
@settings(max_examples=60, deadline=None)
def test_rounding_negative_bounce_speeds_and_negative_zeros_are_cleaned(rows):
    """Bounce speeds a few nm/s below 0 (rounding) read 0; a support keeps its sign; -0. in a
    frame's first contact (fraction and time) reads +0."""
    from warpsim.simulator import _contact_events

    n = len(rows)
    speed = np.array([r[0] for r in rows])
    kind = np.array([int(r[1]) for r in rows])
    fraction = np.array([r[2] for r in rows])
    part = {"frame": np.ones(n, dtype=np.int64), "sphere": np.arange(n), "box": np.zeros(n),
            "kind": kind, "position": np.zeros((n, 3)), "normal": np.tile([0, 1.0, 0], (n, 1)),
            "fraction": fraction, "normal_speed": speed}
    ev = _contact_events([part], 0, 0.25, {"dt": "0.25"}, capacity=10 ** 6)
    bounce = kind == 0
    assert np.array_equal(ev.normal_speed[bounce], np.maximum(speed[bounce], 0.0))
    assert np.array_equal(ev.normal_speed[~bounce], speed[~bounce])
    assert not np.signbit(ev.time).any() and not np.signbit(ev.fraction).any()
    assert np.array_equal(ev.time, np.zeros(n))


def test_events_file_stores_time_and_the_runs_settings(tmp_path):
    pytest.importorskip("pyarrow")
    scene = ws.Scene.load("wedge")
    sim = ws.Simulator(scene, scene.spawn(n=40, seed=3), precision="float64")
    ev = sim.run(30, events=True).events
    assert len(ev) > 0
    # time is (frame - 1 + fraction) dt, computed here independently
    np.testing.assert_array_equal(ev.time, (ev.frame - 1 + ev.fraction) * sim.dt)
    path = ev.write_parquet(tmp_path / "e.parquet", settings={"note": "x", "seed": 3})
    back = ContactEvents.read_parquet(path)
    assert back.settings == {"scene": "wedge", "dt": repr(sim.dt), "precision": "float64",
                             "motion": "linear", "max_bounces": str(sim.max_bounces),
                             "broad_phase": sim.broad_phase, "energy_correction": "true",
                             "note": "x", "seed": "3"}
    assert float(back.settings["dt"]) == sim.dt  # the exact step, to the bit
    np.testing.assert_array_equal(back.time, ev.time)
    with pytest.raises(ValueError, match="settings\\['bad'\\]"):
        ev.write_parquet(tmp_path / "f.parquet", settings={"bad": [1]})


# --- outputs independent of each other ---------------------------------------------------------


def test_a_failing_events_file_loses_neither_the_usd_nor_the_figures(tmp_path, capsys,
                                                                     monkeypatch):
    pytest.importorskip("pyarrow")

    def broken(self, path, settings=None):
        raise ValueError("normal_speed[809] must be >= 0, got -7.45e-09")

    monkeypatch.setattr(ContactEvents, "write_parquet", broken)
    usd = tmp_path / "g.usdc"
    code, out, err = cli(capsys, "run", "wedge", "-n", 20, "--frames", 20, "-o", usd,
                         "--events", tmp_path / "g.parquet", "--error-sample", 2,
                         "--no-progress")
    assert code == 1
    assert error_lines(err) == ["warpsim: error: events file: normal_speed[809] must be >= 0, "
                                "got -7.45e-09"]
    assert usd.is_file() and len(ws.export.read_usd(usd)) == 21  # written, and whole
    assert "energy drift" in out and "contacts:" in out and "wrote" in out
    assert "error" in out.lower().split("wrote")[-1]  # the error sample still ran after it


def test_a_failing_usd_still_writes_the_events(tmp_path, capsys, monkeypatch):
    pytest.importorskip("pyarrow")

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(ws.export, "write_usd", broken)
    events = tmp_path / "g.parquet"
    code, out, err = cli(capsys, "run", "wedge", "-n", 20, "--frames", 20, "-o",
                         tmp_path / "g.usdc", "--events", events, "--no-progress")
    assert code == 1 and error_lines(err) == ["warpsim: error: USD file: disk full"]
    assert len(ContactEvents.read_parquet(events)) > 0


@pytest.mark.parametrize("motion,precision", [("linear", "float64"), ("ballistic", "float32"),
                                              ("ballistic", "float64")])
def test_galton_with_events_writes_everything(tmp_path, capsys, motion, precision):
    """The reported case, shortened: resting contacts by the thousand, every output written."""
    pytest.importorskip("pyarrow")
    code, out, err = cli(capsys, "run", "galton", "-n", 60, "--frames", 240, "--motion", motion,
                         "--precision", precision, "-o", tmp_path / "g.usdc", "--events",
                         tmp_path / "g.parquet", "--no-progress")
    assert code == 0, err
    ev = ContactEvents.read_parquet(tmp_path / "g.parquet")
    assert (ev.normal_speed[ev.kind == 0] >= 0).all()
    supports = int(np.count_nonzero(ev.kind == ws.ContactKind.SUPPORT))
    assert supports > 0
    assert f"contacts: {len(ev) - supports:,} bounces (" in out
    assert f"), {supports:,} resting or sliding (" in out


# --- names and limits ----------------------------------------------------------------------


@given(st.text(max_size=30))
@settings(max_examples=200, deadline=None)
def test_default_names_stay_in_the_working_folder(name):
    out = default_name(name, ".usdc")
    assert Path(out).parent == Path(".") and Path(out).name == out
    assert out.endswith(".usdc") and not out.startswith(".") and len(out) > len(".usdc")
    assert "/" not in out and "\\" not in out and all(c.isascii() for c in out)


@pytest.mark.parametrize("name,expected", [("../escaped", "escaped.usdc"), ("room", "room.usdc"),
                                           ("a/b\\c", "c.usdc"), ("..", "scene.usdc"),
                                           ("my scene", "my_scene.usdc")])
def test_default_name_examples(name, expected):
    assert default_name(name, ".usdc") == expected


def scene_file(tmp_path, header: str, boxes: str = "[[box]]\ncenter = [0, -1, 0]\n"
               "half_extents = [5, 0.5, 5]\n") -> Path:
    path = tmp_path / "s.toml"
    path.write_text(f"{header}\n{boxes}\n[emitter]\ncount = 3\ncenter = [0, 1, 0]\n")
    return path


def test_a_scene_named_outside_writes_here(tmp_path, capsys, monkeypatch):
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    path = scene_file(tmp_path, 'name = "../escaped"')
    code, _, err = cli(capsys, "run", path, "--frames", 2, "--no-progress")
    assert code == 0, err
    assert (work / "escaped.usdc").is_file() and not (tmp_path / "escaped.usdc").exists()


@pytest.mark.parametrize("name", ['""', '"   "'])
def test_an_empty_scene_name_is_refused_by_name(tmp_path, name):
    with pytest.raises(SceneFileError, match="s.toml: name must be a non-empty"):
        ws.Scene.load(scene_file(tmp_path, f"name = {name}"))


def grid(count):
    return (f"[[box_grid]]\norigin = [0, -5, 0]\ncount = {count}\nspacing = [1, 1, 1]\n"
            f"half_extents = [0.1, 0.1, 0.1]\n")


@pytest.mark.parametrize("counts,ok", [
    (["[60000, 1, 1]", "[40000, 1, 1]"], True),      # exactly the limit, over two grids
    (["[60000, 1, 1]", "[60000, 1, 1]"], False),     # each below it, the scene above
    (["[1, 1, 1]", "[99999, 1, 1]"], True),
    (["[100000, 1, 1]", "[1, 1, 1]"], False),
    (["[100001, 1, 1]"], False),
])
def test_the_box_limit_is_the_scenes(tmp_path, counts, ok):
    path = scene_file(tmp_path, "", "".join(grid(c) for c in counts))
    total = sum(int(c.strip("[]").split(",")[0]) for c in counts)
    assert ok == (total <= MAX_BOXES)
    if ok:
        assert len(ws.Scene.load(path).boxes) == total
    else:
        with pytest.raises(SceneFileError, match=f"more than {MAX_BOXES} in the scene"):
            ws.Scene.load(path)


def test_the_readme_states_the_box_limit():
    readme = (Path(__file__).parent.parent / "README.md").read_text()
    assert f"{MAX_BOXES:_}".replace("_", " ") in readme or f"{MAX_BOXES:,}" in readme


def test_broad_phase_grid_runs_and_the_summary_says_what_ran(tmp_path, capsys):
    code, out, err = cli(capsys, "run", "room", "-n", 20, "--frames", 3, "--broad-phase", "grid",
                         "-o", tmp_path / "r.usdc", "--no-progress")
    assert code == 0, err
    assert "broad phase: grid" in out


def test_a_grid_that_cannot_be_built_is_reported():
    """float64 far from the origin: no grid fits, the BVH runs, and stats say so."""
    far = ws.RoundedBoxes(center=np.array([[1e12 + 3.0 * i, 0, 0] for i in range(40)]),
                          half_extents=np.full((40, 3), 1.0))
    swarm = ws.Swarm([[1e12 - 5.0, 0, 0]], [[1.0, 0, 0]], radius=0.1)
    sim = ws.Simulator(ws.Scene(far, gravity=(0, 0, 0)), swarm, precision="float64",
                       broad_phase="grid")
    stats = sim.stats
    assert stats.requested_broad_phase == "grid"
    assert stats.broad_phase in ("bvh", "brute", "grid", "grid-bvh")
    line = describe_broad_phase(stats.broad_phase, stats.requested_broad_phase)
    if stats.broad_phase in ("bvh", "brute"):
        assert "grid asked" in line and stats.broad_phase in line
    assert "grid asked: no grid fits" in describe_broad_phase("bvh", "grid")
    assert describe_broad_phase("grid-bvh", "grid").startswith("grid, falling back to the BVH")


# --- sizes before allocating ---------------------------------------------------------------


def test_a_huge_run_is_refused_before_any_sphere_is_drawn(tmp_path, capsys, monkeypatch):
    def no_draw(*args, **kwargs):
        raise AssertionError("drew the spheres of a run it then refused")

    monkeypatch.setattr(ws.Scene, "spawn", no_draw)
    code, _, err = cli(capsys, "run", "room", "-n", 30_000_000, "-o", tmp_path / "r.usdc")
    assert code == 1 and "--max-bytes" in error_lines(err)[0]
    code, _, err = cli(capsys, "run", "room", "-n", 5_000_000, "--spheres", "0:10",
                       "--max-memory", 2e9, "-o", tmp_path / "r.usdc")
    line = error_lines(err)[0]
    assert "GB in memory" in line and "--max-memory 2.0 GB" in line and "swarm" in line
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("n", [1, 1000, 10 ** 6])
@pytest.mark.parametrize("kept", [1, 10])
def test_footprint_grows_with_what_is_kept(n, kept):
    base = footprint.run_bytes(n, 101, kept=min(kept, n))
    whole = footprint.run_bytes(n, 101)
    assert base.trajectory == 101 * min(kept, n) * 7 * 4
    assert whole.trajectory == 101 * n * 28 and whole.total >= base.total
    double = footprint.run_bytes(n, 101, precision_bytes=8, velocities=True)
    assert double.trajectory == 101 * n * 13 * 8
    assert footprint.run_bytes(n, 101, event_rows=10).events > 0 == base.events


def test_the_kept_spheres_are_the_chosen_ones(tmp_path, capsys):
    usd = tmp_path / "r.usdc"
    code, _, err = cli(capsys, "run", "room", "-n", 300, "--frames", 4, "--spheres", "7,3,250",
                       "-o", usd, "--no-progress")
    assert code == 0, err
    scene = ws.Scene.load("room")
    from warpsim.distributed.draw import sharded_spawn  # the command line's draw

    whole = ws.Simulator(scene, sharded_spawn(scene, 300)).run(4)
    part = ws.Simulator(scene, sharded_spawn(scene, 300)).run(4, spheres=[7, 3, 250])
    assert part.position.shape == (5, 3, 3) and part.sphere_ids.tolist() == [7, 3, 250]
    np.testing.assert_array_equal(part.position, whole.position[:, [7, 3, 250]])
    np.testing.assert_array_equal(part.radius, whole.radius[[7, 3, 250]])
    back = ws.export.read_usd(usd)
    np.testing.assert_array_equal(back.position, whole.position[:, [7, 3, 250]])
    from pxr import Usd, UsdGeom

    from warpsim.export.usd_write import SPHERES

    stage = Usd.Stage.Open(str(usd))
    ids = UsdGeom.PointInstancer.Get(stage, SPHERES)
    assert list(ids.GetIdsAttr().Get()) == [7, 3, 250]


@pytest.mark.parametrize("size,ok", [("100000x100000", False), ("4096x4096", True),
                                     ("16385x16", False), ("16384x16", True),
                                     ("5000x4000", False)])
def test_preview_sizes_are_bounded_before_drawing(size, ok):
    from warpsim.apps.cli import _size

    if ok:
        assert _size(size) == tuple(int(x) for x in size.split("x"))
    else:
        with pytest.raises(Exception, match="at most 16384 pixels on a side"):
            _size(size)


def test_frame_with_movie_is_refused(tmp_path, capsys):
    code, _, err = cli(capsys, "preview", tmp_path / "x.usdc", "--movie", tmp_path / "m.gif",
                       "--frame", 3)
    assert code != 0 and "--frame" in error_lines(err)[0]


def test_the_readme_events_example_runs_without_pandas(tmp_path, monkeypatch):
    import re

    pytest.importorskip("pyarrow")
    readme = (Path(__file__).parent.parent / "README.md").read_text()
    section = readme.split("Contact events: `warpsim run room --events hits.parquet`", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, flags=re.S).group(1)
    assert "pandas" not in code
    scene = ws.Scene.load("wedge")
    ev = ws.Simulator(scene, scene.spawn(n=30)).run(40, events=True).events
    monkeypatch.chdir(tmp_path)
    ev.write_parquet("hits.parquet")
    namespace: dict = {}
    exec(compile(code, "README.md", "exec"), namespace)  # noqa: S102
    bounces = ev.bounces()
    expected = [np.count_nonzero(bounces.box == b) for b in range(len(namespace["per_box"]))]
    assert namespace["per_box"].tolist() == expected and sum(expected) == len(bounces) > 0


# --- the same command, the same spheres -----------------------------------------------------


@pytest.mark.parametrize("n,shards", [(3000, 4), (700, 1), (2100, 3)])
def test_plain_and_sharded_runs_simulate_the_same_spheres(tmp_path, capsys, n, shards):
    """``warpsim run`` and ``warpsim run --shards K`` of the same scene, n and seed: the same
    positions, bit for bit, at every frame (the sharded stage read back whole)."""
    plain, sharded = tmp_path / "p.usdc", tmp_path / "s.usdc"
    args = ("run", "room", "-n", n, "--frames", 6, "--block", 512, "--no-progress")
    code, plain_out, err = cli(capsys, *args, "-o", plain)
    assert code == 0, err
    code, out, err = cli(capsys, *args, "--shards", shards, "-o", sharded)
    assert code == 0, err
    assert f"in {shards} shards" in out

    def energy(text):
        return [line for line in text.splitlines() if line.startswith("energy")]

    assert energy(out) == energy(plain_out) and len(energy(out)) == 1  # the same swarm's
    capped = [line for line in plain_out.splitlines() if "capped:" in line][0]
    assert capped.split("capped:")[1] in out  # sphere-frames and spheres, as the plain run
    from warpsim import distributed

    one = ws.export.read_usd(plain)
    assert len(list((tmp_path / "s.shards").glob("shard_*.usdc"))) == shards
    both = distributed.read(sharded)
    np.testing.assert_array_equal(both.position, one.position)
    np.testing.assert_array_equal(both.orientation, one.orientation)
    # the readers a user reaches for take the sharded root as they take a single file
    whole = ws.export.read_usd(sharded)
    np.testing.assert_array_equal(whole.frame, one.frame)
    np.testing.assert_array_equal(whole.position, one.position)
    np.testing.assert_array_equal(whole.radius, one.radius)
    for k in (0, -1, int(one.frame[2])):
        frame = ws.export.read_usd_frame(sharded, k)
        i = k if k < 0 else int(np.searchsorted(one.frame, k))
        assert frame.frame.tolist() == [int(one.frame[i])]
        np.testing.assert_array_equal(frame.position[0], one.position[i])
    code, out, err = cli(capsys, "preview", sharded, "-o", tmp_path / "s.png", "--size", "64x48")
    assert code == 0, err
    assert (tmp_path / "s.png").stat().st_size > 0


def test_too_many_shards_says_why_and_stale_layers_go(tmp_path, capsys):
    out_path = tmp_path / "s.usdc"
    args = ("run", "room", "-n", 1200, "--frames", 2, "--block", 300, "--no-progress", "-o",
            out_path)
    code, _, err = cli(capsys, *args, "--shards", 4)
    assert code == 0, err
    assert len(list((tmp_path / "s.shards").glob("shard_*.usdc"))) == 4
    code, out, err = cli(capsys, *args, "--shards", 2)
    assert code == 0, err
    assert len(list((tmp_path / "s.shards").glob("shard_*.usdc"))) == 2  # the 4 old ones gone
    code, out, err = cli(capsys, *args, "--shards", 2)  # all reused: no speed of nothing
    assert "nothing simulated" in out and "0 sphere-frames/s" not in out
    assert "energy drift:" in out  # kept in the reused layers' manifests
    code, out, err = cli(capsys, *args, "--shards", 9)
    assert code == 0 and "4 shards, not 9: 1200 spheres make 4 blocks of 300" in err


@pytest.mark.parametrize("slope", [-1.31, 0.0, 0.3, 1.0, 2.0])
def test_accuracy_study_reports_an_order_only_where_the_error_falls_with_dt(slope):
    from warpsim.analysis.accuracy import MIN_ORDER, _orders

    dts = [1 / 30, 1 / 60, 1 / 120, 1 / 240]
    rows = [{"label": "f", "family": "dt", "dt": dt, "error_m": 1e-3 * (dt * 60) ** slope}
            for dt in dts]
    fam = _orders(rows)["f"]
    if slope >= MIN_ORDER:
        assert fam["order"] == pytest.approx(slope, abs=1e-9)
    else:
        assert fam["order"] is None and "does not depend on dt" in fam["note"]


def test_warp_starts_quietly_where_dask_workers_start_it():
    """The shard task starts Warp with its native start-up messages silenced (a machine
    without CUDA prints a warning otherwise; with it, there is nothing to hide either way)."""
    import subprocess
    import sys

    code = "from warpsim.warp_start import init_quietly; init_quietly(); print('ok')"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok"
    assert "warning" not in out.stderr.lower(), out.stderr
