"""Golden determinism: the hash of bundled scenes' state after a fixed run is written here.

A change that alters any bit of any result fails this test. When a change of results is intended
(a physics fix, a new default), print the new values with::

    WARPSIM_PRINT_GOLDEN=1 pytest tests/test_golden.py -q -s

check that the change is the one meant (the other tests say whether the physics still holds),
paste them into ``GOLDEN`` below, and say in the commit message why the results changed.
"""

import hashlib
import os

import numpy as np
import pytest

import warpsim as ws

SPHERES = 200
FRAMES = 90
SEED = 3

#: (scene, precision) -> (sha256 prefix of the state's bytes, total bounces, capped frames).
GOLDEN = {
    ("room", "float32"): ("eff4aaffc8ff9650", 460, 0),
    ("room", "float64"): ("f8574cfdeeeaf442", 460, 0),
    ("spin", "float32"): ("2ef8503057c76cce", 203, 0),
    ("thin-walls", "float64"): ("74c20f0f28517466", 62695, 0),
    ("wedge", "float32"): ("ee89e21bc832cf22", 11901, 450),
    ("nozzle", "float32"): ("418d83c1f07df36c", 22, 0),
}


def state_hash(sim: ws.Simulator) -> str:
    s = sim.state()
    h = hashlib.sha256()
    for a in (s.position, s.velocity, s.angular_momentum, s.orientation, s.energy):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


@pytest.mark.parametrize("scene_name,precision", list(GOLDEN))
def test_golden_state(scene_name, precision):
    scene = ws.Scene.load(scene_name)
    sim = ws.Simulator(scene, scene.spawn(n=SPHERES, seed=SEED), precision=precision,
                       device="cpu")
    sim.step(FRAMES)
    got = (state_hash(sim), sim.stats.bounces, sim.stats.capped)
    if os.environ.get("WARPSIM_PRINT_GOLDEN") == "1":
        print(f'\n    ("{scene_name}", "{precision}"): ("{got[0]}", {got[1]}, {got[2]}),')
    assert got == GOLDEN[(scene_name, precision)]
