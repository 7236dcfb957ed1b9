"""The check on a Ray cluster: one actor per GPU (or per CPU without GPUs), tasks handed out as actors free up.

:class:`RayEngine` connects to a cluster (or starts a local one), starts its actors and runs
:class:`~warp_ccd._src.check.tasks.CheckTask` s on them (:func:`~warp_ccd._src.check.tasks.run_task`), largest first,
each actor
holding one task at a time. An actor (:class:`CheckWorker`) keeps its process warm across tasks: Warp initialised
and its kernels loaded once, its CUDA context, and the stages it opened (the parts of one file read one stage). A
GPU actor holds no CPU: it reads the transforms of a big animation as cluster tasks on its share of the CPUs
(shares of the prims, :data:`~warp_ccd._src.usd.workers.POOL`); a CPU actor reads in its own process. No reader
processes of its own: the cluster schedules all the work. An actor
that dies (a killed process, a lost node) is restarted by Ray and its task run again, up to
:data:`MAX_RETRIES` times (then the task's file fails; the other tasks go on); a worker that lost its task gets
the next one once it answers again (Ray refuses tasks sent to an actor while it restarts, which took longer than
four such refusals on a loaded machine, each of which counted as a loss); workers the cluster cannot place
are ended after :data:`START_TIMEOUT`; results come back as plain data
(:class:`~warp_ccd._src.check.report.CheckReport` pickles without the stage).

``ray`` is imported inside the functions: this module imports without it (``pip install 'warp-ccd[distributed]'``).
"""

from __future__ import annotations

import os
import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from typing import Any

from ..runtime.start import init_warp
from .options import CheckOptions
from .tasks import EXIT_INTERNAL, CheckTask, TaskOutcome, run_task

__all__ = ["FAULT_ENV", "MAX_RETRIES", "START_TIMEOUT", "CheckWorker", "RayEngine"]

MAX_RETRIES = 3
"""How many times a task runs again after its worker died under it (Ray restarts the worker)."""
FAULT_ENV = "WARP_CCD_FAULT_EXIT_ONCE"
"""Fault injection for tests: where this environment variable names a file ``F``, each task an actor starts adds
a line to ``F.starts``; where ``F`` does not exist yet, the first actor to create it writes its process id there
and waits to be killed (:data:`FAULT_WAIT` seconds at most, then it ends its process itself), as a worker killed
mid-task."""
FAULT_WAIT = 300.0
"""Seconds an actor of :data:`FAULT_ENV` waits to be killed."""
RESTART_POLL = 0.2
"""Seconds between two probes of an actor that Ray is restarting."""
START_TIMEOUT = 300.0
"""Seconds the workers have to start (Warp initialised, the CUDA context made); those the cluster cannot place
in that time are ended."""
OPEN_STAGES = 4
"""Stages an actor keeps open (the most recently used)."""


class CheckWorker:
    """A Ray actor's state: its device, and its open stages.

    Args:
        quiet: silence Warp's messages (the driver shows progress and results).
        read_tasks: cluster tasks that read the transforms of a big animation (0 or 1: this process reads them).
    """

    def __init__(self, quiet: bool = True, read_tasks: int = 0) -> None:
        import warp as wp

        wp.config.quiet = quiet
        init_warp()
        self.device = "cuda:0" if wp.is_cuda_available() else "cpu"
        self._stages: OrderedDict[str, Any] = OrderedDict()
        self.read_tasks = read_tasks
        if read_tasks > 1:  # reads of big animations as cluster tasks (the actor holds no CPU of its own)
            from ..usd import workers

            workers.POOL, workers.POOL_WORKERS = _ray_pool, read_tasks

    def run(self, task: CheckTask, options: CheckOptions, frames: Any = None, prims: Any = None) -> TaskOutcome:
        """Runs ``task`` with ``options`` (made for these workers by :meth:`RayEngine.run`) on this actor's
        device; ``frames`` (the time codes of a whole file) and ``prims`` as
        :func:`~warp_ccd._src.check.tasks.run_task` takes them."""
        marker = os.environ.get(FAULT_ENV)
        if marker:
            _fault(marker)
        return run_task(task, options, frames=frames, prims=prims, device=self.device, stage=self._stage(task.path))

    def _stage(self, path: str) -> Any:
        """The file's stage, opened once per actor (None where it cannot be opened: the task names the error)."""
        from ..usd.stage import open_stage

        key = os.path.realpath(path)
        stage = self._stages.get(key)
        if stage is None:
            try:
                stage = open_stage(path)
            except ValueError:
                return None
            self._stages[key] = stage
            while len(self._stages) > OPEN_STAGES:
                self._stages.popitem(last=False)
        self._stages.move_to_end(key)
        return stage

    def pid(self) -> int:
        """This actor's process id."""
        return os.getpid()


