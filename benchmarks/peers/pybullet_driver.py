"""PyBullet (Bullet 3), with and without its continuous collision detection.

Set-up: one rigid sphere body per sphere with maximal coordinates (``useMaximalCoordinates``:
with PyBullet's default multibodies the CCD setting has no effect on a free sphere), the walls
and plates as static boxes (PyBullet's quaternions are (x, y, z, w), as warpsim's). Restitution
1 on spheres and boxes, lateral, rolling and spinning friction 0, no damping, gravity as given,
``fixedTimeStep = dt`` with no substeps; everything else PyBullet's defaults (50 solver
iterations, split impulse, its restitution velocity threshold). Sphere-sphere contacts are off
by collision filters (spheres in group 1 with mask 2, the room in group 2 with mask 1); Bullet's
broad phase still finds the sphere pairs before dropping them. CCD: ``ccdSweptSphereRadius`` =
the sphere radius (PyBullet then sets Bullet's CCD motion threshold to half of it).

Where it differs from the workload: Bullet resolves contacts by a soft iterative solver and
CCD clamps the motion to the time of impact, so an elastic bounce is not exact; a sphere is a
6-DoF rigid body (it may spin; the energy measured is the translational one).
"""

from __future__ import annotations

import contextlib
import os
import sys

import numpy as np

from .workload import Workload

_MODULE = []


@contextlib.contextmanager
def _quiet_c_output():
    """Silence C-level standard output and error (pybullet prints its build date on import)."""
    import ctypes

    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
            yield
            ctypes.CDLL(None).fflush(None)
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in saved:
            os.close(fd)


def pybullet_module():
    """The ``pybullet`` module, imported quietly once (ImportError when it is missing)."""
    if not _MODULE:
        with _quiet_c_output():
            import pybullet
        _MODULE.append(pybullet)
    return _MODULE[0]


class PybulletDriver:
    """PyBullet in DIRECT mode (no GUI), one client per driver.

    Args:
        work: the workload.
        ccd: Bullet's swept-sphere continuous collision detection on the spheres.
    """

    #: ``state()``'s velocity is semi-implicit Euler's step velocity (the mean over the last step)
    step_velocity = True

    def __init__(self, work: Workload, ccd: bool = False):
        p = pybullet_module()
        self.key = "pybullet-ccd" if ccd else "pybullet"
        self.label = "PyBullet CCD" if ccd else "PyBullet"
        self._p = p
        self._n = work.n
        self._client = c = p.connect(p.DIRECT)
        p.setGravity(*work.gravity, physicsClientId=c)
        p.setPhysicsEngineParameter(fixedTimeStep=work.dt, numSubSteps=0, physicsClientId=c)
        for o in work.obstacles:
            shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=o.half_extents,
                                           physicsClientId=c)
            body = p.createMultiBody(0, shape, basePosition=o.center,
                                     baseOrientation=o.rotation, physicsClientId=c)
            p.setCollisionFilterGroupMask(body, -1, 2, 1, physicsClientId=c)
            p.changeDynamics(body, -1, restitution=1.0, lateralFriction=0.0,
                             rollingFriction=0.0, spinningFriction=0.0, physicsClientId=c)
        shape = p.createCollisionShape(p.GEOM_SPHERE, radius=work.radius, physicsClientId=c)
        ids = p.createMultiBody(work.mass, shape, batchPositions=work.position.tolist(),
                                useMaximalCoordinates=True, physicsClientId=c)
        self._ids = [ids] if isinstance(ids, int) else list(ids)
        swept = {"ccdSweptSphereRadius": work.radius} if ccd else {}
        for i, body in enumerate(self._ids):
            p.setCollisionFilterGroupMask(body, -1, 1, 2, physicsClientId=c)
            p.changeDynamics(body, -1, restitution=1.0, lateralFriction=0.0,
                             rollingFriction=0.0, spinningFriction=0.0, linearDamping=0.0,
                             angularDamping=0.0, physicsClientId=c, **swept)
            p.resetBaseVelocity(body, work.velocity[i].tolist(), [0.0, 0.0, 0.0],
                                physicsClientId=c)
        self._saved = p.saveState(physicsClientId=c)

    def reset(self) -> None:
        self._p.restoreState(self._saved, physicsClientId=self._client)

    def step(self, frames: int) -> None:
        p, c = self._p, self._client
        for _ in range(frames):
            p.stepSimulation(physicsClientId=c)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        p, c = self._p, self._client
        pos = np.array([p.getBasePositionAndOrientation(b, physicsClientId=c)[0]
                        for b in self._ids], dtype=np.float64).reshape(self._n, 3)
        vel = np.array([p.getBaseVelocity(b, physicsClientId=c)[0] for b in self._ids],
                       dtype=np.float64).reshape(self._n, 3)
        return pos, vel

    def settings(self) -> dict:
        return dict(self._p.getPhysicsEngineParameters(physicsClientId=self._client))

    def close(self) -> None:
        if self._client is not None:
            self._p.disconnect(physicsClientId=self._client)
            self._client = None
