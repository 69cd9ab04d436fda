"""USD export: round trip, stage metadata, compliance, static obstacles, atomicity, size warning,
and the rounded-box tessellation.

Trajectories here are synthetic numpy arrays (no simulation), with frame indices that do not
start at 0 and are not consecutive, so that time codes provably are the recorded frame indices.
"""

import os
import subprocess
import sys
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pxr import Usd, UsdGeom, UsdShade, UsdUtils

import warpsim
import warpsim.export.files as files_module
import warpsim.export.usd_read as usd_read
import warpsim.export.usd_write as usd_module
from warpsim.export import (
    LargeOutputWarning,
    estimate_usd_bytes,
    half_orientations,
    read_usd,
    read_usd_boxes,
    read_usd_frame,
    write_usd,
)
from warpsim.export.mesh import box_mesh, checker_sphere_mesh, rounded_box_mesh
from warpsim.obstacles import quat_to_matrix

FORMATS = ["usda", "usdc"]
HALF_ULP = 2.0**-12  # half precision rounding error bound for a component in [0.5, 1): 2^-11 / 2


def unit_quaternions(rng, shape):
    q = rng.normal(size=shape + (4,))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def make_trajectory(n_frames=6, n_spheres=5, seed=0, first=7, step=3, dt=1.0 / 60.0):
    """Random float64 frames; frame indices first, first + step, ... (not 0, 1, 2, ...)."""
    rng = np.random.default_rng(seed)
    return warpsim.Trajectory(
        frame=first + step * np.arange(n_frames, dtype=np.int64), dt=dt,
        position=rng.normal(size=(n_frames, n_spheres, 3)) * 3.0,
        orientation=unit_quaternions(rng, (n_frames, n_spheres)),
        radius=rng.uniform(0.05, 0.3, n_spheres))


def make_scene():
    """A floor (sharp), a rotated rounded box, a rounded plate (zero half extent), a sharp stick."""
    boxes = warpsim.RoundedBoxes(
        center=[[0.0, -1.0, 0.0], [1.0, 0.5, -0.5], [-1.5, 0.3, 1.0], [0.0, 2.0, 2.0]],
        half_extents=[[4.0, 0.1, 4.0], [0.5, 0.25, 0.75], [0.6, 0.0, 0.4], [0.0, 0.0, 1.0]],
        rotation=[[0, 0, 0, 1], [0.1, 0.5, -0.2, 0.8], [0.3, 0.0, 0.0, 0.95], [0, 0.7, 0, 0.7]],
        radius=[0.0, 0.1, 0.2, 0.0])
    return warpsim.Scene(boxes, name="test-scene", description="boxes for the export tests")


def all_attributes(stage, root):
    for prim in Usd.PrimRange(stage.GetPrimAtPath(root)):
        yield from prim.GetAttributes()


# --------------------------------------------------------------------------------------------
# Round trip


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_is_float32_exact(tmp_path, fmt):
    traj = make_trajectory()
    out = write_usd(tmp_path / f"anim.{fmt}", make_scene(), traj)
    assert out == tmp_path / f"anim.{fmt}"
    back = read_usd(out)
    np.testing.assert_array_equal(back.frame, traj.frame)
    assert back.frame.dtype == np.int64
    assert back.dt == traj.dt
    np.testing.assert_array_equal(back.position, traj.position.astype(np.float32))
    np.testing.assert_array_equal(back.orientation, traj.orientation.astype(np.float32))
    np.testing.assert_array_equal(back.radius, traj.radius)
    assert back.position.dtype == back.orientation.dtype == np.float32


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_with_stride_and_sphere_subset(tmp_path, fmt):
    traj = make_trajectory(n_frames=10, n_spheres=6)
    subset = [4, 0, 2]
    out = write_usd(tmp_path / f"anim.{fmt}", make_scene(), traj, stride=3, spheres=subset)
    back = read_usd(out)
    expected = traj.subset(subset)
    np.testing.assert_array_equal(back.frame, traj.frame[::3])  # rows 0, 3, 6, 9
    np.testing.assert_array_equal(back.position, expected.position[::3].astype(np.float32))
    np.testing.assert_array_equal(back.orientation, expected.orientation[::3].astype(np.float32))
    np.testing.assert_array_equal(back.radius, expected.radius)
    stage = Usd.Stage.Open(str(out))  # keep the stage alive while its prims are used
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    assert list(instancer.GetIdsAttr().Get()) == subset  # swarm indices of the written spheres


def rotation_entries(q):
    """Rotation matrices (..., 3, 3) of quaternions (x, y, z, w) used as they are (no
    renormalisation): what a reader of the half-precision attribute builds."""
    x, y, z, w = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    return np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
                     2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                     2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
                    axis=-1).reshape(q.shape[:-1] + (3, 3))


def half_ulp(values):
    """The spacing of float16 at each value's magnitude (2^-10 relative, subnormals aside)."""
    v = np.abs(np.asarray(values, dtype=np.float16))
    return (np.nextafter(v, np.float16(np.inf)) - v).astype(np.float64)


