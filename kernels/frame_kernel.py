"""The frame kernel: each task advances its spheres, in turn, by one or many time steps.

A task takes a block of ``spheres_per_task`` spheres (the launch size is the spheres over the
block, rounded up): on the CPU a block of many (``warpsim.model.CPU_SPHERES_PER_TASK``),
since each task first copies the launch's arguments; on a GPU one sphere a thread. Every sphere's
arithmetic is the same whatever the block, so the results are bit-identical.

Per sphere (SPEC "Dynamics of one frame"): the move (the bounce loop along the chord of the
frame's free-flight parabola, or the ballistic loop along the parabola itself), the speed reset
from the energy invariant, and the orientation from the rotation vector.

Velocity convention, both motion models: the stored velocity ``v`` is the velocity at the end of
the state's frame (at t = 0 the swarm's own), and the energy is ``E = 1/2 m |v|^2 - m g . (p -
origin)``. The linear frame moves from ``p`` to ``p + v dt + g dt^2 / 2`` (mean velocity ``v +
g dt / 2``) and ends with ``v + g dt``: exactly the free-flight parabola at every frame, so the
reset is the identity there (to rounding) and only corrects what contacts and rounding change.
Resetting the mean velocity from ``E`` instead (the sheet's literal rule) would not be the
identity in free flight: every flight would be disturbed, every frame.

Free flight (``Features.free_flight``): a frame whose path (the chord, or the arc's chord grown
by its sagitta, grown by the sphere) lies beyond the box holding every box's reject bounds
(``Boxes.lower`` / ``Boxes.upper``) cannot meet a box, so it takes the bounce loop's own
no-contact move inline (the same arithmetic, the same bits) instead of calling the loop and its
broad phase. Built only for swarms that start beyond those bounds: in a closed room the test
would only cost time (it measured 1.18x the float32 frame there). A run of free frames goes on
in a loop of its own, and two things a frame with contacts does every frame are shared by the
run:

- the energy reset: the free move keeps the energy to rounding, so there the reset only removes
  rounding drift; it is applied after the frames whose sphere age (frames since its birth, or
  since the run's frame 0) is a multiple of ``Features.free_reset_every`` (32), and after the
  last free frame before one that is not free. Both depend on the state and the absolute frame
  only (the launch's last frame tests the next frame too), so the results do not depend on the
  split into launches, the recording stride, the threads or the births. Without the
  correction the reset only lowers the speed, so between resets the state may hold up to 32
  frames' rounding above ``E`` (``tests/test_free_flight.py`` bounds it, with the parabola,
  over 10 000 frames). A swarm made of a state starts a new run (age 0): it continues bit for
  bit when that state's age is a multiple of 32.
- the bounds test: the frames up to the next reset, record or the launch's end, and the frame
  after them, are tested at once, against the range of the parabola over them on one axis
  (``envelope_beyond_on``, with the rounding of the frames and of the test allowed for, erring
  early); when it holds every frame's own test would pass, so they go untested, with the bits of
  a test every frame (``Features.free_horizon`` False, checked by the tests). Otherwise the
  frame is tested alone, as before.

A ballistic frame whose free legs meet a contact that may be a support is held there
(``ballistic.ballistic_funcs``' ``free_legs``) and finished outside the loop of frames
(``held_rest``, out of line, then the same settling and counts): the kernel's loop of frames
holds no call, which kept its values in memory across it every frame (0.76 to 0.93x the
ballistic frame in the standard room, the same bits; BENCHMARKS.md, "The ballistic frame's
support path out of its loop"). Frames, records and counts are those of the whole frame.

With ``free_reset_every = 1`` the kernel gives the bits of the kernel without the step. The
orientation of a spinning sphere still turns every frame (its turn over a frame computed once a
run: ``L`` does not change in free flight).

Variants come from :func:`frame_kernel`, keyed by what the scene needs, so a
scene without spin runs a kernel with no spin code in it.
"""

from functools import cache

import warp as wp

from .arc import arc_funcs
from .ballistic import ballistic_funcs
from .bounce import bounce_funcs
from .candidates import BOUNDS_PAD_REL, REJECT_SLACK
from .data import Features, model_structs
from .dynamics import RESET_ULPS, dynamics_funcs
from .precision import precision
from .variant import variant_kernel

