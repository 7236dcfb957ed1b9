"""Checking a USD animation for interpenetration, frame by frame (``warp-ccd check``).

:func:`check_usd` reads a stage once (:class:`~warp_ccd.usd.importer.UsdMeshImport`), runs the
collision pipeline at every time code asked for, and returns a :class:`CheckReport`: per frame,
the prim pairs whose surfaces cross, with their USD face pairs and how deep they cross.

**Touching is not penetrating.** Objects resting on each other touch every frame, and the exact
test reports their triangle pairs (triangles are closed sets). Each reported pair is classified
from the surfaces around it (:mod:`~warp_ccd.stages.crossing`): the surfaces *cross* where one enters
the region behind the other (their insides overlap), and only *touch* where they meet face to
face, edge on edge, edge or vertex on a face. That verdict is a property of the surfaces, not of
how they are cut into triangles. A crossing pair's depth is how far a vertex of either triangle
lies behind the other surface (a vertex poking ``h`` through a face, or a crate sunk ``h`` into a
floor, has depth ``h``); touching pairs have depth 0. A pair penetrates when it crosses deeper
than ``min_depth`` (scene units, default 0: every crossing); the others are counted as touching,
not reported as collisions, unless ``count_touching`` asks for them.

The overlay (:func:`write_overlay`) is a new layer whose sublayer is the checked stage: the
colliding mesh prims get a time-sampled ``primvars:displayColor`` (red while they penetrate,
their own constant colour or grey otherwise); instance proxies are coloured through their
instanceable ancestor, PointInstancer instances through the instancer's per-instance
``displayColor`` (``vertex`` interpolation); with segments, the intersection segments of every
frame are one ``BasisCurves`` prim.

**Clearance** (``clearance=D``, :mod:`~warp_ccd.usd.clearance`): the pipeline also reports the prim
pairs within ``D`` of each other; those a frame does not report as collisions are its *soft clashes*,
with their least distance, closest points and USD faces (:attr:`FrameContacts.soft_clashes`). In the
overlay a prim in a soft clash is yellow at that time code (red and orange win), and each soft
clash's closest points are joined by a curve.

**Self-intersection** (``self_intersections=True``, :mod:`~warp_ccd.usd.self_intersection`): the pipeline
also reports each prim's own triangles that meet beyond the vertices they share, as pairs of its USD
faces with their depth (:attr:`FrameContacts.self_intersections`). In the overlay a prim through itself
is magenta at that time code (red and orange win).

**Continuous** (``continuous=True``, :mod:`~warp_ccd.usd.sweep`): one continuous pipeline more, whose
every detection covers the linear motion since the previous time code, reports per interval between
consecutive time codes the prim pairs that touch at some time in it (:attr:`CheckReport.intervals`),
and marks *tunnelling* those that neither end frame shows intersecting. In the overlay a prim that
tunnels in the interval starting at a time code is orange there (red still wins: it penetrates), and
its ``warpCcd:tunnelling`` attribute is true there.

**Duplicates** (``duplicates=True``, :mod:`~warp_ccd.usd.duplicates`): a pair the detection reports whose
world-space triangle sets coincide (the same geometry placed twice at the same place, a common fault of CAD
exports) is a *duplicate* at that frame (:attr:`FrameContacts.duplicates`), not a touching or penetrating
pair: its rows leave the frame's collisions (and it is no soft clash). In the overlay a duplicate prim is
blue at that time code (red, orange and magenta win). A finding after self-intersections.

**The JSON report** (:meth:`CheckReport.to_json`) carries ``"schema_version"`` (:data:`SCHEMA_VERSION`) and
follows the JSON Schema (draft 2020-12) shipped beside this module, ``report.schema.json``
(:data:`REPORT_SCHEMA_PATH`; :func:`report_schema` returns it as a dict). Every object in it lists its
fields (``additionalProperties: false``), so a report with a field the schema does not know fails
validation. The version's policy: the minor number grows when optional fields are added (a reader of
``1.x`` reads every later ``1.y``), the major number when a field is removed or changes its meaning or
type. ``1.1`` added the ``filters`` section.

**Filters** (:mod:`~warp_ccd.usd.filters`): pairs of two ``worlds``, excluded pairs (``ignore_pairs``, the
stage's ``UsdPhysics`` filters) and, with ``set_a`` / ``set_b``, pairs not of one prim of each set are dropped
by the broad phase (so for every kind of check; self-intersection, per prim, is not filtered).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import TYPE_CHECKING, Any

import numpy as np

from .._typing import DeviceLike, PathLike
from ..geometry.triangle import TOLERANCE
from ..options import number_option
from ..output import PendingFile, check_output_path
from ..stages.clearance import CLEARANCE_MAX
from ..stages.crossing import CrossingClassifier
from .clearance import (
    COLOR_CLEARANCE,
    COLOR_SOFT_CLASH,
    SoftClashes,
    clearance_json,
    clearance_summary,
    frame_clearance_json,
    soft_clash_flags,
    soft_clashes,
)
from .duplicates import (
    COLOR_DUPLICATE,
    REL_TOL,
    duplicate_flags,
    duplicate_pairs,
    duplicates_json,
    duplicates_summary,
    frame_duplicates_json,
)
from .export import COLOR_COLLIDING, COLOR_FREE, COLOR_SEGMENT, segment_points, validate_stage_path
from .filters import FilterSummary, PairFilters
from .self_intersection import (
    COLOR_SELF,
    SelfIntersections,
    frame_self_json,
    self_flags,
    self_json,
    self_summary,
)
from .self_intersection import self_intersections as find_self_intersections
from .sweep import COLOR_TUNNELLING, sweep_interval, sweep_json, sweep_summary, tunnelling_flags
from .tables import pair_table, span

if TYPE_CHECKING:
    from pxr import Usd

__all__ = ["REPORT_SCHEMA_PATH", "SCHEMA_VERSION", "CheckReport", "FrameContacts", "check_usd", "prepare_overlay",
           "report_schema", "write_overlay"]

SCHEMA_VERSION = "1.1"
"""The version of the JSON report's layout (``"schema_version"`` in it): ``MAJOR.MINOR``, the minor number
raised when optional fields are added, the major one when a field is removed or changes meaning or type."""
REPORT_SCHEMA_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "report.schema.json")
"""The JSON Schema (draft 2020-12) of :meth:`CheckReport.to_json`, shipped with the package."""

COLOR_PENETRATING = COLOR_COLLIDING
"""displayColor of a prim while it penetrates another (the animation writer's colliding colour)."""
COLOR_CLEAR = COLOR_FREE
"""displayColor of a coloured prim in frames where it penetrates nothing (when it had no constant colour)."""


@cache
def _schema_text() -> str:
    with open(REPORT_SCHEMA_PATH, encoding="utf-8") as fh:
        return fh.read()


def report_schema() -> dict:
    """The JSON Schema (draft 2020-12) that every :meth:`CheckReport.to_json` (and ``warp-ccd check
    --report``) follows, as a new dict (a caller may change it).

    >>> import jsonschema
    >>> jsonschema.validate(report.to_json(), report_schema())
    """
    return json.loads(_schema_text())


@dataclass
class FrameContacts:
    """What one time code found.

    Attributes:
        time: the time code.
        triangle_pairs: ``(M, 4)`` int32 rows ``(obj_a, face_a, obj_b, face_b)`` of penetrating
            (or, with ``count_touching``, all) triangle pairs, USD face indices, sorted by
            ``(obj_a, obj_b, face_a, face_b)`` and unique (two triangles of one polygon meeting one
            face count once).
        depth: ``(M,)`` float64, the deepest crossing of each row, scene units.
        segments: ``(M, 2, 3)`` float64 intersection segments of the rows (the first triangle
            pair of each), or None.
        num_touching: face pairs that only touch (depth <= ``min_depth``) and are not reported.
        soft_clashes: with a clearance, the :class:`~warp_ccd.usd.clearance.SoftClashes` (prim pairs
            within it that the frame does not report as collisions), else None.
        self_intersections: with ``self_intersections``, the
            :class:`~warp_ccd.usd.self_intersection.SelfIntersections` (prims through themselves), else None.
        duplicates: with ``duplicates``, ``(D, 2)`` int32 object pairs ``(a, b)``, ``a < b``, sorted, whose
            meshes coincide at this time code (:mod:`~warp_ccd.usd.duplicates`; their rows are not in
            ``triangle_pairs`` nor counted in ``num_touching``), else None.
    """

    time: float
    triangle_pairs: np.ndarray
    depth: np.ndarray
    segments: np.ndarray | None = None
    num_touching: int = 0
    soft_clashes: SoftClashes | None = None
    self_intersections: SelfIntersections | None = None
    duplicates: np.ndarray | None = None

    @property
    def object_pairs(self) -> np.ndarray:
        """``(K, 2)`` int32 object pairs ``(a, b)``, ``a < b``, sorted."""
        if len(self.triangle_pairs) == 0:
            return np.zeros((0, 2), np.int32)
        return np.unique(self.triangle_pairs[:, [0, 2]], axis=0).astype(np.int32)


@dataclass
class CheckReport:
    """The result of :func:`check_usd`.

    Attributes:
        stage: the stage's file path (or its in-memory identifier).
        object_path: ``N`` object names (prim paths; ``instancer[i]/...`` for point instances).
        frames: one :class:`FrameContacts` per time code checked, in order.
        min_depth: the depth a triangle pair must exceed to penetrate.
        count_touching: touching pairs were reported as collisions too.
        device: where the pipeline ran.
        seconds: wall time of ``read`` (opening, traversal, topology, transforms at every time
            code), ``build`` (scene, trees, pipeline), ``set`` (moving the scene to each frame:
            poses, deforming points read and copied), ``detect`` (the pipeline's frames) and
            ``classify`` (depths, USD faces, the report's rows).
        skipped: ``(path, reason)`` of the meshes left out.
        missing: the sublayers, references and payloads that could not be opened (checked
            without them; see :func:`~warp_ccd.usd.stage.missing_layers`).
        source: the :class:`~warp_ccd.usd.importer.UsdMeshImport` (its scene is at the last frame).
        intervals: with ``continuous``, one :class:`~warp_ccd.usd.sweep.SweepInterval` per pair of
            consecutive time codes; None otherwise.
        min_distance: with ``continuous``, the distance within which surfaces count as touching.
        ccd_tolerance: with ``continuous``, the continuous test's distance tolerance.
        clearance: the distance of soft clashes (0: none sought).
        self_checked: whether self-intersections were sought.
        duplicates_checked: whether duplicates (coincident meshes) were sought.
        filters: the :class:`~warp_ccd.usd.filters.FilterSummary` of the worlds, excluded pairs and sets
            (the report's ``filters`` section when any was used), or None.
    """

    stage: str
    object_path: list
    frames: list = field(default_factory=list)
    min_depth: float = 0.0
    count_touching: bool = False
    device: str = ""
    seconds: dict = field(default_factory=dict)
    skipped: list = field(default_factory=list)
    missing: list = field(default_factory=list)
    source: object = field(default=None, repr=False, compare=False)
    intervals: list | None = None
    min_distance: float = 0.0
    ccd_tolerance: float = 0.0
    clearance: float = 0.0
    self_checked: bool = False
    duplicates_checked: bool = False
    filters: FilterSummary | None = None

    @property
    def duplicated(self) -> bool:
        """Whether any frame has a pair of coincident meshes (``duplicates`` checks)."""
        return any(f.duplicates is not None and len(f.duplicates) > 0 for f in self.frames)

    @property
    def self_intersecting(self) -> bool:
        """Whether any frame has a prim that intersects itself (``self_intersections`` checks)."""
        return any(f.self_intersections is not None and len(f.self_intersections.face_pairs) > 0
                   for f in self.frames)

    @property
    def soft_clash(self) -> bool:
        """Whether any frame has a soft clash (a pair within the clearance not reported as a collision)."""
        return any(f.soft_clashes is not None and len(f.soft_clashes.object_pairs) > 0 for f in self.frames)

    @property
    def tunnelling(self) -> bool:
        """Whether a pair touches between two time codes where neither shows it intersecting
        (continuous checks only)."""
        return any(bool(iv.tunnelling.any()) for iv in self.intervals or ())

    @property
    def penetrating(self) -> bool:
        """Whether any frame has a penetrating pair: one that crosses deeper than ``min_depth``
        (with ``count_touching``, touching rows are reported but do not make this true)."""
        return any(bool((f.depth > self.min_depth).any()) for f in self.frames)

    @property
    def touching(self) -> bool:
        """Whether any frame has a touching pair (crossing no deeper than ``min_depth``), reported
        (``count_touching``) or only counted."""
        return any(f.num_touching > 0 or bool((f.depth <= self.min_depth).any()) for f in self.frames)

    @property
    def findings(self) -> str | None:
        """What the check found, as the command's exit status reads it: ``"penetrating"`` when a
        pair penetrates, else ``"tunnelling"`` when a continuous check found a pair touching only
        between time codes, else ``"self_intersecting"`` when a prim passes through itself, else
        ``"duplicates"`` when two prims' meshes coincide (``duplicates`` checks), else
        ``"soft_clash"`` when a pair comes within the clearance, else
        ``"touching"`` when pairs touch and ``count_touching`` counts them as collisions, else None
        (exit status 0)."""
        if self.penetrating:
            return "penetrating"
        if self.tunnelling:
            return "tunnelling"
        if self.self_intersecting:
            return "self_intersecting"
        if self.duplicated:
            return "duplicates"
        if self.soft_clash:
            return "soft_clash"
        if self.count_touching and self.touching:
            return "touching"
        return None

    @property
    def worst_frame(self) -> int:
        """Index of the frame with the most penetrating triangle pairs (the first of equals; 0 if none)."""
        counts = [len(f.triangle_pairs) for f in self.frames]
        return int(np.argmax(counts)) if counts else 0

    def pair_summary(self) -> list[dict]:
        """Per prim pair that penetrates in some frame: ``a``, ``b`` (names), ``frames`` (how many),
        ``first`` and ``last`` time codes, ``max_triangle_pairs`` in one frame and ``max_depth``;
        most frames first."""
        stats: dict[tuple[int, int], dict] = {}
        for f in self.frames:
            if not len(f.triangle_pairs):
                continue
            keys, inverse, counts = np.unique(f.triangle_pairs[:, [0, 2]], axis=0, return_inverse=True,
                                              return_counts=True)
            deepest = np.zeros(len(keys))
            np.maximum.at(deepest, inverse.reshape(-1), f.depth)
            for (a, b), c, d in zip(keys.tolist(), counts.tolist(), deepest.tolist()):
                s = stats.setdefault((a, b), {"a": self.object_path[a], "b": self.object_path[b], "frames": 0,
                                              "first": f.time, "last": f.time, "max_triangle_pairs": 0,
                                              "max_depth": 0.0})
                s["frames"] += 1
                s["last"] = f.time
                s["max_triangle_pairs"] = max(s["max_triangle_pairs"], c)
                s["max_depth"] = max(s["max_depth"], d)
        return sorted(stats.values(), key=lambda s: (-s["frames"], s["first"], s["a"], s["b"]))

    def to_json(self) -> dict:
        """The report as JSON-ready data: prims by path, faces by their USD face index.

        It follows :func:`report_schema` (its ``"schema_version"`` is :data:`SCHEMA_VERSION`)."""
        frames = []
        for f in self.frames:
            pairs = []
            rows = f.triangle_pairs
            if len(rows):
                keys, first = np.unique(rows[:, [0, 2]], axis=0, return_index=True)
                ends = list(first[1:]) + [len(rows)]
                for (a, b), s, e in zip(keys.tolist(), first.tolist(), ends):
                    entry = {"a": self.object_path[a], "b": self.object_path[b],
                             "faces": rows[s:e][:, [1, 3]].tolist(),
                             "max_depth": float(f.depth[s:e].max())}
                    if f.segments is not None:
                        entry["segments"] = np.where(np.isfinite(f.segments[s:e]), f.segments[s:e], None).tolist()
                    pairs.append(entry)
            entry = {"time": f.time, "triangle_pairs": int(len(rows)), "touching_pairs": int(f.num_touching),
                     "pairs": pairs}
            if f.soft_clashes is not None:
                entry["soft_clashes"] = frame_clearance_json(f.soft_clashes, self.object_path)
            if f.self_intersections is not None:
                entry["self_intersections"] = frame_self_json(f.self_intersections, self.object_path)
            if f.duplicates is not None:
                entry["duplicates"] = frame_duplicates_json(f.duplicates, self.object_path)
            frames.append(entry)
        with_contacts = [f.time for f in self.frames if len(f.triangle_pairs)]
        out = {
            "schema_version": SCHEMA_VERSION,
            "stage": self.stage,
            "findings": self.findings,
            "penetrating": self.penetrating,
            "touching": self.touching,
            "min_depth": self.min_depth,
            "count_touching": self.count_touching,
            "device": self.device,
            "times": [f.time for f in self.frames],
            "frames_with_contacts": with_contacts,
            "objects": len(self.object_path),
            "skipped": [{"prim": p, "reason": r} for p, r in self.skipped],
            "missing": list(self.missing),
            "pairs": self.pair_summary(),
            "frames": frames,
            "seconds": self.seconds,
        }
        if self.intervals is not None:
            out["tunnelling"] = self.tunnelling
            out["continuous"] = sweep_json(self.intervals, self.object_path, self.min_distance, self.ccd_tolerance)
        if self.clearance > 0.0:
            out["soft_clash"] = self.soft_clash
            out["clearance"] = clearance_json(self.frames, self.object_path, self.clearance)
        if self.self_checked:
            out["self_intersecting"] = self.self_intersecting
            out["self_intersections"] = self_json(self.frames, self.object_path)
        if self.duplicates_checked:
            out["duplicated"] = self.duplicated
            out["duplicates"] = duplicates_json(self.frames, self.object_path, REL_TOL)
        if self.filters is not None and self.filters.used:
            out["filters"] = self.filters.to_json()
        return out

    def json_text(self) -> str:
        """:meth:`to_json` as the text the report file holds (what ``--report -`` prints), newline-terminated."""
        return json.dumps(self.to_json(), indent=1) + "\n"

    def write_json(self, path: PathLike) -> str:
        """Writes :meth:`to_json` to ``path`` (``.json``) through a temporary file moved into place.

        Returns:
            The absolute path written.
        """
        return self.prepare_json(path).commit()

    def prepare_json(self, path: PathLike) -> PendingFile:
        """Writes :meth:`to_json` to a temporary file beside ``path`` (``.json``), not yet in place.

        Returns:
            The :class:`~warp_ccd.output.PendingFile`: :meth:`~warp_ccd.output.PendingFile.commit`
            moves it to ``path``, :meth:`~warp_ccd.output.PendingFile.discard` removes it.
        """
        full, _ = check_output_path(path, (".json",), "report")
        text = self.json_text()
        pending = PendingFile(full)
        try:
            with open(pending.temp_path, "w", encoding="utf-8") as fh:
                fh.write(text)
        except BaseException:
            pending.discard()
            raise
        return pending

    def summary(self, top: int = 10) -> str:
        """A few lines for a terminal: frames with contacts, USD face pairs per frame, the prim
        pairs that collide most, times."""
        n = len(self.frames)
        hit = [f for f in self.frames if len(f.triangle_pairs)]
        per_frame = np.array([len(f.triangle_pairs) for f in self.frames])
        touching = np.array([f.num_touching for f in self.frames])
        what = "penetrating" if not self.count_touching else "intersecting (touching included)"
        lines = [f"{self.stage}: {len(self.object_path)} objects, {n} frames on {self.device}",
                 f"  frames with {what} pairs: {len(hit)} of {n}"
                 + (f" ({hit[0].time:g} .. {hit[-1].time:g})" if hit else ""),
                 f"  face pairs / frame: {what} mean {per_frame.mean() if n else 0.0:.1f}, "
                 f"max {per_frame.max(initial=0)}"
                 + ("" if self.count_touching else f"; touching only, not counted: mean "
                    f"{touching.mean() if n else 0.0:.1f}, max {touching.max(initial=0)}")]
        if self.missing:
            lines.append(f"  not checked, cannot be opened: {', '.join(self.missing)}")
        if self.filters is not None:
            lines[1:1] = self.filters.summary_lines()
        pairs = self.pair_summary()
        ws = max([11] + [len(span(p)) for p in pairs[:top]])
        lines += pair_table(pairs, top, f"frames  {'first..last':<{ws}}  max face pairs  max depth",
                            lambda p: f"{p['frames']:6d}  {span(p):<{ws}}  {p['max_triangle_pairs']:14d}  "
                                      f"{p['max_depth']:.3g}")
        if self.intervals is not None:
            lines += sweep_summary(self.intervals, self.object_path, self.min_distance, top)
        if self.clearance > 0.0:
            lines += clearance_summary(self.frames, self.object_path, self.clearance, top)
        if self.self_checked:
            lines += self_summary(self.frames, self.object_path, top)
        if self.duplicates_checked:
            lines += duplicates_summary(self.frames, self.object_path, top)
        s = self.seconds
        if s:
            per = s.get("detect", 0.0) / max(n, 1) * 1e3
            lines.append(f"  seconds: read {s.get('read', 0):.2f}, build {s.get('build', 0):.2f}, "
                         f"set frames {s.get('set', 0):.2f}, detect {s.get('detect', 0):.2f} ({per:.2f} ms/frame), "
                         f"classify {s.get('classify', 0):.2f}"
                         + (f", continuous {s.get('continuous', 0):.2f}" if self.intervals is not None else ""))
        return "\n".join(lines)


def _frame_contacts(imp, res, depth: np.ndarray, min_depth: float, count_touching: bool, segments: bool,
                    time_code: float, duplicates: bool = False) -> FrameContacts:
    """One frame's rows in USD faces, one per (object, face) pair with its deepest crossing; the
    penetrating ones kept, the others counted. With ``duplicates``, the object pairs whose meshes
    coincide are found among the rows' pairs and their rows left out."""
    rows = res.device_triangle_pairs.numpy().reshape(-1, 4).astype(np.int64)
    seg = res.device_segments.numpy().reshape(-1, 2, 3).astype(np.float64) if segments else None
    dup = None
    if duplicates:
        dup = duplicate_pairs(imp.scene, np.unique(rows[:, [0, 2]], axis=0)) if len(rows) else np.zeros((0, 2),
                                                                                                       np.int32)
        if len(dup):
            n = imp.scene.num_objects
            gone = np.isin(rows[:, 0] * n + rows[:, 2], dup[:, 0].astype(np.int64) * n + dup[:, 1])
            rows, depth = rows[~gone], depth[~gone]
            seg = seg[~gone] if seg is not None else None
    faces = np.stack([rows[:, 0], imp.faces(rows[:, 0], rows[:, 1]), rows[:, 2],
                      imp.faces(rows[:, 2], rows[:, 3])], axis=1).astype(np.int32)
    if len(faces):
        # By (a, b, fa, fb), deepest first, then by triangles: the same row (and segment) on every
        # device, whatever order the device's hits came in.
        order = np.lexsort((rows[:, 3], rows[:, 1], -depth, faces[:, 3], faces[:, 1], faces[:, 2], faces[:, 0]))
        faces, depth = faces[order], depth[order]
        first = np.ones(len(faces), bool)
        first[1:] = (faces[1:] != faces[:-1]).any(axis=1)
        faces, depth = faces[first], depth[first]
        seg = seg[order][first] if seg is not None else None
    keep = np.ones(len(faces), bool) if count_touching else depth > min_depth
    return FrameContacts(float(time_code), faces[keep].reshape(-1, 4), depth[keep],
                         seg[keep] if seg is not None else None, int((~keep).sum()), duplicates=dup)


def check_usd(stage_or_path: Usd.Stage | PathLike, *, frames: slice | Sequence[float] | None = None,
              prims: str | Sequence[str] | None = None, device: DeviceLike = None, precision: str = "float32",
              min_depth: float = 0.0, count_touching: bool = False, segments: bool = False,
              include_invisible: bool = False, include_purposes: Sequence[str] = (), tolerance: float = TOLERANCE,
              progress: bool = False, allow_missing: bool = False, continuous: bool = False,
              min_distance: float = 0.0, clearance: float = 0.0, self_intersections: bool = False,
              duplicates: bool = False, worlds: str | Sequence[str] | None = None,
              ignore_pairs: PathLike | Sequence[Any] | None = None, usd_filters: bool = True,
              set_a: str | Sequence[str] | None = None, set_b: str | Sequence[str] | None = None) -> CheckReport:
    """Finds, frame by frame, the meshes of a USD stage whose surfaces pass through each other.

    Args:
        stage_or_path: a ``Usd.Stage`` or a USD file path.
        frames: time codes (see :func:`~warp_ccd.usd.stage.stage_time_codes`; default: every
            integer time code of the stage's range).
        prims: prim paths or patterns to check (default: the whole stage).
        device: Warp device (default: Warp's preferred device).
        precision: ``"float32"`` or ``"float64"``; float32 becomes float64, with a
            :class:`~warp_ccd.geometry.precision.PrecisionWarning` (``report.source.precision_note``), where
            the coordinates are too far from the origin for it at the triangles' size
            (:func:`~warp_ccd.geometry.precision.needed_precision`).
        min_depth: a triangle pair penetrates when its crossing depth exceeds this (scene units, >= 0).
        count_touching: report touching pairs (depth <= ``min_depth``) as collisions too.
        segments: keep the intersection segments (for the report and the overlay).
        include_invisible: also check invisible prims.
        include_purposes: also check prims of these purposes (``"guide"``, ``"proxy"``).
        tolerance: relative tolerance of the triangle test.
        progress: show progress bars on stderr (reading the transforms of every time code, then
            the frames).
        allow_missing: check a stage whose sublayers, references or payloads cannot all be
            opened (without them; :attr:`CheckReport.missing` lists them) instead of raising; likewise
            an ``ignore_pairs`` pair naming no prim, a ``worlds``, ``set_a`` or ``set_b`` pattern matching no
            checked mesh: a note in the report (``filters.notes``) instead of a ValueError.
        continuous: also report, per interval between consecutive time codes, the prim pairs that
            touch at some time in it (every vertex moving linearly between its positions at the
            two time codes), and which of them tunnel (:attr:`CheckReport.intervals`).
        min_distance: with ``continuous``, pairs that come within this distance (scene units,
            >= 0) count as touching.
        clearance: also report, per frame, the prim pairs within this distance (scene units, >= 0)
            that the frame does not report as collisions: soft clashes (:attr:`FrameContacts.soft_clashes`).
        self_intersections: also report, per frame, the prims that pass through themselves, as pairs of
            their USD faces with a depth (:attr:`FrameContacts.self_intersections`).
        duplicates: report, per frame, the pairs whose meshes coincide (the same triangles at the same
            place, :mod:`~warp_ccd.usd.duplicates`) as duplicates (:attr:`FrameContacts.duplicates`) instead
            of as collisions.
        worlds: prim paths or ``fnmatch`` patterns, every prim they match rooting a world: pairs of two
            worlds are never checked (meshes under no root pair with every world; see
            :class:`~warp_ccd.usd.importer.UsdMeshImport`).
        ignore_pairs: prim pairs never checked: an ignore-pairs file (text: two prim paths or patterns a
            line, separated by whitespace or a comma, ``#`` comments; ``.json``: a list of ``[a, b]``), or
            a sequence of such files and ``(a, b)`` pairs. Every mesh at or under ``a`` is excluded against
            every mesh at or under ``b`` (:mod:`~warp_ccd.usd.filters`).
        usd_filters: also exclude the pairs the stage's ``UsdPhysics.FilteredPairsAPI`` and
            ``UsdPhysics.CollisionGroup`` prims filter out.
        set_a: prim paths or patterns (a string may hold several, comma-separated): with ``set_b``, only
            pairs of one mesh of set A and one of set B are checked (a mesh may be in both).
        set_b: the other set, given with ``set_a``.

    Returns:
        The :class:`CheckReport`.

    Raises:
        ValueError: naming the file or prim: see :class:`~warp_ccd.usd.importer.UsdMeshImport`; or
            a sublayer, reference or payload cannot be opened (unless ``allow_missing``); a bad
            ``ignore_pairs`` file (naming it and the line), a pair naming no prim, a pattern matching
            no checked mesh (unless ``allow_missing``), ``set_a`` without ``set_b``.
    """
    import warp as wp
    from tqdm import tqdm

    from ..pipeline import CollisionPipeline
    from .importer import UsdMeshImport
    from .stage import open_stage, require_layers, stage_time_codes

    number_option("min_depth", min_depth, low=0.0)
    number_option("min_distance", min_distance, low=0.0)
    clearance = number_option("clearance", clearance, low=0.0, high=CLEARANCE_MAX)
    if min_distance > 0.0 and not continuous:
        raise ValueError(f"min_distance is an option of the continuous check (continuous=True), got {min_distance!r}")
    filters = PairFilters(ignore_pairs=ignore_pairs, usd_filters=usd_filters, set_a=set_a, set_b=set_b,
                          allow_missing=allow_missing)
    t = time.perf_counter()
    stage = open_stage(stage_or_path)
    missing = require_layers(stage, allow_missing)
    times = stage_time_codes(stage, frames)
    opened = time.perf_counter() - t
    imp = UsdMeshImport(stage, prims=prims, times=times, include_invisible=include_invisible,
                        include_purposes=include_purposes, device=device, precision=precision, progress=progress,
                        worlds=worlds, filters=filters)
    seconds = dict(imp.seconds)
    seconds["read"] += opened  # the import got the stage open
    t = time.perf_counter()
    scene = imp.scene
    pipe = CollisionPipeline(scene, segments=segments, tolerance=tolerance, clearance=clearance,
                             self_intersections=bool(self_intersections))
    classify = CrossingClassifier(scene, tolerance=tolerance, trees=pipe.boxes)
    # One continuous pipeline for the whole animation: each detect covers the motion since the last.
    sweep = CollisionPipeline(scene, continuous=True, min_distance=min_distance) if continuous else None
    seconds["build"] += time.perf_counter() - t
    seconds["set"] = seconds["detect"] = seconds["classify"] = 0.0
    if continuous:
        seconds["continuous"] = 0.0
    name = stage.GetRootLayer().realPath or stage.GetRootLayer().identifier
    report = CheckReport(name, list(imp.object_path), min_depth=float(min_depth),
                         count_touching=bool(count_touching), device=str(scene.device), skipped=list(imp.skipped),
                         clearance=clearance, self_checked=bool(self_intersections),
                         duplicates_checked=bool(duplicates), filters=imp.filters)
    if continuous:
        report.intervals = []
        report.min_distance = float(min_distance)
        report.ccd_tolerance = float(sweep.narrow.tolerance)
    intersecting = None  # the object pairs of the previous time code (touching included)
    bar = tqdm(range(len(times)), desc="frames", unit="frame", disable=not progress or None, leave=False)
    for k in bar:
        t = time.perf_counter()
        imp.set_frame(k)
        t1 = time.perf_counter()
        res = pipe.detect()
        t_detect = time.perf_counter()
        pairs = res.device_triangle_pairs
        _, depth = classify(pairs)  # 0 where the surfaces only touch
        contacts = _frame_contacts(imp, res, depth, float(min_depth), count_touching, segments, times[k],
                                   bool(duplicates))
        if clearance > 0.0:
            reported = contacts.object_pairs
            if contacts.duplicates is not None and len(contacts.duplicates):  # a duplicate is no soft clash
                reported = np.unique(np.concatenate([reported, contacts.duplicates]), axis=0)
            contacts.soft_clashes = soft_clashes(imp, res, reported)
        if self_intersections:
            contacts.self_intersections = find_self_intersections(imp, res, pipe.self_phase)
        t2 = time.perf_counter()
        seconds["set"] += t1 - t
        seconds["detect"] += t_detect - t1
        seconds["classify"] += t2 - t_detect
        report.frames.append(contacts)
        if continuous:
            t3 = time.perf_counter()
            now = res.intersecting_pairs  # the discrete result's, read before it can change
            if k == 0:
                wp.copy(sweep.world_vertex_start, scene.world_vertex)  # the motion starts at the first time code
            else:
                report.intervals.append(sweep_interval(imp, sweep.detect(), times[k - 1], times[k], intersecting, now))
            intersecting = now
            seconds["continuous"] += time.perf_counter() - t3
        bar.set_postfix(pairs=len(contacts.triangle_pairs), refresh=False)
    bar.close()
    wp.synchronize_device(scene.device)
    report.seconds = {k: round(v, 4) for k, v in seconds.items()}
    report.source = imp
    report.missing = missing
    return report


def write_overlay(report: CheckReport, out_path: PathLike) -> str:
    """Writes a USD layer over the checked stage: penetrating prims in colour per frame (with a
    continuous check, tunnelling prims in orange at the start of the interval, and their
    ``warpCcd:tunnelling`` attribute; with a clearance, prims in a soft clash in yellow; with
    duplicates, prims that coincide with another in blue), and as
    curves the intersection segments (when the check kept them) and the soft clashes' closest points.

    The layer's only sublayer is the checked stage's file (a relative path when they share a
    folder), so it opens as the animation with the overlay on top. Written to a temporary file
    and moved into place (:func:`prepare_overlay`).

    Args:
        report: a :class:`CheckReport` of a stage read from a file.
        out_path: ``.usd``, ``.usdc`` or ``.usda``.

    Returns:
        The absolute path written.

    Raises:
        ValueError: the checked stage was not a file, ``out_path`` is one of its layers' files, or
            the destination cannot be written.
    """
    return prepare_overlay(report, out_path).commit()


def prepare_overlay(report: CheckReport, out_path: PathLike) -> PendingFile:
    """Writes the overlay of :func:`write_overlay` to a temporary file beside ``out_path``, not yet in place.

    Returns:
        The :class:`~warp_ccd.output.PendingFile`: :meth:`~warp_ccd.output.PendingFile.commit`
        moves it to ``out_path``, :meth:`~warp_ccd.output.PendingFile.discard` removes it.

    Raises:
        ValueError: as :func:`write_overlay`.
    """
    from pxr import Gf, Sdf, Usd, UsdGeom, Vt

    from .stage import layer_files

    full, ext = validate_stage_path(out_path)
    imp = report.source
    source = imp.stage.GetRootLayer().realPath
    if not source:
        raise ValueError("overlay: the checked stage is not a file (save it first)")
    if os.path.realpath(full) in layer_files(imp.stage):
        raise ValueError(f"cannot write {out_path}: it is a layer of the checked stage ({os.path.realpath(full)})")
    pending = PendingFile(full)
    try:
        layer = Sdf.Layer.CreateAnonymous(ext)
        layer.subLayerPaths.append(source)
        stage = Usd.Stage.Open(layer)
        src = imp.stage
        stage.SetStartTimeCode(src.GetStartTimeCode())
        stage.SetEndTimeCode(src.GetEndTimeCode())
        stage.SetTimeCodesPerSecond(src.GetTimeCodesPerSecond())
        stage.SetFramesPerSecond(src.GetFramesPerSecond())
        n = len(report.object_path)
        hit = np.zeros((len(report.frames), n), bool)
        for k, f in enumerate(report.frames):
            hit[k, f.triangle_pairs[:, [0, 2]].ravel()] = True
        times = [f.time for f in report.frames]
        # Tunnelling in the interval that starts at a time code (continuous checks): orange there; a
        # soft clash (clearance checks), yellow where neither is.
        tunnel = tunnelling_flags(report.intervals or (), times, n)
        soft = soft_clash_flags(report.frames, n)
        mine = self_flags(report.frames, n)  # a prim through itself (self checks): magenta, after red and orange
        twin = duplicate_flags(report.frames, n)  # a duplicate (duplicates checks): blue, after magenta
        red, orange, yellow = Gf.Vec3f(*COLOR_PENETRATING), Gf.Vec3f(*COLOR_TUNNELLING), Gf.Vec3f(*COLOR_SOFT_CLASH)
        magenta, blue = Gf.Vec3f(*COLOR_SELF), Gf.Vec3f(*COLOR_DUPLICATE)
        with Sdf.ChangeBlock():
            # Prims (instance proxies through their instanceable ancestor), one colour per frame.
            targets: dict[str, tuple[np.ndarray, ...]] = {}
            for i in np.nonzero((hit | tunnel | soft | mine | twin).any(axis=0))[0].tolist():
                if imp.object_instancer[i] is not None:
                    continue
                prim = src.GetPrimAtPath(imp.object_path[i])
                while prim.IsInstanceProxy():
                    prim = prim.GetParent()
                key = str(prim.GetPath())
                was = targets.get(key, (np.zeros(len(times), bool),) * 5)
                targets[key] = (was[0] | hit[:, i], was[1] | tunnel[:, i], was[2] | soft[:, i], was[3] | mine[:, i],
                                was[4] | twin[:, i])
            for path, (flags, tunnels, softs, selfs, twins) in targets.items():
                prim = stage.GetPrimAtPath(path)
                primvar = UsdGeom.PrimvarsAPI(prim).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray,
                                                                  UsdGeom.Tokens.constant)
                clear = Gf.Vec3f(*COLOR_CLEAR)
                own = UsdGeom.PrimvarsAPI(src.GetPrimAtPath(path)).GetPrimvar("displayColor")
                if own and own.GetInterpolation() == UsdGeom.Tokens.constant and own.Get() is not None \
                        and len(own.Get()) == 1:
                    clear = own.Get()[0]
                for tc, f, g, m, d, y in zip(times, flags.tolist(), tunnels.tolist(), selfs.tolist(), twins.tolist(),
                                             softs.tolist()):
                    color = red if f else orange if g else magenta if m else blue if d else yellow if y else clear
                    primvar.Set(Vt.Vec3fArray([color]), tc)
                if report.intervals is not None:
                    flag = prim.CreateAttribute("warpCcd:tunnelling", Sdf.ValueTypeNames.Bool, custom=True)
                    for tc, g in zip(times, tunnels.tolist()):
                        flag.Set(bool(g), tc)
            # PointInstancer instances: the instancer's per-instance colour.
            instancer = np.array(imp.object_instancer, dtype=object)
            for path in sorted({p for p in imp.object_instancer if p is not None}):
                rows = np.nonzero(instancer == path)[0]
                if not (hit[:, rows] | tunnel[:, rows] | soft[:, rows] | mine[:, rows] | twin[:, rows]).any():
                    continue
                schema = UsdGeom.PointInstancer(src.GetPrimAtPath(path))
                size = len(np.asarray(schema.GetProtoIndicesAttr().Get(Usd.TimeCode(times[0]))))
                prim = stage.GetPrimAtPath(path)
                primvar = UsdGeom.PrimvarsAPI(prim).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray,
                                                                  UsdGeom.Tokens.vertex)
                for k, tc in enumerate(times):
                    colors = np.tile(np.asarray(COLOR_CLEAR, np.float32), (size, 1))
                    colors[imp.object_instance[rows][soft[k, rows]]] = COLOR_SOFT_CLASH
                    colors[imp.object_instance[rows][twin[k, rows]]] = COLOR_DUPLICATE
                    colors[imp.object_instance[rows][mine[k, rows]]] = COLOR_SELF
                    colors[imp.object_instance[rows][tunnel[k, rows]]] = COLOR_TUNNELLING
                    colors[imp.object_instance[rows][hit[k, rows]]] = COLOR_PENETRATING
                    primvar.Set(Vt.Vec3fArray.FromNumpy(colors), tc)
        # Defined outside the change block: a new prim needs the stage recomposed. The intersection
        # segments, and the soft clashes' closest points joined, as time-sampled curves.
        curves = []
        world = imp.scene.world_vertex.numpy()
        width = float(np.max(world.max(axis=0) - world.min(axis=0))) * 2e-3 if len(world) else 0.0
        for name, color, parts in (("Segments", COLOR_SEGMENT, [f.segments for f in report.frames]),
                                   ("Clearance", COLOR_CLEARANCE, [None if f.soft_clashes is None
                                                                   else f.soft_clashes.points for f in report.frames])):
            if all(p is None for p in parts):
                continue
            curve = UsdGeom.BasisCurves.Define(stage, f"/WarpCcdCheck/{name}")
            curve.CreateTypeAttr(UsdGeom.Tokens.linear)
            curve.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(Vt.Vec3fArray([Gf.Vec3f(*color)]))
            curve.CreateWidthsAttr(Vt.FloatArray([width or 1e-3]))
            curve.SetWidthsInterpolation(UsdGeom.Tokens.constant)
            counts, points = curve.CreateCurveVertexCountsAttr(), curve.CreatePointsAttr()
            for f, part in zip(report.frames, parts):
                ends = segment_points(part if part is not None else np.zeros((0, 2, 3)))
                counts.Set(Vt.IntArray.FromNumpy(np.full(len(ends) // 2, 2, np.int32)), f.time)
                points.Set(Vt.Vec3fArray.FromNumpy(ends), f.time)
            curves.append(curve)
        del stage, curves  # closed before the sublayer path changes (no recomposition against the wrong folder)
        rel = os.path.relpath(source, os.path.dirname(full))
        if not rel.startswith(".."):  # beside the overlay, or below it: a relative path that moves with both
            layer.subLayerPaths[0] = rel
        args = {"format": "usdc"} if ext == ".usd" else {}
        if not layer.Export(pending.temp_path, args=args):
            raise ValueError(f"cannot write {full}: USD export failed")
    except BaseException:
        pending.discard()
        raise
    return pending
