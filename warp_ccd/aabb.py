"""Axis-aligned bounding boxes of objects (the first stage of the seed design).

One thread per object takes the min/max of its world vertices, then pads the box by
``margin_rel`` times its diagonal, so that pairs the narrow phase calls touching (its tolerance is
relative to the triangles' size, at most the box diagonal) are never culled by the broad phase.
Cost O(V) work, O(max vertices per object) depth.
"""


from typing import Any

import warp as wp

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["BOUNDS_KERNELS", "InstanceBounds", "instance_bounds_kernel", "make_box_rounding", "vertex_bounds"]


@wp.func
def vertex_bounds(world_vertex: wp.array(dtype=Any), start: int, end: int):
    """Exact ``(lower, upper)`` of ``world_vertex[start:end]`` (``end > start``), in its own type."""
    lo = world_vertex[start]
    hi = lo
    for v in range(start + 1, end):
        p = world_vertex[v]
        lo = wp.min(lo, p)
        hi = wp.max(hi, p)
    return lo, hi


ULP_PAD = 2.4e-7
"""Relative outward padding (two float32 units in the last place) when float64 bounds become float32."""


def make_box_rounding(S, V3):
    """``(lower32, upper32)`` functions converting ``V3`` corners to float32 boxes, rounded outward."""
    if S == wp.float32:

        @wp.func
        def lower32(x: V3) -> wp.vec3:
            return x

        @wp.func
        def upper32(x: V3) -> wp.vec3:
            return x

    else:

        @wp.func
        def lower32(x: V3) -> wp.vec3:
            f = wp.vec3(x)
            pad = wp.vec3(wp.abs(f[0]), wp.abs(f[1]), wp.abs(f[2])) * ULP_PAD + wp.vec3(1.0e-30)
            return f - pad

        @wp.func
        def upper32(x: V3) -> wp.vec3:
            f = wp.vec3(x)
            pad = wp.vec3(wp.abs(f[0]), wp.abs(f[1]), wp.abs(f[2])) * ULP_PAD + wp.vec3(1.0e-30)
            return f + pad

    return lower32, upper32


def _make_bounds_kernel(S, V3):
    lower32, upper32 = make_box_rounding(S, V3)

    @wp.kernel
    def instance_bounds_kernel(
        world_vertex: wp.array[V3],
        instance_vertex_start: wp.array[wp.int32],
        margin_rel: S,
        # Outputs
        instance_lower: wp.array[wp.vec3],
        instance_upper: wp.array[wp.vec3],
    ):
        """One thread per object: padded AABB of its world vertices (float32, rounded outward)."""
        i = wp.tid()
        lo, hi = vertex_bounds(world_vertex, instance_vertex_start[i], instance_vertex_start[i + 1])
        pad = margin_rel * wp.length(hi - lo)
        m = V3(pad, pad, pad)
        instance_lower[i] = lower32(lo - m)
        instance_upper[i] = upper32(hi + m)

    return instance_bounds_kernel


BOUNDS_KERNELS = {"float32": _make_bounds_kernel(wp.float32, wp.vec3), "float64": _make_bounds_kernel(wp.float64, wp.vec3d)}
"""Object-box kernels by scene precision."""

instance_bounds_kernel = BOUNDS_KERNELS["float32"]


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
            BOUNDS_KERNELS[scene.precision],
            dim=self.lower.shape[0],
            inputs=[scene.world_vertex, scene.instance_vertex_start, scene.types.scalar(self.margin_rel)],
            outputs=[self.lower, self.upper],
            device=self.device,
        )
