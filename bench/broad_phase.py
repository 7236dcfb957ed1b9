"""Benchmark: the broad phase alone, ms per frame against the number of boxes, with peers.

Boxes like the scaling scene's: cubes whose half sides are uniform in [0.5, 1.5] (the scene's
object radii), centres uniform in a cube of side ``L`` chosen so that each box overlaps
``--overlaps`` others on average, whatever ``N``. Two such cubes overlap when their centres are
within ``h_i + h_j`` on every axis, so a box expects ``(N - 1) * E[(2 (h_i + h_j))^3] / L^3 =
72 (N - 1) / L^3`` partners (``E[(h_i + h_j)^3] = 9``), hence ``L = (72 (N - 1) / overlaps)^(1/3)``
(a little fewer near the walls; the measured mean is printed).

Methods, in the same run on the same boxes, each frame in turn:

* ``sap``: this package's :class:`~warp_ccd._src.broadphase.sap.BroadPhaseSAP`, the reference;
* ``nxn``: this package's :class:`~warp_ccd._src.broadphase.sap.BroadPhaseAllPairs`, for ``N <= --nxn-max``;
* ``warp_bvh``: Warp's ``wp.Bvh`` over the boxes, rebuilt every frame, one ``wp.bvh_query_aabb``
  per box (:class:`WarpBvhBroadPhase`, here);
* ``warp_bvh_refit``: the same tree only refit every frame (boxes do not move here, so this is
  refitting's best case);
* ``newton_sap``: newton's ``BroadPhaseSAP`` when newton is installed, for ``N <= --newton-max``.

A frame is: reset the buffers, launch, copy the counters to pinned host memory, one wait
(:class:`~warp_ccd._src.runtime.frame.CountedFrame`); a buffer that overflowed grows and the frame runs
again. Every method is launched from Python and, on CUDA, also replayed as a captured graph (as
``BroadPhaseSAP.find_pairs`` does); its time is the faster of the two by median (the ``mode``
column), and both are in the JSON (``broad_eager``, ``broad_graph``). ``--warmup`` frames grow
the buffers, load the kernels and capture the graphs; only the ``--frames`` after them are timed (the steady state).

The benchmark judges this package, not its peers: ``nxn`` must give exactly ``sap``'s pairs, and
each peer's differences from ``sap`` are judged by an exact overlap test in numpy. A pair that
``sap`` got wrong ends the run with status 3 (``EXIT_INTERNAL``, after the JSON is written); a peer's wrong pairs
are a finding, reported in the table (``*``) and the JSON (``peer_wrong``).

    python -m bench.broad_phase                             # CPU: N = 1e3..1e5
    python -m bench.broad_phase --device cuda:0 --max-n 1e7  # N = 1e3..1e7
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import warp as wp

from warp_ccd._src.bench.compare import box_overlap_truth, compare_exact
from warp_ccd._src.bench.methods import device_modes
from warp_ccd._src.bench.peers import NewtonBroadPhaseSAP, PeerUnavailable
from warp_ccd._src.bench.timing import ModeFrames, StageTimes
from warp_ccd._src.broadphase.sap import ALL_PAIRS_LIMIT
from warp_ccd._src.cli.common import EXIT_INTERNAL, EXIT_OK
from warp_ccd._src.geometry.box import boxes_overlap
from warp_ccd._src.runtime.buffers import GrowableBuffer, emit_pair
from warp_ccd.stages import BroadPhaseAllPairs, BroadPhaseSAP

from .command import RESULTS, add_run_options, bench_parser, start, write_result

METHODS = ("sap", "nxn", "warp_bvh", "warp_bvh_refit", "newton_sap")
OURS = ("sap", "nxn")
"""This package's methods: they must agree exactly; the others are peers, judged by the truth."""
REFERENCE = "sap"


