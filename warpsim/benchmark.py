"""Benchmarks: speed against error, every figure from one run on one machine.

Run ``python -m warpsim.benchmark [--quick] [--device cpu|cuda:0] [--out PATH.json]
[--only sweep,simulator,accuracy]``. Three sections (see BENCHMARKS.md):

- ``sweep``: sphere-box sweep throughput of the Warp kernel, of :func:`warpsim.collide_boxes`
  (uploads included) and of the vectorised NumPy implementation on the same inputs, and whether
  they agree (brute force over the boxes); then brute force against the BVH broad phase for
  many boxes.
- ``simulator``: sphere-frames per second in the standard room, per kernel feature variant;
  then brute force against the BVH broad phase on the bundled ``galton`` scene.
- ``accuracy``: float32 against float64 sweeps (at the origin and 1e4 m away), simulator error
  against step size, and energy drift over a long run.

Timing: each kernel's module is built (or loaded from Warp's kernel cache) first and that time
is reported apart; then one warm-up call, then the median of several calls, each ended by
``wp.synchronize_device``. Ratios compare figures of the same run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
import warp as wp

from .collide import collide_boxes
from .device import BVH_MIN_BOXES, resolve_device, use_bvh
from .kernels.collide_kernels import collide_kernel
from .kernels.frame_kernel import frame_kernel
from .kernels.precision import precision
from .model import Spheres, kernel_arguments, put_model, to_device
from .numpy_sweep import sweep_boxes_numpy
from .obstacles import RoundedBoxes
from .scene import Scene
from .simulator import Simulator
from .swarm import Swarm

SECTIONS = ("sweep", "simulator", "accuracy")
DEFAULT_OUT = "bench-results/benchmark.json"
SEED = 20240601
DT = 1.0 / 60.0
"""Frame duration [s] of the sweep and simulator benchmarks."""

SPAWN_GAP = 1e-3
"""Gap [m] between a spawned sphere and the nearest obstacle: float32 rounding of the stored
centre must not start a sphere inside a box."""

# Sweep scene: K random boxes, one per BOX_VOLUME of space, spheres of SWEEP_RADIUS at
# SWEEP_SPEED, so that a realistic share of the rows hits something in one frame.
BOX_VOLUME = 2.0
"""Volume of the region [m^3] per random box."""
BOX_HALF = (0.1, 0.8)
"""Range of the random boxes' core half extents [m]; with BOX_VOLUME, a few per cent (K = 1)
to about 13% (K = 64) of the spheres hit a box in one frame."""
SWEEP_MARGIN = 0.5
"""Spheres start in the box region grown by this margin [m] on every side."""
SWEEP_RADIUS = (0.02, 0.1)
"""Sphere radius range [m] of the sweeps."""
SWEEP_SPEED = (5.0, 60.0)
"""Sphere speed range [m/s] of the sweeps."""
FAR_OFFSET = 1e4
"""Translation [m], added to every coordinate, of the far-from-origin accuracy case."""

# Standard room: inner 10 x 6 x 10 m, floor at y = 0, walls 0.1 m thick, 16 rounded plates.
ROOM_HALF = np.array([5.0, 3.0, 5.0])
"""Inner half size of the room [m]; its inner floor is at y = 0."""
WALL_THICKNESS = 0.1
"""[m]"""
ROOM_PLATES = 16
PLATE_ROUNDING = 0.02
"""Rounding radius [m] of the plates (their core has zero thickness)."""
ROOM_SEED = 7
SPHERE_RADIUS = 0.05
"""[m]"""
GALTON_SEED = 1
"""Emitter seed of the galton scene's swarms."""
GALTON_WARMUP_FRAMES = 60
"""Frames (0.5 s) run before the galton timings: the balls start together above the funnel
and meet the first obstacle after about 20 frames; by 60 they are among the pegs."""
ROOM_SPEEDS = (5.0, 60.0)
"""[m/s]"""
BASE_MAX_BOUNCES = 8

VARIANTS = {  # name -> (Scene keyword arguments, Simulator keyword arguments)
    "base": ({}, {}),
    "spin": ({"friction": 0.05}, {}),
    "lossy": ({"energy_retention": 0.9}, {}),
    "no-correction": ({"energy_correction": False}, {}),
    "float64": ({}, {"precision": "float64"}),
    "max_bounces=4": ({}, {"max_bounces": 4}),
    "max_bounces=16": ({}, {"max_bounces": 16}),
}

FULL = {  # sizes, timing target [s] per call, repeats, and the accuracy runs' sizes
    "sweep_n": (10_000, 100_000, 1_000_000), "sweep_k": (1, 16, 64),
    "broad_n": 100_000, "broad_k": (64, 256, 1024), "galton_n": (10_000, 100_000),
    "sim_n": (1_000, 10_000, 100_000, 1_000_000), "target_s": 0.5, "repeats": 5,
    "max_frames": 2000, "acc_sweep_n": 100_000, "acc_sweep_k": 16, "acc_sim_n": 10_000,
    "long_n": 1_000, "long_frames": 10_000}
