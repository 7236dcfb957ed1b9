"""Narrow phase: the exact triangle tests over a scene's candidate pairs, and the :class:`NarrowPhase` stage.

The tests are device functions of :mod:`warp_ccd.geometry` (:func:`~warp_ccd._src.geometry.triangle.tri_tri_moller`,
:func:`~warp_ccd._src.geometry.triangle.tri_tri_edge_face`; their semantics: :mod:`warp_ccd._src.geometry.triangle`).
This module runs them over the rows ``(obj_a, tri_a, obj_b, tri_b)`` of the mid phase's candidates,
on the scene's world vertices, and adds what needs the scene: each hit's segment, and the objects
wholly inside another (:func:`winding_number`).

Over candidate pairs (:class:`NarrowPhase`), Möller's test runs as two launches. One thread per
candidate takes steps 1 to 3, and the pairs that do not cross go to a touch list whose step 4 (six
edge-against-face tests) runs in a second kernel, two threads a pair (the edges of one triangle
against the other's face each; six threads, one test each, recomputed the pair's set-up six
times). A warp of the first kernel then no longer waits for its slowest lane's six tests, the
longest of the test's paths (at 1,000 polyhedra, 874 of 4,917 candidates reach step 4, in nearly
every warp; steps 1 to 3 alone take less than half the whole test's time). The
rare pairs, with a degenerate triangle or coplanar, go from the first kernel to a rare list that
the second kernel's threads past the touch rows take, one a row, with the whole test
(:func:`tri_tri_moller`), so that the first holds only the common path in its registers (capped
at :data:`MAX_REGISTERS` on CUDA, as the second's). The rare list was a third launch of its own
(one graph node more); in the second kernel its branch is one no touch thread takes. Compiled
for sm_90 by ptxas 13.0 (float32), the touch kernel alone spilled 764 bytes and the rare kernel,
capped alike, 1,504; the two in one kernel spill 2,372, about their sum: the rare branch brings
its own spills: a graph node fewer for small frames, a little more local memory for big ones (the
trade is measured in the docs: architecture, narrow phase). The verdicts are those of
:func:`tri_tri_moller`, bit for bit.

Every device gives the same verdict: the module is compiled without floating-point contraction
(``fuse_fp=False``, as the tests ask of the modules that call them). The winding number of the
containment option uses ``atan2`` and may differ in its last bits, far from its decision at 1/2.

Precision: the kernels are Warp generics over the world vertices' type; their float32 and float64
variants are declared with ``wp.overload`` after them (:func:`~warp_ccd._src.geometry.precision.precision_overloads`),
so the module compiles once for both. They take the tolerance in float64 and round it to the
vertices' precision.
"""


from typing import Any

import warp as wp

from ..geometry.precision import precision_overloads
from ..geometry.primitives import _edges_near_face, _unit_normal
from ..geometry.triangle import (
    CONTACT_COPLANAR_A,
    CONTACT_COPLANAR_B,
    CONTACT_NONE,
    CONTACT_SEGMENT,
    CONTACT_TOUCH_TEST,
    METHOD_EDGE_FACE,
    METHOD_MOLLER,
    TOLERANCE,
    _centre,
    _moller_steps,
    tri_tri_edge_face,
    tri_tri_moller,
    tri_tri_segment,
)
from ..runtime.aliases import DeviceLike
from ..runtime.buffers import GrowableBuffer, reserve_slot, used_count
from ..runtime.options import check_option
from ..scene.scene import MeshTopology, Scene, mesh_triangle
from .pairs import PairList, append_hit, append_pair, pair_count, pair_list, pair_triangles

# Forward kernels only; no FMA contraction, so that CPU and CUDA round every step alike.
wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = ["MAX_REGISTERS", "NARROW_METHODS", "NarrowPhase", "winding_number"]


MAX_REGISTERS = 128
"""Most registers a thread of the two kernels of Möller's test on CUDA: as compiled freely they take
255 (with spills) and 164, so that a multiprocessor holds 256 of their threads; at 128 it holds 512,
and the big frames are faster (at 64, slower again: spills; docs: architecture, narrow phase;
``bench/box_tests.py --max-registers``, ``bench/kernel_resources.py``)."""

