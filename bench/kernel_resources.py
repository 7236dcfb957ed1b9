"""Registers, local memory (spills) and resident threads per multiprocessor of the frame's kernels
on a CUDA device: what bounds the occupancy of each (``cuFuncGetAttribute`` on the loaded kernels).

    python -m bench.kernel_resources --device cuda:0 --out bench/results/kernel_resources_cuda0.json
"""

from __future__ import annotations

import ctypes
import sys

from warp_ccd import CollisionPipeline
from warp_ccd._src.bench.report import environment
from warp_ccd._src.broadphase import sap as broad_phase
from warp_ccd._src.midphase import bvh as mid_phase
from warp_ccd._src.narrowphase import continuous
from warp_ccd._src.narrowphase import discrete as narrow_phase
from warp_ccd._src.scene import motion, scene
from warp_ccd._src.trees import bvh, traversal

from .command import add_out_option, bench_parser, parse_options, write_result

# CUfunction_attribute values (CUDA driver API).
_ATTRIBUTES = {"max_threads_per_block": 0, "shared_bytes": 1, "local_bytes": 3, "registers": 4}
_REGISTERS_PER_SM = 65536
_THREADS_PER_SM = 2048


def _kernels() -> dict:
    """The frame's kernels by name (float32 variants of those compiled for both precisions)."""
    return {
        "narrow moller": narrow_phase._NARROW_MOLLER["float32"],
        "narrow touch": narrow_phase._NARROW_TOUCH["float32"],
        "expand": mid_phase._WALK,
        "whole pairs": mid_phase._WHOLE["float32"],
        "pair": traversal.PAIR_KERNELS["float32"],
        "rigid bounds": bvh._RIGID_BOUNDS["float32"],
        "sap sweep": broad_phase._sap_sweep_kernel,
        "motion pose": motion._MOTION_POSE["float32"],
        "world vertex": scene._WORLD_VERTEX["float32"],
        "ccd first": continuous._FIRST["float32"],
        "ccd filter": continuous._FILTER["float32"],
        "ccd search": continuous._SEARCH["float32"],
        "ccd last": continuous._LAST["float32"],
    }


BLOCK_DIMS = {}
"""Block size a kernel is launched with, where not 256 (its module is compiled for it)."""


def attributes(kernel, device, block_dim: int = 256) -> dict:
    """The kernel's attributes on ``device`` as compiled for blocks of ``block_dim``, and the
    threads per multiprocessor its registers allow (blocks of 256)."""
    cuda = ctypes.CDLL("libcuda.so.1")
    fn = kernel.module.load(device, block_dim).get_kernel_hooks(kernel).forward
    out = {}
    for name, code in _ATTRIBUTES.items():
        value = ctypes.c_int()
        cuda.cuFuncGetAttribute(ctypes.byref(value), code, ctypes.c_void_p(fn))
        out[name] = value.value
    per_block = 256 * ((out["registers"] + 7) // 8 * 8)
    out["resident_threads_per_sm"] = min(_THREADS_PER_SM, 256 * (_REGISTERS_PER_SM // max(per_block, 1)))
    return out


def main(argv=None) -> int:
    parser = bench_parser(__doc__.splitlines()[0], device="cuda:0")
    add_out_option(parser)
    args, device = parse_options(parser, argv)
    if not device.is_cuda:
        raise SystemExit("kernel_resources: needs a CUDA device")
    s = scene.Scene.random(200, seed=0, device=device)
    CollisionPipeline(s, graph=False).detect(advance=0.01)  # loads every module of the frame
    CollisionPipeline(s, graph=False, continuous=True).detect(advance=0.01)  # and of a continuous one
    rows = []
    for name, kernel in _kernels().items():
        row = {"kernel": name, "key": kernel.key, **attributes(kernel, device, BLOCK_DIMS.get(name, 256))}
        rows.append(row)
        print(f"{name:<14} registers {row['registers']:>4}  local {row['local_bytes']:>5} B  "
              f"threads/SM {row['resident_threads_per_sm']:>5}", flush=True)
    write_result(args.out, {**environment(device), "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
