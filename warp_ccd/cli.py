"""The ``warp-ccd`` command (also ``python -m warp_ccd``).

Subcommands:

* ``demo``: a seeded random scene of polyhedra in motion, collision detection every frame, the
  animation written to USD (colliding objects in colour), optionally a preview image or GIF, and
  a summary of what was found and how long each stage took.
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


def _build_parser() -> OneLineParser:
    parser = OneLineParser(prog=PROG,
                           description="Collision detection among many moving triangle meshes (NVIDIA Warp).")
    sub = parser.add_subparsers(dest="command", metavar="{demo,bench}", parser_class=OneLineParser)
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
