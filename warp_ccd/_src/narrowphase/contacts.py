"""Contacts a solver can use: per contact a point on each surface, a normal and a depth, a few per object pair.

**What a contact is.** For an object pair ``(a, b)``, ``a < b``: ``point_a`` on the surface of ``a``, ``point_b`` on
the surface of ``b``, a unit ``normal`` from ``b`` to ``a`` (``a`` moves along ``+normal`` to separate) and a
``depth``, with ``point_a = point_b - depth * normal``. ``depth >= 0`` measures penetration with the definition of
:mod:`~warp_ccd._src.narrowphase.depth`: a point of one surface inside the other object's solid, its distance to
that surface; ``depth < 0`` is a speculative contact of a pair apart by ``-depth`` within the margin.

**Candidates** (one pass over the frame's intersecting triangle pairs, the rows):

* *deepest*: the pair's depth witness (:class:`~warp_ccd._src.narrowphase.depth.PenetrationDepth`): the deepest
  point of either surface inside the other's solid and its nearest point on that other surface. Its depth is the
  pair's depth.
* *vertices*: each vertex of a row's triangle that lies inside the other object's closed solid, with its nearest
  point on the other surface and its own depth (a box resting on a floor: its corners).
* *crossing*: the ends of each row's intersection segment, or the corners of the area where coplanar triangles
  overlap, on both surfaces at once (depth 0): where the surfaces meet; the outline of the contact region (and
  the only contacts of open surfaces, which bound no solid, and of surfaces resting on each other).
* *near* (a margin ``d > 0``): a pair apart but within ``d`` gets its closest points, ``depth = -distance``.

The normal of a contact deeper than its tolerance is the direction between its two points. One at depth 0 (a
crossing's end, a vertex on the other surface) has no direction of its own: it takes the pair's *reference
normal*, the deepest contact's direction, or where the pair has none (touching, or open surfaces), the faces':
``n_b - n_a`` normalised (``n_b``, ``b``'s outward normal, where that vanishes: coincident faces). Never zero.

**Reduction** to at most ``max_per_pair`` contacts a pair (default :data:`MAX_PER_PAIR` ``= 8``: 4 span one flat
patch, as box-box manifolds do; 8 leave room for a second patch of a non-convex pair, a peg in a hole touching
two walls): the deepest first, then the one farthest from it, then the one spanning the largest triangle with
those two, then, one at a time, the one farthest from all chosen (the outline of the region). Candidates with
a positive depth are preferred to those at depth 0 at each step. Scores within a relative
:data:`TIE_TOLERANCE` of the best count as equal and the first by identity (kind, vertex or row) wins: objects
that barely move keep the same contacts, not ones flipping among equals.

All in float64 on the world vertices; the candidates are sorted by ``(pair, identity)`` with
``wp.utils.radix_sort_pairs``; one thread a pair reduces. Device agnostic: every device gives the same contacts.
"""

from __future__ import annotations

from functools import cached_property
from typing import Any

import numpy as np
import warp as wp

from ..geometry.precision import precision_overloads
from ..geometry.primitives import _unit_normal
from ..geometry.triangle import CONTACT_AREA, CONTACT_SEGMENT, tri_tri_segment
from ..geometry.triangle import TOLERANCE as TRIANGLE_TOLERANCE
from ..runtime.buffers import WorkArrays, upper_bound
from ..runtime.options import check_option
from ..scene.scene import MeshTopology, Scene, mesh_triangle
from ..trees.bvh import SceneBVH, TreeView
from .depth import _probe, nearest_point
from .surface import SurfaceTopology

__all__ = ["KIND_CROSSING", "KIND_DEEPEST", "KIND_NEAR", "KIND_VERTEX", "MAX_PER_PAIR", "TIE_TOLERANCE", "Contacts",
           "ContactStage"]

wp.set_module_options({"enable_backward": False, "fuse_fp": False})

