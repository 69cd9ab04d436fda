"""Many frames per launch and many workers give the same bits as one launch per frame.

Spheres never interact, so a thread may advance its sphere through many frames with the state in
registers, and the swarm may be split into shards launched from several threads; neither may
change a single bit of any result (state, recorded frames, counters).
"""

import numpy as np
import pytest

import warpsim as ws


def state_bytes(sim: ws.Simulator) -> bytes:
    s = sim.state()
    return b"".join(np.ascontiguousarray(a).tobytes() for a in (
        s.position, s.velocity, s.energy, s.angular_momentum, s.orientation))


def per_frame_reference(scene, swarm, frames, every, **kw):
    """One launch per frame, recording by copying the state out after each stop."""
    sim = ws.Simulator(scene, swarm, workers=1, **kw)
    positions, orientations = [sim.state().position], [sim.state().orientation]
    for k in range(1, frames + 1):
        sim.step(1)
        if k % every == 0 or k == frames:
            positions.append(sim.state().position)
            orientations.append(sim.state().orientation)
    return sim, np.stack(positions), np.stack(orientations)


@pytest.mark.parametrize("scene_name,every", [("room", 7), ("spin", 5), ("galton", 30)])
def test_run_matches_one_launch_per_frame(scene_name, every, precision):
    scene = ws.Scene.load(scene_name)
    swarm = scene.spawn(n=700, seed=4)
    frames = 61
    ref, ref_pos, ref_orient = per_frame_reference(scene, swarm, frames, every,
                                                   precision=precision, device="cpu")
    for workers in (1, 2, 3):
        sim = ws.Simulator(scene, swarm, workers=workers, precision=precision, device="cpu")
        traj = sim.run(frames, every=every)
        assert sim.workers == workers
        assert np.array_equal(traj.position, ref_pos)
        assert np.array_equal(traj.orientation, ref_orient)
        assert state_bytes(sim) == state_bytes(ref)
        assert sim.stats.bounces == ref.stats.bounces
        assert sim.stats.capped == ref.stats.capped
        expected_frames = [0] + [k for k in range(every, frames + 1, every)]
        if expected_frames[-1] != frames:
            expected_frames.append(frames)
        assert traj.frame.tolist() == expected_frames


def test_step_chunks_and_repeated_runs_are_seamless(monkeypatch):
    """Small launches (forced) and runs that start mid-interval change nothing."""
    from warpsim import simulator as simulator_module

    scene = ws.Scene.load("wedge")
    swarm = scene.spawn(n=300, seed=1)
    ref = ws.Simulator(scene, swarm, workers=1, device="cpu")
    ref.step(50)
    monkeypatch.setattr(simulator_module, "LAUNCH_SPHERE_FRAMES", 300 * 3)
    sim = ws.Simulator(scene, swarm, workers=2, device="cpu")
    sim.run(13, every=4)
    sim.step(17)
    traj = sim.run(20, every=6)
    assert traj.frame.tolist() == [30, 36, 42, 48, 50]
    assert state_bytes(sim) == state_bytes(ref)


def test_recorded_velocities_are_the_states(precision):
    """``velocities=True`` records the velocity at each recorded frame: the state's, bit for
    bit (the velocity at the frame's end, see ``State``)."""
    scene = ws.Scene.load("spin")
    swarm = scene.spawn(n=200, seed=2)
    sim = ws.Simulator(scene, swarm, precision=precision, device="cpu")
    ref = ws.Simulator(scene, swarm, precision=precision, device="cpu")
    traj = sim.run(12, every=4, velocities=True)
    assert traj.velocity.shape == traj.position.shape
    for row, frame in enumerate(traj.frame):
        if frame:
            ref.step(int(frame - ref.frame))
        s = ref.state()
        np.testing.assert_array_equal(traj.velocity[row], s.velocity)
        inertia = 0.4 * swarm.mass * swarm.radius ** 2
        rot = s.angular_momentum.astype(np.float64) / inertia[:, None]
        norm = np.linalg.norm(rot, axis=1)
        over = norm > scene.max_angular_speed
        rot[over] *= (scene.max_angular_speed / norm[over])[:, None]
        np.testing.assert_allclose(traj.angular_velocity[row], rot, rtol=1e-5, atol=1e-6)


def test_workers_default_and_bounds():
    scene = ws.Scene.load("room")
    small = ws.Simulator(scene, scene.spawn(n=10, seed=0), device="cpu")
    assert small.workers == 1  # too few spheres to split
    with pytest.raises(ValueError, match="workers"):
        ws.Simulator(scene, scene.spawn(n=10, seed=0), workers=0, device="cpu")


