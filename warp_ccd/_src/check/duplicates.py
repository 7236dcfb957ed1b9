"""What ``warp-ccd check --duplicates`` adds: coincident meshes, the same geometry placed twice.

A CAD export often writes one part twice at the same place (two prims, or two references of one
asset, with the same world transform). The two surfaces then meet everywhere, and the check would
report them as a touching or penetrating pair. With ``duplicates=True`` such a pair is reported as a
*duplicate* instead, frame by frame, and left out of that frame's collisions.

**When two objects coincide.** At a time code, objects ``a`` and ``b`` are duplicates when their
world-space triangle sets are equal: the same number of triangles, and each triangle of one matches
a triangle of the other, as an unordered triple of world vertices, within a tolerance. The order of
a triangle's vertices (its winding) and the order of the triangles do not matter, so a copy with its
faces listed in another order, its vertices renumbered or its faces wound the other way is a
duplicate; a copy rotated or mirrored onto itself is one only where its triangles land on the
other's (a box turned half a turn about an axis through its faces' centres, whose fans map onto
themselves), not where the volumes coincide but the triangulations differ.

**Tolerance.** ``REL_TOL`` (1e-6) of the larger of the two meshes' bounding-box diagonals, and no
less than 4 rounding steps of the world coordinates' floating-point type at their magnitude (two
copies placed through different transform hierarchies differ by a few ulps). A copy moved by 1e-3 of
its size is not a duplicate.

**How, per pair** (numpy, no Python loop over triangles; ``O(m log m)`` for ``m`` triangles): the
triangle counts, then the bounding boxes are compared (most touching pairs stop here); each
triangle's vertices are put in a canonical order (by their projection on a generic direction), the
triangles sorted by their centroids' projection on another, and the two sorted arrays compared row
by row within the tolerance. Rounding the coordinates to a tolerance grid instead would split two
copies of a value that lie on either side of a cell boundary, and sorting by rounded values would
then disorder them; sorting by generic projections disorders only triangles whose keys lie within
the copies' rounding difference of each other (rare, and none for copies that are equal to the
last bit). The rows that still differ are looked for within :data:`WINDOW` positions in the other
array, as unordered vertex triples (in chunks of :data:`CHUNK` rows, stopping at the first that finds
no match: a copy that is not a duplicate costs one chunk).

Only the object pairs the detection reports are tested (coincident surfaces always intersect).
:func:`duplicate_pairs` tests a frame's pairs; :func:`duplicates_json`, :func:`frame_duplicates_json`,
:func:`duplicates_summary` and :func:`duplicate_flags` give the report's section and rows, its lines
of the summary and the overlay's flags (duplicate prims in blue).
"""

from __future__ import annotations

import itertools

import numpy as np

from .tables import pair_table, span

__all__ = ["CHUNK", "COLOR_DUPLICATE", "REL_TOL", "WINDOW", "coincident", "duplicate_flags", "duplicate_pair_summary",
           "duplicate_pairs", "duplicates_json", "duplicates_summary", "frame_duplicates_json"]

COLOR_DUPLICATE = (0.2, 0.45, 1.0)
"""displayColor (linear RGB) in the overlay of a prim that coincides with another at a time code (where
it neither penetrates, tunnels nor passes through itself: those win)."""
REL_TOL = 1e-6
"""The tolerance of :func:`coincident`, relative to the meshes' bounding-box diagonal."""
WINDOW = 4
"""How far (in sorted positions) a triangle that differs row by row is looked for in the other mesh."""
CHUNK = 4096
"""Rows matched at once by the window search (bounds its memory: about 4 kB a row)."""

_ORDER = np.array([1.0, 0.7548776662466927, 0.5698402909980532])
"""A generic direction (powers of the plastic number): the canonical order of a triangle's vertices."""
_ORDER /= np.linalg.norm(_ORDER)
_SORT = np.array([0.5772156649015329, 1.0, -0.8346268416740731])
"""Another generic direction: the order of the triangles, by their centroids."""
_SORT /= np.linalg.norm(_SORT)
_PERMS = np.array(list(itertools.permutations(range(3))))
"""``(6, 3)``: the orders of a triangle's three vertices."""