NARROW_METHODS = {"moller": METHOD_MOLLER, "edge_face": METHOD_EDGE_FACE}
"""The ``narrow_phase`` option's names of the two tests, and their ``method`` ids."""

FOUR_PI = wp.constant(wp.float64(12.566370614359172))
"""The solid angle of the whole sphere (the winding number's unit)."""


@wp.func
def winding_number(mesh: MeshTopology, world_vertex: wp.array[Any], obj: int, num_triangles: int, p: Any):
    """Generalised winding number of point ``p`` w.r.t. object ``obj``'s closed mesh.

    Sum of the solid angles of its triangles seen from ``p`` over 4 pi (Van Oosterom and
    Strackee's formula): about 1 inside, 0 outside, with no special cases for rays through
    edges or vertices. O(m), in the precision of ``p`` and ``world_vertex``.
    """
    total = type(p[0])(0.0)
    for t in range(num_triangles):
        a, b, c = mesh_triangle(mesh, world_vertex, obj, t)
        a = a - p
        b = b - p
        c = c - p
        la = wp.length(a)
        lb = wp.length(b)
        lc = wp.length(c)
        num = wp.dot(a, wp.cross(b, c))
        den = la * lb * lc + wp.dot(a, b) * lc + wp.dot(a, c) * lb + wp.dot(b, c) * la
        total += type(p[0])(2.0) * wp.atan2(num, den)
    return total / type(p[0])(FOUR_PI)


@wp.func
def _point_in_box(p: wp.vec3, lo: wp.vec3, hi: wp.vec3) -> bool:
    """Point ``p`` lies in the closed box (a box of the broad phase: rounded outward, so a float64
    point rounded to float32 stays in it)."""
    return lo[0] <= p[0] and p[0] <= hi[0] and lo[1] <= p[1] and p[1] <= hi[1] and lo[2] <= p[2] and p[2] <= hi[2]


@wp.kernel(cuda_max_registers=MAX_REGISTERS)
def _narrow_moller_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    candidates: PairList,
    tol_rel: wp.float64,
    # Outputs
    hits: PairList,
    object_colliding: wp.array[wp.int32],
    touch: PairList,
    touch_flag: wp.array[wp.int32],
    rare: PairList,
):
    """One thread per candidate ``(obj_a, tri_a, obj_b, tri_b)``: steps 1 to 3 of Möller's test
    (:func:`_moller_steps`); a crossing is a hit, a pair that does not cross goes to the touch
    list (its flag cleared) for step 4 (:func:`_narrow_touch_kernel`), and a pair with a
    degenerate triangle, or coplanar, to the rare list (taken by the touch kernel's threads past the
    touch rows): their code stays out of this kernel, whose registers then hold the common path."""
    k = wp.tid()
    if k >= pair_count(candidates):
        return
    c = candidates.row[k]
    v0, v1, v2, u0, u1, u2 = pair_triangles(mesh, world_vertex, c)
    tol = type(v0[0])(tol_rel)
    na, degenerate_a = _unit_normal(v0, v1, v2, tol)
    nb, degenerate_b = _unit_normal(u0, u1, u2, tol)
    kind = CONTACT_NONE
    is_rare = degenerate_a or degenerate_b
    if not is_rare:
        a0, a1, a2, b0, b1, b2, eps = _centre(v0, v1, v2, u0, u1, u2, tol)
        kind, p, q = _moller_steps(a0, a1, a2, b0, b1, b2, na, nb, eps)
        is_rare = kind == CONTACT_COPLANAR_A or kind == CONTACT_COPLANAR_B
    if kind == CONTACT_TOUCH_TEST:
        slot = append_pair(touch, c)
        if slot >= 0:
            touch_flag[slot] = 0
    elif is_rare:
        append_pair(rare, c)
    elif kind != CONTACT_NONE:
        append_hit(hits, object_colliding, c)


@wp.func
def _rare_row(mesh: MeshTopology, world_vertex: wp.array[Any], c: wp.vec4i, tol_rel: wp.float64, hits: PairList,
              object_colliding: wp.array[wp.int32]):
    """A row of the rare list (a degenerate triangle, or coplanar triangles): the whole of Möller's test
    (:func:`tri_tri_moller`); appends a hit."""
    v0, v1, v2, u0, u1, u2 = pair_triangles(mesh, world_vertex, c)
    if tri_tri_moller(v0, v1, v2, u0, u1, u2, type(v0[0])(tol_rel)):
        append_hit(hits, object_colliding, c)


