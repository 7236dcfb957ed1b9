"""Every option a user sets, and its rule, in one table: :data:`OPTIONS`, checked by :func:`check_option`.

An option is a name with a rule (:class:`Rule`: a number or an integer within bounds, a flag, one of some
names). The options objects (:class:`~warp_ccd._src.pipeline.options.PipelineOptions`,
:class:`~warp_ccd._src.check.options.CheckOptions`) check each of their fields by its rule when they are
made, at the API boundary, and are passed down; a stage class a user builds directly checks the options it
takes by the same rule. A rule is written once, here, so an option has one set of bounds and one message
shape wherever it enters::

    tolerance must be a finite number in [0, 0.1), got 0.5
    leaf_size must be an integer in [1, 256] or None, got 0
    segments must be True or False, got 'yes'
    narrow_phase must be one of ['edge_face', 'moller'], got 'gjk'

Adding an option: its row here, its field in the options object that takes it, and its use.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from .checks import integer_option, is_integer, number_option

__all__ = ["CLEARANCE_MAX", "LEAF_SIZE_MAX", "OPTIONS", "PRECISIONS", "SEPARATING_AXES", "Rule", "check_option",
           "merged_options"]

PRECISIONS = ("float32", "float64")
"""Vertex, pose and test precisions."""

LEAF_SIZE_MAX = 256
"""Most triangles per leaf: a traversal thread emits up to 4 leaf pairs of ``leaf_size**2`` rows at once and its
block of 256 counts them in int32 (:func:`~warp_ccd._src.runtime.buffers.block_reserve`)."""

CLEARANCE_MAX = 1.0e37
"""The largest clearance (scene units): object boxes, float32, are padded by half of it."""

SEPARATING_AXES = (3, 6)
"""Axes of the traversal's box test: 3, ``a``'s; 6, both objects'."""

COUNT_MAX = 2**31 - 1
"""The largest count of a buffer or a loop (int32)."""


@dataclass(frozen=True)
class Rule:
    """What an option takes.

    Attributes:
        kind: ``"number"`` (a finite real, ``bool`` refused), ``"integer"`` (``bool`` refused), ``"flag"``
            (``True`` or ``False``, numpy's too) or ``"choice"`` (one of :attr:`choices`; with bounds, an
            integer within them is taken too).
        low, high: bounds of a number or an integer (None: unbounded on that side).
        low_open, high_open: a number's bound itself excluded.
        choices: the names of a ``"choice"``, or the values of an ``"integer"`` that is not a range.
        allow_none: None is taken too (a default chosen later, by what the option acts on).
    """

    kind: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple = ()
    allow_none: bool = False

    def check(self, name: str, value: Any) -> Any:
        """``value`` checked and normalised (``int``, ``float``, ``bool``, or the name).

        Raises:
            ValueError: ``"{name} must be ..., got {value!r}"``.
        """
        if value is None and self.allow_none:
            return None
        none = " or None" if self.allow_none else ""
        if self.kind == "number":
            if value is None:
                raise ValueError(f"{name} must be a finite number{none}, got None")
            return number_option(name, value, low=self.low, high=self.high, low_open=self.low_open,
                                 high_open=self.high_open)
        if self.kind == "integer":
            return integer_option(name, value, low=self.low, high=self.high, choices=self.choices or None,
                                  allow_none=self.allow_none)
        if self.kind == "flag":
            if isinstance(value, (bool, np.bool_)):
                return bool(value)
            raise ValueError(f"{name} must be True or False{none}, got {value!r}")
        # a choice among names (or, with bounds, an integer within them)
        if isinstance(value, str) and value in self.choices:
            return value
        if self.low is not None and is_integer(value) and self.low <= value <= self.high:
            return int(value)
        also = f" or an integer in [{self.low}, {self.high}]" if self.low is not None else ""
        raise ValueError(f"{name} must be one of {sorted(self.choices)}{also}{none}, got {value!r}")


FLAG = Rule("flag")
CAPACITY = Rule("integer", low=1, allow_none=True)
"""An initial buffer capacity (it grows); None: the stage's default."""