@pytest.mark.parametrize("events", [False, True])
def test_shards_build_their_kernel_once_before_their_threads_launch(monkeypatch, events):
    """The first launch of a kernel builds (or loads) its module; with several shards that
    happens once, in the calling thread, not once in each shard's thread at the same time (two
    threads building one module cost a core each, for a build as long)."""
    import threading

    from warp._src.context import Module

    from warpsim.kernels.frame_kernel import frame_kernel

    scene = ws.Scene.load("room")
    sim = ws.Simulator(scene, scene.spawn(n=600, seed=2), workers=3, device="cpu")
    assert sim.workers == 3
    kernel = frame_kernel(sim._features.but(events=events))
    kernel.module.unload()  # the next launch loads it again, as a first launch does
    first_loads = []
    load = Module.load

    def spy(module, *args, **kwargs):
        if module is kernel.module and not module.execs:
            first_loads.append(threading.current_thread().name)
        return load(module, *args, **kwargs)

    monkeypatch.setattr(Module, "load", spy)
    if events:
        sim.run(3, events=True)
    else:
        sim.step(3)
    assert first_loads == [threading.current_thread().name]


@pytest.mark.parametrize("events,plain", [(False, True), (True, True), (True, False)])
def test_build_loads_the_kernels_asked_for_and_no_other(monkeypatch, events, plain):
    """``build`` loads the plain kernel (what ``step`` launches) and, with ``events``, the one
    with the contact code, or with ``plain=False`` that one alone; a run with events then
    launches only the kernel built; nothing to build is refused."""
    import warp as wp

    from warpsim.kernels.frame_kernel import frame_kernel

    scene = ws.Scene.load("room")
    sim = ws.Simulator(scene, scene.spawn(n=60, seed=3), device="cpu")
    modules = {"plain": sim._kernel.module,
               "events": frame_kernel(sim._features.but(events=True)).module}
    loaded = []
    real = wp.load_module

    def spy(module, device=None):
        loaded.append(next(name for name, m in modules.items() if m is module))
        return real(module, device=device)

    monkeypatch.setattr(wp, "load_module", spy)
    sim.build(events=events, plain=plain)
    assert loaded == [name for name, on in (("plain", plain), ("events", events)) if on]
    if events:
        assert len(sim.run(20, events=True).events) >= 0
    with pytest.raises(ValueError, match="^build: events and plain are both false"):
        sim.build(events=False, plain=False)
    with pytest.raises(ValueError, match="plain must be true or false"):
        sim.build(plain=1)


@pytest.mark.parametrize("workers", [1, 2])
def test_stepping_reads_the_states_the_simulator_holds_now(workers):
    """``step`` packs its launch's arguments once per pair of states: a state set with
    ``set_state``, or a state array replaced on the device state, is read from then on (the
    arrays left behind are filled with NaN, so a launch that still read them would show)."""
    import warp as wp

    scene = ws.Scene.load("room")
    swarm = scene.spawn(n=300, seed=2)
    ref = ws.Simulator(scene, swarm, workers=workers, device="cpu")
    start = ref.state()
    ref.step(9)
    sim = ws.Simulator(scene, ws.Swarm(position=swarm.position + [0.0, 0.01, 0.0],
                                       velocity=-swarm.velocity, radius=swarm.radius,
                                       mass=swarm.mass), workers=workers, device="cpu")
    for _ in range(3):
        sim.step(1)
    left = [sim.state_0, sim.state_1]
    sim.set_state(start)
    for state in left:
        state.position.fill_(float("nan"))
        state.velocity.fill_(float("nan"))
    sim.step(1)
    sim.step(3)
    old = sim.state_0.position
    sim.state_0.position = wp.clone(old)
    old.fill_(float("nan"))
    for _ in range(5):
        sim.step(1)
    assert sim.frame == ref.frame == 9
    assert state_bytes(sim) == state_bytes(ref)


def test_set_state_lets_go_of_the_states_it_replaces():
    """The launches ``step`` recorded hold the states' arrays; ``set_state`` drops them with the
    states, so a large swarm's old state is freed at once, not at the next step."""
    import gc
    import weakref

    scene = ws.Scene.load("room")
    sim = ws.Simulator(scene, scene.spawn(n=50, seed=1), device="cpu")
    sim.step(1)
    sim.step(1)  # a launch recorded for each order of the two states
    old = [weakref.ref(getattr(state, name)) for state in (sim.state_0, sim.state_1)
           for name in ("position", "velocity", "energy")]
    sim.set_state(sim.state())
    gc.collect()
    assert all(ref() is None for ref in old)


