"""Standalone queries: least distances of object pairs however far apart, self-intersections of meshes,
continuous queries of vertex-face and edge-edge primitives."""
