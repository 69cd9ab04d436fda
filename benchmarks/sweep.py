"""Sweep throughput: the collide kernel, ``warpsim.collide_boxes`` and the NumPy baseline.

Run from the repository root: ``python -m benchmarks.sweep [--quick] [--device D] [--out PATH]``.

One frame (dt = 1/60 s) of the first-contact sweep of N spheres against K random boxes, float32:
the Warp kernel alone on arrays already on the device, :func:`warpsim.collide_boxes` end to end
(validation, uploads, kernel, copy back) and :func:`benchmarks.numpy_sweep.sweep_boxes_numpy`
on the same inputs, with their agreement (brute force over the boxes). Then brute force against
the BVH broad phase for many boxes, which must agree bit for bit.
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

import warpsim as ws
from warpsim.device import BVH_MIN_BOXES
from warpsim.kernels.collide_kernels import collide_kernel
from warpsim.kernels.data import Features
from warpsim.kernels.precision import precision
from warpsim.model import (
    Spheres,
    kernel_arguments,
    put_model,
    spheres_per_task,
    task_count,
    to_device,
)

from .common import finish, median_times, parser, print_table, start
from .numpy_sweep import sweep_boxes_numpy

SEED = 20240601
DT = 1.0 / 60.0
"""Frame duration [s]."""

BOX_VOLUME = 2.0
"""Volume of the region [m^3] per random box."""
BOX_HALF = (0.1, 0.8)
"""Range of the random boxes' core half extents [m]; with BOX_VOLUME, a few per cent (K = 1)
to about 13% (K = 64) of the spheres hit a box in one frame."""
SWEEP_MARGIN = 0.5
"""Spheres start in the box region grown by this margin [m] on every side."""
SWEEP_RADIUS = (0.02, 0.1)
"""Sphere radius range [m]."""
SWEEP_SPEED = (5.0, 60.0)
"""Sphere speed range [m/s], every direction."""

FULL = {"sweep_n": (10_000, 100_000, 1_000_000), "sweep_k": (1, 16, 64),
        "broad_n": 100_000, "broad_k": (64, 256, 1024), "repeats": 5}
QUICK = {"sweep_n": (1_000, 10_000), "sweep_k": (1, 16),
         "broad_n": 10_000, "broad_k": (64, 256, 1024), "repeats": 3}


def random_rotations(rng: np.random.Generator, k: int) -> np.ndarray:
    """``k`` uniformly random unit quaternions (x, y, z, w)."""
    q = rng.normal(size=(k, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def sweep_boxes(k: int, rng: np.random.Generator) -> tuple[ws.RoundedBoxes, float]:
    """``k`` random boxes, one per ``BOX_VOLUME``: a third sharp boxes, a third rounded boxes
    (rounding 0.02 to 0.2 m), a third thin rounded plates (rounding 0.01 m), randomly rotated.
    Returns the boxes and the half size [m] of the cube their centres fill."""
    kind = np.arange(k) % 3
    half = rng.uniform(*BOX_HALF, size=(k, 3))
    half[kind == 2, 1] = 0.0
    radius = np.where(kind == 0, 0.0, np.where(kind == 1, rng.uniform(0.02, 0.2, k), 0.01))
    extent = 0.5 * (BOX_VOLUME * k) ** (1 / 3)
    center = rng.uniform(-extent, extent, size=(k, 3))
    return ws.RoundedBoxes(center, half, random_rotations(rng, k), radius), extent


def sweep_inputs(n: int, k: int, seed: int = SEED):
    """A reproducible sweep batch: ``k`` boxes and ``n`` spheres spawned clear of them by the
    package's emitter (radius and speed ranges above, every direction).

    Returns:
        ``(boxes, position [m] (n, 3), velocity [m/s] (n, 3), radius [m] (n,))``.
    """
    rng = np.random.default_rng([seed, n, k])
    boxes, extent = sweep_boxes(k, rng)
    reach = extent + SWEEP_MARGIN
    emitter = ws.Emitter(count=n, half_extents=(reach,) * 3, radius=SWEEP_RADIUS,
                         speed=SWEEP_SPEED, seed=int(rng.integers(2**31)))
    swarm = emitter.spawn(boxes)
    return boxes, swarm.position, swarm.velocity, swarm.radius


def device_sweep(boxes, position, velocity, radius, dt, precision_name, device,
                 broad_phase: str = "brute"):
    """Device arrays for one sweep batch, uploaded once, and the collide kernel launch over them.

    Args:
        broad_phase: ``"brute"`` or ``"bvh"``.

    Returns:
        ``(launch, read)``: ``launch()`` runs the kernel; ``read()`` returns the numpy
        ``{"box": (N,), "t": (N,), "normal": (N, 3)}`` of the last launch.
    """
    p = precision(precision_name)
    n = len(position)
    kernel = collide_kernel(Features(precision=p.name, broad_phase=broad_phase))
    model = put_model(boxes, p, device, broad_phase=broad_phase, dt=dt)
    out = {"box_out": wp.empty(n, dtype=wp.int32, device=device),
           "t_out": wp.empty(n, dtype=p.scalar, device=device)}
    for name in ("contact_out", "normal_out", "new_position_out", "new_velocity_out"):
        out[name] = wp.empty(n, dtype=p.vec3, device=device)
    per_task = spheres_per_task(device)
    args = kernel_arguments(
        kernel, model=model, outputs=out, values={"spheres_per_task": per_task},
        spheres=Spheres(radius=to_device(radius, p.scalar, p, device), mass=None),
        state_in={"position": to_device(position, p.vec3, p, device),
                  "velocity": to_device(velocity, p.vec3, p, device)})
    held = (model, args)  # the arguments carry the BVH's id: its owner must live as long

    def launch() -> None:
        wp.launch(kernel, dim=task_count(n, per_task), inputs=held[1], device=device)

    def read() -> dict:
        return {"box": out["box_out"].numpy(), "t": out["t_out"].numpy(),
                "normal": out["normal_out"].numpy()}

    return launch, read


def build_seconds(kernel, device) -> float:
    """Build (or load from Warp's kernel cache) a kernel's module before any timing [s]."""
    t0 = time.perf_counter()
    wp.load_module(kernel.module, device=device)
    return time.perf_counter() - t0


def sweep_row(n: int, k: int, cfg: dict, device) -> dict:
    """One size: the three implementations on the same inputs, and their agreement."""
    boxes, pos, vel, rad = sweep_inputs(n, k)
    launch, read = device_sweep(boxes, pos, vel, rad, DT, "float32", device)
    cpu = {}
    times = median_times(
        {"warp": launch, "api": lambda: ws.collide_boxes(pos, vel, rad, boxes, DT, device=device,
                                                         broad_phase="brute")},
        device, cfg["repeats"], cpu=cpu)
    (warp_s, warp_reps), (api_s, _) = times["warp"], times["api"]
    ours = read()
    ref = {}
    numpy_s, numpy_reps = median_times(
        {"numpy": lambda: ref.update(sweep_boxes_numpy(pos, vel, rad, boxes, DT,
                                                         dtype=np.float32))},
        device, cfg["repeats"], cpu=cpu)["numpy"]
    same = ours["box"] == np.asarray(ref["box"])
    both = same & (ours["box"] >= 0)
    dt_err = np.abs(ours["t"][both].astype(np.float64) - np.asarray(ref["t"])[both])
    return {"n": n, "k": k, "hit_fraction": float(np.mean(ours["box"] >= 0)),
            "warp_s": warp_s, "warp_repeats": warp_reps,
            "warp_pairs_per_s": n * k / warp_s, "warp_ns_per_sphere": warp_s / n * 1e9,
            "api_s": api_s, "api_ns_per_sphere": api_s / n * 1e9,
            "numpy_s": numpy_s, "numpy_repeats": numpy_reps,
            "numpy_pairs_per_s": n * k / numpy_s, "numpy_ns_per_sphere": numpy_s / n * 1e9,
            "numpy_over_warp": numpy_s / warp_s,
            "warp_cpu_ns_per_sphere": cpu["warp"] / n * 1e9,
            "numpy_cpu_ns_per_sphere": cpu["numpy"] / n * 1e9,
            "numpy_over_warp_cpu": cpu["numpy"] / cpu["warp"],
            "agree_fraction": float(np.mean(same)),
            "max_abs_dt": float(dt_err.max(initial=0.0))}


def broad_phase_row(n: int, k: int, cfg: dict, device) -> dict:
    """One size, brute force against the BVH: kernel times, and bit-for-bit agreement."""
    boxes, pos, vel, rad = sweep_inputs(n, k)
    runs = {bp: device_sweep(boxes, pos, vel, rad, DT, "float32", device, broad_phase=bp)
            for bp in ("brute", "bvh")}
    cpu = {}
    times = median_times({bp: launch for bp, (launch, _) in runs.items()}, device,
                         cfg["repeats"], cpu=cpu)
    res = {bp: read() for bp, (_, read) in runs.items()}
    same = all(np.array_equal(res["brute"][f], res["bvh"][f]) for f in res["brute"])
    (brute_s, reps), (bvh_s, _) = times["brute"], times["bvh"]
    return {"n": n, "k": k, "hit_fraction": float(np.mean(res["bvh"]["box"] >= 0)),
            "repeats": reps, "brute_s": brute_s, "bvh_s": bvh_s,
            "brute_ns_per_sphere": brute_s / n * 1e9, "bvh_ns_per_sphere": bvh_s / n * 1e9,
            "bvh_speedup": brute_s / bvh_s, "brute_cpu_ns_per_sphere": cpu["brute"] / n * 1e9,
            "bvh_cpu_ns_per_sphere": cpu["bvh"] / n * 1e9,
            "bvh_speedup_cpu": cpu["brute"] / cpu["bvh"], "identical": same}


def run(cfg: dict, device) -> dict:
    """Both tables; returns their rows and the kernels' build times."""
    build = {f"collide float32 {bp}": build_seconds(collide_kernel(Features(broad_phase=bp)),
                                                    device)
             for bp in ("brute", "bvh")}
    rows = [sweep_row(n, k, cfg, device) for k in cfg["sweep_k"] for n in cfg["sweep_n"]]
    print_table("Sweep throughput, float32 (one frame, dt = 1/60 s), brute force", rows, [
        ("N", "n", ",d"), ("K", "k", "d"), ("hit", "hit_fraction", ".1%"),
        ("Warp pairs/s", "warp_pairs_per_s", ".3g"), ("Warp ns/sph", "warp_ns_per_sphere", ".3g"),
        ("API ns/sph", "api_ns_per_sphere", ".3g"),
        ("NumPy pairs/s", "numpy_pairs_per_s", ".3g"),
        ("NumPy ns/sph", "numpy_ns_per_sphere", ".3g"),
        ("NumPy/Warp", "numpy_over_warp", ".1f"),
        ("Warp CPU ns/sph", "warp_cpu_ns_per_sphere", ".3g"),
        ("NumPy CPU ns/sph", "numpy_cpu_ns_per_sphere", ".3g"),
        ("NumPy/Warp CPU", "numpy_over_warp_cpu", ".1f"), ("agree", "agree_fraction", ".4%"),
        ("max|dt|", "max_abs_dt", ".2g")])
    broad = [broad_phase_row(cfg["broad_n"], k, cfg, device) for k in cfg["broad_k"]]
    print_table(f"Sweep broad phase, float32: brute force against BVH (N = {cfg['broad_n']:,}; "
                f"without a grid, the BVH from K = {BVH_MIN_BOXES})", broad, [
                    ("N", "n", ",d"), ("K", "k", "d"), ("hit", "hit_fraction", ".1%"),
                    ("brute ns/sph", "brute_ns_per_sphere", ".3g"),
                    ("BVH ns/sph", "bvh_ns_per_sphere", ".3g"),
                    ("brute/BVH", "bvh_speedup", ".2f"),
                    ("brute CPU ns/sph", "brute_cpu_ns_per_sphere", ".3g"),
                    ("BVH CPU ns/sph", "bvh_cpu_ns_per_sphere", ".3g"),
                    ("brute/BVH CPU", "bvh_speedup_cpu", ".2f"), ("identical", "identical", "")])
    for name, seconds in build.items():
        print(f"{name} kernel build (or load from the kernel cache): {seconds:.2f} s")
    return {"build_s": build, "rows": rows, "broad_phase": broad}


def main(argv: list[str] | None = None) -> int:
    args = parser("python -m benchmarks.sweep", __doc__).parse_args(argv)
    started = time.perf_counter()
    device, info, out = start("sweep", args)
    cfg = QUICK if args.quick else FULL
    results = {"machine": info, "quick": args.quick, "settings": cfg, **run(cfg, device)}
    finish(out, results, started)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
