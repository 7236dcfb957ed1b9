"""Checking a USD animation for interpenetration, frame by frame (``warp-ccd check``).

:func:`check_usd` reads a stage once (:class:`~warp_ccd._src.usd.importer.UsdMeshImport`), runs the
collision pipeline at every time code asked for, and returns a :class:`CheckReport`: per frame,
the prim pairs whose surfaces cross, with their USD face pairs and how deep they cross. Its options are one
:class:`~warp_ccd._src.check.options.CheckOptions`, made (and checked) before the stage is read.

**Touching is not penetrating.** Objects resting on each other touch every frame, and the exact
test reports their triangle pairs (triangles are closed sets). Each reported pair is classified
from the surfaces around it (:mod:`~warp_ccd._src.check.crossing`): the surfaces *cross* where one enters
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

**Clearance** (``clearance=D``, :mod:`~warp_ccd._src.check.clearance`): the pipeline also reports the prim
pairs within ``D`` of each other; those a frame does not report as collisions are its *soft clashes*,
with their least distance, closest points and USD faces (:attr:`FrameContacts.soft_clashes`). In the
overlay a prim in a soft clash is yellow at that time code (red and orange win), and each soft
clash's closest points are joined by a curve.

**Self-intersection** (``self_intersections=True``, :mod:`~warp_ccd._src.check.self_intersection`): the pipeline
also reports each prim's own triangles that meet beyond the vertices they share, as pairs of its USD
faces with their depth (:attr:`FrameContacts.self_intersections`). In the overlay a prim through itself
is magenta at that time code (red and orange win).

**Continuous** (``continuous=True``, :mod:`~warp_ccd._src.check.sweep`): one continuous pipeline more, whose
every detection covers the linear motion since the previous time code, reports per interval between
consecutive time codes the prim pairs that touch at some time in it (:attr:`CheckReport.intervals`),
and marks *tunnelling* those that neither end frame shows intersecting. In the overlay a prim that
tunnels in the interval starting at a time code is orange there (red still wins: it penetrates), and
its ``warpCcd:tunnelling`` attribute is true there.

**Duplicates** (``duplicates=True``, :mod:`~warp_ccd._src.check.duplicates`): a pair the detection reports whose
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
type. ``1.1`` added the ``filters`` section. ``2.0``: a pair's ``max_depth`` is its depth as
:mod:`~warp_ccd._src.narrowphase.depth` defines it (null where neither prim is closed), a frame's pairs say
whether they penetrate, ``contained``/``containment`` with ``containment``, and ``filters`` counts the pairs each
of USD Physics' rules excludes (rigid bodies, joints, articulations).

**Filters** (:mod:`~warp_ccd._src.usd.filters`): pairs of two ``worlds``, excluded pairs (``ignore_pairs``, the
stage's ``UsdPhysics`` rules: meshes of one rigid body, bodies a joint joins, filtered pairs, collision groups;
:mod:`~warp_ccd._src.usd.physics`) and, with ``set_a`` / ``set_b``, pairs not of one prim of each set are dropped
by the broad phase (so for every kind of check; self-intersection, per prim, is not filtered).
"""


from __future__ import annotations

import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ..runtime.aliases import DeviceLike, PathLike
from .clearance import soft_clashes
from .crossing import CrossingClassifier, Crossings
from .duplicates import duplicate_pairs
from .options import CheckOptions, check_options
from .overlay import COLOR_CLEAR, COLOR_PENETRATING, prepare_overlay, write_overlay
from .report import REPORT_SCHEMA_PATH, SCHEMA_VERSION, CheckReport, FrameContacts, report_schema
from .self_intersection import self_intersections as find_self_intersections
from .sweep import sweep_interval

if TYPE_CHECKING:
    from pxr import Usd

__all__ = ["COLOR_CLEAR", "COLOR_PENETRATING", "REPORT_SCHEMA_PATH", "SCHEMA_VERSION", "CheckReport", "FrameContacts",
           "check_usd", "prepare_overlay", "report_schema", "write_overlay"]


