"""Shared fixtures: the devices to test on and a tolerance table per precision."""

import numpy as np
import pytest
import warp as wp

import warpsim  # noqa: F401  (sets Warp's log level before anything initialises it)

wp.init()

DEVICES = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])

#: Tolerances per precision. ``rel``: relative error of a computed length against a float64
#: reference at unit scale (a few hundred ulps: the sweep chains ~20 roundings through a square
#: root); ``t_abs``: absolute error of a contact fraction ``t``; ``unit``: deviation of a unit
#: vector's length; ``angle``: normal direction error [rad].
TOLERANCES = {
    "float32": {"rel": 2e-5, "t_abs": 2e-5, "unit": 1e-6, "angle": 2e-3},
    "float64": {"rel": 1e-11, "t_abs": 1e-11, "unit": 1e-13, "angle": 1e-7},
}


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


def np_dtype(precision: str):
    return np.float32 if precision == "float32" else np.float64
