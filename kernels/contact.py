"""The bookkeeping of one contact, shared by the chord's and the parabola's bounce loops.

Both loops (``bounce.bounce_path``, ``ballistic.ballistic_path``) find the contact and reflect
the motion in their own way; what a contact does besides is the same and written here once: the
friction torque on the angular momentum (SPEC "Spin"), one row of the launch's event buffer, and
the energy a lossy bounce gives up. Each is compiled in only when the kernel is built with that
feature (``data.Features``): without it the func is the identity and leaves no code.
"""

from functools import cache
from types import SimpleNamespace

import warp as wp

from .data import model_structs
from .dynamics import dynamics_funcs
from .precision import Precision


@cache
def contact_funcs(p: Precision, spin: bool, lossy: bool, events: bool) -> SimpleNamespace:
    """Build the contact bookkeeping for one precision and feature set.

    Returns:
        Namespace with ``spin`` (:func:`contact_spin`), ``event`` (``write_event``), ``keep``
        (``retention_keep``) and ``loss`` (``bounce_loss``).
    """
    scalar, vec3 = p.scalar, p.vec3
    with_events = events  # the name is the buffer's inside a func
    _, _, Physics, EventBuffer = model_structs(p)
    dyn = dynamics_funcs(p)
    friction_spin, potential = dyn.friction_spin, dyn.potential
    ONE = scalar(1.0)

    @wp.func(inline=True)
    def contact_spin(L: vec3, u: vec3, n: vec3, r: scalar, m: scalar, physics: Physics):
        """The angular momentum [kg m^2/s] after a contact of normal ``n`` at velocity ``u``
        [m/s] (``dynamics.friction_spin``); ``L`` itself without spin."""
        out = L
        if wp.static(spin):
            out = friction_spin(L, u, n, r, m, physics.dt, physics.friction, physics.max_rot)
        return out

    @wp.func(inline=True)
    def write_event(frame: int, sphere: int, box: int, resting: int, contact: vec3, n: vec3,
                    fraction: scalar, speed: scalar, events: EventBuffer):
        """Append one contact to the launch's event buffer (``data.model_structs``'
        ``EventBuffer``; counted even when it is full); nothing without events."""
        if wp.static(with_events):
            row = wp.atomic_add(events.count, 0, 1)
            if row < events.index.shape[0]:
                events.index[row, 0] = frame
                events.index[row, 1] = sphere
                events.index[row, 2] = box
                events.index[row, 3] = resting
                events.vector[row, 0] = contact
                events.vector[row, 1] = n
                events.value[row, 0] = fraction
                events.value[row, 1] = speed

    @wp.func(inline=True)
    def retention_keep(physics: Physics):
        """The factor a lossy bounce scales the speed by, ``sqrt(retention)``; 1 elastic."""
        keep = ONE
        if wp.static(lossy):
            keep = wp.sqrt(physics.retention)
        return keep

    @wp.func(inline=True)
    def bounce_loss(energy: scalar, m: scalar, contact: vec3, physics: Physics):
        """The energy [J] after a lossy bounce at ``contact`` [m]: the kinetic part
        ``E - Ep`` scaled by ``retention``; ``energy`` itself elastic."""
        out = energy
        if wp.static(lossy):
            ep = potential(m, physics.gravity, contact, physics.origin)
            out = ep + physics.retention * (energy - ep)
        return out

    return SimpleNamespace(spin=contact_spin, event=write_event, keep=retention_keep,
                           loss=bounce_loss)
