"""USD in and out: read a stage's meshes as a scene, check an animation for interpenetration, write one.

>>> from warp_ccd import usd
>>> scene = usd.scene_from_usd("anim.usd", time=12)               # the meshes of one time code
>>> report = usd.check_usd("anim.usd", frames=slice(0, 100))      # what penetrates, frame by frame
>>> options = usd.CheckOptions(continuous=True, clearance=0.01)   # the check's options, checked when made
>>> report = usd.check_usd("anim.usd", options)
>>> usd.write_overlay(report, "overlay.usda")                     # a layer that colours it
>>> batch = usd.check_many(["shots/*.usd"], ray=True)            # many files, or long ones in parts, on Ray
>>> with usd.UsdAnimationWriter("out.usd", scene) as writer:      # a simulation, frame by frame
...     writer.add_frame(0, pipe.detect())

Modules: :mod:`~warp_ccd._src.usd.importer` (:class:`UsdMeshImport`: a stage read once, set to each time
code), :mod:`~warp_ccd._src.usd.stage` (opening a stage, its layers and time codes),
:mod:`~warp_ccd._src.usd.meshes` (a mesh prim as triangles), :mod:`~warp_ccd._src.usd.poses` (world matrices as
poses and scales), :mod:`~warp_ccd._src.usd.workers` (the
processes that read transforms in parallel), :mod:`~warp_ccd._src.usd.filters` (worlds, excluded pairs, sets A
and B from prim paths), :mod:`~warp_ccd._src.check.check` (:func:`check_usd`), :mod:`~warp_ccd._src.check.options`
(:class:`CheckOptions`), :mod:`~warp_ccd._src.check.report` (its plain-data report),
:mod:`~warp_ccd._src.check.overlay` (the overlay written from a report), :mod:`~warp_ccd._src.check.batch`
(:func:`check_many`:
files and ranges of time codes as tasks, parts merged), :mod:`~warp_ccd._src.check.cluster` (the tasks on Ray actors),
:mod:`~warp_ccd._src.usd.export` (:class:`UsdAnimationWriter`). ``pxr`` (usd-core) is imported
inside functions only: importing this package works without it.
"""

from ._src.check.batch import BatchReport, FileResult, check_many
from ._src.check.check import check_usd
from ._src.check.options import CheckOptions
from ._src.check.overlay import write_overlay
from ._src.check.report import REPORT_SCHEMA_PATH, SCHEMA_VERSION, CheckReport, FrameContacts, report_schema
from ._src.usd.export import UsdAnimationWriter
from ._src.usd.importer import UsdMeshImport, scene_from_usd
from ._src.usd.stage import open_stage, stage_time_codes

__all__ = [
    "BatchReport",
    "FileResult",
    "REPORT_SCHEMA_PATH",
    "SCHEMA_VERSION",
    "CheckOptions",
    "CheckReport",
    "FrameContacts",
    "UsdAnimationWriter",
    "UsdMeshImport",
    "check_many",
    "check_usd",
    "open_stage",
    "report_schema",
    "scene_from_usd",
    "stage_time_codes",
    "write_overlay",
]
