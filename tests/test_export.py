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
from pxr import Usd, UsdGeom, UsdUtils

import warpsim
import warpsim.export.files as files_module
import warpsim.export.usd as usd_module
from warpsim.export import (
    LargeOutputWarning,
    estimate_usd_bytes,
    read_usd,
    read_usd_boxes,
    write_usd,
)
from warpsim.export.mesh import checker_sphere_mesh, rounded_box_mesh
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


def test_half_precision_orientations_agree(tmp_path):
    """``orientations`` (quath, for older readers) holds the same quaternions, rounded to half."""
    traj = make_trajectory()
    out = write_usd(tmp_path / "anim.usdc", None, traj)
    stage = Usd.Stage.Open(str(out))
    instancer = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Spheres"))
    for k, frame in enumerate(traj.frame):
        half = np.asarray(instancer.GetOrientationsAttr().Get(int(frame)), dtype=np.float64)
        np.testing.assert_allclose(half, traj.orientation[k], rtol=0, atol=HALF_ULP)


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
    assert stage.GetEndTimeCode() == traj.frame[8]  # the last frame kept by stride 2
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

    # What a viewer shows: the cube corner (1, 1, 1) and the mesh points land on the boxes.
    stage = Usd.Stage.Open(str(out))
    prims = stage.GetPrimAtPath("/World/Obstacles").GetChildren()
    assert [p.GetTypeName() for p in prims] == ["Cube", "Mesh", "Mesh", "Cube"]
    rot = scene.boxes.rotation_matrices()
    for i, prim in enumerate(prims):
        to_world = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(0))
        if prim.GetTypeName() == "Cube":
            corner = np.array([1.0, 1.0, 1.0, 1.0]) @ to_world
            expected = rot[i] @ scene.boxes.half_extents[i] + scene.boxes.center[i]
            np.testing.assert_allclose(corner[:3], expected, atol=1e-12)
        else:
            local = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get(), dtype=np.float64)
            world = np.c_[local, np.ones(len(local))] @ to_world
            dist = scene.boxes[i].as_boxes().signed_distance(world[:, :3])
            np.testing.assert_allclose(dist, 0.0, atol=1e-6)  # float32 points


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
    monkeypatch.setattr(usd_module, "_export_layer", partial_then_fail)
    with pytest.raises(OSError, match="disk full"):
        write_usd(tmp_path / f"anim.{fmt}", make_scene(), make_trajectory())
    assert list(tmp_path.iterdir()) == []


def test_failed_write_keeps_the_existing_file(tmp_path, monkeypatch):
    path = tmp_path / "anim.usdc"
    write_usd(path, None, make_trajectory(seed=1))
    before = path.read_bytes()
    monkeypatch.setattr(usd_module, "_export_layer", partial_then_fail)
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


def test_import_warpsim_does_not_import_pxr():
    code = ("import sys, warpsim; assert 'pxr' not in sys.modules; "
            "warpsim.export; assert 'pxr' in sys.modules")
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