@wp.kernel
def _bvh_box_pairs_kernel(
    bvh: wp.uint64,
    lower: wp.array[wp.vec3],
    upper: wp.array[wp.vec3],
    pair_capacity: int,
    # Outputs
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
):
    """One thread per box ``i``: query the tree with the box, keep exact overlaps with ``j > i``."""
    i = wp.tid()
    lo = lower[i]
    hi = upper[i]
    query = wp.bvh_query_aabb(bvh, lo, hi)
    j = int(0)
    while wp.bvh_query_next(query, j):
        if j > i:
            if boxes_overlap(lo, hi, lower[j], upper[j]):
                emit_pair(i, j, pair, pair_count, pair_capacity)


class WarpBvhBroadPhase:
    """Broad phase with Warp's ``wp.Bvh`` over the boxes and one AABB query per box.

    The tree is built on the first launch (and whenever the box arrays change), then rebuilt in
    place (``refit=False``, Warp's default constructor for the device) or only refit
    (``refit=True``: cheaper, but the tree's quality decays as boxes move) at every launch.

    Args:
        device: Warp device.
        refit: refit the tree instead of rebuilding it.
        constructor: ``wp.Bvh`` constructor (None: Warp's default: ``"sah"`` on CPU, ``"lbvh"``
            on CUDA).
    """

    def __init__(self, *, device=None, refit: bool = False, constructor: str | None = None):
        self.device = wp.get_device(device)
        self.refit = bool(refit)
        self.constructor = constructor
        self.bvh = None
        self._boxes = None

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers of its own with counters that :meth:`launch` writes: none (only ``pairs``)."""
        return []

    def launch(self, lower: wp.array, upper: wp.array, pairs: GrowableBuffer) -> None:
        """Writes overlapping pairs of the ``(N,)`` boxes into ``pairs``; host reads nothing."""
        n = lower.shape[0]
        if n < 2:
            return
        if self.bvh is None or self._boxes != (lower.ptr, upper.ptr, n):
            self.bvh = wp.Bvh(lower, upper, constructor=self.constructor)
            self._boxes = (lower.ptr, upper.ptr, n)
        elif self.refit:
            self.bvh.refit()
        else:
            self.bvh.rebuild()
        wp.launch(_bvh_box_pairs_kernel, dim=n, inputs=[self.bvh.id, lower, upper, pairs.capacity],
                  outputs=[pairs.data, pairs.count], device=self.device)


def random_boxes(num_boxes: int, overlaps: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Cubes with half sides ``U(0.5, 1.5)`` spread so each overlaps ``overlaps`` others on average.

    Returns:
        ``(lower, upper)``, ``(N, 3)`` float32 each (scene units).
    """
    rng = np.random.default_rng(seed)
    half = rng.uniform(0.5, 1.5, size=(num_boxes, 1))
    side = (72.0 * max(num_boxes - 1, 1) / overlaps) ** (1.0 / 3.0)
    centre = rng.uniform(0.0, side, size=(num_boxes, 3))
    return (centre - half).astype(np.float32), (centre + half).astype(np.float32)


def make_method(name: str, device):
    """The broad phase called ``name`` (:data:`METHODS`); PeerUnavailable when its library is missing."""
    if name == "sap":
        return BroadPhaseSAP(device=device)
    if name == "nxn":
        return BroadPhaseAllPairs(device=device)
    if name == "warp_bvh":
        return WarpBvhBroadPhase(device=device)
    if name == "warp_bvh_refit":
        return WarpBvhBroadPhase(device=device, refit=True)
    if name == "newton_sap":
        return NewtonBroadPhaseSAP(device=device)
    raise ValueError(f"unknown method {name!r}")