QUICK = {
    "sweep_n": (1_000, 10_000), "sweep_k": (1, 16), "sim_n": (1_000, 10_000),
    "broad_n": 10_000, "broad_k": (64, 256, 1024), "galton_n": (10_000, 100_000),
    "target_s": 0.2, "repeats": 3, "max_frames": 1000, "acc_sweep_n": 10_000, "acc_sweep_k": 16,
    "acc_sim_n": 10_000, "long_n": 1_000, "long_frames": 1_000}
STEP_SIZES = (1 / 30, 1 / 60, 1 / 120, 1 / 240)
"""Time steps [s] of the error-against-step-size runs (1 s of simulated time each)."""


# -- timing -----------------------------------------------------------------------------------

def median_times(calls: dict, device, repeats: int, budget_s: float = 30.0) -> dict:
    """Median wall time [s] of each call, each call ended by a device sync.

    Every call runs once as a warm-up, then the calls take turns for ``repeats`` rounds, so a
    change of load on the machine hits them all alike. Fewer rounds when a round is long: at
    most ``budget_s`` [s] after the warm-ups; warm-ups longer than that are the only samples.

    Returns:
        ``{name: (median seconds, samples)}`` for ``calls = {name: call}``.
    """

    def once(call) -> float:
        start = time.perf_counter()
        call()
        wp.synchronize_device(device)
        return time.perf_counter() - start

    first = {name: once(call) for name, call in calls.items()}
    rounds = min(repeats, int(budget_s / max(sum(first.values()), 1e-9)))
    if rounds == 0:
        return {name: (t, 1) for name, t in first.items()}
    samples = {name: [] for name in calls}
    for _ in range(rounds):
        for name, call in calls.items():
            samples[name].append(once(call))
    return {name: (statistics.median(t), len(t)) for name, t in samples.items()}


def build_kernel(kernel, device) -> dict:
    """Build the kernel's module for ``device`` before any timing.

    Returns:
        ``{"seconds": wall time [s], "cached": whether Warp's kernel cache already held it}``
        (a cached module is only loaded, a fraction of a build); ``cached`` is None off the
        CPU, where the CPU build may already have made the module's cache folder.
    """
    cache = Path(wp.config.kernel_cache_dir or "")
    name = f"wp_{kernel.module.name}"

    def entries() -> set:
        return {p.name for p in cache.glob(name + "*")} if cache.is_dir() else set()

    before = entries()
    start = time.perf_counter()
    wp.load_module(kernel.module, device=device)
    seconds = time.perf_counter() - start
    new = bool(entries() - before)
    return {"seconds": seconds, "cached": (not new) if device.is_cpu else None}


# -- printing ---------------------------------------------------------------------------------

def print_table(title: str, rows: list[dict], columns: list[tuple[str, str, str]]) -> None:
    """Print ``rows`` as a text table; ``columns`` are ``(header, key, format spec)``."""
    cells = [[("-" if r.get(key) is None else format(r[key], spec)) for _, key, spec in columns]
             for r in rows]
    widths = [max([len(h)] + [len(c[i]) for c in cells]) for i, (h, _, _) in enumerate(columns)]
    print(f"\n{title}")
    print("  ".join(h.rjust(w) for (h, _, _), w in zip(columns, widths, strict=True)))
    for c in cells:
        print("  ".join(x.rjust(w) for x, w in zip(c, widths, strict=True)))
    sys.stdout.flush()


