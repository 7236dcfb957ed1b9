"""A drop-in for ``trimesh.collision.CollisionManager`` on the library's scenes, pipelines and queries.

:class:`CollisionManager` has trimesh's methods, arguments and return values (name sets and tuples in the
same order, :class:`ContactData` and :class:`DistanceData`, the same ValueErrors for unknown names and
transforms that are not 4x4), and never imports python-fcl. A mesh is anything with ``vertices`` (n, 3)
and ``faces`` (m, 3) (a ``trimesh.Trimesh``); trimesh itself is never imported here.

How the calls map onto the library:

* The manager's objects make one :class:`~warp_ccd._src.scene.scene.Scene` with a
  :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline`, built on first use after objects were added or
  removed, never by :meth:`CollisionManager.set_transform`, which only changes the object's pose (uploaded with
  the others at the next query). Objects whose meshes have equal vertices and faces share one shape (its
  trees built once).
* ``in_collision_single`` and ``in_collision_other`` put the query mesh, or the other manager's objects, in
  one scene with this manager's, in two collision groups that pair only with each other (the scene's
  ``group`` and ``mask``): the pipeline's broad phase never sees a pair of one side. That scene is kept,
  by the set of objects on both sides (a few such scenes at once), so a call that only moved objects
  uploads poses and detects; a query mesh never seen (equal vertices and faces count as seen) builds one.
* ``return_data``: the pipeline's contacts (``contacts=True``), one :class:`ContactData` each: its point midway
  between the contact's points on the two surfaces, its normal turned to python-fcl's way (from the first name to
  the second), its depth, and each object's triangle.
* ``min_distance_*``: a :class:`~warp_ccd._src.queries.distance.DistanceQuery` on the same scene measures
  object pairs in increasing order of a lower bound (their boxes' gap; for boxes that overlap, minus the
  deepest a point of their overlap can lie in either box), in batches, until the least distance measured
  is below the next pair's bound. Pairs of the internal query are found by the broad phase on boxes grown by
  half an upper bound (the distance of two objects' first vertices, neighbours along the widest axis),
  not among all ``N^2``.

Where it differs from trimesh's FCL-based manager:

* Transforms must be rigid (rotation and translation): a scale, shear or reflection raises ValueError
  naming the object (FCL takes the matrix apart and drops what is not a rotation).
  :func:`scene_to_collision` bakes such a node transform into the mesh's vertices instead.
* Depth and signed distance are the library's (the deepest point of either surface inside the other's
  closed solid): two coincident surfaces have depth 0 where FCL's EPA on convex meshes gives the
  distance to push one out.
* A mesh wholly inside a closed mesh collides with it, whatever their shapes (FCL: only when both are
  convex); surfaces that touch within the library's relative tolerance collide.
* Ties of the least distance go to the pair first in name order (FCL: the first pair its tree visits).
* Contacts are the library's (:mod:`~warp_ccd._src.narrowphase.contacts`): at most ``max_per_pair`` a pair, the
  deepest first, then points spanning the region where the surfaces meet (at depth 0 where they cross); FCL gives
  one contact per crossing triangle pair of non-convex meshes and one (EPA's) for two convex ones.
"""

from __future__ import annotations

import hashlib
import itertools
import math
import sys
import weakref
from collections import OrderedDict
from collections.abc import Callable, Sequence
from functools import cached_property
from typing import Any

import numpy as np
import warp as wp

from ..broadphase.sap import broad_phase_pairs
from ..pipeline.pipeline import CollisionPipeline
from ..queries.distance import DistanceQuery
from ..runtime.aliases import ArrayLike, DeviceLike
from ..runtime.options import check_option
from ..runtime.start import init_warp
from ..scene.scene import Scene, quat_to_matrix, transforms_to_poses
from ..scene.shapes import validate_mesh

__all__ = ["CollisionManager", "CollisionObject", "ContactData", "DistanceData", "scene_to_collision"]

EXTERNAL = "__external"
"""The name a query mesh has in the names of its :class:`ContactData` and :class:`DistanceData` (trimesh's)."""

NO_DISTANCE = sys.float_info.max
"""The least distance reported where there is no pair to measure (FCL's, the largest float)."""

RIGID_TOLERANCE = 1e-4
"""How far from orthonormal a transform's rotation may be (the library's, :func:`transforms_to_poses`)."""

WORLDS_KEPT = 4
"""Scenes a manager keeps at once: its own objects', and those joined with query meshes or other managers."""

FIRST_BATCH = 16
"""Pairs measured in the first batch of a least-distance search (each next batch twice the last)."""

_SERIAL = itertools.count()

