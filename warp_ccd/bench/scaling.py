"""Benchmarks: ms per frame against the number of objects, per stage, with peers in the same run.

``warp-ccd bench`` and ``python -m warp_ccd.bench`` run :func:`main`. For each triangle count
(``--triangles``) and each object count ``N`` (``--objects``), on the scaling scene
``Scene.random(N, seed, shapes)`` (constant density, so the work per object does not depend on
``N``):

1. **Frames.** ``--warmup`` frames (kernel loading, buffers growing, graphs captured), then
   ``--frames`` timed ones. Each frame moves the scene once and then runs every method on the same
   world vertices. On CUDA the move is this package's whole frame, ``detect(advance=dt)`` replayed
   as one CUDA graph (``total_graph``); the motion alone (``motion``, eager) is timed by moving
   again by 0 s (the same poses). Times are wall-clock ms with
   ``wp.synchronize_device`` before and after what is timed; each row gives the min and the
   median over the timed frames.
2. **Methods.**

   * ``warp_ccd``: this package's :class:`~warp_ccd.pipeline.CollisionPipeline`: with
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
     :class:`~warp_ccd.bench.peers.WarpMeshPipeline`, at its best: a frame is refit + query + one
     read of its counter into pinned memory, launched eagerly (``detect_eager``) and, on CUDA, as a
     captured graph (``detect_graph``); ``detect`` is the faster by median.
   * ``fcl`` (peer ``fcl``): python-fcl, :class:`~warp_ccd.bench.peers.FclPipeline`, on the host, for
     ``N <= --fcl-max-objects``; its stages timed in turn.
   * ``warp_ccd_nxn`` (peer ``nxn``): this pipeline with the all-pairs broad phase, for
     ``N <= --nxn-max-objects``.
   * ``newton_sap`` (peer ``newton``): newton's ``BroadPhaseSAP`` alone, on the object boxes this
     pipeline's broad phase saw (``broad``, eager or graph as the built-in; compare with
     ``warp_ccd``'s ``broad``).

   Peers report ``detect`` and ``total`` (``motion + detect``). A peer whose library is missing
   is skipped with a note; a peer that raises is reported with an ``ERROR`` note.
3. **Checks**, on the last frame (:mod:`warp_ccd.bench.compare`), which judge this package, not
   its peers: ``warp_builtin`` and ``fcl`` must find the same object pairs as ``warp_ccd`` up to
   near-touching pairs, their triangle-level differences are classified and counted, and a real
   difference is charged to whichever method an independent arbiter (Warp's float64 test on the
   scaled pair) finds wrong; ``warp_ccd_nxn`` must find the very same triangle pairs and as many
   broad-phase pairs; ``newton_sap`` the same box pairs as this package's
   :class:`~warp_ccd.stages.broad_phase.BroadPhaseSAP` on the same boxes, each differing pair judged by
   an exact overlap test in numpy. A peer found wrong is a finding: its rows are marked ``*``
   (``peer_wrong`` in the JSON). A difference charged to ``warp_ccd`` is a mismatch: the command
   ends with status 3 after everything is written.
4. **Memory** of a fresh ``warp_ccd`` pipeline over two frames: the peak of Warp's allocation
   tracker (``wp.ScopedMemoryTracker``; it sees every Warp allocation, native trees included), on
   CUDA also the memory pool's high-water mark when it rose, and the bytes of the arrays the
   pipeline and the scene hold; per scene triangle too.

Output: a table per case and a summary on stdout (ratios are a peer's median over
``warp_ccd``'s for the same stage: above 1, ``warp_ccd`` is faster), a JSON file (``--out``:
device, date, versions, git commit, ``rows`` of ``method, n_objects, triangles,
triangles_per_object, stage, ms_min, ms_median, object_pairs, triangle_pairs, frames, mode,
peer_wrong`` (for a broad phase alone, ``object_pairs`` counts its box pairs; ``mode``: the faster
of eager and graph behind a best-of stage), ``memory``, ``checks``, ``notes``; rewritten after
each case so that a long run that dies keeps what it measured) and a log-log plot of ms per frame
against ``N`` (``--plot``, needs matplotlib).

Exit status: 0 ``warp_ccd`` stands (peers' wrong answers and failures are reported, not failed),
2 bad arguments, 3 a real mismatch charged to ``warp_ccd``.
"""

from __future__ import annotations

import argparse
import datetime
import importlib.metadata
import json
import math
import os
import platform
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import warp as wp

