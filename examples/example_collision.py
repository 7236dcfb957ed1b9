"""Example Collision

Shows the main loop of warp_ccd: a seeded scene of polyhedra moving on inclined ellipses, a
persistent collision pipeline (bounds -> sweep-and-prune broad phase -> mid phase -> Möller
triangle tests) run every frame on the device, and a USD animation in which every object that
intersects another turns red. Open the stage in usdview or Omniverse to play it.

    python examples/example_collision.py --num-objects 1000 --num-frames 120
    python examples/example_collision.py --stage-path None      # no file, timings only
"""

import numpy as np
import warp as wp

import warp_ccd as wc
from warp_ccd.usd import UsdAnimationWriter


class Example:
    """A random scene, its collision pipeline and (optionally) a USD writer.

    Args:
        stage_path: USD file to write (``.usd``, ``.usdc`` or ``.usda``), or None for no file.
        num_objects: number of objects.
        seed: random seed of the scene.
    """

    def __init__(self, stage_path="example_collision.usd", num_objects=1000, seed=0):
        self.fps = 60
        self.frame_dt = 1.0 / self.fps
        self.frame = 0

        # Polyhedra (tetrahedra, cubes, octahedra, dodecahedra, icosahedra) on Warp's default device.
        self.scene = wc.Scene.random(num_objects, seed=seed)
        self.pipeline = wc.CollisionPipeline(self.scene)
        self.result = None
        self.colliding_counts = []

        # The writer checks the path now, before anything runs.
        self.writer = UsdAnimationWriter(stage_path, self.scene, fps=self.fps) if stage_path else None

    def step(self):
        with wp.ScopedTimer("step", active=True):
            self.scene.advance(self.frame_dt)
            self.result = self.pipeline.detect()
        self.colliding_counts.append(int(np.count_nonzero(self.result.colliding)))

    def render(self):
        if self.writer is None:
            return
        with wp.ScopedTimer("render", active=True):
            self.writer.add_frame(self.frame, self.result)
        self.frame += 1

    def close(self):
        """Writes the USD file (nothing happens without a stage path)."""
        if self.writer is not None:
            self.writer.close()


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--device", type=str, default=None, help="Override the default Warp device.")
    parser.add_argument(
        "--stage-path",
        type=lambda x: None if x == "None" else str(x),
        default="example_collision.usd",
        help="Path to the output USD file (None: no file).",
    )
    parser.add_argument("--num-frames", type=int, default=120, help="Total number of frames.")
    parser.add_argument("--num-objects", type=int, default=1000, help="Number of objects.")

    args = parser.parse_known_args()[0]

    with wp.ScopedDevice(args.device):
        example = Example(stage_path=args.stage_path, num_objects=args.num_objects)

        for _ in range(args.num_frames):
            example.step()
            example.render()

        example.close()

        counts = np.array(example.colliding_counts)
        print(f"{args.num_objects} objects, {args.num_frames} frames: {counts.mean():.1f} colliding objects per frame")
        if args.stage_path:
            print(f"wrote {args.stage_path}")
