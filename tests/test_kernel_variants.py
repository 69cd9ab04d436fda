"""Every kernel every factory can return: no backward code, and arguments found by name.

The factories are enumerated over all their feature flags (``helpers.kernel_variant_specs``,
the enumeration the ahead-of-time GPU build also uses); making a kernel object compiles nothing
(that happens at a launch), so the whole product is checked. Each variant is made in its own
test, not while the module is collected: every test process collects the whole suite, and
making the 540 variants took about 45 s (Warp hashes each one's code to name its module).
"""

import numpy as np
import pytest
from helpers import kernel_variant_specs

import warpsim as ws
from warpsim.kernels.collide_kernels import collide_kernel
from warpsim.kernels.data import Features
from warpsim.kernels.variant import KERNEL_OPTIONS, OPTIMIZATION_LEVEL
from warpsim.model import (
    DeviceState,
    Model,
    Spheres,
    event_buffer,
    kernel_arguments,
    parameter_names,
)

SPECS = {label: (factory, features) for label, factory, features in kernel_variant_specs()}


@pytest.mark.slow
@pytest.mark.parametrize("label", list(SPECS))
def test_kernel_variant(label):
    """The variant's kernel and module carry no backward code; its module is built at level 2
    on every device, not Warp's GPU default of 3 (a 246 s first build of the ballistic kernel
    on an H200 against 2.9 s, at the same speed); and every parameter is a model field, a
    sphere constant, ``<state field>_in`` or an output ending in ``_out``, so the launch helper
    finds each by name, never by position."""
    factory, features = SPECS[label]
    kernel = factory(features)
    for key, value in KERNEL_OPTIONS.items():
        assert kernel.options.get(key) is value, label
        assert kernel.module.options.get(key) is value, label
    assert OPTIMIZATION_LEVEL == 2
    assert kernel.module.options.get("optimization_level") == OPTIMIZATION_LEVEL, label
    assert_parameters_are_fields(label, kernel)


def model_fields() -> set[str]:
    return {f for f in Model.__dataclass_fields__}


def state_fields() -> set[str]:
    return {f for f in DeviceState.__dataclass_fields__}


COLLIDE_OUTPUTS = {"box_out", "t_out", "contact_out", "normal_out", "new_position_out",
                   "new_velocity_out"}
BOUNCE_OUTPUTS = {"bounces_out", "supports_out", "capped_out", "position_out", "velocity_out",
                  "angular_momentum_out"}
FRAME_COUNTERS = {"bounce_count_out", "support_count_out", "capped_count_out",
                  "record_position_out",
                  "record_orientation_out", "record_velocity_out",
                  "record_angular_velocity_out"}
#: Plain per-launch values (the launch helper's ``values``).
LAUNCH_VALUES = {"frame_count", "record_every", "sphere_offset", "first_frame",
                 "spheres_per_task"}
#: Outputs of a whole launch (the launch helper's ``launch_outputs``).
EVENT_OUTPUTS = {"events_out"}


def assert_parameters_are_fields(label, kernel):
    """Every parameter of ``kernel`` is a model field, a sphere constant, ``<state field>_in`` or
    an output ending in ``_out``."""
    sphere_fields = set(Spheres.__dataclass_fields__)
    outputs = COLLIDE_OUTPUTS | BOUNCE_OUTPUTS | FRAME_COUNTERS | EVENT_OUTPUTS
    for name in parameter_names(kernel):
        if name.endswith("_in"):
            assert name[:-3] in state_fields(), (label, name)
        elif name.endswith("_out"):
            assert name[:-4] in state_fields() or name in outputs, (label, name)
        else:
            assert name in model_fields() | sphere_fields | LAUNCH_VALUES, (label, name)


