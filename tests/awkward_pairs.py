"""10^5 seeded near-degenerate triangle pairs, the same bits on every machine, their verdicts, and the
verdicts recorded.

The pairs sit where rounding decides: nearly parallel and nearly coplanar triangles, a vertex
within a few tolerances of the other's plane, shared edges and vertices moved by a hair, slivers
near the degeneracy threshold, points and segments grazing faces and edges; each family at
several scales and offsets, rotated. They are built from ``Generator.random`` and
``Generator.integers`` with add, multiply, divide and square root only (correctly rounded by
numpy on every processor; no BLAS, no transcendental functions, no reductions whose order could
change), so every machine builds the very same inputs (:func:`inputs_digest` is their SHA-256).

:func:`verdicts` runs both triangle tests of :mod:`warp_ccd._src.geometry.triangle` and Möller's segments on
them, on one device. :data:`REFERENCE` (``tests/data/narrow_phase_verdicts.npz``) holds, per precision, the
SHA-256 of the pairs' inputs, the verdicts of both triangle tests (bit-packed) and a SHA-256 of Möller's
segments, as computed on the CPU; the tests judge every device against them. A device whose verdicts differ
rounds differently (see the narrow phase's ``fuse_fp``); the lab's ``bench/narrow_phase.py`` times them and
compares each device with the CPU. To record them anew after a deliberate change of the tests' semantics:

    python tests/awkward_pairs.py --write
"""

from __future__ import annotations

import argparse
import hashlib
import os

import numpy as np
import warp as wp

from warp_ccd._src.geometry.precision import precision_types
from warp_ccd._src.geometry.triangle import (
    CONTACT_SEGMENT,
    TOLERANCE,
    tri_tri_batch_kernel,
    tri_tri_segment_batch_kernel,
)
from warp_ccd._src.narrowphase.discrete import NARROW_METHODS

__all__ = ["METHODS", "NUM_PAIRS", "OFFSETS", "PRECISIONS", "REFERENCE", "SCALES", "SEED", "SMALL", "awkward_pairs",
           "inputs_digest", "read_reference", "verdicts", "write_reference"]

NUM_PAIRS = 100_000
SEED = 20261123
PRECISIONS = ("float32", "float64")
METHODS = ("moller", "edge_face")

REFERENCE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "narrow_phase_verdicts.npz")

SMALL = np.array([0.0, 1e-9, 1e-8, 1e-7, 3e-7, 1e-6, 3e-6, 1e-5, 2e-5, 3e-5, 1e-4, 1e-3, 1e-2])
"""Perturbations, relative to the triangles' size: around the default tolerance 1e-5 and the
rounding of float32 (6e-8) and float64 (1e-16) coordinates."""

SCALES = np.array([1e-3, 1.0, 1e3])
OFFSETS = {"float32": np.array([0.0, 1.0, 1e2, 1e3]), "float64": np.array([0.0, 1e3, 1e6, 1e8])}


def _uniform(rng, lo, hi, shape):
    return lo + (hi - lo) * rng.random(shape)


def _pick(rng, table, n):
    return table[rng.integers(0, len(table), size=n)]


def _signed(rng, table, n):
    return _pick(rng, table, n) * (2.0 * rng.integers(0, 2, size=n) - 1.0)


def _dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _cross(a, b):
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _unit(v):
    return v / np.sqrt(_dot(v, v))[..., None]


def _random_unit(rng, n):
    v = _uniform(rng, -1.0, 1.0, (n, 3))
    v[_dot(v, v) < 1e-6] = (1.0, 0.0, 0.0)
    return _unit(v)


def _rotate(rng, tri, n):
    """Each pair by its own rotation (from a random unit quaternion), elementwise arithmetic only."""
    q = _uniform(rng, -1.0, 1.0, (n, 4))
    norm2 = q[:, 0] * q[:, 0] + q[:, 1] * q[:, 1] + q[:, 2] * q[:, 2] + q[:, 3] * q[:, 3]
    q[norm2 < 1e-6] = (0.0, 0.0, 0.0, 1.0)
    norm2[norm2 < 1e-6] = 1.0
    q = q / np.sqrt(norm2)[:, None]
    x, y, z, w = (q[:, k][:, None] for k in range(4))
    r = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    px, py, pz = tri[..., 0], tri[..., 1], tri[..., 2]
    return np.stack([r[i][0] * px + r[i][1] * py + r[i][2] * pz for i in range(3)], axis=-1)


