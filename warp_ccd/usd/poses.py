"""World matrices as USD writes them (row vectors, ``p_world = p M``) split into poses and uniform scales.

numpy over many objects at once, no ``pxr``: :func:`similarity_split` finds the linear parts that are
a rotation times a uniform scale, :func:`matrix_poses` turns world matrices into ``wp.transform``
rows and scales relative to the linear parts baked into the shapes, and :func:`finite_matrix_poses`
does so where the matrices are finite and says which are. Used by the import (:mod:`~warp_ccd.usd.importer`) and
by its worker processes (:mod:`~warp_ccd.usd.workers`).
"""

from __future__ import annotations

import numpy as np

from ..scene.scene import matrix_to_quat

__all__ = ["SIMILARITY_TOLERANCE", "finite_matrix_poses", "matrix_poses", "similarity_split"]

SIMILARITY_TOLERANCE = 1e-5
"""Relative tolerance within which a transform's linear part counts as a rotation times a uniform scale."""


def similarity_split(linear: np.ndarray, tol: float = SIMILARITY_TOLERANCE):
    """Splits ``(K, 3, 3)`` linear parts (row vectors) into ``scale * rotation`` where they are one.

    Returns:
        ``(scale (K,), rotation (K, 3, 3), ok (K,) bool)``; ``ok`` is False for a non-uniform
        scale, a shear, a reflection or a (near) zero scale.
    """
    gram = linear @ linear.swapaxes(1, 2)
    s2 = np.trace(gram, axis1=1, axis2=2) / 3.0
    dev = np.abs(gram - s2[:, None, None] * np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(linear)
    ok = (s2 > 1e-30) & (det > 0) & (dev <= tol * np.maximum(s2, 1e-300))
    scale = np.sqrt(np.maximum(s2, 0.0))
    rotation = linear / np.where(scale > 0, scale, 1.0)[:, None, None]
    return scale, rotation, ok


def matrix_poses(matrix: np.ndarray, bake: np.ndarray):
    """Poses and scales of world matrices relative to baked linear parts.

    Args:
        matrix: ``(K, 4, 4)`` world matrices (row vectors).
        bake: ``(K, 3, 3)`` linear parts baked into the shapes (identity where nothing is baked).

    Returns:
        ``(poses (K, 7) float64 rows (p, q xyzw), scale (K,), ok (K,) bool)``: ``p_world =
        transform_point(pose, scale * (p bake))`` where ``ok``.
    """
    rel = np.linalg.solve(bake, matrix[:, :3, :3])  # bake^-1 A: p A = (p bake) (bake^-1 A)
    scale, rot, ok = similarity_split(rel)
    poses = np.empty((len(matrix), 7))
    poses[:, :3] = matrix[:, 3, :3]
    # Row-vector rotation R acts as R^T on column vectors (wp.transform_point).
    rot = np.where(ok[:, None, None], rot, np.eye(3))
    poses[:, 3:] = matrix_to_quat(rot.swapaxes(1, 2)) if len(rot) else np.zeros((0, 4))
    return poses, scale, ok


def finite_matrix_poses(matrix: np.ndarray, bake: np.ndarray):
    """:func:`matrix_poses` of the finite ``matrix`` rows (identity in place of the others): ``(finite (K,)
    bool, poses, scale, ok)``; the caller names a prim whose transform is not finite."""
    finite = np.isfinite(matrix).all(axis=(1, 2))
    return (finite, *matrix_poses(np.where(finite[:, None, None], matrix, np.eye(4)), bake))
