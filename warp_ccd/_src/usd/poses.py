"""World matrices as USD writes them (row vectors, ``p_world = p M``) split into poses and uniform scales.

numpy over many objects at once, no ``pxr``: :func:`similarity_split` finds the linear parts that are
a rotation times a uniform scale, :func:`baked_linear` the linear parts baked into the shapes (those
that are not), :func:`matrix_poses` turns world matrices into ``wp.transform`` rows and scales relative
to the linear parts baked into the shapes, and :func:`finite_matrix_poses` does so where the matrices
are finite and says which are. :func:`affine_poses` is the same split for transforms given as their
linear parts and translations component by component (``(3, 3, ...)`` and ``(3, ...)``: one array per
entry over every object and time code), as :mod:`~warp_ccd._src.usd.xforms` composes them: each step is a
pass over the arrays, with no ``(K, 3, 3)`` products of tiny matrices. Used by the import
(:mod:`~warp_ccd._src.usd.importer`), the bulk transform reader and its worker processes
(:mod:`~warp_ccd._src.usd.workers`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["SIMILARITY_TOLERANCE", "affine_poses", "baked_linear", "compose_ops", "finite_matrix_poses", "lerp_samples",
           "matrix_poses", "mul3", "op_transform", "sample_brackets", "similarity_split"]

SIMILARITY_TOLERANCE = 1e-5
"""Relative tolerance within which a transform's linear part counts as a rotation times a uniform scale."""

SINGULAR_DETERMINANT = 1e-30
"""A linear part whose ``|det|`` is at most this is singular: nothing is baked for it."""

_DEG = np.pi / 180.0  # GfDegreesToRadians
_RAD = 180.0 / np.pi  # GfRadiansToDegrees
_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


def _split(lin, tol: float):
    """:func:`similarity_split` of linear parts given entry by entry (``lin[i][j]``: arrays of one
    shape): ``(scale, ok, det)``."""
    (a, b, c), (d, e, f), (g, h, i) = lin
    g00 = a * a + b * b + c * c
    g11 = d * d + e * e + f * f
    g22 = g * g + h * h + i * i
    s2 = (g00 + g11 + g22) / 3.0
    dev = np.maximum(np.maximum(np.abs(g00 - s2), np.abs(g11 - s2)), np.abs(g22 - s2))
    for off in (a * d + b * e + c * f, a * g + b * h + c * i, d * g + e * h + f * i):
        dev = np.maximum(dev, np.abs(off))
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    with np.errstate(invalid="ignore"):
        ok = (s2 > 1e-30) & (det > 0) & (dev <= tol * np.maximum(s2, 1e-300))
    return np.sqrt(np.maximum(s2, 0.0)), ok, det


def similarity_split(linear: np.ndarray, tol: float = SIMILARITY_TOLERANCE) -> tuple:
    """Splits ``(K, 3, 3)`` linear parts (row vectors) into ``scale * rotation`` where they are one.

    Returns:
        ``(scale (K,), rotation (K, 3, 3), ok (K,) bool)``; ``ok`` is False for a non-uniform
        scale, a shear, a reflection or a (near) zero scale.
    """
    linear = np.asarray(linear, np.float64)
    scale, ok, _ = _split([[linear[:, r, c] for c in range(3)] for r in range(3)], tol)
    rotation = linear / np.where(scale > 0, scale, 1.0)[:, None, None]
    return scale, rotation, ok


