"""Batches of continuous-collision queries: :func:`ccd_queries` (numpy or Warp arrays in, numpy out)
and the kernels it launches, :func:`run_queries`' two passes.

A GPU runs a warp as long as its longest lane. Most queries of a frame are ruled out by their
filters (the coplanarity cubic, the whole box: :func:`~warp_ccd._src.geometry.ccd.query_excluded`) and the
rest search tens to hundreds of steps, so the first pass runs every query's filters and lists those
they leave; the second searches those, packed one a thread. The answers are those of one pass (the
filters are the first steps of the search, which is deterministic).
The device functions are in :mod:`warp_ccd._src.geometry.ccd`.
"""

from typing import Any

import numpy as np
import warp as wp

from ..geometry.ccd import CCD_KINDS, CCD_MAX_ITERATIONS, CCD_TOLERANCE, NO_HIT, _points, primitive_toi, query_excluded
from ..geometry.precision import FLOAT32_MAX, coordinate_message, needed_precision
from ..runtime.aliases import ArrayLike, DeviceLike
from ..runtime.options import check_option
from ..runtime.start import init_warp

wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = ["ccd_first_pass_kernel", "ccd_queries", "ccd_second_pass_kernel", "run_queries"]


@wp.kernel
def ccd_first_pass_kernel(kind: int, x0: wp.array2d[Any], x1: wp.array2d[Any], min_distance: wp.float64,
                          toi: wp.array[wp.float64], deferred: wp.array[wp.int32], deferred_count: wp.array[wp.int32]):
    """One query a thread (``x0``, ``x1`` ``(n, 4)`` points at ``t = 0`` and ``t = 1``, ``wp.vec3`` or
    ``wp.vec3d``) through its filters: ``toi`` set to :data:`~warp_ccd._src.geometry.ccd.NO_HIT`, and a
    query they do not rule out listed in ``deferred`` (``deferred_count[0]`` of them; ``deferred``
    holds every query at most) for :data:`ccd_second_pass_kernel`."""
    k = wp.tid()
    toi[k] = NO_HIT
    if not query_excluded(kind, _points(x0[k, 0], x0[k, 1], x0[k, 2], x0[k, 3]),
                          _points(x1[k, 0], x1[k, 1], x1[k, 2], x1[k, 3]), min_distance):
        deferred[wp.atomic_add(deferred_count, 0, 1)] = k


@wp.kernel
def ccd_second_pass_kernel(kind: int, x0: wp.array2d[Any], x1: wp.array2d[Any], min_distance: wp.float64,
                           tolerance: wp.float64, max_iterations: int, deferred: wp.array[wp.int32],
                           deferred_count: wp.array[wp.int32], toi: wp.array[wp.float64]):
    """The deferred queries of :data:`ccd_first_pass_kernel` from the start with ``max_iterations``,
    one a thread, packed: a warp's lanes all search long, none waits idle beside a short one."""
    i = wp.tid()
    if i >= deferred_count[0]:
        return
    k = deferred[i]
    toi[k] = primitive_toi(kind, _points(x0[k, 0], x0[k, 1], x0[k, 2], x0[k, 3]),
                           _points(x1[k, 0], x1[k, 1], x1[k, 2], x1[k, 3]), min_distance, tolerance, max_iterations,
                           NO_HIT)


for _vec in (wp.vec3, wp.vec3d):
    for _kernel in (ccd_first_pass_kernel, ccd_second_pass_kernel):
        wp.overload(_kernel, {"x0": wp.array2d[_vec], "x1": wp.array2d[_vec]})


@wp.kernel
def _count_nonfinite_kernel(x: wp.array2d[Any], count: wp.array[wp.int32]):
    k, i = wp.tid()
    p = x[k, i]
    for ax in range(3):
        if not wp.isfinite(p[ax]):
            wp.atomic_add(count, 0, 1)


for _vec in (wp.vec3, wp.vec3d):
    wp.overload(_count_nonfinite_kernel, {"x": wp.array2d[_vec]})


