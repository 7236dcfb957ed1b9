"""Checking many USD files, or long animations in parts: units of work, their results merged as one run.

:func:`check_many` checks every file of a list (globs expanded) with :func:`~warp_ccd._src.check.check.check_usd` and
returns a :class:`BatchReport`: one :class:`FileResult` per file, its merged
:class:`~warp_ccd._src.check.report.CheckReport`
or the error that stopped it. The work is cut into :class:`~warp_ccd._src.check.tasks.CheckTask` s (:func:`plan_tasks`):
a whole file, or a (file, range of time codes) where there are fewer files than workers or ``frames_per_task``
asks for it; a continuous check's range starts one time code early, so that the interval across the cut is
checked, and that time code's frame is dropped when the parts are merged (:func:`merge_reports`). Every task gets the
one :class:`~warp_ccd._src.check.options.CheckOptions` checked when :func:`check_many` was called (it pickles for
Ray, with the ignore-pairs files it read here: the workers read no option again).

The tasks run in this process one after the other, or on a Ray cluster (:mod:`~warp_ccd._src.check.cluster`: one actor
per GPU, kernels and stages kept warm across tasks). Either way the result is the serial one: each part is a
plain-data report; merged, a file's frames, intervals, pair summaries, JSON and overlay are those of
:func:`~warp_ccd._src.check.check.check_usd` over the whole file (timings apart). One precision for a whole file: a part
whose coordinates need float64 makes every part of its file run in float64, as the serial check would.

A file whose parts find different objects (a prim invisible at the first time code and visible later: the import
reads visibility, PointInstancer masks and prototypes at its first time code) is checked again whole, in one task.

Known difference: a scene whose float32 or float64 choice depends on the time code a part starts at through
deforming points or an animated scale (the choice is made from the first time code read) can choose differently
in parts than in one run; where deforming points move beyond float32's reach only late, one run stops there with an
error ("check it in float64") while the parts run in float64 and report.
"""

from __future__ import annotations

import functools
import glob
import math
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..output import PendingFile, prepare_text
from ..runtime.aliases import DeviceLike, PathLike
from ..runtime.options import check_option
from .options import CheckOptions, check_options
from .report import SCHEMA_VERSION, CheckReport
from .tasks import EXIT_BAD_INPUT, EXIT_CLEAN, EXIT_FINDINGS, EXIT_INTERNAL, CheckTask, TaskOutcome, run_task

__all__ = ["EXIT_BAD_INPUT", "EXIT_CLEAN", "EXIT_FINDINGS", "EXIT_INTERNAL", "BatchReport", "CheckTask", "FileResult",
           "check_many", "expand_paths", "merge_reports", "plan_tasks", "run_task"]

MIN_FRAMES_PER_TASK = 32
"""About the fewest time codes a part of a file gets when files are split to keep every worker busy (parts are
cut evenly: a few may get one less)."""


@dataclass
class FileResult:
    """One file of a batch.

    Attributes:
        path: the file.
        report: its :class:`~warp_ccd._src.check.report.CheckReport` (merged from its parts), or None when it failed.
        error: why it failed (one line naming the file or prim), or None.
        exit_status: 0 nothing found, 1 findings (:attr:`~warp_ccd._src.check.report.CheckReport.findings`), 2 bad
            input, 3 an internal error.
        tasks: how many tasks checked it.
    """

    path: str
    report: CheckReport | None = None
    error: str | None = None
    exit_status: int = EXIT_CLEAN
    tasks: int = 1

    def to_json(self) -> dict:
        """``{"path", "exit_status", "report"}`` or ``{"path", "exit_status", "error"}``."""
        out: dict[str, Any] = {"path": self.path, "exit_status": self.exit_status}
        if self.report is not None:
            out["report"] = self.report.to_json()
        else:
            out["error"] = self.error
        return out


