"""Host-side passes done in blocks of rows on several threads give what the whole-array formula
gives, bit for bit: the helpers themselves (``warpsim.blocks``), and every pass that uses them,
against its formula written out over the whole arrays, with tiny blocks on more threads than
blocks' worth of cores so that every block boundary and thread interleaving is exercised."""

import dataclasses

import numpy as np
import pytest
from helpers import emitter_velocity_formula

import warpsim as ws
from warpsim import blocks, broad_phase, energy, feasibility, validation
from warpsim.emitter import Emitter
from warpsim.simulator import _starts_in_free_flight


@pytest.fixture(params=[1, 3, 7, 64])
def tiny_blocks(request, monkeypatch):
    """Blocks of 1 to 64 rows, on 3 threads."""
    monkeypatch.setattr(blocks, "ROW_BLOCK", request.param)
    monkeypatch.setattr(blocks, "host_cores", lambda: 3)
    return request.param


@pytest.mark.parametrize("n", [0, 1, 5, 64, 65, 200])
@pytest.mark.parametrize("size", [1, 4, 64])
def test_row_blocks_cover_every_row_once_in_order(n, size):
    parts = blocks.row_blocks(n, size)
    rows = np.concatenate([np.arange(n)[p] for p in parts]) if parts else np.zeros(0)
    assert rows.tolist() == list(range(n))
    assert all(0 < p.stop - p.start <= size for p in parts)


def test_map_row_blocks_keeps_the_order_and_raises_the_first_error(tiny_blocks):
    n = 50
    got = blocks.map_row_blocks(n, lambda rows: (rows.start, rows.stop))
    assert got == [(p.start, p.stop) for p in blocks.row_blocks(n)]

    def fail(rows):
        if rows.start <= 10 < rows.stop or rows.start <= 30 < rows.stop:
            raise ValueError(f"row {rows.start}")
        return rows.start

    with pytest.raises(ValueError, match="row"):
        blocks.map_row_blocks(n, fail)


@pytest.mark.parametrize("offset", [0, 1, 2, 3, 1000, 3 * 70_001])
@pytest.mark.parametrize("seed", [0, 12345])
def test_stream_at_continues_a_serial_draw(offset, seed):
    serial = np.random.default_rng(seed)
    before = dict(serial.bit_generator.state)
    whole = serial.uniform(-2.0, 5.0, size=offset + 40)
    rng = np.random.default_rng(seed)
    state = rng.bit_generator.state
    part = blocks.stream_at(state, offset).uniform(-2.0, 5.0, size=40)
    assert part.tobytes() == whole[offset:].tobytes()
    assert rng.bit_generator.state == before  # the source generator is untouched


EMITTERS = [
    Emitter(count=1, velocity=(1.0, -2.0, 0.5), velocity_jitter=(0.5, 0.0, 0.25)),
    Emitter(count=1, speed=(1.0, 300.0), cone_deg=10.0, direction=(0.3, -1.0, 2.0),
            velocity=(-0.0, 1.0, 0.0), velocity_jitter=(0.0, 2.0, 0.0)),
    Emitter(count=1, speed=(0.0, 60.0), cone_deg=180.0, direction=(1.0, 0.0, 0.0)),
]


@pytest.mark.parametrize("emitter", EMITTERS)
@pytest.mark.parametrize("n", [1, 50, 131])
def test_emitter_velocities_in_blocks_are_the_serial_formula(emitter, n, tiny_blocks):
    """The blocked draw is the serial draw from one generator, bit for bit, and leaves the
    generator where the serial draw leaves it."""
    rng = np.random.default_rng(3)
    got = emitter._velocities(rng, n, emitter._cone())
    serial = np.random.default_rng(3)
    assert got.tobytes() == emitter_velocity_formula(emitter, serial, n).tobytes()
    assert rng.random() == serial.random()


