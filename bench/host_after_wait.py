"""How fast the host runs right after it waited: the same host work timed after waits of 0.05 to 50 ms.

A frame's host time (:attr:`~warp_ccd._src.pipeline.pipeline.CollisionResult.host_ms`) is measured right after
the host waited for the previous frame. This measures how much that wait alone slows the host, with
work that does not change with the wait. After a wait of ``T`` ms, one of

* ``sleep``: ``time.sleep(T)`` (no GPU);
* ``spin``: Python spinning on ``time.perf_counter`` for ``T`` (no GPU, the core kept busy);
* ``sync``: a one-thread kernel that runs ``T`` on the GPU, then ``wp.synchronize_device`` (how a
  frame of ``T`` ms ends);

three pieces of host work are timed, each by itself after its own wait:

* ``python``: a fixed bit of Python (a list from an 8-element array, a loop over it, a small
  object), in us;
* ``launch``: ``wp.capture_launch`` of a graph of one tiny kernel (CUDA only), in us;
* ``detect``: ``detect(advance=dt)`` of a pipeline over a small scene (``--objects``, a frame of
  about 0.1 ms on an H100): its ``host_ms`` in us, the same code and scene after every wait.

For ``python``, the thread's CPU time is taken too (``time.thread_time_ns``, around the wall
clock's readings, so it includes them and its own call: 1-6 us more than the wall time when warm):
when the wall time grows and the CPU time does not, the thread was not running. ``steal_ms`` is
the steal time ``/proc/stat`` reports for all CPUs over each case (a virtual machine's host
running something else), per repetition; it counts in clock ticks (10 ms) summed over the CPUs.
The ``sync`` wait is as long as the kernel calibrated once at the start, about ``T``. The
``detect`` row means host time only on CUDA: on the CPU, Warp runs the kernels inside the launch.

JSON (``--out``): device, date, versions, git commit, ``config`` and ``rows`` of ``{"method",
"wait_ms", "work", "us_min", "us_median", "cpu_us_median", "steal_ms"}``.

    python -m bench.host_after_wait --device cuda:0 --out bench/results/host_after_wait_cuda0.json
"""

from __future__ import annotations

import os
import sys
import time
import types

import numpy as np
import warp as wp

from warp_ccd import CollisionPipeline, Scene

from .command import add_out_option, add_row, bench_parser, start, write_result

DT = 1.0 / 60.0
METHODS = ("sleep", "spin", "sync")
WORKS = ("python", "launch", "detect")


@wp.kernel
def _burn_kernel(iterations: int, out: wp.array[float]):
    """One thread: ``iterations`` dependent multiply-adds (a GPU busy for a set time)."""
    x = float(0.0)
    for _ in range(iterations):
        x = x * 0.999999 + 1.0e-6
    out[0] = x


@wp.kernel
def _tiny_kernel(out: wp.array[float]):
    out[0] = out[0] + 1.0


def _python_work(values: np.ndarray):
    """A fixed bit of Python, about 1-3 us when the core is warm."""
    counts = values.tolist()
    total = 0
    for k, c in enumerate(counts):
        total += c + k
    return types.SimpleNamespace(counts=counts, total=total, view=lambda: total)


def _steal_ms() -> float | None:
    """Steal time of all CPUs so far (``/proc/stat``), in ms; None where there is none."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8]) * 1000.0 / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return None


class Waits:
    """Waits of a set length by each method (the GPU kernel calibrated once)."""

    def __init__(self, device):
        self.device = device
        self.out = wp.zeros(1, dtype=float, device=device)
        self.ns_per_iteration = None
        if device.is_cuda:
            wp.launch(_burn_kernel, dim=1, inputs=[1000, self.out], device=device)
            wp.synchronize_device(device)
            n = 2_000_000
            start = time.perf_counter()
            wp.launch(_burn_kernel, dim=1, inputs=[n, self.out], device=device)
            wp.synchronize_device(device)
            self.ns_per_iteration = (time.perf_counter() - start) * 1e9 / n

    def methods(self) -> tuple[str, ...]:
        return METHODS if self.device.is_cuda else METHODS[:2]

    def wait(self, method: str, ms: float) -> None:
        if method == "sleep":
            time.sleep(ms * 1e-3)
        elif method == "spin":
            end = time.perf_counter() + ms * 1e-3
            while time.perf_counter() < end:
                pass
        else:
            iterations = max(1, int(ms * 1e6 / self.ns_per_iteration))
            wp.launch(_burn_kernel, dim=1, inputs=[iterations, self.out], device=self.device)
            wp.synchronize_device(self.device)


def main(argv: list[str] | None = None) -> int:
    parser = bench_parser(__doc__.splitlines()[0])
    parser.add_argument("--waits", type=float, nargs="+", default=[0.05, 1.0, 5.0, 20.0, 50.0], help="ms")
    parser.add_argument("--objects", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=15)
    add_out_option(parser)
    args, device, doc = start(parser, argv)
    waits = Waits(device)
    pipe = CollisionPipeline(Scene.random(args.objects, seed=0, device=device))
    for _ in range(3):
        pipe.detect(advance=DT)
    values = np.arange(8, dtype=np.int64)
    graph = None
    if device.is_cuda:
        with wp.ScopedCapture(device=device) as capture:
            wp.launch(_tiny_kernel, dim=1, inputs=[waits.out], device=device)
        graph = capture.graph
    doc["config"] = {**vars(args), "ns_per_gpu_iteration": waits.ns_per_iteration}
    works = WORKS if graph is not None else ("python", "detect")
    for method in waits.methods():
        for ms in args.waits:
            for work in works:
                wall, cpu = [], []
                steal0 = _steal_ms()
                for _ in range(args.repeats):
                    waits.wait(method, ms)
                    c0, t0 = time.thread_time_ns(), time.perf_counter()
                    if work == "python":
                        _python_work(values)
                    elif work == "launch":
                        wp.capture_launch(graph)
                    else:
                        result = pipe.detect(advance=DT)
                    t1, c1 = time.perf_counter(), time.thread_time_ns()
                    wall.append(result.host_ms * 1e3 if work == "detect" else (t1 - t0) * 1e6)
                    cpu.append((c1 - c0) * 1e-3)
                    wp.synchronize_device(device)
                steal1 = _steal_ms()
                row = {"method": method, "wait_ms": ms, "work": work,
                       "us_min": round(float(np.min(wall)), 2), "us_median": round(float(np.median(wall)), 2),
                       "cpu_us_median": round(float(np.median(cpu)), 2) if work == "python" else None,
                       "steal_ms": None if steal0 is None else round((steal1 - steal0) / args.repeats, 3)}
                add_row(doc, row)
    write_result(args.out, doc)
    return 0


if __name__ == "__main__":
    sys.exit(main())
