"""The closed sets: one list each, members equal to their strings, anything else refused in one
line naming the field."""

import pytest

import warpsim as ws
from warpsim import validation as check
from warpsim.apps.bench import build_parser as bench_parser
from warpsim.apps.cli import build_parser as cli_parser


def test_members_are_their_strings():
    assert ws.Motion.LINEAR == "linear" and ws.Motion("ballistic") is ws.Motion.BALLISTIC
    assert [m.value for m in ws.BroadPhase] == ["auto", "brute", "bvh", "grid", "walk"]
    assert f"{ws.BroadPhase.GRID}" == "grid" and str(ws.Motion.LINEAR) == "linear"
    assert check.broad_phase("bvh") is ws.BroadPhase.BVH
    assert check.motion(ws.Motion.BALLISTIC) is ws.Motion.BALLISTIC
    assert [int(k) for k in ws.ContactKind] == [0, 1]


@pytest.mark.parametrize("value", [True, False, 1, None, "BVH", "octree", b"bvh"])
def test_anything_else_is_refused_as_a_broad_phase(value):
    with pytest.raises(ValueError, match=r"^broad_phase must be one of \('auto', 'brute', "
                                         r"'bvh', 'grid', 'walk'\), got "):
        check.broad_phase(value)


@pytest.mark.parametrize("value", [True, 0, "Linear", "parabola"])
def test_anything_else_is_refused_as_a_motion(value):
    with pytest.raises(ValueError, match=r"^motion must be one of \('linear', 'ballistic'\)"):
        check.motion(value)


def test_a_boolean_broad_phase_is_refused_by_the_simulator(device):
    scene = ws.Scene(ws.RoundedBoxes(center=[[0, -1, 0]], half_extents=[[1, 0.5, 1]]))
    swarm = ws.Swarm([[0.0, 1.0, 0.0]], [[0.0, 0.0, 0.0]], radius=0.1)
    with pytest.raises(ValueError, match="broad_phase"):
        ws.Simulator(scene, swarm, broad_phase=True, device=device)


@pytest.mark.parametrize("parser, head", [(cli_parser, ["run", "room"]), (bench_parser, ["room"])])
def test_the_command_lines_offer_the_one_list(parser, head):
    for member in ws.BroadPhase:
        assert parser().parse_args([*head, "--broad-phase", member.value]).broad_phase == member
    for member in ws.Motion:
        assert parser().parse_args([*head, "--motion", member.value]).motion == member
    with pytest.raises(SystemExit):
        parser().parse_args([*head, "--broad-phase", "octree"])
