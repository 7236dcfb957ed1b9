"""How deep two objects overlap: the deepest point of either surface inside the other's solid.

**Definition.** A closed surface bounds a solid; an open one (a floor sheet, a cloth) bounds none. For
objects ``A`` and ``B``::

    depth(A, B) = max over p in surface(A) inside solid(B) of dist(p, surface(B))

and a pair's depth is the larger of ``depth(A, B)`` and ``depth(B, A)``, each where the second object is
closed; it is undefined (NaN) when neither is. Two unit cubes overlapping by 0.7 with flush faces: 0.3 (the
centre of ``A``'s face inside ``B`` lies 0.3 from ``B``'s far face); a crate sunk ``h`` into a slab: ``h``; a
pole of radius ``r`` through a plate of thickness ``w``: ``max(r, w / 2)``; a pole through a cloth: the
depth of the cloth inside the pole, whichever way the cloth is wound. It depends on the surfaces only, not
on how they are cut into triangles.

**How it is found: branch and bound over the surface.** ``f(p) = dist(p, surface(B))`` is 1-Lipschitz; its
maximum over the part of each triangle of ``A`` inside ``B`` is sought by splitting the triangle into four
(midpoints) where the maximum may still be. A *region* ``R`` (a sub-triangle) is bounded from below by ``f``
at its points found inside ``B`` (its corners, its centroid, and the point below), from above by a small
linear program: ``f <= min over t in S of g_t`` on ``R`` for any set ``S`` of triangles of ``B``, where

* ``B`` convex (closed, one component, every edge convex): ``g_t`` is the distance behind ``t``'s plane, and
  ``f`` inside ``B`` *is* the least of those over all faces, so the bound is exact once ``S`` holds the faces
  nearest at the maximum;
* otherwise: ``g_t`` interpolates ``dist(., t)`` linearly from ``R``'s corners, above it because a distance
  to a triangle is convex; exact where the nearest points lie inside faces, within ``h^2 / 8 d`` of the
  truth near edges and vertices (``h`` the region's size, ``d`` the distance).

``max over R of min g_t`` is the maximum of a concave piecewise-linear function over a triangle: at a
corner, where an edge of ``R`` meets a line ``g_t = g_u``, or where three of them meet; all such points
are tried (:func:`_bound`). ``S`` starts with the triangles of ``B`` nearest to ``R``'s corners and centroid
and the parent region's best point; the point ``p*`` where the bound is reached is then measured, its
nearest triangle joins ``S`` and the program is solved again (cutting planes, Kelley), up to
:data:`MAX_PLANES` triangles. A region is dropped when its bound does not exceed what was already found
by more than the relative tolerance (:data:`CONVEX_TOLERANCE` for convex ``B``, :data:`TOLERANCE`
otherwise: never more than that fraction below the true depth), or when it lies wholly outside ``B``: in
the ball about a sample point outside ``B`` that reaches no surface. Which triangles of ``A`` are tried:
those that meet ``B``'s surface (the rows given), and those wholly inside ``B`` reached from them across edges (a
neighbour that meets nothing of ``B``'s surface is wholly inside or out: its centroid says which; inside spreads);
a contained pair's inner object whole; where the objects are too big to number (:data:`FLAT_CANDIDATES`), those
of ``A``'s tree within ``B``'s box. Every root's centroid is measured first; only the roots whose centroid's
bound beats the depth so found are measured further.

Inside ``B`` or not is the side of a point at its nearest feature of ``B``'s surface (its pseudo-normal:
:func:`~warp_ccd._src.narrowphase.surface._side_at`). Everything runs in float64 on the world vertices,
one thread per region, levels of regions until none is left (at most :data:`MAX_LEVELS`); the host reads
one count a level. Device agnostic: the same arithmetic on every device.

A triangle's own depth (for a pair of intersecting triangles, the deepest of their two parts inside the
other solid: :attr:`DepthResult.row_depth`) is the deepest point the pair's search measured on them: a lower
bound of it, no more refined than the pair's depth needs.

Each object pair's search stops early where it would not end: depths against a non-convex solid are told apart
down to :data:`RESOLUTION` of the smaller object's size (surfaces meeting flush, shallower than that both
ways, would otherwise split their whole shared area ever finer), and a pair measures at most
:data:`PAIR_REGIONS` regions (:attr:`DepthResult.stopped` says which pairs reached it: their depth is then the
deepest point found, a lower bound).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from ..geometry.precision import precision_overloads
from ..geometry.primitives import _closest_on_triangle, _max_abs, _unit_normal
from ..geometry.triangle import TOLERANCE as TRIANGLE_TOLERANCE
from ..runtime.buffers import WorkArrays, reserve_slot, upper_bound
from ..scene.scene import MeshTopology, Scene, mesh_triangle
from ..trees.bvh import SceneBVH, TreeView
from .surface import SurfaceTopology, _side_at, surface_topology

__all__ = ["CONVEX_TOLERANCE", "MAX_LEVELS", "MAX_PLANES", "MAX_REGIONS", "PAIR_REGIONS", "TOLERANCE", "DepthResult",
           "PenetrationDepth"]

wp.set_module_options({"enable_backward": False, "fuse_fp": False})

TOLERANCE = 1.0e-3
"""Relative tolerance of the depth against a non-convex solid: the depth found is never below the true one
by more than this fraction of it, besides what the input's precision resolves (:data:`ROUNDING_ULPS`) and,
against a non-convex solid, :data:`RESOLUTION`."""
CONVEX_TOLERANCE = 1.0e-9
"""Relative tolerance against a convex solid, where the bound is exact (what is left is rounding)."""
PAIR_REGIONS = 1 << 18
"""Most regions one object pair (both ways) measures: a level that would take it past this is not split."""
MAX_LEVELS = 28
"""Most times a triangle is split (regions 4**-28 of it): a bound left then is dropped."""
MAX_REGIONS = 1 << 24
"""Most regions of one level: past it the search stops (:attr:`DepthResult.stopped`)."""
FLAT_CANDIDATES = 1 << 24
"""Where the jobs' first objects hold at most this many triangles in all, the triangles inside the other's solid
are reached from the rows' across edges (a state per triangle); beyond, one thread a job walks its object's tree
for the triangles in the other's box."""
MAX_PLANES = 6
"""Most triangles of the other surface in one region's linear program."""
ROUNDING_ULPS = 8.0
"""What the world vertices' precision resolves, in units in the last place of a region's largest coordinate
plus its size: a bound is lowered by it (float32 at 1 unit from the origin: 1e-6), so that depths equal to
within the input's rounding (a tessellated plateau) do not keep their regions splitting."""
RESOLUTION = 1.0e-4
"""Against a non-convex solid, depths are told apart down to this fraction of the smaller object's box
diagonal (besides the crossing's tolerance): a region whose bound is below it is not split further."""

WITNESS_TIE = 1.0e-6
"""Depths within this fraction of each other are equal when the witness is chosen (:attr:`DepthResult.pair_points`):
the first by place wins."""

TREE_STACK = 64
"""Nodes a nearest-point query keeps to visit: a balanced tree's depth plus one suffices (24 levels hold
16M leaves)."""

BOX_SLACK = 2.0**-15
"""Relative slack of a node box's distance in a nearest-point query, in units of ``|t| + |p - t|``
(pose translation ``t``, query point ``p``): covers the rounding of world vertices computed from
poses (the mid phase's :data:`~warp_ccd._src.trees.bvh.WORLD_ERROR_ULPS` in float32) and of the query point
taken to the box space."""

_NodeStack = wp.types.vector(length=TREE_STACK, dtype=wp.int32)
_Planes = wp.types.vector(length=MAX_PLANES, dtype=wp.float64)
_PlaneIds = wp.types.vector(length=MAX_PLANES, dtype=wp.int32)
Region = wp.types.vector(length=6, dtype=wp.float64)
"""A region: the barycentric ``(u, v)`` of its three corners in its root triangle."""


@wp.func
def _to_box_space(pose: wp.array[Any], scale: wp.array[wp.float32], deforming: wp.array[wp.int32], obj: int,
                  p: wp.vec3d):
    """``p`` in the box space of ``obj`` (its shape's under its pose and scale for a rigid object, the world
    for a deforming one), the box distances' scale, and the slack of a box distance."""
    if deforming[obj] != 0:
        return p, wp.float64(1.0), wp.float64(BOX_SLACK) * wp.length(p)
    x = pose[obj]
    t = wp.vec3d(wp.transform_get_translation(x))
    rf = wp.transform_get_rotation(x)
    r = wp.quatd(wp.float64(rf[0]), wp.float64(rf[1]), wp.float64(rf[2]), wp.float64(rf[3]))
    sc = wp.float64(scale[obj])
    pb = wp.quat_rotate_inv(r, p - t) / sc
    return pb, sc, wp.float64(BOX_SLACK) * (wp.length(t) + wp.length(p - t))


