"""The lab's timing helpers, beside the scaling benchmark's (:mod:`warp_ccd._src.bench.timing`: ``synced_ms``,
``ModeFrames``, ``StageTimes``, which the lab imports from there).

* :func:`ms_stats`: a row's numbers, min and median of timings in ms.
* :func:`detect_frames`: a pipeline's ``detect(advance=dt)`` frames, each timed by ``synced_ms``, with their
  host time.
"""

from __future__ import annotations

import numpy as np

from warp_ccd._src.bench.timing import synced_ms

__all__ = ["detect_frames", "ms_stats"]


def ms_stats(values) -> dict:
    """``{"ms_min", "ms_median"}`` of timings in ms (a benchmark row's numbers)."""
    return {"ms_min": float(np.min(values)), "ms_median": float(np.median(values))}


def detect_frames(pipe, count: int, dt: float) -> tuple[list[float], list[float]]:
    """``count`` frames of ``pipe.detect(advance=dt)``, each timed by
    :func:`~warp_ccd._src.bench.timing.synced_ms`.

    Args:
        pipe: a :class:`~warp_ccd.CollisionPipeline`, warmed up.
        count: frames to time.
        dt: s the scene advances each frame.

    Returns:
        ``(wall, host)``: ms per frame, wall-clock and Python's own (``FrameResult.host_ms``).
    """
    wall, host = [], []
    for _ in range(count):
        result = []
        wall.append(synced_ms(lambda: result.append(pipe.detect(advance=dt)), pipe.device))
        host.append(result[0].host_ms)
    return wall, host
