"""The inclusion search of one continuous-collision query over boxes of its parameters.

A query (:mod:`warp_ccd._src.geometry.ccd`) is the function ``F(t, u, v)`` of its four moving points,
multilinear in ``(t, u, v)``; each coordinate of ``F`` over a box of parameters lies between its
least and greatest value at the box's eight corners (:func:`_axis_range`). :func:`_box_search` is
the depth-first search over dyadic boxes, lower halves first, that rejects a box whose corners all
lie beyond the rounding (and the least distance) on one axis, splits the others, and accepts a box
that is small enough (the tolerance) or that certainly holds a root (:func:`_proves_root`: the
Poincare-Miranda test on ``F`` preconditioned by the inverse of its Jacobian). Corner values are
float64, each within ``ERROR_SCALE`` times the largest coordinate of the query on its axis of the
true one (``docs/ARCHITECTURE.md``, "Continuous collision").

Compiled without floating-point contraction (``fuse_fp=False``), as every module that calls it, so
that every device gives the same answers.
"""

import math

import warp as wp

wp.set_module_options({"enable_backward": False, "fuse_fp": False})

KIND_VERTEX_FACE = wp.constant(0)
KIND_EDGE_EDGE = wp.constant(1)

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
def _value(kind: int, x0: wp.vec4d, x1: wp.vec4d, t: wp.float64, u: wp.float64, v: wp.float64) -> wp.float64:
    """One coordinate of ``F`` at ``(t, u, v)``."""
    return _corner(kind, _lerp(x0[0], x1[0], t), _lerp(x0[1], x1[1], t), _lerp(x0[2], x1[2], t),
                   _lerp(x0[3], x1[3], t), u, v)


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

MIRANDA_ROUNDING = wp.constant(wp.float64(2.0**-48))
"""Bound on the rounding of one preconditioned value ``sum_j A_ij F_j`` (three products and two sums
in float64: about ``3 * 2^-53``; tenfold slack), relative to ``sum_j |A_ij| |F_j|`` at that corner."""


