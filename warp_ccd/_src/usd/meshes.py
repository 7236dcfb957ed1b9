"""USD meshes as triangles: a mesh prim's topology and points read once, its polygons fanned.

:func:`read_meshes` reads many ``UsdGeom.Mesh`` prims at the first time code into :class:`MeshData`
(points, triangles, the USD face of every triangle, whether the points are time-sampled, a content
hash for sharing shapes): per prim only the raw arrays are read (the attributes it does not author
are not asked for), then every mesh is validated and fanned at once, in numpy over the concatenated
arrays; the first mesh at fault (in the order given) raises the error :func:`read_mesh` raises for
it alone. :func:`read_mesh` reads one; :func:`fan_triangles` turns one mesh's polygons into
triangles. Used by :class:`~warp_ccd._src.usd.importer.UsdMeshImport`; ``pxr`` is imported inside the functions.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pxr import Usd

__all__ = ["MeshData", "fan_triangles", "read_mesh", "read_meshes"]


@dataclass
class MeshData:
    """One source of mesh data: a mesh prim, or a prototype's mesh shared by its instance proxies."""

    path: str
    points_attr: object
    points: np.ndarray  # (n, 3) float64 at the first time code
    triangles: np.ndarray  # (m, 3) int32
    triangle_face: np.ndarray  # (m,) int32 USD face index of each triangle
    deforming: bool  # points time-sampled
    key: bytes = b""  # content hash, for sharing shapes

    def points_at(self, time) -> np.ndarray:
        """``(n, 3)`` float64 points at ``time`` (a ``Usd.TimeCode``): read again where they are time-sampled.

        Raises:
            ValueError: naming the prim, when their number changed or one is not finite.
        """
        if not self.deforming:
            return self.points
        p = _points(self.points_attr.Get(time), self.path, float(time.GetValue())).astype(np.float64, copy=False)
        if p.shape != self.points.shape:
            raise ValueError(f"prim {self.path}: {len(p)} points at time {float(time.GetValue()):g}, "
                             f"{len(self.points)} at the first time code (a changing vertex count is not supported)")
        if not np.isfinite(p).all():
            raise ValueError(f"prim {self.path}: non-finite points at time {float(time.GetValue()):g}")
        return p


def fan_triangles(counts: np.ndarray, indices: np.ndarray, holes: np.ndarray, path: str, num_points: int):
    """Fan triangulation of USD polygons, vectorised (``n - 2`` triangles from a face of ``n`` vertices).

    Args:
        counts: ``(F,)`` ``faceVertexCounts``.
        indices: ``faceVertexIndices``, ``sum(counts)`` entries.
        holes: ``holeIndices``: faces left out.
        path: the prim's path, for the messages.
        num_points: how many points the indices refer to.

    Returns:
        ``(triangles (m, 3) int32 point indices, face (m,) int32 USD face index of each)``.

    Raises:
        ValueError: naming the prim: a face of fewer than 3 vertices, counts and indices that do
            not agree, an index outside the points, a hole index that is not a face index.
    """
    counts = np.asarray(counts, np.int64)
    indices = np.asarray(indices, np.int64)
    if counts.size and counts.min() < 3:
        f = int(np.argmax(counts < 3))
        raise ValueError(f"prim {path}: face {f} has {int(counts[f])} vertices (faceVertexCounts[{f}] = "
                         f"{int(counts[f])}; at least 3 needed)")
    if counts.sum() != indices.size:
        raise ValueError(f"prim {path}: faceVertexCounts sum to {int(counts.sum())}, "
                         f"but faceVertexIndices has {indices.size} entries")
    if indices.size and (indices.min() < 0 or indices.max() >= num_points):
        k = int(np.argmax((indices < 0) | (indices >= num_points)))
        raise ValueError(f"prim {path}: faceVertexIndices[{k}] = {int(indices[k])} is outside its {num_points} points")
    start = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    keep = np.ones(counts.size, bool)
    if holes.size:
        bad = (holes < 0) | (holes >= counts.size)
        if bad.any():
            k = int(np.argmax(bad))
            raise ValueError(f"prim {path}: holeIndices[{k}] = {int(holes[k])} is not a face index "
                             f"(it has {counts.size} faces)")
        keep[holes] = False
    per_face = counts[keep] - 2
    face = np.repeat(np.nonzero(keep)[0], per_face)
    if face.size == 0:
        return np.zeros((0, 3), np.int32), np.zeros(0, np.int32)
    # k-th triangle of a face: (first, first + k + 1, first + k + 2)
    first = start[face]
    k = np.arange(face.size) - np.repeat(np.cumsum(per_face) - per_face, per_face)
    tri = np.stack([indices[first], indices[first + k + 1], indices[first + k + 2]], axis=1)
    return tri.astype(np.int32), face.astype(np.int32)