def run_size(num_boxes: int, methods: list[str], args, device) -> dict:
    """Times every method on one box set; returns times, pair counts, checks and notes."""
    lo, hi = random_boxes(num_boxes, args.overlaps, args.seed)
    lower = wp.array(lo, dtype=wp.vec3, device=device)
    upper = wp.array(hi, dtype=wp.vec3, device=device)
    notes, runners = [], {}
    for name in methods:
        if name == "nxn" and num_boxes > args.nxn_max:
            notes.append(f"nxn skipped: {num_boxes} boxes > --nxn-max {args.nxn_max}")
            continue
        if name == "newton_sap" and args.newton_max is not None and num_boxes > args.newton_max:
            notes.append(f"newton_sap skipped: {num_boxes} boxes > --newton-max {args.newton_max}")
            continue
        try:
            broad = make_method(name, device)
        except PeerUnavailable as exc:
            notes.append(f"{name} skipped: {exc}")
            continue
        pairs = GrowableBuffer(wp.vec2i, max(64, 2 * num_boxes), device, f"{name} pairs")
        modes = device_modes(device)
        runners[name] = (pairs, ModeFrames.broad_phase(broad, lambda: (lower, upper), pairs, device, modes))
    times = {name: StageTimes() for name in runners}
    counts = {}
    for frame in range(args.warmup + args.frames):
        for name, (pairs, frames) in runners.items():
            t = frames.run("broad")
            counts[name] = frames.counts[0]
            if frame >= args.warmup:
                times[name].add(t)
    results = {name: pairs.numpy(counts[name]).reshape(-1, 2) for name, (pairs, _) in runners.items()}
    truth = box_overlap_truth(lo, hi)
    checks = [compare_exact(REFERENCE, results[REFERENCE], name, rows, "box pairs",
                            truth=None if name in OURS else truth)
              for name, rows in results.items() if name != REFERENCE]
    return {"times": times, "counts": counts, "checks": checks, "notes": notes}


def decades(low: int, high: int) -> list[int]:
    """``low, 10 low, ...`` up to ``high`` (``high`` itself last if it is not a decade step)."""
    out, n = [], low
    while n <= high:
        out.append(n)
        n *= 10
    if out[-1] != high:
        out.append(high)
    return out


def _count(text: str) -> int:
    value = float(text.replace("_", ""))
    if value != int(value) or value < 2:
        raise argparse.ArgumentTypeError(f"expected an integer >= 2, got {text!r}")
    return int(value)