@wp.func
def _proves_root(kind: int, x0: MAT34D, x1: MAT34D, lo: wp.vec3d, w: wp.vec3d, err: wp.vec3d) -> bool:
    """Whether the box ``[lo, lo + w]`` certainly holds a root of ``F`` (a contact at some ``t`` in
    it): the Poincare-Miranda test on ``G = A F``, ``A`` the inverse of ``F``'s Jacobian at the box's
    centre (any invertible ``A`` will do: ``G`` and ``F`` have the same roots). When for each
    parameter ``G``'s coordinate of that parameter is negative on one of its two faces and positive
    on the other, ``G`` has a root in the box. ``F`` is multilinear, so each coordinate of ``G`` is
    too and takes its extremes over a face at the face's four corners; ``err`` bounds the error of
    a corner value of ``F`` per axis, and the test asks for a margin that covers it through ``A`` and
    the rounding of ``A F``. ``A`` is invertible when ``|A J - I| < 1`` (checked, with room for
    rounding). A box of a vertex-face query must lie inside the triangle ``u + v <= 1``.

    Lean on registers (it runs inside the searches): ``G``'s corner values are recomputed for each
    of its coordinates rather than held."""
    u_hi = lo[1] + w[1]
    v_hi = lo[2] + w[2]
    if kind == KIND_VERTEX_FACE and u_hi + v_hi > _F1:
        return False
    t_hi = lo[0] + w[0]
    tc = lo[0] + _HALF * w[0]
    uc = lo[1] + _HALF * w[1]
    vc = lo[2] + _HALF * w[2]
    jac = MAT33D()
    for ax in range(3):
        # F is linear along each parameter: its derivative is a difference of two values.
        jac[ax, 0] = _value(kind, x0[ax], x1[ax], _F1, uc, vc) - _value(kind, x0[ax], x1[ax], _F0, uc, vc)
        jac[ax, 1] = _value(kind, x0[ax], x1[ax], tc, _F1, vc) - _value(kind, x0[ax], x1[ax], tc, _F0, vc)
        jac[ax, 2] = _value(kind, x0[ax], x1[ax], tc, uc, _F1) - _value(kind, x0[ax], x1[ax], tc, uc, _F0)
    a = wp.inverse(jac)
    r = a @ jac
    for i in range(3):
        row = wp.abs(r[i, 0] - wp.where(i == 0, _F1, _F0)) + wp.abs(r[i, 1] - wp.where(i == 1, _F1, _F0)) + \
            wp.abs(r[i, 2] - wp.where(i == 2, _F1, _F0))
        # Each row on its own (wp.max would pass over a nan): false for a singular Jacobian
        # (inverse 0) and for nan.
        if not (row <= _HALF):
            return False
    for i in range(3):
        ai = wp.vec3d(a[i, 0], a[i, 1], a[i, 2])
        absa = wp.vec3d(wp.abs(ai[0]), wp.abs(ai[1]), wp.abs(ai[2]))
        low_min = _INF
        low_max = -_INF
        high_min = _INF
        high_max = -_INF
        scale = _F0
        for corner in range(8):
            t = wp.where((corner & 4) == 0, lo[0], t_hi)
            u = wp.where((corner & 1) == 0, lo[1], u_hi)
            v = wp.where((corner & 2) == 0, lo[2], v_hi)
            f = wp.vec3d(_value(kind, x0[0], x1[0], t, u, v), _value(kind, x0[1], x1[1], t, u, v),
                         _value(kind, x0[2], x1[2], t, u, v))
            g = ai[0] * f[0] + ai[1] * f[1] + ai[2] * f[2]
            scale = wp.max(scale, wp.dot(absa, wp.vec3d(wp.abs(f[0]), wp.abs(f[1]), wp.abs(f[2]))))
            # The face of parameter i this corner lies on: t (bit 4), u (bit 1), v (bit 2).
            on_high = (i == 0 and (corner & 4) != 0) or (i == 1 and (corner & 1) != 0) or \
                (i == 2 and (corner & 2) != 0)
            if on_high:
                high_min = wp.min(high_min, g)
                high_max = wp.max(high_max, g)
            else:
                low_min = wp.min(low_min, g)
                low_max = wp.max(low_max, g)
        margin = _F2 * wp.dot(absa, err) + MIRANDA_ROUNDING * scale + ERROR_FLOOR
        if not ((low_max < -margin and high_min > margin) or (low_min > margin and high_max < -margin)):
            return False
    return True


@wp.func
def _box_search(kind: int, x0: MAT34D, x1: MAT34D, start_lo: wp.vec3d, start_w: wp.vec3d, tol: wp.vec3d,
                eps: wp.vec3d, err: wp.vec3d, tolerance: wp.float64, max_iterations: int, best_in: wp.float64,
                prove: bool):
    """The depth-first search over the boxes under ``[start_lo, start_lo + start_w]`` (a dyadic box)
    for a toi before ``best_in``: ``(toi, boxes examined, whether it ran out of max_iterations)``.
    ``tol``: the parameter widths the tolerance asks for; ``eps``: the margin of a rejection per axis
    (rounding and least distance); ``err``: the rounding alone (:func:`_proves_root`); ``prove``:
    whether a box that is not settled is tested for a root (a search over a whole box; a search
    over one narrow time interval whose root proof failed skips the test, which would fail again)."""
    lo = wp.vec3d(start_lo)
    w = wp.vec3d(start_w)
    path = _path_t()
    depth = int(0)
    best = best_in
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
                    elif prove and _proves_root(kind, x0, x1, lo, w, err):
                        # A contact lies in the box: only its time needs narrowing (accepted once
                        # its t-width is within the tolerance's).
                        if w[0] > tol[0] and w[0] > WIDTH_MIN:
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
    return best, iterations, exhausted
