"""The result of a check (:func:`~warp_ccd._src.check.check.check_usd`) as plain data: :class:`CheckReport` and its
:class:`FrameContacts`, their JSON (:meth:`CheckReport.to_json`, following :func:`report_schema`) and summary.

A report holds numbers, strings and numpy arrays only (the import it came from rides along in
:attr:`CheckReport.source` where it ran, and is left out when the report is pickled), so that reports of
parts of a check computed elsewhere (other processes, a cluster) can be sent back and merged
(:func:`~warp_ccd._src.check.batch.merge_reports`).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from functools import cache

import numpy as np

from ..output import PendingFile, prepare_text
from ..runtime.aliases import PathLike
from ..usd.filters import FilterSummary
from .clearance import SoftClashes, clearance_json, clearance_summary, frame_clearance_json
from .duplicates import REL_TOL, duplicates_json, duplicates_summary, frame_duplicates_json
from .self_intersection import SelfIntersections, frame_self_json, self_json, self_summary
from .sweep import sweep_json, sweep_summary
from .tables import pair_table, span

__all__ = ["REPORT_SCHEMA_PATH", "SCHEMA_VERSION", "CheckReport", "FrameContacts", "report_schema"]

SCHEMA_VERSION = "2.0"
"""The version of the JSON report's layout (``"schema_version"`` in it): ``MAJOR.MINOR``, the minor number
raised when optional fields are added, the major one when a field is removed or changes meaning or type."""
REPORT_SCHEMA_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "report.schema.json")
"""The JSON Schema (draft 2020-12) of :meth:`CheckReport.to_json`, shipped with the package."""


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


def _containment_stats(frames: list, object_path: list) -> list[dict]:
    """Per ``(inner, outer)`` pair contained in some frame: names, frames, first and last time codes, depth."""
    stats: dict[tuple[int, int], dict] = {}
    for f in frames:
        if f.contained is None:
            continue
        for (i, o), d in zip(f.contained.tolist(), f.contained_depth.tolist()):
            s = stats.setdefault((i, o), {"inner": object_path[i], "outer": object_path[o], "frames": 0,
                                          "first": f.time, "last": f.time, "max_depth": None})
            s["frames"] += 1
            s["last"] = f.time
            if not np.isnan(d):
                s["max_depth"] = d if s["max_depth"] is None else max(s["max_depth"], d)
    return sorted(stats.values(), key=lambda s: (-s["frames"], s["first"], s["inner"], s["outer"]))


def _containment_json(frames: list, object_path: list) -> dict:
    """The report's ``containment`` section: every contained pair over the frames."""
    return {"pairs": _containment_stats(frames, object_path)}


def _containment_summary(frames: list, object_path: list, top: int) -> list[str]:
    """The summary's lines on meshes wholly inside another."""
    stats = _containment_stats(frames, object_path)
    lines = [f"  contained (a mesh wholly inside another): {len(stats)} pairs"]
    for s in stats[:top]:
        depth = "undefined" if s["max_depth"] is None else f"{s['max_depth']:.3g}"
        lines.append(f"    {s['inner']} inside {s['outer']}: {s['frames']} frames "
                     f"({s['first']:g} .. {s['last']:g}), max depth {depth}")
    return lines