def test_a_gpu_launch_holds_many_frames_and_a_recording_one_keeps_its_buffers_bounded(
        monkeypatch):
    """On a GPU, ``step`` launches hold 100 frames and more up to 1e7 spheres (10 at 1e8): a
    frame there costs a fifth of a nanosecond a sphere, and one frame a launch made every frame
    pay what a launch pays once. ``run``'s launches keep the CPU's budget on every device, as
    the memory check (``footprint.run_bytes``) counts their record buffers."""
    from types import SimpleNamespace

    from warpsim import footprint
    from warpsim import simulator as simulator_module

    scene = ws.Scene.load("room")
    sim = ws.Simulator(scene, scene.spawn(n=50, seed=1), device="cpu")
    budget = simulator_module.LAUNCH_SPHERE_FRAMES
    for n in (1, 50, 10**6, 10**7, 10**8):
        monkeypatch.setattr(sim, "_n", n)
        monkeypatch.setattr(sim, "device", SimpleNamespace(is_cpu=True))
        cpu = sim._frames_per_launch()
        monkeypatch.setattr(sim, "device", SimpleNamespace(is_cpu=False))
        gpu = sim._frames_per_launch()
        assert cpu == max(1, budget // n)
        assert gpu >= cpu and gpu * n <= simulator_module.GPU_LAUNCH_SPHERE_FRAMES or gpu == 1
        if n <= 10**7:
            assert gpu >= 100
        assert sim._frames_per_launch() >= (10 if n <= 10**8 else 1)
        for every in (1, 3, 250):
            for is_cpu in (True, False):
                monkeypatch.setattr(sim, "device", SimpleNamespace(is_cpu=is_cpu))
                frames = sim._frames_per_launch(every, records=True)
                assert frames % every == 0 and frames >= every
                rows = frames // every
                expected = footprint.run_bytes(n, 2, every=every, launch_sphere_frames=budget)
                assert 2 * rows * n * 7 * 4 <= max(expected.launch, 2 * n * 7 * 4)


def everything(sim: ws.Simulator, traj) -> dict:
    """Every result of a run: the state, the recorded frames and velocities, the counters and
    the contact table's columns (when the run kept its contacts)."""
    out = {"state": state_bytes(sim), "bounces": sim.stats.bounces,
           "supports": sim.stats.supports, "capped": sim.stats.capped}
    for name in ("position", "orientation", "velocity", "angular_velocity"):
        out[name] = np.asarray(getattr(traj, name)).tobytes()
    if traj.events is not None:
        out.update({k: np.asarray(v).tobytes() for k, v in traj.events.columns().items()})
    return out


# the kernel variants other tests build too (a cold suite builds each new one, seconds each):
# the nozzle's births with the linear model in float32 and without events
@pytest.mark.parametrize("scene_name,motion,precision,events", [
    ("room", "linear", "float32", True), ("room", "linear", "float64", True),
    ("plates", "ballistic", "float32", True), ("plates", "ballistic", "float64", True),
    ("spin", "linear", "float32", True), ("spin", "linear", "float64", True),
    ("nozzle", "linear", "float32", False)])
def test_the_spheres_a_task_advances_change_no_bit(scene_name, motion, precision, events):
    """A CPU task advances a block of spheres in turn (a GPU thread one): whatever the block,
    one sphere (the GPU's mapping), a few, blocks that straddle the shards' borders, or one
    block larger than the swarm, every result is the same bits, records, events and births
    (``nozzle`` emits over time) included, with one worker or three."""
    from warpsim import model

    scene = ws.Scene.load(scene_name)
    swarm = scene.spawn(n=101, seed=5)
    assert model.CPU_SPHERES_PER_TASK > 1

    def results(per_task, workers):
        sim = ws.Simulator(scene, swarm, workers=workers, motion=motion, precision=precision,
                           device="cpu")
        assert sim._per_task == model.CPU_SPHERES_PER_TASK
        assert sim._features.births == (scene_name == "nozzle")
        sim._per_task = per_task
        sim.step(3)  # the recorded step launches
        traj = sim.run(90, every=6, velocities=True, events=events)
        return everything(sim, traj)

    reference = results(1, 1)
    assert reference["bounces"] > 0
    for per_task, workers in ((3, 1), (7, 3), (64, 3), (500, 1)):
        assert results(per_task, workers) == reference, (per_task, workers)


@pytest.mark.parametrize("motion", ["linear", "ballistic"])
def test_the_single_frame_queries_change_no_bit_with_the_block(monkeypatch, motion, precision):
    """``collide_boxes`` and ``bounce`` launch a task a block of spheres on the CPU too: one
    sphere a task (the GPU's mapping), a few, or one block larger than the batch give the same
    bits in every output."""
    import dataclasses

    from warpsim import model

    scene = ws.Scene.load("room")
    swarm = dataclasses.replace(scene.emitter, count=301, speed=60.0).spawn(scene.boxes, seed=3)
    dt = 4 * scene.dt  # long paths: many contacts, several bounces

    gravity = scene.gravity if motion == "ballistic" else None
    # friction (the spin code) where other tests build that variant too
    friction = 0.3 if (precision, motion) == ("float32", "linear") else 0.0

    def results(per_task):
        monkeypatch.setattr(model, "CPU_SPHERES_PER_TASK", per_task)
        c = ws.collide_boxes(swarm.position, swarm.velocity, swarm.radius, scene.boxes, dt,
                             precision=precision, motion=motion, gravity=gravity, device="cpu")
        b = ws.bounce(swarm.position, swarm.velocity, swarm.radius, scene.boxes, dt,
                      precision=precision, motion=motion, gravity=gravity, friction=friction,
                      device="cpu")
        return ({k: np.asarray(v).tobytes() for k, v in vars(c).items()},
                {k: np.asarray(v).tobytes() for k, v in vars(b).items()}, int(c.hit.sum()),
                int(b.bounces.sum()))

    reference = results(1)
    assert reference[2] > 20 and reference[3] > 20
    for per_task in (4, 64, 1000):
        assert results(per_task) == reference, per_task
