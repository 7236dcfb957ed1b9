"""USD import: the meshes of a stage as a :class:`~warp_ccd._src.scene.scene.Scene`, at each time code asked for.

:class:`UsdMeshImport` traverses the stage once and reads, per mesh, its topology and points, and
per object its world transform at every time code asked for:

* **Objects.** Every ``UsdGeom.Mesh`` under the chosen prims is one object, instance proxies of
  instanceable prims included; a ``UsdGeom.PointInstancer`` gives one object per (instance,
  mesh of its prototype), with the instance transform (the prototype root's own transform
  included, as USD computes it) and the instancer's mask at the first time code. Invisible prims
  (``visibility = invisible`` at the first time code) and prims of purpose ``guide`` or
  ``proxy`` are skipped with their subtrees unless asked for; so are meshes without faces.
* **Triangles.** Polygons are fanned (``n - 2`` triangles from a face of ``n`` vertices; faces in
  ``holeIndices`` are left out), wound so that their normals point out of the object: a
  ``leftHanded`` mesh, or one whose points a mirror was baked into, is wound the other way round
  (penetrating or touching is decided by the sides of surfaces, :mod:`~warp_ccd._src.check.crossing`);
  :attr:`UsdMeshImport.triangle_face` maps every triangle of the
  scene back to its USD face index. Faces of fewer than 3 vertices, indices outside the points,
  ``holeIndices`` that are not face indices, non-finite points and animated topology are errors
  naming the prim; so are a PointInstancer's negative or out-of-range ``protoIndices`` (naming
  the instance), prototypes outside its subtree, and zero or non-finite orientations.
* **Shapes** are stored once and shared by the objects that show them: instance proxies of one
  prototype, a PointInstancer's instances of one prototype, and meshes whose points and
  triangles are byte for byte the same.
* **Transforms.** A world transform ``M`` (USD's row-vector convention, ``p_world = p M``) whose
  linear part is a rotation times a uniform scale becomes a pose and ``object_scale``. One with
  a non-uniform scale, a shear or a reflection is baked into a shape of its own (the points times
  the linear part at the first time code), and the object moves rigidly from there while the
  rest of its transform stays a rotation and a uniform scale. A **mirror** (a negative scale, a
  negative determinant) is valid: the mesh is wound the other way round, and it is checked as the
  mirrored surface it is. A **zero scale** (a singular linear part, at any time code read) collapses
  the mesh onto a plane, a line or a point: a ValueError names the prim, the xform op and the time
  (:func:`~warp_ccd._src.usd.xforms.xform_fault`); so does a mirror that comes or goes during the
  animation (the winding chosen at the first time code would turn the surface inside out), an xform
  op whose value USD makes no transform of (a wrong type) and one that is not finite.
* **Attribute types.** ``points`` must hold 3-vectors (a flat ``float[]`` is refused), and
  ``faceVertexCounts``, ``faceVertexIndices`` and ``holeIndices`` integers: an error names the prim,
  the attribute and the time code (:mod:`~warp_ccd._src.usd.meshes`).
* **Precision.** Where float32 cannot resolve the coordinates of every time code read at the
  triangles' size (:func:`~warp_ccd._src.geometry.precision.needed_precision`: coordinates beyond about
  ``8.4e3`` times the typical triangle), the scene is float64 instead, with a
  :class:`~warp_ccd._src.geometry.precision.PrecisionWarning`; beyond what float64 resolves (``4.5e12`` times)
  or float32's range, a ValueError names the prim. Deforming points are read frame by frame and
  checked as they come (:meth:`UsdMeshImport.set_frame` raises).
* **Rigid or deforming.** An object is deforming when its points are time-sampled, or when its
  transform changes shape over time (an animated non-uniform scale): its world vertices are
  computed on the host each frame (``points(t) M(t)``) and copied to the device. Every other
  object is rigid: only its pose (and scale) changes, and the scene's kernel places its vertices.

Cost: the stage is traversed once, a few ``pxr`` calls a prim (its type's schemas asked once per type
name, purpose and visibility only where authored); meshes are read as raw arrays, a few calls each,
and validated, fanned and hashed together (:func:`~warp_ccd._src.usd.meshes.read_meshes`). The world
transforms of animated prims are read in bulk (:func:`~warp_ccd._src.usd.xforms.read_world_poses`): their
xform ops' time samples, each read with its attribute's dictionary, composed and split into poses in
numpy; only what the bulk read cannot reproduce takes one ``UsdGeom.XformCache`` lookup per prim and
time code (an order of magnitude costlier than a sample read in bulk). From :data:`PARALLEL_LOOKUPS`
prim-time codes on, worker processes (each opening the file) read shares of the prims while this
process reads one. Per time code, one ``ComputeInstanceTransformsAtTime`` per animated PointInstancer
and one ``points`` read per time-sampled mesh; static transforms and points are read once. The bulk
read made a check of 10,000 rigid prims over 240 time codes about nine times faster, most of what is
left being the transforms (the measurements: ``docs/site/architecture/usd.md``). Poses of every time
code are read and decomposed up front, which is where an animated transform that does not stay a
similarity is found. Objects are ordered static rigid, animated rigid, then deforming, so that a frame
copies two contiguous pose slices and one contiguous tail of world vertices.

:func:`scene_from_usd` is the short way to the scene of one time code. The stage is opened by
:mod:`~warp_ccd._src.usd.stage`, meshes are read and fanned by :mod:`~warp_ccd._src.usd.meshes`, world matrices
are read in bulk by :mod:`~warp_ccd._src.usd.xforms` and become poses in :mod:`~warp_ccd._src.usd.poses`, and the worker
processes are :mod:`~warp_ccd._src.usd.workers`.
"""

from __future__ import annotations

