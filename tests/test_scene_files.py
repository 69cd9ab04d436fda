"""Scene files (TOML) and emitters: loading, validation messages, grids, rotations, spawning.

No Warp kernel runs here: everything is host-side numpy.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest
from helpers import TEST_SALT

import warpsim
from warpsim.emitter import Emitter
from warpsim.obstacles import RoundedBoxes, quat_to_matrix
from warpsim.scene import Scene
from warpsim.scene_files import SceneFileError, euler_deg_to_quat, list_scenes

load_scene = Scene.load

BUNDLED = ("galton", "nozzle", "pinball", "room", "spin", "staircase", "thin-walls", "wedge")

# One floor slab, three unit cubes (box[1..3]) and an emitter well clear of all of them.
MINIMAL = """\
[[box]]
center = [0.0, -1.0, 0.0]
half_extents = [5.0, 0.5, 5.0]

[[box]]
center = [3.0, 0.0, 0.0]
half_extents = [0.5, 0.5, 0.5]

[[box]]
center = [-3.0, 0.0, 0.0]
half_extents = [0.5, 0.5, 0.5]

[[box]]
center = [0.0, 0.0, 3.0]
half_extents = [0.5, 0.5, 0.5]

[emitter]
count = 5
center = [0.0, 1.0, 0.0]
"""


def write(tmp_path: Path, text: str, name: str = "scene.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def swarm_arrays(swarm) -> dict[str, np.ndarray]:
    return {f: getattr(swarm, f) for f in ("position", "velocity", "radius", "mass",
                                           "angular_momentum", "orientation")}


# --- bundled scenes --------------------------------------------------------------------------


def test_list_scenes_names_sorted_with_one_line_descriptions():
    scenes = list_scenes()
    names = [name for name, _ in scenes]
    assert names == sorted(names)
    assert set(BUNDLED) <= set(names)
    for name, description in scenes:
        assert description.strip(), name
        assert "\n" not in description
    assert warpsim.list_scenes() == scenes


@pytest.mark.parametrize("name", BUNDLED)
def test_bundled_scene_loads(name):
    scene = load_scene(name)
    assert isinstance(scene, Scene)
    assert scene.name == name
    assert scene.description == dict(list_scenes())[name]
    assert Path(scene.source).name == f"{name}.toml"
    assert Path(scene.source).is_file()
    assert isinstance(scene.emitter, Emitter)
    assert len(scene.boxes) >= 6  # a closed room, at least
    # Quick on a laptop CPU: moderate counts, sensible steps.
    assert scene.emitter.count <= 5000
    assert 0.0 < scene.dt <= 1.0 / 30.0
    assert scene.frames * scene.dt <= 10.0


@pytest.mark.slow
@pytest.mark.parametrize("name", BUNDLED)
def test_bundled_scene_spawns_deterministically_and_clear_of_obstacles(name):
    scene = load_scene(name)
    a, b, c = scene.spawn(seed=1), scene.spawn(seed=1), scene.spawn(seed=2)
    assert len(a) == scene.emitter.count
    for field, value in swarm_arrays(a).items():
        assert np.array_equal(value, swarm_arrays(b)[field]), field
    assert not np.array_equal(a.position, c.position)
    assert np.array_equal(scene.spawn().position, scene.spawn(seed=scene.emitter.seed).position)

    for swarm in (a, c):
        distance = scene.boxes.signed_distance(swarm.position)
        assert (distance >= swarm.radius[:, None]).all(), "a sphere starts inside or touching"
        # Spawned among the obstacles, not outside the whole scene.
        reach = scene.boxes.bounding_radius()[:, None]
        assert (swarm.position >= (scene.boxes.center - reach).min(axis=0)).all()
        assert (swarm.position <= (scene.boxes.center + reach).max(axis=0)).all()


def test_thin_walls_has_paper_thin_and_rotated_plates():
    boxes = load_scene("thin-walls").boxes
    thinnest = boxes.half_extents.min(axis=1)
    assert (thinnest == 0.0).sum() >= 2
    assert (thinnest == 1e-4).sum() >= 2
    rotated = np.abs(np.abs(boxes.rotation[:, 3]) - 1.0) > 1e-9
    assert rotated.sum() >= 4
    assert (load_scene("thin-walls").spawn().radius <= 0.011).all()


@pytest.mark.skipif(TEST_SALT is not None, reason="the room file holds the draws of the "
                    "generator's own seed (WARPSIM_TEST_SALT moves them)")
def test_room_is_the_benchmark_standard_room():
    from standard_room import standard_room

    boxes = load_scene("room").boxes
    assert len(boxes) == 22
    rotated = np.abs(np.abs(boxes.rotation[:, 3]) - 1.0) > 1e-9
    assert rotated.sum() == 16
    reference = standard_room()
    for field in ("center", "half_extents", "rotation", "radius"):
        assert np.allclose(getattr(boxes, field), getattr(reference, field), rtol=0.0,
                           atol=1e-12), field


def test_load_by_name_path_string_and_path_agree():
    by_name = load_scene("room")
    by_path = load_scene(Path(by_name.source))
    by_str = load_scene(by_name.source)
    assert by_name.boxes == by_path.boxes == by_str.boxes
    assert by_name.emitter == by_path.emitter == by_str.emitter
    assert Scene.load("room").boxes == by_name.boxes


# --- user files and defaults -----------------------------------------------------------------


def test_scene_by_path_uses_documented_defaults(tmp_path):
    path = write(tmp_path, MINIMAL, "my-scene.toml")
    scene = load_scene(path)
    assert scene.name == "my-scene"
    assert scene.description == ""
    assert scene.source == str(path)
    assert scene.dt == 1.0 / 60.0 and scene.frames == 240 and scene.max_bounces == 8
    assert scene.gravity.tolist() == [0.0, -9.81, 0.0]
    assert scene.friction == 0.0 and scene.energy_retention == 1.0
    assert scene.energy_correction is True and scene.max_angular_speed == 50.0
    assert len(scene.boxes) == 4
    assert scene.boxes.radius.tolist() == [0.0] * 4
    assert scene.boxes.rotation.tolist() == [[0.0, 0.0, 0.0, 1.0]] * 4
    assert scene.emitter == Emitter(count=5, center=(0.0, 1.0, 0.0))
    e = scene.emitter
    assert (e.half_extents, e.radius, e.mass) == ((0.5, 0.5, 0.5), (0.05, 0.05), (1.0, 1.0))
    assert (e.velocity, e.velocity_jitter, e.speed) == ((0.0,) * 3, (0.0,) * 3, None)
    assert (e.seed, e.angular_momentum) == (0, (0.0,) * 3)
    assert (e.direction, e.cone_deg) == (None, None)  # they shape the speed term only


def test_every_setting_is_read(tmp_path):
    text = MINIMAL.replace("count = 5", (
        "count = 4\nhalf_extents = [0.2, 0.3, 0.4]\nradius = [0.01, 0.02]\nmass = [1.0, 2.0]\n"
        "velocity = [1.0, 2.0, 3.0]\nvelocity_jitter = [0.1, 0.0, 0.1]\nspeed = [3.0, 4.0]\n"
        "direction = [0.0, 0.0, 2.0]\ncone_deg = 10.0\nangular_momentum = [0.0, 0.5, 0.0]\n"
        "seed = 7\nclearance = 0.01"))
    text = ('name = "custom"\ndescription = "one line"\n'
            "[simulation]\ndt = 0.005\nframes = 10\nmax_bounces = 3\n"
            "[physics]\ngravity = [0.0, 0.0, -1.0]\nfriction = 0.5\nenergy_retention = 0.9\n"
            "energy_correction = false\nmax_angular_speed = 20.0\n" + text)
    scene = load_scene(write(tmp_path, text))
    assert (scene.name, scene.description) == ("custom", "one line")
    assert (scene.dt, scene.frames, scene.max_bounces) == (0.005, 10, 3)
    assert scene.gravity.tolist() == [0.0, 0.0, -1.0]
    assert (scene.friction, scene.energy_retention, scene.energy_correction,
            scene.max_angular_speed) == (0.5, 0.9, False, 20.0)
    assert scene.emitter == Emitter(
        count=4, center=(0.0, 1.0, 0.0), half_extents=(0.2, 0.3, 0.4), radius=(0.01, 0.02),
        mass=(1.0, 2.0), velocity=(1.0, 2.0, 3.0), velocity_jitter=(0.1, 0.0, 0.1),
        speed=(3.0, 4.0), direction=(0.0, 0.0, 2.0), cone_deg=10.0,
        angular_momentum=(0.0, 0.5, 0.0), seed=7, clearance=0.01)


# --- error messages --------------------------------------------------------------------------


def _replace_box(index: int, extra: str, half_extents: str = "[0.5, 0.5, 0.5]") -> str:
    """MINIMAL with box[index] (1..3) given other half extents and extra lines."""
    blocks = MINIMAL.split("[[box]]\n")
    lines = blocks[index + 1].splitlines()
    lines[1] = f"half_extents = {half_extents}"
    blocks[index + 1] = "\n".join(lines[:2] + [extra, ""] + lines[2:]) + "\n"
    return "[[box]]\n".join(blocks)


GRID = ("[[box_grid]]\norigin = [0.0, 0.0, 0.0]\ncount = [2, 2, 1]\nspacing = [1.0, 1.0, 1.0]\n"
        "half_extents = [0.1, 0.1, 0.1]\n")

# (name, file text, the whole message after "<path>: ")
ERROR_CASES = [
    ("unknown key with suggestion", MINIMAL.replace("[[box]]\ncenter = [0.0, 0.0, 3.0]",
                                                    "[[box]]\ncentre = [0.0, 0.0, 3.0]"),
     "unknown key 'centre' in box[3]; did you mean 'center'?"),
    ("negative half extent", _replace_box(2, "", "[0.5, -0.1, 0.5]"),
     "box[2].half_extents[1] must be >= 0, got -0.1"),
    ("zero quaternion", _replace_box(2, "rotation = [0.0, 0.0, 0.0, 0.0]"),
     "box[2].rotation must be a finite non-zero quaternion (x, y, z, w), got (0, 0, 0, 0)"),
    ("nan quaternion", _replace_box(3, "rotation = [0.0, nan, 0.0, 1.0]"),
     "box[3].rotation must be a finite non-zero quaternion (x, y, z, w), got (0, nan, 0, 1)"),
    ("short quaternion", _replace_box(1, "rotation = [0.0, 0.0, 1.0]"),
     "box[1].rotation must be a quaternion (x, y, z, w), got shape (3,)"),
    ("rotation and rotation_deg", _replace_box(1, "rotation = [0.0, 0.0, 0.0, 1.0]\n"
                                                  "rotation_deg = [0.0, 0.0, 90.0]"),
     "box[1]: give either rotation (quaternion) or rotation_deg (Euler angles), not both"),
    ("string in rotation_deg", _replace_box(2, 'rotation_deg = [0.0, "90", 0.0]'),
     "box[2].rotation_deg[1] must be a number, got '90'"),
    ("negative rounding radius", _replace_box(3, "radius = -0.5"),
     "box[3].radius must be >= 0, got -0.5"),
    ("string radius", _replace_box(3, 'radius = "0.1"'),
     "box[3].radius must be a number, got '0.1'"),
    ("infinite centre", MINIMAL.replace("[3.0, 0.0, 0.0]", "[inf, 0.0, 0.0]"),
     "box[1].center must be finite, got (inf, 0, 0)"),
    ("boolean as number", _replace_box(1, "", "[0.5, true, 0.5]"),
     "box[1].half_extents[1] must be a number, got True"),
    ("integer too large for a float", _replace_box(1, "", "[0.5, 0.5, 0.5]").replace(
        "[3.0, 0.0, 0.0]", "[3.0, 0.0, " + "9" * 400 + "]"),
     "box[1].center must be a number a float64 can hold, got [3.0, 0.0, " + "9" * 46 + "..."),
    ("missing centre", MINIMAL.replace("center = [3.0, 0.0, 0.0]\n", ""),
     "box[1].center is required"),
    ("single [box] table", "[box]\ncenter = [0.0, 0.0, 0.0]\nhalf_extents = [1.0, 1.0, 1.0]\n"
                           "[emitter]\ncount = 1\n",
     "box must be written [[box]] (an array of tables), not [box]"),
    ("no obstacles", "[emitter]\ncount = 1\n",
     "no obstacles: add at least one [[box]] or [[box_grid]] table"),
    ("missing emitter", MINIMAL.split("[emitter]")[0],
     "missing [emitter] table (its count is required)"),
    ("missing emitter count", MINIMAL.replace("count = 5\n", ""), "emitter.count is required"),
    ("unknown emitter key", MINIMAL.replace("count = 5", "count = 5\nvelocity_spread = 1.0"),
     "unknown key 'velocity_spread' in [emitter]; did you mean 'velocity'?"),
    ("emitter radius range reversed", MINIMAL.replace("count = 5", "count = 5\n"
                                                      "radius = [0.2, 0.1]"),
     "emitter.radius must be a scalar or [min, max] with min <= max, got [0.2, 0.1]"),
    ("emitter negative radius", MINIMAL.replace("count = 5", "count = 5\nradius = [-0.1, 0.1]"),
     "emitter.radius[0] must be >= 0, got -0.1"),
    ("emitter boolean radius", MINIMAL.replace("count = 5", "count = 5\nradius = true"),
     "emitter.radius must be a number, got True"),
    ("emitter count not an integer", MINIMAL.replace("count = 5", "count = 5.0"),
     "emitter.count must be an integer, got 5.0"),
    ("emitter count of 2**31", MINIMAL.replace("count = 5", "count = 2147483648"),
     "emitter.count must be <= 2147483647 (integers must be below 2**31), got 2147483648"),
    ("emitter seed of 2**63", MINIMAL.replace("count = 5", "count = 5\nseed = "
                                              "9223372036854775807"),
     "emitter.seed must be <= 2147483647 (integers must be below 2**31), got "
     "9223372036854775807"),
    ("emitter direction without speed", MINIMAL.replace("count = 5", "count = 5\n"
                                                        "direction = [1.0, 0.0, 0.0]"),
     "emitter.direction only shapes the speed term: give emitter.speed too, or leave "
     "direction out"),
    ("emitter cone without speed", MINIMAL.replace("count = 5", "count = 5\ncone_deg = 10.0"),
     "emitter.cone_deg only shapes the speed term: give emitter.speed too, or leave "
     "cone_deg out"),
    ("emitter zero direction", MINIMAL.replace("count = 5", "count = 5\nspeed = 1.0\n"
                                               "direction = [0.0, 0.0, 0.0]"),
     "emitter.direction must be a non-zero vector, got (0, 0, 0)"),
    ("physics key at the top level", "friction = 0.3\n" + MINIMAL,
     "unknown key 'friction' in the top level; it belongs in the [physics] table"),
    ("unknown table", "[simulaton]\ndt = 0.01\n" + MINIMAL,
     "unknown key 'simulaton' in the top level; did you mean 'simulation'?"),
    ("bad dt", "[simulation]\ndt = 0.0\n" + MINIMAL, "simulation.dt must be > 0, got 0"),
    ("string dt", "[simulation]\ndt = \"0.01\"\n" + MINIMAL,
     "simulation.dt must be a number, got '0.01'"),
    ("bad frames", "[simulation]\nframes = 2.5\n" + MINIMAL,
     "simulation.frames must be an integer, got 2.5"),
    ("huge frames", "[simulation]\nframes = 4294967296\n" + MINIMAL,
     "simulation.frames must be <= 2147483647 (integers must be below 2**31), got 4294967296"),
    ("max_bounces above the cap", "[simulation]\nmax_bounces = 4294967296\n" + MINIMAL,
     "simulation.max_bounces must be <= 1024 (contacts per sphere per frame), got 4294967296"),
    ("max_bounces of 2**63 - 1", "[simulation]\nmax_bounces = 9223372036854775807\n" + MINIMAL,
     "simulation.max_bounces must be <= 1024 (contacts per sphere per frame), got "
     "9223372036854775807"),
    ("bad retention", "[physics]\nenergy_retention = 1.5\n" + MINIMAL,
     "physics.energy_retention must be <= 1, got 1.5"),
    ("energy_correction not a bool", "[physics]\nenergy_correction = 1\n" + MINIMAL,
     "physics.energy_correction must be true or false, got 1"),
    ("gravity with a boolean", "[physics]\ngravity = [0.0, false, 0.0]\n" + MINIMAL,
     "physics.gravity[1] must be a number, got False"),
    ("unknown physics key", "[physics]\ngravty = [0.0, 0.0, 0.0]\n" + MINIMAL,
     "unknown key 'gravty' in [physics]; did you mean 'gravity'?"),
    ("name not a string", "name = 3\n" + MINIMAL, "name must be a string, got 3"),
    ("grid zero count", MINIMAL + GRID.replace("[2, 2, 1]", "[2, 0, 1]"),
     "box_grid[0].count[1] must be >= 1, got 0"),
    ("grid float count", MINIMAL + GRID.replace("[2, 2, 1]", "[2, 2.0, 1]"),
     "box_grid[0].count[1] must be an integer, got 2.0"),
    ("grid huge count", MINIMAL + GRID.replace("[2, 2, 1]", "[2, 99999999999, 1]"),
     "box_grid[0].count[1] must be <= 2147483647 (integers must be below 2**31), got "
     "99999999999"),
    ("grid too many boxes", MINIMAL + GRID.replace("[2, 2, 1]", "[1000, 1000, 1]"),
     "box_grid[0].count [1000, 1000, 1] makes 1000000 boxes, more than 100000 in the scene "
     "with the 4 boxes before it"),
    ("grid bad stagger axis", MINIMAL + GRID + "stagger_axis = 'w'\n",
     "box_grid[0].stagger_axis must be one of 'x', 'y', 'z', got 'w'"),
    ("grid negative half extent", MINIMAL + GRID.replace("[0.1, 0.1, 0.1]", "[0.1, 0.1, -1.0]"),
     "box_grid[0].half_extents[2] must be >= 0, got -1"),
    ("grid missing spacing", MINIMAL + GRID.replace("spacing = [1.0, 1.0, 1.0]\n", ""),
     "box_grid[0].spacing is required"),
]


@pytest.mark.slow
@pytest.mark.parametrize("text, message", [c[1:] for c in ERROR_CASES],
                         ids=[c[0] for c in ERROR_CASES])
def test_bad_file_error_names_file_table_key_and_index(tmp_path, text, message):
    with pytest.raises(SceneFileError) as info:
        load_scene(write(tmp_path, text))
    assert isinstance(info.value, ValueError)
    assert str(info.value) == f"{tmp_path / 'scene.toml'}: {message}"


def test_toml_syntax_error_gives_file_and_line(tmp_path):
    text = MINIMAL.replace("count = 5", "count = = 5")
    line = text.splitlines().index("count = = 5") + 1
    with pytest.raises(ValueError, match=r"scene\.toml: invalid TOML: .*line " + str(line)):
        load_scene(write(tmp_path, text))


def test_unknown_scene_name_lists_the_bundled_ones():
    with pytest.raises(ValueError) as info:
        load_scene("rooom")
    message = str(info.value)
    assert "unknown scene 'rooom'" in message and "did you mean 'room'?" in message
    for name in BUNDLED:
        assert name in message


def test_missing_file_is_reported(tmp_path):
    with pytest.raises(ValueError, match=re.escape(f"{tmp_path / 'nope.toml'}: scene file not "
                                                   "found")):
        load_scene(tmp_path / "nope.toml")


# --- box grids and rotations -----------------------------------------------------------------


def test_box_grid_expands_after_boxes_with_stagger_on_odd_rows(tmp_path):
    text = MINIMAL + """
