"""The overlay of a check: a USD layer over the checked stage that colours what the check found, frame by frame.

:func:`write_overlay` writes it from a :class:`~warp_ccd._src.check.report.CheckReport` alone (plain data: it
can come from another process or be merged from parts); the checked stage is opened again from its file
where the report does not carry the import it came from. See :mod:`~warp_ccd._src.check.check` for the colours.
"""

from __future__ import annotations

import os

import numpy as np

from ..output import PendingFile
from ..runtime.aliases import PathLike
from ..usd.export import COLOR_COLLIDING, COLOR_FREE, COLOR_SEGMENT, segment_points, validate_stage_path
from .clearance import COLOR_CLEARANCE, COLOR_SOFT_CLASH, soft_clash_flags
from .duplicates import COLOR_DUPLICATE, duplicate_flags
from .report import CheckReport
from .self_intersection import COLOR_SELF, self_flags
from .sweep import COLOR_TUNNELLING, tunnelling_flags

__all__ = ["COLOR_CLEAR", "COLOR_CONTAINED", "COLOR_PENETRATING", "contained_flags", "prepare_overlay", "write_overlay"]

COLOR_PENETRATING = COLOR_COLLIDING
"""displayColor of a prim while it penetrates another (the animation writer's colliding colour)."""
COLOR_CLEAR = COLOR_FREE
"""displayColor of a coloured prim in frames where it penetrates nothing (when it had no constant colour)."""
COLOR_CONTAINED = (0.55, 0.25, 0.95)
"""displayColor (linear RGB) of a prim wholly inside another, or holding one (``containment`` checks), where it
penetrates nothing (red wins)."""


def contained_flags(frames: list, num_objects: int) -> np.ndarray:
    """``(F, N)`` bool: object ``i`` lies wholly inside another, or holds one, at frame ``k``."""
    flags = np.zeros((len(frames), num_objects), bool)
    for k, f in enumerate(frames):
        if f.contained is not None:
            flags[k, f.contained.ravel()] = True
    return flags



