"""The options of a collision pipeline, as one object checked when made: :class:`PipelineOptions`.

:class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` and :func:`~warp_ccd._src.pipeline.pipeline.collide`
build one at the API boundary (from an object given, or from keywords) and pass it down to the stage factories;
nothing below re-reads a keyword. Each field is checked by its rule in the one table of rules
(:data:`~warp_ccd._src.runtime.options.OPTIONS`), then the rules that join options (a continuous pipeline has
no segments, ...) are checked here.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, fields
from typing import Any

from ..geometry.ccd import CCD_MAX_ITERATIONS, CCD_TOLERANCE
from ..geometry.triangle import TOLERANCE
from ..runtime.options import check_option, merged_options

__all__ = ["DEFORMING_LEAF_SIZE", "RIGID_LEAF_SIZE", "PipelineOptions", "pipeline_options"]

RIGID_LEAF_SIZE = 1
"""Default triangles per leaf in a scene of rigid objects: the level by level descent tests node pairs at
memory speed, and a leaf pair's boxes are its triangles' boxes, so that fewer pairs reach the exact test
(half as many as with leaves of 2); measured fastest at every scale of the scaling benchmark (see the docs'
performance page)."""

DEFORMING_LEAF_SIZE = 4
"""Default triangles per leaf in a scene with deforming objects, whose trees are refit every frame: a
quarter of the nodes to refit (and of the bytes it moves), for more triangle pairs per leaf pair. Not in a
continuous frame (its leaf pairs' triangle pairs each cost a continuous test, dearer than a refit), nor with
self-intersections (a leaf's pairs are candidates of the adjacency-aware test, the self frame's costliest
kernel)."""

CONTINUOUS_ONLY = {"min_distance": 0.0, "ccd_tolerance": CCD_TOLERANCE, "ccd_max_iterations": CCD_MAX_ITERATIONS}
"""Options of continuous detection alone, and their defaults (the values a discrete pipeline must keep)."""


@dataclass(frozen=True)
class PipelineOptions:
    """Every option of a :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline`, checked when made.

    Attributes:
        broad_phase: ``"sap"`` (default: sweep and prune on a grid) or ``"all_pairs"`` (the reference;
            ``"nxn"`` names it too).
        mid_phase: ``"bvh"`` (default: tree against tree) or ``"all_pairs"`` (the reference: every triangle
            pair of each object pair).
        narrow_phase: ``"moller"`` (default) or ``"edge_face"``.
        tolerance: relative tolerance of touching contacts, in ``[0, 0.1)`` (see
            :mod:`warp_ccd._src.geometry.triangle`).
        timings: synchronise after each stage and report ms per stage (frames are then launched eagerly).
        graph: replay each frame as a captured CUDA graph (None, the default: on CUDA, unless ``timings``);
            False launches every kernel from Python (the CPU always does). Both give the same results.
        leaf_size: triangles per tree leaf (``bvh`` mid phase), in ``[1, 256]``; None: 1, or 4 in a discrete
            pipeline of a scene with deforming objects that does not seek self-intersections (fewer nodes to
            refit each frame).
        cut_depth: least level of the tree cut whose boxes make a big rigid object's box for the broad phase
            (``bvh`` mid phase; see :class:`~warp_ccd._src.trees.bvh.SceneBVH`).
        separating_axes: the traversal's box test (``bvh`` mid phase): 6 (default), the box around one
            object's box in the other's space, both ways round; 3, one way.
        object_bounds: a rigid object's box for the broad phase (``bvh`` mid phase): ``"auto"`` (default),
            ``"vertices"``, ``"tree"``, or the most vertices of an object whose box comes from its vertices.
        segments: also compute the intersection segment of each triangle pair.
        containment: also report objects wholly inside another (winding number of one vertex).
        pair_capacity: initial capacity (>= 1) of the broad phase's object pairs; every buffer grows (None,
            for each capacity: the stage's default).
        entry_capacity: initial capacity of the sweep's grid entries.
        candidate_capacity: initial capacity of the candidate triangle pairs.
        hit_capacity: initial capacity of the intersecting triangle pairs.
        front_capacity: initial capacity of the traversal's front of node pairs.
        near_capacity: initial capacity of the object pairs within the clearance.
        self_capacity: initial capacity of the self-intersecting triangle pairs.
        rebuild_every: rebuild the trees' triangle order before every ``k``-th frame (deforming meshes whose
            refit trees have loosened; the results are the same, the traversal faster); 0 (default) never.
            Not with the ``all_pairs`` mid phase (no trees).
        continuous: report what collides over the linear motion of every world vertex since the previous
            frame (triangle pairs that meet at some ``t`` in ``[0, 1]``, with their times of impact). Not
            with ``segments``, ``containment``, another ``narrow_phase``, a ``clearance`` or
            ``self_intersections``.
        min_distance: with ``continuous``, pairs that come within this distance (scene units, infinity
            norm, >= 0) collide too.
        ccd_tolerance: with ``continuous``, the test's distance tolerance (> 0, scene units).
        ccd_max_iterations: with ``continuous``, the most boxes one primitive query examines (past it the
            answer is a conservative collision).
        clearance: also report every object pair whose surfaces come within this distance (scene units, in
            ``[0, 1e37]``), with its least distance, closest points and direction; 0 (default) adds nothing.
        self_intersections: also report the triangles of each object that meet each other beyond the
            vertices they share (``bvh`` mid phase).
        contacts: also report contacts a solver can use (:attr:`CollisionResult.contacts
            <warp_ccd._src.pipeline.result.CollisionResult.contacts>`, :mod:`warp_ccd._src.narrowphase.contacts`):
            per contact a point on each surface, a normal from ``b`` to ``a`` and a depth. Not with ``continuous``.
        max_per_pair: with ``contacts``, the most contacts an object pair keeps (in ``[1, 32]``; default 8).
        margin: with ``contacts``, pairs apart by at most this distance (scene units) get a speculative contact
            (their closest points, depth minus the distance); the pipeline's clearance is at least the margin.
    """

    broad_phase: str = "sap"
    mid_phase: str = "bvh"
    narrow_phase: str = "moller"
    tolerance: float = TOLERANCE
    timings: bool = False
    graph: bool | None = None
    leaf_size: int | None = None
    cut_depth: int = 3
    separating_axes: int = 6
    object_bounds: str | int = "auto"
    segments: bool = False
    containment: bool = False
    pair_capacity: int | None = None
    entry_capacity: int | None = None
    candidate_capacity: int | None = None
    hit_capacity: int | None = None
    front_capacity: int | None = None
    rebuild_every: int = 0
    continuous: bool = False
    min_distance: float = 0.0
    ccd_tolerance: float = CCD_TOLERANCE
    ccd_max_iterations: int = CCD_MAX_ITERATIONS
    clearance: float = 0.0
    near_capacity: int | None = None
    self_intersections: bool = False
    self_capacity: int | None = None
    contacts: bool = False
    max_per_pair: int = 8
    margin: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, check_option(f.name, getattr(self, f.name)))
        if self.graph and self.timings:
            raise ValueError("graph: a frame timed stage by stage (timings=True) cannot be one graph")
        if self.rebuild_every and self.mid_phase == "all_pairs":
            raise ValueError("rebuild_every must be 0 with the all_pairs mid phase (no trees), "
                             f"got {self.rebuild_every!r}")
        if self.self_intersections and self.mid_phase != "bvh":
            raise ValueError("self_intersections: needs the trees of the bvh mid phase, "
                             f"got mid_phase={self.mid_phase!r}")
        if self.margin > self.clearance:  # speculative contacts come from the pairs within the clearance
            object.__setattr__(self, "clearance", self.margin)
        if not self.contacts:
            for name, default in (("max_per_pair", 8), ("margin", 0.0)):
                if getattr(self, name) != default:
                    raise ValueError(f"{name} is an option of contacts (contacts=True), got {getattr(self, name)!r}")
        if not self.continuous:
            for name, default in CONTINUOUS_ONLY.items():
                if getattr(self, name) != default:
                    raise ValueError(f"{name} is an option of continuous detection (continuous=True), "
                                     f"got {getattr(self, name)!r}")
            return
        if self.segments:
            raise ValueError("segments: a continuous pipeline has no intersection segments (continuous=True)")
        if self.containment:
            raise ValueError("containment: a continuous pipeline does not report containment (continuous=True)")
        if self.narrow_phase != "moller":
            raise ValueError(f"narrow_phase: a continuous pipeline's narrow phase is its own (continuous=True), "
                             f"got {self.narrow_phase!r}")
        if self.contacts:
            raise ValueError("contacts: a continuous pipeline reports times of impact, not contacts (continuous=True)")
        if self.clearance > 0.0:
            raise ValueError("clearance: a continuous pipeline's least distance is its min_distance "
                             f"(continuous=True), got clearance={self.clearance!r}")
        if self.self_intersections:
            raise ValueError("self_intersections: a continuous pipeline does not report self-intersections "
                             "(continuous=True)")

    def replace(self, **changes: Any) -> PipelineOptions:
        """A copy with ``changes`` (checked as a new object is)."""
        return dataclasses.replace(self, **changes)


def pipeline_options(options: PipelineOptions | None, changes: dict[str, Any], where: str) -> PipelineOptions:
    """The pipeline options an API call gets: ``options`` (or the defaults) with the keyword ``changes`` over it
    (:func:`~warp_ccd._src.runtime.options.merged_options`; ``where`` names the call in a TypeError)."""
    return merged_options(PipelineOptions, options, changes, where)
