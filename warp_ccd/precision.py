"""The two scene precisions and their Warp types.

A scene is float32 or float64: the type of its shape vertices, poses and world vertices, and of the
exact triangle test (object and node boxes stay float32, rounded outward). Kernels are written once
as Warp generics and their two variants declared with ``wp.overload`` over :data:`PRECISIONS`
(:func:`precision_overloads`), and the variant of the scene's precision is what is launched.
"""

import warp as wp

__all__ = ["PRECISIONS", "precision_overloads", "precision_types"]

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


def precision_overloads(kernel, arg_types) -> dict:
    """Declares a generic kernel's variant for each precision.

    Args:
        kernel: the generic kernel.
        arg_types: ``arg_types(scalar, vec3, quat, transform)`` -> ``{argument: Warp type}`` of one
            precision (:func:`precision_types` gives the four).

    Returns:
        ``{precision: variant}``. Launch the variant itself: given the generic kernel, every
        launch matches its arguments' types against the overloads first (tens of microseconds
        of host time a launch, more on the first).
    """
    return {p: wp.overload(kernel, arg_types(*precision_types(p))) for p in PRECISIONS}