def write_overlay(report: CheckReport, out_path: PathLike) -> str:
    """Writes a USD layer over the checked stage: penetrating prims in colour per frame (with a
    continuous check, tunnelling prims in orange at the start of the interval, and their
    ``warpCcd:tunnelling`` attribute; with a clearance, prims in a soft clash in yellow; with
    duplicates, prims that coincide with another in blue; with containment, a prim wholly inside another and
    the one holding it in violet), and as
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
        The :class:`~warp_ccd._src.output.PendingFile`: :meth:`~warp_ccd._src.output.PendingFile.commit`
        moves it to ``out_path``, :meth:`~warp_ccd._src.output.PendingFile.discard` removes it.

    Raises:
        ValueError: as :func:`write_overlay`.
    """
    from pxr import Gf, Sdf, Usd, UsdGeom, Vt

    from ..usd.stage import layer_files, open_stage

    full, ext = validate_stage_path(out_path)
    imp = report.source
    if imp is not None:
        src = imp.stage
    else:  # a report from elsewhere (another process, merged from parts): its stage from its file
        if not os.path.isfile(report.stage):
            raise ValueError(f"overlay: the checked stage {report.stage} is not a file (save it first)")
        src = open_stage(report.stage)
    source = src.GetRootLayer().realPath
    if not source:
        raise ValueError("overlay: the checked stage is not a file (save it first)")
    if os.path.realpath(full) in layer_files(src):
        raise ValueError(f"cannot write {out_path}: it is a layer of the checked stage ({os.path.realpath(full)})")
    pending = PendingFile(full)
    try:
        layer = Sdf.Layer.CreateAnonymous(ext)
        layer.subLayerPaths.append(source)
        stage = Usd.Stage.Open(layer)
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
        inner = contained_flags(report.frames, n)  # containment checks: violet, after red
        red, orange, yellow = Gf.Vec3f(*COLOR_PENETRATING), Gf.Vec3f(*COLOR_TUNNELLING), Gf.Vec3f(*COLOR_SOFT_CLASH)
        magenta, blue, violet = Gf.Vec3f(*COLOR_SELF), Gf.Vec3f(*COLOR_DUPLICATE), Gf.Vec3f(*COLOR_CONTAINED)
        with Sdf.ChangeBlock():
            # Prims (instance proxies through their instanceable ancestor), one colour per frame.
            targets: dict[str, tuple[np.ndarray, ...]] = {}
            for i in np.nonzero((hit | tunnel | soft | mine | twin | inner).any(axis=0))[0].tolist():
                if report.object_instancer[i] is not None:
                    continue
                prim = src.GetPrimAtPath(report.object_path[i])
                while prim.IsInstanceProxy():
                    prim = prim.GetParent()
                key = str(prim.GetPath())
                was = targets.get(key, (np.zeros(len(times), bool),) * 6)
                targets[key] = (was[0] | hit[:, i], was[1] | tunnel[:, i], was[2] | soft[:, i], was[3] | mine[:, i],
                                was[4] | twin[:, i], was[5] | inner[:, i])
            for path, (flags, tunnels, softs, selfs, twins, inners) in targets.items():
                prim = stage.GetPrimAtPath(path)
                primvar = UsdGeom.PrimvarsAPI(prim).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray,
                                                                  UsdGeom.Tokens.constant)
                clear = Gf.Vec3f(*COLOR_CLEAR)
                own = UsdGeom.PrimvarsAPI(src.GetPrimAtPath(path)).GetPrimvar("displayColor")
                if own and own.GetInterpolation() == UsdGeom.Tokens.constant and own.Get() is not None \
                        and len(own.Get()) == 1:
                    clear = own.Get()[0]
                for tc, f, c, g, m, d, y in zip(times, flags.tolist(), inners.tolist(), tunnels.tolist(),
                                                selfs.tolist(), twins.tolist(), softs.tolist()):
                    color = (red if f else violet if c else orange if g else magenta if m else blue if d
                             else yellow if y else clear)
                    primvar.Set(Vt.Vec3fArray([color]), tc)
                if report.intervals is not None:
                    flag = prim.CreateAttribute("warpCcd:tunnelling", Sdf.ValueTypeNames.Bool, custom=True)
                    for tc, g in zip(times, tunnels.tolist()):
                        flag.Set(bool(g), tc)
            # PointInstancer instances: the instancer's per-instance colour.
            instancer = np.array(report.object_instancer, dtype=object)
            for path in sorted({p for p in report.object_instancer if p is not None}):
                rows = np.nonzero(instancer == path)[0]
                if not (hit[:, rows] | tunnel[:, rows] | soft[:, rows] | mine[:, rows] | twin[:, rows]
                        | inner[:, rows]).any():
                    continue
                schema = UsdGeom.PointInstancer(src.GetPrimAtPath(path))
                size = len(np.asarray(schema.GetProtoIndicesAttr().Get(Usd.TimeCode(times[0]))))
                prim = stage.GetPrimAtPath(path)
                primvar = UsdGeom.PrimvarsAPI(prim).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray,
                                                                  UsdGeom.Tokens.vertex)
                for k, tc in enumerate(times):
                    colors = np.tile(np.asarray(COLOR_CLEAR, np.float32), (size, 1))
                    colors[report.object_instance[rows][soft[k, rows]]] = COLOR_SOFT_CLASH
                    colors[report.object_instance[rows][twin[k, rows]]] = COLOR_DUPLICATE
                    colors[report.object_instance[rows][mine[k, rows]]] = COLOR_SELF
                    colors[report.object_instance[rows][tunnel[k, rows]]] = COLOR_TUNNELLING
                    colors[report.object_instance[rows][inner[k, rows]]] = COLOR_CONTAINED
                    colors[report.object_instance[rows][hit[k, rows]]] = COLOR_PENETRATING
                    primvar.Set(Vt.Vec3fArray.FromNumpy(colors), tc)
        # Defined outside the change block: a new prim needs the stage recomposed. The intersection
        # segments, and the soft clashes' closest points joined, as time-sampled curves.
        curves = []
        width = report.extent * 2e-3
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

