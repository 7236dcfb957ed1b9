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

from ..runtime.options import PRECISIONS, check_option

__all__ = ["PRECISIONS", "RESOLUTION", "PrecisionWarning", "coordinate_limit", "coordinate_message", "needed_precision",
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

"""Scene precisions: the type of shape vertices, poses and world vertices (boxes stay float32)."""


def precision_types(precision: str) -> tuple:
    """``(scalar, vec3, quat, transform)`` Warp types of a scene precision.

    Raises:
        ValueError: ``precision`` is not ``"float32"`` or ``"float64"``.
    """
    if check_option("precision", precision) == "float64":
        return wp.float64, wp.vec3d, wp.quatd, wp.transformd
    return wp.float32, wp.vec3, wp.quat, wp.transform


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
    r = float(max_coordinate)
    for precision in PRECISIONS:
        if r <= coordinate_limit(size, precision):
            return precision
    return None


def coordinate_limit(size: float, precision: str) -> float:
    """The largest ``|coordinate|`` that ``precision`` resolves at triangles of ``size`` (the rule of
    :func:`needed_precision`): ``1e-3 * s / 2**-23`` in float32, ``1e-3 * s / 2**-52`` in float64 (scaling
    by a power of two is exact, so ``R <= limit`` is ``R * step <= 1e-3 * s``), never beyond float32's range.

    Args:
        size: ``s``, the typical triangle size (scene units; 0: only float32's range is checked).
        precision: ``"float32"`` or ``"float64"``.

    Returns:
        The limit (scene units).
    """
    s = float(size)
    if not s > 0.0:
        return FLOAT32_MAX
    step = FLOAT64_STEP if precision == "float64" else FLOAT32_STEP
    return min(FLOAT32_MAX, RESOLUTION * s / step)


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
    without vertices), from ``(V, 3)`` vertices and ``(S + 1,)`` offsets.

    Each distance is ``np.linalg.norm`` of the vertex in float64, taken only for the few vertices
    whose squared distance lies within ``2**-40`` of its shape's largest: summed in any order, the
    squares differ by a few units in the last place (``2**-51``), so no other vertex can have the
    largest norm, and the maximum is that of the norm of every vertex, bit for bit.
    """
    start = np.asarray(vertex_start, np.int64)
    radius = np.zeros(len(start) - 1)
    v = np.asarray(vertices)
    if not len(v):
        return radius
    has = np.flatnonzero(start[1:] > start[:-1])  # a shape's segment ends where the next non-empty one starts
    if not len(has):
        return radius
    first = start[:-1][has]
    x, y, z = (v[:, k].astype(np.float64) for k in range(3))
    square = (x * x + y * y) + z * z
    top = np.maximum.reduceat(square, first)
    low = top - (top * 2.0**-40 + 2.0**-1070)  # NaN for an infinite top: then every vertex of the shape
    near = first[0] + np.flatnonzero(~(square[first[0]:] < np.repeat(low, np.diff(first, append=len(v)))))
    segment = np.searchsorted(first, near, side="right") - 1
    np.maximum.at(radius, has[segment], np.linalg.norm(np.asarray(v[near], np.float64), axis=1))
    return radius


SIZE_SAMPLE = 4096
"""Most triangles of one shape whose longest edges give its median (:func:`triangle_size`): a bigger
shape's are evenly spaced through it, so that a scene of big meshes costs its check little."""


def _longest_edges(v: np.ndarray, corner: np.ndarray) -> np.ndarray:
    """``(t,)`` float64 longest edge of each triangle of ``(3, t)`` vertex rows ``corner`` of ``v``:
    each squared edge summed ``(dx**2 + dy**2) + dz**2`` in float64, one square root of the largest."""
    p = v.take(corner, axis=0).astype(np.float64, copy=False)  # (corner, t, xyz), gathered in the vertices' type
    squared = np.empty((3, corner.shape[1]))
    d = np.empty_like(squared)
    for k in range(3):
        x = p[:, :, k]
        np.subtract(x[1], x[0], out=d[0])  # edges 0 -> 1, 1 -> 2, 2 -> 0
        np.subtract(x[2], x[1], out=d[1])
        np.subtract(x[0], x[2], out=d[2])
        d *= d
        if k:
            squared += d
        else:
            squared, d = d, squared
    return np.sqrt(np.maximum(np.maximum(squared[0], squared[1]), squared[2]))


def _segment_medians(values: np.ndarray, count: np.ndarray) -> np.ndarray:
    """``(S,)`` lower median of each of ``S`` consecutive segments of ``values`` (``count`` long; 0
    for an empty one): the value of rank ``(c - 1) // 2`` in its segment.

    Segments of ``2**(e-1)`` to ``2**e - 1`` values share one ``(k, w)`` table (``w`` the longest),
    each padded by ``-inf`` before and ``+inf`` after its values so that its median lands in the
    same column ``(w - 1) // 2`` of every row, found by one ``np.partition``: one selection per
    power of two, no sort.
    """
    median = np.zeros(len(count))
    first = np.cumsum(count) - count
    padded = np.concatenate([values, [-np.inf, np.inf]])  # padding at len(values) and len(values) + 1
    width_class = np.frexp(count)[1]  # e of 2**(e-1) <= count < 2**e, 0 for an empty segment
    for e in np.unique(width_class[width_class > 0]).tolist():
        rows = np.flatnonzero(width_class == e)
        c = count[rows]
        w = int(c.max())
        k = (w - 1) // 2
        index = first[rows, None] + np.arange(w)
        if not (c == w).all():
            before = k - (c - 1) // 2  # -inf padding of each row: rank (c - 1) // 2 of its values lands at k
            col = np.arange(w) - before[:, None]  # position in the row's segment
            index = np.where(col < 0, len(values),
                             np.where(col >= c[:, None], len(values) + 1, index - before[:, None]))
        table = padded.take(index)
        table.partition(k, axis=1)
        median[rows] = table[:, k]
    return median


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
    taken = np.minimum(tcount, SIZE_SAMPLE)
    vbase = np.repeat(vstart[:-1], taken)  # each sampled triangle's first vertex row
    rows = None  # every triangle
    if tcount.max() > SIZE_SAMPLE:  # big shapes: triangles (j * m) // SAMPLE, j < SAMPLE, evenly spaced
        j = np.arange(len(vbase)) - np.repeat(np.cumsum(taken) - taken, taken)
        m = np.repeat(np.where(tcount > SIZE_SAMPLE, tcount, SIZE_SAMPLE), taken)  # SAMPLE: j itself
        rows = np.repeat(tstart[:-1], taken) + (j * m) // SIZE_SAMPLE
    v = np.asarray(vertices)
    longest = np.empty(len(vbase))
    step = 1 << 14  # triangles a block: temporaries that stay in the cache
    for lo in range(0, len(vbase), step):
        corner = tri[lo:lo + step] if rows is None else tri.take(rows[lo:lo + step], axis=0)
        longest[lo:lo + step] = _longest_edges(v, np.add(corner.T, vbase[lo:lo + step], order="C"))
    keep = longest > 0.0
    kept = np.concatenate([[0], np.cumsum(keep)])
    ends = np.cumsum(taken)
    count = kept[ends] - kept[ends - taken]
    median = _segment_medians(longest[keep], count)
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