def _fault(marker: str) -> None:
    """The test's fault of :data:`FAULT_ENV`: the task's start counted, and the first task to claim ``marker`` (created
    exclusively) waits to be killed."""
    with open(marker + ".starts", "a") as fh:
        fh.write(f"{os.getpid()}\n")
    try:
        fh = open(marker, "x")
    except FileExistsError:
        return
    with fh:
        fh.write(str(os.getpid()))
    time.sleep(FAULT_WAIT)
    os._exit(1)


def _ray_pool(fn: Callable, tasks: list) -> Callable[[], list]:
    """:data:`~warp_ccd._src.usd.workers.POOL` on Ray: ``fn`` on every task as a task of one CPU, retried where its
    worker dies; returns the wait for their results."""
    import ray

    remote = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(fn)
    refs = [remote.remote(t) for t in tasks]
    return lambda: ray.get(refs)


class RayEngine:
    """Actors on a Ray cluster that run check tasks.

    Args:
        address: the cluster (``"auto"``, ``"host:port"``, ``"ray://host:port"``); None or ``"local"``: the one
            this process is connected to, else a new local cluster.
        workers: actors to start (default: one per GPU of the cluster, else one per CPU); more than the GPUs share
            them.

    Attributes:
        workers: how many actors run.
        gpus: whether the actors run on GPUs.
        gpu_share: the GPU each actor holds (1; a fraction where there are more workers than GPUs; 0 on CPUs).

    Raises:
        ValueError: Ray is not installed, or the cluster cannot be reached.
    """

    def __init__(self, address: str | None = None, workers: int | None = None) -> None:
        try:
            import ray
        except ImportError:
            raise ValueError("Ray is not installed: pip install 'warp-ccd[distributed]'") from None
        self._ray = ray
        self._started = False
        if not ray.is_initialized():
            try:
                ray.init(address=None if address in (None, "local") else address, include_dashboard=False,
                         log_to_driver=False, logging_level="ERROR", configure_logging=False)
            except (ConnectionError, RuntimeError, ValueError) as exc:
                raise ValueError(f"cannot reach the Ray cluster {address or '(local)'}: {exc}") from None
            self._started = True
        resources = ray.cluster_resources()
        num_gpus = int(resources.get("GPU", 0))
        self.gpus = num_gpus > 0
        self.workers = workers or (num_gpus if self.gpus else max(1, int(resources.get("CPU", 1))))
        # More workers than GPUs (or CPUs, without GPUs) share them: a fraction each, so that all can be placed.
        num_cpus = max(1.0, float(resources.get("CPU", 1)))
        self.gpu_share = min(1.0, num_gpus / self.workers) if self.gpus else 0.0
        cpu_share = 0 if self.gpus else min(1.0, num_cpus / self.workers)
        # Ray restarts a dead actor (always); the driver runs its task again, up to MAX_RETRIES times per task.
        actor = ray.remote(CheckWorker).options(num_gpus=self.gpu_share, num_cpus=cpu_share, max_restarts=-1,
                                                max_task_retries=0)
        # GPU workers hold no CPU: each reads the transforms of a big animation as tasks on its share of the
        # cluster's CPUs (CPU workers hold them all and read in their own process).
        self.read_tasks = int(num_cpus // self.workers) if self.gpus else 0
        self._actors = []
        self._actors = self._placed([actor.remote(True, self.read_tasks) for _ in range(self.workers)])
        self.workers = len(self._actors)

    def _placed(self, actors: list) -> list:
        """The actors that started within :data:`START_TIMEOUT` seconds (the others, which the cluster cannot
        place, are ended).

        Raises:
            ValueError: none started.
        """
        ray = self._ray
        probes = {a.pid.remote(): a for a in actors}
        ready, waiting = ray.wait(list(probes), num_returns=len(probes), timeout=START_TIMEOUT)
        alive = []
        for ref in ready:
            try:
                ray.get(ref)
                alive.append(probes[ref])
            except ray.exceptions.RayError:
                ray.kill(probes[ref])
        for ref in waiting:
            ray.kill(probes[ref])
        if not alive:
            self.close()
            raise ValueError(f"no Ray worker started within {START_TIMEOUT:g} s (are the cluster's "
                             f"{'GPUs' if self.gpus else 'CPUs'} taken?)")
        return alive

    def run(self, tasks: Sequence[CheckTask], options: CheckOptions, done: Callable[[TaskOutcome], None] | None = None,
            *, frames: Any = None, prims: Any = None) -> list[TaskOutcome]:
        """Runs ``tasks`` (in the order given, each on the next free actor); ``done`` is called as each ends.

        The actors get ``options`` without progress bars and with their own readers: a big animation's transforms
        read as cluster tasks (GPU actors: ``read_workers=None``) or in the actor's process (CPU actors: 0).
        ``frames`` (the time codes of a whole file) and ``prims``: as :func:`~warp_ccd._src.check.tasks.run_task`
        takes them.

        Returns:
            The outcomes, in the order of ``tasks``. A task whose worker died more than :data:`MAX_RETRIES` times
            under it is an internal error of its file.
        """
        ray = self._ray
        options = options.replace(read_workers=None if self.read_tasks > 1 else 0, progress=False)
        pending = list(enumerate(tasks))[::-1]
        running: dict[Any, tuple[int, Any]] = {}
        waking: dict[Any, tuple[Any, float]] = {}  # a probe of an actor that lost its task: (actor, since)
        out: list[TaskOutcome | None] = [None] * len(tasks)
        tries = [0] * len(tasks)
        free = list(self._actors)
        while pending or running or waking:  # an actor that lost its task is awaited: the next run has it too
            while pending and free:
                i, task = pending.pop()
                actor = free.pop()
                tries[i] += 1
                running[actor.run.remote(task, options, frames, prims)] = (i, actor)
            if not running and not waking:  # every actor gone for good
                for i, task in pending:
                    out[i] = TaskOutcome(task, error="internal error: no Ray worker is left", status=EXIT_INTERNAL)
                    if done is not None:
                        done(out[i])
                break
            ready, _ = ray.wait(list(running) + list(waking), num_returns=1)
            for ref in ready:
                if ref in waking:
                    self._woken(ref, waking, free)
                    continue
                i, actor = running.pop(ref)
                try:
                    out[i] = ray.get(ref)
                    free.append(actor)
                except ray.exceptions.RayError as exc:
                    waking[actor.pid.remote()] = (actor, time.monotonic())  # Ray restarts it: its next task then
                    if tries[i] <= MAX_RETRIES:
                        pending.append((i, tasks[i]))
                        continue
                    first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
                    out[i] = TaskOutcome(tasks[i], error=f"internal error: the worker was lost {tries[i]} times "
                                         f"({first})", status=EXIT_INTERNAL)
                if done is not None:
                    done(out[i])
        return out

    def _woken(self, probe: Any, waking: dict, free: list) -> None:
        """An actor's probe after it lost its task has answered: the actor is free again where it did; probed again
        while Ray restarts it (every :data:`RESTART_POLL` seconds, for :data:`START_TIMEOUT` seconds at most); ended
        and dropped where it is gone for good."""
        ray = self._ray
        actor, since = waking.pop(probe)
        try:
            ray.get(probe)
            free.append(actor)
            return
        except ray.exceptions.RayError as exc:
            restarting = isinstance(exc, getattr(ray.exceptions, "ActorUnavailableError", ()))
            if restarting and time.monotonic() - since < START_TIMEOUT:
                time.sleep(RESTART_POLL)
                waking[actor.pid.remote()] = (actor, since)
                return
        ray.kill(actor)
        self._actors.remove(actor)

    def close(self) -> None:
        """Ends the actors, and the local cluster where this engine started it."""
        for a in self._actors:
            self._ray.kill(a)
        self._actors = []
        if self._started:
            self._ray.shutdown()
