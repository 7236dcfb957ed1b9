"""warp_ccd's mesh-mesh contacts in a newton simulation: :class:`MeshContactBridge`.

>>> import newton
>>> from warp_ccd.newton import MeshContactBridge
>>> bridge = MeshContactBridge(model)                 # the model's mesh shapes as a warp_ccd scene
>>> contacts = bridge.contacts()                      # one newton.Contacts for both pipelines
>>> solver = newton.solvers.SolverXPBD(model)
>>> for _ in range(steps):
...     bridge.collide(state_0, contacts)             # newton's pairs, then the mesh-mesh pairs, appended
...     solver.step(state_0, state_1, control, contacts, dt)
...     state_0, state_1 = state_1, state_0

Every mesh-mesh shape pair newton would test (:attr:`newton.Model.shape_contact_pairs`) is tested by warp_ccd
(exact triangle tests, contacts reduced to ``max_per_pair`` a pair, depths measured inside the other's solid);
every other pair (a mesh on the ground plane, primitives) by newton's own pipeline, as it would be without the
bridge. A frame: one kernel places each mesh object from ``state.body_q`` (``body_q[shape_body] *
shape_transform``), warp_ccd's frame runs on them (:class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline`,
``contacts=True``), and one kernel appends its contacts to newton's arrays. No host read but warp_ccd's one read
of its counters a frame.

newton 1.8, as read from its source (``newton/_src/sim/model.py``, ``contacts.py``, ``collide.py``,
``geometry/narrow_phase.py``, the solvers):

* **Shapes and bodies.** A :class:`newton.Model` holds its shapes as flat arrays: ``shape_type``
  (:class:`newton.GeoType`, ``MESH`` = 8), ``shape_body`` (the body of each shape, ``-1`` for a static shape of
  the world), ``shape_transform`` (shape to body frame; to world for ``-1``), ``shape_scale`` (a ``vec3``, applied
  to the mesh's vertices when queried: a ``newton.Mesh`` keeps them unscaled), ``shape_source`` (host list: the
  ``newton.Mesh`` of a mesh shape, ``vertices`` ``(n, 3)`` float32 and flat ``indices``; ``shape_source_ptr`` its
  ``wp.Mesh`` ids), ``shape_margin`` (surface thickness [m]), ``shape_gap`` (extra detection distance [m],
  ``builder.rigid_gap`` = 0.1 by default), ``shape_flags`` (``COLLIDE_SHAPES``), ``shape_world`` (``-1``: every
  world), ``shape_collision_group``, ``shape_collision_filter_pairs``. The body poses live in the state:
  ``state.body_q`` ``(body_count,)`` ``wp.transform``, the body *origin* frame in world (``model.body_com`` is
  the centre of mass in that frame). ``model.shape_contact_pairs`` (built on first access) is the list of
  shape pairs that may collide, every filter applied: shapes that collide, of compatible worlds and groups
  (positive groups only among themselves, negative ones with all but themselves, 0 never), not of one body,
  not a filter pair, not both static.
* **Contacts** (:class:`newton.Contacts`, one buffer of capacity ``rigid_contact_max``): ``rigid_contact_count``
  ``(1,)`` int32 (a view of ``contact_counters[0]``, zeroed by the pipeline's first kernel); per contact
  ``rigid_contact_shape0`` / ``shape1`` (shape ids), ``rigid_contact_point0`` / ``point1`` (the contact point on
  each shape's surface, in its *body* frame, ``inverse(body_q[shape_body]) * world``), ``rigid_contact_normal``
  (world, unit, **from shape 0 toward shape 1**: shape 1 moves along ``+normal`` to separate),
  ``rigid_contact_margin0`` / ``margin1`` (effective radius + ``shape_margin``: 0 + margin for a mesh),
  ``rigid_contact_offset0`` / ``offset1`` (body frame: ``+margin0 * normal`` and ``-margin1 * normal``, the
  friction anchors' shift), ``rigid_contact_tids`` (0), and optional arrays (per-contact stiffness, damping and
  friction with hydroelastic shapes, surface velocities, match indices with contact matching, forces). The
  separation solvers use is ``dot(normal, world(point1) - world(point0)) - (margin0 + margin1)``: negative
  penetrates; a contact is written when it is at most ``shape_gap[0] + shape_gap[1]``.
* **newton's pipeline** (:class:`newton.CollisionPipeline`; ``Model.collide`` is deprecated since 1.5):
  ``collide(state, contacts)`` computes shape boxes from ``body_q`` (zeroing the counters), finds candidate pairs
  (``broad_phase="explicit"``, the default, takes ``shape_contact_pairs`` or ``shape_pairs_filtered``; ``"nxn"``
  and ``"sap"`` apply groups and filter pairs themselves), then its ``NarrowPhase`` routes each pair: analytic
  primitive pairs, GJK/MPR for convex ones, mesh-plane and mesh-convex by triangles, mesh-mesh by sampling each
  mesh against the other's signed distance (a texture SDF when built, else ``wp.Mesh`` point queries with a
  sign), with a global reduction of mesh contacts; ``write_contact`` fills the arrays above. Runs on the CPU
  (measured here: two mesh cubes on a plane, 3.7 ms a step with XPBD, warm kernel cache).
* **Solvers reading the rigid contacts.** :class:`~newton.solvers.SolverXPBD` (positional constraints, friction
  from ``shape_material_mu``; runs on the CPU), :class:`~newton.solvers.SolverSemiImplicit` and
  :class:`~newton.solvers.SolverFeatherstone` (penalty forces ``eval_body_contact`` from ``shape_material_ke``,
  ``kd``, ``kf``, ``mu``; both run on the CPU), :class:`~newton.solvers.SolverMuJoCo` with
  ``use_mujoco_contacts=False`` (MuJoCo Warp, CUDA only: its CPU backend ``use_mujoco_cpu=True`` must use
  MuJoCo's own contacts), :class:`~newton.solvers.SolverVBD` (rigid bodies by AVBD), ``SolverSteel``,
  ``SolverKamino`` and the coupled solvers.

**How the two pipelines share one buffer.** The bridge splits ``model.shape_contact_pairs`` once: the pairs of
two mesh shapes go to warp_ccd, the rest to a newton pipeline of its own with ``broad_phase="explicit"`` and
those pairs alone (``shape_pairs_filtered``). :meth:`MeshContactBridge.collide` runs newton's pipeline first (it
zeroes the counters and writes its contacts), then appends warp_ccd's after newton's count with an atomic add.
The capacity of :meth:`MeshContactBridge.contacts` is newton's own estimate plus ``mesh_contact_max``; contacts
beyond the capacity are counted (:attr:`MeshContactBridge.dropped`), never written past it. newton's filters hold
for the mesh pairs too: the warp_ccd scene has newton's worlds (``shape_world``) and excludes every mesh pair of
compatible worlds that ``shape_contact_pairs`` omits (one body, groups, filter pairs, static pairs). Not
supported for the appended contacts: newton's contact matching and deterministic sort (they run inside newton's
pipeline, before the append), per-contact hydroelastic properties (written as 0: unset), surface velocities
(written as zero).

**How steady, at what cost (measured on the CPU, 2 cores).** Three mesh cubes of side 0.2 m stacked on newton's
ground plane, XPBD (8 iterations) at 480 Hz for 1.25 s (``tests/test_newton_bridge.py``): 6.8 ms a step (newton's
pipeline for the plane 1.6, poses 0.15, warp_ccd's frame with contacts 3.5, the append 0.08, XPBD 1.4). Once at
rest (0.6 s) no body gains more than 0.046 J (0.12% of its potential energy), the deepest contact is 0.86 mm
(0.43% of the side), and the cubes creep up to 2.6 cm. newton's own mesh contacts on the same scene: 3.5 ms a
step, 0.0015 J, no creep. The jitter comes from the contacts, not the bridge: a pair apart within the margin gets
one contact (its closest points) where newton writes a manifold within the gap, so a resting pair flips between
8 contacts and 1 from step to step; at the deepest point of a shallow resting contact the distances to the other
solid's bottom and side faces are equal (a depth is a max of a min), and where the witness takes the side, the
pair's reference normal, which its depth-0 contacts take too, points sideways (seen: 5 of a cube's 8). The
one-point speculative contact also makes landings bounce: a cube dropped 5 cm flat onto another sinks 4.5 mm in
one step and XPBD's correction throws it up 4 cm. ``slop`` keeps resting pairs intersecting (fewer flips; at 240
Hz it lowered the largest energy gain from 0.2-1.2 J to 0.03-0.15 J). Non-convex pairs cost more: in
``examples/example_newton_pile.py`` a resting pair of rings costs warp_ccd's depth search about 45 ms a step on
the CPU at 256 triangles a ring, about 1 s at 480. :meth:`MeshContactBridge.collide` reads
warp_ccd's counters once a step and computes the contacts partly on the host: it is not captured in a CUDA graph,
unlike newton's pipeline.

**Conventions mapped.** A warp_ccd contact of objects ``a < b`` (their newton shapes in increasing order) has its
normal from ``b`` to ``a`` and ``point_a = point_b - depth * normal``: it becomes ``shape0 = a``, ``shape1 = b``,
``normal = -normal`` (from shape 0 toward shape 1), ``point0 = point_a``, ``point1 = point_b`` in their bodies'
frames, so that newton's separation ``dot(normal, point1 - point0) - margins`` is ``-depth - margins``. A contact
is kept where that separation is at most the pair's gap (``gap``: newton's ``shape_gap`` sum, or one value for
every pair); warp_ccd's margin is the largest gap plus margins of any mesh pair.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import warp as wp

from ..pipeline.pipeline import CollisionPipeline
from ..runtime.aliases import DeviceLike
from ..runtime.checks import integer_option, number_option
from ..scene.scene import Scene

__all__ = ["MESH_CONTACTS_PER_OBJECT", "MeshContactBridge", "mesh_pairs"]

wp.set_module_options({"enable_backward": False})

MESH_CONTACTS_PER_OBJECT = 6
"""Default room for mesh-mesh contacts: ``max_per_pair`` contacts for this many pairs a mesh object (a body in a
pile touches a few others), or for every allowed pair where they are fewer."""


@wp.kernel
def _object_pose_kernel(
    body_q: wp.array[wp.transform],
    shape_body: wp.array[wp.int32],
    shape_transform: wp.array[wp.transform],
    object_shape: wp.array[wp.int32],
    # Outputs
    object_pose: wp.array[wp.transform],
):
    """One thread per mesh object: its world pose ``body_q[body] * shape_transform`` (the shape transform alone
    for a static shape, ``body == -1``)."""
    i = wp.tid()
    s = object_shape[i]
    b = shape_body[s]
    x = shape_transform[s]
    if b >= 0:
        x = wp.transform_multiply(body_q[b], x)
    object_pose[i] = x


@wp.func
def _world_to_body(body_q: wp.array[wp.transform], body: int):
    """The world-to-body transform of ``body`` (identity for the world, ``-1``)."""
    if body < 0:
        return wp.transform_identity()
    return wp.transform_inverse(body_q[body])


@wp.func
def _kept(contact_depth: wp.array[wp.float64], contact_pair: wp.array[wp.vec2i], object_shape: wp.array[wp.int32],
          shape_margin: wp.array[wp.float32], shape_gap: wp.array[wp.float32], gap: float, i: int):
    """Whether contact ``i`` lies within its pair's gap (``gap < 0``: newton's ``shape_gap[0] + shape_gap[1]``)."""
    pair = contact_pair[i]
    s0 = object_shape[pair[0]]
    s1 = object_shape[pair[1]]
    pair_gap = gap
    if gap < 0.0:
        pair_gap = shape_gap[s0] + shape_gap[s1]
    return -wp.float32(contact_depth[i]) - (shape_margin[s0] + shape_margin[s1]) <= pair_gap


@wp.kernel
def _keep_contacts_kernel(
    contact_count: wp.array[wp.int32],
    contact_pair: wp.array[wp.vec2i],
    contact_depth: wp.array[wp.float64],
    object_shape: wp.array[wp.int32],
    shape_margin: wp.array[wp.float32],
    shape_gap: wp.array[wp.float32],
    gap: float,
    # Outputs
    keep: wp.array[wp.int32],
):
    """One thread per warp_ccd contact slot: 1 for a contact within its pair's gap, else 0 (scanned into slots)."""
    i = wp.tid()
    keep[i] = 0
    if i < contact_count[0] and _kept(contact_depth, contact_pair, object_shape, shape_margin, shape_gap, gap, i):
        keep[i] = 1