def test_emitter_positions_in_blocks_are_the_serial_draws(tiny_blocks):
    """Start positions, redraws included (half the region is inside a block): each centre is
    the serial stream's draw, the first clear one of its turns (an independent loop over the
    draws), and every centre is clear."""
    box = ws.RoundedBoxes(center=[[0.0, 0.0, 0.0]], half_extents=[[0.5, 1.0, 1.0]],
                          radius=[0.1])
    e = Emitter(count=97, half_extents=(1.0, 0.5, 0.5), radius=0.05, seed=11)
    swarm = e.spawn(box)
    position_stream = np.random.default_rng(np.random.SeedSequence(11).spawn(4)[3])
    center, half = np.asarray(e.center), np.asarray(e.half_extents)
    expected = center + half * position_stream.uniform(-1.0, 1.0, size=(97, 3))
    need = swarm.radius + e.clearance
    pending = np.arange(97)
    for _ in range(200):
        clear = box.signed_distance(expected[pending])[:, 0] >= need[pending]
        pending = pending[~clear]
        if pending.size == 0:
            break
        expected[pending] = center + half * position_stream.uniform(-1.0, 1.0,
                                                                   size=(pending.size, 3))
    assert swarm.position.tobytes() == expected.tobytes()


def room_swarm(n: int, seed: int = 5) -> tuple[ws.Scene, ws.Swarm]:
    scene = ws.Scene.load("room")
    emitter = dataclasses.replace(scene.emitter, count=n)
    return scene, emitter.spawn(scene.boxes, seed=seed)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_initial_energy_in_blocks_is_the_formula(precision, tiny_blocks):
    scene, swarm = room_swarm(150)
    sim = ws.Simulator(scene, swarm, device="cpu", precision=precision, workers=1)
    dtype = np.float32 if precision == "float32" else np.float64
    p = swarm.position.astype(dtype).astype(np.float64)
    v = swarm.velocity.astype(dtype).astype(np.float64)
    g = np.asarray(scene.gravity, dtype=np.float64)
    expected = (0.5 * swarm.mass * np.einsum("ij,ij->i", v, v)
                - swarm.mass * ((p - sim.energy_origin) @ g))
    assert np.asarray(sim.initial_energy).tobytes() == expected.tobytes()


def test_reach_in_blocks_is_the_formula(tiny_blocks):
    rng = np.random.default_rng(2)
    n = 123
    position = rng.normal(size=(n, 3)) * 3.0
    velocity = rng.normal(size=(n, 3)) * 7.0
    radius = rng.uniform(0.0, 0.2, size=n)
    g, dt = np.array([0.0, -9.81, 0.0]), 1.0 / 60.0
    for lowest in (None, -40.0):
        speed2 = np.einsum("ij,ij->i", velocity, velocity)
        if lowest is not None:
            speed2 = speed2 + 2.0 * np.maximum(-(position @ g) - lowest, 0.0)
        half_path = 0.5 * (np.sqrt(speed2) + float(np.linalg.norm(g)) * dt) * dt
        expected = broad_phase.REACH_FACTOR * float(
            np.quantile(half_path + radius, broad_phase.REACH_QUANTILE))
        assert broad_phase.reach(position, velocity, radius, g, dt, lowest) == expected


def test_region_bounds_and_norms_in_blocks_are_the_formula(tiny_blocks):
    rng = np.random.default_rng(4)
    p = rng.normal(size=(77, 3)) * np.array([1.0, 1e3, 1e-3])
    p[40] = [1e200, -1e200, 0.0]  # norms without overflow in the squares
    p[41] = 0.0
    low, high = energy.region_bounds(ws.RoundedBoxes(center=np.zeros((0, 3)),
                                                     half_extents=np.zeros((0, 3))), p)
    assert low.tolist() == p.min(axis=0).tolist() and high.tolist() == p.max(axis=0).tolist()
    scale = np.abs(p).max(axis=1)
    safe = np.where(scale > 0.0, scale, 1.0)
    expected = scale * np.linalg.norm(p / safe[:, None], axis=1)
    assert feasibility._norms(p).tobytes() == expected.tobytes()


