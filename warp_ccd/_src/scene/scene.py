"""Scenes: shapes stored once, objects by shape id, world vertices on one device.

Data layout (struct of arrays, all on ``scene.device``):

* Shapes: local vertices of all shapes concatenated (``shape_vertex``), triangles as local vertex
  indices (``shape_triangle``), and ``shape_vertex_start`` / ``shape_triangle_start`` offsets
  (``S + 1`` entries each).
* Objects: ``object_shape`` (shape id), ``object_scale`` (uniform scale),
  ``object_pose`` (``wp.transform``), ``object_vertex_start`` and ``object_triangle_start``
  (``N + 1`` entries each). A triangle is identified by ``(object, local triangle id)``; its
  global id is ``object_triangle_start[object] + local id``. Triangles are never copied per
  object.
* World vertices of all objects concatenated (``world_vertex``, ``V`` entries), with
  ``vertex_object`` giving the owner of each.

Kernels find a triangle's world vertices with :func:`mesh_triangle` from the index arrays (the
:class:`MeshTopology` struct, the same at both precisions) and ``world_vertex`` (``wp.vec3`` or
``wp.vec3d``), a separate generic argument.

Three ways to move a scene: ``advance(dt)`` for scenes with an :class:`~warp_ccd._src.scene.motion.EllipseMotion`,
``set_transforms`` / ``set_poses`` for rigid objects placed by the caller, and writing
``world_vertex`` directly (``set_world_vertices`` or a kernel of one's own) for deforming meshes.
"""

import math
from collections.abc import Sequence
from functools import cached_property
from itertools import chain
from typing import Any

import numpy as np
import warp as wp

from ..geometry.precision import (
    coordinate_message,
    needed_precision,
    precision_overloads,
    precision_types,
    shape_radius,
    triangle_size,
)
from ..runtime.aliases import ArrayLike, DeviceLike
from ..runtime.arrays import device_view, host_array, is_device_array, packed_arrays
from ..runtime.checks import integer_option, number_option
from ..runtime.start import init_warp
from .filter import CollisionFilter
from .inputs import InputCheck
from .motion import EllipseMotion, advance_time
from .shapes import MeshSet, row_max, validate_meshes
from .shapes import shape as _named_shape

# Forward kernels only; no FMA contraction, so that world vertices from the same poses are the same
# bits on every device (the narrow phase's verdicts then agree too).
wp.set_module_options({"enable_backward": False, "fuse_fp": False})

__all__ = ["QUAT_TOLERANCE", "MeshTopology", "Scene", "matrix_to_quat", "mesh_triangle", "poses_to_rows",
           "quat_to_matrix", "transforms_to_poses"]


@wp.struct
class MeshTopology:
    """Which world vertices make triangle ``(object, local id)``: everything but the vertices
    themselves, which kernels take as a separate ``world_vertex`` array of either precision."""

    shape_triangle: wp.array[wp.vec3i]
    shape_triangle_start: wp.array[wp.int32]
    object_shape: wp.array[wp.int32]
    object_vertex_start: wp.array[wp.int32]
    object_triangle_start: wp.array[wp.int32]


@wp.func
def mesh_triangle(topology: MeshTopology, world_vertex: wp.array[Any], obj: int, tri: int):
    """World positions ``(a, b, c)`` of local triangle ``tri`` of object ``obj``."""
    s = topology.object_shape[obj]
    idx = topology.shape_triangle[topology.shape_triangle_start[s] + tri]
    base = topology.object_vertex_start[obj]
    return (
        world_vertex[base + idx[0]],
        world_vertex[base + idx[1]],
        world_vertex[base + idx[2]],
    )


@wp.kernel
def _world_vertex_kernel(
    shape_vertex: wp.array[Any],
    shape_vertex_start: wp.array[wp.int32],
    object_shape: wp.array[wp.int32],
    object_scale: wp.array[wp.float32],
    object_pose: wp.array[Any],
    object_vertex_start: wp.array[wp.int32],
    vertex_object: wp.array[wp.int32],
    # Outputs
    world_vertex: wp.array[Any],
):
    """One thread per world vertex: ``pose * (scale * local vertex)``."""
    v = wp.tid()
    i = vertex_object[v]
    local = v - object_vertex_start[i]
    p = shape_vertex[shape_vertex_start[object_shape[i]] + local]
    world_vertex[v] = wp.transform_point(object_pose[i], p * type(p[0])(object_scale[i]))


_WORLD_VERTEX = precision_overloads(_world_vertex_kernel, lambda s, v, q, t: {
    "shape_vertex": wp.array[v], "object_pose": wp.array[t], "world_vertex": wp.array[v]})