from .. import __version__
from ..cli.common import CliError, OneLineParser, quiet_warp, resolve_device
from ..output import PendingFile, check_output_path
from ..pipeline import CollisionPipeline
from ..scene.scene import Scene
from ..stages.broad_phase import find_pairs, make_broad_phase
from ..stages.buffers import GrowableBuffer
from .compare import PairCheck, box_overlap_truth, compare_exact, compare_triangle_pairs
from .peers import FclPipeline, NewtonBroadPhaseSAP, PeerUnavailable, WarpMeshPipeline
from .timing import MODES, ModeFrames, StageTimes, run_stages, synced_ms

__all__ = [
    "PEERS",
    "BenchReport",
    "PipelineMethod",
    "StageTimes",
    "array_bytes",
    "build_parser",
    "environment",
    "main",
    "measure_pipeline_memory",
    "parse_triangles",
    "run_case",
    "write_json",
]

EXIT_OK = 0
EXIT_MISMATCH = 3

PEERS = ("builtin", "fcl", "nxn", "newton")
"""Peer names accepted by ``--peers``."""

REFERENCE = "warp_ccd"
"""Name of this package's pipeline in rows and checks."""

DT = 1.0 / 60.0
"""Time step of a frame, s."""

JSON_EXTENSIONS = (".json",)
PLOT_EXTENSIONS = (".png", ".svg", ".pdf")

NXN_MAX_OBJECTS = {"cpu": 3000, "cuda": 20000}
"""Default ``--nxn-max-objects`` per device kind: the all-pairs broad phase is O(N^2)."""


# ---------------------------------------------------------------------------------------------
# Methods run on a scene


class PipelineMethod:
    """This package's pipeline: timed per stage (``timings=True``), and as whole frames in every mode
    of :func:`device_modes` (``detect_eager``, ``detect_graph``, ``total_graph``, host times).

    Args:
        name: row name.
        scene: the scene.
        **options: :class:`~warp_ccd.pipeline.CollisionPipeline` options (e.g. ``broad_phase``).
    """

    def __init__(self, name: str, scene: Scene, **options):
        self.name = name
        self.scene = scene
        self.device = scene.device
        self.staged = CollisionPipeline(scene, timings=True, **options)
        self.modes = device_modes(scene.device)
        self.pipes = {m: CollisionPipeline(scene, graph=m == "graph", **options) for m in self.modes}
        self.plain = self.pipes["eager"]
        self.result = None

    def advance(self, dt: float) -> tuple[float, dict]:
        """Moves the scene by ``dt``. With a graph mode the move is part of the frame: ``detect(advance=dt)``
        replayed as one graph, timed as ``total_graph`` (its host time ``host_graph``); the motion alone is
        then timed by moving again by 0 s (the same poses). Else the motion alone, eagerly.

        Returns:
            ``(motion ms, {stage: ms})``.
        """
        if "graph" not in self.pipes:
            return synced_ms(lambda: self.scene.advance(dt), self.device), {}
        wall, host = self._graph_frame(dt)
        times = {"total_graph": wall, "host_graph": host}
        return synced_ms(lambda: self.scene.advance(0.0), self.device), times

    def _graph_frame(self, dt: float) -> tuple[float, float]:
        """One fused graph frame ``detect(advance=dt)``: ``(wall ms, host ms)``."""
        pipe = self.pipes["graph"]
        out = {}

        def frame():
            out["result"] = pipe.detect(advance=dt)

        wall = synced_ms(frame, self.device)
        return wall, out["result"].host_ms

    def loop(self, dt: float, count: int) -> list[dict]:
        """``count`` fused graph frames ``detect(advance=dt)`` back to back, nothing else between them
        (a simulation loop); per frame ``{"loop_graph": wall ms, "host_loop_graph": host ms}``.
        Empty without a graph mode."""
        if "graph" not in self.pipes:
            return []
        return [dict(zip(("loop_graph", "host_loop_graph"), self._graph_frame(dt))) for _ in range(count)]

    def run(self) -> dict:
        """One frame of detection on the scene as it is; ms per stage, ``detect_synced``, ``detect_<mode>``
        and ``host_eager``."""
        staged = self.staged.detect()
        times = {("detect_synced" if k == "total" else k): v for k, v in (staged.timings or {}).items()}
        out = {}
        for mode, pipe in self.pipes.items():

            def detect(pipe=pipe, mode=mode):
                out[mode] = pipe.detect()

            times[f"detect_{mode}" if len(self.pipes) > 1 else "detect"] = synced_ms(detect, self.device)
        times["host_eager" if len(self.pipes) > 1 else "host"] = out["eager"].host_ms
        self.result = out["eager"]
        return times

    def triangle_pairs(self) -> np.ndarray:
        """``(M, 4)`` rows of the last frame."""
        return self.result.triangle_pairs

    def object_boxes(self) -> tuple:
        """``(lower, upper)`` ``(N,)`` object boxes the broad phase saw in the last frame."""
        return self.plain.boxes.lower, self.plain.boxes.upper

    def counts(self) -> tuple:
        """``(object pairs, triangle pairs)`` of the last frame."""
        return len(self.result.object_pairs), self.result.num_triangle_pairs


