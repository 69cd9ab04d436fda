"""Mutation check of the geometry kernels: how many planted bugs the fast test subset catches.

Run on demand, never in CI (each mutant rebuilds the Warp modules that contain it)::

    pip install -e ".[mutation]"
    python -m benchmarks.mutation kernels/capsule.py kernels/slab.py

mutmut 2 (configured under ``[tool.mutmut]`` in ``pyproject.toml``) edits one source file in
place per mutant (a flipped comparison, another constant, a swapped operator, ...), runs that
file's fast test subset (``SUBSETS``), stops at its first failure and puts the file back. A
mutant is *killed* when a test fails, *survives* when all pass. The script runs mutmut under
``nice`` on one process, then prints a table per file and writes
``benchmarks/results/mutation.json``; the surviving mutants are listed with their diffs
(``mutmut show ID``) so that each gets a test or a note in BENCHMARKS.md saying why it is
equivalent. Do not read ``.mutmut-cache`` while a
run is going: mutmut's own lookups then fail ("Attribute Mutant.line is required").
"""

from __future__ import annotations

import argparse
import json
import os
import sqlite3
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.common import RESULTS

CACHE = Path(".mutmut-cache")
"""mutmut's record of every mutant and its status (SQLite, in the working directory)."""

PYTEST = "python -m pytest -x -q -p no:cacheprovider "

#: The fast test subset per kernel file: tests that build only small kernels that contain the
#: file's funcs (a cold Warp build per mutant dominates the time). The subsets run in float64
#: only (``-k float64``: one build per kernel instead of two; the funcs are the same source in
#: both precisions, and float64's tolerances are the tighter). The arc's subset calls its funcs
#: through one test kernel (``tests/test_arc_funcs.py``, and ``tests/test_arc_walk.py`` with the
#: same kernel; about 12 s a mutant) instead of the collide kernels that
#: ``test_arc_face_after_edge.py`` and ``test_arc_sweep.py`` build.
SUBSETS = {
    "kernels/capsule.py": "tests/test_func_contracts.py::test_segment_sphere_and_capsule "
                          "tests/test_func_contracts.py::test_far_passes_agree_with_the_exact_root "
                          "tests/test_rounded_box_funcs.py -k float64",
    "kernels/slab.py": "tests/test_func_contracts.py "
                       "tests/test_far_paths.py::test_point_sized_box_from_300_m",
    "kernels/rounded_box.py": "tests/test_rounded_box_funcs.py -k float64",
    "kernels/arc.py": "tests/test_arc_funcs.py tests/test_arc_walk.py -k float64",
}

KILLED = {"ok_killed", "ok_suspicious"}  # suspicious: a test failed, only slowly
SURVIVED = {"bad_survived"}


def run_mutmut(paths: list[str]) -> None:
    """``mutmut run`` over ``paths`` (one file at a time, low priority); exit codes 2/4/8 say
    that mutants survived or timed out, which is what the table reports."""
    with tempfile.TemporaryDirectory(prefix="mutation-kernels-") as kernel_cache:
        # every mutant's modules go to a private kernel cache, removed afterwards
        env = dict(os.environ, WARP_CACHE_PATH=kernel_cache,
                   PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}")
        for path in paths:
            runner = PYTEST + SUBSETS.get(path, SUBSETS["kernels/arc.py"])
            subprocess.run(["nice", "-n", "19", sys.executable, "-m", "mutmut", "run",
                            "--paths-to-mutate", path, "--runner", runner, "--no-progress"],
                           env=env, check=False)


def statuses() -> dict[str, dict[str, int]]:
    """Per source file, the count of mutants per mutmut status."""
    with sqlite3.connect(CACHE) as db:
        rows = db.execute(
            "SELECT SourceFile.filename, Mutant.status, COUNT(*) FROM Mutant "
            "JOIN Line ON Mutant.line = Line.id JOIN SourceFile ON Line.sourcefile = "
            "SourceFile.id GROUP BY SourceFile.filename, Mutant.status").fetchall()
    out: dict[str, dict[str, int]] = {}
    for filename, status, count in rows:
        out.setdefault(filename, {})[status] = count
    return out


def survivors() -> list[tuple[int, str]]:
    """``(id, file)`` of every surviving mutant."""
    with sqlite3.connect(CACHE) as db:
        return db.execute(
            "SELECT Mutant.id, SourceFile.filename FROM Mutant JOIN Line ON Mutant.line = "
            "Line.id JOIN SourceFile ON Line.sourcefile = SourceFile.id "
            "WHERE Mutant.status IN ('bad_survived')").fetchall()


def table(counts: dict[str, dict[str, int]]) -> list[dict]:
    """One row per file: killed, survived, other (timeouts, not run) and the score."""
    rows = []
    for filename, by_status in sorted(counts.items()):
        killed = sum(n for s, n in by_status.items() if s in KILLED)
        survived = sum(n for s, n in by_status.items() if s in SURVIVED)
        other = sum(by_status.values()) - killed - survived
        tested = killed + survived
        rows.append({"file": filename, "killed": killed, "survived": survived, "other": other,
                     "score": killed / tested if tested else float("nan")})
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="*", help="kernel files to mutate (default: none, "
                        "only report what .mutmut-cache holds)")
    parser.add_argument("--json", type=Path, default=RESULTS / "mutation.json")
    args = parser.parse_args(argv)
    if args.paths:
        run_mutmut(args.paths)
    if not CACHE.exists():
        print("no .mutmut-cache here: give the kernel files to mutate", file=sys.stderr)
        return 1
    rows = table(statuses())
    print("| file | killed | survived | other | score |")
    print("|---|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['file']} | {r['killed']} | {r['survived']} | {r['other']} "
              f"| {r['score']:.0%} |")
    alive = survivors()
    for mutant_id, filename in alive:
        print(f"\nsurvivor {mutant_id} ({filename}):")
        subprocess.run([sys.executable, "-m", "mutmut", "show", str(mutant_id)], check=False)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"files": rows, "survivors": [m for m, _ in alive]},
                                    indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
