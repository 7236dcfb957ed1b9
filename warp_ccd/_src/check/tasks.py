"""A unit of work of a check over many files, and running one: :class:`CheckTask`, :class:`TaskOutcome`,
:func:`run_task`. Shared by the check in this process and on a Ray cluster (:mod:`~warp_ccd._src.check.batch`,
:mod:`~warp_ccd._src.check.cluster`).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..runtime.aliases import DeviceLike
from .options import CheckOptions
from .report import CheckReport

__all__ = ["EXIT_BAD_INPUT", "EXIT_CLEAN", "EXIT_FINDINGS", "EXIT_INTERNAL", "CheckTask", "TaskOutcome", "run_task"]

EXIT_CLEAN, EXIT_FINDINGS, EXIT_BAD_INPUT, EXIT_INTERNAL = 0, 1, 2, 3
"""A file's status, as ``warp-ccd check`` exits: nothing found, findings, bad input, an internal error."""


@dataclass
class CheckTask:
    """One unit of work: a file, or a range of its time codes.

    Attributes:
        file: index of the file in the batch.
        path: the file.
        times: ``(F,)`` float64 time codes to check, or None: the file's ``frames`` (the whole file).
        part: the part's number among its file's parts, in time order.
        skip: frames of the part's report that belong to the part before (1 where a continuous check's part
            starts one time code early), dropped when merged.
    """

    file: int
    path: str
    times: np.ndarray | None = None
    part: int = 0
    skip: int = 0

    @property
    def frames(self) -> int:
        """Its number of time codes (0: the whole file, not counted up front)."""
        return 0 if self.times is None else len(self.times)


@dataclass
class TaskOutcome:
    """What a task gave: its report, or the error that stopped it (``status``: 2 bad input, 3 internal)."""

    task: CheckTask
    report: CheckReport | None = None
    error: str | None = None
    status: int = EXIT_CLEAN


def run_task(task: CheckTask, options: CheckOptions, *, frames: Any = None, prims: str | Sequence[str] | None = None,
             device: DeviceLike = None, stage: Any = None) -> TaskOutcome:
    """Runs one task with :func:`~warp_ccd._src.check.check.check_usd`; a bad input or an internal error becomes the
    outcome's error, not an exception.

    Args:
        task: the task.
        options: the batch's :class:`~warp_ccd._src.check.options.CheckOptions` (checked already).
        frames: the time codes of a whole file (as :func:`~warp_ccd._src.check.check.check_usd` takes them); a
            part's own ``times`` replace them.
        prims: the prims to check (as :func:`~warp_ccd._src.check.check.check_usd` takes them).
        device: the Warp device to check on.
        stage: the file's ``Usd.Stage`` when it is already open (a worker keeps them), else None.
    """
    from ..geometry.precision import PrecisionWarning
    from .check import check_usd

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PrecisionWarning)  # the report carries it (precision_note)
            report = check_usd(task.path if stage is None else stage, options,
                               frames=frames if task.times is None else task.times, prims=prims, device=device)
    except ValueError as exc:
        return TaskOutcome(task, error=str(exc), status=EXIT_BAD_INPUT)
    except Exception as exc:  # noqa: BLE001 (a file's failure is reported; the others go on)
        return TaskOutcome(task, error=f"internal error: {type(exc).__name__}: {exc}", status=EXIT_INTERNAL)
    report.source = None  # plain data, as it would come back from another process
    return TaskOutcome(task, report)
