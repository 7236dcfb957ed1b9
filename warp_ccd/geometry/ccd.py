"""Continuous collision of moving primitives: the earliest time a vertex meets a face, or an edge an edge.

Each vertex moves linearly from its position at ``t = 0`` to its position at ``t = 1``. A
vertex-face pair ``(p; f0, f1, f2)`` collides when at some ``t`` the point lies on the closed
triangle, an edge-edge pair ``(ea0, ea1; eb0, eb1)`` when the two closed segments meet; with a
minimum separation ``d``, when they come within ``d`` (in the infinity norm, so every pair within
Euclidean ``d`` is among them). The time of impact (toi) is the earliest such ``t``.

The method is Tight Inclusion's (Wang et al. 2021, "A Large Scale Benchmark and an Inclusion-Based
Algorithm for Continuous Collision Detection"), with its own certified error bound and a stackless
depth-first search:

* Both pairs are the roots of a function ``F(t, u, v)`` over a box of parameters: for vertex-face
  ``F = p(t) - (f0(t) + u (f1(t) - f0(t)) + v (f2(t) - f0(t)))`` with ``u, v >= 0, u + v <= 1``;
  for edge-edge ``F = ea0(t) + u (ea1(t) - ea0(t)) - eb0(t) - v (eb1(t) - eb0(t))`` with
  ``u, v`` in ``[0, 1]``. ``F`` is multilinear (of degree one in each parameter), so over any box of
  parameters each coordinate of ``F`` lies between the least and the greatest of its values at the
  box's eight corners: when, on some axis, every corner is above ``d`` or every one below ``-d``,
  the box holds no collision.
* Corner values are computed in float64 (float32 inputs are converted exactly) in a fixed order;
  each is within ``eps = 2^-45 * m`` of its true value, ``m`` the largest absolute coordinate of
  the eight points on that axis (a forward error bound of the evaluation, about 65 units in the
  last place of ``m``, with fourfold slack; see ``docs/ARCHITECTURE.md``). A box is rejected only
  when its corners lie beyond ``d + eps``: a true collision is never rejected.
* Boxes are bisected (dyadic intervals, exact in float64) until one is *accepted*: its values all
  lie within ``d + eps`` of the origin, or span at most ``tolerance`` on every axis, or its
  parameter widths all fall below the widths that ``tolerance`` asks for (as Tight Inclusion
  derives them from the motion). An accepted box reports its least ``t``: the toi is never later
  than the true one, and a false positive lies within about ``tolerance`` of a true contact.
* The search is depth-first, lower halves first, and keeps going while a box could start earlier
  than the best toi found; the split at each depth depends only on the depth (the widest
  dimension relative to its tolerance, as Tight Inclusion splits), so the path back up needs no
  stack: a thread holds three lower corners and three widths. Past ``max_iterations`` boxes the
  answer is a collision at the earliest time any unfinished box starts (conservative).

Every device gives the same answer: compile the calling module with ``fuse_fp=False`` (as this
module is), so that CUDA does not contract ``a * b + c`` into an FMA.

:func:`vertex_face_toi`, :func:`edge_edge_toi` and :func:`triangle_pair_toi` are the device
functions; :mod:`warp_ccd.geometry.ccd_queries` runs batches of queries from numpy (``ccd_queries``).
"""

from __future__ import annotations

import math
from typing import Any

import warp as wp

from .primitives import _pick
from .triangle import TOLERANCE, tri_tri_moller

wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = [
    "CCD_KINDS",
    "CCD_MAX_ITERATIONS",
    "CCD_TOLERANCE",
    "NO_HIT",
    "pair_meets",
    "pair_query",
    "pair_search",
    "edge_edge_toi",
    "triangle_pair_toi",
    "vertex_face_toi",
]

CCD_TOLERANCE = 1.0e-6
"""Default distance tolerance of a query (same units as the coordinates): an accepted box's values
span at most this much, so a false positive comes within about this distance (Tight Inclusion's
default)."""

CCD_MAX_ITERATIONS = 1_000_000
"""Default cap on the boxes one query examines; past it the query reports a collision at the
earliest time an unfinished box starts (a conservative answer; no query of the test sets gets near)."""

FIRST_PASS_ITERATIONS = 4
"""Boxes a query may examine in the first pass (:func:`~warp_ccd.geometry.ccd_queries.run_queries`,
the continuous narrow phase). On a GPU a warp runs as long as its longest lane: a frame's queries mostly end in a
box or a few, a few percent search hundreds; the first pass settles the short ones, the second runs
the rest packed together."""