def device_modes(device) -> tuple:
    """How device peers are launched on ``device``: eagerly, and on CUDA also as a captured graph."""
    return MODES if wp.get_device(device).is_cuda else ("eager",)


class HostPeerMethod:
    """A host peer of :mod:`warp_ccd.bench.peers` (python-fcl), timed stage by stage (:func:`run_stages`)."""

    def __init__(self, peer, device):
        self.name = peer.name
        self.peer = peer
        self.device = device

    def run(self) -> dict:
        """One frame; ms per peer stage and ``detect``."""
        return run_stages(self.peer.stages(), self.peer.finish, self.device)

    def triangle_pairs(self) -> np.ndarray:
        """``(M, 4)`` rows of the last frame."""
        return self.peer.triangle_pairs()

    def counts(self) -> tuple:
        """``(object pairs, triangle pairs)`` of the last frame."""
        t = self.triangle_pairs()
        return (len(np.unique(t[:, [0, 2]], axis=0)) if len(t) else 0), len(t)


class DevicePeerMethod(HostPeerMethod):
    """A device peer of :mod:`warp_ccd.bench.peers` at its best: each frame is its ``launch()`` and one
    read of its counters into pinned memory (:class:`~warp_ccd.bench.timing.CountedFrame`), run in
    every mode of :func:`device_modes` in turn. Stages ``detect_eager``, ``detect_graph``; the
    report's ``detect`` is the faster of the two (by median)."""

    def __init__(self, peer, device):
        super().__init__(peer, device)
        self.frames = ModeFrames(peer.launch, peer.counters, device, device_modes(device))
        self.count = 0

    def run(self) -> dict:
        """One frame per mode; ms of ``detect_<mode>`` (``detect`` with one mode)."""
        times = self.frames.run("detect")
        self.count = self.frames.counts[0]
        return times

    def triangle_pairs(self) -> np.ndarray:
        """``(M, 4)`` rows of the last frame."""
        return self.peer.triangle_pairs(self.count)


class BroadPhaseMethod:
    """A broad phase alone on the object boxes of ``source`` (run after it in each frame), at its best:
    launch and one counter read, in every mode of :func:`device_modes` (stages ``broad_eager``,
    ``broad_graph``; ``broad`` is the faster)."""

    def __init__(self, name: str, broad, source: PipelineMethod, device):
        self.name = name
        self.broad = broad
        self.source = source
        self.device = device
        n = source.plain.scene.num_objects
        self.pairs = GrowableBuffer(wp.vec2i, max(64, 4 * n), device, f"{name} pairs")
        self.frames = ModeFrames.broad_phase(broad, source.object_boxes, self.pairs, device, device_modes(device))
        self.num_pairs = 0

    def run(self) -> dict:
        """One frame per mode; ms of ``broad_<mode>`` (``broad`` with one mode)."""
        times = self.frames.run("broad")
        self.num_pairs = self.frames.counts[0]
        return times

    def box_pairs(self) -> np.ndarray:
        """``(K, 2)`` box pairs of the last frame, as the broad phase wrote them."""
        return self.pairs.numpy(self.num_pairs).reshape(-1, 2)

    def box_truth(self):
        """The exact overlap test of the boxes this method saw (:func:`~warp_ccd.bench.compare.box_overlap_truth`)."""
        return box_overlap_truth(*self.source.object_boxes())

    def reference_box_pairs(self) -> np.ndarray:
        """``(K, 2)`` pairs of this package's :class:`~warp_ccd.stages.broad_phase.BroadPhaseSAP` on the same boxes."""
        lower, upper = self.source.object_boxes()
        pairs = GrowableBuffer(wp.vec2i, self.pairs.capacity, self.device, "reference box pairs")
        count = find_pairs(make_broad_phase("sap", device=self.device), lower, upper, pairs)
        return pairs.numpy(count).reshape(-1, 2)

    def counts(self) -> tuple:
        """``(box pairs, None)`` of the last frame."""
        return self.num_pairs, None


# ---------------------------------------------------------------------------------------------
# Memory