@wp.func
def nearest_triangle(mesh: MeshTopology, tree: TreeView, pose: wp.array[Any], scale: wp.array[wp.float32],
                     deforming: wp.array[wp.int32], world_vertex: wp.array[Any], obj: int, p: wp.vec3d,
                     tol_rel: wp.float64):
    """The distance from ``p`` to the surface of ``obj`` and its nearest non-degenerate triangle, down the
    object's tree: nodes whose box is farther than the nearest so far are skipped. A degenerate triangle (a
    sliver patching a T-junction) counts for the distance but not as the nearest: it has no side, and its points
    lie on its neighbours' edges. ``(distance, local triangle)``; ``(inf, -1)`` for an object without triangles."""
    pb, sc, slack = _to_box_space(pose, scale, deforming, obj, p)
    best = wp.float64(1.0e300)
    proper = wp.float64(1.0e300)
    best_tri = int(-1)
    s = mesh.object_shape[obj]
    if mesh.shape_triangle_start[s + 1] == mesh.shape_triangle_start[s]:
        return best, best_tri
    node_start = tree.layout_node_start[tree.shape_layout[s]]
    slot_start = tree.object_node_start[obj]
    tri_start = tree.shape_tri_order_start[s]
    zero = wp.vec3d()
    stack = _NodeStack()
    stack[0] = 0
    top = int(1)
    while top > 0:
        top -= 1
        node = stack[top]
        gap = wp.max(wp.max(wp.vec3d(tree.node_lower[slot_start + node]) - pb,
                            pb - wp.vec3d(tree.node_upper[slot_start + node])), zero)
        if wp.length(gap) * sc - slack > proper:
            continue
        child = tree.node_child[node_start + node]
        if child[0] < 0:
            rng = tree.node_triangle[node_start + node]
            for j in range(rng[0], rng[0] + rng[1]):
                tri = tree.tri_order[tri_start + j]
                y0, y1, y2 = mesh_triangle(mesh, world_vertex, obj, tri)
                x0 = wp.vec3d(y0)
                x1 = wp.vec3d(y1)
                x2 = wp.vec3d(y2)
                c, feature = _closest_on_triangle(p, x0, x1, x2)
                d = wp.length(p - c)
                best = wp.min(best, d)
                if d < proper or (d == proper and tri < best_tri):
                    n, degenerate = _unit_normal(x0, x1, x2, tol_rel)
                    if not degenerate:
                        proper = d
                        best_tri = tri
        elif top + 2 <= TREE_STACK:
            stack[top] = child[1]
            stack[top + 1] = child[0]
            top += 2
    return best, best_tri


@wp.func
def nearest_point(mesh: MeshTopology, world_vertex: wp.array[Any], obj: int, tri: int, p: wp.vec3d):
    """The point of local triangle ``tri`` of ``obj`` nearest to ``p`` (world, float64)."""
    y0, y1, y2 = mesh_triangle(mesh, world_vertex, obj, tri)
    c, feature = _closest_on_triangle(p, wp.vec3d(y0), wp.vec3d(y1), wp.vec3d(y2))
    return c


@wp.func
def _probe(mesh: MeshTopology, surface: SurfaceTopology, tree: TreeView, pose: wp.array[Any],
           scale: wp.array[wp.float32], deforming: wp.array[wp.int32], world_vertex: wp.array[Any], obj: int,
           p: wp.vec3d, tol_rel: wp.float64):
    """``p`` against the surface of ``obj``: ``(distance, nearest triangle, inside)``."""
    d, t = nearest_triangle(mesh, tree, pose, scale, deforming, world_vertex, obj, p, tol_rel)
    inside = t >= 0 and _side_at(mesh, surface, world_vertex, obj, t, p, tol_rel) < wp.float64(0.0)
    return d, t, inside


@wp.func
def _plane_values(mesh: MeshTopology, surface: SurfaceTopology, world_vertex: wp.array[Any], obj: int, t: int,
                  convex: int, c0: wp.vec3d, c1: wp.vec3d, c2: wp.vec3d, tol_rel: wp.float64):
    """The bound ``g_t`` (module docstring) at a region's corners: how far behind triangle ``t``'s plane
    (``convex``), else the distance to ``t``. A degenerate triangle of a convex solid bounds nothing."""
    y0, y1, y2 = mesh_triangle(mesh, world_vertex, obj, t)
    a = wp.vec3d(y0)
    b = wp.vec3d(y1)
    c = wp.vec3d(y2)
    if convex != 0:
        n, degenerate = _unit_normal(a, b, c, tol_rel)
        if degenerate:
            big = wp.float64(1.0e300)
            return wp.vec3d(big, big, big)
        n = n * surface.shape_side[mesh.object_shape[obj]]
        return wp.vec3d(-wp.dot(n, c0 - a), -wp.dot(n, c1 - a), -wp.dot(n, c2 - a))
    q0, f0 = _closest_on_triangle(c0, a, b, c)
    q1, f1 = _closest_on_triangle(c1, a, b, c)
    q2, f2 = _closest_on_triangle(c2, a, b, c)
    return wp.vec3d(wp.length(c0 - q0), wp.length(c1 - q1), wp.length(c2 - q2))


@wp.func
def _least(g0: _Planes, g1: _Planes, g2: _Planes, m: int, a: wp.float64, b: wp.float64):
    """``min over the first m of g`` at barycentric ``(a, b)`` of the region (``g0`` at corner 0, ...)."""
    v = wp.float64(1.0e300)
    for i in range(m):
        v = wp.min(v, g0[i] + a * (g1[i] - g0[i]) + b * (g2[i] - g0[i]))
    return v


@wp.func
def _try(g0: _Planes, g1: _Planes, g2: _Planes, m: int, a: wp.float64, b: wp.float64, best: wp.float64,
         ba: wp.float64, bb: wp.float64):
    """The better of ``(best, ba, bb)`` and the point ``(a, b)`` (clamped into the region)."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    a = wp.clamp(a, zero, one)
    b = wp.clamp(b, zero, one - a)
    v = _least(g0, g1, g2, m, a, b)
    if v > best:
        return v, a, b
    return best, ba, bb


@wp.func
def _corner_ab(k: int):
    """Barycentric ``(a, b)`` of the region's corner ``k``."""
    if k == 1:
        return wp.float64(1.0), wp.float64(0.0)
    if k == 2:
        return wp.float64(0.0), wp.float64(1.0)
    return wp.float64(0.0), wp.float64(0.0)


@wp.func
def _pick3(v: wp.vec3d, k: int):
    if k == 1:
        return v[1]
    if k == 2:
        return v[2]
    return v[0]


@wp.func
def _bound(g0: _Planes, g1: _Planes, g2: _Planes, m: int):
    """``max over the region of min over the first m of g``: a concave piecewise-linear function's maximum
    over a triangle, at a corner, where an edge meets a line ``g_i = g_j``, or where three ``g`` are equal.
    ``(value, a, b)``, the point barycentric in the region."""
    best = wp.float64(-1.0e300)
    ba = wp.float64(0.0)
    bb = wp.float64(0.0)
    for k in range(3):
        a, b = _corner_ab(k)
        best, ba, bb = _try(g0, g1, g2, m, a, b, best, ba, bb)
    for i in range(m):
        for j in range(i + 1, m):
            h = wp.vec3d(g0[i] - g0[j], g1[i] - g1[j], g2[i] - g2[j])
            for k in range(3):
                hp = _pick3(h, k)
                hq = _pick3(h, (k + 1) % 3)
                if (hp < wp.float64(0.0) and hq > wp.float64(0.0)) or (hp > wp.float64(0.0) and hq < wp.float64(0.0)):
                    s = hp / (hp - hq)
                    pa, pb = _corner_ab(k)
                    qa, qb = _corner_ab((k + 1) % 3)
                    best, ba, bb = _try(g0, g1, g2, m, pa + s * (qa - pa), pb + s * (qb - pb), best, ba, bb)
            for q in range(j + 1, m):
                e = wp.vec3d(g0[i] - g0[q], g1[i] - g1[q], g2[i] - g2[q])
                # h(a, b) = 0 and e(a, b) = 0, each h0 + a (h1 - h0) + b (h2 - h0).
                m00 = h[1] - h[0]
                m01 = h[2] - h[0]
                m10 = e[1] - e[0]
                m11 = e[2] - e[0]
                det = m00 * m11 - m01 * m10
                scale = wp.max(wp.abs(m00 * m11), wp.abs(m01 * m10))
                if det != wp.float64(0.0) and wp.abs(det) > wp.float64(1.0e-14) * scale:
                    a = (-h[0] * m11 + e[0] * m01) / det
                    b = (-e[0] * m00 + h[0] * m10) / det
                    if a >= wp.float64(0.0) and b >= wp.float64(0.0) and a + b <= wp.float64(1.0):
                        best, ba, bb = _try(g0, g1, g2, m, a, b, best, ba, bb)
    return best, ba, bb