NO_HIT = wp.constant(wp.float64(math.inf))
"""The toi of a pair that never collides."""

CCD_KINDS = {"vertex_face": 0, "edge_edge": 1}
"""Query kinds of :func:`~warp_ccd.geometry.ccd_queries.ccd_queries` and their codes in the kernels."""

KIND_VERTEX_FACE = wp.constant(0)
KIND_EDGE_EDGE = wp.constant(1)

PAIR_QUERIES = 15
"""Primitive queries of a triangle pair: 3 + 3 vertex-face, 3 x 3 edge-edge."""

ERROR_SCALE = wp.constant(wp.float64(2.0**-45))
"""Certified error of a corner value, relative to the largest absolute coordinate on its axis."""

ERROR_SCALE_ROTATED = wp.constant(wp.float64(2.0**-44))
"""Certified error of a corner value in the contact frame, relative to the largest absolute
coordinate of the query's points on any axis (rotating the points adds its own rounding; see
``docs/ARCHITECTURE.md``)."""

ERROR_FLOOR = wp.constant(wp.float64(1.0e-300))
"""Absolute error added to cover gradual underflow."""

WIDTH_MIN = wp.constant(wp.float64(2.0**-53))
"""Parameter intervals are never split below this width (a box that narrow is accepted): every
corner ``k * 2^-l`` in ``[0, 1]`` stays exact in float64, so ``lo + w``, ``lo - w`` and the climb's
parity test are exact (narrower, ``lo + w`` could round back to ``lo`` and the search revisit one
box for ever)."""

DISCRETE_PAD = wp.constant(wp.float64(2.0 * TOLERANCE * math.sqrt(3.0)))
"""Triangles whose boxes at ``t = 0`` are apart by more than this times their extent cannot meet in
the discrete test (its tolerance is ``TOLERANCE`` times their longest edge)."""

_F0 = wp.constant(wp.float64(0.0))
_F1 = wp.constant(wp.float64(1.0))
_F2 = wp.constant(wp.float64(2.0))
_HALF = wp.constant(wp.float64(0.5))
_INF = wp.constant(wp.float64(math.inf))


@wp.func
def _lerp(x0: wp.float64, x1: wp.float64, t: wp.float64) -> wp.float64:
    return x0 + (x1 - x0) * t


@wp.func
def _corner(kind: int, a: wp.float64, b: wp.float64, c: wp.float64, d: wp.float64, u: wp.float64,
            v: wp.float64) -> wp.float64:
    """One coordinate of ``F`` at ``(u, v)``, from the four points' coordinates at one time."""
    if kind == KIND_VERTEX_FACE:  # a = p, b c d = f0 f1 f2
        return a - (b + ((c - b) * u + (d - b) * v))
    return (a + (b - a) * u) - (c + (d - c) * v)  # a b = ea0 ea1, c d = eb0 eb1


@wp.func
def _axis_values(kind: int, x0: wp.vec4d, x1: wp.vec4d, t: wp.float64, u_lo: wp.float64, u_hi: wp.float64,
                 v_lo: wp.float64, v_hi: wp.float64) -> wp.vec4d:
    """One coordinate of ``F`` at the four ``(u, v)`` corners of a box at time ``t`` (``x0``, ``x1``:
    the four points' coordinates on that axis at ``t = 0`` and ``t = 1``), in the order
    ``(u_lo, v_lo), (u_hi, v_lo), (u_lo, v_hi), (u_hi, v_hi)``."""
    a = _lerp(x0[0], x1[0], t)
    b = _lerp(x0[1], x1[1], t)
    c = _lerp(x0[2], x1[2], t)
    d = _lerp(x0[3], x1[3], t)
    return wp.vec4d(_corner(kind, a, b, c, d, u_lo, v_lo), _corner(kind, a, b, c, d, u_hi, v_lo),
                    _corner(kind, a, b, c, d, u_lo, v_hi), _corner(kind, a, b, c, d, u_hi, v_hi))