def _families(rng, n):
    """``(ta, tb)`` ``(n, 3, 3)`` float64 in a unit frame, six families mixed."""
    family = rng.integers(0, 6, size=n)
    ta = _uniform(rng, -1.0, 1.0, (n, 3, 3))
    ta[:, :, 2] = 0.0  # a in the plane z = 0
    tb = _uniform(rng, -1.0, 1.0, (n, 3, 3))
    centre = (ta[:, 0] + ta[:, 1] + ta[:, 2]) / 3.0
    # 0: b nearly parallel to a, about a's centroid, tilted by a small angle about the line x = 0
    # of a's plane, and lifted.
    m = family == 0
    tilt = _pick(rng, SMALL, n)
    lift = _signed(rng, SMALL, n)
    flat = _uniform(rng, -0.6, 0.6, (n, 3, 3)) + centre[:, None, :]
    flat[:, :, 2] = flat[:, :, 0] * tilt[:, None] + lift[:, None]
    tb[m] = flat[m]
    # 1: one vertex of b within a few tolerances of a's plane, near a's boundary or inside it.
    m = family == 1
    w = _uniform(rng, -0.05, 1.05, (n, 3))
    w = w / (w[:, 0] + w[:, 1] + w[:, 2])[:, None]
    near = w[:, 0:1] * ta[:, 0] + w[:, 1:2] * ta[:, 1] + w[:, 2:3] * ta[:, 2]
    near[:, 2] = _signed(rng, SMALL, n)
    tb[m, 0] = near[m]
    # 2: b shares an edge (or a vertex) of a, moved by a hair.
    m = family == 2
    hair = _random_unit(rng, n) * _pick(rng, SMALL, n)[:, None]
    tb[m, 0] = (ta[:, 0] + hair)[m]
    share_edge = m & (rng.integers(0, 2, size=n) == 1)
    tb[share_edge, 1] = (ta[:, 1] - hair)[share_edge]
    # 3: coplanar or nearly so, overlapping or touching in the plane.
    m = family == 3
    shift = _uniform(rng, -1.0, 1.0, (n, 3)) * 0.5
    coplanar = ta[:, [1, 2, 0]] + shift[:, None, :]
    coplanar[:, :, 2] = _signed(rng, SMALL, n)[:, None] * (rng.integers(0, 2, size=(n, 3)))
    tb[m] = coplanar[m]
    # 4: a is a sliver (or a segment) near the degeneracy threshold, crossing or grazing b.
    m = family == 4
    p = _uniform(rng, -1.0, 1.0, (n, 3))
    q = _uniform(rng, -1.0, 1.0, (n, 3))
    side = _random_unit(rng, n)
    along = rng.random((n, 1))
    d = q - p
    third = p + d * along + side * (_pick(rng, SMALL, n) * np.sqrt(_dot(d, d)))[:, None]
    tb_flat = tb.copy()
    tb_flat[:, :, 2] = _signed(rng, SMALL, n)[:, None]
    sliver = np.stack([p, q, third], axis=1)
    ta[m] = sliver[m]
    tb[m] = tb_flat[m]
    # 5: a point (or a repeated-vertex segment) on or near b's face, edges or vertices; or two
    # slivers a hair apart.
    m = family == 5
    w = _uniform(rng, -0.02, 1.02, (n, 3))
    w[rng.integers(0, 2, size=n) == 1, 0] = 0.0  # half of them on an edge line
    w = w / (w[:, 0] + w[:, 1] + w[:, 2])[:, None]
    on_b = w[:, 0:1] * tb[:, 0] + w[:, 1:2] * tb[:, 1] + w[:, 2:3] * tb[:, 2]
    nb = _unit(_cross(tb[:, 1] - tb[:, 0], tb[:, 2] - tb[:, 0]))
    x = on_b + nb * _signed(rng, SMALL, n)[:, None]
    kind = rng.integers(0, 3, size=n)
    point = np.stack([x, x, x], axis=1)
    segment = np.stack([x, x, x + _random_unit(rng, n) * 0.5], axis=1)
    pair = np.stack([x - d * 0.5, x + d * 0.5, x + d * 0.25 + side * 1e-9], axis=1)
    ta[m & (kind == 0)] = point[m & (kind == 0)]
    ta[m & (kind == 1)] = segment[m & (kind == 1)]
    two = m & (kind == 2)
    ta[two] = pair[two]
    tb[two] = np.stack([x + side * 0.5, x - side * 0.5 + nb * _signed(rng, SMALL, n)[:, None],
                        x + nb * 1e-9], axis=1)[two]
    return ta, tb