@dataclass
class FrameContacts:
    """What one time code found.

    Attributes:
        time: the time code.
        triangle_pairs: ``(M, 4)`` int32 rows ``(obj_a, face_a, obj_b, face_b)`` of penetrating
            (or, with ``count_touching``, all) triangle pairs, USD face indices, sorted by
            ``(obj_a, obj_b, face_a, face_b)`` and unique (two triangles of one polygon meeting one
            face count once).
        depth: ``(M,)`` float64, the depth of each row, scene units: the deepest point measured on its two faces
            inside the other prim's closed solid (at least the row's tolerance where the faces cross; 0 where they
            only touch); NaN where neither prim is closed.
        segments: ``(M, 2, 3)`` float64 intersection segments of the rows (the first triangle
            pair of each), or None.
        num_touching: face pairs not reported: they only touch, or their prims' crossing is no deeper than
            ``min_depth``.
        soft_clashes: with a clearance, the :class:`~warp_ccd._src.check.clearance.SoftClashes` (prim pairs
            within it that the frame does not report as collisions), else None.
        self_intersections: with ``self_intersections``, the
            :class:`~warp_ccd._src.check.self_intersection.SelfIntersections` (prims through themselves), else None.
        duplicates: with ``duplicates``, ``(D, 2)`` int32 object pairs ``(a, b)``, ``a < b``, sorted, whose
            meshes coincide at this time code (:mod:`~warp_ccd._src.check.duplicates`; their rows are not in
            ``triangle_pairs`` nor counted in ``num_touching``), else None.
        penetrating: ``(M,)`` bool, whether each row belongs to a penetrating pair and crosses (all True unless
            ``count_touching`` reports touching rows too); None: every row (a report made before rows had it).
        pairs: ``(K, 2)`` int32 the penetrating object pairs ``(a, b)``, ``a < b``, sorted.
        pair_depth: ``(K,)`` float64 their depths (:mod:`~warp_ccd._src.narrowphase.depth`, scene units): the
            deepest point of either surface inside the other's closed solid; NaN where neither is closed.
        contained: with ``containment``, ``(C, 2)`` int32 ``(inner, outer)`` object pairs, the inner's surface
            wholly inside the outer's solid, else None.
        contained_depth: ``(C,)`` float64 how deep each inner surface lies inside its outer solid, or None.
    """

    time: float
    triangle_pairs: np.ndarray
    depth: np.ndarray
    segments: np.ndarray | None = None
    num_touching: int = 0
    soft_clashes: SoftClashes | None = None
    self_intersections: SelfIntersections | None = None
    duplicates: np.ndarray | None = None
    penetrating: np.ndarray | None = None
    pairs: np.ndarray | None = None
    pair_depth: np.ndarray | None = None
    contained: np.ndarray | None = None
    contained_depth: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.penetrating is None:
            self.penetrating = np.ones(len(self.triangle_pairs), bool)
        if self.pairs is None:  # a frame made by hand: each pair's depth, its rows' deepest
            hit = self.triangle_pairs[self.penetrating]
            self.pairs, at = np.unique(hit[:, [0, 2]], axis=0, return_inverse=True)
            self.pairs = self.pairs.astype(np.int32).reshape(-1, 2)
            self.pair_depth = np.full(len(self.pairs), -np.inf)
            np.maximum.at(self.pair_depth, at.reshape(-1), self.depth[self.penetrating])

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
            without them; see :func:`~warp_ccd._src.usd.stage.missing_layers`).
        source: the :class:`~warp_ccd._src.usd.importer.UsdMeshImport` (its scene is at the last frame), where the
            check ran in this process; None in a report that was pickled (sent from another process) or merged.
        intervals: with ``continuous``, one :class:`~warp_ccd._src.check.sweep.SweepInterval` per pair of
            consecutive time codes; None otherwise.
        min_distance: with ``continuous``, the distance within which surfaces count as touching.
        ccd_tolerance: with ``continuous``, the continuous test's distance tolerance.
        clearance: the distance of soft clashes (0: none sought).
        self_checked: whether self-intersections were sought.
        duplicates_checked: whether duplicates (coincident meshes) were sought.
        containment_checked: whether meshes wholly inside another were sought.
        filters: the :class:`~warp_ccd._src.usd.filters.FilterSummary` of the worlds, excluded pairs and sets
            (the report's ``filters`` section when any was used), or None.
        object_instancer: ``N`` PointInstancer paths of the objects (None for a mesh prim), for the overlay.
        object_instance: ``(N,)`` int64 instance index of each object in its PointInstancer (-1 for a mesh prim).
        extent: the largest side of the world vertices' bounding box at the last time code checked, scene units
            (the width of the overlay's curves).
        precision: the precision the check ran in (``"float32"``, or ``"float64"`` where asked for or where the
            coordinates needed it).
        precision_note: why the check ran in float64 though float32 was asked for, or None.
        max_coordinate: the largest ``|coordinate|`` of a world vertex over the time codes read, scene units
            (:attr:`~warp_ccd._src.usd.importer.UsdMeshImport.max_coordinate`).
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
    containment_checked: bool = False
    filters: FilterSummary | None = None
    object_instancer: list = field(default_factory=list)
    object_instance: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    extent: float = 0.0
    precision: str = "float32"
    precision_note: str | None = None
    max_coordinate: float = 0.0

    def __getstate__(self) -> dict:
        """Pickled without :attr:`source` (a USD stage and device arrays do not travel): plain data only."""
        state = dict(self.__dict__)
        state["source"] = None
        return state

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
        """Whether any frame has a penetrating pair: its surfaces cross, deeper than ``min_depth`` or with an
        undefined depth (with ``count_touching``, touching rows are reported but do not make this true)."""
        return any(len(f.pairs) > 0 for f in self.frames)

    @property
    def touching(self) -> bool:
        """Whether any frame has a touching pair (or a crossing no deeper than ``min_depth``), reported
        (``count_touching``) or only counted."""
        return any(f.num_touching > 0 or not bool(f.penetrating.all()) for f in self.frames)

    @property
    def contained(self) -> bool:
        """Whether any frame has a mesh wholly inside another (``containment`` checks)."""
        return any(f.contained is not None and len(f.contained) > 0 for f in self.frames)

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
        if self.contained:
            return "contained"
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

    def findings_per_frame(self) -> np.ndarray:
        """``(F,)`` int64 findings of each frame, of every kind the report has: its reported triangle pairs, and
        the rows of each other finding it holds (every :class:`FrameContacts` field but its time, depths,
        segments, touching count and what describes its rows or pairs: an array's rows, or those of a finding's
        ``face_pairs`` or ``object_pairs``: self-intersecting face pairs, soft clashes, duplicates, contained
        pairs, ...), plus the tunnelling pairs of the interval that starts at it (continuous checks)."""

        def rows(value) -> int:
            value = getattr(value, "face_pairs", getattr(value, "object_pairs", value))
            return len(value) if isinstance(value, np.ndarray) else 0

        skip = ("time", "depth", "segments", "num_touching", "penetrating", "pairs", "pair_depth", "contained_depth")
        counts = np.array([sum(rows(v) for k, v in vars(f).items() if k not in skip) for f in self.frames], np.int64)
        for k, iv in enumerate((self.intervals or [])[: len(counts)]):
            counts[k] += int(np.count_nonzero(iv.tunnelling))
        return counts

    @property
    def worst_frame(self) -> int:
        """Index of the frame with the most findings (:meth:`findings_per_frame`; the first of equals; 0 if
        none): the frame ``check --preview`` draws."""
        counts = self.findings_per_frame()
        return int(np.argmax(counts)) if len(counts) else 0

    def pair_summary(self) -> list[dict]:
        """Per prim pair reported in some frame (penetrating; touching too with ``count_touching``): ``a``,
        ``b`` (names), ``frames`` (how many), ``first`` and ``last`` time codes, ``max_triangle_pairs`` in one
        frame and ``max_depth`` (its largest depth: 0 where it only touches, None where it is undefined, neither
        prim closed); most frames first."""
        stats: dict[tuple[int, int], dict] = {}
        for f in self.frames:
            if not len(f.triangle_pairs):
                continue
            keys, counts = np.unique(f.triangle_pairs[:, [0, 2]], axis=0, return_counts=True)
            depth = dict(zip(map(tuple, f.pairs.tolist()), f.pair_depth.tolist()))
            for (a, b), c in zip(keys.tolist(), counts.tolist()):
                d = depth.get((a, b), 0.0)
                s = stats.setdefault((a, b), {"a": self.object_path[a], "b": self.object_path[b], "frames": 0,
                                              "first": f.time, "last": f.time, "max_triangle_pairs": 0,
                                              "max_depth": None if np.isnan(d) else 0.0})
                s["frames"] += 1
                s["last"] = f.time
                s["max_triangle_pairs"] = max(s["max_triangle_pairs"], c)
                if s["max_depth"] is not None and not np.isnan(d):
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
                depth = {(a, b): d for (a, b), d in zip(f.pairs.tolist(), f.pair_depth.tolist())}
                for (a, b), s, e in zip(keys.tolist(), first.tolist(), ends):
                    d = depth.get((a, b), 0.0)
                    entry = {"a": self.object_path[a], "b": self.object_path[b],
                             "faces": rows[s:e][:, [1, 3]].tolist(), "penetrating": (a, b) in depth,
                             "max_depth": None if np.isnan(d) else float(d)}
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
            if f.contained is not None:
                entry["contained"] = [{"inner": self.object_path[i], "outer": self.object_path[o],
                                       "depth": None if np.isnan(d) else float(d)}
                                      for (i, o), d in zip(f.contained.tolist(), f.contained_depth.tolist())]
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
        if self.containment_checked:
            out["contained"] = self.contained
            out["containment"] = _containment_json(self.frames, self.object_path)
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
            The :class:`~warp_ccd._src.output.PendingFile`: :meth:`~warp_ccd._src.output.PendingFile.commit`
            moves it to ``path``, :meth:`~warp_ccd._src.output.PendingFile.discard` removes it.
        """
        return prepare_text(path, self.json_text(), (".json",), "report")

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
                                      + ("undefined (open surfaces)" if p["max_depth"] is None
                                         else f"{p['max_depth']:.3g}"))
        if self.containment_checked:
            lines += _containment_summary(self.frames, self.object_path, top)
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