@wp.func
def _axis_range(kind: int, x0: wp.vec4d, x1: wp.vec4d, lo: wp.vec3d, w: wp.vec3d):
    """Least and greatest of one coordinate of ``F`` over the 8 corners of the box ``[lo, lo + w]``,
    and how much it changes along an edge of the box in ``t``, ``u`` and ``v`` (the most of the
    box's four edges in each)."""
    u_hi = lo[1] + w[1]
    v_hi = lo[2] + w[2]
    f = _axis_values(kind, x0, x1, lo[0], lo[1], u_hi, lo[2], v_hi)
    g = _axis_values(kind, x0, x1, lo[0] + w[0], lo[1], u_hi, lo[2], v_hi)
    low = wp.min(wp.min(wp.min(f[0], f[1]), wp.min(f[2], f[3])), wp.min(wp.min(g[0], g[1]), wp.min(g[2], g[3])))
    high = wp.max(wp.max(wp.max(f[0], f[1]), wp.max(f[2], f[3])), wp.max(wp.max(g[0], g[1]), wp.max(g[2], g[3])))
    dt = wp.max(wp.max(wp.abs(g[0] - f[0]), wp.abs(g[1] - f[1])), wp.max(wp.abs(g[2] - f[2]), wp.abs(g[3] - f[3])))
    du = wp.max(wp.max(wp.abs(f[1] - f[0]), wp.abs(f[3] - f[2])), wp.max(wp.abs(g[1] - g[0]), wp.abs(g[3] - g[2])))
    dv = wp.max(wp.max(wp.abs(f[2] - f[0]), wp.abs(f[3] - f[1])), wp.max(wp.abs(g[2] - g[0]), wp.abs(g[3] - g[1])))
    return low, high, wp.vec3d(dt, du, dv)


@wp.func
def _linf(a: wp.vec3d) -> wp.float64:
    return wp.max(wp.max(wp.abs(a[0]), wp.abs(a[1])), wp.abs(a[2]))


@wp.func
def _max_abs4(x0: wp.vec4d, x1: wp.vec4d) -> wp.float64:
    m = _F0
    for i in range(4):
        m = wp.max(m, wp.max(wp.abs(x0[i]), wp.abs(x1[i])))
    return m


@wp.func
def _tol_div(tolerance: wp.float64, length: wp.float64) -> wp.float64:
    if length > _F0:
        return tolerance / length
    return _INF


@wp.func
def _get(v: wp.vec3d, j: int) -> wp.float64:
    """``v[j]`` through static indices (a dynamic index puts a vector in a GPU thread's local memory,
    which the search reads every box)."""
    if j == 0:
        return v[0]
    if j == 1:
        return v[1]
    return v[2]


@wp.func
def _put(v: wp.vec3d, j: int, x: wp.float64) -> wp.vec3d:
    """``v`` with ``v[j] = x``, through static indices."""
    if j == 0:
        return wp.vec3d(x, v[1], v[2])
    if j == 1:
        return wp.vec3d(v[0], x, v[2])
    return wp.vec3d(v[0], v[1], x)


@wp.func
def _next_split(w: wp.vec3d, tol: wp.vec3d, spread: wp.vec3d) -> int:
    """The parameter to split: among those wider than their tolerance, the one along which the
    unfinished coordinates of ``F`` change most (``spread``), else the widest relative to its
    tolerance (the lowest index on a tie); -1 when none is wider (a leaf)."""
    best = int(-1)
    best_s = -_F1
    best_r = _F1
    by_ratio = int(-1)
    for j in range(3):
        r = w[j] / tol[j]
        if r > _F1 and w[j] > WIDTH_MIN:
            if spread[j] > best_s:
                best = j
                best_s = spread[j]
            if r > best_r:
                by_ratio = j
                best_r = r
    if best_s > _F0:
        return best
    return by_ratio


PATH_WORDS = 4
"""64-bit words of a search's path: 2 bits a level, so :data:`MAX_DEPTH` levels."""

MAX_DEPTH = wp.constant(32 * PATH_WORDS)
"""Deepest level of a search: a box there is accepted (conservative; tolerances that ask for more
splits than this, 128 halvings over three parameters, are not met)."""

_path_t = wp.types.vector(length=PATH_WORDS, dtype=wp.uint64)


@wp.func
def _path_word(path: _path_t, word: int) -> wp.uint64:
    if word == 0:
        return path[0]
    if word == 1:
        return path[1]
    if word == 2:
        return path[2]
    return path[3]


@wp.func
def _path_push(path: _path_t, depth: int, dim: int) -> _path_t:
    """``path`` with parameter ``dim`` split at level ``depth`` (static indices only, as :func:`_get`)."""
    word = depth >> 5
    shift = wp.uint64((depth & 31) * 2)
    x = (_path_word(path, word) & ~(wp.uint64(3) << shift)) | (wp.uint64(dim) << shift)
    out = path
    if word == 0:
        out[0] = x
    elif word == 1:
        out[1] = x
    elif word == 2:
        out[2] = x
    else:
        out[3] = x
    return out


