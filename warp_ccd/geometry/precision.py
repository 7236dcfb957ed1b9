"""The two scene precisions and their Warp types.

A scene is float32 or float64: the type of its shape vertices, poses and world vertices, and of the
exact triangle test (object and node boxes stay float32, rounded outward). Kernels are written once
as Warp generics and their two variants declared with ``wp.overload`` over :data:`PRECISIONS`
(:func:`precision_overloads`), and the variant of the scene's precision is what is launched.

**Which precision a scene needs** (:func:`needed_precision`): a coordinate ``x`` is held to
within half a unit in the last place, at most ``|x| * 2**-24`` in float32 and ``|x| * 2**-53`` in
float64. With ``R`` the largest ``|coordinate|`` of the world vertices and ``s`` the scene's
typical triangle size (:func:`triangle_size`: the median longest edge of its triangles), a
precision is good enough while one unit in the last place at ``R``, ``R * 2**-23`` (float32) or
``R * 2**-52`` (float64), stays within :data:`RESOLUTION` ``= 1e-3`` of ``s``: float32 while
``R <= 8.4e3 * s``, float64 while ``R <= 4.5e12 * s``. Beyond that the exact test would decide
touching and crossing on rounding, not on the geometry. Coordinates beyond float32's range
(``3.4e38``) fit no scene at all: object and node boxes are float32 at both precisions.
"""

import numpy as np
import warp as wp

__all__ = ["PRECISIONS", "RESOLUTION", "PrecisionWarning", "coordinate_message", "needed_precision",
           "precision_overloads", "precision_types", "shape_radius", "triangle_size"]

RESOLUTION = 1e-3
"""One unit in the last place at the largest coordinate may be at most this fraction of the typical
triangle size (:func:`needed_precision`)."""
FLOAT32_STEP = 2.0**-23
"""float32's unit in the last place relative to the number (its machine epsilon; an upper bound)."""
FLOAT64_STEP = 2.0**-52
"""float64's unit in the last place relative to the number."""
FLOAT32_MAX = float(np.finfo(np.float32).max)
"""The largest float32 (``3.4e38``): boxes are float32, so no coordinate may exceed it."""


class PrecisionWarning(UserWarning):
    """A scene's coordinates are too far from the origin for float32 at its triangles' size, and it
    is checked in float64 instead."""

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


def needed_precision(max_coordinate: float, size: float) -> str | None:
    """The precision that resolves a scene's geometry (see the module docstring).

    Args:
        max_coordinate: ``R``, the largest ``|coordinate|`` of the world vertices (scene units).
        size: ``s``, the typical triangle size (scene units; 0 when every triangle is degenerate:
            then only float32's range is checked).

    Returns:
        ``"float32"``, ``"float64"`` when only float64 resolves it, or None when neither does
        (``R * 2**-52 > 1e-3 * s``, or ``R`` beyond float32's range).
    """
    r, s = float(max_coordinate), float(size)
    if not r <= FLOAT32_MAX:
        return None
    if s > 0.0 and r * FLOAT64_STEP > RESOLUTION * s:
        return None
    if s > 0.0 and r * FLOAT32_STEP > RESOLUTION * s:
        return "float64"
    return "float32"


def coordinate_message(max_coordinate: float, size: float, precision: str) -> str:
    """``"coordinates up to R are beyond <precision> at triangles of size s (its step there: u)"``,
    or beyond float32's range."""
    if not float(max_coordinate) <= FLOAT32_MAX:
        return f"coordinates up to {max_coordinate:.3g} are beyond float32's range ({FLOAT32_MAX:.3g}, which boxes use)"
    step = max_coordinate * (FLOAT64_STEP if precision == "float64" else FLOAT32_STEP)
    return (f"coordinates up to {max_coordinate:.3g} are beyond {precision} at triangles of size {size:.3g} "
            f"(its step there: {step:.2g})")


def shape_radius(vertices: np.ndarray, vertex_start: np.ndarray) -> np.ndarray:
    """``(S,)`` float64 largest distance of each shape's vertices from its origin (0 for a shape
    without vertices), from ``(V, 3)`` vertices and ``(S + 1,)`` offsets."""
    start = np.asarray(vertex_start, np.int64)
    radius = np.zeros(len(start) - 1)
    if len(vertices):
        norm = np.linalg.norm(np.asarray(vertices, np.float64), axis=1)
        has = start[1:] > start[:-1]  # a shape's segment ends where the next non-empty one starts
        radius[has] = np.maximum.reduceat(norm, start[:-1][has])
    return radius


