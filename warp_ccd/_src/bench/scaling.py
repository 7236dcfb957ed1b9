"""The scaling benchmark's command: ms per frame against the number of objects, per stage, with peers in
the same run.

``warp-ccd bench`` and ``python -m warp_ccd.bench`` run :func:`main`, for example:

    python -m warp_ccd.bench --device cuda:0 --objects 1e2 1e3 1e4 1e5 1e6 --triangles poly 80 \\
        --out bench/results/scaling_cuda0.json --plot bench/results/scaling_cuda0.png

For each triangle count (``--triangles``, :func:`~warp_ccd._src.bench.meshes.parse_triangles`) and each
object count ``N`` (``--objects``), on the scaling scene ``Scene.random(N, seed, shapes)`` (constant
density, so the work per object does not depend on ``N``), :func:`~warp_ccd._src.bench.methods.run_case`
runs:

1. **Frames.** ``--warmup`` frames (kernel loading, buffers growing, graphs captured), then
   ``--frames`` timed ones. Each frame moves the scene once and then runs every method on the same
   world vertices. On CUDA the move is this package's whole frame, ``detect(advance=dt)`` replayed
   as one CUDA graph (``total_graph``); the motion alone (``motion``, eager) is timed by moving
   again by 0 s (the same poses). Times are wall-clock ms with
   ``wp.synchronize_device`` before and after what is timed; each row gives the min and the
   median over the timed frames.
2. **Methods** (:mod:`warp_ccd._src.bench.methods`).

   * ``warp_ccd``: this package's :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline`: with
     ``timings=True`` for the stages it reports (whatever their names; it synchronises after each,
     and the sum is ``detect_synced``), and timed around ``detect()`` (the frame's launches, its one
     counter read, the result's views) launched eagerly (``detect_eager``) and, on CUDA, replayed
     as a graph (``detect_graph``). ``total_eager`` is ``motion + detect_eager``; ``total_graph``
     the fused frame above; ``total`` and ``detect`` the faster mode by median (the number to
     quote). ``host_eager`` / ``host_graph``: Python's time in ``detect()`` without the waits,
     taken in these interleaved frames, right after the peers ran (the host's caches hold their
     work, not this frame's). After the checks, on CUDA, ``--frames`` more fused frames run back
     to back, as a simulation loop runs them: ``loop_graph`` (wall ms) and ``host_loop_graph``.
   * ``warp_builtin`` (peer ``builtin``): Warp's own tools,
     :class:`~warp_ccd._src.bench.peers.WarpMeshPipeline`, at its best: a frame is refit + query + one
     read of its counter into pinned memory, launched eagerly (``detect_eager``) and, on CUDA, as a
     captured graph (``detect_graph``); ``detect`` is the faster by median.
   * ``fcl`` (peer ``fcl``): python-fcl, :class:`~warp_ccd._src.bench.peers.FclPipeline`, on the host, for
     ``N <= --fcl-max-objects``; its stages timed in turn.
   * ``warp_ccd_nxn`` (peer ``nxn``): this pipeline with the all-pairs broad phase, for
     ``N <= --nxn-max-objects``.
   * ``newton_sap`` (peer ``newton``): newton's ``BroadPhaseSAP`` alone, on the object boxes this
     pipeline's broad phase saw (``broad``, eager or graph as the built-in; compare with
     ``warp_ccd``'s ``broad``).

   Peers report ``detect`` and ``total`` (``motion + detect``). A peer whose library is missing
   is skipped with a note; a peer that raises is reported with an ``ERROR`` note.
3. **Checks**, on the last frame (:mod:`warp_ccd._src.bench.compare`), which judge this package, not
   its peers: ``warp_builtin`` and ``fcl`` must find the same object pairs as ``warp_ccd`` up to
   near-touching pairs, their triangle-level differences are classified and counted, and a real
   difference is charged to whichever method an independent arbiter (Warp's float64 test on the
   scaled pair) finds wrong; ``warp_ccd_nxn`` must find the very same triangle pairs and as many
   broad-phase pairs; ``newton_sap`` the same box pairs as this package's
   :class:`~warp_ccd._src.broadphase.sap.BroadPhaseSAP` on the same boxes, each differing pair judged by
   an exact overlap test in numpy. A peer found wrong is a finding: its rows are marked ``*``
   (``peer_wrong`` in the JSON). A difference charged to ``warp_ccd`` is a mismatch: the command
   ends with status 3 after everything is written.
4. **Memory** (:mod:`warp_ccd._src.bench.memory`) of a fresh ``warp_ccd`` pipeline over two frames: the
   peak of Warp's allocation tracker (``wp.ScopedMemoryTracker``; it sees every Warp allocation,
   native trees included), on CUDA also the memory pool's high-water mark when it rose, and the
   bytes of the arrays the pipeline and the scene hold; per scene triangle too.

Output (:mod:`warp_ccd._src.bench.report`): a table per case and a summary on stdout (ratios are a peer's
median over ``warp_ccd``'s for the same stage: above 1, ``warp_ccd`` is faster), a JSON file (``--out``:
device, date, versions, git commit, ``rows`` of ``method, n_objects, triangles,
triangles_per_object, stage, ms_min, ms_median, object_pairs, triangle_pairs, frames, mode,
peer_wrong`` (for a broad phase alone, ``object_pairs`` counts its box pairs; ``mode``: the faster
of eager and graph behind a best-of stage), ``memory``, ``checks``, ``notes``; rewritten after
each case so that a long run that dies keeps what it measured) and a log-log plot of ms per frame
against ``N`` (``--plot``, needs matplotlib).

Exit status (:mod:`warp_ccd._src.cli.common`'s codes): 0 ``EXIT_OK``, ``warp_ccd`` stands (peers' wrong answers
and failures are reported, not failed); 2 ``EXIT_USAGE``, bad arguments; 3 ``EXIT_INTERNAL``, a real
mismatch charged to ``warp_ccd`` (a bug in it).
"""