def machine(device) -> dict:
    """Where the figures come from: platform, CPU model, core count, versions, device."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")),
                       cpu)
    except OSError:
        pass
    return {"platform": platform.platform(), "python": platform.python_version(), "cpu": cpu,
            "cores": os.cpu_count(), "numpy": np.__version__, "warp": wp.__version__,
            "device": device.alias, "device_name": device.name}


# -- scenes and swarms ------------------------------------------------------------------------

def random_rotations(rng: np.random.Generator, k: int) -> np.ndarray:
    """``k`` uniformly random unit quaternions (x, y, z, w)."""
    q = rng.normal(size=(k, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def clearance(boxes: RoundedBoxes, points: np.ndarray, radius) -> np.ndarray:
    """Distance [m] from each sphere ``(points, radius)`` to the nearest box; < 0: overlap."""
    out = np.empty(len(points))
    chunk = max(1, 2_000_000 // max(len(boxes), 1))  # bounds the (chunk, K, 3) temporaries
    for s in range(0, len(points), chunk):
        out[s:s + chunk] = boxes.signed_distance(points[s:s + chunk]).min(axis=1)
    return out - radius


def spawn_clear(boxes: RoundedBoxes, n: int, low, high, radius: float,
                rng: np.random.Generator) -> np.ndarray:
    """``n`` centres [m] uniform in the box ``[low, high]``, each at least ``radius + SPAWN_GAP``
    [m] from every obstacle (``radius``: the largest sphere radius)."""
    kept, count, free = [], 0, 0.9  # free: the share of candidates kept, guessed then measured
    for _ in range(100):
        cand = rng.uniform(low, high, size=(int(1.1 * (n - count) / free) + 64, 3))
        ok = clearance(boxes, cand, radius) >= SPAWN_GAP
        free = max(float(ok.mean()), 0.01)
        cand = cand[ok][:n - count]
        kept.append(cand)
        count += len(cand)
        if count == n:
            return np.concatenate(kept)
    raise RuntimeError(f"could not place {n} spheres clear of the obstacles")


def random_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` uniformly random unit vectors, (n, 3)."""
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def sweep_boxes(k: int, rng: np.random.Generator) -> tuple[RoundedBoxes, float]:
    """``k`` random boxes, one per ``BOX_VOLUME``: a third sharp boxes, a third rounded boxes,
    a third thin rounded plates, randomly rotated. Returns the boxes and the region half size
    [m] their centres fill."""
    kind = np.arange(k) % 3
    half = rng.uniform(*BOX_HALF, size=(k, 3))
    half[kind == 2, 1] = 0.0
    radius = np.where(kind == 0, 0.0, np.where(kind == 1, rng.uniform(0.02, 0.2, k), 0.01))
    extent = 0.5 * (BOX_VOLUME * k) ** (1 / 3)
    center = rng.uniform(-extent, extent, size=(k, 3))
    return RoundedBoxes(center, half, random_rotations(rng, k), radius), extent


def sweep_inputs(n: int, k: int, seed: int = SEED):
    """A reproducible sweep batch: boxes and ``n`` spheres clear of them, moving at random.

    Returns:
        ``(boxes, position [m] (n, 3), velocity [m/s] (n, 3), radius [m] (n,))``.
    """
    rng = np.random.default_rng([seed, n, k])
    boxes, extent = sweep_boxes(k, rng)
    radius = rng.uniform(*SWEEP_RADIUS, size=n)
    reach = extent + SWEEP_MARGIN
    position = spawn_clear(boxes, n, -reach, reach, SWEEP_RADIUS[1], rng)
    velocity = random_directions(rng, n) * rng.uniform(*SWEEP_SPEED, size=(n, 1))
    return boxes, position, velocity, radius


def standard_room() -> RoundedBoxes:
    """The standard room: 6 walls around an inner 10 x 6 x 10 m space (floor at y = 0) and 16
    randomly rotated rounded plates from a fixed seed."""
    hx, hy, hz = ROOM_HALF
    w = WALL_THICKNESS / 2  # walls overlap at the edges: no gap at any corner
    center = [(0, -w, 0), (0, 2 * hy + w, 0), (-hx - w, hy, 0), (hx + w, hy, 0),
              (0, hy, -hz - w), (0, hy, hz + w)]
    half = ([(hx + 2 * w, w, hz + 2 * w)] * 2 + [(w, hy + 2 * w, hz + 2 * w)] * 2
            + [(hx + 2 * w, hy + 2 * w, w)] * 2)
    walls = RoundedBoxes(center, half)
    rng = np.random.default_rng(ROOM_SEED)
    margin = 1.5  # [m] > sqrt(2) * 1 m + rounding: the plates stay clear of the walls
    plate_center = rng.uniform((-hx + margin, margin, -hz + margin),
                               (hx - margin, 2 * hy - margin, hz - margin), size=(ROOM_PLATES, 3))
    plate_half = np.column_stack([rng.uniform(0.3, 1.0, ROOM_PLATES), np.zeros(ROOM_PLATES),
                                  rng.uniform(0.3, 1.0, ROOM_PLATES)])
    plates = RoundedBoxes(plate_center, plate_half, random_rotations(rng, ROOM_PLATES),
                          PLATE_ROUNDING)
    return RoundedBoxes.concatenate([walls, plates])


def room_swarm(boxes: RoundedBoxes, n: int, speed: float, seed: int = SEED) -> Swarm:
    """``n`` spheres of radius ``SPHERE_RADIUS`` inside the room, clear of every obstacle,
    moving at ``speed`` [m/s] in random directions."""
    rng = np.random.default_rng([seed, n, int(speed * 1000)])
    inner = ROOM_HALF - SPHERE_RADIUS - SPAWN_GAP
    low = (-inner[0], ROOM_HALF[1] - inner[1], -inner[2])
    high = (inner[0], ROOM_HALF[1] + inner[1], inner[2])
    position = spawn_clear(boxes, n, low, high, SPHERE_RADIUS, rng)
    return Swarm(position, random_directions(rng, n) * speed, SPHERE_RADIUS)


def outside_room(position: np.ndarray) -> int:
    """Centres outside the room's inner space (tunnelled) or not finite."""
    low = (-ROOM_HALF[0], 0.0, -ROOM_HALF[2])
    high = (ROOM_HALF[0], 2 * ROOM_HALF[1], ROOM_HALF[2])
    inside = np.all((position >= low) & (position <= high), axis=1)
    return int(np.count_nonzero(~inside))


