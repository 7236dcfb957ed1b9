"""``warp-ccd check`` over several files, or on a Ray cluster (``--ray``):
:func:`~warp_ccd._src.check.batch.check_many`.

One file on a cluster writes what one file in one process writes (the report and overlay of the merged
result are the serial ones). Several files: a summary each and one line for the batch; ``--report`` holds every
file's report (or its error) in one JSON file (:meth:`~warp_ccd._src.check.batch.BatchReport.to_json`), ``--usd-out``
is a folder that receives ``<name>_overlay.usd`` for each file with findings. A file that fails is reported and
the others go on; the exit status is the worst over the files. ``--preview`` (one picture of one scene) is for one
file in one process.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable

from .common import (
    REPORT_STDOUT,
    CliError,
    check_options_from,
    flat_values,
    init_warp,
    pending_outputs,
    quiet_warp,
    refuse_overwriting,
    require_usd,
    resolve_device,
)

__all__ = ["check_batch"]

def _overlay_paths(files: list[str], folder: str) -> list[str]:
    """``folder/<name>_overlay.usd`` per file; names made unique with the parent folder's name where they repeat."""
    names = [os.path.splitext(os.path.basename(f))[0] for f in files]
    out = []
    for f, n in zip(files, names):
        if names.count(n) > 1:
            n = f"{os.path.basename(os.path.dirname(os.path.abspath(f)))}_{n}"
        out.append(os.path.join(folder, f"{n}_overlay.usd"))
    if len(set(out)) < len(out):
        dup = next(p for p in out if out.count(p) > 1)
        raise ValueError(f"--usd-out: two files would write {dup}; check them in separate runs")
    return out


def check_batch(args, files: list[str], frames, fail: Callable[[str], CliError]) -> tuple[int, str | None]:
    """Runs ``check`` on ``files`` with :func:`~warp_ccd._src.check.batch.check_many` (on Ray with ``--ray``).

    Returns:
        The worst exit status over the files, and with ``--report -`` the JSON text (else None).
    """
    from ..check.batch import check_many
    from ..check.overlay import prepare_overlay

    several = len(files) > 1
    to_stdout = args.report == REPORT_STDOUT
    try:
        if args.preview is not None:
            raise ValueError("--preview is for one file checked in one process (without --ray)")
        if args.workers is not None and args.ray is None:
            raise ValueError("--workers is an option of --ray")
        inputs = [("one of the files to check", f) for f in files]
        refuse_overwriting(inputs, [(flag, path) for flag, path in (("--report", None if to_stdout else args.report),
                                                                    ("--usd-out", args.usd_out)) if path is not None])
        if args.report is not None and not to_stdout:
            from ..output import check_output_path

            check_output_path(args.report, (".json",), "report")
        overlays = None
        if args.usd_out is not None:
            if several:
                if os.path.exists(args.usd_out) and not os.path.isdir(args.usd_out):
                    raise ValueError(f"--usd-out {args.usd_out}: with several files, a folder for their overlays")
                overlays = _overlay_paths(files, args.usd_out)
                refuse_overwriting(inputs, [("--usd-out's overlay", path) for path in overlays])
                try:
                    os.makedirs(args.usd_out, exist_ok=True)
                except OSError as exc:
                    raise ValueError(f"--usd-out {args.usd_out}: cannot make the folder ({exc.strerror})") from None
            else:
                from ..usd.export import validate_stage_path

                validate_stage_path(args.usd_out)
                overlays = [args.usd_out]
        options = check_options_from(args)
    except ValueError as exc:
        raise fail(str(exc)) from None
    require_usd(fail)
    quiet_warp()
    device = None
    if args.ray is None:
        init_warp()
        try:
            device = resolve_device(args.device)
        except ValueError as exc:
            raise fail(str(exc)) from None
    try:
        batch = check_many(files, options, frames=frames, prims=flat_values(args.prims), device=device,
                           ray=args.ray is not None, ray_address=None if args.ray in (None, "local") else args.ray,
                           workers=args.workers, frames_per_task=args.frames_per_task, given_as=args.given_as)
    except ValueError as exc:
        raise fail(str(exc)) from None
    if not several and batch.files[0].report is None:
        raise CliError(f"warp-ccd check: error: {batch.files[0].error}", batch.files[0].exit_status)
    for f in batch.files:
        if f.report is not None and f.report.precision_note:
            print(f"warp-ccd check: note: {f.report.precision_note}", file=sys.stderr)
    print(batch.summary(top=args.top) if several else _one(batch, args.top))
    text = None
    with pending_outputs(fail) as (pending, lines):
        if several:
            if to_stdout:
                text = batch.json_text()
            elif args.report is not None:
                pending.append(batch.prepare_json(args.report))
                lines.append("  report : {}")
        else:  # one file: it has its report (its failure ended the command above)
            report = batch.files[0].report
            if to_stdout:
                text = report.json_text()
            elif args.report is not None:
                pending.append(report.prepare_json(args.report))
                lines.append("  report : {}")
        if overlays is not None:
            for f, path in zip(batch.files, overlays):
                if f.report is not None and (f.report.findings or not several):
                    pending.append(prepare_overlay(f.report, path))
                    lines.append("  overlay: {}")
    if to_stdout:
        print("  report : standard output")
    return batch.exit_status, text


def _one(batch, top: int) -> str:
    """The summary of a batch of one file: its report's, and the workers that ran it."""
    f = batch.files[0]
    return f.report.summary(top=top) + f"\n  on {batch.workers} {batch.engine} workers, {f.tasks} tasks"