def array_bytes(*roots, exclude: set | None = None) -> tuple[int, set]:
    """Bytes of the distinct ``wp.array`` buffers reachable from ``roots``.

    Follows attributes of this package's objects (its ``wp.struct`` instances too), lists, tuples
    and dicts. Views are not counted
    twice: an array without its own allocation counts only when it lies outside every counted one.

    Args:
        roots: objects to walk (a scene, a pipeline...).
        exclude: buffer addresses not to count (e.g. the scene's, when measuring a pipeline).

    Returns:
        ``(bytes, addresses counted)``.
    """
    exclude = set(exclude or ())
    seen, arrays, stack = set(), {}, list(roots)
    while stack:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, wp.array):
            if obj.ptr and obj.ptr not in exclude:
                arrays[obj.ptr] = max(arrays.get(obj.ptr, (0, False)), (int(obj.capacity), obj.deleter is not None))
        elif isinstance(obj, (list, tuple, set)):
            stack.extend(obj)
        elif isinstance(obj, dict):
            stack.extend(obj.values())
        elif hasattr(obj, "__dict__") and any(c.__module__.startswith("warp_ccd") for c in type(obj).__mro__):
            stack.extend(vars(obj).values())  # this package's objects, and instances of its wp.structs
    owners = sorted((p, c) for p, (c, owns) in arrays.items() if owns)
    total = sum(c for _, c in owners)
    starts = np.array([p for p, _ in owners], np.uint64)
    ends = np.array([p + c for p, c in owners], np.uint64)
    for p, (c, owns) in arrays.items():
        if not owns:
            k = int(np.searchsorted(starts, np.uint64(p), side="right")) - 1
            if k < 0 or p >= int(ends[k]):
                total += c
    return total, set(arrays)


_UNITS = {"B": 1, "KB": 1024, "MB": 1024**2, "GB": 1024**3, "TB": 1024**4}


def _tracker_peak(text: str, device) -> int | None:
    """The ``Peak usage`` of ``device`` in a Warp allocation-tracker report, in bytes."""
    lines = text.splitlines()
    try:
        start = next(k for k, line in enumerate(lines) if line.strip() == "Peak usage:")
    except StopIteration:
        return None
    for line in lines[start + 1:]:
        parts = line.split()
        if len(parts) != 3 or parts[2] not in _UNITS:
            break
        if parts[0] == str(device):
            try:
                return int(float(parts[1]) * _UNITS[parts[2]])
            except ValueError:
                return None
    return None


def measure_pipeline_memory(scene: Scene, frames: int = 2) -> dict:
    """Memory of a fresh default :class:`~warp_ccd.pipeline.CollisionPipeline` over ``frames`` frames.

    Returns:
        ``scene_bytes`` (arrays the scene holds), ``pipeline_resident_bytes`` (arrays the
        pipeline holds afterwards), on CUDA ``mempool_peak_bytes`` (the pool's high-water mark
        minus its use before, when the mark rose, else None), ``pipeline_peak_bytes`` (the peak
        of Warp's allocation tracker while building and running the pipeline; else the pool's;
        else the resident bytes) with its ``peak_source``, and the byte counts per scene triangle.
    """
    device = scene.device
    scene_bytes, scene_ptrs = array_bytes(scene)
    wp.synchronize_device(device)
    use_pool = device.is_cuda and wp.is_mempool_enabled(device)
    if use_pool:
        pool_used, pool_high = wp.get_mempool_used_mem_current(device), wp.get_mempool_used_mem_high(device)

    def build_and_run():
        pipe = CollisionPipeline(scene)
        for _ in range(frames):
            pipe.detect()
        wp.synchronize_device(device)
        return pipe

    peak = None
    tracker = getattr(wp, "ScopedMemoryTracker", None)
    if tracker is not None:
        reports = []
        with tracker("warp_ccd.bench", print=False, report_func=reports.append) as t:
            t.clear()
            pipe = build_and_run()
            t.report(max_items=0)
        peak = _tracker_peak(reports[-1], device) if reports else None
    else:
        pipe = build_and_run()
    out = {"scene_bytes": scene_bytes}
    out["pipeline_resident_bytes"], _ = array_bytes(pipe, exclude=scene_ptrs)
    if use_pool:
        high = wp.get_mempool_used_mem_high(device)
        out["mempool_peak_bytes"] = int(high - pool_used) if high > pool_high else None
    if peak is not None:
        out["pipeline_peak_bytes"], out["peak_source"] = peak, "warp alloc tracker"
    elif out.get("mempool_peak_bytes"):
        out["pipeline_peak_bytes"], out["peak_source"] = out["mempool_peak_bytes"], "CUDA mempool high-water mark"
    else:
        out["pipeline_peak_bytes"], out["peak_source"] = out["pipeline_resident_bytes"], "resident arrays"
    tri = max(scene.num_triangles, 1)
    for key in ("scene_bytes", "pipeline_resident_bytes", "pipeline_peak_bytes"):
        out[key.replace("_bytes", "_bytes_per_triangle")] = out[key] / tri
    del pipe
    return out


