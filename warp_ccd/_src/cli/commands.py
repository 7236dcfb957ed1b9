"""The ``warp-ccd`` command (also ``python -m warp_ccd``).

Subcommands:

* ``demo``: a seeded random scene of polyhedra in motion, collision detection every frame, the
  animation written to USD (colliding objects in colour), optionally a preview image or GIF, and
  a summary of what was found and how long each stage took. With ``--continuous``, fast small
  boxes flying through thin walls (:mod:`warp_ccd._src.cli.tunnelling`), detected at every frame and
  continuously over every frame step: the contacts only the continuous detection saw are counted.
* ``check``: every interpenetration in a USD animation, frame by frame (:mod:`warp_ccd._src.check.check`): a
  summary table, optionally a JSON report, a USD overlay and a picture of the worst frame; with
  ``--continuous``, also the prim pairs that touch between consecutive time codes, and which of them
  tunnel (no end frame shows them); with ``--clearance D``, the prim pairs closer than ``D`` (soft
  clashes); with ``--self``, the prims that pass through themselves; with ``--duplicates``, the prim
  pairs whose meshes coincide (reported as duplicates, not as collisions); ``--worlds``,
  ``--ignore-pairs`` (and the stage's ``UsdPhysics`` rules, unless ``--no-usd-filters``), ``--set-a`` with
  ``--set-b`` leave pairs out (:mod:`warp_ccd._src.usd.filters`). Exit status 0 when nothing
  penetrates, 1 when something does (or tunnels, or passes through itself, or duplicates another, or
  comes within the clearance, or, with ``--count-touching``, touches), 2 when the input or the
  arguments are bad, 3 on an internal error, so that it can gate a pipeline. No output may be the
  input or one of its layers; every output is written to a temporary file and all are moved into
  place at the end, so a failed run writes nothing. ``--report -`` prints the JSON report on standard
  output (last, once every file is in place) and everything else the command prints on stderr.
* ``bench``: the scaling benchmark against peers (:mod:`warp_ccd.bench`); every argument after ``bench`` goes there.

Bad arguments end with one line on stderr and a non-zero exit status, never a traceback; so does
an unexpected exception (exit status 3), unless ``--debug`` asks for its traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import re
import sys
import time
import traceback
import types
import warnings

from .common import (
    EXIT_ERROR,
    EXIT_FINDINGS,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    REPORT_STDOUT,
    CliError,
    OneLineParser,
    QuietClosedStdout,
    check_options_from,
    flat_values,
    init_warp,
    pending_outputs,
    quiet_warp,
    refuse_overwriting,
    require_usd,
    resolve_device,
    uncached_modules,
)

__all__ = ["main"]

PROG = "warp-ccd"

CHECK_KERNEL_MODULES = ("warp_ccd._src.scene.scene", "warp_ccd._src.trees.build", "warp_ccd._src.trees.bvh",
                        "warp_ccd._src.broadphase.sap", "warp_ccd._src.midphase.bvh",
                        "warp_ccd._src.narrowphase.discrete",
                        "warp_ccd._src.runtime.buffers", "warp_ccd._src.check.crossing",
                        "warp_ccd._src.narrowphase.depth")
"""The modules whose Warp kernels ``check`` runs (``warp_ccd.preview`` too with ``--preview``)."""
CONTINUOUS_KERNEL_MODULES = ("warp_ccd._src.narrowphase.continuous",)
"""The modules whose Warp kernels ``check --continuous`` runs besides."""
CLEARANCE_KERNEL_MODULES = ("warp_ccd._src.narrowphase.clearance",)
"""The modules whose Warp kernels ``check --clearance`` runs besides."""
SELF_KERNEL_MODULES = ("warp_ccd._src.narrowphase.self_intersection",)
"""The modules whose Warp kernels ``check --self`` runs besides."""

_DASH_VALUE = re.compile(r"-\.?\d")
"""A value that starts like a negative number (``-5:10``), which argparse would take for an option."""

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


def _number(text: str) -> float:
    """A number's text as a float (its bounds are the option's rule, checked with the others)."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def _integer(text: str) -> int:
    """An integer's text as an int (its bounds are the option's rule, checked with the others)."""
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


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
    demo.add_argument("--continuous", action="store_true",
                      help="fast small boxes flying through thin walls, detected at each frame and continuously "
                      "over each frame step; an object is coloured when it collides at any time of the step to "
                      "the frame, and the contacts the frames alone miss are counted")

    check = sub.add_parser(
        "check",
        help="find every interpenetration in a USD animation, frame by frame (exit 1 if any)",
        description="Read a USD stage's meshes, detect the prim pairs whose surfaces pass through each other at "
        "every frame, print a summary, optionally write a JSON report, a USD overlay and a picture. "
        "With --continuous, also the prim pairs that touch between consecutive time codes (each vertex "
        "moving linearly), marked tunnelling where neither end frame shows them. "
        "With --clearance D, also the prim pairs closer than D (soft clashes), with their least distance and "
        "closest points. "
        "With --self, also the prims that pass through themselves, as pairs of their faces with a depth. "
        "With --duplicates, the prim pairs whose meshes coincide (the same triangles at the same place) are "
        "reported as duplicates, not as colliding. "
        "With --containment, also the closed meshes wholly inside another. "
        "--ignore-pairs, --set-a with --set-b, --worlds (and the stage's UsdPhysics filters) leave pairs unchecked. "
        "Exit status: 0 nothing penetrates, 1 something does (or lies inside another with --containment, or "
        "tunnels, or passes through itself with --self, "
        "or duplicates another with --duplicates, or comes within --clearance, or "
        "touches with --count-touching), 2 bad arguments or input, 3 an internal error.",
    )
    check.add_argument("stages", nargs="+", metavar="IN.usd",
                       help="the USD files to check (.usd, .usda, .usdc, .usdz), or glob patterns ('shots/*.usd', "
                       "'assets/**/*.usdc'; quoted). With several files: one summary each, --report holds every "
                       "file's report, --usd-out is a folder; the exit status is the worst over the files")
    check.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                       help="run on a Ray cluster: one worker per GPU (else per CPU), long animations cut into ranges "
                       "of time codes; the results are those of one process. ADDRESS: 'auto', HOST:PORT or "
                       "ray://HOST:PORT (default: a local cluster). Needs pip install 'warp-ccd[distributed]'")
    check.add_argument("--workers", type=_integer, default=None, metavar="N",
                       help="with --ray: workers to start (default: one per GPU of the cluster, else one per CPU)")
    check.add_argument("--frames-per-task", type=_integer, default=None, metavar="N",
                       help="cut every file into ranges of N time codes, one task each (default: whole files, cut "
                       "only where there are fewer files than workers)")
    check.add_argument("--read-workers", type=_integer, default=None, metavar="N",
                       help="processes that read the transforms of a big animation, in this process's check "
                       "(default: chosen by its size; 0: none; Ray workers read in their own process)")
    check.add_argument("--frames", default=None, metavar="START:END[:STEP]",
                       help="time codes to check, END included (default: the stage's time range)")
    check.add_argument("--prims", type=_prims, action="append", default=None, metavar="PATH[,PATH...]",
                       help="prim paths or fnmatch patterns to check ('/World/Robot', '/World/*/Wheel*'); several "
                       "separated by commas or by repeating --prims (default: all)")
    check.add_argument("--device", default=None, help="Warp device (default: cuda:0 if available, else cpu)")
    check.add_argument("--precision", default="float32", metavar="{float32,float64}",
                       help="vertices, poses and the exact test (default: %(default)s)")
    check.add_argument("--min-depth", type=_number, default=0.0, metavar="D",
                       help="a prim pair whose surfaces cross penetrates when its depth exceeds D scene units: the "
                       "deepest point of either surface inside the other's closed solid, measured to that solid's "
                       "surface (two cubes overlapping by 0.7 with flush faces: 0.3); resting contact has depth 0; "
                       "two open surfaces (sheets, cloths) that cross have no depth and always penetrate "
                       "(default: %(default)s)")
    check.add_argument("--count-touching", action="store_true",
                       help="report touching (resting) contact as collisions too")
    check.add_argument("--continuous", action="store_true",
                       help="also report the prim pairs that touch between consecutive time codes (each vertex "
                       "moving linearly), with the time of first contact; a pair that neither end frame shows "
                       "intersecting is tunnelling, a finding like a penetration")
    check.add_argument("--min-distance", type=_number, default=0.0, metavar="D",
                       help="with --continuous, surfaces that come within D scene units count as touching "
                       "(default: %(default)s)")
    check.add_argument("--clearance", type=_number, default=0.0, metavar="D",
                       help="also report the prim pairs whose surfaces come within D scene units and are not "
                       "colliding (soft clashes), with their least distance and closest points; a finding like a "
                       "penetration (default: %(default)s, none)")
    check.add_argument("--self", dest="self_intersections", action="store_true",
                       help="also report the prims that pass through themselves (triangles of one mesh meeting beyond "
                       "the vertices they share: a cloth through itself, overlapping bodies in one CAD mesh), as "
                       "pairs of their faces with a depth; a finding like a penetration")
    check.add_argument("--containment", action="store_true",
                       help="also report the closed meshes wholly inside another's solid (no surface crossing), "
                       "with their depth; a finding like a penetration")
    check.add_argument("--duplicates", action="store_true",
                       help="report the prim pairs whose meshes coincide (the same triangles at the same place, "
                       "e.g. a part exported twice) as duplicates instead of as touching or penetrating; a "
                       "finding like a penetration")
    check.add_argument("--report", default=None, metavar="REPORT.json",
                       help="write the JSON report here; '-': to standard output (the summary and every other "
                       "message then go to stderr)")
    check.add_argument("--usd-out", default=None, metavar="OVERLAY.usd",
                       help="write a layer over IN.usd with the penetrating prims in colour per frame")
    check.add_argument("--segments", action="store_true",
                       help="keep the intersection segments: in the report, and as curves in the overlay")
    check.add_argument("--preview", default=None, metavar="PICTURE.png", help="a picture of the worst frame (.png)")
    check.add_argument("--include-invisible", action="store_true", help="also check invisible prims")
    check.add_argument("--include-purpose", dest="include_purposes", action="append", default=[],
                       metavar="{guide,proxy}", help="also check prims of this purpose (repeatable)")
    check.add_argument("--top", type=_count(1), default=10, help="prim pairs in the summary table (default: 10)")
    check.add_argument("--worlds", action="append", default=None, metavar="PATTERN",
                       help="prim path or fnmatch pattern ('/World/envs/*'): every prim it matches roots a world, "
                       "and meshes of two worlds are never checked against each other; meshes under no root pair "
                       "with every world (repeatable)")
    check.add_argument("--ignore-pairs", action="append", default=None, metavar="FILE",
                       help="prim pairs never checked: two prim paths or patterns a line, separated by whitespace "
                       "or a comma, '#' comments; a .json file: a list of [a, b]. Every mesh under a is excluded "
                       "against every mesh under b (repeatable)")
    check.add_argument("--no-usd-filters", dest="usd_filters", action="store_false",
                       help="check the pairs the stage's UsdPhysics rules leave out too: meshes of one rigid "
                       "body, bodies a joint joins (physics:collisionEnabled false), filtered pairs and collision "
                       "groups (default: they are excluded)")
    check.add_argument("--set-a", type=_prims, action="append", default=None, metavar="PATH[,PATH...]",
                       help="with --set-b: only pairs of one mesh under these prims (paths or fnmatch patterns) "
                       "and one under --set-b's are checked, as clash tools do (repeatable)")
    check.add_argument("--set-b", type=_prims, action="append", default=None, metavar="PATH[,PATH...]",
                       help="the other set of --set-a (a mesh may be in both)")
    check.add_argument("--allow-missing", action="store_true",
                       help="check a stage whose sublayers, references or payloads cannot all be opened, "
                       "without them; an --ignore-pairs line naming no prim, a --worlds, --set-a or --set-b "
                       "pattern matching no checked mesh: a note (default: an error)")

    for command in (demo, check):
        command.add_argument("--debug", action="store_true",
                             help="on an internal error, print the traceback (default: one line)")
    # The flag each option of the check is given as (dest: the option's name), for the messages of its rules.
    check.set_defaults(given_as=check.flags())
    sub.add_parser("bench", help="the scaling benchmark against peers (arguments after 'bench' go to "
                   "warp_ccd.bench)", add_help=False)
    return parser


