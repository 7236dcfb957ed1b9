"""The scaling benchmark's peers: other ways to find the same pairs, timed and cross-checked in the same run.

Each peer works on the same :class:`~warp_ccd._src.scene.scene.Scene` (or the same boxes) as this package,
so :mod:`warp_ccd._src.bench.scaling` can time them frame by frame and compare what they find. Optional
libraries are imported inside the class that needs them; a missing one raises
:class:`PeerUnavailable` naming the package, and the benchmark skips that peer with a note.

Scene peers are run at their best, as a careful user of each library runs it:

* a device peer exposes ``launch()`` (a whole frame on the device, no host read, nothing
  allocated, so it can be captured in a CUDA graph), ``counters`` (buffers whose counters are read once
  after the frame, into pinned memory) and ``triangle_pairs(count)``;
* a host peer exposes ``stages()`` (``(name, callable)`` pairs run in order every frame),
  ``finish()`` (True when the frame must run again) and ``triangle_pairs()``.

* :class:`WarpMeshPipeline`: Warp's built-in tools alone. One ``wp.Mesh`` over all world
  triangles (its points *are* ``scene.world_vertex``), refit every frame; one
  ``wp.mesh_query_aabb`` per triangle over the triangle's own box; Warp's float32
  ``wp.intersect_tri_tri`` on candidates of different objects. Cost: O(T log T) queries plus the
  candidates. Warp's test snaps plane distances below an absolute 1e-6 (on the unnormalised
  normal), so on small triangles it reports some pairs that are apart by up to about
  ``1e-6 / |n|``: compare with it through :mod:`warp_ccd._src.bench.compare`, never for equality.
* :class:`FclPipeline`: python-fcl (CPU). One ``BVHModel`` per object, built once with the
  object's uniform scale baked into its vertices (FCL transforms are rigid, and every object of a
  random scene has its own scale), one ``fcl.Transform`` per object updated every frame from the
  scene's poses, a ``DynamicAABBTreeCollisionManager`` updated and queried for triangle contacts.
  This is what a user of FCL with rigid objects does.

Broad-phase peers follow :class:`~warp_ccd._src.broadphase.sap.BroadPhaseSAP`'s interface,
``launch(lower, upper, pairs)`` into a :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of ``wp.vec2i``
(the caller resets it and checks its counter after) and ``counters`` (buffers of their own with
counters: none here):

* :class:`NewtonBroadPhaseSAP`: newton's ``newton.geometry.BroadPhaseSAP`` (one fixed sweep
  direction, every box in one world and one collision group). Its rows are unordered: ``(a, b)``
  or ``(b, a)``.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..runtime.buffers import GrowableBuffer, reserve_slot
from ..scene.scene import Scene

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = [
    "fcl_bvh",
    "FclPipeline",
    "NewtonBroadPhaseSAP",
    "PeerUnavailable",
    "WarpMeshPipeline",
    "scene_triangle_vertex_index",
]


def fcl_bvh(vertices, triangles):
    """A python-fcl ``BVHModel`` (its default OBBRSS) of one mesh: float64 vertices, int64 triangles."""
    import fcl

    model = fcl.BVHModel()
    model.beginModel(len(vertices), len(triangles))
    model.addSubModel(np.asarray(vertices, np.float64), np.asarray(triangles, np.int64))
    model.endModel()
    return model


class PeerUnavailable(RuntimeError):
    """A peer's library is not installed or cannot run here; the message says which and why."""