def test_half_precision_orientations_are_the_best_half_rounding(tmp_path):
    """``orientations`` (quath, what Blender reads): each component within one half-precision
    step of the normalised quaternion (or of its negative), a rotation at least as close to the
    true one as plain nearest rounding gives (the matrix used without renormalising), and the
    sign of each quaternion kept from frame to frame."""
    traj = make_trajectory(n_frames=8, n_spheres=400, seed=4)
    rng = np.random.default_rng(5)
    # un-normalised input (lengths 0.5 to 2), and slowly turning spheres (consecutive frames
    # close, so that a sign flip between frames would be a writer's choice, not the data's)
    traj.orientation = (traj.orientation[:1] + 0.02 * rng.normal(size=traj.orientation.shape)) \
        * rng.uniform(0.5, 2.0, size=traj.orientation.shape[:2] + (1,))
    traj.orientation[:, :, :] *= np.where(rng.random((8, 400, 1)) < 0.5, -1.0, 1.0)  # any sign
    out = write_usd(tmp_path / "anim.usdc", None, traj)
    stage = Usd.Stage.Open(str(out))
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    previous = None
    for k, frame in enumerate(traj.frame):
        half = np.asarray(instancer.GetOrientationsAttr().Get(int(frame)), dtype=np.float64)
        unit = traj.orientation[k] / np.linalg.norm(traj.orientation[k], axis=1, keepdims=True)
        sign = np.where((half * unit).sum(axis=1) < 0.0, -1.0, 1.0)[:, None]
        target = sign * unit
        assert (np.abs(half - target) <= half_ulp(target) * (1 + 1e-9)).all()
        true = rotation_entries(unit)
        err = np.abs(rotation_entries(half) - true).max(axis=(1, 2))
        nearest = np.abs(rotation_entries(unit.astype(np.float16)) - true).max(axis=(1, 2))
        assert (err <= nearest + 1e-12).all()
        assert err.max() < 8 * 2.0**-11  # a few half-precision steps at most
        if previous is not None:
            assert ((half * previous).sum(axis=1) >= 0.0).all()  # the short way between frames
        previous = half


