"""Which prim pairs a USD check tests: worlds, excluded pairs (a file, the stage's physics filters), sets.

Everything here turns prim paths into the :class:`~warp_ccd._src.scene.filter.CollisionFilter` arguments of the
import's scene (``world``, ``group``, ``mask``, ``exclude_pairs``), once, before the first frame; the
broad phase then never pairs what they rule out.

* **Paths and patterns.** A path names the prim at it and, with it, every mesh object at or under it
  (an ``Xform`` names the meshes below). A path with ``*``, ``?`` or ``[`` is an ``fnmatch`` pattern
  matched against whole prim paths (``*`` crosses ``/``, as ``--prims`` does): every prim it matches
  names its meshes. A PointInstancer's instances lie under the instancer (their prototype's mesh does).
  :class:`PrimIndex` answers these for every object at once: the objects' prim paths and their ancestors
  are listed once, a pattern is matched against the ancestors (one regular expression over the unique
  ancestors), and the objects under the matches come from an index (numpy, no loop over objects).
* **Worlds** (``worlds``): every prim a pattern matches roots one world; a mesh belongs to the world
  of its outermost matching ancestor (a match inside a world stays in it). Worlds are numbered in the
  order of their roots' paths (sorted); a mesh under no root is in world ``-1`` (it pairs with every world).
* **Excluded pairs** (``ignore_pairs``): a text file of prim path pairs, one pair a line, the two
  separated by whitespace or a comma, ``#`` comments and blank lines ignored; or, for a file ending in
  ``.json``, a list of ``[a, b]`` pairs; or pairs given in Python. Every mesh under ``a`` is excluded
  against every mesh under ``b``. A line naming no prim of the stage is an error (naming the file and
  line) unless ``allow_missing``, then a note.
* **The stage's physics filters** (``usd_filters``): ``UsdPhysics.FilteredPairsAPI`` (a prim's
  ``physics:filteredPairs`` targets: its meshes never collide with theirs), and ``UsdPhysics.CollisionGroup``
  prims (``physics:filteredGroups``, ``physics:mergeGroup``, ``physics:invertFilteredGroups``, as
  ``UsdPhysics.CollisionGroup.ComputeCollisionGroupTable`` reads them; members from the
  ``collectionAPI:colliders`` collection): the members of two groups that do not collide are excluded
  pairwise. Objects in no group are not affected (an inverted group's filter applies among groups only).
* **The stage's rigid bodies and joints** (``usd_filters`` too; :mod:`~warp_ccd._src.usd.physics`): meshes of one
  ``UsdPhysics.RigidBodyAPI`` body are one object (never checked against each other), and the meshes of two
  bodies that a ``UsdPhysics.Joint`` with ``physics:collisionEnabled`` false joins are never checked against
  each other. The report counts the pairs each rule excludes.
* **Sets** (``set_a``, ``set_b``): only pairs with one object in set A and the other in set B are
  tested, through collision groups and masks: A only ``group 1 mask 2``, B only ``group 2 mask 1``,
  both ``group 3 mask 3``, neither ``group 0 mask 0`` (never tested). A pattern matching no checked
  mesh is an error unless ``allow_missing``.

Excluded pairs are object index pairs, built with numpy per line (its two sides' objects, every pair);
at most :data:`MAX_EXCLUDED` in all (use sets or worlds for large blocks).
"""

from __future__ import annotations

import fnmatch
import json
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..runtime.aliases import PathLike
from .physics import PhysicsPrims, body_keys, joint_keys, object_bodies

if TYPE_CHECKING:
    from pxr import Usd

__all__ = ["MAX_EXCLUDED", "FilterSummary", "PairFilters", "PrimIndex", "PrimPair", "read_pair_file", "world_ids"]

MAX_EXCLUDED = 50_000_000
"""Most object pairs the excluded pairs may expand to (400 MB of keys); beyond it, a ValueError."""

_GLOB = "*?["


