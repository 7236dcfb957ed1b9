"""The scaling benchmark's methods, run on one scene frame by frame, and its cases.

:func:`run_case` builds the scaling scene of one ``(triangles, N)``, moves it and runs every method
on the same world vertices each frame, times them (:mod:`warp_ccd._src.bench.timing`), checks what the
peers find against this package (:mod:`warp_ccd._src.bench.compare`) and measures memory
(:mod:`warp_ccd._src.bench.memory`); :mod:`warp_ccd._src.bench.scaling` describes the stages each method
reports.

* :class:`PipelineMethod`: this package's :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline`, per stage and
  as whole frames, eager and (on CUDA) as a graph.
* :class:`HostPeerMethod`: a host peer (python-fcl), stage by stage.
* :class:`DevicePeerMethod`: a device peer (Warp's built-in pipeline) at its best, in every mode.
* :class:`BroadPhaseMethod`: a broad phase alone (newton's) on the boxes this pipeline saw.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from ..broadphase.sap import find_pairs, make_broad_phase
from ..pipeline.pipeline import CollisionPipeline
from ..runtime.buffers import GrowableBuffer
from ..runtime.frame import MODES
from ..scene.scene import Scene
from .compare import PairCheck, box_overlap_truth, compare_exact, compare_triangle_pairs
from .memory import measure_pipeline_memory
from .meshes import parse_triangles
from .peers import FclPipeline, NewtonBroadPhaseSAP, PeerUnavailable, WarpMeshPipeline
from .timing import ModeFrames, StageTimes, run_stages, synced_ms

__all__ = [
    "DT",
    "PEERS",
    "REFERENCE",
    "BroadPhaseMethod",
    "CaseResult",
    "DevicePeerMethod",
    "HostPeerMethod",
    "PipelineMethod",
    "device_modes",
    "run_case",
]

PEERS = ("builtin", "fcl", "nxn", "newton")
"""Peer names accepted by ``--peers``."""

REFERENCE = "warp_ccd"
"""Name of this package's pipeline in rows and checks."""

DT = 1.0 / 60.0
"""Time step of a frame, s."""

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
        **options: :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` options (e.g. ``broad_phase``).
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
    """A host peer of :mod:`warp_ccd._src.bench.peers` (python-fcl), timed stage by stage (:func:`run_stages`)."""

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
    """A device peer of :mod:`warp_ccd._src.bench.peers` at its best: each frame is its ``launch()`` and one
    read of its counters into pinned memory (:class:`~warp_ccd._src.runtime.frame.CountedFrame`), run in
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
        """The exact overlap test of the boxes this method saw
        (:func:`~warp_ccd._src.bench.compare.box_overlap_truth`)."""
        return box_overlap_truth(*self.source.object_boxes())

    def reference_box_pairs(self) -> np.ndarray:
        """``(K, 2)`` pairs of this package's :class:`~warp_ccd._src.broadphase.sap.BroadPhaseSAP` on the same boxes."""
        lower, upper = self.source.object_boxes()
        pairs = GrowableBuffer(wp.vec2i, self.pairs.capacity, self.device, "reference box pairs")
        count = find_pairs(make_broad_phase("sap", device=self.device), lower, upper, pairs)
        return pairs.numpy(count).reshape(-1, 2)

    def counts(self) -> tuple:
        """``(box pairs, None)`` of the last frame."""
        return self.num_pairs, None


# ---------------------------------------------------------------------------------------------
# One case: one scene, all methods


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
                methods.append(PipelineMethod("warp_ccd_nxn", scene, broad_phase="all_pairs"))
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