[[box_grid]]
origin = [10.0, 0.0, 0.0]
count = [3, 2, 1]
spacing = [1.0, 2.0, 0.0]
stagger = [0.5, 0.0, 0.0]
half_extents = [0.0, 0.0, 0.3]
radius = 0.1
rotation_deg = [0.0, 0.0, 90.0]

[[box_grid]]
origin = [0.0, 5.0, 0.0]
count = [1, 1, 3]
spacing = [0.0, 0.0, 0.5]
stagger = [0.0, 0.25, 0.0]
stagger_axis = "z"
half_extents = [0.1, 0.1, 0.1]
"""
    boxes = load_scene(write(tmp_path, text)).boxes
    assert len(boxes) == 4 + 6 + 3
    grid = boxes[4:10]
    assert grid.center.tolist() == [[10.0, 0.0, 0.0], [11.0, 0.0, 0.0], [12.0, 0.0, 0.0],
                                    [10.5, 2.0, 0.0], [11.5, 2.0, 0.0], [12.5, 2.0, 0.0]]
    assert (grid.half_extents == [0.0, 0.0, 0.3]).all() and (grid.radius == 0.1).all()
    assert np.allclose(grid.rotation, euler_deg_to_quat([0.0, 0.0, 90.0]))
    assert boxes[10:].center.tolist() == [[0.0, 5.0, 0.0], [0.0, 5.25, 0.5], [0.0, 5.0, 1.0]]
    assert boxes[:4] == load_scene(write(tmp_path, MINIMAL, "plain.toml")).boxes


def test_galton_pegs_are_staggered_rows():
    boxes = load_scene("galton").boxes
    pegs = boxes[boxes.radius == 0.01]
    assert len(pegs) == 14 * 10
    rows = np.unique(np.round(pegs.center[:, 1], 9))
    assert len(rows) == 10
    first = pegs.center[np.isclose(pegs.center[:, 1], rows[0]), 0]
    second = pegs.center[np.isclose(pegs.center[:, 1], rows[1]), 0]
    assert np.allclose(second - first, 0.04)


def test_rotation_deg_90_about_z_maps_local_x_to_world_y(tmp_path):
    text = _replace_box(1, "rotation_deg = [0.0, 0.0, 90.0]")
    q = load_scene(write(tmp_path, text)).boxes.rotation[1]
    m = quat_to_matrix(q)
    assert np.allclose(m @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    assert np.allclose(m @ [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], atol=1e-15)
    assert np.allclose(q, [0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)])


def _rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@pytest.mark.parametrize("angles", [(90.0, 0.0, 0.0), (0.0, 90.0, 0.0), (90.0, 0.0, 90.0),
                                    (30.0, -45.0, 120.0), (-170.0, 80.0, 5.0)])
def test_rotation_deg_is_extrinsic_x_then_y_then_z(angles):
    rx, ry, rz = np.radians(angles)
    expected = _rz(rz) @ _ry(ry) @ _rx(rx)
    q = euler_deg_to_quat(angles)
    assert math.isclose(np.linalg.norm(q), 1.0, rel_tol=1e-15)
    assert np.allclose(quat_to_matrix(q), expected, atol=1e-14)


def test_rotation_quaternion_is_normalised(tmp_path):
    text = _replace_box(1, "rotation = [0.0, 0.0, 2.0, 0.0]")
    assert load_scene(write(tmp_path, text)).boxes.rotation[1].tolist() == [0.0, 0.0, 1.0, 0.0]


# --- the emitter -----------------------------------------------------------------------------


FLOOR = RoundedBoxes(center=[[0.0, -1.0, 0.0]], half_extents=[[5.0, 0.5, 5.0]])


def test_emitter_velocity_jitter_and_ranges():
    e = Emitter(count=2000, center=(0.0, 1.0, 0.0), half_extents=(1.0, 0.2, 0.0),
                radius=(0.01, 0.02), mass=(2.0, 3.0), velocity=(1.0, -2.0, 0.0),
                velocity_jitter=(0.5, 0.0, 0.25), angular_momentum=(0.0, 0.0, 0.3))
    s = e.spawn(FLOOR)
    assert ((s.radius >= 0.01) & (s.radius <= 0.02)).all() and np.ptp(s.radius) > 0.009
    assert ((s.mass >= 2.0) & (s.mass <= 3.0)).all()
    assert (np.abs(s.position - [0.0, 1.0, 0.0]) <= [1.0, 0.2, 0.0]).all()
    assert (s.position[:, 2] == 0.0).all()
    assert (np.abs(s.velocity - [1.0, -2.0, 0.0]) <= [0.5, 0.0, 0.25]).all()
    assert (s.velocity[:, 1] == -2.0).all()
    assert (s.angular_momentum == [0.0, 0.0, 0.3]).all()
    assert (s.orientation == [0.0, 0.0, 0.0, 1.0]).all()


@pytest.mark.parametrize("emitter", [
    Emitter(count=1, velocity=(1.0, -2.0, 0.5), velocity_jitter=(0.5, 0.0, 0.25)),
    Emitter(count=1, speed=(1.0, 300.0), cone_deg=10.0, direction=(0.3, -1.0, 2.0),
            velocity=(-0.0, 1.0, 0.0), velocity_jitter=(0.0, 2.0, 0.0)),
    Emitter(count=1, speed=(5.0, 5.0), cone_deg=0.0, direction=(0.0, 0.0, -1.0)),
    Emitter(count=1, speed=(0.0, 60.0), cone_deg=180.0, direction=(1.0, 0.0, 0.0)),
])
def test_emitter_velocities_are_the_written_formula_bit_for_bit(emitter):
    """The draw's in-place arithmetic gives, bit for bit, the formula written out:
    ``v0 + j U + s (cos(theta) a + sin(theta) cos(phi) u + sin(theta) sin(phi) w)``."""
    from helpers import emitter_velocity_formula

    n = 4000
    got = emitter._velocities(np.random.default_rng(3), n, emitter._cone())
    assert got.tobytes() == emitter_velocity_formula(emitter, np.random.default_rng(3),
                                                     n).tobytes()


@pytest.mark.parametrize("spin", [(0.0, 0.0, 0.0), (-0.0, 0.0, 0.0), (0.0, 1e-300, 0.0)])
def test_emitter_angular_momentum_keeps_its_bits(spin):
    """Every sphere starts with the emitter's angular momentum, bit for bit (a negative zero
    too: a spinning kernel's arithmetic can carry its sign)."""
    s = Emitter(count=50, angular_momentum=spin).spawn(FLOOR)
    expected = np.tile(np.asarray(spin, dtype=np.float64), (50, 1))
    assert s.angular_momentum.shape == (50, 3)
    assert s.angular_momentum.tobytes() == expected.tobytes()


