"""The floor of the frame loop: what warpsim spends per sphere-frame beyond the physics.

Run from the repository root:
``python -m benchmarks.frame_floor [--quick] [--repeats R] [--out PATH]``.

Free flight, one core: the standard room's swarm (its emitter, ``workers=1``) in a scene whose
only box lies 10 km away, so no sphere ever reaches it, against a bare Warp kernel that does the
same gravity step and one plane test with the state in registers (the floor any frame loop
stands on). Between the two, kernels built here from the package's own ``@wp.func`` s add one
part of the frame at a time, so the table attributes the cost:

- ``bare``: ``x += (v + g dt / 2) dt``, ``v += g dt``, one plane test; the state in registers;
- ``+ candidate loop``: the bare step plus the broad phase's lookup of the frame's path over the
  boxes (``nearest.model_nearest_hit``; nothing is hit);
- ``+ energy reset``: the bare step plus ``dynamics.energy_along_gravity`` every frame (the
  linear model's default reset, which the frame kernel runs after every move with a box in
  reach, and in a run of free frames once in ``FREE_RESET_EVERY`` frames);
- ``warpsim``: ``Simulator.step(F)``, the frame kernel itself (the reset, the counters, the
  recording branches, the state written once);
- ``warpsim, reset and test every frame``: the same with the kernel whose runs of free frames
  reset the energy and test the bounds every frame (``Features.free_reset_every = 1``,
  ``free_horizon = False``: the arithmetic of the second round, measured in the same run);
- ``warpsim, standard room``: the same swarm among the standard room's 22 boxes, for scale.

Both precisions and both motion models (the partial loops are the same for both; the
ballistic kernel has no energy reset by default). Every row is the best of ``R`` turns of
``time.thread_time`` around one launch of ``F`` frames (with ``workers=1`` the CPU launch runs
on the launching thread), the kernels taking turns so that the machine's load falls on all
alike; the ratio column is against ``bare`` of the same precision and motion.
"""

import time

import numpy as np
import warp as wp

import warpsim as ws
from warpsim.kernels import precision as fp
from warpsim.kernels.data import model_structs
from warpsim.kernels.dynamics import dynamics_funcs
from warpsim.kernels.frame_kernel import frame_kernel
from warpsim.kernels.nearest import model_nearest_hit
from warpsim.kernels.variant import variant_kernel

from .common import ROOM, finish, parser, print_table, start

SEED = 20240601
FAR = 1.0e4
"""Distance [m] of the free-flight scene's only box from the room's centre."""
FLOOR = -1.0e5
"""Height [m] of the bare kernel's plane: below anything a sphere reaches, so the test is
always made and never taken (as the free-flight scene's box)."""


def far_scene(room: ws.Scene) -> ws.Scene:
    """The room's gravity, emitter and time step, with one box ``FAR`` away instead of its
    22."""
    far = ws.RoundedBoxes(center=[[FAR, 0.0, 0.0]], half_extents=[[1.0, 1.0, 1.0]],
                          radius=[0.05])
    return ws.Scene(far, gravity=room.gravity, emitter=room.emitter, dt=room.dt,
                    name="free-flight")


def part_kernels(sim: ws.Simulator) -> dict:
    """The bare loop and the partial frame loops, for ``sim``'s precision and broad phase, each
    ``kernel(model structs, radius, mass, frames, state in, state out)``: the same step, plus
    one part of the frame each."""
    p = fp.precision(sim.precision)
    scalar, vec3 = p.scalar, p.vec3
    Boxes, BroadPhase, Physics, _ = model_structs(p)
    nearest_hit = model_nearest_hit(p, sim.broad_phase)
    energy_along_gravity = dynamics_funcs(p).energy_along_gravity
    HALF = scalar(0.5)
    FLOOR_AT = scalar(FLOOR)

    def part(kind: str):
        """One partial loop: ``"bare"``, ``"lookup"`` (+ the candidate loop) or ``"reset"`` (+
        the energy reset)."""

        @variant_kernel
        def loop(boxes: Boxes, broad: BroadPhase, physics: Physics, radius: wp.array[scalar],
                 mass: wp.array[scalar], frames: int, position_in: wp.array[vec3],
                 velocity_in: wp.array[vec3], energy_in: wp.array[scalar],
                 position_out: wp.array[vec3], velocity_out: wp.array[vec3],
                 energy_out: wp.array[scalar]):
            i = wp.tid()
            x = position_in[i]
            v = velocity_in[i]
            energy = energy_in[i]
            r = radius[i]
            m = mass[i]
            g = physics.gravity
            dt = physics.dt
            hits = wp.int32(0)
            for _f in range(frames):
                d = dt * (v + (HALF * dt) * g)
                if wp.static(kind == "lookup"):
                    box, t, n = nearest_hit(x, d, r, -1, boxes, broad)
                    if box >= 0:
                        hits += 1
                x = x + d
                v = v + dt * g
                if wp.static(kind == "reset"):
                    v = energy_along_gravity(v, energy, m, g, x, physics.origin, 1)
                if wp.static(kind == "bare"):
                    if x[1] < FLOOR_AT:  # counted, the state untouched (as the lookup's hit)
                        hits += 1
            position_out[i] = x
            velocity_out[i] = v
            energy_out[i] = scalar(hits)

        return loop

    return {"bare": part("bare"), "+ candidate loop": part("lookup"),
            "+ energy reset": part("reset")}


