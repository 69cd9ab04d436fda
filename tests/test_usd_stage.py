"""Scenes from an artist's USD stage, and results that compose over it.

The set is authored here with pxr as a DCC tool would write it: Z up, centimetres, nested
transforms with translate, rotate and scale ops, colliders (one disabled), a sphere, a box mesh
with a rounding radius, a light, a camera and a material. The world boxes expected are worked
out by hand below (in metres), never from the code under test.
"""

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdPhysics, UsdShade
from test_export import compliance_errors

import warpsim as ws
from warpsim.export import read_usd, write_usd
from warpsim.export.stage_in import StageObstacles

CM = 0.01  # metres per unit of the set
S45 = math.sqrt(0.5)
#: Rz(90 deg) @ Rx(30 deg), written out: the block's rotation in the world.
C30, S30 = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
RZ90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
RX30 = np.array([[1.0, 0.0, 0.0], [0.0, C30, -S30], [0.0, S30, C30]])
#: The box mesh's corners in its own frame [cm], corner k at bits (k & 1, k >> 1 & 1, k >> 2).
CRATE_SIZE = np.array([40.0, 20.0, 10.0])
CRATE_CORNERS = [tuple(CRATE_SIZE * [(k >> a) & 1 for a in range(3)]) for k in range(8)]
CRATE_FACES = [0, 2, 3, 1, 4, 5, 7, 6, 0, 1, 5, 4, 2, 6, 7, 3, 0, 4, 6, 2, 1, 3, 7, 5]

#: What the set holds, in metres, worked out by hand. /Set translates by (100, 50, 0) cm and
#: turns 90 deg about z, (x, y, z) -> (-y, x, z):
#: - Floor: cube of size 100 scaled (4, 3, 0.1), at (0, 0, -5) in /Set: half extents
#:   (200, 150, 5) cm, centre (100, 50, -5) cm; its top is the plane z = 0.
#: - Block: cube of size 2 scaled (10, 20, 5), turned 30 deg about x, at (30, 0, 20) in /Set/Group
#:   which scales by 2: half (20, 40, 10) cm, centre (60, 0, 40) in /Set -> (100, 110, 40) cm.
#: - Crate: box mesh [0, 40] x [0, 20] x [0, 10] cm at (-50, 0, 0) in /Set, rounded by 2 cm:
#:   centre (-30, 10, 5) -> (90, 20, 5) cm, core half extents (20, 10, 5) - 2 cm.
EXPECTED = {
    "center": np.array([[1.0, 0.5, -0.05], [1.0, 1.1, 0.4], [0.9, 0.2, 0.05]]),
    "half_extents": np.array([[2.0, 1.5, 0.05], [0.2, 0.4, 0.1], [0.18, 0.08, 0.03]]),
    "matrix": np.array([RZ90, RZ90 @ RX30, RZ90]),
    "radius": np.array([0.0, 0.0, 0.02]),
}
EXPECTED_READ = {"Cube": 2, "Mesh": 1}
EXPECTED_SKIPPED = {"disabled collider": 1, "Sphere not a box": 1, "not a collider": 1}