@wp.func
def _has(ids: _PlaneIds, m: int, t: int):
    for i in range(m):
        if ids[i] == t:
            return True
    return False


@wp.func
def _corner(x0: wp.vec3d, x1: wp.vec3d, x2: wp.vec3d, u: wp.float64, v: wp.float64):
    return x0 + u * (x1 - x0) + v * (x2 - x0)


@wp.kernel
def _region_kernel(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    tree: TreeView,
    pose: wp.array[Any],
    scale: wp.array[wp.float32],
    deforming: wp.array[wp.int32],
    world_vertex: wp.array[Any],
    job: wp.array[wp.vec2i],
    job_convex: wp.array[wp.int32],
    root_job: wp.array[wp.int32],
    root_tri: wp.array[wp.int32],
    region_root: wp.array[wp.int32],
    region: wp.array[Region],
    region_hint: wp.array[wp.int32],
    tol_rel: wp.float64,
    resolution: wp.float64,
    quick: int,
    # Outputs
    region_bound: wp.array[wp.float64],
    region_next_hint: wp.array[wp.int32],
    job_depth: wp.array[wp.float64],
    root_depth: wp.array[wp.float64],
    job_count: wp.array[wp.int64],
    region_low: wp.array[wp.float64],
    region_point: wp.array[wp.vec3d],
    region_near: wp.array[wp.int32],
):
    """One thread per region (counted in ``job_count``): its lower bound (the deepest of its points measured
    inside the other
    solid, into ``job_depth`` and ``root_depth``), its upper bound (:func:`_bound` with cutting planes;
    below 0 for a region wholly outside), and the triangle nearest to its best point (its children's hint); its
    deepest point measured inside (``region_low``, 0 where none; ``region_point``; the other surface's nearest
    triangle there, ``region_near``: the depth's witness, :func:`_pick_witness_kernel`)."""
    k = wp.tid()
    r = region_root[k]
    j = root_job[r]
    wp.atomic_add(job_count, j, wp.int64(1))
    src = job[j][0]
    dst = job[j][1]
    convex = job_convex[j]
    y0, y1, y2 = mesh_triangle(mesh, world_vertex, src, root_tri[r])
    x0 = wp.vec3d(y0)
    x1 = wp.vec3d(y1)
    x2 = wp.vec3d(y2)
    uv = region[k]
    c0 = _corner(x0, x1, x2, uv[0], uv[1])
    c1 = _corner(x0, x1, x2, uv[2], uv[3])
    c2 = _corner(x0, x1, x2, uv[4], uv[5])
    size = wp.max(wp.max(wp.length(c1 - c0), wp.length(c2 - c1)), wp.length(c0 - c2))
    rounding = resolution * (wp.max(wp.max(_max_abs(c0), _max_abs(c1)), _max_abs(c2)) + size)
    ids = _PlaneIds()
    m = int(0)
    low = wp.float64(0.0)
    low_p = c0
    low_t = int(-1)
    # The signed distance (+ inside) is 1-Lipschitz: at most its value at a sample plus the reach from it.
    lipschitz = wp.float64(1.0e300)
    for i in range(4):
        # The centroid first: a region wholly outside (most triangles in the other's box) ends there.
        q = (c0 + c1 + c2) / wp.float64(3.0)
        if i == 1:
            q = c0
        if i == 2:
            q = c1
        if i == 3:
            q = c2
        d, t, inside = _probe(mesh, surface, tree, pose, scale, deforming, world_vertex, dst, q, tol_rel)
        reach = wp.max(wp.max(wp.length(c0 - q), wp.length(c1 - q)), wp.length(c2 - q))
        if inside:
            if d > low:
                low_p = q
                low_t = t
            low = wp.max(low, d)
            lipschitz = wp.min(lipschitz, d + reach)
        else:
            lipschitz = wp.min(lipschitz, reach - d)
            if lipschitz + rounding <= wp.float64(0.0):
                region_bound[k] = wp.float64(-1.0)
                region_next_hint[k] = t
                region_low[k] = low
                region_point[k] = low_p
                region_near[k] = low_t
                if low > wp.float64(0.0):  # sides told apart near the surface may disagree: keep what was found
                    wp.atomic_max(job_depth, j, low)
                    wp.atomic_max(root_depth, r, low)
                return
        if quick != 0:  # the centroid alone: its depth, and the bound it gives (1-Lipschitz)
            region_bound[k] = wp.max(lipschitz, wp.float64(-1.0))
            region_next_hint[k] = t
            region_low[k] = low
            region_point[k] = low_p
            region_near[k] = low_t
            if low > wp.float64(0.0):
                wp.atomic_max(job_depth, j, low)
                wp.atomic_max(root_depth, r, low)
            return
        if t >= 0 and not _has(ids, m, t):
            ids[m] = t
            m += 1
    hint = region_hint[k]
    if hint >= 0 and not _has(ids, m, hint):
        ids[m] = hint
        m += 1
    bound = wp.float64(-1.0)
    if lipschitz + rounding > wp.float64(0.0) and m > 0:  # else wholly outside: in a ball that meets no surface
        g0 = _Planes()
        g1 = _Planes()
        g2 = _Planes()
        for i in range(m):
            g = _plane_values(mesh, surface, world_vertex, dst, ids[i], convex, c0, c1, c2, tol_rel)
            g0[i] = g[0]
            g1[i] = g[1]
            g2[i] = g[2]
        for _it in range(MAX_PLANES):
            bound, a, b = _bound(g0, g1, g2, m)
            p = _corner(c0, c1, c2, a, b)
            d, t, inside = _probe(mesh, surface, tree, pose, scale, deforming, world_vertex, dst, p, tol_rel)
            if inside:
                if d > low:
                    low_p = p
                    low_t = t
                low = wp.max(low, d)
            hint = t
            if bound <= low + rounding or t < 0 or _has(ids, m, t) or m == MAX_PLANES:
                break
            g = _plane_values(mesh, surface, world_vertex, dst, t, convex, c0, c1, c2, tol_rel)
            ids[m] = t
            g0[m] = g[0]
            g1[m] = g[1]
            g2[m] = g[2]
            m += 1
        # What the input's precision resolves is no depth: a bound within it of what was found is that.
        bound = wp.max(wp.min(bound, lipschitz) - rounding, low)
    region_bound[k] = bound
    region_next_hint[k] = hint
    region_low[k] = low
    region_point[k] = low_p
    region_near[k] = low_t
    if low > wp.float64(0.0):
        wp.atomic_max(job_depth, j, low)
        wp.atomic_max(root_depth, r, low)


@wp.kernel
def _inside_kernel(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    tree: TreeView,
    pose: wp.array[Any],
    scale: wp.array[wp.float32],
    deforming: wp.array[wp.int32],
    world_vertex: wp.array[Any],
    pair: wp.array[wp.vec2i],
    tol_rel: wp.float64,
    # Outputs
    inside: wp.array[wp.int32],
):
    """One thread per ``(inner, outer)`` pair whose surfaces do not meet: whether the inner object's first vertex lies
    inside the outer solid (then all of it does)."""
    k = wp.tid()
    src = pair[k][0]
    dst = pair[k][1]
    s = mesh.object_shape[src]
    inside[k] = 0
    if mesh.shape_triangle_start[s + 1] == mesh.shape_triangle_start[s]:
        return
    local = mesh.shape_triangle[mesh.shape_triangle_start[s]][0]
    v = wp.vec3d(world_vertex[mesh.object_vertex_start[src] + local])
    d, t, hit = _probe(mesh, surface, tree, pose, scale, deforming, world_vertex, dst, v, tol_rel)
    if hit:
        inside[k] = 1


@wp.kernel
def _stop_kernel(
    job_count: wp.array[wp.int64],
    job_before: wp.array[wp.int64],
    job_twin: wp.array[wp.int32],
    budget: wp.int64,
    # Outputs
    job_stop: wp.array[wp.int32],
):
    """One thread per job: stops it (and its pair's other way, by the same sums) where splitting this level
    would take the pair past ``budget`` regions (``job_count`` now, ``job_before`` before this level)."""
    j = wp.tid()
    total = job_count[j]
    level = job_count[j] - job_before[j]
    t = job_twin[j]
    if t >= 0:
        total += job_count[t]
        level += job_count[t] - job_before[t]
    if total + wp.int64(4) * level > budget:
        job_stop[j] = 1


@wp.func
def _mid(uv: Region, i: int, k: int):
    """Barycentric ``(u, v)`` of the midpoint of corners ``i`` and ``k`` of a region."""
    half = wp.float64(0.5)
    return (uv[2 * i] + uv[2 * k]) * half, (uv[2 * i + 1] + uv[2 * k + 1]) * half