@pytest.mark.parametrize("cone_deg", [0.0, 20.0, 180.0])
def test_emitter_speed_range_and_cone(cone_deg):
    direction = np.array([1.0, 2.0, -2.0]) / 3.0
    e = Emitter(count=2000, center=(0.0, 2.0, 0.0), speed=(3.0, 4.0),
                direction=tuple(3.0 * direction), cone_deg=cone_deg)
    v = e.spawn(FLOOR).velocity
    speed = np.linalg.norm(v, axis=1)
    assert ((speed >= 3.0 - 1e-12) & (speed <= 4.0 + 1e-12)).all()
    cos_angle = (v / speed[:, None]) @ direction  # compared as cosines: arccos is ill-posed at 1
    assert (cos_angle >= math.cos(math.radians(cone_deg)) - 1e-12).all()
    if cone_deg == 180.0:  # isotropic: the mean direction is near zero
        assert np.linalg.norm((v / speed[:, None]).mean(axis=0)) < 0.1


def test_emitter_streams_are_independent_per_quantity():
    a = Emitter(count=50, center=(0.0, 1.0, 0.0))
    b = Emitter(count=50, center=(0.0, 1.0, 0.0), speed=5.0, velocity_jitter=(1.0, 1.0, 1.0))
    assert np.array_equal(a.spawn(FLOOR).position, b.spawn(FLOOR).position)
    assert len(a.spawn(FLOOR, n=7)) == 7


