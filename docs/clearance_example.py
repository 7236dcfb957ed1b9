"""Draws docs/clearance.png: clearance and distance queries on real meshes, the closest points drawn.

The scanned bunny (12,200 triangles) with the four CAD parts of an RJ45 plug (newton's example assets)
placed around it, scaled up 12 times: off its left 0.05 from its surface, off its right 0.1, sunk
0.06 into its top, 0.4 below it. ``wc.collide(meshes, clearance=0.15)`` reports the three within
0.15 (the sunk one at distance 0, its point on the intersection, its direction the direction of
least penetration);
``wc.distance(bunny, parts)`` measures all four, however far. Closest points joined by lines,
distances written beside them. Run: ``.venv/bin/python docs/clearance_example.py`` (needs matplotlib
and newton: ``pip install -e '.[test,bench]'``).
"""

import importlib.util
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

import warp_ccd as wc  # noqa: E402

GAPS = (0.05, 0.1, -0.06, 0.4)
"""How far each part stands off the bunny's surface (negative: sunk into it)."""
SIDES = ((-1.0, 0.2, 0.0), (1.0, 0.3, 0.0), (0.0, 1.0, 0.3), (0.5, -1.0, -0.3))
"""The directions (the bunny's frame, y up) of the bunny's points the parts stand off: its left,
right, top and underside."""
CLEARANCE = 0.15


def asset_meshes(name: str) -> list:
    """The meshes of one of newton's example assets, as this package's USD reader gives them."""
    from warp_ccd.usd import scene_from_usd

    folder = os.path.join(os.path.dirname(importlib.util.find_spec("newton").origin), "examples", "assets")
    return [(v.astype(np.float64), t) for v, t in scene_from_usd(os.path.join(folder, name), device="cpu",
                                                                   precision="float64").world_meshes()]


def scene() -> list:
    """The bunny, then the parts placed around it."""
    bunny = asset_meshes("bunny.usd")
    bv = bunny[0][0]
    centre = bv.mean(axis=0)
    meshes = list(bunny)
    for (v, t), gap, side in zip(asset_meshes("rj45_plug.usd"), GAPS, SIDES):
        v = (v - v.mean(axis=0)) * 12.0
        anchor = int(np.argmax(bv @ np.asarray(side)))
        out = (bv[anchor] - centre) / np.linalg.norm(bv[anchor] - centre)
        v = v + bv[anchor] + out * (np.abs(v @ out).max() + gap)
        for _ in range(3 if gap > 0 else 0):  # slide it along until its distance is the gap
            v = v - out * (wc.distance(bunny[0], (v, t), precision="float64").distance[0] - gap)
        meshes.append((v, t))
    return meshes


def main() -> str:
    meshes = scene()
    near = wc.collide(meshes, clearance=CLEARANCE, precision="float64")
    far = wc.distance(meshes[0], meshes[1:], precision="float64")
    fig = plt.figure(figsize=(9, 7.2), dpi=110)
    ax = fig.add_subplot(projection="3d")
    status = {int(b): ("intersecting" if i else "within") for (a, b), i in zip(near.object_pairs,
                                                                                near.object_intersecting) if a == 0}
    colours = {"intersecting": "#e0451f", "within": "#f2c12e", None: "#9a9a9a"}
    for k, (v, t) in enumerate(meshes):
        colour = "#d8d4cc" if k == 0 else colours[status.get(k)]
        poly = Poly3DCollection(v[t][:, :, [0, 2, 1]], facecolor=colour, edgecolor="none",
                                alpha=0.35 if k == 0 else 0.9)
        ax.add_collection3d(poly)
    for row, (a, b) in enumerate(far.pairs):
        p, q = far.closest_points[row]
        d = far.distance[row]
        within = d <= CLEARANCE
        ax.plot(*np.stack([p, q])[:, [0, 2, 1]].T, color="#1f6fd1", lw=2.0, ls="-" if within else "--")
        ax.scatter(*np.stack([p, q])[:, [0, 2, 1]].T, color="#1f6fd1", s=12, depthshade=False)
        label = "sunk in: 0 (intersecting)" if d == 0 else f"{d:.3f}" + ("" if within else f" (beyond {CLEARANCE:g})")
        away = (p + q) / 2 - meshes[0][0].mean(axis=0)
        ax.text(*((p + q) / 2 + 0.45 * away / np.linalg.norm(away))[[0, 2, 1]], label, color="#10335f", fontsize=10,
                ha="center", zorder=100, bbox={"facecolor": "white", "alpha": 0.7, "edgecolor": "none", "pad": 1.5})
    everything = np.concatenate([v for v, _ in meshes])[:, [0, 2, 1]]
    lo, hi = everything.min(axis=0), everything.max(axis=0)
    mid, half = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.view_init(elev=14, azim=-70)
    ax.set_box_aspect(None, zoom=1.35)
    ax.set_axis_off()
    ax.set_title(f"wc.collide(meshes, clearance={CLEARANCE:g}): {len(near.object_pairs)} pairs within "
                 f"({int(near.object_intersecting.sum())} intersecting); wc.distance(bunny, parts)\n"
                 "closest points joined (red: intersecting, yellow: within the clearance, grey: beyond it)",
                 fontsize=10)
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "clearance.png")
    fig.savefig(path, bbox_inches="tight")
    return path


if __name__ == "__main__":
    print(main())