@wp.kernel
def _split_kernel(
    region_root: wp.array[wp.int32],
    region: wp.array[Region],
    region_bound: wp.array[wp.float64],
    region_next_hint: wp.array[wp.int32],
    root_job: wp.array[wp.int32],
    job_twin: wp.array[wp.int32],
    job_tolerance: wp.array[wp.float64],
    job_floor: wp.array[wp.float64],
    job_depth: wp.array[wp.float64],
    job_stop: wp.array[wp.int32],
    split: int,
    capacity: int,
    # Outputs
    out_root: wp.array[wp.int32],
    out_region: wp.array[Region],
    out_hint: wp.array[wp.int32],
    out_count: wp.array[wp.int64],
):
    """One thread per region: its four halves into the next level, unless its bound does not beat what
    was found (its pair's depth, both ways) by the job's relative tolerance, or its floor (depths below it are
    not told apart), or its job stopped (:data:`PAIR_REGIONS`)."""
    k = wp.tid()
    bound = region_bound[k]
    r = region_root[k]
    j = root_job[r]
    if job_stop[j] != 0:
        return
    found = job_depth[j]
    twin = job_twin[j]
    if twin >= 0:
        found = wp.max(found, job_depth[twin])
    if bound <= wp.max(found * (wp.float64(1.0) + job_tolerance[j]), job_floor[j]):
        return
    if split == 0:  # kept whole: the first level's survivors of its centroids' bounds
        slot = int(wp.atomic_add(out_count, 0, wp.int64(1)))
        if slot < capacity:
            out_region[slot] = region[k]
            out_root[slot] = r
            out_hint[slot] = region_next_hint[k]
        return
    slot = int(wp.atomic_add(out_count, 0, wp.int64(4)))
    if slot + 4 > capacity:
        return
    uv = region[k]
    a0, a1 = _mid(uv, 0, 1)
    b0, b1 = _mid(uv, 1, 2)
    e0, e1 = _mid(uv, 2, 0)
    hint = region_next_hint[k]
    out_region[slot] = Region(uv[0], uv[1], a0, a1, e0, e1)
    out_region[slot + 1] = Region(a0, a1, uv[2], uv[3], b0, b1)
    out_region[slot + 2] = Region(e0, e1, b0, b1, uv[4], uv[5])
    out_region[slot + 3] = Region(a0, a1, b0, b1, e0, e1)
    for i in range(4):
        out_root[slot + i] = r
        out_hint[slot + i] = hint


@wp.func
def _centroid_uv(uv: Region):
    """The barycentric ``(u, v)`` of a region's centroid in its root triangle, clamped to ``[0, 1]``."""
    third = wp.float64(1.0 / 3.0)
    u = wp.clamp((uv[0] + uv[2] + uv[4]) * third, wp.float64(0.0), wp.float64(1.0))
    v = wp.clamp((uv[1] + uv[3] + uv[5]) * third, wp.float64(0.0), wp.float64(1.0))
    return u, v


@wp.func
def _witness_key(tri: int, uv: Region):
    """A region's place, to choose one witness among equal depths the same way on every device: its centroid's
    distance from its root triangle's centroid (barycentric, 15 bits), then its root triangle, then its
    centroid (8 bits each). Among the points of a plateau (a box sunk flat into another) the middle of a
    triangle wins, not a corner of the plateau, where another face of the solid is as near and gives another
    direction."""
    third = wp.float64(1.0 / 3.0)
    u, v = _centroid_uv(uv)
    off = wp.min((wp.abs(u - third) + wp.abs(v - third)) * wp.float64(0.75), wp.float64(1.0))  # in [0, 1]
    place = wp.int64(int(u * wp.float64(255.0))) * wp.int64(256) + wp.int64(int(v * wp.float64(255.0)))
    return (wp.int64(int(off * wp.float64(32767.0))) * wp.int64(2147483648) + wp.int64(tri)) * wp.int64(65536) + place


@wp.func
def _bids(low: wp.float64, depth: wp.float64, kept: wp.float64):
    """Whether a region's deepest point ``low`` may be its job's witness: within :data:`WITNESS_TIE` of the job's
    depth, and deeper than the witness kept by more than that (points of a plateau, equal but for rounding, are
    one choice: the same under motions of the order of rounding)."""
    tie = wp.float64(WITNESS_TIE)
    return low > wp.float64(0.0) and low >= depth * (wp.float64(1.0) - tie) and low > kept * (wp.float64(1.0) + tie)


@wp.kernel
def _pick_witness_kernel(
    region_root: wp.array[wp.int32],
    region: wp.array[Region],
    region_low: wp.array[wp.float64],
    root_job: wp.array[wp.int32],
    root_tri: wp.array[wp.int32],
    job_depth: wp.array[wp.float64],
    job_witness_depth: wp.array[wp.float64],
    # Outputs
    job_witness_key: wp.array[wp.int64],
):
    """One thread per region of a level: a region whose deepest point is its job's depth, deeper than the witness
    kept so far, bids its place (:func:`_witness_key`); the least wins."""
    k = wp.tid()
    low = region_low[k]
    r = region_root[k]
    j = root_job[r]
    if _bids(low, job_depth[j], job_witness_depth[j]):
        wp.atomic_min(job_witness_key, j, _witness_key(root_tri[r], region[k]))


@wp.func
def _witness_fine_key(uv: Region):
    """A region's centroid to 30 bits a coordinate: among regions of one :func:`_witness_key` (the same root triangle
    and coarse place), the least wins; no two regions of one root share it."""
    scale = wp.float64(1073741823.0)
    u, v = _centroid_uv(uv)
    return wp.int64(int(u * scale)) * wp.int64(1073741824) + wp.int64(int(v * scale))


@wp.kernel
def _pick_witness_fine_kernel(
    region_root: wp.array[wp.int32],
    region: wp.array[Region],
    region_low: wp.array[wp.float64],
    root_job: wp.array[wp.int32],
    root_tri: wp.array[wp.int32],
    job_depth: wp.array[wp.float64],
    job_witness_depth: wp.array[wp.float64],
    job_witness_key: wp.array[wp.int64],
    # Outputs
    job_witness_fine: wp.array[wp.int64],
):
    """One thread per region of a level: the bidders of the winning place bid their centroid
    (:func:`_witness_fine_key`)."""
    k = wp.tid()
    low = region_low[k]
    r = region_root[k]
    j = root_job[r]
    if _bids(low, job_depth[j], job_witness_depth[j]) and job_witness_key[j] == _witness_key(root_tri[r], region[k]):
        wp.atomic_min(job_witness_fine, j, _witness_fine_key(region[k]))


@wp.kernel
def _keep_witness_kernel(
    region_root: wp.array[wp.int32],
    region: wp.array[Region],
    region_low: wp.array[wp.float64],
    region_point: wp.array[wp.vec3d],
    region_near: wp.array[wp.int32],
    root_job: wp.array[wp.int32],
    root_tri: wp.array[wp.int32],
    job_depth: wp.array[wp.float64],
    job_witness_key: wp.array[wp.int64],
    job_witness_fine: wp.array[wp.int64],
    # Outputs
    job_witness_depth: wp.array[wp.float64],
    job_witness_point: wp.array[wp.vec3d],
    job_witness_triangles: wp.array[wp.vec2i],
):
    """One thread per region of a level: the winner of :func:`_pick_witness_kernel` keeps its point as its job's
    witness (the point, its root triangle and the other surface's nearest triangle there)."""
    k = wp.tid()
    low = region_low[k]
    r = region_root[k]
    j = root_job[r]
    if _bids(low, job_depth[j], job_witness_depth[j]):
        if job_witness_key[j] == _witness_key(root_tri[r], region[k]) and \
                job_witness_fine[j] == _witness_fine_key(region[k]):
            job_witness_depth[j] = low
            job_witness_point[j] = region_point[k]
            job_witness_triangles[j] = wp.vec2i(root_tri[r], region_near[k])


@wp.kernel
def _witness_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    job: wp.array[wp.vec2i],
    job_witness_depth: wp.array[wp.float64],
    job_witness_point: wp.array[wp.vec3d],
    job_witness_triangles: wp.array[wp.vec2i],
    # Outputs
    job_witness_other: wp.array[wp.vec3d],
):
    """One thread per job with a witness: its nearest point on the other surface (on the nearest triangle found)."""
    j = wp.tid()
    t = job_witness_triangles[j][1]
    if job_witness_depth[j] <= wp.float64(0.0) or t < 0:
        return
    job_witness_other[j] = nearest_point(mesh, world_vertex, job[j][1], t, job_witness_point[j])