CollisionAnswer = bool | tuple[bool, set] | tuple[bool, list] | tuple[bool, set, list]
"""What the ``in_collision_*`` calls return: ``is_collision``, then the names and the :class:`ContactData` list where
asked for (trimesh's)."""

DistanceAnswer = float | tuple[float, Any] | tuple[float, Any, Any]
"""What the ``min_distance_*`` calls return: the distance, then the names and the :class:`DistanceData` where asked
for (trimesh's)."""


class ContactData:
    """One contact of two objects (trimesh's ``ContactData``, python-fcl's contact).

    Args:
        names: the two objects' names, in order: the normal points from the first to the second.
        point: ``(3,)`` the contact point, midway between the deepest points of the two surfaces.
        normal: ``(3,)`` unit normal from ``names[0]`` to ``names[1]``: the second object moves along it to
            separate (python-fcl's convention).
        depth: penetration depth along the normal (>= 0).
        triangles: the triangle of each object in contact, in the order of ``names``.

    Attributes:
        names: the set of the two names.
    """

    def __init__(self, names: Sequence, point: ArrayLike, normal: ArrayLike, depth: float,
                 triangles: Sequence[int]) -> None:
        self.names = set(names)
        self._inds = {names[0]: int(triangles[0]), names[1]: int(triangles[1])}
        self._point = np.asarray(point, np.float64)
        self._normal = np.asarray(normal, np.float64)
        self._depth = float(depth)

    @property
    def normal(self) -> np.ndarray:
        """``(3,)`` float64 unit normal, from the first object to the second."""
        return self._normal

    @property
    def point(self) -> np.ndarray:
        """``(3,)`` float64 contact point."""
        return self._point

    @property
    def depth(self) -> float:
        """Penetration depth of the contact (>= 0)."""
        return self._depth

    def index(self, name: Any) -> int:
        """The triangle (face index) of the object called ``name`` in contact."""
        return self._inds[name]

    def __repr__(self) -> str:
        return f"ContactData(names={self.names}, point={self._point.tolist()}, depth={self._depth:.6g})"


class DistanceData:
    """The least distance of two objects (trimesh's ``DistanceData``).

    Args:
        names: the two objects' names, in order.
        distance: their least distance; negative where they intersect (minus the pair's depth, where the
            library measures it).
        points: ``(2, 3)`` the closest point of each, in the order of ``names``.
        triangles: the closest triangle of each, in the order of ``names``.

    Attributes:
        names: the set of the two names.
    """

    def __init__(self, names: Sequence, distance: float, points: ArrayLike, triangles: Sequence[int]) -> None:
        points = np.asarray(points, np.float64).reshape(2, 3)
        self.names = set(names)
        self._inds = {names[0]: int(triangles[0]), names[1]: int(triangles[1])}
        self._points = {names[0]: points[0], names[1]: points[1]}
        self._distance = float(distance)

    @property
    def distance(self) -> float:
        """The least distance of the two objects."""
        return self._distance

    def index(self, name: Any) -> int:
        """The closest triangle (face index) of the object called ``name``."""
        return self._inds[name]

    def point(self, name: Any) -> np.ndarray:
        """``(3,)`` float64 closest point on the object called ``name``."""
        return self._points[name]

    def __repr__(self) -> str:
        return f"DistanceData(names={self.names}, distance={self._distance:.6g})"