def scene_triangle_vertex_index(scene: Scene, triangles=None) -> np.ndarray:
    """Global vertex indices of scene triangles given by global id (default: all, in order).

    Global triangle ``g = scene.object_triangle_start_np[i] + t`` is local triangle ``t`` of
    object ``i``; its vertices are rows of ``scene.world_vertex``.

    Args:
        scene: the scene.
        triangles: ``(K,)`` global triangle ids, or None for ``0 .. T - 1``.

    Returns:
        ``(K, 3)`` int32 indices into the ``(V,)`` world vertices.
    """
    if triangles is None:
        triangles = np.arange(scene.num_triangles, dtype=np.int64)
    g = np.asarray(triangles, np.int64).reshape(-1)
    if g.size == 0:
        return np.zeros((0, 3), np.int32)
    shape_tri = np.concatenate([t for _, t in scene.shape_meshes]).astype(np.int64)
    inst = np.searchsorted(scene.object_triangle_start_np, g, side="right") - 1
    local = g - scene.object_triangle_start_np[inst]
    shape_start = scene.shape_triangle_start_np[scene.object_shape_np[inst]]
    tri = shape_tri[shape_start + local] + scene.object_vertex_start_np[inst][:, None]
    return tri.astype(np.int32)


@wp.kernel
def _count_to_int64_kernel(count32: wp.array[wp.int32], count: wp.array[wp.int64]):
    """Copies newton's int32 pair counter into our int64 one."""
    count[0] = wp.int64(count32[0])


# ---------------------------------------------------------------------------------------------
# Warp's built-in pipeline: wp.Mesh + wp.mesh_query_aabb + wp.intersect_tri_tri


@wp.kernel
def _mesh_triangle_pairs_kernel(
    mesh: wp.uint64,
    point: wp.array[wp.vec3],
    index: wp.array[wp.int32],
    triangle_object: wp.array[wp.int32],
    object_triangle_start: wp.array[wp.int32],
    hit_capacity: int,
    # Outputs
    hit: wp.array[wp.vec4i],
    hit_count: wp.array[wp.int64],
):
    """One thread per global triangle ``t``: query the mesh with the triangle's box, test each
    later triangle ``f > t`` of another object with ``wp.intersect_tri_tri`` (float32).

    Writes rows ``(obj_a, tri_a, obj_b, tri_b)`` of local triangle ids, ``obj_a < obj_b`` (global
    ids grow with the object id), through the capacity + counter protocol.
    """
    t = wp.tid()
    a0 = point[index[3 * t]]
    a1 = point[index[3 * t + 1]]
    a2 = point[index[3 * t + 2]]
    lo = wp.min(wp.min(a0, a1), a2)
    hi = wp.max(wp.max(a0, a1), a2)
    obj = triangle_object[t]
    query = wp.mesh_query_aabb(mesh, lo, hi)
    f = int(0)
    while wp.mesh_query_next(query, f):
        if f > t:
            obj_f = triangle_object[f]
            if obj_f != obj:
                b0 = point[index[3 * f]]
                b1 = point[index[3 * f + 1]]
                b2 = point[index[3 * f + 2]]
                if wp.intersect_tri_tri(a0, a1, a2, b0, b1, b2) != 0:
                    slot = reserve_slot(hit_count, hit_capacity)
                    if slot >= 0:
                        hit[slot] = wp.vec4i(obj, t - object_triangle_start[obj],
                                             obj_f, f - object_triangle_start[obj_f])


