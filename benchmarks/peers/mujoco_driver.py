"""MuJoCo, with its discrete contacts and (MuJoCo 4 on) its speculative contacts.

Set-up: one body with a free joint per sphere, the walls and plates as box geoms of the world
body (MuJoCo's quaternions are (w, x, y, z): converted). Contacts are made elastic and
frictionless as far as MuJoCo's soft-constraint model allows, with the recipe of its
speculative-contacts notes: ``condim = 1`` (frictionless), ``solref = "0 -2/dt"`` (the direct
form: no stiffness, damping 2/dt, which reverses the normal velocity in one step) and a stiff
impedance ``solimp = "0.995 0.995 0.001"``; gravity as given, ``timestep = dt``; everything
else MuJoCo's defaults (Euler integrator, Newton solver, pyramidal cone). Sphere-sphere
contacts are off (spheres: ``contype 1, conaffinity 0``; room: ``0, 1``); MuJoCo's broad phase
still sorts all sphere bodies. Speculative: ``<flag speculative="enable"/>``, contacts created
before impact from a sweep with the pre-step velocities (new in MuJoCo 4.0).

Where it differs from the workload: contacts are soft constraints solved each step (a resting
sphere sinks a little), discrete contacts miss what a step jumps over, and a sphere is a 6-DoF
body (the energy measured is the translational one).
"""

from __future__ import annotations

import numpy as np

from .workload import Workload


def speculative_available() -> bool:
    """Whether this MuJoCo has speculative contacts (4.0 on)."""
    import mujoco

    return hasattr(mujoco.mjtEnableBit, "mjENBL_SPECULATIVE")


def model_xml(work: Workload, speculative: bool) -> str:
    """The MJCF model of the workload (see the module docstring)."""
    dt = work.dt
    default = (f'<geom condim="1" solref="0 {-2.0 / dt:.17g}" solimp="0.995 0.995 0.001"/>')
    walls = "".join(
        f'<geom type="box" pos="{o.center[0]:.17g} {o.center[1]:.17g} {o.center[2]:.17g}" '
        f'size="{o.half_extents[0]:.17g} {o.half_extents[1]:.17g} {o.half_extents[2]:.17g}" '
        f'quat="{o.rotation[3]:.17g} {o.rotation[0]:.17g} {o.rotation[1]:.17g} '
        f'{o.rotation[2]:.17g}" contype="0" conaffinity="1"/>' for o in work.obstacles)
    bodies = "".join(
        f'<body pos="{p[0]:.17g} {p[1]:.17g} {p[2]:.17g}"><freejoint/>'
        f'<geom type="sphere" size="{work.radius:.17g}" mass="{work.mass:.17g}" '
        'contype="1" conaffinity="0"/></body>' for p in work.position)
    g = work.gravity
    flag = '<flag speculative="enable"/>' if speculative else ""
    return (f'<mujoco><option timestep="{dt:.17g}" gravity="{g[0]:.17g} {g[1]:.17g} '
            f'{g[2]:.17g}">{flag}</option><default>{default}</default>'
            f'<worldbody>{walls}{bodies}</worldbody></mujoco>')


class MujocoDriver:
    """MuJoCo's C engine through its Python bindings, ``mj_step`` once per frame.

    Args:
        work: the workload.
        speculative: enable speculative contacts (ValueError on a MuJoCo without them).
    """

    #: ``state()``'s velocity is semi-implicit Euler's step velocity (the mean over the last step)
    step_velocity = True

    def __init__(self, work: Workload, speculative: bool = False):
        import mujoco

        if speculative and not speculative_available():
            raise ValueError(f"MuJoCo {mujoco.__version__} has no speculative contacts "
                             "(new in 4.0)")
        self.key = "mujoco-speculative" if speculative else "mujoco"
        self.label = "MuJoCo speculative" if speculative else "MuJoCo"
        self._mj = mujoco
        self._model = mujoco.MjModel.from_xml_string(model_xml(work, speculative))
        self._data = mujoco.MjData(self._model)
        self._n = work.n
        self._velocity = np.asarray(work.velocity, dtype=np.float64)
        self.reset()

    def reset(self) -> None:
        self._mj.mj_resetData(self._model, self._data)
        self._data.qvel.reshape(self._n, 6)[:, :3] = self._velocity

    def step(self, frames: int) -> None:
        m, d, mj_step = self._model, self._data, self._mj.mj_step
        for _ in range(frames):
            mj_step(m, d)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        q = self._data.qpos.reshape(self._n, 7)
        v = self._data.qvel.reshape(self._n, 6)
        return q[:, :3].astype(np.float64), v[:, :3].astype(np.float64)

    def settings(self) -> dict:
        mj, o = self._mj, self._model.opt
        return {"version": mj.__version__, "timestep": o.timestep,
                "integrator": mj.mjtIntegrator(o.integrator).name,
                "solver": mj.mjtSolver(o.solver).name, "iterations": o.iterations,
                "ls_iterations": o.ls_iterations, "tolerance": o.tolerance,
                "cone": mj.mjtCone(o.cone).name,
                "sphere_solref": self._model.geom_solref[-1].tolist(),
                "sphere_solimp": self._model.geom_solimp[-1].tolist(),
                "sphere_condim": int(self._model.geom_condim[-1]),
                "speculative": self.key == "mujoco-speculative",
                "warnings": {mj.mjtWarning(i).name: int(w.number)
                             for i, w in enumerate(self._data.warning) if w.number}}

    def close(self) -> None:
        pass