@wp.func
def _path_dim(path: _path_t, depth: int) -> int:
    """The parameter split at level ``depth``."""
    return int((_path_word(path, depth >> 5) >> wp.uint64((depth & 31) * 2)) & wp.uint64(3))


@wp.func
def _is_upper_half(lo: wp.float64, w: wp.float64) -> bool:
    """Whether the interval ``[lo, lo + w]`` (``lo`` a multiple of the power of two ``w``) is the
    upper half of its parent."""
    k = lo / w
    return wp.floor(k * _HALF) * _F2 != k


MAT34D = wp.types.matrix(shape=(3, 4), dtype=wp.float64)
"""Four points on the three axes (rows x, y, z; columns the points)."""


@wp.func
def _pending_start(lo_in: wp.vec3d, w_in: wp.vec3d, path: _path_t, depth_in: int, include_box: bool) -> wp.float64:
    """The earliest start time of the boxes a search stopped at box ``(lo, w)`` (level ``depth``)
    has not finished: each upper sibling still ahead on the way up, and the box itself when
    ``include_box``."""
    lo = wp.vec3d(lo_in)
    w = wp.vec3d(w_in)
    start = _INF
    if include_box:
        start = lo[0]
    depth = depth_in
    while depth > 0:
        depth -= 1
        j = _path_dim(path, depth)
        lj = _get(lo, j)
        wj = _get(w, j)
        if _is_upper_half(lj, wj):
            lo = _put(lo, j, lj - wj)
        else:
            sibling = lo[0]
            if j == 0:
                sibling = lo[0] + w[0]
            start = wp.min(start, sibling)
        w = _put(w, j, wj * _F2)
    return start


MAT33D = wp.types.matrix(shape=(3, 3), dtype=wp.float64)


@wp.func
def _column(x: MAT34D, j: int) -> wp.vec3d:
    return wp.vec3d(x[0, j], x[1, j], x[2, j])


@wp.func
def _contact_frame(kind: int, x0: MAT34D, x1: MAT34D) -> MAT33D:
    """Rows of an orthonormal frame (computed, so orthonormal to rounding: invertible, which is all
    the search needs) whose third row is the normal of the face (vertex-face) or of the two edges
    (edge-edge), summed over both ends of the motion; the identity when that normal vanishes."""
    n = wp.vec3d()
    a = wp.vec3d()
    for k in range(2):
        x = x0
        if k == 1:
            x = x1
        if kind == KIND_VERTEX_FACE:
            e = _column(x, 2) - _column(x, 1)
            n += wp.cross(e, _column(x, 3) - _column(x, 1))
        else:
            e = _column(x, 1) - _column(x, 0)
            n += wp.cross(e, _column(x, 3) - _column(x, 2))
        a += e
    length = wp.length(n)
    if not (length > _F0):
        return wp.identity(n=3, dtype=wp.float64)
    n = n / length
    a = a - n * wp.dot(a, n)  # the first axis along the face's (the first edge's) first edge, if it can be
    la = wp.length(a)
    if not (la > wp.float64(1.0e-3) * wp.length(n)):
        # Any unit vector across n: from the axis n leans on least.
        axis = wp.vec3d(_F1, _F0, _F0)
        if wp.abs(n[1]) < wp.abs(n[0]) and wp.abs(n[1]) <= wp.abs(n[2]):
            axis = wp.vec3d(_F0, _F1, _F0)
        elif wp.abs(n[2]) < wp.abs(n[0]):
            axis = wp.vec3d(_F0, _F0, _F1)
        a = wp.cross(n, axis)
        la = wp.length(a)
    a = a / la
    b = wp.cross(n, a)
    return wp.matrix_from_rows(a, b, n)