class WarpMeshPipeline:
    """Warp's built-in collision tools over a whole scene (see module docs).

    Args:
        scene: the scene; the mesh's points are ``scene.world_vertex`` itself.
        capacity: initial capacity of the hit buffer (it grows).
        constructor: ``wp.Mesh`` BVH constructor (None: Warp's default for the device).
    """

    name = "warp_builtin"
    """Name of this peer in benchmark rows."""

    def __init__(self, scene: Scene, *, capacity: int | None = None, constructor: str | None = None):
        self.scene = scene
        self.device = scene.device
        d = self.device
        n = scene.num_objects
        tri = scene_triangle_vertex_index(scene)
        self.index = wp.array(tri.reshape(-1), dtype=wp.int32, device=d)
        counts = np.diff(scene.object_triangle_start_np)
        self.triangle_object = wp.array(np.repeat(np.arange(n, dtype=np.int32), counts), dtype=wp.int32, device=d)
        self.mesh = wp.Mesh(points=scene.world_vertex, indices=self.index, bvh_constructor=constructor)
        self.hits = GrowableBuffer(wp.vec4i, capacity or max(256, 4 * n), d, "built-in triangle pairs")

    def refit(self) -> None:
        """Refits the mesh's tree to the current world vertices."""
        self.mesh.refit()

    def query(self) -> None:
        """One query per triangle; hits into :attr:`hits` (host reads nothing)."""
        if self.scene.num_triangles == 0:
            return
        wp.launch(
            _mesh_triangle_pairs_kernel,
            dim=self.scene.num_triangles,
            inputs=[self.mesh.id, self.scene.world_vertex, self.index, self.triangle_object,
                    self.scene.object_triangle_start, self.hits.capacity],
            outputs=[self.hits.data, self.hits.count],
            device=self.device,
        )

    def launch(self) -> None:
        """One frame on the device: reset the counter, refit, query. The host reads nothing and
        nothing is allocated, so the frame can be captured in a graph
        (:class:`~warp_ccd._src.runtime.frame.CountedFrame` reads :attr:`counters` after it)."""
        self.hits.reset()
        self.refit()
        self.query()

    @property
    def counters(self) -> list:
        """The buffers with counters that :meth:`launch` resets and writes: ``[hits]``."""
        return [self.hits]

    def triangle_pairs(self, count: int | None = None) -> np.ndarray:
        """``(M, 4)`` int32 rows ``(obj_a, tri_a, obj_b, tri_b)`` of the last frame, sorted.

        Args:
            count: the frame's hit count (default: read the counter now).
        """
        t = self.hits.numpy(count).reshape(-1, 4).astype(np.int32)
        return t[np.lexsort((t[:, 3], t[:, 2], t[:, 1], t[:, 0]))]


# ---------------------------------------------------------------------------------------------
# python-fcl


class FclPipeline:
    """python-fcl's dynamic AABB tree with per-triangle contacts (CPU; see module docs).

    Args:
        scene: the scene (a rigid one: poses and uniform scales; ``scene.deforming`` is refused).
        max_contacts: FCL's ``num_max_contacts``. FCL stops silently at it, so a frame that
            reaches it is run again with twice the limit.

    Raises:
        PeerUnavailable: python-fcl is not installed.
        ValueError: a deforming scene (FCL models are rigid).
    """

    name = "fcl"
    """Name of this peer in benchmark rows."""

    def __init__(self, scene: Scene, *, max_contacts: int = 1_000_000):
        try:
            import fcl
        except ImportError as exc:
            raise PeerUnavailable(f"python-fcl is not installed ({exc})") from None
        if scene.deforming:
            raise ValueError("fcl peer: a deforming scene has no rigid poses")
        self._fcl = fcl
        self.scene = scene
        self.max_contacts = int(max_contacts)
        self.objects = []
        self._object_of = {}
        for i in range(scene.num_objects):
            v, t = scene.shape_meshes[scene.object_shape_np[i]]
            # Scale in float32 first, as the scene's world-vertex kernel does.
            model = fcl_bvh((v * np.float32(scene.object_scale_np[i])).astype(np.float64), t)
            self._object_of[id(model)] = i
            self.objects.append((model, fcl.CollisionObject(model, fcl.Transform())))
        self._set_transforms()
        self.manager = fcl.DynamicAABBTreeCollisionManager()
        self.manager.registerObjects([o for _, o in self.objects])
        self.manager.setup()
        self.data = None

    def _set_transforms(self) -> None:
        fcl = self._fcl
        pose = self.scene.object_pose.numpy().astype(np.float64).reshape(-1, 7)  # (px, py, pz, qx, qy, qz, qw)
        quat_wxyz = pose[:, [6, 3, 4, 5]]
        for (_, obj), p, q in zip(self.objects, pose[:, :3], quat_wxyz):
            obj.setTransform(fcl.Transform(q, p))

    def update(self) -> None:
        """Copies the scene's poses to the host, sets one ``fcl.Transform`` per object, updates the tree."""
        self._set_transforms()
        self.manager.update()

    def collide(self) -> None:
        """All pairs of intersecting triangles of different objects (host, one thread)."""
        fcl = self._fcl
        request = fcl.CollisionRequest(num_max_contacts=self.max_contacts, enable_contact=True)
        self.data = fcl.CollisionData(request=request)
        self.manager.collide(self.data, fcl.defaultCollisionCallback)

    def stages(self) -> list:
        """``[("update", ...), ("collide", ...)]``, run in this order every frame."""
        return [("update", self.update), ("collide", self.collide)]

    def finish(self) -> bool:
        """True (and a doubled limit) when FCL reached ``max_contacts`` and may have dropped some."""
        if len(self.data.result.contacts) >= self.max_contacts:
            self.max_contacts *= 2
            return True
        return False

    def triangle_pairs(self) -> np.ndarray:
        """``(M, 4)`` int32 rows ``(obj_a, tri_a, obj_b, tri_b)`` of the last frame, sorted."""
        rows = set()
        for c in self.data.result.contacts:
            a, b = self._object_of[id(c.o1)], self._object_of[id(c.o2)]
            ta, tb = c.b1, c.b2
            if a > b:
                a, b, ta, tb = b, a, tb, ta
            rows.add((a, ta, b, tb))
        if not rows:
            return np.zeros((0, 4), np.int32)
        t = np.array(sorted(rows), np.int32)
        return t