@wp.kernel
def _count_contacts_kernel(
    keep: wp.array[wp.int32],
    slot: wp.array[wp.int32],
    contact_max: int,
    # Outputs
    out_count: wp.array[wp.int32],
    dropped: wp.array[wp.int32],
):
    """One thread: newton's count raised by the contacts kept; those past ``contact_max`` counted in ``dropped``."""
    last = keep.shape[0] - 1
    total = slot[last] + keep[last]
    end = out_count[0] + total
    if end > contact_max:
        dropped[0] = dropped[0] + wp.min(end - contact_max, total)
    out_count[0] = end


@wp.kernel
def _append_contacts_kernel(
    contact_count: wp.array[wp.int32],
    contact_pair: wp.array[wp.vec2i],
    contact_point_a: wp.array[wp.vec3d],
    contact_point_b: wp.array[wp.vec3d],
    contact_normal: wp.array[wp.vec3d],
    contact_depth: wp.array[wp.float64],
    object_shape: wp.array[wp.int32],
    body_q: wp.array[wp.transform],
    shape_body: wp.array[wp.int32],
    shape_margin: wp.array[wp.float32],
    shape_gap: wp.array[wp.float32],
    gap: float,
    slop: float,
    contact_max: int,
    keep: wp.array[wp.int32],
    slot: wp.array[wp.int32],
    out_count: wp.array[wp.int32],
    # Outputs
    out_shape0: wp.array[wp.int32],
    out_shape1: wp.array[wp.int32],
    out_point0: wp.array[wp.vec3],
    out_point1: wp.array[wp.vec3],
    out_offset0: wp.array[wp.vec3],
    out_offset1: wp.array[wp.vec3],
    out_normal: wp.array[wp.vec3],
    out_margin0: wp.array[wp.float32],
    out_margin1: wp.array[wp.float32],
    out_tids: wp.array[wp.int32],
    out_stiffness: wp.array[wp.float32],
    out_damping: wp.array[wp.float32],
    out_friction: wp.array[wp.float32],
    out_surface_velocity: wp.array[wp.vec3],
):
    """One thread per warp_ccd contact slot: a contact within its pair's gap (``keep``) written to newton's arrays at
    newton's count plus its scanned ``slot``, in warp_ccd's order on every device (module docs: conventions mapped);
    those past ``contact_max`` are not written (:func:`_count_contacts_kernel` counts them). The thickness written
    is ``shape_margin - slop / 2`` a side (the gap is measured from the surfaces, without the slop)."""
    i = wp.tid()
    if i >= contact_count[0] or keep[i] == 0:
        return
    pair = contact_pair[i]
    s0 = object_shape[pair[0]]
    s1 = object_shape[pair[1]]
    margin0 = shape_margin[s0] - 0.5 * slop  # the thickness the solver reads
    margin1 = shape_margin[s1] - 0.5 * slop
    index = out_count[0] + slot[i]  # newton's count (raised after this kernel) plus the scanned slot: in order
    if index >= contact_max:
        return
    x0 = _world_to_body(body_q, shape_body[s0])
    x1 = _world_to_body(body_q, shape_body[s1])
    n = -wp.vec3(contact_normal[i])  # newton's: from shape 0 toward shape 1
    out_shape0[index] = s0
    out_shape1[index] = s1
    out_point0[index] = wp.transform_point(x0, wp.vec3(contact_point_a[i]))
    out_point1[index] = wp.transform_point(x1, wp.vec3(contact_point_b[i]))
    out_offset0[index] = wp.transform_vector(x0, margin0 * n)
    out_offset1[index] = wp.transform_vector(x1, -margin1 * n)
    out_normal[index] = n
    out_margin0[index] = margin0
    out_margin1[index] = margin1
    out_tids[index] = 0
    if out_stiffness.shape[0] > 0:
        out_stiffness[index] = 0.0
        out_damping[index] = 0.0
        out_friction[index] = 0.0
    if out_surface_velocity.shape[0] > 0:
        out_surface_velocity[index] = wp.vec3(0.0)


