"""Continuous-collision queries with known answers, and seeded random ones for the exact reference.

:func:`crafted_cases`: hand-made vertex-face and edge-edge queries, each a :class:`Case` ``(kind, x0, x1,
min_distance, hit, toi, name)``, with ``x0``, ``x1`` of shape (4, 3) (rows p, f0, f1, f2 or ea0, ea1,
eb0, eb1), the expected verdict and the expected earliest toi (None for no hit). Every coordinate is a
multiple of 2**-26, so each case translated by 1e4 or 1e8 (also listed) is exactly representable in float64 and
has the same answer. :func:`random_queries`: seeded mixes of random motions, near misses and hits close to
edges and vertices; their truth comes from :mod:`ccd_reference`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

TRANSLATIONS = (0.0, 1e4, 1e8)
D = 2.0**-10
"""The min_distance of the crafted distance cases."""
TINY = 2.0**-26
"""A motion of about 1.5e-8: one unit in the last place at 1e8."""


class Case(NamedTuple):
    kind: str
    x0: np.ndarray
    x1: np.ndarray
    min_distance: float
    hit: bool
    toi: float | None
    name: str


_TRI = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
_SEG_B = [(-1, 0, 0), (1, 0, 0)]


def _vf(name, p0, p1, hit, toi, face0=_TRI, face1=None, d=0.0):
    x0 = np.array([p0, *face0], np.float64)
    x1 = np.array([p1, *(face0 if face1 is None else face1)], np.float64)
    return Case("vertex_face", x0, x1, d, hit, toi, name)


def _ee(name, a0, a1, hit, toi, b0=_SEG_B, b1=None, d=0.0):
    x0 = np.array([*a0, *b0], np.float64)
    x1 = np.array([*a1, *(b0 if b1 is None else b1)], np.float64)
    return Case("edge_edge", x0, x1, d, hit, toi, name)


def _base_cases() -> list[Case]:
    z = TINY
    vf = [
        _vf("through the interior", (0.25, 0.25, 1), (0.25, 0.25, -1), True, 0.5),
        _vf("face moving onto a still vertex", (0.25, 0.25, 0), (0.25, 0.25, 0), True, 0.5,
            face0=[(0, 0, -1), (1, 0, -1), (0, 1, -1)], face1=[(0, 0, 1), (1, 0, 1), (0, 1, 1)]),
        _vf("in the face plane, entering", (-1, 0.25, 0), (1, 0.25, 0), True, 0.5),
        _vf("in the face plane, outside", (-1, 2, 0), (2, 2, 0), False, None),
        _vf("in the face plane, toward the hypotenuse", (1, 1, 0), (0, 0, 0), True, 0.5),
        _vf("onto the hypotenuse", (0.5, 0.5, 1), (0.5, 0.5, -1), True, 0.5),
        _vf("onto an axis edge", (0.5, 0, 1), (0.5, 0, -1), True, 0.5),
        _vf("onto a vertex", (1, 0, 1), (1, 0, -1), True, 0.5),
        _vf("onto the origin vertex", (0, 0, 1), (0, 0, -1), True, 0.5),
        _vf("missing an edge by 2^-10", (0.5, -D, 1), (0.5, -D, -1), False, None),
        _vf("missing a vertex by 2^-10", (1 + D, 0, 1), (1 + D, 0, -1), False, None),
        _vf("touching at t=0", (0.25, 0.25, 0), (0.25, 0.25, 1), True, 0.0),
        _vf("touching at t=1", (0.25, 0.25, 1), (0.25, 0.25, 0), True, 1.0),
        _vf("still, touching", (0.25, 0.25, 0), (0.25, 0.25, 0), True, 0.0),
        _vf("still, separated", (0.25, 0.25, 0.5), (0.25, 0.25, 0.5), False, None),
        _vf("tiny motion through", (0.25, 0.25, z), (0.25, 0.25, -z), True, 0.5),
        _vf("tiny motion onto the face", (0.25, 0.25, z), (0.25, 0.25, 0), True, 1.0),
        _vf("tiny motion, separated", (0.25, 0.25, D), (0.25, 0.25, D - z), False, None),
        _vf("tiny face motion onto the vertex", (0.25, 0.25, 0), (0.25, 0.25, 0), True, 0.5,
            face0=[(0, 0, -z), (1, 0, -z), (0, 1, -z)], face1=[(0, 0, z), (1, 0, z), (0, 1, z)]),
        _vf("face collapsing to a point on the vertex", (0.5, 0.5, 1), (0.5, 0.5, -1), True, 0.5,
            face1=[(1, 1, 0), (0, 1, 0), (1, 0, 0)]),
        _vf("face collapsing to a point beside the vertex", (0.75, 0.5, 1), (0.75, 0.5, -1), False, None,
            face1=[(1, 1, 0), (0, 1, 0), (1, 0, 0)]),
        _vf("face collapsing to a segment under the vertex", (0.25, 0.5, 1), (0.25, -0.5, -1), True, 0.5,
            face1=[(0, 0, 0), (1, 0, 0), (1, -1, 0)]),
        _vf("face collapsing to a segment beside the vertex", (1.5, 0, 1), (1.5, 0, -1), False, None,
            face1=[(0, 0, 0), (1, 0, 0), (1, -1, 0)]),
        _vf("passing at d/2", (-1, 0.25, D / 2), (2, 0.25, D / 2), True, (1 - D) / 3, d=D),
        _vf("passing at 2d", (-1, 0.25, 2 * D), (2, 0.25, 2 * D), False, None, d=D),
        _vf("through the interior with d", (0.25, 0.25, 1), (0.25, 0.25, -1), True, (1 - D) / 2, d=D),
    ]
    up = [(0.5, -1, 1), (0.5, 1, 1)]
    down = [(0.5, -1, -1), (0.5, 1, -1)]
    ee = [
        _ee("crossing", up, down, True, 0.5),
        _ee("crossing beside the end", [(1 + D, -1, 1), (1 + D, 1, 1)], [(1 + D, -1, -1), (1 + D, 1, -1)], False,
            None),
        _ee("crossing at an end", [(1, -1, 1), (1, 1, 1)], [(1, -1, -1), (1, 1, -1)], True, 0.5),
        _ee("endpoint onto endpoint", [(1, 0, 1), (1, 1, 1)], [(1, 0, -1), (1, 1, -1)], True, 0.5),
        _ee("endpoint onto the interior, coplanar", [(0.5, 0, 1), (0.5, 0, 2)], [(0.5, 0, -1), (0.5, 0, 0)], True,
            0.5),
        _ee("parallel, becoming collinear", [(-1, 0, 1), (1, 0, 1)], [(-1, 0, -1), (1, 0, -1)], True, 0.5),
        _ee("parallel, coplanar apart", [(-1, 1, 1), (1, 1, 1)], [(-1, 1, -1), (1, 1, -1)], False, None),
        _ee("parallel, disjoint along the line", [(2, 0, 1), (3, 0, 1)], [(2, 0, -1), (3, 0, -1)], False, None),
        _ee("collinear, overlapping", [(-2, 0, 0), (0.5, 0, 0)], [(-2, 0, 0), (0.5, 0, 0)], True, 0.0),
        _ee("collinear, sliding into overlap", [(-3, 0, 0), (-2, 0, 0)], [(-1, 0, 0), (2, 0, 0)], True, 0.25),
        _ee("collinear, disjoint", [(-3, 0, 0), (-2, 0, 0)], [(-2.5, 0, 0), (-1.5, 0, 0)], False, None),
        _ee("touching at t=0", [(0.5, -1, 0), (0.5, 1, 0)], [(0.5, -1, 1), (0.5, 1, 1)], True, 0.0),
        _ee("touching at t=1", up, [(0.5, -1, 0), (0.5, 1, 0)], True, 1.0),
        _ee("still, crossing", [(0.5, -1, 0), (0.5, 1, 0)], [(0.5, -1, 0), (0.5, 1, 0)], True, 0.0),
        _ee("still, separated", up, up, False, None),
        _ee("tiny motion through", [(0.5, -1, z), (0.5, 1, z)], [(0.5, -1, -z), (0.5, 1, -z)], True, 0.5),
        _ee("tiny motion, separated", [(0.5, -1, D), (0.5, 1, D)], [(0.5, -1, D - z), (0.5, 1, D - z)], False,
            None),
        _ee("edge collapsing to a point on the other", [(0.5, -1, 1), (0.5, 1, 1)], [(0.5, 1, -1), (0.5, -1, -1)],
            True, 0.5),
        _ee("edge collapsing to a point beside the other", [(1.5, -1, 1), (1.5, 1, 1)],
            [(1.5, 1, -1), (1.5, -1, -1)], False, None),
        _ee("passing at d/2", [(2, -1, D / 2), (2, 1, D / 2)], [(-2, -1, D / 2), (-2, 1, D / 2)], True,
            (1 - D) / 4, d=D),
        _ee("passing at 2d", [(2, -1, 2 * D), (2, 1, 2 * D)], [(-2, -1, 2 * D), (-2, 1, 2 * D)], False, None, d=D),
        _ee("crossing with d", up, down, True, (1 - D) / 2, d=D),
    ]
    return vf + ee


def crafted_cases() -> list[Case]:
    """Every base case at each translation of :data:`TRANSLATIONS` (along (1, -1, 1)), exact in float64."""
    out = []
    for case in _base_cases():
        for shift in TRANSLATIONS:
            offset = np.array([shift, -shift, shift])
            x0, x1 = case.x0 + offset, case.x1 + offset
            assert np.array_equal(x0 - offset, case.x0) and np.array_equal(x1 - offset, case.x1), case.name
            name = case.name if shift == 0 else f"{case.name} (+{shift:g})"
            out.append(case._replace(x0=x0, x1=x1, name=name))
    return out


# --- seeded random queries ----------------------------------------------------------------------------------------


def _unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _offsets(rng, n):
    """Signed distances from exact contact: zero, 1e-9 .. 1e-2 on a log scale, either sign."""
    mag = 10.0 ** rng.uniform(-9, -2, n)
    mag[rng.random(n) < 0.15] = 0.0
    return mag * rng.choice([-1.0, 1.0], n)


def random_queries(kind: str, n: int, seed: int, min_distance: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` queries ``(x0, x1)`` of shape (n, 4, 3) float64 around the unit cube: a third uniform random
    motions, two thirds points (or edges) crossing the triangle's plane (the other edge) near its edges and
    vertices, at offsets of 1e-9 .. 1e-2 inside or outside (plus ``min_distance`` when given), with the
    triangle moving rigidly and slightly deforming."""
    rng = np.random.default_rng(seed)
    x0 = rng.random((n, 4, 3))
    x1 = x0 + 0.5 * rng.normal(size=(n, 4, 3))
    crafted = np.nonzero(rng.random(n) < 2 / 3)[0]
    m = len(crafted)
    shift = rng.normal(scale=0.3, size=(m, 3))
    wobble = rng.normal(scale=1e-3, size=(m, 3, 3)) * (rng.random((m, 1, 1)) < 0.5)
    tc = rng.uniform(0.0, 1.0, m)  # crossing time
    off = _offsets(rng, m) + np.sign(rng.normal(size=m)) * min_distance
    if kind == "vertex_face":
        face = rng.random((m, 3, 3))
        # a point near an edge (or a vertex) of the face, pushed across it by the offset
        which = rng.integers(0, 3, m)
        a, b = face[np.arange(m), which], face[np.arange(m), (which + 1) % 3]
        s = rng.uniform(-0.1, 1.1, m)
        at_vertex = rng.random(m) < 0.2
        s[at_vertex] = rng.choice([0.0, 1.0], int(at_vertex.sum()))
        on_edge = a + s[:, None] * (b - a)
        centroid = face.mean(axis=1)
        inward = centroid - on_edge
        inward /= np.linalg.norm(inward, axis=1, keepdims=True)
        cross_at = on_edge + off[:, None] * inward
        normal = np.cross(face[:, 1] - face[:, 0], face[:, 2] - face[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        height = rng.uniform(0.05, 0.5, m)
        p0 = cross_at + height[:, None] * normal
        p_vel = -height[:, None] * normal / tc[:, None].clip(1e-3) + shift
        x0[crafted] = np.concatenate([p0[:, None], face], axis=1)
        x1[crafted] = np.concatenate([(p0 + p_vel)[:, None], face + shift[:, None] + wobble], axis=1)
    elif kind == "edge_edge":
        b = rng.random((m, 2, 3))
        a_dir = _unit(rng, m) * rng.uniform(0.2, 1.0, (m, 1))
        sb = rng.uniform(-0.05, 1.05, m)
        ra = rng.choice([0.0, 1.0, 0.5], m) + rng.normal(scale=0.05, size=m) * (rng.random(m) < 0.5)
        meet = b[:, 0] + sb[:, None] * (b[:, 1] - b[:, 0])
        side = np.cross(a_dir, b[:, 1] - b[:, 0])
        side /= np.linalg.norm(side, axis=1, keepdims=True)
        meet = meet + off[:, None] * side
        height = rng.uniform(0.05, 0.5, m)
        a0_at = meet - ra[:, None] * a_dir  # edge a's position at the crossing time
        a0_t0 = a0_at + height[:, None] * side
        edge_a0 = np.stack([a0_t0, a0_t0 + a_dir], axis=1)
        vel = -height[:, None] * side / tc[:, None].clip(1e-3) + shift
        x0[crafted] = np.concatenate([edge_a0, b], axis=1)
        x1[crafted] = np.concatenate([edge_a0 + vel[:, None], b + shift[:, None] + wobble[:, :2]], axis=1)
    else:
        raise ValueError(f"unknown kind {kind!r}")
    return x0, x1
