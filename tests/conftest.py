"""Shared fixtures: every test that takes ``device`` runs on each available Warp device."""

import os
import sys

import numpy as np
import pytest
import warp as wp

wp.config.quiet = True
wp.config.log_level = wp.LOG_WARNING
wp.init()

sys.path.insert(0, os.path.dirname(__file__))

DEVICES = [str(d) for d in wp.get_devices()]
DEFAULT_DEVICE = str(wp.get_device())
"""Warp's default device (``cuda:0`` where there is one), for tests whose device does not matter."""


@pytest.fixture(params=DEVICES)
def device(request):
    """Each available Warp device: ``cpu`` (when Warp has a CPU compiler) and every CUDA device."""
    return request.param


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