import fnmatch
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..geometry.precision import PrecisionWarning, coordinate_message, needed_precision, shape_radius, triangle_size
from ..runtime.aliases import DeviceLike, PathLike
from ..runtime.checks import integer_option
from ..runtime.options import check_option
from ..scene.scene import Scene
from ..scene.shapes import MeshSet
from .filters import FilterSummary, PairFilters, PrimIndex, world_ids
from .meshes import MeshData, read_meshes
from .poses import SINGULAR_DETERMINANT, baked_linear, finite_matrix_poses, matrix_poses
from .stage import MAX_FRAMES, open_stage
from .workers import auto_workers, read_shared
from .xforms import WorldPoses, XformInfo, paused_gc, world_transform, xform_fault

if TYPE_CHECKING:
    from pxr import Usd

__all__ = ["PARALLEL_LOOKUPS", "UsdMeshImport", "scene_from_usd"]

PARALLEL_LOOKUPS = 1_000_000
"""Prim-time codes (animated prims times time codes) from which a file's transforms are read by worker
processes too, each opening the file and reading a share of the prims (starting one and opening the file
costs about what reading several hundred thousand prim-time codes in bulk does: ``docs/site/architecture/usd.md``)."""


@dataclass
class _Instancer:
    """A PointInstancer: its kept instances and the meshes of its prototypes."""

    path: str
    schema: object
    instance_index: np.ndarray  # (I,) USD indices of the instances kept (mask at the first time code)
    proto_index: np.ndarray  # (I,) prototype of each kept instance
    slots: list = field(default_factory=list)  # (prototype, mesh data index, mesh prim, prototype root prim)
    varying: bool = False


ZERO_QUATERNION = 1e-6
"""A PointInstancer orientation whose norm is below this is zero: no rotation (an error)."""


def _check_orientations(rec: _Instancer, code) -> None:
    """Raises ValueError naming the instancer and the instance whose orientation at ``code`` is zero
    (norm below :data:`ZERO_QUATERNION`) or not finite, among the instances kept."""
    for attr in (rec.schema.GetOrientationsAttr(), rec.schema.GetOrientationsfAttr()):
        value = attr.Get(code) if attr.HasAuthoredValue() else None
        if value is None or len(value) == 0:
            continue
        q = np.asarray(value, np.float64).reshape(-1, 4)
        kept = rec.instance_index[rec.instance_index < len(q)]
        norm = np.linalg.norm(q[kept], axis=1)
        bad = ~np.isfinite(norm) | (norm < ZERO_QUATERNION)
        if bad.any():
            i = int(kept[np.argmax(bad)])
            what = "is not finite" if not np.isfinite(norm[np.argmax(bad)]) else "is zero"
            raise ValueError(f"prim {rec.path}: {attr.GetName()}[{i}] (instance {i}) {what} at time "
                             f"{code.GetValue():g} (a rotation needs a nonzero quaternion)")