def _prims(text: str) -> list[str]:
    """``--prims``: one prim path or pattern, or several separated by commas."""
    parts = [p.strip() for p in text.split(",")]
    if not all(parts):
        raise argparse.ArgumentTypeError(f"expected prim paths separated by commas, got {text!r}")
    return parts


def _join_dash_values(argv: list[str]) -> list[str]:
    """``--frames -5:10`` as ``--frames=-5:10``: argparse takes a value starting with ``-`` for an
    option unless it is a plain negative number."""
    out = []
    i = 0
    while i < len(argv):
        if argv[i] == "--frames" and i + 1 < len(argv) and _DASH_VALUE.match(argv[i + 1]):
            out.append(f"--frames={argv[i + 1]}")
            i += 2
            continue
        if argv[i] == "--":
            out += argv[i:]
            break
        out.append(argv[i])
        i += 1
    return out


def _run_demo(args) -> int:
    from ..preview import validate_preview_path
    from ..usd.export import validate_stage_path

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
    init_warp()
    import numpy as np
    from tqdm import tqdm

    from ..pipeline.pipeline import CollisionPipeline
    from ..preview import PreviewRenderer, save_preview
    from ..scene.scene import Scene
    from ..usd.export import UsdAnimationWriter

    try:
        device = resolve_device(args.device)
    except ValueError as exc:
        raise CliError(f"{PROG} demo: error: {exc}") from None
    dt = 1.0 / 60.0
    start = time.perf_counter()
    walls = sweep = tally = None
    if args.continuous:
        from .tunnelling import ContactTally, ThinWalls

        try:
            walls = ThinWalls(args.num_objects, seed=args.seed, device=device)
        except ValueError as exc:
            raise CliError(f"{PROG} demo: error: {exc}") from None
        scene = walls.scene
        sweep = CollisionPipeline(scene, continuous=True, timings=True)  # its motion starts at frame 0
        tally = ContactTally()
        sweep_ms = np.full(args.num_frames, np.nan)
    else:
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
            if walls is None:
                scene.advance(dt)
            else:
                walls.place(frame)
            res = pipe.detect()
            colliding = res.colliding
            shown = res
            if sweep is not None:  # over the step from the previous frame (frame 0: no motion)
                at_frame = res.object_pairs
                step = sweep.detect()
                tally.add(at_frame, step.object_pairs)
                sweep_ms[frame] = (step.timings or {}).get("total", np.nan)
                colliding = colliding | step.colliding
                shown = types.SimpleNamespace(colliding=colliding, segments=res.segments)
            colliding_counts[frame] = int(colliding.sum())
            pair_counts[frame] = res.num_triangle_pairs
            for s, ms in (res.timings or {}).items():
                stage_ms.setdefault(s, np.full(args.num_frames, np.nan))[frame] = ms
            t = time.perf_counter()
            writer.add_frame(frame, shown)  # its flags, and its segments with --segments
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
        f"{PROG} demo: {n} objects, {f} frames on {device} (seed {args.seed})"
        + (f", continuous: fast boxes through thin walls ({n - walls.num_walls} boxes, {walls.num_walls} "
           f"wall{'s' if walls.num_walls > 1 else ''})" if walls else ""),
        f"  colliding objects / frame : mean {colliding_counts.mean():.1f} "
        f"({100.0 * colliding_counts.mean() / n:.1f} %), max {colliding_counts.max()}",
        f"  triangle pairs / frame    : mean {pair_counts.mean():.1f}, max {pair_counts.max()}",
        f"  ms / frame by stage       : {stages}  ({timed_note})",
        f"  USD                       : {out_path} ({size_mb:.1f} MB, export {export_s:.2f} s)",
    ]
    if tally is not None:
        lines[4:4] = [
            f"  contacts (object pairs)   : at the frames {tally.at_frames}, over the frame steps "
            f"{tally.over_steps}, only continuous (the frames miss them) {tally.only_continuous}",
            f"  continuous ms / frame     : total {np.nanmean(sweep_ms[timed]):.3f}  ({timed_note})",
        ]
    if preview_path is not None:
        what = f"{len(frames)} frames" if gif else "last frame"
        lines.append(f"  preview                   : {preview_path} ({what}, {preview_s:.2f} s)")
    lines.append(f"  wall time                 : {wall:.2f} s")
    print("\n".join(lines))
    return EXIT_OK


