"""``benchmarks.instructions``: the saved case is the bundled scene (so both sides of a
comparison run the scene the study names), and the counts come back from callgrind (when
valgrind is installed)."""

import hashlib
import json
import shutil

import numpy as np
import pytest

import warpsim as ws
from benchmarks import instructions as study


def scene_from_saved(path: str) -> tuple[ws.Scene, ws.Swarm]:
    """The scene and swarm as the counted process rebuilds them from the saved arrays."""
    d = np.load(path)
    scene = ws.Scene(ws.RoundedBoxes(d["center"], d["half_extents"], d["rotation"],
                                     d["box_radius"]), **json.loads(str(d["physics"])))
    return scene, ws.Swarm(d["position"], d["velocity"], d["radius"], d["mass"])


@pytest.mark.parametrize("name", ["room", "spin", "plates"])
def test_the_saved_case_advances_as_the_bundled_scene(name, tmp_path):
    """The arrays and physics the study saves give the same states, bit for bit, as the
    bundled scene (its gravity, friction, retention, step, cap and clamp) with the same
    swarm: friction and spin (``spin``) and a lossy scene of plates included."""
    path = study.save_case(name, 64, 7.0, tmp_path)
    rebuilt, swarm = scene_from_saved(path)
    bundled = ws.Scene.load(name)
    states = []
    for scene in (bundled, rebuilt):  # the study names the motion; here the scene's own
        sim = ws.Simulator(scene, swarm, motion=bundled.motion, workers=1, device="cpu")
        sim.step(20)
        states.append(sim.state())
    for field in ("position", "velocity", "angular_momentum", "orientation", "energy"):
        np.testing.assert_array_equal(getattr(states[0], field), getattr(states[1], field),
                                      err_msg=field)
    if name == "room":  # its emitter has only the speed term, in every direction
        assert np.allclose(np.linalg.norm(swarm.velocity, axis=1), 7.0)


def test_the_summary_names_every_event_and_only_known_ones():
    """callgrind's closing summary, with and without the cache simulation (event names with
    digits), read into the study's names; other events are left out, no summary is None."""
    branch = ("==1== Events    : Ir Bc Bcm Bi Bim\n==1== Collected : 1000 200 30 4 1\n"
              "==1==\n==1== I refs: 1,000\n")
    assert study.summary(branch) == {"instructions": 1000, "branches": 200, "mispredicted": 30,
                                     "indirect": 4, "indirect_mispredicted": 1}
    cache = ("==7== Events    : Ir Dr Dw I1mr D1mr D1mw ILmr DLmr DLmw Bc Bcm Bi Bim Ge\n"
             "==7== Collected : 900 300 120 2 5 6 1 3 4 150 20 2 0 7\n")
    got = study.summary(cache)
    assert got == {"instructions": 900, "data_reads": 300, "data_writes": 120,
                   "l1_instruction_misses": 2, "l1_read_misses": 5, "l1_write_misses": 6,
                   "ll_instruction_misses": 1, "ll_read_misses": 3, "ll_write_misses": 4,
                   "branches": 150, "mispredicted": 20, "indirect": 2,
                   "indirect_mispredicted": 0}
    assert set(study.MEMORY_FIGURES) <= set(got)
    assert study.summary("==1== no summary here\n") is None


@pytest.mark.parametrize(("flags", "expected"), [
    ("fpu sse2 avx avx2 fma bmi2", ""),  # AMD family 25: the code is the CPU's own
    ("fpu avx avx2 avx512f avx512dq avx512vl avx_vnni", " -target-feature -avx512f"),
    ("", ""),
])
def test_counted_kernels_leave_out_only_what_valgrind_cannot_run(flags, expected):
    """On a CPU with AVX-512 (which valgrind does not run) the counted kernel is built
    without it, in clang's front-end form; on others with no change; the first ``flags``
    line of ``/proc/cpuinfo`` decides, and a text without one changes nothing."""
    text = f"processor\t: 0\nflags\t\t: {flags}\nbugs\t\t: avx512f\n\nprocessor\t: 1\n"
    assert study.valgrind_flags(text) == expected
    assert study.valgrind_flags("processor\t: 0\n") == ""


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("valgrind") is None or shutil.which("callgrind_control") is None,
                    reason="valgrind is not installed (Debian's valgrind package)")