def energy_above_floor(sim: Simulator, energy: np.ndarray) -> np.ndarray:
    """A per-sphere energy of ``sim`` [J] (float64, see ``Simulator.mechanical_energy``) with
    the floor (y = 0) as the reference height: positive for every sphere in the room."""
    return energy - sim.mass * (sim.energy_origin @ sim.scene.gravity)


# -- 1. sweep ---------------------------------------------------------------------------------

def device_sweep(boxes, position, velocity, radius, dt, precision_name, device,
                 bvh: bool = False):
    """Device arrays for one sweep batch, uploaded once, and the collide kernel launch over them.

    Args:
        bvh: the BVH broad phase (else brute force over the boxes).

    Returns:
        ``(launch, read)``: ``launch()`` runs the kernel; ``read()`` returns the numpy
        ``{"box": (N,), "t": (N,), "normal": (N, 3)}`` of the last launch.
    """
    p = precision(precision_name)
    n = len(position)
    kernel = collide_kernel(p.name, "bvh" if bvh else "brute")
    model = put_model(boxes, p, device, broad_phase="bvh" if bvh else "brute", dt=dt)
    out = {"box_out": wp.empty(n, dtype=wp.int32, device=device),
           "t_out": wp.empty(n, dtype=p.scalar, device=device)}
    for name in ("contact_out", "normal_out", "new_position_out", "new_velocity_out"):
        out[name] = wp.empty(n, dtype=p.vec3, device=device)
    args = kernel_arguments(
        kernel, model=model, outputs=out,
        spheres=Spheres(radius=to_device(radius, p.scalar, p, device), mass=None),
        state_in={"position": to_device(position, p.vec3, p, device),
                  "velocity": to_device(velocity, p.vec3, p, device)})
    held = (model, args)  # the arguments carry the BVH's id: its owner must live as long

    def launch() -> None:
        wp.launch(kernel, dim=n, inputs=held[1], device=device)

    def read() -> dict:
        return {"box": out["box_out"].numpy(), "t": out["t_out"].numpy(),
                "normal": out["normal_out"].numpy()}

    return launch, read


def sweep_row(n: int, k: int, cfg: dict, device) -> dict:
    """One sweep size: timings of the three implementations on the same inputs, agreement
    (brute force over the boxes: the BVH has its own table)."""
    boxes, pos, vel, rad = sweep_inputs(n, k)
    launch, read = device_sweep(boxes, pos, vel, rad, DT, "float32", device)
    times = median_times(
        {"warp": launch, "api": lambda: collide_boxes(pos, vel, rad, boxes, DT, device=device,
                                                      broad_phase="brute")},
        device, cfg["repeats"])
    (warp_s, warp_reps), (api_s, _) = times["warp"], times["api"]
    ours = read()
    ref = {}
    numpy_s, numpy_reps = median_times(
        {"numpy": lambda: ref.update(sweep_boxes_numpy(pos, vel, rad, boxes, DT,
                                                         dtype=np.float32))},
        device, cfg["repeats"])["numpy"]
    same = ours["box"] == np.asarray(ref["box"])
    both = same & (ours["box"] >= 0)
    dt_err = np.abs(ours["t"][both].astype(np.float64) - np.asarray(ref["t"])[both])
    return {"n": n, "k": k, "hit_fraction": float(np.mean(ours["box"] >= 0)),
            "warp_s": warp_s, "warp_repeats": warp_reps,
            "warp_pairs_per_s": n * k / warp_s, "warp_ns_per_sphere": warp_s / n * 1e9,
            "api_s": api_s, "api_ns_per_sphere": api_s / n * 1e9,
            "numpy_s": numpy_s, "numpy_repeats": numpy_reps,
            "numpy_pairs_per_s": n * k / numpy_s, "numpy_ns_per_sphere": numpy_s / n * 1e9,
            "numpy_over_warp": numpy_s / warp_s, "agree_fraction": float(np.mean(same)),
            "max_abs_dt": float(dt_err.max(initial=0.0))}


def broad_phase_row(n: int, k: int, cfg: dict, device) -> dict:
    """One sweep size, brute force against the BVH broad phase: kernel times, and whether the
    two give the same results bit for bit."""
    boxes, pos, vel, rad = sweep_inputs(n, k)
    runs = {bp: device_sweep(boxes, pos, vel, rad, DT, "float32", device, bvh=bp == "bvh")
            for bp in ("brute", "bvh")}
    times = median_times({bp: launch for bp, (launch, _) in runs.items()}, device,
                         cfg["repeats"])
    res = {bp: read() for bp, (_, read) in runs.items()}
    same = all(np.array_equal(res["brute"][f], res["bvh"][f]) for f in res["brute"])
    (brute_s, reps), (bvh_s, _) = times["brute"], times["bvh"]
    return {"n": n, "k": k, "hit_fraction": float(np.mean(res["bvh"]["box"] >= 0)),
            "repeats": reps, "brute_s": brute_s, "bvh_s": bvh_s,
            "brute_ns_per_sphere": brute_s / n * 1e9, "bvh_ns_per_sphere": bvh_s / n * 1e9,
            "bvh_speedup": brute_s / bvh_s, "identical": same}


