"""The studies' own kernels still build against the package's funcs (a study is not run by
the tests, so a changed func signature would otherwise break it unnoticed)."""

import warnings

import numpy as np
import warp as wp

import warpsim as ws


def test_the_frame_floor_partial_loops_build_and_step_free_flight():
    """``benchmarks.frame_floor``'s bare, lookup and reset loops over a few spheres of the
    free-flight scene: each moves them along the same free-flight chords (``x + (v + g dt /
    2) dt`` a frame, in float32), and none is hit."""
    from benchmarks import frame_floor as ff

    room = ws.Scene.load("room")
    swarm = room.spawn(n=8, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ws.PrecisionWarning)
        sim = ws.Simulator(ff.far_scene(room), swarm, precision="float32", workers=1,
                           device="cpu")
    sim.build()
    frames = 3
    dt = float(room.dt)
    g = np.asarray(room.gravity, dtype=np.float64)
    x0 = np.asarray(swarm.position, dtype=np.float64)
    v0 = np.asarray(swarm.velocity, dtype=np.float64)
    t = frames * dt
    expected = x0 + v0 * t + 0.5 * g * t * t  # the chords' ends lie on the parabola
    for name, kernel in ff.part_kernels(sim).items():
        out = sim.state_0.empty_like()
        ff.part_call(sim, kernel, frames, out)()
        wp.synchronize_device(sim.device)
        got = out.position.numpy().astype(np.float64)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-4, err_msg=name)
        if name != "+ energy reset":  # the others count hits in their energy slot
            assert np.all(out.energy.numpy() == 0), name