def matrix_of(q) -> np.ndarray:
    """Rotation matrix of a unit quaternion (x, y, z, w), written out (column vectors)."""
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def corners(center, matrix, half) -> np.ndarray:
    """The 8 corners of a box, (8, 3)."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return np.asarray(center) + (signs * half) @ np.asarray(matrix).T


def assert_same_points(got, expected, atol):
    """The same 8 points in any order: each expected point has its own got point within
    ``atol`` (the corners of a box are far apart compared with ``atol``)."""
    distance = np.linalg.norm(np.asarray(got)[:, None] - np.asarray(expected)[None], axis=2)
    nearest = distance.argmin(axis=0)
    assert sorted(nearest.tolist()) == list(range(len(got))), distance
    assert distance.min(axis=0).max() <= atol, distance.min(axis=0)


def collider(prim, enabled=True):
    api = UsdPhysics.CollisionAPI.Apply(prim.GetPrim())
    if not enabled:
        api.CreateCollisionEnabledAttr(False)
    return prim


def box_mesh(stage, path, points, faces=CRATE_FACES):
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([Gf.Vec3f(*p) for p in points])
    mesh.CreateFaceVertexCountsAttr([4] * (len(faces) // 4))
    mesh.CreateFaceVertexIndicesAttr(faces)
    mesh.CreateExtentAttr(UsdGeom.Mesh.ComputeExtent(mesh.GetPointsAttr().Get()))
    return mesh


def author_set(path, *, physics_scene=True, root="/Set"):
    """The artist's set (see ``EXPECTED``), saved at ``path``."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, CM)
    top = UsdGeom.Xform.Define(stage, root)
    stage.SetDefaultPrim(top.GetPrim())
    top.AddTranslateOp().Set(Gf.Vec3d(100.0, 50.0, 0.0))
    top.AddRotateZOp().Set(90.0)

    floor = collider(UsdGeom.Cube.Define(stage, f"{root}/Floor"))
    floor.CreateSizeAttr(100.0)
    floor.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, -5.0))
    floor.AddScaleOp(UsdGeom.XformOp.PrecisionDouble).Set(Gf.Vec3d(4.0, 3.0, 0.1))
    group = UsdGeom.Xform.Define(stage, f"{root}/Group")
    group.AddScaleOp().Set(Gf.Vec3f(2.0, 2.0, 2.0))
    block = collider(UsdGeom.Cube.Define(stage, f"{root}/Group/Block"))
    block.AddTranslateOp().Set(Gf.Vec3d(30.0, 0.0, 20.0))
    block.AddRotateXOp().Set(30.0)
    block.AddScaleOp().Set(Gf.Vec3f(10.0, 20.0, 5.0))
    crate = collider(box_mesh(stage, f"{root}/Crate", CRATE_CORNERS))
    crate.AddTranslateOp().Set(Gf.Vec3d(-50.0, 0.0, 0.0))
    crate.GetPrim().CreateAttribute("warpsim:radius", Sdf.ValueTypeNames.Double).Set(2.0)

    ghost = collider(UsdGeom.Cube.Define(stage, f"{root}/Ghost"), enabled=False)
    ghost.AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 300.0))
    collider(UsdGeom.Sphere.Define(stage, f"{root}/Ball")).CreateRadiusAttr(10.0)
    UsdGeom.Cube.Define(stage, f"{root}/Decoration")  # drawn, but not a collider

    material = UsdShade.Material.Define(stage, f"{root}/Looks/Paint")
    shader = UsdShade.Shader.Define(stage, f"{root}/Looks/Paint/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(floor.GetPrim()).Bind(material)
    UsdLux.SphereLight.Define(stage, f"{root}/Key").AddTranslateOp().Set(Gf.Vec3d(0, 0, 400))
    UsdGeom.Camera.Define(stage, f"{root}/Camera").AddTranslateOp().Set(Gf.Vec3d(0, -800, 150))
    if physics_scene:
        scene = UsdPhysics.Scene.Define(stage, "/PhysicsScene")
        scene.CreateGravityDirectionAttr(Gf.Vec3f(0.0, 0.0, -1.0))
        scene.CreateGravityMagnitudeAttr(981.0)  # [cm/s^2]
    stage.GetRootLayer().Save()
    return path


@pytest.fixture
def set_path(tmp_path):
    return author_set(tmp_path / "set.usda")


def assert_boxes(boxes, expected, atol=1e-12):
    np.testing.assert_allclose(boxes.center, expected["center"], rtol=0, atol=atol)
    np.testing.assert_allclose(boxes.half_extents, expected["half_extents"], rtol=0, atol=atol)
    np.testing.assert_allclose([matrix_of(q) for q in boxes.rotation], expected["matrix"],
                               rtol=0, atol=atol)
    np.testing.assert_allclose(boxes.radius, expected["radius"], rtol=0, atol=atol)


# --------------------------------------------------------------------------------------------
# Reading the set


def test_boxes_read_are_the_hand_computed_world_boxes_in_metres(set_path):
    boxes = ws.obstacles_from_usd(set_path)
    assert isinstance(boxes, StageObstacles) and isinstance(boxes, ws.RoundedBoxes)
    assert_boxes(boxes, EXPECTED)
    info = boxes.stage
    assert (info.up_axis, info.meters_per_unit) == ("Z", CM)
    assert info.read == EXPECTED_READ and info.skipped == EXPECTED_SKIPPED
    np.testing.assert_allclose(info.gravity, (0.0, 0.0, -9.81), rtol=0, atol=1e-12)
    assert info.gravity_source == "/PhysicsScene"
    line = info.summary()
    assert "\n" not in line
    for part in ("read 3 obstacles (2 Cube, 1 Mesh)", "skipped 3 prims", "1 disabled collider",
                 "1 Sphere not a box", "1 not a collider", "Z up", "0.01 m per unit",
                 "(0, 0, -9.81) m/s^2 from /PhysicsScene"):
        assert part in line, line


def test_one_subtree_and_no_colliders_means_every_box(tmp_path):
    path = author_set(tmp_path / "set.usda", physics_scene=False)
    stage = Usd.Stage.Open(str(path))
    for prim in stage.Traverse():  # no collider anywhere: every box counts, the sphere not
        prim.RemoveAPI(UsdPhysics.CollisionAPI)
    stage.GetRootLayer().Save()
    boxes = ws.obstacles_from_usd(path)
    assert boxes.stage.read == {"Cube": 4, "Mesh": 1}  # Ghost and Decoration are boxes too
    assert boxes.stage.skipped == {"Sphere not a box": 1}
    np.testing.assert_allclose(boxes.stage.gravity, (0.0, 0.0, -9.81), rtol=0, atol=0)
    assert boxes.stage.gravity_source == ""
    group = ws.obstacles_from_usd(path, prim="/Set/Group")
    assert len(group) == 1 and group.stage.prim == "/Set/Group"
    assert_boxes(group, {k: v[1:2] for k, v in EXPECTED.items()})


def test_mirror_and_shear_are_refused_naming_the_prim(tmp_path):
    stage = Usd.Stage.CreateNew(str(tmp_path / "bad.usda"))
    mirrored = UsdGeom.Cube.Define(stage, "/Set/Mirrored")
    mirrored.AddScaleOp().Set(Gf.Vec3f(-1.0, 1.0, 1.0))
    stage.GetRootLayer().Save()
    with pytest.raises(ValueError, match=r"bad.usda: /Set/Mirrored: the transform mirrors"):
        ws.obstacles_from_usd(tmp_path / "bad.usda")
    mirrored.GetPrim().SetActive(False)
    sheared = UsdGeom.Xform.Define(stage, "/Set/Squash")  # scales what its child turned
    sheared.AddScaleOp().Set(Gf.Vec3f(1.0, 3.0, 1.0))
    child = box_mesh(stage, "/Set/Squash/Crate", CRATE_CORNERS)
    child.AddRotateZOp().Set(30.0)
    stage.GetRootLayer().Save()
    with pytest.raises(ValueError, match=r"/Set/Squash/Crate: the transform shears the box"):
        ws.obstacles_from_usd(tmp_path / "bad.usda")


@pytest.mark.parametrize("case, edit, message", [
    ("rounding larger than the box", lambda s: s.GetPrimAtPath("/Set/Crate").GetAttribute(
        "warpsim:radius").Set(6.0), r"/Set/Crate: warpsim:radius = 6 is more than half"),
    ("no such prim", None, r"no prim '/Nowhere'"),
    ("not USD", "garbage", r"USD could not read .*set.usda"),
])
def test_bad_sets_are_one_line_errors(set_path, case, edit, message):
    prim = None
    if edit is None:
        prim = "/Nowhere"
    elif edit == "garbage":
        set_path.write_text("#usda 1.0\n(\n  this is not USD\n", encoding="utf-8")
    else:
        stage = Usd.Stage.Open(str(set_path))
        edit(stage)
        stage.GetRootLayer().Save()
    with pytest.raises(ValueError, match=message) as info:
        ws.obstacles_from_usd(set_path, prim=prim)
    assert "\n" not in str(info.value)


def test_meshes_that_are_not_boxes_are_skipped(tmp_path):
    stage = Usd.Stage.CreateNew(str(tmp_path / "odd.usda"))
    points = list(CRATE_CORNERS)
    box_mesh(stage, "/Set/Box", points)
    bent = list(points)
    bent[7] = (40.0, 20.0, 12.0)  # one corner lifted: a hexahedron, not a box
    box_mesh(stage, "/Set/Bent", bent)
    twisted = list(CRATE_FACES)
    twisted[0:4] = [0, 3, 2, 1]  # a face crossing itself: its edges cut across the face
    box_mesh(stage, "/Set/Twisted", points, twisted)
    box_mesh(stage, "/Set/Prism", points[:6], [0, 1, 3, 2, 0, 2, 4, 1, 3, 5])
    stage.GetRootLayer().Save()
    boxes = ws.obstacles_from_usd(tmp_path / "odd.usda")
    assert boxes.stage.read == {"Mesh": 1} and boxes.stage.skipped == {"Mesh not a box": 3}
    np.testing.assert_allclose(boxes.center, [[0.2, 0.1, 0.05]], rtol=0, atol=1e-15)  # 1 cm


def rotations(draw_quaternion):
    q = np.array(draw_quaternion, dtype=np.float64)
    return matrix_of(q / np.linalg.norm(q))


quaternion = st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 0.1)