def bench_sweep(cfg: dict, device) -> dict:
    """Sweep throughput: Warp kernel alone, ``collide_boxes`` end to end, NumPy; agreement.
    Then brute force against the BVH broad phase for many boxes."""
    compile_s = build_kernel(collide_kernel("float32", "brute"), device)
    compile_bvh = build_kernel(collide_kernel("float32", "bvh"), device)
    rows = [sweep_row(n, k, cfg, device) for k in cfg["sweep_k"] for n in cfg["sweep_n"]]
    print_table("Sweep throughput, float32 (one frame, dt = 1/60 s), brute force", rows, [
        ("N", "n", ",d"), ("K", "k", "d"), ("hit", "hit_fraction", ".1%"),
        ("Warp pairs/s", "warp_pairs_per_s", ".3g"), ("Warp ns/sph", "warp_ns_per_sphere", ".3g"),
        ("API ns/sph", "api_ns_per_sphere", ".3g"),
        ("NumPy pairs/s", "numpy_pairs_per_s", ".3g"),
        ("NumPy ns/sph", "numpy_ns_per_sphere", ".3g"),
        ("NumPy/Warp", "numpy_over_warp", ".1f"), ("agree", "agree_fraction", ".4%"),
        ("max|dt|", "max_abs_dt", ".2g")])
    broad = [broad_phase_row(cfg["broad_n"], k, cfg, device) for k in cfg["broad_k"]]
    print_table(f"Sweep broad phase, float32: brute force against BVH (N = {cfg['broad_n']:,}; "
                f"'auto' takes the BVH from K = {BVH_MIN_BOXES})", broad, [
                    ("N", "n", ",d"), ("K", "k", "d"), ("hit", "hit_fraction", ".1%"),
                    ("brute ns/sph", "brute_ns_per_sphere", ".3g"),
                    ("BVH ns/sph", "bvh_ns_per_sphere", ".3g"),
                    ("brute/BVH", "bvh_speedup", ".2f"), ("identical", "identical", "")])
    for name, c in (("float32", compile_s), ("float32 BVH", compile_bvh)):
        print(f"collide kernel {name} build: {c['seconds']:.2f} s"
              f"{' (loaded from the kernel cache)' if c['cached'] else ''}")
    return {"compile": {"collide float32": compile_s, "collide float32 bvh": compile_bvh},
            "rows": rows, "broad_phase": broad}


# -- 2. simulator -----------------------------------------------------------------------------

def variant_setup(name: str, boxes: RoundedBoxes):
    """The scene, Simulator keyword arguments and frame kernel of a feature variant."""
    scene_kw, sim_kw = VARIANTS[name]
    scene = Scene(boxes, **scene_kw)
    prec = sim_kw.get("precision", "float32")
    bounces = sim_kw.get("max_bounces", BASE_MAX_BOUNCES)
    kernel = frame_kernel(prec, bounces, scene.friction > 0.0, scene.energy_correction,
                          scene.energy_retention < 1.0,
                          "bvh" if use_bvh("auto", len(boxes)) else "brute")
    return scene, {"precision": prec, "max_bounces": bounces}, kernel


def frames_per_call(sim: Simulator, cfg: dict) -> int:
    """Frames that make one timed call last about ``cfg["target_s"]``, from one warm-up frame."""
    start = time.perf_counter()
    sim.step(1)
    one = time.perf_counter() - start
    return max(1, min(cfg["max_frames"], math.ceil(cfg["target_s"] / max(one, 1e-9))))