class UsdMeshImport:
    """A stage's meshes, read once, as a :class:`~warp_ccd._src.scene.scene.Scene` that can be set to each time code.

    Example::

        imp = UsdMeshImport("anim.usd", times=stage_time_codes(open_stage("anim.usd")))
        pipe = CollisionPipeline(imp.scene)
        for k in range(len(imp.times)):
            imp.set_frame(k)
            res = pipe.detect()
            names = [imp.object_path[i] for i in res.object_pairs.ravel()]

    Args:
        stage_or_path: a ``Usd.Stage`` or the path of a USD file.
        prims: prim paths (``"/World/Robot"``) or ``fnmatch`` patterns (``"/World/*/Wheel*"``):
            meshes at or under a chosen prim are read. Default: the whole stage.
        times: time codes the scene will be set to (default: the stage's start time code, or 0).
        include_invisible: also read invisible prims.
        include_purposes: also read prims of these purposes (``"guide"``, ``"proxy"``).
        device: Warp device of the scene.
        precision: ``"float32"`` or ``"float64"`` (see :class:`~warp_ccd._src.scene.scene.Scene`); float32
            becomes float64 where the coordinates need it (see the module docstring).
        workers: processes that read the transforms of animated prims of a stage saved in a file, this
            one included (each other opens the file; every one reads a share of the prims). Default: the
            CPU count (at most 16) when there are at least :data:`PARALLEL_LOOKUPS` prim-time codes, else
            none; 0 or 1: none, everything is read in this process. A stage with unsaved edits is always
            read in this process.
        progress: show a progress bar on stderr while the transforms of every time code are read.
        worlds: prim paths or ``fnmatch`` patterns (``"/World/envs/*"``): every prim they match roots a
            world, and meshes at or under it belong to it (to its outermost matching ancestor); worlds are
            numbered in the order of their roots' paths, meshes under no root are world ``-1`` and pair
            with every world. Objects of two worlds never pair (the scene's ``world``). Default: one world.
        filters: the :class:`~warp_ccd._src.usd.filters.PairFilters` (excluded pairs, the stage's physics
            filters, sets A and B) turned into the scene's ``exclude_pairs``, ``group`` and ``mask``, or None.

    Attributes:
        stage: the ``Usd.Stage``.
        times: ``(F,)`` float64 time codes.
        scene: the :class:`~warp_ccd._src.scene.scene.Scene`, at ``times[0]`` until :meth:`set_frame`.
        frame: index of the time code the scene was last set to.
        object_path: ``N`` names: the mesh prim's path, or ``"<instancer>[<i>]<mesh path in the
            prototype>"`` for a PointInstancer's instance ``i``.
        object_prim: ``N`` mesh prim paths (the prototype's mesh for point instances).
        object_deforming: ``(N,)`` bool, world vertices set each frame.
        triangle_face: ``(T,)`` int32 USD face index of every shape triangle, indexed like
            ``scene.shape_triangle`` (shape start + local triangle).
        skipped: ``(path, reason)`` of the meshes left out (no faces, invisible, purpose).
        max_coordinate: the largest ``|coordinate|`` of any world vertex over the time codes
            (deforming points: at the first one), scene units.
        triangle_size: the typical triangle size (:func:`~warp_ccd._src.geometry.precision.triangle_size`).
        precision_note: why the scene is float64 though float32 was asked for, or None (also
            given as a :class:`~warp_ccd._src.geometry.precision.PrecisionWarning`).
        seconds: wall time of ``read`` (opening, traversal, topology, transforms at every time
            code) and ``build`` (the scene on its device, the first frame).
        object_world: ``(N,)`` int64 world of each object (``-1``: every world), or None without ``worlds``.
        filters: the :class:`~warp_ccd._src.usd.filters.FilterSummary` of ``worlds`` and ``filters`` (what
            they were and did).

    Raises:
        ValueError: naming the file or prim: a missing or unreadable file, a prim path that does
            not exist, patterns that match nothing (``worlds`` and sets: no checked mesh; unless
            ``filters.allow_missing``), a pair of ``filters`` naming no prim, a stage without meshes, a bad mesh or
            PointInstancer, more than :data:`~warp_ccd._src.usd.stage.MAX_FRAMES` time codes, or coordinates beyond
            float64
            at the triangles' size.
    """

    def __init__(self, stage_or_path: Usd.Stage | PathLike, *, prims: str | Sequence[str] | None = None,
                 times: Sequence[float] | np.ndarray | None = None, include_invisible: bool = False,
                 include_purposes: Sequence[str] = (), device: DeviceLike = None, precision: str = "float32",
                 workers: int | None = None, progress: bool = False, worlds: str | Sequence[str] | None = None,
                 filters: PairFilters | None = None) -> None:
        from pxr import Usd

        self._start = time.perf_counter()
        self.stage = open_stage(stage_or_path)
        if times is None:  # the start time code (even of a range whose end comes before it), else 0
            times = [self.stage.GetStartTimeCode() if self.stage.HasAuthoredTimeCodeRange() else 0.0]
        self.times = np.atleast_1d(np.asarray(times, np.float64))
        if self.times.ndim != 1 or self.times.size == 0 or not np.isfinite(self.times).all():
            raise ValueError(f"times: expected finite time codes, got {times!r}")
        if self.times.size > MAX_FRAMES:
            raise ValueError(f"times: {self.times.size} time codes, more than {MAX_FRAMES} at once")
        self._progress = bool(progress)
        self._codes = [Usd.TimeCode(float(t)) for t in self.times]
        purposes = {"default", "render"} | {check_option("include_purposes", p) for p in include_purposes}
        self.skipped: list[tuple[str, str]] = []
        self._meshes: list[MeshData] = []
        self._mesh_by_source: dict[str, int] = {}
        self._instancers: list[_Instancer] = []
        self._xinfo = XformInfo(self.stage)
        self._workers = workers
        self._prim_args = None if prims is None else ([prims] if isinstance(prims, str) else list(prims))
        self._worlds = worlds
        self._filters = filters
        with paused_gc():  # millions of pxr values alive while reading: collections would scan them over and over
            mesh_prims = self._traverse(prims, include_invisible, purposes)
            self._build(mesh_prims, device, precision)

    # ------------------------------------------------------------------ traversal
    def _roots(self, prims):
        """``(roots, patterns)``: the prims named by path, then the pseudo-root when there are
        patterns (whose subtree is filtered by them; the named prims' subtrees are not)."""
        stage = self.stage
        if prims is None:
            return [stage.GetPseudoRoot()], None
        if isinstance(prims, (str, bytes)) or not hasattr(prims, "__iter__"):
            prims = [prims]
        paths, patterns = [], []
        for p in prims:
            p = str(p)
            (patterns if any(c in p for c in "*?[") else paths).append(p)
        roots = []
        for p in paths:
            prim = stage.GetPrimAtPath(p) if p.startswith("/") else None
            if prim is None or not prim.IsValid():
                raise ValueError(f"prims: no prim at {p!r} in the stage")
            roots.append(prim)
        if patterns:
            roots.append(stage.GetPseudoRoot())
        return roots, patterns or None

    def _traverse(self, prims, include_invisible: bool, purposes: set) -> list:
        """Walks the chosen subtrees once; returns ``(mesh prim, path, authored property names)``,
        records the PointInstancers. A few ``pxr`` calls a prim: its type's schemas are asked once per
        type name, purpose and visibility only where authored."""
        from pxr import Usd, UsdGeom

        roots, patterns = self._roots(prims)
        named = len(roots) - (1 if patterns else 0)  # roots[named:] is the pseudo-root that patterns filter
        t0 = self._codes[0]
        predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
        found, seen = [], set()
        by_pattern = 0  # meshes and instancers that a pattern selects
        kinds: dict[str, tuple] = {}  # type name -> (Imageable, PointInstancer, Mesh)
        for r, root in enumerate(roots):
            filtering = patterns is not None and r >= named
            if root.IsA(UsdGeom.Imageable) and not root.IsPseudoRoot():
                img = UsdGeom.Imageable(root)
                if img.ComputePurpose() not in purposes or (
                        not include_invisible and img.ComputeVisibility(t0) == UsdGeom.Tokens.invisible):
                    raise ValueError(f"prims: {root.GetPath()} is invisible or of purpose {img.ComputePurpose()}")
            it = iter(Usd.PrimRange(root, predicate))
            chosen = None  # with patterns: the depth of the matched ancestor, while inside its subtree
            for prim in it:
                path = prim.GetPath()
                key = str(path)
                if filtering:
                    depth = path.pathElementCount
                    if chosen is not None and depth <= chosen:
                        chosen = None
                    if chosen is None and any(fnmatch.fnmatchcase(key, pat) for pat in patterns):
                        chosen = depth
                type_name = prim.GetTypeName()
                kind = kinds.get(type_name)
                if kind is None:
                    kind = kinds[type_name] = (prim.IsA(UsdGeom.Imageable), prim.IsA(UsdGeom.PointInstancer),
                                               prim.IsA(UsdGeom.Mesh), self._xinfo.xformable(type_name, prim))
                names = None
                if kind[0]:
                    names = prim.GetAuthoredPropertyNames()  # attributes it does not author are not asked for
                    self._xinfo.seed(key, names, kind[3])
                    attr = prim.GetAttribute("purpose") if "purpose" in names else None
                    purpose = attr.Get() if attr is not None and attr.HasAuthoredValue() else "default"
                    if purpose not in purposes:
                        self.skipped.append((key, f"purpose {purpose}"))
                        it.PruneChildren()
                        continue
                    if not include_invisible and "visibility" in names and \
                            prim.GetAttribute("visibility").Get(t0) == UsdGeom.Tokens.invisible:
                        self.skipped.append((key, "invisible"))
                        it.PruneChildren()
                        continue
                selected = not filtering or chosen is not None
                if filtering and selected and (kind[1] or kind[2]):
                    by_pattern += 1
                if kind[1]:
                    it.PruneChildren()  # prototypes are drawn through the instancer only
                    if selected and key not in seen:
                        seen.add(key)
                        self._add_instancer(prim)
                    continue
                if selected and kind[2] and key not in seen:
                    seen.add(key)
                    found.append((prim, key, names))
        if patterns and not by_pattern:
            raise ValueError(f"prims: no mesh matches {', '.join(patterns)}")
        return found

    def _mesh_data(self, prim) -> int:
        """Index of the mesh data of ``prim`` (read once per prim, or per prototype for instance proxies)."""
        return self._mesh_datas([(prim, str(prim.GetPath()), None)])[0]

    def _mesh_datas(self, prims: list) -> list[int]:
        """:meth:`_mesh_data` of ``(prim, path, authored property names or None)``, the new ones read together
        (:func:`~warp_ccd._src.usd.meshes.read_meshes`: the first at fault raises, in this order)."""
        out, new, pending = [], {}, []
        for prim, path, names in prims:
            source = prim.GetPrimInPrototype() if prim.IsInstanceProxy() else prim
            key = path if source is prim else str(source.GetPath())
            k = self._mesh_by_source.get(key)
            if k is None:
                k = new.get(key)
                if k is None:
                    k = new[key] = len(self._meshes) + len(new)
                    pending.append((source, path, names))
            out.append(k)
        if pending:
            self._meshes += read_meshes([p[0] for p in pending], [p[1] for p in pending], self._codes[0],
                                        [p[2] for p in pending] if all(p[2] is not None for p in pending) else None)
            self._mesh_by_source.update(new)
        return out

    def _add_instancer(self, prim) -> None:
        from pxr import Usd, UsdGeom

        name = str(prim.GetPath())
        inst = UsdGeom.PointInstancer(prim)
        t0 = self._codes[0]
        indices_attr = inst.GetProtoIndicesAttr()
        proto_idx = indices_attr.Get(t0)
        proto_idx = np.zeros(0, np.int64) if proto_idx is None else np.asarray(proto_idx, np.int64)
        if indices_attr.ValueMightBeTimeVarying():
            for code in self._codes[1:]:
                if not np.array_equal(np.asarray(indices_attr.Get(code), np.int64), proto_idx):
                    raise ValueError(f"prim {name}: protoIndices change at time {code.GetValue():g} (instances "
                                     "that change prototype or number are not supported)")
        targets = inst.GetPrototypesRel().GetForwardedTargets()
        if proto_idx.size and proto_idx.min() < 0:
            i = int(np.argmax(proto_idx < 0))
            raise ValueError(f"prim {name}: protoIndices has index {int(proto_idx[i])} at instance {i} "
                             "(prototype indices start at 0)")
        if proto_idx.size and proto_idx.max() >= len(targets):
            i = int(np.argmax(proto_idx >= len(targets)))
            raise ValueError(f"prim {name}: protoIndices refer to prototype {int(proto_idx[i])} at instance {i}, "
                             f"but it has {len(targets)} prototypes")
        outside = [t for t in targets if not t.HasPrefix(prim.GetPath()) or t == prim.GetPath()]
        if outside:
            raise ValueError(f"prim {name}: prototype {outside[0]} is not under the instancer "
                             "(USD requires a PointInstancer's prototypes beneath it)")
        mask = inst.ComputeMaskAtTime(t0)
        keep = np.arange(proto_idx.size) if not mask else np.nonzero(np.asarray(mask, bool))[0]
        record = _Instancer(name, inst, keep, proto_idx[keep])
        predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
        for proto, target in enumerate(targets):
            root = self.stage.GetPrimAtPath(target)
            if not root.IsValid():
                raise ValueError(f"prim {name}: prototype {target} does not exist")
            for p in Usd.PrimRange(root, predicate):
                if p.IsA(UsdGeom.Mesh):
                    record.slots.append((proto, self._mesh_data(p), p, root))
                    record.varying |= self._world_varies(p, stop=root.GetParent())
        record.varying |= self._world_varies(prim) or any(
            prim.GetAttribute(a).ValueMightBeTimeVarying()
            for a in ("positions", "orientations", "orientationsf", "scales", "velocities", "angularVelocities",
                      "accelerations"))
        self._instancers.append(record)

    def _world_varies(self, prim, stop=None) -> bool:
        """Whether ``prim``'s transform (relative to ``stop``, or the world) may change over time."""
        return self._xinfo.varies(prim, stop)

    # ------------------------------------------------------------------ objects and transforms
    def _build(self, mesh_prims: list, device, precision: str) -> None:
        # Objects in traversal order: mesh prims, then each instancer's instances, prototype mesh by mesh.
        obj_mesh, obj_path, obj_prim, obj_varying, obj_instancer, obj_instance, obj_handle = [], [], [], [], [], [], []
        self._prims, self._prim_paths = [], []
        for (prim, path, _), k in zip(mesh_prims, self._mesh_datas(mesh_prims)):
            if len(self._meshes[k].triangles) == 0:
                self.skipped.append((path, "no faces"))
                continue
            obj_mesh.append([k])
            obj_path.append([path])
            obj_prim.append([path])
            obj_varying.append([self._xinfo.varies(prim, key=path)])
            obj_instancer.append([-1])
            obj_instance.append([-1])
            obj_handle.append([len(self._prims)])
            self._prims.append(prim)
            self._prim_paths.append(path)
        for j, rec in enumerate(self._instancers):
            for slot, (proto, k, p, root) in enumerate(rec.slots):
                if len(self._meshes[k].triangles) == 0:
                    self.skipped.append((str(p.GetPath()), "no faces"))
                    continue
                which = rec.instance_index[rec.proto_index == proto]
                suffix = str(p.GetPath())[len(str(root.GetParent().GetPath()).rstrip("/")):]
                obj_mesh.append(np.full(which.size, k))
                obj_path.append([f"{rec.path}[{i}]{suffix}" for i in which.tolist()])
                obj_prim.append([str(p.GetPath())] * which.size)
                obj_varying.append(np.full(which.size, rec.varying))
                obj_instancer.append(np.full(which.size, j))
                obj_instance.append(which)
                obj_handle.append(np.full(which.size, slot))
        obj_path = [x for part in obj_path for x in part]
        obj_prim = [x for part in obj_prim for x in part]
        n = len(obj_path)
        if n == 0:
            layer = self.stage.GetRootLayer()
            where = f" under {', '.join(map(str, self._prim_args))}" if self._prim_args else ""
            raise ValueError(f"{layer.realPath or layer.identifier}: no meshes with faces{where}")

        def flat(parts, dtype):
            return np.concatenate([np.asarray(x, dtype) for x in parts])

        obj_mesh = flat(obj_mesh, np.int64)
        obj_varying = flat(obj_varying, bool)
        self._obj_instancer = flat(obj_instancer, np.int64)
        self._obj_instance = flat(obj_instance, np.int64)
        self._obj_handle = flat(obj_handle, np.int64)

        # World matrices at every time code: static objects once; animated prims in bulk (read_world_poses,
        # here or in worker processes); a PointInstancer's instances at each time code.
        varying = np.nonzero(obj_varying)[0]
        by_prim = self._obj_instancer[varying] < 0
        read_v, rest = varying[by_prim], varying[~by_prim]
        others = np.setdiff1d(np.arange(n), read_v)
        first = np.empty((n, 4, 4))
        first[others] = self._matrices(self._codes[0], others)
        read = self._world_poses(read_v)
        first[read_v] = read.first
        finite = np.isfinite(first).all(axis=(1, 2))
        if not finite.all():
            self._not_finite(obj_path, int(np.argmin(finite)), float(self.times[0]))
        if not read.finite.all():
            f, k = np.unravel_index(int(np.argmin(read.finite)), read.finite.shape)
            self._not_finite(obj_path, int(read_v[k]), float(self.times[f]))
        self._check_linear(obj_path, np.arange(n), first, float(self.times[0]))
        bake, similar0 = baked_linear(first)  # baked at the first time code
        deforming = np.array([self._meshes[k].deforming for k in obj_mesh.tolist()], bool)
        poses0, scale0, ok0 = matrix_poses(first, bake)
        deforming |= ~ok0
        if rest.size:  # float64 poses until the precision is known
            var_poses = np.empty((len(self._codes), varying.size, 7))
            var_scale = np.empty((len(self._codes), varying.size), np.float32)
            var_ok = np.ones(varying.size, bool)
            var_poses[:, by_prim], var_scale[:, by_prim], var_ok[by_prim] = read.poses, read.scale, read.ok
        else:  # every animated object read in bulk: its arrays as they are
            var_poses, var_scale, var_ok = read.poses, read.scale.astype(np.float32), read.ok.copy()
        for f, code in enumerate(self._codes if rest.size else ()):
            finite, var_poses[f, ~by_prim], var_scale[f, ~by_prim], ok = finite_matrix_poses(
                first[rest] if f == 0 else self._matrices(code, rest), bake[rest])
            if not finite.all():
                self._not_finite(obj_path, int(rest[np.argmin(finite)]), float(code.GetValue()))
            var_ok[~by_prim] &= ok
        deforming[varying[~var_ok]] = True

        # Order: static rigid, animated rigid, deforming.
        is_var = np.zeros(n, bool)
        is_var[varying] = True
        group = np.where(deforming, 2, np.where(is_var, 1, 0))
        order = np.argsort(group, kind="stable")
        self._num_static = int((group == 0).sum())
        self._num_rigid = self._num_static + int((group == 1).sum())
        var_pos = np.full(n, -1, np.int64)
        var_pos[varying] = np.arange(varying.size)
        anim = var_pos[order[self._num_static:self._num_rigid]]
        same = anim.size == varying.size and np.array_equal(anim, np.arange(anim.size))  # no copy needed
        self._anim_poses = var_poses if same else var_poses[:, anim]
        self._anim_scale = var_scale if same else var_scale[:, anim]
        self._scale_varies = bool(anim.size and np.ptp(self._anim_scale, axis=0).max() > 0)
        del var_poses, var_scale
        defo = order[self._num_rigid:]
        self._def_mesh = obj_mesh[defo]
        self._def_matrix = first[defo]  # world matrices of the deforming objects, re-read where they vary
        self._def_varying = np.nonzero(is_var[defo])[0]
        self._def_varying_objects = defo[self._def_varying]

        self.object_path = [obj_path[i] for i in order]
        self.object_prim = [obj_prim[i] for i in order]
        self.object_deforming = deforming[order]
        self.object_instancer = [self._instancers[j].path if j >= 0 else None for j in self._obj_instancer[order]]
        self.object_instance = self._obj_instance[order]
        self._object_instancer_id = self._obj_instancer[order]

        # Shapes: rigid objects share one per (mesh content, baked linear part); each deforming object has its own.
        canonical: dict[bytes, int] = {}
        same = np.array([canonical.setdefault(m.key, k) for k, m in enumerate(self._meshes)], np.int64)
        o_mesh = obj_mesh[order]
        o_def = deforming[order]
        o_baked = ~similar0[order] & ~o_def
        key = np.zeros((n, 11))
        key[:, 0] = np.where(o_def, np.arange(n), -1)
        key[:, 1] = same[o_mesh]
        key[:, 2:] = np.where(o_baked[:, None], bake[order].reshape(n, 9), 0.0)
        _, first_use, shape_of = np.unique(key, axis=0, return_index=True, return_inverse=True)
        by_use = np.argsort(first_use)  # shapes numbered in order of first use
        rank = np.empty_like(by_use)
        rank[by_use] = np.arange(by_use.size)
        shape_of = rank[shape_of.reshape(-1)]
        shape_vertices, shape_triangles, shape_faces = [], [], []
        for pos in first_use[by_use].tolist():
            i = int(order[pos])
            data = self._meshes[int(obj_mesh[i])]
            linear = first[i, :3, :3] if o_def[pos] else bake[i] if o_baked[pos] else np.eye(3)
            if o_def[pos]:
                verts = data.points @ linear + first[i, 3, :3]  # world, at the first time code
            else:
                verts = data.points @ linear if o_baked[pos] else data.points
            shape_vertices.append(verts)
            # A mirror baked into the points turns the winding round: wound back, the normals still
            # point out of the object.
            mirrored = np.linalg.det(linear) < 0
            shape_triangles.append(np.ascontiguousarray(data.triangles[:, ::-1]) if mirrored else data.triangles)
            shape_faces.append(data.triangle_face)
        vcount = np.array([len(v) for v in shape_vertices], np.int64)
        tcount = np.array([len(t) for t in shape_triangles], np.int64)
        packed = MeshSet(np.concatenate(shape_vertices), np.concatenate(shape_triangles).astype(np.int32),
                         np.concatenate([[0], np.cumsum(vcount)]), np.concatenate([[0], np.cumsum(tcount)]))
        self.triangle_face = np.concatenate(shape_faces).astype(np.int32)

        poses = poses0[order].copy()
        scale = scale0[order].copy()
        defo_slice = slice(self._num_rigid, n)
        poses[defo_slice] = np.array([0, 0, 0, 0, 0, 0, 1.0])
        scale[defo_slice] = 1.0
        precision = self._choose_precision(packed, shape_of, poses, scale, precision)
        fdtype = np.float64 if precision == "float64" else np.float32
        packed.vertices = packed.vertices.astype(fdtype)
        self._anim_poses = self._anim_poses.astype(fdtype, copy=False)
        filter_args = self._filter_arguments()
        self.seconds = {"read": time.perf_counter() - self._start}
        start = time.perf_counter()
        self.scene = Scene(packed, shape_of, object_scale=scale, poses=poses,
                           deforming=np.arange(n) >= self._num_rigid, device=device, precision=precision,
                           **filter_args)
        self.scene.usd = self
        self.set_frame(0)
        self.seconds["build"] = time.perf_counter() - start

    def _filter_arguments(self) -> dict:
        """The scene's ``world``, ``exclude_pairs``, ``group`` and ``mask`` from ``worlds`` and ``filters``
        (:mod:`~warp_ccd._src.usd.filters`); sets :attr:`object_world` and :attr:`filters`."""
        summary = FilterSummary()
        self.object_world = None
        allow = self._filters is not None and self._filters.allow_missing
        index = PrimIndex(self.object_prim) if self._worlds is not None or self._filters is not None else None
        if self._worlds is not None:
            self.object_world, summary = world_ids(self.stage, index, self._worlds, allow, summary)
        args = {"world": self.object_world}
        if self._filters is not None:
            instances = None
            if self._instancers:
                instances = (self._object_instancer_id, [rec.path for rec in self._instancers], self.object_instance)
            more, summary = self._filters.resolve(self.stage, index, summary, instances)
            args.update(more)
        self.filters = summary
        return args

    def _choose_precision(self, packed: MeshSet, shape_of: np.ndarray, poses: np.ndarray, scale: np.ndarray,
                          precision: str) -> str:
        """The scene's precision: ``precision``, or float64 (with a
        :class:`~warp_ccd._src.geometry.precision.PrecisionWarning`) where float32 does not resolve the
        coordinates of every time code read at the triangles' size
        (:func:`~warp_ccd._src.geometry.precision.needed_precision`); sets :attr:`max_coordinate`,
        :attr:`triangle_size` and :attr:`precision_note`.

        Args:
            packed: the shapes, float64 (deforming objects' in world space at the first time code).
            shape_of: ``(N,)`` shape of each object (in object order).
            poses, scale: ``(N, 7)`` and ``(N,)`` first poses and scales (identity for deforming objects).
            precision: the precision asked for.

        Raises:
            ValueError: naming the prim with the largest coordinate, when even float64 does not
                resolve them, or they exceed float32's range.
        """
        radius = shape_radius(packed.vertices, packed.vertex_start)[shape_of]
        reach = np.abs(poses[:, :3]).max(axis=1) + scale * radius  # static rigid (deforming: radius alone)
        a, b = self._num_static, self._num_rigid
        if b > a:  # animated rigid: over every time code
            reach[a:b] = np.abs(self._anim_poses[:, :, :3]).max(axis=(0, 2)) \
                + self._anim_scale.max(axis=0) * radius[a:b]
        if b < len(reach):  # deforming: the world points themselves
            far = np.zeros(len(packed))
            owner = np.repeat(np.arange(len(packed)), np.diff(packed.vertex_start))
            np.maximum.at(far, owner, np.abs(packed.vertices).max(axis=1))
            reach[b:] = far[shape_of[b:]]
        worst = int(np.argmax(reach))
        self.max_coordinate = float(reach[worst])
        self.triangle_size = triangle_size(packed.vertices, packed.triangles, packed.vertex_start,
                                           packed.triangle_start, shape_of, scale)
        self.precision_note = None
        needed = needed_precision(self.max_coordinate, self.triangle_size)
        if needed is None:
            raise ValueError(f"prim {self.object_path[worst]}: "
                             f"{coordinate_message(self.max_coordinate, self.triangle_size, 'float64')}")
        if needed == "float64" and precision == "float32":
            self.precision_note = (f"prim {self.object_path[worst]}: "
                                   f"{coordinate_message(self.max_coordinate, self.triangle_size, 'float32')}: "
                                   "checking in float64")
            warnings.warn(self.precision_note, PrecisionWarning, stacklevel=4)
            return "float64"
        return precision

    def _world_poses(self, objects: np.ndarray) -> WorldPoses:
        """The :class:`~warp_ccd._src.usd.xforms.WorldPoses` of prim ``objects`` (indices in traversal order)
        at every time code: read in this process, or by worker processes that each open the file and
        read a share of the prims (see ``workers``)."""
        handles = self._obj_handle[objects].tolist()
        prims = [self._prims[h] for h in handles]
        paths = [self._prim_paths[h] for h in handles]
        workers = self._workers
        if workers is None:
            workers = auto_workers() if objects.size * len(self._codes) >= PARALLEL_LOOKUPS else 0
        return read_shared(self.stage, prims, paths, self.times, workers, info=self._xinfo, progress=self._progress)

    def _check_linear(self, names: list, objects: np.ndarray, matrix: np.ndarray, time: float,
                      first: np.ndarray | None = None) -> None:
        """Raises ValueError naming the prim (and the xform op, :func:`~warp_ccd._src.usd.xforms.xform_fault`)
        where a world matrix ``matrix[k]`` of object ``objects[k]`` (traversal order; ``names[k]`` its
        path) at ``time`` has a zero scale (a singular linear part: the mesh collapses onto a plane, a
        line or a point), or, given the ``first`` matrices, where it mirrors and the first one did not
        or the other way round (the winding chosen at the first time code would be wrong: the inside and
        outside of the surface swap). A mirror that holds at every time code is valid: the mesh is wound
        the other way round (the module docstring)."""
        det = np.linalg.det(np.asarray(matrix, np.float64)[:, :3, :3])
        zero = ~(np.abs(det) > SINGULAR_DETERMINANT) & np.isfinite(det)
        if zero.any():
            k = int(np.argmax(zero))
            obj = int(objects[k])
            fault = None
            if self._obj_instancer[obj] < 0:
                fault = xform_fault(self._prims[int(self._obj_handle[obj])], time, singular=True)
            raise ValueError(fault or f"prim {names[k]}: its world transform at time {time:g} has a zero scale: "
                             "it collapses the mesh")
        if first is not None:
            flips = (det < 0) != (np.linalg.det(np.asarray(first, np.float64)[:, :3, :3]) < 0)
            if flips.any():
                k = int(np.argmax(flips))
                raise ValueError(f"prim {names[k]}: its world transform at time {time:g} "
                                 f"{'mirrors' if det[k] < 0 else 'no longer mirrors'} where the first time code's "
                                 "did not: a mirror that comes or goes in an animation turns the surface inside out "
                                 "(not supported)")

    def _not_finite(self, obj_path: list, obj: int, time: float) -> None:
        """Raises the ValueError for object ``obj``'s world transform that is not finite at ``time``,
        naming the xform op at fault where one is (:func:`~warp_ccd._src.usd.xforms.xform_fault`)."""
        h = int(self._obj_handle[obj])
        rec = self._obj_instancer[obj]
        fault = xform_fault(self._prims[h], time) if rec < 0 else None
        raise ValueError(fault or f"prim {obj_path[obj]}: its world transform is not finite at time {time:g}")

    def _matrices(self, code, objects: np.ndarray) -> np.ndarray:
        """``(K, 4, 4)`` world matrices (row vectors) of ``objects`` (indices in traversal order) at ``code``."""
        from pxr import UsdGeom

        out = np.empty((objects.size, 4, 4))
        cache = UsdGeom.XformCache(code)
        which = self._obj_instancer[objects]
        rows = np.nonzero(which < 0)[0]
        if rows.size:
            prims = self._prims
            t = float(code.GetValue())
            out[rows] = np.array([world_transform(cache, prims[h], t)
                                  for h in self._obj_handle[objects[rows]].tolist()], np.float64).reshape(-1, 4, 4)
        for j in np.unique(which[which >= 0]).tolist():
            rec = self._instancers[j]
            rows = np.nonzero(which == j)[0]
            _check_orientations(rec, code)
            xforms = rec.schema.ComputeInstanceTransformsAtTime(
                code, code, UsdGeom.PointInstancer.IncludeProtoXform, UsdGeom.PointInstancer.IgnoreMask)
            xforms = np.asarray(xforms, np.float64).reshape(-1, 4, 4)
            if xforms.shape[0] <= int(rec.instance_index.max(initial=-1)):
                raise ValueError(f"prim {rec.path}: {xforms.shape[0]} instance transforms at time "
                                 f"{code.GetValue():g}, fewer than its instances")
            world = world_transform(cache, rec.schema.GetPrim(), float(code.GetValue()))
            # Each prototype mesh's transform relative to its prototype root (whose own transform
            # the instance transforms include), once per mesh.
            rel = np.array([cache.ComputeRelativeTransform(p, root)[0] for _, _, p, root in rec.slots],
                           np.float64).reshape(-1, 4, 4)
            out[rows] = rel[self._obj_handle[objects[rows]]] @ xforms[self._obj_instance[objects[rows]]] @ world
        return out

    # ------------------------------------------------------------------ frames
    def set_frame(self, frame: int) -> None:
        """Moves the scene to ``times[frame]``: poses and scales of animated rigid objects, world
        vertices of every object (a kernel), and the deforming objects' vertices from the host.

        Raises:
            ValueError: a bad frame index, or a deforming mesh whose points change in number, are
                not finite, or reach beyond what the scene's precision resolves at that time
                (naming the prim).
        """
        integer_option("set_frame: frame", frame, low=0, high=len(self.times) - 1)
        scene = self.scene
        a, b = self._num_static, self._num_rigid
        if b > a:
            dtype = np.float64 if scene.precision == "float64" else np.float32
            scene.object_pose[a:b].assign(self._anim_poses[frame].astype(dtype))
            if self._scale_varies:
                scene.object_scale[a:b].assign(self._anim_scale[frame].astype(np.float32))
                scene.object_scale_np[a:b] = self._anim_scale[frame]
        scene.pose_world_vertices()
        if b < scene.num_objects:
            code = self._codes[frame]
            matrix = self._def_matrix
            if self._def_varying.size:
                matrix = matrix.copy()
                matrix[self._def_varying] = self._matrices(code, self._def_varying_objects)
                self._check_linear([self.object_path[b + d] for d in self._def_varying.tolist()],
                                   self._def_varying_objects, matrix[self._def_varying], float(self.times[frame]),
                                   self._def_matrix[self._def_varying])
            read: dict[int, np.ndarray] = {}
            parts = []
            for d, k in enumerate(self._def_mesh.tolist()):
                p = read.get(k)
                if p is None:
                    p = read[k] = self._meshes[k].points_at(code)
                parts.append(p @ matrix[d, :3, :3] + matrix[d, 3, :3])
            world = np.concatenate(parts)
            start = int(scene.object_vertex_start_np[b])
            self._check_deforming_reach(world, start, frame)
            scene.world_vertex[start:].assign(world.astype(np.float64 if scene.precision == "float64" else np.float32))
        self.frame = int(frame)

    def _check_deforming_reach(self, world: np.ndarray, start: int, frame: int) -> None:
        """Raises ValueError naming the prim when the deforming objects' world points ``world``
        (``(V, 3)`` float64, from world vertex ``start`` on) at ``times[frame]`` reach beyond what
        the scene's precision resolves at the triangles' size (read frame by frame, they were not
        known up front)."""
        reach = max(float(world.max(initial=0.0)), -float(world.min(initial=0.0)))
        if reach <= self.max_coordinate:
            return
        precision = self.scene.precision
        needed = needed_precision(reach, self.triangle_size)
        if needed == "float32" or (needed == "float64" and precision == "float64"):
            return
        v = int(np.argmax(np.abs(world).max(axis=1))) + start
        i = int(np.searchsorted(self.scene.object_vertex_start_np, v, side="right") - 1)
        hint = ": check it in float64 (precision='float64', --precision float64)" if needed else ""
        raise ValueError(f"prim {self.object_path[i]} at time {self.times[frame]:g}: "
                         f"{coordinate_message(reach, self.triangle_size, precision if needed else 'float64')}{hint}")

    def faces(self, objects: np.ndarray, triangles: np.ndarray) -> np.ndarray:
        """USD face indices of local triangles ``triangles`` of objects ``objects`` (same shapes, int32)."""
        s = self.scene.object_shape_np[objects]
        return self.triangle_face[self.scene.shape_triangle_start_np[s] + triangles]


