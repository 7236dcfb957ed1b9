"""Lab: where the contacts frame (:mod:`warp_ccd._src.narrowphase.contacts`) spends its time on the scaling scene:
Python's profile of one ``detect()`` (sorted by own time), then the GPU time of each kernel of one frame.

    python -m bench.contacts_profile 100000 > bench/results/contacts_profile_cuda0.txt
"""

import cProfile
import pstats
import sys
import time

import warp as wp

import warp_ccd as wc


def main() -> None:
    wp.config.quiet = True
    n = int(float(sys.argv[1])) if len(sys.argv) > 1 else 100_000
    dev = "cuda:0" if wp.get_cuda_device_count() else "cpu"
    scene = wc.Scene.random(n, seed=0, device=dev)
    pipe = wc.CollisionPipeline(scene, contacts=True)
    for _ in range(3):
        pipe.detect()
    wp.synchronize()
    t = time.perf_counter()
    res = pipe.detect()
    wp.synchronize()
    print(f"{n} objects: contacts frame {(time.perf_counter() - t) * 1e3:.1f} ms, {res.contacts.count} contacts, "
          f"{len(res.object_pairs)} pairs, {res.num_triangle_pairs} rows, depth levels {pipe.depth.level_regions}")
    prof = cProfile.Profile()
    prof.enable()
    pipe.detect()
    wp.synchronize()
    prof.disable()
    pstats.Stats(prof).sort_stats("tottime").print_stats(25)
    wp.timing_begin(cuda_filter=wp.TIMING_ALL)
    pipe.detect()
    agg: dict[str, list] = {}
    for x in wp.timing_end():
        agg.setdefault(x.name.split("_cuda_kernel")[0][:60], []).append(x.elapsed)
    total = sum(sum(v) for v in agg.values())
    print(f"GPU activities: {total:.2f} ms in all")
    for name, v in sorted(agg.items(), key=lambda kv: -sum(kv[1]))[:25]:
        print(f"  {sum(v):8.3f} ms  {len(v):5d}x  {name}")


if __name__ == "__main__":
    main()