def test_emitter_rejects_and_resamples_near_obstacles():
    # The region straddles a block: about half of the first draws land inside it.
    block = RoundedBoxes(center=[[0.0, 0.0, 0.0]], half_extents=[[0.5, 1.0, 1.0]], radius=[0.1])
    s = Emitter(count=500, half_extents=(1.0, 0.5, 0.5), radius=0.05).spawn(block)
    distance = block.signed_distance(s.position)[:, 0]
    assert (distance >= s.radius + 1e-3).all()


def test_emitter_hopeless_region_stops_early_and_says_how_many_draws():
    block = RoundedBoxes(center=[[0.0, 0.0, 0.0]], half_extents=[[2.0, 2.0, 2.0]])
    with pytest.raises(ValueError) as info:
        Emitter(count=10).spawn(block)
    assert str(info.value) == (
        "emitter region is too crowded: not one of 320 draws (32 for each of the 10 spheres) was "
        "clear of the obstacles (signed distance >= radius + clearance), so spawning stopped "
        "early; the obstacles fill (almost) all of the region (center [0.0, 0.0, 0.0], "
        "half_extents [0.5, 0.5, 0.5]): move or enlarge it, or use smaller spheres")
    with pytest.raises(ValueError) as info:  # one sphere: all 200 of its draws are made
        Emitter(count=1).spawn(block)
    assert str(info.value).startswith("emitter region is too crowded: 1 of 1 spheres were not "
                                      "clear of the obstacles (signed distance >= radius + "
                                      "clearance) in 200 draws each; ")