@dataclass
class BatchReport:
    """The result of :func:`check_many`.

    Attributes:
        files: one :class:`FileResult` per file, in the order given.
        engine: ``"serial"`` (this process) or ``"ray"``.
        workers: how many workers ran the tasks (1 in this process).
        seconds: wall time of the whole batch, ``{"total": s}``.
    """

    files: list[FileResult] = field(default_factory=list)
    engine: str = "serial"
    workers: int = 1
    seconds: dict = field(default_factory=dict)

    @property
    def exit_status(self) -> int:
        """The worst status over the files (0 when there are none)."""
        return max((f.exit_status for f in self.files), default=EXIT_CLEAN)

    @property
    def reports(self) -> list[CheckReport | None]:
        """The files' reports (None where a file failed), in order."""
        return [f.report for f in self.files]

    def to_json(self) -> dict:
        """The batch as JSON-ready data: ``schema_version``, ``exit_status``, ``engine``, ``workers``, ``seconds``
        and ``files`` (each with its :meth:`~warp_ccd._src.check.report.CheckReport.to_json` report or its error)."""
        return {"schema_version": SCHEMA_VERSION, "exit_status": self.exit_status, "engine": self.engine,
                "workers": self.workers, "seconds": self.seconds, "files": [f.to_json() for f in self.files]}

    def json_text(self) -> str:
        """:meth:`to_json` as the text the report file holds (what ``--report -`` prints), newline-terminated."""
        import json

        return json.dumps(self.to_json(), indent=1) + "\n"

    def prepare_json(self, path: PathLike) -> PendingFile:
        """Writes :meth:`to_json` to a temporary file beside ``path`` (``.json``), not yet in place."""
        return prepare_text(path, self.json_text(), (".json",), "report")

    def summary(self, top: int = 10) -> str:
        """Each file's summary (or its error), then one line for the batch."""
        lines = []
        for f in self.files:
            lines.append(f.report.summary(top=top) if f.report is not None else f"{f.path}: error: {f.error}")
        found = sum(f.exit_status == EXIT_FINDINGS for f in self.files)
        failed = sum(f.exit_status >= EXIT_BAD_INPUT for f in self.files)
        total = self.seconds.get("total")
        lines.append(f"{len(self.files)} files: {found} with findings, {failed} failed"
                     + (f"; {self.engine}, {self.workers} workers" if self.engine != "serial" else "")
                     + (f"; {total:.2f} s" if total is not None else ""))
        return "\n".join(lines)


def expand_paths(paths: PathLike | Sequence[PathLike]) -> list[str]:
    """Files and glob patterns (``*``, ``?``, ``[...]``, ``**`` for any folders) as a list of files.

    A name that exists is taken as it is; a pattern is replaced by its matches, sorted. The same file twice is
    kept once (the first time).

    Raises:
        ValueError: no paths, or a pattern matching no file.
    """
    if isinstance(paths, (str, bytes, os.PathLike)):
        paths = [paths]
    out: list[str] = []
    for given in paths:
        text = os.fsdecode(os.fspath(given))
        if os.path.exists(text) or not glob.has_magic(text):
            found = [text]
        else:
            found = sorted(p for p in glob.glob(text, recursive=True) if os.path.isfile(p))
            if not found:
                raise ValueError(f"{text}: no file matches this pattern")
        out.extend(found)
    if not out:
        raise ValueError("no USD files given")
    seen: set[str] = set()
    return [p for p in out if not (os.path.realpath(p) in seen or seen.add(os.path.realpath(p)))]


def plan_tasks(paths: Sequence[str], *, frames: Any = None, workers: int = 1, frames_per_task: int | None = None,
               continuous: bool = False) -> tuple[list[CheckTask], dict[int, str]]:
    """Cuts the work into tasks.

    A file is one task, unless ``frames_per_task`` is given or there are fewer files than ``workers``: then its
    time codes (:func:`~warp_ccd._src.usd.stage.stage_time_codes` of ``frames``) are cut into ranges of
    ``frames_per_task`` (default: an even share of every worker, at least :data:`MIN_FRAMES_PER_TASK`). With
    ``continuous``, every range but the first starts one time code early (its :attr:`CheckTask.skip` is 1).

    Returns:
        ``(tasks, errors)``: the tasks, largest first; ``errors`` maps the index of a file that could not be
        opened to count its time codes to the message.
    """
    from ..usd.stage import open_stage, stage_time_codes

    tasks: list[CheckTask] = []
    errors: dict[int, str] = {}
    split = frames_per_task is not None or len(paths) < workers
    paths = [os.path.abspath(p) for p in paths]  # workers elsewhere open them from another folder
    if not split:
        return [CheckTask(i, p) for i, p in enumerate(paths)], errors
    counted: dict[int, np.ndarray] = {}
    for i, p in enumerate(paths):
        try:
            counted[i] = stage_time_codes(open_stage(p), frames)
        except ValueError as exc:
            errors[i] = str(exc)
    total = sum(len(t) for t in counted.values())
    size = frames_per_task or max(MIN_FRAMES_PER_TASK, math.ceil(total / max(workers, 1)))
    for i, times in counted.items():
        parts = max(1, math.ceil(len(times) / size))
        cuts = np.linspace(0, len(times), parts + 1).round().astype(int)
        for k in range(parts):
            lo = cuts[k] - (1 if continuous and k > 0 else 0)
            tasks.append(CheckTask(i, paths[i], times[lo:cuts[k + 1]], k, cuts[k] - lo))
    tasks.sort(key=lambda t: -t.frames)
    return tasks, errors


