"""Shared fixtures: the devices to test on and a tolerance table per precision (their values
are in ``helpers``, which tests import directly), and the hypothesis profiles.

Hypothesis runs under a named profile (``HYPOTHESIS_PROFILE``): ``ci`` (the default) draws the
same examples on every run (``derandomize=True``, no example database), so what the suite
catches does not vary between runs or machines; ``wide`` draws fresh random examples each run,
``helpers.WIDE_FACTOR`` times as many in the tests that size themselves with
``helpers.examples``, for a search on demand (``HYPOTHESIS_PROFILE=wide python -m pytest``).
``WARPSIM_TEST_SALT=N`` does the same for the NumPy seeds (``helpers.TEST_SALT``).
"""

import fcntl
import os

import numpy as np
import pytest
from helpers import DEVICES, HYPOTHESIS_PROFILE, TEST_SALT, TOLERANCES, salted_default_rng
from hypothesis import settings

if TEST_SALT is not None:
    np.random.default_rng = salted_default_rng(np.random.default_rng, TEST_SALT)

settings.register_profile("ci", derandomize=True, database=None, deadline=None,
                          print_blob=True)
settings.register_profile("wide", derandomize=False, deadline=None, print_blob=True)
settings.load_profile(HYPOTHESIS_PROFILE)


@pytest.fixture(params=DEVICES)
def device(request):
    """Every available Warp device: ``cpu``, plus ``cuda:0`` when there is one."""
    return request.param


@pytest.fixture(params=["float32", "float64"])
def precision(request):
    return request.param


@pytest.fixture
def tol(precision):
    return TOLERANCES[precision]


def build_each_module_once():
    """Test processes (pytest-xdist's workers) share Warp's kernel cache on disk, but nothing
    stops two of them from building the same kernel variant at the same time, each for several
    seconds. Here a process takes a lock file named for the module (in the cache directory)
    around its first load of each module, so a second process waits for the first's build and
    loads it from the cache. Warp's module class is internal: without it, nothing changes."""
    import warp as wp

    try:
        from warp._src.context import Module
    except ImportError:
        return
    original = Module.load
    passed = set()

    def load(self, device, *args, **kwargs):
        if id(self) in passed or not wp.config.kernel_cache_dir:
            return original(self, device, *args, **kwargs)
        folder = os.path.join(wp.config.kernel_cache_dir, "build-locks")
        os.makedirs(folder, exist_ok=True)
        with open(os.path.join(folder, self.get_module_identifier() + ".lock"), "w") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                return original(self, device, *args, **kwargs)
            finally:
                passed.add(id(self))

    Module.load = load


if os.environ.get("PYTEST_XDIST_WORKER"):
    build_each_module_once()