@pytest.mark.parametrize("bad_rows", [[0], [5], [6, 2], [64, 65], [129]])
def test_the_first_non_finite_row_is_named_across_blocks(bad_rows, tiny_blocks):
    arr = np.ones((130, 3))
    for i in bad_rows:
        arr[i, i % 3] = np.nan if i % 2 else np.inf
    with pytest.raises(ValueError, match=rf"^position\[{min(bad_rows)}\] must be finite"):
        validation.vec3_array("position", arr)


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("side", [-1.0, 1.0])
@pytest.mark.parametrize("where", [0, 31, 99])
def test_free_flight_choice_in_blocks_is_the_direct_test(axis, side, where, tiny_blocks):
    """A sphere placed wholly beyond the obstacles' bounds on one side of one axis, or just
    touching them (not beyond), at any row: the blocked choice is the direct test's."""
    scene, swarm = room_swarm(100)
    from warpsim.device import bvh_bounds
    lower, upper = bvh_bounds(scene.boxes.center, scene.boxes.world_extent())
    lo, hi = lower.min(axis=0), upper.max(axis=0)
    for beyond in (True, False):
        position = swarm.position.copy()
        r = swarm.radius[where]
        edge = hi[axis] + r if side > 0 else lo[axis] - r
        position[where, axis] = edge + side * 1e-6 if beyond else edge
        moved = ws.Swarm(position=position, velocity=swarm.velocity, radius=swarm.radius,
                         mass=swarm.mass)
        rr = moved.radius[:, None]
        direct = bool(np.any(moved.position - rr > hi) or np.any(moved.position + rr < lo))
        assert direct or not beyond  # the case is what it says
        assert _starts_in_free_flight(scene.boxes, moved) == direct


@pytest.mark.parametrize("q", [(0.0, 0.0, 0.0, 1.0), (1.0, 2.0, -2.0, 4.0), (0.0, -0.0, 3.0, 0.0)])
def test_one_orientation_for_all_in_blocks_is_the_tiled_row(q, tiny_blocks):
    got = validation.unit_quat_array("orientation", q, 131)
    row = np.asarray(q, dtype=np.float64)
    norm = np.linalg.norm(row)
    row = row if abs(norm - 1.0) <= validation.UNIT_SLACK else row / norm
    assert got.shape == (131, 4)
    assert got.tobytes() == np.tile(row, (131, 1)).tobytes()


@pytest.mark.parametrize("bad", [0, 5, 64, 130])
def test_the_first_too_large_row_is_named_across_blocks(bad, tiny_blocks):
    """The start checks' per-row magnitudes in blocks: the first row whose coordinate, or whose
    angular momentum, float32 cannot square is the one named."""
    scene, swarm = room_swarm(131)
    position = swarm.position.copy()
    position[bad, 1] = -1e30
    position[min(bad + 7, 130), 0] = 1e30
    moved = ws.Swarm(position=position, velocity=swarm.velocity, radius=swarm.radius,
                     mass=swarm.mass)
    with pytest.raises(ValueError, match=rf"^position\[{bad}\] .* too large for float32"):
        feasibility.check_run(scene, moved, scene.dt, "float32", 8)
    spin = np.zeros((131, 3))
    spin[bad, 2] = -1e39
    spun = ws.Swarm(position=swarm.position, velocity=swarm.velocity, radius=swarm.radius,
                    mass=swarm.mass, angular_momentum=spin)
    with pytest.raises(ValueError, match=rf"^angular_momentum\[{bad}\] .* too large"):
        feasibility.check_run(scene, spun, scene.dt, "float32", 8)


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("width", [1, 3, 4])
def test_upload_in_blocks_is_the_cast(precision, width, tiny_blocks):
    """The device copy of host values (``model.to_device``): each value rounded once to the
    precision, as a whole-array cast rounds it, into an array of its own (not a view of the
    input)."""
    from warpsim.kernels import precision as fp
    from warpsim.model import to_device

    p = fp.precision(precision)
    dtype = {1: p.scalar, 3: p.vec3, 4: p.quat}[width]
    rng = np.random.default_rng(width)
    values = rng.normal(size=(133, width)) * 10.0 ** rng.integers(-30, 30, size=(133, 1))
    values = values[:, 0] if width == 1 else values
    out = to_device(values, dtype, p, "cpu")
    assert out.dtype == dtype and out.shape == (133,)
    got = out.numpy()
    assert got.tobytes() == np.ascontiguousarray(values, dtype=p.np_dtype).tobytes()
    values[:] = 0.0
    assert out.numpy().tobytes() == got.tobytes()  # not a view of the input


