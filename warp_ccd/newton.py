"""warp_ccd's mesh-mesh contacts in a newton simulation (newton >= 1.8, imported here: ``pip install newton``).

>>> from warp_ccd.newton import MeshContactBridge
>>> bridge = MeshContactBridge(model)                  # a newton.Model: its mesh shapes as warp_ccd objects
>>> contacts = bridge.contacts()                       # a newton.Contacts for both pipelines
>>> bridge.collide(state, contacts)                    # newton's pairs, then warp_ccd's mesh-mesh contacts
>>> solver.step(state, next_state, control, contacts, dt)

See :mod:`~warp_ccd._src.compat.newton` for how newton lays out its shapes and contacts, and how the two
pipelines share one buffer.
"""

from ._src.compat.newton import MESH_CONTACTS_PER_OBJECT, MeshContactBridge, mesh_pairs

__all__ = ["MESH_CONTACTS_PER_OBJECT", "MeshContactBridge", "mesh_pairs"]
