"""One set of checks for every input: types, integers, messages, and the scene files' reuse of them.

No Warp kernel runs here: everything is host-side numpy.
"""

from __future__ import annotations

import ast
import importlib
import math
from pathlib import Path

import numpy as np
import pytest

import warpsim as ws
from warpsim import validation as check
from warpsim.emitter import Emitter
from warpsim.scene_files import SceneFileError

PACKAGE = Path(ws.__file__).resolve().parent
FLOOR = ws.RoundedBoxes(center=[[0.0, -0.5, 0.0]], half_extents=[[5.0, 0.5, 5.0]])
GOOD_SWARM = dict(position=np.zeros((4, 3)) + (0.0, 1.0, 0.0), velocity=np.zeros((4, 3)))


def _raises(build, message: str) -> None:
    with pytest.raises(ValueError) as info:
        build()
    assert str(info.value) == message


# --- numbers are numbers -----------------------------------------------------------------------

# Values numpy alone would take: "0.1" -> 0.1, True -> 1.0, None -> nan, [0.1, True] -> [0.1, 1].
NOT_NUMBERS = [
    ("0.1", "{f} must be a number, got '0.1'"),
    (True, "{f} must be a number, got True"),
    (np.True_, "{f} must be a number, got np.True_"),
    (None, "{f} must be a number, got None"),
    (b"1", "{f} must be a number, got b'1'"),
    (np.array(True), "{f} must hold numbers, got an array of bool"),
    (np.array(["0.1"]), "{f} must hold numbers, got an array of <U3"),
    (1 + 2j, "{f} must hold numbers, got an array of complex128"),
]

SCALAR_FIELDS = {  # field -> how to build an object from that value
    "Swarm.radius": lambda v: ws.Swarm(**GOOD_SWARM, radius=v),
    "Swarm.mass": lambda v: ws.Swarm(**GOOD_SWARM, mass=v),
    "Scene.dt": lambda v: ws.Scene(FLOOR, dt=v),
    "Scene.friction": lambda v: ws.Scene(FLOOR, friction=v),
    "Scene.energy_retention": lambda v: ws.Scene(FLOOR, energy_retention=v),
    "Scene.max_angular_speed": lambda v: ws.Scene(FLOOR, max_angular_speed=v),
    "RoundedBox.radius": lambda v: ws.RoundedBox(radius=v),
    "RoundedBoxes.radius": lambda v: ws.RoundedBoxes(FLOOR.center, FLOOR.half_extents,
                                                     radius=v),
    "Emitter.clearance": lambda v: Emitter(count=1, clearance=v),
    "Emitter.radius": lambda v: Emitter(count=1, radius=v),
}


@pytest.mark.slow
@pytest.mark.parametrize("field", SCALAR_FIELDS)
@pytest.mark.parametrize("value, message", NOT_NUMBERS,
                         ids=[repr(v) for v, _ in NOT_NUMBERS])
def test_scalars_refuse_what_is_not_a_number(field, value, message):
    name = field.split(".")[1]
    if field == "RoundedBoxes.radius" and value is None:  # documented: None is sharp boxes
        assert SCALAR_FIELDS[field](value).radius.tolist() == [0.0]
        return
    _raises(lambda: SCALAR_FIELDS[field](value), message.format(f=name))


VECTOR_FIELDS = {
    "Swarm.position": (lambda v: ws.Swarm(position=v, velocity=np.zeros((2, 3))), 2),
    "Swarm.velocity": (lambda v: ws.Swarm(position=np.zeros((2, 3)), velocity=v), 2),
    "Swarm.angular_momentum": (lambda v: ws.Swarm(position=np.zeros((2, 3)),
                                                  velocity=np.zeros((2, 3)),
                                                  angular_momentum=v), 2),
    "RoundedBoxes.center": (lambda v: ws.RoundedBoxes(v, np.ones((2, 3))), 2),
    "RoundedBoxes.half_extents": (lambda v: ws.RoundedBoxes(np.zeros((2, 3)), v), 2),
    "Scene.gravity": (lambda v: ws.Scene(FLOOR, gravity=v), None),
    "RoundedBox.center": (lambda v: ws.RoundedBox(center=v), None),
    "Emitter.velocity": (lambda v: Emitter(count=1, velocity=v), None),
}


