"""Spheres born over time: before its birth a sphere does not exist; after it, it moves bit for
bit as the only sphere of a run started at its birth with the same state.

The independent computation is that run itself: each sphere simulated alone from frame 0 (a
kernel without the births feature), its frame ``k`` compared with frame ``b + k`` of the run
with births, bit for bit, its contacts with their frames shifted by ``b``.
"""

from dataclasses import replace

import numpy as np
import pytest

import warpsim as ws
from warpsim import simulator as simulator_module

FRAMES = 120
BIRTHS = np.array([0, 7, 0, 30, 55, 80, 119, 200])
"""Birth frames: at the start, mid-run, on the last frame (born, never moved) and after the run
(never appears)."""


def spin_swarm(births=BIRTHS) -> tuple[ws.Scene, ws.Swarm]:
    """Spheres thrown down the spin scene's ramp (friction spins them), born at ``births``."""
    scene = ws.Scene.load("spin")
    drawn = scene.spawn(n=len(births), seed=3)
    swarm = ws.Swarm(drawn.position, drawn.velocity, drawn.radius, drawn.mass,
                     birth_frame=births)
    return scene, swarm


def alone(swarm: ws.Swarm, i: int) -> ws.Swarm:
    """Sphere ``i`` of ``swarm`` as a swarm of its own, born at frame 0."""
    return ws.Swarm(swarm.position[[i]], swarm.velocity[[i]], swarm.radius[[i]],
                    swarm.mass[[i]], angular_momentum=swarm.angular_momentum[[i]],
                    orientation=swarm.orientation[[i]])


def events_of(table, sphere: int, shift: int) -> dict:
    """The contacts of one sphere, frames shifted back by ``shift``, as comparable columns."""
    rows = table.of_sphere(sphere)
    return {"frame": rows.frame - shift, "fraction": rows.fraction, "box": rows.box,
            "kind": rows.kind, "position": rows.position, "normal": rows.normal,
            "normal_speed": rows.normal_speed}


def check_against_alone(scene, swarm, traj, sim, every, **kw):
    """Every sphere of ``traj`` (a run with births) against its own run from its birth."""
    frames = int(traj.frame[-1])
    expected_bounces = 0
    lived = 0
    for i, b in enumerate(swarm.birth_frame):
        unborn = traj.frame < b
        assert np.isnan(traj.position[unborn, i]).all()
        assert np.isnan(traj.orientation[unborn, i]).all()
        if b > frames:
            assert len(traj.events.of_sphere(i)) == 0
            continue
        ref = ws.Simulator(scene, alone(swarm, i), workers=1, **kw)
        assert not ref._features.births
        rows = np.flatnonzero(traj.frame >= b)
        if b < frames:
            want = ref.run(frames - int(b), every=1, velocities=True, events=True)
            at = traj.frame[rows] - b  # the alone run's record of each of those frames
            for name in ("position", "orientation", "velocity", "angular_velocity"):
                got = getattr(traj, name)[rows, i]
                assert np.array_equal(got, getattr(want, name)[at, 0]), (name, i, b)
            got_events, want_events = events_of(traj.events, i, b), events_of(want.events, 0, 0)
            for name, values in want_events.items():
                assert np.array_equal(got_events[name], values), (name, i, b)
            expected_bounces += ref.stats.bounces
            lived += frames - int(b)
        else:  # born on the last frame: recorded at its birth state, never moved
            assert np.array_equal(traj.position[rows, i],
                                  swarm.position[[i]].astype(traj.position.dtype))
    assert sim.stats.bounces == expected_bounces
    assert sim.stats.sphere_frames == lived
    assert traj.birth_frame.tolist() == swarm.birth_frame.tolist()
    assert traj.alive().tolist() == (traj.frame[:, None] >= swarm.birth_frame[None]).tolist()


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_born_sphere_moves_as_a_run_started_at_its_birth(precision, motion):
    scene, swarm = spin_swarm()
    kw = dict(precision=precision, motion=motion, device="cpu")
    sim = ws.Simulator(scene, swarm, workers=1, **kw)
    assert sim.spin and sim._features.births
    traj = sim.run(FRAMES, every=1, velocities=True, events=True)
    assert traj.events.frame.size > 0 and np.nanmax(np.abs(traj.angular_velocity[-1])) > 0
    check_against_alone(scene, swarm, traj, sim, 1, **kw)