def baked_linear(first: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The linear parts baked into the shapes: the world matrix's own where it is not a rotation
    times a uniform scale (and not singular), identity elsewhere.

    Args:
        first: ``(K, 4, 4)`` world matrices at the first time code (row vectors).

    Returns:
        ``(bake (K, 3, 3), similar (K,) bool)``: ``similar`` where the linear part is a similarity.
    """
    lin = np.asarray(first, np.float64)[:, :3, :3]
    _, ok, det = _split([[lin[:, r, c] for c in range(3)] for r in range(3)], SIMILARITY_TOLERANCE)
    keep = ok | (np.abs(det) <= SINGULAR_DETERMINANT) | ~np.isfinite(det)
    return np.where(keep[:, None, None], np.eye(3), lin), ok


def _quaternions(r, shape) -> np.ndarray:
    """Unit quaternions ``(x, y, z, w)`` of rotations acting on column vectors, given entry by entry
    (``r[i][j]``: arrays of ``shape``), as :func:`~warp_ccd._src.scene.scene.matrix_to_quat` computes them
    (the same four cases, each on its own elements): ``(*shape, 4)`` float64."""
    r = [[np.broadcast_to(np.asarray(r[i][j], np.float64), shape).ravel() for j in range(3)] for i in range(3)]
    n = r[0][0].size
    q = np.empty((4, n))
    tr = r[0][0] + r[1][1] + r[2][2]
    d0, d1, d2 = r[0][0], r[1][1], r[2][2]
    case = np.where(d0 >= d1, np.where(d0 >= d2, 0, 2), np.where(d1 >= d2, 1, 2))
    case[tr > np.maximum(np.maximum(d0, d1), d2)] = 3
    for c in range(4):
        at = np.nonzero(case == c)[0]
        if not at.size:
            continue

        def e(i: int, j: int, at=at) -> np.ndarray:
            return r[i][j][at]

        if c == 3:
            s = np.sqrt(1.0 + tr[at]) * 2.0
            q[0, at] = (e(2, 1) - e(1, 2)) / s
            q[1, at] = (e(0, 2) - e(2, 0)) / s
            q[2, at] = (e(1, 0) - e(0, 1)) / s
            q[3, at] = s / 4
        else:
            i, j, k = c, (c + 1) % 3, (c + 2) % 3
            s = np.sqrt(1.0 + e(i, i) - e(j, j) - e(k, k)) * 2.0
            q[i, at] = s / 4
            q[j, at] = (e(j, i) + e(i, j)) / s
            q[k, at] = (e(k, i) + e(i, k)) / s
            q[3, at] = (e(k, j) - e(j, k)) / s
    q /= np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return np.moveaxis(q, 0, -1).reshape(*shape, 4)


def affine_poses(linear: list, translation: list, bake_inverse: list | None = None) -> tuple[np.ndarray, np.ndarray,
                                                                                         np.ndarray]:
    """Poses and scales of affine transforms given entry by entry, relative to baked linear parts.

    Args:
        linear: ``linear[i][j]``, arrays broadcasting to one shape ``S`` (objects by time codes, say):
            entry ``(i, j)`` of the linear part (row vectors).
        translation: ``translation[j]``, arrays broadcasting to ``S``: the translation row.
        bake_inverse: ``bake_inverse[i][j]``, arrays broadcasting to ``S``: the inverse of the linear
            part baked into each shape, or None where nothing is baked.

    Returns:
        ``(poses (*S, 7) float64 rows (p, q xyzw), scale S, ok S bool)``, as :func:`matrix_poses`.
    """
    shape = np.broadcast_shapes(*(np.shape(x) for row in linear for x in row), *(np.shape(x) for x in translation))
    if bake_inverse is not None:  # bake^-1 A, entry by entry
        linear = [[bake_inverse[i][0] * linear[0][j] + bake_inverse[i][1] * linear[1][j]
                   + bake_inverse[i][2] * linear[2][j] for j in range(3)] for i in range(3)]
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        scale, ok, _ = _split(linear, SIMILARITY_TOLERANCE)
        scale, ok = np.broadcast_to(scale, shape), np.broadcast_to(ok, shape)
        inv = 1.0 / np.where(ok, scale, 1.0)
        # Row-vector rotation R acts as R^T on column vectors (wp.transform_point): r[i][j] = R[j][i].
        # Where the part is no similarity, the identity's quaternion replaces whatever came out.
        quat = _quaternions([[linear[j][i] * inv for j in range(3)] for i in range(3)], shape)
    if not ok.all():
        quat[~ok] = (0.0, 0.0, 0.0, 1.0)
    poses = np.empty((*shape, 7))
    for j in range(3):
        poses[..., j] = translation[j]
    poses[..., 3:] = quat
    return poses, np.array(scale, np.float64), np.array(ok)


def matrix_poses(matrix: np.ndarray, bake: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses and scales of world matrices relative to baked linear parts.

    Args:
        matrix: ``(K, 4, 4)`` world matrices (row vectors).
        bake: ``(K, 3, 3)`` linear parts baked into the shapes (identity where nothing is baked).

    Returns:
        ``(poses (K, 7) float64 rows (p, q xyzw), scale (K,), ok (K,) bool)``: ``p_world =
        transform_point(pose, scale * (p bake))`` where ``ok``.
    """
    matrix = np.asarray(matrix, np.float64)
    lin = [[matrix[:, i, j] for j in range(3)] for i in range(3)]
    baked = ~(bake == np.eye(3)).all(axis=(1, 2))
    if baked.any():  # bake^-1 A: p A = (p bake) (bake^-1 A)
        rel = matrix[:, :3, :3].copy()
        rel[baked] = np.linalg.solve(bake[baked], matrix[baked, :3, :3])
        lin = [[rel[:, i, j] for j in range(3)] for i in range(3)]
    return affine_poses(lin, [matrix[:, 3, j] for j in range(3)])


def finite_matrix_poses(matrix: np.ndarray, bake: np.ndarray) -> tuple:
    """:func:`matrix_poses` of the finite ``matrix`` rows (identity in place of the others): ``(finite (K,)
    bool, poses, scale, ok)``; the caller names a prim whose transform is not finite."""
    finite = np.isfinite(matrix).all(axis=(1, 2))
    return (finite, *matrix_poses(np.where(finite[:, None, None], matrix, np.eye(4)), bake))


# ---------------------------------------------------------------------- USD's op matrices, entry by entry
def mul3(a: list, b: list) -> list:
    """Product ``a @ b`` of two 3x3 matrices given entry by entry: ``a[i][j]`` arrays (or numbers) that
    broadcast together; the sums in order ``k = 0, 1, 2``, as ``GfMatrix`` multiplies."""
    return [[a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j] for j in range(3)] for i in range(3)]


