"""Shared fixtures: every test that takes ``device`` runs on each available Warp device."""

import os

import numpy as np
import pytest
import warp as wp

wp.config.quiet = True
wp.config.log_level = wp.LOG_WARNING
wp.init()

ALL_DEVICES = [str(d) for d in wp.get_devices()]
"""Every Warp device present (tests that compare devices use these)."""
HOST_DEVICES = [d for d in ALL_DEVICES if not wp.get_device(d).is_cuda]
"""The host devices Warp compiles for: none where Warp has no CPU compiler (a CUDA machine's Warp may not)."""
CUDA_DEVICES = [d for d in ALL_DEVICES if wp.get_device(d).is_cuda]
"""Every CUDA device present."""

_WANTED = [w for w in os.environ.get("WARP_CCD_TEST_DEVICES", "").split(",") if w]
DEVICES = [d for d in ALL_DEVICES if not _WANTED or d in _WANTED or d.split(":")[0] in _WANTED]
if not DEVICES:
    raise pytest.UsageError(f"WARP_CCD_TEST_DEVICES={os.environ['WARP_CCD_TEST_DEVICES']!r} names none of the "
                            f"devices present: {ALL_DEVICES}")
"""The devices the ``device`` fixture runs each test on: all of them, or those named (``cuda:0``) or
kinds (``cuda``, ``cpu``) listed in the ``WARP_CCD_TEST_DEVICES`` environment variable."""
DEFAULT_DEVICE = str(wp.get_device())
"""Warp's default device (``cuda:0`` where there is one), for tests whose device does not matter."""


@pytest.fixture(params=DEVICES)
def device(request):
    """Each available Warp device: ``cpu`` (when Warp has a CPU compiler) and every CUDA device."""
    return request.param


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def message_lines(err: str) -> list[str]:
    """A command's own stderr lines: less blank lines, Warp's native CUDA-driver notice, and the
    notice that kernels are being compiled (a cold kernel cache, as on a fresh machine)."""
    return [line for line in err.strip().splitlines()
            if line.strip() and not line.startswith("Warp CUDA") and "compiling kernels" not in line]
