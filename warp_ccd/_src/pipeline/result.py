"""What a frame found: :class:`CollisionResult`, views of a pipeline's device buffers read on demand.

A result of :meth:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline.detect` holds the device arrays the frame
wrote (triangle pairs, flags, and what the options asked for: segments, containment, times of
impact, the pairs within a clearance) with the counts the frame's one read gave; the host arrays
(sorted rows, object pairs, distances) are computed on first access and cached.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
import warp as wp

__all__ = ["NEAR_ROWS", "CollisionResult"]


NEAR_ROWS = ("device_near_pairs", "device_near_distance", "device_near_points", "device_near_normal",
             "device_near_triangles", "device_near_intersecting")
"""The rows of a result with a clearance (:class:`~warp_ccd._src.narrowphase.clearance.ClearancePhase`), each
a device view of one of its arrays, in the order of its ``near`` buffer."""


class CollisionResult:
    """What one frame found. Arrays are computed on first access and cached.

    A result of :meth:`CollisionPipeline.detect` holds views of the pipeline's device buffers,
    valid until its next ``detect()`` overwrites them: read what you need first (the numpy
    properties copy to the host on first access and keep their copy), or keep
    :meth:`copy`, which owns its arrays.

    Attributes:
        num_objects: ``N``.
        timings: per-stage wall times in ms (``refit``, ``broad``, ``mid``, ``narrow``,
            ``total``) when the pipeline was asked for them, else None.
        host_ms: Python's time in ``detect()`` (launching, reading, building this result; not
            waiting for the device), in ms.
        runs: how many times ``detect()`` ran the frame for it (more than 1 when a buffer grew).
        device_colliding: ``(N,)`` int32 flags on the device.
        continuous: whether it is a continuous result (pairs that collide over a motion, with
            their times of impact: :attr:`triangle_toi`, :attr:`object_toi`, :attr:`toi`).
        clearance: the distance of a result with a clearance (:attr:`object_pairs` are then the
            pairs within it, with :attr:`object_distance`, :attr:`closest_points`,
            :attr:`object_normal`, :attr:`closest_triangles`, :attr:`object_intersecting`), else 0.
        device_near: with a clearance, ``(N,)`` int32 flags on the device (:attr:`near`), else None.
        device_self_pairs, device_self_colliding: with self-intersections, ``(M,)`` ``wp.vec3i`` rows
            ``(object, tri_a, tri_b)`` (unsorted) and ``(N,)`` int32 flags on the device, else None.
        object_world: ``(N,)`` int64 world id of each object (a scene built with ``world=``), else
            None (one world); :attr:`pair_world` gives each object pair's.
        contacts: with ``contacts=True``, the frame's :class:`~warp_ccd._src.narrowphase.contacts.Contacts`
            (per contact a point on each surface, a normal from ``b`` to ``a``, a depth), else None.

    Every ``device_*`` array is a ``wp.array``: hand it to torch, JAX or CuPy without a copy through
    DLPack (``torch.from_dlpack(res.device_colliding)``) or with ``wp.to_torch``.

    Made by :meth:`CollisionPipeline.detect`; made directly, it takes device arrays
    (``device_triangle_pairs`` ``(M,)`` ``wp.vec4i``, ``device_colliding``, and optionally
    ``device_contained``, ``device_segments``, ``device_toi``: a continuous result's; ``near``: a
    result with a clearance, ``{name: array}`` for each of :data:`NEAR_ROWS` and ``device_near``;
    ``self_rows``: a result with self-intersections, ``(device_self_pairs, device_self_colliding)``)
    and the counts it reports.
    """

    def __init__(self, num_objects: int, device_triangle_pairs: wp.array, device_colliding: wp.array,
                 timings: dict | None = None, num_candidates: int = 0, num_broad_pairs: int = 0,
                 device_contained: wp.array | None = None, device_segments: wp.array | None = None,
                 device_toi: wp.array | None = None, clearance: float = 0.0, near: dict | None = None,
                 self_rows: tuple | None = None) -> None:
        self._hold(num_objects, device_colliding, timings, num_candidates, num_broad_pairs,
                   int(device_triangle_pairs.shape[0]), {})
        self.__dict__.update(device_triangle_pairs=device_triangle_pairs, device_contained=device_contained,
                             device_segments=device_segments, device_toi=device_toi,
                             continuous=device_toi is not None)
        if near is not None:
            self.__dict__.update(near, clearance=float(clearance))
        if self_rows is not None:
            self.__dict__.update(device_self_pairs=self_rows[0], device_self_colliding=self_rows[1])

    @classmethod
    def _of_buffers(cls, num_objects: int, rows: dict, device_colliding: wp.array, timings: dict | None,
                    num_candidates: int, num_broad_pairs: int, clearance: float = 0.0,
                    device_near: wp.array | None = None) -> CollisionResult:
        """A result over a pipeline's buffers, made in a few steps (it is Python's time of every
        frame): ``rows`` maps each of ``device_triangle_pairs`` (required), ``device_contained``
        ``device_segments``, ``device_toi``, :data:`NEAR_ROWS`, ``device_self_pairs`` and
        ``device_self_colliding`` to ``(buffer array, count)``, sliced on first access (a view costs
        Python time every frame; a name left out is None; ``device_toi`` makes it continuous,
        ``device_near_pairs`` one with a ``clearance``)."""
        result = cls.__new__(cls)
        result._hold(num_objects, device_colliding, timings, num_candidates, num_broad_pairs,
                     rows["device_triangle_pairs"][1], rows)
        result.continuous = "device_toi" in rows
        if device_near is not None:
            result.__dict__.update(clearance=clearance, device_near=device_near)
        return result

    def _hold(self, num_objects: int, device_colliding: wp.array, timings: dict | None, num_candidates: int,
              num_broad_pairs: int, num_triangle_pairs: int, rows: dict) -> None:
        """Sets what every result holds (``rows``: the views made on first access, as in :meth:`_of_buffers`)."""
        self.__dict__.update(num_objects=num_objects, device_colliding=device_colliding, timings=timings,
                             num_candidates=num_candidates, num_broad_pairs=num_broad_pairs,
                             _num_triangle_pairs=num_triangle_pairs, host_ms=0.0, runs=1, _rows=rows,
                             continuous=False, clearance=0.0, device_near=None, object_world=None, contacts=None)

    def _view(self, name: str):
        held = self._rows.get(name)
        return None if held is None else held[0][: held[1]]

    @cached_property
    def device_triangle_pairs(self) -> wp.array:
        """``(M,)`` ``wp.vec4i`` on the device, unsorted."""
        return self._view("device_triangle_pairs")

    @cached_property
    def device_self_pairs(self) -> wp.array | None:
        """``(M,)`` ``wp.vec3i`` rows ``(object, tri_a, tri_b)`` on the device, unsorted; None without
        ``self_intersections``."""
        return self._view("device_self_pairs")

    @cached_property
    def device_self_colliding(self) -> wp.array | None:
        """``(N,)`` int32 flags on the device: the object intersects itself; None without ``self_intersections``."""
        return self._view("device_self_colliding")

    @cached_property
    def self_pairs(self) -> np.ndarray | None:
        """``(M, 3)`` int32 rows ``(object, tri_a, tri_b)``, ``tri_a < tri_b`` (local triangle ids), rows
        sorted: triangles of one object that meet beyond the vertices they share
        (:func:`~warp_ccd._src.geometry.adjacent.tri_tri_self`). None without ``self_intersections``."""
        if self.device_self_pairs is None:
            return None
        t = self.device_self_pairs.numpy().reshape(-1, 3).astype(np.int32)
        return t[np.lexsort((t[:, 2], t[:, 1], t[:, 0]))]

    @cached_property
    def self_colliding(self) -> np.ndarray | None:
        """``(N,)`` bool: the object intersects itself; None without ``self_intersections``."""
        if self.device_self_colliding is None:
            return None
        return self.device_self_colliding.numpy().astype(bool)

    @cached_property
    def device_contained(self) -> wp.array | None:
        """``(K,)`` ``wp.vec2i`` ``(inner, outer)`` pairs on the device, or None without ``containment``."""
        return self._view("device_contained")

    @cached_property
    def device_segments(self) -> wp.array | None:
        """``(M, 2)`` segment end points on the device (rows of :attr:`device_triangle_pairs`), or
        None without ``segments``."""
        return self._view("device_segments")

    @cached_property
    def device_near_pairs(self) -> wp.array | None:
        """With a clearance, ``(K,)`` ``wp.vec2i`` object pairs ``(a, b)``, ``a < b``, within it, on the
        device, unsorted (the rows of the ``device_near_*`` arrays); else None."""
        return self._view("device_near_pairs")

    @cached_property
    def device_near_distance(self) -> wp.array | None:
        """``(K,)`` least distances (the scene's precision) of :attr:`device_near_pairs`, or None."""
        return self._view("device_near_distance")

    @cached_property
    def device_near_points(self) -> wp.array | None:
        """``(K, 2)`` closest points (on ``a``, on ``b``; the scene's vector type) of
        :attr:`device_near_pairs`, or None."""
        return self._view("device_near_points")

    @cached_property
    def device_near_normal(self) -> wp.array | None:
        """``(K,)`` unit directions from ``a`` to ``b`` of :attr:`device_near_pairs`, or None."""
        return self._view("device_near_normal")

    @cached_property
    def device_near_triangles(self) -> wp.array | None:
        """``(K,)`` ``wp.vec2i`` closest triangle pairs ``(tri_a, tri_b)`` of :attr:`device_near_pairs`, or None."""
        return self._view("device_near_triangles")

    @cached_property
    def device_near_intersecting(self) -> wp.array | None:
        """``(K,)`` int32, 1 where the pair of :attr:`device_near_pairs` intersects, or None."""
        return self._view("device_near_intersecting")

    @cached_property
    def _near_order(self) -> np.ndarray:
        """Row order of :attr:`device_near_pairs` that sorts the pairs."""
        p = self.device_near_pairs.numpy().reshape(-1, 2)
        return np.lexsort((p[:, 1], p[:, 0]))

    def _near_rows(self, name: str, shape: tuple, dtype) -> np.ndarray | None:
        """Device rows ``name`` (one of :data:`NEAR_ROWS`) in the order of :attr:`object_pairs`, or None."""
        rows = getattr(self, name)
        if rows is None:
            return None
        return rows.numpy().reshape(-1, *shape).astype(dtype)[self._near_order]

    @cached_property
    def object_distance(self) -> np.ndarray | None:
        """With a clearance, ``(K,)`` float64: each row of :attr:`object_pairs`' least distance
        between the two surfaces (0 for an intersecting pair), scene units; else None."""
        return self._near_rows("device_near_distance", (), np.float64)

    @cached_property
    def closest_points(self) -> np.ndarray | None:
        """With a clearance, ``(K, 2, 3)`` float64: each row of :attr:`object_pairs`' closest points,
        on ``a`` then on ``b`` (one point of the intersection, twice, for an intersecting pair); else None."""
        return self._near_rows("device_near_points", (2, 3), np.float64)

    @cached_property
    def object_normal(self) -> np.ndarray | None:
        """With a clearance, ``(K, 3)`` float64 unit directions from ``a`` to ``b``: ``(q - p) / |q - p|``
        from the closest points; for an intersecting pair the direction of least penetration
        (:mod:`warp_ccd._src.narrowphase.clearance`); else None."""
        return self._near_rows("device_near_normal", (3,), np.float64)

    @cached_property
    def closest_triangles(self) -> np.ndarray | None:
        """With a clearance, ``(K, 2)`` int32 ``(tri_a, tri_b)``: the triangle pair of each row of
        :attr:`object_pairs` that attains its distance (local triangle ids); else None."""
        return self._near_rows("device_near_triangles", (2,), np.int32)

    @cached_property
    def object_intersecting(self) -> np.ndarray | None:
        """With a clearance, ``(K,)`` bool: whether the surfaces of each row of :attr:`object_pairs`
        intersect (then some of its triangle pairs are in :attr:`triangle_pairs`); else None."""
        return self._near_rows("device_near_intersecting", (), bool)

    @cached_property
    def near(self) -> np.ndarray | None:
        """With a clearance, ``(N,)`` bool: the object comes within it of another; else None."""
        return None if self.device_near is None else self.device_near.numpy().astype(bool)

    @cached_property
    def device_toi(self) -> wp.array | None:
        """``(M,)`` float64 times of impact in ``[0, 1]`` on the device (rows of
        :attr:`device_triangle_pairs`), or None for a discrete result."""
        return self._view("device_toi")

    @cached_property
    def triangle_toi(self) -> np.ndarray | None:
        """``(M,)`` float64 time of impact of each row of :attr:`triangle_pairs` (same order): the
        earliest ``t`` in ``[0, 1]`` at which the two triangles meet (or come within the pipeline's
        ``min_distance``), never later than the true one; 0 for a pair that meets at the start.
        None for a discrete result."""
        if self.device_toi is None:
            return None
        self.triangle_pairs  # noqa: B018 (computes the row order)
        return self.device_toi.numpy()[self._order]

    @cached_property
    def object_toi(self) -> np.ndarray | None:
        """``(K,)`` float64 earliest time of impact of each row of :attr:`object_pairs` (the least of
        its triangle pairs'), or None for a discrete result."""
        if self.device_toi is None:
            return None
        t = self.triangle_pairs
        out = np.full(len(self.object_pairs), np.inf)
        if len(t):
            _, row = np.unique(t[:, [0, 2]], axis=0, return_inverse=True)
            np.minimum.at(out, row.reshape(-1), self.triangle_toi)
        return out

    @property
    def toi(self) -> float:
        """The earliest time of impact of the frame (``inf`` when nothing collides, and for a
        discrete result)."""
        t = self.triangle_toi
        return float(t.min()) if t is not None and len(t) else float("inf")

    def copy(self) -> "CollisionResult":
        """The same result with device arrays of its own (valid after the next ``detect()``)."""

        def own(a):
            return None if a is None else wp.clone(a)

        near = None
        if self.device_near is not None:
            near = {name: own(getattr(self, name)) for name in (*NEAR_ROWS, "device_near")}
        self_rows = None
        if self.device_self_pairs is not None:
            self_rows = (own(self.device_self_pairs), own(self.device_self_colliding))
        out = CollisionResult(self.num_objects, own(self.device_triangle_pairs), own(self.device_colliding),
                              self.timings, self.num_candidates, self.num_broad_pairs, own(self.device_contained),
                              own(self.device_segments), own(self.device_toi), self.clearance, near, self_rows)
        out.host_ms, out.runs, out.object_world = self.host_ms, self.runs, self.object_world
        return out

    @cached_property
    def pair_world(self) -> np.ndarray:
        """``(K,)`` int64 world id of each row of :attr:`object_pairs`: its objects' world (the one not
        in world ``-1`` when one is; ``-1`` when both are); zeros for a scene without worlds."""
        p = self.object_pairs
        if self.object_world is None:
            return np.zeros(len(p), np.int64)
        return np.maximum(self.object_world[p[:, 0]], self.object_world[p[:, 1]]).astype(np.int64)

    @property
    def num_triangle_pairs(self) -> int:
        """``M``, the number of intersecting triangle pairs."""
        return self._num_triangle_pairs

    @cached_property
    def triangle_pairs(self) -> np.ndarray:
        """``(M, 4)`` int32 rows ``(obj_a, tri_a, obj_b, tri_b)``, ``obj_a < obj_b``, rows sorted.

        ``tri_a`` is the local triangle index within object ``obj_a``'s mesh.
        """
        t = self.device_triangle_pairs.numpy().reshape(-1, 4).astype(np.int32)
        self._order = np.lexsort((t[:, 3], t[:, 2], t[:, 1], t[:, 0]))
        return t[self._order]

    @cached_property
    def segments(self) -> np.ndarray | None:
        """``(M, 2, 3)`` end points of the intersection segment of each row of
        :attr:`triangle_pairs` (same order; a point when they only touch; NaN for coplanar
        contacts, whose intersection is an area). None unless asked for with ``segments=True``."""
        if self.device_segments is None:
            return None
        self.triangle_pairs  # noqa: B018 (computes the row order)
        return self.device_segments.numpy().reshape(-1, 2, 3)[self._order]

    @cached_property
    def object_pairs(self) -> np.ndarray:
        """``(K, 2)`` int32 pairs ``(a, b)``, ``a < b``, of objects whose surfaces intersect; sorted.
        With a clearance, the pairs whose surfaces come within it (the intersecting ones among them)."""
        if self.device_near is not None:
            return self._near_rows("device_near_pairs", (2,), np.int32)
        return self.intersecting_pairs

    @cached_property
    def intersecting_pairs(self) -> np.ndarray:
        """``(J, 2)`` int32 pairs ``(a, b)``, ``a < b``, of objects whose surfaces intersect (those of
        :attr:`triangle_pairs`), sorted: :attr:`object_pairs` without a clearance."""
        t = self.triangle_pairs
        if t.shape[0] == 0:
            return np.zeros((0, 2), np.int32)
        n = np.int64(max(self.num_objects, 1))
        key = np.unique(t[:, 0].astype(np.int64) * n + t[:, 2])  # one int64 key a row: no sort of records
        return np.stack([key // n, key % n], axis=1).astype(np.int32)

    @cached_property
    def containment_pairs(self) -> np.ndarray | None:
        """``(C, 2)`` int32 rows ``(inner, outer)``: ``inner`` lies wholly inside ``outer`` with no
        surface intersection; sorted. None unless the pipeline was built with ``containment=True``."""
        if self.device_contained is None:
            return None
        c = self.device_contained.numpy().reshape(-1, 2).astype(np.int32)
        if len(c) and len(self.triangle_pairs):
            # Drop pairs whose surfaces intersect: pair keys a * N + b (a < b) looked up in the sorted
            # keys of the intersecting object pairs.
            n = np.int64(self.num_objects)
            key = np.minimum(c[:, 0], c[:, 1]).astype(np.int64) * n + np.maximum(c[:, 0], c[:, 1])
            surface = self.intersecting_pairs[:, 0].astype(np.int64) * n + self.intersecting_pairs[:, 1]
            c = c[~np.isin(key, surface)].reshape(-1, 2)
        return c[np.lexsort((c[:, 1], c[:, 0]))]

    @cached_property
    def colliding(self) -> np.ndarray:
        """``(N,)`` bool: the object's surface intersects another object's (or, with containment
        asked for, it contains or lies inside another)."""
        flags = self.device_colliding.numpy().astype(bool)
        if self.device_contained is not None:
            flags[self.containment_pairs.ravel()] = True
        return flags

    def __repr__(self) -> str:
        toi = f", toi={self.toi}" if self.continuous else ""
        near = ""
        if self.device_near is not None:
            near = f", clearance={self.clearance}, near_pairs={len(self.object_pairs)}"
        if self.device_self_pairs is not None:
            near += f", self_pairs={self.device_self_pairs.shape[0]}"
        return (f"CollisionResult(objects={self.num_objects}, triangle_pairs={self.num_triangle_pairs}{toi}{near}, "
                f"timings={self.timings})")