def test_half_orientations_is_never_worse_than_nearest_rounding():
    """Over random rotations, the chosen half quaternions beat component-wise nearest rounding
    on the largest rotation-matrix error (and never lose on any single quaternion)."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=(20_000, 4))
    unit = q / np.linalg.norm(q, axis=1, keepdims=True)
    best = half_orientations(q).astype(np.float64)
    true = rotation_entries(unit)
    err = np.abs(rotation_entries(best) - true).max(axis=(1, 2))
    nearest = np.abs(rotation_entries(unit.astype(np.float16)) - true).max(axis=(1, 2))
    assert (err <= nearest + 1e-12).all()
    assert err.max() < nearest.max()
    identity = half_orientations([[0.0, 0.0, 0.0, 3.0]])  # exact in half: kept exactly
    np.testing.assert_array_equal(identity, [[0, 0, 0, 1]])


@pytest.mark.parametrize("still", [0.0, 0.5, 1.0])
def test_half_orientations_of_unchanged_rows_are_the_whole_computation(still):
    """Reusing the previous frame's half values for the rows that did not turn gives exactly
    what the whole computation gives, frame after frame, signs included."""
    rng = np.random.default_rng(11)
    n, frames = 3000, 6
    q = np.empty((frames, n, 4))
    q[0] = rng.normal(size=(n, 4))
    for f in range(1, frames):
        turned = rng.random(n) >= still
        q[f] = q[f - 1]
        q[f, turned] = rng.normal(size=(int(turned.sum()), 4))
        q[f, turned & (rng.random(n) < 0.5)] *= -1.0  # the same rotation, the other sign too
    whole = incremental = incremental_q = None
    for f in range(frames):
        whole = half_orientations(q[f], whole)
        incremental, incremental_q = half_orientations(q[f], incremental, incremental_q), q[f]
        np.testing.assert_array_equal(incremental, whole)


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("spheres", [None, [4, 0, 2]])
def test_every_frame_writes_its_own_orientations_repeated_or_not(tmp_path, fmt, spheres):
    """Frames whose quaternions repeat the frame before's to the bit (a swarm that does not
    spin) write the same arrays again; any other frame writes its own: ``orientationsf`` at
    each sample is the float32 of that frame's quaternions, bits included in ``.usda`` (a frame
    that differs from the one before only by a zero's sign writes that sign; the crate format,
    ``.usdc``, stores arrays equal by value once, so there the sign of a zero may be that of an
    equal array written before), and ``orientations`` is what the half-precision choice gives
    frame after frame from scratch."""
    traj = make_trajectory(n_frames=7, n_spheres=5, seed=4)
    q = traj.orientation
    q[1] = q[0]  # repeated
    q[2] = q[0]
    q[3] = unit_quaternions(np.random.default_rng(5), (5,))  # turned
    q[4] = q[0]  # back to an earlier frame's
    q[4, 1, 2] = 0.0
    q[5] = q[4]
    q[5, 1, 2] = -0.0  # only a zero's sign differs from the frame before
    q[6] = q[5]
    out = write_usd(tmp_path / f"anim.{fmt}", None, traj, spheres=spheres)
    stage = Usd.Stage.Open(str(out))
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    chosen = np.arange(5) if spheres is None else np.asarray(spheres)
    whole = None
    for k, frame in enumerate(traj.frame):
        want = q[k][chosen]
        got_f = np.array(instancer.GetOrientationsfAttr().Get(float(frame)), dtype=np.float32)
        if fmt == "usda":
            np.testing.assert_array_equal(got_f.view(np.uint32),
                                          want.astype(np.float32).view(np.uint32))
        else:
            np.testing.assert_array_equal(got_f, want.astype(np.float32))
        whole = half_orientations(want, whole)
        got_h = np.array(instancer.GetOrientationsAttr().Get(float(frame)), dtype=np.float16)
        np.testing.assert_array_equal(got_h, whole)


@pytest.mark.parametrize("attribute", ["orientationsf", "orientations"])
def test_usd_reads_rotations_in_warpsim_convention(tmp_path, attribute):
    """USD's own instance transforms equal warpsim's (x, y, z, w) rotations and positions.

    This checks the quaternion component order independently of our reader: with only the
    half-precision ``orientations`` left, the same holds to half precision.
    """
    traj = make_trajectory()
    out = write_usd(tmp_path / "anim.usda", None, traj)
    stage = Usd.Stage.Open(str(out))
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    if attribute == "orientations":
        instancer.GetOrientationsfAttr().Clear()
    k = 2
    xforms = np.array(instancer.ComputeInstanceTransformsAtTime(int(traj.frame[k]),
                                                                int(traj.frame[k])))
    # Gf matrices act on row vectors: rows 0..2 are the images of the scaled local axes.
    linear = np.transpose(xforms[:, :3, :3], (0, 2, 1))
    expected = quat_to_matrix(traj.orientation[k]) * traj.radius.astype(np.float32)[:, None, None]
    tol = 1e-6 if attribute == "orientationsf" else 4 * HALF_ULP
    np.testing.assert_allclose(linear, expected, rtol=0, atol=tol)
    np.testing.assert_allclose(xforms[:, 3, :3], traj.position[k].astype(np.float32), atol=0)


def test_overwrite_reads_the_new_file(tmp_path):
    path = tmp_path / "anim.usdc"
    first, second = make_trajectory(seed=1), make_trajectory(seed=2, first=0, step=1)
    write_usd(path, None, first)
    read_usd(path)
    write_usd(path, None, second)
    back = read_usd(path)  # never a cached layer of the previous file
    np.testing.assert_array_equal(back.frame, second.frame)
    np.testing.assert_array_equal(back.position, second.position.astype(np.float32))


def test_read_rejects_files_not_written_by_warpsim(tmp_path):
    stage = Usd.Stage.CreateNew(str(tmp_path / "other.usda"))
    UsdGeom.Xform.Define(stage, "/World")
    stage.Save()
    with pytest.raises(ValueError, match="PointInstancer"):
        read_usd(tmp_path / "other.usda")
    with pytest.raises(FileNotFoundError):
        read_usd(tmp_path / "missing.usda")


# --------------------------------------------------------------------------------------------
# Stage


@pytest.mark.parametrize("fmt", FORMATS)
def test_stage_time_metadata_and_axes(tmp_path, fmt):
    dt = 1.0 / 30.0
    traj = make_trajectory(n_frames=9, first=1_000_003, step=7, dt=dt)
    out = write_usd(tmp_path / f"anim.{fmt}", None, traj, stride=2)
    stage = Usd.Stage.Open(str(out))
    assert stage.GetTimeCodesPerSecond() == 1.0 / dt
    assert stage.GetFramesPerSecond() == 1.0 / dt
    assert stage.GetStartTimeCode() == traj.frame[0]
    assert stage.GetEndTimeCode() == traj.frame[8]  # rows 0, 2, 4, 6, 8: the last is row 8
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().GetPath() == "/World"
    positions = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres")).GetPositionsAttr()
    assert positions.GetTimeSamples() == [float(f) for f in traj.frame[::2]]


def compliance_errors(path) -> list[str]:
    """Errors of USD's compliance checker (``UsdUtils.ComplianceChecker`` where the installed
    USD has it; newer releases replaced it by the ``UsdValidation`` validators)."""
    checker_type = getattr(UsdUtils, "ComplianceChecker", None)
    if checker_type is not None:
        checker = checker_type()
        checker.CheckCompliance(str(path))
        return list(checker.GetErrors()) + list(checker.GetFailedChecks())
    from pxr import UsdValidation

    context = UsdValidation.ValidationContext(
        UsdValidation.ValidationRegistry().GetOrLoadAllValidators())
    return [f"{e.GetName()}: {e.GetMessage()}" for e in context.Validate(Usd.Stage.Open(str(path)))
            if e.GetType() == UsdValidation.ValidationErrorType.Error]


@pytest.mark.parametrize("fmt", FORMATS)
def test_compliance_checker_reports_no_errors(tmp_path, fmt):
    out = write_usd(tmp_path / f"anim.{fmt}", make_scene(), make_trajectory())
    assert compliance_errors(out) == []


def test_checker_would_catch_a_broken_stage(tmp_path):
    """The compliance check is not vacuous: a stage without up axis or default prim fails it."""
    stage = Usd.Stage.CreateNew(str(tmp_path / "bare.usda"))
    UsdGeom.Sphere.Define(stage, "/Ball")
    stage.Save()
    assert compliance_errors(tmp_path / "bare.usda")


def test_obstacles_and_static_data_have_no_time_samples(tmp_path):
    out = write_usd(tmp_path / "anim.usdc", make_scene(), make_trajectory())
    stage = Usd.Stage.Open(str(out))
    obstacle_attrs = list(all_attributes(stage, "/World/Obstacles"))
    assert obstacle_attrs
    assert [a.GetPath() for a in obstacle_attrs if a.GetNumTimeSamples()] == []
    instancer = stage.GetPrimAtPath("/World/Spheres")
    animated = sorted(a.GetName() for a in all_attributes(stage, "/World/Spheres")
                      if a.GetNumTimeSamples())
    assert animated == ["orientations", "orientationsf", "positions"]
    assert instancer.GetAttribute("scales").Get() is not None


def test_obstacles_round_trip_and_world_placement(tmp_path):
    scene = make_scene()
    out = write_usd(tmp_path / "anim.usda", scene, make_trajectory())
    back = read_usd_boxes(out)
    for field in ("center", "half_extents", "rotation", "radius"):
        np.testing.assert_allclose(getattr(back, field), getattr(scene.boxes, field),
                                   rtol=0, atol=1e-15)

    # What a viewer shows: every obstacle is a mesh whose points land on its box's surface.
    stage = Usd.Stage.Open(str(out))
    prims = stage.GetPrimAtPath("/World/Obstacles").GetChildren()
    assert [p.GetTypeName() for p in prims] == ["Mesh"] * 4
    for i, prim in enumerate(prims):
        to_world = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(0))
        local = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get(), dtype=np.float64)
        world = np.c_[local, np.ones(len(local))] @ to_world
        dist = scene.boxes[i].as_boxes().signed_distance(world[:, :3])
        np.testing.assert_allclose(dist, 0.0, atol=1e-6)  # float32 points
        if scene.boxes.radius[i] == 0.0:  # a sharp box: its 8 corners, each on 3 faces
            corners = np.unique(np.round(local, 6), axis=0)
            assert len(local) == 24 and len(corners) == len(np.unique(
                np.round(box_mesh(scene.boxes.half_extents[i])[0], 6), axis=0))


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_obstacle_keeps_its_material_and_colour(tmp_path, fmt):
    """What importers need to keep the look: each obstacle is a Mesh (not a Cube, whose
    material Blender drops) with the obstacle material bound and a constant displayColor."""
    out = write_usd(tmp_path / f"anim.{fmt}", make_scene(), make_trajectory())
    stage = Usd.Stage.Open(str(out))
    prims = stage.GetPrimAtPath("/World/Obstacles").GetChildren()
    assert len(prims) == 4
    for prim in prims:
        assert prim.GetTypeName() == "Mesh"
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        assert material.GetPath() == "/World/Looks/Obstacle"
        assert prim.HasAPI(UsdShade.MaterialBindingAPI)
        color = UsdGeom.Gprim(prim).GetDisplayColorPrimvar()
        assert color.GetInterpolation() == UsdGeom.Tokens.constant
        np.testing.assert_allclose(color.Get()[0], usd_module.OBSTACLE_COLOR, rtol=1e-6)
    # the shapes are abstract: never drawn themselves
    shapes = stage.GetPrimAtPath("/World/ObstacleShapes")
    assert shapes.IsAbstract()
    drawn = [p.GetPath() for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    assert not any(str(p).startswith("/World/ObstacleShapes") for p in drawn)


def test_identical_boxes_share_one_mesh(tmp_path):
    """A lattice of equal boxes stores the mesh once; placements and exact data per box."""
    k = 50
    rng = np.random.default_rng(3)
    boxes = warpsim.RoundedBoxes(center=rng.uniform(-5, 5, (k, 3)),
                                 half_extents=np.tile([0.2, 0.1, 0.3], (k, 1)),
                                 rotation=unit_quaternions(rng, (k,)),
                                 radius=np.where(np.arange(k) % 2, 0.05, 0.0))
    out = write_usd(tmp_path / "anim.usdc", boxes, make_trajectory())
    stage = Usd.Stage.Open(str(out))
    assert len(stage.GetPrimAtPath("/World/ObstacleShapes").GetAllChildren()) == 2
    back = read_usd_boxes(out)
    for field in ("center", "half_extents", "radius"):
        np.testing.assert_array_equal(getattr(back, field), getattr(boxes, field))
    np.testing.assert_allclose(back.rotation, boxes.rotation, rtol=0, atol=1e-15)
    one_shape = warpsim.RoundedBoxes(center=boxes.center, half_extents=boxes.half_extents)
    small = write_usd(tmp_path / "one.usdc", one_shape, make_trajectory()).stat().st_size
    assert small < 14_500 + 200 * k  # the mesh is not repeated per box


def test_no_scene_writes_spheres_only(tmp_path):
    out = write_usd(tmp_path / "anim.usda", None, make_trajectory())
    assert read_usd_boxes(out) is None
    assert read_usd(out).sphere_count == 5


# --------------------------------------------------------------------------------------------
# Files: atomic writes, extensions, size


def test_bad_extension_names_the_path(tmp_path):
    for name in ("anim.usd", "anim.usdz", "anim.txt", "anim"):
        with pytest.raises(ValueError, match=name):
            write_usd(tmp_path / name, None, make_trajectory())
    assert list(tmp_path.iterdir()) == []


def partial_then_fail(layer, path):
    """Stand-in for the exporter that dies halfway through writing the file."""
    with open(path, "wb") as f:
        f.write(b"PXR-USDC half a file")
    raise OSError("disk full")


@pytest.mark.parametrize("fmt", FORMATS)
def test_failed_write_leaves_nothing(tmp_path, monkeypatch, fmt):
    monkeypatch.setattr(usd_module, "export_layer", partial_then_fail)
    with pytest.raises(OSError, match="disk full"):
        write_usd(tmp_path / f"anim.{fmt}", make_scene(), make_trajectory())
    assert list(tmp_path.iterdir()) == []


def test_failed_write_keeps_the_existing_file(tmp_path, monkeypatch):
    path = tmp_path / "anim.usdc"
    write_usd(path, None, make_trajectory(seed=1))
    before = path.read_bytes()
    monkeypatch.setattr(usd_module, "export_layer", partial_then_fail)
    with pytest.raises(OSError):
        write_usd(path, None, make_trajectory(seed=2))
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["anim.usdc"]


def test_failed_rename_leaves_no_temporary(tmp_path, monkeypatch):
    path = tmp_path / "anim.usda"
    path.write_text("previous content")
    seen = []

    def failing_replace(src, dst):
        seen.append(os.path.basename(src))
        raise PermissionError("target locked")

    monkeypatch.setattr(files_module.os, "replace", failing_replace)
    with pytest.raises(PermissionError):
        write_usd(path, None, make_trajectory())
    assert path.read_text() == "previous content"
    assert [p.name for p in tmp_path.iterdir()] == ["anim.usda"]
    # The temporary name kept the real extension (USD picks the format from it).
    assert seen[0].startswith("anim.tmp") and seen[0].endswith(".usda")


def test_size_warning_when_estimate_exceeds_max_bytes(tmp_path):
    with pytest.warns(LargeOutputWarning, match="stride"):
        write_usd(tmp_path / "anim.usdc", None, make_trajectory(), max_bytes=1000)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        write_usd(tmp_path / "anim.usdc", None, make_trajectory(), max_bytes=1000, warn=False)
        write_usd(tmp_path / "anim.usdc", None, make_trajectory())  # default: far below 2 GB


@pytest.mark.slow
@pytest.mark.parametrize("fmt", FORMATS)
def test_size_estimate_matches_measured_files(tmp_path, fmt):
    """The calibrated model stays within 15% of real files of another shape than it was fit on."""
    traj = make_trajectory(n_frames=40, n_spheres=300, seed=3)
    out = write_usd(tmp_path / f"anim.{fmt}", None, traj)
    actual = out.stat().st_size
    assert abs(estimate_usd_bytes(300, 40, fmt) - actual) < 0.15 * actual
    assert estimate_usd_bytes(300, 20, f".{fmt}") < estimate_usd_bytes(300, 40, fmt)
    with pytest.raises(ValueError, match="fmt"):
        estimate_usd_bytes(1, 1, "usdz")


def test_bad_selection_is_refused(tmp_path):
    traj = make_trajectory(n_spheres=4)
    path = tmp_path / "anim.usda"
    for kwargs, match in [({"stride": 0}, "stride"), ({"stride": 1.5}, "stride"),
                          ({"spheres": [0, 4]}, r"spheres\[1\]"),
                          ({"spheres": [1, 1]}, "repeat"), ({"spheres": [0.5]}, "spheres")]:
        with pytest.raises(ValueError, match=match):
            write_usd(path, None, traj, **kwargs)
    with pytest.raises(FileNotFoundError):
        write_usd(tmp_path / "missing" / "anim.usda", None, traj)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_import_warpsim_does_not_import_pxr():
    code = ("import sys, warpsim; assert 'pxr' not in sys.modules; "
            "warpsim.export.write_usd; assert 'pxr' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


@pytest.mark.slow
def test_the_file_helpers_do_not_import_pxr():
    """``warpsim.export.files`` is standard library only: a writer of events or JSON uses it
    without loading USD."""
    code = ("import sys; import warpsim.export.files; from warpsim.export import check_writable; "
            "assert 'pxr' not in sys.modules, 'pxr loaded'; "
            "assert 'PIL' not in sys.modules, 'Pillow loaded'")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


# --------------------------------------------------------------------------------------------
# Meshes


def edge_counts(counts, indices):
    """Directed edges of a polygon mesh -> number of faces using each."""
    edges = {}
    start = 0
    for n in counts:
        face = indices[start:start + n]
        start += n
        for a, b in zip(face, np.roll(face, -1), strict=True):
            edges[(int(a), int(b))] = edges.get((int(a), int(b)), 0) + 1
    return edges


def signed_volume_and_area(points, counts, indices):
    volume = area = 0.0
    start = 0
    for n in counts:
        face = points[indices[start:start + n]]
        start += n
        for k in range(1, n - 1):
            a, b, c = face[0], face[k], face[k + 1]
            volume += np.dot(a, np.cross(b, c)) / 6.0
            area += 0.5 * np.linalg.norm(np.cross(b - a, c - a))
    return volume, area


def assert_closed_oriented_manifold(points, counts, indices):
    edges = edge_counts(counts, indices)
    assert all(c == 1 for c in edges.values()), "a directed edge is used twice"
    assert all((b, a) in edges for a, b in edges), "an edge has one face only"
    euler = len(points) - len(edges) // 2 + len(counts)
    assert euler == 2  # a sphere-like closed surface
    assert np.unique(indices).size == len(points)  # no unused vertex


@pytest.mark.slow
@settings(max_examples=40, deadline=None)
@given(h=st.tuples(*[st.sampled_from([0.0, 0.25, 1.0, 3.0])] * 3),
       radius=st.sampled_from([0.0, 0.05, 0.5, 2.0]), segments=st.sampled_from([2, 4, 8]))
def test_rounded_box_mesh_vertices_at_exact_distance(h, radius, segments):
    points, counts, indices = rounded_box_mesh(h, radius, segments)
    core = np.asarray(h)
    distance = np.linalg.norm(points - np.clip(points, -core, core), axis=1)
    np.testing.assert_allclose(distance, radius, rtol=0, atol=1e-14 * (1.0 + radius + max(h)))
    assert points.shape == ((segments + 2) ** 3 - segments**3, 3)
    assert counts.shape == (6 * (segments + 1) ** 2,) and (counts == 4).all()
    assert_closed_oriented_manifold(points, counts, indices)


@pytest.mark.slow
@pytest.mark.parametrize("segments, tol", [(4, 0.03), (8, 0.008), (16, 0.002)])
def test_rounded_box_mesh_volume_and_area_converge(segments, tol):
    """Outward-facing (positive volume) and close to the exact rounded box (Steiner formulas)."""
    h, r = np.array([1.0, 0.5, 0.25]), 0.3
    a, b, c = 2.0 * h
    volume = a * b * c + 2 * r * (a * b + b * c + c * a) + np.pi * r**2 * (a + b + c) \
        + 4.0 / 3.0 * np.pi * r**3
    area = 2 * (a * b + b * c + c * a) + 2 * np.pi * r * (a + b + c) + 4 * np.pi * r**2
    v, s = signed_volume_and_area(*rounded_box_mesh(h, r, segments))
    assert 0 < volume - v < tol * volume  # inscribed: a little smaller
    assert 0 < area - s < tol * area


def test_checker_sphere_mesh():
    points, counts, indices, light = checker_sphere_mesh(16, 8)
    np.testing.assert_allclose(np.linalg.norm(points, axis=1), 1.0, atol=1e-15)
    assert_closed_oriented_manifold(points, counts, indices)
    volume, _ = signed_volume_and_area(points, counts, indices)
    assert 0.9 * 4.0 / 3.0 * np.pi < volume < 4.0 / 3.0 * np.pi
    assert light.sum() == len(light) // 2  # the eight octants split the faces evenly
    start = 0
    for n, is_light in zip(counts, light, strict=True):
        corner = points[indices[start:start + n]]
        start += n
        signs = np.sign(np.where(np.abs(corner) < 1e-12, 0.0, corner))
        # every corner lies in (the closure of) the face's octant
        face_sign = np.sign(corner.mean(axis=0))
        assert ((signs == 0) | (signs == face_sign)).all()
        assert (face_sign.prod() > 0) == is_light


@pytest.mark.parametrize("args", [((1, 1), 0.1, 8), ((1, 1, -1), 0.1, 8), ((1, 1, 1), -0.1, 8),
                                  ((1, 1, 1), 0.1, 3), ((1, 1, 1), 0.1, 0)])
def test_rounded_box_mesh_bad_input(args):
    with pytest.raises(ValueError):
        rounded_box_mesh(*args)


# --------------------------------------------------------------------------------------------
# Motion data, frame selection, reading one frame


def with_motion(traj, seed=9, spin=True):
    """The trajectory with random velocities [m/s] and angular velocities [rad/s]."""
    rng = np.random.default_rng(seed)
    shape = traj.position.shape
    traj.velocity = rng.normal(size=shape) * 4.0
    traj.angular_velocity = rng.normal(size=shape) * 10.0 if spin else np.zeros(shape)
    return traj


@pytest.mark.parametrize("fmt", FORMATS)
def test_velocities_round_trip_and_usd_units(tmp_path, fmt):
    """``velocities`` are the trajectory's to the float32 bit; ``angularVelocities`` are in
    degrees per second, world frame: USD's own placement between two samples moves each
    instance by v * delta and turns it by omega * delta about the world axis."""
    traj = with_motion(make_trajectory(n_frames=4, n_spheres=6, first=10, step=1, dt=0.02))
    out = write_usd(tmp_path / f"anim.{fmt}", None, traj)
    back = read_usd(out)
    np.testing.assert_array_equal(back.velocity, traj.velocity.astype(np.float32))
    np.testing.assert_allclose(back.angular_velocity, traj.angular_velocity, rtol=1e-6, atol=0)

    stage = Usd.Stage.Open(str(out))
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    degrees = np.asarray(instancer.GetAngularVelocitiesAttr().Get(10), dtype=np.float64)
    np.testing.assert_allclose(degrees, np.degrees(traj.angular_velocity[0]), rtol=1e-6)
    half = 0.5  # time codes after frame 10: half a frame, dt / 2 seconds
    xforms = np.array(instancer.ComputeInstanceTransformsAtTime(10 + half, 10))
    moved = traj.position[0] + traj.velocity[0] * half * traj.dt
    np.testing.assert_allclose(xforms[:, 3, :3], moved, rtol=0, atol=1e-5)
    omega = traj.angular_velocity[0]
    angle = np.linalg.norm(omega, axis=1) * half * traj.dt
    axis = omega / np.linalg.norm(omega, axis=1, keepdims=True)
    turn = quat_to_matrix(np.c_[axis * np.sin(angle / 2)[:, None], np.cos(angle / 2)])
    expected = turn @ quat_to_matrix(traj.orientation[0]) * traj.radius[:, None, None]
    linear = np.transpose(xforms[:, :3, :3], (0, 2, 1))
    np.testing.assert_allclose(linear, expected, rtol=0, atol=2e-6)


def test_velocities_written_only_when_asked_and_present(tmp_path):
    traj = with_motion(make_trajectory())
    plain = write_usd(tmp_path / "plain.usdc", None, traj, velocities=False)
    assert read_usd(plain).velocity is None and read_usd(plain).angular_velocity is None
    with pytest.raises(ValueError, match="velocities"):
        write_usd(tmp_path / "x.usdc", None, make_trajectory(), velocities=True)
    bad = make_trajectory()
    bad.velocity = np.zeros((2, 5, 3))
    with pytest.raises(ValueError, match=r"trajectory\.velocity"):
        write_usd(tmp_path / "x.usdc", None, bad)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.usdc"]


def test_stride_keeps_the_last_frame_like_run_every(tmp_path):
    traj = with_motion(make_trajectory(n_frames=10))
    out = write_usd(tmp_path / "anim.usdc", None, traj, stride=4)
    back = read_usd(out)
    np.testing.assert_array_equal(back.frame, traj.frame[[0, 4, 8, 9]])
    np.testing.assert_array_equal(back.velocity, traj.velocity[[0, 4, 8, 9]].astype(np.float32))
    out = write_usd(tmp_path / "anim.usdc", None, traj, stride=100)
    np.testing.assert_array_equal(read_usd(out).frame, traj.frame[[0, 9]])


def test_read_usd_frame_by_frame_index_and_from_the_end(tmp_path):
    traj = with_motion(make_trajectory(n_frames=5, first=7, step=3))  # frames 7, 10, ..., 19
    out = write_usd(tmp_path / "anim.usda", None, traj, spheres=[3, 1])
    for frame, row in ((10, 1), (-1, 4), (-5, 0), (19, 4)):
        one = read_usd_frame(out, frame)
        assert one.frame.tolist() == [traj.frame[row]]
        np.testing.assert_array_equal(one.position[0],
                                      traj.position[row][[3, 1]].astype(np.float32))
        np.testing.assert_array_equal(one.velocity[0],
                                      traj.velocity[row][[3, 1]].astype(np.float32))
        np.testing.assert_array_equal(one.radius, traj.radius[[3, 1]])
    for bad, match in ((11, r"7\.\.19"), (-6, "only 5"), (2.0, "integer"), (True, "integer")):
        with pytest.raises(ValueError, match=match):
            read_usd_frame(out, bad)


def test_upper_case_extension_keeps_the_name_and_the_format(tmp_path):
    out = write_usd(tmp_path / "anim.USDC", None, make_trajectory())
    assert [p.name for p in tmp_path.iterdir()] == ["anim.USDC"]
    assert out.read_bytes()[:8] == b"PXR-USDC"
    out = write_usd(tmp_path / "text.UsdA", None, make_trajectory())
    assert out.read_bytes()[:9] == b"#usda 1.0"
    np.testing.assert_array_equal(read_usd(out).frame, make_trajectory().frame)


# --------------------------------------------------------------------------------------------
# Errors: one line, naming the file


@pytest.mark.parametrize("content", [b"PXR-USDC truncated", b"#usda 1.0\n( broken",
                                     b"\x00\x01 not usd at all"])
@pytest.mark.parametrize("suffix", [".usdc", ".usda"])
def test_corrupt_files_give_one_line_value_errors(tmp_path, content, suffix):
    path = tmp_path / f"bad{suffix}"
    path.write_bytes(content)
    for reader in (read_usd, read_usd_boxes, lambda p: read_usd_frame(p, 0)):
        with pytest.raises(ValueError) as info:
            reader(path)
        message = str(info.value)
        assert str(path) in message and "\n" not in message
        assert type(info.value) is ValueError  # not pxr's Tf.ErrorException


def test_unwritable_destination_is_an_os_error_naming_the_file(tmp_path, monkeypatch):
    """pxr's own failure to write becomes one OSError line naming the file."""
    from pxr import Tf

    def failing_export(self, path, *args, **kwargs):
        raise Tf.ErrorException("\n\tError in 'Sdf::Export' at line 1 in file x.cpp : "
                                "'Unable to open file for write'")

    from pxr import Sdf

    monkeypatch.setattr(Sdf.Layer, "Export", failing_export)
    with pytest.raises(OSError) as info:
        write_usd(tmp_path / "anim.usdc", None, make_trajectory())
    assert "anim" in str(info.value) and "Unable to open file for write" in str(info.value)
    assert "\n" not in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_check_writable_before_a_long_run(tmp_path):
    from warpsim.export import check_writable

    (tmp_path / "dir.usdc").mkdir()
    assert check_writable(tmp_path / "a.USDC", (".usdc", ".usda")) == tmp_path / "a.USDC"
    assert [p.name for p in tmp_path.iterdir()] == ["dir.usdc"]  # the probe file is gone
    for bad, error, match in (("", ValueError, "empty"), ("  ", ValueError, "empty"),
                              (tmp_path / "a.obj", ValueError, "must end in"),
                              (tmp_path / "dir.usdc", ValueError, "folder"),
                              (tmp_path / "no" / "a.usdc", FileNotFoundError, "does not exist")):
        with pytest.raises(error, match=match):
            check_writable(bad, (".usdc", ".usda"))
    if os.path.isdir("/proc"):  # a virtual file system: nothing can be created there
        with pytest.raises(OSError, match="/proc"):
            check_writable("/proc/x.usdc", (".usdc",))