@wp.func
def _search(kind: int, x0: MAT34D, x1: MAT34D, min_distance: wp.float64, tolerance: wp.float64,
            max_iterations: int, t_end: wp.float64):
    """Earliest toi before ``t_end`` of one query in float64, or ``t_end`` when there is none, and
    whether the search ran out of ``max_iterations`` (its answer is then the conservative one).

    Args:
        kind: ``KIND_VERTEX_FACE`` (points p, f0, f1, f2) or ``KIND_EDGE_EDGE`` (ea0, ea1, eb0, eb1).
        x0, x1: the four points at ``t = 0`` and ``t = 1``, rows x, y, z.
        min_distance: minimum separation (>= 0, infinity norm).
        tolerance: distance tolerance (> 0).
        max_iterations: most boxes examined.
        t_end: only times before it are searched (:data:`NO_HIT` for all of ``[0, 1]``; a smaller
            value when an earlier query already found that toi).
    """
    eps = wp.vec3d()
    for ax in range(3):
        eps[ax] = ERROR_SCALE * _max_abs4(x0[ax], x1[ax]) + ERROR_FLOOR + min_distance
    lo = wp.vec3d(_F0, _F0, _F0)
    w = wp.vec3d(_F1, _F1, _F1)
    # Most queries of a frame are far apart: the whole box is rejected before anything else is computed.
    for ax in range(3):
        fl, fh, change = _axis_range(kind, x0[ax], x1[ax], lo, w)
        if fl > eps[ax] or fh < -eps[ax]:
            return t_end, int(0)
    if min_distance == _F0:
        # Search in a frame whose third axis is the face's normal (vertex-face) or the edges' common
        # normal (edge-edge): F = 0 does not depend on the frame, and there the distance along the
        # normal rejects times far from the contact whatever the box's extent over the face.
        r = _contact_frame(kind, x0, x1)
        if r[0, 0] != _F1 or r[1, 1] != _F1:
            m = _F0
            for ax in range(3):
                m = wp.max(m, _max_abs4(x0[ax], x1[ax]))
            x0 = r @ x0
            x1 = r @ x1
            e = ERROR_SCALE_ROTATED * m + ERROR_FLOOR
            eps = wp.vec3d(e, e, e)
    # Parameter tolerances from the whole box (Tight Inclusion's compute_*_tolerances: the tolerance
    # over three times the longest edge of F's box along each parameter, in the infinity norm;
    # infinite along a parameter F does not depend on); in the contact frame the box is tested again.
    longest = wp.vec3d()
    for ax in range(3):
        fl, fh, change = _axis_range(kind, x0[ax], x1[ax], lo, w)
        if fl > eps[ax] or fh < -eps[ax]:
            return t_end, int(0)
        longest = wp.max(longest, change)
    three = wp.float64(3.0)
    tol = wp.vec3d(_tol_div(tolerance, three * longest[0]), _tol_div(tolerance, three * longest[1]),
                   _tol_div(tolerance, three * longest[2]))
    path = _path_t()
    depth = int(0)
    best = t_end
    iterations = int(0)
    exhausted = int(0)
    done = bool(False)
    while not done:
        descend = int(-1)
        visit = lo[0] < best
        if kind == KIND_VERTEX_FACE and lo[1] + lo[2] > _F1:
            visit = False  # wholly outside the triangle u + v <= 1
        if visit:
            iterations += 1
            reject = bool(False)
            finished = bool(True)
            spread = wp.vec3d()
            for ax in range(3):
                if not reject:
                    fl, fh, change = _axis_range(kind, x0[ax], x1[ax], lo, w)
                    e = eps[ax]
                    if fl > e or fh < -e:
                        reject = True
                    elif (fl < -e or fh > e) and fh - fl > tolerance:
                        # Neither within d + eps everywhere nor within the tolerance of it.
                        finished = False
                        spread = wp.max(spread, change)
            if not reject:
                if not finished and depth < MAX_DEPTH:
                    if best < lo[0] + w[0] and w[0] > tol[0] and w[0] > WIDTH_MIN:
                        # The box straddles the best toi so far: only its part before it matters.
                        descend = 0
                    else:
                        descend = _next_split(w, tol, spread)
                if descend < 0:
                    best = lo[0]  # accepted (lo[0] < best)
            if iterations >= max_iterations:
                # Out of budget: a collision no later than any unfinished box could hold one.
                best = wp.min(best, _pending_start(lo, w, path, depth, descend >= 0))
                exhausted = 1
                done = True
        if not done:
            if descend >= 0:
                path = _path_push(path, depth, descend)
                depth += 1
                w = _put(w, descend, _get(w, descend) * _HALF)  # the lower half first
            else:
                # Next box: climb past upper halves, then step to the upper sibling.
                climbing = bool(True)
                while climbing:
                    if depth == 0:
                        climbing = False
                        done = True
                    else:
                        j = _path_dim(path, depth - 1)
                        lj = _get(lo, j)
                        wj = _get(w, j)
                        if _is_upper_half(lj, wj):
                            lo = _put(lo, j, lj - wj)
                            w = _put(w, j, wj * _F2)
                            depth -= 1
                        else:
                            lo = _put(lo, j, lj + wj)
                            climbing = False
    return best, exhausted