def is_pattern(path: str) -> bool:
    """Whether ``path`` is an ``fnmatch`` pattern (holds ``*``, ``?`` or ``[``)."""
    return any(c in path for c in _GLOB)


@dataclass(frozen=True)
class PrimPair:
    """Two prim paths (or patterns) whose meshes never collide, and where the pair was given.

    Attributes:
        a: a prim path or pattern.
        b: a prim path or pattern.
        source: where it came from (``"pairs.txt:3"``, ``"ignore_pairs[0]"``), for messages.
    """

    a: str
    b: str
    source: str


def _check_path(text: Any, where: str) -> str:
    if not isinstance(text, str) or not text.startswith("/"):
        raise ValueError(f"{where}: expected a prim path or pattern starting with '/', got {text!r}")
    return text


def read_pair_file(path: PathLike) -> list[PrimPair]:
    """The prim pairs of an ignore-pairs file (see the module docstring).

    Args:
        path: a text file (one pair a line, whitespace or a comma between the two paths, ``#``
            comments), or a ``.json`` file holding a list of ``[a, b]`` pairs.

    Returns:
        The pairs, each with its file and line (``.json``: its entry) as ``source``.

    Raises:
        ValueError: naming the file (and line): missing, a folder, unreadable, or a malformed line.
    """
    name = os.fspath(path)
    if not os.path.exists(name):
        raise ValueError(f"cannot read the ignore-pairs file {name}: no such file")
    if os.path.isdir(name):
        raise ValueError(f"cannot read the ignore-pairs file {name}: it is a folder")
    try:
        with open(name, encoding="utf-8") as fh:
            text = fh.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"cannot read the ignore-pairs file {name}: {exc}") from None
    out = []
    if name.lower().endswith(".json"):
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ValueError(f"{name}:{exc.lineno}: not valid JSON ({exc.msg})") from None
        if not isinstance(data, list):
            raise ValueError(f"{name}: expected a JSON list of [a, b] prim path pairs, got {type(data).__name__}")
        for k, item in enumerate(data):
            where = f"{name}: entry {k}"
            if not isinstance(item, list) or len(item) != 2:
                raise ValueError(f"{where}: expected a pair [a, b] of prim paths, got {json.dumps(item)}")
            out.append(PrimPair(_check_path(item[0], where), _check_path(item[1], where), where))
        return out
    for lineno, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].strip()
        if not body:
            continue
        where = f"{name}:{lineno}"
        parts = [p for p in re.split(r"[,\s]+", body) if p]
        if len(parts) != 2 or body.count(",") > 1:
            raise ValueError(f"{where}: expected two prim paths separated by whitespace or a comma, got {body!r}")
        out.append(PrimPair(_check_path(parts[0], where), _check_path(parts[1], where), where))
    return out


def pair_sources(ignore_pairs: PathLike | Sequence[Any] | None) -> tuple[list[PrimPair], list[str]]:
    """``ignore_pairs`` as ``(pairs, files)``: a file path, or a sequence whose items are file paths,
    ``(a, b)`` prim path pairs or :class:`PrimPair` objects.

    Raises:
        ValueError: a bad file (see :func:`read_pair_file`) or item.
    """
    if ignore_pairs is None:
        return [], []
    items = [ignore_pairs] if isinstance(ignore_pairs, (str, bytes, os.PathLike)) else list(ignore_pairs)
    pairs: list[PrimPair] = []
    files: list[str] = []
    for k, item in enumerate(items):
        if isinstance(item, PrimPair):
            pairs.append(item)
        elif isinstance(item, (str, bytes, os.PathLike)):
            name = os.fsdecode(item)
            files.append(name)
            pairs += read_pair_file(name)
        else:
            where = f"ignore_pairs[{k}]"
            if not isinstance(item, Sequence) or len(item) != 2:
                raise ValueError(f"{where}: expected a file or a pair (a, b) of prim paths, got {item!r}")
            pairs.append(PrimPair(_check_path(item[0], where), _check_path(item[1], where), where))
    return pairs, files


