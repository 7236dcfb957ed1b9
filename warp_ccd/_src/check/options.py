"""The options of a USD check, as one object checked when made: :class:`CheckOptions`.

:func:`~warp_ccd._src.check.check.check_usd`, :func:`~warp_ccd._src.check.batch.check_many` and ``warp-ccd check``
build one at their boundary (from an object given, from keywords, from the command line's flags) before anything
is read, and pass it down: to the tasks of a batch (it pickles, for Ray), to the pipelines the check runs
(:meth:`CheckOptions.pipeline_options`, :meth:`CheckOptions.sweep_options`). Nothing below re-reads a keyword.

Each field is checked by its rule in the one table of rules (:data:`~warp_ccd._src.runtime.options.OPTIONS`;
``tolerance``, ``clearance``, ``min_distance`` and ``precision`` by the rows the pipeline's options use too), then
the rules that join options: ``min_distance`` with ``continuous``, here; ``set_a`` with ``set_b``, and the
ignore-pairs files read, by the :class:`~warp_ccd._src.usd.filters.PairFilters` made here
(:attr:`CheckOptions.pair_filters`). The prim patterns of ``worlds`` are checked where they are matched, by the
USD import (:func:`~warp_ccd._src.usd.filters.world_ids`), which :func:`~warp_ccd._src.usd.importer.scene_from_usd`
shares.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from dataclasses import InitVar, dataclass, fields
from typing import Any

from ..geometry.triangle import TOLERANCE
from ..pipeline.options import PipelineOptions
from ..runtime.aliases import PathLike
from ..runtime.options import check_option, merged_options
from ..usd.filters import PairFilters

__all__ = ["CheckOptions", "check_options"]

_PATTERNS = ("worlds", "set_a", "set_b")
"""Options that take prim paths or patterns: one string (several comma-separated) or a sequence of them."""


def _patterns(value: str | Sequence[str] | None) -> tuple[str, ...] | None:
    """Prim patterns as a tuple (a string: one item; the import splits it at commas), or None."""
    if value is None or isinstance(value, tuple):
        return value
    return (value,) if isinstance(value, str) else tuple(value)


def _pair_items(value: PathLike | Sequence[Any] | None) -> tuple | None:
    """``ignore_pairs`` as a tuple: files as ``str``, pairs as tuples (the items themselves are checked by
    :class:`~warp_ccd._src.usd.filters.PairFilters`)."""
    if value is None:
        return None
    items = [value] if isinstance(value, (str, bytes, os.PathLike)) else list(value)
    return tuple(os.fsdecode(i) if isinstance(i, (str, bytes, os.PathLike))
                 else tuple(i) if isinstance(i, list) else i for i in items)


@dataclass(frozen=True)
class CheckOptions:
    """Every option of a USD check (:func:`~warp_ccd._src.check.check.check_usd`), checked when made.

    The stage, its time codes (``frames``), the prims to check (``prims``) and the device are the check's inputs,
    not options: :func:`~warp_ccd._src.check.check.check_usd` takes them besides.

    Attributes:
        precision: ``"float32"`` (default) or ``"float64"``: vertices, poses and the exact test; float32 becomes
            float64, with a :class:`~warp_ccd._src.geometry.precision.PrecisionWarning`, where the coordinates are
            too far from the origin for it at the triangles' size.
        min_depth: a pair whose surfaces cross penetrates when its depth exceeds this (scene units, >= 0; default
            0: every crossing). The depth is the deepest point of either surface inside the other's closed solid
            (:mod:`~warp_ccd._src.narrowphase.depth`); a crossing of two open surfaces has none (undefined) and
            penetrates whatever ``min_depth``.
        count_touching: report touching pairs (and crossings no deeper than ``min_depth``) as collisions too.
        segments: keep the intersection segments (``(M, 2, 3)`` per frame: the report and the overlay).
        include_invisible: also check invisible prims.
        include_purposes: also check prims of these purposes (``"guide"``, ``"proxy"``; ``"render"`` and
            ``"default"`` are always checked); a tuple.
        tolerance: relative tolerance of the triangle test, in ``[0, 0.1)`` (the pipeline's ``tolerance``).
        progress: show progress bars on stderr (reading the transforms of every time code, then the frames; a
            batch: one bar over the time codes of all its tasks).
        allow_missing: check a stage whose sublayers, references or payloads cannot all be opened (without
            them) instead of raising; likewise an ``ignore_pairs`` pair naming no prim, a ``worlds``, ``set_a``
            or ``set_b`` pattern matching no checked mesh: a note in the report instead of a ValueError.
        continuous: also report, per interval between consecutive time codes, the prim pairs that touch at some
            time in it (every vertex moving linearly between its positions at the two time codes), and which of
            them tunnel.
        min_distance: with ``continuous``, pairs that come within this distance (scene units, infinity norm,
            >= 0) count as touching (the continuous pipeline's ``min_distance``).
        clearance: also report, per frame, the prim pairs within this distance (scene units, in ``[0, 1e37]``)
            that the frame does not report as collisions: soft clashes (the pipeline's ``clearance``).
        self_intersections: also report, per frame, the prims that pass through themselves, as pairs of their
            USD faces with a depth.
        containment: also report, per frame, the closed meshes wholly inside another's solid (no surface
            crossing), with their depth: how deep the inner surface lies inside the outer solid.
        duplicates: report, per frame, the pairs whose meshes coincide (the same triangles at the same place) as
            duplicates instead of as collisions.
        worlds: prim paths or ``fnmatch`` patterns (a tuple; a string may hold several, comma-separated), every
            prim they match rooting a world: pairs of two worlds are never checked (meshes under no root pair
            with every world); None: one world.
        ignore_pairs: prim pairs never checked: a tuple of ignore-pairs files (text: two prim paths or patterns
            a line, separated by whitespace or a comma, ``#`` comments; ``.json``: a list of ``[a, b]``) and
            ``(a, b)`` pairs (a single file may be given as it is); every mesh at or under ``a`` is excluded
            against every mesh at or under ``b``. The files are read when the options are made.
        usd_filters: also exclude the pairs the stage's ``UsdPhysics`` rules leave out (default True): meshes of
            one ``RigidBodyAPI`` body, bodies a ``Joint`` joins with ``physics:collisionEnabled`` false
            (:mod:`~warp_ccd._src.usd.physics`), ``FilteredPairsAPI`` and ``CollisionGroup`` prims.
        set_a: prim paths or patterns (a string may hold several, comma-separated; held as a tuple, one pattern
            an item): with ``set_b``, only pairs of one mesh of set A and one of set B are checked (a mesh may be
            in both).
        set_b: the other set, given with ``set_a``.
        read_workers: processes that read the transforms (>= 0; None, the default: chosen by the stage's size;
            0: read in this process). A batch's Ray workers choose their own.

    Args:
        given_as: the names the options were given as, where they are not the fields' (the command line:
            ``{"min_depth": "--min-depth", ...}``): a message names what the user wrote. Not kept.

    Raises:
        ValueError: ``"{name} must be ..., got {value!r}"`` (the rule of the option in
            :data:`~warp_ccd._src.runtime.options.OPTIONS`), ``min_distance`` without ``continuous``, ``set_a``
            without ``set_b`` (or the reverse), a bad prim pattern of a set, an ignore-pairs file that cannot be
            read (naming it and the line) or a bad pair.
    """

    precision: str = "float32"
    min_depth: float = 0.0
    count_touching: bool = False
    segments: bool = False
    include_invisible: bool = False
    include_purposes: tuple[str, ...] = ()
    tolerance: float = TOLERANCE
    progress: bool = False
    allow_missing: bool = False
    continuous: bool = False
    min_distance: float = 0.0
    clearance: float = 0.0
    self_intersections: bool = False
    containment: bool = False
    duplicates: bool = False
    worlds: tuple[str, ...] | None = None
    ignore_pairs: tuple | None = None
    usd_filters: bool = True
    set_a: tuple[str, ...] | None = None
    set_b: tuple[str, ...] | None = None
    read_workers: int | None = None
    given_as: InitVar[Mapping[str, str] | None] = None

    def __post_init__(self, given_as: Mapping[str, str] | None) -> None:
        names = dict(given_as or {})

        def rule(name: str, value: Any) -> Any:  # the option's rule in the one table, named as it was given
            return check_option(name, value, names.get(name))

        purposes = (self.include_purposes,) if isinstance(self.include_purposes, str) else self.include_purposes
        normal = {"include_purposes": tuple(rule("include_purposes", p) for p in purposes),
                  "ignore_pairs": _pair_items(self.ignore_pairs),
                  **{name: _patterns(getattr(self, name)) for name in _PATTERNS}}
        for f in fields(self):
            value = getattr(self, f.name)
            object.__setattr__(self, f.name, normal[f.name] if f.name in normal else rule(f.name, value))
        if self.min_distance > 0.0 and not self.continuous:
            raise ValueError(f"{names.get('min_distance', 'min_distance')} is an option of the continuous check "
                             f"({names.get('continuous', 'continuous=True')}), got {self.min_distance!r}")
        # set_a with set_b, their patterns, the ignore-pairs files: checked (and the files read) once, here.
        filters = PairFilters(ignore_pairs=self.ignore_pairs, usd_filters=self.usd_filters, set_a=self.set_a,
                              set_b=self.set_b, allow_missing=self.allow_missing)
        object.__setattr__(self, "_pair_filters", filters)
        for name in ("set_a", "set_b"):  # split at commas, as the filters read them
            object.__setattr__(self, name, _patterns(getattr(filters, name)))

    @property
    def pair_filters(self) -> PairFilters:
        """The :class:`~warp_ccd._src.usd.filters.PairFilters` of ``ignore_pairs``, ``usd_filters``, ``set_a``,
        ``set_b`` and ``allow_missing``, made (the ignore-pairs files read) when these options were."""
        return self._pair_filters

    def pipeline_options(self) -> PipelineOptions:
        """The options of the pipeline that detects each frame: ``segments``, ``tolerance``, ``clearance``,
        ``self_intersections`` and ``containment``."""
        return PipelineOptions(segments=self.segments, tolerance=self.tolerance, clearance=self.clearance,
                               self_intersections=self.self_intersections, containment=self.containment)

    def sweep_options(self) -> PipelineOptions:
        """The options of the continuous pipeline that sweeps each interval (``continuous``): its
        ``min_distance``."""
        return PipelineOptions(continuous=True, min_distance=self.min_distance)

    def replace(self, **changes: Any) -> CheckOptions:
        """A copy with ``changes`` (checked as a new object is)."""
        return dataclasses.replace(self, **changes)


def check_options(options: CheckOptions | None, changes: dict[str, Any], where: str) -> CheckOptions:
    """What a check is called with: ``options`` (or the defaults) with the keyword ``changes`` over it, as one
    checked object (:func:`~warp_ccd._src.runtime.options.merged_options`; ``where`` names the call,
    ``"check_usd"`` or ``"check_many"``, in a TypeError)."""
    return merged_options(CheckOptions, options, changes, where)
