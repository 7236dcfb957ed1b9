"""A frame of device work and its one counter read: launched from Python, or replayed as a CUDA graph.

A frame is: reset every counter of a :class:`~warp_ccd._src.runtime.buffers.CounterRead` (one memset), enqueue
the work (kernels that stop at device-side counters; launch sizes are capacities), copy the
counters into pinned host memory (one small kernel: the pinned block is mapped into the device's
address space), wait once. On CUDA the three are captured once in a graph (``wp.ScopedCapture``)
and replayed (``wp.capture_launch``): no Python per kernel, no allocation, no host read inside
the frame.

When a counter passed its buffer's capacity, the buffer grows (new storage), the frame runs again
eagerly (which also sizes any scratch that follows the buffers' capacities) and the next frame is
captured anew: a graph is captured only right after an eager run, and replayed only while none of
the frame's buffers got new storage since (:attr:`CounterRead.generation
<warp_ccd._src.runtime.buffers.CounterRead.generation>`, one integer to compare). Nothing is dropped.
"""

from __future__ import annotations

import time

import warp as wp

from .buffers import CounterRead

__all__ = ["MODES", "CountedFrame", "FrameCache", "frame_mode"]

MODES = ("eager", "graph")
"""How a device frame is launched: from Python each time, or as a replayed graph."""


def frame_mode(device, graph: bool | None) -> str:
    """The mode of a ``graph`` option: ``"graph"`` for True, ``"eager"`` for False, None: graph on CUDA.

    Raises:
        ValueError: ``graph`` is not a bool or None, or asks for a graph on a device without CUDA.
    """
    if graph is not None and not isinstance(graph, bool):
        raise ValueError(f"graph must be True, False or None, got {graph!r}")
    device = wp.get_device(device)
    if graph and not device.is_cuda:
        raise ValueError(f"graph: CUDA graphs need a CUDA device, got {device}")
    return "graph" if (device.is_cuda if graph is None else graph) else "eager"


class CountedFrame:
    """One frame of device work with its counter read, run until every buffer holds its items.

    Args:
        launch: enqueues the frame's work on the reader's device; reads nothing on the host and
            allocates nothing once it has run eagerly with the buffers' current storage (it is
            captured in graph mode). The counters of ``counter_read`` are reset before it.
        counter_read: the :class:`~warp_ccd._src.runtime.buffers.CounterRead` of every buffer the frame fills.
        mode: ``"eager"`` or ``"graph"`` (CUDA only).

    Attributes:
        host_ms: host time of the last :meth:`run_once` (or of all runs of the last :meth:`run`),
            in ms: Python's time launching and reading, without the time spent waiting.
        wait_ms: the time spent waiting for the device in the same runs, in ms.
        captures: graphs captured so far (a capture follows each growth of a buffer).
    """

    def __init__(self, launch, counter_read: CounterRead, mode: str = "eager"):
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        if mode == "graph" and not counter_read.device.is_cuda:
            raise ValueError(f"graph mode needs a CUDA device, got {counter_read.device}")
        self.launch = launch
        self.counter_read = counter_read
        self.device = counter_read.device
        self.mode = mode
        self.graph = None
        self.captures = 0
        self.host_ms = 0.0
        self.wait_ms = 0.0
        self._captured = None  # storage generation when the graph was captured
        self._eager = None  # storage generation of the last eager run

    def _enqueue(self) -> None:
        self.counter_read.reset()
        self.launch()
        self.counter_read.enqueue()

    def enqueue(self) -> None:
        """Enqueues the frame and its read: replays the graph, captures one (right after an eager run
        at the same storage generation) or launches eagerly."""
        generation = self.counter_read.generation  # a buffer's new storage makes the graph stale
        if self.mode == "graph":
            if self.graph is not None and self._captured == generation:
                wp.capture_launch(self.graph)
                return
            if self._eager == generation:
                with wp.ScopedCapture(device=self.device, force_module_load=False) as capture:
                    self._enqueue()
                self.graph, self._captured = capture.graph, generation
                self.captures += 1
                wp.capture_launch(self.graph)
                return
        self._enqueue()
        self._eager = generation

    def run_once(self) -> bool:
        """Enqueues the frame, waits, reads the counters; returns True when a buffer grew (the frame's
        results are incomplete: run it again). Sets :attr:`host_ms` and :attr:`wait_ms`."""
        start = time.perf_counter()
        self.enqueue()
        launched = time.perf_counter()
        wp.synchronize_device(self.device)
        waited = time.perf_counter()
        grew = self.counter_read.read()
        self.host_ms = (launched - start + time.perf_counter() - waited) * 1e3
        self.wait_ms = (waited - launched) * 1e3
        return grew

    def run(self) -> list[int]:
        """Runs the frame until every buffer held its items; returns the counts (:attr:`host_ms`,
        :attr:`wait_ms`: of all its runs)."""
        host = wait = 0.0
        while True:
            grew = self.run_once()
            host += self.host_ms
            wait += self.wait_ms
            if not grew:
                break
        self.host_ms, self.wait_ms = host, wait
        return self.counter_read.counts

    @property
    def counts(self) -> list[int]:
        """The counts of the last frame (zeros before the first)."""
        return self.counter_read.counts


class FrameCache:
    """A few :class:`CountedFrame` s over one counter read, by key (a caller's frame variants:
    the scene's step, the box arrays); a caller with ever new keys starts over past ``limit``.

    Args:
        counter_read: the :class:`~warp_ccd._src.runtime.buffers.CounterRead` every frame reads.
        mode: ``"eager"`` or ``"graph"``.
        limit: most frames kept.

    Attributes:
        frames: ``{key: CountedFrame}``.
    """

    def __init__(self, counter_read: CounterRead, mode: str, limit: int = 8):
        self.counter_read = counter_read
        self.mode = mode
        self.limit = limit
        self.frames = {}

    def get(self, key, launch) -> CountedFrame:
        """The frame of ``key``, made with ``launch`` (see :class:`CountedFrame`) the first time."""
        frame = self.frames.get(key)
        if frame is None:
            if len(self.frames) >= self.limit:
                self.frames.clear()
            frame = self.frames[key] = CountedFrame(launch, self.counter_read, self.mode)
        return frame