@pytest.mark.parametrize("n", [0, 1, 64, 131])
@pytest.mark.parametrize("low,high", [(0.0, 1.0), (0.02, 0.02), (-3.0, 5.0)])
def test_uniform_rows_are_the_serial_draw(n, low, high, tiny_blocks):
    rng, serial = np.random.default_rng(9), np.random.default_rng(9)
    got = blocks.uniform_rows(rng, low, high, n)
    assert got.tobytes() == serial.uniform(low, high, size=n).tobytes()
    assert rng.random() == serial.random()


def test_the_simulator_shares_the_swarms_frozen_arrays():
    """Masses, radii and birth frames are the swarm's own read-only arrays, not copies: a
    write into them is refused (it would not reach the device anyway)."""
    scene, swarm = room_swarm(20)
    sim = ws.Simulator(scene, swarm, device="cpu", workers=1)
    assert sim.mass is swarm.mass and sim.birth_frame is swarm.birth_frame
    for array in (sim.mass, sim.birth_frame):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = 1


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int32, np.uint16])
def test_input_arrays_are_copied_in_blocks_to_float64(dtype, tiny_blocks):
    """A numeric array given for a swarm's field is copied, in blocks, to float64 values of
    its own: the whole-array conversion's values, strided inputs included, never a view."""
    rng = np.random.default_rng(1)
    base = (rng.normal(size=(140, 6)) * 1000).astype(dtype)
    value = base[::2, 1::2]  # strided rows and columns
    got = validation.vec3_array("position", value)
    assert got.dtype == np.float64 and got.tobytes() == np.array(value, np.float64).tobytes()
    base[:] = 0
    assert np.any(got != 0.0)  # its own copy


def test_scalars_are_checked_once_and_named_without_an_index(tiny_blocks):
    assert validation.per_item("radius", 0.5, 70).tolist() == [0.5] * 70
    assert np.signbit(validation.per_item("radius", -0.0, 3, minimum=0.0)).all()
    with pytest.raises(ValueError, match=r"^radius must be >= 0, got -1$"):
        validation.per_item("radius", -1.0, 70, minimum=0.0)
    with pytest.raises(ValueError, match=r"^mass must be > 0, got 0$"):
        validation.per_item("mass", 0.0, 70, positive=True)
    assert validation.frame_array("birth_frame", 0, 70).tolist() == [0] * 70
    assert validation.frame_array("birth_frame", np.uint8(7), 5).tolist() == [7] * 5
    with pytest.raises(ValueError, match=r"^birth_frame must be >= 0, got -3$"):
        validation.frame_array("birth_frame", -3, 70)
    with pytest.raises(ValueError, match=r"^birth_frame\[4\] must be below 2\*\*31"):
        validation.frame_array("birth_frame", [0, 1, 2, 3, 2**31], 5)