def _frame_contacts(imp, res, found: Crossings, o: CheckOptions, time_code: float, num_faces: int,
                    contained: np.ndarray | None) -> FrameContacts:
    """One frame's rows in USD faces, one per (object, face) pair with its deepest crossing; the rows of
    penetrating pairs kept (every row with ``count_touching``), the others counted. A pair penetrates when
    its surfaces cross and its depth exceeds ``min_depth``, or its depth is undefined (neither object closed).
    With ``duplicates``, the object pairs whose meshes coincide are found among the rows' pairs and their rows
    left out. ``num_faces``: more than the largest USD face index; ``contained``: the frame's ``(inner,
    outer)`` pairs (with ``containment``), whose depths ``found`` holds."""
    rows = res.device_triangle_pairs.numpy().reshape(-1, 4).astype(np.int64)
    seg = res.device_segments.numpy().reshape(-1, 2, 3).astype(np.float64) if o.segments else None
    depth = found.depth
    pair_at = found.row_pair(rows)
    deep = np.isnan(found.pair_depth) | (found.pair_depth > o.min_depth)
    pen = found.crossing & (pair_at >= 0)
    pen[pen] = deep[pair_at[pen]]
    dup = None
    if o.duplicates:
        dup = duplicate_pairs(imp.scene, np.unique(rows[:, [0, 2]], axis=0)) if len(rows) else np.zeros((0, 2),
                                                                                                       np.int32)
        if len(dup):
            n = imp.scene.num_objects
            gone = np.isin(rows[:, 0] * n + rows[:, 2], dup[:, 0].astype(np.int64) * n + dup[:, 1])
            rows, depth, pen, pair_at = rows[~gone], depth[~gone], pen[~gone], pair_at[~gone]
            seg = seg[~gone] if seg is not None else None
    # The penetrating pairs, with their depths.
    hit = np.unique(pair_at[pen])
    pairs, pair_depth = found.pairs[hit].reshape(-1, 2), found.pair_depth[hit]
    faces = np.stack([rows[:, 0], imp.faces(rows[:, 0], rows[:, 1]), rows[:, 2],
                      imp.faces(rows[:, 2], rows[:, 3])], axis=1).astype(np.int32)
    if len(faces) and seg is None:
        # By (a, b, fa, fb), each face pair once with its deepest crossing (which of its triangle
        # pairs is deepest does not show without segments): one sort of one key where it fits in 63 bits.
        order, starts = _face_pair_groups(faces, imp.scene.num_objects, num_faces)
        faces = faces[order][starts]
        depth = np.maximum.reduceat(depth[order], starts)
        pen = np.logical_or.reduceat(pen[order], starts)
    elif len(faces):
        # By (a, b, fa, fb), deepest first, then by triangles: the same row (and segment) on every
        # device, whatever order the device's hits came in.
        order = np.lexsort((rows[:, 3], rows[:, 1], -np.nan_to_num(depth, nan=np.inf), faces[:, 3], faces[:, 1],
                            faces[:, 2], faces[:, 0]))
        faces, depth, pen = faces[order], depth[order], pen[order]
        first = np.ones(len(faces), bool)
        first[1:] = (faces[1:] != faces[:-1]).any(axis=1)
        group = np.cumsum(first) - 1
        pen = np.bincount(group, pen, minlength=int(first.sum()))[group] > 0 if len(pen) else pen
        faces, depth, pen = faces[first], depth[first], pen[first]
        seg = seg[order][first]
    keep = np.ones(len(faces), bool) if o.count_touching else pen
    out = FrameContacts(float(time_code), faces[keep].reshape(-1, 4), depth[keep],
                        seg[keep] if seg is not None else None, int((~keep).sum()), duplicates=dup,
                        penetrating=pen[keep], pairs=pairs.astype(np.int32), pair_depth=pair_depth)
    if contained is not None:
        out.contained = np.asarray(contained, np.int32).reshape(-1, 2)
        out.contained_depth = np.asarray(found.contained_depth, np.float64)
    return out


