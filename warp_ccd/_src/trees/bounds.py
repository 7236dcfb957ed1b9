"""Object boxes: the refit stage of the all-pairs mid phase.

:class:`ObjectBounds`: one thread per object takes the min/max of its world vertices, then pads
the box by ``margin_rel`` times its diagonal, so that pairs the narrow phase calls touching (its
tolerance is relative to the triangles' size, at most the box diagonal) are never culled by the
broad phase. Cost O(V) work, O(max vertices per object) depth. A continuous frame's boxes are
swept: the box of an object's vertices at both ends of its motion, padded by a distance too. With
a clearance every box is padded by half of it (:func:`pad_boxes`, which the trees' object boxes use
too).
"""

from typing import Any

import warp as wp

from ..geometry.box import box_lower32, box_upper32, vertex_bounds
from ..geometry.precision import precision_overloads
from ..runtime.aliases import DeviceLike
from ..scene.scene import Scene

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["ObjectBounds", "pad_boxes"]


@wp.kernel
def _object_bounds_kernel(
    world_vertex: wp.array[Any],
    object_vertex_start: wp.array[wp.int32],
    margin_rel: Any,
    # Outputs
    object_lower: wp.array[wp.vec3],
    object_upper: wp.array[wp.vec3],
):
    """One thread per object: padded AABB of its world vertices (float32, rounded outward)."""
    i = wp.tid()
    lo, hi = vertex_bounds(world_vertex, object_vertex_start[i], object_vertex_start[i + 1])
    pad = margin_rel * wp.length(hi - lo)
    m = type(lo)(pad, pad, pad)
    object_lower[i] = box_lower32(lo - m)
    object_upper[i] = box_upper32(hi + m)


@wp.kernel
def _swept_bounds_kernel(
    world_vertex: wp.array[Any],
    world_vertex_start: wp.array[Any],
    object_vertex_start: wp.array[wp.int32],
    margin_rel: Any,
    pad_abs: wp.float64,
    # Outputs
    object_lower: wp.array[wp.vec3],
    object_upper: wp.array[wp.vec3],
):
    """One thread per object: the AABB of its vertices at both ends of a linear motion (it holds the
    object all along), padded by ``margin_rel`` times its diagonal plus ``pad_abs`` in float64,
    rounded outward."""
    i = wp.tid()
    lo, hi = vertex_bounds(world_vertex, object_vertex_start[i], object_vertex_start[i + 1])
    lo0, hi0 = vertex_bounds(world_vertex_start, object_vertex_start[i], object_vertex_start[i + 1])
    lo = wp.min(lo, lo0)
    hi = wp.max(hi, hi0)
    pad = margin_rel * wp.length(hi - lo)
    m = type(lo)(pad, pad, pad)
    object_lower[i] = box_lower32(wp.vec3d(lo - m) - wp.vec3d(pad_abs))
    object_upper[i] = box_upper32(wp.vec3d(hi + m) + wp.vec3d(pad_abs))


@wp.kernel
def _pad_boxes_kernel(
    pad: wp.float64,
    # Outputs
    lower: wp.array[wp.vec3],
    upper: wp.array[wp.vec3],
):
    """One thread per box: every side moved out by ``pad`` (scene units), in float64, rounded outward."""
    i = wp.tid()
    lower[i] = box_lower32(wp.vec3d(lower[i]) - wp.vec3d(pad, pad, pad))
    upper[i] = box_upper32(wp.vec3d(upper[i]) + wp.vec3d(pad, pad, pad))


def pad_boxes(lower: wp.array, upper: wp.array, pad: float) -> None:
    """Moves every side of the boxes ``lower`` / ``upper`` (``(N,)`` ``wp.vec3``) out by ``pad`` (scene
    units, rounded outward): half a clearance on each object's box, so that objects within the
    clearance have overlapping boxes. Nothing when ``pad`` is 0."""
    if pad > 0.0 and lower.shape[0]:
        wp.launch(_pad_boxes_kernel, dim=lower.shape[0], inputs=[wp.float64(pad)], outputs=[lower, upper],
                  device=lower.device)


_OBJECT_BOUNDS = precision_overloads(_object_bounds_kernel,
                                       lambda s, v, q, t: {"world_vertex": wp.array[v], "margin_rel": s})
_SWEPT_BOUNDS = precision_overloads(_swept_bounds_kernel, lambda s, v, q, t: {
    "world_vertex": wp.array[v], "world_vertex_start": wp.array[v], "margin_rel": s})


class ObjectBounds:
    """Owns ``lower`` / ``upper`` ``(N,)`` ``wp.vec3`` arrays of object boxes (scene units).

    Args:
        num_objects: ``N``.
        device: Warp device.
        margin_rel: padding relative to each box's diagonal (the narrow phase's tolerance).
        pad_abs: padding in scene units of a swept box (:meth:`refit` with ``world_vertex_start``:
            a continuous test's least distance plus its tolerance).
        box_pad: padding in scene units of every box (half a clearance: :func:`pad_boxes`).
    """

    def __init__(self, num_objects: int, *, device: DeviceLike = None, margin_rel: float = 0.0, pad_abs: float = 0.0,
                 box_pad: float = 0.0) -> None:
        self.device = wp.get_device(device)
        self.margin_rel = float(margin_rel)
        self.pad_abs = float(pad_abs)
        self.box_pad = float(box_pad)
        self.lower = wp.zeros(num_objects, dtype=wp.vec3, device=self.device)
        self.upper = wp.zeros(num_objects, dtype=wp.vec3, device=self.device)

    @property
    def counters(self) -> list:
        """Buffers with counters that :meth:`refit` writes: none (its arrays have fixed sizes)."""
        return []

    def refit(self, scene: Scene, world_vertex_start: wp.array | None = None) -> None:
        """Computes the boxes from ``scene.world_vertex`` and ``scene.object_vertex_start``; with
        ``world_vertex_start`` (``(V,)``, the scene's vector type), the boxes swept over the linear
        motion from it to ``scene.world_vertex``, padded by :attr:`pad_abs` too."""
        if self.lower.shape[0] == 0:
            return
        if world_vertex_start is not None:
            wp.launch(_SWEPT_BOUNDS[scene.precision], dim=self.lower.shape[0],
                      inputs=[scene.world_vertex, world_vertex_start, scene.object_vertex_start,
                              scene.scalar_type(self.margin_rel), wp.float64(self.pad_abs)],
                      outputs=[self.lower, self.upper], device=self.device)
        else:
            wp.launch(
                _OBJECT_BOUNDS[scene.precision],
                dim=self.lower.shape[0],
                inputs=[scene.world_vertex, scene.object_vertex_start, scene.scalar_type(self.margin_rel)],
                outputs=[self.lower, self.upper],
                device=self.device,
            )
        pad_boxes(self.lower, self.upper, self.box_pad)