@pytest.mark.slow
def test_emitter_few_spheres_get_all_their_draws():
    # 90 % of the region is obstacle: one sphere fails 32 draws in 3.4 % of the seeds, but all
    # 200 only with probability 0.9**200 = 7e-10, so every one of these seeds places it.
    block = RoundedBoxes(center=[[-0.2, 0.0, 0.0]], half_extents=[[1.0, 1.0, 1.0]])
    emitter = Emitter(count=1, half_extents=(1.0, 0.5, 0.5), radius=0.0, clearance=0.0)
    for seed in range(200):
        p = emitter.spawn(block, seed=seed).position
        assert p[0, 0] >= 0.8


def _plate_scene(radius: str) -> str:
    """A plate at x = 0 that every point of the region [-1, 1]^3 is within 1 m of."""
    return ("[[box]]\ncenter = [0.0, 0.0, 0.0]\nhalf_extents = [0.0, 10.0, 10.0]\n"
            f"[emitter]\ncount = 50\nhalf_extents = [1.0, 1.0, 1.0]\nradius = {radius}\n")


def test_emitter_partly_crowded_region_counts_the_spheres_left(tmp_path):
    # Spheres with radius + clearance above 1 m fit nowhere, the others almost surely do.
    scene = load_scene(write(tmp_path, _plate_scene("[0.01, 1.5]")))
    radius = scene.emitter.spawn(RoundedBoxes(center=[[0.0, 50.0, 0.0]],
                                              half_extents=[[0.0, 0.0, 0.0]])).radius
    hopeless = int((radius + 1e-3 > 1.0).sum())
    with pytest.raises(SceneFileError) as info:
        scene.spawn()
    left = int(re.match(r"scene\.toml: emitter region is too crowded: (\d+) of 50 spheres were "
                        r"not clear of the obstacles \(signed distance >= radius \+ clearance\) "
                        r"in 200 draws each; ", str(info.value)).group(1))
    assert hopeless <= left <= hopeless + 3


