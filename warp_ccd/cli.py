"""The ``warp-ccd`` command (also ``python -m warp_ccd``).

Subcommands:

* ``demo``: a seeded random scene of polyhedra in motion, collision detection every frame, the
  animation written to USD (colliding objects in colour), optionally a preview image or GIF, and
  a summary of what was found and how long each stage took.
* ``check``: every interpenetration in a USD animation, frame by frame (:mod:`warp_ccd.check`): a
  summary table, optionally a JSON report, a USD overlay and a picture of the worst frame. Exit
  status 0 when nothing penetrates, 1 when something does, 2 when the input or the arguments
  are bad (nothing is written then), so that it can gate a pipeline.
* ``bench``: the benchmarks of :mod:`warp_ccd.bench`; every argument after ``bench`` goes there.

Bad arguments end with one line on stderr and a non-zero exit status, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import time

from .cli_common import (
    EXIT_ERROR,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    OneLineParser,
    quiet_warp,
    resolve_device,
)

__all__ = ["main"]

PROG = "warp-ccd"

def _count(minimum: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value

    parse.__name__ = "count"
    return parse


def _depth(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value >= 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text}")
    return value


def _frames(text: str | None):
    """``START:END[:STEP]`` (either end may be empty) or one time code, as :func:`check_usd` takes it."""
    if text is None:
        return None
    parts = text.split(":")
    try:
        values = [float(p) if p.strip() else None for p in parts]
    except ValueError:
        raise ValueError(f"--frames: expected START:END[:STEP] or a time code, got {text!r}") from None
    if len(parts) == 1:
        if values[0] is None:
            raise ValueError("--frames: empty")
        return [values[0]]
    if len(parts) > 3:
        raise ValueError(f"--frames: expected START:END[:STEP], got {text!r}")
    return slice(*values)


def _build_parser() -> OneLineParser:
    parser = OneLineParser(prog=PROG,
                           description="Collision detection among many moving triangle meshes (NVIDIA Warp).")
    sub = parser.add_subparsers(dest="command", metavar="{demo,check,bench}", parser_class=OneLineParser)
    sub.required = True

    demo = sub.add_parser(
        "demo",
        help="random polyhedra in motion -> USD animation with colliding objects in colour",
        description="Simulate a seeded random scene, detect collisions every frame, write a USD animation "
        "(colliding objects in red) and print a summary.",
    )
    demo.add_argument("--num-objects", type=_count(1), default=1000, help="number of objects (default: %(default)s)")
    demo.add_argument("--num-frames", type=_count(1), default=120,
                      help="number of frames, 60 per second (default: %(default)s)")
    demo.add_argument("--device", default=None, help="Warp device (default: cuda:0 if available, else cpu)")
    demo.add_argument("--out", default="collisions.usd",
                      help="USD file: .usd/.usdc binary, .usda text (default: %(default)s)")
    demo.add_argument("--preview", default=None,
                      help="also render a preview: .png the last frame, .gif the whole animation (default: none)")
    demo.add_argument("--seed", type=_count(0), default=0, help="random seed of the scene (default: %(default)s)")
    demo.add_argument("--aabb", action="store_true", help="also write each object's bounding box as a wireframe")
    demo.add_argument("--segments", action="store_true", help="also write the intersection segments as line markers")

    check = sub.add_parser(
        "check",
        help="find every interpenetration in a USD animation, frame by frame (exit 1 if any)",
        description="Read a USD stage's meshes, detect the prim pairs whose surfaces pass through each other at "
        "every frame, print a summary, optionally write a JSON report, a USD overlay and a picture. "
        "Exit status: 0 nothing penetrates, 1 something does, 2 bad arguments or input.",
    )
    check.add_argument("stage", metavar="IN.usd", help="the USD file to check (.usd, .usda, .usdc, .usdz)")
    check.add_argument("--frames", default=None, metavar="START:END[:STEP]",
                       help="time codes to check, END included (default: the stage's time range)")
    check.add_argument("--prims", nargs="+", default=None, metavar="PATH",
                       help="prim paths or fnmatch patterns ('/World/Robot', '/World/*/Wheel*'); default: all")
    check.add_argument("--device", default=None, help="Warp device (default: cuda:0 if available, else cpu)")
    check.add_argument("--precision", choices=("float32", "float64"), default="float32",
                       help="vertices, poses and the exact test (default: %(default)s)")
    check.add_argument("--min-depth", type=_depth, default=0.0, metavar="D",
                       help="a triangle pair penetrates when it crosses deeper than D scene units; resting "
                       "contact has depth 0 (default: %(default)s)")
    check.add_argument("--count-touching", action="store_true",
                       help="report touching (resting) contact as collisions too")
    check.add_argument("--report", default=None, metavar="REPORT.json", help="write the JSON report here")
    check.add_argument("--usd-out", default=None, metavar="OVERLAY.usd",
                       help="write a layer over IN.usd with the penetrating prims in colour per frame")
    check.add_argument("--segments", action="store_true",
                       help="keep the intersection segments: in the report, and as curves in the overlay")
    check.add_argument("--preview", default=None, metavar="PICTURE.png", help="a picture of the worst frame (.png)")
    check.add_argument("--include-invisible", action="store_true", help="also check invisible prims")
    check.add_argument("--include-purpose", action="append", choices=("guide", "proxy"), default=[],
                       help="also check prims of this purpose (repeatable)")
    check.add_argument("--top", type=_count(1), default=10, help="prim pairs in the summary table (default: 10)")

    sub.add_parser("bench", help="benchmarks (arguments after 'bench' go to warp_ccd.bench)", add_help=False)
    return parser


def _run_demo(args) -> int:
    from .preview import validate_preview_path
    from .usd import validate_stage_path

    # Every check that can fail does so before the simulation starts.
    try:
        validate_stage_path(args.out)
        if args.preview is not None:
            validate_preview_path(args.preview)
    except ValueError as exc:
        raise CliError(f"{PROG} demo: error: {exc}") from None
    try:
        import pxr  # noqa: F401
    except ImportError:
        raise CliError(f"{PROG} demo: error: usd-core is not installed (pip install usd-core)", EXIT_ERROR) from None

    quiet_warp()
    import numpy as np
    from tqdm import tqdm

    from .pipeline import CollisionPipeline
    from .preview import PreviewRenderer, save_preview
    from .scene import Scene
    from .usd import UsdAnimationWriter

    try:
        device = resolve_device(args.device)
    except ValueError as exc:
        raise CliError(f"{PROG} demo: error: {exc}") from None
    dt = 1.0 / 60.0
    start = time.perf_counter()
    scene = Scene.random(args.num_objects, seed=args.seed, device=device)
    pipe = CollisionPipeline(scene, timings=True, segments=args.segments)
    writer = UsdAnimationWriter(args.out, scene, fps=60, aabb=args.aabb, segments=args.segments)
    renderer = None
    gif = args.preview is not None and args.preview.lower().endswith(".gif")
    frames = []
    colliding_counts = np.zeros(args.num_frames, np.int64)
    pair_counts = np.zeros(args.num_frames, np.int64)
    stage_ms: dict[str, np.ndarray] = {}  # stage name -> ms per frame, in the pipeline's order
    export_s = 0.0
    preview_s = 0.0
    try:
        bar = tqdm(range(args.num_frames), desc="frames", unit="frame", disable=None, file=sys.stderr)
        for frame in bar:
            scene.advance(dt)
            res = pipe.detect()
            colliding = res.colliding
            colliding_counts[frame] = int(colliding.sum())
            pair_counts[frame] = res.num_triangle_pairs
            for s, ms in (res.timings or {}).items():
                stage_ms.setdefault(s, np.full(args.num_frames, np.nan))[frame] = ms
            t = time.perf_counter()
            writer.add_frame(frame, colliding)
            export_s += time.perf_counter() - t
            if args.preview is not None and (gif or frame == args.num_frames - 1):
                t = time.perf_counter()
                if renderer is None:
                    renderer = PreviewRenderer(scene, *((480, 360) if gif else (640, 480)))
                frames.append(renderer.render(colliding))
                preview_s += time.perf_counter() - t
            bar.set_postfix(colliding=colliding_counts[frame], refresh=False)
        bar.close()
        t = time.perf_counter()
        out_path = writer.close()
        export_s += time.perf_counter() - t
        preview_path = None
        if frames:
            t = time.perf_counter()
            preview_path = save_preview(frames, args.preview, fps=50)
            preview_s += time.perf_counter() - t
    except BaseException:
        writer.abort()
        raise
    wall = time.perf_counter() - start

    n, f = args.num_objects, args.num_frames
    # The first frame loads (or compiles) the kernels; leave it out of the stage times if we can.
    timed = slice(1, None) if f > 1 else slice(None)
    timed_note = f"frames 2-{f}" if f > 1 else "1 frame, includes kernel loading"
    order = sorted(stage_ms, key=lambda s: s == "total")  # "total" last
    stages = "  ".join(f"{s} {np.nanmean(stage_ms[s][timed]):.3f}" for s in order) or "n/a"
    size_mb = os.path.getsize(out_path) / 1e6
    lines = [
        f"{PROG} demo: {n} objects, {f} frames on {device} (seed {args.seed})",
        f"  colliding objects / frame : mean {colliding_counts.mean():.1f} "
        f"({100.0 * colliding_counts.mean() / n:.1f} %), max {colliding_counts.max()}",
        f"  triangle pairs / frame    : mean {pair_counts.mean():.1f}, max {pair_counts.max()}",
        f"  ms / frame by stage       : {stages}  ({timed_note})",
        f"  USD                       : {out_path} ({size_mb:.1f} MB, export {export_s:.2f} s)",
    ]
    if preview_path is not None:
        what = f"{len(frames)} frames" if gif else "last frame"
        lines.append(f"  preview                   : {preview_path} ({what}, {preview_s:.2f} s)")
    lines.append(f"  wall time                 : {wall:.2f} s")
    print("\n".join(lines))
    return EXIT_OK


def _run_check(args) -> int:
    def fail(message: str) -> CliError:  # bad arguments or input: exit 2 (1 means "penetrates")
        return CliError(f"{PROG} check: error: {message}", EXIT_USAGE)

    # Every destination is checked before the stage is read; nothing is written on an error.
    try:
        if args.report is not None:
            from .output import check_output_path

            check_output_path(args.report, (".json",), "report")
        if args.usd_out is not None:
            from .usd import validate_stage_path

            validate_stage_path(args.usd_out)
        if args.preview is not None:
            from .preview import validate_preview_path

            if validate_preview_path(args.preview)[1] != ".png":
                raise ValueError(f"cannot write {args.preview}: the preview of a check is one picture (use .png)")
        frames = _frames(args.frames)
    except ValueError as exc:
        raise fail(str(exc)) from None
    try:
        import pxr  # noqa: F401
    except ImportError:
        raise fail("usd-core is not installed (pip install usd-core)") from None
    quiet_warp()
    from .check import check_usd, write_overlay

    try:
        device = resolve_device(args.device)
        report = check_usd(args.stage, frames=frames, prims=args.prims, device=device, precision=args.precision,
                           min_depth=args.min_depth, count_touching=args.count_touching, segments=args.segments,
                           include_invisible=args.include_invisible, include_purposes=tuple(args.include_purpose),
                           progress=True)
    except ValueError as exc:
        raise fail(str(exc)) from None
    print(report.summary(top=args.top))
    try:
        if args.report is not None:
            print(f"  report : {report.write_json(args.report)}")
        if args.usd_out is not None:
            print(f"  overlay: {write_overlay(report, args.usd_out)}")
        if args.preview is not None:
            import numpy as np

            from .preview import PreviewRenderer, save_preview

            worst = report.worst_frame
            imp = report.source
            imp.set_frame(worst)
            colliding = np.zeros(len(report.object_path), bool)
            colliding[report.frames[worst].triangle_pairs[:, [0, 2]].ravel()] = True
            picture = PreviewRenderer(imp.scene, 640, 480).render(colliding)
            print(f"  preview: {save_preview([picture], args.preview)} (time {report.frames[worst].time:g})")
    except ValueError as exc:
        raise fail(str(exc)) from None
    return EXIT_ERROR if report.penetrating else EXIT_OK


def _run_bench(argv: list[str]) -> int:
    try:
        bench = importlib.import_module("warp_ccd.bench")
    except ModuleNotFoundError as exc:
        if exc.name in ("warp_ccd.bench", "warp_ccd"):
            print(f"{PROG} bench: error: the benchmark module warp_ccd.bench is not available in this "
                  "installation", file=sys.stderr)
            return EXIT_USAGE
        print(f"{PROG} bench: error: warp_ccd.bench needs {exc.name!r}, which is not installed", file=sys.stderr)
        return EXIT_USAGE
    entry = getattr(bench, "main", None)
    if not callable(entry):
        print(f"{PROG} bench: error: warp_ccd.bench has no main(argv)", file=sys.stderr)
        return EXIT_USAGE
    try:
        status = entry(list(argv))
    except SystemExit as exc:  # argparse inside the benchmarks
        status = exc.code
    if status is None:
        return EXIT_OK
    return status if isinstance(status, int) else EXIT_ERROR


def main(argv: list[str] | None = None) -> int:
    """Runs the ``warp-ccd`` command.

    Args:
        argv: arguments without the program name (default: ``sys.argv[1:]``).

    Returns:
        Exit status: 0 success, 1 failure while running, 2 bad arguments, 130 interrupted.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "bench":
        return _run_bench(argv[1:])
    try:
        try:
            args = _build_parser().parse_args(argv)
        except SystemExit as exc:  # --help
            return exc.code if isinstance(exc.code, int) else EXIT_OK
        if args.command == "demo":
            return _run_demo(args)
        if args.command == "check":
            return _run_check(args)
        raise CliError(f"{PROG}: error: unknown command {args.command!r}")
    except CliError as exc:
        print(str(exc), file=sys.stderr)
        return exc.status
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted; no file was written", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (ValueError, TypeError, OSError, MemoryError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return EXIT_ERROR


if __name__ == "__main__":
    sys.exit(main())