@wp.kernel
def _convex_kernel(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    world_vertex: wp.array[Any],
    solid: wp.array[wp.int32],
    solid_start: wp.array[wp.int32],
    num_solids: int,
    tol_rel: wp.float64,
    # Outputs
    convex: wp.array[wp.int32],
):
    """One thread per triangle of the solids asked about (``solid``, their triangles numbered from
    ``solid_start``): clears a solid's convex flag where one of its edges bends inward (the vertex across it
    in front of the triangle's plane by more than four times ``tol_rel`` times the triangle's longest edge), or
    where one of its triangles is degenerate."""
    g = wp.tid()
    a = upper_bound(solid_start, 0, num_solids, g) - 1  # the last solid whose triangles start at or before g
    if convex[a] == 0:
        return
    obj = solid[a]
    t = g - solid_start[a]
    s = mesh.object_shape[obj]
    y0, y1, y2 = mesh_triangle(mesh, world_vertex, obj, t)
    x0 = wp.vec3d(y0)
    x1 = wp.vec3d(y1)
    x2 = wp.vec3d(y2)
    n, degenerate = _unit_normal(x0, x1, x2, tol_rel)
    if degenerate:
        # A sliver (say, patching a T-junction) would hide the bend between the faces on either side of it:
        # such a solid is not taken for convex.
        convex[a] = 0
        return
    n = n * surface.shape_side[s]
    size = wp.max(wp.max(wp.length(x1 - x0), wp.length(x2 - x1)), wp.length(x0 - x2))
    for k in range(3):
        nbr = surface.neighbour[mesh.shape_triangle_start[s] + t][k]
        if nbr >= 0:
            z0, z1, z2 = mesh_triangle(mesh, world_vertex, obj, nbr)
            far = wp.max(wp.max(wp.dot(n, wp.vec3d(z0) - x0), wp.dot(n, wp.vec3d(z1) - x0)),
                         wp.dot(n, wp.vec3d(z2) - x0))
            if far > tol_rel * size * wp.float64(4.0):
                convex[a] = 0


@wp.kernel
def _candidates_kernel(
    mesh: MeshTopology,
    tree: TreeView,
    pose: wp.array[Any],
    scale: wp.array[wp.float32],
    deforming: wp.array[wp.int32],
    object_lower: wp.array[wp.vec3],
    object_upper: wp.array[wp.vec3],
    job: wp.array[wp.vec2i],
    row_key: wp.array[wp.int64],
    num_rows: int,
    stride: wp.int64,
    first_root: int,
    capacity: int,
    # Outputs
    root_job: wp.array[wp.int32],
    root_tri: wp.array[wp.int32],
    count: wp.array[wp.int64],
):
    """One thread per job: the triangles of its first object whose tree leaves meet the box of its
    second (taken to the first's box space), other than the rows' (``row_key``, sorted keys
    ``job * stride + triangle``), appended as roots after ``first_root``."""
    j = wp.tid()
    src = job[j][0]
    dst = job[j][1]
    lo = wp.vec3d(object_lower[dst])
    hi = wp.vec3d(object_upper[dst])
    blo = wp.vec3d(1.0e300, 1.0e300, 1.0e300)
    bhi = -blo
    slack = wp.float64(0.0)
    for corner in range(8):
        p = wp.vec3d(lo[0], lo[1], lo[2])
        if corner & 1:
            p[0] = hi[0]
        if corner & 2:
            p[1] = hi[1]
        if corner & 4:
            p[2] = hi[2]
        pb, sc, sl = _to_box_space(pose, scale, deforming, src, p)
        blo = wp.min(blo, pb)
        bhi = wp.max(bhi, pb)
        slack = wp.max(slack, sl / sc)
    blo = blo - wp.vec3d(slack, slack, slack)
    bhi = bhi + wp.vec3d(slack, slack, slack)
    s = mesh.object_shape[src]
    if mesh.shape_triangle_start[s + 1] == mesh.shape_triangle_start[s]:
        return
    node_start = tree.layout_node_start[tree.shape_layout[s]]
    slot_start = tree.object_node_start[src]
    tri_start = tree.shape_tri_order_start[s]
    stack = _NodeStack()
    stack[0] = 0
    top = int(1)
    while top > 0:
        top -= 1
        node = stack[top]
        nlo = wp.vec3d(tree.node_lower[slot_start + node])
        nhi = wp.vec3d(tree.node_upper[slot_start + node])
        if nlo[0] > bhi[0] or nlo[1] > bhi[1] or nlo[2] > bhi[2] or blo[0] > nhi[0] or blo[1] > nhi[1] or (
                blo[2] > nhi[2]):
            continue
        child = tree.node_child[node_start + node]
        if child[0] < 0:
            rng = tree.node_triangle[node_start + node]
            for i in range(rng[0], rng[0] + rng[1]):
                tri = tree.tri_order[tri_start + i]
                key = wp.int64(j) * stride + wp.int64(tri)
                after = upper_bound(row_key, 0, num_rows, key)  # the rows' keys are sorted
                if after > 0 and row_key[after - 1] == key:
                    continue
                slot = reserve_slot(count, capacity)
                if slot >= 0:
                    root_job[first_root + slot] = j
                    root_tri[first_root + slot] = tri
        elif top + 2 <= TREE_STACK:
            stack[top] = child[1]
            stack[top + 1] = child[0]
            top += 2


@wp.kernel
def _whole_kernel(
    job_start: wp.array[wp.int64],
    num_jobs: int,
    job_whole: wp.array[wp.int32],
    first_root: int,
    capacity: int,
    # Outputs
    root_job: wp.array[wp.int32],
    root_tri: wp.array[wp.int32],
    count: wp.array[wp.int64],
):
    """One thread per (job, triangle of its first object), the triangles of the jobs numbered from
    ``job_start``: every triangle of a job flagged in ``job_whole`` (a contained pair's inner object, which
    meets nothing of the other's surface), appended as a root after ``first_root``."""
    g = wp.int64(wp.tid())
    j = upper_bound(job_start, 0, num_jobs, g) - 1  # the last job whose triangles start at or before g
    if job_whole[j] == 0:
        return
    slot = reserve_slot(count, capacity)
    if slot >= 0:
        root_job[first_root + slot] = j
        root_tri[first_root + slot] = int(g - job_start[j])


@wp.kernel
def _mark_rows_kernel(
    root_job: wp.array[wp.int32],
    root_tri: wp.array[wp.int32],
    job_start: wp.array[wp.int64],
    # Outputs
    state: wp.array[wp.int32],
):
    """One thread per row root: its triangle's state, 1 (it meets the other's surface)."""
    k = wp.tid()
    state[job_start[root_job[k]] + wp.int64(root_tri[k])] = 1


@wp.kernel
def _seed_kernel(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    tree: TreeView,
    pose: wp.array[Any],
    scale: wp.array[wp.float32],
    deforming: wp.array[wp.int32],
    world_vertex: wp.array[Any],
    job: wp.array[wp.vec2i],
    job_start: wp.array[wp.int64],
    root_job: wp.array[wp.int32],
    root_tri: wp.array[wp.int32],
    tol_rel: wp.float64,
    first_root: int,
    capacity: int,
    # Outputs
    state: wp.array[wp.int32],
    out_job: wp.array[wp.int32],
    out_tri: wp.array[wp.int32],
    count: wp.array[wp.int64],
):
    """One thread per (row root, edge): the triangle across the edge, where it meets nothing of the other's
    surface (state 0), lies wholly inside or wholly outside the other's solid: its centroid says which
    (state 2 inside, appended as a root after ``first_root``; 3 outside)."""
    k, e = wp.tid()
    j = root_job[k]
    src = job[j][0]
    s = mesh.object_shape[src]
    nbr = surface.neighbour[mesh.shape_triangle_start[s] + root_tri[k]][e]
    if nbr < 0:
        return
    g = job_start[j] + wp.int64(nbr)
    if state[g] != 0:
        return
    y0, y1, y2 = mesh_triangle(mesh, world_vertex, src, nbr)
    c = (wp.vec3d(y0) + wp.vec3d(y1) + wp.vec3d(y2)) / wp.float64(3.0)
    d, t, inside = _probe(mesh, surface, tree, pose, scale, deforming, world_vertex, job[j][1], c, tol_rel)
    mark = 3
    if inside:
        mark = 2
    if wp.atomic_cas(state, int(g), 0, mark) == 0 and inside:
        slot = reserve_slot(count, capacity)
        if slot >= 0:
            out_job[first_root + slot] = j
            out_tri[first_root + slot] = nbr


@wp.kernel
def _spread_kernel(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    job: wp.array[wp.vec2i],
    job_start: wp.array[wp.int64],
    root_job: wp.array[wp.int32],
    root_tri: wp.array[wp.int32],
    begin: int,
    end: int,
    capacity: int,
    # Outputs
    state: wp.array[wp.int32],
    count: wp.array[wp.int64],
):
    """One thread per (inside root of the last step, edge): the triangle across the edge, unless it meets the
    other's surface or was reached already, is inside too (no surface crossed between them): a root, appended."""
    k, e = wp.tid()
    i = begin + k
    if i >= end:
        return
    j = root_job[i]
    s = mesh.object_shape[job[j][0]]
    nbr = surface.neighbour[mesh.shape_triangle_start[s] + root_tri[i]][e]
    if nbr < 0:
        return
    if wp.atomic_cas(state, int(job_start[j] + wp.int64(nbr)), 0, 2) == 0:
        slot = reserve_slot(count, capacity)
        if slot >= 0:
            root_job[end + slot] = j
            root_tri[end + slot] = nbr