def with_features(sim: ws.Simulator, **changes) -> ws.Simulator:
    """``sim`` running the frame kernel built with ``changes`` to its features."""
    sim._features = sim._features.but(**changes)
    sim._kernel = frame_kernel(sim._features)
    return sim


def part_call(sim: ws.Simulator, kernel, frames: int, out=None):
    """A call launching ``kernel`` over ``sim``'s swarm for ``frames`` frames, its state
    written into ``out`` (a state like ``sim.state_0``; by default a new one)."""
    if out is None:
        out = sim.state_0.empty_like()
    args = [sim.model.boxes, sim.model.broad, sim.model.physics, sim.spheres.radius,
            sim.spheres.mass, frames, sim.state_0.position, sim.state_0.velocity,
            sim.state_0.energy, out.position, out.velocity, out.energy]

    def call():
        wp.launch(kernel, dim=len(sim), device=sim.device, inputs=args)

    return call


def best_times(calls: dict, repeats: int) -> dict:
    """Best ``time.thread_time`` [s] of each call over ``repeats`` turns (a warm-up first)."""
    for call in calls.values():
        call()
    best = {name: float("inf") for name in calls}
    for _ in range(repeats):
        for name, call in calls.items():
            t0 = time.thread_time()
            call()
            best[name] = min(best[name], time.thread_time() - t0)
    return best


def case_rows(precision: str, motion: str, n: int, frames: int, repeats: int) -> list[dict]:
    room = ws.Scene.load(ROOM)
    swarm = room.spawn(n=n, seed=SEED)
    far = far_scene(room)
    import warnings

    with warnings.catch_warnings():  # float32 far from the origin: the box only, never reached
        warnings.simplefilter("ignore", ws.PrecisionWarning)
        sim = ws.Simulator(far, swarm, precision=precision, motion=motion, workers=1,
                           device="cpu")
        every_frame = with_features(
            ws.Simulator(far, swarm, precision=precision, motion=motion, workers=1,
                         device="cpu"), free_reset_every=1, free_horizon=False)
    room_sim = ws.Simulator(room, swarm, precision=precision, motion=motion, workers=1,
                            device="cpu")
    for s in (sim, every_frame, room_sim):
        s.build()
    kernels = part_kernels(sim)
    calls = {name: part_call(sim, kernel, frames) for name, kernel in kernels.items()}
    calls["warpsim"] = lambda: sim.step(frames)
    calls["warpsim, reset and test every frame"] = lambda: every_frame.step(frames)
    calls["warpsim, standard room"] = lambda: room_sim.step(frames)
    best = best_times(calls, repeats)
    ns = {name: t / (n * frames) * 1e9 for name, t in best.items()}
    return [{"precision": precision, "motion": motion, "loop": name, "ns": value,
             "ratio": value / ns["bare"], "broad_phase": (room_sim.broad_phase
                                                          if "room" in name
                                                          else sim.broad_phase)}
            for name, value in ns.items()]


def main(argv=None) -> None:
    p = parser("frame_floor", __doc__)
    p.add_argument("--repeats", type=int, default=None, help="turns per loop (default 7)")
    p.add_argument("--cases", default=None,
                   help="comma-separated PRECISION/MOTION pairs (default: all four)")
    args = p.parse_args(argv)
    started = time.perf_counter()
    _, info, out = start("frame_floor", args)
    n, frames = (5_000, 60) if args.quick else (20_000, 240)
    repeats = args.repeats or (3 if args.quick else 7)
    cases = ([(prec, motion) for motion in ("linear", "ballistic")
              for prec in ("float32", "float64")] if args.cases is None
             else [tuple(c.split("/")) for c in args.cases.split(",")])
    rows = []
    for prec, motion in cases:
        rows += case_rows(prec, motion, n, frames, repeats)
    print_table(f"Free flight (one box {FAR:g} m away), the standard room's swarm, N = {n:,}, "
                f"F = {frames}, one core, best of {repeats}: ns per sphere-frame",
                rows, [("precision", "precision", "s"), ("motion", "motion", "s"),
                       ("loop", "loop", "s"), ("broad phase", "broad_phase", "s"),
                       ("ns", "ns", ".2f"), ("x bare", "ratio", ".2f")])
    finish(out, {"machine": info, "spheres": n, "frames": frames, "repeats": repeats,
                 "rows": rows}, started)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
