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
