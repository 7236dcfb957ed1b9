"""Queries over meshes beyond a frame's pairs: least distances however far apart (:class:`DistanceQuery`,
:func:`distance`) and one mesh's self-intersections (:func:`self_intersections`).

Where a pipeline with a clearance (:class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` ``clearance=d``) reports
the pairs of a scene within ``d``, a distance query answers "how far is the arm from the table" for
chosen object pairs with no cut-off: a branch and bound over each pair's two trees on the device
(:mod:`warp_ccd._src.queries.tree_distance`). :class:`DistanceQuery` keeps the trees (built once; a deforming
object's refit at each query) and its buffers, and runs each query as one frame (a CUDA graph on
CUDA); :func:`distance` is the one-shot form over meshes.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property

import numpy as np
import warp as wp

from ..geometry.triangle import TOLERANCE
from ..narrowphase.depth import PenetrationDepth
from ..narrowphase.self_intersection import SelfIntersection
from ..runtime.aliases import ArrayLike, DeviceLike
from ..runtime.buffers import CounterRead, GrowableBuffer
from ..runtime.frame import FrameCache, frame_mode
from ..runtime.options import check_option
from ..scene.scene import Scene
from ..scene.shapes import validate_meshes
from ..trees.bvh import SceneBVH
from .tree_distance import TreeDistance

__all__ = ["DistanceQuery", "DistanceResult", "distance", "self_intersections"]


def _pairs_array(pairs, num_objects: int, sets: tuple | None = None) -> np.ndarray:
    """``pairs`` as a checked ``(P, 2)`` int32 array of ids ``a != b`` below ``num_objects``; with
    ``sets``, ``(n_a, n_b)``, rows ``(i, j)`` of one set against another instead."""
    p = np.asarray(pairs)
    if p.size == 0:
        p = p.reshape(0, 2).astype(np.int64)
    if p.ndim != 2 or p.shape[1] != 2 or (p.size and not np.issubdtype(p.dtype, np.integer)):
        raise ValueError(f"pairs: expected a (P, 2) array of integer object ids, got {p.dtype} {p.shape}")
    p = p.astype(np.int64)
    if sets is not None:
        if p.size and (p.min() < 0 or p[:, 0].max() >= sets[0] or p[:, 1].max() >= sets[1]):
            raise ValueError(f"pairs: rows (i, j) need 0 <= i < {sets[0]} (meshes_a) and 0 <= j < {sets[1]} "
                             f"(meshes_b), got {p.min()}..{p.max()}")
        return p.astype(np.int32)
    if p.size and (p.min() < 0 or p.max() >= num_objects):
        raise ValueError(f"pairs: object ids must lie in [0, {num_objects}), got {p.min()}..{p.max()}")
    same = np.nonzero(p[:, 0] == p[:, 1])[0] if p.size else []
    if len(same):
        raise ValueError(f"pairs: row {int(same[0])} pairs object {int(p[same[0], 0])} with itself")
    return p.astype(np.int32)


class DistanceQuery:
    """The least distance of chosen object pairs of a :class:`~warp_ccd._src.scene.scene.Scene`, at every
    :meth:`query`, however far apart (see the module docstring).

    Args:
        scene: the scene (its world vertices are read at each query; deforming objects' trees are refit).
        pairs: ``(P, 2)`` object ids ``(a, b)``, ``a != b``, to measure (default: every pair ``a < b``).
        tolerance: relative tolerance of the triangle tests: triangles that intersect or touch within
            it are at distance 0 (:func:`~warp_ccd.geometry.tri_tri_distance`).
        leaf_size: triangles per tree leaf (default 1).
        graph: run each query as a captured CUDA graph (default: on CUDA).
        front_capacity: initial capacity of the walk's front of node pairs (it grows).
        listed_capacity: initial capacity of the walk's measured triangle pairs (it grows).
        signed: the distance of intersecting pairs, and of pairs one of which lies wholly inside the other's closed
            solid, is minus their penetration depth (python-fcl's sign; the depth of
            :mod:`~warp_ccd._src.narrowphase.depth`: the deepest point of either surface inside the other's solid),
            their closest points the depth's witness (a point of one surface inside the other and its nearest point
            on that other); False: 0 and one point of the intersection. Touching pairs and pairs of open surfaces
            (no solid) stay at 0.

    Attributes:
        bvh: the :class:`~warp_ccd._src.trees.bvh.SceneBVH`; ``stage``: the
            :class:`~warp_ccd._src.queries.tree_distance.TreeDistance`; ``pairs``: the
            :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of queried pairs (``pair_ids``: on the host).
    """

    def __init__(self, scene: Scene, pairs: ArrayLike | None = None, *, tolerance: float = TOLERANCE,
                 leaf_size: int = 1, graph: bool | None = None, front_capacity: int | None = None,
                 listed_capacity: int | None = None, signed: bool = True) -> None:
        if not isinstance(scene, Scene):
            raise TypeError(f"scene: expected a warp_ccd.Scene, got {type(scene).__name__}")
        n = scene.num_objects
        if pairs is None:
            a, b = np.triu_indices(n, 1)
            pairs = np.stack([a, b], axis=1)
        self.pair_ids = _pairs_array(pairs, n)
        self.scene = scene
        self.device = d = scene.device
        mode = frame_mode(d, graph)
        self.bvh = SceneBVH(scene, leaf_size=check_option("leaf_size", leaf_size),
                            margin_rel=tolerance)
        count = len(self.pair_ids)
        # First capacities: 64 node pairs a queried pair plus two per triangle of the queried objects
        # (pairs of objects close together keep the node pairs facing each other), 16 listed a pair.
        tris = np.diff(scene.object_triangle_start_np)
        facing = int(tris[np.unique(self.pair_ids)].sum()) if count else 0
        self.stage = TreeDistance(
            self.bvh, tolerance=tolerance, device=d,
            front_capacity=check_option("front_capacity", front_capacity)
            or max(1024, 64 * count + 2 * facing),
            listed_capacity=check_option("listed_capacity", listed_capacity)
            or max(1024, 16 * count))
        self.pairs = GrowableBuffer(wp.vec2i, max(1, count), d, "queried pairs")
        if count:
            self.pairs.data[:count].assign(wp.array(self.pair_ids, dtype=wp.vec2i, device=d))
        self.pairs.count.fill_(count)
        self.pairs.last_count = count
        self.counter_read = CounterRead(self.stage.counters, d, stages=[0, 1], watch=scene.input_check.fault)
        self._frames = FrameCache(self.counter_read, mode)
        self.signed = bool(check_option("signed", signed))
        self.tolerance = float(tolerance)
        self._depth = None

    def set_pairs(self, pairs: ArrayLike) -> None:
        """Measures other object pairs from the next :meth:`query` on, keeping the trees and the buffers as
        they have grown (a caller that picks its pairs query by query, as a nearest-pair search does).

        Args:
            pairs: ``(P, 2)`` object ids ``(a, b)``, ``a != b``.

        Raises:
            ValueError: a bad shape, an id out of range, or a pair of an object with itself.
        """
        ids = _pairs_array(pairs, self.scene.num_objects)
        count = len(ids)
        if self.pairs.ensure(count):
            self.counter_read.generation += 1  # a captured query holds the old storage
        if count:
            self.pairs.data[:count].assign(wp.array(ids, dtype=wp.vec2i, device=self.device))
        self.pairs.count.fill_(count)
        self.pairs.last_count = count
        self.pair_ids = ids

    def _launch(self) -> None:
        self.bvh.refit(self.scene, object_boxes=False)  # deforming trees; no broad phase needs boxes
        self.stage.launch(self.scene, self.pairs)

    def query(self) -> DistanceResult:
        """Measures every queried pair on the scene's world vertices now.

        Returns:
            A :class:`~warp_ccd._src.queries.distance.DistanceResult` holding views of this query's device arrays,
            valid until the next ``query()`` (its numpy arrays, once read, are its own).
        """
        runs = 1
        grew = self._frames.get(None, self._launch).run_once()
        if self.counter_read.watched:  # the scene's device-side inputs (set_poses, ...) were bad
            self.scene.input_check.raise_for(self.counter_read.watched)
        while grew:  # a buffer grew: measure again
            grew = self._frames.get(None, self._launch).run_once()
            runs += 1
        stage, count = self.stage, len(self.pair_ids)
        if self.signed and count:
            self._sign(stage, count)
        return DistanceResult(self.pair_ids, stage.distance[:count], stage.point[:count], stage.normal[:count],
                              stage.triangle[:count], runs=runs)

    def _sign(self, stage: TreeDistance, count: int) -> None:
        """Intersecting pairs' distances made minus their depths, with the depth's witness as closest points and
        the direction from ``a`` to ``b`` ``(p - q) / |p - q|`` (``a`` leaves ``b`` along minus it), written into
        the query's arrays; likewise a pair apart whose one object lies wholly inside the other's closed solid (its
        inner surface's depth). The depths come from :class:`~warp_ccd._src.narrowphase.depth.PenetrationDepth`
        down the query's trees, over each object's triangles within the other's box."""
        dist = stage.distance[:count].numpy()
        if self._depth is None:
            self._depth = PenetrationDepth(self.scene, trees=self.bvh, triangle_tolerance=self.tolerance)
        ids = self.pair_ids.astype(np.int64)
        apart = np.flatnonzero(dist > 0.0)
        a_in_b = np.zeros(count, bool)
        b_in_a = np.zeros(count, bool)
        a_in_b[apart] = self._depth.inside(ids[apart])
        b_in_a[apart] = self._depth.inside(ids[apart, ::-1]) & ~a_in_b[apart]
        hit = np.flatnonzero(dist <= 0.0)
        inner = np.flatnonzero(a_in_b | b_in_a)
        if not len(hit) and not len(inner):
            return
        self.bvh.refit(self.scene)  # the object boxes too: each object's triangles within the other's are measured
        contained = np.where(a_in_b[inner, None], ids[inner], ids[inner, ::-1])  # (inner, outer)
        found = self._depth(np.sort(ids[hit], axis=1), in_boxes=True, contained=contained)
        swap = ids[hit, 0] > ids[hit, 1]
        # Every signed row: (row, depth, (point on a, point on b), (tri a, tri b)).
        points = np.concatenate([np.where(swap[:, None, None], found.pair_points[:, ::-1], found.pair_points),
                                 np.where(b_in_a[inner, None, None], found.contained_points[:, ::-1],
                                          found.contained_points)])
        tris = np.concatenate([np.where(swap[:, None], found.pair_triangles[:, ::-1], found.pair_triangles),
                               np.where(b_in_a[inner, None], found.contained_triangles[:, ::-1],
                                        found.contained_triangles)])
        depth = np.concatenate([found.pair_depth, found.contained_depth])
        rows = np.concatenate([hit, inner])
        ok = np.isfinite(depth) & (depth > 0.0) & np.isfinite(points).all(axis=(1, 2))
        if not ok.any():
            return
        at, depth, points, tris = rows[ok], depth[ok], points[ok], tris[ok]
        gap = points[:, 0] - points[:, 1]
        normal = gap / np.maximum(np.linalg.norm(gap, axis=1), 1e-300)[:, None]
        all_dist, all_points = dist.copy(), stage.point[:count].numpy()
        all_normal, all_tris = stage.normal[:count].numpy(), stage.triangle[:count].numpy()
        all_dist[at] = -depth
        all_points[at] = points
        all_normal[at] = normal
        all_tris[at] = tris
        d = self.device
        stage.distance[:count].assign(wp.array(all_dist, dtype=stage.distance.dtype, device=d))
        stage.point[:count].assign(wp.array(all_points, dtype=stage.point.dtype, device=d))
        stage.normal[:count].assign(wp.array(all_normal, dtype=stage.normal.dtype, device=d))
        stage.triangle[:count].assign(wp.array(all_tris, dtype=wp.vec2i, device=d))


def _as_meshes(meshes, name: str) -> list:
    """A sequence of ``(vertices, triangles)`` (one mesh alone is taken as a list of one)."""
    if isinstance(meshes, tuple) and len(meshes) == 2 and np.ndim(meshes[0]) == 2:
        return [meshes]
    if isinstance(meshes, (str, bytes)) or not isinstance(meshes, Sequence):
        raise TypeError(f"{name}: expected a sequence of (vertices, triangles), got {type(meshes).__name__}")
    return list(meshes)


def distance(meshes_a: Sequence, meshes_b: Sequence | None = None, transforms_a: ArrayLike | None = None,
             transforms_b: ArrayLike | None = None, *, pairs: ArrayLike | None = None, device: DeviceLike = None,
             precision: str = "float32", tolerance: float = TOLERANCE, signed: bool = True) -> DistanceResult:
    """One-shot least distances between meshes, however far apart ("how far is the arm from the table").

    Args:
        meshes_a: ``(vertices (n, 3), triangles (m, 3))`` meshes (or one such pair).
        meshes_b: a second set; without it, the pairs of ``meshes_a`` among themselves.
        transforms_a: ``(N, 4, 4)`` rigid transforms of ``meshes_a``, or None (vertices in world space;
            without them while ``transforms_b`` is given, the meshes are placed by identities).
        transforms_b: ``(N, 4, 4)`` rigid transforms of ``meshes_b``, or None (vertices in world space;
            without them while ``transforms_a`` is given, the meshes are placed by identities).
        pairs: ``(P, 2)`` rows ``(i, j)`` to measure: mesh ``i`` of ``meshes_a`` against ``j`` of
            ``meshes_b`` (or of ``meshes_a``); default every ``(i, j)`` (``i < j`` within one set).
        device: Warp device (default: Warp's default device).
        precision: ``"float32"`` or ``"float64"`` (vertices, poses and the tests).
        tolerance: relative tolerance of the triangle tests (see :class:`DistanceQuery`).
        signed: intersecting pairs at minus their penetration depth (python-fcl's sign; see :class:`DistanceQuery`).

    Returns:
        :class:`~warp_ccd._src.queries.distance.DistanceResult`: per row of ``pairs`` (indices into the sets as given)
        the least distance, closest points, direction and closest triangles.

    Raises:
        ValueError / TypeError: naming the bad mesh (``meshes_b mesh 2: ...``), transform or pair.
    """
    a = _as_meshes(meshes_a, "meshes_a")
    b = None if meshes_b is None else _as_meshes(meshes_b, "meshes_b")
    n_a = len(a)
    meshes = a if b is None else a + b
    transforms = None
    if transforms_a is not None or transforms_b is not None:
        eye = np.broadcast_to(np.eye(4), (len(meshes), 4, 4))
        t_a = eye[:n_a] if transforms_a is None else np.asarray(transforms_a, np.float64)
        t_b = eye[n_a:] if transforms_b is None else np.asarray(transforms_b, np.float64)
        if t_a.shape != (n_a, 4, 4):
            raise ValueError(f"transforms_a: expected shape ({n_a}, 4, 4), got {t_a.shape}")
        if b is not None and t_b.shape != (len(b), 4, 4):
            raise ValueError(f"transforms_b: expected shape ({len(b)}, 4, 4), got {t_b.shape}")
        transforms = t_a if b is None else np.concatenate([t_a, t_b])
    try:
        scene = Scene.from_meshes(meshes, transforms, device=device, precision=precision)
    except ValueError:
        for name, group in (("meshes_a", a), ("meshes_b", b or [])):
            validate_meshes(group, kind=f"{name} mesh")  # names the set and the mesh within it
        raise
    if b is None:
        rows = np.stack(np.triu_indices(n_a, 1), axis=1) if pairs is None else _pairs_array(pairs, n_a)
        ids = rows
    else:
        if pairs is None:
            i, j = np.meshgrid(np.arange(n_a), np.arange(len(b)), indexing="ij")
            rows = np.stack([i.ravel(), j.ravel()], axis=1)
        else:
            rows = _pairs_array(pairs, n_a + len(b), sets=(n_a, len(b)))
        ids = rows + [0, n_a]
    query = DistanceQuery(scene, ids, tolerance=tolerance, signed=signed)
    result = query.query()
    result.pairs = rows.astype(np.int32)
    return result


def self_intersections(vertices: ArrayLike, triangles: ArrayLike, *, device: DeviceLike = None,
                       precision: str = "float32", tolerance: float = TOLERANCE, leaf_size: int = 1) -> np.ndarray:
    """The pairs of triangles of one mesh that meet other than through the vertices they share (a cloth
    folded through itself, a scan or a boolean result with self-intersections).

    Triangles sharing an edge meet only where they overlap beyond it (a fold flat onto itself), triangles
    sharing a vertex only where they meet somewhere else; vertices at exactly one position are one vertex
    (:func:`~warp_ccd._src.narrowphase.self_intersection.weld_vertices`); the test and its tolerance:
    :func:`~warp_ccd._src.geometry.adjacent.tri_tri_self`.

    Args:
        vertices: ``(n, 3)`` float vertices.
        triangles: ``(m, 3)`` int vertex indices.
        device: Warp device (default: Warp's default device).
        precision: ``"float32"`` or ``"float64"`` (vertices and the test).
        tolerance: relative tolerance of the triangle test (touching within it counts).
        leaf_size: triangles per tree leaf.

    Returns:
        ``(M, 2)`` int32 rows ``(tri_a, tri_b)``, ``tri_a < tri_b``, sorted.

    Raises:
        ValueError / TypeError: naming the problem with the mesh.
    """
    scene = Scene.from_meshes([(vertices, triangles)], device=device, precision=precision)
    bvh = SceneBVH(scene, leaf_size=check_option("leaf_size", leaf_size), margin_rel=tolerance)
    stage = SelfIntersection(scene, bvh, tolerance=tolerance)
    return np.ascontiguousarray(stage.shape_rows[:, 1:])


class DistanceResult:
    """Least distances of object pairs (:meth:`~warp_ccd._src.queries.distance.DistanceQuery.query`,
    :func:`~warp_ccd._src.queries.distance.distance`): device arrays, read to the host on first access.

    Attributes:
        pairs: ``(P, 2)`` int32 rows ``(a, b)`` measured (the ids the caller gave).
        runs: how many times the query ran (more than 1 when a buffer grew).
        device_distance, device_points, device_normal, device_triangles: the device arrays, ``(P,)``,
            ``(P, 2)``, ``(P,)`` and ``(P,)`` ``wp.vec2i``, in the scene's precision (views of the
            query's buffers: valid until its next query).
    """

    def __init__(self, pairs: np.ndarray, device_distance: wp.array, device_points: wp.array,
                 device_normal: wp.array, device_triangles: wp.array, runs: int = 1) -> None:
        self.pairs = np.asarray(pairs, np.int32).reshape(-1, 2)
        self.device_distance = device_distance
        self.device_points = device_points
        self.device_normal = device_normal
        self.device_triangles = device_triangles
        self.runs = runs

    @cached_property
    def distance(self) -> np.ndarray:
        """``(P,)`` float64 least distance of each pair's surfaces, scene units; where they intersect, minus the
        pair's penetration depth (a signed query, the default; 0 where they only touch or neither is closed)."""
        return self.device_distance.numpy().astype(np.float64)

    @cached_property
    def closest_points(self) -> np.ndarray:
        """``(P, 2, 3)`` float64: a closest point on ``a``, then on ``b``; where they intersect (signed), the depth's
        witness: the deepest point of one surface inside the other and its nearest point on that other surface
        (else one point of the intersection twice)."""
        return self.device_points.numpy().reshape(-1, 2, 3).astype(np.float64)

    @cached_property
    def normal(self) -> np.ndarray:
        """``(P, 3)`` float64 unit directions from ``a`` to ``b``: ``(q - p) / |q - p|`` (``a`` moving along minus
        it moves away); where the surfaces intersect (signed, a positive depth) ``(p - q) / |p - q|`` of the depth's
        witness (``a`` moving along minus it by the depth leaves ``b`` at that point); where they only touch, from
        the normals of the closest triangles, ``n_a - n_b`` normalised (zero when that vanishes)."""
        return self.device_normal.numpy().reshape(-1, 3).astype(np.float64)

    @cached_property
    def closest_triangles(self) -> np.ndarray:
        """``(P, 2)`` int32 ``(tri_a, tri_b)``: the triangle pair that attains each distance (the least
        such pair by ``tri_a``, then ``tri_b``)."""
        return self.device_triangles.numpy().reshape(-1, 2).astype(np.int32)

    def copy(self) -> "DistanceResult":
        """The same result with device arrays of its own (valid after the query's next ``query()``)."""
        return DistanceResult(self.pairs.copy(), wp.clone(self.device_distance), wp.clone(self.device_points),
                              wp.clone(self.device_normal), wp.clone(self.device_triangles), self.runs)

    @cached_property
    def intersecting(self) -> np.ndarray:
        """``(P,)`` bool: the pair's surfaces intersect (or touch within the tolerance)."""
        return self.distance <= 0.0

    def __repr__(self) -> str:
        low = f", least={self.distance.min():.6g}" if len(self.pairs) else ""
        return f"DistanceResult(pairs={len(self.pairs)}{low}, runs={self.runs})"
