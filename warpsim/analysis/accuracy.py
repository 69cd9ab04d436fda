"""The speed-against-error study of one scene: ``warpsim accuracy SCENE``.

Every setting simulates the same swarm for the same simulated time and is measured against the
exact reference (:mod:`warpsim.analysis.reference`) with
:func:`warpsim.analysis.error_report.measure`. The settings come in families, one curve each:

- ``linear float32`` / ``linear float64``: the step ``dt`` from 1/30 s to 1/960 s;
- ``no correction float32`` / ``no correction float64``: the same without the energy reset;
- ``max_bounces float32``: the bounce cap from 1 to 32 at dt = 1/60 s;
- ``ballistic float32`` / ``ballistic float64``: the exact-arc motion model over ``dt``.

The error of a setting is the mean over the swarm of the position error at the error horizon
(0.5 s by default; positions diverge exponentially later, see the error report). The mean, not
the median: the reference starts every run from its own velocity at time 0, so a sphere that
has not touched anything yet has no error but rounding, and the error is the contacts'. The
study also keeps the median and 90th percentile, the first-contact errors, the time to 1 mm
divergence, and the invariants.
Speed is timed apart on a larger swarm (``--speed-n``) for the same simulated time, after a
build and a warm-up frame, the best of ``TIMING_REPEATS`` runs: sphere-frames per second, and
simulated sphere-seconds per wall second (sphere-frames per second times ``dt``: what it costs
to simulate one second), the x axis of the Pareto plot. The convergence order of each ``dt``
family is the least-squares slope of ``log(error)`` against ``log(dt)``.

Writes ``DIR/accuracy.json``, the table ``DIR/accuracy.md`` and, with matplotlib (the
``plots`` extra), ``DIR/pareto.png`` and ``DIR/convergence.png``; every file is written
atomically.
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time
from dataclasses import dataclass

import numpy as np

from ..energy import lowest_potential
from ..export.files import atomic_output, write_bytes, write_json
from ..machine import machine
from . import error_report
from .reference import simulate

#: Frame rates [1/s] of the full study: dt from 1/30 s to 1/960 s.
RATES = (30, 60, 120, 240, 480, 960)
#: ... and of ``--quick``.
QUICK_RATES = (30, 60, 120, 240)

#: Bounce caps of the ``max_bounces`` family (at ``BOUNCES_RATE``).
BOUNCES = (1, 2, 4, 8, 16, 32)
QUICK_BOUNCES = (1, 2, 8, 32)
BOUNCES_RATE = 60

FAMILIES = ("linear", "no-correction", "bounces", "ballistic")
PRECISIONS = ("float32", "float64")

#: Defaults of the full study and of ``--quick``: spheres measured, simulated time [s], the
#: error horizon [s], and spheres timed.
FULL = {"n": 256, "horizon": 1.0, "error_horizon": 0.5, "speed_n": 8192}
QUICK = {"n": 64, "horizon": 0.5, "error_horizon": 0.5, "speed_n": 2048}

#: Errors below this [m] are float rounding, not discretisation: left out of the order fit.
ORDER_FIT_FLOOR = 1e-12

#: Errors below this [m] are drawn at it (an exact zero has no place on a log axis).
PLOT_FLOOR = 1e-16

PLOTS_MISSING = 'matplotlib is needed for plots: pip install "warpsim[plots]" (or pass --no-plots)'


@dataclass
class Setting:
    """One point of the study."""

    family: str
    precision: str
    rate: int
    max_bounces: int
    energy_correction: bool
    motion: str

    @property
    def dt(self) -> float:
        return 1.0 / self.rate

    def label(self) -> str:
        return f"{self.family} {self.precision}"


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        prog="warpsim accuracy",
        description="Speed against error of one scene: dt, precision, max_bounces, energy "
                    "correction and motion model, measured against the exact reference.")
    p.add_argument("scene", metavar="SCENE", help="bundled scene name or path to a .toml file")
    p.add_argument("-n", type=int, default=None,
                   help=f"spheres measured against the reference (default {FULL['n']}, "
                        f"--quick {QUICK['n']})")
    p.add_argument("--quick", action="store_true",
                   help="a smaller study (fewer steps, spheres and caps; about a minute)")
    p.add_argument("--out", default="accuracy-results", metavar="DIR",
                   help="output folder for accuracy.json and the plots")
    p.add_argument("--device", default=None, help="Warp device (default: Warp's default)")
    p.add_argument("--seed", type=int, default=0, help="seed of the swarm")
    p.add_argument("--horizon", type=float, default=None,
                   help="simulated time per setting [s] (default 1, --quick 0.5)")
    p.add_argument("--error-horizon", type=float, default=None,
                   help="time of the position error plotted [s] (default 0.5)")
    p.add_argument("--rates", default=None,
                   help="frame rates 1/dt, comma separated (default 30,...,960)")
    p.add_argument("--bounces", default=None,
                   help="max_bounces values of the bounces family, comma separated")
    p.add_argument("--precisions", default=",".join(PRECISIONS),
                   help="float32,float64 or one of them")
    p.add_argument("--families", default=",".join(FAMILIES),
                   help=f"families to run, comma separated, of {','.join(FAMILIES)}")
    p.add_argument("--speed-n", type=int, default=None,
                   help="spheres of the timing runs (default 8192, --quick 2048)")
    p.add_argument("--no-plots", action="store_true", help="write the JSON only")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Run the study; returns the exit status (errors are one line on standard error)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = parse_args(argv)
        config = _config(args)
        config["argv"] = argv
        return _run(config)
    except (ValueError, OSError) as exc:
        print(f"warpsim accuracy: error: {exc}", file=sys.stderr)
        return 2


def _ints(name: str, text: str | None, default) -> tuple[int, ...]:
    if text is None:
        return tuple(default)
    try:
        values = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError as exc:
        raise ValueError(f"--{name} must be integers separated by commas, got {text!r}") from exc
    if not values or min(values) < 1:
        raise ValueError(f"--{name} must be integers >= 1, got {text!r}")
    return values


def _names(name: str, text: str, allowed) -> tuple[str, ...]:
    values = tuple(x.strip() for x in text.split(",") if x.strip())
    for v in values:
        if v not in allowed:
            raise ValueError(f"--{name}: unknown {v!r}; choose from {', '.join(allowed)}")
    if not values:
        raise ValueError(f"--{name} is empty")
    return values


def _config(args) -> dict:
    """Everything checked before the first simulation: scene, numbers, output, plotting."""
    from ..scene import Scene

    base = QUICK if args.quick else FULL
    scene = Scene.load(args.scene)
    n = base["n"] if args.n is None else args.n
    if n < 1:
        raise ValueError(f"-n must be >= 1, got {n}")
    horizon = base["horizon"] if args.horizon is None else args.horizon
    if not np.isfinite(horizon) or horizon <= 0:
        raise ValueError(f"--horizon must be > 0, got {horizon}")
    err_h = min(base["error_horizon"], horizon) if args.error_horizon is None \
        else args.error_horizon
    if not 0 < err_h <= horizon:
        raise ValueError(f"--error-horizon must be in (0, horizon = {horizon:g}], got {err_h}")
    speed_n = base["speed_n"] if args.speed_n is None else args.speed_n
    if speed_n < 1:
        raise ValueError(f"--speed-n must be >= 1, got {speed_n}")
    rates = _ints("rates", args.rates, QUICK_RATES if args.quick else RATES)
    bounces = _ints("bounces", args.bounces, QUICK_BOUNCES if args.quick else BOUNCES)
    precisions = _names("precisions", args.precisions, PRECISIONS)
    families = _names("families", args.families, FAMILIES)
    plots = not args.no_plots
    if plots:
        try:
            import matplotlib  # noqa: F401
        except ImportError as exc:
            raise ValueError(PLOTS_MISSING) from exc
    os.makedirs(args.out, exist_ok=True)
    if not os.access(args.out, os.W_OK):
        raise ValueError(f"--out {args.out!r} is not writable")
    return {"scene": scene, "scene_arg": args.scene, "n": n, "seed": args.seed,
            "horizon": horizon, "error_horizon": err_h, "speed_n": speed_n, "rates": rates,
            "bounces": bounces, "precisions": precisions, "families": families,
            "plots": plots, "out": args.out, "device": args.device, "quick": args.quick}


def settings_of(config: dict, scene) -> list[Setting]:
    """The study's settings, family by family."""
    out = []
    mb, ec = scene.max_bounces, scene.energy_correction
    for fam in config["families"]:
        for prec in config["precisions"]:
            if fam == "linear":
                out += [Setting("linear", prec, r, mb, ec, "linear") for r in config["rates"]]
            elif fam == "no-correction":
                out += [Setting("no correction" if ec else "correction", prec, r, mb, not ec,
                                "linear") for r in config["rates"]]
            elif fam == "bounces" and prec == config["precisions"][0]:
                out += [Setting("max_bounces", prec, BOUNCES_RATE, b, ec, "linear")
                        for b in config["bounces"]]
            elif fam == "ballistic":
                out += [Setting("ballistic", prec, r, mb, False, "ballistic")
                        for r in config["rates"]]
    return out


