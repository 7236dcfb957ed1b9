"""Worker processes that read the world transforms of a stage saved in a file, a share of the prims each.

:func:`run_pose_workers` starts one process per task, passing the task and the result through pickle
files in a temporary folder; each runs :func:`read_poses`, which opens the file and reads the world
transforms of its prims at every time code (:func:`~warp_ccd._src.usd.xforms.read_world_poses`: in bulk where
the op stacks allow it). The bulk reader's cost grows with the samples read, so the prims are split
(each worker reads its prims' samples once), not the time codes (each worker would read every
prim's ops and, with whole-dictionary reads, every sample).

A worker is a fresh interpreter (nothing of the caller's ``__main__`` is imported again) that imports
this module without running the package's ``__init__`` (the ``warp_ccd`` and ``warp_ccd.usd`` packages
are registered bare, :data:`BOOTSTRAP`): it needs numpy, pxr and tqdm, not Warp, and starts in a
fraction of a second. :class:`~warp_ccd._src.usd.importer.UsdMeshImport` uses them from
:data:`~warp_ccd._src.usd.importer.PARALLEL_LOOKUPS` prim-time codes on, reading one share of the prims itself
while the workers read the others.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import tempfile
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from . import xforms

if TYPE_CHECKING:
    from pxr import Usd

__all__ = ["BOOTSTRAP", "POOL", "POOL_WORKERS", "auto_workers", "boot_packages", "read_poses", "read_shared",
           "run_pose_workers"]

BOOTSTRAP = """import sys, types
for _name, _path in {packages!r}:
    _module = types.ModuleType(_name)
    _module.__path__ = [_path]
    sys.modules[_name] = _module