# ---------------------------------------------------------------------------------------------
# One case: one scene, all methods


def parse_triangles(spec: str) -> tuple[str, tuple | None]:
    """``"poly"`` -> the five polyhedra of :meth:`~warp_ccd.scene.scene.Scene.random`; ``"80"`` (``20 * 4**L``)
    or ``"icosphereL"`` -> icosphere level L; ``"mixed"`` -> meshes of the sizes of real assets, 120
    to 12,640 triangles (:mod:`warp_ccd.bench.meshes`).

    Returns:
        ``(label, shapes)``: ``shapes`` for :meth:`Scene.random` (None: its default polyhedra).

    Raises:
        ValueError: an unknown spec.
    """
    text = str(spec).strip().lower()
    if text == "poly":
        return "poly", None
    if text == "mixed":
        from .meshes import real_mesh_set

        return "mixed", real_mesh_set()
    if text.startswith("icosphere") and text[len("icosphere"):].isdigit():
        level = int(text[len("icosphere"):])
        return str(20 * 4**level), (f"icosphere{level}",)
    if text.isdigit():
        count = int(text)
        for level in range(9):
            if 20 * 4**level == count:
                return text, (f"icosphere{level}",)
    known = ", ".join(str(20 * 4**k) for k in range(6))
    raise ValueError(f"--triangles: {spec!r} is neither 'poly', 'mixed' nor an icosphere's triangle count "
                     f"({known}, ...)")


@dataclass
class CaseResult:
    """Everything measured for one ``(triangles, N)``."""

    label: str
    num_objects: int
    num_triangles: int
    times: dict  # method -> StageTimes
    counts: dict  # method -> (object pairs, triangle pairs)
    checks: list  # PairCheck
    memory: dict | None
    notes: list

    @property
    def ok(self) -> bool:
        """No real mismatch charged to this package."""
        return all(c.ok for c in self.checks)

    @property
    def wrong_peers(self) -> set:
        """Peers whose answers the checks found wrong (findings, not failures)."""
        return {c.peer for c in self.checks if not c.peer_ok}


def _make_peers(scene: Scene, peers: list, ours: PipelineMethod, args, notes: list) -> list:
    device = scene.device
    n = scene.num_objects
    methods = []
    for peer in peers:
        try:
            if peer == "builtin":
                methods.append(DevicePeerMethod(WarpMeshPipeline(scene), device))
            elif peer == "fcl":
                if n > args.fcl_max_objects:
                    notes.append(f"fcl skipped: {n} objects > --fcl-max-objects {args.fcl_max_objects}")
                    continue
                methods.append(HostPeerMethod(FclPipeline(scene), device))
            elif peer == "nxn":
                limit = args.nxn_max_objects
                if limit is None:
                    limit = NXN_MAX_OBJECTS["cuda" if device.is_cuda else "cpu"]
                if n > limit:
                    notes.append(f"nxn skipped: {n} objects > --nxn-max-objects {limit}")
                    continue
                methods.append(PipelineMethod("warp_ccd_nxn", scene, broad_phase="nxn"))
            elif peer == "newton":
                methods.append(BroadPhaseMethod("newton_sap", NewtonBroadPhaseSAP(device=device), ours, device))
        except PeerUnavailable as exc:
            notes.append(f"{peer} skipped: {exc}")
    return methods


def _checks(scene: Scene, ours: PipelineMethod, methods: list) -> list[PairCheck]:
    checks = []
    ours_rows = ours.triangle_pairs()
    for m in methods:
        if isinstance(m, BroadPhaseMethod):
            checks.append(compare_exact("warp_ccd_sap", m.reference_box_pairs(), m.name, m.box_pairs(), "box pairs",
                                        truth=m.box_truth()))
        elif isinstance(m, PipelineMethod):
            check = compare_exact(REFERENCE, ours_rows, m.name, m.triangle_pairs(), "triangle pairs", width=4)
            ours_broad, peer_broad = ours.result.num_broad_pairs, m.result.num_broad_pairs
            if ours_broad != peer_broad:
                check.mismatches.append(f"{m.name} finds {peer_broad} broad-phase pairs, {REFERENCE} {ours_broad}")
            checks.append(check)
        else:
            checks.append(compare_triangle_pairs(scene, REFERENCE, ours_rows, m.name, m.triangle_pairs()))
    return checks


