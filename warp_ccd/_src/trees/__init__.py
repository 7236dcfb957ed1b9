"""Bounds: object boxes without trees (the reference), a tree per shape built on the device and refit
bottom-up, and the one tree-pair traversal (a front of node pairs, level by level) that the mid phase,
the self-intersection stage and the distance query plug their tests into."""