#: Rounding allowance of a run's bounds test for many frames (:func:`frame_kernel`'s
#: ``envelope_beyond_on``), in ulps per frame of the coordinate's scale: a frame's step rounds
#: its coordinate and velocity at most twice each (half an ulp each) and the test about five
#: times; 8 errs early by a factor of 2 or more, so the test never proves a frame clear that its
#: own test would not pass.
HORIZON_ULPS = 8.0


@cache
def frame_kernel(features: Features):
    """Build the frame kernel for one feature set.

    Each sphere is advanced by ``frame_count`` frames with its state in registers (a task does
    ``spheres_per_task`` of them in turn), its state written once at the end, and (when
    ``record_every > 0``) every ``record_every``-th frame and the last one written into the
    record arrays. The frames are the same
    arithmetic in the same order as one launch per frame, so the results are bit-identical
    whatever the frames per launch (a run of free frames included: its resets fall on frames of
    the sphere's age).

    Args:
        features: what the kernel is built for (``data.Features``); every field is read:
            ``spin``: friction torque on ``L`` at contacts and orientation integration; without
            it the angular momentum and orientation arrays are neither read nor written.
            ``energy_correction``: reset ``|v|`` from the energy after the move; without it the
            speed is only ever lowered to the energy bound, so energy is never gained either
            way. ``lossy``: ``energy_retention < 1``. ``broad_phase``: how each sphere finds its
            candidate boxes (bit-identical results whichever). ``events``: write every contact
            into the launch's event buffer; without it no event code is compiled and the buffer
            is not touched. ``motion``: ``"linear"``, the sheet's chord per frame
            (``bounce.bounce_path``), or ``"ballistic"``, the exact parabola
            (``ballistic.ballistic_path``); the state's velocity is the true one at the frame's
            end for both. A linear kernel contains no ballistic code and vice versa.
            ``free_flight``: test each frame's path against the boxes' overall bounds first
            and take the free step inline when it lies beyond them; runs of free frames reset
            the energy once in ``free_reset_every`` frames of age and before a frame that is
            not free, and test their bounds once for many frames (``free_horizon``; module
            docstring).
            ``births``: sphere ``i`` takes the step into absolute frame ``k`` only when ``k >
            birth_frame[i]`` (its state is the one at its birth until then, and the frames it
            takes are the arithmetic of a run started at its birth); without it
            ``birth_frame`` is never read.

    Kernel parameters beyond the model structs, the sphere constants and the state:
        frame_count: frames this launch advances (>= 0).
        record_every: record one frame in this many and the launch's last one (0: none).
        sphere_offset: index of the launch's first sphere in the swarm (event rows name it).
        first_frame: absolute frame of the state the launch starts from (births compare it).
        spheres_per_task: spheres each task advances, one after another (>= 1): task ``j``
            takes the launch's spheres ``j * spheres_per_task`` on, up to the last, so the
            launch needs ``ceil(N / spheres_per_task)`` tasks (``N``: ``position_in``'s rows).
        record_position_out, record_orientation_out: (records, N) centres [m] and orientations.
        record_velocity_out, record_angular_velocity_out: (records, N) velocity at the
            recorded frame [m/s] (the state's) and world angular velocity ``Rot`` [rad/s];
            written only when the arrays have rows (a (0, N) array skips them).
        events_out: the event buffer; an event's frame is the frame within the launch, from 1.
        bounce_count_out, support_count_out, capped_count_out: per-sphere counters added to:
            bounces (contacts that reflect), resting or sliding contacts on a support, and
            frames stopped by the cap.
    """
    p = precision(features.precision)
    scalar, vec3, quat = p.scalar, p.vec3, p.quat
    Boxes, BroadPhase, Physics, EventBuffer = model_structs(p)
    spin, energy_correction = features.spin, features.energy_correction
    free_flight = features.free_flight
    births = features.births
    motion = features.motion
    # the ballistic frame's free legs stop at a contact that may be a support, and the kernel
    # finishes that frame (``held_rest``, out of line) outside its loop of frames: a call in
    # the loop kept the loop's values in memory across it, every frame (BENCHMARKS.md, "The
    # ballistic frame's support path out of its loop")
    defer = motion == "ballistic"
    if defer:
        ballistic = ballistic_funcs(features)
        path, held_rest = ballistic.free_legs, ballistic.held_rest
    else:
        path = bounce_funcs(features).bounce_path
    dyn = dynamics_funcs(p)
    energy_along_gravity = dyn.energy_along_gravity
    energy_along_velocity = dyn.energy_along_velocity
    kinetic_energy = dyn.kinetic_energy
    potential = dyn.potential
    rotation_vector = dyn.rotation_vector
    inertia = dyn.inertia
    integrate_orientation = dyn.integrate_orientation
    orientation_step = dyn.orientation_step
    turned = dyn.turned
    # the arc's functions only where a ballistic frame calls them: a linear variant builds
    # none of them (each @wp.func is parsed when it is made)
    arc_point = arc_funcs(p).arc_point if motion == "ballistic" else None
    ZERO = scalar(0.0)
    HALF = scalar(0.5)
    EIGHTH = scalar(0.125)
    RESET_SLACK = scalar(RESET_ULPS * p.eps)
    SLACK = scalar(1.0 + REJECT_SLACK)
    PAD_REL = scalar(BOUNDS_PAD_REL)
    HORIZON_SLACK = scalar(HORIZON_ULPS * p.eps)
    RESET_EVERY = features.free_reset_every
    horizon = features.free_horizon
    RAISE = 1 if energy_correction else 0

    @wp.func(inline=True)
    def beyond_on(a: scalar, d: scalar, grow: scalar, lower: scalar, upper: scalar):
        """1 when the path from ``a`` [m] along ``d`` [m] on one axis, grown by ``grow`` [m],
        lies beyond ``[lower, upper]`` [m] on that axis (:func:`clear_of_boxes`' test of one
        axis)."""
        e = a + d
        reach = grow * SLACK + PAD_REL * (wp.abs(a) + wp.abs(d) + grow)
        out = int(0)
        if wp.max(a, e) + reach < lower or wp.min(a, e) - reach > upper:
            out = 1
        return out

    @wp.func(inline=True)
    def clear_of_boxes(a: vec3, d: vec3, grow: vec3, lower: vec3, upper: vec3, first: int):
        """The first axis (from ``first``, then the others in order; -1: none) on which the
        path from ``a`` [m] along the chord ``d`` [m], its bounds grown by ``grow`` [m] per
        axis, lies beyond ``lower`` / ``upper`` [m] (``Boxes.lower``, ``Boxes.upper``, plain
        values: no struct is copied): then every box's reject (``candidates.bounds_funcs``'
        ``apart``) refuses it and the candidate loop would find nothing, whatever the broad
        phase. The path side is padded by ``BOUNDS_PAD_REL`` of its coordinates (the
        reject's rounding of the path; the box side is padded on the host), so an axis is
        never wrong; -1 only means "look". Each axis's test is the same arithmetic whatever
        ``first`` is, so the answer (some axis or none) does not depend on it: a run of free
        frames starts from the axis that cleared the last one, usually the only one tested.
        """
        out = int(-1)
        if first >= 0:
            if beyond_on(a[first], d[first], grow[first], lower[first], upper[first]) == 1:
                out = first
        if out < 0:
            for i in range(3):
                if out < 0 and i != first:
                    if beyond_on(a[i], d[i], grow[i], lower[i], upper[i]) == 1:
                        out = i
        return out

    @wp.func(inline=True)
    def envelope_beyond_on(a: scalar, v: scalar, g: scalar, t: scalar, dt: scalar, frames: int,
                           grow: scalar, lower: scalar, upper: scalar):
        """1 when :func:`beyond_on` passes every one of ``frames`` free frames from the
        coordinate ``a`` [m] with the velocity ``v`` [m/s] under gravity ``g`` [m/s^2] on one
        axis, ``t = frames dt`` [s], each frame's path grown by ``grow`` [m].

        The frames' chords lie on the parabola ``a + v s + g s^2 / 2``, ``s`` in ``[0, t]``,
        so within ``[lo, hi]`` (each of ``v`` and ``g`` counted only on the side it moves
        to), and each frame's reach is at most the one of a path from ``lo`` along ``hi -
        lo``. The floats follow the parabola to ``drift``: the step's rounding of the
        coordinate and of the velocity over ``frames`` frames and of this test
        (``HORIZON_ULPS``), which errs early: 0 only means "test each frame"."""
        half_tt = HALF * t * t
        lo = a + wp.min(v, ZERO) * t + wp.min(g, ZERO) * half_tt
        hi = a + wp.max(v, ZERO) * t + wp.max(g, ZERO) * half_tt
        span = hi - lo
        big = wp.max(wp.abs(lo), wp.abs(hi))
        k = scalar(frames + 1)
        drift = HORIZON_SLACK * k * (big + span + grow
                                     + k * dt * (wp.abs(v) + wp.abs(g) * (t + dt)))
        reach = grow * SLACK + PAD_REL * (big + span + grow) + drift
        out = int(0)
        if hi + reach < lower or lo - reach > upper:
            out = 1
        return out

    @wp.func(inline=True)
    def horizon_clear(x: vec3, v: vec3, grow: vec3, physics: Physics, boxes: Boxes, first: int,
                      frames: int):
        """The axis (-1: none; from ``first``, then the others) on which each of the next
        ``frames`` free frames from ``x`` [m] with the velocity ``v`` [m/s], their paths grown
        by ``grow`` [m] per axis (:func:`path_grow`), certainly passes the frame's own test
        (:func:`clear_of_boxes`): then those frames are free without a test, the same answer
        as testing each (:func:`envelope_beyond_on`)."""
        g = physics.gravity
        dt = physics.dt
        t = scalar(frames) * dt
        lower = boxes.lower
        upper = boxes.upper
        out = int(-1)
        if envelope_beyond_on(x[first], v[first], g[first], t, dt, frames, grow[first],
                              lower[first], upper[first]) == 1:
            out = first
        if out < 0:
            for i in range(3):
                if out < 0 and i != first:
                    if envelope_beyond_on(x[i], v[i], g[i], t, dt, frames, grow[i], lower[i],
                                          upper[i]) == 1:
                        out = i
        return out

    @wp.func(inline=True)
    def free_reset(x: vec3, v: vec3, energy: scalar, m: scalar, physics: Physics):
        """The energy reset of a frame without supports (both motions' settling, and a run of
        free frames): ``v`` [m/s] against the energy ``E`` [J] at ``x`` [m] through its part
        along gravity, raised back only with the correction."""
        return energy_along_gravity(v, energy, m, physics.gravity, x, physics.origin, RAISE)

    @wp.func(inline=True)
    def linear_grow(r: scalar, physics: Physics):
        """How far [m] per axis the sphere reaches beyond the linear frame's chord: ``r``."""
        return vec3(r, r, r)

    @wp.func(inline=True)
    def linear_clear(x: vec3, v: vec3, r: scalar, physics: Physics, boxes: Boxes, first: int):
        """The axis (-1: none) on which the linear frame's chord from ``x`` [m] with the
        velocity ``v`` [m/s] at the frame's start lies beyond every box's bounds
        (:func:`clear_of_boxes`, from axis ``first``)."""
        d = (v + physics.gravity * (HALF * physics.dt)) * physics.dt
        return clear_of_boxes(x, d, linear_grow(r, physics), boxes.lower, boxes.upper, first)

    @wp.func(inline=True)
    def linear_free(x: vec3, v: vec3, physics: Physics):
        """The linear frame without contact: the chord ``(v + g dt / 2) dt`` and the velocity
        at its end, ``v + g dt`` (``bounce.bounce_path``'s no-contact arithmetic)."""
        half_kick = physics.gravity * (HALF * physics.dt)
        w = v + half_kick
        return x + w * physics.dt, w + half_kick

    @wp.func(inline=True)
    def linear_settle(x: vec3, v: vec3, L: vec3, o: quat, energy: scalar, r: scalar,
                      m: scalar, physics: Physics, supports: int):
        """The linear frame after its move: the energy reset (a frame with ``supports``
        resting contacts keeps the lower of the two energies) and the orientation."""
        gravity = physics.gravity
        origin = physics.origin
        if supports > 0:
            # a resting contact is inelastic: keep the state and take its energy when that is
            # lower by more than rounding; never more: a state above E (rounding on a long
            # slide) has its speed scaled down, along the surface it slides on
            ep = potential(m, gravity, x, origin)
            state_energy = kinetic_energy(m, v) + ep
            slack = RESET_SLACK * (wp.abs(energy) + wp.abs(ep))
            if energy - state_energy > slack:
                energy = state_energy
            elif state_energy - energy > slack:
                have = kinetic_energy(m, v)
                kinetic = energy - ep
                if kinetic <= ZERO or have <= ZERO:
                    v = vec3(ZERO, ZERO, ZERO)
                else:
                    v = v * wp.sqrt(kinetic / have)
        else:
            v = free_reset(x, v, energy, m, physics)
        if wp.static(spin):
            rot = rotation_vector(L, inertia(m, r), physics.max_rot)
            o = integrate_orientation(o, rot, physics.dt)
        return v, o, energy

    @wp.func(inline=True)
    def ballistic_grow(r: scalar, physics: Physics):
        """How far [m] per axis the sphere reaches beyond the ballistic frame's chord: the
        sagitta ``|g| dt^2 / 8`` and the radius (as ``nearest_arc.arc_path``)."""
        gravity = physics.gravity
        k = EIGHTH * physics.dt * physics.dt
        return vec3(wp.abs(gravity[0]) * k + r, wp.abs(gravity[1]) * k + r,
                    wp.abs(gravity[2]) * k + r)

    @wp.func(inline=True)
    def ballistic_clear(x: vec3, v: vec3, r: scalar, physics: Physics, boxes: Boxes,
                        first: int):
        """The axis (-1: none) on which the ballistic frame's arc from ``x`` [m] with the
        velocity ``v`` [m/s] lies beyond every box's bounds: its chord's bounds grown by
        :func:`ballistic_grow` (:func:`clear_of_boxes`, from axis ``first``)."""
        gravity = physics.gravity
        dt = physics.dt
        return clear_of_boxes(x, dt * (v + (HALF * dt) * gravity), ballistic_grow(r, physics),
                              boxes.lower, boxes.upper, first)

    @wp.func(inline=True)
    def ballistic_free(x: vec3, v: vec3, physics: Physics):
        """The ballistic frame without contact: the parabola's point and velocity at ``dt``
        (``ballistic.ballistic_path``'s no-contact arithmetic)."""
        return arc_point(x, v, physics.gravity, physics.dt), v + physics.dt * physics.gravity

    @wp.func(inline=True)
    def ballistic_settle(x: vec3, v: vec3, L: vec3, o: quat, energy: scalar, r: scalar,
                         m: scalar, physics: Physics, supports: int):
        """The ballistic frame after its move: the speed against the energy bound (raised
        back only with the correction) and the orientation. After a frame with supports
        (the sphere may be sliding) the speed is scaled, its direction kept along the
        surface; otherwise only the part along gravity changes (the sideways speed kept)."""
        if supports > 0:
            v = energy_along_velocity(v, energy, m, physics.gravity, x, physics.origin, RAISE)
        else:
            v = free_reset(x, v, energy, m, physics)
        if wp.static(spin):
            rot = rotation_vector(L, inertia(m, r), physics.max_rot)
            o = integrate_orientation(o, rot, physics.dt)
        return v, o, energy

    if motion == "ballistic":
        frame_clear, free_move, settle = ballistic_clear, ballistic_free, ballistic_settle
        path_grow = ballistic_grow
    else:
        frame_clear, free_move, settle = linear_clear, linear_free, linear_settle
        path_grow = linear_grow

    @wp.func(inline=True)
    def spin_turn(L: vec3, o: quat, r: scalar, m: scalar, physics: Physics):
        """The orientation's turn over one frame of a free run (``L`` [kg m^2/s] never changes
        there), computed once a run: ``dynamics.orientation_step`` of the rotation vector;
        ``turned`` applies it, the arithmetic of ``integrate_orientation``."""
        return orientation_step(o, rotation_vector(L, inertia(m, r), physics.max_rot),
                                physics.dt)

    @wp.func(inline=True)
    def nothing_held():
        """What a frame that is not held returns for :func:`held_frame`: ``(held, rest,
        box, s, n, held_counts)`` = ``(0, 0, -1, 0, 0, 0)``."""
        return int(0), ZERO, int(-1), ZERO, vec3(ZERO, ZERO, ZERO), wp.vec3i(0, 0, 0)

    @wp.func(inline=True)
    def one_frame(x: vec3, v: vec3, L: vec3, o: quat, energy: scalar, r: scalar, m: scalar,
                  physics: Physics, boxes: Boxes, broad: BroadPhase, frame: int, sphere: int,
                  events: EventBuffer):
        """One frame of the motion model compiled in; returns the state and the frame's
        counts. ``v`` is the velocity at the frame's start, and the one at its end comes back.

        Free flight when the frame's path meets no box's bounds (:func:`linear_clear`,
        :func:`ballistic_clear`): the loop's own arithmetic for a frame without contact, without
        its call. Then the settling: the linear model's chord keeps the energy exactly in free
        flight, so its reset changes nothing there and only removes drift; the ballistic motion
        keeps the energy itself, so without the correction its speed is only ever lowered to
        the energy bound (float error is never turned into a gain), with it the rounding drift
        is put back through the component along gravity.
        """
        bounces = int(0)
        capped = int(0)
        supports = int(0)
        clear = int(-1)
        held, rest, box, s, n, _counts = nothing_held()
        if wp.static(free_flight):
            clear = frame_clear(x, v, r, physics, boxes, -1)
        if clear >= 0:
            x, v = free_move(x, v, physics)
        else:
            if wp.static(defer):
                x, v, L, energy, bounces, capped, supports, held, rest, box, s, n = path(
                    x, v, r, m, L, energy, physics, boxes, broad, frame, sphere, events)
            else:
                x, v, L, energy, bounces, capped, supports = path(
                    x, v, r, m, L, energy, physics, boxes, broad, frame, sphere, events)
        if held == 0:
            v, o, energy = settle(x, v, L, o, energy, r, m, physics, supports)
        return x, v, L, o, energy, bounces, capped, supports, held, rest, box, s, n

    @wp.func(inline=True)
    def counted_frame(live: int, x: vec3, v: vec3, L: vec3, o: quat, energy: scalar,
                      r: scalar, m: scalar, physics: Physics, boxes: Boxes, broad: BroadPhase,
                      frame: int, sphere: int, events: EventBuffer, bounces: int, supports: int,
                      capped: int):
        """:func:`one_frame` for a sphere that exists (``live`` 1; 0: the state stays), its
        counts added to the launch's (bounces that reflect, supports, capped frames). A
        ballistic frame held at a contact that may be a support (``held`` 1) comes back as
        :func:`one_frame` leaves it, with its own counts (``held_counts``: bounces, capped,
        supports), for :func:`held_frame`."""
        held, rest, box, s, n, held_counts = nothing_held()
        if live == 1:
            x, v, L, o, energy, b, c, sp, held, rest, box, s, n = one_frame(
                x, v, L, o, energy, r, m, physics, boxes, broad, frame, sphere, events)
            if held == 0:
                bounces += b - sp
                supports += sp
                capped += c
            else:
                held_counts = wp.vec3i(b, c, sp)
        return x, v, L, o, energy, bounces, supports, capped, held, rest, box, s, n, held_counts

    @wp.func(inline=True)
    def record_frame(f: int, frame_count: int, record_every: int, row: int, i: int,
                     with_motion: bool, x: vec3, v: vec3, L: vec3, o: quat, r: scalar,
                     m: scalar, physics: Physics, orientation_in: wp.array[quat],
                     record_position_out: wp.array2d[vec3],
                     record_orientation_out: wp.array2d[quat],
                     record_velocity_out: wp.array2d[vec3],
                     record_angular_velocity_out: wp.array2d[vec3]):
        """Sphere ``i``'s record of the launch's frame ``f`` (from 0) into row ``row`` when it
        is one in ``record_every`` or the launch's last; returns the next row."""
        if record_every > 0:
            if (f + 1) % record_every == 0 or f + 1 == frame_count:
                record_position_out[row, i] = x
                if wp.static(spin):
                    record_orientation_out[row, i] = o
                else:
                    record_orientation_out[row, i] = orientation_in[i]
                if with_motion:
                    record_velocity_out[row, i] = v
                    if wp.static(spin):
                        record_angular_velocity_out[row, i] = rotation_vector(
                            L, inertia(m, r), physics.max_rot)
                    else:
                        record_angular_velocity_out[row, i] = vec3()
                row += 1
        return row

    @wp.func(inline=True)
    def held_frame(f: int, frame_count: int, record_every: int, row: int, i: int,
                   with_motion: bool, x: vec3, v: vec3, L_held: vec3, o_held: quat, L: vec3,
                   o: quat, energy: scalar, r: scalar, m: scalar, physics: Physics,
                   boxes: Boxes, broad: BroadPhase, sphere: int, events: EventBuffer,
                   rest: scalar, box: int, s: scalar, n: vec3, held_counts: wp.vec3i,
                   bounces: int, supports: int, capped: int, orientation_in: wp.array[quat],
                   record_position_out: wp.array2d[vec3],
                   record_orientation_out: wp.array2d[quat],
                   record_velocity_out: wp.array2d[vec3],
                   record_angular_velocity_out: wp.array2d[vec3]):
        """The launch's frame ``f`` that :func:`counted_frame` held (its state, ``L_held`` and
        ``o_held`` and its own counts as it returned them), finished from its contact with
        ``box`` at ``s`` [s] along the leg (normal ``n``, ``rest`` [s] of the frame left):
        ``held_rest``, the settling, the counts and the record, as :func:`one_frame` and
        :func:`counted_frame` would have made them, the kernel's ``L`` and ``o`` updated where
        they are the loop's (spin). Returns the state, the counts and the next record row."""
        if wp.static(defer):
            x, v, L_held, energy, b, c, sp = held_rest(
                x, v, L_held, energy, rest, held_counts[0], held_counts[1], held_counts[2], r,
                m, physics, boxes, broad, f + 1, sphere, events, box, s, n)
            v, o_held, energy = settle(x, v, L_held, o_held, energy, r, m, physics, sp)
            bounces += b - sp
            supports += sp
            capped += c
            if wp.static(spin):
                L = L_held
                o = o_held
        row = record_frame(f, frame_count, record_every, row, i, with_motion, x, v, L, o, r, m,
                           physics, orientation_in, record_position_out,
                           record_orientation_out, record_velocity_out,
                           record_angular_velocity_out)
        return x, v, L, o, energy, bounces, supports, capped, row

    @variant_kernel
    def advance_frames(
        # Model:
        boxes: Boxes,
        broad: BroadPhase,
        physics: Physics,
        radius: wp.array[scalar],
        mass: wp.array[scalar],
        birth_frame: wp.array[wp.int32],
        frame_count: int,
        record_every: int,
        sphere_offset: int,
        first_frame: int,
        spheres_per_task: int,
        # In:
        position_in: wp.array[vec3],
        velocity_in: wp.array[vec3],
        energy_in: wp.array[scalar],
        angular_momentum_in: wp.array[vec3],
        orientation_in: wp.array[quat],
        # Out:
        position_out: wp.array[vec3],
        velocity_out: wp.array[vec3],
        energy_out: wp.array[scalar],
        angular_momentum_out: wp.array[vec3],
        orientation_out: wp.array[quat],
        bounce_count_out: wp.array[wp.int32],
        support_count_out: wp.array[wp.int32],
        capped_count_out: wp.array[wp.int32],
        record_position_out: wp.array2d[vec3],
        record_orientation_out: wp.array2d[quat],
        record_velocity_out: wp.array2d[vec3],
        record_angular_velocity_out: wp.array2d[vec3],
        events_out: EventBuffer,
    ):
        # each task advances a block of spheres, one after another: a task first copies the
        # launch's arguments (on the CPU about 230 instructions a task, since a store to an
        # output array may alias them), which one sphere a task paid once per sphere and
        # launch (BENCHMARKS.md, "A launch's cost per sphere"); on a GPU a block is one sphere
        i = wp.tid() * spheres_per_task
        last = wp.min(i + spheres_per_task, position_in.shape[0])
        while i < last:
            sphere = sphere_offset + i
            r = radius[i]
            m = mass[i]
            x = position_in[i]
            v = velocity_in[i]
            energy = energy_in[i]
            L = vec3()
            o = quat()
            if wp.static(spin):
                L = angular_momentum_in[i]
                o = orientation_in[i]
            bounces = int(0)
            supports = int(0)
            capped = int(0)
            row = int(0)
            with_motion = record_velocity_out.shape[0] > 0
            born = int(0)
            if wp.static(births):
                born = birth_frame[i] - first_frame  # frames of this launch before its birth
            # a ballistic frame held at a contact that may be a support: its state and counts
            # (counted_frame), finished outside the inner loop of frames (held_frame)
            held, rest, box, s, n, held_counts = nothing_held()
            L_new = L
            o_new = o
            f = int(0)
            if wp.static(free_flight):
                # a frame beyond every box's bounds takes the free step; a run of them goes on in
                # a loop of its own, with no call of the bounce loop in it (the same moves, bits)
                grow = path_grow(r, physics)
                age = first_frame  # the sphere's age after the launch's frame f is age + f + 1
                if wp.static(births):
                    age = first_frame - birth_frame[i]
            # free flight: the test of frame f: an axis, -1 (not free), -2 (not made)
            free = int(-2)
            while f < frame_count:
                if wp.static(free_flight):
                    while held == 0 and f < frame_count:
                        live = int(1)
                        if wp.static(births):
                            if f < born:
                                live = 0
                        if live == 1 and free == -2:
                            free = frame_clear(x, v, r, physics, boxes, -1)
                        if live == 1 and free >= 0:
                            turn_by = o
                            turning = int(0)
                            if wp.static(spin):
                                turn_by, turning = spin_turn(L, o, r, m, physics)
                            # frames to the next energy reset: an age multiple of RESET_EVERY
                            to_reset = RESET_EVERY - (age + f) % RESET_EVERY
                            while free >= 0 and f < frame_count:
                                # frames to take untested: up to the next reset, record and the
                                # launch's end, when they and the frame after them are proven clear
                                k = wp.min(to_reset, frame_count - f)
                                if record_every > 0:
                                    k = wp.min(k, record_every - f % record_every)
                                after = int(-2)  # the test of the frame after them
                                if wp.static(horizon):
                                    sure = horizon_clear(x, v, grow, physics, boxes, free, k + 1)
                                    if sure >= 0:
                                        free = sure
                                        after = sure
                                    else:
                                        k = 1
                                else:
                                    k = 1
                                taken = int(0)  # a while loop: see candidates.nearest_cell
                                while taken < k:
                                    x, v = free_move(x, v, physics)
                                    if wp.static(spin):
                                        o = turned(o, turn_by, turning)
                                    taken += 1
                                f += k
                                to_reset -= k
                                # the last frame's energy reset: at an age multiple of
                                # RESET_EVERY, and before a frame that is not free (tested at the
                                # launch's end too, so that the state is that of any other split
                                # into launches)
                                reset = int(0)
                                if to_reset == 0:
                                    reset = 1
                                    to_reset = RESET_EVERY
                                elif after == -2:
                                    after = frame_clear(x, v, r, physics, boxes, free)
                                    if after < 0:
                                        reset = 1
                                if reset == 1:
                                    v = free_reset(x, v, energy, m, physics)
                                    after = -2
                                    if f < frame_count:
                                        after = frame_clear(x, v, r, physics, boxes, free)
                                row = record_frame(f - 1, frame_count, record_every, row, i,
                                                   with_motion, x, v, L, o, r, m, physics,
                                                   orientation_in, record_position_out,
                                                   record_orientation_out, record_velocity_out,
                                                   record_angular_velocity_out)
                                free = after
                        else:
                            (x, v, L_new, o_new, energy, bounces, supports, capped, held, rest,
                             box, s, n, held_counts) = counted_frame(
                                live, x, v, L, o, energy, r, m, physics, boxes, broad, f + 1,
                                sphere, events_out, bounces, supports, capped)
                            if held == 0:
                                if wp.static(spin):  # else L and o are not the loop's
                                    L = L_new
                                    o = o_new
                                row = record_frame(f, frame_count, record_every, row, i,
                                                   with_motion, x, v, L, o, r, m, physics,
                                                   orientation_in, record_position_out,
                                                   record_orientation_out, record_velocity_out,
                                                   record_angular_velocity_out)
                                f += 1
                                free = -2
                else:
                    while held == 0 and f < frame_count:
                        live = int(1)
                        if wp.static(births):
                            if f < born:
                                live = 0
                        (x, v, L_new, o_new, energy, bounces, supports, capped, held, rest, box, s,
                         n, held_counts) = counted_frame(
                            live, x, v, L, o, energy, r, m, physics, boxes, broad, f + 1, sphere,
                            events_out, bounces, supports, capped)
                        if held == 0:
                            if wp.static(spin):  # else L and o are not the loop's
                                L = L_new
                                o = o_new
                            row = record_frame(f, frame_count, record_every, row, i, with_motion,
                                               x, v, L, o, r, m, physics, orientation_in,
                                               record_position_out, record_orientation_out,
                                               record_velocity_out, record_angular_velocity_out)
                            f += 1
                if held == 1:
                    x, v, L, o, energy, bounces, supports, capped, row = held_frame(
                        f, frame_count, record_every, row, i, with_motion, x, v, L_new, o_new, L,
                        o, energy, r, m, physics, boxes, broad, sphere, events_out, rest, box, s,
                        n, held_counts, bounces, supports, capped, orientation_in,
                        record_position_out, record_orientation_out, record_velocity_out,
                        record_angular_velocity_out)
                    held = 0
                    f += 1
                    free = -2
            position_out[i] = x
            velocity_out[i] = v
            energy_out[i] = energy
            if wp.static(spin):
                angular_momentum_out[i] = L
                orientation_out[i] = o
            bounce_count_out[i] += bounces
            support_count_out[i] += supports
            capped_count_out[i] += capped
            i += 1

    return advance_frames
