"""Memory of this package's pipeline: the arrays it holds and the peak of Warp's allocations.

:func:`measure_pipeline_memory` is the scaling benchmark's memory measurement (one per case);
:func:`array_bytes` counts the distinct ``wp.array`` buffers an object holds.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..pipeline.pipeline import CollisionPipeline
from ..scene.scene import Scene

__all__ = ["array_bytes", "measure_pipeline_memory"]


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
    """Memory of a fresh default :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` over ``frames`` frames.

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
