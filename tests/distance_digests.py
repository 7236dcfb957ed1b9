"""Recorded digests of distances, one verdict on every device: the SHA-256 of what
:func:`warp_ccd.geometry.tri_tri_distance` gives on the near-degenerate pairs of
``tests/awkward_pairs.py``, of a clearance frame's rows and a distance query's answers, and of a contacts frame and
signed distances on fixed scenes, as computed on the CPU (``tests/data/distance_digests.json``). A device whose digests
differ rounds differently (see ``fuse_fp``). To record them anew after a deliberate change:

    python tests/distance_digests.py --write
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os

import numpy as np
import warp as wp

import warp_ccd as wc
from warp_ccd._src.geometry.distance import tri_tri_distance_batch_kernel
from warp_ccd._src.scene.shapes import icosphere

from awkward_pairs import PRECISIONS, awkward_pairs

REFERENCE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "distance_digests.json")


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def pair_digest(precision: str, device) -> str:
    """Distances and closest points of the awkward pairs."""
    ta, tb = awkward_pairs(precision)
    vec, scalar = (wp.vec3d, wp.float64) if precision == "float64" else (wp.vec3, wp.float32)
    a = wp.array(ta, dtype=vec, device=device)
    b = wp.array(tb, dtype=vec, device=device)
    d = wp.zeros(len(ta), dtype=scalar, device=device)
    p = wp.zeros((len(ta), 2), dtype=vec, device=device)
    wp.launch(tri_tri_distance_batch_kernel, dim=len(ta), inputs=[a, b, wp.float64(wc.TOLERANCE)], outputs=[d, p],
              device=device)
    return _digest(d.numpy(), p.numpy())


def scene_digest(precision: str, device) -> str:
    """A clearance frame's rows and a distance query's answers on seeded icospheres."""
    rng = np.random.default_rng(17)
    shapes = [icosphere(1), icosphere(2)]
    n = 12
    q = rng.normal(size=(n, 4))
    poses = np.concatenate([rng.uniform(0, 3.5, (n, 3)), q / np.linalg.norm(q, axis=1, keepdims=True)], axis=1)
    scene = wc.Scene(shapes, rng.integers(0, 2, n), object_scale=rng.uniform(0.5, 1.5, n), poses=poses, device=device,
                     precision=precision)
    res = wc.CollisionPipeline(scene, clearance=0.3).detect()
    far = wc.DistanceQuery(scene, signed=False).query()  # the least distances (signed ones: test_contacts)
    # An intersecting pair's direction is a sum of float64 atomics, in the order the device ran them: its
    # last bits may vary, so only the others' directions are held to the record.
    apart = ~res.object_intersecting
    return _digest(res.object_pairs, res.object_distance, res.closest_points, res.object_normal[apart],
                   res.object_intersecting, res.closest_triangles, far.distance, far.closest_points,
                   far.closest_triangles)


def contacts_digest(precision: str, device) -> str:
    """A contacts frame (points, normals, depths, triangles, reduced) and the signed distances on seeded
    icospheres over a box: one set of contacts on every device."""
    rng = np.random.default_rng(23)
    ball = icosphere(2)
    meshes = []
    for _ in range(6):
        q, _r = np.linalg.qr(rng.normal(size=(3, 3)))
        meshes.append((np.asarray(ball[0], np.float64) @ q.T + rng.uniform(-0.8, 0.8, 3), ball[1]))
    v, t = wc.scene.shape("cube")
    meshes.append((np.asarray(v) * [3, 3, 0.5] - [0, 0, 1.2], t))
    c = wc.contacts(meshes, device=device, precision=precision, max_per_pair=6)
    d = wc.distance(meshes, device=device, precision=precision)
    return _digest(c.pairs, c.triangles, c.point_a, c.point_b, c.normal, c.depth, d.distance, d.closest_points)


def digests(device) -> dict:
    out = {}
    for precision in PRECISIONS:
        out[f"pairs_{precision}"] = pair_digest(precision, device)
        out[f"scene_{precision}"] = scene_digest(precision, device)
        out[f"contacts_{precision}"] = contacts_digest(precision, device)
    return out


def read_reference() -> dict:
    with open(REFERENCE) as fh:
        return json.load(fh)


def write_reference(device="cpu") -> None:
    with open(REFERENCE, "w") as fh:
        json.dump(digests(device), fh, indent=1)
        fh.write("\n")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="record the CPU's digests")
    if parser.parse_args().write:
        wp.config.quiet = True
        write_reference()
        print(f"written {REFERENCE}")