MAX_PER_PAIR = 8
"""Default most contacts an object pair keeps (module docstring)."""
MAX_PER_PAIR_LIMIT = 32
"""Largest ``max_per_pair`` accepted (the option's rule, :data:`~warp_ccd._src.runtime.options.OPTIONS`)."""
TIE_TOLERANCE = 1.0e-6
"""Scores (depths, distances, areas) within this fraction of the best are equal: the first by identity wins."""
_TIE = wp.constant(wp.float64(TIE_TOLERANCE))
KIND_DEEPEST = wp.constant(0)
"""Candidate kind: the pair's depth witness."""
KIND_VERTEX = wp.constant(1)
"""Candidate kind: a vertex of a row's triangle inside the other solid."""
KIND_CROSSING = wp.constant(2)
"""Candidate kind: an end of a row's intersection segment."""
KIND_NEAR = wp.constant(3)
"""Candidate kind: the closest points of a pair apart within the margin."""
NO_KEY = wp.constant(wp.int64(0x7FFFFFFFFFFFFFFF))
"""Key of an empty candidate slot: sorted last."""
ROW_SLOTS = 12
"""Candidate slots of a row: three vertices of each triangle, then the two ends of its segment or the (at most
six) corners of the area where coplanar triangles overlap."""

_Chosen = wp.types.vector(length=MAX_PER_PAIR_LIMIT, dtype=wp.int32)
_Polygon = wp.types.matrix(shape=(9, 3), dtype=wp.float64)


@wp.func
def _key(pair: int, kind: int, ident: int):
    """A candidate's sort key: its pair, then its kind, then its identity (a vertex or a row end)."""
    return wp.int64(pair) * wp.int64(4294967296) + wp.int64(kind) * wp.int64(1073741824) + wp.int64(ident)


@wp.func
def _outward(mesh: MeshTopology, surface: SurfaceTopology, world_vertex: wp.array[Any], obj: int, tri: int,
             tol_rel: wp.float64):
    """The outward unit normal of a local triangle (zero for a degenerate one)."""
    y0, y1, y2 = mesh_triangle(mesh, world_vertex, obj, tri)
    n, degenerate = _unit_normal(wp.vec3d(y0), wp.vec3d(y1), wp.vec3d(y2), tol_rel)
    if degenerate:
        return wp.vec3d()
    return n * surface.shape_side[mesh.object_shape[obj]]


@wp.func
def _face_normal(na: wp.vec3d, nb: wp.vec3d):
    """A normal from ``b`` to ``a`` from two faces' outward normals: ``nb - na`` normalised, else ``nb``, else
    ``-na``, else ``+z``."""
    m = nb - na
    if wp.length(m) > wp.float64(1.0e-6):
        return wp.normalize(m)
    if wp.length(nb) > wp.float64(0.5):
        return nb
    if wp.length(na) > wp.float64(0.5):
        return -na
    return wp.vec3d(wp.float64(0.0), wp.float64(0.0), wp.float64(1.0))


@wp.func
def _corner_of(poly: _Polygon, i: int):
    return wp.vec3d(poly[i, 0], poly[i, 1], poly[i, 2])


@wp.func
def _clip_edge(poly: _Polygon, count: int, o: wp.vec3d, m: wp.vec3d, eps: wp.float64):
    """Sutherland-Hodgman: the polygon's part where ``dot(x - o, m) >= -eps``."""
    out = _Polygon()
    k = int(0)
    for i in range(count):
        p = _corner_of(poly, i)
        q = _corner_of(poly, (i + 1) % count)
        dp = wp.dot(p - o, m)
        dq = wp.dot(q - o, m)
        if dp >= -eps:
            if k < 9:
                out[k, 0] = p[0]
                out[k, 1] = p[1]
                out[k, 2] = p[2]
                k += 1
        if (dp >= -eps) != (dq >= -eps):
            x = p + (q - p) * (dp / (dp - dq))
            if k < 9:
                out[k, 0] = x[0]
                out[k, 1] = x[1]
                out[k, 2] = x[2]
                k += 1
    return out, k


