"""The shapes of the benchmarks' scenes: the ``--triangles`` specs (:func:`parse_triangles`), and meshes
of the sizes of real assets, made procedurally (seeded), for the scaling benchmark's ``mixed`` scene:
objects drawn from a scanned-statue-like blob, a smaller animal-like blob, an open cloth sheet and a
few CAD and drone parts, from 120 to about 12,700 triangles.

Every mesh is centred on its bounding box and scaled to radius 1 (its farthest vertex at distance
1), in float32 with int32 triangles, and is the same at every call (:func:`real_mesh_set` caches).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["REAL_MESHES", "parse_triangles", "real_mesh_set"]


def _grid_triangles(rows: int, cols: int, wrap: bool) -> np.ndarray:
    """Two triangles per cell of a ``rows x cols`` vertex grid (vertex ``r * cols + c``), the columns
    closed into a ring when ``wrap``."""
    c_end = cols if wrap else cols - 1
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(c_end), indexing="ij")
    r, c = r.ravel(), c.ravel()
    a = r * cols + c
    b = r * cols + (c + 1) % cols
    d = (r + 1) * cols + c
    e = (r + 1) * cols + (c + 1) % cols
    return np.concatenate([np.stack([a, d, e], 1), np.stack([a, e, b], 1)])


def _fan(centre: int, ring: np.ndarray, flip: bool) -> np.ndarray:
    """Triangles from vertex ``centre`` to each edge of the closed ``ring`` of vertex ids."""
    nxt = np.roll(ring, -1)
    tri = np.stack([np.full_like(ring, centre), ring, nxt], 1)
    return tri[:, [0, 2, 1]] if flip else tri


def _latlong(n_lat: int, n_lon: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit sphere of ``n_lat - 1`` rings of ``n_lon`` vertices and two poles: ``2 n_lon (n_lat - 1)``
    triangles."""
    theta = np.pi * np.arange(1, n_lat) / n_lat
    phi = 2.0 * np.pi * np.arange(n_lon) / n_lon
    t, p = np.meshgrid(theta, phi, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    v = np.concatenate([[[0.0, 0.0, 1.0]], ring, [[0.0, 0.0, -1.0]]])
    body = _grid_triangles(n_lat - 1, n_lon, wrap=True) + 1
    south = len(v) - 1
    top = _fan(0, 1 + np.arange(n_lon), flip=False)
    bottom = _fan(south, 1 + (n_lat - 2) * n_lon + np.arange(n_lon), flip=True)
    return v, np.concatenate([top, body, bottom])


def _blob(n_lat: int, n_lon: int, seed: int, bumps: int, amplitude: float, stretch) -> tuple:
    """A lumpy closed surface: a sphere whose radius varies smoothly (a sum of ``bumps`` seeded
    waves over the directions), then stretched along the axes."""
    v, t = _latlong(n_lat, n_lon)
    rng = np.random.default_rng(seed)
    k = rng.normal(size=(bumps, 3)) * rng.uniform(1.0, 3.0, size=(bumps, 1))
    phase = rng.uniform(0, 2 * np.pi, bumps)
    radius = 1.0 + amplitude * np.sin(v @ k.T + phase).mean(axis=1)
    return v * radius[:, None] * np.asarray(stretch), t


def _cloth(nx: int, ny: int) -> tuple:
    """An open sheet of ``nx x ny`` vertices, draped: waves along both sides and a fold."""
    x, y = np.meshgrid(np.linspace(-1.0, 1.0, nx), np.linspace(-1.2, 1.2, ny), indexing="ij")
    z = 0.12 * np.sin(4.0 * x) * np.cos(3.0 * y) - 0.5 * np.maximum(0.0, x - 0.3) ** 2
    return np.stack([x, y, z], -1).reshape(-1, 3), _grid_triangles(nx, ny, wrap=False)


def _torus(n_major: int, n_minor: int, minor: float = 0.35) -> tuple:
    """A ring: ``2 n_major n_minor`` triangles."""
    u, w = np.meshgrid(2 * np.pi * np.arange(n_major) / n_major, 2 * np.pi * np.arange(n_minor) / n_minor,
                       indexing="ij")
    r = 1.0 + minor * np.cos(w)
    v = np.stack([r * np.cos(u), r * np.sin(u), minor * np.sin(w)], -1).reshape(-1, 3)
    # rows of the grid are the major angle (closed too): wrap the rows by adding the first row again
    t = _grid_triangles(n_major + 1, n_minor, wrap=True) % (n_major * n_minor)
    return v, t


def _tube(n_around: int, n_along: int, section, twist: float) -> tuple:
    """A closed tube along x: an elliptic ``section`` (half axes), twisted by ``twist`` radians
    end to end, capped: ``2 n_around (n_along - 1) + 2 n_around`` triangles."""
    a = 2 * np.pi * np.arange(n_around) / n_around
    x = np.linspace(-1.0, 1.0, n_along)
    s, ang = np.meshgrid(x, a, indexing="ij")
    rot = twist * 0.5 * (s + 1.0)
    cy, cz = section[0] * np.cos(ang), section[1] * np.sin(ang)
    v = np.stack([s, cy * np.cos(rot) - cz * np.sin(rot), cy * np.sin(rot) + cz * np.cos(rot)], -1).reshape(-1, 3)
    body = _grid_triangles(n_along, n_around, wrap=True)
    ends = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    first, last = len(v), len(v) + 1
    caps = [_fan(first, np.arange(n_around), flip=True), _fan(last, (n_along - 1) * n_around + np.arange(n_around),
                                                             flip=False)]
    return np.concatenate([v, ends]), np.concatenate([body, *caps])


def _superellipsoid(n_lat: int, n_lon: int, power: float = 0.3) -> tuple:
    """A box with rounded edges (a superellipsoid of exponent ``power``)."""
    v, t = _latlong(n_lat, n_lon)
    return np.sign(v) * np.abs(v) ** power * np.array([1.0, 0.7, 0.45]), t


REAL_MESHES = (
    ("statue", lambda: _blob(78, 78, seed=1, bumps=24, amplitude=0.35, stretch=(0.8, 0.7, 1.0))),  # 12,012
    ("animal", lambda: _blob(45, 45, seed=2, bumps=12, amplitude=0.45, stretch=(1.0, 0.6, 0.7))),  # 3,960
    ("cloth", lambda: _cloth(80, 81)),  # 12,640, open
    ("ring", lambda: _torus(45, 20)),  # 1,800
    ("bracket", lambda: _superellipsoid(21, 20)),  # 800
    ("blade", lambda: _tube(10, 21, (0.18, 0.03), twist=1.2)),  # 420
    ("spacer", lambda: _tube(30, 2, (0.6, 0.6), twist=0.0)),  # 120
)
"""``(name, maker)`` of the mixed scene's meshes; the comment gives each one's triangles."""


@lru_cache(maxsize=1)
def real_mesh_set() -> tuple:
    """The :data:`REAL_MESHES`, each ``(vertices (n, 3) float32, triangles (m, 3) int32)``, centred on
    its bounding box and scaled to radius 1 (cached: the same arrays every call)."""
    out = []
    for _, make in REAL_MESHES:
        v, t = make()
        v = v - 0.5 * (v.min(axis=0) + v.max(axis=0))
        v = v / np.linalg.norm(v, axis=1).max()
        v.setflags(write=False)
        t = np.ascontiguousarray(t, dtype=np.int32)
        t.setflags(write=False)
        out.append((v.astype(np.float32), t))
    return tuple(out)


def parse_triangles(spec: str) -> tuple[str, tuple | None]:
    """``"poly"`` -> the five polyhedra of :meth:`~warp_ccd._src.scene.scene.Scene.random`; ``"80"`` (``20 * 4**L``)
    or ``"icosphereL"`` -> icosphere level L; ``"mixed"`` -> meshes of the sizes of real assets, 120
    to 12,640 triangles (:func:`real_mesh_set`).

    Returns:
        ``(label, shapes)``: ``shapes`` for :meth:`Scene.random` (None: its default polyhedra).

    Raises:
        ValueError: an unknown spec.
    """
    text = str(spec).strip().lower()
    if text == "poly":
        return "poly", None
    if text == "mixed":
        return "mixed", real_mesh_set()
    if text.startswith("icosphere") and text[len("icosphere"):].isdigit():
        level = int(text[len("icosphere"):])
        return str(20 * 4**level), (f"icosphere{level}",)
    if text.isdigit():
        count = int(text)
        for level in range(9):
            if 20 * 4**level == count:
                return text, (f"icosphere{level}",)
    known = ", ".join(str(20 * 4**k) for k in range(6))
    raise ValueError(f"--triangles: {spec!r} is neither 'poly', 'mixed' nor an icosphere's triangle count "
                     f"({known}, ...)")
