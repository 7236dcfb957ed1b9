"""Example User Meshes

Shows collision detection on meshes of one's own, moved two ways:

* rigid objects placed by 4x4 transforms every frame: a large icosphere that spins in place and
  four small ones (one shared mesh, so one shape instanced four times) whose orbit radius breathes
  in and out, so that they sink into the large sphere and leave it again
  (``Scene.from_meshes(meshes, transforms)`` then ``scene.set_transforms(...)``);
* a deforming mesh whose vertices are rewritten every frame: an icosphere that pulsates and
  twists among six small static cubes, touching them at the height of each pulse
  (``Scene.from_meshes(meshes, deforming=True)`` then ``scene.set_world_vertices(...)``).

Each scene is written to its own USD animation (the deforming one beside the stage path, with
``_deforming`` added to its name), colliding objects in red.
"""

import os

import numpy as np
import warp as wp

import warp_ccd as wc
from warp_ccd.usd import UsdAnimationWriter


def rotation_y(angle):
    """``(3, 3)`` rotation about +Y by ``angle`` radians."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rigid_transforms(t, num_small):
    """``(1 + num_small, 4, 4)`` transforms at time ``t`` seconds: the large sphere, then the small ones."""
    m = np.tile(np.eye(4), (1 + num_small, 1, 1))
    m[0, :3, :3] = rotation_y(0.8 * t)
    for k in range(num_small):
        phase = 2.0 * np.pi * k / num_small
        radius = 2.3 + 0.6 * np.sin(2.0 * t + phase)  # contact below 1.5 + 0.6 = 2.1
        angle = 0.5 * t + phase
        m[1 + k, :3, :3] = rotation_y(-1.5 * t + phase)
        m[1 + k, :3, 3] = radius * np.array([np.cos(angle), 0.25 * np.sin(3.0 * angle), np.sin(angle)])
    return m


def pulsating_sphere(vertices, t):
    """World vertices of the deforming icosphere at time ``t``: radius 1 +- 0.25, twisted about +Y."""
    scale = 1.0 + 0.25 * np.sin(3.0 * t)
    twist = 0.6 * np.sin(1.3 * t) * vertices[:, 1]  # angle grows with height
    c, s = np.cos(twist), np.sin(twist)
    x, y, z = vertices[:, 0], vertices[:, 1], vertices[:, 2]
    return scale * np.stack([c * x + s * z, y, -s * x + c * z], axis=1)


def deforming_path(stage_path):
    root, ext = os.path.splitext(stage_path)
    return f"{root}_deforming{ext}"


class Example:
    """Two small scenes of user meshes, their pipelines and (optionally) USD writers.

    Args:
        stage_path: USD file of the rigid scene (the deforming one goes beside it), or None.
    """

    def __init__(self, stage_path="example_user_meshes.usd"):
        self.fps = 60
        self.frame_dt = 1.0 / self.fps
        self.frame = 0
        self.time = 0.0

        # Rigid: meshes in local coordinates; the same tuple passed four times is one shape.
        large = wc.scene.icosphere(3)
        small_v, small_t = wc.scene.icosphere(2)
        small = (0.6 * small_v, small_t)
        self.num_small = 4
        meshes = [(1.5 * large[0], large[1])] + [small] * self.num_small
        self.rigid = wc.Scene.from_meshes(meshes, rigid_transforms(0.0, self.num_small))
        self.rigid_pipeline = wc.CollisionPipeline(self.rigid)

        # Deforming: vertices are given in world space, all objects concatenated, every frame.
        self.sphere_vertices, sphere_triangles = wc.scene.icosphere(3)
        cube_v, cube_t = wc.scene.shape("cube")
        directions = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)
        self.cube_vertices = np.concatenate([0.3 * cube_v + 1.3 * d for d in directions])
        cubes = [(0.3 * cube_v + 1.3 * d, cube_t) for d in directions]
        self.deforming = wc.Scene.from_meshes(
            [(self.sphere_vertices, sphere_triangles), *cubes], deforming=True
        )
        self.deforming.set_world_vertices(self.world_vertices(0.0))
        self.deforming_pipeline = wc.CollisionPipeline(self.deforming)

        self.rigid_result = None
        self.deforming_result = None
        self.rigid_writer = None
        self.deforming_writer = None
        if stage_path:
            self.rigid_writer = UsdAnimationWriter(stage_path, self.rigid, fps=self.fps)
            self.deforming_writer = UsdAnimationWriter(deforming_path(stage_path), self.deforming, fps=self.fps)

    def world_vertices(self, t):
        """``(V, 3)`` world vertices of the deforming scene at time ``t``: the sphere, then the cubes."""
        return np.concatenate([pulsating_sphere(self.sphere_vertices, t), self.cube_vertices])

    def step(self):
        self.time += self.frame_dt
        with wp.ScopedTimer("step", active=True):
            self.rigid.set_transforms(rigid_transforms(self.time, self.num_small))
            self.rigid_result = self.rigid_pipeline.detect()
            self.deforming.set_world_vertices(self.world_vertices(self.time))
            self.deforming_result = self.deforming_pipeline.detect()

    def render(self):
        if self.rigid_writer is not None:
            self.rigid_writer.add_frame(self.frame, self.rigid_result)
            self.deforming_writer.add_frame(self.frame, self.deforming_result)
        self.frame += 1

    def close(self):
        """Writes the USD files (nothing happens without a stage path)."""
        if self.rigid_writer is not None:
            self.rigid_writer.close()
            self.deforming_writer.close()


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--device", type=str, default=None, help="Override the default Warp device.")
    parser.add_argument(
        "--stage-path",
        type=lambda x: None if x == "None" else str(x),
        default="example_user_meshes.usd",
        help="Path to the output USD file of the rigid scene (None: no file).",
    )
    parser.add_argument("--num-frames", type=int, default=240, help="Total number of frames.")

    args = parser.parse_known_args()[0]

    with wp.ScopedDevice(args.device):
        example = Example(stage_path=args.stage_path)

        rigid_pairs = 0
        deforming_pairs = 0
        for _ in range(args.num_frames):
            example.step()
            example.render()
            rigid_pairs += len(example.rigid_result.object_pairs)
            deforming_pairs += len(example.deforming_result.object_pairs)

        example.close()

        print(f"{args.num_frames} frames: {rigid_pairs / args.num_frames:.2f} colliding pairs per frame (rigid), "
              f"{deforming_pairs / args.num_frames:.2f} (deforming)")
        if args.stage_path:
            print(f"wrote {args.stage_path} and {deforming_path(args.stage_path)}")
