"""What ``warp-ccd check --self`` adds: meshes that pass through themselves.

A check with ``self_intersections=True`` runs its pipeline with ``self_intersections=True``
(:mod:`warp_ccd._src.narrowphase.self_intersection`): every frame also reports, per prim, the pairs of its own
triangles that meet beyond the vertices they share (a cloth folded through itself, an arm through the
torso of one skinned mesh, a CAD export whose bodies overlap in one mesh), as pairs of its USD faces
with their depth (the deepest crossing of their triangles, :func:`~warp_ccd.geometry.crossing_depth`:
0 for a fold flat onto itself). Self-intersections are findings (exit status 1) after penetration and
tunnelling.

:class:`SelfIntersections` holds one frame's; :func:`self_intersections` makes them from a result;
:func:`self_json`, :func:`self_summary` and :func:`self_flags` give the report's section, its lines of
the summary and the overlay's flags (self-intersecting prims in magenta).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["COLOR_SELF", "SelfIntersections", "frame_self_json", "self_flags", "self_intersections", "self_json",
           "self_summary"]

COLOR_SELF = (0.85, 0.2, 0.85)
"""displayColor (linear RGB) in the overlay of a prim that intersects itself at a time code (where it
neither penetrates another nor tunnels: those win)."""


@dataclass
class SelfIntersections:
    """One frame's self-intersections.

    Attributes:
        face_pairs: ``(M, 3)`` int32 rows ``(object, face_a, face_b)``, ``face_a <= face_b`` (USD face
            indices; equal where two triangles of one fanned polygon meet), sorted, unique.
        depth: ``(M,)`` float64, the deepest crossing of each row's triangle pairs, scene units.
    """

    face_pairs: np.ndarray
    depth: np.ndarray

    @property
    def objects(self) -> np.ndarray:
        """The objects that intersect themselves, sorted."""
        return np.unique(self.face_pairs[:, 0]).astype(np.int32)


def self_intersections(imp, result, phase) -> SelfIntersections:
    """The self-intersections of a frame.

    Args:
        imp: the :class:`~warp_ccd._src.usd.importer.UsdMeshImport` (its triangles' USD faces).
        result: the frame's :class:`~warp_ccd._src.pipeline.pipeline.CollisionResult` with ``self_pairs``.
        phase: the pipeline's :class:`~warp_ccd._src.narrowphase.self_intersection.SelfIntersection` (depths).
    """
    rows = result.self_pairs
    if len(rows) == 0:
        return SelfIntersections(np.zeros((0, 3), np.int32), np.zeros(0))
    depth = phase.depth(imp.scene, rows)
    fa = imp.faces(rows[:, 0], rows[:, 1])
    fb = imp.faces(rows[:, 0], rows[:, 2])
    faces = np.stack([rows[:, 0], np.minimum(fa, fb), np.maximum(fa, fb)], axis=1).astype(np.int64)
    keys, inverse = np.unique(faces, axis=0, return_inverse=True)
    deepest = np.zeros(len(keys))
    np.maximum.at(deepest, inverse.ravel(), depth)
    return SelfIntersections(keys.astype(np.int32), deepest)


def self_prim_summary(frames: list, object_path: list) -> list[dict]:
    """Per prim that intersects itself in some frame: ``prim``, ``frames``, ``first``, ``last``,
    ``max_face_pairs`` in one frame and ``max_depth``; most frames first."""
    stats: dict[int, dict] = {}
    for f in frames:
        found = f.self_intersections
        if found is None or not len(found.face_pairs):
            continue
        for obj in found.objects.tolist():
            mine = found.face_pairs[:, 0] == obj
            s = stats.setdefault(obj, {"prim": object_path[obj], "frames": 0, "first": f.time, "last": f.time,
                                       "max_face_pairs": 0, "max_depth": 0.0})
            s["frames"] += 1
            s["last"] = f.time
            s["max_face_pairs"] = max(s["max_face_pairs"], int(mine.sum()))
            s["max_depth"] = max(s["max_depth"], float(found.depth[mine].max()))
    return sorted(stats.values(), key=lambda s: (-s["frames"], -s["max_depth"], s["prim"]))


def frame_self_json(found: SelfIntersections, object_path: list) -> list[dict]:
    """One frame's self-intersections as JSON rows: prim by path, USD faces, depth."""
    return [{"prim": object_path[o], "faces": [a, b], "depth": d}
            for (o, a, b), d in zip(found.face_pairs.tolist(), found.depth.tolist())]


def self_json(frames: list, object_path: list) -> dict:
    """The report's ``self_intersections`` section: whether any frame has one, and the per prim summary
    (:func:`self_prim_summary`); each frame's rows are in its entry."""
    return {"self_intersecting": any(f.self_intersections is not None and len(f.self_intersections.face_pairs)
                                     for f in frames),
            "prims": self_prim_summary(frames, object_path)}


def self_summary(frames: list, object_path: list, top: int) -> list[str]:
    """The summary's lines on self-intersections."""
    hit = [f for f in frames if f.self_intersections is not None and len(f.self_intersections.face_pairs)]
    prims = self_prim_summary(frames, object_path)
    lines = [f"  self-intersections: {len(prims)} prims in {len(hit)} of {len(frames)} frames"]
    if prims:
        w = min(max(len(p["prim"]) for p in prims[:top]), 60)
        lines.append(f"  {'prim':<{w}}  frames  first..last  face pairs  max depth")
        for p in prims[:top]:
            span = f"{p['first']:g}..{p['last']:g}"
            lines.append(f"  {p['prim']:<{w}}  {p['frames']:6d}  {span:<11}  {p['max_face_pairs']:10d}  "
                         f"{p['max_depth']:.4g}")
        if len(prims) > top:
            lines.append(f"  ... {len(prims) - top} more prims (see the report)")
    return lines


def self_flags(frames: list, num_objects: int) -> np.ndarray:
    """``(F, N)`` bool: object ``i`` intersects itself at frame ``k``."""
    flags = np.zeros((len(frames), num_objects), bool)
    for k, f in enumerate(frames):
        if f.self_intersections is not None:
            flags[k, f.self_intersections.objects] = True
    return flags