# ---------------------------------------------------------------------------------------------
# newton's sweep and prune


class NewtonBroadPhaseSAP:
    """newton's ``BroadPhaseSAP`` behind ``launch(lower, upper, pairs)``.

    All boxes are put in collision group 1 (so every pair may collide), with no gap and no filter,
    in world 0 or the worlds given (newton's per-world sweep: a segmented sort of each world's boxes,
    world -1's appended to every world). newton sweeps along one fixed direction and sorts with Warp's
    radix sort. Rows are written as newton finds them: ``(a, b)`` or ``(b, a)``.

    Args:
        device: Warp device.
        shape_world: ``(N,)`` world of each box (newton's convention: ``-1`` pairs with every world), or
            None (every box in world 0).

    Raises:
        PeerUnavailable: newton is not installed or fails to import.
    """

    def __init__(self, *, device=None, shape_world: np.ndarray | None = None):
        self.shape_world_np = None if shape_world is None else np.asarray(shape_world, np.int32)
        try:
            from newton.geometry import BroadPhaseSAP
        except Exception as exc:  # ImportError, or newton failing on this Warp
            raise PeerUnavailable(f"newton is not available ({type(exc).__name__}: {exc})") from None
        self._sap_class = BroadPhaseSAP
        self.device = wp.get_device(device)
        self.num_boxes = -1
        self.sap = None

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers of its own with counters that :meth:`launch` writes: none (only ``pairs``)."""
        return []

    def _resize(self, n: int) -> None:
        if n == self.num_boxes:
            return
        d = self.device
        self.num_boxes = n
        world = np.zeros(n, np.int32) if self.shape_world_np is None else self.shape_world_np
        if len(world) != n:
            raise ValueError(f"shape_world: {len(world)} worlds for {n} boxes")
        self.sap = self._sap_class(world, device=d)
        self.count32 = wp.zeros(1, dtype=wp.int32, device=d)  # newton counts in int32
        self.shape_group = wp.array(np.ones(n, np.int32), dtype=wp.int32, device=d)
        self.shape_world = wp.array(world, dtype=wp.int32, device=d)

    def launch(self, lower: wp.array, upper: wp.array, pairs: GrowableBuffer) -> None:
        """Writes overlapping pairs of the ``(N,)`` boxes into ``pairs`` (newton zeroes its counter)."""
        n = lower.shape[0]
        if n < 2:
            return
        self._resize(n)
        self.sap.launch(lower, upper, None, self.shape_group, self.shape_world, n,
                        pairs.data, self.count32, device=self.device)
        wp.launch(_count_to_int64_kernel, dim=1, inputs=[self.count32], outputs=[pairs.count], device=self.device)