def _scene_with(scene, energy_correction: bool):
    if scene.energy_correction == energy_correction:
        return scene
    variant = copy.copy(scene)
    variant.energy_correction = energy_correction
    return variant


def _simulator(scene, swarm, s: Setting, device):
    """The simulator of a setting."""
    from ..simulator import Simulator

    return Simulator(_scene_with(scene, s.energy_correction), swarm, dt=s.dt,
                     max_bounces=s.max_bounces, device=device, precision=s.precision,
                     motion=s.motion)


def _run(config: dict) -> int:
    scene = config["scene"]
    swarm = scene.spawn(n=config["n"], seed=config["seed"])
    timing_swarm = scene.spawn(n=config["speed_n"], seed=config["seed"] + 1)
    g = np.asarray(scene.gravity, dtype=np.float64)
    lowest = lowest_potential(scene.gravity, scene.boxes, swarm.position)
    settings = settings_of(config, scene)
    notes: list[str] = []
    rows: list[dict] = []
    references: dict = {}
    started = time.perf_counter()
    ref_seconds = 0.0
    device_used = str(config["device"])
    print(f"accuracy study: scene {scene.name!r}, {len(swarm)} spheres measured over "
          f"{config['horizon']:g} s, {len(settings)} settings", file=sys.stderr)
    for s in settings:
        sim = _simulator(scene, swarm, s, config["device"])
        frames = max(1, round(config["horizon"] / s.dt))
        times = np.arange(frames + 1) * s.dt
        key = s.rate  # every model starts from the swarm's velocity: one reference per dt
        if key not in references:
            t0 = time.perf_counter()
            references[key] = simulate(scene, swarm, float(times[-1]), times)
            ref_seconds += time.perf_counter() - t0
        ref = references[key]
        sim.build()
        device_used = str(sim.device)
        position, velocity = error_report.record_every_frame(sim, frames)
        figures = error_report.measure(position, velocity, times, s.dt, g, s.motion, ref,
                                       lowest=lowest)
        invariants = error_report.run_invariants(sim, _scene_with(scene, s.energy_correction),
                                                 swarm)
        err = np.linalg.norm(position - ref.position, axis=2)[:, ~ref.incomplete]
        j = int(round(config["error_horizon"] / s.dt))
        speed = _time(scene, timing_swarm, s, config["device"], frames)
        row = {"family": s.family, "label": s.label(), "precision": s.precision,
               "dt": s.dt, "rate": s.rate, "max_bounces": s.max_bounces,
               "energy_correction": s.energy_correction, "motion": s.motion, "frames": frames,
               "error_m": float(np.mean(err[j])), "error_median_m": float(np.median(err[j])),
               "error_p90_m": float(np.percentile(err[j], 90)),
               "error_time_s": float(times[j]), **speed, **figures, "invariants": invariants}
        rows.append(row)
        print(f"  {s.label():28s} dt=1/{s.rate:<4d} max_bounces={s.max_bounces:<3d} "
              f"error {row['error_m']:.3g} m  {speed['sphere_frames_per_s']:.3g} "
              f"sphere-frames/s", file=sys.stderr)
    families = _orders(rows)
    result = {
        "scene": scene.name, "scene_argument": config["scene_arg"], "spheres": len(swarm),
        "seed": config["seed"], "horizon_s": config["horizon"],
        "error_horizon_s": config["error_horizon"], "timing_spheres": len(timing_swarm),
        "quick": config["quick"], "machine": _machine(device_used),
        "command": "warpsim accuracy " + " ".join(config.get("argv", [])),
        "reference": {"seconds": ref_seconds, "runs": len(references),
                      "incomplete": int(sum(r.incomplete.sum() for r in references.values())),
                      "bounces": int(sum(len(r.events.bounces())
                                         for r in references.values()))},
        "families": families, "settings": rows, "notes": notes,
        "seconds": time.perf_counter() - started}
    out = config["out"]
    write_json(os.path.join(out, "accuracy.json"), error_report._plain(result))
    write_bytes(os.path.join(out, "accuracy.md"), markdown(result).encode())
    written = [os.path.join(out, "accuracy.json"), os.path.join(out, "accuracy.md")]
    if config["plots"]:
        written += plot(result, out)
    _print_summary(result)
    for path in written:
        print(f"wrote {path}")
    return 0