def bench_simulator(cfg: dict, device) -> dict:
    """Sphere-frames per second in the standard room, per feature variant, speed and N.

    For each speed and N the variants run the same number of frames per call and take turns,
    so their cost ratios to ``base`` come from the same stretch of time.
    """
    boxes = standard_room()
    setups = {name: variant_setup(name, boxes) for name in VARIANTS}
    compile_rows = [{"variant": name, **build_kernel(kernel, device)}
                    for name, (_, _, kernel) in setups.items()]
    rows = []
    for speed in ROOM_SPEEDS:
        for n in cfg["sim_n"]:
            swarm = room_swarm(boxes, n, speed)
            sims = {name: Simulator(scene, swarm, dt=DT, device=device, **kw)
                    for name, (scene, kw, _) in setups.items()}
            frames = frames_per_call(sims["base"], cfg)
            times = median_times({name: partial(sim.step, frames) for name, sim in sims.items()},
                                 device, cfg["repeats"])
            for name, sim in sims.items():
                seconds, reps = times[name]
                per = seconds / (frames * n)
                stats = sim.stats
                rows.append({"variant": name, "speed": speed, "n": n, "frames": frames,
                             "repeats": reps, "seconds": seconds,
                             "sphere_frames_per_s": 1.0 / per, "ns_per_sphere_frame": per * 1e9,
                             "bounces_per_sphere_frame": stats.bounces / stats.sphere_frames,
                             "capped": stats.capped,
                             "cost_vs_base": seconds / times["base"][0]})
            del sims
    rows.sort(key=lambda r: list(VARIANTS).index(r["variant"]))
    print_table(f"Simulator, standard room ({len(boxes)} boxes, r = {SPHERE_RADIUS} m, "
                f"dt = 1/60 s)", rows, [
                    ("variant", "variant", ""), ("m/s", "speed", "g"), ("N", "n", ",d"),
                    ("frames", "frames", "d"), ("sphere-frames/s", "sphere_frames_per_s", ".3g"),
                    ("ns/sph-frame", "ns_per_sphere_frame", ".3g"),
                    ("bounces/sph-frame", "bounces_per_sphere_frame", ".3f"),
                    ("capped", "capped", "d"), ("cost/base", "cost_vs_base", ".2f")])
    galton = galton_broad_phase(cfg, device)
    compile_rows += galton.pop("compile")
    print_table("Frame kernel build per variant (or load, when in Warp's kernel cache)",
                compile_rows, [("variant", "variant", ""), ("seconds", "seconds", ".2f"),
                               ("cached", "cached", "")])
    return {"boxes": len(boxes), "compile": compile_rows, "rows": rows, "galton": galton}


def galton_broad_phase(cfg: dict, device) -> dict:
    """The bundled ``galton`` scene (its own dt, settings and emitter), brute force against the
    BVH broad phase: both simulators run ``GALTON_WARMUP_FRAMES`` untimed, then take turns over
    the same frames from the same swarm, so they do the same work; their states must stay
    bit-identical."""
    scene = Scene.load("galton")
    flags = (scene.max_bounces, scene.friction > 0.0, scene.energy_correction,
             scene.energy_retention < 1.0)
    compile_rows = [{"variant": f"galton {bp}",
                     **build_kernel(frame_kernel("float32", *flags, bp), device)}
                    for bp in ("brute", "bvh")]
    rows = []
    for n in cfg["galton_n"]:
        swarm = scene.spawn(n=n, seed=GALTON_SEED)
        sims = {bp: Simulator(scene, swarm, device=device, broad_phase=bp)
                for bp in ("brute", "bvh")}
        for sim in sims.values():
            sim.step(GALTON_WARMUP_FRAMES)
        frames = frames_per_call(sims["brute"], cfg)
        sims["bvh"].step(1)
        times = median_times({bp: partial(sim.step, frames) for bp, sim in sims.items()},
                             device, cfg["repeats"])
        a, b = sims["brute"].state(), sims["bvh"].state()
        same = all(np.array_equal(getattr(a, f), getattr(b, f))
                   for f in ("position", "velocity", "energy"))
        (brute_s, reps), (bvh_s, _) = times["brute"], times["bvh"]
        stats = sims["bvh"].stats
        rows.append({"scene": "galton", "n": n, "frames": frames, "repeats": reps,
                     "sim_frames": stats.frames, "brute_s": brute_s, "bvh_s": bvh_s,
                     "brute_ns_per_sphere_frame": brute_s / (frames * n) * 1e9,
                     "bvh_ns_per_sphere_frame": bvh_s / (frames * n) * 1e9,
                     "bvh_speedup": brute_s / bvh_s,
                     "bounces_per_sphere_frame": stats.bounces / stats.sphere_frames,
                     "identical": same})
        del sims
    print_table(f"Simulator broad phase, galton scene ({len(scene.boxes)} boxes, "
                f"dt = {scene.dt:.4g} s): brute force against BVH", rows, [
                    ("N", "n", ",d"), ("frames", "frames", "d"),
                    ("brute ns/sph-frame", "brute_ns_per_sphere_frame", ".3g"),
                    ("BVH ns/sph-frame", "bvh_ns_per_sphere_frame", ".3g"),
                    ("brute/BVH", "bvh_speedup", ".2f"),
                    ("bounces/sph-frame", "bounces_per_sphere_frame", ".3f"),
                    ("identical", "identical", "")])
    return {"boxes": len(scene.boxes), "compile": compile_rows, "rows": rows}


# -- 3. accuracy ------------------------------------------------------------------------------