@pytest.mark.parametrize("where", [None, 0, 63, 64, 130])
def test_spin_and_births_are_found_in_any_block(where, tiny_blocks):
    """A single spinning sphere, or a single one born late, at any row, is seen."""
    scene, swarm = room_swarm(131)
    spin = np.zeros((131, 3))
    births = np.zeros(131, dtype=np.int64)
    if where is not None:
        spin[where, 2] = -1e-300
        births[where] = 3
    spun = ws.Swarm(position=swarm.position, velocity=swarm.velocity, radius=swarm.radius,
                    mass=swarm.mass, angular_momentum=spin, birth_frame=births)
    assert spun.has_births == (where is not None)
    assert ws.Simulator(scene, spun, device="cpu", workers=1).spin == (where is not None)


def _digest_formula(*arrays):
    """``blocks.digest`` written out serially: the header and the blocks' SHA-256 in order."""
    import hashlib

    whole = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        whole.update(f"{a.dtype.str}{a.shape}".encode())
        rows = a.reshape(a.shape[0], int(np.prod(a.shape[1:]))) if a.ndim else a.reshape(1, 1)
        for part in blocks.row_blocks(rows.shape[0]):
            whole.update(hashlib.sha256(rows[part].tobytes()).digest())
    return whole.digest()


@pytest.mark.parametrize("n", [0, 1, 2, 63, 64, 65, 130])
def test_digest_is_its_formula_and_sees_every_change(tiny_blocks, n):
    """The digest of a few arrays (an (n, 3) float64, an (n,) one, a small (4, 4) one and a
    0-d one) is its serial formula, bit for bit; flipping any one bit of any value, swapping
    two rows, reshaping an array and writing -0.0 for 0.0 each change it."""
    rng = np.random.default_rng(n)
    arrays = [rng.normal(size=(n, 3)), rng.uniform(size=n), rng.normal(size=(4, 4)),
              np.array(2.5)]
    base = blocks.digest(*arrays)
    assert base == _digest_formula(*arrays) == blocks.digest(*[a.copy() for a in arrays])
    flips = [(j, i) for j, a in enumerate(arrays) if a.size
             for i in rng.integers(0, a.size, 3)]
    for j, i in flips:
        for bit in rng.integers(0, 64, 4):
            changed = [a.copy() for a in arrays]
            flat = changed[j].reshape(-1).view(np.uint64)
            flat[i] ^= np.uint64(1) << np.uint64(bit)
            assert blocks.digest(*changed) != base, (j, i, bit)
    if n >= 2:
        swapped = [a.copy() for a in arrays]
        swapped[0][[0, n - 1]] = swapped[0][[n - 1, 0]]
        assert blocks.digest(*swapped) != base
    reshaped = [arrays[0], arrays[1], arrays[2].reshape(2, 8), arrays[3]]
    assert blocks.digest(*reshaped) != base
    zeros = np.zeros(5)
    assert blocks.digest(zeros) != blocks.digest(-zeros)


@pytest.mark.parametrize("n", [0, 1, 63, 64, 65, 130])
@pytest.mark.parametrize("shape", [(), (3,), (4,)])
def test_copy_and_fill_rows_are_the_whole_array_assignment(tiny_blocks, n, shape):
    """``copy_rows`` (float64 into float64 and into float32, NumPy's cast) and ``fill_rows``
    (one row, or one value, for every row) against ``out[:] = ...`` on the whole array; a copy
    of another number of rows is refused."""
    rng = np.random.default_rng(n)
    values = rng.normal(size=(n, *shape)) * 10.0 ** rng.integers(-30, 30, (n, *shape))
    for dtype in (np.float64, np.float32):
        whole = np.empty((n, *shape), dtype=dtype)
        whole[:] = values
        got = blocks.copy_rows(np.empty((n, *shape), dtype=dtype), values)
        assert got.dtype == dtype and got.tobytes() == whole.tobytes()
    row = rng.normal(size=shape)
    for fill in (row, 2.5):
        whole = np.empty((n, *shape))
        whole[:] = fill
        assert blocks.fill_rows(np.empty((n, *shape)), fill).tobytes() == whole.tobytes()
    with pytest.raises(ValueError, match="rows"):
        blocks.copy_rows(np.empty((n + 1, *shape)), values)
