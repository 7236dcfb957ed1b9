"""Timing a frame the way a careful Warp user runs it, and summarising the times (the scaling benchmark's).

* :func:`synced_ms`: wall-clock ms of a call, the device synchronised before and after.
* :class:`~warp_ccd._src.runtime.frame.CountedFrame` (the library's): one frame of device work followed by one
  small kernel copying its counters into pinned host memory and one wait, launched eagerly from
  Python or replayed as a captured graph. A counter past its buffer's capacity grows the buffer,
  and the frame is captured again and rerun: nothing is dropped.
* :class:`ModeFrames`: the same frame in several modes, run in turn (one counter block).
* :func:`run_stages`: a host-side peer's stages in order, each timed.
* :class:`StageTimes`: ms per stage over the timed frames; min and median, and for a method
  timed both eagerly and as a graph, the better of the two under the plain stage name.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from ..runtime.buffers import CounterRead
from ..runtime.frame import CountedFrame

__all__ = ["ModeFrames", "StageTimes", "run_stages", "synced_ms"]


def synced_ms(fn, device) -> float:
    """Wall-clock ms of ``fn()``, with the device synchronised before and after."""
    wp.synchronize_device(device)
    start = time.perf_counter()
    fn()
    wp.synchronize_device(device)
    return (time.perf_counter() - start) * 1e3


class ModeFrames:
    """The same frame in each of several modes (a :class:`CountedFrame` each, all reading one
    :class:`~warp_ccd._src.runtime.buffers.CounterRead`), run in turn.

    Args:
        launch: enqueues the frame's work (see :class:`CountedFrame`; the counters are reset before it).
        buffers: the :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` s whose counters the frame reads.
        device: Warp device.
        modes: the modes (:data:`~warp_ccd._src.runtime.frame.MODES`, or a subset).
    """

    def __init__(self, launch, buffers: list, device, modes):
        self.device = wp.get_device(device)
        counter_read = CounterRead(buffers, self.device)
        self.frames = {m: CountedFrame(launch, counter_read, m) for m in modes}

    @classmethod
    def broad_phase(cls, broad, boxes, pairs, device, modes) -> "ModeFrames":
        """A broad phase's frame: ``broad.launch(*boxes(), pairs)``; ``boxes()`` gives the
        ``(lower, upper)`` arrays. Read: ``pairs`` and the broad phase's ``counters``."""

        def launch():
            broad.launch(*boxes(), pairs)

        return cls(launch, [pairs, *broad.counters], device, modes)

    def run(self, stage: str) -> dict:
        """One frame per mode, each timed with :func:`synced_ms`.

        Returns:
            ``{stage: ms}`` for a single mode, else ``{f"{stage}_{mode}": ms}`` per mode.
        """
        if len(self.frames) == 1:
            (frame,) = self.frames.values()
            return {stage: synced_ms(frame.run, self.device)}
        return {f"{stage}_{mode}": synced_ms(frame.run, self.device) for mode, frame in self.frames.items()}

    @property
    def counts(self) -> list[int]:
        """The counts of the last frame (every mode finds the same)."""
        return next(iter(self.frames.values())).counts


def run_stages(stages: list, finish, device) -> dict:
    """Runs a host-side peer's frame: its stages in order, each synchronised and timed, then ``finish()``.

    Args:
        stages: ``(name, callable)`` pairs.
        finish: returns True when a buffer grew (the frame reruns).
        device: Warp device to synchronise.

    Returns:
        ms per stage name, plus ``detect`` (stages and ``finish`` together), of the last run.
    """
    while True:
        times = {}
        wp.synchronize_device(device)
        start = time.perf_counter()
        t = start
        for name, fn in stages:
            fn()
            wp.synchronize_device(device)
            now = time.perf_counter()
            times[name] = (now - t) * 1e3
            t = now
        rerun = finish()
        times["detect"] = (time.perf_counter() - start) * 1e3
        if not rerun:
            return times


@dataclass
class StageTimes:
    """ms per stage over the timed frames of one method.

    A method timed in both :data:`~warp_ccd._src.runtime.frame.MODES` records ``<stage>_eager`` and ``<stage>_graph``;
    :meth:`summary` then also gives ``<stage>``, the mode with the lower median (its min and median
    together), and :attr:`best_mode` says which (a stage timed eagerly only is ``<stage>`` too).
    """

    ms: dict = field(default_factory=dict)
    best_mode: dict = field(default_factory=dict)

    def add(self, times: dict) -> None:
        """Appends one frame's ``{stage: ms}``."""
        for stage, value in times.items():
            self.ms.setdefault(stage, []).append(float(value))

    def summary(self) -> dict:
        """``{stage: (ms_min, ms_median)}``, best-of-modes stages included."""
        out = {s: (float(np.min(v)), float(np.median(v))) for s, v in self.ms.items()}
        for stage in list(out):
            if not stage.endswith("_eager") or stage[: -len("_eager")] in self.ms:
                continue
            base = stage[: -len("_eager")]
            graph = out.get(f"{base}_graph")
            mode = "graph" if graph is not None and graph[1] < out[stage][1] else "eager"
            out[base] = out[f"{base}_{mode}"]
            if graph is not None:
                self.best_mode[base] = mode
        return out

    def has(self, stage: str) -> bool:
        """Whether ``stage`` was timed (in any mode)."""
        return stage in self.ms or f"{stage}_eager" in self.ms

    def frames(self, stage: str) -> int:
        """Timed frames behind ``stage`` (a best-of-modes stage: its eager one's)."""
        return len(self.ms.get(stage) or self.ms.get(f"{stage}_eager", []))