@pytest.mark.slow
@settings(max_examples=40, deadline=None)
@given(local_q=quaternion, world_q=quaternion,
       half=st.lists(st.floats(0.01, 5.0), min_size=3, max_size=3),
       center=st.lists(st.floats(-50.0, 50.0), min_size=3, max_size=3),
       shift=st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=3),
       scale=st.floats(0.1, 10.0), order=st.permutations(range(8)), flip=st.booleans())
def test_any_box_mesh_in_any_rigid_transform_is_read(tmp_path_factory, local_q, world_q, half,
                                                     center, shift, scale, order, flip):
    """A box mesh (its corners in any order, faces wound either way) under a uniform scale,
    rotation and translation reads as the box whose corners are the transformed points."""
    local_r, world_r = rotations(local_q), rotations(world_q)
    signs = np.array([[(k >> a) & 1 for a in range(3)] for k in range(8)]) * 2.0 - 1.0
    local = np.asarray(center) + (signs * half) @ local_r.T
    faces = np.array(CRATE_FACES).reshape(6, 4)
    if flip:
        faces = faces[:, ::-1]
    rank = np.argsort(order)  # corner k is stored as point rank[k]
    points = local[list(order)]
    matrix = np.eye(4)
    matrix[:3, :3] = (scale * world_r).T  # USD row vectors: p_world = p @ M[:3, :3] + M[3, :3]
    matrix[3, :3] = shift
    stage = Usd.Stage.CreateInMemory("box.usda")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)  # (USD's fallback is centimetres)
    mesh = box_mesh(stage, "/Box", points, rank[faces].reshape(-1).tolist())
    mesh.AddTransformOp().Set(Gf.Matrix4d(matrix.tolist()))
    path = tmp_path_factory.mktemp("box") / "box.usda"
    stage.GetRootLayer().Export(str(path))
    boxes = ws.obstacles_from_usd(path)
    expected = np.asarray(shift) + scale * (np.asarray(points, dtype=np.float32)
                                            .astype(np.float64) @ world_r.T)
    got = corners(boxes.center[0], matrix_of(boxes.rotation[0]), boxes.half_extents[0])
    # The float32 points are a box only to their rounding (2^-24 of the largest coordinate);
    # the box read is exact, so its corners are off the points by a few such roundings.
    rounding = 2.0**-24 * scale * np.abs(points).max()
    assert_same_points(got, expected, atol=16.0 * rounding + 1e-12 * np.abs(shift).max())