def _quat_matrix(r, x, y, z):
    """``GfMatrix3d::_SetRotateFromQuat`` (real ``r``, imaginary ``(x, y, z)``), entry by entry."""
    return [[1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + z * r), 2.0 * (z * x - y * r)],
            [2.0 * (x * y - z * r), 1.0 - 2.0 * (z * z + x * x), 2.0 * (y * z + x * r)],
            [2.0 * (z * x + y * r), 2.0 * (y * z - x * r), 1.0 - 2.0 * (y * y + x * x)]]


def _axis_angle(ax, ay, az, degrees):
    """``GfRotation(axis, degrees)`` (a unit axis) as a matrix, through ``GetQuat`` as USD computes it:
    the half angle's sine and cosine, the quaternion normalised."""
    half = degrees * _DEG / 2.0
    s, c = np.sin(half), np.cos(half)
    x, y, z = ax * s, ay * s, az * s
    length = np.sqrt(x * x + y * y + z * z + c * c)
    tiny = length < 1e-10
    if tiny.any():  # GetNormalized: identity below GF_MIN_VECTOR_LENGTH
        c, length = np.where(tiny, 1.0, c), np.where(tiny, 1.0, length)
        x, y, z = (np.where(tiny, 0.0, u) for u in (x, y, z))
    return _quat_matrix(c / length, x / length, y / length, z / length)


def _orient(v, inverse: bool):
    """``GfRotation(GfQuatd(q))`` as a matrix (``SetQuat``: the axis the normalised imaginary part, the
    angle ``2 acos(real)``; identity for an imaginary part shorter than 1e-10), inverted by negating
    the angle. ``v``: ``(..., 4)`` float64 ``(i, j, k, real)``."""
    x, y, z, r = np.moveaxis(v, -1, 0).copy()  # one contiguous array per component
    length = np.sqrt(x * x + y * y + z * z)
    valid = length > 1e-10
    everywhere = valid.all()
    inv_len = 1.0 / (length if everywhere else np.where(valid, length, 1.0))
    degrees = 2.0 * (np.arccos(np.clip(r, -1.0, 1.0)) * _RAD)
    m = _axis_angle(x * inv_len, y * inv_len, z * inv_len, -degrees if inverse else degrees)
    return m if everywhere else [[np.where(valid, m[i][j], float(i == j)) for j in range(3)] for i in range(3)]


