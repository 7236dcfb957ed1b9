"""Broad phase: object pairs whose boxes overlap: sweep and prune on a grid, and the all-pairs reference."""