def _query_points(name: str, x, device) -> wp.array:
    """``x`` as an ``(n, 4)`` array of ``wp.vec3`` / ``wp.vec3d`` on ``device``, validated."""
    if isinstance(x, wp.array):
        if x.dtype in (wp.vec3, wp.vec3d) and x.ndim == 2 and x.shape[1] == 4:
            arr = x
        elif x.dtype in (wp.float32, wp.float64) and x.ndim == 3 and x.shape[1:] == (4, 3):
            arr = x.view(wp.vec3 if x.dtype == wp.float32 else wp.vec3d).reshape((x.shape[0], 4)) \
                if x.is_contiguous else None
            if arr is None:
                raise ValueError(f"{name}: a device array must be contiguous")
        else:
            raise ValueError(f"{name}: expected an (n, 4, 3) float array, got a Warp array of {x.dtype.__name__} "
                             f"and shape {x.shape}")
        if str(arr.device) != str(device):
            arr = arr.to(device)
        if arr.shape[0]:
            count = wp.zeros(1, dtype=wp.int32, device=device)
            wp.launch(_count_nonfinite_kernel, dim=arr.shape, inputs=[arr], outputs=[count], device=device)
            if int(count.numpy()[0]):
                raise ValueError(f"{name}: {int(count.numpy()[0])} coordinates are not finite")
        return arr
    a = np.asarray(x)
    if a.ndim != 3 or a.shape[1:] != (4, 3):
        raise ValueError(f"{name}: expected an (n, 4, 3) array, got shape {a.shape}")
    if a.dtype.kind not in "fiu":
        raise ValueError(f"{name}: expected float coordinates, got dtype {a.dtype}")
    if a.size and not np.isfinite(a).all():
        bad = int(np.nonzero(~np.isfinite(a).reshape(len(a), -1).all(axis=1))[0][0])
        raise ValueError(f"{name}: query {bad} has a coordinate that is not finite")
    if a.dtype == np.float32:
        return wp.array(np.ascontiguousarray(a), dtype=wp.vec3, device=device)
    return wp.array(np.ascontiguousarray(a, dtype=np.float64), dtype=wp.vec3d, device=device)