@pytest.mark.slow
@settings(max_examples=30, deadline=None)
@given(world_q=quaternion, scale=st.lists(st.floats(0.05, 20.0), min_size=3, max_size=3),
       shear=st.floats(0.01, 1.0), axis=st.integers(0, 2))
def test_cube_scale_gives_half_extents_and_any_shear_is_refused(tmp_path_factory, world_q,
                                                                scale, shear, axis):
    r = rotations(world_q)
    linear = r @ np.diag(scale)  # scale along the cube's own axes, then turn: a box
    matrix = np.eye(4)
    matrix[:3, :3] = linear.T
    folder = tmp_path_factory.mktemp("cube")
    stage = Usd.Stage.CreateNew(str(folder / "cube.usda"))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    cube = UsdGeom.Cube.Define(stage, "/Cube")
    op = cube.AddTransformOp()
    op.Set(Gf.Matrix4d(matrix.tolist()))
    stage.GetRootLayer().Save()
    boxes = ws.obstacles_from_usd(folder / "cube.usda")
    np.testing.assert_allclose(boxes.half_extents[0], scale, rtol=1e-12)  # size 2: half = 1
    np.testing.assert_allclose(matrix_of(boxes.rotation[0]), r, rtol=0, atol=1e-12)
    sheared = np.eye(3)
    sheared[axis, (axis + 1) % 3] = shear  # one axis leans on another
    matrix[:3, :3] = (linear @ sheared).T
    op.Set(Gf.Matrix4d(matrix.tolist()))
    stage.GetRootLayer().Save()
    with pytest.raises(ValueError, match="/Cube: the transform shears the box"):
        ws.obstacles_from_usd(folder / "cube.usda")


def test_warpsims_own_output_reads_back_as_a_set(tmp_path):
    scene = ws.Scene.load("room")  # sharp walls and rounded, rotated, zero-thickness plates
    traj = ws.Simulator(scene, scene.spawn(n=4, seed=0)).run(2)
    path = write_usd(tmp_path / "room.usdc", scene, traj)
    boxes = ws.obstacles_from_usd(path)
    assert boxes.stage.read == {"Mesh": len(scene.boxes)}
    assert boxes.stage.skipped == {"PointInstancer": 1}  # the spheres and their prototype
    assert (boxes.stage.up_axis, boxes.stage.meters_per_unit) == ("Y", 1.0)
    assert boxes.stage.gravity == (0.0, -9.81, 0.0)
    np.testing.assert_array_equal(boxes.half_extents, scene.boxes.half_extents)
    np.testing.assert_array_equal(boxes.radius, scene.boxes.radius)
    np.testing.assert_allclose(boxes.center, scene.boxes.center, rtol=0, atol=1e-15)
    np.testing.assert_allclose(boxes.rotation_matrices(), scene.boxes.rotation_matrices(),
                               rtol=0, atol=1e-15)


