"""Benchmark: the whole frame, per stage and in total, against Warp's built-in pipeline.

A thin front end to :mod:`warp_ccd.bench` (the ``warp-ccd bench`` command) with this benchmark's
defaults: the scaling scene of icospheres of 80 triangles and of 1,280 triangles, Warp's
built-in pipeline (``wp.Mesh`` refit, ``wp.mesh_query_aabb``, ``wp.intersect_tri_tri``) as the peer
in the same run, triangle pairs compared and their differences classified, results in
``bench/results/pipeline_<device>.json`` and ``.png`` (under the working directory). Rows per
stage: ``motion``, this pipeline's own stages (refit of the bounds and trees, broad, mid, narrow),
``detect`` and ``total``. Every option of ``warp-ccd bench`` is accepted and overrides these defaults.

    python -m bench.pipeline
    python -m bench.pipeline --device cuda:0 --objects 1e2 1e3 1e4 1e5 1e6
    python -m bench.pipeline --peers builtin,fcl,nxn,newton
"""

from __future__ import annotations

import sys

from warp_ccd._src.bench.scaling import build_parser
from warp_ccd._src.bench.scaling import main as bench_main
from warp_ccd._src.cli.common import CliError, resolve_device

from .command import RESULTS

PROG = "python -m bench.pipeline"
DEFAULTS = ["--triangles", "80", "1280", "--peers", "builtin", "--objects", "100", "1000", "3000"]


def main(argv: list[str] | None = None) -> int:
    argv = DEFAULTS + list(sys.argv[1:] if argv is None else argv)
    try:
        args = build_parser(PROG).parse_args(argv)
    except CliError:
        return bench_main(argv, prog=PROG)  # which reports the bad argument in one line
    try:
        tag = str(resolve_device(args.device)).replace(":", "")
    except ValueError:
        tag = "unknown"  # warp_ccd.bench reports the bad device
    if args.out is None:
        RESULTS.mkdir(parents=True, exist_ok=True)
        argv += ["--out", str(RESULTS / f"pipeline_{tag}.json")]
    if args.plot is None:
        RESULTS.mkdir(parents=True, exist_ok=True)
        argv += ["--plot", str(RESULTS / f"pipeline_{tag}.png")]
    return bench_main(argv, prog=PROG)


if __name__ == "__main__":
    sys.exit(main())
