"""Every bundled scene loads, spawns and runs a few frames of the simulator, sanely."""

import numpy as np
import pytest

import warpsim as ws

SCENES = [name for name, _ in ws.list_scenes()]


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENES)
def test_bundled_scene_runs(device, name):
    """A few frames with each scene's own settings (its kernel variant): finite, nobody inside
    an obstacle beyond float32 rounding of the scene's coordinates, energy not gained."""
    scene = ws.Scene.load(name)
    n = min(scene.emitter.count, 64)
    swarm = scene.spawn(n=n, seed=1)
    sim = ws.Simulator(scene, swarm, device=device)
    traj = sim.run(5)
    assert traj.position.shape == (6, n, 3)
    alive = traj.alive()  # a scene whose spheres are born over time: only the born are drawn
    assert np.isnan(traj.position[~alive]).all()
    assert np.isfinite(traj.position[alive]).all() and np.isfinite(traj.orientation[alive]).all()
    scale = np.abs(scene.boxes.center).max() + np.abs(scene.boxes.world_extent()).max()
    tol = 64 * np.finfo(np.float32).eps * scale
    born = alive[-1]
    depth = scene.boxes.signed_distance(traj.position[-1][born].astype(np.float64)) \
        - swarm.radius[born, None]
    assert depth.min() >= -tol, (name, depth.min())
    state = sim.state()
    gain = sim.mechanical_energy(state) - sim.initial_energy.astype(np.float64)
    e_scale = np.abs(sim.initial_energy).max() + 1.0
    assert gain.max() <= 64 * np.finfo(np.float32).eps * e_scale
    np.testing.assert_allclose(np.linalg.norm(state.orientation, axis=1), 1.0, atol=1e-5)
