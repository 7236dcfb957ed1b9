"""Polyhedra the scenes are built from, and validation of user meshes.

Every shape is returned as ``(vertices, triangles)``: ``vertices`` a ``(n, 3)`` float32 array of
positions in local coordinates (unit size: every vertex lies on the unit sphere, so the
circumradius is 1), ``triangles`` an ``(m, 3)`` int32 array of vertex indices wound
counter-clockwise seen from outside (the normal ``(b - a) x (c - a)`` points outward).

All meshes that enter the library pass :func:`validate_mesh` or, many at once,
:func:`validate_meshes` (the same checks over the concatenated arrays: no Python per mesh beyond
gathering them), which raise a ``ValueError`` naming the object and the problem instead of letting
malformed data reach a kernel.
"""

from __future__ import annotations

from collections.abc import Sequence
from operator import attrgetter

import numpy as np

from ..runtime.aliases import ArrayLike
from ..runtime.checks import integer_option

__all__ = [
    "SHAPES",
    "figure_eight_torus",
    "sheet",
    "cube",
    "dodecahedron",
    "icosahedron",
    "icosphere",
    "octahedron",
    "shape",
    "tetrahedron",
    "triangle",
    "MeshSet",
    "validate_mesh",
    "validate_meshes",
]


def _orient_outward(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Flips triangles of a convex, origin-centred mesh so that their normals point outward."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    inward = np.einsum("ij,ij->i", normal, a + b + c) < 0.0
    out = triangles.copy()
    out[inward] = out[inward][:, [0, 2, 1]]
    return out


def _finish(vertices, triangles) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices, dtype=np.float64)
    v = v / np.linalg.norm(v, axis=1, keepdims=True)
    t = _orient_outward(v, np.asarray(triangles, dtype=np.int32))
    return v.astype(np.float32), t.astype(np.int32)