@wp.kernel(cuda_max_registers=MAX_REGISTERS)
def _narrow_touch_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    touch: PairList,
    rare: PairList,
    tol_rel: wp.float64,
    # Outputs
    touch_flag: wp.array[wp.int32],
    hits: PairList,
    object_colliding: wp.array[wp.int32],
):
    """Step 4 of Möller's test, two threads per row ``u`` of the touch list: thread ``2 u`` tests
    the edges of triangle a against b's face, ``2 u + 1`` those of b against a's
    (:func:`~warp_ccd._src.geometry.primitives._edges_near_face`; each thread computes the one normal and
    the edge normals of its face once). The pair touches when one of the six edge tests says so
    (:func:`~warp_ccd._src.geometry.primitives._edges_meet`); the first thread to find it (its flag)
    appends the row.

    The threads past the touch rows' ``2 touch_capacity`` take the rare list, one row each
    (:func:`_rare_row`), in the same launch: the rare list is complete when this kernel starts, as
    the touch list is. Their branch holds the whole test, beside the touch step's and not in its
    way: it is taken by no thread of the touch rows (see the module docstring on registers)."""
    t = wp.tid()
    if t >= 2 * touch.capacity:
        k = t - 2 * touch.capacity
        if k < pair_count(rare):
            _rare_row(mesh, world_vertex, rare.row[k], tol_rel, hits, object_colliding)
        return
    u = t / 2
    side = t - 2 * u
    if u >= pair_count(touch):
        return
    c = touch.row[u]
    v0, v1, v2, u0, u1, u2 = pair_triangles(mesh, world_vertex, c)
    tol = type(v0[0])(tol_rel)
    a0, a1, a2, b0, b1, b2, eps = _centre(v0, v1, v2, u0, u1, u2, tol)
    near = False
    if side == 0:  # only the face's normal (both triangles are not degenerate: step 1 to 3 decide those)
        nb, degenerate_b = _unit_normal(u0, u1, u2, tol)
        near, p, q = _edges_near_face(a0, a1, a2, b0, b1, b2, nb, eps)
    else:
        na, degenerate_a = _unit_normal(v0, v1, v2, tol)
        near, p, q = _edges_near_face(b0, b1, b2, a0, a1, a2, na, eps)
    if near and wp.atomic_add(touch_flag, u, 1) == 0:
        append_hit(hits, object_colliding, c)


@wp.kernel
def _narrow_edge_face_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    candidates: PairList,
    tol_rel: wp.float64,
    # Outputs
    hits: PairList,
    object_colliding: wp.array[wp.int32],
):
    """One thread per candidate ``(obj_a, tri_a, obj_b, tri_b)``: the edge-face test, append hits."""
    k = wp.tid()
    if k >= pair_count(candidates):
        return
    c = candidates.row[k]
    a0, a1, a2, b0, b1, b2 = pair_triangles(mesh, world_vertex, c)
    if tri_tri_edge_face(a0, a1, a2, b0, b1, b2, tol_rel):
        append_hit(hits, object_colliding, c)


@wp.kernel
def _segment_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    hits: PairList,
    tol_rel: wp.float64,
    # Outputs
    segment: wp.array2d[Any],
):
    """One thread per triangle pair found: its intersection segment (NaN for coplanar areas)."""
    k = wp.tid()
    if k >= pair_count(hits):
        return
    c = hits.row[k]
    a0, a1, a2, b0, b1, b2 = pair_triangles(mesh, world_vertex, c)
    kind, p, q = tri_tri_segment(a0, a1, a2, b0, b1, b2, tol_rel)
    if kind != CONTACT_SEGMENT:
        nan = type(p[0])(wp.nan)
        p = type(p)(nan, nan, nan)
        q = p
    segment[k, 0] = p
    segment[k, 1] = q