def run_case(num_objects: int, triangles: str, args, device) -> CaseResult:
    """Builds the scaling scene, runs all methods frame by frame, checks and measures memory.

    Args:
        num_objects: ``N``.
        triangles: a ``--triangles`` spec (see :func:`parse_triangles`).
        args: parsed options (``seed``, ``frames``, ``warmup``, ``peers``, limits, ``memory``).
        device: Warp device.
    """
    label, shapes = parse_triangles(triangles)
    kwargs = {} if shapes is None else {"shapes": shapes}
    scene = Scene.random(num_objects, seed=args.seed, device=device, **kwargs)
    notes = []
    ours = PipelineMethod(REFERENCE, scene)
    methods = [ours, *_make_peers(scene, args.peers, ours, args, notes)]
    times = {m.name: StageTimes() for m in methods}
    failed = set()
    for frame in range(args.warmup + args.frames):
        motion, frame_times = ours.advance(DT)
        for m in methods:
            if m.name in failed:
                continue
            try:
                t = m.run()
            except Exception as exc:  # a peer failing must not lose the other measurements
                if m is ours:
                    raise
                failed.add(m.name)
                notes.append(f"ERROR {m.name} failed at frame {frame}: {type(exc).__name__}: {exc}")
                continue
            if m is ours:
                t = {"motion": motion, **t, **frame_times}
            for detect in ("detect", *(f"detect_{mode}" for mode in MODES)):
                total = "total" + detect[len("detect"):]
                if detect in t and total not in t:
                    t[total] = motion + t[detect]
            if frame >= args.warmup:
                times[m.name].add(t)
    live = [m for m in methods if m.name not in failed]
    checks = _checks(scene, ours, live[1:])
    counts = {m.name: m.counts() for m in live}
    for t in ours.loop(DT, args.frames):  # after the checks: these frames move the scene on
        times[ours.name].add(t)
    memory = measure_pipeline_memory(scene) if args.memory else None
    return CaseResult(label, num_objects, scene.num_triangles, {m.name: times[m.name] for m in live},
                      counts, checks, memory, notes)


# ---------------------------------------------------------------------------------------------
# Report: rows, tables, JSON, plot


def _bytes(n: float | None) -> str:
    if n is None:
        return "-"
    for unit, size in (("GB", 1024**3), ("MB", 1024**2), ("KB", 1024)):
        if n >= size:
            return f"{n / size:.2f} {unit}"
    return f"{int(n)} B"


def _git_commit() -> tuple[str | None, bool | None]:
    """``(commit, tracked files other than bench/results/ modified)`` of the code that runs: ``WARP_CCD_GIT_COMMIT`` and
    ``WARP_CCD_GIT_DIRTY`` ("0" or "1") from the environment when set (a copy of the tree on
    another machine, whose git, if any, need not describe it), else the checkout's HEAD, else Nones."""
    if os.environ.get("WARP_CCD_GIT_COMMIT"):
        dirty = os.environ.get("WARP_CCD_GIT_DIRTY")
        return os.environ["WARP_CCD_GIT_COMMIT"], (None if dirty is None else dirty == "1")
    root = Path(__file__).resolve().parents[2]
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10)
        if commit.returncode != 0:
            return None, None
        # Result files written by earlier benchmarks of the same run are not a change of the code.
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".",
                                ":(exclude)bench/results"], cwd=root, capture_output=True, text=True, timeout=10)
        return commit.stdout.strip(), bool(dirty.stdout.strip())
    except (OSError, subprocess.SubprocessError):
        return None, None


