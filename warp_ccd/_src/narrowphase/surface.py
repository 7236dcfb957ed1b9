"""The sides of a scene's surfaces: their topology, built once on the host, and inside kernels
which side of a surface a point lies on.

:func:`surface_topology` builds the :class:`SurfaceTopology` of all the scene's shapes at once
(numpy): each triangle's neighbour across each edge (-1 on a boundary or non-manifold edge), each
vertex's fan of triangles and whether it lies on a boundary, the two-sided faces (a triangle listed
twice), and which way each shape faces (:func:`shape_sides`: a closed solid wound inside out is
turned round). It depends on the shapes alone, not on the poses or the world vertices.

Inside kernels, in float64 on an object's world vertices: the triangle across an edge, its normal
oriented as the triangle's (:func:`_neighbour`); a vertex's angle-weighted pseudo-normal
(:func:`_fan_normal`); a point's distance to a triangle, negative where the point lies behind the
surface by the pseudo-normal of the closest feature (:func:`_signed_distance`, Bærentzen and
Aanæs); and which side of an object's surface a point lies on at its nearest triangle
(:func:`_side_at`). The penetrating-or-touching verdicts and depths of
:mod:`~warp_ccd._src.check.crossing` use them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from ..geometry.primitives import _closest_on_triangle, _unit_normal
from ..scene.scene import MeshTopology, mesh_triangle

__all__ = ["SurfaceTopology", "shape_sides", "shape_solids", "surface_topology"]

wp.set_module_options({"enable_backward": False, "fuse_fp": False})


@wp.struct
class SurfaceTopology:
    """Neighbours and vertex fans of every shape's triangles, for the sides of a surface.

    ``neighbour[shape_triangle_start[s] + t][k]``: the local triangle across edge ``k`` (vertices
    ``k``, ``k + 1``) of triangle ``t`` of shape ``s``, -1 on a boundary or non-manifold edge.
    The fan of local vertex ``v`` of shape ``s``: local triangles ``fan[fan_start[g]:fan_start[g + 1]]``
    with ``g = shape_vertex_start[s] + v``; ``vertex_open[g]`` 1 on a boundary. ``two_sided[t]`` (as
    ``neighbour``) 1 for a triangle listed twice in its shape (a two-sided sheet: nothing behind it;
    the edge joining it to its twin is open). ``shape_side[s]``: 1, or -1 for a closed solid wound
    inside out (:func:`shape_sides`), which turns its normals the right way round.
    ``shape_solid[s]``: 0 for an open surface (it bounds no solid), 1 for a closed one (no open edge, no
    two-sided face), 2 for a closed one of Euler characteristic 2 (one component, a sphere's topology: where
    every edge is convex, it bounds a convex solid).
    """

    neighbour: wp.array[wp.vec3i]
    two_sided: wp.array[wp.int32]
    vertex_open: wp.array[wp.int32]
    shape_side: wp.array[wp.float64]
    shape_solid: wp.array[wp.int32]
    shape_vertex_start: wp.array[wp.int32]
    fan_start: wp.array[wp.int32]
    fan: wp.array[wp.int32]


def surface_topology(scene) -> SurfaceTopology:
    """Neighbours across edges and vertex fans of all the scene's shapes, built at once (numpy).

    Args:
        scene: a :class:`~warp_ccd._src.scene.scene.Scene`.

    Returns:
        The :class:`SurfaceTopology` on the scene's device.
    """
    tri_local = scene.shapes.triangles.astype(np.int64).reshape(-1, 3)
    t_start = scene.shape_triangle_start_np.astype(np.int64)
    v_start = scene.shape_vertex_start_np.astype(np.int64)
    num_tri = len(tri_local)
    tri_shape = np.repeat(np.arange(len(t_start) - 1), np.diff(t_start))
    tri = tri_local + v_start[tri_shape][:, None]  # shape-vertex ids, unique over all shapes
    num_vertices = int(v_start[-1])
    # Edges k = (k, k + 1): a manifold edge is used by exactly two triangles.
    e0 = tri.reshape(-1)
    e1 = np.roll(tri, -1, axis=1).reshape(-1)
    key = np.minimum(e0, e1) * max(num_vertices, 1) + np.maximum(e0, e1)
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    starts = np.ones(len(key), bool)
    starts[1:] = sorted_key[1:] != sorted_key[:-1]
    group = np.cumsum(starts) - 1
    size = np.bincount(group)[group]
    partner = np.full(len(key), -1, np.int64)
    two = np.nonzero((size == 2) & starts)[0]
    partner[order[two]] = order[two + 1]
    partner[order[two + 1]] = order[two]
    neighbour = np.where(partner >= 0, partner // 3, -1)
    # Two-sided faces: a triangle listed twice (its twin reversed or not) is a sheet of no thickness.
    by_corners = np.sort(tri, axis=1)
    _, twin_group, twin_count = np.unique(by_corners, axis=0, return_inverse=True, return_counts=True)
    two_sided = twin_count[twin_group.reshape(-1)] > 1
    # A rim edge of a two-sided sheet joins the face to its own twin: an open edge, not a fold.
    across = np.maximum(neighbour, 0)
    own_twin = (neighbour >= 0) & (twin_group.reshape(-1)[across] == np.repeat(twin_group.reshape(-1), 3))
    neighbour = np.where(own_twin, -1, neighbour)
    open_edge = neighbour < 0
    neighbour = np.where(neighbour >= 0, neighbour - t_start[tri_shape.repeat(3)], -1)
    vertex_open = np.zeros(num_vertices, bool)
    vertex_open[e0[open_edge]] = True
    vertex_open[e1[open_edge]] = True
    # Fans: the triangles at each shape vertex, as local triangle ids.
    corner = tri.reshape(-1)
    by_vertex = np.argsort(corner, kind="stable")
    fan_start = np.zeros(num_vertices + 1, np.int64)
    np.cumsum(np.bincount(corner, minlength=num_vertices), out=fan_start[1:])
    fan = (by_vertex // 3) - t_start[tri_shape[by_vertex // 3]]
    side = shape_sides(scene.shapes.vertices.reshape(-1, 3), tri, tri_shape, len(t_start) - 1, open_edge)
    solid = shape_solids(tri, tri_shape, len(t_start) - 1, open_edge, num_vertices)
    d = scene.device
    s = SurfaceTopology()
    s.neighbour = wp.array(neighbour.reshape(num_tri, 3).astype(np.int32), dtype=wp.vec3i, device=d)
    s.two_sided = wp.array(two_sided.astype(np.int32), dtype=wp.int32, device=d)
    s.vertex_open = wp.array(vertex_open.astype(np.int32), dtype=wp.int32, device=d)
    s.shape_side = wp.array(side, dtype=wp.float64, device=d)
    s.shape_solid = wp.array(solid, dtype=wp.int32, device=d)
    s.shape_vertex_start = scene.shape_vertex_start
    s.fan_start = wp.array(fan_start.astype(np.int32), dtype=wp.int32, device=d)
    s.fan = wp.array(fan.astype(np.int32), dtype=wp.int32, device=d)
    return s


def shape_sides(vertices: np.ndarray, tri: np.ndarray, tri_shape: np.ndarray, num_shapes: int,
                open_edge: np.ndarray) -> np.ndarray:
    """Which way each shape faces: -1 for a solid wound inside out, else 1.

    A closed shape (no open edge) whose signed volume, its triangles' cones from its centroid, is
    negative has its normals pointing in: it is turned round. Open surfaces (a floor, a cloth, a
    terrain, a solid with a hole) are taken as wound: their volume says nothing of their side.

    Args:
        vertices: ``(V, 3)`` all shapes' vertices; tri: ``(T, 3)`` int64 indices into them.
        tri_shape: ``(T,)`` shape of each triangle; num_shapes: how many shapes.
        open_edge: ``(T * 3,)`` bool, edge ``k`` of triangle ``t`` at ``3 t + k`` is open.

    Returns:
        ``(num_shapes,)`` float64, 1 or -1.
    """
    v = np.asarray(vertices, np.float64)
    counts = np.bincount(tri_shape, minlength=num_shapes).astype(np.float64)
    centre = np.zeros((num_shapes, 3))
    corners = v[tri].mean(axis=1)
    for axis in range(3):
        centre[:, axis] = np.bincount(tri_shape, corners[:, axis], minlength=num_shapes) / np.maximum(counts, 1)
    x = v[tri] - centre[tri_shape][:, None, :]
    volume = np.bincount(tri_shape, np.einsum("ij,ij->i", x[:, 0], np.cross(x[:, 1], x[:, 2])),
                         minlength=num_shapes)
    open_edges = np.bincount(np.repeat(tri_shape, 3), open_edge.astype(np.float64), minlength=num_shapes)
    return np.where((volume < 0) & (open_edges == 0), -1.0, 1.0)


def shape_solids(tri: np.ndarray, tri_shape: np.ndarray, num_shapes: int, open_edge: np.ndarray,
                 num_vertices: int) -> np.ndarray:
    """Whether each shape bounds a solid (:class:`SurfaceTopology`'s ``shape_solid``): 0 open (an open or
    non-manifold edge), 1 closed, 2 closed with Euler characteristic ``V - E + F = 2`` (one component).

    Args:
        tri: ``(T, 3)`` int64 shape-vertex ids (unique over all shapes); tri_shape: ``(T,)`` shape of each.
        num_shapes: how many shapes; open_edge: ``(T * 3,)`` bool as in :func:`shape_sides`.
        num_vertices: shape vertices in all.

    Returns:
        ``(num_shapes,)`` int32.
    """
    faces = np.bincount(tri_shape, minlength=num_shapes)
    open_edges = np.bincount(np.repeat(tri_shape, 3), open_edge.astype(np.int64), minlength=num_shapes)
    used = np.zeros(num_vertices, bool)
    used[tri.reshape(-1)] = True
    vertex_shape = np.zeros(num_vertices, np.int64)
    vertex_shape[tri.reshape(-1)] = np.repeat(tri_shape, 3)
    vertices = np.bincount(vertex_shape[used], minlength=num_shapes)
    # Closed: every edge joins exactly two faces, so E = 3F / 2.
    euler = 2 * vertices - faces  # twice V - E + F
    closed = (open_edges == 0) & (faces > 0)
    return np.where(closed, np.where(euler == 4, 2, 1), 0).astype(np.int32)


@wp.func
def _local_triangle(mesh: MeshTopology, world_vertex: wp.array[Any], obj: int, tri: int, o: wp.vec3d):
    """Triangle ``tri`` of object ``obj`` in float64, relative to ``o``, and its local vertex ids."""
    x0, x1, x2 = mesh_triangle(mesh, world_vertex, obj, tri)
    s = mesh.object_shape[obj]
    idx = mesh.shape_triangle[mesh.shape_triangle_start[s] + tri]
    return wp.vec3d(x0) - o, wp.vec3d(x1) - o, wp.vec3d(x2) - o, idx


@wp.func
def _neighbour(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    world_vertex: wp.array[Any],
    obj: int,
    tri: int,
    idx: wp.vec3i,
    k: int,
    o: wp.vec3d,
    tol_rel: wp.float64,
):
    """The triangle across edge ``k`` of ``tri``: ``(found, normal oriented as the triangle's, its
    vertex off the edge)``; ``found`` 1, or 0 on a boundary or non-manifold edge, 2 for a
    degenerate or two-sided neighbour (no side)."""
    s = mesh.object_shape[obj]
    nbr = surface.neighbour[mesh.shape_triangle_start[s] + tri][k]
    if nbr < 0:
        return 0, wp.vec3d(), wp.vec3d()
    y0, y1, y2, jdx = _local_triangle(mesh, world_vertex, obj, nbr, o)
    n, degenerate = _unit_normal(y0, y1, y2, tol_rel)
    if degenerate or surface.two_sided[mesh.shape_triangle_start[s] + nbr] != 0:
        return 2, wp.vec3d(), wp.vec3d()
    i0 = idx[k]
    i1 = idx[(k + 1) % 3]
    # Consistent orientation walks the shared edge the other way round.
    same_way = (jdx[0] == i0 and jdx[1] == i1) or (jdx[1] == i0 and jdx[2] == i1) or (jdx[2] == i0 and jdx[0] == i1)
    if same_way:
        n = -n
    n = n * surface.shape_side[s]
    y = y0
    if jdx[1] != i0 and jdx[1] != i1:
        y = y1
    if jdx[2] != i0 and jdx[2] != i1:
        y = y2
    return 1, n, y


@wp.func
def _fan_normal(
    mesh: MeshTopology, surface: SurfaceTopology, world_vertex: wp.array[Any], obj: int, v: int, o: wp.vec3d
):
    """Angle-weighted normal of the fan of local vertex ``v`` of object ``obj`` (not normalised)."""
    s = mesh.object_shape[obj]
    g = surface.shape_vertex_start[s] + v
    acc = wp.vec3d()
    for f in range(surface.fan_start[g], surface.fan_start[g + 1]):
        x0, x1, x2, idx = _local_triangle(mesh, world_vertex, obj, surface.fan[f], o)
        n = wp.cross(x1 - x0, x2 - x0)
        ln = wp.length(n)
        # The fan triangle's edges from its corner at v.
        e1 = x1 - x0
        e2 = x2 - x0
        if idx[1] == v:
            e1 = x2 - x1
            e2 = x0 - x1
        if idx[2] == v:
            e1 = x0 - x2
            e2 = x1 - x2
        l1 = wp.length(e1)
        l2 = wp.length(e2)
        if ln > wp.float64(0.0) and l1 > wp.float64(0.0) and l2 > wp.float64(0.0):
            cosine = wp.clamp(wp.dot(e1, e2) / (l1 * l2), wp.float64(-1.0), wp.float64(1.0))
            acc = acc + n * (wp.acos(cosine) / ln)
    return acc * surface.shape_side[s]


@wp.func
def _signed_distance(
    mesh: MeshTopology,
    surface: SurfaceTopology,
    world_vertex: wp.array[Any],
    obj: int,
    tri: int,
    idx: wp.vec3i,
    x0: wp.vec3d,
    x1: wp.vec3d,
    x2: wp.vec3d,
    n: wp.vec3d,
    degenerate: bool,
    o: wp.vec3d,
    tol_rel: wp.float64,
    p: wp.vec3d,
):
    """Distance from ``p`` to triangle ``tri`` of ``obj``, negative when ``p`` lies behind the
    surface there (by the pseudo-normal of the closest point's feature); positive where there is
    no side: a degenerate or two-sided triangle, a closest point on an open edge or vertex (``p``
    lies beyond the surface's rim, not behind it)."""
    c, feature = _closest_on_triangle(p, x0, x1, x2)
    dist = wp.length(p - c)
    s = mesh.object_shape[obj]
    if degenerate or surface.two_sided[mesh.shape_triangle_start[s] + tri] != 0:
        return dist
    pn = n
    if feature >= 4:
        found, n2, y = _neighbour(mesh, surface, world_vertex, obj, tri, idx, feature - 4, o, tol_rel)
        if found != 1:
            return dist
        pn = n + n2
    elif feature >= 1:
        v = idx[feature - 1]
        if surface.vertex_open[surface.shape_vertex_start[s] + v] != 0:
            return dist
        pn = _fan_normal(mesh, surface, world_vertex, obj, v, o)
    if wp.dot(p - c, pn) < wp.float64(0.0):
        return -dist
    return dist


@wp.func
def _side_at(mesh: MeshTopology, surface: SurfaceTopology, world_vertex: wp.array[Any], obj: int, tri: int,
             p: wp.vec3d, tol_rel: wp.float64):
    """-1 when ``p`` lies behind the surface of ``obj`` at its nearest point, on triangle ``tri``
    (the closest feature's pseudo-normal), else 1."""
    if tri < 0:
        return wp.float64(1.0)
    zero = wp.vec3d()
    y0, y1, y2, idx = _local_triangle(mesh, world_vertex, obj, tri, zero)
    n, degenerate = _unit_normal(y0, y1, y2, tol_rel)
    n = n * surface.shape_side[mesh.object_shape[obj]]
    d = _signed_distance(mesh, surface, world_vertex, obj, tri, idx, y0, y1, y2, n, degenerate, zero, tol_rel, p)
    if d < wp.float64(0.0):
        return wp.float64(-1.0)
    return wp.float64(1.0)