def op_transform(op_type: str, inverse: bool, v: np.ndarray) -> tuple:
    """An xform op's transform as ``UsdGeomXformOp::GetOpTransform`` builds it, entry by entry.

    Args:
        op_type: ``translate``, ``translateX``, ``scale``, ``rotateY``, ``rotateXYZ``, ``orient``, ``transform``, ...
        inverse: an inverse op (``!invert!``).
        v: ``(..., k)`` float64 values: ``k`` 1 (single axis), 3 (vectors, three-axis angles in degrees), 4
            (quaternions ``(i, j, k, real)``) or 16 (a row-major matrix, affine).

    Returns:
        ``("t", translation)``, ``("d", diagonal)``, ``("m", 3x3)`` or ``("a", 3x3, translation)``: lists of
        arrays of shape ``v.shape[:-1]`` (row vectors: ``p' = p M``).
    """
    if op_type in ("translate", "translateX", "translateY", "translateZ"):
        if op_type == "translate":
            t = [v[..., 0], v[..., 1], v[..., 2]]
        else:
            t = [v[..., 0] * 0.0 if a != op_type[-1] else v[..., 0] for a in "XYZ"]
        return ("t", [-x for x in t] if inverse else t)
    if op_type in ("scale", "scaleX", "scaleY", "scaleZ"):
        d = [v[..., 0], v[..., 1], v[..., 2]] if op_type == "scale" else \
            [v[..., 0] if a == op_type[-1] else v[..., 0] * 0.0 + 1.0 for a in "XYZ"]
        return ("d", [1.0 / x for x in d] if inverse else d)
    if op_type in ("rotateX", "rotateY", "rotateZ"):
        return ("m", _axis_angle(*_AXES[op_type[-1]], -v[..., 0] if inverse else v[..., 0]))
    if op_type == "orient":
        return ("m", _orient(v, inverse))
    if op_type == "transform":
        m = v.reshape(*v.shape[:-1], 4, 4)
        lin, t = m[..., :3, :3], m[..., 3, :3]
        if inverse:
            lin = np.linalg.inv(lin)
            t = -np.einsum("...j,...jk->...k", t, lin)
        return ("a", [[lin[..., i, j] for j in range(3)] for i in range(3)], [t[..., j] for j in range(3)])
    order = op_type[len("rotate"):]  # three-axis rotations: one GfRotation per axis, multiplied in order
    mats = {a: _axis_angle(*_AXES[a], -v[..., i] if inverse else v[..., i]) for i, a in enumerate("XYZ")}
    seq = order[::-1] if inverse else order
    return ("m", mul3(mul3(mats[seq[0]], mats[seq[1]]), mats[seq[2]]))


def compose_ops(ops: list) -> tuple:
    """A local transform from its ops' transforms, as ``UsdGeomXformable`` composes them: ``M = I; M = M @ op``
    for each op in order (the ops of an op order, last first), the affine part only. Products that only
    multiply by one or add zero are skipped (their results are the same).

    Args:
        ops: :func:`op_transform` results, in composition order.

    Returns:
        ``(linear, translation)``: the 3x3 entry by entry (None for identity) and the translation row (None
        for zero), arrays broadcasting to the ops' shapes.
    """
    lin, diag, t = None, None, None  # lin: full 3x3; diag: a diagonal; neither: identity
    for op in ops:
        if op[0] == "t":
            t = op[1] if t is None else [t[j] + op[1][j] for j in range(3)]
            continue
        if op[0] == "d":
            d = op[1]
            if lin is not None:
                lin = [[lin[i][j] * d[j] for j in range(3)] for i in range(3)]
            else:
                diag = d if diag is None else [diag[j] * d[j] for j in range(3)]
            if t is not None:
                t = [t[j] * d[j] for j in range(3)]
            continue
        m = op[1]
        if lin is not None:
            lin = mul3(lin, m)
        elif diag is not None:
            lin = [[diag[i] * m[i][j] for j in range(3)] for i in range(3)]
        else:
            lin = m
        diag = None
        if t is not None:
            t = [t[0] * m[0][j] + t[1] * m[1][j] + t[2] * m[2][j] for j in range(3)]
        if op[0] == "a":
            t = op[2] if t is None else [t[j] + op[2][j] for j in range(3)]
    if lin is None and diag is not None:
        zero = diag[0] * 0.0
        lin = [[diag[i] if i == j else zero for j in range(3)] for i in range(3)]
    return lin, t