@wp.func
def _coplanar_overlap(x0: wp.vec3d, x1: wp.vec3d, x2: wp.vec3d, y0: wp.vec3d, y1: wp.vec3d, y2: wp.vec3d,
                      eps: wp.float64):
    """The corners of the area where two coplanar triangles overlap: ``a``'s triangle clipped by ``b``'s edges
    (within ``eps``). ``(corners, count)``."""
    poly = _Polygon()
    for i in range(3):
        x = x0
        if i == 1:
            x = x1
        if i == 2:
            x = x2
        poly[i, 0] = x[0]
        poly[i, 1] = x[1]
        poly[i, 2] = x[2]
    count = int(3)
    nb = wp.cross(y1 - y0, y2 - y0)
    for i in range(3):
        p = y0
        q = y1
        if i == 1:
            p = y1
            q = y2
        if i == 2:
            p = y2
            q = y0
        m = wp.cross(nb, q - p)
        ml = wp.length(m)
        if ml > wp.float64(0.0) and count > 0:
            poly, count = _clip_edge(poly, count, p, m / ml, eps)
    return poly, count


@wp.func
def _one_side(n: wp.vec3d, o: wp.vec3d, x0: wp.vec3d, x1: wp.vec3d, x2: wp.vec3d, eps: wp.float64):
    """Whether a triangle lies on one side of the plane through ``o`` with normal ``n`` (within ``eps``)."""
    d0 = wp.dot(x0 - o, n)
    d1 = wp.dot(x1 - o, n)
    d2 = wp.dot(x2 - o, n)
    return (d0 >= -eps and d1 >= -eps and d2 >= -eps) or (d0 <= eps and d1 <= eps and d2 <= eps)


@wp.func
def _touch_normal(x0: wp.vec3d, x1: wp.vec3d, x2: wp.vec3d, y0: wp.vec3d, y1: wp.vec3d, y2: wp.vec3d, na: wp.vec3d,
                  nb: wp.vec3d, eps: wp.float64):
    """The normal where triangles of ``a`` and ``b`` meet, in a pair with no depth: the face one triangle rests on
    (``a``'s triangle on one side of ``b``'s plane: ``nb``; ``b``'s on one side of ``a``'s: ``-na``), else
    :func:`_face_normal`. A cube resting on a floor: the floor's normal along the cube's bottom edges too."""
    a_rests = wp.length(nb) > wp.float64(0.5) and _one_side(nb, y0, x0, x1, x2, eps)
    b_rests = wp.length(na) > wp.float64(0.5) and _one_side(na, x0, y0, y1, y2, eps)
    if a_rests and not b_rests:
        return nb
    if b_rests and not a_rests:
        return -na
    return _face_normal(na, nb)


