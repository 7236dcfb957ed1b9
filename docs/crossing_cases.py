"""Draws docs/crossing_cases.png: the verdict of :mod:`warp_ccd._src.check.crossing` in the plane across an
intersection segment, for the cases users meet. Run: ``.venv/bin/python docs/crossing_cases.py``
(needs matplotlib: ``pip install -e '.[bench]'``)."""

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

# Each surface seen across the segment: rays (angles, degrees) from the crossing point, and which
# directions lie behind it (its inside), as in crossing._behind: a sheet's half-plane, a convex
# fold's wedge (behind both faces), a concave fold's union.
CASES = [
    ("crate sunk in a floor:\na grid line under its wall", "crosses",
     {"rays": [180, 0], "inside": lambda a: np.sin(a) < 0},  # floor, two triangles, facing up
     {"rays": [90, 270], "inside": lambda a: np.cos(a) > 0}),  # the crate's wall, facing -x
    ("crate resting on a floor", "touches",
     {"rays": [180, 0], "inside": lambda a: np.sin(a) < 0},
     {"rays": [90, 0], "inside": lambda a: (np.sin(a) > 0) & (np.cos(a) > 0)}),  # wall and bottom: convex
    ("boxes overlapping,\nfaces flush", "crosses",
     {"rays": [180, 0], "inside": lambda a: np.sin(a) > 0},  # B's bottom, facing down
     {"rays": [90, 180], "inside": lambda a: (np.sin(a) > 0) & (np.cos(a) < 0)}),  # A's wall and bottom
    ("edge on edge", "touches",
     {"rays": [60, 120], "inside": lambda a: (np.sin(a) > 0) & (np.abs(np.cos(a)) < 0.5)},
     {"rays": [240, 300], "inside": lambda a: (np.sin(a) < 0) & (np.abs(np.cos(a)) < 0.5)}),
    ("open shells meeting\n(a parting plane)", "touches",
     {"rays": [180], "inside": lambda a: np.zeros_like(a, bool)},  # a boundary: nothing behind it
     {"rays": [0], "inside": lambda a: np.zeros_like(a, bool)}),
    ("a wall through\na concave corner", "crosses",
     {"rays": [180, 270], "inside": lambda a: (np.sin(a) > 0) | (np.cos(a) > 0)},  # concave: behind either
     {"rays": [45, 225], "inside": lambda a: np.sin(a - np.pi / 4) < 0}),
]


def draw(ax, title, verdict, a, b):
    angles = np.radians(np.linspace(0, 360, 721))
    for surface, colour in ((a, "tab:blue"), (b, "tab:orange")):
        inside = surface["inside"](angles)
        for k in np.nonzero(inside)[0]:
            ax.fill([0, np.cos(angles[k]), np.cos(angles[k + 1] if k + 1 < len(angles) else angles[0])],
                    [0, np.sin(angles[k]), np.sin(angles[k + 1] if k + 1 < len(angles) else angles[0])],
                    color=colour, alpha=0.18, lw=0)
        for r in surface["rays"]:
            t = np.radians(r)
            ax.plot([0, np.cos(t)], [0, np.sin(t)], color=colour, lw=3)
    both = a["inside"](angles) & b["inside"](angles)
    ax.set_title(f"{title}\n{verdict}", fontsize=9, color="tab:red" if both.any() else "black")
    ax.plot([0], [0], "ko", ms=4)
    ax.set_xlim(-1.1, 1.1)
    ax.set_ylim(-1.1, 1.1)
    ax.set_aspect("equal")
    ax.axis("off")


def main():
    fig, axes = plt.subplots(1, len(CASES), figsize=(2.3 * len(CASES), 3.3))
    for ax, (title, verdict, a, b) in zip(axes, CASES):
        draw(ax, title, verdict, a, b)
    fig.suptitle("Across the segment where two surfaces meet: lines are the surfaces, shading what lies behind "
                 "each;\nthey cross where one goes into the other's shading (the insides overlap)", fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 0.86))
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "crossing_cases.png")
    fig.savefig(out, dpi=110)
    print(out)


if __name__ == "__main__":
    main()