def test_every_simulator_argument_is_the_named_array():
    """The frame kernel's arguments, as the simulator assembles them, are the very arrays of the
    named fields (a swapped pair of same-typed arrays would fail here)."""
    boxes = ws.RoundedBoxes(center=[[0, 0, 0], [3, 0, 0]], half_extents=[[1, 0.1, 1]] * 2)
    swarm = ws.Swarm(position=[[0, 1, 0], [3, 1, 0]], velocity=[[1, 0, 0], [0, 1, 0]],
                     radius=0.1)
    sim = ws.Simulator(ws.Scene(boxes, friction=0.1), swarm, device="cpu")
    records = sim._records(2, True)
    events = {"events_out": event_buffer(sim.model.precision, sim.device, 4)}
    values = {"frame_count": 3, "record_every": 2, "sphere_offset": 0, "first_frame": 0,
              "spheres_per_task": 1}
    args = kernel_arguments(sim._kernel, model=sim.model, spheres=sim.spheres,
                            state_in=sim.state_0, state_out=sim.state_1,
                            outputs={**sim.counters, **records}, launch_outputs=events,
                            values=values)
    for name, value in zip(parameter_names(sim._kernel), args, strict=True):
        if name.endswith("_in"):
            assert value is getattr(sim.state_0, name[:-3])
        elif name.endswith("_out") and name[:-4] in state_fields():
            assert value is getattr(sim.state_1, name[:-4])
        elif name.endswith("_out"):
            assert value is {**sim.counters, **records, **events}[name]
        elif name in LAUNCH_VALUES:
            assert value == values[name]
        elif name in model_fields():
            assert value is getattr(sim.model, name)
        else:
            assert value is getattr(sim.spheres, name)


def test_missing_or_ambiguous_source_is_an_error():
    kernel = collide_kernel(Features())
    with pytest.raises(KeyError, match="no source provides parameter 'boxes'"):
        kernel_arguments(kernel, state_in={}, outputs={})
    sim_boxes = ws.RoundedBoxes(center=[[0, 0, 0]], half_extents=[[1, 1, 1]])
    sim = ws.Simulator(ws.Scene(sim_boxes), ws.Swarm([[0, 3, 0]], [[0, 0, 0]]), device="cpu")
    with pytest.raises(KeyError, match="both"):
        kernel_arguments(sim._kernel, model=sim.model, spheres=sim.spheres,
                         values={"physics": np.float32(0.1)}, state_in=sim.state_0,
                         state_out=sim.state_1, outputs=sim.counters)


def test_model_structs_hold_the_named_data():
    """Inside the model's structs every field holds its own quantity, in the boxes' order: the
    host values (float64, independent of the device copy) come back field by field."""
    rng = np.random.default_rng(5)
    q = rng.normal(size=(3, 4))
    boxes = ws.RoundedBoxes(center=rng.uniform(-3, 3, (3, 3)),
                            half_extents=rng.uniform(0.1, 1, (3, 3)),
                            rotation=q / np.linalg.norm(q, axis=1, keepdims=True),
                            radius=[0.0, 0.05, 0.2])
    scene = ws.Scene(boxes, gravity=(0.5, -9.0, 0.25), friction=0.3, energy_retention=0.75,
                     max_angular_speed=20.0)
    sim = ws.Simulator(scene, ws.Swarm([[0, 9, 0]], [[0, 0, 0]], radius=0.1), device="cpu",
                       precision="float64", max_bounces=5)
    m = sim.model
    expected = {"center": boxes.center, "rotation": boxes.rotation_matrices(),
                "half_extents": boxes.half_extents, "radius": boxes.radius,
                "extent": boxes.world_extent()}
    for name, host in expected.items():
        assert np.array_equal(getattr(m.boxes, name).numpy(), host), name
    ph = m.physics
    assert tuple(ph.gravity) == (0.5, -9.0, 0.25)
    assert tuple(ph.origin) == tuple(sim.energy_origin)
    assert (float(ph.dt), float(ph.friction), float(ph.max_rot), float(ph.retention),
            int(ph.max_bounces)) == (sim.dt, 0.3, 20.0, 0.75, 5)