@wp.func
def primitive_toi(kind: int, x0: MAT34D, x1: MAT34D, min_distance: wp.float64, tolerance: wp.float64,
                  max_iterations: int, t_end: wp.float64) -> wp.float64:
    """Earliest toi before ``t_end`` of one query in float64 (``x0``, ``x1``: the four points at
    ``t = 0`` and ``t = 1``, rows x, y, z), or ``t_end`` when there is none (see :func:`_search`)."""
    toi, exhausted = _search(kind, x0, x1, min_distance, tolerance, max_iterations, t_end)
    return toi


@wp.func
def _points(a: Any, b: Any, c: Any, d: Any) -> MAT34D:
    return MAT34D(wp.float64(a[0]), wp.float64(b[0]), wp.float64(c[0]), wp.float64(d[0]),
                  wp.float64(a[1]), wp.float64(b[1]), wp.float64(c[1]), wp.float64(d[1]),
                  wp.float64(a[2]), wp.float64(b[2]), wp.float64(c[2]), wp.float64(d[2]))


@wp.func
def vertex_face_toi(p_t0: Any, f0_t0: Any, f1_t0: Any, f2_t0: Any, p_t1: Any, f0_t1: Any, f1_t1: Any, f2_t1: Any,
                    min_distance: wp.float64, tolerance: wp.float64, max_iterations: int) -> wp.float64:
    """Earliest time in ``[0, 1]`` the moving point ``p`` comes within ``min_distance`` of the moving
    closed triangle ``(f0, f1, f2)``, or :data:`NO_HIT` (``wp.vec3`` or ``wp.vec3d`` points at
    ``t = 0`` and ``t = 1``; computed in float64; see the module docstring)."""
    return primitive_toi(KIND_VERTEX_FACE, _points(p_t0, f0_t0, f1_t0, f2_t0), _points(p_t1, f0_t1, f1_t1, f2_t1),
                         min_distance, tolerance, max_iterations, NO_HIT)


@wp.func
def edge_edge_toi(ea0_t0: Any, ea1_t0: Any, eb0_t0: Any, eb1_t0: Any, ea0_t1: Any, ea1_t1: Any, eb0_t1: Any,
                  eb1_t1: Any, min_distance: wp.float64, tolerance: wp.float64, max_iterations: int) -> wp.float64:
    """Earliest time in ``[0, 1]`` the moving closed segments ``(ea0, ea1)`` and ``(eb0, eb1)`` come
    within ``min_distance``, or :data:`NO_HIT` (as :func:`vertex_face_toi`)."""
    return primitive_toi(KIND_EDGE_EDGE, _points(ea0_t0, ea1_t0, eb0_t0, eb1_t0),
                         _points(ea0_t1, ea1_t1, eb0_t1, eb1_t1), min_distance, tolerance, max_iterations, NO_HIT)


@wp.func
def _abs3(v: wp.vec3d) -> wp.vec3d:
    return wp.vec3d(wp.abs(v[0]), wp.abs(v[1]), wp.abs(v[2]))


@wp.func
def _max3(v: wp.vec3d) -> wp.float64:
    return wp.max(wp.max(v[0], v[1]), v[2])


@wp.func
def _apart(lo_p: wp.vec3d, hi_p: wp.vec3d, lo_q: wp.vec3d, hi_q: wp.vec3d, gap: wp.vec3d) -> bool:
    """Whether boxes ``p`` and ``q`` are more than ``gap`` apart on some axis."""
    for ax in range(3):
        if lo_p[ax] - hi_q[ax] > gap[ax] or lo_q[ax] - hi_p[ax] > gap[ax]:
            return True
    return False


@wp.func
def pair_query(q: int, a0: wp.vec3d, a1: wp.vec3d, a2: wp.vec3d, b0: wp.vec3d, b1: wp.vec3d, b2: wp.vec3d,
               a0e: wp.vec3d, a1e: wp.vec3d, a2e: wp.vec3d, b0e: wp.vec3d, b1e: wp.vec3d, b2e: wp.vec3d):
    """Query ``q`` (of :data:`PAIR_QUERIES`) of two moving triangles: ``(kind, x0, x1)``; 0-2 a vertex
    of ``a`` against face ``b``, 3-5 a vertex of ``b`` against face ``a``, 6-14 edge ``(q - 6) // 3``
    of ``a`` against edge ``(q - 6) % 3`` of ``b``."""
    kind = KIND_VERTEX_FACE
    i = q % 3
    if q < 3:
        x0 = _points(_pick(a0, a1, a2, i), b0, b1, b2)
        x1 = _points(_pick(a0e, a1e, a2e, i), b0e, b1e, b2e)
    elif q < 6:
        x0 = _points(_pick(b0, b1, b2, i), a0, a1, a2)
        x1 = _points(_pick(b0e, b1e, b2e, i), a0e, a1e, a2e)
    else:
        kind = KIND_EDGE_EDGE
        i = (q - 6) // 3
        j = (q - 6) % 3
        x0 = _points(_pick(a0, a1, a2, i), _pick(a0, a1, a2, (i + 1) % 3), _pick(b0, b1, b2, j),
                     _pick(b0, b1, b2, (j + 1) % 3))
        x1 = _points(_pick(a0e, a1e, a2e, i), _pick(a0e, a1e, a2e, (i + 1) % 3), _pick(b0e, b1e, b2e, j),
                     _pick(b0e, b1e, b2e, (j + 1) % 3))
    return kind, x0, x1