OPTIONS: dict[str, Rule] = {
    # What runs: the methods of the stages, the precision.
    "broad_phase": Rule("choice", choices=("sap", "all_pairs", "nxn")),
    "mid_phase": Rule("choice", choices=("bvh", "all_pairs")),
    "narrow_phase": Rule("choice", choices=("moller", "edge_face")),
    "precision": Rule("choice", choices=PRECISIONS),
    # What counts as a contact.
    "tolerance": Rule("number", low=0.0, high=0.1, high_open=True),
    "min_depth": Rule("number", low=0.0),
    "count_touching": FLAG,
    # What is reported besides.
    "segments": FLAG,
    "containment": FLAG,
    "continuous": FLAG,
    "min_distance": Rule("number", low=0.0),
    "ccd_tolerance": Rule("number", low=0.0, low_open=True),
    "ccd_max_iterations": Rule("integer", low=1, high=COUNT_MAX),
    "clearance": Rule("number", low=0.0, high=CLEARANCE_MAX),
    "self_intersections": FLAG,
    "contacts": FLAG,
    "signed": FLAG,
    "max_per_pair": Rule("integer", low=1, high=32),  # contacts' MAX_PER_PAIR_LIMIT
    "margin": Rule("number", low=0.0, high=CLEARANCE_MAX),
    "duplicates": FLAG,
    # How a frame runs.
    "timings": FLAG,
    "graph": Rule("flag", allow_none=True),
    "leaf_size": Rule("integer", low=1, high=LEAF_SIZE_MAX, allow_none=True),
    "cut_depth": Rule("integer", low=0, high=16),
    "separating_axes": Rule("integer", choices=SEPARATING_AXES),
    "object_bounds": Rule("choice", choices=("auto", "tree", "vertices"), low=0, high=COUNT_MAX),
    "rebuild_every": Rule("integer", low=0),
    # Initial capacities (every buffer grows).
    "pair_capacity": CAPACITY,
    "entry_capacity": Rule("integer", low=1, high=COUNT_MAX // 2 - 1, allow_none=True),
    "candidate_capacity": CAPACITY,
    "hit_capacity": CAPACITY,
    "front_capacity": CAPACITY,
    "near_capacity": CAPACITY,
    "self_capacity": CAPACITY,
    "listed_capacity": CAPACITY,
    # What a USD check reads.
    "include_invisible": FLAG,
    "include_purposes": Rule("choice", choices=("guide", "proxy", "render", "default")),  # each of them
    "allow_missing": FLAG,
    "usd_filters": FLAG,
    "read_workers": Rule("integer", low=0, allow_none=True),
    "progress": FLAG,
    # How a check of many files runs.
    "workers": Rule("integer", low=1, allow_none=True),
    "frames_per_task": Rule("integer", low=1, allow_none=True),
}
"""Every option by name, and its rule."""


def merged_options(kind: type, options: Any, changes: dict[str, Any], where: str) -> Any:
    """The options object an API call gets: ``options`` (an instance of the options dataclass ``kind``, or None
    for its defaults) with the keyword ``changes`` over it, checked as a new object is.

    Args:
        kind: the options class (``PipelineOptions``, ``CheckOptions``).
        options: an instance of it, or None.
        changes: the keyword options given besides (fields of ``kind``).
        where: the call, for the message of a wrong object or an unknown keyword (``"CollisionPipeline"``).

    Raises:
        TypeError: ``options`` is no ``kind``, or a keyword is no field of it.
        ValueError: a bad option (naming it).
    """
    if options is not None and not isinstance(options, kind):
        raise TypeError(f"{where}: options must be a {kind.__name__}, got {type(options).__name__}")
    unknown = sorted(set(changes) - {f.name for f in dataclasses.fields(kind)})
    if unknown:
        raise TypeError(f"{where}() got an unexpected keyword argument {unknown[0]!r}")
    if options is None:
        return kind(**changes)
    return dataclasses.replace(options, **changes) if changes else options


def check_option(name: str, value: Any, given_as: str | None = None) -> Any:
    """``value`` of option ``name`` checked by its rule in :data:`OPTIONS` (and normalised).

    Args:
        name: the option.
        value: what was given.
        given_as: the keyword the caller took it as, where it is not ``name`` (a continuous query's
            ``tolerance`` is the option ``ccd_tolerance``): the message names what the user wrote.

    Raises:
        ValueError: naming the option, what it takes, and the value given.
    """
    return OPTIONS[name].check(given_as or name, value)
