"""Continuous collision of moving primitives: the earliest time a vertex meets a face, or an edge an edge.

Each vertex moves linearly from its position at ``t = 0`` to its position at ``t = 1``. A
vertex-face pair ``(p; f0, f1, f2)`` collides when at some ``t`` the point lies on the closed
triangle, an edge-edge pair ``(ea0, ea1; eb0, eb1)`` when the two closed segments meet; with a
minimum separation ``d``, when they come within ``d`` (in the infinity norm, so every pair within
Euclidean ``d`` is among them). The time of impact (toi) is the earliest such ``t``.

The method is Tight Inclusion's (Wang et al. 2021, "A Large Scale Benchmark and an Inclusion-Based
Algorithm for Continuous Collision Detection"), with its own certified error bound, a stackless
depth-first search, root proofs, and a certified coplanarity filter in front:

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
  derives them from the motion), or it certainly holds a root and its time width is within the
  tolerance's (:func:`~warp_ccd._src.geometry.ccd_boxes._proves_root`: the Poincare-Miranda test on
  ``F`` preconditioned by its inverse Jacobian, with margins for every rounding). An accepted box
  reports its least ``t``: the toi is never later than the true one, and a false positive lies
  within about ``tolerance`` of a true contact.
* The search is depth-first, lower halves first, and keeps going while a box could start earlier
  than the best toi found; the path back up is two bits a level, so it needs no stack: a thread
  holds three lower corners and three widths. Past ``max_iterations`` boxes the answer is a
  collision at the earliest time any unfinished box starts (conservative).
* At ``d = 0`` a contact needs the four points coplanar: the determinant of the query's three
  difference vectors, a cubic ``c(t)`` in Bernstein form with a certified error bound
  (:func:`_coplanarity`), must vanish. A query whose cubic keeps one sign over ``[0, 1]`` is ruled
  out at once (most queries of a frame). Otherwise the search walks dyadic time intervals earliest
  first, drops those over which ``c`` keeps one sign, halves the others down to the time
  tolerance, and there most often settles the interval with one test (:func:`_leaf_verdict`: a
  Miranda box around the point where ``F`` is least proves a contact; a plane that separates
  ``F``'s values over the interval from the origin proves none), else searches its boxes as
  above. A query costs tens of cheap steps instead of hundreds of boxes; the cubic and the plane
  only ever rule times out, and a contact only counts when proved, so the guarantees are the
  search's. A cubic near zero for long (a motion in one plane) falls back to
  the search over the whole box.

Every device gives the same answer: compile the calling module with ``fuse_fp=False`` (as this
module is), so that CUDA does not contract ``a * b + c`` into an FMA.

:func:`vertex_face_toi`, :func:`edge_edge_toi` and :func:`triangle_pair_toi` are the device
functions; :mod:`warp_ccd._src.queries.ccd` runs batches of queries from numpy (``ccd_queries``).
"""

from __future__ import annotations

import math
from typing import Any

import warp as wp

from .ccd_boxes import (
    _F0,
    _F1,
    _F2,
    _HALF,
    _INF,
    ERROR_FLOOR,
    ERROR_SCALE,
    ERROR_SCALE_ROTATED,
    KIND_EDGE_EDGE,
    KIND_VERTEX_FACE,
    MAT33D,
    MAT34D,
    MIRANDA_ROUNDING,
    WIDTH_MIN,
    _axis_range,
    _box_search,
    _is_upper_half,
    _linf,
    _max_abs4,
    _proves_root,
    _tol_div,
    _value,
)
from .primitives import _pick, _unit_normal
from .triangle import CONTACT_NONE, CONTACT_SEGMENT, TOLERANCE, _centre, _moller_steps, tri_tri_moller

wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = [
    "CCD_KINDS",
    "CCD_MAX_ITERATIONS",
    "CCD_TOLERANCE",
    "NO_HIT",
    "pair_meets",
    "pair_meets_common",
    "pair_near_mask",
    "pair_query",
    "pair_search",
    "query_excluded",
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

NO_HIT = wp.constant(wp.float64(math.inf))
"""The toi of a pair that never collides."""

CCD_KINDS = {"vertex_face": 0, "edge_edge": 1}
"""Query kinds of :func:`~warp_ccd._src.queries.ccd.ccd_queries` and their codes in the kernels."""

PAIR_QUERIES = 15
"""Primitive queries of a triangle pair: 3 + 3 vertex-face, 3 x 3 edge-edge."""

DISCRETE_PAD = wp.constant(wp.float64(2.0 * TOLERANCE * math.sqrt(3.0)))
"""Triangles whose boxes at ``t = 0`` are apart by more than this times their extent cannot meet in
the discrete test (its tolerance is ``TOLERANCE`` times their longest edge)."""

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


COPLANAR_ERROR = wp.constant(wp.float64(2.0**-44))
"""Certified error of a Bernstein coefficient of the coplanarity cubic (:func:`_coplanarity`),
relative to the cube of the largest absolute coordinate of its three difference vectors: a
determinant of float64 differences is within about ``50 * 2^-53`` of it; eightfold slack."""

BERNSTEIN_ROUNDING = wp.constant(wp.float64(2.0**-46))
"""Bound on the rounding of the cubic's Bernstein coefficients over a sub-interval (three convex
combinations, :func:`_blossom`), relative to the largest coefficient over ``[0, 1]``."""

COPLANAR_LEAVES = 8
"""Intervals of the coplanarity search narrowed down to the time tolerance before a query falls
back to the search over its whole box (a cubic that stays near zero over a long time: a motion in
or near one plane)."""

ONE_BELOW = wp.constant(wp.float64(1.0 - 2.0**-52))
"""A bound on a rounded sum that keeps the exact sum within 1."""

PROOF_HALF_WIDTH = wp.constant(wp.float64(2.0**-16))
"""Half width in ``u`` and ``v`` of the box :func:`_leaf_verdict` builds around the estimated contact."""


@wp.func
def _det3(a: wp.vec3d, b: wp.vec3d, c: wp.vec3d) -> wp.float64:
    return wp.dot(a, wp.cross(b, c))


@wp.func
def _coplanarity(kind: int, x0: MAT34D, x1: MAT34D):
    """Bernstein coefficients over ``[0, 1]`` of the cubic ``c(t)``, the determinant of the query's
    three difference vectors at ``t`` (``f1 - f0``, ``f2 - f0``, ``p - f0``; or ``ea1 - ea0``,
    ``eb1 - eb0``, ``eb0 - ea0``), zero exactly when the four points are coplanar, which every
    contact at ``min_distance = 0`` needs; and a bound on their error. Each difference moves
    linearly, so ``c``'s coefficients are the determinants of the ends' vectors taken from one end
    or the other, averaged (its blossom)."""
    # Static column indices only: a matrix indexed at run time would sit in a thread's local memory.
    a0 = _column(x0, 2) - _column(x0, 1)  # f1 - f0
    a1 = _column(x1, 2) - _column(x1, 1)
    b0 = _column(x0, 3) - _column(x0, 1)  # f2 - f0
    b1 = _column(x1, 3) - _column(x1, 1)
    q0 = _column(x0, 0) - _column(x0, 1)  # p - f0
    q1 = _column(x1, 0) - _column(x1, 1)
    if kind == KIND_EDGE_EDGE:
        a0 = _column(x0, 1) - _column(x0, 0)  # ea1 - ea0
        a1 = _column(x1, 1) - _column(x1, 0)
        b0 = _column(x0, 3) - _column(x0, 2)  # eb1 - eb0
        b1 = _column(x1, 3) - _column(x1, 2)
        q0 = _column(x0, 2) - _column(x0, 0)  # eb0 - ea0
        q1 = _column(x1, 2) - _column(x1, 0)
    third = wp.float64(1.0) / wp.float64(3.0)
    c = wp.vec4d(_det3(a0, b0, q0),
                 (_det3(a1, b0, q0) + _det3(a0, b1, q0) + _det3(a0, b0, q1)) * third,
                 (_det3(a0, b1, q1) + _det3(a1, b0, q1) + _det3(a1, b1, q0)) * third,
                 _det3(a1, b1, q1))
    m = wp.max(wp.max(_linf(a0), _linf(a1)), wp.max(wp.max(_linf(b0), _linf(b1)), wp.max(_linf(q0), _linf(q1))))
    big = wp.max(wp.max(wp.abs(c[0]), wp.abs(c[1])), wp.max(wp.abs(c[2]), wp.abs(c[3])))
    return c, COPLANAR_ERROR * m * m * m + BERNSTEIN_ROUNDING * big + ERROR_FLOOR


@wp.func
def _blossom(c: wp.vec4d, s1: wp.float64, s2: wp.float64, s3: wp.float64) -> wp.float64:
    """The blossom (polar form) of the cubic with Bernstein coefficients ``c`` at ``(s1, s2, s3)``."""
    d0 = c[0] + (c[1] - c[0]) * s1
    d1 = c[1] + (c[2] - c[1]) * s1
    d2 = c[2] + (c[3] - c[2]) * s1
    e0 = d0 + (d1 - d0) * s2
    e1 = d1 + (d2 - d1) * s2
    return e0 + (e1 - e0) * s3


@wp.func
def _one_signed_on(c: wp.vec4d, a: wp.float64, b: wp.float64, e: wp.float64) -> bool:
    """Whether the cubic keeps one sign over ``[a, b]``: its Bernstein coefficients there (its
    blossom at ``a`` and ``b``) all beyond ``e`` on one side (they bound it)."""
    c0 = _blossom(c, a, a, a)
    c1 = _blossom(c, a, a, b)
    c2 = _blossom(c, a, b, b)
    c3 = _blossom(c, b, b, b)
    if c0 > e and c1 > e and c2 > e and c3 > e:
        return True
    return c0 < -e and c1 < -e and c2 < -e and c3 < -e


@wp.func
def _hull_side(kind: int, x0: MAT34D, x1: MAT34D, a: wp.float64, b: wp.float64, lam: wp.vec3d,
               err: wp.vec3d) -> bool:
    """Whether ``lam . F`` is below zero, beyond its rounding, at every corner of the query's domain
    at both ends of the time interval ``[a, b]`` (the triangle's three corners of ``(u, v)``, or the
    square's four). ``F`` is affine in ``(u, v)`` at one time and in ``t`` at one ``(u, v)``, so its
    values over the interval and the whole domain lie in the convex hull of those points: then the
    hyperplane ``lam`` separates them all from the origin, and the interval holds no contact."""
    abs_lam = wp.vec3d(wp.abs(lam[0]), wp.abs(lam[1]), wp.abs(lam[2]))
    bound = _F2 * wp.dot(abs_lam, err) + ERROR_FLOOR
    scale = _F0
    worst = -_INF
    corners = 4
    if kind == KIND_VERTEX_FACE:
        corners = 3
    for end in range(2):
        t = wp.where(end == 0, a, b)
        for k in range(corners):
            u = wp.where(k == 1 or k == 3, _F1, _F0)
            v = wp.where(k >= 2, _F1, _F0)
            f = wp.vec3d(_value(kind, x0[0], x1[0], t, u, v), _value(kind, x0[1], x1[1], t, u, v),
                         _value(kind, x0[2], x1[2], t, u, v))
            value = wp.dot(lam, f)
            size = wp.dot(abs_lam, wp.vec3d(wp.abs(f[0]), wp.abs(f[1]), wp.abs(f[2])))
            if not (wp.isfinite(value) and wp.isfinite(size)):
                return False  # wp.max would pass over a nan
            worst = wp.max(worst, value)
            scale = wp.max(scale, size)
    return worst < -(bound + MIRANDA_ROUNDING * scale)


@wp.func
def _leaf_verdict(kind: int, x0: MAT34D, x1: MAT34D, a: wp.float64, wt: wp.float64, err: wp.vec3d) -> int:
    """What one test settles about the time interval ``[a, a + wt]``: 1, a contact certainly lies in
    it; -1, certainly none; 0, neither (its boxes are then searched).

    ``(u, v)`` solves ``F = 0`` in the least-squares sense at the interval's middle (``F`` is affine in
    ``(u, v)`` at one time). Inside the domain (by :data:`PROOF_HALF_WIDTH`), :func:`_proves_root`
    on the box of the interval and a square of that half width around it. Outside, the constraint
    it breaks most (``u >= 0``, ``v >= 0``, ``u + v <= 1`` or ``u, v <= 1``), preconditioned by the
    inverse Jacobian ``A`` (``A F`` is about ``(t - t*, u - u*, v - v*)``), gives the hyperplane of
    :func:`_hull_side`: all of the domain lies on the far side of that constraint's line."""
    tc = a + _HALF * wt
    f = wp.vec3d()
    fu = wp.vec3d()
    fv = wp.vec3d()
    ft = wp.vec3d()
    for ax in range(3):
        f[ax] = _value(kind, x0[ax], x1[ax], tc, _F0, _F0)
        fu[ax] = _value(kind, x0[ax], x1[ax], tc, _F1, _F0) - f[ax]
        fv[ax] = _value(kind, x0[ax], x1[ax], tc, _F0, _F1) - f[ax]
    uu = wp.dot(fu, fu)
    uv = wp.dot(fu, fv)
    vv = wp.dot(fv, fv)
    det = uu * vv - uv * uv
    if not (det > _F0):
        return 0
    pu = wp.dot(fu, f)
    pv = wp.dot(fv, f)
    u = (uv * pv - vv * pu) / det
    v = (uv * pu - uu * pv) / det
    h = PROOF_HALF_WIDTH
    u_lo = u - h
    v_lo = v - h
    u_hi = u_lo + _F2 * h
    v_hi = v_lo + _F2 * h
    inside = u_lo >= _F0 and v_lo >= _F0 and u_hi <= _F1 and v_hi <= _F1
    if kind == KIND_VERTEX_FACE:
        inside = inside and u_hi + v_hi <= ONE_BELOW  # the rounded sum within 1 - 2^-52: the exact one within 1
    if inside:
        if _proves_root(kind, x0, x1, wp.vec3d(a, u_lo, v_lo), wp.vec3d(wt, u_hi - u_lo, v_hi - v_lo), err):
            return 1
        return 0
    # The most broken constraint, as a row mu of the preconditioned coordinates (t, u, v).
    mu = wp.vec3d(_F0, -_F1, _F0)  # u >= 0
    worst = -u
    if -v > worst:
        mu = wp.vec3d(_F0, _F0, -_F1)  # v >= 0
        worst = -v
    if kind == KIND_VERTEX_FACE:
        if u + v - _F1 > worst:
            mu = wp.vec3d(_F0, _F1, _F1)  # u + v <= 1
    else:
        if u - _F1 > worst:
            mu = wp.vec3d(_F0, _F1, _F0)  # u <= 1
            worst = u - _F1
        if v - _F1 > worst:
            mu = wp.vec3d(_F0, _F0, _F1)  # v <= 1
    for ax in range(3):
        ft[ax] = _value(kind, x0[ax], x1[ax], _F1, u, v) - _value(kind, x0[ax], x1[ax], _F0, u, v)
    jac = wp.matrix_from_cols(ft, fu, fv)
    lam = wp.transpose(wp.inverse(jac)) @ mu  # lam . F = mu . (A F); any lam separates soundly
    if _hull_side(kind, x0, x1, a, a + wt, lam, err):
        return -1
    return 0


@wp.func
def _coplanar_search(kind: int, c: wp.vec4d, c_err: wp.float64, x0: MAT34D, x1: MAT34D, tol: wp.vec3d,
                     eps: wp.vec3d, err: wp.vec3d, tolerance: wp.float64, max_iterations: int,
                     t_end: wp.float64):
    """The search at ``min_distance = 0`` through the times the four points may be coplanar:
    ``(toi, steps, exhausted, fall back)``.

    A depth-first search over dyadic time intervals, earliest first, drops each interval over which
    the coplanarity cubic ``c`` (Bernstein coefficients, error ``c_err``) keeps one sign: no contact
    can happen there. An interval that it cannot drop is halved until it is no wider than the time
    tolerance ``tol[0]``; there, :func:`_leaf_verdict` proves a contact (its start is then the
    toi) or none, or else the boxes over that interval are searched (:func:`_box_search`). More than
    :data:`COPLANAR_LEAVES` such intervals (a cubic near zero for long): fall back (the caller runs
    the search over the whole box)."""
    a = _F0
    wt = _F1
    best = t_end
    steps = int(0)
    leaves = int(0)
    done = bool(False)
    while not done:
        descend = bool(False)
        if a < best:
            steps += 1
            b = a + wt
            if not _one_signed_on(c, a, b, c_err):
                if wt > tol[0] and wt > WIDTH_MIN:
                    descend = True
                else:
                    leaves += 1
                    if leaves > COPLANAR_LEAVES:
                        return best, steps, int(0), int(1)
                    verdict = _leaf_verdict(kind, x0, x1, a, wt, err)
                    if verdict > 0:
                        best = a
                    elif verdict == 0:
                        found, boxes, ran_out = _box_search(kind, x0, x1, wp.vec3d(a, _F0, _F0),
                                                            wp.vec3d(wt, _F1, _F1), tol, eps, err, tolerance,
                                                            wp.max(max_iterations - steps, 1), best, False)
                        steps += boxes
                        best = found
                        if ran_out != 0:
                            return wp.min(best, b), steps, int(1), int(0)
            if steps >= max_iterations:
                # Out of budget: a collision no earlier than any interval not yet finished (this
                # one when it was to be halved, else the ones after it).
                return wp.min(best, wp.where(descend, a, b)), steps, int(1), int(0)
        if descend:
            wt = wt * _HALF
        else:
            climbing = bool(True)
            while climbing:
                if wt >= _F1:
                    climbing = False
                    done = True
                elif _is_upper_half(a, wt):
                    a = a - wt
                    wt = wt * _F2
                else:
                    a = a + wt
                    climbing = False
    return best, steps, int(0), int(0)


@wp.func
def _filters(kind: int, x0: MAT34D, x1: MAT34D, min_distance: wp.float64):
    """A query's filters: ``(excluded, c, c_err)``, whether they rule out any contact
    (:func:`query_excluded`), and the coplanarity cubic they computed (at ``min_distance = 0``;
    zeros otherwise), which the search goes on with."""
    c = wp.vec4d()
    c_err = _F0
    if min_distance == _F0:
        c, c_err = _coplanarity(kind, x0, x1)
        if _one_signed_on(c, _F0, _F1, c_err):
            return True, c, c_err
    lo = wp.vec3d(_F0, _F0, _F0)
    w = wp.vec3d(_F1, _F1, _F1)
    for ax in range(3):
        e = ERROR_SCALE * _max_abs4(x0[ax], x1[ax]) + ERROR_FLOOR + min_distance
        fl, fh, change = _axis_range(kind, x0[ax], x1[ax], lo, w)
        if fl > e or fh < -e:
            return True, c, c_err
    return False, c, c_err


@wp.func
def query_excluded(kind: int, x0: MAT34D, x1: MAT34D, min_distance: wp.float64) -> bool:
    """Whether a query's filters rule out any contact: at ``min_distance = 0`` the coplanarity cubic
    keeps one sign over ``[0, 1]`` (:func:`_coplanarity`: the four points are never coplanar, most
    queries of a frame), or ``F`` over the whole box of parameters stays beyond ``min_distance``
    plus the rounding on one axis."""
    excluded, c, c_err = _filters(kind, x0, x1, min_distance)
    return excluded


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
        max_iterations: most boxes (and coplanarity intervals) examined.
        t_end: only times before it are searched (:data:`NO_HIT` for all of ``[0, 1]``; a smaller
            value when an earlier query already found that toi).
    """
    excluded, c, c_err = _filters(kind, x0, x1, min_distance)  # the cubic in world axes, before the rotation
    if excluded:
        return t_end, int(0)
    err = wp.vec3d()
    for ax in range(3):
        err[ax] = ERROR_SCALE * _max_abs4(x0[ax], x1[ax]) + ERROR_FLOOR
    eps = err + wp.vec3d(min_distance, min_distance, min_distance)
    lo = wp.vec3d(_F0, _F0, _F0)
    w = wp.vec3d(_F1, _F1, _F1)
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
            err = wp.vec3d(e, e, e)
            eps = err
    # Parameter tolerances from the whole box (Tight Inclusion's compute_*_tolerances: the tolerance
    # over three times the longest edge of F's box along each parameter, in the infinity norm;
    # infinite along a parameter F does not depend on); in the contact frame the box is tested again
    # (the world's axes were, by _filters).
    longest = wp.vec3d()
    for ax in range(3):
        fl, fh, change = _axis_range(kind, x0[ax], x1[ax], lo, w)
        if fl > eps[ax] or fh < -eps[ax]:
            return t_end, int(0)
        longest = wp.max(longest, change)
    three = wp.float64(3.0)
    tol = wp.vec3d(_tol_div(tolerance, three * longest[0]), _tol_div(tolerance, three * longest[1]),
                   _tol_div(tolerance, three * longest[2]))
    used = int(0)
    if min_distance == _F0:
        best, used, exhausted, fall_back = _coplanar_search(kind, c, c_err, x0, x1, tol, eps, err, tolerance,
                                                            max_iterations, t_end)
        if fall_back == 0:
            return best, exhausted
        if used >= max_iterations:
            return _F0, int(1)  # nothing proved yet: the conservative answer is the start
    # Root proofs pay at min_distance 0 (a proved root is the contact); with a least distance the
    # first contact comes before any root, and the proofs only cost (they doubled the time of a query
    # set with d > 0 on a GPU: docs/site/architecture/continuous.md, "Root proofs").
    best, boxes, exhausted = _box_search(kind, x0, x1, lo, w, tol, eps, err, tolerance, max_iterations - used,
                                         t_end, min_distance == _F0)
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
def _beyond_reach(a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any) -> bool:
    """Whether two triangles' boxes are apart by more than the discrete test's reach
    (:data:`DISCRETE_PAD` times their extent): the test cannot find them touching."""
    lo_a = wp.min(wp.min(wp.vec3d(a0), wp.vec3d(a1)), wp.vec3d(a2))
    hi_a = wp.max(wp.max(wp.vec3d(a0), wp.vec3d(a1)), wp.vec3d(a2))
    lo_b = wp.min(wp.min(wp.vec3d(b0), wp.vec3d(b1)), wp.vec3d(b2))
    hi_b = wp.max(wp.max(wp.vec3d(b0), wp.vec3d(b1)), wp.vec3d(b2))
    pad = DISCRETE_PAD * _max3(wp.max(hi_a - lo_a, hi_b - lo_b))
    if _apart(lo_a, hi_a, lo_b, hi_b, wp.vec3d(pad, pad, pad)):
        return True
    return False


@wp.func
def pair_meets(a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any) -> bool:
    """The discrete test (:func:`~warp_ccd._src.geometry.triangle.tri_tri_moller`, its tolerance) on two
    triangles at one time, run only where their boxes come within twice its tolerance."""
    if _beyond_reach(a0, a1, a2, b0, b1, b2):
        return False
    return tri_tri_moller(a0, a1, a2, b0, b1, b2, type(a0[0])(TOLERANCE))


@wp.func
def _swept(p_t0: Any, p_t1: Any):
    """The box of a point over a linear motion (exact: a minimum and a maximum)."""
    return wp.min(p_t0, p_t1), wp.max(p_t0, p_t1)


@wp.func
def pair_near_mask(a0_t0: Any, a1_t0: Any, a2_t0: Any, b0_t0: Any, b1_t0: Any, b2_t0: Any, a0_t1: Any,
                   a1_t1: Any, a2_t1: Any, b0_t1: Any, b1_t1: Any, b2_t1: Any, min_distance: wp.float64) -> int:
    """Bit ``q`` set for each query (:func:`pair_query`) of two moving triangles whose two primitives'
    swept boxes come within ``eps + min_distance`` plus the discrete test's reach on every axis:
    the others have no root (their ``F`` lies in the difference of the boxes, whose one rounding is
    within ``eps``), so most of a candidate's 15 queries end at a few comparisons. The boxes are
    exact in the points' own precision (a minimum and a maximum); the comparisons are in float64."""
    lo_a0, hi_a0 = _swept(a0_t0, a0_t1)
    lo_a1, hi_a1 = _swept(a1_t0, a1_t1)
    lo_a2, hi_a2 = _swept(a2_t0, a2_t1)
    lo_b0, hi_b0 = _swept(b0_t0, b0_t1)
    lo_b1, hi_b1 = _swept(b1_t0, b1_t1)
    lo_b2, hi_b2 = _swept(b2_t0, b2_t1)
    tri_lo_a = wp.vec3d(wp.min(wp.min(lo_a0, lo_a1), lo_a2))
    tri_hi_a = wp.vec3d(wp.max(wp.max(hi_a0, hi_a1), hi_a2))
    tri_lo_b = wp.vec3d(wp.min(wp.min(lo_b0, lo_b1), lo_b2))
    tri_hi_b = wp.vec3d(wp.max(wp.max(hi_b0, hi_b1), hi_b2))
    m = wp.max(wp.max(_abs3(tri_lo_a), _abs3(tri_hi_a)), wp.max(_abs3(tri_lo_b), _abs3(tri_hi_b)))
    # The discrete test's reach too (DISCRETE_PAD times the triangles' extent, their swept boxes'
    # here, no smaller than at t = 1): see pair_search for why a row without near queries needs no
    # discrete test at t = 1.
    reach = DISCRETE_PAD * _max3(wp.max(tri_hi_a - tri_lo_a, tri_hi_b - tri_lo_b))
    pad = ERROR_FLOOR + min_distance + reach
    e = m * ERROR_SCALE + wp.vec3d(pad, pad, pad)
    mask = int(0)
    num_queries = int(PAIR_QUERIES)  # a loop, not 15 copies (Warp unrolls constant ranges)
    for q in range(num_queries):
        i = q % 3
        near = bool(False)
        if q < 3:  # vertex i of a against face b
            near = not _apart(wp.vec3d(_pick(lo_a0, lo_a1, lo_a2, i)), wp.vec3d(_pick(hi_a0, hi_a1, hi_a2, i)),
                              tri_lo_b, tri_hi_b, e)
        elif q < 6:  # vertex i of b against face a
            near = not _apart(wp.vec3d(_pick(lo_b0, lo_b1, lo_b2, i)), wp.vec3d(_pick(hi_b0, hi_b1, hi_b2, i)),
                              tri_lo_a, tri_hi_a, e)
        else:  # edge i of a against edge j of b
            i = (q - 6) // 3
            j = (q - 6) % 3
            i1 = (i + 1) % 3
            j1 = (j + 1) % 3
            lo_ea = wp.vec3d(wp.min(_pick(lo_a0, lo_a1, lo_a2, i), _pick(lo_a0, lo_a1, lo_a2, i1)))
            hi_ea = wp.vec3d(wp.max(_pick(hi_a0, hi_a1, hi_a2, i), _pick(hi_a0, hi_a1, hi_a2, i1)))
            lo_eb = wp.vec3d(wp.min(_pick(lo_b0, lo_b1, lo_b2, j), _pick(lo_b0, lo_b1, lo_b2, j1)))
            hi_eb = wp.vec3d(wp.max(_pick(hi_b0, hi_b1, hi_b2, j), _pick(hi_b0, hi_b1, hi_b2, j1)))
            near = not _apart(lo_ea, hi_ea, lo_eb, hi_eb, e)
        if near:
            mask = mask | (1 << q)
    return mask


MEETS_UNDECIDED = wp.constant(2)
""":func:`pair_meets_common`'s answer for a pair it leaves to :func:`pair_meets`."""


@wp.func
def pair_meets_common(a0: Any, a1: Any, a2: Any, b0: Any, b1: Any, b2: Any) -> int:
    """:func:`pair_meets` on its common path, as the discrete narrow phase's first kernel runs it
    (steps 1 to 3 of Möller's test, :func:`~warp_ccd._src.geometry.triangle._moller_steps`, on two
    triangles that are not degenerate): 1 they meet, 0 they do not, :data:`MEETS_UNDECIDED` for a
    pair only the whole test decides (a touching test, a coplanar or degenerate pair). A kernel
    that calls it leaves the whole test, and its registers, to another."""
    if _beyond_reach(a0, a1, a2, b0, b1, b2):
        return 0
    tol = type(a0[0])(TOLERANCE)
    na, degenerate_a = _unit_normal(a0, a1, a2, tol)
    nb, degenerate_b = _unit_normal(b0, b1, b2, tol)
    if degenerate_a or degenerate_b:
        return MEETS_UNDECIDED
    c0, c1, c2, d0, d1, d2, eps = _centre(a0, a1, a2, b0, b1, b2, tol)
    kind, p, q = _moller_steps(c0, c1, c2, d0, d1, d2, na, nb, eps)
    if kind == CONTACT_NONE:
        return 0
    if kind == CONTACT_SEGMENT:
        return 1
    return MEETS_UNDECIDED


@wp.func
def pair_search(a0_t0: Any, a1_t0: Any, a2_t0: Any, b0_t0: Any, b1_t0: Any, b2_t0: Any, a0_t1: Any, a1_t1: Any,
                a2_t1: Any, b0_t1: Any, b1_t1: Any, b2_t1: Any, min_distance: wp.float64, tolerance: wp.float64,
                max_iterations: int) -> wp.float64:
    """:func:`triangle_pair_toi` (its body): the discrete test at ``t = 0``; the queries of
    :func:`pair_near_mask`, each searched on its own (:func:`primitive_toi`); the discrete test at
    ``t = 1`` when none hits. A frame's narrow phase runs the same steps in passes
    (:mod:`warp_ccd._src.narrowphase.continuous`), with the same answer."""
    if pair_meets(a0_t0, a1_t0, a2_t0, b0_t0, b1_t0, b2_t0):
        return _F0
    mask = pair_near_mask(a0_t0, a1_t0, a2_t0, b0_t0, b1_t0, b2_t0, a0_t1, a1_t1, a2_t1, b0_t1, b1_t1, b2_t1,
                          min_distance)
    best = NO_HIT
    num_queries = int(PAIR_QUERIES)
    for q in range(num_queries):
        if (mask >> q) & 1 != 0:
            kind, x0, x1 = pair_query(q, wp.vec3d(a0_t0), wp.vec3d(a1_t0), wp.vec3d(a2_t0), wp.vec3d(b0_t0),
                                      wp.vec3d(b1_t0), wp.vec3d(b2_t0), wp.vec3d(a0_t1), wp.vec3d(a1_t1),
                                      wp.vec3d(a2_t1), wp.vec3d(b0_t1), wp.vec3d(b1_t1), wp.vec3d(b2_t1))
            best = wp.min(best, primitive_toi(kind, x0, x1, min_distance, tolerance, max_iterations, NO_HIT))
    if best > _F1 and mask != 0 and pair_meets(a0_t1, a1_t1, a2_t1, b0_t1, b1_t1, b2_t1):
        # Nothing before t = 1: the pair still collides when the discrete test finds it touching at
        # the end, so that a continuous frame holds what a discrete frame at either end holds. With
        # no near query it cannot: apart at t = 0, the triangles can only come to meet through a
        # vertex-face or edge-edge contact (a near query), so at t = 1 they are still apart, by the
        # least distance of their vertex-face and edge-edge pairs, each more than the discrete
        # test's reach (their boxes are).
        best = _F1
    return best


@wp.func
def triangle_pair_toi(a0_t0: Any, a1_t0: Any, a2_t0: Any, b0_t0: Any, b1_t0: Any, b2_t0: Any, a0_t1: Any,
                      a1_t1: Any, a2_t1: Any, b0_t1: Any, b1_t1: Any, b2_t1: Any, min_distance: wp.float64,
                      tolerance: wp.float64, max_iterations: int) -> wp.float64:
    """Earliest time in ``[0, 1]`` two moving closed triangles ``a`` and ``b`` touch: 0 when they
    already meet at ``t = 0`` (:func:`~warp_ccd._src.geometry.triangle.tri_tri_moller`, its tolerance),
    else the earliest toi of their 6 vertex-face and 9 edge-edge pairs, else 1 when they meet at
    ``t = 1`` (the discrete test again), else :data:`NO_HIT`.

    Two triangles that start apart can only come to meet through a vertex-face or an edge-edge
    contact, so this is their first contact (within ``min_distance``). Each query is searched on
    its own (a frame's second pass runs the long ones side by side, with the same answer).
    """
    return pair_search(a0_t0, a1_t0, a2_t0, b0_t0, b1_t0, b2_t0, a0_t1, a1_t1, a2_t1, b0_t1, b1_t1, b2_t1,
                       min_distance, tolerance, max_iterations)
