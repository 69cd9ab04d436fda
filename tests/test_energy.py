"""The one energy scale (``warpsim.energy``) against hand-computed answers, and its invariance
to where heights are measured from."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import warpsim as ws
from warpsim import energy

FLOOR = ws.RoundedBoxes(center=[[0.0, -0.5, 0.0]], half_extents=[[5.0, 0.5, 5.0]])


def test_the_scale_is_the_energy_above_the_lowest_point():
    """A 2 kg sphere 3 m above a floor whose bottom is at y = -1, moving at 4 m/s."""
    g, m, y, v = 9.81, 2.0, 3.0, 4.0
    low, high = energy.region_bounds(FLOOR, [[0.0, y, 0.0]])
    np.testing.assert_array_equal(low, [-5.0, -1.0, -5.0])
    np.testing.assert_array_equal(high, [5.0, 3.0, 5.0])
    lowest = energy.lowest_potential((0.0, -g, 0.0), FLOOR, [[0.0, y, 0.0]])
    assert lowest == g * -1.0  # -g . x at the floor's bottom
    e0 = 0.5 * m * v * v + m * g * y
    np.testing.assert_allclose(energy.energy_scale([e0], [m], lowest),
                               [0.5 * m * v * v + m * g * (y + 1.0)], rtol=1e-15)
    assert energy.energy_scale([-1.0], [1.0], 0.0)[0] == energy.ENERGY_FLOOR


@settings(max_examples=50, deadline=None)
@given(st.floats(-100, 100), st.floats(-100, 100), st.floats(-100, 100))
def test_the_scale_does_not_depend_on_the_origin_of_heights(ox, oy, oz):
    g = np.array([0.0, -9.81, 0.0])
    m = np.array([1.0, 3.0])
    start = np.array([[0.0, 2.0, 0.0], [1.0, 0.5, -2.0]])
    speed2 = np.array([1.0, 9.0])

    def scale(origin):
        e0 = 0.5 * m * speed2 - m * ((start - origin) @ g)
        return energy.energy_scale(e0, m, energy.lowest_potential(g, FLOOR, start, origin))

    np.testing.assert_allclose(scale(np.array([ox, oy, oz])), scale(np.zeros(3)), rtol=1e-9,
                               atol=1e-9)


def test_a_run_starts_with_no_change(device):
    scene = ws.Scene(FLOOR)
    swarm = ws.Swarm([[0.0, 1.0, 0.0], [1.0, 2.0, 0.0]], [[1.0, 0.0, 0.0]] * 2, radius=0.1)
    sim = ws.Simulator(scene, swarm, device=device, precision="float64")
    np.testing.assert_allclose(energy.relative_change(sim, swarm.position), 0.0, atol=1e-12)