def _typed(value, attribute: str, path: str, time: float, kind: str) -> np.ndarray:
    """A mesh attribute's value as an array, checked for its type where it is read: ``kind`` ``"points"``
    (an array of 3-vectors of float, double or half: ``point3f[]`` and its kin) or ``"integers"`` (an
    integer array: ``faceVertexCounts``, ``faceVertexIndices``, ``holeIndices``).

    Raises:
        ValueError: ``prim <path>: <attribute> at time <t> is a <type> ...``: a flat ``float[]`` is
            not points, and ``float[]`` indices are not indices (numpy would round them).
    """
    a = np.asarray(value)
    ok = (a.ndim == 2 and a.shape[1] == 3 and a.dtype.kind == "f") if kind == "points" else \
        (a.ndim == 1 and (a.dtype.kind in "iu" or a.size == 0 and a.dtype.kind != "O"))
    if not ok:
        want = "an array of 3-vectors (point3f[])" if kind == "points" else "an integer array (int[])"
        raise ValueError(f"prim {path}: {attribute} at time {time:g} is a {type(value).__name__} ({a.size} values), "
                         f"not {want}")
    return a


def _points(value, path: str, time: float) -> np.ndarray:
    """``points`` as an ``(n, 3)`` array, checked by :func:`_typed`."""
    return _typed(value, "points", path, time, "points")


def _raw(source, t0, names=None, path: str = "") -> tuple:
    """The raw arrays of one mesh prim: ``(points attribute, points, counts, indices, holes, left-handed,
    deforming, animated topology attribute name or None)``. ``names``: its authored property names, if
    known (attributes it does not author are not read)."""
    if names is None:
        names = source.GetAuthoredPropertyNames()
    points_attr = source.GetAttribute("points")
    counts_attr, indices_attr = source.GetAttribute("faceVertexCounts"), source.GetAttribute("faceVertexIndices")
    animated = next((a.GetName() for a in (counts_attr, indices_attr) if a.ValueMightBeTimeVarying()), None)
    raw = points_attr.Get(t0)
    counts, indices = counts_attr.Get(t0), indices_attr.Get(t0)
    holes = source.GetAttribute("holeIndices").Get(t0) if "holeIndices" in names else None
    left = "orientation" in names and source.GetAttribute("orientation").Get(t0) == "leftHanded"
    time = float(t0.GetValue()) if not t0.IsDefault() else float("nan")
    path = path or str(source.GetPath())
    return (points_attr, np.zeros((0, 3)) if raw is None else _points(raw, path, time),
            np.zeros(0, np.int32) if counts is None else _typed(counts, "faceVertexCounts", path, time, "integers"),
            np.zeros(0, np.int32) if indices is None else _typed(indices, "faceVertexIndices", path, time, "integers"),
            np.zeros(0, np.int64) if holes is None else
            _typed(holes, "holeIndices", path, time, "integers").astype(np.int64),
            left, points_attr.ValueMightBeTimeVarying(), animated)


def _check(name: str, raw: tuple) -> None:
    """Raises the ValueError naming the prim that :func:`read_mesh` raises for this mesh, if any."""
    _, points, counts, indices, holes, _, _, animated = raw
    if animated is not None:
        raise ValueError(f"prim {name}: animated topology ({animated} is time-sampled) is not supported")
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():
        raise ValueError(f"prim {name}: point {int(np.argmin(finite))} is not finite")
    fan_triangles(counts, indices, holes, name, len(points))


