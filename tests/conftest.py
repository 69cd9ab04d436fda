"""Shared fixtures: the devices to test on and a tolerance table per precision (their values
are in ``helpers``, which tests import directly), and the hypothesis profiles.

Hypothesis runs under a named profile (``HYPOTHESIS_PROFILE``): ``ci`` (the default) draws the
same examples on every run (``derandomize=True``, no example database), so what the suite
catches does not vary between runs or machines; ``wide`` draws fresh random examples each run,
``helpers.WIDE_FACTOR`` times as many in the tests that size themselves with
``helpers.examples``, for a search on demand (``HYPOTHESIS_PROFILE=wide python -m pytest``).
"""

import pytest
from helpers import DEVICES, HYPOTHESIS_PROFILE, TOLERANCES
from hypothesis import settings

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