@wp.kernel
def _containment_kernel(
    mesh: MeshTopology,
    world_vertex: wp.array[Any],
    object_lower: wp.array[wp.vec3],
    object_upper: wp.array[wp.vec3],
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
    pair_capacity: int,
    contained_capacity: int,
    # Outputs
    contained: wp.array[wp.vec2i],
    contained_count: wp.array[wp.int64],
):
    """One thread per object pair, each way round: is the inner object's first vertex inside the
    outer object's box (a box may be loose: a rigid object's comes from its tree) and then inside
    the outer object (winding number above 1/2)? Writes ``(inner, outer)``."""
    k = wp.tid()
    if k >= used_count(pair_count, pair_capacity):
        return
    p = pair[k]
    for side in range(2):
        inner = p[side]
        outer = p[1 - side]
        point = world_vertex[mesh.object_vertex_start[inner]]
        if _point_in_box(wp.vec3(point), object_lower[outer], object_upper[outer]):
            m = mesh.object_triangle_start[outer + 1] - mesh.object_triangle_start[outer]
            if winding_number(mesh, world_vertex, outer, m, point) > type(point[0])(0.5):
                slot = reserve_slot(contained_count, contained_capacity)
                if slot >= 0:
                    contained[slot] = wp.vec2i(inner, outer)


# Both precisions, declared up front: the module compiles once, for float32 and float64 together.
# The kernels take the tolerance in float64 and round it to the vertices' precision.
_NARROW_MOLLER, _NARROW_TOUCH, _NARROW_EDGE_FACE, _CONTAINMENT = (
    precision_overloads(k, lambda s, v, q, t: {"world_vertex": wp.array[v]})
    for k in (_narrow_moller_kernel, _narrow_touch_kernel, _narrow_edge_face_kernel, _containment_kernel))
_SEGMENT = precision_overloads(_segment_kernel, lambda s, v, q, t: {"world_vertex": wp.array[v],
                                                                  "segment": wp.array2d[v]})