def merge_reports(parts: Sequence[CheckReport], skip: Sequence[int] = ()) -> CheckReport:
    """One report from the reports of consecutive ranges of one file's time codes, in time order.

    Args:
        parts: the parts' reports (all of one precision).
        skip: per part, how many of its first frames belong to the part before (a continuous check's overlap).

    Returns:
        The report a check of the whole range gives: frames and intervals in time order, timings summed,
        the precision note and largest coordinate over the parts, the extent of the last part.

    Raises:
        ValueError: the parts are not of one file, objects and precision.
    """
    if not parts:
        raise ValueError("merge_reports: no parts")
    skip = list(skip) or [0] * len(parts)
    if len(skip) != len(parts):
        raise ValueError(f"merge_reports: {len(skip)} skips for {len(parts)} parts")
    first = parts[0]
    for p in parts[1:]:
        if p.stage != first.stage or p.object_path != first.object_path or p.precision != first.precision:
            raise ValueError(f"merge_reports: parts of {first.stage} disagree on their stage, objects or precision")
    merged = CheckReport(**{k: v for k, v in first.__dict__.items() if k != "source"})
    merged.frames = [f for p, s in zip(parts, skip) for f in p.frames[s:]]
    if first.intervals is not None:
        merged.intervals = [iv for p in parts for iv in p.intervals]
    keys = dict.fromkeys(k for p in parts for k in p.seconds)
    merged.seconds = {k: round(sum(p.seconds.get(k, 0.0) for p in parts), 4) for k in keys}
    far = max(parts, key=lambda p: p.max_coordinate)
    merged.max_coordinate = far.max_coordinate
    merged.precision_note = far.precision_note or next((p.precision_note for p in parts if p.precision_note), None)
    merged.extent = parts[-1].extent
    return merged


def _by_file(outcomes: Sequence[TaskOutcome]) -> dict[int, list[TaskOutcome]]:
    """The outcomes of each file, by its index in the batch."""
    by_file: dict[int, list[TaskOutcome]] = {}
    for o in outcomes:
        by_file.setdefault(o.task.file, []).append(o)
    return by_file


def _file_results(paths: Sequence[str], outcomes: Sequence[TaskOutcome], errors: dict[int, str]) -> list[FileResult]:
    """Per file: its parts merged, or the error of its earliest failing part (the one a serial run meets first)."""
    by_file = _by_file(outcomes)
    results = []
    for i, path in enumerate(paths):
        if i in errors:
            results.append(FileResult(path, error=errors[i], exit_status=EXIT_BAD_INPUT, tasks=0))
            continue
        parts = sorted(by_file.get(i, []), key=lambda o: o.task.part)
        failed = [o for o in parts if o.report is None]
        if failed:
            results.append(FileResult(path, error=failed[0].error, exit_status=failed[0].status, tasks=len(parts)))
            continue
        report = merge_reports([o.report for o in parts], [o.task.skip for o in parts])
        results.append(FileResult(path, report, exit_status=EXIT_FINDINGS if report.findings else EXIT_CLEAN,
                                  tasks=len(parts)))
    return results


Run = Callable[[list[CheckTask], CheckOptions], list[TaskOutcome]]
"""Runs tasks with options (on the batch's engine, over its time codes and prims)."""


def _one_precision(outcomes: list[TaskOutcome], options: CheckOptions, run: Run) -> list[TaskOutcome]:
    """Runs again in float64 the float32 parts of a file whose other parts needed float64 (as one run would)."""
    reported = [[o for o in parts if o.report is not None] for parts in _by_file(outcomes).values()]
    again = [o for parts in reported if len({o.report.precision for o in parts}) > 1
             for o in parts if o.report.precision == "float32"]
    if not again:
        return outcomes
    redone = {id(o.task): r for o, r in zip(again, run([o.task for o in again], options.replace(precision="float64")))}
    return [redone.get(id(o.task), o) for o in outcomes]


def _whole_files(outcomes: list[TaskOutcome], options: CheckOptions, run: Run) -> list[TaskOutcome]:
    """Checks whole, as one task, the files whose parts found different objects, or where a part found bad input (a
    prim visible, or an instance present, from a later time code on: the import reads them at its first time code,
    as one run does, so a pattern or set may match nothing in a part): the one-run result or error."""
    again = [parts[0].task for parts in _by_file(outcomes).values()
             if len(parts) > 1 and (any(o.status == EXIT_BAD_INPUT for o in parts)
                                    or len({tuple(o.report.object_path) for o in parts if o.report}) > 1)]
    if not again:
        return outcomes
    whole = [CheckTask(t.file, t.path) for t in again]
    files = {t.file for t in whole}
    return [o for o in outcomes if o.task.file not in files] + run(whole, options)


