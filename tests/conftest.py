"""Shared fixtures: the devices to test on and a tolerance table per precision (their values
are in ``helpers``, which tests import directly)."""

import pytest
from helpers import DEVICES, TOLERANCES


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


#: Modules whose import alone is slow (they build every kernel variant while being collected):
#: the fast tier (``-m "not slow"``) does not collect them; the full suite does.
SLOW_TO_COLLECT = {"test_kernel_variants.py"}


def pytest_ignore_collect(collection_path, config):
    if collection_path.name in SLOW_TO_COLLECT and config.getoption("markexpr") == "not slow":
        return True
    return None