def _canonical(tri: np.ndarray) -> np.ndarray:
    """``(m, 3, 3)`` triangles, each one's vertices ordered by their projection on ``_ORDER``, the
    triangles by their centroids' projection on ``_SORT``."""
    order = np.argsort(tri @ _ORDER, axis=1, kind="stable")
    tri = np.take_along_axis(tri, order[:, :, None], axis=1)
    return tri[np.argsort(tri.sum(axis=1) @ _SORT, kind="stable")]


def _matched(p: np.ndarray, q: np.ndarray, rows: np.ndarray, tol: float) -> bool:
    """Whether each triangle ``p[rows]`` equals, as an unordered triple of vertices within ``tol``,
    one of ``q``'s within :data:`WINDOW` positions of its own."""
    m = len(q)
    for s in range(0, len(rows), CHUNK):
        part = rows[s:s + CHUNK]
        near = np.clip(part[:, None] + np.arange(-WINDOW, WINDOW + 1), 0, m - 1)  # (r, k)
        cand = q[near][:, :, _PERMS]  # (r, k, 6, 3, 3): every candidate in every vertex order
        dist = np.abs(cand - p[part][:, None, None]).max(axis=(3, 4)).min(axis=2)  # (r, k)
        if not (dist <= tol).any(axis=1).all():
            return False
    return True


def coincident(vertex_a: np.ndarray, triangle_a: np.ndarray, vertex_b: np.ndarray, triangle_b: np.ndarray,
               rel_tol: float = REL_TOL) -> bool:
    """Whether two meshes' triangle sets are equal (see the module docstring).

    Args:
        vertex_a: ``(n_a, 3)`` float32 or float64 world vertices of mesh ``a``, scene units.
        triangle_a: ``(m_a, 3)`` int vertex indices of its triangles.
        vertex_b: ``(n_b, 3)`` world vertices of mesh ``b``.
        triangle_b: ``(m_b, 3)`` int vertex indices of its triangles.
        rel_tol: tolerance relative to the larger bounding-box diagonal (>= 0).

    Returns:
        True when ``m_a == m_b > 0`` and every triangle of ``a`` matches one of ``b`` (and the other way
        round) as an unordered vertex triple within the tolerance.
    """
    triangle_a, triangle_b = np.asarray(triangle_a), np.asarray(triangle_b)
    m = len(triangle_a)
    if m == 0 or m != len(triangle_b):
        return False
    vertex_a, vertex_b = np.asarray(vertex_a), np.asarray(vertex_b)
    eps = max(np.finfo(v.dtype).eps if np.issubdtype(v.dtype, np.floating) else 0.0 for v in (vertex_a, vertex_b))
    a = vertex_a.astype(np.float64, copy=False)[triangle_a]  # (m, 3, 3)
    b = vertex_b.astype(np.float64, copy=False)[triangle_b]
    lo_a, hi_a = a.min(axis=(0, 1)), a.max(axis=(0, 1))
    lo_b, hi_b = b.min(axis=(0, 1)), b.max(axis=(0, 1))
    diag = max(float(np.linalg.norm(hi_a - lo_a)), float(np.linalg.norm(hi_b - lo_b)))
    reach = float(max(np.abs(lo_a).max(), np.abs(hi_a).max(), np.abs(lo_b).max(), np.abs(hi_b).max()))
    tol = max(rel_tol * diag, 4.0 * eps * reach)
    if np.abs(lo_a - lo_b).max() > tol or np.abs(hi_a - hi_b).max() > tol:
        return False
    a, b = _canonical(a), _canonical(b)
    rows = np.nonzero(np.abs(a - b).max(axis=(1, 2)) > tol)[0]
    if rows.size == 0:
        return True
    return _matched(a, b, rows, tol) and _matched(b, a, rows, tol)


