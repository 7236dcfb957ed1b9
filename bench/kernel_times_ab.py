"""Where a frame's time goes in two source trees of warp_ccd (before and after a change), on one GPU: the frame's
wall time as one graph and eagerly, and each kernel's GPU time a frame (Warp's timing, eager launches), for
polyhedra at 10^3 and 10^5 objects (or the counts given). The trees run in processes of their own, as in
:mod:`bench.frame_ab`.

    python bench/kernel_times_ab.py BEFORE_ROOT AFTER_ROOT [OBJECTS ...]
"""
import json
import os
import subprocess
import sys
import time

import numpy as np


def worker(n_list):
    import warp as wp

    import warp_ccd as wc
    wp.config.quiet = True
    out = {}
    for n in n_list:
        scene = wc.Scene.random(n, seed=0, device="cuda:0")
        for graph in (True, False):
            pipe = wc.CollisionPipeline(scene, graph=graph)
            for _ in range(5):
                pipe.detect(advance=1 / 60)
            wp.synchronize()
            ms = []
            for _ in range(50):
                t = time.perf_counter()
                pipe.detect(advance=1 / 60)
                ms.append((time.perf_counter() - t) * 1e3)
            out[f"{n}_{'graph' if graph else 'eager'}_wall_ms"] = float(np.median(ms))
        wp.timing_begin(cuda_filter=wp.TIMING_ALL)
        frames = 20
        for _ in range(frames):
            pipe.detect(advance=1 / 60)
        res = wp.timing_end()
        agg = {}
        for r in res:
            agg[r.name] = agg.get(r.name, 0.0) + r.elapsed
        out[f"{n}_kernels_us"] = {k: round(v * 1e3 / frames, 2) for k, v in sorted(agg.items(), key=lambda x: -x[1])}
        out[f"{n}_gpu_sum_us"] = round(sum(agg.values()) * 1e3 / frames, 2)
    print("RESULT " + json.dumps(out))


if __name__ == "__main__":
    if sys.argv[1] == "--worker":
        worker([int(x) for x in sys.argv[2:]])
        sys.exit(0)
    before, after = sys.argv[1], sys.argv[2]
    from frame_ab import tree_env  # beside this script (run by its path)

    counts = sys.argv[3:] or ["1000", "100000"]
    for side, tree in (("before", before), ("after", os.path.abspath(after))):
        env = tree_env(tree)
        p = subprocess.run([sys.executable, os.path.abspath(__file__), "--worker", *counts], capture_output=True,
                           text=True, env=env, cwd="/tmp")
        line = [x for x in p.stdout.splitlines() if x.startswith("RESULT ")]
        if not line:
            print(p.stdout[-2000:], p.stderr[-3000:])
            continue
        d = json.loads(line[0][7:])
        print("==", side)
        for k, v in d.items():
            if isinstance(v, dict):
                print(k, json.dumps(dict(list(v.items())[:14])))
            else:
                print(k, v)
