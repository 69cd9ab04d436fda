"""The comparison's table (Markdown) and its one plot (PNG), from the results of
:func:`benchmarks.peers.run.run`."""

from __future__ import annotations

import io
from pathlib import Path

ENERGY_FLOOR = 1e-9
"""Smallest |energy drift| the plot's log axis shows; smaller drifts (float rounding) are drawn
on this line."""

COLORS = {"warpsim": "#d62728", "numpy": "#7f7f7f", "pybullet": "#1f77b4",
          "mujoco": "#2ca02c", "newton": "#9467bd"}
MARKERS = {5.0: "o", 60.0: "^"}


def _share(count: int, n: int) -> str:
    if count == 0:
        return "0"
    return f"{count} ({100 * count / n:.3g}%)"


def _signed(x) -> str:
    return "n/a" if x is None else f"{x:+.2g}"


def _error(e) -> str:
    if e is None or e["median"] is None:
        return "n/a | n/a"
    early = e["median_at"].get("0.1")
    return (f"{'n/a' if early is None else format(early, '.2g')} | "
            f"{e['median']:.2g} ({e['worst']:.2g})")


def markdown(results: dict) -> str:
    """The table: one row per engine setting and speed, and the lines that say what ran."""
    rows = results["rows"]
    m, v = results["machine"], results["versions"]
    w = results["workload"]
    lines = [
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['platform']}, Python {m['python']}; "
        + ", ".join(f"{k} {val}" for k, val in v.items() if val) + ".",
        "",
        f"Workload: {w['n']} spheres per speed (radius {w['radius_m']} m), room "
        f"{' x '.join(f'{x:g}' for x in w['room_inner_m'])} m with {w['plates']} plates "
        f"{w['plate_thickness_m']} m thick, gravity, dt = 1/{round(1 / w['dt_s'])} s, "
        f"{w['frames']} frames; {results['options']['repeats']} timed rounds, medians.",
        "",
        "| engine | m/s | ns per sphere-frame: median (best) | × warpsim float32 | set-up s | "
        "escaped | inside | energy drift | error at 0.1 s, m | error over 1 s, m: median "
        "(worst) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        ratio = "n/a" if r["over_baseline"] is None else f"{r['over_baseline']:.3g}"
        lines.append(
            f"| {r['label']} | {r['speed']:g} | {r['ns_per_sphere_frame']:.3g} "
            f"({r['best_ns_per_sphere_frame']:.3g}) | {ratio} | "
            f"{r['setup_s']:.2g} | {_share(r['escaped'], r['n'])} | "
            f"{_share(r['inside'], r['n'])} | {_signed(r['energy_drift']['total'])} | "
            f"{_error(r['error'])} |")
    notes = [f"{k}: {why}" for k, why in results["left_out"].items()]
    missing_ref = {s: why for s, why in results["reference"].items()
                   if not why.startswith("reference computed")}
    notes += [f"error at {s} m/s: n/a, {why}" for s, why in missing_ref.items()]
    if notes:
        lines += ["", "Left out: " + "; ".join(notes) + "."]
    return "\n".join(lines) + "\n"


def _family(key: str) -> str:
    return key.split("-")[0]


def plot(results: dict, path: Path) -> None:
    """Speed against escaped spheres and against energy drift, one point per setting and
    speed; written atomically to ``path`` (PNG).

    Raises:
        ImportError: with the extra to install, when matplotlib is missing.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:
        raise ImportError('matplotlib is needed for the plot: pip install "warpsim[peers]"'
                          ) from exc
    from warpsim.export.files import write_bytes

    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 5.6), constrained_layout=True)
    for r in results["rows"]:
        color = COLORS.get(_family(r["setting"]), "black")
        variant = any(v in r["setting"] for v in ("speculative", "ccd", "float64"))
        kw = {"color": color, "marker": MARKERS.get(r["speed"], "s"), "markersize": 9,
              "markerfacecolor": "none" if variant else color, "markeredgewidth": 1.6,
              "linestyle": "none"}
        x = r["ns_per_sphere_frame"]
        left.plot(x, 100.0 * r["escaped"] / r["n"], **kw)
        drift = r["energy_drift"]["total"]
        if drift is not None:
            right.plot(x, max(abs(drift), ENERGY_FLOOR), **kw)
    left.set(xscale="log", xlabel="ns per sphere-frame, one core (left is faster)",
             ylabel="spheres escaped from the closed room after 10 s [%]",
             title="Speed against spheres lost through the walls")
    right.set(xscale="log", yscale="log", xlabel="ns per sphere-frame, one core (left is faster)",
              ylabel=f"|energy drift| after 10 s (drifts below {ENERGY_FLOOR:g} drawn there)",
              title="Speed against energy error (elastic contacts: 0 is right)")
    for ax in (left, right):
        ax.grid(True, which="both", alpha=0.3)
    handles, labels = [], []
    for r in results["rows"]:
        if r["label"] in labels:
            continue
        color = COLORS.get(_family(r["setting"]), "black")
        variant = any(v in r["setting"] for v in ("speculative", "ccd", "float64"))
        handles.append(plt.Line2D([], [], color=color, marker="s", markersize=9,
                                  markerfacecolor="none" if variant else color,
                                  markeredgewidth=1.6, linestyle="none"))
        labels.append(r["label"])
    handles += [plt.Line2D([], [], color="black", marker=m, linestyle="none",
                           markerfacecolor="none") for m in MARKERS.values()]
    labels += [f"{v:g} m/s" for v in MARKERS]
    fig.legend(handles, labels, loc="outside lower center", ncol=6, fontsize=8, frameon=False)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=130)
    plt.close(fig)
    write_bytes(path, buf.getvalue())
