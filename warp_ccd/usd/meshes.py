"""USD meshes as triangles: a mesh prim's topology and points read once, its polygons fanned.

:func:`read_mesh` reads a ``UsdGeom.Mesh`` at the first time code into a :class:`MeshData` (points,
triangles, the USD face of every triangle, whether the points are time-sampled, a content hash for
sharing shapes); :func:`fan_triangles` turns polygons into triangles in numpy. Used by
:class:`~warp_ccd.usd.importer.UsdMeshImport`; ``pxr`` is imported inside the functions.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

__all__ = ["MeshData", "fan_triangles", "read_mesh"]


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
        p = np.asarray(self.points_attr.Get(time), dtype=np.float64).reshape(-1, 3)
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
        raise ValueError(f"prim {path}: face {f} has {int(counts[f])} vertices (at least 3 needed)")
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
    from pxr import UsdGeom

    mesh = UsdGeom.Mesh(source)
    for attr in (mesh.GetFaceVertexCountsAttr(), mesh.GetFaceVertexIndicesAttr()):
        if attr.ValueMightBeTimeVarying():
            raise ValueError(f"prim {name}: animated topology ({attr.GetName()} is time-sampled) is not supported")
    points_attr = mesh.GetPointsAttr()
    raw = points_attr.Get(t0)
    points = np.zeros((0, 3)) if raw is None else np.asarray(raw, dtype=np.float64).reshape(-1, 3)
    counts = mesh.GetFaceVertexCountsAttr().Get(t0)
    indices = mesh.GetFaceVertexIndicesAttr().Get(t0)
    holes = mesh.GetHoleIndicesAttr().Get(t0)
    counts = np.zeros(0, np.int64) if counts is None else np.asarray(counts)
    indices = np.zeros(0, np.int64) if indices is None else np.asarray(indices)
    holes = np.zeros(0, np.int64) if holes is None else np.asarray(holes, np.int64)
    if not np.isfinite(points).all():
        v = int(np.argmin(np.isfinite(points).all(axis=1)))
        raise ValueError(f"prim {name}: point {v} is not finite")
    tri, face = fan_triangles(counts, indices, holes, name, len(points))
    if mesh.GetOrientationAttr().Get(t0) == UsdGeom.Tokens.leftHanded:
        tri = np.ascontiguousarray(tri[:, ::-1])  # wound right-handed: normals out of the object
    deforming = points_attr.ValueMightBeTimeVarying()
    digest = hashlib.blake2b(points.astype(np.float64).tobytes(), digest_size=16)
    digest.update(tri.tobytes())
    return MeshData(name, points_attr, points, tri, face, deforming, digest.digest())