@pytest.mark.parametrize("field", VECTOR_FIELDS)
@pytest.mark.parametrize("bad", [True, "1", None, np.bool_(False)], ids=repr)
def test_vectors_name_the_row_of_a_non_number(field, bad):
    build, rows = VECTOR_FIELDS[field]
    name = field.split(".")[1]
    if rows is None:  # one vector: the component's index
        value, where = [0.0, bad, 0.0], f"{name}[1]"
    else:  # rows of vectors: the row's index
        value, where = [[0.0, 1.0, 0.0], [0.0, 0.0, bad]], f"{name}[1]"
    _raises(lambda: build(value), f"{where} must be a number, got {bad!r}")
    _raises(lambda: build(np.array(value, dtype=object)),
            f"{where} must be a number, got {bad!r}")


def test_numbers_of_every_numeric_type_are_taken():
    for value in (0.25, 1, np.float32(0.25), np.int64(1), np.float16(0.5), np.array(0.25)):
        assert ws.Swarm(**GOOD_SWARM, radius=value).radius.dtype == np.float64
    swarm = ws.Swarm(position=np.zeros((2, 3), dtype=np.int32), velocity=[(1, 2, 3), (4, 5, 6)],
                     radius=np.array([1, 2], dtype=np.uint8))
    assert swarm.velocity.tolist() == [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]
    assert swarm.radius.tolist() == [1.0, 2.0]


def test_a_huge_integer_or_a_ragged_list_is_one_line():
    _raises(lambda: ws.Scene(FLOOR, dt=10**400),
            "dt must be a number a float64 can hold, got " + "1" + "0" * 56 + "...")
    _raises(lambda: ws.Swarm(position=[[0.0, 0.0, 0.0], [0.0, 0.0]], velocity=np.zeros((2, 3))),
            "position must be a number or a regular array of numbers, got [[0.0, 0.0, 0.0], "
            "[0.0, 0.0]]")


# --- integers ----------------------------------------------------------------------------------

INTEGER_FIELDS = {
    "frames": (lambda v: ws.Scene(FLOOR, frames=v), 1, check.INT_LIMIT - 1),
    "max_bounces": (lambda v: ws.Scene(FLOOR, max_bounces=v), 1, check.MAX_BOUNCES),
    "count": (lambda v: Emitter(count=v), 1, check.INT_LIMIT - 1),
    "seed": (lambda v: Emitter(count=1, seed=v), 0, check.INT_LIMIT - 1),
}


def _integer_limit_message(field: str, value: int) -> str:
    if field == "max_bounces":
        return f"max_bounces must be <= 1024 (contacts per sphere per frame), got {value}"
    return f"{field} must be <= 2147483647 (integers must be below 2**31), got {value}"


@pytest.mark.parametrize("field", INTEGER_FIELDS)
def test_integers_are_bounded_ints(field):
    build, low, high = INTEGER_FIELDS[field]
    build(low)
    build(np.int64(high))  # numpy integers are integers
    for value in (high + 1, 2**31, 2**32, 2**64 + 3, 10**30):
        _raises(lambda v=value: build(v), _integer_limit_message(field, value))
    _raises(lambda: build(low - 1), f"{field} must be >= {low}, got {low - 1}")
    for value in (True, np.True_, 2.0, "3", None, np.array(3)):
        _raises(lambda v=value: build(v), f"{field} must be an integer, got {value!r}")


def test_max_bounces_cap_is_the_documented_one():
    assert check.MAX_BOUNCES == 1024
    assert ws.Scene(FLOOR, max_bounces=1024).max_bounces == 1024
    assert check.bounce_cap(np.int32(7)) == 7 and type(check.bounce_cap(np.int32(7))) is int


def test_booleans_are_flags_and_only_flags():
    assert ws.Scene(FLOOR, energy_correction=np.False_).energy_correction is False
    # None is the motion model's default: on for the linear model, off for the ballistic one
    assert ws.Scene(FLOOR, energy_correction=None).energy_correction is True
    assert ws.Scene(FLOOR, motion="ballistic").energy_correction is False
    assert ws.Scene(FLOOR, motion="ballistic", energy_correction=True).energy_correction is True
    for value in (1, 0, "true"):
        _raises(lambda v=value: ws.Scene(FLOOR, energy_correction=v),
                f"energy_correction must be true or false, got {value!r}")