@pytest.mark.slow
@pytest.mark.parametrize("radius", ["1e30", "[0.01, 1.2]"])
def test_emitter_radius_that_fits_nowhere_is_refused_first(tmp_path, radius):
    scene = load_scene(write(tmp_path, _plate_scene(radius)))
    largest = float(radius.strip("[]").split(",")[-1])
    bound = math.sqrt(3.0)  # farthest corner of the region from the plate's centre
    message = (f"emitter radius up to {largest:g} m plus clearance 0.001 m fits nowhere: no point "
               f"of the region (center [0.0, 0.0, 0.0], half_extents [1.0, 1.0, 1.0]) is "
               f"farther than {bound:.3g} m from box 0; use smaller spheres or move the region")
    with pytest.raises(SceneFileError) as info:
        scene.spawn()
    if largest > bound:
        assert str(info.value) == f"scene.toml: {message}"
    else:  # fits the bound, but not the plate: the crowding error
        assert "too crowded" in str(info.value)
    with pytest.raises(ValueError) as info:  # the API, without a file
        scene.emitter.spawn(scene.boxes)
    assert not isinstance(info.value, SceneFileError)
    assert (str(info.value) == message) == (largest > bound)


def test_spawn_refuses_a_swarm_inside_an_obstacle_from_any_emitter(tmp_path):
    class Dropper:  # an emitter of our own: the scene still checks what it returns
        def spawn(self, boxes, n=None, seed=None):
            return warpsim.Swarm(position=[[0.0, 5.0, 0.0], [3.0, 0.1, 0.0]],
                                 velocity=np.zeros((2, 3)), radius=0.2)
    scene = Scene(load_scene(write(tmp_path, MINIMAL)).boxes, emitter=Dropper())
    with pytest.raises(ValueError) as info:
        scene.spawn()
    assert str(info.value) == ("sphere 1 starts 0.6 m inside box 1 (position (3, 0.1, 0), "
                               "radius 0.2): spheres must start outside the obstacles or "
                               "touching them")
    with pytest.raises(ValueError, match=r"n must be >= 1, got 0"):
        scene.spawn(n=0)