from __future__ import annotations

import argparse
import math
import sys

from ..cli.common import EXIT_INTERNAL, EXIT_OK, EXIT_USAGE, CliError, OneLineParser, quiet_warp, resolve_device
from ..output import check_output_path
from .meshes import parse_triangles
from .methods import PEERS, REFERENCE, run_case
from .report import JSON_EXTENSIONS, PLOT_EXTENSIONS, BenchReport

__all__ = ["build_parser", "main"]


def _count(text: str) -> int:
    """An object count: ``1000``, ``1e5``, ``100_000``."""
    try:
        value = float(text.replace("_", ""))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a count, got {text!r}") from None
    if not math.isfinite(value) or value != int(value) or value < 2:
        raise argparse.ArgumentTypeError(f"expected an integer >= 2, got {text!r}")
    return int(value)


def _non_negative(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}")
    return value


def _positive(text: str) -> int:
    value = _non_negative(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return value


def _peers(text: str) -> list[str]:
    if text.strip().lower() in ("", "none"):
        return []
    names = [t.strip().lower() for t in text.split(",") if t.strip()]
    bad = [t for t in names if t not in PEERS]
    if bad:
        raise argparse.ArgumentTypeError(f"unknown peer(s) {', '.join(bad)}; known: {', '.join(PEERS)} or none")
    return list(dict.fromkeys(names))


def _triangles(text: str) -> str:
    try:
        parse_triangles(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def build_parser(prog: str = "warp-ccd bench") -> argparse.ArgumentParser:
    """The options of :func:`main` (defaults sized for about a minute on one CPU thread)."""
    parser = OneLineParser(
        prog=prog,
        description="Collision detection ms per frame against the number of objects, per stage, with Warp's "
        "built-in pipeline, python-fcl, the all-pairs broad phase and newton's sweep and prune in the same run.",
    )
    parser.add_argument("--device", default=None, help="Warp device (default: cuda:0 if available, else cpu)")
    parser.add_argument("--objects", type=_count, nargs="+", default=[100, 1000, 3000, 10000],
                        help="object counts N; 1e5 is accepted (default: %(default)s)")
    parser.add_argument("--triangles", type=_triangles, nargs="+", default=["poly", "80"],
                        help="triangles per object: 'poly' (the five polyhedra, 4 to 36 triangles), 'mixed' "
                        "(meshes of the sizes of real assets, 120 to 12,640 triangles) or an icosphere's "
                        "count 20*4**L (80: icosphere1, 1280: icosphere3) (default: %(default)s)")
    parser.add_argument("--frames", type=_positive, default=10, help="timed frames per case (default: %(default)s)")
    parser.add_argument("--warmup", type=_non_negative, default=2,
                        help="untimed frames before them (default: %(default)s)")
    parser.add_argument("--peers", type=_peers, default=list(PEERS),
                        help=f"comma-separated peers among {','.join(PEERS)}, or none (default: all)")
    parser.add_argument("--fcl-max-objects", type=_count, default=10000,
                        help="largest N run with python-fcl (default: %(default)s)")
    parser.add_argument("--nxn-max-objects", type=_count, default=None,
                        help="largest N run with the all-pairs broad phase (default: 3000 on CPU, 20000 on CUDA)")
    parser.add_argument("--seed", type=_non_negative, default=0, help="seed of the scenes (default: %(default)s)")
    parser.add_argument("--no-memory", dest="memory", action="store_false", help="skip the memory measurement")
    parser.add_argument("--out", default=None, help="JSON file to write (default: none)")
    parser.add_argument("--plot", default=None, help="log-log plot to write: .png, .svg or .pdf (default: none)")
    return parser


def main(argv: list[str] | None = None, *, prog: str = "warp-ccd bench") -> int:
    """Runs the benchmark (see module docs).

    Args:
        argv: arguments without the program name (default: ``sys.argv[1:]``).
        prog: program name in usage and messages.

    Returns:
        Exit status: ``EXIT_OK`` (0) ``warp_ccd`` stands, ``EXIT_USAGE`` (2) bad arguments, ``EXIT_INTERNAL`` (3)
        a real mismatch charged to ``warp_ccd``.
    """
    parser = build_parser(prog)
    try:
        args = parser.parse_args(sys.argv[1:] if argv is None else list(argv))
    except CliError as exc:
        print(exc, file=sys.stderr)
        return exc.status
    quiet_warp()
    try:
        device = resolve_device(args.device)
        # Fail on a bad destination now, not after the measurements.
        if args.out:
            check_output_path(args.out, JSON_EXTENSIONS, "JSON")
        if args.plot:
            check_output_path(args.plot, PLOT_EXTENSIONS, "plot")
    except ValueError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    config = {k: v for k, v in vars(args).items() if k not in ("device",)}
    report = BenchReport(device, config)
    print(f"{prog}: {device} ({getattr(device, 'name', '')}), objects {args.objects}, triangles {args.triangles}, "
          f"peers {','.join(args.peers) or 'none'}, {args.frames} frames after {args.warmup} warm-up", flush=True)
    for triangles in args.triangles:
        for n in sorted(args.objects):
            case = run_case(n, triangles, args, device)
            report.add(case)
            print(report.case_table(case) + "\n", flush=True)
            if args.out:
                report.write_json(args.out)
    print(report.summary_table())
    if args.out:
        print(f"results written to {args.out}")
    if args.plot:
        note = report.plot(args.plot)
        print(note if note else f"plot written to {args.plot}")
    if not report.ok:
        bad = [f"{c.num_objects} objects, triangles {c.label}" for c in report.cases if not c.ok]
        print(f"{prog}: MISMATCH between methods in: {'; '.join(bad)} (see the check lines above)", file=sys.stderr)
        return EXIT_INTERNAL
    wrong = sorted({p for c in report.cases for p in c.wrong_peers})
    if wrong:
        print(f"{prog}: {REFERENCE} stands; wrong answers from {', '.join(wrong)} (findings, marked * above)")
    return EXIT_OK
