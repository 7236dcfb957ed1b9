"""A drop-in for ``trimesh.collision.CollisionManager`` on warp_ccd (python-fcl never imported).

>>> from warp_ccd.trimesh import CollisionManager
>>> m = CollisionManager()
>>> m.add_object("a", mesh_a); m.add_object("b", mesh_b, transform)
>>> hit, names, contacts = m.in_collision_internal(return_names=True, return_data=True)
>>> distance, names = m.min_distance_internal(return_names=True)

The same methods, arguments and return values as trimesh's; the differences (rigid transforms only, the
library's depth, containment in any closed mesh) are in :mod:`warp_ccd._src.compat.trimesh`.
"""

from ._src.compat.trimesh import CollisionManager, ContactData, DistanceData, scene_to_collision

__all__ = ["CollisionManager", "ContactData", "DistanceData", "scene_to_collision"]