@wp.kernel
def _row_candidates_kernel(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    tree: TreeView,
    pose: wp.array[Any],
    scale: wp.array[wp.float32],
    deforming: wp.array[wp.int32],
    world_vertex: wp.array[Any],
    object_solid: wp.array[wp.int32],
    row: wp.array[wp.vec4i],
    row_pair: wp.array[wp.int32],
    pair_reference: wp.array[wp.vec3d],
    tol_rel: wp.float64,
    # Outputs
    cand_key: wp.array[wp.int64],
    cand_point_a: wp.array[wp.vec3d],
    cand_point_b: wp.array[wp.vec3d],
    cand_normal: wp.array[wp.vec3d],
    cand_depth: wp.array[wp.float64],
    cand_triangles: wp.array[wp.vec2i],
):
    """One thread per row and slot (:data:`ROW_SLOTS`): slots 0-2 the vertices of ``a``'s triangle inside ``b``'s
    solid, 3-5 those of ``b``'s inside ``a``'s, 6-7 the ends of the segment where the triangles meet."""
    k, slot = wp.tid()
    c = k * ROW_SLOTS + slot
    cand_key[c] = NO_KEY
    rw = row[k]
    oa = rw[0]
    ta = rw[1]
    ob = rw[2]
    tb = rw[3]
    p = row_pair[k]
    ref = pair_reference[p]
    a0, a1, a2 = mesh_triangle(mesh, world_vertex, oa, ta)
    b0, b1, b2 = mesh_triangle(mesh, world_vertex, ob, tb)
    x0 = wp.vec3d(a0)
    x1 = wp.vec3d(a1)
    x2 = wp.vec3d(a2)
    y0 = wp.vec3d(b0)
    y1 = wp.vec3d(b1)
    y2 = wp.vec3d(b2)
    size = wp.max(wp.max(wp.length(x1 - x0), wp.length(x2 - x1)), wp.max(wp.length(y1 - y0), wp.length(y2 - y1)))
    eps = tol_rel * size
    if slot < 6:
        side = slot // 3  # 0: a vertex of a inside b; 1: a vertex of b inside a
        i = slot % 3
        src = oa
        dst = ob
        tsrc = ta
        if side == 1:
            src = ob
            dst = oa
            tsrc = tb
        if object_solid[dst] == 0:
            return
        s = mesh.object_shape[src]
        local = mesh.shape_triangle[mesh.shape_triangle_start[s] + tsrc][i]
        v = wp.vec3d(world_vertex[mesh.object_vertex_start[src] + local])
        d, t, inside = _probe(mesh, surface, tree, pose, scale, deforming, world_vertex, dst, v, tol_rel)
        if not inside:
            return
        q = nearest_point(mesh, world_vertex, dst, t, v)
        gap = q - v
        depth = wp.length(gap)
        if side == 0:  # v on a, q on b: a moves along q - v to leave
            cand_point_a[c] = v
            cand_point_b[c] = q
            cand_triangles[c] = wp.vec2i(ta, t)
        else:  # v on b, q on a: a moves along v - q ... written as point_b - point_a
            cand_point_a[c] = q
            cand_point_b[c] = v
            cand_triangles[c] = wp.vec2i(t, tb)
            gap = v - q
        n = ref
        if depth > eps:
            n = gap / depth
        elif wp.length(ref) < wp.float64(0.5):
            nd = _outward(mesh, surface, world_vertex, dst, t, tol_rel)
            if side == 0:
                n = _face_normal(wp.vec3d(), nd)
            else:
                n = _face_normal(nd, wp.vec3d())
        cand_normal[c] = n
        cand_depth[c] = depth
        cand_key[c] = _key(p, KIND_VERTEX, side * (1 << 29) + local)
        return
    kind, s0, s1 = tri_tri_segment(x0, x1, x2, y0, y1, y2, tol_rel)
    e = slot - 6
    q = s0
    if kind == CONTACT_SEGMENT:
        if e > 1 or (e == 1 and wp.length(s1 - s0) <= eps):
            return  # the two ends (one, for a segment of no length)
        if e == 1:
            q = s1
    elif kind == CONTACT_AREA:
        poly, count = _coplanar_overlap(x0, x1, x2, y0, y1, y2, eps)
        if e >= count:
            return
        q = _corner_of(poly, e)
    else:
        return
    n = ref
    if wp.length(ref) < wp.float64(0.5):
        n = _touch_normal(x0, x1, x2, y0, y1, y2, _outward(mesh, surface, world_vertex, oa, ta, tol_rel),
                          _outward(mesh, surface, world_vertex, ob, tb, tol_rel), eps)
    cand_point_a[c] = q
    cand_point_b[c] = q
    cand_normal[c] = n
    cand_depth[c] = wp.float64(0.0)
    cand_triangles[c] = wp.vec2i(ta, tb)
    cand_key[c] = _key(p, KIND_CROSSING, 6 * k + e)


@wp.kernel
def _pair_candidates_kernel(
    pair_point: wp.array2d[wp.float64],
    pair_triangles: wp.array[wp.vec2i],
    pair_kind: wp.array[wp.int32],
    offset: int,
    # Outputs
    cand_key: wp.array[wp.int64],
    cand_point_a: wp.array[wp.vec3d],
    cand_point_b: wp.array[wp.vec3d],
    cand_normal: wp.array[wp.vec3d],
    cand_depth: wp.array[wp.float64],
    cand_triangles: wp.array[wp.vec2i],
):
    """One thread per pair: its deepest contact (the depth's witness) or its near contact (closest points of a pair
    apart), given as points on ``a`` and on ``b``; ``pair_kind`` -1 where it has none."""
    p = wp.tid()
    c = offset + p
    cand_key[c] = NO_KEY
    kind = pair_kind[p]
    if kind < 0:
        return
    pa = wp.vec3d(pair_point[p, 0], pair_point[p, 1], pair_point[p, 2])
    pb = wp.vec3d(pair_point[p, 3], pair_point[p, 4], pair_point[p, 5])
    gap = pb - pa
    dist = wp.length(gap)
    if dist <= wp.float64(0.0):
        return
    n = gap / dist
    depth = dist
    if kind == KIND_NEAR:  # apart: a lies along the normal from b
        n = -n
        depth = -dist
    cand_point_a[c] = pa
    cand_point_b[c] = pb
    cand_normal[c] = n
    cand_depth[c] = depth
    cand_triangles[c] = pair_triangles[p]
    cand_key[c] = _key(p, kind, 0)