def _patterns(values: str | Sequence[str] | None, name: str) -> list[str] | None:
    """Patterns as a list (a string may hold several separated by commas), or None."""
    if values is None:
        return None
    items = [values] if isinstance(values, str) else list(values)
    out = [p.strip() for v in items for p in str(v).split(",")]
    if not out or not all(out):
        raise ValueError(f"{name}: expected prim paths or patterns, got {values!r}")
    for p in out:
        _check_path(p, name)
    return out


class PrimIndex:
    """The objects at or under each prim: the objects' prim paths, their ancestors, and both ways between.

    Args:
        object_prim: ``N`` prim paths, one per object (a point instance: its prototype's mesh).

    Attributes:
        ancestors: the ``A`` distinct prim paths at or above some object (their ids' order).
    """

    def __init__(self, object_prim: Sequence[str]) -> None:
        self.num_objects = len(object_prim)
        row_id: dict[str, int] = {}
        self._object_row = np.fromiter((row_id.setdefault(p, len(row_id)) for p in object_prim), np.int64,
                                       count=self.num_objects)
        self._id: dict[str, int] = {}
        col, counts = [], []
        for p in row_id:  # per prim path (not per object, not per frame): its ancestors, root first
            cut = [0] + [k for k in range(1, len(p)) if p[k] == "/"] + [len(p)]  # 0: the root, "/"
            col += [self._id.setdefault(p[:k] or "/", len(self._id)) for k in cut]
            counts.append(len(cut))
        self.ancestors = np.array(list(self._id), dtype=object)
        self._col = np.asarray(col, np.int64)  # per (row, depth): ancestor id
        counts = np.asarray(counts, np.int64)
        self._row_start = np.concatenate([[0], np.cumsum(counts)])
        self._row_of = np.repeat(np.arange(len(row_id)), counts)
        unique = row_id
        # Both ways, as CSR: ancestor -> rows under it, row -> its objects.
        by_col = np.argsort(self._col, kind="stable")
        self._anc_rows = self._row_of[by_col]
        self._anc_start = np.searchsorted(self._col[by_col], np.arange(len(self.ancestors) + 1))
        self._row_objects = np.argsort(self._object_row, kind="stable")
        self._row_obj_start = np.searchsorted(self._object_row[self._row_objects], np.arange(len(unique) + 1))
        self._cache: dict[str, np.ndarray] = {}

    def match(self, path: str) -> np.ndarray:
        """``(A,)`` bool: the ancestors ``path`` names (itself, or those a pattern matches)."""
        hit = np.zeros(len(self.ancestors), bool)
        if is_pattern(path):
            regex = re.compile(fnmatch.translate(path))
            hit[:] = [regex.match(a) is not None for a in self.ancestors.tolist()]
            root = self._id.get("/")
            if root is not None:  # a pattern names prims, never the pseudo-root ("/*" is every top prim)
                hit[root] = False
        else:
            k = self._id.get(path.rstrip("/") or "/")
            if k is not None:
                hit[k] = True
        return hit

    def select(self, path: str) -> np.ndarray:
        """Sorted object indices at or under the prims ``path`` names (a path: from the index, without a
        pass over every object; a pattern: :meth:`match`, remembered for the next time)."""
        out = self._cache.get(path)
        if out is not None:
            return out
        if is_pattern(path):
            out = np.nonzero(self.objects_under(self.match(path)))[0]
            self._cache[path] = out
            return out
        k = self._id.get(path.rstrip("/") or "/")
        if k is None:
            return np.zeros(0, np.int64)
        rows = self._anc_rows[self._anc_start[k]:self._anc_start[k + 1]]
        start, stop = self._row_obj_start[rows], self._row_obj_start[rows + 1]
        counts = stop - start
        offsets = np.repeat(start - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
        return np.sort(self._row_objects[np.arange(int(counts.sum())) + offsets])

    def objects_under(self, hit: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: the objects at or under an ancestor in ``hit`` (``(A,)`` bool)."""
        rows = np.zeros(len(self._row_start) - 1, bool)
        rows[self._row_of[hit[self._col]]] = True
        return rows[self._object_row]

    def ancestor_id(self, path: str) -> int | None:
        """The id of the ancestor at ``path`` (no pattern), or None when no object is at or under it."""
        return self._id.get(path.rstrip("/") or "/")

    @property
    def depth(self) -> np.ndarray:
        """``(A,)`` int64: each ancestor's depth (``/`` 0, ``/World`` 1, ``/World/A`` 2)."""
        names = self.ancestors.astype(str)
        return np.where(names == "/", 0, np.char.count(names, "/")).astype(np.int64)

    def innermost(self, hit: np.ndarray) -> np.ndarray:
        """``(N,)`` int64: each object's innermost (nearest) ancestor in ``hit`` (an ancestor id), or ``-1``."""
        pos = np.nonzero(hit[self._col])[0][::-1]  # root last within each row: the first per row is innermost
        rows, first = np.unique(self._row_of[pos], return_index=True)
        out = np.full(len(self._row_start) - 1, -1, np.int64)
        out[rows] = self._col[pos[first]]
        return out[self._object_row]

    def outermost(self, hit: np.ndarray) -> np.ndarray:
        """``(N,)`` int64: each object's outermost ancestor in ``hit`` (an ancestor id), or ``-1``."""
        pos = np.nonzero(hit[self._col])[0]  # root first within each row: the first per row is outermost
        rows, first = np.unique(self._row_of[pos], return_index=True)
        out = np.full(len(self._row_start) - 1, -1, np.int64)
        out[rows] = self._col[pos[first]]
        return out[self._object_row]


def _stage_has_match(stage: Usd.Stage, path: str) -> bool:
    """Whether a prim of ``stage`` is at ``path`` (or matches the pattern ``path``)."""
    from pxr import Sdf, Usd

    if not is_pattern(path):
        return bool(Sdf.Path.IsValidPathString(path)) and stage.GetPrimAtPath(path).IsValid()
    regex = re.compile(fnmatch.translate(path))
    predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
    return any(regex.match(str(p.GetPath())) for p in Usd.PrimRange(stage.GetPseudoRoot(), predicate))


def _keys(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Keys ``min << 32 | max`` of every pair of an object of ``a`` and one of ``b`` (indices), itself left out."""
    i = np.repeat(a.astype(np.int64), len(b))
    j = np.tile(b.astype(np.int64), len(a))
    keep = i != j
    i, j = i[keep], j[keep]
    return (np.minimum(i, j) << 32) | np.maximum(i, j)


def _pairs_of(keys: list[np.ndarray]) -> np.ndarray:
    k = np.unique(np.concatenate(keys)) if keys else np.zeros(0, np.int64)
    return np.stack([k >> 32, k & 0xFFFFFFFF], axis=1).astype(np.int64).reshape(-1, 2)


@dataclass
class FilterSummary:
    """What the filters of a check were and what they did (the report's ``filters`` section).

    Attributes:
        worlds: the world patterns, or None.
        world_roots: the prim paths rooting the worlds that hold meshes, in world order.
        ignore_files: the ignore-pairs files read.
        ignore_lines: prim pairs given (file lines and pairs given in Python).
        excluded_given: object pairs they exclude.
        usd_filters: whether the stage's physics filters were read (None: no filters were asked about).
        usd_filtered_pairs: ``physics:filteredPairs`` targets read.
        usd_collision_groups: ``UsdPhysics.CollisionGroup`` prims read.
        usd_rigid_bodies: enabled ``UsdPhysics.RigidBodyAPI`` prims read (:mod:`~warp_ccd._src.usd.physics`).
        usd_joints: ``UsdPhysics.Joint`` prims read.
        usd_articulations: ``UsdPhysics.ArticulationRootAPI`` prims read.
        excluded_usd: object pairs the physics filters exclude (the union of the four below).
        excluded_rigid_body: object pairs of two meshes of one rigid body.
        excluded_joints: object pairs of two bodies a joint joins with ``collisionEnabled`` false.
        excluded_filtered_pairs: object pairs ``physics:filteredPairs`` exclude.
        excluded_collision_groups: object pairs of collision groups that do not collide.
        excluded: object pairs excluded in all (given and from USD, each once).
        set_a: the set A patterns, or None.
        set_b: the set B patterns, or None.
        set_a_objects: objects in set A.
        set_b_objects: objects in set B.
        notes: what was left out (``allow_missing``) or not supported.
    """

    worlds: list[str] | None = None
    world_roots: list[str] = field(default_factory=list)
    ignore_files: list[str] = field(default_factory=list)
    ignore_lines: int = 0
    excluded_given: int = 0
    usd_filters: bool | None = None
    usd_filtered_pairs: int = 0
    usd_collision_groups: int = 0
    usd_rigid_bodies: int = 0
    usd_joints: int = 0
    usd_articulations: int = 0
    excluded_usd: int = 0
    excluded_rigid_body: int = 0
    excluded_joints: int = 0
    excluded_filtered_pairs: int = 0
    excluded_collision_groups: int = 0
    excluded: int = 0
    set_a: list[str] | None = None
    set_b: list[str] | None = None
    set_a_objects: int = 0
    set_b_objects: int = 0
    notes: list[str] = field(default_factory=list)

    @property
    def used(self) -> bool:
        """Whether any filter was asked for or found (the report then has a ``filters`` section)."""
        return bool(self.worlds or self.set_a or self.ignore_lines or self.ignore_files or self.usd_filters is False
                    or self._usd_read or self.notes)

    @property
    def _usd_read(self) -> bool:
        return bool(self.usd_filtered_pairs or self.usd_collision_groups or self.usd_rigid_bodies or self.usd_joints
                    or self.usd_articulations)

    def to_json(self) -> dict:
        """The report's ``filters`` section."""
        return {"excluded_pairs": self.excluded, "excluded_given": self.excluded_given,
                "excluded_usd": self.excluded_usd, "ignore_pairs": list(self.ignore_files),
                "ignore_lines": self.ignore_lines, "usd_filters": bool(self.usd_filters),
                "usd_filtered_pairs": self.usd_filtered_pairs, "usd_collision_groups": self.usd_collision_groups,
                "set_a": self.set_a, "set_b": self.set_b, "set_a_objects": self.set_a_objects,
                "set_b_objects": self.set_b_objects, "worlds": self.worlds, "world_count": len(self.world_roots),
                "world_roots": list(self.world_roots), "notes": list(self.notes),
                "usd_rigid_bodies": self.usd_rigid_bodies, "usd_joints": self.usd_joints,
                "usd_articulations": self.usd_articulations, "excluded_rigid_body": self.excluded_rigid_body,
                "excluded_joints": self.excluded_joints, "excluded_filtered_pairs": self.excluded_filtered_pairs,
                "excluded_collision_groups": self.excluded_collision_groups}

    def summary_lines(self) -> list[str]:
        """The summary's header lines on the filters (none when no filter was used)."""
        if not self.used:
            return []
        lines = []
        if self.excluded or self.ignore_lines or self._usd_read or self.usd_filters is False:
            usd = (f"{self.excluded_usd} from USD physics filters ({self.excluded_rigid_body} within "
                   f"{self.usd_rigid_bodies} rigid bodies, {self.excluded_joints} by {self.usd_joints} joints, "
                   f"{self.excluded_filtered_pairs} by {self.usd_filtered_pairs} filtered pairs, "
                   f"{self.excluded_collision_groups} by {self.usd_collision_groups} collision groups)"
                   if self.usd_filters else "USD physics filters off")
            lines.append(f"  excluded object pairs: {self.excluded} ({self.excluded_given} given in "
                         f"{self.ignore_lines} prim pairs; {usd})")
        if self.set_a is not None:
            lines.append(f"  only set A x set B: A {', '.join(self.set_a)} ({self.set_a_objects} objects), "
                         f"B {', '.join(self.set_b or [])} ({self.set_b_objects} objects)")
        if self.worlds is not None:
            lines.append(f"  worlds: {len(self.world_roots)} ({', '.join(self.worlds)}); pairs of two worlds "
                         "not checked")
        lines += [f"  note: {n}" for n in self.notes]
        return lines


@dataclass
class PairFilters:
    """The filters a USD check applies besides worlds (see the module docstring), before they are
    resolved against the objects of a stage.

    Args:
        ignore_pairs: an ignore-pairs file, or a sequence of files and ``(a, b)`` prim path pairs, or None.
        usd_filters: read the stage's ``UsdPhysics`` rigid bodies, joints, filtered pairs and collision groups.
        set_a: prim paths or patterns of set A (a string may hold several, comma-separated), or None.
        set_b: likewise for set B; given with ``set_a`` or not at all.
        allow_missing: a prim pair naming no prim, or a set or world pattern matching no checked mesh,
            is a note instead of an error.

    Raises:
        ValueError: a bad file or pair, ``set_a`` without ``set_b`` (or the reverse).
    """

    def __init__(self, *, ignore_pairs: PathLike | Sequence[Any] | None = None, usd_filters: bool = True,
                 set_a: str | Sequence[str] | None = None, set_b: str | Sequence[str] | None = None,
                 allow_missing: bool = False) -> None:
        self.pairs, self.files = pair_sources(ignore_pairs)
        self.usd_filters = bool(usd_filters)
        self.set_a = _patterns(set_a, "set_a")
        self.set_b = _patterns(set_b, "set_b")
        if (self.set_a is None) != (self.set_b is None):
            raise ValueError("set_a and set_b go together (--set-a and --set-b): pairs of one prim of each are "
                             f"checked; only {'set_a' if self.set_b is None else 'set_b'} given")
        self.allow_missing = bool(allow_missing)

    def resolve(self, stage: Usd.Stage, object_prim: Sequence[str] | PrimIndex,
                summary: FilterSummary | None = None,
                instances: tuple[np.ndarray, Sequence[str], np.ndarray] | None = None) -> tuple[dict, FilterSummary]:
        """The scene's filter arguments for objects ``object_prim`` of ``stage``.

        Args:
            stage: the stage the prim paths name prims of.
            object_prim: ``N`` prim paths, one per object, or their :class:`PrimIndex`.
            summary: a summary to fill in (one holding the worlds already), or None.
            instances: the point instances among the objects, ``(instancer, paths, instance)``: ``(N,)`` int64
                each object's PointInstancer (an index into ``paths``, ``-1`` for none), the instancers' prim
                paths, and ``(N,)`` int64 each point instance's index; or None (no object is one). A rigid body
                inside a prototype is one body per instance.

        Returns:
            ``(arguments, summary)``: ``exclude_pairs``, ``group`` and ``mask`` for the
            :class:`~warp_ccd._src.scene.scene.Scene` (each None when not used), and the :class:`FilterSummary`.

        Raises:
            ValueError: a pair naming no prim, a set pattern matching no checked mesh (unless
                ``allow_missing``), a joint with a bad body target (naming the joint), or more than
                :data:`MAX_EXCLUDED` excluded pairs.
        """
        index = object_prim if isinstance(object_prim, PrimIndex) else PrimIndex(object_prim)
        s = summary if summary is not None else FilterSummary()
        s.ignore_files = list(self.files)
        s.ignore_lines = len(self.pairs)
        s.usd_filters = self.usd_filters
        budget = [MAX_EXCLUDED]
        given = []
        for pair in self.pairs:
            sides = []
            for path in (pair.a, pair.b):
                objects = index.select(path)
                if not len(objects) and not _stage_has_match(stage, path):
                    message = f"{pair.source}: {path} names no prim of the stage"
                    if not self.allow_missing:
                        raise ValueError(message + " (--allow-missing: a note instead)")
                    s.notes.append(message + "; pair ignored")
                sides.append(objects)
            given.append(self._expand(sides[0], sides[1], pair.source, budget))
        rules = self._usd_keys(stage, index, s, budget, instances) if self.usd_filters else {}
        usd = [k for keys in rules.values() for k in keys]
        counts = {rule: len(np.unique(np.concatenate(keys))) if keys else 0 for rule, keys in rules.items()}
        s.excluded_rigid_body = counts.get("rigid_body", 0)
        s.excluded_joints = counts.get("joints", 0)
        s.excluded_filtered_pairs = counts.get("filtered_pairs", 0)
        s.excluded_collision_groups = counts.get("collision_groups", 0)
        given_pairs, usd_pairs = _pairs_of(given), _pairs_of(usd)
        s.excluded_given, s.excluded_usd = len(given_pairs), len(usd_pairs)
        excluded = _pairs_of(given + usd)
        s.excluded = len(excluded)
        args: dict = {"exclude_pairs": excluded if len(excluded) else None, "group": None, "mask": None}
        if self.set_a is not None:
            in_a = self._set(self.set_a, index, stage, "set_a", s)
            in_b = self._set(self.set_b, index, stage, "set_b", s)
            s.set_a, s.set_b = list(self.set_a), list(self.set_b)
            s.set_a_objects, s.set_b_objects = int(in_a.sum()), int(in_b.sum())
            args["group"] = in_a.astype(np.int64) | (in_b.astype(np.int64) << 1)
            args["mask"] = (in_a.astype(np.int64) << 1) | in_b.astype(np.int64)
        return args, s

    @staticmethod
    def _expand(a: np.ndarray, b: np.ndarray, source: str, budget: list) -> np.ndarray:
        size = len(a) * len(b)
        if size > budget[0]:
            raise ValueError(f"{source}: the excluded pairs reach more than {MAX_EXCLUDED} object pairs "
                             f"({len(a)} x {len(b)} here); for large blocks use sets (--set-a, --set-b) or worlds")
        budget[0] -= size
        return _keys(a, b)

    def _set(self, patterns: list[str], index: PrimIndex, stage: Usd.Stage, name: str,
             s: FilterSummary) -> np.ndarray:
        inside = np.zeros(index.num_objects, bool)
        for p in patterns:
            objects = index.objects_under(index.match(p))
            if not objects.any():
                message = f"{name}: {p} matches no mesh that is checked"
                if not self.allow_missing:
                    raise ValueError(message + " (--allow-missing: a note instead)")
                s.notes.append(message)
            inside |= objects
        return inside

    def _usd_keys(self, stage: Usd.Stage, index: PrimIndex, s: FilterSummary, budget: list,
                  instances: tuple[np.ndarray, Sequence[str], np.ndarray] | None) -> dict[str, list[np.ndarray]]:
        """Excluded pairs from the stage's physics, per rule (``rigid_body``, ``joints``, ``filtered_pairs``,
        ``collision_groups``): its rigid bodies and joints (:mod:`~warp_ccd._src.usd.physics`),
        ``FilteredPairsAPI`` and ``CollisionGroup`` prims."""
        from pxr import Usd, UsdPhysics

        keys = []
        predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
        groups = False
        found = PhysicsPrims()
        for prim in Usd.PrimRange(stage.GetPseudoRoot(), predicate):
            if prim.IsA(UsdPhysics.CollisionGroup):
                groups = True
            found.add(prim)
            if not prim.HasAPI(UsdPhysics.FilteredPairsAPI):
                continue
            path = str(prim.GetPath())
            mine = index.select(path)
            for target in UsdPhysics.FilteredPairsAPI(prim).GetFilteredPairsRel().GetTargets():
                s.usd_filtered_pairs += 1
                source = f"prim {path}: physics:filteredPairs target {target}"
                if not stage.GetPrimAtPath(target).IsValid():
                    s.notes.append(f"{source} is no prim of the stage; ignored")
                    continue
                theirs = index.select(str(target))
                keys.append(self._expand(mine, theirs, source, budget))
        s.usd_rigid_bodies, s.usd_joints = len(found.bodies), found.num_joints
        s.usd_articulations = found.num_articulations
        s.notes += found.notes
        instancer = instance = None
        if instances is not None:
            which, paths, instance = instances
            anc = np.array([-1 if (k := index.ancestor_id(p)) is None else k for p in paths] + [-1], np.int64)
            instancer = anc[np.asarray(which, np.int64)]  # -1 picks the last entry: no instancer
        body, group = object_bodies(index, found.bodies, instancer, instance)
        return {"rigid_body": [body_keys(group, index, body, budget)],
                "joints": [joint_keys(found.joints, index, body, found.bodies, budget)],
                "filtered_pairs": keys,
                "collision_groups": self._group_keys(stage, index, s, budget) if groups else []}

    def _group_keys(self, stage: Usd.Stage, index: PrimIndex, s: FilterSummary, budget: list) -> list[np.ndarray]:
        from pxr import Usd, UsdPhysics

        table = UsdPhysics.CollisionGroup.ComputeCollisionGroupTable(stage)
        paths = list(table.GetGroups())
        s.usd_collision_groups = len(paths)
        members = []
        for path in paths:
            group = UsdPhysics.CollisionGroup(stage.GetPrimAtPath(path))
            query = group.GetCollidersCollectionAPI().ComputeMembershipQuery()
            included = Usd.CollectionAPI.ComputeIncludedPaths(query, stage, Usd.TraverseInstanceProxies())
            hit = np.zeros(len(index.ancestors), bool)
            ids = [index._id.get(str(p)) for p in included]
            hit[[k for k in ids if k is not None]] = True
            members.append(np.nonzero(index.objects_under(hit))[0])
            if group.GetInvertFilteredGroupsAttr().Get():
                s.notes.append(f"collision group {path} inverts its filter: applied among collision groups only "
                               "(objects in no group still collide with its members)")
        keys = []
        for i in range(len(paths)):
            for j in range(i, len(paths)):
                if not table.IsCollisionEnabled(i, j):
                    keys.append(self._expand(members[i], members[j],
                                             f"collision groups {paths[i]} and {paths[j]}", budget))
        return keys


def world_ids(stage: Usd.Stage, object_prim: Sequence[str] | PrimIndex, worlds: str | Sequence[str],
              allow_missing: bool = False, summary: FilterSummary | None = None) -> tuple[np.ndarray, FilterSummary]:
    """The world of each object (see the module docstring).

    Args:
        stage: the stage (for messages).
        object_prim: ``N`` prim paths, one per object, or their :class:`PrimIndex`.
        worlds: prim paths or patterns, each prim they match rooting one world.
        allow_missing: a pattern that matches no checked mesh is a note instead of an error.
        summary: a summary to fill in, or None.

    Returns:
        ``((N,) int64 world ids, -1 outside every world; the summary)``.

    Raises:
        ValueError: a pattern that matches no checked mesh (unless ``allow_missing``).
    """
    patterns = _patterns(worlds, "worlds")
    s = summary if summary is not None else FilterSummary()
    index = object_prim if isinstance(object_prim, PrimIndex) else PrimIndex(object_prim)
    hit = np.zeros(len(index.ancestors), bool)
    for p in patterns:
        mine = index.match(p)
        if not index.objects_under(mine).any():
            where = stage.GetRootLayer().realPath or stage.GetRootLayer().identifier
            message = f"worlds: {p} matches no mesh that is checked in {where}"
            if not allow_missing:
                raise ValueError(message + " (--allow-missing: a note instead)")
            s.notes.append(message)
        hit |= mine
    root = index.outermost(hit)
    roots, world = np.unique(root[root >= 0], return_inverse=True)
    names = index.ancestors[roots]
    order = np.argsort(names.astype(str), kind="stable")  # worlds in the order of their roots' paths
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    ids = np.full(index.num_objects, -1, np.int64)
    ids[root >= 0] = rank[world.reshape(-1)]
    s.worlds = patterns
    s.world_roots = names[order].tolist()
    return ids, s
