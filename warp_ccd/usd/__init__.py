"""USD in and out: read a stage's meshes as a scene, check an animation for interpenetration, write one.

>>> from warp_ccd import usd
>>> scene = usd.scene_from_usd("anim.usd", time=12)               # the meshes of one time code
>>> report = usd.check_usd("anim.usd", frames=slice(0, 100))      # what penetrates, frame by frame
>>> usd.write_overlay(report, "overlay.usda")                     # a layer that colours it
>>> batch = usd.check_many(["shots/*.usd"], ray=True)            # many files, or long ones in parts, on Ray
>>> with usd.UsdAnimationWriter("out.usd", scene) as writer:      # a simulation, frame by frame
...     writer.add_frame(0, pipe.detect())

Modules: :mod:`~warp_ccd.usd.importer` (:class:`UsdMeshImport`: a stage read once, set to each time
code), :mod:`~warp_ccd.usd.stage` (opening a stage, its layers and time codes),
:mod:`~warp_ccd.usd.meshes` (a mesh prim as triangles), :mod:`~warp_ccd.usd.poses` (world matrices as
poses and scales), :mod:`~warp_ccd.usd.workers` (the
processes that read transforms in parallel), :mod:`~warp_ccd.usd.filters` (worlds, excluded pairs, sets A
and B from prim paths), :mod:`~warp_ccd.usd.check` (:func:`check_usd`), :mod:`~warp_ccd.usd.report` (its
plain-data report),
:mod:`~warp_ccd.usd.overlay` (the overlay written from a report), :mod:`~warp_ccd.usd.batch` (:func:`check_many`:
files and ranges of time codes as tasks, parts merged), :mod:`~warp_ccd.usd.cluster` (the tasks on Ray actors),
:mod:`~warp_ccd.usd.export` (:class:`UsdAnimationWriter`). ``pxr`` (usd-core) is imported
inside functions only: importing this package works without it. The names of the module
``warp_ccd.usd`` of 0.1 (now :mod:`~warp_ccd.usd.export`) still resolve here for one release, with a
warning.
"""

from .._deprecated import module_aliases
from .batch import BatchReport, FileResult, check_many
from .check import (
    REPORT_SCHEMA_PATH,
    SCHEMA_VERSION,
    CheckReport,
    FrameContacts,
    check_usd,
    report_schema,
    write_overlay,
)
from .export import UsdAnimationWriter
from .importer import UsdMeshImport, scene_from_usd
from .stage import open_stage, stage_time_codes

__all__ = [
    "BatchReport",
    "FileResult",
    "REPORT_SCHEMA_PATH",
    "SCHEMA_VERSION",
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

# The module warp_ccd.usd of 0.1 is now warp_ccd.usd.export: its other public names, kept one release.
__getattr__ = module_aliases(__name__, {name: f"warp_ccd.usd.export:{name}" for name in (
    "COLOR_COLLIDING", "COLOR_FREE", "COLOR_SEGMENT", "STAGE_EXTENSIONS", "segment_points", "validate_stage_path")})