def test_births_across_launches_threads_and_every(monkeypatch, precision):
    """Launch chunks that start before, at and after births, two threads, and a recording
    stride change no bit of a run with births."""
    scene, swarm = spin_swarm()
    kw = dict(precision=precision, device="cpu")
    whole = ws.Simulator(scene, swarm, workers=1, **kw)
    ref = whole.run(FRAMES, every=1, velocities=True, events=True)
    monkeypatch.setattr(simulator_module, "LAUNCH_SPHERE_FRAMES", len(BIRTHS) * 4)
    sim = ws.Simulator(scene, swarm, workers=2, **kw)
    assert sim.workers == 2
    first = sim.run(33, every=3, velocities=True, events=True)
    sim.step(17)
    rest = sim.run(FRAMES - 50, every=3, velocities=True, events=True)
    for part in (first, rest):
        rows = np.searchsorted(ref.frame, part.frame)
        for name in ("position", "orientation", "velocity"):
            assert np.array_equal(getattr(part, name), getattr(ref, name)[rows],
                                  equal_nan=True), name
        # a run's first angular velocity is the host's (float64, rounded), the others the
        # kernel's: compare the kernel's
        assert np.array_equal(part.angular_velocity[1:], ref.angular_velocity[rows[1:]],
                              equal_nan=True)
        inside = (ref.events.frame > part.frame[0]) & (ref.events.frame <= part.frame[-1])
        want = ref.events.select(np.flatnonzero(inside))
        for name in ("frame", "sphere", "box", "kind", "fraction", "position", "normal",
                     "normal_speed"):
            assert np.array_equal(getattr(part.events, name), getattr(want, name)), name
    assert sim.stats.bounces == whole.stats.bounces
    assert sim.stats.sphere_frames == whole.stats.sphere_frames


def test_all_born_at_zero_builds_no_births_code():
    scene, swarm = spin_swarm(np.zeros(3, dtype=np.int64))
    assert not swarm.has_births
    assert not ws.Simulator(scene, swarm, device="cpu")._features.births


@pytest.mark.parametrize("value,message", [
    ([0, -1, 2], r"birth_frame\[1\] must be >= 0, got -1"),
    ([0, 1.0, 2], "birth_frame must be integers"),
    ([0, 1], r"birth_frame must be an integer or have shape \(3,\)"),
    (True, "birth_frame must be integers"),
    ([0, 2**31, 0], r"birth_frame\[1\] must be below 2\*\*31"),
    # beyond int64: reported as the value given, never wrapped to a negative one
    (np.uint64(2**63 + 5), r"^birth_frame must be below 2\*\*31, got 9223372036854775813$"),
    (2**64, r"^birth_frame must be below 2\*\*31, got 18446744073709551616$"),
    (np.array([0, 0, 2**64 - 1], dtype=np.uint64),
     r"^birth_frame\[2\] must be below 2\*\*31, got 18446744073709551615$"),
    ([0, 2**70, -1], r"^birth_frame\[2\] must be >= 0, got -1$"),
    ([0, 2**70, 1], r"^birth_frame\[1\] must be below 2\*\*31, got 1180591620717411303424$"),
    (-2**70, r"^birth_frame must be >= 0, got -1180591620717411303424$"),
    ([0, 2**70, 1.5], "birth_frame must be integers"),
    # a bool among integers would become 0 or 1: refused as a bool alone is
    ([0, True, 2], r"^birth_frame\[1\] must be a number, got True$"),
    ((np.bool_(False), 1, 2), r"^birth_frame\[0\] must be a number, got np.False_$"),
])
def test_bad_birth_frames_are_refused_naming_the_index(value, message):
    with pytest.raises(ValueError, match=message):
        ws.Swarm(np.zeros((3, 3)), np.zeros((3, 3)), birth_frame=value)