def _run_check(args) -> int:
    """``check``; with ``--report -``, everything but the JSON report printed on stderr, the report on
    stdout once every file output is in place (nothing on stdout after an error)."""
    if args.report != REPORT_STDOUT:
        return _check(args)[0]
    stdout = sys.stdout
    with contextlib.redirect_stdout(sys.stderr):  # stdout holds the JSON alone: json.loads(stdout) works
        status, text = _check(args)
    stdout.write(text)
    stdout.flush()
    return status


def _check(args) -> tuple[int, str | None]:
    """Runs ``check``. Returns the exit status, and with ``--report -`` the report's JSON text (else None)."""
    def fail(message: str) -> CliError:  # bad arguments or input: exit 2 (1 means "penetrates")
        return CliError(f"{PROG} check: error: {message}", EXIT_USAGE)

    from ..check.batch import expand_paths

    try:
        files = expand_paths(args.stages)
    except ValueError as exc:
        raise fail(str(exc)) from None
    if len(files) > 1 or args.ray is not None:
        from .batch import check_batch

        try:
            frames = _frames(args.frames)
        except ValueError as exc:
            raise fail(str(exc)) from None
        return check_batch(args, files, frames, fail)
    args.stage = files[0]
    to_stdout = args.report == REPORT_STDOUT
    outputs = [(flag, path) for flag, path in (("--report", None if to_stdout else args.report),
                                               ("--usd-out", args.usd_out), ("--preview", args.preview))
               if path is not None]
    # Every destination is checked before the stage is read; nothing is written on an error.
    try:
        refuse_overwriting([("the input", args.stage)], outputs)
        for i, output in enumerate(outputs):
            refuse_overwriting([(f"the {flag} file", path) for flag, path in outputs[:i]], [output])
        if args.report is not None and not to_stdout:
            from ..output import check_output_path

            check_output_path(args.report, (".json",), "report")
        if args.usd_out is not None:
            from ..usd.export import validate_stage_path

            validate_stage_path(args.usd_out)
        if args.preview is not None:
            from ..preview import validate_preview_path

            if validate_preview_path(args.preview)[1] != ".png":
                raise ValueError(f"cannot write {args.preview}: the preview of a check is one picture (use .png)")
        frames = _frames(args.frames)
        options = check_options_from(args)
    except ValueError as exc:
        raise fail(str(exc)) from None
    require_usd(fail)
    quiet_warp()
    init_warp()
    from ..check.check import check_usd
    from ..check.overlay import prepare_overlay
    from ..usd.stage import layer_files, missing_layers, open_stage, require_layers

    t = time.perf_counter()
    try:
        stage = open_stage(args.stage)
        missing = missing_layers(stage)
        # A layer the stage uses (or one it names but cannot open) is an input too.
        refuse_overwriting([(f"a layer of {args.stage}", p) for p in layer_files(stage)]
                            + [(f"an asset {args.stage} uses", p) for p in missing], outputs)
        require_layers(stage, options.allow_missing, missing)
        device = resolve_device(args.device)
    except ValueError as exc:
        raise fail(str(exc)) from None
    opened = time.perf_counter() - t

    modules = (CHECK_KERNEL_MODULES + (CONTINUOUS_KERNEL_MODULES if options.continuous else ())
               + (CLEARANCE_KERNEL_MODULES if options.clearance > 0.0 else ())
               + (SELF_KERNEL_MODULES if options.self_intersections else ())
               + (("warp_ccd.preview",) if args.preview is not None else ()))
    for name in modules:
        importlib.import_module(name)
    if uncached_modules(device, modules):
        print(f"{PROG} check: compiling kernels for {device} (not in Warp's kernel cache yet; later runs "
              "reuse them)...", file=sys.stderr, flush=True)
    from ..geometry.precision import PrecisionWarning

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", PrecisionWarning)
            report = check_usd(stage, options, frames=frames, prims=flat_values(args.prims), device=device)
    except ValueError as exc:  # the input at fault: the line names the file
        text = str(exc)
        raise fail(text if text.startswith((args.stage, os.path.realpath(args.stage))) else f"{args.stage}: {text}") \
            from None
    for w in caught:  # a switch to float64: one plain line (others as Python shows them)
        if issubclass(w.category, PrecisionWarning):
            print(f"{PROG} check: note: {w.message}", file=sys.stderr)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    report.seconds["read"] = round(report.seconds.get("read", 0.0) + opened, 4)  # the stage was opened here
    print(report.summary(top=args.top))

    # Every output to a temporary file first; all moved into place once all are written.
    text = None
    with pending_outputs(fail) as (pending, lines):
        if to_stdout:
            text = report.json_text()  # printed once the files are in place
        elif args.report is not None:
            pending.append(report.prepare_json(args.report))
            lines.append("  report : {}")
        if args.usd_out is not None:
            pending.append(prepare_overlay(report, args.usd_out))
            lines.append("  overlay: {}")
        if args.preview is not None:
            import numpy as np

            from ..preview import PreviewRenderer, prepare_preview

            worst = report.worst_frame
            imp = report.source
            imp.set_frame(worst)
            colliding = np.zeros(len(report.object_path), bool)
            colliding[report.frames[worst].triangle_pairs[:, [0, 2]].ravel()] = True
            picture = PreviewRenderer(imp.scene, 640, 480).render(colliding)
            pending.append(prepare_preview([picture], args.preview))
            lines.append(f"  preview: {{}} (time {report.frames[worst].time:g})")
    if to_stdout:
        print("  report : standard output")
    return (EXIT_FINDINGS if report.findings else EXIT_OK), text


