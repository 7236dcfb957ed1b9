"""Draws docs/contacts_cases.png: the contacts :func:`warp_ccd.contacts` gives (points, normals from ``b`` to ``a``,
depths) in three cases, seen from the side: a crate sunk into a slab, two boxes stacked with flush sides, a ball
pressed into another. Every point and arrow is computed by the library. Run:
``.venv/bin/python docs/contacts_cases.py`` (needs matplotlib: ``pip install -e '.[bench]'``)."""

import os

import matplotlib
import numpy as np

import warp_ccd as wc

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from scipy.spatial import ConvexHull  # noqa: E402

BLUE, ORANGE, RED, GREY = "#4c72b0", "#dd8452", "#c44e52", "#555555"


def box(lo, hi):
    """An axis-aligned box, outward-wound."""
    v, t = wc.scene.shape("cube")
    v = np.asarray(v, float)
    v = (v - v.min(0)) / np.ptp(v, 0)
    return v * (np.asarray(hi, float) - lo) + lo, t


def outline(ax, mesh, color, label):
    """The mesh's side view (x, z): the hull of its vertices' projections, filled."""
    p = np.asarray(mesh[0])[:, [0, 2]]
    ring = p[ConvexHull(p).vertices]
    ax.fill(*ring.T, color=color, alpha=0.2, ec=color, lw=2)
    ax.text(*(p.min(0) + [0.05, 0.05]), label, color=color, fontsize=11)


def draw(ax, meshes, title, **kwargs):
    outline(ax, meshes[0], BLUE, "a")
    outline(ax, meshes[1], ORANGE, "b")
    c = wc.contacts(meshes, **kwargs)
    scale = 0.35
    for k in range(c.count):
        pa, pb, n, d = c.point_a[k], c.point_b[k], c.normal[k], c.depth[k]
        color = RED if d > 1e-9 else GREY
        ax.plot(*np.stack([pa, pb])[:, [0, 2]].T, "-", color=color, lw=2, zorder=3)  # the depth: a to b
        ax.plot(*pa[[0, 2]], "o", color=BLUE, ms=5, zorder=4)
        ax.plot(*pb[[0, 2]], "o", color=ORANGE, ms=5, zorder=4)
        ax.annotate("", xy=pb[[0, 2]] + scale * n[[0, 2]], xytext=pb[[0, 2]],
                    arrowprops={"arrowstyle": "->", "color": color, "lw": 1.5})
    deep = int(np.argmax(c.depth))
    ax.set_title(f"{title}\n{c.count} contacts, deepest {c.depth[deep]:.3g}", fontsize=10)
    ax.set_aspect("equal")
    ax.axis("off")


def main(path: str) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.4))
    draw(axes[0], [box([-0.6, -0.4, -0.15], [0.6, 0.4, 0.85]), box([-1.5, -1.5, -0.8], [1.5, 1.5, 0.0])],
         "a crate (a) sunk 0.15 into a slab (b):\nits corners at the depth, normals out of the slab")
    draw(axes[1], [box([0, 0, 0.9], [1, 1, 1.9]), box([0, 0, 0], [1, 1, 1])],
         "boxes stacked with flush sides, 0.1 deep:\nthe deepest point, the outline at depth 0", max_per_pair=4)
    ball = wc.scene.icosphere(3)
    draw(axes[2], [(np.asarray(ball[0]) * 0.6 + [1.2, 0.0, 0.3], ball[1]), ball],
         "a ball (a) pressed into another:\nthe deepest contact and the rim of the crossing")
    fig.suptitle("each contact: its point on a (blue) to its point on b (orange), red where deeper than 0; "
                 "arrow: the normal, from b to a", fontsize=10, y=0.06)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


if __name__ == "__main__":
    main(os.path.join(os.path.dirname(os.path.abspath(__file__)), "contacts_cases.png"))