@wp.kernel
def _vertex_to_float32_kernel(src: wp.array[wp.vec3d], dst: wp.array[wp.vec3]):
    """One thread per vertex: float64 to float32 (nearest)."""
    v = wp.tid()
    dst[v] = wp.vec3(src[v])


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Unit quaternions to rotation matrices.

    Args:
        q: ``(N, 4)`` unit quaternions ``(x, y, z, w)`` (Warp's order).

    Returns:
        ``(N, 3, 3)`` float64 rotation matrices acting on column vectors.
    """
    x, y, z, w = np.asarray(q, np.float64).reshape(-1, 4).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=1)


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """Rotation matrices to unit quaternions.

    Args:
        r: ``(N, 3, 3)`` rotation matrices acting on column vectors (``p' = r p``).

    Returns:
        ``(N, 4)`` float64 unit quaternions ``(x, y, z, w)`` (Warp's order, as in ``wp.transform``).
    """
    r = np.asarray(r, dtype=np.float64)
    n = r.shape[0]
    q = np.empty((n, 4))
    tr = np.trace(r, axis1=1, axis2=2)
    diag = np.stack([r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]], axis=1)
    case = np.where(tr > diag.max(axis=1), 3, diag.argmax(axis=1))
    for c in range(4):
        m = case == c
        if not m.any():
            continue
        rm = r[m]
        if c == 3:
            s = np.sqrt(1.0 + tr[m]) * 2.0
            q[m] = np.stack(
                [(rm[:, 2, 1] - rm[:, 1, 2]) / s, (rm[:, 0, 2] - rm[:, 2, 0]) / s, (rm[:, 1, 0] - rm[:, 0, 1]) / s,
                 s / 4],
                axis=1,
            )
        else:
            i, j, k = c, (c + 1) % 3, (c + 2) % 3
            s = np.sqrt(1.0 + rm[:, i, i] - rm[:, j, j] - rm[:, k, k]) * 2.0
            out = np.empty((m.sum(), 4))
            out[:, i] = s / 4
            out[:, j] = (rm[:, j, i] + rm[:, i, j]) / s
            out[:, k] = (rm[:, k, i] + rm[:, i, k]) / s
            out[:, 3] = (rm[:, k, j] - rm[:, j, k]) / s
            q[m] = out
    return q / np.linalg.norm(q, axis=1, keepdims=True)


QUAT_TOLERANCE = 1e-3
"""How far from 1 the norm of a given quaternion may be (it is used as given, as Warp's transforms use it)."""


def poses_to_rows(poses: ArrayLike, num_objects: int, *, name: str = "poses") -> np.ndarray:
    """Validates ``(N, 7)`` poses ``(px, py, pz, qx, qy, qz, qw)`` (Warp's order), kept as given (bit for bit).

    Args:
        poses: ``(N, 7)`` array-like.
        num_objects: expected ``N``.
        name: the argument's name, for errors.

    Returns:
        ``(N, 7)`` float64 rows.

    Raises:
        ValueError: naming the first bad row.
    """
    try:
        p = np.asarray(host_array(poses, name), dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: not an array of numbers ({exc})") from None
    if p.shape != (num_objects, 7):
        raise ValueError(f"{name}: expected shape ({num_objects}, 7) for {num_objects} objects, got {p.shape}")
    finite = np.isfinite(p).all(axis=1)
    if not finite.all():
        raise ValueError(f"{name}: row {int(np.argmin(finite))} is not finite")
    norm = np.linalg.norm(p[:, 3:], axis=1)
    bad = np.abs(norm - 1.0) > QUAT_TOLERANCE
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"{name}: row {i} has a quaternion of norm {norm[i]:.6g}, not unit (x, y, z, w)")
    with np.errstate(over="ignore"):
        if not np.isfinite(p.astype(np.float32)).all():
            raise ValueError(f"{name}: translations overflow float32")
    return p


def transforms_to_poses(transforms: ArrayLike, num_objects: int, *, tol: float = 1e-4) -> np.ndarray:
    """Validates rigid transforms and converts them to ``wp.transform`` rows.

    Args:
        transforms: ``(N, 4, 4)`` array-like, each a rotation (orthonormal, determinant +1, within ``tol``)
            and a translation, bottom row ``(0, 0, 0, 1)``; or ``(N, 7)`` poses ``(px, py, pz, qx, qy, qz, qw)``
            (position, then quaternion x, y, z, w: Warp's order), each quaternion unit within
            :data:`QUAT_TOLERANCE` (used as given). Any :data:`~warp_ccd._src.runtime.arrays.ArrayLike` (torch, JAX,
            Warp).
        num_objects: expected ``N``.
        tol: tolerance of the rigidity checks.

    Returns:
        ``(N, 7)`` float64 rows ``(px, py, pz, qx, qy, qz, qw)``.

    Raises:
        ValueError: naming the first bad transform and what is wrong with it.
    """
    try:
        m = np.asarray(host_array(transforms, "transforms"), dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"transforms: not an array of numbers ({exc})") from None
    if m.ndim == 2 and m.shape[-1] == 7:
        return poses_to_rows(m, num_objects, name="transforms")
    if m.shape != (num_objects, 4, 4):
        raise ValueError(f"transforms: expected shape ({num_objects}, 4, 4) or ({num_objects}, 7) for "
                         f"{num_objects} objects, got {m.shape}")
    if num_objects == 0:
        return np.zeros((0, 7), np.float64)
    finite = np.isfinite(m).all(axis=(1, 2))
    if not finite.all():
        raise ValueError(f"transform {int(np.argmin(finite))}: contains NaN or inf")
    bottom = np.abs(m[:, 3] - np.array([0.0, 0.0, 0.0, 1.0])).max(axis=1) > tol
    if bottom.any():
        i = int(np.argmax(bottom))
        raise ValueError(f"transform {i}: bottom row must be (0, 0, 0, 1), got {m[i, 3].tolist()}")
    r = m[:, :3, :3]
    ortho = np.abs(np.einsum("nji,njk->nik", r, r) - np.eye(3)).max(axis=(1, 2)) > tol
    if ortho.any():
        i = int(np.argmax(ortho))
        raise ValueError(f"transform {i}: not rigid (rotation part is not orthonormal: scale or shear)")
    det = np.linalg.det(r)
    if (det < 0).any():
        i = int(np.argmax(det < 0))
        raise ValueError(f"transform {i}: not rigid (reflection, determinant {det[i]:.3g})")
    out = np.empty((num_objects, 7), np.float64)
    out[:, :3] = m[:, :3, 3]
    out[:, 3:] = matrix_to_quat(r)
    with np.errstate(over="ignore"):
        if not np.isfinite(out.astype(np.float32)).all():
            raise ValueError("transforms: translations overflow float32")
    return out


def _check_coordinates(packed: MeshSet, inst: np.ndarray, poses: np.ndarray | None, precision: str) -> None:
    """Raises ValueError when ``precision`` does not resolve the scene's world vertices at its triangles'
    size (:func:`~warp_ccd._src.geometry.precision.needed_precision`), naming the mesh with the largest coordinate.

    Args:
        packed: the meshes (float64 vertices: world vertices when ``poses`` is None).
        inst: ``(N,)`` shape of each object.
        poses: ``(N, 7)`` rigid poses, or None.
        precision: the scene's precision.
    """
    if not inst.size or not len(packed.vertices):
        return
    if poses is None:
        far = row_max(np.abs(packed.vertices))
        owner = np.repeat(np.arange(len(packed)), np.diff(packed.vertex_start))
        per_shape = np.zeros(len(packed))
        np.maximum.at(per_shape, owner, far)
        reach = per_shape[inst]
    else:  # |world coordinate| <= |translation| + the shape's radius
        reach = np.abs(poses[:, :3]).max(axis=1) + shape_radius(packed.vertices, packed.vertex_start)[inst]
    worst = int(np.argmax(reach))
    size = triangle_size(packed.vertices, packed.triangles, packed.vertex_start, packed.triangle_start, inst)
    needed = needed_precision(reach[worst], size)
    if needed is None:
        raise ValueError(f"mesh {worst}: {coordinate_message(reach[worst], size, 'float64')}: move the scene "
                         "nearer the origin")
    if needed == "float64" and precision == "float32":
        raise ValueError(f"mesh {worst}: {coordinate_message(reach[worst], size, 'float32')}: "
                         "use precision='float64'")


def _deforming_flags(deforming: bool | ArrayLike, n: int) -> np.ndarray:
    """``deforming`` as a bool or an ``(n,)`` bool array, or ValueError."""
    flags = host_array(deforming, "deforming")
    if flags.dtype != bool or flags.shape not in ((), (n,)):
        raise ValueError(f"deforming: expected a bool or ({n},) bools, got {flags.dtype} {flags.shape}")
    return flags


class Scene:
    """Shapes, objects, poses and world vertices of ``N`` objects on one device.

    Most users build scenes with :meth:`random` or :meth:`from_meshes`.

    Args:
        shapes: sequence of ``(vertices (n, 3), triangles (m, 3))`` meshes, each validated, or a
            :class:`~warp_ccd._src.scene.shapes.MeshSet` that :func:`~warp_ccd._src.scene.shapes.validate_meshes`
            returned.
        object_shape: ``(N,)`` shape id of each object.
        object_scale: ``(N,)`` uniform scale of each object (default 1).
        poses: ``(N, 7)`` rows ``(px, py, pz, qx, qy, qz, qw)`` (default identity).
        motion: optional :class:`EllipseMotion`; then :meth:`advance` moves the objects.
        deforming: True when the caller writes every object's world vertices
            (:meth:`set_world_vertices`), False (default) when poses place them all, or an ``(N,)``
            bool mask of the objects whose vertices the caller writes (the others stay rigid: their
            trees are never refit, see :mod:`warp_ccd._src.trees.bvh`).
        device: Warp device (default: Warp's default device).
        precision: ``"float32"`` (default) or ``"float64"``: type of shape vertices, poses and
            world vertices, and of the exact triangle test. Object and node boxes stay float32,
            rounded outward.
        world: ``(N,)`` integer world id of each object: objects of different worlds never pair, world
            ``-1`` pairs with every world (thousands of environments in one scene, one launch each
            stage). None: one world.
        group: ``(N,)`` 32-bit collision group of each object: a pair collides when
            ``group[a] & mask[b]`` and ``group[b] & mask[a]`` are non-zero. None: every bit set.
        mask: ``(N,)`` 32-bit collision mask of each object (the groups it collides with). None: every bit set.
        exclude_pairs: ``(E, 2)`` object indices of pairs that never collide (meant to touch).
            The filters apply in the broad phase (:mod:`warp_ccd._src.scene.filter`).

    Attributes:
        scalar_type, vec3_type, transform_type: the Warp types of its precision
            (:func:`~warp_ccd._src.geometry.precision.precision_types`).
        topology: the :class:`MeshTopology` struct kernels take beside ``world_vertex``.
        time_device: ``(1,)`` float64, the motion's time on the device (see :attr:`time`).
        collision_filter: the :class:`~warp_ccd._src.scene.filter.CollisionFilter` of ``world``, ``group``,
            ``mask`` and ``exclude_pairs``, or None when none is given.
        input_check: the :class:`~warp_ccd._src.scene.inputs.InputCheck` of device-side inputs (its fault
            is raised by the pipeline's next ``detect()``, or by :meth:`check_inputs`).
    """

    def __init__(
        self,
        shapes: Sequence | MeshSet,
        object_shape: ArrayLike,
        *,
        object_scale: ArrayLike | None = None,
        poses: ArrayLike | None = None,
        motion: EllipseMotion | None = None,
        deforming: bool | ArrayLike = False,
        device: DeviceLike = None,
        precision: str = "float32",
        world: ArrayLike | None = None,
        group: ArrayLike | None = None,
        mask: ArrayLike | None = None,
        exclude_pairs: ArrayLike | None = None,
    ) -> None:
        init_warp()  # without the no-CUDA-driver notice on a machine without a GPU
        self.scalar_type, self.vec3_type, _, self.transform_type = precision_types(precision)
        self.device = wp.get_device(device)
        self.precision = precision
        fdtype = np.float64 if precision == "float64" else np.float32
        if isinstance(shapes, MeshSet):
            packed = shapes
            if packed.vertices.dtype != fdtype:
                packed = MeshSet(packed.vertices.astype(fdtype), packed.triangles, packed.vertex_start,
                                 packed.triangle_start)
        else:
            packed = validate_meshes(list(shapes), kind="shape", dtype=fdtype)
        self.shapes = packed
        num_shapes = len(packed)
        inst = host_array(object_shape, "object_shape")
        if inst.ndim != 1 or (inst.size and not np.issubdtype(inst.dtype, np.integer)):
            raise ValueError(
                f"object_shape: expected a 1-D array of integer shape ids, got {inst.dtype} {inst.shape}")
        inst = inst.astype(np.int64)
        if inst.size and (inst.min() < 0 or inst.max() >= num_shapes):
            raise ValueError(f"object_shape: ids must lie in [0, {num_shapes}), got {inst.min()}..{inst.max()}")
        n = inst.size
        self.num_objects = n
        self.num_shapes = num_shapes
        flags = _deforming_flags(deforming, n)
        self.object_deforming_np = np.broadcast_to(flags, (n,)).copy()
        """``(N,)`` bool: the objects whose world vertices the caller writes."""
        self.deforming = bool(self.object_deforming_np.any()) or (flags.ndim == 0 and bool(flags))
        self.motion = motion
        if motion is not None and motion.num_objects != n:
            raise ValueError(f"motion: has {motion.num_objects} objects, scene has {n}")
        if motion is not None and motion.precision != precision:
            raise ValueError(f"motion: precision {motion.precision}, scene {precision}")

        scale = np.ones(n, np.float32) if object_scale is None else np.asarray(
            host_array(object_scale, "object_scale"), np.float32)
        if scale.shape != (n,) or not np.isfinite(scale).all() or (scale <= 0).any():
            raise ValueError(f"object_scale: expected ({n},) finite positive values")
        if poses is None:
            poses = np.tile(np.array([0, 0, 0, 0, 0, 0, 1], np.float64), (n, 1))
        poses = poses_to_rows(poses, n).astype(fdtype)
        filters = (world, group, mask, exclude_pairs)
        self.collision_filter = None if all(f is None for f in filters) else CollisionFilter(
            n, world=world, group=group, mask=mask, exclude_pairs=exclude_pairs, device=device)

        # Host-side topology (static): offsets of shapes and objects.
        shape_nv = np.diff(packed.vertex_start)
        shape_nt = np.diff(packed.triangle_start)
        self.shape_vertex_start_np = packed.vertex_start.astype(np.int32)
        self.shape_triangle_start_np = packed.triangle_start.astype(np.int32)
        self.object_shape_np = inst.astype(np.int32)
        inst_nv = shape_nv[inst] if n else np.zeros(0, np.int64)
        inst_nt = shape_nt[inst] if n else np.zeros(0, np.int64)
        vstart = np.concatenate([[0], np.cumsum(inst_nv)])
        tstart = np.concatenate([[0], np.cumsum(inst_nt)])
        if vstart[-1] >= 2**31 or tstart[-1] >= 2**31:
            raise ValueError(f"scene too large: {vstart[-1]} vertices, {tstart[-1]} triangles (limit 2**31 - 1)")
        self.object_vertex_start_np = vstart.astype(np.int32)
        self.object_triangle_start_np = tstart.astype(np.int32)
        self.num_world_vertices = int(vstart[-1])
        self.num_triangles = int(tstart[-1])
        self.object_scale_np = scale

        d = self.device
        vec3 = self.vec3_type
        (self.shape_vertex, self.shape_triangle, self.shape_vertex_start, self.shape_triangle_start,
         self.object_shape, self.object_scale, self.object_pose, self.object_vertex_start, self.object_triangle_start,
         self.vertex_object) = packed_arrays([  # the small ones in one copy
            (packed.vertices, vec3), (packed.triangles, wp.vec3i), (self.shape_vertex_start_np, wp.int32),
            (self.shape_triangle_start_np, wp.int32), (self.object_shape_np, wp.int32), (scale, wp.float32),
            (poses, self.transform_type), (self.object_vertex_start_np, wp.int32),
            (self.object_triangle_start_np, wp.int32), (np.repeat(np.arange(n, dtype=np.int32), inst_nv), wp.int32)], d)
        self.world_vertex = wp.zeros(self.num_world_vertices, dtype=vec3, device=d)
        self.topology = MeshTopology()
        self.topology.shape_triangle = self.shape_triangle
        self.topology.shape_triangle_start = self.shape_triangle_start
        self.topology.object_shape = self.object_shape
        self.topology.object_vertex_start = self.object_vertex_start
        self.topology.object_triangle_start = self.object_triangle_start
        self._time = 0.0
        self.time_device = wp.zeros(1, dtype=wp.float64, device=d)
        size = triangle_size(packed.vertices, packed.triangles, packed.vertex_start, packed.triangle_start, inst, scale)
        radius = shape_radius(packed.vertices, packed.vertex_start)[inst] * scale if n else np.zeros(0)
        self.input_check = InputCheck(d, precision=precision, size=size, object_radius=radius)
        if motion is not None:
            motion.launch(self.time_device, self.object_pose)
        self.pose_world_vertices()  # a deforming scene too: it starts as its meshes were given

    # ------------------------------------------------------------------ construction
    @classmethod
    def random(
        cls,
        num_objects: int,
        seed: int = 0,
        shapes: Sequence = ("tetrahedron", "cube", "octahedron", "dodecahedron", "icosahedron"),
        density: float = 0.04,
        size_range: tuple[float, float] = (0.5, 1.5),
        device: DeviceLike = None,
        precision: str = "float32",
    ) -> "Scene":
        """Seeded polyhedra moving on inclined ellipses, spread at constant density.

        Object radii are ``U(size_range)``; centres are uniform in a cube whose side is chosen so that the
        objects' bounding spheres fill ``density`` of its volume. Each object orbits a few of its own sizes,
        so the fraction of objects in contact stays about the same for any ``num_objects``.

        Args:
            num_objects: ``N >= 0``.
            seed: random seed (same seed, same scene).
            shapes: shape names (see :func:`warp_ccd._src.scene.shapes.shape`) or ``(vertices, triangles)``
                meshes, chosen uniformly; each is scaled to the object's radius (a mesh as given,
                so give meshes of radius about 1).
            density: volume fraction of bounding spheres, in ``(0, 1)``.
            size_range: ``(min, max)`` radius in scene units.
            device: Warp device.
            precision: ``"float32"`` or ``"float64"`` (see :class:`Scene`).
        """
        integer_option("num_objects", num_objects, low=0)
        number_option("density", density, low=0.0, high=1.0, low_open=True, high_open=True)
        integer_option("seed", seed, low=0, allow_none=True)
        try:
            lo, hi = (float(x) for x in size_range)
        except (TypeError, ValueError):
            raise ValueError(f"size_range must be (min, max) numbers, got {size_range!r}") from None
        if not 0.0 < lo <= hi or not np.isfinite(hi):
            raise ValueError(f"size_range must be 0 < min <= max, got {size_range!r}")
        if len(shapes) == 0:
            raise ValueError("shapes: at least one shape name is needed")
        meshes = [_named_shape(s) if isinstance(s, str) else s for s in shapes]
        rng = np.random.default_rng(seed)
        n = int(num_objects)
        inst = rng.integers(0, len(meshes), size=n)
        radius = rng.uniform(lo, hi, size=n)
        volume = (4.0 / 3.0) * np.pi * float(np.sum(radius**3))
        side = (volume / density) ** (1.0 / 3.0) if n else 1.0
        centre = rng.uniform(-0.5 * side, 0.5 * side, size=(n, 3))
        motion = EllipseMotion.random(rng, centre, radius, device=device, precision=precision)
        scene = cls(meshes, inst, object_scale=radius, motion=motion, device=device, precision=precision)
        return scene

    @classmethod
    def from_meshes(
        cls,
        meshes: Sequence,
        transforms: ArrayLike | None = None,
        *,
        deforming: bool | ArrayLike = False,
        device: DeviceLike = None,
        precision: str = "float32",
        world: ArrayLike | None = None,
        group: ArrayLike | None = None,
        mask: ArrayLike | None = None,
        exclude_pairs: ArrayLike | None = None,
    ) -> "Scene":
        """A scene of user meshes, one object per mesh.

        Meshes passed as the very same array objects share one shape (instancing).

        Args:
            meshes: sequence of ``(vertices (n, 3) float, triangles (m, 3) int)`` (numpy, torch, JAX,
                CuPy or Warp arrays).
            transforms: ``(N, 4, 4)`` rigid transforms or ``(N, 7)`` poses (position, then quaternion
                ``x, y, z, w``), or None when vertices are in world space.
            deforming: True when the caller will write every object's world vertices each frame
                (:meth:`set_world_vertices`), or an ``(N,)`` bool mask of those objects.
            device: Warp device.
            precision: ``"float32"`` or ``"float64"`` (see :class:`Scene`).
            world: ``(N,)`` integer world id of each object, or None: one world (see :class:`Scene`).
            group: ``(N,)`` 32-bit collision group of each object, or None: every bit set (see :class:`Scene`).
            mask: ``(N,)`` 32-bit collision mask of each object, or None: every bit set (see :class:`Scene`).
            exclude_pairs: ``(E, 2)`` object indices of pairs that never collide, or None (see :class:`Scene`).

        Raises:
            ValueError: a bad mesh or transform (naming it), or world vertices too far from the
                origin for ``precision`` at the triangles' size (naming the mesh with the largest
                coordinate; :func:`~warp_ccd._src.geometry.precision.needed_precision`): float32 beyond about
                ``8.4e3`` times the typical triangle size (use ``precision="float64"``), float64
                beyond ``4.5e12`` times, either beyond ``3.4e38``. Only the vertices as given are
                checked, not later poses.
        """
        if isinstance(meshes, (str, bytes)) or not isinstance(meshes, Sequence):
            raise TypeError(f"meshes: expected a sequence of (vertices, triangles), got {type(meshes).__name__}")
        if not (set(map(type, meshes)) <= {tuple, list} and set(map(len, meshes)) <= {2}):  # else one by one
            pairs = [isinstance(m, (tuple, list)) and len(m) == 2 for m in meshes]
            if not all(pairs):
                i = pairs.index(False)
                raise ValueError(f"mesh {i}: expected a (vertices, triangles) pair, got {type(meshes[i]).__name__}")
        n = len(meshes)
        flags = _deforming_flags(deforming, n)
        if flags.any() or n == 0:
            source = np.arange(n)
            inst = source
        else:  # the very same arrays share one shape, numbered in order of first use
            key = np.fromiter(map(id, chain.from_iterable(meshes)), np.int64, 2 * n).reshape(n, 2)
            _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
            by_use = np.argsort(first)
            rank = np.empty_like(by_use)
            rank[by_use] = np.arange(len(by_use))
            source = first[by_use]
            inst = rank[inverse.reshape(-1)]
        given = [meshes[i] for i in source.tolist()] if len(source) < n else list(meshes)
        if not set(map(type, chain.from_iterable(given))) <= {np.ndarray}:  # numpy as is
            given = [tuple(a if type(a) is np.ndarray else host_array(a, f"mesh {i}") for a in given[k])
                     for k, i in enumerate(source.tolist())]
        packed = validate_meshes(given, labels=source, kind="mesh", dtype=np.float64)
        poses = None
        if transforms is not None:
            if flags.ndim == 0 and flags:
                raise ValueError("transforms: a deforming scene takes world vertices, not transforms")
            poses = transforms_to_poses(transforms, n)
        precision_types(precision)  # a bad precision named before the guard's message
        _check_coordinates(packed, np.asarray(inst, np.int64), poses, precision)
        return cls(packed, np.asarray(inst, np.int64), poses=poses, deforming=flags, device=device,
                   precision=precision, world=world, group=group, mask=mask, exclude_pairs=exclude_pairs)

    # ------------------------------------------------------------------ motion
    def update_world_vertices(self) -> None:
        """Recomputes ``world_vertex`` from the poses (not for deforming scenes: their caller writes
        the world vertices; they start as the meshes were given)."""
        if self.deforming:
            return
        self.pose_world_vertices()

    def pose_world_vertices(self) -> None:
        """Computes every object's world vertices from the shapes, scales and poses (one kernel),
        deforming or not: for a scene that mixes both, whose caller then overwrites the deforming
        objects' vertices (as :class:`~warp_ccd._src.usd.importer.UsdMeshImport` does)."""
        if self.num_world_vertices == 0:
            return
        wp.launch(
            _WORLD_VERTEX[self.precision],
            dim=self.num_world_vertices,
            inputs=[
                self.shape_vertex,
                self.shape_vertex_start,
                self.object_shape,
                self.object_scale,
                self.object_pose,
                self.object_vertex_start,
                self.vertex_object,
            ],
            outputs=[self.world_vertex],
            device=self.device,
        )

    @property
    def time(self) -> float:
        """Seconds of motion so far (the host's copy of :attr:`time_device`); setting it moves
        nothing until the next :meth:`advance`."""
        return self._time

    @time.setter
    def time(self, value: float) -> None:
        value = self._seconds(value, "time")
        self._time = value
        self.time_device.fill_(value)

    @staticmethod
    def _seconds(dt, what: str = "advance: dt") -> float:
        if type(dt) is float and math.isfinite(dt):  # the common case, checked fast (host time of a frame)
            return dt
        return number_option(f"{what} (seconds)", dt)

    def advance(self, dt: float) -> None:
        """Moves time forward by ``dt`` seconds: poses, then world vertices, all in kernels."""
        self.advance_host(dt)
        self.enqueue_advance(dt)

    def advance_host(self, dt: float) -> float:
        """The host's half of :meth:`advance`: validates ``dt`` and adds it to :attr:`time`
        (for a frame whose device half, :meth:`enqueue_advance`, is replayed from a CUDA graph).

        Returns:
            ``dt`` as a float.
        """
        if self.motion is None:
            raise ValueError("advance: this scene has no motion (use set_transforms or set_world_vertices)")
        dt = self._seconds(dt)
        self._time += dt
        return dt

    def enqueue_advance(self, dt: float) -> None:
        """The device's half of :meth:`advance`: poses at :attr:`time_device` ``+ dt``, the device
        time moved on by ``dt``, then the world vertices. Enqueues kernels only (capturable)."""
        if self.num_objects:
            self.motion.launch(self.time_device, self.object_pose, step=dt)
        advance_time(self.time_device, dt)
        self.update_world_vertices()

    def set_transforms(self, transforms: ArrayLike) -> None:
        """Places the objects with rigid transforms, then updates world vertices.

        Args:
            transforms: ``(N, 4, 4)`` rigid transforms or ``(N, 7)`` poses (position, then quaternion
                ``x, y, z, w``). An array already on this scene's device (a ``wp.array``, or a torch,
                JAX or CuPy array through DLPack or ``__cuda_array_interface__``) is read in place by a
                kernel that checks it (no copy through the host: a bad row is raised by the next
                ``detect()`` or :meth:`check_inputs`); a host array is checked here, then uploaded. A
                transform that places its object beyond what the scene's precision resolves at its triangle
                size (:func:`~warp_ccd._src.geometry.precision.needed_precision`) is bad.

        Raises:
            ValueError: a deforming scene, a bad shape, or (host arrays) the first bad transform.
        """
        if self.deforming:
            raise ValueError("set_transforms: a deforming scene takes world vertices")
        if is_device_array(transforms):
            self._device_poses(transforms, "set_transforms", matrices=True)
        else:
            poses = transforms_to_poses(transforms, self.num_objects)
            self._check_reach(poses, "set_transforms")
            self.object_pose.assign(poses.astype(np.float64 if self.precision == "float64" else np.float32))
        self.update_world_vertices()

    def set_poses(self, poses: ArrayLike) -> None:
        """Places the objects with ``(N, 7)`` poses (position, then quaternion ``x, y, z, w``: Warp's
        order), then updates world vertices.

        Args:
            poses: ``(N, 7)`` float32 or float64 rows, or ``(N,)`` ``wp.transform`` /
                ``wp.transformd``. An array on this scene's device (Warp, torch, JAX, CuPy) is read in
                place and checked by a kernel (see :meth:`set_transforms`); a host array is checked
                here, then uploaded.

        Raises:
            ValueError: a bad shape, an array on another device than a CUDA scene's host, or (host
                arrays) the first bad row.
        """
        if is_device_array(poses):
            self._device_poses(poses, "set_poses", matrices=False)
        else:
            rows = poses_to_rows(poses, self.num_objects, name="set_poses")
            self._check_reach(rows, "set_poses")
            self.object_pose.assign(rows.astype(np.float64 if self.precision == "float64" else np.float32))
        self.update_world_vertices()

    def _check_reach(self, poses: np.ndarray, source: str) -> None:
        """Raises ValueError for the first of host ``(N, 7)`` ``poses`` that places its object beyond what the
        scene's precision resolves at its triangles' size (the device's check, :mod:`warp_ccd._src.scene.inputs`)."""
        with np.errstate(over="ignore", invalid="ignore"):
            reach = np.abs(np.asarray(poses[:, :3], np.float64)).max(axis=1, initial=0.0) \
                + self.input_check.object_radius_np
        msg = self.input_check.far_row(reach, source)
        if msg is not None:
            raise ValueError(msg)

    def _device_poses(self, x, source: str, matrices: bool) -> None:
        """Enqueues the kernel that reads poses (or, with ``matrices``, ``(N, 4, 4)`` transforms too)
        from a device array into :attr:`object_pose`, checking them (:mod:`warp_ccd._src.scene.inputs`)."""
        view = device_view(x, source, self.device)
        n = self.num_objects
        out = self.object_pose.view(self.scalar_type)
        if view.shape == (n, 7):
            self.input_check.poses(view, out, source)
        elif matrices and view.shape == (n, 4, 4):
            self.input_check.matrices(view, out, source)
        else:
            shapes = f"({n}, 4, 4) or ({n}, 7)" if matrices else f"({n}, 7)"
            raise ValueError(f"{source}: expected shape {shapes}, got {view.shape}")

    def set_world_vertices(self, vertices: ArrayLike) -> None:
        """Writes world vertices of all objects, concatenated (deforming meshes; a rigid object's must
        be where its pose puts it, as :meth:`pose_world_vertices` computes).

        Args:
            vertices: ``(V, 3)`` float32 or float64, or ``(V,)`` ``wp.vec3`` / ``wp.vec3d``. An array
                on this scene's device (Warp, torch, JAX, CuPy) is read in place and checked by a
                kernel (no copy through the host; a vertex that is not finite is raised by the next
                ``detect()`` or :meth:`check_inputs`); a host array is checked here (shape,
                finiteness), then uploaded. A vertex with a coordinate beyond what the scene's precision
                resolves at its triangle size (:func:`~warp_ccd._src.geometry.precision.needed_precision`) is
                bad too.

        Raises:
            ValueError: a rigid scene, a bad shape, or (host arrays) the first vertex not finite or too far.
        """
        if not self.deforming:
            raise ValueError("set_world_vertices: this scene's objects are rigid, placed by their poses "
                             "(set_transforms, set_poses); build it with deforming=True to write world vertices")
        if is_device_array(vertices):
            view = device_view(vertices, "set_world_vertices", self.device)
            if view.shape != (self.num_world_vertices, 3):
                raise ValueError(f"set_world_vertices: expected shape ({self.num_world_vertices}, 3) "
                                 f"(or {self.num_world_vertices} {self.vec3_type.__name__}), got {view.shape}")
            self.input_check.vertices(view, self.world_vertex.view(self.scalar_type), "set_world_vertices")
            return
        v = np.asarray(vertices, dtype=np.float64)
        if v.shape != (self.num_world_vertices, 3):
            raise ValueError(f"set_world_vertices: expected shape ({self.num_world_vertices}, 3), got {v.shape}")
        if not np.isfinite(v).all():
            bad = int(np.argmin(np.isfinite(v).all(axis=1)))
            obj = int(np.searchsorted(self.object_vertex_start_np, bad, side="right") - 1)
            raise ValueError(f"set_world_vertices: vertex {bad} (object {obj}) is not finite")
        with np.errstate(over="ignore"):
            v = v.astype(np.float64 if self.precision == "float64" else np.float32)
        if not np.isfinite(v).all():
            raise ValueError("set_world_vertices: vertices overflow float32")
        msg = self.input_check.far_row(row_max(np.abs(v)) if len(v) else np.zeros(0), "set_world_vertices")
        if msg is not None:
            raise ValueError(msg)
        self.world_vertex.assign(v)

    def check_inputs(self) -> None:
        """Waits for the device and raises the fault of device-side inputs now (a pipeline's
        ``detect()`` raises it at the end of its frame, with no extra wait).

        Raises:
            ValueError: naming the setter, the row and the problem.
        """
        self.input_check.check()

    @property
    def object_world(self) -> np.ndarray:
        """``(N,)`` int64 world id of each object (zeros when the scene has no worlds)."""
        f = self.collision_filter
        return np.zeros(self.num_objects, np.int64) if f is None else f.object_world

    # ------------------------------------------------------------------ views
    @cached_property
    def shape_meshes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per shape ``(local vertices (n, 3), triangles (m, 3) int32)``: views of :attr:`shapes`
        (made on first use: one Python pair per shape, for export and inspection)."""
        return self.shapes.meshes()

    def world_vertex32(self) -> wp.array:
        """World vertices as float32 ``wp.vec3`` (for rendering and export): ``world_vertex`` itself
        in a float32 scene, a copy rounded to nearest (refreshed on each call) in a float64 one."""
        if self.precision == "float32":
            return self.world_vertex
        if getattr(self, "_world_vertex32", None) is None:
            self._world_vertex32 = wp.zeros(self.num_world_vertices, dtype=wp.vec3, device=self.device)
        if self.num_world_vertices:
            wp.launch(_vertex_to_float32_kernel, dim=self.num_world_vertices, inputs=[self.world_vertex],
                      outputs=[self._world_vertex32], device=self.device)
        return self._world_vertex32

    def world_meshes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per object ``(world vertices (n, 3) float32 or float64, triangles (m, 3) int32)``, on the host."""
        wv = self.world_vertex.numpy()
        out = []
        for i in range(self.num_objects):
            v = wv[self.object_vertex_start_np[i] : self.object_vertex_start_np[i + 1]]
            out.append((v, self.shape_meshes[self.object_shape_np[i]][1]))
        return out