#: Timing runs per setting; the fastest counts (the others were slowed by the machine).
TIMING_REPEATS = 3


def _time(scene, swarm, s: Setting, device, frames: int) -> dict:
    """Sphere-frames per second of ``frames`` frames (the best of ``TIMING_REPEATS``), after a
    build and one warm-up frame."""
    sim = _simulator(scene, swarm, s, device)
    sim.build()
    sim.step(1)
    best = float("inf")
    for _ in range(TIMING_REPEATS):
        before = sim.stats.seconds
        sim.step(frames)
        best = min(best, sim.stats.seconds - before)
    rate = frames * len(swarm) / best if best > 0 else float("nan")
    return {"sphere_frames_per_s": rate, "sphere_seconds_per_s": rate * s.dt,
            "ns_per_sphere_frame": 1e9 / rate if rate > 0 else None}


def _orders(rows: list[dict]) -> dict:
    """Per family: its points and, for a dt family, the fitted convergence order."""
    out: dict = {}
    for row in rows:
        fam = out.setdefault(row["label"], {"family": row["family"], "points": 0})
        fam["points"] += 1
    for label, fam in out.items():
        pts = [r for r in rows if r["label"] == label]
        if fam["family"] == "max_bounces" or len(pts) < 2:
            fam["order"] = None
            continue
        dt = np.array([r["dt"] for r in pts])
        err = np.array([r["error_m"] for r in pts])
        use = err > ORDER_FIT_FLOOR
        if use.sum() >= 2 and np.ptp(np.log(dt[use])) > 0:
            slope, intercept = np.polyfit(np.log(dt[use]), np.log(err[use]), 1)
            fam["order"], fam["fit_log_intercept"] = float(slope), float(intercept)
        else:
            fam["order"] = None
            fam["note"] = "errors at float rounding: no order"
        fam["fit_points"] = int(use.sum())
    return out


