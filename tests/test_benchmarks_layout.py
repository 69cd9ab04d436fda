"""The benchmarks' bookkeeping: BENCHMARKS.md's table names every study, each study writes by
default where its committed results are, and the machine description carries the git commit."""

import re
import subprocess
from pathlib import Path

import pytest

from benchmarks import common
from warpsim.machine import git_commit, machine

ROOT = Path(__file__).resolve().parents[1]
HELPERS = {"__init__", "__main__", "common", "numpy_sweep"}  # modules that are not a study


def table_commands() -> list[str]:
    text = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    table = text.split("| command | measures |", 1)[1].split("\n\n", 1)[0]
    return re.findall(r"^\| `python -m benchmarks\.(\w+)`", table, flags=re.M)


def test_the_table_covers_every_study():
    studies = {p.stem for p in (ROOT / "benchmarks").glob("*.py")} - HELPERS
    studies |= {p.parent.name for p in (ROOT / "benchmarks").glob("*/__main__.py")}
    assert sorted(table_commands()) == sorted(studies)


def test_the_default_folder_holds_the_committed_results():
    """Each committed result is a study's default file, ``STUDY.json``, or one of its runs with
    other options, ``STUDY-VARIANT.json`` (``--out``; BENCHMARKS.md names the command)."""
    assert common.RESULTS == ROOT / "benchmarks" / "results"
    committed = {p.stem.split("-", 1)[0] for p in common.RESULTS.glob("*.json")}
    assert committed <= set(table_commands())
    text = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    assert "bench-results" not in text


def test_git_commit_of_a_repository_and_of_a_plain_folder(tmp_path):
    assert git_commit(tmp_path) == {"commit": None, "dirty": None}
    try:
        subprocess.run(["git", "init", "-q", str(tmp_path)], check=True)
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("git is not available")
    (tmp_path / "a.txt").write_text("one\n")
    env = ["-c", "user.name=t", "-c", "user.email=t@example.org"]
    subprocess.run(["git", *env, "-C", str(tmp_path), "add", "a.txt"], check=True)
    subprocess.run(["git", *env, "-C", str(tmp_path), "commit", "-qm", "one"], check=True)
    log = subprocess.run(["git", "-C", str(tmp_path), "log", "--format=%H"], check=True,
                         capture_output=True, text=True).stdout.split()
    assert git_commit(tmp_path) == {"commit": log[0], "dirty": False}
    (tmp_path / "a.txt").write_text("two\n")
    assert git_commit(tmp_path) == {"commit": log[0], "dirty": True}


def test_machine_records_versions_and_commit():
    info = machine()
    assert {"platform", "cpu", "cpu_id", "cores", "python", "numpy", "warp", "warpsim",
            "commit", "dirty"} <= set(info)


#: The studies that take ``--device`` and start through :func:`benchmarks.common.start`.
DEVICE_STUDIES = ("speed", "sweep", "hot_loop", "accuracy_tables", "opt_level", "broad_walk",
                  "end_to_end", "frame_floor")


@pytest.mark.parametrize("name", DEVICE_STUDIES)
def test_a_device_that_is_not_there_is_one_line_and_no_file(name, tmp_path):
    """``--device cuda:0`` on a machine without it (or any unknown device) stops the study
    before it measures anything, with one line naming the study and the device, and writes no
    results file."""
    import importlib

    study = importlib.import_module(f"benchmarks.{name}")
    out = tmp_path / "results.json"
    with pytest.raises(SystemExit) as stop:
        study.main(["--quick", "--device", "nosuch:7", "--out", str(out)])
    message = str(stop.value)
    assert "\n" not in message
    assert message.startswith(f"python -m benchmarks.{name}: error: device 'nosuch:7'")
    assert not out.exists()