def scene_from_usd(stage_or_path: Usd.Stage | PathLike, *, prims: str | Sequence[str] | None = None,
                   time: float | None = None, device: DeviceLike = None, precision: str = "float32",
                   **options: Any) -> Scene:
    """A scene of the meshes of a USD stage, at one time code (see :class:`UsdMeshImport`).

    Every ``UsdGeom.Mesh`` under ``prims`` (instance proxies and PointInstancer instances
    included; invisible, guide and proxy prims left out) is one object, polygons fanned into
    triangles, placed by its world transform. ``scene.usd`` holds the import: object names
    (``scene.usd.object_path``), the USD face of every triangle (``scene.usd.faces``), and
    ``scene.usd.set_frame(k)`` for the other time codes of ``options["times"]``.

    Args:
        stage_or_path: a ``Usd.Stage`` or a USD file path.
        prims: prim paths or ``fnmatch`` patterns (default: the whole stage).
        time: the time code (default: the stage's start time code, or 0 without a time range);
            or pass ``times=[...]`` to prepare several and move with ``scene.usd.set_frame``.
        device: Warp device.
        precision: ``"float32"`` or ``"float64"``.
        **options: ``times``, ``include_invisible``, ``include_purposes``, ``workers``, ``progress``,
            ``worlds`` (prim patterns, each match rooting a world whose meshes never pair with another
            world's) and ``filters`` of :class:`UsdMeshImport`.

    Returns:
        The :class:`~warp_ccd._src.scene.scene.Scene`, with the import as ``scene.usd``.

    Raises:
        ValueError: naming the file or the prim at fault (see :class:`UsdMeshImport`); ``time``
            and ``times`` both given.
    """
    if time is not None:
        if "times" in options:
            raise ValueError("scene_from_usd: give time or times, not both")
        options["times"] = [time]
    return UsdMeshImport(stage_or_path, prims=prims, device=device, precision=precision, **options).scene
