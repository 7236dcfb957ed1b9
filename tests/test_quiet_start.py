"""What a run prints before its own output: on a machine without a GPU no CUDA-driver notice from
Warp (:mod:`warp_ccd._src.runtime.start`), and the tree build compiles without compiler warnings."""

import os
import subprocess
import sys

import pytest
import warp as wp

from warp_ccd._src.runtime.start import DRIVER_NOTICE

from conftest import HOST_DEVICES

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run_python(code: str, **env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600,
                          env={**os.environ, **env})


@pytest.mark.skipif(wp.is_cuda_available(), reason="a machine without a CUDA driver")
def test_no_cuda_driver_notice_on_a_machine_without_a_gpu():
    code = ("import numpy as np, warp_ccd as wc\n"
            "v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)\n"
            "print(wc.collide([(v, np.array([[0, 1, 2]]))] * 2, device='cpu').object_pairs.tolist())\n")
    done = run_python(code)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().endswith("[[0, 1]]")
    assert DRIVER_NOTICE not in done.stderr and DRIVER_NOTICE not in done.stdout, done.stderr


@pytest.mark.skipif(not HOST_DEVICES, reason="Warp has no CPU compiler here")
def test_the_tree_build_compiles_without_warnings(tmp_path):
    """``_axis_key_kernel``'s sign bit was an int32 literal that overflowed (``-Wconstant-conversion``:
    2147483648 to -2147483648, about 30 lines on the first compile)."""
    code = ("import warp as wp\nwp.config.quiet = True\nwp.init()\n"
            "import warp_ccd._src.trees.build as b\nwp.load_module(b, device='cpu')\n")
    done = run_python(code, WARP_CACHE_PATH=str(tmp_path))
    assert done.returncode == 0, done.stderr
    warnings = [line for line in done.stderr.splitlines() if "warning:" in line and DRIVER_NOTICE not in line]
    assert not warnings and "2147483648" not in done.stderr, done.stderr
