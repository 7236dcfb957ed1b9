"""The exact geometry as ``@wp.func``\\ s: boxes, the triangle-triangle tests, distances, times of impact,
and the precision a scene needs. Imports Warp and numpy only."""