def tetrahedron() -> tuple[np.ndarray, np.ndarray]:
    """Regular tetrahedron: 4 vertices, 4 triangles."""
    v = [[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]
    t = [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]
    return _finish(v, t)


def cube() -> tuple[np.ndarray, np.ndarray]:
    """Cube: 8 vertices, 12 triangles (two per face)."""
    v = [[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]  # index = 4*ix + 2*iy + iz
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    t = [tri for a, b, c, d in quads for tri in ([a, b, c], [a, c, d])]
    return _finish(v, t)


def octahedron() -> tuple[np.ndarray, np.ndarray]:
    """Regular octahedron: 6 vertices, 8 triangles."""
    v = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
    t = [[x, y, z] for x in (0, 1) for y in (2, 3) for z in (4, 5)]
    return _finish(v, t)


def _icosahedron_raw() -> tuple[np.ndarray, np.ndarray]:
    phi = (1.0 + 5.0**0.5) / 2.0
    v = []
    for a in (-1.0, 1.0):
        for b in (-phi, phi):
            v += [[0.0, a, b], [a, b, 0.0], [b, 0.0, a]]
    v = np.asarray(v)
    d = np.linalg.norm(v[:, None] - v[None], axis=2)
    edge = 2.0  # edge length of this icosahedron
    near = np.abs(d - edge) < 1e-9
    t = [
        [i, j, k]
        for i in range(12)
        for j in range(i + 1, 12)
        for k in range(j + 1, 12)
        if near[i, j] and near[j, k] and near[i, k]
    ]
    return v, np.asarray(t)


def icosahedron() -> tuple[np.ndarray, np.ndarray]:
    """Regular icosahedron: 12 vertices, 20 triangles."""
    return _finish(*_icosahedron_raw())


def dodecahedron() -> tuple[np.ndarray, np.ndarray]:
    """Regular dodecahedron: 20 vertices, 36 triangles (each pentagon fanned into three).

    Built as the dual of the icosahedron: one vertex per icosahedron face, one pentagon per
    icosahedron vertex.
    """
    iv, it = _icosahedron_raw()
    iv = iv / np.linalg.norm(iv, axis=1, keepdims=True)
    centre = iv[it].mean(axis=1)
    centre /= np.linalg.norm(centre, axis=1, keepdims=True)
    t = []
    for k in range(12):
        ring = np.nonzero((it == k).any(axis=1))[0]  # the 5 faces around icosahedron vertex k
        axis = iv[k]
        ref = centre[ring[0]] - axis * np.dot(centre[ring[0]], axis)
        other = np.cross(axis, ref)
        ang = np.arctan2(centre[ring] @ other, centre[ring] @ ref)
        ring = ring[np.argsort(ang)]
        t += [[ring[0], ring[i], ring[i + 1]] for i in range(1, 4)]
    return _finish(centre, t)


def triangle() -> tuple[np.ndarray, np.ndarray]:
    """One equilateral triangle in the z = 0 plane, normal +z, circumradius 1."""
    ang = np.array([0.0, 2.0, 4.0]) * np.pi / 3.0
    v = np.stack([np.cos(ang), np.sin(ang), np.zeros(3)], axis=1).astype(np.float32)
    return v, np.array([[0, 1, 2]], dtype=np.int32)


def icosphere(level: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Unit sphere approximated by a subdivided icosahedron.

    Args:
        level: number of subdivisions; the mesh has ``20 * 4**level`` triangles
            (level 1: 80, level 3: 1,280, level 4: 5,120).

    Returns:
        ``(vertices (n, 3) float32, triangles (20 * 4**level, 3) int32)``.
    """
    integer_option("icosphere: level", level, low=0, high=8)
    v, t = _icosahedron_raw()
    v = list(v / np.linalg.norm(v, axis=1, keepdims=True))
    t = [list(tri) for tri in t]
    for _ in range(level):
        midpoint: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int) -> int:
            key = (min(a, b), max(a, b))
            if key not in midpoint:
                p = v[a] + v[b]
                v.append(p / np.linalg.norm(p))
                midpoint[key] = len(v) - 1
            return midpoint[key]

        new = []
        for a, b, c in t:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        t = new
    return _finish(np.asarray(v), t)


def sheet(n: int = 32, size: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A square cloth sheet in the z = 0 plane: an ``n x n`` grid of vertices over ``[0, size]^2``, each
    cell two triangles (``2 (n - 1)^2`` in all; ``n = 72``: 10,082).

    Returns:
        ``(vertices (n * n, 3) float32, triangles (2 (n - 1)^2, 3) int32)``; vertex ``i * n + j`` lies
        at ``(j, i) * size / (n - 1)``.
    """
    integer_option("sheet: n", n, low=2, high=46341)
    x, y = np.meshgrid(np.linspace(0.0, size, n), np.linspace(0.0, size, n))
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    a = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    t = np.concatenate([np.stack([a, a + 1, a + n], 1), np.stack([a + 1, a + n + 1, a + n], 1)])
    return v.astype(np.float32), t.reshape(2, -1, 3).transpose(1, 0, 2).reshape(-1, 3).astype(np.int32)


def figure_eight_torus(nu: int = 64, nv: int = 32, radius: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """A closed tube whose cross-section is a figure eight, swept around a circle: a torus that passes
    through itself along the circle where the eight crosses itself (a self-intersecting test mesh).

    Args:
        nu: segments around the circle; nv: around the cross-section (even: the crossing falls between
            vertices, not on them).
        radius: of the circle (the eight is 2 wide, 1 high).

    Returns:
        ``(vertices (nu * nv, 3) float32, triangles (2 nu nv, 3) int32)``.
    """
    integer_option("figure_eight_torus: nu", nu, low=3, high=1 << 15)
    integer_option("figure_eight_torus: nv", nv, low=4, high=1 << 15)
    u = np.linspace(0.0, 2.0 * np.pi, nu, endpoint=False)[:, None]
    w = (np.arange(nv)[None, :] + 0.5) * 2.0 * np.pi / nv
    r = radius + np.sin(w)  # the eight (sin w, sin w cos w) in the plane of the circle's radius and z
    v = np.stack([r * np.cos(u), r * np.sin(u), np.sin(w) * np.cos(w) + 0.0 * u], axis=2).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, ((i + 1) % nu) * nv + j
    c, d = ((i + 1) % nu) * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    t = np.stack([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], axis=2).reshape(-1, 3)
    return v.astype(np.float32), t.astype(np.int32)


SHAPES = {
    "tetrahedron": tetrahedron,
    "cube": cube,
    "octahedron": octahedron,
    "dodecahedron": dodecahedron,
    "icosahedron": icosahedron,
    "triangle": triangle,
}
"""Name -> factory of the fixed polyhedra; ``icosphere`` takes a level (also named ``icosphereN``)."""


def shape(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Returns the shape called ``name``: a key of :data:`SHAPES` or ``"icosphere<level>"``."""
    if name in SHAPES:
        return SHAPES[name]()
    if isinstance(name, str) and name.startswith("icosphere"):
        rest = name[len("icosphere") :]
        if rest == "":
            return icosphere(1)
        if rest.isdigit():
            return icosphere(int(rest))
    known = ", ".join([*SHAPES, "icosphere<level>"])
    raise ValueError(f"unknown shape {name!r}; known shapes: {known}")


def validate_mesh(vertices: ArrayLike, triangles: ArrayLike, name: str = "mesh",
                  dtype: type[np.floating] = np.float32) -> tuple[np.ndarray, np.ndarray]:
    """Checks one triangle mesh and returns it as contiguous ``dtype`` / int32 arrays.

    Args:
        vertices: ``(n, 3)`` array-like of finite positions.
        triangles: ``(m, 3)`` array-like of integer vertex indices in ``[0, n)``, ``m >= 1``.
        name: how the object is called in error messages (e.g. ``"mesh 3"``).
        dtype: ``np.float32`` (default) or ``np.float64``: type of the returned vertices (they
            must be finite in float32 either way).

    Returns:
        ``(vertices (n, 3) dtype, triangles (m, 3) int32)``.

    Raises:
        ValueError: naming ``name`` and the problem: wrong shape, non-numeric or non-finite
            vertices, non-integer triangle indices, indices out of range, no triangles.
    """
    try:
        v = np.asarray(vertices)
    except Exception as exc:  # ragged nested lists and the like
        raise ValueError(f"{name}: vertices are not an array of numbers ({exc})") from None
    if not (np.issubdtype(v.dtype, np.integer) or np.issubdtype(v.dtype, np.floating)):
        raise ValueError(f"{name}: vertices must be real numbers, got dtype {v.dtype}")
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"{name}: vertices must have shape (n, 3), got {v.shape}")
    if v.shape[0] < 3:
        raise ValueError(f"{name}: a mesh needs at least 3 vertices, got {v.shape[0]}")
    if not np.all(np.isfinite(v)):
        bad = int(np.nonzero(~np.isfinite(v).all(axis=1))[0][0])
        raise ValueError(f"{name}: vertex {bad} is not finite ({v[bad].tolist()})")
    with np.errstate(over="ignore"):
        v32 = v.astype(np.float32)
    if not np.all(np.isfinite(v32)):
        raise ValueError(f"{name}: vertices overflow float32 (largest magnitude {np.abs(v).max():.3g})")

    try:
        t = np.asarray(triangles)
    except Exception as exc:
        raise ValueError(f"{name}: triangles are not an array of integers ({exc})") from None
    if t.dtype == bool or not np.issubdtype(t.dtype, np.integer):
        raise ValueError(f"{name}: triangles must be integer vertex indices, got dtype {t.dtype}")
    if t.ndim != 2 or t.shape[1] != 3:
        raise ValueError(f"{name}: triangles must have shape (m, 3), got {t.shape}")
    if t.shape[0] == 0:
        raise ValueError(f"{name}: the mesh has no triangles")
    lo, hi = int(t.min()), int(t.max())
    if lo < 0 or hi >= v.shape[0]:
        bad = int(np.nonzero(((t < 0) | (t >= v.shape[0])).any(axis=1))[0][0])
        raise ValueError(
            f"{name}: triangle {bad} has vertex index out of range [0, {v.shape[0]}): {t[bad].tolist()}"
        )
    out = v32 if dtype == np.float32 else v.astype(dtype)
    return np.ascontiguousarray(out), np.ascontiguousarray(t.astype(np.int32))


def row_max(a: np.ndarray) -> np.ndarray:
    """``(n,)`` largest of each row of an ``(n, 3)`` array, column against column (numpy's
    ``a.max(axis=1)`` over rows of three takes about 20x the time); NaN spreads as it does there."""
    return np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2])


class MeshSet:
    """Many triangle meshes packed end to end (what :func:`validate_meshes` returns).

    Attributes:
        vertices: ``(V, 3)`` float32 or float64, all meshes' vertices.
        triangles: ``(T, 3)`` int32 mesh-local vertex indices.
        vertex_start, triangle_start: ``(S + 1,)`` int64 offsets of each mesh.
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, vertex_start: np.ndarray,
                 triangle_start: np.ndarray) -> None:
        self.vertices = vertices
        self.triangles = triangles
        self.vertex_start = vertex_start
        self.triangle_start = triangle_start

    def __len__(self) -> int:
        return len(self.vertex_start) - 1

    def mesh(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Mesh ``k`` as ``(vertices, triangles)`` views."""
        v0, v1 = self.vertex_start[k], self.vertex_start[k + 1]
        t0, t1 = self.triangle_start[k], self.triangle_start[k + 1]
        return self.vertices[v0:v1], self.triangles[t0:t1]

    def meshes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Every mesh as ``(vertices, triangles)`` views (one Python pair per mesh)."""
        vs = np.split(self.vertices, self.vertex_start[1:-1])
        ts = np.split(self.triangles, self.triangle_start[1:-1])
        return list(zip(vs, ts))


def validate_meshes(meshes: Sequence[tuple[ArrayLike, ArrayLike]], labels: ArrayLike | None = None, kind: str = "mesh",
                    dtype: type[np.floating] = np.float32) -> MeshSet:
    """Checks many triangle meshes at once (the checks of :func:`validate_mesh`, vectorised over
    their concatenation) and packs them.

    Args:
        meshes: sequence of ``(vertices (n, 3), triangles (m, 3))`` pairs.
        labels: ``(S,)`` integers naming the meshes in errors (``"{kind} {label}"``; default
            their positions).
        kind: the word before the label (``"mesh"``, ``"shape"``).
        dtype: ``np.float32`` or ``np.float64``: type of the packed vertices.

    Returns:
        The :class:`MeshSet`.

    Raises:
        ValueError: naming the first bad mesh and its first problem, as :func:`validate_mesh` does
            for that mesh.
    """
    labels = np.arange(len(meshes)) if labels is None else np.asarray(labels)

    def name(k) -> str:
        return f"{kind} {int(labels[k])}"

    def each() -> None:  # the slow path, only to name a problem the fast one cannot place
        for k, (v, t) in enumerate(meshes):
            validate_mesh(v, t, name=name(k), dtype=dtype)

    if len(meshes) == 0:
        return MeshSet(np.zeros((0, 3), dtype), np.zeros((0, 3), np.int32), np.zeros(1, np.int64),
                       np.zeros(1, np.int64))
    try:
        pairs = list(map(tuple, meshes))  # any iterable pair, as unpacking takes it
        if set(map(len, pairs)) != {2}:
            raise ValueError("not pairs")
        vs, ts = (list(map(np.asarray, arrays)) for arrays in zip(*pairs))
    except Exception:  # ragged, not pairs: let the per-mesh checks say which
        each()
        raise
    # Ranks, widths and kinds of number, from one attribute of each array (bool, strings, objects,
    # wrong shapes: the per-mesh checks name the mesh), each distinct value once.
    t_types = set(map(attrgetter("dtype"), ts))
    if {s[1:] for s in set(map(attrgetter("shape"), vs))} != {(3,)} \
            or {s[1:] for s in set(map(attrgetter("shape"), ts))} != {(3,)} \
            or not {d.kind for d in set(map(attrgetter("dtype"), vs))} <= set("iuf") \
            or not {d.kind for d in t_types} <= set("iu"):
        each()
        raise ValueError("meshes: arrays of inconsistent shapes or types")  # not reached: some mesh is bad
    v = np.concatenate(vs)  # new arrays: converted below without another copy
    # int32 indices (the usual) checked as they are; wider ones in int64, where every value fits
    narrow = all(d == np.int32 or d.itemsize < 4 for d in t_types)
    t = np.concatenate(ts, dtype=np.int32 if narrow else np.int64, casting="unsafe")
    num_v = np.fromiter(map(len, vs), np.int64, len(vs))
    num_t = np.fromiter(map(len, ts), np.int64, len(ts))
    vstart = np.concatenate([[0], np.cumsum(num_v)])
    tstart = np.concatenate([[0], np.cumsum(num_t)])

    def mesh_of_vertex(row):
        return int(np.searchsorted(vstart, row, side="right") - 1)

    # Each check over all meshes (flat reductions first, rows only to name the culprit); the error
    # names the first bad mesh, and for it the first problem in validate_mesh's order.
    found = []  # (mesh, check, message)
    few = np.flatnonzero(num_v < 3)
    if len(few):
        k = int(few[0])
        found.append((k, 0, f"{name(k)}: a mesh needs at least 3 vertices, got {num_v[k]}"))
    finite = None
    if not np.isfinite(v).all():
        finite = np.isfinite(v).all(axis=1)
        row = int(np.argmin(finite))
        k = mesh_of_vertex(row)
        found.append((k, 1, f"{name(k)}: vertex {row - vstart[k]} is not finite ({v[row].tolist()})"))
    with np.errstate(over="ignore"):
        v32 = v.astype(np.float32)
    if not np.isfinite(v32).all():
        over = ~np.isfinite(v32).all(axis=1) & (True if finite is None else finite)
        if over.any():
            k = mesh_of_vertex(int(np.argmax(over)))
            big = np.abs(v[vstart[k]:vstart[k + 1]]).max()
            found.append((k, 2, f"{name(k)}: vertices overflow float32 (largest magnitude {big:.3g})"))
    empty = np.flatnonzero(num_t == 0)
    if len(empty):
        k = int(empty[0])
        found.append((k, 3, f"{name(k)}: the mesh has no triangles"))
    # Largest index of each mesh against its vertex count (rows only to name the culprit).
    with_t = num_t > 0
    t_max = np.full(len(num_t), -1, np.int64)
    if len(t):
        t_max[with_t] = np.maximum.reduceat(row_max(t), tstart[:-1][with_t])
    if len(t) and (t.min() < 0 or (t_max >= num_v).any()):
        limit = np.repeat(num_v, num_t)[:, None]
        row = int(np.argmax(((t < 0) | (t >= limit)).any(axis=1)))
        k = int(np.searchsorted(tstart, row, side="right") - 1)
        found.append((k, 4, f"{name(k)}: triangle {row - tstart[k]} has vertex index out of range "
                            f"[0, {num_v[k]}): {t[row].tolist()}"))
    if found:
        raise ValueError(min(found)[2])
    out = v32 if dtype == np.float32 else v.astype(dtype, copy=False)
    return MeshSet(np.ascontiguousarray(out), np.ascontiguousarray(t.astype(np.int32, copy=False)),
                   vstart.astype(np.int64), tstart.astype(np.int64))