def environment(device) -> dict:
    """What a result file records about where it was measured.

    Returns:
        ``device``, ``device_name``, ``date`` (UTC, ISO 8601), ``versions`` (Python, platform,
        warp_ccd, Warp, numpy and the optional peers' packages, None when missing),
        ``git_commit`` and ``git_dirty``.
    """
    versions = {"python": platform.python_version(), "platform": platform.platform(), "warp_ccd": __version__,
                "warp": wp.__version__, "numpy": np.__version__}
    for dist in ("python-fcl", "newton", "matplotlib"):
        try:
            versions[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            versions[dist] = None
    commit, dirty = _git_commit()
    return {
        "device": str(device),
        "device_name": getattr(device, "name", None),
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "versions": versions,
        "git_commit": commit,
        "git_dirty": dirty,
    }


def write_json(path: str, document: dict) -> None:
    """Writes ``document`` to ``path``, replaced in one step (see :mod:`warp_ccd.output`).

    Raises:
        ValueError: ``path`` is not a writable ``.json`` destination.
    """
    full, _ = check_output_path(path, JSON_EXTENSIONS, "JSON")
    pending = PendingFile(full)
    with open(pending.temp_path, "w") as f:
        json.dump(document, f, indent=1)
        f.write("\n")
    pending.commit()


class BenchReport:
    """Collects cases; prints tables; writes JSON and the plot.

    Args:
        device: Warp device.
        config: options to record (JSON-ready).
        reference: the method ratios are taken against.
    """

    def __init__(self, device, config: dict, reference: str = REFERENCE):
        self.device = device
        self.config = config
        self.reference = reference
        self.cases: list[CaseResult] = []
        self.environment = environment(device)

    def add(self, case: CaseResult) -> None:
        """Adds a measured case."""
        self.cases.append(case)

    @property
    def ok(self) -> bool:
        """No real mismatch in any case."""
        return all(c.ok for c in self.cases)

    def rows(self) -> list[dict]:
        """One dict per ``(method, N, triangles, stage)``."""
        out = []
        for c in self.cases:
            for method, st in c.times.items():
                obj, tri = c.counts.get(method, (None, None))
                for stage, (lo, med) in st.summary().items():
                    out.append({
                        "method": method, "n_objects": c.num_objects, "triangles": c.label,
                        "triangles_per_object": round(c.num_triangles / max(c.num_objects, 1), 3),
                        "stage": stage, "ms_min": lo, "ms_median": med,
                        "object_pairs": obj, "triangle_pairs": tri, "frames": st.frames(stage),
                        "mode": st.best_mode.get(stage), "peer_wrong": method in c.wrong_peers,
                    })
        return out

    def to_json(self) -> dict:
        """The JSON document."""
        return {
            **self.environment,
            "config": self.config,
            "rows": self.rows(),
            "memory": [{"method": self.reference, "n_objects": c.num_objects, "triangles": c.label,
                        "num_triangles": c.num_triangles, **c.memory} for c in self.cases if c.memory],
            "checks": [{"n_objects": c.num_objects, "triangles": c.label, **k.to_dict()}
                       for c in self.cases for k in c.checks],
            "notes": [{"n_objects": c.num_objects, "triangles": c.label, "note": note}
                      for c in self.cases for note in c.notes],
            "ok": self.ok,
        }

    def write_json(self, path: str) -> None:
        """Writes :meth:`to_json` to ``path``."""
        write_json(path, self.to_json())

    def case_table(self, c: CaseResult) -> str:
        """The table of one case, its memory, checks and verdict."""
        ref = c.times.get(self.reference)
        ref_med = {s: m for s, (_, m) in ref.summary().items()} if ref else {}
        lines = [
            f"== {c.num_objects:,} objects, triangles {c.label} ({c.num_triangles / max(c.num_objects, 1):.1f} per "
            f"object, {c.num_triangles:,} in all) on {self.device}, {self.config['frames']} frames after "
            f"{self.config['warmup']} warm-up",
            f"{'method':<14}{'stage':<15}{'ms min':>10}{'ms median':>11}{'/' + self.reference:>14}"
            f"{'object pairs':>14}{'tri pairs':>11}",
        ]
        for method, st in c.times.items():
            obj, tri = c.counts.get(method, (None, None))
            summary = st.summary()
            name = method + ("*" if method in c.wrong_peers else "")
            for k, (stage, (lo, med)) in enumerate(summary.items()):
                ratio = ""
                if method != self.reference and stage in ref_med and ref_med[stage] > 0:
                    ratio = f"{med / ref_med[stage]:.2f}x"
                if stage in st.best_mode:
                    stage = f"{stage} ({st.best_mode[stage]})"
                last = k == len(summary) - 1
                obj_text = obj if last and obj is not None else ""
                tri_text = tri if last and tri is not None else ""
                lines.append(f"{name if k == 0 else '':<14}{stage:<15}{lo:>10.3f}{med:>11.3f}{ratio:>14}"
                             f"{obj_text:>14}{tri_text:>11}")
        if c.memory:
            m = c.memory
            pool = f", CUDA pool high-water {_bytes(m['mempool_peak_bytes'])}" if m.get("mempool_peak_bytes") else ""
            lines.append(f"memory: {self.reference} pipeline peak {_bytes(m['pipeline_peak_bytes'])} "
                         f"({m['pipeline_peak_bytes_per_triangle']:.1f} B/triangle, {m['peak_source']}{pool}), "
                         f"resident {_bytes(m['pipeline_resident_bytes'])}; scene {_bytes(m['scene_bytes'])} "
                         f"({m['scene_bytes_per_triangle']:.1f} B/triangle)")
        lines += [f"note: {n}" for n in c.notes]
        lines += [f"check: {k.summary()}" for k in c.checks]
        for k in c.checks:
            lines += [f"  MISMATCH: {m}" for m in k.mismatches]
            lines += [f"  PEER WRONG: {m}" for m in k.peer_errors]
        if c.wrong_peers:
            lines.append(f"* {', '.join(sorted(c.wrong_peers))}: wrong answers in this case (a finding about the "
                         f"peer, judged by an independent check; {self.reference} stands)")
        agreeing = ", ".join(k.peer for k in c.checks if k.ok and k.peer_ok)
        verdict = "OK" if c.ok else "MISMATCH"
        lines.append(f"VERDICT {c.num_objects:,} objects, triangles {c.label}: {verdict}"
                     + (f" ({agreeing} agree with {self.reference})" if c.ok and agreeing else "")
                     + ("" if c.checks else " (no peer to compare with)"))
        return "\n".join(lines)

    def summary_table(self, stage: str = "total") -> str:
        """Medians of ``stage`` per N and method, with each peer's ratio to the reference."""
        methods = []
        for c in self.cases:
            for m, st in c.times.items():
                if st.has(stage) and m not in methods:
                    methods.append(m)
        broad = [m for c in self.cases for m, st in c.times.items() if not st.has("detect") and st.has("broad")]
        broad = list(dict.fromkeys(([self.reference] if broad else []) + broad))
        width = 22
        head = f"{'triangles':<10}{'objects':>10}" + "".join(f"{m:>{width}}" for m in methods)
        if broad:
            head += "   | broad:" + "".join(f"{m:>{width}}" for m in broad)
        lines = [f"ms per frame, median ({stage} = motion + detection; in brackets: peer / {self.reference}), "
                 f"{self.device}",
                 head]

        def cell(c, m, s):
            st = c.times.get(m)
            if st is None or not st.has(s):
                return f"{'-':>{width}}"
            med = st.summary()[s][1]
            ref = c.times.get(self.reference)
            text = f"{med:.3f}"
            if m != self.reference and ref is not None and ref.has(s) and ref.summary()[s][1] > 0:
                text += f" ({med / ref.summary()[s][1]:.2f}x)"
            if m in c.wrong_peers:
                text += "*"
            return f"{text:>{width}}"

        for c in self.cases:
            line = f"{c.label:<10}{c.num_objects:>10,}" + "".join(cell(c, m, stage) for m in methods)
            if broad:
                line += "   |       " + "".join(cell(c, m, "broad") for m in broad)
            lines.append(line)
        if any(c.wrong_peers for c in self.cases):
            lines.append("* the peer's answers were wrong in that case (see its check lines)")
        return "\n".join(lines)

    def plot(self, path: str) -> str | None:
        """Log-log ms per frame (median ``total``; broad phases dashed) against N; returns a note
        when matplotlib is missing (then nothing is written)."""
        try:
            from matplotlib.figure import Figure
        except ImportError as exc:
            return f"plot skipped: matplotlib is not installed ({exc})"
        fig = Figure(figsize=(8, 5.5), dpi=120)
        ax = fig.subplots()
        methods = list(dict.fromkeys(m for c in self.cases for m in c.times))
        labels = list(dict.fromkeys(c.label for c in self.cases))
        colours = {m: f"C{k % 10}" for k, m in enumerate(methods)}
        markers = {t: "osD^vP*X"[k % 8] for k, t in enumerate(labels)}
        series = {}
        for c in self.cases:
            for m, st in c.times.items():
                summary = st.summary()
                # Whole frames solid; broad phases dashed (this package's too, beside newton's).
                for stage, style in (("total", "-"), ("broad", "--")):
                    if stage not in summary or (stage == "broad" and m != self.reference and "total" in summary):
                        continue
                    key = (m, stage, c.label, style, stage in st.best_mode)
                    series.setdefault(key, []).append((c.num_objects, summary[stage][1]))
        for (m, stage, label, style, best_of), pts in series.items():
            pts.sort()
            what = ("frame" if stage == "total" else "broad phase") + (", best of eager/graph" if best_of else "")
            ax.plot([p[0] for p in pts], [p[1] for p in pts], style, color=colours[m], marker=markers[label],
                    markersize=4, label=f"{m} ({what}), triangles {label}")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("objects N")
        ax.set_ylabel("ms per frame (median)")
        device_name = getattr(self.device, "name", self.device)
        ax.set_title(f"warp_ccd scaling on {device_name} ({self.environment['date'][:10]})")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        full, _ = check_output_path(path, PLOT_EXTENSIONS, "plot")
        pending = PendingFile(full)
        fig.savefig(pending.temp_path)
        pending.commit()
        return None


# ---------------------------------------------------------------------------------------------
# Command line


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
        Exit status: 0 ``warp_ccd`` stands, 2 bad arguments, 3 a real mismatch charged to ``warp_ccd``.
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
        return 2
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
        return EXIT_MISMATCH
    wrong = sorted({p for c in report.cases for p in c.wrong_peers})
    if wrong:
        print(f"{prog}: {REFERENCE} stands; wrong answers from {', '.join(wrong)} (findings, marked * above)")
    return EXIT_OK
