"""What ``warp-ccd check --clearance D`` adds: soft clashes, prim pairs closer than a clearance.

A check with a clearance ``D`` runs its pipeline with ``clearance=D``
(:mod:`warp_ccd._src.narrowphase.clearance`): every frame also reports the prim pairs whose surfaces come
within ``D``, with their least distance, the two closest points and the USD faces they lie on. A
*soft clash* is such a pair that the frame does not already report as a collision (penetrating, or
touching with ``count_touching``): a cable 3 mm from a hot part, a part resting on another (distance
0, touching). Soft clashes are findings (exit status 1) after penetration and tunnelling.

:class:`SoftClashes` holds one frame's; :func:`soft_clashes` makes them from a result;
:func:`clearance_json`, :func:`clearance_summary` and :func:`soft_clash_flags` give the report's
section, its lines of the summary and the overlay's flags (soft-clashing prims in yellow, their
closest points joined by curves).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .tables import pair_table, span

__all__ = ["COLOR_CLEARANCE", "COLOR_SOFT_CLASH", "SoftClashes", "clearance_json", "clearance_summary",
           "soft_clash_flags", "soft_clashes"]

COLOR_SOFT_CLASH = (0.98, 0.85, 0.2)
"""displayColor (linear RGB) in the overlay of a prim in a soft clash at a time code (where it neither
penetrates nor tunnels: those win)."""
COLOR_CLEARANCE = (0.1, 0.75, 0.95)
"""displayColor of the overlay's curves from each soft clash's closest point on one prim to the other's."""


@dataclass
class SoftClashes:
    """One frame's prim pairs within the clearance that it does not report as collisions.

    Attributes:
        object_pairs: ``(K, 2)`` int32 ``(a, b)``, ``a < b``, sorted.
        distance: ``(K,)`` float64 least distance of each pair's surfaces (0: they touch), scene units.
        points: ``(K, 2, 3)`` float64 closest points, on ``a`` then on ``b``.
        faces: ``(K, 2)`` int32 USD face indices ``(face_a, face_b)`` the points lie on.
    """

    object_pairs: np.ndarray
    distance: np.ndarray
    points: np.ndarray
    faces: np.ndarray


def soft_clashes(imp, result, reported: np.ndarray) -> SoftClashes:
    """The soft clashes of a frame.

    Args:
        imp: the :class:`~warp_ccd._src.usd.importer.UsdMeshImport` (its triangles' USD faces).
        result: the frame's :class:`~warp_ccd._src.pipeline.pipeline.CollisionResult` with a clearance.
        reported: ``(J, 2)`` object pairs the frame reports as collisions.

    Returns:
        The :class:`SoftClashes`: the result's pairs within the clearance less ``reported``.
    """
    pairs = np.asarray(result.object_pairs, np.int64).reshape(-1, 2)
    n = np.int64(max(len(imp.object_path), 1))
    keep = ~np.isin(pairs[:, 0] * n + pairs[:, 1], np.asarray(reported, np.int64).reshape(-1, 2) @ [n, 1])
    tri = result.closest_triangles[keep]
    pairs = pairs[keep]
    faces = np.stack([imp.faces(pairs[:, 0], tri[:, 0]), imp.faces(pairs[:, 1], tri[:, 1])], axis=1)
    return SoftClashes(pairs.astype(np.int32), result.object_distance[keep], result.closest_points[keep],
                       faces.astype(np.int32).reshape(-1, 2))


def clearance_pair_summary(frames: list, object_path: list) -> list[dict]:
    """Per prim pair in a soft clash in some frame: ``a``, ``b``, ``frames``, ``first``, ``last``,
    ``min_distance`` and the time code ``at`` of that least distance (the first of equals); most
    frames first."""
    stats: dict[tuple[int, int], dict] = {}
    for f in frames:
        near = f.soft_clashes
        if near is None:
            continue
        for (a, b), d in zip(near.object_pairs.tolist(), near.distance.tolist()):
            s = stats.setdefault((a, b), {"a": object_path[a], "b": object_path[b], "frames": 0, "first": f.time,
                                          "last": f.time, "min_distance": d, "at": f.time})
            s["frames"] += 1
            s["last"] = f.time
            if d < s["min_distance"]:
                s["min_distance"], s["at"] = d, f.time
    return sorted(stats.values(), key=lambda s: (-s["frames"], s["min_distance"], s["a"], s["b"]))


def frame_clearance_json(near: SoftClashes, object_path: list) -> list[dict]:
    """One frame's soft clashes as JSON rows: prims by path, faces, distance, closest points."""
    return [{"a": object_path[a], "b": object_path[b], "distance": d, "faces": fa, "points": p}
            for (a, b), d, fa, p in zip(near.object_pairs.tolist(), near.distance.tolist(), near.faces.tolist(),
                                        near.points.tolist())]


def clearance_json(frames: list, object_path: list, clearance: float) -> dict:
    """The report's ``clearance`` section: the distance, whether any frame has a soft clash, and the
    per prim pair summary (:func:`clearance_pair_summary`); each frame's rows are in its entry."""
    return {"clearance": clearance,
            "soft_clashes": any(f.soft_clashes is not None and len(f.soft_clashes.object_pairs) for f in frames),
            "pairs": clearance_pair_summary(frames, object_path)}


def clearance_summary(frames: list, object_path: list, clearance: float, top: int) -> list[str]:
    """The summary's lines on soft clashes."""
    hit = [f for f in frames if f.soft_clashes is not None and len(f.soft_clashes.object_pairs)]
    pairs = clearance_pair_summary(frames, object_path)
    lines = [f"  soft clashes (within {clearance:g}, not reported as collisions): {len(pairs)} prim pairs in "
             f"{len(hit)} of {len(frames)} frames"]
    return lines + pair_table(pairs, top, "frames  first..last  least distance (at)",
                              lambda p: f"{p['frames']:6d}  {span(p):<11}  {p['min_distance']:.4g} ({p['at']:g})")


def soft_clash_flags(frames: list, num_objects: int) -> np.ndarray:
    """``(F, N)`` bool: object ``i`` is in a soft clash at frame ``k``."""
    flags = np.zeros((len(frames), num_objects), bool)
    for k, f in enumerate(frames):
        if f.soft_clashes is not None:
            flags[k, f.soft_clashes.object_pairs.ravel()] = True
    return flags