def mesh_pairs(model: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Splits a newton model's collision pairs between warp_ccd and newton.

    Args:
        model: a finalized :class:`newton.Model`.

    Returns:
        ``(mesh_shapes, mesh_mesh, other)``: ``(M,)`` int32 the mesh shapes of some mesh-mesh pair, increasing
        (warp_ccd's objects, in this order); ``(P, 2)`` int32 the mesh-mesh pairs of
        ``model.shape_contact_pairs`` as object indices ``a < b``, rows sorted; ``(Q, 2)`` int32 the other pairs,
        as newton's shape ids, in their order.
    """
    import newton

    pairs = model.shape_contact_pairs
    pairs = np.zeros((0, 2), np.int32) if pairs is None else pairs.numpy().reshape(-1, 2).astype(np.int32)
    is_mesh = model.shape_type.numpy() == int(newton.GeoType.MESH)
    both = is_mesh[pairs[:, 0]] & is_mesh[pairs[:, 1]] if len(pairs) else np.zeros(0, bool)
    mesh_shapes = np.unique(pairs[both]).astype(np.int32)
    objects = np.searchsorted(mesh_shapes, pairs[both])
    rows = np.unique(np.sort(objects, axis=1), axis=0).astype(np.int32).reshape(-1, 2)
    return mesh_shapes, rows, pairs[~both]


def _excluded_pairs(world: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """The object pairs of compatible worlds (equal, or one of them ``-1``) that ``allowed`` omits.

    Args:
        world: ``(M,)`` world of each object.
        allowed: ``(P, 2)`` object pairs ``a < b``.

    Returns:
        ``(E, 2)`` int64 object pairs ``a < b``. Costs the sum over worlds of (objects of the world plus the
        global ones) squared: a few global meshes and many worlds of a few meshes each stay small.
    """
    glob = np.flatnonzero(world < 0)
    keys = []

    def add(a: np.ndarray, b: np.ndarray) -> None:
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        keep = lo != hi
        keys.append((lo[keep].astype(np.int64) << 32) | hi[keep])

    ia, ib = np.triu_indices(len(glob), 1)
    add(glob[ia], glob[ib])
    for w in np.unique(world[world >= 0]):
        local = np.flatnonzero(world == w)
        ia, ib = np.triu_indices(len(local), 1)
        add(local[ia], local[ib])
        ga, la = np.meshgrid(glob, local, indexing="ij")
        add(ga.ravel(), la.ravel())
    every = np.unique(np.concatenate(keys)) if keys else np.zeros(0, np.int64)
    ok = (allowed[:, 0].astype(np.int64) << 32) | allowed[:, 1]
    out = np.setdiff1d(every, ok)
    return np.stack([out >> 32, out & 0xFFFFFFFF], axis=1)


class MeshContactBridge:
    """warp_ccd's contacts for the mesh-mesh shape pairs of a newton model, appended to newton's own.

    Args:
        model: a finalized :class:`newton.Model`; its mesh shapes (``GeoType.MESH``) of some mesh-mesh pair in
            ``model.shape_contact_pairs`` become warp_ccd objects, vertices scaled by ``shape_scale``.
        max_per_pair: the most contacts a mesh pair keeps (warp_ccd's reduction).
        gap: the separation up to which a mesh contact is written (newton's rule: ``dot(normal, p1 - p0) -
            margins <= gap``): None, each pair's ``shape_gap`` sum, newton's own rule; a number >= 0, the same for
            every mesh pair (0: touching and penetrating contacts alone, a cheaper frame).
        slop: a depth [m] the solver leaves alone (Box2D's linear slop): each side's thickness is written as
            ``shape_margin - slop / 2``, so that surfaces come to rest about ``slop`` deep and a resting pair keeps
            intersecting (module docs: stability). 0 (default): none.
        mesh_contact_max: room for mesh-mesh contacts in :meth:`contacts` (None:
            ``max_per_pair * min(pairs, MESH_CONTACTS_PER_OBJECT * objects)``).
        rigid_contact_max: the whole capacity of :meth:`contacts` (None: newton's estimate for the model plus
            ``mesh_contact_max``).
        precision: of the warp_ccd scene's vertices and poses, ``"float32"`` or ``"float64"``.
        device: Warp device (default: the model's).
        newton_options: more keywords of :class:`newton.CollisionPipeline` (not ``broad_phase``,
            ``shape_pairs_filtered``, ``rigid_contact_max``: the bridge sets them).
        **options: options of warp_ccd's :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline`
            (``tolerance``, capacities, ...).

    Attributes:
        model: the newton model.
        mesh_shapes: ``(M,)`` int32 the newton shape of each warp_ccd object.
        mesh_pairs: ``(P, 2)`` int32 the object pairs warp_ccd may report (``a < b``).
        newton_pairs: ``(Q, 2)`` int32 the shape pairs left to newton's pipeline.
        scene: the warp_ccd :class:`~warp_ccd._src.scene.scene.Scene` of the mesh objects (None without
            mesh pairs), placed by :meth:`update_poses`.
        pipeline: warp_ccd's pipeline (None without mesh pairs).
        newton_pipeline: newton's :class:`newton.CollisionPipeline` for the other pairs.
        object_pose: ``(M,)`` ``wp.transform`` the poses the last :meth:`update_poses` computed.
        result: the last frame's :class:`~warp_ccd._src.pipeline.result.CollisionResult` (its ``contacts``:
            warp_ccd's contacts in world space, depths included), or None.
        margin: warp_ccd's contact margin (module docs).
        gap, slop, max_per_pair: the options of those names.
        mesh_contact_max, rigid_contact_max: the capacities.

    Raises:
        ImportError: newton is not installed.
        ValueError: a bad option, or a mesh shape warp_ccd cannot take (naming it).
    """

    def __init__(self, model: Any, *, max_per_pair: int = 8, gap: float | None = None, slop: float = 0.0,
                 mesh_contact_max: int | None = None, rigid_contact_max: int | None = None,
                 precision: str = "float32", device: DeviceLike = None, newton_options: dict | None = None,
                 **options: Any) -> None:
        import newton

        self.model = model
        self.device = wp.get_device(device if device is not None else model.device)
        self.max_per_pair = integer_option("max_per_pair", max_per_pair, low=1)
        self.gap = None if gap is None else number_option("gap", gap, low=0.0)
        self.slop = number_option("slop", slop, low=0.0)
        newton_options = dict(newton_options or {})
        for name in ("broad_phase", "shape_pairs_filtered", "rigid_contact_max"):
            if name in newton_options:
                raise ValueError(f"newton_options: {name} is set by the bridge")
        self.mesh_shapes, self.mesh_pairs, self.newton_pairs = mesh_pairs(model)
        m, p = len(self.mesh_shapes), len(self.mesh_pairs)
        if mesh_contact_max is None:
            mesh_contact_max = self.max_per_pair * min(p, MESH_CONTACTS_PER_OBJECT * m)
        self.mesh_contact_max = integer_option("mesh_contact_max", mesh_contact_max, low=0)

        shape_margin = model.shape_margin.numpy()
        shape_gap = model.shape_gap.numpy()
        if p:
            a, b = self.mesh_shapes[self.mesh_pairs[:, 0]], self.mesh_shapes[self.mesh_pairs[:, 1]]
            pair_gap = shape_gap[a] + shape_gap[b] if self.gap is None else np.full(p, self.gap)
            self.margin = float(np.max(pair_gap + shape_margin[a] + shape_margin[b]))
        else:
            self.margin = 0.0

        pairs = wp.array(self.newton_pairs.reshape(-1, 2), dtype=wp.vec2i, device=self.device)
        if rigid_contact_max is None:  # newton's estimate for its pairs, then room for ours
            probe = newton.CollisionPipeline(model, broad_phase="explicit", shape_pairs_filtered=pairs,
                                             publish_capacity=False, **newton_options)
            rigid_contact_max = probe.rigid_contact_max + self.mesh_contact_max
            del probe
        self.rigid_contact_max = integer_option("rigid_contact_max", rigid_contact_max, low=1)
        self.newton_pipeline = newton.CollisionPipeline(model, broad_phase="explicit", shape_pairs_filtered=pairs,
                                                        rigid_contact_max=self.rigid_contact_max, **newton_options)

        self._shape_body = model.shape_body
        self._shape_transform = model.shape_transform
        self._shape_margin = model.shape_margin
        self._shape_gap = model.shape_gap
        self.object_shape = wp.array(self.mesh_shapes, dtype=wp.int32, device=self.device)
        self.object_pose = wp.zeros(m, dtype=wp.transform, device=self.device)
        self.dropped_device = wp.zeros(1, dtype=wp.int32, device=self.device)
        self._keep: wp.array | None = None  # the append's flags and slots (a scan: contacts kept in order)
        self._slot: wp.array | None = None
        self._empty = {t: wp.empty(0, dtype=t, device=self.device) for t in (wp.float32, wp.vec3)}
        self.result = None
        self.scene = None
        self.pipeline = None
        if p == 0:
            return
        self.scene = Scene(*self._shapes(model), device=self.device, precision=precision,
                           world=model.shape_world.numpy()[self.mesh_shapes],
                           exclude_pairs=_excluded_pairs(model.shape_world.numpy()[self.mesh_shapes], self.mesh_pairs))
        contact_options = {"contacts": True, "max_per_pair": self.max_per_pair}
        if self.margin > 0.0:
            contact_options["margin"] = self.margin
        self.pipeline = CollisionPipeline(self.scene, **contact_options, **options)

    def _shapes(self, model: Any) -> tuple[list, np.ndarray]:
        """The warp_ccd shapes of the mesh objects, ``([(vertices, triangles), ...], object_shape)``: one per
        distinct (newton mesh, scale), vertices scaled."""
        scale = model.shape_scale.numpy()
        shapes, index, object_shape = [], {}, []
        for s in self.mesh_shapes.tolist():
            mesh = model.shape_source[s]
            if mesh is None or getattr(mesh, "vertices", None) is None:
                raise ValueError(f"shape {s}: a mesh shape without its newton.Mesh in model.shape_source")
            key = (id(mesh), tuple(np.asarray(scale[s], np.float64).tolist()))
            if key not in index:
                index[key] = len(shapes)
                vertices = np.asarray(mesh.vertices, np.float64).reshape(-1, 3) * np.asarray(scale[s], np.float64)
                shapes.append((vertices, np.asarray(mesh.indices, np.int32).reshape(-1, 3)))
            object_shape.append(index[key])
        return shapes, np.asarray(object_shape, np.int64)

    def contacts(self) -> Any:
        """A :class:`newton.Contacts` of capacity :attr:`rigid_contact_max`, for :meth:`collide` and the solvers."""
        return self.newton_pipeline.contacts()

    def update_poses(self, state: Any) -> None:
        """Places the mesh objects where ``state.body_q`` puts their shapes (one kernel, then the scene's
        checked copy and its world vertices: no host read)."""
        if self.scene is None:
            return
        wp.launch(_object_pose_kernel, dim=len(self.mesh_shapes),
                  inputs=[state.body_q, self._shape_body, self._shape_transform, self.object_shape],
                  outputs=[self.object_pose], device=self.device)
        self.scene.set_poses(self.object_pose)

    def collide(self, state: Any, contacts: Any, **newton_kwargs: Any) -> Any:
        """Fills ``contacts`` for ``state``: newton's pipeline for its pairs, then warp_ccd's mesh-mesh contacts
        appended.

        Args:
            state: a :class:`newton.State` of the model (``body_q`` read).
            contacts: a :class:`newton.Contacts` (from :meth:`contacts`).
            **newton_kwargs: passed to :meth:`newton.CollisionPipeline.collide` (``dt``, ...).

        Returns:
            ``contacts``.
        """
        self.newton_pipeline.collide(state, contacts, **newton_kwargs)
        if self.scene is None:
            return contacts
        self.update_poses(state)
        self.result = self.pipeline.detect()
        self.append(state, self.result.contacts, contacts)
        return contacts

    def append(self, state: Any, source: Any, contacts: Any) -> None:
        """Appends the contacts of ``source`` to newton's ``contacts`` in their order (flags, a scan, a write, a count).

        Args:
            state: the :class:`newton.State` the contacts were found at (``body_q``: body frames).
            source: warp_ccd contacts of this bridge's scene: ``device_count`` ``(1,)`` int32, ``device_pairs``
                ``wp.vec2i`` object pairs ``a < b``, ``device_point_a``, ``device_point_b``, ``device_normal``
                ``wp.vec3d`` (from ``b`` to ``a``), ``device_depth`` float64.
            contacts: the :class:`newton.Contacts` to append to.
        """
        count = getattr(source, "count", None)
        if count is not None and count > self.mesh_contact_max:
            warnings.warn(f"MeshContactBridge: {count} mesh-mesh contacts, room for {self.mesh_contact_max} "
                          "(mesh_contact_max): those past the buffer's capacity are dropped (see dropped)",
                          RuntimeWarning, stacklevel=3)
        capacity = source.device_pairs.shape[0]
        if capacity == 0:
            return
        d = self.device

        def optional(a: wp.array | None, dtype) -> wp.array:
            return a if a is not None else self._empty[dtype]

        gap = -1.0 if self.gap is None else self.gap
        if self._keep is None or self._keep.shape[0] != capacity:
            self._keep = wp.empty(capacity, dtype=wp.int32, device=d)
            self._slot = wp.empty(capacity, dtype=wp.int32, device=d)
        wp.launch(_keep_contacts_kernel, dim=capacity,
                  inputs=[source.device_count, source.device_pairs, source.device_depth, self.object_shape,
                          self._shape_margin, self._shape_gap, gap],
                  outputs=[self._keep], device=d)
        wp.utils.array_scan(self._keep, self._slot, inclusive=False)
        wp.launch(_append_contacts_kernel, dim=capacity,
                  inputs=[source.device_count, source.device_pairs, source.device_point_a, source.device_point_b,
                          source.device_normal, source.device_depth, self.object_shape, state.body_q,
                          self._shape_body, self._shape_margin, self._shape_gap, gap, self.slop,
                          contacts.rigid_contact_max, self._keep, self._slot, contacts.rigid_contact_count],
                  outputs=[contacts.rigid_contact_shape0, contacts.rigid_contact_shape1,
                           contacts.rigid_contact_point0, contacts.rigid_contact_point1,
                           contacts.rigid_contact_offset0, contacts.rigid_contact_offset1,
                           contacts.rigid_contact_normal, contacts.rigid_contact_margin0,
                           contacts.rigid_contact_margin1, contacts.rigid_contact_tids,
                           optional(contacts.rigid_contact_stiffness, wp.float32),
                           optional(contacts.rigid_contact_damping, wp.float32),
                           optional(contacts.rigid_contact_friction, wp.float32),
                           optional(contacts.rigid_contact_surface_velocity, wp.vec3)],
                  device=d)
        wp.launch(_count_contacts_kernel, dim=1, inputs=[self._keep, self._slot, contacts.rigid_contact_max],
                  outputs=[contacts.rigid_contact_count, self.dropped_device], device=d)

    @property
    def dropped(self) -> int:
        """Mesh-mesh contacts not written for want of room since the bridge was made (reads the device)."""
        return int(self.dropped_device.numpy()[0])