def sweep_accuracy(cfg: dict, device) -> dict:
    """float32 against float64 collide kernels on the same sweeps, at the origin and 1e4 m
    away; float32 and float64 throughput side by side."""
    n, k = cfg["acc_sweep_n"], cfg["acc_sweep_k"]
    boxes, pos, vel, rad = sweep_inputs(n, k, seed=SEED + 1)
    compile_s = {p: build_kernel(collide_kernel(p, "brute"), device)
                 for p in ("float32", "float64")}
    rows = []
    for offset in (0.0, FAR_OFFSET):
        moved = RoundedBoxes(boxes.center + offset, boxes.half_extents, boxes.rotation,
                             boxes.radius)
        runs = {p: device_sweep(moved, pos + offset, vel, rad, DT, p, device)
                for p in ("float32", "float64")}
        times = median_times({p: launch for p, (launch, _) in runs.items()}, device,
                             cfg["repeats"])
        secs = {p: t for p, (t, _) in times.items()}
        res = {p: read() for p, (_, read) in runs.items()}
        a, b = res["float32"], res["float64"]
        both = (a["box"] == b["box"]) & (b["box"] >= 0)
        path = np.linalg.norm(vel[both] * DT, axis=1)
        pos_err = np.abs(a["t"][both].astype(np.float64) - b["t"][both]) * path
        n32, n64 = a["normal"][both].astype(np.float64), b["normal"][both]
        angle = np.degrees(np.arctan2(np.linalg.norm(np.cross(n32, n64), axis=1),
                                      np.einsum("ij,ij->i", n32, n64)))
        rows.append({
            "offset": offset, "n": n, "k": k, "hits": int(np.count_nonzero(b["box"] >= 0)),
            "hit_miss_disagree": int(np.count_nonzero((a["box"] >= 0) != (b["box"] >= 0))),
            "box_disagree": int(np.count_nonzero(a["box"] != b["box"])),
            "max_pos_err": float(pos_err.max(initial=0.0)),
            "p99_pos_err": float(np.percentile(pos_err, 99)) if pos_err.size else 0.0,
            "max_normal_deg": float(angle.max(initial=0.0)),
            "f32_ns_per_sphere": secs["float32"] / n * 1e9,
            "f64_ns_per_sphere": secs["float64"] / n * 1e9,
            "f64_over_f32": secs["float64"] / secs["float32"]})
    print_table(f"Sweep accuracy, float32 against float64 (N = {n:,}, K = {k})", rows, [
        ("offset m", "offset", "g"), ("hits", "hits", ",d"),
        ("hit/miss diff", "hit_miss_disagree", "d"), ("box diff", "box_disagree", "d"),
        ("max |dt||d| m", "max_pos_err", ".2g"), ("p99 m", "p99_pos_err", ".2g"),
        ("max normal deg", "max_normal_deg", ".2g"),
        ("f32 ns/sph", "f32_ns_per_sphere", ".3g"), ("f64 ns/sph", "f64_ns_per_sphere", ".3g"),
        ("f64/f32", "f64_over_f32", ".2f")])
    return {"compile": compile_s, "rows": rows}


def room_check(sim: Simulator, scene: Scene, swarm: Swarm) -> dict:
    """Energy drift ``|E - E0| / E0`` and largest gain ``(E - E0) / E0`` over the spheres (energy
    above the floor), the smallest clearance [m] (< 0: a sphere inside an obstacle) and the
    tunnelled count."""
    s = sim.state()
    e0 = energy_above_floor(sim, sim.initial_energy)
    change = (energy_above_floor(sim, sim.mechanical_energy(s)) - e0) / e0
    return {"max_drift": float(np.max(np.abs(change))), "max_gain": float(np.max(change)),
            "min_clearance": float(clearance(scene.boxes, s.position.astype(np.float64),
                                             swarm.radius).min()),
            "outside": outside_room(s.position)}


def step_size_error(cfg: dict, device) -> list[dict]:
    """The standard room at 60 m/s for 1 s of simulated time, per step size, precision and
    energy correction (without it the integrator's own energy error shows)."""
    boxes = standard_room()
    swarm = room_swarm(boxes, cfg["acc_sim_n"], 60.0, seed=SEED + 2)
    rows = []
    for correction in (True, False):
        scene = Scene(boxes, energy_correction=correction)
        for prec in ("float32", "float64"):
            build_kernel(frame_kernel(prec, BASE_MAX_BOUNCES, False, correction, False,
                                      "bvh" if use_bvh("auto", len(boxes)) else "brute"),
                         device)
            for dt in STEP_SIZES:
                sim = Simulator(scene, swarm, dt=dt, max_bounces=BASE_MAX_BOUNCES,
                                device=device, precision=prec)
                sim.step(round(1.0 / dt))
                stats = sim.stats
                rows.append({"correction": correction, "precision": prec, "dt": dt,
                             "frames": stats.frames,
                             "sim_s_per_wall_s": stats.frames * dt / stats.seconds,
                             "capped": stats.capped, **room_check(sim, scene, swarm)})
    print_table(f"Step size against error: standard room, 60 m/s, 1 s simulated, "
                f"N = {len(swarm):,}", rows, [
                    ("correction", "correction", ""), ("precision", "precision", ""),
                    ("frames", "frames", "d"), ("sim s / wall s", "sim_s_per_wall_s", ".3g"),
                    ("max |E-E0|/E0", "max_drift", ".2g"), ("max gain", "max_gain", ".2g"),
                    ("min clearance m", "min_clearance", ".2g"), ("capped", "capped", "d"),
                    ("outside", "outside", "d")])
    return rows


