"""The hypothesis profiles the README describes: fixed examples by default, a wider search on
demand; and the NumPy seeds' salt (``WARPSIM_TEST_SALT``), the same search for the tests that
draw with NumPy."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from helpers import (
    HYPOTHESIS_PROFILE,
    NUMPY_DEFAULT_RNG,
    TEST_SALT,
    WIDE_FACTOR,
    examples,
    salted_default_rng,
)
from hypothesis import settings


def test_default_profile_is_reproducible():
    """Without ``HYPOTHESIS_PROFILE`` the ``ci`` profile is loaded: derandomized, no database."""
    if "HYPOTHESIS_PROFILE" not in os.environ:
        assert HYPOTHESIS_PROFILE == "ci"
    if HYPOTHESIS_PROFILE == "ci":
        assert settings.default.derandomize
        assert settings.default.database is None
        assert examples(7) == 7


def test_wide_profile_draws_fresh_and_more_examples():
    wide = settings.get_profile("wide")
    assert not wide.derandomize
    if HYPOTHESIS_PROFILE == "wide":
        assert examples(7) == 7 * WIDE_FACTOR


def test_salted_seeds_draw_what_the_salt_and_the_seed_draw_together():
    original = NUMPY_DEFAULT_RNG
    salted = salted_default_rng(original, 101)
    assert salted(7).random() == original([101, 7]).random() != original(7).random()
    assert salted([3, 4]).random() == original([101, 3, 4]).random()
    assert salted(np.int64(7)).random() == original([101, 7]).random()
    seq = np.random.SeedSequence(5)
    assert salted(seq).random() == original(np.random.SeedSequence(5)).random()
    assert isinstance(salted(None), np.random.Generator)


def test_the_seeds_are_the_written_ones_unless_a_salt_is_set():
    if TEST_SALT is None:
        assert np.random.default_rng is NUMPY_DEFAULT_RNG
    else:
        assert np.random.default_rng(7).random() == \
            NUMPY_DEFAULT_RNG([TEST_SALT, 7]).random()


def test_the_salt_reaches_the_tests_processes(tmp_path):
    """``WARPSIM_TEST_SALT`` set for a run of pytest: the tests' draws move (the conftest
    salts them in every process)."""
    test = tmp_path / "test_draw.py"
    test.write_text("import numpy as np\n\n\ndef test_draw():\n"
                    "    print('DRAW', np.random.default_rng(7).random())\n")
    tests = Path(__file__).parent
    draws = {}
    for salt in (None, "101"):
        env = {k: v for k, v in os.environ.items() if k != "WARPSIM_TEST_SALT"}
        if salt is not None:
            env["WARPSIM_TEST_SALT"] = salt
        out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-s", "-p", "no:cacheprovider",
                              "--rootdir", str(tests), "--confcutdir", str(tests),
                              "-c", os.devnull, "-p", "conftest", str(test)],
                             capture_output=True, text=True, env={**env, "PYTHONPATH": str(tests)},
                             cwd=tmp_path)
        assert out.returncode == 0, out.stdout + out.stderr
        draws[salt] = float(out.stdout.split("DRAW ")[1].split()[0])
    assert draws[None] == NUMPY_DEFAULT_RNG(7).random()
    assert draws["101"] == NUMPY_DEFAULT_RNG([101, 7]).random()