def main(argv: list[str] | None = None) -> int:
    parser = bench_parser(__doc__.split("\n\n")[0], device_help="Warp device (default: cuda:0 if available, else cpu)")
    parser.add_argument("--min-n", type=_count, default=1000, help="smallest number of boxes (default: %(default)s)")
    parser.add_argument("--max-n", type=_count, default=None,
                        help="largest number of boxes, decades from --min-n (default: 1e5 on CPU, 1e6 on CUDA)")
    parser.add_argument("--n", type=_count, nargs="+", default=None, help="explicit box counts (instead of decades)")
    parser.add_argument("--overlaps", type=float, default=2.0,
                        help="mean number of boxes each box overlaps (default: %(default)s)")
    parser.add_argument("--methods", default=",".join(METHODS),
                        help="comma-separated subset of %(default)s (default: all)")
    parser.add_argument("--nxn-max", type=_count, default=None,
                        help=f"largest N for nxn (default: 10000 on CPU, {ALL_PAIRS_LIMIT} on CUDA)")
    parser.add_argument("--newton-max", type=_count, default=None, help="largest N for newton_sap (default: all)")
    add_run_options(parser, frames=5, warmup=2, seed=0, frames_help="timed frames (default: %(default)s)",
                    warmup_help="untimed frames before them, at least 1 (default: %(default)s)",
                    seed_help="seed of the boxes (default: %(default)s)",
                    out_help="JSON file (default: bench/results/broad_phase_<device>.json)")
    args, device, doc = start(parser, argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        parser.error(f"--methods: unknown {', '.join(bad) or '(none)'}; known: {', '.join(METHODS)}")
    if REFERENCE not in methods:
        methods.insert(0, REFERENCE)
    if args.frames < 1 or args.warmup < 1 or args.overlaps <= 0:
        parser.error("--frames and --warmup must be at least 1, --overlaps positive")
    if args.nxn_max is None:
        args.nxn_max = ALL_PAIRS_LIMIT if device.is_cuda else 10000
    max_n = args.max_n or (1_000_000 if device.is_cuda else 100_000)
    if args.n is None and max_n < args.min_n:
        parser.error(f"--max-n {max_n} is below --min-n {args.min_n}")
    sizes = args.n or decades(args.min_n, max_n)
    out = args.out
    if out is None:
        RESULTS.mkdir(parents=True, exist_ok=True)
        out = str(RESULTS / f"broad_phase_{str(device).replace(':', '')}.json")

    print(f"broad phase on {device} ({doc['device_name']}), {args.overlaps} overlaps per box, "
          f"{args.frames} frames after {args.warmup} warm-up; ms per frame min / median, ratio to {REFERENCE}, "
          f"best mode (e eager, g graph); * wrong pairs")
    width = 24
    print(f"{'boxes':>11}" + "".join(f"{m:>{width}}" for m in methods) + f"{'pairs':>12}{'overlaps/box':>14}")
    rows, checks, notes, ok = doc["rows"], [], [], True
    for n in sorted(sizes):
        res = run_size(n, methods, args, device)
        line = f"{n:>11,}"
        ref_med = res["times"][REFERENCE].summary()["broad"][1]
        wrong = {c.peer for c in res["checks"] if not c.peer_ok}
        for m in methods:
            st = res["times"].get(m)
            if st is None:
                line += f" {'-':>{width - 1}}"
                continue
            summary = st.summary()
            lo, med = summary["broad"]
            ratio = "" if m == REFERENCE else f" {med / ref_med:.1f}x"
            mode = {"graph": "g", "eager": "e"}.get(st.best_mode.get("broad"), "")
            line += f" {f'{lo:.3f}/{med:.3f}{ratio}{mode}' + ('*' if m in wrong else ''):>{width - 1}}"
            for stage, (s_lo, s_med) in summary.items():
                rows.append({"method": m, "n_boxes": n, "stage": stage, "ms_min": s_lo, "ms_median": s_med,
                             "pairs": res["counts"][m], "frames": st.frames(stage),
                             "mode": st.best_mode.get(stage), "peer_wrong": m in wrong})
        pairs = res["counts"][REFERENCE]
        print(line + f"{pairs:>12,}{2 * pairs / n:>14.2f}", flush=True)
        for note in res["notes"]:
            print(f"    note: {note}")
            notes.append({"n_boxes": n, "note": note})
        for check in res["checks"]:
            if not check.ok:
                ok = False
                print(f"    MISMATCH: {check.summary()}")
                for m in check.mismatches:
                    print(f"      {m}")
            if not check.peer_ok:
                print(f"    PEER WRONG (a finding; {REFERENCE} stands): {check.summary()}")
                for m in check.peer_errors:
                    print(f"      {m}")
            checks.append({"n_boxes": n, **check.to_dict()})
        agree = ", ".join(c.peer for c in res["checks"] if c.ok and c.peer_ok)
        print(f"    VERDICT {n:,} boxes: {'OK' if all(c.ok for c in res['checks']) else 'MISMATCH'}"
              + (f" ({agree} agree with {REFERENCE})" if agree else ""))
        doc.update(config={**vars(args), "methods": methods, "sizes": sorted(sizes)}, checks=checks, notes=notes,
                   ok=ok)
        write_result(out, doc)
    print(f"results written to {out}")
    if not ok:
        print("python -m bench.broad_phase: MISMATCH between broad phases (see above)", file=sys.stderr)
        return EXIT_INTERNAL
    return EXIT_OK


if __name__ == "__main__":
    sys.exit(main())
