"""The discrete frame of two source trees of warp_ccd side by side: before and after a change, on one GPU, in one
run, alternating the trees round by round so that drift of clocks or temperature falls on both alike.

Each round starts one process per tree (its ``warp_ccd`` on ``PYTHONPATH``); a process builds each scene with the
public API both trees share (``Scene.random``, ``CollisionPipeline``), warms up, and times ``detect(advance=1/60)``
frame by frame (motion, the frame as one CUDA graph on CUDA, the counters' read): the frame as a user runs it. The
scenes are the scaling benchmark's: polyhedra at constant density, and meshes of the sizes of real assets
(``mixed``, made once by the newer tree's benchmark and handed to both as the same arrays).

    python -m bench.frame_ab --before /tmp/before --after . --out bench/results/frame_ab_cuda0.json

The result lists, per scene and tree, every round's median and minimum ms a frame, the median over rounds, and the
ratio after / before of the medians.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

SCENES = (("poly", 1_000, 400), ("poly", 100_000, 100), ("poly", 1_000_000, 30), ("mixed", 10_000, 60))
"""``(triangles, objects, frames timed)`` of each scene."""

WARMUP = 5
DT = 1.0 / 60.0


def _worker(scenes: list, meshes_file: str, device: str) -> list[dict]:
    """In the process of one tree: every scene's frames timed (ms)."""
    import warp as wp

    import warp_ccd as wc

    wp.config.quiet = True
    mixed = np.load(meshes_file, allow_pickle=True)["meshes"].tolist() if meshes_file else None
    out = []
    for triangles, n, frames in scenes:
        kwargs = {"shapes": mixed} if triangles == "mixed" else {}
        scene = wc.Scene.random(n, seed=0, device=device, **kwargs)
        pipe = wc.CollisionPipeline(scene)
        for _ in range(WARMUP):
            pipe.detect(advance=DT)
        wp.synchronize_device(device)
        ms, pairs = [], []
        for _ in range(frames):
            t = time.perf_counter()
            res = pipe.detect(advance=DT)
            ms.append((time.perf_counter() - t) * 1e3)
            pairs.append(res.num_triangle_pairs)
        out.append({"triangles": triangles, "objects": n, "frames": frames, "ms_median": float(np.median(ms)),
                    "ms_min": float(np.min(ms)), "triangle_pairs_last": int(pairs[-1]),
                    "triangles_per_object": scene.num_triangles / max(n, 1)})
        del pipe, scene
    return out


def tree_env(tree: str) -> dict:
    """The environment of a process that imports ``warp_ccd`` from ``tree`` alone: the tree first on
    ``PYTHONPATH``, then the entries that hold no ``warp_ccd`` (Warp's, where it is not installed)."""
    others = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep)
              if p and not os.path.isdir(os.path.join(p, "warp_ccd"))]
    return dict(os.environ, PYTHONPATH=os.pathsep.join([tree, *others]))


def _git_commit(root: str) -> str | None:
    try:
        return subprocess.run(["git", "-C", root, "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.frame_ab", description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", required=True, help="root of the tree before (holds warp_ccd/)")
    parser.add_argument("--after", required=True, help="root of the tree after")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--device", default="cuda:0")
    parser.add_argument("--smoke", action="store_true", help="tiny scenes (to check the script on a CPU)")
    parser.add_argument("--out", default=None, help="JSON result (default: print it)")
    parser.add_argument("--worker", nargs=3, metavar=("SCENES", "MESHES", "DEVICE"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        scenes, meshes, device = args.worker
        import warp_ccd

        print(f"TREE {os.path.dirname(os.path.dirname(os.path.abspath(warp_ccd.__file__)))}", flush=True)
        print("RESULT " + json.dumps(_worker(json.loads(scenes), meshes, device)))
        return 0
    scenes = [("poly", 100, 4), ("mixed", 20, 3)] if args.smoke else list(SCENES)
    from warp_ccd._src.bench.meshes import real_mesh_set

    tmp = tempfile.mkdtemp()
    meshes_file = os.path.join(tmp, "mixed.npz")
    mixed = np.empty(len(real_mesh_set()), dtype=object)
    mixed[:] = [(np.asarray(v), np.asarray(t)) for v, t in real_mesh_set()]
    np.savez(meshes_file, meshes=mixed)
    trees = {"before": os.path.abspath(args.before), "after": os.path.abspath(args.after)}
    runs = {side: [] for side in trees}
    seen = {}
    for r in range(args.rounds):
        for side in (("before", "after") if r % 2 == 0 else ("after", "before")):
            # The script by its path, from a folder of no warp_ccd: the tree's is the only one on the path.
            env = tree_env(trees[side])
            proc = subprocess.run([sys.executable, os.path.abspath(__file__), "--before", "-", "--after", "-",
                                   "--worker", json.dumps(scenes), meshes_file, args.device],
                                  capture_output=True, text=True, env=env, cwd=tmp)
            line = [x for x in proc.stdout.splitlines() if x.startswith("RESULT ")]
            if proc.returncode != 0 or not line:
                print(proc.stdout[-3000:], proc.stderr[-3000:], file=sys.stderr)
                return 1
            tree = [x for x in proc.stdout.splitlines() if x.startswith("TREE ")][0][len("TREE "):]
            runs[side].append(json.loads(line[0][len("RESULT "):]))
            seen[side] = tree
            print(f"round {r} {side}: " + ", ".join(f"{c['triangles']} {c['objects']}: {c['ms_median']:.4f} ms"
                                                   for c in runs[side][-1]), flush=True)
    rows = []
    for k, (triangles, n, frames) in enumerate(scenes):
        row = {"triangles": triangles, "objects": n, "frames": frames}
        for side in trees:
            medians = [run[k]["ms_median"] for run in runs[side]]
            row[side] = {"round_medians": medians, "round_mins": [run[k]["ms_min"] for run in runs[side]],
                         "median": float(np.median(medians)), "min": float(min(run[k]["ms_min"] for run in runs[side])),
                         "triangle_pairs_last": runs[side][0][k]["triangle_pairs_last"]}
        row["after_over_before"] = row["after"]["median"] / row["before"]["median"]
        rows.append(row)
    import warp as wp

    wp.config.quiet = True
    doc = {"what": "discrete frame, detect(advance=1/60), before and after, alternating rounds",
           "device": args.device, "device_name": wp.get_device(args.device).name,
           "date": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "warp": wp.__version__,
           "before_commit": os.environ.get("BEFORE_COMMIT") or _git_commit(trees["before"]),
           "after_commit": os.environ.get("WARP_CCD_GIT_COMMIT") or _git_commit(trees["after"]),
           "trees": seen, "rounds": args.rounds, "warmup": WARMUP, "rows": rows}
    text = json.dumps(doc, indent=1)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text + "\n")
    for row in rows:
        print(f"{row['triangles']:>6} {row['objects']:>9,}: before {row['before']['median']:.4f} ms, after "
              f"{row['after']['median']:.4f} ms, after/before {row['after_over_before']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