@pytest.mark.parametrize("kwargs, message", [
    ({"count": 0}, "count must be >= 1, got 0"),
    ({"count": True}, "count must be an integer, got True"),
    ({"count": 2**31}, "count must be <= 2147483647 (integers must be below 2**31), got "
                       "2147483648"),
    ({"count": 1, "radius": -0.1}, "radius must be >= 0, got -0.1"),
    ({"count": 1, "radius": "0.1"}, "radius must be a number, got '0.1'"),
    ({"count": 1, "radius": None}, "radius must be a number, got None"),
    ({"count": 1, "mass": (0.0, 1.0)}, "mass[0] must be > 0, got 0"),
    ({"count": 1, "mass": (1.0, True)}, "mass[1] must be a number, got True"),
    ({"count": 1, "half_extents": (1.0, -1.0, 1.0)}, "half_extents[1] must be >= 0, got -1"),
    ({"count": 1, "speed": 1.0, "cone_deg": 181.0}, "cone_deg must be <= 180, got 181"),
    ({"count": 1, "speed": (2.0, 1.0)},
     "speed must be a scalar or [min, max] with min <= max, got [2, 1]"),
    ({"count": 1, "speed": 1.0, "direction": (0.0, 0.0, 0.0)},
     "direction must be a non-zero vector, got (0, 0, 0)"),
    ({"count": 1, "direction": (1.0, 0.0, 0.0)},
     "direction only shapes the speed term: give speed too, or leave direction out"),
    ({"count": 1, "cone_deg": 30.0},
     "cone_deg only shapes the speed term: give speed too, or leave cone_deg out"),
    ({"count": 1, "velocity": (0.0, float("nan"), 0.0)},
     "velocity must be finite, got (0, nan, 0)"),
    ({"count": 1, "seed": -3}, "seed must be >= 0, got -3"),
    ({"count": 1, "seed": 1.0}, "seed must be an integer, got 1.0"),
    ({"count": 1, "clearance": np.array(True)},
     "clearance must hold numbers, got an array of bool"),
])
def test_emitter_validation(kwargs, message):
    with pytest.raises(ValueError) as info:
        Emitter(**kwargs)
    assert str(info.value) == message


