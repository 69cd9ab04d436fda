"""Resting contacts are counted apart from bounces (``Stats.supports``, the frame kernel's
``support_count_out``): analytic cases and the contact table's own kinds."""

import math

import numpy as np
import pytest

import warpsim as ws
from warpsim.vocabulary import ContactKind

G = 9.81
MOTIONS = ("linear", "ballistic")


def floor() -> ws.RoundedBoxes:
    """A floor whose top face is the plane y = 0."""
    return ws.RoundedBoxes(center=[[0.0, -0.5, 0.0]], half_extents=[[5.0, 0.5, 5.0]])


@pytest.mark.parametrize("motion", MOTIONS)
def test_a_ball_at_rest_on_a_floor_makes_no_bounce_and_one_support_a_frame(precision, motion):
    """At rest on the floor, gravity pressing it on: every frame's contact is a support, none
    is a bounce, and the ball stays where it is."""
    r, frames = 0.1, 30
    sim = ws.Simulator(ws.Scene(floor(), motion=motion),
                       ws.Swarm([[0.0, r, 0.0]], [[0.0, 0.0, 0.0]], radius=r),
                       precision=precision, device="cpu")
    traj = sim.run(frames, events=True)
    stats = sim.stats
    assert stats.bounces == 0
    assert stats.supports == frames
    assert stats.contacts == frames
    assert np.all(traj.events.kind == ContactKind.SUPPORT)
    np.testing.assert_array_equal(sim.state().position[0], np.array([0.0, r, 0.0],
                                                                    dtype=sim.state().position.dtype))


@pytest.mark.parametrize("motion", MOTIONS)
def test_a_dropped_ball_counts_its_bounces(precision, motion):
    """Dropped from h onto an elastic floor it bounces at t0 (1 + 2k), t0 = sqrt(2 h / g): in
    T seconds floor((T / t0 + 1) / 2) bounces, and nothing rests."""
    h, r, dt, seconds = 1.0, 0.1, 1.0 / 60.0, 2.0
    sim = ws.Simulator(ws.Scene(floor(), motion=motion),
                       ws.Swarm([[0.0, h + r, 0.0]], [[0.25, 0.0, 0.0]], radius=r), dt=dt,
                       precision=precision, device="cpu")
    traj = sim.run(round(seconds / dt), events=True)
    t0 = math.sqrt(2.0 * h / G)
    assert sim.stats.bounces == math.floor((seconds / t0 + 1.0) / 2.0)
    assert sim.stats.supports == 0
    assert len(traj.events) == sim.stats.contacts


@pytest.mark.parametrize("motion", MOTIONS)
def test_the_counters_match_the_contact_tables_kinds(motion):
    """A swarm that bounces and comes to rest (the galton scene): the kernel's two counters are
    the contact table's bounces and supports, row for row."""
    scene = ws.Scene.load("galton")
    sim = ws.Simulator(scene, scene.spawn(n=64, seed=5), motion=motion, device="cpu")
    traj = sim.run(240, every=60, events=True)
    events = traj.events
    assert events.dropped == 0
    supports = int(np.count_nonzero(events.kind == ContactKind.SUPPORT))
    assert sim.stats.supports == supports > 0
    assert sim.stats.bounces == len(events) - supports > 0