def test_callgrind_counts_the_frames_and_only_them(tmp_path):
    """The same swarm twice over (each sphere and its copy take the same path: there are no
    sphere-sphere contacts) costs twice the instructions and branches, to 1 %: what the
    count holds besides the spheres' frames (the build, the start-up, the launch from Python)
    is under 1 % of it; the simulated mispredictions nearly double (the predictor has seen
    the copies' branch patterns before, so to 10 %); the counted run ends in the state of the
    same frames run without valgrind; and it ran the object the build outside valgrind made
    (the code this machine runs, and no build of a minute or more inside valgrind)."""
    path = study.save_case("room", 300, 5.0, tmp_path)
    d = dict(np.load(path))
    doubled = {k: (np.concatenate([v, v]) if k in ("position", "velocity", "radius", "mass")
                   else v) for k, v in d.items()}
    twice = str(tmp_path / "twice.npz")
    np.savez(twice, **doubled)
    one = study.count(None, "float32", "linear", 10, "auto", path)
    two = study.count(None, "float32", "linear", 10, "auto", twice)
    for key in ("instructions", "branches"):
        assert two[key] / one[key] == pytest.approx(2.0, rel=0.01), key
    assert two["mispredicted"] / one["mispredicted"] == pytest.approx(2.0, rel=0.1)
    assert one["native_object"] and two["native_object"]
    assert one["instructions"] > 100 * 300 * 10  # at least 100 instructions a sphere-frame
    assert 0 < one["mispredicted"] < one["branches"] < one["instructions"]
    scene, swarm = scene_from_saved(path)
    sim = ws.Simulator(scene, swarm, precision="float32", motion="linear", workers=1,
                       device="cpu")
    sim.step(1 + 10)
    h = hashlib.sha256()
    s = sim.state()
    for field in ("position", "velocity", "angular_momentum", "orientation", "energy"):
        h.update(np.ascontiguousarray(getattr(s, field)).tobytes())
    assert one["hash"] == h.hexdigest()[:16]


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("valgrind") is None or shutil.which("callgrind_control") is None
                    or shutil.which("addr2line") is None,
                    reason="valgrind or addr2line is not installed")
def test_where_puts_the_counts_on_the_kernels_statements(tmp_path):
    """``--where`` (with ``--memory``): the kernel's statements hold all but a sliver of the
    counted instructions (the rest is the launch's C++ around the kernel), the same totals as
    without line tables and the cache model, their data writes are some of the counted ones,
    the cell list's loop is among the statements of a grid run, and the runs of the loads
    that wait for their stores are some of each statement's instructions."""
    path = study.save_case("room", 300, 60.0, tmp_path)
    plain = study.count(None, "float32", "linear", 10, "auto", path)
    where = study.count(None, "float32", "linear", 10, "auto", path, where=True, memory=True)
    writes = sum(s["data_writes"] for s in where["statements"])
    assert 0 < writes <= where["data_writes"]
    assert 0 < where["l1_read_misses"] <= where["data_reads"]
    assert where["instructions"] == pytest.approx(plain["instructions"], rel=1e-3)
    placed = sum(s["instructions"] for s in where["statements"] if s["file"] != "?")
    assert placed >= 0.97 * where["instructions"]
    assert sum(s["mispredicted"] for s in where["statements"]) <= where["mispredicted"]
    assert any(s["file"] == "candidates.py" and "cell_start" in s["text"]
               for s in where["statements"])
    # the runs of the loads that wait for their stores: some of the statement's instructions
    assert all(0 <= s["split_loads"] <= s["instructions"] for s in where["statements"])