# --------------------------------------------------------------------------------------------
# Every variant: validators clean, size estimate close


def variants():
    """(name, write_usd keywords, trajectory maker, scene maker)."""
    return [
        ("plain", {}, make_trajectory, make_scene),
        ("velocities", {}, lambda: with_motion(make_trajectory()), make_scene),
        ("no spin velocities", {}, lambda: with_motion(make_trajectory(), spin=False),
         make_scene),
        ("subset and stride", {"spheres": [4, 0], "stride": 4},
         lambda: with_motion(make_trajectory(n_frames=9)), make_scene),
        ("no obstacles", {}, make_trajectory, lambda: None),
        ("one sphere one frame", {}, lambda: make_trajectory(n_frames=1, n_spheres=1),
         make_scene),
    ]


@pytest.mark.slow
@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("variant", variants(), ids=lambda v: v[0])
def test_validators_clean_on_every_variant(tmp_path, fmt, variant):
    _, kwargs, traj, scene = variant
    out = write_usd(tmp_path / f"anim.{fmt}", scene(), traj(), **kwargs)
    assert compliance_errors(out) == []


@pytest.mark.slow
def test_size_estimate_counts_obstacles_spin_and_velocities(tmp_path):
    """Within 15% of written files, for spinning and non-spinning spheres, with velocities,
    and with obstacles of shared and of distinct shapes."""
    rng = np.random.default_rng(11)
    k = 60
    shared = warpsim.RoundedBoxes(center=rng.uniform(-9, 9, (k, 3)),
                                  half_extents=np.tile([0.3, 0.2, 0.1], (k, 1)),
                                  radius=np.where(np.arange(k) % 3 == 0, 0.05, 0.0))
    distinct = warpsim.RoundedBoxes(center=rng.uniform(-9, 9, (k, 3)),
                                    half_extents=rng.uniform(0.1, 1.0, (k, 3)),
                                    radius=np.where(np.arange(k) % 2 == 0, 0.05, 0.0))
    n, f = 200, 30
    for boxes in (None, shared, distinct):
        for spinning in (True, False):
            for velocities in (False, True):
                traj = make_trajectory(n_frames=f, n_spheres=n, seed=3)
                if not spinning:
                    traj.orientation[:] = [0.0, 0.0, 0.0, 1.0]
                if velocities:
                    with_motion(traj, spin=spinning)
                out = write_usd(tmp_path / "anim.usdc", boxes, traj)
                actual = out.stat().st_size
                estimate = estimate_usd_bytes(n, f, "usdc", boxes=boxes, spinning=spinning,
                                              velocities=velocities)
                assert abs(estimate - actual) < 0.15 * actual, (boxes, spinning, velocities)


