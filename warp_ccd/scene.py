"""The scene: shapes stored once, objects placed by poses (rigid) or given world vertices (deforming),
their motion, and the flat device arrays every stage reads (:class:`Scene`).

>>> from warp_ccd.scene import Scene, shape, icosphere
>>> scene = Scene([shape("cube"), icosphere(2)], [0, 1, 1], poses=poses)   # 3 objects of 2 shapes

Modules: :mod:`~warp_ccd._src.scene.shapes` (seed polyhedra, icospheres, a cloth sheet, a self-intersecting
torus, mesh validation),
:mod:`~warp_ccd._src.scene.motion` (inclined-ellipse motion, one kernel for every pose),
:mod:`~warp_ccd._src.scene.scene` (:class:`Scene`, the :class:`MeshTopology` struct kernels read),
:mod:`~warp_ccd._src.scene.filter` (worlds, collision groups and masks, excluded pairs: which pairs may collide),
:mod:`~warp_ccd._src.scene.inputs` (poses, transforms and world vertices read from device arrays, checked on the
device).
Imports Warp, numpy and :mod:`warp_ccd.geometry` only.
"""

from ._src.scene.filter import CollisionFilter
from ._src.scene.motion import EllipseMotion
from ._src.scene.scene import (
    MeshTopology,
    Scene,
    matrix_to_quat,
    mesh_triangle,
    poses_to_rows,
    quat_to_matrix,
    transforms_to_poses,
)
from ._src.scene.shapes import (
    SHAPES,
    MeshSet,
    figure_eight_torus,
    icosphere,
    shape,
    sheet,
    validate_mesh,
    validate_meshes,
)

__all__ = [
    "SHAPES",
    "CollisionFilter",
    "EllipseMotion",
    "MeshSet",
    "MeshTopology",
    "Scene",
    "figure_eight_torus",
    "icosphere",
    "matrix_to_quat",
    "mesh_triangle",
    "poses_to_rows",
    "quat_to_matrix",
    "shape",
    "sheet",
    "transforms_to_poses",
    "validate_mesh",
    "validate_meshes",
]