SIZE_SAMPLE = 4096
"""Most triangles of one shape whose longest edges give its median (:func:`triangle_size`): a bigger
shape's are evenly spaced through it, so that a scene of big meshes costs its check little."""


def triangle_size(vertices: np.ndarray, triangles: np.ndarray, vertex_start: np.ndarray,
                  triangle_start: np.ndarray, object_shape: np.ndarray, object_scale=None) -> float:
    """The scene's typical triangle size: the median, over its objects' triangles, of each
    triangle's longest edge (each shape's median taken once, over at most :data:`SIZE_SAMPLE` of
    its triangles evenly spaced through it, times each object's scale).

    Triangles of zero size (every vertex the same point) count for nothing.

    Args:
        vertices: ``(V, 3)`` shape vertices; ``triangles``: ``(T, 3)`` shape-local indices.
        vertex_start, triangle_start: ``(S + 1,)`` offsets of each shape.
        object_shape: ``(N,)`` shape of each object.
        object_scale: ``(N,)`` uniform scale of each object (default 1).

    Returns:
        The size (scene units), 0.0 when no triangle has a size.
    """
    tri = np.asarray(triangles)
    tstart = np.asarray(triangle_start, np.int64)
    vstart = np.asarray(vertex_start, np.int64)
    inst = np.asarray(object_shape, np.int64)
    if not len(tri) or not inst.size:
        return 0.0
    tcount = np.diff(tstart)
    num_shapes = len(tcount)
    if tcount.max() > SIZE_SAMPLE:  # big shapes: triangles (j * m) // SAMPLE, j < SAMPLE, evenly spaced
        taken = np.minimum(tcount, SIZE_SAMPLE)
        owner = np.repeat(np.arange(num_shapes), taken)
        m = tcount[owner]
        j = np.arange(len(owner)) - (np.cumsum(taken) - taken)[owner]
        tri, tcount = tri[tstart[owner] + np.where(m > SIZE_SAMPLE, (j * m) // SIZE_SAMPLE, j)], taken
    else:
        owner = np.repeat(np.arange(num_shapes), tcount)
    v = np.asarray(vertices)
    longest = np.empty(len(tri))
    step = 1 << 18  # triangles a block: bounded temporaries for scenes of millions
    for lo in range(0, len(tri), step):
        corner = (tri[lo:lo + step] + vstart[owner[lo:lo + step], None]).T  # (3, t) vertex rows
        x, y, z = (v[corner, k].astype(np.float64, copy=False) for k in range(3))  # (3, t) each

        def squared(i: int, j: int) -> np.ndarray:  # |corner j - corner i|^2, summed x, y, z in turn
            return ((x[j] - x[i]) ** 2 + (y[j] - y[i]) ** 2) + (z[j] - z[i]) ** 2

        longest[lo:lo + step] = np.sqrt(np.maximum(np.maximum(squared(0, 1), squared(1, 2)), squared(2, 0)))
    keep = longest > 0.0
    values, owner = longest[keep], owner[keep]
    count = np.bincount(owner, minlength=num_shapes)
    # Each shape's median: the values sorted once, then their ranks grouped by shape by one sort of
    # the integers shape * K + rank (as a lexsort by shape, then size, orders them, at half its cost).
    order = np.argsort(values)
    key = np.sort(owner[order] * len(values) + np.arange(len(values)))
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    median = np.zeros(num_shapes)
    has = count > 0
    median[has] = values[order[key[first[has] + (count[has] - 1) // 2] % len(values)]]
    scale = np.ones(inst.size) if object_scale is None else np.asarray(object_scale, np.float64)
    size = median[inst] * scale
    weight = count[inst]
    use = (size > 0.0) & (weight > 0)
    if not use.any():
        return 0.0
    size, weight = size[use], weight[use]
    by_size = np.argsort(size)
    cum = np.cumsum(weight[by_size])
    return float(size[by_size][np.searchsorted(cum, 0.5 * cum[-1])])