@wp.func
def pair_meets(a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any) -> bool:
    """The discrete test (:func:`~warp_ccd.geometry.triangle.tri_tri_moller`, its tolerance) on two
    triangles at one time, run only where their boxes come within twice its tolerance."""
    lo_a = wp.min(wp.min(wp.vec3d(a0), wp.vec3d(a1)), wp.vec3d(a2))
    hi_a = wp.max(wp.max(wp.vec3d(a0), wp.vec3d(a1)), wp.vec3d(a2))
    lo_b = wp.min(wp.min(wp.vec3d(b0), wp.vec3d(b1)), wp.vec3d(b2))
    hi_b = wp.max(wp.max(wp.vec3d(b0), wp.vec3d(b1)), wp.vec3d(b2))
    pad = DISCRETE_PAD * _max3(wp.max(hi_a - lo_a, hi_b - lo_b))
    if _apart(lo_a, hi_a, lo_b, hi_b, wp.vec3d(pad, pad, pad)):
        return False
    return tri_tri_moller(a0, a1, a2, b0, b1, b2, type(a0[0])(TOLERANCE))


@wp.func
def pair_search(a0_t0: Any, a1_t0: Any, a2_t0: Any, b0_t0: Any, b1_t0: Any, b2_t0: Any, a0_t1: Any, a1_t1: Any,
                a2_t1: Any, b0_t1: Any, b1_t1: Any, b2_t1: Any, min_distance: wp.float64, tolerance: wp.float64,
                max_iterations: int, defer: bool):
    """:func:`triangle_pair_toi`, with each query's search within ``max_iterations`` boxes, and the
    mask of the queries that needed more (bit ``q``). With ``defer`` those queries' (conservative)
    answers are left out of the toi and the end test is skipped when the mask is not 0: a second
    pass runs them in full (:func:`pair_query`, :func:`pair_meets` at ``t = 1``), and the minimum of
    both is then :func:`triangle_pair_toi`'s answer exactly (each query is searched on its own)."""
    # Swept boxes (float64, exact): a vertex's over both ends holds it at every t, a triangle's holds
    # the moving triangle. A query whose two boxes are apart by more than eps + d on an axis has no
    # root (its F lies in the difference of the boxes; the one rounding of that difference is within
    # eps), so most of a candidate's 15 queries end at a few comparisons.
    a0 = wp.vec3d(a0_t0)
    a1 = wp.vec3d(a1_t0)
    a2 = wp.vec3d(a2_t0)
    b0 = wp.vec3d(b0_t0)
    b1 = wp.vec3d(b1_t0)
    b2 = wp.vec3d(b2_t0)
    a0e = wp.vec3d(a0_t1)
    a1e = wp.vec3d(a1_t1)
    a2e = wp.vec3d(a2_t1)
    b0e = wp.vec3d(b0_t1)
    b1e = wp.vec3d(b1_t1)
    b2e = wp.vec3d(b2_t1)
    lo_a0 = wp.min(a0, a0e)
    lo_a1 = wp.min(a1, a1e)
    lo_a2 = wp.min(a2, a2e)
    hi_a0 = wp.max(a0, a0e)
    hi_a1 = wp.max(a1, a1e)
    hi_a2 = wp.max(a2, a2e)
    lo_b0 = wp.min(b0, b0e)
    lo_b1 = wp.min(b1, b1e)
    lo_b2 = wp.min(b2, b2e)
    hi_b0 = wp.max(b0, b0e)
    hi_b1 = wp.max(b1, b1e)
    hi_b2 = wp.max(b2, b2e)
    tri_lo_a = wp.min(wp.min(lo_a0, lo_a1), lo_a2)
    tri_hi_a = wp.max(wp.max(hi_a0, hi_a1), hi_a2)
    tri_lo_b = wp.min(wp.min(lo_b0, lo_b1), lo_b2)
    tri_hi_b = wp.max(wp.max(hi_b0, hi_b1), hi_b2)
    m = wp.max(wp.max(_abs3(tri_lo_a), _abs3(tri_hi_a)), wp.max(_abs3(tri_lo_b), _abs3(tri_hi_b)))
    e = m * ERROR_SCALE + wp.vec3d(ERROR_FLOOR + min_distance, ERROR_FLOOR + min_distance, ERROR_FLOOR + min_distance)
    if pair_meets(a0_t0, a1_t0, a2_t0, b0_t0, b1_t0, b2_t0):
        return _F0, int(0)
    best = NO_HIT
    mask = int(0)
    num_queries = int(PAIR_QUERIES)  # a loop, not 15 copies of the search (Warp unrolls constant ranges)
    for q in range(num_queries):
        i = q % 3
        if q < 3:  # vertex i of a against face b
            near = not _apart(_pick(lo_a0, lo_a1, lo_a2, i), _pick(hi_a0, hi_a1, hi_a2, i), tri_lo_b, tri_hi_b, e)
        elif q < 6:  # vertex i of b against face a
            near = not _apart(_pick(lo_b0, lo_b1, lo_b2, i), _pick(hi_b0, hi_b1, hi_b2, i), tri_lo_a, tri_hi_a, e)
        else:  # edge i of a against edge j of b
            i = (q - 6) // 3
            j = (q - 6) % 3
            i1 = (i + 1) % 3
            j1 = (j + 1) % 3
            lo_ea = wp.min(_pick(lo_a0, lo_a1, lo_a2, i), _pick(lo_a0, lo_a1, lo_a2, i1))
            hi_ea = wp.max(_pick(hi_a0, hi_a1, hi_a2, i), _pick(hi_a0, hi_a1, hi_a2, i1))
            lo_eb = wp.min(_pick(lo_b0, lo_b1, lo_b2, j), _pick(lo_b0, lo_b1, lo_b2, j1))
            hi_eb = wp.max(_pick(hi_b0, hi_b1, hi_b2, j), _pick(hi_b0, hi_b1, hi_b2, j1))
            near = not _apart(lo_ea, hi_ea, lo_eb, hi_eb, e)
        if near:
            kind, x0, x1 = pair_query(q, a0, a1, a2, b0, b1, b2, a0e, a1e, a2e, b0e, b1e, b2e)
            toi, ran_out = _search(kind, x0, x1, min_distance, tolerance, max_iterations, NO_HIT)
            if ran_out != 0 and defer:
                mask = mask | (1 << q)
            else:
                best = wp.min(best, toi)
    if best > _F1 and mask == 0:
        # Nothing before t = 1: the pair still collides when the discrete test finds it touching at
        # the end, so that a continuous frame holds what a discrete frame at either end holds.
        if pair_meets(a0_t1, a1_t1, a2_t1, b0_t1, b1_t1, b2_t1):
            best = _F1
    return best, mask