@pytest.mark.parametrize("fmt", ["usda", "usdc"])
def test_usd_hides_the_unborn_and_reads_them_back_as_nan(tmp_path, fmt):
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom
    from test_export import compliance_errors

    from warpsim.export import read_usd, write_usd

    scene, swarm = spin_swarm()
    sim = ws.Simulator(scene, swarm, workers=1, device="cpu")
    traj = sim.run(FRAMES, every=1, velocities=True)
    out = write_usd(tmp_path / f"births.{fmt}", scene, traj, stride=4)
    assert compliance_errors(out) == []
    stage = Usd.Stage.Open(str(out))
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    invisible = instancer.GetInvisibleIdsAttr()
    written = traj.frame[np.unique(np.r_[np.arange(0, len(traj), 4), len(traj) - 1])]
    for frame in written:
        hidden = sorted(np.asarray(invisible.Get(float(frame)), dtype=np.int64).tolist())
        assert hidden == np.flatnonzero(BIRTHS > frame).tolist(), frame
        # what a renderer draws: the instancer's own visibility mask
        mask = np.asarray(instancer.ComputeMaskAtTime(float(frame)))
        if mask.size:
            assert mask.tolist() == (BIRTHS <= frame).tolist()
    back = read_usd(out)
    assert back.frame.tolist() == written.tolist()
    assert back.birth_frame.tolist() == BIRTHS.tolist()
    rows = np.searchsorted(traj.frame, written)
    for name in ("position", "orientation", "velocity"):
        want = getattr(traj, name)[rows].astype(np.float32)
        assert np.array_equal(getattr(back, name), want, equal_nan=True), name
    assert np.isnan(back.position[~back.alive()]).all()
    assert not np.isnan(back.position[back.alive()]).any()


# --- scene files: [emitter] start, rate, duration --------------------------------------------

NOZZLE_DT = 1.0 / 120.0


def test_nozzle_births_are_the_nearest_frames_of_the_emission_times():
    scene = ws.Scene.load("nozzle")
    swarm = scene.spawn(n=50)
    # sphere k is emitted at k / 200 s: frame 0.6 k, rounded to the nearest (halves to even)
    by_hand = [int(np.rint(0.6 * k)) for k in range(50)]
    assert swarm.birth_frame.tolist() == by_hand
    assert scene.spawn(n=50, dt=NOZZLE_DT / 2).birth_frame.tolist() == [
        int(np.rint(1.2 * k)) for k in range(50)]
    # the same spheres whatever the births: the draw does not depend on them
    plain = replace(scene.emitter, rate=None).spawn(scene.boxes, n=50)
    assert np.array_equal(plain.position, swarm.position) and not plain.has_births


@pytest.mark.parametrize("table, frames", [
    ({"duration": 0.5}, [int(np.rint(k * 0.5 / 10 * 120)) for k in range(10)]),
    ({"rate": 20.0, "duration": 0.5}, [int(np.rint(k / 20 * 120)) for k in range(10)]),
    ({"start": 0.25}, [30] * 10),
    ({"start": 0.25, "rate": 40.0}, [int(np.rint((0.25 + k / 40) * 120)) for k in range(10)]),
])
def test_emitter_tables_give_their_birth_frames(table, frames):
    emitter = ws.Emitter.from_table({"count": 10, **table})
    assert emitter.birth_frames(NOZZLE_DT).tolist() == frames


@pytest.mark.parametrize("table, message", [
    ({"rate": 0.0}, "emitter.rate must be > 0"),
    ({"rate": -1.0}, "emitter.rate must be > 0"),
    ({"duration": 0.0}, "emitter.duration must be > 0"),
    ({"start": -1.0}, "emitter.start must be >= 0"),
    ({"rate": "fast"}, "emitter.rate must be a number"),
    ({"rate": 30.0, "duration": 0.5},
     r"emitter.rate x emitter.duration = 15 spheres, but emitter.count is 10"),
])
def test_bad_emission_timing_is_refused_naming_the_key(table, message):
    with pytest.raises(ValueError, match=message):
        ws.Emitter.from_table({"count": 10, **table})


def test_an_emitter_of_births_needs_the_runs_dt():
    scene = ws.Scene.load("nozzle")
    with pytest.raises(ValueError, match="spawn it with the run's dt"):
        scene.emitter.spawn(scene.boxes, n=4)


# --- error reports: each sphere against the reference from its birth -------------------------