_REGION = precision_overloads(_region_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v], "pose": wp.array[t]})
_CANDIDATES = precision_overloads(_candidates_kernel, lambda s, v, q, t: {"pose": wp.array[t]})
_SEED = precision_overloads(_seed_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v], "pose": wp.array[t]})
_CONVEX = precision_overloads(_convex_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v]})
_WITNESS = precision_overloads(_witness_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v]})
_INSIDE = precision_overloads(_inside_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v], "pose": wp.array[t]})


@wp.kernel
def _roots_kernel(
    count: int,
    # Outputs
    region_root: wp.array[wp.int32],
    region: wp.array[Region],
    region_hint: wp.array[wp.int32],
):
    """The first level: each root triangle whole."""
    k = wp.tid()
    if k >= count:
        return
    region_root[k] = k
    region[k] = Region(wp.float64(0.0), wp.float64(0.0), wp.float64(1.0), wp.float64(0.0), wp.float64(0.0),
                       wp.float64(1.0))
    region_hint[k] = -1


class DepthResult:
    """What :class:`PenetrationDepth` found, host arrays.

    Attributes:
        pair_depth: ``(K,)`` float64 depth of each object pair asked for (scene units), NaN where neither
            object is closed (undefined).
        row_depth: ``(M,)`` float64 depth of each triangle row: the deepest point the pair's search measured on
            its two triangles inside the other object's solid (a lower bound of their own depth), NaN where neither
            object is closed.
        contained_depth: ``(C,)`` float64 depth of each ``(inner, outer)`` pair: how deep the inner surface
            lies inside the outer solid.
        regions: regions measured in all (the work done).
        levels: levels of regions.
        stopped: ``(K,)`` bool, the pair's search stopped before every region was decided (:data:`PAIR_REGIONS`,
            :data:`MAX_LEVELS` levels, or a level of more than :data:`MAX_REGIONS` regions): its depth is the
            deepest point found, a lower bound.
        pair_points: ``(K, 2, 3)`` float64 the depth's witness of each pair (world, scene units): the deepest point
            found of one surface inside the other's solid and its nearest point on that other surface, given as
            ``(point on a, point on b)``, ``|a - b|`` the pair's depth (within :data:`WITNESS_TIE` of it); NaN where the
            depth is 0 or undefined. Among points of equal depth (within :data:`WITNESS_TIE`), one chosen by place
            (root triangle, then position in it), the same on every device.
        pair_triangles: ``(K, 2)`` int32 the local triangles of ``a`` and ``b`` the witness lies on, -1 where none.
        contained_points, contained_triangles: ``(C, 2, 3)``, ``(C, 2)``: each contained pair's witness, as
            ``(point on the inner, point on the outer)``, and their triangles (NaN, -1 where none).
    """

    def __init__(self, pair_depth: np.ndarray, row_depth: np.ndarray, contained_depth: np.ndarray, regions: int,
                 levels: int, stopped: np.ndarray | None = None, pair_points: np.ndarray | None = None,
                 pair_triangles: np.ndarray | None = None) -> None:
        self.pair_depth = pair_depth
        self.row_depth = row_depth
        self.contained_depth = contained_depth
        self.regions = regions
        self.levels = levels
        self.stopped = np.zeros(len(pair_depth), bool) if stopped is None else stopped
        k = len(pair_depth)
        self.pair_points = np.full((k, 2, 3), np.nan) if pair_points is None else pair_points
        self.contained_points = np.full((len(contained_depth), 2, 3), np.nan)
        self.contained_triangles = np.full((len(contained_depth), 2), -1, np.int32)
        self.pair_triangles = np.full((k, 2), -1, np.int32) if pair_triangles is None else pair_triangles