def test_rigid_bodies_earth_gravity_and_usds_fallback_units(tmp_path):
    """Parts of an enabled rigid body move: not obstacles (a disabled one is static). A physics
    scene that gives only a direction has Earth's gravity; no metersPerUnit means centimetres."""
    stage = Usd.Stage.CreateNew(str(tmp_path / "bodies.usda"))
    for name, enabled in (("Cart", True), ("Parked", False)):
        body = UsdGeom.Xform.Define(stage, f"/{name}")
        api = UsdPhysics.RigidBodyAPI.Apply(body.GetPrim())
        if not enabled:
            api.CreateRigidBodyEnabledAttr(False)
        UsdGeom.Cube.Define(stage, f"/{name}/Body").AddTranslateOp().Set(Gf.Vec3d(0, 300, 0))
    UsdPhysics.Scene.Define(stage, "/Physics").CreateGravityDirectionAttr(Gf.Vec3f(1, 0, 0))
    stage.GetRootLayer().Save()
    boxes = ws.obstacles_from_usd(tmp_path / "bodies.usda")
    assert boxes.stage.read == {"Cube": 1} and boxes.stage.skipped == {"rigid body": 1}
    assert boxes.stage.meters_per_unit == 0.01 and boxes.stage.up_axis == "Y"
    np.testing.assert_allclose(boxes.center, [[0.0, 3.0, 0.0]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(boxes.half_extents, [[0.01, 0.01, 0.01]], rtol=0, atol=1e-17)
    assert boxes.stage.gravity == (9.81, 0.0, 0.0)


@pytest.mark.slow
def test_importing_warpsim_does_not_load_pxr():
    code = ("import sys, warpsim; assert 'pxr' not in sys.modules; "
            "assert 'obstacles_from_usd' in warpsim.__all__; warpsim.obstacles_from_usd; "
            "assert 'pxr' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


# --------------------------------------------------------------------------------------------
# A run on the set: the result composes over it


SCENE_FILE = """\
name = "on-set"
description = "spheres dropped on the artist's set"

[simulation]
dt = 0.016666666666666666
frames = 45
{physics}
[obstacles]
usd = "{usd}"

[emitter]
count = 24
center = [1.8, 0.5, 0.5]     # metres, in the set's axes (z up), over the floor only
half_extents = [0.3, 0.3, 0.1]
radius = 0.02
"""


def write_scene(folder, usd="set.usda", physics=""):
    path = folder / "scene.toml"
    path.write_text(SCENE_FILE.format(usd=usd, physics=physics), encoding="utf-8")
    return path


def test_scene_file_reads_the_stage_relative_to_itself(set_path, tmp_path):
    scene = ws.Scene.load(write_scene(tmp_path))
    assert_boxes(scene.boxes, EXPECTED)
    np.testing.assert_allclose(scene.gravity, (0.0, 0.0, -9.81), rtol=0, atol=1e-12)
    own = ws.Scene.load(write_scene(tmp_path, physics="[physics]\ngravity = [0, 0, -1.62]\n"))
    np.testing.assert_array_equal(own.gravity, (0.0, 0.0, -1.62))  # the file's wins


@pytest.mark.parametrize("usd, extra, message", [
    ("missing.usda", "", r"scene.toml: obstacles.usd: no USD file at .*missing.usda"),
    ("set.usda", "\n[[box]]\ncenter = [0, 0, 0]\nhalf_extents = [1, 1, 1]\n",
     r"scene.toml: \[\[box\]\] and \[\[box_grid\]\] tables cannot be mixed"),
])
def test_scene_file_errors_name_the_file_and_the_table(set_path, tmp_path, usd, extra, message):
    path = write_scene(tmp_path, usd=usd)
    path.write_text(path.read_text(encoding="utf-8") + extra, encoding="utf-8")
    with pytest.raises(ws.SceneFileError, match=message):
        ws.Scene.load(path)


@pytest.mark.parametrize("fmt", ["usda", "usdc"])
def test_run_composes_over_the_set_in_its_axes_and_units(set_path, tmp_path, fmt):
    scene = ws.Scene.load(write_scene(tmp_path))
    swarm = scene.spawn(seed=3)
    traj = ws.Simulator(scene, swarm).run(scene.frames)
    out = write_usd(tmp_path / f"result.{fmt}", scene, traj)
    assert sorted(os.listdir(tmp_path)) == ["result." + fmt, "scene.toml", "set.usda"]

    # Falling on the floor (its top is z = 0) along -z, the set's up axis: never through it.
    z = traj.position[..., 2]
    assert z.min() >= swarm.radius.min() - 1e-5
    # Each reached the floor: a fall from at most 0.6 m hits at below 3.5 m/s, 5.8 cm a frame.
    assert (z.min(axis=0) < swarm.radius + 0.058).all()
    xy = traj.position[:, :, :2]
    assert np.abs(xy - xy[0]).max() <= 1e-6  # gravity along -z moves nothing sideways

    layer = Sdf.Layer.FindOrOpen(str(out))
    assert list(layer.subLayerPaths) == ["./set.usda"]
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == CM
    for prim in ("/Set/Floor", "/Set/Key", "/Set/Camera", "/Set/Looks/Paint", "/PhysicsScene"):
        assert stage.GetPrimAtPath(prim), prim  # the artist's own prims, not copies
    assert not stage.GetPrimAtPath("/World/Obstacles")
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    to_world = np.array(instancer.ComputeLocalToWorldTransform(Usd.TimeCode(0)))
    np.testing.assert_allclose(to_world, np.diag([100.0, 100.0, 100.0, 1.0]), rtol=1e-15)
    assert compliance_errors(out) == [] and compliance_errors(set_path) == []

    back = read_usd(out)  # the trajectory in metres, as stored
    np.testing.assert_array_equal(back.position, traj.position.astype(np.float32))
    np.testing.assert_array_equal(back.radius, traj.radius)
    assert back.dt == traj.dt
    again = ws.obstacles_from_usd(out)  # a result is a set too: the set's boxes, once
    assert_boxes(again, EXPECTED)
    assert again.stage.skipped == {**EXPECTED_SKIPPED, "PointInstancer": 1}


def test_spheres_stay_in_the_world_frame_of_a_set_with_its_own_world_prim(tmp_path):
    path = author_set(tmp_path / "set.usda", root="/World")  # the set's root moves and turns
    scene = ws.Scene.load(write_scene(tmp_path))
    traj = ws.Simulator(scene, scene.spawn(n=2, seed=0)).run(2)
    out = write_usd(tmp_path / "result.usdc", scene, traj)
    stage = Usd.Stage.Open(str(out))
    assert stage.GetPrimAtPath("/World/Floor")
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    to_world = np.array(instancer.ComputeLocalToWorldTransform(Usd.TimeCode(0)))
    np.testing.assert_allclose(to_world, np.diag([100.0, 100.0, 100.0, 1.0]), rtol=1e-15)
    assert path.exists()


def test_result_over_the_set_is_refused_and_the_set_is_untouched(set_path, tmp_path):
    scene = ws.Scene.load(write_scene(tmp_path))
    traj = ws.Simulator(scene, scene.spawn(n=2, seed=0)).run(1)
    before = set_path.read_bytes()
    with pytest.raises(ValueError, match="is the set the result composes over"):
        write_usd(set_path, scene, traj)
    assert set_path.read_bytes() == before


def test_cli_run_prints_what_it_read_and_composes(set_path, tmp_path, capsys):
    from warpsim.apps.cli import main

    scene_path = write_scene(tmp_path)
    sub = tmp_path / "renders"
    sub.mkdir()
    code = main(["run", str(scene_path), "-o", str(sub / "shot.usdc"), "--no-progress",
                 "--frames", "10"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "set.usda: read 3 obstacles (2 Cube, 1 Mesh); skipped 3 prims" in captured.err
    assert list(Sdf.Layer.FindOrOpen(str(sub / "shot.usdc")).subLayerPaths) == ["../set.usda"]
    assert read_usd(sub / "shot.usdc").position.shape == (11, 24, 3)
    code = main(["run", str(scene_path), "-o", str(set_path), "--no-progress"])
    assert code == 1 and "is the set the result composes over" in capsys.readouterr().err
    code = main(["run", str(scene_path), "--dask", "--no-progress"])
    assert code == 1 and "USD stage runs unsharded" in capsys.readouterr().err


def readme_section() -> str:
    readme = Path(__file__).resolve().parents[1] / "README.md"
    if not readme.is_file():
        pytest.skip("README.md not present (installed package)")
    text = readme.read_text(encoding="utf-8")
    return text.split("## Scenes on your own USD set", 1)[1].split("\n## ", 1)[0]


def test_readme_scene_file_runs_on_a_set_and_its_summary_is_what_run_prints(set_path,
                                                                           tmp_path):
    section = readme_section()
    toml = re.search(r"```toml\n(.*?)```", section, flags=re.S).group(1)
    (tmp_path / "on-set.toml").write_text(toml, encoding="utf-8")
    scene = ws.Scene.load(tmp_path / "on-set.toml")
    swarm = scene.spawn(n=20, seed=1)
    assert (swarm.position[:, 2] > 1.2).all()  # the emitter's region, z up, in metres
    traj = ws.Simulator(scene, swarm).run(30)
    assert traj.position[..., 2].min() >= swarm.radius.min() - 1e-5  # above the floor, z = 0
    out = write_usd(tmp_path / "shot.usdc", scene, traj)
    assert list(Sdf.Layer.FindOrOpen(str(out)).subLayerPaths) == ["./set.usda"]
    quoted = re.search(r"`warpsim run` prints it:\n`(.*?)`", section, flags=re.S).group(1)
    assert " ".join(quoted.split()) == scene.boxes.stage.summary()


# --------------------------------------------------------------------------------------------
# Positions that keep their precision far from the origin


def far_trajectory(center, spread, n=5, frames=61, speed=0.01, dt=1.0 / 60.0, seed=0):
    """float64 spheres around ``center`` [m], ``spread`` [m] apart at most, moving ``speed``
    [m/s] along x."""
    rng = np.random.default_rng(seed)
    start = np.asarray(center, dtype=np.float64) + rng.uniform(-spread / 2, spread / 2, (n, 3))
    t = np.arange(frames) * dt
    position = start[None] + t[:, None, None] * np.array([speed, 0.0, 0.0])
    return ws.Trajectory(frame=np.arange(frames), dt=dt, position=position,
                         orientation=np.tile([0.0, 0.0, 0.0, 1.0], (frames, n, 1)),
                         radius=np.full(n, 0.05))


def test_far_float64_positions_keep_their_motion(tmp_path):
    """The issue's case: at x = 1e5 m, 10 mm/s over 61 frames is 2 distinct float32 values;
    stored from a per-frame origin it keeps 2^-24 of the swarm's 2 m grid."""
    traj = far_trajectory((1e5, 20.0, -3e4), spread=1.5)
    assert len(np.unique(traj.position[:, 0, 0].astype(np.float32))) <= 3  # what float32 keeps
    out = write_usd(tmp_path / "far.usdc", None, traj)
    back = read_usd(out)
    assert back.position.dtype == np.float64
    assert len(np.unique(back.position[:, 0, 0])) == 61
    np.testing.assert_allclose(back.position, traj.position, rtol=0, atol=2.0 * 2.0**-24)
    # Read back exactly: the stored double origin plus the stored float32 offsets.
    stage = Usd.Stage.Open(str(out))
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    origin = instancer.GetPrim().GetAttribute("xformOp:translate:warpsimOrigin")
    for f in (0, 30, 60):
        rel = np.array(instancer.GetPositionsAttr().Get(f), dtype=np.float32)
        np.testing.assert_array_equal(back.position[f],
                                      np.array(origin.Get(f)) + rel.astype(np.float64))
        to_world = np.array(instancer.ComputeLocalToWorldTransform(Usd.TimeCode(f)))
        np.testing.assert_allclose(rel @ to_world[:3, :3] + to_world[3, :3], back.position[f],
                                   rtol=1e-15)  # viewers place the spheres where they are
    assert compliance_errors(out) == []


def test_files_near_the_origin_have_no_origin_op(tmp_path):
    traj = far_trajectory((30.0, 2.0, -10.0), spread=8.0)  # 30 m away: float32 keeps 2 um
    out = write_usd(tmp_path / "near.usda", None, traj)
    stage = Usd.Stage.Open(str(out))
    prim = stage.GetPrimAtPath("/World/Spheres")
    assert not prim.GetAttribute("xformOp:translate:warpsimOrigin")
    assert not prim.GetAttribute("xformOpOrder").HasAuthoredValue()
    np.testing.assert_array_equal(read_usd(out).position, traj.position.astype(np.float32))


@pytest.mark.slow
@settings(max_examples=25, deadline=None)
@given(center=st.lists(st.floats(-1e7, 1e7), min_size=3, max_size=3),
       spread=st.floats(0.0, 300.0), seed=st.integers(0, 100))
def test_every_position_keeps_its_documented_precision(tmp_path_factory, center, spread, seed):
    """``2^-16 G`` anywhere, ``2^-24 G`` far from the origin (G: the swarm's largest side
    rounded up to a power of two, at least 1 m; export/origins.py)."""
    traj = far_trajectory(center, spread, n=4, frames=2, seed=seed)
    out = write_usd(tmp_path_factory.mktemp("far") / "far.usdc", None, traj)
    back = read_usd(out)
    for f in range(2):
        p = traj.position[f]
        grid = 2.0 ** math.ceil(math.log2(max(float(np.ptp(p, axis=0).max()), 1.0)))
        far = np.abs(p).max() >= 256.0 * grid
        bound = (2.0**-24 if far else 2.0**-16) * grid
        assert np.abs(back.position[f] - p).max() <= bound


def test_composed_result_keeps_far_positions_in_the_sets_units(set_path, tmp_path):
    scene = ws.Scene.load(write_scene(tmp_path))
    traj = far_trajectory((2e4, 0.0, 3.0), spread=1.0, frames=3)
    out = write_usd(tmp_path / "far.usda", scene, traj)
    stage = Usd.Stage.Open(str(out))
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    order = instancer.GetXformOpOrderAttr().Get()
    assert list(order) == ["!resetXformStack!", "xformOp:scale", "xformOp:translate:warpsimOrigin"]
    rel = np.array(instancer.GetPositionsAttr().Get(2), dtype=np.float64)
    to_world = np.array(instancer.ComputeLocalToWorldTransform(Usd.TimeCode(2)))
    back = read_usd(out)
    np.testing.assert_allclose(back.position, traj.position, rtol=0, atol=2.0**-24)
    np.testing.assert_allclose(rel @ to_world[:3, :3] + to_world[3, :3],  # in centimetres
                               back.position[2] / CM, rtol=1e-12, atol=1e-9)
    assert compliance_errors(out) == []


def shard_instancers_of(stage):
    return [UsdGeom.PointInstancer(p) for p in stage.GetPrimAtPath("/World/Spheres").GetChildren()]


def assert_composed_over_the_set(out, set_sublayer="./set.usda"):
    """``out`` opens over the set: the set's units, axes and prims, no copy of its boxes, and
    every sphere instancer mapped from metres to centimetres in the world frame."""
    layer = Sdf.Layer.FindOrOpen(str(out))
    assert list(layer.subLayerPaths)[-1] == set_sublayer
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == CM
    for prim in ("/Set/Floor", "/Set/Key", "/Set/Camera", "/PhysicsScene"):
        assert stage.GetPrimAtPath(prim), prim
    assert not stage.GetPrimAtPath("/World/Obstacles")
    prim = stage.GetPrimAtPath("/World/Spheres")
    instancers = ([UsdGeom.PointInstancer(prim)] if prim.IsA(UsdGeom.PointInstancer)
                  else shard_instancers_of(stage))
    assert instancers
    for instancer in instancers:
        to_world = np.array(instancer.ComputeLocalToWorldTransform(Usd.TimeCode(0)))
        np.testing.assert_allclose(to_world, np.diag([100.0, 100.0, 100.0, 1.0]), rtol=1e-15)
    assert compliance_errors(out) == []
    assert_boxes(ws.export.read_usd_boxes(out), EXPECTED)  # what preview draws: the set's boxes


@pytest.mark.parametrize("fmt", ["usda", "usdc"])
def test_sharded_run_composes_over_the_set_as_a_plain_run(set_path, tmp_path, fmt):
    from warpsim import distributed as wd

    scene = ws.Scene.load(write_scene(tmp_path))
    out = tmp_path / f"sharded.{fmt}"
    summary = wd.run(scene, out, n=24, seed=3, frames=12, every=3, block=8, shards=3,
                     progress=False)
    assert summary.shards == 3
    assert_composed_over_the_set(out)
    swarm = wd.sharded_spawn(scene, 24, 3, 8)
    plain = ws.Simulator(scene, swarm).run(12, every=3)
    back = read_usd(out)
    np.testing.assert_array_equal(back.frame, plain.frame)
    np.testing.assert_array_equal(back.position, plain.position.astype(np.float32))
    z = back.position[..., 2]  # falling along the set's -z onto its floor, never through it
    assert z.min() >= swarm.radius.min() - 1e-5 and (z[-1] < z[0]).all()
    with pytest.raises(ValueError, match="is the set the result composes over"):
        wd.run(scene, set_path, n=8, frames=2, block=8, progress=False)


def test_preview_of_a_composed_result_draws_the_sets_boxes(set_path, tmp_path):
    from PIL import ImageChops

    from warpsim.export import draw_frame, render_preview

    scene = ws.Scene.load(write_scene(tmp_path))
    traj = ws.Simulator(scene, scene.spawn(seed=3)).run(6)
    out = write_usd(tmp_path / "result.usdc", scene, traj)
    assert_composed_over_the_set(out)
    png = render_preview(out, -1, tmp_path / "frame.png", size=(160, 90))
    boxes = ws.RoundedBoxes(center=EXPECTED["center"], half_extents=EXPECTED["half_extents"],
                            rotation=[quat_of(m) for m in EXPECTED["matrix"]],
                            radius=EXPECTED["radius"])
    want, _ = draw_frame(boxes, traj.position[-1], traj.orientation[-1], traj.radius,
                         size=(160, 90))
    from PIL import Image

    got = Image.open(png).convert("RGB")
    assert ImageChops.difference(got, want).getbbox() is None or np.abs(
        np.asarray(got, dtype=int) - np.asarray(want, dtype=int)).max() <= 1
    bare, _ = draw_frame(None, traj.position[-1], traj.orientation[-1], traj.radius,
                         size=(160, 90))
    assert ImageChops.difference(got, bare).getbbox() is not None  # the set is drawn


def quat_of(matrix) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w) of a rotation matrix (w > 0 here: no half turns)."""
    m = np.asarray(matrix)
    w = math.sqrt(max(0.0, 1.0 + m[0, 0] + m[1, 1] + m[2, 2])) / 2.0
    return ((m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w),
            (m[1, 0] - m[0, 1]) / (4 * w), w)
