"""Draws docs/depth_cases.png: what the depth of a penetrating pair is
(:mod:`warp_ccd._src.narrowphase.depth`), in a cross-section of three cases. Run:
``.venv/bin/python docs/depth_cases.py`` (needs matplotlib: ``pip install -e '.[bench]'``)."""

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

BLUE, ORANGE, RED = "#4c72b0", "#dd8452", "#c44e52"


def solid(ax, x0, y0, w, h, color, label):
    ax.add_patch(Rectangle((x0, y0), w, h, facecolor=color, alpha=0.25, edgecolor=color, lw=2))
    ax.text(x0 + 0.04, y0 + h - 0.1, label, color=color, fontsize=11, va="top")


def arrow(ax, p, q, text, offset=(0.03, 0.03)):
    ax.annotate("", xy=q, xytext=p, arrowprops={"arrowstyle": "<->", "color": RED, "lw": 2})
    ax.plot(*p, "o", color=RED, ms=6)
    ax.text((p[0] + q[0]) / 2 + offset[0], (p[1] + q[1]) / 2 + offset[1], text, color=RED, fontsize=11)


def main(path: str) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.4))
    # Flush cubes: A = [-0.5, 0.5]^2, B = A moved by 0.3 along x. The centre of A's face x = 0.5 lies 0.3
    # inside B, 0.3 from B's face x = 0.8 (no vertex of either lies inside the other).
    ax = axes[0]
    solid(ax, -0.5, -0.5, 1.0, 1.0, BLUE, "A")
    solid(ax, -0.2, -0.5, 1.0, 1.0, ORANGE, "B")
    ax.plot([0.5, 0.5], [-0.5, 0.5], color=BLUE, lw=4)
    arrow(ax, (0.5, 0.0), (0.8, 0.0), "0.3")
    ax.set_title("two unit cubes overlapping by 0.7, faces flush:\ndepth 0.3 (every vertex is on a surface)")
    # A pole of radius r through a plate of thickness w: max(r, w / 2).
    ax = axes[1]
    solid(ax, -1.2, -0.15, 2.4, 0.3, ORANGE, "plate")
    solid(ax, -0.35, -0.9, 0.7, 1.8, BLUE, "pole")
    ax.plot([-0.35, 0.35], [0.15, 0.15], color=ORANGE, lw=4)
    arrow(ax, (0.0, 0.15), (0.35, 0.15), "r", (0.0, 0.05))
    ax.plot([-0.35, -0.35], [-0.15, 0.15], color=BLUE, lw=4)
    arrow(ax, (-0.35, 0.0), (-0.35, 0.15), "w/2", (-0.32, -0.05))
    ax.set_title("a pole of radius r through a plate of thickness w:\ndepth max(r, w/2)")
    # A pole through a cloth: the cloth has no inside, its winding cannot matter.
    ax = axes[2]
    solid(ax, -0.35, -0.9, 0.7, 1.8, BLUE, "pole")
    ax.plot([-1.2, 1.2], [0.0, 0.0], color=ORANGE, lw=3)
    ax.text(0.5, 0.05, "cloth (open)", color=ORANGE, fontsize=11)
    arrow(ax, (0.0, 0.0), (0.35, 0.0), "r", (-0.05, -0.13))
    ax.set_title("a pole through a cloth (an open sheet):\ndepth r, the cloth inside the pole, either winding")
    for ax in axes:
        ax.set_aspect("equal")
        ax.set_xlim(-1.3, 1.3)
        ax.set_ylim(-1.0, 1.0)
        ax.axis("off")
    fig.suptitle("depth = the deepest point of either surface inside the other's closed solid, to its surface",
                 fontsize=12)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    main(os.path.join(os.path.dirname(os.path.abspath(__file__)), "depth_cases.png"))