def test_emitter_speed_defaults_its_cone():
    e = Emitter(count=1, speed=2.0)
    assert (e.speed, e.direction, e.cone_deg) == ((2.0, 2.0), (0.0, 1.0, 0.0), 180.0)
    assert Emitter(count=1, speed=2.0, direction=(0.0, 1.0, 0.0), cone_deg=180.0) == e
    assert Emitter.from_table({"count": 1, "speed": 2.0}) == e
    with pytest.raises(ValueError, match=r"^unknown key 'sped' in \[emitter\]$"):
        Emitter.from_table({"count": 1, "sped": 2.0})


def test_inputs_are_never_mutated():
    center = np.array([0.0, 1.0, 0.0])
    jitter = np.array([0.5, 0.5, 0.5])
    e = Emitter(count=20, center=center, velocity_jitter=jitter)
    center[1] = 100.0  # the emitter holds its own copy
    assert e.center == (0.0, 1.0, 0.0)
    assert jitter.tolist() == [0.5, 0.5, 0.5]
    before = {f: getattr(FLOOR, f).copy() for f in ("center", "half_extents", "rotation",
                                                    "radius")}
    e.spawn(FLOOR, seed=3)
    for field, value in before.items():
        assert np.array_equal(getattr(FLOOR, field), value)
    # Loading twice gives equal, independent scenes.
    first, second = load_scene("galton"), load_scene("galton")
    assert first.boxes == second.boxes and first.emitter == second.emitter
    assert not first.boxes.center.flags.writeable


def test_documented_example_loads_and_spawns(tmp_path):
    doc = Path(__file__).resolve().parents[1] / "README.md"
    if not doc.is_file():
        pytest.skip("README.md not present (installed package)")
    section = doc.read_text(encoding="utf-8").split("## Scene files (TOML)", 1)[1]
    blocks = re.findall(r"```toml\n(.*?)```", section.split("\n## ", 1)[0], flags=re.S)
    assert len(blocks) == 1
    scene = load_scene(write(tmp_path, blocks[0], "example.toml"))
    assert scene.name == "example" and len(scene.boxes) == 8 + 12
    swarm = scene.spawn()
    assert len(swarm) == 500
    assert (scene.boxes.signed_distance(swarm.position) >= swarm.radius[:, None]).all()
