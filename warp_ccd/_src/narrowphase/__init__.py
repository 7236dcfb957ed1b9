"""Narrow phases: the exact tests of a frame's candidates: discrete (Möller), continuous (times of impact),
clearance (least distances), self-intersection (a mesh through itself)."""
