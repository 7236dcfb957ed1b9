"""Device functions for your own Warp kernels: the exact triangle tests and the box helpers.

Import this module into a module of Warp kernels and call its functions inside them, on ``wp.vec3``
or ``wp.vec3d`` vertices: the tests compute in the vertices' precision, with a tolerance relative to
the triangles' size (semantics, tolerance and degenerate triangles: :mod:`warp_ccd._src.geometry.triangle`).
Compile that module without floating-point contraction, for the same verdict on every device::

    import warp as wp
    from warp_ccd import geometry

    wp.set_module_options({"fuse_fp": False})

    @wp.kernel
    def meet(a: wp.array2d[wp.vec3], b: wp.array2d[wp.vec3], hit: wp.array[wp.int32]):
        k = wp.tid()
        if geometry.tri_tri_moller(a[k, 0], a[k, 1], a[k, 2], b[k, 0], b[k, 1], b[k, 2], geometry.TOLERANCE):
            hit[k] = 1

Distance: :func:`tri_tri_distance` gives how far apart two closed triangles are and a closest pair
of points (0 and a common point when they intersect; :mod:`warp_ccd._src.geometry.distance`).

Continuous collision: :func:`vertex_face_toi`, :func:`edge_edge_toi` and :func:`triangle_pair_toi`
give the earliest time in ``[0, 1]`` that linearly moving primitives touch, or :data:`NO_HIT`
(conservative: never late, never missed; :mod:`warp_ccd._src.geometry.ccd`).

Boxes are float32 ``wp.vec3`` corners: :func:`boxes_overlap` tests two closed boxes, :func:`box_lower32` /
:func:`box_upper32` round a corner outward to float32, :func:`vertex_bounds` bounds a run of vertices.
"""

from ._src.geometry.box import BOX_EMPTY, box_lower32, box_upper32, boxes_overlap, vertex_bounds
from ._src.geometry.ccd import (
    CCD_MAX_ITERATIONS,
    CCD_TOLERANCE,
    NO_HIT,
    edge_edge_toi,
    triangle_pair_toi,
    vertex_face_toi,
)
from ._src.geometry.distance import DISTANCE_ERROR_ULPS, tri_tri_distance
from ._src.geometry.triangle import (
    CONTACT_AREA,
    CONTACT_NONE,
    CONTACT_SEGMENT,
    METHOD_EDGE_FACE,
    METHOD_MOLLER,
    TOLERANCE,
    crossing_depth,
    tri_tri_edge_face,
    tri_tri_moller,
    tri_tri_segment,
    tri_tri_test,
)

__all__ = [
    "BOX_EMPTY",
    "CCD_MAX_ITERATIONS",
    "CCD_TOLERANCE",
    "CONTACT_AREA",
    "CONTACT_NONE",
    "CONTACT_SEGMENT",
    "DISTANCE_ERROR_ULPS",
    "METHOD_EDGE_FACE",
    "METHOD_MOLLER",
    "NO_HIT",
    "TOLERANCE",
    "box_lower32",
    "box_upper32",
    "boxes_overlap",
    "crossing_depth",
    "edge_edge_toi",
    "tri_tri_distance",
    "tri_tri_edge_face",
    "tri_tri_moller",
    "tri_tri_segment",
    "tri_tri_test",
    "triangle_pair_toi",
    "vertex_bounds",
    "vertex_face_toi",
]
