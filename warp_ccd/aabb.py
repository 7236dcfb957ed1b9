"""Axis-aligned bounding boxes of objects (the first stage of the seed design).

One thread per object takes the min/max of its world vertices, then pads the box by
``margin_rel`` times its diagonal, so that pairs the narrow phase calls touching (its tolerance is
relative to the triangles' size, at most the box diagonal) are never culled by the broad phase.
Cost O(V) work, O(max vertices per object) depth.
"""

from __future__ import annotations

import warp as wp

__all__ = ["InstanceBounds", "instance_bounds_kernel", "vertex_bounds"]


@wp.func
def vertex_bounds(world_vertex: wp.array[wp.vec3], start: int, end: int):
    """Exact ``(lower, upper)`` of ``world_vertex[start:end]`` (``end > start``)."""
    lo = world_vertex[start]
    hi = lo
    for v in range(start + 1, end):
        p = world_vertex[v]
        lo = wp.min(lo, p)
        hi = wp.max(hi, p)
    return lo, hi


@wp.kernel
def instance_bounds_kernel(
    world_vertex: wp.array[wp.vec3],
    instance_vertex_start: wp.array[wp.int32],
    margin_rel: float,
    # Outputs
    instance_lower: wp.array[wp.vec3],
    instance_upper: wp.array[wp.vec3],
):
    """One thread per object: padded AABB of its world vertices."""
    i = wp.tid()
    lo, hi = vertex_bounds(world_vertex, instance_vertex_start[i], instance_vertex_start[i + 1])
    pad = margin_rel * wp.length(hi - lo)
    m = wp.vec3(pad, pad, pad)
    instance_lower[i] = lo - m
    instance_upper[i] = hi + m


class InstanceBounds:
    """Owns ``lower`` / ``upper`` ``(N,)`` ``wp.vec3`` arrays of object boxes (scene units).

    Args:
        num_objects: ``N``.
        device: Warp device.
        margin_rel: padding relative to each box's diagonal (the narrow phase's tolerance).
    """

    def __init__(self, num_objects: int, *, device=None, margin_rel: float = 0.0):
        self.device = wp.get_device(device)
        self.margin_rel = float(margin_rel)
        self.lower = wp.zeros(num_objects, dtype=wp.vec3, device=self.device)
        self.upper = wp.zeros(num_objects, dtype=wp.vec3, device=self.device)

    def launch(self, scene) -> None:
        """Computes the boxes from ``scene.world_vertex`` and ``scene.instance_vertex_start``."""
        if self.lower.shape[0] == 0:
            return
        wp.launch(
            instance_bounds_kernel,
            dim=self.lower.shape[0],
            inputs=[scene.world_vertex, scene.instance_vertex_start, self.margin_rel],
            outputs=[self.lower, self.upper],
            device=self.device,
        )