def plot(result: dict, out: str) -> list[str]:
    """The Pareto plot and the convergence plot; returns the paths written."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.ticker import LogFormatterSciNotation, LogLocator
    except ImportError as exc:
        raise ValueError(PLOTS_MISSING) from exc
    rows = result["settings"]
    labels = list(dict.fromkeys(r["label"] for r in rows))
    paths = []
    title = (f"{result['scene']}: {result['spheres']} spheres, mean position error at "
             f"{result['error_horizon_s']:g} s")
    fig, ax = plt.subplots(figsize=(7.0, 4.6), dpi=90)
    for i, label in enumerate(labels):  # one colour per family in both plots
        pts = [r for r in rows if r["label"] == label]
        x = [r["sphere_seconds_per_s"] for r in pts]
        y = [max(r["error_m"], PLOT_FLOOR) for r in pts]
        ax.plot(x, y, "o-", label=label, ms=4, color=f"C{i}")
        for r, xi, yi in zip(pts, x, y, strict=True):
            tag = (f"mb {r['max_bounces']}" if r["family"] == "max_bounces"
                   else f"1/{r['rate']}")
            ax.annotate(tag, (xi, yi), fontsize=6, textcoords="offset points", xytext=(3, 3))
    paths.append(_finish_log_plot(
        plt, fig, ax, "simulated sphere-seconds per wall second (sphere-frames/s x dt)", title,
        os.path.join(out, "pareto.png"), LogLocator, LogFormatterSciNotation))

    fig, ax = plt.subplots(figsize=(7.0, 4.6), dpi=90)
    for i, label in enumerate(labels):
        fam = result["families"][label]
        if fam["family"] == "max_bounces":
            continue
        pts = [r for r in rows if r["label"] == label]
        dt = [r["dt"] for r in pts]
        y = [max(r["error_m"], PLOT_FLOOR) for r in pts]
        order = fam.get("order")
        text = (f"{label} (order {order:.2f})" if order is not None
                else f"{label} (rounding only)")
        ax.plot(dt, y, "o-", label=text, ms=4, color=f"C{i}")
    paths.append(_finish_log_plot(plt, fig, ax, "dt [s]", title,
                                  os.path.join(out, "convergence.png"), LogLocator,
                                  LogFormatterSciNotation))
    return paths


def markdown(result: dict) -> str:
    """The study's table in Markdown (what ``DIR/accuracy.md`` holds)."""

    def num(value, fmt=".2g"):
        return "n/a" if value is None else format(value, fmt)

    h = result["error_horizon_s"]
    lines = [f"Scene `{result['scene']}`, {result['spheres']} spheres over "
             f"{result['horizon_s']:g} s; timing on {result['timing_spheres']} spheres "
             f"({result['machine']['device']}).", "",
             f"| setting | dt | max_bounces | mean error at {h:g} s [m] | median [m] | "
             "median error at 0.1 s [m] | 1st contacts: time error, median [s] | "
             "contact position error, median [m] | time to 1 mm, median [s] | "
             "energy drift, max | energy against the reference, max | ns per sphere-frame |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["settings"]:
        c = r["contacts"]
        short = r["position_error"].get("0.1 s", {}).get("median_m")
        div = r["divergence"]["1 mm"]
        div_text = num(div["median_s"], ".3g") if div["median_s"] is not None \
            else f"> {result['horizon_s']:g}"
        lines.append(
            f"| {r['label']} | 1/{r['rate']} | {r['max_bounces']} | {num(r['error_m'])} | "
            f"{num(r['error_median_m'])} | {num(short)} | {num(c.get('time_error_median_s'))} "
            f"| {num(c.get('position_error_median_m'))} | {div_text} | "
            f"{num(r['invariants']['energy_drift_max'])} | "
            f"{num(r['energy']['max_relative'])} | {num(r['ns_per_sphere_frame'], '.0f')} |")
    orders = [f"{label}: {fam['order']:.2f}" for label, fam in result["families"].items()
              if fam.get("order") is not None]
    if orders:
        lines += ["", "Convergence order (slope of log error against log dt): "
                  + "; ".join(orders) + "."]
    lines += [f"Note: {n}" for n in result["notes"]]
    return "\n".join(lines) + "\n"


def _finish_log_plot(plt, fig, ax, xlabel: str, title: str, path: str, locator, formatter):
    """Log-log axes, labels, grid and legend of a study plot; saves it and returns its path."""
    ax.set_xscale("log")
    ax.set_yscale("log")
    _log_ticks(ax, locator, formatter)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("position error [m]")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    saved = _save(fig, path)
    plt.close(fig)
    return saved


def _log_ticks(ax, locator, formatter) -> None:
    """Labels at 1, 2 and 5 times each power of ten on the x axis (small, so they never
    overlap)."""
    ax.xaxis.set_minor_locator(locator(subs=(2.0, 5.0)))
    ax.xaxis.set_minor_formatter(formatter(labelOnlyBase=False))
    ax.tick_params(axis="x", which="minor", labelsize=7)


def _save(fig, path: str) -> str:
    """The figure as a PNG at ``path``, written atomically."""
    with atomic_output(path) as tmp:
        fig.savefig(tmp, format="png")
    return path


def _machine(device: str) -> dict:
    """:func:`warpsim.machine.machine`, the device the study ran on, and matplotlib's version
    when it is there (the plots)."""
    info = dict(machine(), device=device)
    try:
        import matplotlib

        info["matplotlib"] = matplotlib.__version__
    except ImportError:
        pass
    return info


def _print_summary(result: dict) -> None:
    print(f"accuracy of {result['scene']!r}: mean position error at "
          f"{result['error_horizon_s']:g} s, {result['spheres']} spheres")
    print(f"{'setting':28s} {'dt':>8s} {'bounces':>7s} {'error m':>10s} {'1st contact s':>13s} "
          f"{'Msph-fr/s':>9s} {'drift':>8s}")
    for r in result["settings"]:
        c = r["contacts"].get("time_error_median_s")
        contact = f"{c:.3g}" if c is not None else "n/a"
        drift = r["invariants"]["energy_drift_max"]
        if drift is None:
            drift = r["energy"]["max_relative"]
        print(f"{r['label']:28s} {'1/' + str(r['rate']):>8s} {r['max_bounces']:>7d} "
              f"{r['error_m']:>10.3g} {contact:>13s} "
              f"{r['sphere_frames_per_s'] / 1e6:>9.3g} {drift:>8.2g}")
    for label, fam in result["families"].items():
        if fam.get("order") is not None:
            print(f"convergence order of {label}: {fam['order']:.2f}")
    for note in result["notes"]:
        print(f"note: {note}")


if __name__ == "__main__":
    sys.exit(main())
