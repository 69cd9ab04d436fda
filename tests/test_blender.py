"""Import into Blender (the ``bpy`` module): frame range, positions, rotations, and every
obstacle's material. Skipped where ``bpy`` is not installed (``pip install bpy``: Blender as a
Python module, large, one Python version per Blender release)."""

import numpy as np
import pytest

import warpsim
from warpsim.export import write_usd

bpy = pytest.importorskip("bpy")

#: Blender's importer turns Y-up into Z-up: (x, y, z) in the file -> (x, -z, y) in Blender.
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
POSITION_TOL = 2e-6  # [m] float32 positions of a few metres, as Blender stores them
#: Blender reads the half-precision orientations: a rotation matrix entry is off by at most a
#: few half-precision steps (2^-11 each).
ROTATION_TOL = 4 * 2.0**-11


def scene_and_trajectory():
    boxes = warpsim.RoundedBoxes(
        center=[[0.0, -1.0, 0.0], [1.0, 0.5, -0.5], [-1.5, 0.3, 1.0], [0.0, 2.0, 2.0]],
        half_extents=[[4.0, 0.1, 4.0], [0.5, 0.25, 0.75], [0.6, 0.0, 0.4], [0.3, 0.2, 1.0]],
        rotation=[[0, 0, 0, 1], [0.1, 0.5, -0.2, 0.8], [0.3, 0.0, 0.0, 0.95], [0, 0.7, 0, 0.7]],
        radius=[0.0, 0.1, 0.2, 0.0])
    rng = np.random.default_rng(0)
    n, f = 6, 4
    q = rng.normal(size=(f, n, 4))
    traj = warpsim.Trajectory(frame=np.arange(3, 3 + f), dt=1 / 60,
                              position=rng.normal(size=(f, n, 3)),
                              orientation=q / np.linalg.norm(q, axis=-1, keepdims=True),
                              radius=np.full(n, 0.1))
    return warpsim.Scene(boxes, name="blender-test"), traj


def test_blender_import_keeps_frames_positions_rotations_and_materials(tmp_path):
    from warpsim.obstacles import quat_to_matrix

    scene, traj = scene_and_trajectory()
    path = write_usd(tmp_path / "anim.usdc", scene, traj)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.wm.usd_import(filepath=str(path)) == {"FINISHED"}
    blender = bpy.context.scene
    assert (blender.frame_start, blender.frame_end) == (traj.frame[0], traj.frame[-1])

    boxes = sorted((o for o in bpy.data.objects if o.name.startswith("Box_")),
                   key=lambda o: o.name)
    assert len(boxes) == len(scene.boxes)
    for i, obj in enumerate(boxes):
        assert obj.type == "MESH" and len(obj.data.polygons) > 0
        assert [s.material.name for s in obj.material_slots if s.material] == ["Obstacle"]
        np.testing.assert_allclose(np.array(obj.matrix_world.translation),
                                   Y_UP_TO_Z_UP @ scene.boxes.center[i], atol=POSITION_TOL)

    for k, frame in enumerate(traj.frame):
        blender.frame_set(int(frame))
        graph = bpy.context.evaluated_depsgraph_get()
        placed = [np.array(inst.matrix_world) for inst in graph.object_instances
                  if inst.is_instance and inst.object.name.startswith("CheckerBall")]
        assert len(placed) == traj.sphere_count
        position = np.array([m[:3, 3] for m in placed])
        expected = traj.position[k].astype(np.float32) @ Y_UP_TO_Z_UP.T
        order = [int(np.argmin(np.linalg.norm(expected - p, axis=1))) for p in position]
        assert sorted(order) == list(range(traj.sphere_count))
        np.testing.assert_allclose(position, expected[order], atol=POSITION_TOL)
        rotation = np.array([m[:3, :3] for m in placed]) / traj.radius[order, None, None]
        # the prototype's mesh stays in the file's frame: instance = axis change @ rotation
        true = Y_UP_TO_Z_UP @ quat_to_matrix(traj.orientation[k][order])
        np.testing.assert_allclose(rotation, true, atol=ROTATION_TOL)


def test_blender_import_of_a_result_composed_over_a_set(tmp_path):
    """A result over an artist's set (Z up, centimetres): Blender brings in the set's own
    objects and the spheres where the composed stage puts them, in one frame (the set's axes,
    so no axis change), at one unit scale for both (metres or the set's centimetres, whichever
    Blender's unit conversion gives)."""
    from pxr import Usd, UsdGeom
    from test_usd_stage import author_set, write_scene

    author_set(tmp_path / "set.usda")
    scene = warpsim.Scene.load(write_scene(tmp_path))
    traj = warpsim.Simulator(scene, scene.spawn(n=6, seed=3)).run(4)
    path = write_usd(tmp_path / "result.usdc", scene, traj)
    stage = Usd.Stage.Open(str(path))
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    floor = UsdGeom.Xformable(stage.GetPrimAtPath("/Set/Floor"))
    floor_at = np.array(floor.ComputeLocalToWorldTransform(Usd.TimeCode(0)))[3, :3]  # [cm]

    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert bpy.ops.wm.usd_import(filepath=str(path)) == {"FINISHED"}
    blender = bpy.context.scene
    names = {o.name for o in bpy.data.objects}
    assert {"Floor", "Block", "Crate"} <= names  # the set's objects, not warpsim's copies
    assert not any(name.startswith("Box_") for name in names)
    scale = np.array(bpy.data.objects["Floor"].matrix_world.translation)[0] / floor_at[0]
    assert scale == pytest.approx(1.0, rel=1e-6) or scale == pytest.approx(0.01, rel=1e-6)
    np.testing.assert_allclose(np.array(bpy.data.objects["Floor"].matrix_world.translation),
                               scale * floor_at, rtol=1e-6, atol=1e-6)
    for frame in traj.frame:
        blender.frame_set(int(frame))
        graph = bpy.context.evaluated_depsgraph_get()
        placed = np.array([np.array(inst.matrix_world)[:3, 3] for inst in graph.object_instances
                           if inst.is_instance and inst.object.name.startswith("CheckerBall")])
        assert len(placed) == traj.sphere_count
        time = Usd.TimeCode(float(frame))
        to_world = np.array(instancer.ComputeLocalToWorldTransform(time))
        usd = np.array([(np.array(m) @ to_world)[3, :3]  # [cm], in the set's world
                        for m in instancer.ComputeInstanceTransformsAtTime(time, time)])
        np.testing.assert_allclose(usd, traj.position[frame] / 0.01, rtol=1e-5, atol=1e-3)
        expected = scale * usd
        order = [int(np.argmin(np.linalg.norm(expected - p, axis=1))) for p in placed]
        assert sorted(order) == list(range(traj.sphere_count))
        np.testing.assert_allclose(placed, expected[order], atol=100 * scale * POSITION_TOL)