@wp.func
def _area(a: wp.vec3d, b: wp.vec3d, c: wp.vec3d):
    return wp.length(wp.cross(b - a, c - a)) * wp.float64(0.5)


@wp.func
def _score(step: int, chosen: _Chosen, m: int, point: wp.array[wp.vec3d], order: wp.array[wp.int32], c: int):
    """What candidate ``c`` adds at ``step``: its distance from the first chosen (step 1), the area it spans with the
    first two (step 2), its least distance from all chosen (later); -1 if already chosen."""
    x = point[order[c]]
    least = wp.float64(1.0e300)
    for i in range(m):
        if chosen[i] == c:
            return wp.float64(-1.0)
        least = wp.min(least, wp.length(x - point[order[chosen[i]]]))
    if step == 1:
        return wp.length(x - point[order[chosen[0]]])
    if step == 2:
        return _area(point[order[chosen[0]]], point[order[chosen[1]]], x)
    return least


@wp.func
def _next(step: int, chosen: _Chosen, m: int, point: wp.array[wp.vec3d], depth: wp.array[wp.float64],
          order: wp.array[wp.int32], first: int, end: int, zero: wp.float64, floor: wp.float64):
    """The candidate of ``[first, end)`` (sorted positions) that adds most at ``step`` (:func:`_score`), among those
    deeper than ``zero`` first, then among all: the first within :data:`TIE_TOLERANCE` of the best; -1 where none
    adds more than ``floor``."""
    for tier in range(2):
        top = wp.float64(0.0)
        for c in range(first, end):
            if tier == 0 and depth[order[c]] <= zero:
                continue
            top = wp.max(top, _score(step, chosen, m, point, order, c))
        if top > floor:
            for c in range(first, end):
                if tier == 0 and depth[order[c]] <= zero:
                    continue
                if _score(step, chosen, m, point, order, c) >= top * (wp.float64(1.0) - _TIE):
                    return c
    return int(-1)


@wp.kernel
def _reduce_kernel(
    sorted_key: wp.array[wp.int64],
    order: wp.array[wp.int32],
    num_candidates: int,
    cand_point_a: wp.array[wp.vec3d],
    cand_depth: wp.array[wp.float64],
    max_per_pair: int,
    tol_rel: wp.float64,
    # Outputs
    pair_chosen: wp.array2d[wp.int32],
    pair_count: wp.array[wp.int32],
):
    """One thread per pair: its candidates (a range of the sorted keys) reduced to at most ``max_per_pair``
    (module docstring), as indices into the candidate arrays."""
    p = wp.tid()
    first = upper_bound(sorted_key, 0, num_candidates, wp.int64(p) * wp.int64(4294967296) - wp.int64(1))
    end = upper_bound(sorted_key, first, num_candidates, wp.int64(p + 1) * wp.int64(4294967296) - wp.int64(1))
    pair_count[p] = 0
    if end <= first:
        return
    chosen = _Chosen()
    # The deepest: the first within the tie tolerance of the deepest.
    best = wp.float64(-1.0e300)
    for c in range(first, end):
        best = wp.max(best, cand_depth[order[c]])
    pick = first
    for c in range(first, end):
        if cand_depth[order[c]] >= best - _TIE * wp.abs(best):
            pick = c
            break
    chosen[0] = pick
    m = int(1)
    # How far the candidates spread: below the tolerance of it, points are one.
    spread = wp.float64(0.0)
    for c in range(first, end):
        spread = wp.max(spread, wp.length(cand_point_a[order[c]] - cand_point_a[order[pick]]))
    eps = tol_rel * spread
    zero = wp.max(_TIE * wp.abs(best), eps)
    while m < max_per_pair:
        step = wp.min(m, 3)
        floor = eps
        if step == 2:
            floor = eps * spread
        found = _next(step, chosen, m, cand_point_a, cand_depth, order, first, end, zero, floor)
        if found < 0 and step == 2:  # all on one line: the farthest from the chosen instead
            found = _next(3, chosen, m, cand_point_a, cand_depth, order, first, end, zero, eps)
        if found < 0:
            break
        chosen[m] = found
        m += 1
    for i in range(m):
        pair_chosen[p, i] = order[chosen[i]]
    pair_count[p] = m