def test_reading_boxes_from_the_layer_equals_composition(tmp_path):
    """read_usd_boxes reads the layer's specs directly (fast for 1e5 boxes); on any file it
    does not recognise as laid out by write_usd (an edited box, a sublayer) it composes the
    stage instead. Both give the boxes USD itself composes."""
    scene = make_scene()
    out = write_usd(tmp_path / "anim.usda", scene, make_trajectory())

    def composed(path):
        return usd_read.boxes_of_stage(Usd.Stage.Open(str(path)), path)

    def same(a, b):
        return all(np.array_equal(getattr(a, f), getattr(b, f))
                   for f in ("center", "half_extents", "rotation", "radius"))

    assert same(read_usd_boxes(out), composed(out))
    stage = Usd.Stage.Open(str(out))
    box = stage.GetPrimAtPath("/World/Obstacles/Box_0001")
    box.GetAttribute("xformOp:translate").Set((5.0, 6.0, 7.0))  # moved in a DCC, say
    box.GetAttribute("warpsim:radius").Set(0.25)  # an override on the box, not its shape
    stage.GetRootLayer().Save()
    edited = read_usd_boxes(out)
    assert same(edited, composed(out))
    assert edited.center[1].tolist() == [5.0, 6.0, 7.0] and edited.radius[1] == 0.25
    assert edited.radius[0] == scene.boxes.radius[0]


def test_trajectory_repr_is_one_short_line():
    traj = with_motion(make_trajectory(n_frames=200, n_spheres=1000))
    text = repr(traj)
    assert text == ("Trajectory(200 records x 1000 spheres, frames 7..604, dt=0.016666666666666666 "
                    "s, float64, with velocity, angular_velocity)")
    sub = traj.subset([3, 1])
    assert sub.sphere_count == 2 and sub.velocity.shape == (200, 2, 3)
    np.testing.assert_array_equal(sub.angular_velocity, traj.angular_velocity[:, [3, 1]])