def awkward_pairs(precision: str, n: int = NUM_PAIRS, seed: int = SEED):
    """``(ta, tb)`` ``(n, 3, 3)`` arrays of ``precision``: the near-degenerate pairs, rotated, scaled
    and moved away from the origin (float32 up to 1e3, float64 up to 1e8)."""
    rng = np.random.default_rng(seed)
    ta, tb = _families(rng, n)
    both = _rotate(rng, np.concatenate([ta, tb], axis=1), n)
    scale = _pick(rng, SCALES, n)[:, None, None]
    offset = _uniform(rng, -1.0, 1.0, (n, 1, 3)) * _pick(rng, OFFSETS[precision], n)[:, None, None]
    both = both * scale + offset
    dtype = np.float32 if precision == "float32" else np.float64
    return both[:, :3].astype(dtype), both[:, 3:].astype(dtype)


def inputs_digest(precision: str) -> str:
    """SHA-256 of the pairs' bytes (little-endian)."""
    ta, tb = awkward_pairs(precision)
    return hashlib.sha256(ta.astype(ta.dtype.newbyteorder("<")).tobytes()
                          + tb.astype(tb.dtype.newbyteorder("<")).tobytes()).hexdigest()


def verdicts(precision: str, device, swap: bool = False) -> dict:
    """Both tests' verdicts ``(n,)`` bool and Möller's segments' SHA-256 on ``device`` (``swap``:
    each pair's triangles in the other order)."""
    ta, tb = awkward_pairs(precision)
    if swap:
        ta, tb = tb, ta
    _, vec3, _, _ = precision_types(precision)
    a = wp.array(ta, dtype=vec3, device=device)
    b = wp.array(tb, dtype=vec3, device=device)
    out = {}
    for method in METHODS:
        hit = wp.zeros(len(ta), dtype=wp.int32, device=device)
        wp.launch(tri_tri_batch_kernel, dim=len(ta), inputs=[a, b, NARROW_METHODS[method], wp.float64(TOLERANCE)],
                  outputs=[hit], device=device)
        out[method] = hit.numpy().astype(bool)
    kind = wp.zeros(len(ta), dtype=wp.int32, device=device)
    seg = wp.zeros((len(ta), 2), dtype=vec3, device=device)
    wp.launch(tri_tri_segment_batch_kernel, dim=len(ta), inputs=[a, b, wp.float64(TOLERANCE)],
              outputs=[kind, seg], device=device)
    k = kind.numpy()
    s = seg.numpy().reshape(len(ta), 6)
    s[k != CONTACT_SEGMENT] = 0.0  # only crossings have a segment
    out["segment_kind"] = k
    digest = hashlib.sha256(k.astype("<i4").tobytes() + s.astype(s.dtype.newbyteorder("<")).tobytes())
    out["segment_sha256"] = digest.hexdigest()
    return out


def write_reference(device="cpu") -> None:
    """Records the inputs' digests and ``device``'s verdicts in :data:`REFERENCE`."""
    data = {}
    for precision in PRECISIONS:
        got = verdicts(precision, device)
        data[f"{precision}_inputs_sha256"] = np.array(inputs_digest(precision))
        data[f"{precision}_segment_sha256"] = np.array(got["segment_sha256"])
        for method in METHODS:
            data[f"{precision}_{method}"] = np.packbits(got[method])
    os.makedirs(os.path.dirname(REFERENCE), exist_ok=True)
    np.savez_compressed(REFERENCE, **data)


def read_reference() -> dict:
    """The recorded digests (str) and verdicts (``(n,)`` bool)."""
    with np.load(REFERENCE) as f:
        return {k: (str(v) if v.dtype.kind == "U" else np.unpackbits(v)[:NUM_PAIRS].astype(bool)) for k, v in f.items()}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help=f"record the CPU's verdicts in {REFERENCE}")
    args = parser.parse_args()
    if args.write:
        wp.config.quiet = True
        write_reference("cpu")
        print(f"written: {REFERENCE}")
    for precision in PRECISIONS:
        print(precision, inputs_digest(precision))