class NarrowPhase:
    """Exact tests of candidate triangle pairs; owns what it writes: the hit buffer, the
    per-object flags and, when asked for, the hits' segments and the containment pairs.

    Args:
        num_objects: ``N`` (size of :attr:`object_colliding`).
        method: ``"moller"`` (default) or ``"edge_face"``.
        tolerance: relative tolerance of the test.
        capacity: initial capacity of the hit buffer (it grows).
        segments: also compute each hit's intersection segment (:attr:`segment`).
        containment: also find objects wholly inside another (:attr:`contained`), from the
            object pairs where one holds the other's first vertex in its box.
        device: Warp device.

    Attributes:
        hits: :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of ``wp.vec4i`` rows
            ``(obj_a, tri_a, obj_b, tri_b)``.
        touch: with ``method="moller"``, the :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of the
            candidates that do not cross and may touch (step 4, tested two threads a row by a
            second kernel; else None), with ``touch_flag``, ``(touch.capacity,)`` int32.
        rare: with ``method="moller"``, the :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of the
            candidates with a degenerate triangle or coplanar triangles (tested whole by the touch
            kernel's threads past the touch rows; else None).
        object_colliding: ``(N,)`` int32, 1 for an object with a hit.
        segment: ``(hits.capacity, 2)`` end points (the scene's vector type) of each hit's
            segment (NaN for coplanar contacts), or None without ``segments``.
        contained: :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of ``wp.vec2i`` rows
            ``(inner, outer)``, or None without ``containment``.
    """

    def __init__(self, num_objects: int, *, method: str = "moller", tolerance: float = TOLERANCE,
                 capacity: int = 1024, segments: bool = False, containment: bool = False,
                 device: DeviceLike = None) -> None:
        self.method = check_option("narrow_phase", method)
        self.tolerance = check_option("tolerance", tolerance)
        self.segments = check_option("segments", segments)
        self.device = wp.get_device(device)
        self.hits = GrowableBuffer(wp.vec4i, capacity, self.device, "triangle pairs")
        self.touch = (GrowableBuffer(wp.vec4i, capacity, self.device, "candidates that may touch")
                      if method == "moller" else None)
        self.rare = (GrowableBuffer(wp.vec4i, 64, self.device, "candidates degenerate or coplanar")
                     if method == "moller" else None)
        self.touch_flag = None
        self.object_colliding = wp.zeros(num_objects, dtype=wp.int32, device=self.device)
        self.segment = None
        self.contained = (GrowableBuffer(wp.vec2i, max(16, num_objects // 8), self.device, "contained pairs")
                          if check_option("containment", containment) else None)
        self.toi = None  # a discrete test has no times of impact (ContinuousNarrowPhase has)

    @property
    def pad_abs(self) -> float:
        """Padding in scene units the boxes upstream need besides the tolerance's: none (the test sees one
        moment)."""
        return 0.0

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers with counters that :meth:`launch` resets and writes; the caller reads
        their counters after it."""
        return [b for b in (self.hits, self.touch, self.rare, self.contained) if b is not None]

    def launch(self, scene: Scene, candidates: GrowableBuffer, object_pairs: GrowableBuffer | None = None,
               object_lower: wp.array | None = None, object_upper: wp.array | None = None, *,
               world_vertex_start: wp.array | None = None, reset_counters: bool = True) -> None:
        """Tests the candidates of ``scene``: resets and writes the hits and the flags, and the
        segments and the containment pairs when asked for (host reads nothing).

        Args:
            scene: the :class:`~warp_ccd._src.scene.scene.Scene` (its world vertices now).
            candidates: ``wp.vec4i`` candidate triangle pairs.
            object_pairs: the broad phase's object pairs (needed with ``containment``).
            object_lower: the ``(N,)`` lower corners of the object boxes it saw (needed with ``containment``).
            object_upper: the ``(N,)`` upper corners of those boxes (needed with ``containment``).
            world_vertex_start: None (the discrete tests see one moment; the narrow phases take the same
                arguments).
            reset_counters: zero the counters of :attr:`counters` first; False when the caller
                has zeroed them already (a frame zeroes all its counters with one memset).
        """
        if world_vertex_start is not None:
            raise ValueError("world_vertex_start: the discrete narrow phase tests one moment (continuous=True "
                             "tests a motion)")
        if self.contained is not None and (object_pairs is None or object_lower is None or object_upper is None):
            raise ValueError("containment: launch needs the object pairs and the object boxes")
        d = self.device
        if reset_counters:
            for buffer in self.counters:
                buffer.reset()
        self.object_colliding.zero_()
        tol = wp.float64(self.tolerance)
        hits = self.hits
        if self.touch is None:
            wp.launch(_NARROW_EDGE_FACE[scene.precision], dim=candidates.capacity,
                      inputs=[scene.topology, scene.world_vertex, pair_list(candidates), tol],
                      outputs=[pair_list(hits), self.object_colliding], device=d)
        else:
            touch = self.touch
            if self.touch_flag is None or self.touch_flag.shape[0] != touch.capacity:  # follows the capacity
                self.touch_flag = wp.zeros(touch.capacity, dtype=wp.int32, device=d)
            rare = self.rare
            hit_list, touch_list, rare_list = pair_list(hits), pair_list(touch), pair_list(rare)
            wp.launch(_NARROW_MOLLER[scene.precision], dim=candidates.capacity,
                      inputs=[scene.topology, scene.world_vertex, pair_list(candidates), tol],
                      outputs=[hit_list, self.object_colliding, touch_list, self.touch_flag, rare_list], device=d)
            # The touch step's rows, two threads each, then the rare rows, one thread each: one launch.
            wp.launch(_NARROW_TOUCH[scene.precision], dim=2 * touch.capacity + rare.capacity,
                      inputs=[scene.topology, scene.world_vertex, touch_list, rare_list, tol],
                      outputs=[self.touch_flag, hit_list, self.object_colliding], device=d)
        if self.segments:
            if self.segment is None or self.segment.shape[0] != hits.capacity or self.segment.dtype != scene.vec3_type:
                self.segment = wp.zeros((hits.capacity, 2), dtype=scene.vec3_type, device=d)
            wp.launch(_SEGMENT[scene.precision], dim=hits.capacity,
                      inputs=[scene.topology, scene.world_vertex, pair_list(hits), tol],
                      outputs=[self.segment], device=d)
        if self.contained is not None:
            wp.launch(
                _CONTAINMENT[scene.precision],
                dim=object_pairs.capacity,
                inputs=[scene.topology, scene.world_vertex, object_lower, object_upper, object_pairs.data,
                        object_pairs.count, object_pairs.capacity, self.contained.capacity],
                outputs=[self.contained.data, self.contained.count],
                device=d,
            )
