"""USD stages as the import and the check open them: the stage of a path, its layers, its time codes.

:func:`open_stage` opens a file (or passes a ``Usd.Stage`` through), naming the path in every
error, without USD's own warnings about the layers it could not open (``Tf.DiagnosticTrap``, where pxr has
it: those layers are the caller's to name, in one error or in a report's ``missing``);
:func:`missing_layers` lists the sublayers, references and payloads that composition could not open,
:func:`require_layers` refuses them unless asked to check without; :func:`layer_files`
lists every file a stage reads (so that no output is written over one of them);
:func:`stage_time_codes` turns ``frames`` (``None``, numbers or a ``slice``) into the time codes to
check. ``pxr`` is imported inside the functions.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..runtime.aliases import PathLike

if TYPE_CHECKING:
    from pxr import Usd

__all__ = ["MAX_FRAMES", "layer_files", "missing_layers", "open_stage", "require_layers", "stage_time_codes"]

MAX_FRAMES = 10**6
"""The most time codes one read takes (every one is looked up, and its poses kept, up front)."""


def open_stage(stage_or_path: Usd.Stage | PathLike) -> Usd.Stage:
    """A ``Usd.Stage`` from a stage or a file path.

    Raises:
        ValueError: the file is missing or USD cannot open it (the message names the path).
    """
    from pxr import Sdf, Usd

    if isinstance(stage_or_path, Usd.Stage):
        return stage_or_path
    try:
        path = os.fsdecode(os.fspath(stage_or_path))
    except TypeError:
        raise ValueError(f"stage: expected a Usd.Stage or a file path, got {type(stage_or_path).__name__}") from None
    if os.path.isdir(path):
        raise ValueError(f"cannot read {path}: it is a directory, not a USD file")
    if not os.path.isfile(path):
        raise ValueError(f"cannot read {path}: no such file")
    if not os.access(path, os.R_OK):
        raise ValueError(f"cannot read {path}: permission denied")
    try:
        loaded = Sdf.Layer.Find(path)
        if loaded is not None:
            loaded.Reload()  # a layer still open from an earlier read: the file as it is now
        stage = _open_without_missing_warnings(path)
    except Exception as exc:  # pxr.Tf.ErrorException
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValueError(f"cannot read {path}: not a USD file USD can open ({first})") from None
    if stage is None:
        raise ValueError(f"cannot read {path}: not a USD file USD can open")
    return stage


def _open_without_missing_warnings(path: str) -> Usd.Stage:
    """``Usd.Stage.Open(path)``, less the warnings USD reports (on standard error) for the sublayers,
    references and payloads it could not open: each names one of :func:`missing_layers`, which the caller
    reports. Every other diagnostic is passed on as USD reports it. Without ``Tf.DiagnosticTrap`` (USD before
    it), USD's warnings are printed as before."""
    from pxr import Tf, Usd

    trap_type = getattr(Tf, "DiagnosticTrap", None)
    if trap_type is None:
        return Usd.Stage.Open(path)
    with trap_type() as trap:  # on leaving, what is left of the trapped diagnostics is reported as usual
        stage = Usd.Stage.Open(path)
        if stage is not None and trap.HasWarnings():
            missing = set(missing_layers(stage))
            trap.EraseMatching(lambda d: isinstance(d, Tf.Warning) and _asset_of(d.commentary) in missing)
    return stage


def _asset_of(text: str) -> str:
    """The first ``@asset@`` path of a USD message (the whole message stripped where it names none)."""
    import re

    match = re.search(r"@([^@]+)@", text)
    return match.group(1) if match else text.strip()


def missing_layers(stage) -> list[str]:
    """The sublayers, references and payloads of a stage that could not be opened.

    USD opens a stage whose sublayer, reference or payload files are missing (it reports a
    warning, which :func:`open_stage` holds back, and composes the stage without them); this lists those
    files, as composition reported them (``Usd.Stage.GetCompositionErrors``; muted layers are not listed).

    Args:
        stage: a ``Usd.Stage``.

    Returns:
        Their asset paths (absolute where USD made them so), sorted, each once.
    """
    from pxr import Ar, Pcp

    if hasattr(stage, "GetCompositionErrors"):
        kinds = (Pcp.ErrorType_InvalidAssetPath, Pcp.ErrorType_InvalidSublayerPath)
        errors = stage.GetCompositionErrors()
        return sorted({_asset_of(str(error)) for error in errors if error.errorType in kinds})
    # Older USD: every composition arc of the layers in use that does not resolve.
    resolver = Ar.GetResolver()
    found = set()
    for layer in stage.GetUsedLayers():
        for asset in layer.GetCompositionAssetDependencies():
            path = layer.ComputeAbsolutePath(asset) if not layer.anonymous else asset
            if path and not resolver.Resolve(path):
                found.add(path)
    return sorted(found)