def test_index_list_refuses_floats_and_bools():
    assert check.index_list("frames", [2, 0], 3).tolist() == [2, 0]
    _raises(lambda: check.index_list("frames", [0.0, 1.5], 3),
            "frames must be integer indices, got an array of float64")
    _raises(lambda: check.index_list("frames", [True], 3),
            "frames must be integer indices, got an array of bool")
    # among integers NumPy would make a bool 1: refused too, naming it
    _raises(lambda: check.index_list("frames", [0, True], 3),
            "frames[1] must be a number, got True")
    _raises(lambda: check.index_list("frames", (np.True_, 2), 3),
            "frames[0] must be a number, got np.True_")
    _raises(lambda: check.index_list("frames", [0, 3], 3), "frames[1] = 3 is out of range [0, 3)")


def test_checks_return_copies_and_never_touch_their_input():
    value = np.array([[0.0, 1.0, 0.0]])
    out = check.vec3_array("position", value)
    assert np.shares_memory(out, value) is False
    value.setflags(write=False)  # a read-only input is fine too
    assert check.nonnegative_vec3_array("h", value).flags.writeable
    q = [0.0, 0.0, 0.0, 2.0]
    assert check.unit_quat("rotation", q).tolist() == [0.0, 0.0, 0.0, 1.0]
    assert q == [0.0, 0.0, 0.0, 2.0]


# --- the scene files use the same checks -------------------------------------------------------