def duplicate_pairs(scene, object_pairs: np.ndarray, rel_tol: float = REL_TOL) -> np.ndarray:
    """The object pairs among ``object_pairs`` whose meshes coincide at the scene's current pose.

    Args:
        scene: the :class:`~warp_ccd._src.scene.scene.Scene`, its world vertices set to the frame.
        object_pairs: ``(K, 2)`` int object pairs ``(a, b)`` (those the frame's detection reports).
        rel_tol: see :func:`coincident`.

    Returns:
        ``(D, 2)`` int32 rows of ``object_pairs`` that are duplicates, in their order.
    """
    pairs = np.asarray(object_pairs, np.int64).reshape(-1, 2)
    if len(pairs) == 0:
        return np.zeros((0, 2), np.int32)
    vstart, tstart = scene.object_vertex_start_np, scene.shapes.triangle_start
    shape = scene.object_shape_np
    ntri = tstart[shape + 1] - tstart[shape]
    # Only pairs of equal triangle counts are read back from the device.
    pairs = pairs[ntri[pairs[:, 0]] == ntri[pairs[:, 1]]]
    meshes: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def mesh(i: int) -> tuple[np.ndarray, np.ndarray]:
        if i not in meshes:
            s = int(shape[i])
            meshes[i] = (scene.world_vertex[int(vstart[i]):int(vstart[i + 1])].numpy(),
                         scene.shapes.triangles[int(tstart[s]):int(tstart[s + 1])])
        return meshes[i]

    keep = [(a, b) for a, b in pairs.tolist() if coincident(*mesh(a), *mesh(b), rel_tol=rel_tol)]
    return np.array(keep, np.int32).reshape(-1, 2)


def duplicate_pair_summary(frames: list, object_path: list) -> list[dict]:
    """Per prim pair that coincides in some frame: ``a``, ``b``, ``frames`` (how many), ``first``,
    ``last`` and ``times`` (the time codes); most frames first."""
    stats: dict[tuple[int, int], dict] = {}
    for f in frames:
        if f.duplicates is None:
            continue
        for a, b in f.duplicates.tolist():
            s = stats.setdefault((a, b), {"a": object_path[a], "b": object_path[b], "frames": 0, "first": f.time,
                                          "last": f.time, "times": []})
            s["frames"] += 1
            s["last"] = f.time
            s["times"].append(f.time)
    return sorted(stats.values(), key=lambda s: (-s["frames"], s["first"], s["a"], s["b"]))


def frame_duplicates_json(pairs: np.ndarray, object_path: list) -> list[dict]:
    """One frame's duplicates as JSON rows ``{"a", "b"}`` (prims by path)."""
    return [{"a": object_path[a], "b": object_path[b]} for a, b in pairs.tolist()]


def duplicates_json(frames: list, object_path: list, rel_tol: float = REL_TOL) -> dict:
    """The report's ``duplicates`` section: the relative tolerance, whether any frame has a duplicate,
    and the per prim pair summary (:func:`duplicate_pair_summary`); each frame's rows are in its entry."""
    return {"tolerance": float(rel_tol),
            "duplicated": any(f.duplicates is not None and len(f.duplicates) for f in frames),
            "pairs": duplicate_pair_summary(frames, object_path)}


def duplicates_summary(frames: list, object_path: list, top: int) -> list[str]:
    """The summary's lines on duplicates."""
    hit = [f for f in frames if f.duplicates is not None and len(f.duplicates)]
    pairs = duplicate_pair_summary(frames, object_path)
    lines = [f"  duplicates (coincident meshes, not reported as collisions): {len(pairs)} prim pairs in "
             f"{len(hit)} of {len(frames)} frames"]
    return lines + pair_table(pairs, top, "frames  first..last", lambda p: f"{p['frames']:6d}  {span(p)}")


def duplicate_flags(frames: list, num_objects: int) -> np.ndarray:
    """``(F, N)`` bool: object ``i`` coincides with another at frame ``k``."""
    flags = np.zeros((len(frames), num_objects), bool)
    for k, f in enumerate(frames):
        if f.duplicates is not None:
            flags[k, f.duplicates.ravel()] = True
    return flags
