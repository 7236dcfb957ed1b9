"""Draws docs/self_intersection.png: meshes that pass through themselves, their self-intersecting faces marked.

Left, a cloth sheet (40 x 40 vertices, 3,042 triangles) whose right half is folded back over the left and
waves through it; right, a figure-eight torus (a tube whose cross-section crosses itself, all around its
circle). ``wc.self_intersections(vertices, triangles)`` gives the pairs of triangles that meet other than
through the vertices they share; the triangles in such pairs are drawn in magenta, the others in grey.
Neighbouring triangles, which share vertices and edges, are not reported. Run:
``.venv/bin/python docs/self_intersection_example.py`` (needs matplotlib: ``pip install -e '.[test,bench]'``).
"""

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

import warp_ccd as wc  # noqa: E402

MAGENTA = (0.85, 0.2, 0.85)
GREY = (0.78, 0.8, 0.84)


def folded_cloth(n: int = 40):
    """A sheet whose half beyond x = 0.5 is folded back over the rest as a wave crossing it."""
    v, t = wc.scene.sheet(n)
    v = v.astype(np.float64)
    f = v[:, 0] > 0.5
    x = v[f, 0] - 0.5
    v[f, 0] = 0.5 + 0.37 / (n - 1) - x  # folded back, no column onto another
    v[f, 2] = 0.04 * np.sin(2.0 * np.pi * (2.0 * v[f, 1] + x)) + 0.3 * x**2  # the wave crosses the flat half
    return v, t


def draw(ax, v, t, pairs, title, view):
    """The mesh with the faces of ``pairs`` in magenta."""
    marked = np.zeros(len(t), bool)
    marked[pairs.ravel()] = True
    colors = np.where(marked[:, None], MAGENTA, GREY)
    light = np.array([0.3, -0.4, 0.85]) / np.linalg.norm([0.3, -0.4, 0.85])
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-30
    shade = 0.55 + 0.45 * np.abs(n @ light)
    ax.add_collection3d(Poly3DCollection(v[t], facecolors=colors * shade[:, None], edgecolors="none",
                                         linewidths=0.0, alpha=0.92))
    lo, hi = v.min(axis=0), v.max(axis=0)
    c, r = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set_xlim(c[0] - r, c[0] + r)
    ax.set_ylim(c[1] - r, c[1] + r)
    ax.set_zlim(c[2] - r, c[2] + r)
    ax.view_init(*view)
    ax.set_box_aspect((1, 1, 1), zoom=1.6)
    ax.set_axis_off()
    faces = len(np.unique(pairs))
    ax.set_title(f"{title}\n{len(t):,} triangles: {len(pairs):,} self-intersecting pairs, {faces:,} faces",
                 fontsize=9)


def main(path: str = os.path.join(os.path.dirname(__file__), "self_intersection.png")) -> str:
    fig = plt.figure(figsize=(10, 4.6), dpi=110)
    cloth = folded_cloth()
    torus = wc.scene.figure_eight_torus(96, 32)
    for k, ((v, t), title, view) in enumerate(((cloth, "a cloth folded through itself", (28, -60)),
                                               (torus, "a figure-eight torus", (32, -50)))):
        pairs = wc.self_intersections(v, t, device="cpu")
        draw(fig.add_subplot(1, 2, k + 1, projection="3d"), np.asarray(v, np.float64), t, pairs, title, view)
    fig.suptitle("wc.self_intersections: triangles meeting beyond the vertices they share (magenta)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    return path


if __name__ == "__main__":
    print(main())