class _InProcess:
    """The engine of a check without Ray: the tasks run here, one after the other, on ``device``."""

    def __init__(self, device: DeviceLike = None) -> None:
        self.device = device

    def run(self, tasks: Sequence[CheckTask], options: CheckOptions, done: Callable[[TaskOutcome], None] | None = None,
            *, frames: Any = None, prims: Any = None) -> list[TaskOutcome]:
        """Runs ``tasks`` in order (``frames``, ``prims``: as :func:`~warp_ccd._src.check.tasks.run_task` takes
        them); ``done`` is called as each ends."""
        out = []
        for t in tasks:
            out.append(run_task(t, options, frames=frames, prims=prims, device=self.device))
            if done is not None:
                done(out[-1])
        return out

    def close(self) -> None:
        """Nothing to end."""


def check_many(paths: PathLike | Sequence[PathLike], options: CheckOptions | None = None, *, frames: Any = None,
               prims: str | Sequence[str] | None = None, device: DeviceLike = None, ray: bool = False,
               ray_address: str | None = None, workers: int | None = None, frames_per_task: int | None = None,
               given_as: Mapping[str, str] | None = None, **kwargs: Any) -> BatchReport:
    """Checks many USD files (or long animations in parts), in this process or on a Ray cluster.

    Example::

        batch = check_many(["shots/*.usd"], ray=True, clearance=0.01)
        for f in batch.files:
            print(f.path, f.exit_status, f.report.findings if f.report else f.error)

    Args:
        paths: USD files or glob patterns (:func:`expand_paths`).
        options: the :class:`~warp_ccd._src.check.options.CheckOptions` of every file's check (checked when it was
            made; passed to the tasks as it is), or None: the defaults. Its ``progress`` is one bar on stderr over
            the time codes of all tasks; its ``read_workers`` count in this process only (Ray workers choose their
            own).
        frames: the time codes of every file (as :func:`~warp_ccd._src.check.check.check_usd` takes them).
        prims: the prims to check in every file (as :func:`~warp_ccd._src.check.check.check_usd` takes them).
        device: the Warp device of a check in this process (Ray actors use their GPU, or the CPU).
        ray: run the tasks on a Ray cluster (:mod:`~warp_ccd._src.check.cluster`): a local one unless ``ray_address``
            names one (``"auto"``, ``"host:port"``, ``"ray://host:port"``), or the one this process is connected
            to already. Needs ``pip install 'warp-ccd[distributed]'``.
        ray_address: the cluster to connect to (implies ``ray``).
        workers: Ray actors (>= 1; default: one per GPU of the cluster, else one per CPU); in this process: the
            parts a lone file is cut into (default 1: whole files).
        frames_per_task: cut every file into ranges of this many time codes (>= 1; default: see :func:`plan_tasks`).
        given_as: the names ``workers`` and ``frames_per_task`` were given as, for their messages (the command
            line: its flags).
        **kwargs: options by name (fields of :class:`~warp_ccd._src.check.options.CheckOptions`, over
            ``options``).

    Returns:
        The :class:`BatchReport`; a file that fails is reported there (``error``, ``exit_status`` 2 or 3) and the
        others go on.

    Raises:
        TypeError: a keyword that is no option.
        ValueError: a bad option (before any file is read), no files, a pattern matching nothing, Ray asked for but
            not installed or not reachable.
    """
    from tqdm import tqdm

    start = time.perf_counter()
    options = check_options(options, kwargs, "check_many")
    names = dict(given_as or {})
    workers = check_option("workers", workers, names.get("workers"))
    frames_per_task = check_option("frames_per_task", frames_per_task, names.get("frames_per_task"))
    files = expand_paths(paths)
    tasks_options = options.replace(progress=False) if options.progress else options  # one bar: the batch's
    use_ray = bool(ray) or ray_address is not None
    if use_ray:
        from .cluster import RayEngine

        engine = RayEngine(ray_address, workers)
        count = engine.workers
    else:
        engine, count = _InProcess(device), workers or 1
    run = functools.partial(engine.run, frames=frames, prims=prims)
    bar = None
    try:
        tasks, errors = plan_tasks(files, frames=frames, workers=count, frames_per_task=frames_per_task,
                                   continuous=options.continuous)
        bar = tqdm(total=sum(t.frames or 1 for t in tasks), desc="checking", unit="frame", leave=False,
                   disable=not options.progress or None, file=sys.stderr)

        def done(outcome: TaskOutcome) -> None:
            bar.update(outcome.task.frames or 1)

        outcomes = run(tasks, tasks_options, done)
        outcomes = _one_precision(_whole_files(outcomes, tasks_options, run), tasks_options, run)
    finally:
        if bar is not None:
            bar.close()
        engine.close()
    return BatchReport(_file_results(files, outcomes, errors), "ray" if use_ray else "serial", count,
                       {"total": round(time.perf_counter() - start, 4)})
