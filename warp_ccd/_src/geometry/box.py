"""Axis-aligned bounding boxes: the box helpers every stage shares, inside kernels.

Boxes are float32 ``wp.vec3`` corners at every scene precision: :func:`box_lower32` /
:func:`box_upper32` round a corner outward, :func:`boxes_overlap` tests two closed boxes.
"""


from typing import Any

import warp as wp

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["BOX_EMPTY", "box_lower32", "box_upper32", "boxes_overlap", "vertex_bounds"]


@wp.func
def boxes_overlap(lo_a: wp.vec3, hi_a: wp.vec3, lo_b: wp.vec3, hi_b: wp.vec3) -> bool:
    """Closed boxes: True when they overlap or touch on every axis."""
    return (
        lo_a[0] <= hi_b[0]
        and lo_b[0] <= hi_a[0]
        and lo_a[1] <= hi_b[1]
        and lo_b[1] <= hi_a[1]
        and lo_a[2] <= hi_b[2]
        and lo_b[2] <= hi_a[2]
    )


@wp.func
def vertex_bounds(world_vertex: wp.array[Any], start: int, end: int):
    """Exact ``(lower, upper)`` of ``world_vertex[start:end]`` (``end > start``), in its own type."""
    lo = world_vertex[start]
    hi = lo
    for v in range(start + 1, end):
        p = world_vertex[v]
        lo = wp.min(lo, p)
        hi = wp.max(hi, p)
    return lo, hi


BOX_EMPTY = wp.constant(1.0e30)
"""An empty box's corners, ``(BOX_EMPTY, ...)`` below and ``(-BOX_EMPTY, ...)`` above: any point grows it."""

ULP_PAD = wp.constant(2.4e-7)
"""Relative outward padding (two float32 units in the last place) when float64 bounds become float32."""

BOX_PAD_MIN = wp.constant(1.0e-30)
"""Absolute outward padding of a float64 corner rounded to float32 (for corners at zero)."""


@wp.func
def _rounding_pad(f: wp.vec3) -> wp.vec3:
    """Outward padding of a float32 corner ``f`` rounded from float64: two units in the last place."""
    return wp.vec3(wp.abs(f[0]), wp.abs(f[1]), wp.abs(f[2])) * ULP_PAD + wp.vec3(BOX_PAD_MIN)


# A box corner as float32 (boxes are float32 at every precision), rounded outward: a float32
# corner as it is, a float64 one padded by two units in the last place (one overload each).
@wp.func
def box_lower32(x: wp.vec3) -> wp.vec3:
    """Lower corner ``x`` as a float32 corner at or below it."""
    return x


@wp.func
def box_lower32(x: wp.vec3d) -> wp.vec3:  # noqa: F811 (the float64 overload)
    """Lower corner ``x`` as a float32 corner at or below it."""
    f = wp.vec3(x)
    return f - _rounding_pad(f)


@wp.func
def box_upper32(x: wp.vec3) -> wp.vec3:
    """Upper corner ``x`` as a float32 corner at or above it."""
    return x


@wp.func
def box_upper32(x: wp.vec3d) -> wp.vec3:  # noqa: F811 (the float64 overload)
    """Upper corner ``x`` as a float32 corner at or above it."""
    f = wp.vec3(x)
    return f + _rounding_pad(f)