def _check_reach(a0: wp.array, a1: wp.array) -> None:
    """Raises ValueError where a query's coordinates are too far from the origin for its size, as
    ``collide()`` refuses them (:func:`~warp_ccd._src.geometry.precision.needed_precision`, float64: the
    queries' precision at best): the query's size is the extent of its eight points (``x0`` and ``x1``),
    its reach their largest ``|coordinate|``; the worst query is named."""
    p = np.concatenate([a0.numpy(), a1.numpy()], axis=1).astype(np.float64, copy=False)  # (n, 8, 3)
    reach = np.abs(p).max(axis=(1, 2))
    size = (p.max(axis=1) - p.min(axis=1)).max(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(size > 0.0, reach / size, 0.0)
    worst = int(np.argmax(reach)) if reach.max() > FLOAT32_MAX else int(np.argmax(ratio))
    if needed_precision(reach[worst], size[worst]) is None:
        raise ValueError(f"query {worst}: {coordinate_message(reach[worst], size[worst], 'float64')}: move the "
                         "queries nearer the origin")


def run_queries(kind: int, x0: wp.array, x1: wp.array, min_distance: float, tolerance: float, max_iterations: int,
                toi: wp.array, deferred: wp.array | None = None, deferred_count: wp.array | None = None) -> None:
    """Enqueues the two passes over ``n`` queries (no host read: a graph can hold them): every query's
    filters, then the search of the queries they leave, packed.

    Args:
        kind: a code of :data:`CCD_KINDS`.
        x0, x1: ``(n, 4)`` ``wp.vec3`` / ``wp.vec3d`` points at ``t = 0`` and ``t = 1``.
        min_distance, tolerance, max_iterations: as in :func:`ccd_queries`.
        toi: ``(n,)`` float64 output.
        deferred, deferred_count: scratch, ``(n,)`` and ``(1,)`` int32 (allocated when None).
    """
    n = x0.shape[0]
    device = x0.device
    if deferred is None:
        deferred = wp.empty(n, dtype=wp.int32, device=device)
    if deferred_count is None:
        deferred_count = wp.zeros(1, dtype=wp.int32, device=device)
    else:
        deferred_count.zero_()
    d, tol = wp.float64(min_distance), wp.float64(tolerance)
    wp.launch(ccd_first_pass_kernel, dim=n, inputs=[kind, x0, x1, d], outputs=[toi, deferred, deferred_count],
              device=device)
    wp.launch(ccd_second_pass_kernel, dim=n, inputs=[kind, x0, x1, d, tol, max_iterations, deferred, deferred_count],
              outputs=[toi], device=device)


def ccd_queries(kind: str, x0: ArrayLike, x1: ArrayLike, *, min_distance: float = 0.0, tolerance: float = CCD_TOLERANCE,
                max_iterations: int = CCD_MAX_ITERATIONS, device: DeviceLike = None) -> tuple[np.ndarray, np.ndarray]:
    """Continuous collision of many moving vertex-face or edge-edge pairs.

    Args:
        kind: ``"vertex_face"`` (rows p, f0, f1, f2) or ``"edge_edge"`` (rows ea0, ea1, eb0, eb1).
        x0: ``(n, 4, 3)`` float32 or float64 points at ``t = 0`` (numpy, or Warp arrays of that shape
            or ``(n, 4)`` ``wp.vec3`` / ``wp.vec3d``); every vertex moves linearly to its point of ``x1``.
        x1: the same points at ``t = 1``, in the same form as ``x0``.
        min_distance: minimum separation (>= 0, same units; infinity norm).
        tolerance: distance tolerance of a query (> 0; a false positive comes within about it).
        max_iterations: most boxes one query examines (>= 1; past it the answer is conservative).
        device: Warp device (default: Warp's default device).

    Returns:
        ``(hit, toi)``: ``(n,)`` bool and ``(n,)`` float64 earliest time of impact in ``[0, 1]``
        (``inf`` where no hit), never later than the true one; the same on every device, and for
        float32 inputs the same as for the same values in float64.

    Raises:
        ValueError: an unknown ``kind``, a bad shape, non-finite coordinates, coordinates too far
            from the origin for a query's size (as ``collide()`` refuses them:
            :func:`~warp_ccd._src.geometry.precision.needed_precision` in float64, naming the query),
            ``x0`` and ``x1`` of different lengths, or a bad option.
    """
    if not isinstance(kind, str) or kind not in CCD_KINDS:
        raise ValueError(f"kind must be one of {tuple(CCD_KINDS)}, got {kind!r}")
    min_distance = check_option("min_distance", min_distance)
    tolerance = check_option("ccd_tolerance", tolerance, given_as="tolerance")
    max_iterations = check_option("ccd_max_iterations", max_iterations, given_as="max_iterations")
    init_warp()
    device = wp.get_device(device)
    a0 = _query_points("x0", x0, device)
    a1 = _query_points("x1", x1, device)
    if a0.shape[0] != a1.shape[0]:
        raise ValueError(f"x0 and x1 must hold the same number of queries, got {a0.shape[0]} and {a1.shape[0]}")
    if a0.dtype != a1.dtype:  # float32 values are exact in float64: compute both in float64
        a0, a1 = (a if a.dtype == wp.vec3d else wp.array(a.numpy().astype(np.float64), dtype=wp.vec3d, device=device)
                  for a in (a0, a1))
    n = a0.shape[0]
    if n:
        _check_reach(a0, a1)
    toi = wp.empty(n, dtype=wp.float64, device=device)
    if n:
        run_queries(CCD_KINDS[kind], a0, a1, min_distance, tolerance, max_iterations, toi)
    t = toi.numpy()
    return t <= 1.0, t