def read_meshes(sources: list, names: list[str], t0: Usd.TimeCode, authored: list | None = None) -> list[MeshData]:
    """:func:`read_mesh` of many mesh prims: the raw arrays per prim, then validated, fanned and wound
    over all of them at once.

    Args:
        sources: ``M`` ``UsdGeom.Mesh`` prims to read (a prototype's mesh for an instance proxy).
        names: the ``M`` paths that messages name.
        t0: the first ``Usd.TimeCode`` read.
        authored: each prim's authored property names (``Usd.Prim.GetAuthoredPropertyNames``), or
            None to ask for them.

    Returns:
        ``M`` :class:`MeshData`, in order.

    Raises:
        ValueError: naming the first prim at fault, as :func:`read_mesh` does (an attribute of the
            wrong type as it is read: :func:`_typed`).
    """
    raws = [_raw(s, t0, None if authored is None else authored[k], names[k]) for k, s in enumerate(sources)]
    m = len(raws)
    if not m:
        return []
    npts = np.array([len(r[1]) for r in raws], np.int64)
    nface = np.array([r[2].size for r in raws], np.int64)
    nidx = np.array([r[3].size for r in raws], np.int64)
    points = np.concatenate([r[1] for r in raws]).astype(np.float64, copy=False)
    counts = np.concatenate([r[2] for r in raws]).astype(np.int64, copy=False)
    indices = np.concatenate([r[3] for r in raws]).astype(np.int64, copy=False)
    vstart, fstart, istart = (np.concatenate([[0], np.cumsum(x)]) for x in (npts, nface, nidx))
    # Every check of read_mesh, per mesh at once; the first mesh at fault raises as read_mesh would.
    fault = np.array([r[7] is not None for r in raws])
    fault |= np.bincount(np.repeat(np.arange(m), npts), ~np.isfinite(points).all(axis=1), m) > 0
    fault |= np.bincount(np.repeat(np.arange(m), nface), counts < 3, m) > 0
    sums = np.bincount(np.repeat(np.arange(m), nface), counts, m).astype(np.int64)
    fault |= sums != nidx
    owner = np.repeat(np.arange(m), nidx)
    fault |= np.bincount(owner, (indices < 0) | (indices >= npts[owner]), m) > 0
    fault |= np.array([r[4].size > 0 and bool(((r[4] < 0) | (r[4] >= r[2].size)).any()) for r in raws])
    if fault.any():
        k = int(np.argmax(fault))
        _check(names[k], raws[k])
    keep = np.ones(counts.size, bool)
    for k, r in enumerate(raws):
        if r[4].size:
            keep[fstart[k] + r[4]] = False
    face_owner = np.repeat(np.arange(m), nface)
    start = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    per_face = np.where(keep, counts - 2, 0)
    face = np.repeat(np.arange(counts.size), per_face)
    first = start[face]
    k = np.arange(face.size) - np.repeat(np.cumsum(per_face) - per_face, per_face)
    tri = np.stack([indices[first], indices[first + k + 1], indices[first + k + 2]], axis=1).astype(np.int32)
    tri_owner = face_owner[face]
    left = np.array([r[5] for r in raws])
    if left.any():  # wound right-handed: normals out of the object
        flip = left[tri_owner]
        tri[flip] = tri[flip, ::-1]
    local_face = (face - fstart[tri_owner]).astype(np.int32)
    tstart = np.concatenate([[0], np.cumsum(np.bincount(tri_owner, minlength=m))])
    out = []
    for k, r in enumerate(raws):
        pts, t = points[vstart[k]:vstart[k + 1]], tri[tstart[k]:tstart[k + 1]]
        digest = hashlib.blake2b(pts.tobytes(), digest_size=16)
        digest.update(t.tobytes())
        out.append(MeshData(names[k], r[0], pts, t, local_face[tstart[k]:tstart[k + 1]], r[6], digest.digest()))
    return out


def read_mesh(source, name: str, t0) -> MeshData:
    """The topology and points of a mesh prim, polygons fanned into triangles wound right-handed.

    Args:
        source: the ``UsdGeom.Mesh`` prim to read (a prototype's mesh for an instance proxy).
        name: the path that messages name (the instance proxy's own).
        t0: the first ``Usd.TimeCode`` read: its points, topology, orientation.

    Returns:
        The :class:`MeshData`.

    Raises:
        ValueError: naming the prim: animated topology, a non-finite point, a bad polygon
            (:func:`fan_triangles`).
    """
    return read_meshes([source], [name], t0)[0]