def long_run_drift(cfg: dict, device) -> list[dict]:
    """Energy drift over a long run (dt = 1/60 s) per room speed, energy correction and
    precision; the state is checked at ten points along the run."""
    boxes = standard_room()
    n, frames = cfg["long_n"], cfg["long_frames"]
    rows = []
    for speed in ROOM_SPEEDS:
        swarm = room_swarm(boxes, n, speed, seed=SEED + 3)
        for correction in (True, False):
            scene = Scene(boxes, energy_correction=correction)
            for prec in ("float32", "float64"):
                sim = Simulator(scene, swarm, dt=DT, max_bounces=BASE_MAX_BOUNCES,
                                device=device, precision=prec)
                checks = []
                for _ in range(10):
                    sim.step(max(1, frames // 10))
                    checks.append(room_check(sim, scene, swarm))
                stats = sim.stats
                rows.append({"speed": speed, "correction": correction, "precision": prec,
                             "frames": sim.frame,
                             "max_drift": max(c["max_drift"] for c in checks),
                             "final_drift": checks[-1]["max_drift"],
                             "max_gain": max(c["max_gain"] for c in checks),
                             "min_clearance": min(c["min_clearance"] for c in checks),
                             "outside": checks[-1]["outside"],
                             "ns_per_sphere_frame": stats.seconds / stats.sphere_frames * 1e9})
    print_table(f"Long run: energy drift, N = {n:,}, dt = 1/60 s", rows, [
        ("m/s", "speed", "g"), ("correction", "correction", ""), ("precision", "precision", ""),
        ("frames", "frames", ",d"), ("max |E-E0|/E0", "max_drift", ".2g"),
        ("final", "final_drift", ".2g"), ("max gain", "max_gain", ".2g"),
        ("min clearance m", "min_clearance", ".2g"),
        ("outside", "outside", "d"), ("ns/sph-frame", "ns_per_sphere_frame", ".3g")])
    return rows


def bench_accuracy(cfg: dict, device) -> dict:
    """Speed against error: sweep precision, step size, long-run energy drift."""
    return {"sweep": sweep_accuracy(cfg, device), "step_size": step_size_error(cfg, device),
            "long_run": long_run_drift(cfg, device)}


# -- entry point ------------------------------------------------------------------------------

RUNNERS = {"sweep": bench_sweep, "simulator": bench_simulator, "accuracy": bench_accuracy}


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """The command-line options (``argv`` None: the process's own)."""
    parser = argparse.ArgumentParser(prog="python -m warpsim.benchmark",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="small sizes and short timings (noisy; for development)")
    parser.add_argument("--device", default=None,
                        help="Warp device: cpu or cuda:0 (default: Warp's, cuda:0 when present)")
    parser.add_argument("--out", default=DEFAULT_OUT, help=f"JSON results (default {DEFAULT_OUT})")
    parser.add_argument("--only", default=",".join(SECTIONS),
                        help=f"comma-separated sections among {','.join(SECTIONS)}")
    if argv and argv[0] == "--":  # as forwarded by ``warpsim bench -- --quick``
        argv = argv[1:]
    args = parser.parse_args(argv)
    args.only = [s.strip() for s in args.only.split(",") if s.strip()]
    unknown = sorted(set(args.only) - set(SECTIONS))
    if unknown or not args.only:
        parser.error(f"--only takes sections among {','.join(SECTIONS)}, got {unknown or 'none'}")
    return args


def main(argv: list[str] | None = None) -> int:
    """Run the chosen sections, print their tables and write the JSON.

    Returns:
        The exit code: 0, or 2 when the device is not available.
    """
    args = parse_args(argv)
    try:
        device = resolve_device(args.device)
    except ValueError as exc:
        print(f"benchmark: {exc}", file=sys.stderr)
        return 2
    cfg = QUICK if args.quick else FULL
    info = machine(device)
    print(f"warpsim benchmark{' (quick)' if args.quick else ''}: {info['cpu']}, "
          f"{info['cores']} cores, {info['platform']}, numpy {info['numpy']}, "
          f"warp {info['warp']}, device {info['device']} ({info['device_name']})")
    results = {"machine": info, "quick": args.quick, "settings": cfg, "sections": {}}
    start = time.perf_counter()
    for name in args.only:
        t0 = time.perf_counter()
        results["sections"][name] = RUNNERS[name](cfg, device)
        results["sections"][name]["runtime_s"] = time.perf_counter() - t0
    results["runtime_s"] = time.perf_counter() - start
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=1, default=float))
    print(f"\nruntime {results['runtime_s']:.1f} s; results written to {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