def test_error_report_measures_each_sphere_from_its_birth():
    from warpsim.analysis.error_report import compare

    scene, drawn = spin_swarm(np.zeros(6, dtype=np.int64))
    born_late = ws.Swarm(drawn.position, drawn.velocity, drawn.radius, drawn.mass,
                         birth_frame=12)
    late = ws.Simulator(scene, born_late, workers=1, device="cpu")
    traj = late.run(48, every=1)
    plain = ws.Simulator(scene, drawn, workers=1, device="cpu")
    plain_traj = plain.run(36, every=1)
    for got, want in ((compare(late, scene, born_late, sample=3),
                       compare(plain, scene, drawn, sample=3)),
                      (compare(traj, scene, born_late, sample=3),
                       compare(plain_traj, scene, drawn, sample=3))):
        got, want = got.to_dict(), want.to_dict()
        assert got["invariants"].pop("frames") == 48 and want["invariants"].pop("frames") == 36
        assert got["horizon_s"] == pytest.approx(36 * scene.dt)
        for key in ("sample", "horizon_s", "contacts", "position_error", "divergence",
                    "invariants", "reference", "energy"):
            assert got[key] == want[key], key
    # spheres not born by the end are never sampled
    mixed = ws.Swarm(drawn.position, drawn.velocity, drawn.radius, drawn.mass,
                     birth_frame=[0, 60, 0, 60, 0, 60])
    sim = ws.Simulator(scene, mixed, workers=1, device="cpu")
    sim.step(30)
    report = compare(sim, scene, mixed, sample=6)
    assert report.sample.tolist() == [0, 2, 4]
    assert report.invariants["spheres"] == 3


def test_file_estimate_counts_the_unborn_slots_the_file_holds(tmp_path):
    pytest.importorskip("pxr")
    from warpsim.export import estimate_usd_bytes, write_usd

    scene = ws.Scene.load("nozzle")
    swarm = scene.spawn(n=300)
    traj = ws.Simulator(scene, swarm, device="cpu").run(scene.frames, every=2)
    unborn = int((~traj.alive()).sum())
    assert unborn > 0.2 * traj.alive().size
    for fmt in ("usdc", "usda"):
        size = write_usd(tmp_path / f"n.{fmt}", scene, traj).stat().st_size
        estimate = estimate_usd_bytes(len(swarm), len(traj), fmt, boxes=scene.boxes,
                                      spinning=False, unborn=unborn)
        assert abs(estimate - size) <= 0.1 * size, (fmt, estimate, size)


@pytest.mark.slow
def test_cli_births_at_another_dt_are_the_same_with_shards(tmp_path):
    """``warpsim run`` counts births in frames of its ``--dt``, in one process and in shards."""
    pytest.importorskip("pxr")
    import subprocess
    import sys

    from warpsim.export import read_usd

    def run(*extra):
        out = tmp_path / f"nozzle{len(extra)}.usdc"
        done = subprocess.run([sys.executable, "-m", "warpsim.apps.cli", "run", "nozzle", "-n",
                               "40", "--frames", "30", "--dt", "0.005", "-o", str(out),
                               "--block", "16", "--no-progress", *extra],
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        return read_usd(out)

    plain, sharded = run(), run("--shards", "2")
    births = np.rint(np.arange(40) / 200.0 / 0.005).astype(np.int64)  # k / 200 s at 5 ms
    assert plain.birth_frame.tolist() == births.tolist()
    assert sharded.birth_frame.tolist() == births.tolist()
    assert np.array_equal(plain.position, sharded.position, equal_nan=True)
    assert np.isnan(plain.position[~plain.alive()]).all()


def test_preview_draws_only_the_born(tmp_path):
    pytest.importorskip("pxr")
    from PIL import Image, ImageChops

    from warpsim.export import draw_frame, render_preview, write_usd
    from warpsim.export.preview import scene_bounds

    scene, swarm = spin_swarm()
    traj = ws.Simulator(scene, swarm, workers=1, device="cpu").run(40, every=10)
    out = write_usd(tmp_path / "births.usdc", scene, traj)
    png = render_preview(out, 30, tmp_path / "frame.png", size=(160, 90))
    born = BIRTHS <= 30
    assert 0 < born.sum() < len(BIRTHS)
    row = list(traj.frame).index(30)
    bounds = scene_bounds(scene.boxes, traj.position[row][born], traj.radius[born])
    want, _ = draw_frame(scene.boxes, traj.position[row][born].astype(np.float32),
                         traj.orientation[row][born].astype(np.float32), traj.radius[born],
                         size=(160, 90), bounds=bounds)
    assert ImageChops.difference(Image.open(png).convert("RGB"), want).getbbox() is None