class _Shape:
    """A mesh as managers keep it: float64 vertices and int32 faces (read-only copies, checked), its box, and
    whether it is closed. Equal meshes are one :class:`_Shape` (:func:`_shape_of`)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        self.vertices = vertices
        self.faces = faces
        self.lower = vertices.min(axis=0)
        self.upper = vertices.max(axis=0)
        self.first = vertices[0]
        for a in (vertices, faces):
            a.flags.writeable = False

    @cached_property
    def closed(self) -> bool:
        """Every edge is shared by exactly two faces (the mesh bounds a solid)."""
        f = self.faces.astype(np.int64)
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        _, count = np.unique(edges[:, 0] * (int(f.max()) + 1) + edges[:, 1], return_counts=True)
        return bool((count == 2).all())


_SHAPES: weakref.WeakValueDictionary = weakref.WeakValueDictionary()
"""Every live :class:`_Shape` by the digest of its arrays: equal meshes share one, across managers."""


def _shape_of(mesh: Any, what: str) -> _Shape:
    """The :class:`_Shape` of ``mesh`` (its ``vertices`` and ``faces``), shared with every equal mesh.

    Raises:
        TypeError: ``mesh`` has no ``vertices`` or ``faces``.
        ValueError: a bad mesh (:func:`~warp_ccd._src.scene.shapes.validate_mesh`'s message, naming ``what``).
    """
    try:
        vertices, faces = mesh.vertices, mesh.faces
    except AttributeError:
        raise TypeError(f"{what}: expected a mesh with vertices and faces (a trimesh.Trimesh), "
                        f"got {type(mesh).__name__}") from None
    v, f = validate_mesh(vertices, faces, name=what, dtype=np.float64)
    digest = hashlib.blake2b(v.tobytes(), digest_size=16)
    digest.update(f.tobytes())
    key = (v.shape[0], f.shape[0], digest.digest())
    shape = _SHAPES.get(key)
    if shape is None:
        shape = _SHAPES[key] = _Shape(np.array(v, np.float64), np.array(f, np.int32))
    return shape


def _matrix(transform: ArrayLike | None, what: str) -> np.ndarray:
    """``transform`` (None: the identity) as a ``(4, 4)`` float64 rigid transform.

    Raises:
        ValueError: ``"transform must be (4,4)!"`` (trimesh's), or naming ``what`` and why it is not rigid.
    """
    if transform is None:
        return np.eye(4)
    m = np.array(transform, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError("transform must be (4,4)!")
    problem = _rigid_problem(m)
    if problem is not None:
        raise ValueError(f"{what}: {problem}")
    return m


def _rigid_problem(m: np.ndarray) -> str | None:
    """Why the ``(4, 4)`` float64 ``m`` is not a rigid transform, or None (one matrix, quickly: every
    :meth:`CollisionManager.set_transform` checks one)."""
    (a, b, c, x), (d, e, f, y), (g, h, i, z), bottom = m.tolist()  # Python floats: a few microseconds
    if not all(map(math.isfinite, (a, b, c, x, d, e, f, y, g, h, i, z, *bottom))):
        return "transform contains NaN or inf"
    if bottom != [0.0, 0.0, 0.0, 1.0]:
        return f"transform's bottom row must be (0, 0, 0, 1), got {bottom}"
    off = max(abs(a * a + b * b + c * c - 1.0), abs(d * d + e * e + f * f - 1.0), abs(g * g + h * h + i * i - 1.0),
              abs(a * d + b * e + c * f), abs(a * g + b * h + c * i), abs(d * g + e * h + f * i))
    if off > RIGID_TOLERANCE:
        return "transform is not rigid (scale or shear); warp_ccd takes rotations and translations only"
    if a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) < 0.0:
        return "transform is not rigid (a reflection); warp_ccd takes rotations and translations only"
    return None


def _answer(result: Any, names: Any, data: Any, return_names: bool, return_data: bool) -> Any:
    """trimesh's return values: ``result``, then the names and the data where asked for."""
    if return_names and return_data:
        return result, names, data
    if return_names:
        return result, names
    if return_data:
        return result, data
    return result


class _World:
    """One scene of objects with its pipelines and distance query, placed by the managers' poses.

    Args:
        shapes: the :class:`_Shape` of each object.
        split: None (every pair of objects may collide), or ``k``: objects ``[0, k)`` pair only with
            objects ``[k, N)`` (two collision groups).
        names: each object's name (the query mesh's: ``"__external"``), for the data returned and messages.
        device: the Warp device.
        max_per_pair: most contacts a pair (``return_data``).
    """

    def __init__(self, shapes: list[_Shape], split: int | None, names: list, device: wp.Device,
                 max_per_pair: int) -> None:
        self.shapes = shapes
        self.split = split
        self.names = names
        self.device = device
        self.max_per_pair = max_per_pair
        first: dict[int, int] = {}
        self.object_shape = np.array([first.setdefault(id(s), len(first)) for s in shapes], np.int64)
        distinct = list({id(s): s for s in shapes}.values())
        self.meshes = [(s.vertices, s.faces) for s in distinct]
        self.lower = np.array([s.lower for s in shapes]).reshape(-1, 3)
        self.upper = np.array([s.upper for s in shapes]).reshape(-1, 3)
        self.first = np.array([s.first for s in shapes]).reshape(-1, 3)
        n = len(shapes)
        self.group = self.mask = None
        if split is not None:
            side = np.arange(n) >= split
            self.group = np.where(side, 2, 1).astype(np.int64)
            self.mask = np.where(side, 1, 2).astype(np.int64)
        self.scene = None
        self.rows = None

    def _build(self, precision: str) -> None:
        self.scene = Scene(self.meshes, self.object_shape, device=self.device, precision=precision,
                           group=self.group, mask=self.mask)
        self.pipelines: dict[bool, CollisionPipeline] = {}
        self.query = None
        self.rows = None

    def place(self, rows: np.ndarray) -> None:
        """Places the objects at ``(N, 7)`` poses (uploaded only where they changed); a scene whose float32
        does not resolve them at its triangles' size is built again in float64.

        Raises:
            ValueError: naming the object placed too far from the origin for float64 too.
        """
        if self.scene is None:
            self._build("float32")
        elif self.rows is not None and np.array_equal(rows, self.rows):
            return
        try:
            self.scene.set_poses(rows)
        except ValueError as exc:
            if self.scene.precision == "float64":
                raise self._far(rows, exc) from None
            self._build("float64")
            try:
                self.scene.set_poses(rows)
            except ValueError as again:
                raise self._far(rows, again) from None
        self.rows = rows.copy()

    def _far(self, rows: np.ndarray, exc: ValueError) -> ValueError:
        reach = np.abs(rows[:, :3]).max(axis=1) + np.linalg.norm(np.maximum(-self.lower, self.upper), axis=1)
        return ValueError(f"{self.names[int(np.argmax(reach))]!r}: placed too far from the origin ({exc})")

    def pipeline(self, contacts: bool) -> CollisionPipeline:
        """The pipeline (containment asked for; with ``contacts``, contacts too), made on first use."""
        pipe = self.pipelines.get(contacts)
        if pipe is None:
            options = {"containment": True}
            if contacts:
                options.update(contacts=True, max_per_pair=self.max_per_pair)
            pipe = self.pipelines[contacts] = CollisionPipeline(self.scene, **options)
        return pipe

    def collide(self, contacts: bool = False) -> tuple[np.ndarray, Any]:
        """Detects at the poses placed: ``(K, 2)`` int32 colliding pairs ``(a, b)``, ``a < b``, sorted (surfaces
        that intersect, or a mesh inside a closed one), and with ``contacts`` the result's contacts."""
        res = self.pipeline(contacts).detect()
        # Object pairs as int64 keys a * N + b, made unique (cheaper than the result's sorted triangle rows).
        n = np.int64(len(self.shapes))
        rows = res.device_triangle_pairs.numpy().reshape(-1, 4).astype(np.int64)
        keys = [rows[:, 0] * n + rows[:, 2]]
        inside = res.device_contained.numpy().reshape(-1, 2).astype(np.int64)
        if len(inside):  # (inner, outer): a mesh inside a closed one
            inside = inside[np.array([self.shapes[o].closed for o in inside[:, 1].tolist()], bool)]
            keys.append(inside.min(axis=1) * n + inside.max(axis=1))
        key = np.unique(np.concatenate(keys))
        pairs = np.stack([key // n, key % n], axis=1).astype(np.int32)
        return pairs, (res.contacts if contacts else None)

    def boxes(self) -> tuple[np.ndarray, np.ndarray]:
        """``(N, 3)`` world boxes around the objects (their local boxes placed, then boxed again)."""
        rot = quat_to_matrix(self.rows[:, 3:])
        center = np.einsum("nij,nj->ni", rot, (self.lower + self.upper) / 2) + self.rows[:, :3]
        half = np.einsum("nij,nj->ni", np.abs(rot), (self.upper - self.lower) / 2)
        return center - half, center + half

    def anchors(self) -> np.ndarray:
        """``(N, 3)`` a point of each object's surface: its first vertex, placed."""
        return np.einsum("nij,nj->ni", quat_to_matrix(self.rows[:, 3:]), self.first) + self.rows[:, :3]

    def distances(self, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Least distances of ``(P, 2)`` object pairs at the poses placed: ``(P,)`` float64 (0 for crossing
        open surfaces, whose depth is undefined), ``(P, 2, 3)`` closest points, ``(P, 2)`` closest triangles."""
        if self.query is None:
            self.query = DistanceQuery(self.scene, pairs)
        else:
            self.query.set_pairs(pairs)
        res = self.query.query()
        return np.nan_to_num(res.distance, nan=0.0), res.closest_points, res.closest_triangles


def _pair_bounds(lower: np.ndarray, upper: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Lower bounds on the signed distance of object pairs ``(a[k], b[k])`` whose surfaces lie in boxes
    ``[lower, upper]``: the boxes' gap where they are apart; where they overlap, minus the deepest a point
    of the overlap lies inside either box (no point of one surface inside the other's solid lies deeper in
    that solid, which its box holds)."""
    lo_a, hi_a, lo_b, hi_b = lower[a], upper[a], lower[b], upper[b]
    axis_gap = np.maximum(lo_b - hi_a, lo_a - hi_b)
    gap = np.linalg.norm(np.maximum(axis_gap, 0.0), axis=1)
    olo, ohi = np.maximum(lo_a, lo_b), np.minimum(hi_a, hi_b)

    def inside(lo, hi):  # per axis the most a point of the overlap can lie inside [lo, hi]; the least axis's
        m = np.clip((lo + hi) / 2, olo, ohi)
        return np.minimum(m - lo, hi - m).min(axis=1)

    depth = np.maximum(inside(lo_a, hi_a), inside(lo_b, hi_b))
    return np.where((axis_gap > 0.0).any(axis=1), gap, -np.maximum(depth, 0.0))


def _near_pairs(world: _World) -> tuple[np.ndarray, np.ndarray]:
    """The object pairs of ``world`` (across its split, where it has one) that may be the closest, with
    their lower bounds (:func:`_pair_bounds`): those whose bound is at most an upper bound ``U`` on the least
    distance, found by the broad phase on the boxes grown by ``U / 2``. ``U``: the least distance between
    the first vertices of two objects next to each other along the axis where those vertices spread most."""
    lower, upper = world.boxes()
    p = world.anchors()
    order = np.argsort(p[:, int(np.argmax(np.ptp(p, axis=0)))], kind="stable")
    step = np.linalg.norm(p[order[1:]] - p[order[:-1]], axis=1)
    if world.split is not None:  # neighbours from both sides only
        side = order >= world.split
        step = step[side[1:] != side[:-1]]
    reach = float(step.min())
    pad = reach / 2
    cand = broad_phase_pairs(lower - pad, upper + pad, device=world.device, group=world.group, mask=world.mask)
    bound = _pair_bounds(lower, upper, cand[:, 0], cand[:, 1])
    keep = bound <= reach
    return cand[keep], bound[keep]


def _nearest(world: _World, pairs: np.ndarray, bound: np.ndarray, key: Callable[[np.ndarray], Any]):
    """The closest of ``(P, 2)`` object pairs (``P >= 1``) by their lower bounds ``bound``: measured in
    increasing order of bound, in batches, until the least distance measured is below the next bound.

    Returns:
        ``(pair (2,), distance, points (2, 3), triangles (2,))``; of pairs at the least distance, the one whose
        ``key(pair)`` is least.
    """
    order = np.lexsort((pairs[:, 1], pairs[:, 0], bound))
    pairs, bound = pairs[order], bound[order]
    best = np.inf
    found = []
    start, batch = 0, FIRST_BATCH
    while start < len(pairs) and bound[start] <= best:
        stop = start + int(np.searchsorted(bound[start : start + batch], best, side="right"))
        d, points, triangles = world.distances(pairs[start:stop])
        found.append((pairs[start:stop], d, points, triangles))
        best = min(best, float(d.min()))
        start, batch = stop, 2 * batch
    rows, d, points, triangles = (np.concatenate(parts) for parts in zip(*found))
    tied = np.flatnonzero(d == d.min())
    k = int(tied[0])
    if len(tied) > 1:
        try:
            k = int(min(tied.tolist(), key=lambda i: key(rows[i])))
        except TypeError:  # names that do not compare: the first of the tied pairs measured
            pass
    return rows[k], float(d[k]), points[k], triangles[k]


class CollisionObject:
    """What :meth:`CollisionManager.add_object` returns (where trimesh's returns FCL's collision object):
    the object's name and mesh, and its transform now.

    Attributes:
        name: the object's name.
        mesh: the mesh given.
    """

    def __init__(self, manager: CollisionManager, name: Any, mesh: Any) -> None:
        self._manager = weakref.ref(manager)
        self.name = name
        self.mesh = mesh

    @property
    def transform(self) -> np.ndarray | None:
        """``(4, 4)`` float64 transform the object has now (None once it left its manager)."""
        manager = self._manager()
        i = None if manager is None else manager._index.get(self.name)
        return None if i is None else manager._matrices[i].copy()

    def __repr__(self) -> str:
        return f"CollisionObject(name={self.name!r})"


def _other(manager: Any) -> CollisionManager:
    """``manager``, checked to be a :class:`CollisionManager`."""
    if not isinstance(manager, CollisionManager):
        raise TypeError(f"other_manager: expected a warp_ccd CollisionManager, got {type(manager).__name__}")
    return manager


class CollisionManager:
    """A mesh-mesh collision manager: trimesh's ``CollisionManager`` on warp_ccd (see the module docstring).

    Args:
        device: Warp device of its scenes (default: Warp's default device).
        max_per_pair: most contacts a pair of objects reports (``return_data``).
    """

    def __init__(self, *, device: DeviceLike = None, max_per_pair: int = 8) -> None:
        init_warp()
        self.device = wp.get_device(device)
        self.max_per_pair = check_option("max_per_pair", max_per_pair)
        self._serial = next(_SERIAL)
        self._names: list = []
        self._index: dict = {}
        self._shapes: list[_Shape] = []
        self._matrices = np.zeros((0, 4, 4))
        self._rows: np.ndarray | None = None  # (N, 7) poses of the matrices; None: to convert
        self._version = 0  # moves on when objects are added or removed: scenes are built again
        self._worlds: OrderedDict = OrderedDict()

    # ------------------------------------------------------------------ objects
    def add_object(self, name: Any, mesh: Any, transform: ArrayLike | None = None) -> CollisionObject:
        """Adds an object, or replaces the object of that name.

        Args:
            name: a hashable name.
            mesh: a mesh with ``vertices`` (n, 3) and ``faces`` (m, 3), such as a ``trimesh.Trimesh``.
            transform: ``(4, 4)`` rigid transform of the object (default: the identity).

        Returns:
            A :class:`CollisionObject` of the object.

        Raises:
            ValueError: a transform not ``(4, 4)`` (``"transform must be (4,4)!"``) or not rigid, or a bad mesh,
                naming the object.
        """
        m = _matrix(transform, f"object {name!r}")
        shape = _shape_of(mesh, f"mesh of object {name!r}")
        i = self._index.get(name)
        if i is None:
            i = self._index[name] = len(self._names)
            self._names.append(name)
            self._shapes.append(shape)
            if i == len(self._matrices):
                self._matrices = np.concatenate([self._matrices, np.tile(np.eye(4), (max(8, i), 1, 1))])
            self._version += 1
        elif self._shapes[i] is not shape:
            self._shapes[i] = shape
            self._version += 1
        self._matrices[i] = m
        self._rows = None
        return CollisionObject(self, name, mesh)

    def remove_object(self, name: Any) -> None:
        """Removes the object called ``name``.

        Raises:
            ValueError: ``"{name} not in collision manager!"``.
        """
        i = self._index.get(name)
        if i is None:
            raise ValueError(f"{name} not in collision manager!")
        del self._names[i], self._shapes[i]
        self._matrices = np.delete(self._matrices, i, axis=0)
        self._index = {n: k for k, n in enumerate(self._names)}
        self._rows = None
        self._version += 1

    def set_transform(self, name: Any, transform: ArrayLike) -> None:
        """Moves the object called ``name`` (its pose alone: the scene is not built again).

        Args:
            name: the object's name.
            transform: ``(4, 4)`` rigid transform.

        Raises:
            ValueError: ``"{name} not in collision manager!"``, a transform not ``(4, 4)``, or one not rigid.
        """
        i = self._index.get(name)
        if i is None:
            raise ValueError(f"{name} not in collision manager!")
        self._matrices[i] = _matrix(transform, f"object {name!r}")
        self._rows = None

    def _poses(self) -> np.ndarray:
        """``(N, 7)`` float64 poses of the objects (position, quaternion x, y, z, w)."""
        if self._rows is None:
            n = len(self._names)
            self._rows = transforms_to_poses(self._matrices[:n], n)
        return self._rows

    def _world(self, key: tuple, shapes: Callable[[], list[_Shape]], split: int | None, names: list) -> _World:
        """The scene of ``key`` (made with ``shapes()`` the first time), among the few kept."""
        world = self._worlds.get(key)
        if world is None:
            world = self._worlds[key] = _World(shapes(), split, names, self.device, self.max_per_pair)
            while len(self._worlds) > WORLDS_KEPT:
                self._worlds.popitem(last=False)
        else:
            self._worlds.move_to_end(key)
        world.names = names
        return world

    def _own_world(self) -> _World:
        """The scene of this manager's objects, placed."""
        world = self._world(("own", self._version), lambda: list(self._shapes), None, self._names)
        world.place(self._poses())
        return world

    def _single_world(self, mesh: Any, transform: ArrayLike | None) -> _World:
        """The scene of this manager's objects and ``mesh`` (the last object) in two groups, placed."""
        shape = _shape_of(mesh, "query mesh")
        row = transforms_to_poses(_matrix(transform, "query mesh")[None], 1)
        world = self._world(("single", self._version, id(shape)), lambda: [*self._shapes, shape],
                            len(self._names), [*self._names, EXTERNAL])
        world.place(np.concatenate([self._poses(), row]))
        return world

    def _other_world(self, other: CollisionManager) -> _World:
        """The scene of this manager's objects and ``other``'s (after them) in two groups, placed."""
        world = self._world(("other", self._version, other._serial, other._version),
                            lambda: [*self._shapes, *other._shapes], len(self._names), [*self._names, *other._names])
        world.place(np.concatenate([self._poses(), other._poses()]))
        return world

    # ------------------------------------------------------------------ collisions
    def _contacts(self, world: _World, contacts: Any) -> list[ContactData]:
        """One :class:`ContactData` per contact, its names in the scene's object order (python-fcl's normal:
        from the first to the second, where the library's points from the second to the first)."""
        if contacts is None or not len(contacts.pairs):
            return []
        names = world.names
        point = (np.asarray(contacts.point_a, np.float64) + np.asarray(contacts.point_b, np.float64)) / 2
        normal = -np.asarray(contacts.normal, np.float64)
        return [ContactData((names[a], names[b]), point[k], normal[k], depth, tri)
                for k, ((a, b), depth, tri) in enumerate(zip(contacts.pairs.tolist(),
                                                             np.asarray(contacts.depth, np.float64).tolist(),
                                                             contacts.triangles.tolist()))]

    def in_collision_single(self, mesh: Any, transform: ArrayLike | None = None, return_names: bool = False,
                            return_data: bool = False) -> CollisionAnswer:
        """Whether ``mesh`` placed by ``transform`` collides with any of the manager's objects.

        Args:
            mesh: a mesh with ``vertices`` and ``faces``.
            transform: ``(4, 4)`` rigid transform of the mesh (default: the identity).
            return_names: also return the set of names of the objects it collides with.
            return_data: also return a list of :class:`ContactData` (names: the object's and ``"__external"``).

        Returns:
            ``is_collision``, then ``names`` and ``contacts`` where asked for.
        """
        if not self._names:
            _shape_of(mesh, "query mesh")
            _matrix(transform, "query mesh")
            return _answer(False, set(), [], return_names, return_data)
        world = self._single_world(mesh, transform)
        pairs, contacts = world.collide(return_data)
        names = {self._names[a] for a in pairs[:, 0].tolist()}
        data = self._contacts(world, contacts) if return_data else []
        return _answer(bool(len(pairs)), names, data, return_names, return_data)

    def in_collision_internal(self, return_names: bool = False, return_data: bool = False) -> CollisionAnswer:
        """Whether any two of the manager's objects collide.

        Args:
            return_names: also return the set of colliding pairs of names, each tuple sorted.
            return_data: also return a list of :class:`ContactData`.

        Returns:
            ``is_collision``, then ``names`` and ``contacts`` where asked for.
        """
        if len(self._names) < 2:
            return _answer(False, set(), [], return_names, return_data)
        world = self._own_world()
        pairs, contacts = world.collide(return_data)
        names = {tuple(sorted((self._names[a], self._names[b]))) for a, b in pairs.tolist()}
        data = self._contacts(world, contacts) if return_data else []
        return _answer(bool(len(pairs)), names, data, return_names, return_data)

    def in_collision_other(self, other_manager: CollisionManager, return_names: bool = False,
                           return_data: bool = False) -> CollisionAnswer:
        """Whether any object of this manager collides with any of ``other_manager``'s.

        Args:
            other_manager: another :class:`CollisionManager`.
            return_names: also return the set of colliding pairs ``(name here, name there)``.
            return_data: also return a list of :class:`ContactData`.

        Returns:
            ``is_collision``, then ``names`` and ``contacts`` where asked for.
        """
        if not (_other(other_manager)._names and self._names):
            return _answer(False, set(), [], return_names, return_data)
        world = self._other_world(other_manager)
        pairs, contacts = world.collide(return_data)
        n = len(self._names)
        names = {(self._names[a], other_manager._names[b - n]) for a, b in pairs.tolist()}
        data = self._contacts(world, contacts) if return_data else []
        return _answer(bool(len(pairs)), names, data, return_names, return_data)

    # ------------------------------------------------------------------ distances
    def _distance_data(self, world: _World, pair: np.ndarray, d: float, points: np.ndarray,
                       triangles: np.ndarray) -> DistanceData:
        return DistanceData((world.names[pair[0]], world.names[pair[1]]), d, points, triangles)

    def min_distance_single(self, mesh: Any, transform: ArrayLike | None = None, return_name: bool = False,
                            return_data: bool = False) -> DistanceAnswer:
        """The least distance between ``mesh`` placed by ``transform`` and the manager's objects (negative
        where they intersect: minus the depth).

        Args:
            mesh: a mesh with ``vertices`` and ``faces``.
            transform: ``(4, 4)`` rigid transform of the mesh (default: the identity).
            return_name: also return the name of the closest object.
            return_data: also return a :class:`DistanceData` (names: the object's and ``"__external"``).

        Returns:
            ``distance`` (the largest float when the manager is empty), then ``name`` and ``data`` where asked
            for (None when the manager is empty).
        """
        n = len(self._names)
        if n == 0:
            _shape_of(mesh, "query mesh")
            _matrix(transform, "query mesh")
            return _answer(NO_DISTANCE, None, None, return_name, return_data)
        world = self._single_world(mesh, transform)
        pairs = np.stack([np.arange(n), np.full(n, n)], axis=1).astype(np.int32)
        lower, upper = world.boxes()
        pair, d, points, triangles = _nearest(world, pairs, _pair_bounds(lower, upper, pairs[:, 0], pairs[:, 1]),
                                              key=lambda p: self._names[p[0]])
        data = self._distance_data(world, pair, d, points, triangles) if return_data else None
        return _answer(d, self._names[pair[0]], data, return_name, return_data)

    def min_distance_internal(self, name: Any = None, return_names: bool = False,
                              return_data: bool = False) -> DistanceAnswer:
        """The least distance between two of the manager's objects, or between the object called ``name``
        and the others (negative where they intersect: minus the depth).

        Args:
            name: an object's name, or None: every pair.
            return_names: also return the closest pair's names, sorted.
            return_data: also return a :class:`DistanceData`.

        Returns:
            ``distance`` (the largest float where there is no pair), then ``names`` and ``data`` where asked
            for (None where there is no pair).

        Raises:
            ValueError: ``"{name} not in collision manager!"``.
        """
        n = len(self._names)
        if name is not None:
            if name not in self._index:
                raise ValueError(f"{name} not in collision manager!")
            if n < 2:
                return _answer(NO_DISTANCE, None, None, return_names, return_data)
            world = self._own_world()
            i = self._index[name]
            others = np.delete(np.arange(n), i)
            pairs = np.stack([np.full(n - 1, i), others], axis=1).astype(np.int32)
            lower, upper = world.boxes()
            bound = _pair_bounds(lower, upper, pairs[:, 0], pairs[:, 1])
        else:
            if n < 2:
                return _answer(NO_DISTANCE, None, None, return_names, return_data)
            world = self._own_world()
            pairs, bound = _near_pairs(world)
        pair, d, points, triangles = _nearest(
            world, pairs, bound, key=lambda p: tuple(sorted((self._names[p[0]], self._names[p[1]]))))
        data = self._distance_data(world, pair, d, points, triangles) if return_data else None
        names = tuple(sorted((self._names[pair[0]], self._names[pair[1]])))
        return _answer(d, names, data, return_names, return_data)

    def min_distance_other(self, other_manager: CollisionManager, return_names: bool = False,
                           return_data: bool = False) -> DistanceAnswer:
        """The least distance between an object of this manager and one of ``other_manager``'s (negative
        where they intersect: minus the depth).

        Args:
            other_manager: another :class:`CollisionManager`.
            return_names: also return the closest pair's names ``(name here, name there)``.
            return_data: also return a :class:`DistanceData`.

        Returns:
            ``distance`` (the largest float where either manager is empty), then ``names`` and ``data`` where
            asked for (None where there is no pair).
        """
        if not (_other(other_manager)._names and self._names):
            return _answer(NO_DISTANCE, None, None, return_names, return_data)
        world = self._other_world(other_manager)
        n = len(self._names)
        pairs, bound = _near_pairs(world)
        pair, d, points, triangles = _nearest(
            world, pairs, bound, key=lambda p: (self._names[p[0]], other_manager._names[p[1] - n]))
        data = self._distance_data(world, pair, d, points, triangles) if return_data else None
        return _answer(d, (self._names[pair[0]], other_manager._names[pair[1] - n]), data, return_names,
                       return_data)


def scene_to_collision(scene: Any, **kwargs: Any) -> tuple[CollisionManager, dict]:
    """A :class:`CollisionManager` of the meshes of a ``trimesh.Scene``, one object per geometry node.

    A node transform that is not rigid (a scale) is baked into a copy of the mesh's vertices, the object
    placed by the identity.

    Args:
        scene: a ``trimesh.Scene``.
        **kwargs: options of :class:`CollisionManager` (``device``, ``max_per_pair``).

    Returns:
        ``(manager, {node name: CollisionObject})``.
    """
    manager = CollisionManager(**kwargs)
    objects = {}
    for node in scene.graph.nodes_geometry:
        transform, geometry = scene.graph[node]
        mesh = scene.geometry[geometry]
        m = np.asarray(transform, np.float64)
        if m.shape == (4, 4) and _rigid_problem(m) is not None and hasattr(mesh, "vertices"):
            mesh = _Placed(np.asarray(mesh.vertices, np.float64) @ m[:3, :3].T + m[:3, 3], mesh.faces)
            m = None
        objects[node] = manager.add_object(name=node, mesh=mesh, transform=m)
    return manager, objects


class _Placed:
    """A mesh's vertices under a transform that is not rigid, with its faces (:func:`scene_to_collision`)."""

    def __init__(self, vertices: np.ndarray, faces: ArrayLike) -> None:
        self.vertices = vertices
        self.faces = faces
