"""The scene of ``warp-ccd demo --continuous``: fast small boxes flying through thin walls.

Each box flies back and forth along x between the first wall and the last (bouncing at the ends) so
fast that in one frame step it moves several times its own size plus a wall's thickness: at most
frames it is clear of every wall, yet between two frames it passes through one. Discrete detection
at the frames misses most of those contacts; continuous detection over each frame step (every
vertex moving linearly from one frame to the next, as the USD animation interpolates) catches them.
:class:`ContactTally` counts the contacts seen at the frames, over the steps, and over the steps
only (tunnelling).
"""

from __future__ import annotations

import numpy as np

__all__ = ["ContactTally", "ThinWalls"]

WALL_THICKNESS = 0.05
WALL_SPACING = 8.0
"""Distance between walls: a box crosses one in about a fifth of its frame steps."""
BOX_HALF = 0.1
SPEED_RANGE = (1.2, 2.4)
"""Distance along x a box flies in one frame step: 6 to 12 times its size."""


def box_mesh(half) -> tuple[np.ndarray, np.ndarray]:
    """A closed box of 12 triangles centred at the origin, half extents ``half`` ``(3,)``."""
    h = np.asarray(half, np.float64)
    v = np.array([[(h if (k >> a) & 1 else -h)[a] for a in range(3)] for k in range(8)])
    t = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4], [2, 6, 3], [3, 6, 7],
                  [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]], np.int32)
    return v, t


def _rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """``(n, 3, 3)`` random rotation matrices (from uniform random unit quaternions)."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                     np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                     np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], 1)


class ThinWalls:
    """Thin walls across x and fast small boxes flying through them.

    Square walls parallel to the y-z plane, ``WALL_SPACING`` apart, as many as make the scene about
    as long as it is wide (at least one), with about half a square unit of wall per box; the other
    objects are boxes of side ``2 * BOX_HALF``, each at its own height and depth, turned at random,
    flying along x at its own speed (``SPEED_RANGE`` per frame) from a random start, between half a
    spacing before the first wall and half a spacing after the last.

    Args:
        num_objects: walls and boxes together, >= 2.
        seed: random seed (same seed, same scene).
        device: Warp device.

    Attributes:
        scene: the :class:`~warp_ccd._src.scene.scene.Scene` (rigid), placed at frame 0.
        num_walls: the walls (objects ``0 .. num_walls - 1``); the boxes follow.
    """

    def __init__(self, num_objects: int, seed: int = 0, device=None):
        from ..scene.scene import Scene

        if num_objects < 2:
            raise ValueError(f"--continuous: the demo needs at least 2 objects (a wall and a box), got {num_objects}")
        rng = np.random.default_rng(seed)
        side = max(3.0, float(np.sqrt(num_objects * 0.5)))  # about half a square unit of wall per box
        self.num_walls = w = max(1, min(num_objects - 1, round(side / WALL_SPACING)))
        boxes = num_objects - w
        wall = box_mesh((WALL_THICKNESS / 2, side / 2, side / 2))
        box = box_mesh((BOX_HALF, BOX_HALF, BOX_HALF))
        self._wall_x = WALL_SPACING * np.arange(w)
        self._lo = -WALL_SPACING / 2
        self._length = WALL_SPACING * w  # the boxes fly in [lo, lo + length]
        self._yz = rng.uniform(-side / 2 + BOX_HALF, side / 2 - BOX_HALF, size=(boxes, 2))
        self._phase = rng.uniform(0.0, 2 * self._length, size=boxes)
        self._speed = rng.uniform(*SPEED_RANGE, size=boxes)
        self._rotation = _rotations(rng, boxes)
        self.scene = Scene.from_meshes([wall] * w + [box] * boxes, self.transforms(0), device=device)

    def transforms(self, frame: int) -> np.ndarray:
        """``(N, 4, 4)`` the objects' transforms at ``frame``: the walls still, the boxes bouncing."""
        n = self.num_walls + len(self._speed)
        m = np.tile(np.eye(4), (n, 1, 1))
        m[: self.num_walls, 0, 3] = self._wall_x
        s = np.mod(self._phase + self._speed * frame, 2 * self._length)  # a triangle wave in [0, length]
        x = self._lo + np.where(s <= self._length, s, 2 * self._length - s)
        m[self.num_walls:, :3, :3] = self._rotation
        m[self.num_walls:, :3, 3] = np.column_stack([x, self._yz])
        return m

    def place(self, frame: int) -> None:
        """Moves the scene to ``frame``."""
        self.scene.set_transforms(self.transforms(frame))


class ContactTally:
    """Object pairs in contact, counted per frame (discrete) and per frame step (continuous).

    Attributes:
        at_frames: pairs seen at the frames, summed over frames.
        over_steps: pairs seen over the frame steps (continuous), summed over steps.
        only_continuous: pairs of a step that neither of its two frames shows (tunnelling), summed.
    """

    def __init__(self):
        self.at_frames = self.over_steps = self.only_continuous = 0
        self._previous: set | None = None

    def add(self, discrete_pairs: np.ndarray, continuous_pairs: np.ndarray) -> None:
        """Counts one frame: ``(K, 2)`` object pairs found at it, and over the step that led to it."""
        now = {tuple(p) for p in np.asarray(discrete_pairs).reshape(-1, 2).tolist()}
        step = {tuple(p) for p in np.asarray(continuous_pairs).reshape(-1, 2).tolist()}
        self.at_frames += len(now)
        self.over_steps += len(step)
        self.only_continuous += len(step - now - (self._previous or set()))
        self._previous = now