def _ray_before_files(argv: list[str]) -> list[str]:
    """``check --ray IN.usd ...``: the file is a file, not ``--ray``'s address (``--ray=local IN.usd ...``)."""
    out = list(argv)
    for k, arg in enumerate(out[:-1]):
        if arg == "--ray" and _looks_like_file(out[k + 1]):
            out[k] = "--ray=local"
    return out


def _looks_like_file(text: str) -> bool:
    """Whether a ``--ray`` value is a USD file or pattern (``--ray IN.usd``) rather than a cluster's address."""
    from ..usd.export import STAGE_EXTENSIONS

    return os.path.exists(text) or text.lower().endswith(tuple(STAGE_EXTENSIONS + (".usdz",))) or "*" in text


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
        Exit status: 0 success; 1 ``check`` found collisions (``demo``: it failed while running);
        2 bad arguments or input; 3 an internal error (an unexpected exception: one line on stderr,
        its traceback with ``--debug``); 130 interrupted.
    """
    stdout = sys.stdout
    sys.stdout = QuietClosedStdout(stdout)  # a reader that has gone: the verdict's status, no BrokenPipeError
    try:
        return _main(list(sys.argv[1:] if argv is None else argv))
    finally:
        sys.stdout.flush()
        sys.stdout = stdout


def _main(argv: list[str]) -> int:
    """:func:`main` with its standard output in place."""
    if argv and argv[0] == "bench":
        return _run_bench(argv[1:])
    args = None
    try:
        try:
            args = _build_parser().parse_args(_ray_before_files(_join_dash_values(argv)))
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
        if args is None or args.command != "demo":
            return _internal_error(exc, args)
        print(f"{PROG}: error: {exc}", file=sys.stderr)  # the demo's failures while running: exit status 1
        return EXIT_ERROR
    except Exception as exc:
        return _internal_error(exc, args)


def _internal_error(exc: Exception, args) -> int:
    """One line on stderr for an unexpected exception (a bug, or the machine: memory, the device;
    not the input), its traceback first with ``--debug``; returns :data:`EXIT_INTERNAL`."""
    debug = getattr(args, "debug", False)
    if debug:
        traceback.print_exception(exc)
    text = str(exc).strip().splitlines()
    where = f" {args.command}" if args is not None else ""
    hint = "" if debug else " (--debug prints the traceback)"
    print(f"{PROG}{where}: internal error: {type(exc).__name__}" + (f": {text[0]}" if text else "") + hint,
          file=sys.stderr)
    return EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())