@wp.kernel
def _gather_kernel(
    pair_chosen: wp.array2d[wp.int32],
    pair_count: wp.array[wp.int32],
    pair_start: wp.array[wp.int32],
    pair_ids: wp.array[wp.vec2i],
    cand_point_a: wp.array[wp.vec3d],
    cand_point_b: wp.array[wp.vec3d],
    cand_normal: wp.array[wp.vec3d],
    cand_depth: wp.array[wp.float64],
    cand_triangles: wp.array[wp.vec2i],
    # Outputs
    out_pairs: wp.array[wp.vec2i],
    out_point_a: wp.array[wp.vec3d],
    out_point_b: wp.array[wp.vec3d],
    out_normal: wp.array[wp.vec3d],
    out_depth: wp.array[wp.float64],
    out_triangles: wp.array[wp.vec2i],
):
    """One thread per pair and slot: the chosen contacts, packed pair after pair."""
    p, i = wp.tid()
    if i >= pair_count[p]:
        return
    c = pair_chosen[p, i]
    o = pair_start[p] + i
    out_pairs[o] = pair_ids[p]
    out_point_a[o] = cand_point_a[c]
    out_point_b[o] = cand_point_b[c]
    out_normal[o] = cand_normal[c]
    out_depth[o] = cand_depth[c]
    out_triangles[o] = cand_triangles[c]


_ROW_CANDIDATES = precision_overloads(_row_candidates_kernel,
                                      lambda s, v, q, t: {"world_vertex": wp.array[v], "pose": wp.array[t]})


class Contacts:
    """Contacts of a frame (module docstring): device arrays, read to the host on first access.

    Attributes:
        count: number of contacts ``C``.
        device_pairs, device_point_a, device_point_b, device_normal, device_depth, device_triangles: device arrays
            of at least ``C`` items (``wp.vec2i``, ``wp.vec3d`` x3, float64, ``wp.vec2i``); ``device_count``: ``(1,)``
            int32 holding ``C``.
        pair_depth: ``(K,)`` float64 the depth of each object pair of :attr:`object_pairs` (NaN: neither closed).
    """

    def __init__(self, count: int, device_pairs: wp.array, device_point_a: wp.array, device_point_b: wp.array,
                 device_normal: wp.array, device_depth: wp.array, device_triangles: wp.array, device_count: wp.array,
                 object_pairs: np.ndarray, pair_depth: np.ndarray) -> None:
        self.count = int(count)
        self.device_pairs = device_pairs
        self.device_point_a = device_point_a
        self.device_point_b = device_point_b
        self.device_normal = device_normal
        self.device_depth = device_depth
        self.device_triangles = device_triangles
        self.device_count = device_count
        self.object_pairs = np.asarray(object_pairs, np.int32).reshape(-1, 2)
        self.pair_depth = np.asarray(pair_depth, np.float64)

    def _read(self, a, shape) -> np.ndarray:
        if self.count == 0:
            return np.zeros((0, *shape[1:]))
        return a[: self.count].numpy().reshape(shape)

    @cached_property
    def pairs(self) -> np.ndarray:
        """``(C, 2)`` int32 object ids ``(a, b)``, ``a < b``; a pair's contacts together, pairs sorted."""
        return self._read(self.device_pairs, (-1, 2)).astype(np.int32)

    @cached_property
    def point_a(self) -> np.ndarray:
        """``(C, 3)`` float64 world points on the surface of ``a``."""
        return self._read(self.device_point_a, (-1, 3)).astype(np.float64)

    @cached_property
    def point_b(self) -> np.ndarray:
        """``(C, 3)`` float64 world points on the surface of ``b``."""
        return self._read(self.device_point_b, (-1, 3)).astype(np.float64)

    @cached_property
    def normal(self) -> np.ndarray:
        """``(C, 3)`` float64 unit normals from ``b`` to ``a``: ``a`` moves along it to separate."""
        return self._read(self.device_normal, (-1, 3)).astype(np.float64)

    @cached_property
    def depth(self) -> np.ndarray:
        """``(C,)`` float64: penetration (>= 0; ``point_a = point_b - depth * normal``), or minus the separation of a
        speculative contact (< 0)."""
        return self._read(self.device_depth, (-1,)).astype(np.float64)

    @cached_property
    def triangles(self) -> np.ndarray:
        """``(C, 2)`` int32 the local triangles of ``a`` and ``b`` each contact lies on."""
        return self._read(self.device_triangles, (-1, 2)).astype(np.int32)

    def __len__(self) -> int:
        return self.count

    def __repr__(self) -> str:
        deepest = f", deepest={self.depth.max():.6g}" if self.count else ""
        return f"Contacts(count={self.count}, pairs={len(self.object_pairs)}{deepest})"


