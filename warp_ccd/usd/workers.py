"""Worker processes that read the world transforms of a stage saved in a file, a share of the time codes each.

:func:`run_pose_workers` starts one process per task (``python -m warp_ccd.usd.workers TASK OUT``:
a fresh interpreter, so nothing of the caller's ``__main__`` is imported again), passing the task and
the result through pickle files in a temporary folder; each runs :func:`read_poses`, which opens the
file, looks up the world transforms of the given prims at its time codes and splits them into poses
(:func:`~warp_ccd.usd.poses.finite_matrix_poses`). :class:`~warp_ccd.usd.importer.UsdMeshImport`
uses them from :data:`~warp_ccd.usd.importer.PARALLEL_LOOKUPS` lookups on.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import tempfile

import numpy as np
from tqdm import tqdm

from .poses import finite_matrix_poses

__all__ = ["read_poses", "run_pose_workers"]


def run_pose_workers(tasks: list, progress: bool = False) -> list:
    """Runs :func:`read_poses` on each task in a process of its own (``python -m
    warp_ccd.usd.workers TASK OUT``: nothing of the caller's ``__main__`` is imported again).

    Args:
        tasks: :func:`read_poses` tasks, one per process.
        progress: a bar on stderr counts the time codes of the workers done.

    Returns:
        The results of :func:`read_poses`, in the order of ``tasks``.

    Raises:
        ValueError: a worker failed (the message ends with the last line it wrote to stderr).
    """
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    with tempfile.TemporaryDirectory(prefix="warp_ccd-read-") as folder:
        procs = []
        for i, task in enumerate(tasks):
            src, dst = os.path.join(folder, f"task{i}.pkl"), os.path.join(folder, f"out{i}.pkl")
            with open(src, "wb") as fh:
                pickle.dump(task, fh)
            procs.append((subprocess.Popen([sys.executable, "-m", "warp_ccd.usd.workers", src, dst], env=env,
                                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True), dst))
        results = []
        bar = tqdm(total=sum(len(task[2]) for task in tasks), desc="reading transforms", unit="time code",
                   leave=False, disable=not progress or None, file=sys.stderr)
        for (proc, dst), task in zip(procs, tasks):
            _, err = proc.communicate()
            bar.update(len(task[2]))
            if proc.returncode != 0:
                last = err.strip().splitlines()[-1] if err.strip() else f"exit status {proc.returncode}"
                raise ValueError(f"reading transforms in a worker process failed: {last}")
            with open(dst, "rb") as fh:
                results.append(pickle.load(fh))
        bar.close()
    return results


def read_poses(task):
    """Opens a stage file and splits the world transforms of some prims at some time codes into poses.

    Args:
        task: ``(path, prim_paths, times, bake)``: the USD file, ``P`` prim paths, ``(F,)`` time codes
            and ``(P, 3, 3)`` linear parts baked into the shapes (:func:`~warp_ccd.usd.poses.matrix_poses`).

    Returns:
        ``(poses (F, P, 7), scale (F, P), ok (P,), finite (F, P))``: ``ok`` where the transform is a
        similarity relative to ``bake`` at every time code, ``finite`` where it is finite.
    """
    path, prim_paths, times, bake = task
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(path)
    prims = [stage.GetPrimAtPath(p) for p in prim_paths]
    poses = np.empty((len(times), len(prims), 7))
    scale = np.empty((len(times), len(prims)))
    finite = np.empty((len(times), len(prims)), bool)
    ok = np.ones(len(prims), bool)
    for f, t in enumerate(times):
        cache = UsdGeom.XformCache(Usd.TimeCode(float(t)))
        m = np.array([cache.GetLocalToWorldTransform(p) for p in prims], np.float64).reshape(-1, 4, 4)
        finite[f], poses[f], scale[f], good = finite_matrix_poses(m, bake)
        ok &= good
    return poses, scale, ok, finite


if __name__ == "__main__":  # a worker of run_pose_workers: python -m warp_ccd.usd.workers TASK OUT
    with open(sys.argv[1], "rb") as _task:
        _result = read_poses(pickle.load(_task))
    with open(sys.argv[2], "wb") as _out:
        pickle.dump(_result, _out)