# ---------------------------------------------------------------------- time samples
def sample_brackets(keys: np.ndarray, lt: np.ndarray, times: np.ndarray, offset: tuple, held: bool) -> tuple:
    """USD's bracketing samples of time codes among one spec's sorted sample times, and how it mixes them.

    Args:
        keys: ``(n,)`` sample times (layer time), sorted.
        lt: ``(F,)`` the time codes in layer time.
        times: ``(F,)`` the time codes (stage time).
        offset: ``(scale, offset)`` of the layer offset (stage time = layer time * scale + offset).
        held: held interpolation.

    Returns:
        ``(lower (F,), upper (F,), alpha (F,), lerp (F,) bool)``: the value is sample ``lower`` where ``lerp``
        is False (on a sample, before the first, after the last, held interpolation, samples closer than
        1e-6 in layer time, ``alpha`` 0), else ``lerp(alpha, lower, upper)``, ``alpha`` from the samples'
        stage times as ``Usd_Interpolate`` takes it.
    """
    n = keys.size
    i = np.searchsorted(keys, lt, side="left")  # keys[i - 1] < lt <= keys[i]
    hi = np.minimum(i, n - 1)
    lo = np.where(keys[hi] == lt, hi, np.maximum(i - 1, 0))
    first, last = lt <= keys[0], lt >= keys[-1]
    lo = np.where(first, 0, np.where(last, n - 1, lo))
    hi = np.where(first, 0, np.where(last, n - 1, hi))
    lerp = ~(np.abs(keys[lo] - keys[hi]) < 1e-6) & (not held)
    stage = keys * offset[0] + offset[1]
    lower, upper = stage[lo], stage[hi]
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = np.where(lerp, (times - lower) / np.where(lerp, upper - lower, 1.0), 0.0)
    lerp &= alpha != 0.0
    return lo, hi, alpha, lerp


def lerp_samples(kind: str, code: str, a: np.ndarray, b: np.ndarray, alpha: np.ndarray) -> np.ndarray | None:
    """``Usd_Lerp(alpha, a, b)`` in the value's own precision (``code`` ``d`` or ``f``; ``alpha`` broadcasts
    against the values' leading axes): ``GfLerp`` component by component, ``GfSlerp`` for quaternions.
    None where it cannot be reproduced (a ``quatf`` slerp without the C library's ``sinf``)."""
    al = alpha[..., None]
    if kind == "quat":
        return _slerp(code, a, b, al)
    if code == "d" or kind == "scalar":  # a float scalar: computed in double, rounded once
        out = (1 - al) * a.astype(np.float64) + al * b.astype(np.float64)
        return out.astype(a.dtype)
    # GfVec3f: each product rounded to float, then a float sum
    return ((1 - al) * a.astype(np.float64)).astype(np.float32) + (al * b.astype(np.float64)).astype(np.float32)


def _c_sinf():
    """The C library's ``sinf`` (what ``GfSlerp`` of ``quatf`` calls for the sine of its angle), or None."""
    try:
        import ctypes

        sinf = ctypes.CDLL(None).sinf
    except (OSError, AttributeError, TypeError):
        return None
    sinf.restype, sinf.argtypes = ctypes.c_float, [ctypes.c_float]
    return sinf


_SINF = _c_sinf()


def _slerp(code: str, q0: np.ndarray, q1: np.ndarray, alpha: np.ndarray) -> np.ndarray | None:
    """``GfSlerp(alpha, q0, q1)`` of ``(..., 4)`` quaternions ``(i, j, k, real)``. For ``quatf`` as USD's float
    arithmetic goes: the dot product in float, the angle rounded to float, its sine the C library's
    ``sinf`` (one call per distinct angle), the two weights rounded to float, then a float sum."""
    cos = (q0[..., 0] * q1[..., 0] + q0[..., 1] * q1[..., 1] + q0[..., 2] * q1[..., 2]) + q0[..., 3] * q1[..., 3]
    cos = cos.astype(np.float64)[..., None]
    flip = cos < 0.0
    cos = np.abs(cos)
    standard = (1.0 - cos) > 0.00001
    theta = np.arccos(np.minimum(cos, 1.0))
    if code == "f":
        theta = theta.astype(np.float32)
        angles, where = np.unique(theta[standard], return_inverse=True)
        if angles.size and _SINF is None:
            return None
        sin = np.ones(theta.shape)
        sin[standard] = np.array([_SINF(x) for x in angles.tolist()], np.float64)[where.reshape(-1)]
        theta = theta.astype(np.float64)
    else:
        sin = np.sin(theta)
    with np.errstate(divide="ignore", invalid="ignore"):
        s0 = np.where(standard, np.sin((1.0 - alpha) * theta) / sin, 1.0 - alpha)
        s1 = np.where(standard, np.sin(alpha * theta) / sin, alpha)
    s1 = np.where(flip, -s1, s1)
    if code == "f":
        return s0.astype(np.float32) * q0 + s1.astype(np.float32) * q1
    return s0 * q0 + s1 * q1
