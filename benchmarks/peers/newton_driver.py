"""Newton (NVIDIA's Warp-based engine): particles against static shapes, on its CPU device.

Set-up: one Newton particle per sphere (radius and mass as given), the walls and plates as
static box shapes (``body = -1``; Newton's ``wp.quat`` is (x, y, z, w), as warpsim's), y up,
gravity as given, ``SolverXPBD`` with ``enable_restitution=True`` (its particle-shape contacts
take a restitution, the semi-implicit solver's only penalty springs), restitution 1 and
friction 0 (``soft_contact_mu`` and every shape's ``mu``), one solver step of ``dt`` per frame
after ``CollisionPipeline.collide`` on the frame's start state. Particle-particle contacts are
off (no hash grid, ``particle_max_radius = 0``). Two settings of the particle-shape contact
gap (the distance, added to the radius, within which ``collide`` reports a contact):

- ``Newton XPBD``: Newton's default gap, 0.01 m;
- ``Newton XPBD speculative``: a gap of the farthest a sphere moves in one step,
  ``(speed + |g| dt) dt``, so every contact the step can reach is known before it (the
  speculative-contact idea; XPBD then projects the sphere onto the contact plane).

Where it differs from the workload: XPBD's contacts are position projections against the
contact plane found at the step's start (not a sweep), and its restitution only acts on
contacts the sphere already touched at the step's start. Warp CPU kernels run on one core.
"""

from __future__ import annotations

import numpy as np

from .workload import Workload

DEFAULT_GAP = 0.01
"""Newton's default particle-shape contact gap [m] (``CollisionPipeline``'s
``soft_contact_gap``)."""


def speculative_gap(work: Workload) -> float:
    """The farthest [m] a sphere of the workload moves in one step: ``(speed + |g| dt) dt``."""
    return (work.speed + float(np.linalg.norm(work.gravity)) * work.dt) * work.dt


class NewtonDriver:
    """Newton particles with ``SolverXPBD`` on ``cpu``.

    Args:
        work: the workload.
        speculative: use :func:`speculative_gap` as the contact gap instead of
            ``DEFAULT_GAP``.
    """

    #: ``state()``'s velocity is semi-implicit Euler's step velocity (the mean over the last step)
    step_velocity = True

    def __init__(self, work: Workload, speculative: bool = False):
        import newton
        import warp as wp

        self.key = "newton-xpbd-speculative" if speculative else "newton-xpbd"
        self.label = "Newton XPBD speculative" if speculative else "Newton XPBD"
        self._wp = wp
        self._work = work
        self._gap = speculative_gap(work) if speculative else DEFAULT_GAP
        builder = newton.ModelBuilder(up_axis=newton.Axis.Y, gravity=tuple(work.gravity))
        cfg = newton.ModelBuilder.ShapeConfig(mu=0.0, restitution=1.0,
                                              has_shape_collision=False)
        for o in work.obstacles:
            builder.add_shape_box(-1, xform=wp.transform(wp.vec3(*o.center), wp.quat(*o.rotation)),
                                  hx=o.half_extents[0], hy=o.half_extents[1],
                                  hz=o.half_extents[2], cfg=cfg)
        builder.add_particles(pos=[wp.vec3(*p) for p in work.position],
                              vel=[wp.vec3(*v) for v in work.velocity],
                              mass=[work.mass] * work.n, radius=[work.radius] * work.n)
        model = builder.finalize(device="cpu")
        model.particle_grid = None          # no particle-particle contacts
        model.particle_max_radius = 0.0
        model.soft_contact_mu = 0.0
        model.soft_contact_restitution = 1.0
        self._model = model
        self._solver = newton.solvers.SolverXPBD(model, enable_restitution=True)
        self._pipeline = newton.CollisionPipeline(model, soft_contact_gap=self._gap)
        self._contacts = self._pipeline.contacts()
        self._control = model.control()
        self._states = [model.state(), model.state()]
        self._q0 = wp.clone(self._states[0].particle_q)
        self._qd0 = wp.clone(self._states[0].particle_qd)
        self.step(1)        # compiles Newton's kernels (or loads them from Warp's cache)
        self.reset()

    def reset(self) -> None:
        s = self._states[0]
        s.particle_q.assign(self._q0)
        s.particle_qd.assign(self._qd0)

    def step(self, frames: int) -> None:
        s0, s1 = self._states
        dt = self._work.dt
        for _ in range(frames):
            self._pipeline.collide(s0, self._contacts)
            s0.clear_forces()
            self._solver.step(s0, s1, self._control, self._contacts, dt)
            s0, s1 = s1, s0
        self._states = [s0, s1]
        self._wp.synchronize_device("cpu")

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        s = self._states[0]
        return (s.particle_q.numpy().astype(np.float64),
                s.particle_qd.numpy().astype(np.float64))

    def settings(self) -> dict:
        import newton

        return {"version": newton.__version__, "solver": "SolverXPBD",
                "iterations": self._solver.iterations, "enable_restitution": True,
                "soft_contact_gap": self._gap, "soft_contact_restitution": 1.0,
                "soft_contact_mu": 0.0, "device": "cpu",
                "soft_contact_max": int(self._contacts.soft_contact_max)}

    def close(self) -> None:
        pass