class PenetrationDepth:
    """The depth of object pairs of a scene (module docstring), as the scene's world vertices are now.

    Owns the scene's :class:`~warp_ccd._src.narrowphase.surface.SurfaceTopology` and its work buffers
    (grown as needed). Nearest points are found down the pipeline's trees when they are given (as they
    stand after its ``detect()``), else down trees of its own, refit at every call.

    Example::

        pipe = CollisionPipeline(scene)
        depth = PenetrationDepth(scene, trees=pipe.boxes)
        res = pipe.detect()
        d = depth(res.intersecting_pairs, rows=res.triangle_pairs).pair_depth
    """

    def __init__(self, scene: Scene, *, trees: SceneBVH | None = None, tolerance: float = TOLERANCE,
                 triangle_tolerance: float = TRIANGLE_TOLERANCE, surface: SurfaceTopology | None = None) -> None:
        """
        Args:
            scene: the :class:`~warp_ccd._src.scene.scene.Scene`.
            trees: the pipeline's :class:`~warp_ccd._src.trees.bvh.SceneBVH` (``CollisionPipeline.boxes``), or
                None: trees of its own.
            tolerance: relative tolerance against a non-convex solid (:data:`TOLERANCE`).
            triangle_tolerance: relative tolerance of degenerate triangles and of an edge's convexity.
            surface: the scene's surface topology, when the caller has it already.
        """
        self.scene = scene
        self.tolerance = float(tolerance)
        self.triangle_tolerance = float(triangle_tolerance)
        self.own_trees = not isinstance(trees, SceneBVH)
        self.trees = SceneBVH(scene) if self.own_trees else trees
        self.surface = surface if surface is not None else surface_topology(scene)
        shape_solid = self.surface.shape_solid.numpy()
        self.object_solid = shape_solid[scene.object_shape.numpy()].astype(np.int32)
        counts = np.diff(scene.shape_triangle_start_np)[scene.object_shape.numpy()]
        self.object_triangles = counts.astype(np.int64)
        self.stride = int(counts.max(initial=0)) + 1
        # Each object's size (its shape's box diagonal, scaled): the resolution of depths against it.
        v = np.asarray(scene.shapes.vertices, np.float64).reshape(-1, 3)
        start = np.asarray(scene.shape_vertex_start_np, np.int64)
        diag = np.zeros(len(start) - 1)
        full = np.diff(start) > 0
        if len(v):
            lo = np.minimum.reduceat(v, start[:-1][full], axis=0)
            hi = np.maximum.reduceat(v, start[:-1][full], axis=0)
            diag[full] = np.linalg.norm(hi - lo, axis=1)
        self.object_size = diag[scene.object_shape.numpy()] * scene.object_scale.numpy().astype(np.float64)
        self._work = WorkArrays(scene.device)
        self.resolution = ROUNDING_ULPS * float(np.finfo(np.float32 if scene.precision == "float32"
                                                         else np.float64).eps)

    def inside(self, pairs: np.ndarray) -> np.ndarray:
        """``(P,)`` bool: each ``(inner, outer)`` pair's inner object lies inside the outer's closed solid, for pairs
        whose surfaces do not meet (one vertex decides: the side at its nearest feature). False where the outer is
        open."""
        pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
        if not len(pairs):
            return np.zeros(0, bool)
        scene, d = self.scene, self.scene.device
        if self.own_trees:
            self.trees.refit(scene)
        out = wp.zeros(len(pairs), dtype=wp.int32, device=d)
        wp.launch(_INSIDE[scene.precision], dim=len(pairs),
                  inputs=[scene.topology, self.surface, self.trees.tree, scene.object_pose, scene.object_scale,
                          self.trees.object_deforming, scene.world_vertex,
                          wp.array(pairs.astype(np.int32), dtype=wp.vec2i, device=d), self.triangle_tolerance],
                  outputs=[out], device=d)
        return (out.numpy() != 0) & (self.object_solid[pairs[:, 1]] > 0)

    def jobs(self, pairs: np.ndarray, contained: np.ndarray) -> np.ndarray:
        """``(J, 2)`` int32 rows ``(src, dst)``: a surface measured inside a closed object, both ways for each
        pair, inner into outer for each contained pair; unique, sorted."""
        pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
        contained = np.asarray(contained, np.int64).reshape(-1, 2)
        cand = np.concatenate([pairs, pairs[:, ::-1], contained])
        cand = cand[self.object_solid[cand[:, 1]] > 0] if len(cand) else cand
        n = np.int64(max(self.scene.num_objects, 1))
        key = np.unique(cand[:, 0] * n + cand[:, 1])  # one sort of one key, not of rows
        return np.stack([key // n, key % n], axis=1).astype(np.int32).reshape(-1, 2)

    def __call__(self, pairs: np.ndarray, rows: np.ndarray | None = None, contained: np.ndarray | None = None,
                 floors: np.ndarray | None = None, in_boxes: bool = False) -> DepthResult:
        """Measures the depth of object pairs.

        Args:
            pairs: ``(K, 2)`` object pairs.
            rows: ``(M, 4)`` rows ``(obj_a, tri_a, obj_b, tri_b)`` of triangles of those pairs that meet (local
                triangle ids): their triangles are measured first, each to its own depth.
            contained: ``(C, 2)`` ``(inner, outer)`` object pairs, the inner wholly inside the outer's solid.
            floors: ``(K,)`` the depth below which each pair's depths need not be told apart (scene units: its
                crossing's tolerance), or None: 0. Where both ways of a pair stay below it (surfaces that only
                meet), the search stops there instead of refining about every point where they meet.
            in_boxes: measure every triangle of each object within the other's box (its tree walked), not only those
                reached from the rows: for pairs known to intersect without their rows (the trees' object boxes must
                be current).

        Returns:
            The :class:`DepthResult`.
        """
        scene = self.scene
        d = scene.device
        pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
        rows = np.zeros((0, 4), np.int64) if rows is None else np.asarray(rows, np.int64).reshape(-1, 4)
        contained = np.zeros((0, 2), np.int64) if contained is None else np.asarray(contained, np.int64).reshape(-1, 2)
        jobs = self.jobs(pairs, contained)
        num_jobs = len(jobs)
        self.level_regions: list[int] = []  # regions measured at each level (the work done), for benchmarks
        if num_jobs == 0:
            nan = np.full(len(pairs), np.nan)
            return DepthResult(nan, np.full(len(rows), np.nan), np.zeros(len(contained)), 0, 0)
        if self.own_trees:
            self.trees.refit(scene)
        job_key = jobs[:, 0].astype(np.int64) * scene.num_objects + jobs[:, 1]
        ab = self._job_of(job_key, pairs[:, 0], pairs[:, 1])
        ba = self._job_of(job_key, pairs[:, 1], pairs[:, 0])
        # The rows' triangles, each a root of its job.
        stride = np.int64(self.stride)
        ja = self._job_of(job_key, rows[:, 0], rows[:, 2])
        jb = self._job_of(job_key, rows[:, 2], rows[:, 0])
        keys = np.concatenate([ja[ja >= 0] * stride + rows[ja >= 0, 1], jb[jb >= 0] * stride + rows[jb >= 0, 3]])
        row_key = np.unique(keys)
        job_dev = wp.array(jobs, dtype=wp.vec2i, device=d)
        count = wp.zeros(1, dtype=wp.int64, device=d)
        tree = self.trees
        per_job = self.object_triangles[jobs[:, 0]]
        flat_total = int(per_job.sum())
        if flat_total <= FLAT_CANDIDATES and not in_boxes:
            flat_start = wp.array(np.concatenate([[0], np.cumsum(per_job)[:-1]]).astype(np.int64), dtype=wp.int64,
                                  device=d)
            root_job, root_tri, num_roots = self._roots_by_adjacency(jobs, job_dev, flat_start, flat_total, row_key,
                                                                     contained)
        else:
            root_job, root_tri, num_roots = self._roots_in_boxes(job_dev, num_jobs, row_key)
        # Which solids are convex: closed with a sphere's topology, and no edge bending inward now.
        solids, job_solid = np.unique(jobs[:, 1], return_inverse=True)
        start = np.concatenate([[0], np.cumsum(self.object_triangles[solids])]).astype(np.int32)
        flags = wp.array((self.object_solid[solids] == 2).astype(np.int32), dtype=wp.int32, device=d)
        if start[-1]:
            wp.launch(_CONVEX[scene.precision], dim=int(start[-1]),
                      inputs=[scene.topology, self.surface, scene.world_vertex,
                              wp.array(solids.astype(np.int32), dtype=wp.int32, device=d),
                              wp.array(start[:-1], dtype=wp.int32, device=d), len(solids), self.triangle_tolerance],
                      outputs=[flags], device=d)
        convex = flags.numpy()[job_solid.reshape(-1)]
        job_convex = wp.array(convex.astype(np.int32), dtype=wp.int32, device=d)
        job_tolerance = wp.array(np.where(convex != 0, CONVEX_TOLERANCE, self.tolerance), dtype=wp.float64, device=d)
        twin = self._job_of(job_key, jobs[:, 1], jobs[:, 0])
        floor = np.zeros(num_jobs)
        if floors is not None and len(pairs):
            for way in (ab, ba):
                np.maximum.at(floor, way[way >= 0], np.asarray(floors, np.float64)[way >= 0])
        smaller = np.minimum(self.object_size[jobs[:, 0]], self.object_size[jobs[:, 1]])
        floor = np.where(convex != 0, floor, np.maximum(floor, RESOLUTION * smaller))
        job_twin = wp.array(twin.astype(np.int32), dtype=wp.int32, device=d)
        job_floor = wp.array(floor, dtype=wp.float64, device=d)
        job_depth = wp.zeros(num_jobs, dtype=wp.float64, device=d)
        job_count = wp.zeros(num_jobs, dtype=wp.int64, device=d)
        job_before = wp.zeros(num_jobs, dtype=wp.int64, device=d)
        job_stop = wp.zeros(num_jobs, dtype=wp.int32, device=d)
        root_depth = wp.zeros(num_roots, dtype=wp.float64, device=d)
        witness_depth = wp.zeros(num_jobs, dtype=wp.float64, device=d)
        witness_key = wp.empty(num_jobs, dtype=wp.int64, device=d)
        witness_fine = wp.empty(num_jobs, dtype=wp.int64, device=d)
        witness_point = wp.zeros(num_jobs, dtype=wp.vec3d, device=d)
        witness_other = wp.zeros(num_jobs, dtype=wp.vec3d, device=d)
        witness_triangles = wp.full(num_jobs, wp.vec2i(-1, -1), dtype=wp.vec2i, device=d)
        # Levels of regions.
        n = num_roots
        cur = [self._work.get(f"{name}0", n, t) for name, t in (("root", wp.int32), ("region", Region),
                                                                ("hint", wp.int32))]
        wp.launch(_roots_kernel, dim=n, inputs=[n], outputs=cur, device=d)
        total = 0
        level = 0
        exhausted = False
        quick = 1  # first the roots' centroids alone: the deep ones set a depth that drops most others
        step = 0
        while n > 0 and level < MAX_LEVELS:
            total += n
            self.level_regions.append(n)
            bound = self._work.get("bound", n, wp.float64)
            next_hint = self._work.get("next_hint", n, wp.int32)
            low = self._work.get("low", n, wp.float64)
            low_point = self._work.get("low_point", n, wp.vec3d)
            low_near = self._work.get("low_near", n, wp.int32)
            wp.launch(_REGION[scene.precision], dim=n,
                      inputs=[scene.topology, self.surface, tree.tree, scene.object_pose, scene.object_scale,
                              tree.object_deforming, scene.world_vertex, job_dev, job_convex, root_job, root_tri,
                              cur[0], cur[1], cur[2], self.triangle_tolerance, self.resolution, quick],
                      outputs=[bound, next_hint, job_depth, root_depth, job_count, low, low_point, low_near], device=d)
            witness_key.fill_(np.iinfo(np.int64).max)
            witness_fine.fill_(np.iinfo(np.int64).max)
            wp.launch(_pick_witness_kernel, dim=n,
                      inputs=[cur[0], cur[1], low, root_job, root_tri, job_depth, witness_depth],
                      outputs=[witness_key], device=d)
            wp.launch(_pick_witness_fine_kernel, dim=n,
                      inputs=[cur[0], cur[1], low, root_job, root_tri, job_depth, witness_depth, witness_key],
                      outputs=[witness_fine], device=d)
            wp.launch(_keep_witness_kernel, dim=n,
                      inputs=[cur[0], cur[1], low, low_point, low_near, root_job, root_tri, job_depth, witness_key,
                              witness_fine],
                      outputs=[witness_depth, witness_point, witness_triangles], device=d)
            wp.launch(_stop_kernel, dim=num_jobs, inputs=[job_count, job_before, job_twin, PAIR_REGIONS],
                      outputs=[job_stop], device=d)
            wp.copy(job_before, job_count)
            step += 1
            level += 1 - quick
            want = n if quick else 4 * n
            while True:
                nxt = [self._work.get(f"{name}{step % 2}", want, t)
                       for name, t in (("root", wp.int32), ("region", Region), ("hint", wp.int32))]
                count.zero_()
                wp.launch(_split_kernel, dim=n,
                          inputs=[cur[0], cur[1], bound, next_hint, root_job, job_twin, job_tolerance, job_floor,
                                  job_depth, job_stop, 1 - quick, nxt[0].shape[0]],
                          outputs=[nxt[0], nxt[1], nxt[2], count], device=d)
                m = int(count.numpy()[0])
                if m <= nxt[0].shape[0]:
                    break
                if m > MAX_REGIONS:  # give up refining: what was found stands (a lower bound)
                    m = 0
                    exhausted = True
                    break
                want = m
            cur, n = nxt, m
            quick = 0
        wp.launch(_WITNESS[scene.precision], dim=num_jobs,
                  inputs=[scene.topology, scene.world_vertex, job_dev, witness_depth, witness_point, witness_triangles],
                  outputs=[witness_other], device=d)
        depth_job = job_depth.numpy()
        depth_root = root_depth.numpy()
        # Per pair, per row, per contained pair.
        pair_depth = np.fmax(np.where(ab >= 0, depth_job[np.maximum(ab, 0)], np.nan),
                             np.where(ba >= 0, depth_job[np.maximum(ba, 0)], np.nan))
        row_depth = np.fmax(self._root_depth(depth_root, row_key, ja, rows[:, 1], stride),
                            self._root_depth(depth_root, row_key, jb, rows[:, 3], stride))
        inner = self._job_of(job_key, contained[:, 0], contained[:, 1])
        contained_depth = np.where(inner >= 0, depth_job[np.maximum(inner, 0)], np.nan)
        stop = job_stop.numpy() != 0
        stopped = (np.where(ab >= 0, stop[np.maximum(ab, 0)], False) | np.where(ba >= 0, stop[np.maximum(ba, 0)], False)
                   | exhausted | (n > 0))
        # Each pair's witness: the deeper way's (a's way on a tie), as points on a and on b.
        has = witness_depth.numpy() > 0.0
        src, dst = witness_point.numpy(), witness_other.numpy()
        tris = witness_triangles.numpy()
        depth_ab = np.where(ab >= 0, depth_job[np.maximum(ab, 0)], -1.0)
        depth_ba = np.where(ba >= 0, depth_job[np.maximum(ba, 0)], -1.0)
        use_ab = depth_ab >= depth_ba
        way = np.maximum(np.where(use_ab, ab, ba), 0)
        ok = np.where(use_ab, ab, ba) >= 0
        ok &= has[way]
        points = np.where(use_ab[:, None, None], np.stack([src[way], dst[way]], 1), np.stack([dst[way], src[way]], 1))
        points[~ok] = np.nan
        triangles = np.where(use_ab[:, None], tris[way], tris[way][:, ::-1]).astype(np.int32)
        triangles[~ok] = -1
        result = DepthResult(pair_depth, row_depth, contained_depth, total, level, stopped, points, triangles)
        # Each contained pair's witness: its inner surface's deepest point inside the outer solid, (inner, outer).
        way = np.maximum(inner, 0)
        found = (inner >= 0) & has[way]
        result.contained_points = np.stack([src[way], dst[way]], 1).reshape(-1, 2, 3)
        result.contained_points[~found] = np.nan
        result.contained_triangles = np.where(found[:, None], tris[way], -1).astype(np.int32).reshape(-1, 2)
        return result

    def _row_roots(self, row_key: np.ndarray, size: int) -> tuple[wp.array, wp.array]:
        """Root buffers of at least ``size`` roots, the rows' triangles first."""
        d = self.scene.device
        root_job = self._work.get("root_job", size, wp.int32)
        root_tri = self._work.get("root_tri", size, wp.int32)
        if len(row_key):
            stride = np.int64(self.stride)
            root_job[:len(row_key)].assign(wp.array((row_key // stride).astype(np.int32), dtype=wp.int32, device=d))
            root_tri[:len(row_key)].assign(wp.array((row_key % stride).astype(np.int32), dtype=wp.int32, device=d))
        return root_job, root_tri

    def _roots_by_adjacency(self, jobs: np.ndarray, job_dev: wp.array, job_start: wp.array, total: int,
                            row_key: np.ndarray, contained: np.ndarray) -> tuple:
        """The triangles to measure: the rows', then those of each job's first object wholly inside the other's
        solid, reached from the rows' across edges: a row triangle's neighbour that meets nothing of the other's
        surface is wholly inside or wholly outside (its centroid says which), and an inside triangle's such
        neighbours are inside too, one launch a step; the triangles of a contained pair's inner object, all.
        ``(root_job, root_tri, count)``. A component of the first object that meets nothing of the other's
        surface and holds no row is not reached (unless the pair is contained)."""
        scene, d, tree = self.scene, self.scene.device, self.trees
        num_rows, num_jobs = len(row_key), len(jobs)
        root_job, root_tri = self._row_roots(row_key, num_rows + total)
        capacity = root_job.shape[0]
        state = self._work.get("state", total, wp.int32)
        state.zero_()
        count = wp.zeros(1, dtype=wp.int64, device=d)
        if num_rows:
            wp.launch(_mark_rows_kernel, dim=num_rows, inputs=[root_job, root_tri, job_start], outputs=[state],
                      device=d)
            wp.launch(_SEED[scene.precision], dim=(num_rows, 3),
                      inputs=[scene.topology, self.surface, tree.tree, scene.object_pose, scene.object_scale,
                              tree.object_deforming, scene.world_vertex, job_dev, job_start, root_job, root_tri,
                              self.triangle_tolerance, num_rows, capacity - num_rows],
                      outputs=[state, root_job, root_tri, count], device=d)
        begin, end = num_rows, num_rows + int(count.numpy()[0])
        while end > begin:
            count.zero_()
            wp.launch(_spread_kernel, dim=(end - begin, 3),
                      inputs=[scene.topology, self.surface, job_dev, job_start, root_job, root_tri, begin, end,
                              capacity - end],
                      outputs=[state, count], device=d)
            begin, end = end, end + int(count.numpy()[0])
        # A contained pair's inner object: all of it.
        inner = np.zeros(num_jobs, np.int32)
        if len(contained):
            key = jobs[:, 0].astype(np.int64) * scene.num_objects + jobs[:, 1]
            inner[np.isin(key, contained[:, 0].astype(np.int64) * scene.num_objects + contained[:, 1])] = 1
        if inner.any():
            count.zero_()
            wp.launch(_whole_kernel, dim=total,
                      inputs=[job_start, num_jobs, wp.array(inner, dtype=wp.int32, device=d), end, capacity - end],
                      outputs=[root_job, root_tri, count], device=d)
            end += int(count.numpy()[0])
        return root_job, root_tri, end

    def _roots_in_boxes(self, job_dev: wp.array, num_jobs: int, row_key: np.ndarray) -> tuple:
        """The triangles to measure where the jobs' first objects are too big to number (:data:`FLAT_CANDIDATES`):
        the rows', then each job's first object's triangles in the other's box, one thread a job down the first
        object's tree. ``(root_job, root_tri, count)``."""
        scene, d, tree = self.scene, self.scene.device, self.trees
        num_rows = len(row_key)
        key_dev = wp.array(row_key if num_rows else np.zeros(1, np.int64), dtype=wp.int64, device=d)
        capacity = max(4 * num_rows + 64, 2 * num_jobs)
        count = wp.zeros(1, dtype=wp.int64, device=d)
        while True:
            root_job, root_tri = self._row_roots(row_key, num_rows + capacity)
            count.zero_()
            wp.launch(_CANDIDATES[scene.precision], dim=num_jobs,
                      inputs=[scene.topology, tree.tree, scene.object_pose, scene.object_scale, tree.object_deforming,
                              tree.lower, tree.upper, job_dev, key_dev, num_rows, np.int64(self.stride), num_rows,
                              root_job.shape[0] - num_rows],
                      outputs=[root_job, root_tri, count], device=d)
            extra = int(count.numpy()[0])
            if num_rows + extra <= root_job.shape[0]:
                return root_job, root_tri, num_rows + extra
            capacity = extra
            self._work.drop("root_job")
            self._work.drop("root_tri")

    def _job_of(self, job_key: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
        """The job index of each ``(src, dst)``, -1 where there is none."""
        key = np.asarray(src, np.int64) * self.scene.num_objects + np.asarray(dst, np.int64)
        at = np.minimum(np.searchsorted(job_key, key), max(len(job_key) - 1, 0))
        return np.where((len(job_key) > 0) & (job_key[at] == key), at, -1) if len(key) else np.zeros(0, np.int64)

    @staticmethod
    def _root_depth(depth_root: np.ndarray, row_key: np.ndarray, job: np.ndarray, tri: np.ndarray,
                    stride: np.int64) -> np.ndarray:
        """The depth of each row triangle's root (NaN where its job does not exist)."""
        key = job * stride + tri
        at = np.minimum(np.searchsorted(row_key, key), max(len(row_key) - 1, 0))
        ok = (job >= 0) & (len(row_key) > 0)
        return np.where(ok, depth_root[at] if len(row_key) else np.nan, np.nan)
