"""The error report: a run measured against the exact reference (:mod:`warpsim.analysis.reference`).

In a room full of plates, trajectories diverge exponentially from any perturbation, so a
position error after ten seconds says nothing about a simulator. The report gives measures
that do:

- **contacts**: the first ``k`` contacts of each sphere, matched in order with the reference's
  (bounces only, both sides filtered by the same size of velocity change), their time error [s]
  and contact-position error [m]; matching stops at the first pair whose normals disagree
  (from there the two runs have taken different paths);
- **short horizons**: the position error [m] at 0.1 s, 0.5 s and 1 s (those the run reaches);
- **time to divergence**: how long [s] until a sphere's position error first exceeds 1 mm and
  1 cm (spheres that never do count as "beyond the horizon");
- **energy** of the sample against the reference at the horizon (relative to each sphere's
  energy above the scene's lowest point, the scale of :mod:`warpsim.energy`): with lossy
  contacts this is the energy figure;
- **invariants** of the whole run: energy drift (:mod:`warpsim.energy`; none with lossy
  contacts, whose energy falls by design), spheres that
  escaped (left the bounds of the obstacles and of the starting positions: in a closed room,
  went through a wall), spheres inside an obstacle (deeper than the run's rounding), spheres
  stopped by the bounce cap.

How the simulator's contacts are found: the sampled spheres are run again alone in a new
:class:`warpsim.Simulator` with the same settings (spheres are independent, so they follow the
same paths as in the full run), one frame at a time, reading the state velocity after each
frame. A frame whose velocity differs from free flight (``u_prev + g dt``) by more than
``CONTACT_DV_FRAMES`` frames of gravity (plus ``CONTACT_DV_MIN``) holds a contact; its normal is
the direction of that change, and its time comes from the frame's path: for the linear model
the chord ``A -> C`` with the mean velocity ``u_prev + g dt / 2`` then ``C -> B`` with the
reflected one (``u - g dt / 2``), for the
ballistic model the two parabola arcs; both give the contact time in closed form (several
contacts in one frame count as one). From a :class:`warpsim.Trajectory` (positions only) the
velocities are estimated from consecutive frames, so every frame must be recorded; a contact
in the next frame spoils that estimate, so contact figures from a trajectory are rougher.

Velocity convention: the reference starts each sphere from the swarm's own velocity, the
velocity at time 0 for both motion models, and a state's velocity is the one at its frame's
end. Both models are exact at every frame in free flight, so what the report measures is the
error of contacts.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import validation as check
from ..energy import energy_scale, lowest_potential, region_bounds, relative_change
from ..events import ContactEvents
from ..scene import Scene
from ..swarm import Swarm
from ..trajectory import Trajectory
from ..vocabulary import ContactKind
from .reference import ReferenceRun, simulate

#: The short horizons [s] at which position errors are reported.
HORIZONS = (0.1, 0.5, 1.0)

#: Position errors [m] whose first crossing is the "time to divergence".
DIVERGENCE_THRESHOLDS = (1e-3, 1e-2)

#: A frame holds a contact when its velocity change beyond free flight exceeds this many frames
#: of gravity: a resting or sliding support changes it by one frame of gravity at most.
CONTACT_DV_FRAMES = 3.0

#: ... plus this much [m/s]: below it (and in zero gravity) float rounding and the energy reset
#: move the velocity, not contacts.
CONTACT_DV_MIN = 1e-3

#: Two contacts match when their normals agree to within this cosine (about 25 degrees).
NORMAL_MATCH_COS = 0.9

#: Contacts per sphere compared with the reference by default.
DEFAULT_CONTACTS = 5

#: Centres closer than this to an obstacle's surface, inside it, in units of the rounding of
#: the run's precision at the scene's scale, count as "inside" (rounding is not a penetration).
INSIDE_ULPS = 64.0

#: Length of the reference run when the simulator has not been stepped yet [s].
DEFAULT_HORIZON = 1.0


@dataclass
class ErrorReport:
    """The figures of :func:`compare` (all in SI units; see the module's docstring).

    Attributes:
        settings: how the run was made (dt, precision, max_bounces, motion) and measured.
        sample: indices of the spheres compared, into the run's swarm.
        horizon: simulated time compared [s].
        contacts: first-k contact errors (time [s], position [m]) and counts.
        position_error: per short horizon, the error statistics [m] over the sample.
        divergence: per threshold, the time to divergence statistics [s].
        invariants: the whole run's energy drift, escaped, inside and capped counts.
        reference: the reference's own figures (events, incomplete spheres, cost).
        energy: the sample's energy error against the reference at the horizon, relative.
    """

    settings: dict
    sample: np.ndarray
    horizon: float
    contacts: dict
    position_error: dict
    divergence: dict
    invariants: dict
    reference: dict = field(default_factory=dict)
    energy: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """A JSON-ready dictionary of every figure."""
        return _plain({"settings": self.settings, "sample": self.sample.tolist(),
                       "horizon_s": self.horizon, "contacts": self.contacts,
                       "position_error": self.position_error, "divergence": self.divergence,
                       "invariants": self.invariants, "reference": self.reference,
                       "energy": self.energy})

    def summary(self) -> str:
        """The report as a few lines of text (what ``warpsim run --error-sample`` prints)."""
        s = self.settings
        lines = [f"error against the exact reference: {len(self.sample)} sampled spheres, "
                 f"{self.horizon:g} s ({s.get('precision', '?')}, dt = {s.get('dt', 0):.6g} s, "
                 f"motion {s.get('motion', '?')}, {s.get('source', '')})"]
        c = self.contacts
        if c.get("compared", 0):
            lines.append(
                f"  first {c['k']} contacts: {c['compared']} compared, "
                f"time error median {_fmt(c['time_error_median_s'], 's')}, "
                f"max {_fmt(c['time_error_max_s'], 's')}; position error median "
                f"{_fmt(c['position_error_median_m'], 'm')}, max "
                f"{_fmt(c['position_error_max_m'], 'm')}; "
                f"{c['mismatched_spheres']} spheres took another contact")
        else:
            lines.append(f"  first contacts: {c.get('note', 'none in the horizon')}")
        for key, e in self.position_error.items():
            lines.append(f"  position error at {key}: median {_fmt(e['median_m'], 'm')}, "
                         f"90% {_fmt(e['p90_m'], 'm')}, max {_fmt(e['max_m'], 'm')}")
        for key, d in self.divergence.items():
            median = d["median_s"]
            text = f"> {self.horizon:g} s" if median is None else _fmt(median, "s")
            lines.append(f"  time to {key} error: median {text}, "
                         f"{d['diverged']}/{d['spheres']} spheres within {self.horizon:g} s")
        if self.energy.get("max_relative") is not None:
            lines.append(f"  energy against the reference at {self.horizon:g} s: median "
                         f"{self.energy['median_relative']:.2g}, max "
                         f"{self.energy['max_relative']:.2g} (relative)")
        inv = self.invariants
        parts = []
        if inv.get("energy_drift_max") is not None:
            parts.append(f"energy drift max {inv['energy_drift_max']:.2g} "
                         f"(median {inv['energy_drift_median']:.2g})")
        for key in ("escaped", "inside", "capped_spheres"):
            if inv.get(key) is not None:
                parts.append(f"{key.replace('_', ' ')} {inv[key]}")
        if parts:
            lines.append(f"  whole run ({inv.get('spheres', '?')} spheres): " + ", ".join(parts))
        ref = self.reference
        if ref.get("incomplete"):
            lines.append(f"  reference gave up on {ref['incomplete']} spheres (not compared)")
        return "\n".join(lines)


def compare(sim_or_trajectory, scene: Scene, swarm: Swarm, sample: int = 32, seed: int = 0,
            horizon: float | None = None, contacts: int = DEFAULT_CONTACTS,
            motion: str | None = None) -> ErrorReport:
    """Measure a run against the exact reference on a seeded sample of its spheres.

    Args:
        sim_or_trajectory: a :class:`warpsim.Simulator` (after, or before, its run: its
            settings are what matters; the sampled spheres are simulated again from ``swarm``)
            or a :class:`warpsim.Trajectory` of that run with every frame recorded from frame 0.
        scene: the run's scene.
        swarm: the run's initial swarm.
        sample: spheres compared, >= 1 (all of them when the swarm is smaller).
        seed: seed of the sample.
        horizon: simulated time compared [s]; default: the simulator's frames so far (or
            ``DEFAULT_HORIZON`` before any), the trajectory's length. With births
            (``swarm.birth_frame``) the sample is drawn among the spheres born before the
            run's last frame, each is compared from its birth (the simulator's and the
            reference's run of it both start there, with its state at birth), and the
            horizon is at most the shortest life in the sample.
        contacts: contacts per sphere compared, >= 1.
        motion: the motion model of a trajectory (``"linear"`` by default); a simulator's own
            is used otherwise.

    Returns:
        :class:`ErrorReport`.

    Raises:
        ValueError: a bad argument (naming it).
    """
    from ..simulator import Simulator

    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a warpsim.Scene, got {type(scene).__name__}")
    if not isinstance(swarm, Swarm):
        raise ValueError(f"swarm must be a warpsim.Swarm, got {type(swarm).__name__}")
    sample = check.positive_int("sample", sample)
    contacts = check.positive_int("contacts", contacts)
    seed = check.positive_int("seed", seed, minimum=0)
    n = len(swarm)
    if not isinstance(sim_or_trajectory, (Simulator, Trajectory)):
        raise ValueError("sim_or_trajectory must be a warpsim.Simulator or a warpsim.Trajectory, "
                         f"got {type(sim_or_trajectory).__name__}")
    births = swarm.birth_frame
    if isinstance(sim_or_trajectory, Simulator):
        end = sim_or_trajectory.frame or max(1, round(_horizon(horizon, DEFAULT_HORIZON)
                                                      / float(sim_or_trajectory.dt)))
    else:
        end = int(sim_or_trajectory.frame[-1]) if len(sim_or_trajectory) else 0
    lived = np.flatnonzero(births < end) if swarm.has_births else n  # spheres that moved
    count = np.size(lived) if swarm.has_births else n
    if count == 0:
        raise ValueError(f"no sphere of the swarm is born before frame {end}: nothing to "
                         f"compare")
    idx = np.sort(np.random.default_rng(seed).choice(lived, size=min(sample, count),
                                                     replace=False))
    life = end - int(births[idx].max())  # frames the shortest-lived sampled sphere ran
    sub = _subswarm(swarm, idx)
    g = np.asarray(scene.gravity, dtype=np.float64)
    if isinstance(sim_or_trajectory, Simulator):
        sim = sim_or_trajectory
        dt = float(sim.dt)
        motion = getattr(sim, "motion", "linear")
        elapsed = sim.frame * dt
        horizon = _horizon(horizon, elapsed if sim.frame else DEFAULT_HORIZON)
        frames = max(1, round(horizon / dt))
        if swarm.has_births:
            frames = min(frames, life)
        position, velocity = record_every_frame(_like(sim, scene, sub), frames)
        settings = {"dt": dt, "precision": sim.precision, "max_bounces": sim.max_bounces,
                    "motion": motion, "source": "sampled spheres simulated again"}
        invariants = run_invariants(sim, scene, swarm)
    else:
        traj = sim_or_trajectory
        if traj.sphere_count != n:
            raise ValueError(f"trajectory has {traj.sphere_count} spheres, swarm has {n}")
        if len(traj) < 2 or traj.frame[0] != 0 or np.any(np.diff(traj.frame) != 1):
            raise ValueError("trajectory must record every frame from frame 0 (every=1)")
        dt = float(traj.dt)
        motion = motion or "linear"
        horizon = _horizon(horizon, float(traj.frame[-1]) * dt)
        frames = min(life, max(1, round(horizon / dt)))
        # each sphere's frames from its birth (frame b + k of the run is its own frame k)
        position = np.stack([traj.position[b:b + frames + 1, i] for i, b in
                             zip(idx, births[idx], strict=True)], axis=1).astype(np.float64)
        velocity = velocities_from_positions(position, dt, g, motion)
        settings = {"dt": dt, "precision": str(traj.position.dtype), "max_bounces": None,
                    "motion": motion, "source": "recorded trajectory"}
        invariants = trajectory_invariants(traj, scene)
    times = np.arange(frames + 1) * dt
    horizon = float(times[-1])
    ref = simulate(scene, sub, horizon, times)
    figures = measure(position, velocity, times, dt, g, motion, ref, contacts,
                      lowest=lowest_potential(scene.gravity, scene.boxes, swarm.position))
    return ErrorReport(settings=settings, sample=idx, horizon=horizon,
                       contacts=figures["contacts"], position_error=figures["position_error"],
                       divergence=figures["divergence"], invariants=invariants,
                       reference=reference_figures(ref), energy=figures["energy"])


def measure(position: np.ndarray, velocity: np.ndarray | None, times: np.ndarray, dt: float,
            gravity: np.ndarray, motion: str, ref: ReferenceRun,
            contacts: int = DEFAULT_CONTACTS, lowest: float | None = None) -> dict:
    """The error figures of one run's frames against a reference sampled at the same times.

    Args:
        position: the run's centres at ``times`` [m], shape (T, K, 3) (frame ``j`` at
            ``times[j] = j dt``).
        velocity: the run's state velocities at ``times`` [m/s], (T, K, 3), or None (then
            estimated from ``position``).
        times: frame times [s], (T,). dt: time step [s]. gravity: [m/s^2], (3,).
        motion: ``"linear"`` or ``"ballistic"`` (how a frame's path is read).
        ref: the reference for the same spheres, sampled at ``times``.
        contacts: contacts per sphere compared.
        lowest: the lowest potential energy per unit mass in the scene [J/kg] (see
            :func:`warpsim.energy.lowest_potential`), the zero of the energy scale; None: the
            lowest over the frames.

    Returns:
        ``{"contacts", "position_error", "divergence", "energy"}`` (plain numbers); ``energy``
        is the energy error against the reference at the last frame, relative to each sphere's
        energy above ``lowest`` (what lossy runs are judged by).
    """
    position = np.asarray(position, dtype=np.float64)
    if velocity is None:
        velocity = velocities_from_positions(position, dt, gravity, motion)
    keep = ~ref.incomplete
    err = np.linalg.norm(position - ref.position, axis=2)[:, keep]  # (T, K')
    horizon = float(times[-1])
    pos_err = {}
    for h in HORIZONS:
        if h <= horizon + 0.5 * dt:
            j = int(round(h / dt))
            e = err[j]
            pos_err[f"{h:g} s"] = {"time_s": float(times[j]), **_stats(e, "m")}
    divergence = {}
    for thr in DIVERGENCE_THRESHOLDS:
        over = err > thr
        first = np.where(over.any(axis=0), times[np.argmax(over, axis=0)], np.inf)
        finite = first[np.isfinite(first)]
        median = float(np.median(first)) if len(first) else None
        divergence[f"{thr * 1e3:g} mm"] = {
            "threshold_m": thr, "spheres": int(len(first)), "diverged": int(len(finite)),
            "median_s": median if median is not None and np.isfinite(median) else None,
            "min_s": float(finite.min()) if len(finite) else None}
    found = contacts_from_frames(position, velocity, dt, gravity, motion)
    contact_figs = match_contacts(found, ref, np.flatnonzero(keep), contacts,
                                  _dv_threshold(dt, gravity), dt)
    g = np.asarray(gravity, dtype=np.float64)
    end = velocity[-1]
    e_run = 0.5 * np.einsum("ki,ki->k", end, end) - position[-1] @ g
    e_ref = (0.5 * np.einsum("ki,ki->k", ref.velocity[-1], ref.velocity[-1])
             - ref.position[-1] @ g)
    e_start = 0.5 * np.einsum("ki,ki->k", ref.velocity[0], ref.velocity[0]) - ref.position[0] @ g
    if lowest is None:
        lowest = float(np.min(-(ref.position[:, keep] @ g))) if keep.any() else 0.0
    rel = (np.abs(e_run - e_ref) / energy_scale(e_start, 1.0, lowest))[keep]
    energy = {"time_s": float(times[-1]), **_stats(rel, "relative")}
    return {"contacts": contact_figs, "position_error": pos_err, "divergence": divergence,
            "energy": energy}


# -- the simulator side ------------------------------------------------------------------------


def record_every_frame(sim, frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Positions and state velocities after every frame (frame 0 first), float64,
    (frames + 1, N, 3) each."""
    s = sim.state()
    pos, vel = [s.position.astype(np.float64)], [s.velocity.astype(np.float64)]
    for _ in range(frames):
        sim.step(1)
        s = sim.state()
        pos.append(s.position.astype(np.float64))
        vel.append(s.velocity.astype(np.float64))
    return np.stack(pos), np.stack(vel)


def velocities_from_positions(position: np.ndarray, dt: float, gravity, motion: str):
    """State velocities estimated from consecutive frames (exact when the next frame has no
    contact): ``u_j = (x_{j+1} - x_j) / dt - g dt / 2`` for both motion models (each frame's
    free flight is the parabola's chord); the last frame repeats the one before plus a kick.
    ``motion`` is accepted for symmetry with :func:`contacts_from_frames`."""
    g = np.asarray(gravity, dtype=np.float64)
    vel = np.empty_like(position)
    vel[:-1] = np.diff(position, axis=0) / dt - 0.5 * g * dt
    vel[-1] = vel[-2] + g * dt if len(position) > 1 else 0.0
    return vel


def contacts_from_frames(position, velocity, dt: float, gravity, motion: str,
                         threshold: float | None = None) -> ContactEvents:
    """Contacts of each sphere read from its frames (see the module's docstring).

    Args:
        position, velocity: (T, K, 3) [m], [m/s], frame ``j`` at time ``j dt``.
        threshold: velocity change [m/s] that marks a contact (default from the constants).

    Returns:
        The contacts as a table (``sphere`` the column ``k`` of the arrays, by sphere then
        time; ``box`` -1 and ``normal_speed`` NaN: the frames do not tell them), every one a
        bounce.
    """
    g = np.asarray(gravity, dtype=np.float64)
    thr = _dv_threshold(dt, g) if threshold is None else threshold
    a, b = position[:-1], position[1:]
    v0, v1 = velocity[:-1], velocity[1:]
    pre = v0 + g * dt  # the velocity at the frame's end in free flight
    dv = v1 - pre
    hit = np.linalg.norm(dv, axis=2) > thr  # (T-1, K)
    empty, none = np.zeros(0), np.zeros(0, np.int64)
    times, fractions, spheres, frame_of = [empty], [empty], [none], [none]
    points, normals = [np.zeros((0, 3))], [np.zeros((0, 3))]
    for k in range(position.shape[1]):
        frames = np.flatnonzero(hit[:, k])
        d = -dv[frames, k]  # u0 + g dt - u1: the change of the mean (linear) / end velocity
        size2 = np.einsum("ij,ij->i", d, d)
        # linear: B - A = w0 tau + w1 (dt - tau), w0 = u0 + g dt/2, w1 = u1 - g dt/2;
        # ballistic: the two arcs; both give d tau = B - A - u1 dt + g dt^2 / 2
        rhs = b[frames, k] - a[frames, k] - v1[frames, k] * dt + 0.5 * g * dt * dt
        tau = np.clip(np.einsum("ij,ij->i", d, rhs) / size2, 0.0, dt)
        if motion == "ballistic":
            point = a[frames, k] + v0[frames, k] * tau[:, None] + 0.5 * g * tau[:, None] ** 2
        else:
            point = a[frames, k] + (v0[frames, k] + 0.5 * g * dt) * tau[:, None]
        times.append(frames * dt + tau)
        points.append(point)
        normals.append(-d / np.sqrt(size2)[:, None])
        spheres.append(np.full(len(frames), k, dtype=np.int64))
        frame_of.append(frames + 1)
        fractions.append(tau / dt)
    count = sum(len(t) for t in times)
    return ContactEvents(time=np.concatenate(times), sphere=np.concatenate(spheres),
                         box=np.full(count, -1, dtype=np.int32),
                         position=np.concatenate(points), normal=np.concatenate(normals),
                         normal_speed=np.full(count, np.nan),
                         kind=np.full(count, ContactKind.BOUNCE, dtype=np.int8),
                         frame=np.concatenate(frame_of), fraction=np.concatenate(fractions))


def match_contacts(found: ContactEvents, ref: ReferenceRun, spheres, k: int,
                   threshold: float, frame: float) -> dict:
    """The first ``k`` contacts of each sphere matched in order with the reference's bounces
    that change the velocity by more than ``threshold`` [m/s] (``2 x`` normal speed);
    ``frame`` is the run's time step [s] (a contact in the last two frames may be unmatched)."""
    dts, dxs, mismatched, spheres_with = [], [], 0, 0
    for i in spheres:
        ev = ref.events.of_sphere(i).bounces()
        big = 2.0 * ev.normal_speed > threshold
        rt, rp, rn = ev.time[big][:k], ev.position[big][:k], ev.normal[big][:k]
        mine = found.of_sphere(i)
        st, sp, sn = mine.time[:k], mine.position[:k], mine.normal[:k]
        m = min(len(rt), len(st))
        if len(rt) or len(st):
            spheres_with += 1
        for j in range(m):
            if float(rn[j] @ sn[j]) < NORMAL_MATCH_COS:
                mismatched += 1
                break
            dts.append(abs(st[j] - rt[j]))
            dxs.append(float(np.linalg.norm(sp[j] - rp[j])))
        else:
            extra = np.concatenate([rt[m:], st[m:]])
            if m < k and np.any(extra < ref.t_end - 2.0 * frame):
                mismatched += 1  # one side had a contact the other did not (not at the end)
    out = {"k": k, "compared": len(dts), "spheres_with_contacts": spheres_with,
           "mismatched_spheres": mismatched, "dv_threshold_mps": threshold}
    if dts:
        out.update(time_error_median_s=float(np.median(dts)),
                   time_error_p90_s=float(np.percentile(dts, 90)),
                   time_error_max_s=float(np.max(dts)),
                   position_error_median_m=float(np.median(dxs)),
                   position_error_p90_m=float(np.percentile(dxs, 90)),
                   position_error_max_m=float(np.max(dxs)))
    else:
        out["note"] = "no contact within the horizon"
    return out


def run_invariants(sim, scene: Scene, swarm: Swarm) -> dict:
    """Energy drift, escaped, inside and capped counts of a simulator's whole swarm now (the
    spheres born so far)."""
    s = sim.state()
    born = swarm.birth_frame <= sim.frame
    drift = np.abs(relative_change(sim, swarm.position, s))[born]
    stats = sim.stats
    pos = s.position.astype(np.float64)[born]
    lossy = scene.energy_retention < 1.0 or not born.any()  # no drift to speak of
    return {"spheres": int(born.sum()), "frames": stats.frames,
            "energy_drift_max": None if lossy else float(drift.max()),
            "energy_drift_median": None if lossy else float(np.median(drift)),
            "escaped": escaped(scene, pos, swarm.position),
            "inside": inside(scene, pos, swarm.radius[born], sim.precision),
            "capped_spheres": stats.capped_spheres, "capped_sphere_frames": stats.capped}


def trajectory_invariants(traj: Trajectory, scene: Scene) -> dict:
    born = traj.alive()[-1]
    pos = traj.position[-1].astype(np.float64)[born]
    precision = "float32" if traj.position.dtype == np.float32 else "float64"
    first = np.searchsorted(traj.frame, np.zeros(traj.sphere_count, dtype=np.int64)
                            if traj.birth_frame is None else traj.birth_frame)[born]
    start = traj.position[first, np.flatnonzero(born)].astype(np.float64)
    return {"spheres": int(born.sum()), "frames": int(traj.frame[-1]),
            "energy_drift_max": None, "energy_drift_median": None,
            "escaped": escaped(scene, pos, start),
            "inside": inside(scene, pos, traj.radius[born], precision),
            "capped_spheres": None, "capped_sphere_frames": None}


def escaped(scene: Scene, position: np.ndarray, start: np.ndarray) -> int:
    """Spheres whose centre [m] is outside the scene's region: the world bounds of the
    obstacles and of the spheres' ``start`` positions together (for a closed room: spheres
    that went through a wall; in an open scene: that left it)."""
    low, high = region_bounds(scene.boxes, start)
    out = np.any((position < low) | (position > high), axis=1)
    return int(np.count_nonzero(out))


def inside(scene: Scene, position: np.ndarray, radius, precision: str) -> int:
    """Spheres overlapping an obstacle by more than the rounding of ``precision``."""
    if not len(scene.boxes):
        return 0
    eps = np.finfo(np.float32 if precision == "float32" else np.float64).eps
    low, high = region_bounds(scene.boxes, np.zeros((0, 3)))  # the obstacles' bounds
    scale = max(1.0, float(np.abs(np.concatenate([low, high])).max()))
    depth = scene.boxes.signed_distance(position).min(axis=1) - np.asarray(radius)
    return int(np.count_nonzero(depth < -INSIDE_ULPS * eps * scale))


def reference_figures(ref: ReferenceRun) -> dict:
    return {"spheres": len(ref.incomplete), "incomplete": int(ref.incomplete.sum()),
            "bounces": len(ref.events.bounces()), "steps": int(ref.steps.sum())}


# -- helpers -----------------------------------------------------------------------------------


def _like(sim, scene: Scene, sub: Swarm):
    """A simulator for ``sub`` with ``sim``'s settings: its broad phase asked for by name (a
    grid's fallback, ``grid-bvh`` or ``walk-bvh``, is the grid's, ``grid`` or ``walk``: the
    choice a simulator makes for the same scene and precision)."""
    from ..simulator import Simulator

    kwargs = dict(dt=sim.dt, max_bounces=sim.max_bounces, device=sim.device,
                  precision=sim.precision,
                  broad_phase=str(sim.broad_phase).removesuffix("-bvh"))
    motion = getattr(sim, "motion", None)
    if motion is not None and motion != "linear":
        kwargs["motion"] = motion
    return Simulator(scene, sub, **kwargs)


def _subswarm(swarm: Swarm, idx: np.ndarray) -> Swarm:
    return Swarm(position=swarm.position[idx], velocity=swarm.velocity[idx],
                 radius=swarm.radius[idx], mass=swarm.mass[idx],
                 angular_momentum=swarm.angular_momentum[idx],
                 orientation=swarm.orientation[idx])


def _horizon(value, default: float) -> float:
    if value is None:
        return max(default, 0.0) or DEFAULT_HORIZON
    return check.scalar("horizon", value, positive=True)


def _dv_threshold(dt: float, gravity) -> float:
    return CONTACT_DV_FRAMES * float(np.linalg.norm(gravity)) * dt + CONTACT_DV_MIN


def _stats(values: np.ndarray, unit: str) -> dict:
    if len(values) == 0:
        return {f"median_{unit}": None, f"p90_{unit}": None, f"max_{unit}": None}
    return {f"median_{unit}": float(np.median(values)),
            f"p90_{unit}": float(np.percentile(values, 90)),
            f"max_{unit}": float(np.max(values))}


def _fmt(value, unit: str) -> str:
    if value is None:
        return "n/a"
    return f"{value:.3g} {unit}"


def _plain(obj):
    """Numbers, lists and dicts only (numpy scalars and arrays converted; inf/nan -> None)."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if np.isfinite(x) else None
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    return obj