@wp.func
def triangle_pair_toi(a0_t0: Any, a1_t0: Any, a2_t0: Any, b0_t0: Any, b1_t0: Any, b2_t0: Any, a0_t1: Any,
                      a1_t1: Any, a2_t1: Any, b0_t1: Any, b1_t1: Any, b2_t1: Any, min_distance: wp.float64,
                      tolerance: wp.float64, max_iterations: int) -> wp.float64:
    """Earliest time in ``[0, 1]`` two moving closed triangles ``a`` and ``b`` touch: 0 when they
    already meet at ``t = 0`` (:func:`~warp_ccd.geometry.triangle.tri_tri_moller`, its tolerance),
    else the earliest toi of their 6 vertex-face and 9 edge-edge pairs, else 1 when they meet at
    ``t = 1`` (the discrete test again), else :data:`NO_HIT`.

    Two triangles that start apart can only come to meet through a vertex-face or an edge-edge
    contact, so this is their first contact (within ``min_distance``). Each query is searched on
    its own (a frame's second pass runs the long ones side by side, with the same answer).
    """
    toi, exhausted = pair_search(a0_t0, a1_t0, a2_t0, b0_t0, b1_t0, b2_t0, a0_t1, a1_t1, a2_t1, b0_t1, b1_t1, b2_t1,
                                 min_distance, tolerance, max_iterations, False)
    return toi
