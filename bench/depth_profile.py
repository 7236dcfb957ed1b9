"""Lab: where the check's depth (:mod:`warp_ccd._src.narrowphase.depth`) spends a frame on the benchmark stages of
:mod:`bench.usd_check` (10,000 rigid prims, 100 deforming 10k-triangle meshes): per frame the classify step's
wall time, rows, pairs, regions per level; then the GPU time of each kernel of one depth call.

    python -m bench.depth_profile > bench/results/depth_profile_cuda0.txt
"""

import os
import tempfile
import time

import numpy as np
import warp as wp

import warp_ccd as wc
from warp_ccd._src.check.crossing import CrossingClassifier
from warp_ccd._src.usd.importer import UsdMeshImport
from warp_ccd._src.usd.stage import open_stage, stage_time_codes

from .usd_check import write_deforming_stage, write_rigid_stage


def main() -> None:
    wp.config.quiet = True
    dev = "cuda:0" if wp.get_cuda_device_count() else "cpu"
    folder = tempfile.mkdtemp()
    for kind in ("rigid", "deforming"):
        path = os.path.join(folder, kind + ".usdc")
        if kind == "rigid":
            write_rigid_stage(path, 10000 if dev != "cpu" else 200, 4, device=dev)
        else:
            write_deforming_stage(path, 100 if dev != "cpu" else 3, 4)
        stage = open_stage(path)
        imp = UsdMeshImport(stage, times=stage_time_codes(stage, None), device=dev)
        pipe = wc.CollisionPipeline(imp.scene)
        classify = CrossingClassifier(imp.scene, trees=pipe.boxes)
        for k in range(4):
            imp.set_frame(k)
            res = pipe.detect()
            wp.synchronize()
            t = time.perf_counter()
            found = classify(res.device_triangle_pairs)
            wp.synchronize()
            print(kind, k, f"classify {(time.perf_counter() - t) * 1e3:.1f} ms", "rows",
                  res.device_triangle_pairs.shape[0], "pairs", len(found.pairs), "levels",
                  classify.depth.level_regions, flush=True)
        import cProfile
        import pstats

        prof = cProfile.Profile()
        prof.enable()
        classify(res.device_triangle_pairs)
        wp.synchronize()
        prof.disable()
        pstats.Stats(prof).sort_stats("tottime").print_stats(12)
        rows = res.device_triangle_pairs.numpy().reshape(-1, 4)
        wp.timing_begin(cuda_filter=wp.TIMING_ALL)
        classify.depth(found.pairs, rows[found.crossing], floors=np.full(len(found.pairs), 1e-6))
        agg: dict[str, list] = {}
        for x in wp.timing_end():
            a = agg.setdefault(x.name, [0, 0.0])
            a[0] += 1
            a[1] += x.elapsed
        for name, (count, ms) in sorted(agg.items(), key=lambda kv: -kv[1][1])[:8]:
            print("  ", kind, name, count, f"{ms:.2f} ms", flush=True)


if __name__ == "__main__":
    main()