from warp_ccd._src.usd.workers import main
main(sys.argv[1], sys.argv[2])
"""
"""The worker's command (``python -c``): ``warp_ccd``, ``warp_ccd._src`` and ``warp_ccd._src.usd`` registered as
bare packages of their folders (the worker imports no more than this folder's modules), then :func:`main` on the
task and result files."""


POOL: Callable[[Callable, list], Callable[[], list]] | None = None
"""Where worker processes come from: None, processes started here; or ``POOL(fn, tasks)``, which starts ``fn`` on
every task elsewhere and returns a function that waits for their results in order (a Ray worker sets it, so that
reads run as tasks the cluster schedules on its CPUs)."""


POOL_WORKERS = 0
"""With :data:`POOL`: how many tasks a big read is split into (its owner's share of the cluster's CPUs)."""


def auto_workers() -> int:
    """The readers of a big animation when none were asked for: :data:`POOL_WORKERS` with a :data:`POOL`, else one
    process per CPU (at most 16)."""
    return POOL_WORKERS if POOL is not None else min(os.cpu_count() or 1, 16)


def boot_packages() -> tuple[tuple[str, str], ...]:
    """``(package, folder)`` of ``warp_ccd`` and the packages down to this module's: what a worker registers
    (:data:`BOOTSTRAP`) to import this module and no other of the package."""
    usd = os.path.dirname(os.path.abspath(__file__))
    src = os.path.dirname(usd)
    return ("warp_ccd", os.path.dirname(src)), ("warp_ccd._src", src), ("warp_ccd._src.usd", usd)


def run_pose_workers(tasks: list, progress: bool = False, local: Callable[[], Any] | None = None) -> tuple[list, Any]:
    """Runs :func:`read_poses` on each task in a process of its own, and ``local`` in this process meanwhile.

    Args:
        tasks: :func:`read_poses` tasks, one per process.
        progress: a bar on stderr counts the prims of the workers done.
        local: work for this process while the workers run (its share of the prims), or None.

    Returns:
        ``(results, local result)``: the results of :func:`read_poses` in the order of ``tasks``, and what
        ``local`` returned (None without it).

    Raises:
        ValueError: a worker failed (the message ends with the last line it wrote to stderr).
    """
    if POOL is not None:
        collect = POOL(read_poses, tasks)
        mine = local() if local is not None else None
        return collect(), mine
    from tqdm import tqdm  # here: importing warp_ccd needs no progress bars

    boot = BOOTSTRAP.format(packages=boot_packages())
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    with tempfile.TemporaryDirectory(prefix="warp_ccd-read-") as folder:
        procs = []
        for i, task in enumerate(tasks):
            src, dst = os.path.join(folder, f"task{i}.pkl"), os.path.join(folder, f"out{i}.pkl")
            with open(src, "wb") as fh:
                pickle.dump(task, fh)
            procs.append((subprocess.Popen([sys.executable, "-c", boot, src, dst], env=env, stdout=subprocess.DEVNULL,
                                           stderr=subprocess.PIPE, text=True), dst))
        mine = local() if local is not None else None
        results = []
        bar = tqdm(total=sum(len(task[1]) for task in tasks), desc="reading transforms", unit="prim",
                   leave=False, disable=not progress or None, file=sys.stderr)
        for (proc, dst), task in zip(procs, tasks):
            _, err = proc.communicate()
            bar.update(len(task[1]))
            if proc.returncode != 0:
                last = err.strip().splitlines()[-1] if err.strip() else f"exit status {proc.returncode}"
                raise ValueError(f"reading transforms in a worker process failed: {last}")
            with open(dst, "rb") as fh:
                results.append(pickle.load(fh))
        bar.close()
    return results, mine


def read_shared(stage: Usd.Stage, prims: list, paths: list[str], times: np.ndarray, workers: int, *,
                info: xforms.XformInfo | None = None, progress: bool = False) -> xforms.WorldPoses:
    """:func:`~warp_ccd._src.usd.xforms.read_world_poses` of prims split over ``workers`` processes, this one
    included: each other opens the file and reads a share of the prims while this one reads the first
    share. In this process alone for ``workers`` of 0 or 1, and for a stage not saved as it is (unsaved
    edits, a session layer with content, no file).

    Args:
        stage: the ``Usd.Stage``.
        prims: ``P`` prims (not PointInstancer instances).
        paths: their paths.
        times: ``(F,)`` float64 time codes.
        workers: processes to read with, this one included.
        info: the :class:`~warp_ccd._src.usd.xforms.XformInfo` of ``stage`` for this process's share.
        progress: show a progress bar on stderr.

    Returns:
        The :class:`~warp_ccd._src.usd.xforms.WorldPoses` of the prims, in their order (the same, bit for bit,
        however they are split).
    """
    layer = stage.GetRootLayer()
    workers = min(workers, len(prims))
    clean = layer.realPath and not any(x.dirty for x in stage.GetUsedLayers()) and stage.GetSessionLayer().empty
    # A worker opens the file with the defaults: linear interpolation, every payload loaded, no population mask.
    clean = clean and _opened_as_by_default(stage)
    if workers <= 1 or not clean:
        return xforms.read_world_poses(stage, prims, times, paths=paths, info=info, progress=progress)
    chunks = [c.tolist() for c in np.array_split(np.arange(len(paths)), workers) if c.size]
    tasks = [(layer.realPath, [paths[i] for i in c], times, xforms.FAST_XFORMS) for c in chunks[1:]]
    own = chunks[0]  # this process's share, read while the workers read theirs
    parts, mine = run_pose_workers(tasks, progress, local=lambda: xforms.read_world_poses(
        stage, [prims[i] for i in own], times, paths=[paths[i] for i in own], info=info))
    parts = [mine, *parts]
    return xforms.WorldPoses(*(np.concatenate([getattr(p, name) for p in parts], axis=axis) for name, axis in
                               (("first", 0), ("poses", 1), ("scale", 1), ("ok", 0), ("finite", 1), ("fast", 0))))


def _opened_as_by_default(stage: Usd.Stage) -> bool:
    """Whether ``stage`` reads as ``Usd.Stage.Open(its file)`` does: linear interpolation, every payload loaded,
    no population mask (a worker process opens the file so)."""
    from pxr import Usd

    if stage.GetInterpolationType() != Usd.InterpolationTypeLinear:
        return False
    if not stage.GetPopulationMask().IncludesSubtree("/"):
        return False
    return stage.GetLoadRules().IsLoadedWithAllDescendants("/")


def read_poses(task: tuple) -> xforms.WorldPoses:
    """Opens a stage file and reads the world transforms of some prims at every time code.

    Args:
        task: ``(path, prim_paths, times, fast)``: the USD file, ``P`` prim paths, ``(F,)`` time codes, and
            whether to read in bulk where the op stacks allow it (:data:`~warp_ccd._src.usd.xforms.FAST_XFORMS`).

    Returns:
        The :class:`~warp_ccd._src.usd.xforms.WorldPoses` of the prims.
    """
    from pxr import Usd

    path, prim_paths, times, fast = task
    xforms.FAST_XFORMS = fast
    stage = Usd.Stage.Open(path)
    return xforms.read_world_poses(stage, [stage.GetPrimAtPath(p) for p in prim_paths], times)


def main(src: str, dst: str) -> None:
    """A worker of :func:`run_pose_workers`: the task pickled in ``src``, the result pickled to ``dst``."""
    with open(src, "rb") as fh:
        result = read_poses(pickle.load(fh))
    with open(dst, "wb") as fh:
        pickle.dump(result, fh, protocol=pickle.HIGHEST_PROTOCOL)
