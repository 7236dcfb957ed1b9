"""Whole scenes whose results are recorded, so that every device and every later version of the
code can be checked against them bit for bit.

Each scene is placed by poses computed here in numpy (no motion kernel: ``sin`` and ``cos`` may
round differently on each device), so that its world vertices, and everything after them, are the
same bits on every device. The pipeline runs with several option sets, segments and containment
on; recorded per run: the triangle pairs, their segments, the per-object flags and the
containment pairs. :mod:`test_scene_results` judges the record itself by brute force in float64.

Record them anew only after a deliberate change of semantics (and see that test pass)::

    python tests/scene_results.py --write
"""

from __future__ import annotations

import argparse
import os

import numpy as np

PRECISIONS = ("float32", "float64")
RECORD = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "scene_results.npz")
OPTIONS = {
    "default": {},
    "edge_face": {"narrow_phase": "edge_face"},
    "all_pairs_nxn": {"mid_phase": "all_pairs", "broad_phase": "all_pairs"},
    "leaf4": {"leaf_size": 4},
}
"""Pipeline option sets, each run on every scene."""


def _unit_quaternions(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def scenes(precision: str, device) -> dict:
    """``{name: Scene}``: polyhedra, icospheres among icosahedra, and big spheres with small cubes
    (some inside them) far from the origin."""
    import warp_ccd as wc

    out = {}
    rng = np.random.default_rng(11)
    polyhedra = ("tetrahedron", "cube", "octahedron", "dodecahedron", "icosahedron")
    for name, shapes, n, density in (("polyhedra", polyhedra, 300, 0.08),
                                     ("spheres", ("icosphere", "icosahedron"), 90, 0.1)):
        meshes = [wc.scene.shape(s) for s in shapes]
        radius = rng.uniform(0.5, 1.5, n)
        side = ((4.0 / 3.0) * np.pi * np.sum(radius**3) / density) ** (1.0 / 3.0)
        poses = np.concatenate([rng.uniform(-side / 2, side / 2, (n, 3)), _unit_quaternions(rng, n)], axis=1)
        out[name] = wc.Scene(meshes, rng.integers(0, len(meshes), n), object_scale=radius, poses=poses,
                             device=device, precision=precision)
    big = wc.scene.icosphere(3)
    cube_v, cube_t = wc.scene.shape("cube")
    small = (cube_v * 0.15, cube_t)
    n = 14
    q = _unit_quaternions(rng, n)
    x, y, z, w = q.T
    transforms = np.zeros((n, 4, 4))
    transforms[:, :3, :3] = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], 1)
    transforms[:, :3, 3] = rng.uniform(-1.5, 1.5, (n, 3)) + 1000.0
    transforms[:, 3, 3] = 1.0
    out["far_spheres_and_cubes"] = wc.Scene.from_meshes([big if k % 2 == 0 else small for k in range(n)],
                                                        transforms, device=device, precision=precision)
    return out


def results(precision: str, device) -> dict:
    """``{"<precision>/<scene>/<options>/<field>": array}`` of one device."""
    import warp_ccd as wc

    out = {}
    for scene_name, scene in scenes(precision, device).items():
        for option_name, options in OPTIONS.items():
            res = wc.CollisionPipeline(scene, segments=True, containment=True, **options).detect()
            key = f"{precision}/{scene_name}/{option_name}"
            out[f"{key}/triangle_pairs"] = res.triangle_pairs
            out[f"{key}/segments"] = res.segments
            out[f"{key}/colliding"] = res.colliding
            out[f"{key}/containment_pairs"] = res.containment_pairs
    return out


def read_reference() -> dict:
    with np.load(RECORD) as f:
        return {k: f[k] for k in f.files}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help=f"record the CPU's results in {RECORD}")
    args = parser.parse_args()
    import warp as wp

    wp.config.quiet = True
    out = {}
    for precision in PRECISIONS:
        out.update(results(precision, "cpu"))
    for key in sorted(out):
        if key.endswith("/triangle_pairs") or key.endswith("/containment_pairs"):
            print(f"{key}: {len(out[key])}")
    if args.write:
        np.savez_compressed(RECORD, **out)
        print(f"wrote {RECORD}")


if __name__ == "__main__":
    main()