def require_layers(stage, allow_missing: bool = False, missing: list[str] | None = None) -> list[str]:
    """:func:`missing_layers` of a stage, an error unless they may be left out.

    Args:
        stage: a ``Usd.Stage``.
        allow_missing: check the stage without them (else a ValueError).
        missing: the stage's :func:`missing_layers`, when already known.

    Returns:
        The missing layers' asset paths.

    Raises:
        ValueError: naming the stage and the first of them, unless ``allow_missing``.
    """
    missing = missing_layers(stage) if missing is None else missing
    if missing and not allow_missing:
        root = stage.GetRootLayer()
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise ValueError(f"{root.realPath or root.identifier}: cannot open {missing[0]}{more}, a sublayer, reference "
                         "or payload of the stage (--allow-missing, allow_missing=True, checks it without)")
    return missing


def layer_files(stage) -> list[str]:
    """The files of every layer a stage uses: its root layer, sublayers, references, payloads and
    value clips (a layer inside a ``.usdz`` package as the package), resolved through symbolic links.

    Args:
        stage: a ``Usd.Stage``.

    Returns:
        Absolute real paths, sorted, each once (anonymous layers have none).
    """
    from pxr import Ar

    found = set()
    for layer in stage.GetUsedLayers():
        path = layer.realPath
        if not path:
            continue
        if Ar.IsPackageRelativePath(path):
            path = Ar.SplitPackageRelativePathOuter(path)[0]
        found.add(os.path.realpath(path))
    return sorted(found)


def stage_time_codes(stage: Usd.Stage, frames: float | Sequence[float] | slice | None = None) -> np.ndarray:
    """The time codes to check.

    Args:
        stage: a ``Usd.Stage``.
        frames: ``None`` (every integer time code of the stage's authored range; ``[0]`` when it
            has none), a number, a sequence of numbers, or ``(start, end)`` / ``(start, end, step)``
            given as a ``slice`` (``end`` included; a missing ``start`` or ``end`` is the stage's).

    Returns:
        ``(F,)`` float64 time codes, increasing, at most :data:`MAX_FRAMES` of them.

    Raises:
        ValueError: an empty, non-finite or decreasing range, a step <= 0, times outside the
            stage's authored range, a stage range whose start is after its end (when the frames
            come from it), or more than :data:`MAX_FRAMES` time codes.
    """
    has_range = stage.HasAuthoredTimeCodeRange()
    lo, hi = float(stage.GetStartTimeCode()), float(stage.GetEndTimeCode())
    layer = stage.GetRootLayer()
    name = layer.realPath or layer.identifier
    reversed_range = has_range and hi < lo
    from_stage = frames is None or (isinstance(frames, slice) and (frames.start is None or frames.stop is None))
    if reversed_range and from_stage:
        raise ValueError(f"{name}: its startTimeCode {lo:g} is after its endTimeCode {hi:g}; choose the time codes "
                         "with frames (--frames START:END[:STEP])")
    if frames is None:
        if not has_range:
            return np.zeros(1)
        frames = slice(lo, hi, 1.0)
    if isinstance(frames, slice):
        start = lo if frames.start is None else frames.start
        end = hi if frames.stop is None else frames.stop
        step = 1.0 if frames.step is None else frames.step
        try:
            start, end, step = float(start), float(end), float(step)
        except (TypeError, ValueError):
            raise ValueError(f"frames: expected numbers, got {frames!r}") from None
        if not np.isfinite([start, end, step]).all() or step <= 0 or end < start:
            raise ValueError(f"frames: need start <= end and step > 0, got {start:g}:{end:g}:{step:g}")
        count = np.floor((end - start) / step + 1e-9) + 1
        if count > MAX_FRAMES:
            raise ValueError(f"{name}: {count:.0f} time codes in {start:g}..{end:g} (step {step:g}), more than "
                             f"{MAX_FRAMES} at once; choose fewer with frames (--frames START:END[:STEP])")
        times = start + step * np.arange(int(count))
    else:
        try:
            times = np.atleast_1d(np.asarray(frames, dtype=np.float64))
        except (TypeError, ValueError):
            raise ValueError(f"frames: expected numbers, got {frames!r}") from None
        if times.ndim != 1 or times.size == 0 or not np.isfinite(times).all():
            raise ValueError(f"frames: expected finite time codes, got {frames!r}")
        if (np.diff(times) <= 0).any():
            raise ValueError("frames: time codes must increase")
        if times.size > MAX_FRAMES:
            raise ValueError(f"frames: {times.size} time codes, more than {MAX_FRAMES} at once")
    if has_range and not reversed_range and (times[0] < lo - 1e-9 or times[-1] > hi + 1e-9):
        raise ValueError(f"frames {times[0]:g}..{times[-1]:g} lie outside the stage's time range {lo:g}..{hi:g}")
    return times