def _face_pair_groups(faces: np.ndarray, num_objects: int, num_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """``(M, 4)`` rows ``(a, face_a, b, face_b)`` grouped by ``(a, b, face_a, face_b)``: the order that sorts
    them and where each group starts in it; one sort of a packed key (a sort of two where it does not fit)."""
    a, fa, b, fb = (faces[:, k].astype(np.int64) for k in range(4))
    pair, face = a * num_objects + b, fa * max(num_faces, 1) + fb
    if (max(num_objects, 1) ** 2) * (max(num_faces, 1) ** 2) < 2**63:
        key = pair * max(num_faces, 1) ** 2 + face
        order = np.argsort(key)
        key = key[order]
        starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    else:
        order = np.lexsort((face, pair))
        p, f = pair[order], face[order]
        starts = np.flatnonzero(np.r_[True, (p[1:] != p[:-1]) | (f[1:] != f[:-1])])
    return order, starts


def check_usd(stage_or_path: Usd.Stage | PathLike, options: CheckOptions | None = None, *,
              frames: slice | Sequence[float] | None = None, prims: str | Sequence[str] | None = None,
              device: DeviceLike = None, **kwargs: Any) -> CheckReport:
    """Finds, frame by frame, the meshes of a USD stage whose surfaces pass through each other.

    Example::

        report = check_usd("anim.usd", frames=slice(0, 100), clearance=0.01)
        report = check_usd("anim.usd", CheckOptions(continuous=True, min_distance=0.001), device="cuda:0")

    Args:
        stage_or_path: a ``Usd.Stage`` or a USD file path.
        options: a :class:`~warp_ccd._src.check.options.CheckOptions` (every option, checked when it was made), or
            None: the defaults.
        frames: time codes (see :func:`~warp_ccd._src.usd.stage.stage_time_codes`; default: every
            integer time code of the stage's range).
        prims: prim paths or patterns to check (default: the whole stage).
        device: Warp device (default: Warp's preferred device).
        **kwargs: options by name (fields of :class:`~warp_ccd._src.check.options.CheckOptions`, over
            ``options``): ``check_usd(path, min_depth=0.01, continuous=True)``; checked before anything is read.

    Returns:
        The :class:`CheckReport`.

    Raises:
        TypeError: a keyword that is no option.
        ValueError: a bad option (see :class:`~warp_ccd._src.check.options.CheckOptions`); naming the file or prim:
            see :class:`~warp_ccd._src.usd.importer.UsdMeshImport`; or a sublayer, reference or payload cannot be
            opened (unless ``allow_missing``), a pair naming no prim, a pattern matching no checked mesh (unless
            ``allow_missing``).
    """
    import warp as wp
    from tqdm import tqdm

    from ..pipeline.pipeline import CollisionPipeline
    from ..usd.importer import UsdMeshImport
    from ..usd.stage import open_stage, require_layers, stage_time_codes

    o = check_options(options, kwargs, "check_usd")
    t = time.perf_counter()
    stage = open_stage(stage_or_path)
    missing = require_layers(stage, o.allow_missing)
    times = stage_time_codes(stage, frames)
    opened = time.perf_counter() - t
    imp = UsdMeshImport(stage, prims=prims, times=times, include_invisible=o.include_invisible,
                        include_purposes=o.include_purposes, device=device, precision=o.precision,
                        progress=o.progress, worlds=o.worlds, filters=o.pair_filters, workers=o.read_workers)
    seconds = dict(imp.seconds)
    seconds["read"] += opened  # the import got the stage open
    t = time.perf_counter()
    scene = imp.scene
    pipe = CollisionPipeline(scene, o.pipeline_options())
    classify = CrossingClassifier(scene, tolerance=o.tolerance, trees=pipe.boxes)
    # One continuous pipeline for the whole animation: each detect covers the motion since the last.
    sweep = CollisionPipeline(scene, o.sweep_options()) if o.continuous else None
    seconds["build"] += time.perf_counter() - t
    seconds["set"] = seconds["detect"] = seconds["classify"] = 0.0
    if o.continuous:
        seconds["continuous"] = 0.0
    name = stage.GetRootLayer().realPath or stage.GetRootLayer().identifier
    report = CheckReport(name, list(imp.object_path), min_depth=o.min_depth, count_touching=o.count_touching,
                         device=str(scene.device), skipped=list(imp.skipped), clearance=o.clearance,
                         self_checked=o.self_intersections, duplicates_checked=o.duplicates,
                         containment_checked=o.containment, filters=imp.filters)
    if o.continuous:
        report.intervals = []
        report.min_distance = o.min_distance
        report.ccd_tolerance = float(sweep.narrow.tolerance)
    intersecting = None  # the object pairs of the previous time code (touching included)
    num_faces = int(imp.triangle_face.max(initial=-1)) + 1
    bar = tqdm(range(len(times)), desc="frames", unit="frame", disable=not o.progress or None, leave=False)
    for k in bar:
        t = time.perf_counter()
        imp.set_frame(k)
        t1 = time.perf_counter()
        res = pipe.detect()
        t_detect = time.perf_counter()
        contained = res.containment_pairs if o.containment else None
        found = classify(res.device_triangle_pairs, contained)
        contacts = _frame_contacts(imp, res, found, o, times[k], num_faces, contained)
        if o.clearance > 0.0:
            reported = contacts.object_pairs
            if contacts.duplicates is not None and len(contacts.duplicates):  # a duplicate is no soft clash
                reported = np.unique(np.concatenate([reported, contacts.duplicates]), axis=0)
            contacts.soft_clashes = soft_clashes(imp, res, reported)
        if o.self_intersections:
            contacts.self_intersections = find_self_intersections(imp, res, pipe.self_phase)
        t2 = time.perf_counter()
        seconds["set"] += t1 - t
        seconds["detect"] += t_detect - t1
        seconds["classify"] += t2 - t_detect
        report.frames.append(contacts)
        if o.continuous:
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
    report.object_instancer = list(imp.object_instancer)
    report.object_instance = np.asarray(imp.object_instance, np.int64)
    world = scene.world_vertex.numpy()
    report.extent = float(np.max(world.max(axis=0) - world.min(axis=0))) if len(world) else 0.0
    report.precision = str(scene.precision)
    report.precision_note = imp.precision_note
    report.max_coordinate = float(imp.max_coordinate)
    return report