def _toml(value) -> str:
    """A TOML literal of a Python value (numbers, booleans, strings, lists)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, float) and math.isnan(value):
        return "nan"
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return repr(value)


BASE = {"box": {"center": [0.0, -0.5, 0.0], "half_extents": [5.0, 0.5, 5.0]},
        "emitter": {"count": 3, "center": [0.0, 1.0, 0.0]}}

# (table, key, bad value, how the API is given the same value)
SAME_CHECK = [
    ("simulation", "dt", -0.5, lambda v: ws.Scene(FLOOR, dt=v)),
    ("simulation", "dt", "0.1", lambda v: ws.Scene(FLOOR, dt=v)),
    ("simulation", "dt", True, lambda v: ws.Scene(FLOOR, dt=v)),
    ("simulation", "frames", 0, lambda v: ws.Scene(FLOOR, frames=v)),
    ("simulation", "frames", 2**40, lambda v: ws.Scene(FLOOR, frames=v)),
    ("simulation", "max_bounces", 4294967296, lambda v: ws.Scene(FLOOR, max_bounces=v)),
    ("simulation", "max_bounces", 3.0, lambda v: ws.Scene(FLOOR, max_bounces=v)),
    ("physics", "gravity", [0.0, float("nan"), 0.0], lambda v: ws.Scene(FLOOR, gravity=v)),
    ("physics", "gravity", [0.0, -9.81], lambda v: ws.Scene(FLOOR, gravity=v)),
    ("physics", "friction", -1.0, lambda v: ws.Scene(FLOOR, friction=v)),
    ("physics", "energy_retention", 0.0, lambda v: ws.Scene(FLOOR, energy_retention=v)),
    ("physics", "energy_correction", 1, lambda v: ws.Scene(FLOOR, energy_correction=v)),
    ("physics", "max_angular_speed", float("inf"), lambda v: ws.Scene(FLOOR,
                                                                      max_angular_speed=v)),
    ("box", "center", [0.0, float("inf"), 0.0], lambda v: ws.RoundedBox(center=v)),
    ("box", "half_extents", [5.0, -0.5, 5.0], lambda v: ws.RoundedBox(half_extents=v)),
    ("box", "half_extents", [5.0, 0.5, False], lambda v: ws.RoundedBox(half_extents=v)),
    ("box", "rotation", [0.0, 0.0, 0.0, 0.0], lambda v: ws.RoundedBox(rotation=v)),
    ("box", "rotation", [0.0, 0.0, 1.0], lambda v: ws.RoundedBox(rotation=v)),
    ("box", "radius", -0.25, lambda v: ws.RoundedBox(radius=v)),
    ("box", "radius", "0.1", lambda v: ws.RoundedBox(radius=v)),
    ("emitter", "count", 0, lambda v: Emitter(count=v)),
    ("emitter", "radius", [0.3, 0.2], lambda v: Emitter(count=1, radius=v)),
    ("emitter", "radius", [0.1, -0.2], lambda v: Emitter(count=1, radius=v)),
    ("emitter", "mass", [1.0, 2.0, 3.0], lambda v: Emitter(count=1, mass=v)),
    ("emitter", "half_extents", [1.0, 1.0, -1.0], lambda v: Emitter(count=1, half_extents=v)),
    ("emitter", "velocity_jitter", [0.0, "1", 0.0],
     lambda v: Emitter(count=1, velocity_jitter=v)),
    ("emitter", "direction", [1.0, 0.0, 0.0], lambda v: Emitter(count=1, direction=v)),
    ("emitter", "cone_deg", 45.0, lambda v: Emitter(count=1, cone_deg=v)),
    ("emitter", "seed", -1, lambda v: Emitter(count=1, seed=v)),
    ("emitter", "clearance", -0.001, lambda v: Emitter(count=1, clearance=v)),
]


def _scene_text(table: str, key: str, value) -> str:
    tables = {name: dict(content) for name, content in BASE.items()}
    tables.setdefault(table, {})[key] = value
    lines = []
    for name, content in tables.items():
        lines.append(f"[[{name}]]" if name == "box" else f"[{name}]")
        lines += [f"{k} = {_toml(v)}" for k, v in content.items()]
    return "\n".join(lines) + "\n"


@pytest.mark.slow
@pytest.mark.parametrize("table, key, value, api", SAME_CHECK,
                         ids=[f"{t}.{k}={v!r}" for t, k, v, _ in SAME_CHECK])
def test_a_file_value_gets_the_api_message_with_the_file_and_table(tmp_path, table, key,
                                                                   value, api):
    with pytest.raises(ValueError) as api_error:
        api(value)
    path = tmp_path / "scene.toml"
    path.write_text(_scene_text(table, key, value), encoding="utf-8")
    with pytest.raises(SceneFileError) as file_error:
        ws.Scene.load(path)
    where = "box[0]" if table == "box" else table
    api_message = str(api_error.value)
    assert api_message.startswith(key)
    # the same words, the field named as the file names it (and the speed it asks for)
    expected = f"{where}.{api_message}".replace("give speed", f"give {where}.speed")
    assert str(file_error.value) == f"{path}: {expected}"


# --- one place, no cycles ----------------------------------------------------------------------

CHECKED_MODULES = ("validation", "feasibility", "energy", "obstacles", "swarm", "scene",
                   "scene_files", "emitter", "footprint")


def _imports_of(module: str) -> set[str]:
    """The warpsim modules ``module`` imports, at its top or inside functions."""
    tree = ast.parse((PACKAGE / f"{module}.py").read_text(encoding="utf-8"))
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            if node.module:
                found.add(node.module.split(".")[0])
            else:
                found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("warpsim."):
            found.add(node.module.split(".")[1])
    return found


def test_the_checks_import_nothing_of_warpsim_but_its_vocabulary():
    """Every module may import the checks (import circles: ``tests/test_package.py``); besides
    the vocabulary they use only the row blocks' helper, which uses only the core count."""
    assert _imports_of("validation") == {"vocabulary", "blocks"}
    assert _imports_of("vocabulary") == set()
    assert _imports_of("blocks") == {"cores"}
    assert _imports_of("cores") == set()
    assert _imports_of("feasibility") == {"validation", "blocks"}
    assert "scene" not in _imports_of("scene_files")


@pytest.mark.parametrize("module", CHECKED_MODULES)
def test_every_numeric_constant_says_why(module):
    """A module-level number in capitals is followed by its reason (a docstring)."""
    values = vars(importlib.import_module(f"warpsim.{module}"))
    body = ast.parse((PACKAGE / f"{module}.py").read_text(encoding="utf-8")).body
    for node, after in zip(body, body[1:] + [None], strict=True):
        if not (isinstance(node, ast.Assign) and len(node.targets) == 1
                and isinstance(node.targets[0], ast.Name) and node.targets[0].id.isupper()):
            continue
        value = values[node.targets[0].id]
        if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
            continue
        documented = (isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                      and isinstance(after.value.value, str))
        assert documented, f"{module}.{node.targets[0].id} has no reason"