class ContactStage:
    """Contacts from a frame's rows, the pairs' depths and (with a margin) their near pairs (module docstring).

    Owns its work arrays (grown as needed).

    Args:
        scene: the :class:`~warp_ccd._src.scene.scene.Scene`.
        trees: the :class:`~warp_ccd._src.trees.bvh.SceneBVH` nearest points are found down (as the frame left it).
        surface: the scene's :class:`~warp_ccd._src.narrowphase.surface.SurfaceTopology`.
        object_solid: ``(N,)`` int, nonzero for an object with a closed surface.
        max_per_pair: most contacts a pair keeps (:data:`MAX_PER_PAIR`).
        tolerance: relative tolerance (of triangle sizes: a depth below it has no direction of its own).
    """

    def __init__(self, scene: Scene, trees: SceneBVH, surface: SurfaceTopology, object_solid: np.ndarray, *,
                 max_per_pair: int = MAX_PER_PAIR, tolerance: float = TRIANGLE_TOLERANCE) -> None:
        self.scene = scene
        self.trees = trees
        self.surface = surface
        self.max_per_pair = check_option("max_per_pair", max_per_pair)
        self.tolerance = float(tolerance)
        self.object_solid = wp.array(np.asarray(object_solid, np.int32), dtype=wp.int32, device=scene.device)
        self._work = WorkArrays(scene.device)

    def __call__(self, pairs: np.ndarray, rows: np.ndarray, pair_depth: np.ndarray, pair_points: np.ndarray,
                 pair_triangles: np.ndarray, near: dict | None = None) -> Contacts:
        """The contacts of object pairs.

        Args:
            pairs: ``(K, 2)`` object pairs ``a < b``, sorted, unique: those that intersect, then (with a margin)
                those apart within it.
            rows: ``(M, 4)`` rows ``(obj_a, tri_a, obj_b, tri_b)`` of triangles that meet (of the first pairs).
            pair_depth: ``(K,)`` each pair's depth (NaN: undefined; apart pairs: ignored).
            pair_points: ``(K, 2, 3)`` each pair's depth witness (points on ``a``, on ``b``; NaN: none), or for a
                pair apart its closest points.
            pair_triangles: ``(K, 2)`` the witness's (or closest points') triangles.
            near: None, or ``{"apart": (K,) bool}``: which pairs are apart (their points are closest points).

        Returns:
            The :class:`Contacts`.
        """
        scene, d = self.scene, self.scene.device
        pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
        rows = np.asarray(rows, np.int64).reshape(-1, 4)
        k, m = len(pairs), len(rows)
        kmax = self.max_per_pair
        count_dev = wp.zeros(1, dtype=wp.int32, device=d)
        if k == 0:
            empty = [wp.zeros(0, dtype=t, device=d) for t in (wp.vec2i, wp.vec3d, wp.vec3d, wp.vec3d, wp.float64,
                                                              wp.vec2i)]
            return Contacts(0, *empty, count_dev, np.zeros((0, 2), np.int32), np.zeros(0))
        n = np.int64(max(scene.num_objects, 1))
        pair_key = pairs[:, 0] * n + pairs[:, 1]
        row_pair = np.searchsorted(pair_key, rows[:, 0] * n + rows[:, 2]).astype(np.int32)
        points = np.asarray(pair_points, np.float64).reshape(-1, 2, 3)
        apart = np.zeros(k, bool) if near is None else np.asarray(near["apart"], bool)
        has_point = np.isfinite(points).all(axis=(1, 2))
        kind = np.where(has_point, np.where(apart, int(KIND_NEAR), int(KIND_DEEPEST)), -1).astype(np.int32)
        gap = points[:, 1] - points[:, 0]
        length = np.linalg.norm(gap, axis=1)
        reference = np.zeros((k, 3))
        deep = has_point & ~apart & (length > 0)
        reference[deep] = gap[deep] / length[deep, None]
        total = m * ROW_SLOTS + k
        cap = 2 * total  # radix sort scratch
        key = self._work.get("key", cap, wp.int64)
        value = self._work.get("value", cap, wp.int32)
        cand = [self._work.get(name, total, t) for name, t in (("point_a", wp.vec3d), ("point_b", wp.vec3d),
                                                             ("normal", wp.vec3d), ("depth", wp.float64),
                                                             ("triangles", wp.vec2i))]
        ref_dev = wp.array(reference, dtype=wp.vec3d, device=d)
        if m:
            wp.launch(_ROW_CANDIDATES[scene.precision], dim=(m, ROW_SLOTS),
                      inputs=[scene.topology, self.surface, self.trees.tree, scene.object_pose, scene.object_scale,
                              self.trees.object_deforming, scene.world_vertex, self.object_solid,
                              wp.array(rows.astype(np.int32), dtype=wp.vec4i, device=d),
                              wp.array(row_pair, dtype=wp.int32, device=d), ref_dev, self.tolerance],
                      outputs=[key, *cand], device=d)
        wp.launch(_pair_candidates_kernel, dim=k,
                  inputs=[wp.array(np.nan_to_num(points.reshape(k, 6)), dtype=wp.float64, device=d),
                          wp.array(np.asarray(pair_triangles, np.int32).reshape(k, 2), dtype=wp.vec2i, device=d),
                          wp.array(kind, dtype=wp.int32, device=d), m * ROW_SLOTS],
                  outputs=[key, *cand], device=d)
        wp.copy(value, wp.array(np.arange(total, dtype=np.int32), dtype=wp.int32, device=d), count=total)
        wp.utils.radix_sort_pairs(key, value, total)
        chosen = self._work.get("chosen", (k, kmax), wp.int32)
        per_pair = self._work.get("per_pair", k, wp.int32)
        wp.launch(_reduce_kernel, dim=k, inputs=[key, value, total, cand[0], cand[3], kmax, self.tolerance],
                  outputs=[chosen, per_pair], device=d)
        start = self._work.get("start", k, wp.int32)
        wp.utils.array_scan(per_pair[:k], start[:k], inclusive=False)
        counts = per_pair[:k].numpy()
        c = int(counts.sum())
        out = [wp.empty(max(c, 1), dtype=t, device=d) for t in (wp.vec2i, wp.vec3d, wp.vec3d, wp.vec3d, wp.float64,
                                                                  wp.vec2i)]
        wp.launch(_gather_kernel, dim=(k, kmax),
                  inputs=[chosen, per_pair, start, wp.array(pairs.astype(np.int32), dtype=wp.vec2i, device=d), *cand],
                  outputs=out, device=d)
        count_dev.fill_(c)
        depth = np.where(apart, np.nan, np.asarray(pair_depth, np.float64))
        return Contacts(c, *out, count_dev, pairs.astype(np.int32), depth)
