"""The two scene precisions and their Warp types.

A scene is float32 or float64: the type of its shape vertices, poses and world vertices, and of the
exact triangle test (object and node boxes stay float32, rounded outward). Kernels are written once
as Warp generics and their two variants declared with ``wp.overload`` over :data:`PRECISIONS`.
"""

import warp as wp

__all__ = ["PRECISIONS", "precision_types"]

PRECISIONS = ("float32", "float64")
"""Scene precisions: the type of shape vertices, poses and world vertices (boxes stay float32)."""


def precision_types(precision: str) -> tuple:
    """``(scalar, vec3, quat, transform)`` Warp types of a scene precision.

    Raises:
        ValueError: ``precision`` is not ``"float32"`` or ``"float64"``.
    """
    if precision == "float64":
        return wp.float64, wp.vec3d, wp.quatd, wp.transformd
    if precision == "float32":
        return wp.float32, wp.vec3, wp.quat, wp.transform
    raise ValueError(f"precision must be 'float32' or 'float64', got {precision!r}")
