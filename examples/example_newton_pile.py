"""Example Newton Pile

Non-convex meshes falling into a pile under newton's XPBD solver: rings (tori) dropped over a peg and onto
each other, and L-shaped blocks landing on the ground and on the rings. Every mesh-mesh contact comes from
warp_ccd (:class:`warp_ccd.newton.MeshContactBridge`: exact triangle tests, contacts reduced to 8 a pair, depth
measured inside the other's solid); the contacts with the ground plane come from newton's own pipeline, in the
same ``newton.Contacts`` buffer. Writes a USD animation with newton's USD viewer; open it in usdview. On a CPU
a frame (8 solver steps) takes 1-2.5 s once the pile forms, most of it warp_ccd's depth of resting ring pairs.

    python examples/example_newton_pile.py --num-frames 120
    python examples/example_newton_pile.py --stage-path None      # no file, timings only
"""

import newton
import numpy as np
import warp as wp

from warp_ccd.newton import MeshContactBridge


def torus(major=0.3, minor=0.08, segments=16, sides=8):
    """A closed ring about the z axis, outward triangles: ``(vertices (n, 3) float32, triangles (m, 3) int32)``."""
    u = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)[:, None]
    w = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)[None, :]
    r = major + minor * np.cos(w)
    v = np.stack([r * np.cos(u), r * np.sin(u), minor * np.sin(w) + 0.0 * u], axis=2).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(segments), np.arange(sides), indexing="ij")
    a, b = i * sides + j, ((i + 1) % segments) * sides + j
    c, d = ((i + 1) % segments) * sides + (j + 1) % sides, i * sides + (j + 1) % sides
    t = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return v.astype(np.float32), t.astype(np.int32)


def l_block(length=0.5, height=0.4, thickness=0.15, depth=0.25):
    """An L-shaped prism (a foot ``length`` long, an upright ``height`` tall, both ``thickness`` thick),
    ``depth`` deep along y, centred near its centre of mass: ``(vertices, triangles)``, outward triangles."""
    outline = np.array([[0.0, 0.0], [length, 0.0], [length, thickness], [thickness, thickness],
                        [thickness, height], [0.0, height]])  # counter-clockwise in (x, z)
    outline -= outline.mean(axis=0)
    n = len(outline)
    front = np.column_stack([outline[:, 0], np.full(n, -depth / 2), outline[:, 1]])
    back = front + [0.0, depth, 0.0]
    v = np.concatenate([front, back])
    cap = [[0, 1, 2], [0, 2, 3], [0, 3, 5], [3, 4, 5]]  # the L as four triangles, counter-clockwise in (x, z)
    t = [[a, c, b] for a, b, c in cap] + [[a + n, b + n, c + n] for a, b, c in cap]  # front faces -y
    for k in range(n):
        k1 = (k + 1) % n
        t += [[k, k1, k1 + n], [k, k1 + n, k + n]]
    v, t = v.astype(np.float32), np.asarray(t, np.int32)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    return v, (t if volume > 0 else t[:, ::-1].copy())


def peg(radius=0.1, height=0.8, sides=12):
    """A closed prism standing on z = 0 (``sides``-gon of ``radius``, ``height`` tall): ``(vertices, triangles)``."""
    ang = np.linspace(0.0, 2.0 * np.pi, sides, endpoint=False)
    ring = np.column_stack([radius * np.cos(ang), radius * np.sin(ang)])
    v = np.concatenate([np.column_stack([ring, np.zeros(sides)]), np.column_stack([ring, np.full(sides, height)]),
                        [[0.0, 0.0, 0.0], [0.0, 0.0, height]]])
    lo, hi = 2 * sides, 2 * sides + 1
    t = []
    for k in range(sides):
        k1 = (k + 1) % sides
        t += [[k, k1, k1 + sides], [k, k1 + sides, k + sides], [lo, k1, k], [hi, k + sides, k1 + sides]]
    return v.astype(np.float32), np.asarray(t, np.int32)


class Example:
    """A pile of rings and L-blocks, its newton model and solver, warp_ccd's mesh contacts and (optionally) a
    USD viewer.

    Args:
        stage_path: USD file to write, or None for no file.
        num_rings: rings dropped over the peg, one above the other.
        num_blocks: L-blocks dropped beside the peg.
        fps: frames a second; ``substeps`` solver steps a frame.
        seed: random seed of the drop poses.
    """

    def __init__(self, stage_path="example_newton_pile.usd", num_rings=3, num_blocks=3, fps=60, substeps=8, seed=0):
        self.fps = fps
        self.frame_dt = 1.0 / fps
        self.substeps = substeps
        self.sim_dt = self.frame_dt / substeps
        self.sim_time = 0.0
        rng = np.random.default_rng(seed)

        builder = newton.ModelBuilder()
        builder.default_shape_cfg.mu = 0.6
        builder.add_ground_plane()
        ring, block, post = torus(), l_block(), peg()
        ring_mesh = newton.Mesh(ring[0], ring[1].reshape(-1))
        block_mesh = newton.Mesh(block[0], block[1].reshape(-1))
        builder.add_shape_mesh(-1, mesh=newton.Mesh(post[0], post[1].reshape(-1)))  # static: the world's
        for k in range(num_rings):  # over the peg, tilted a little, each higher than the last
            tilt = wp.quat_rpy(*(float(a) for a in (*rng.uniform(-0.25, 0.25, 2), rng.uniform(0.0, np.pi))))
            centre = wp.vec3(*(float(x) for x in rng.uniform(-0.05, 0.05, 2)), 0.9 + 0.3 * k)
            body = builder.add_body(xform=wp.transform(centre, tilt), label=f"ring{k}")
            builder.add_shape_mesh(body, mesh=ring_mesh)
        top = 0.9 + 0.3 * num_rings + 0.3
        for k in range(num_blocks):  # above the rings' rims, landing on them, the ground and each other
            ang = 2.0 * np.pi * k / max(num_blocks, 1)
            pose = wp.transform(wp.vec3(float(0.5 * np.cos(ang)), float(0.5 * np.sin(ang)), top + 0.45 * k),
                                wp.quat_rpy(*(float(a) for a in rng.uniform(-np.pi, np.pi, 3))))
            body = builder.add_body(xform=pose, label=f"block{k}")
            builder.add_shape_mesh(body, mesh=block_mesh)
        self.model = builder.finalize()

        # warp_ccd for the mesh pairs, newton's pipeline for the rest (the ground plane), one Contacts buffer.
        self.bridge = MeshContactBridge(self.model)
        self.contacts = self.bridge.contacts()
        self.solver = newton.solvers.SolverXPBD(self.model, iterations=8)
        self.state_0, self.state_1 = self.model.state(), self.model.state()
        self.control = self.model.control()

        self.viewer = None
        if stage_path:
            self.viewer = newton.viewer.ViewerUSD(stage_path, fps=fps, num_frames=None)
            self.viewer.set_model(self.model)

    def step(self):
        with wp.ScopedTimer("step", active=True):
            for _ in range(self.substeps):
                self.state_0.clear_forces()
                self.bridge.collide(self.state_0, self.contacts)
                self.solver.step(self.state_0, self.state_1, self.control, self.contacts, self.sim_dt)
                self.state_0, self.state_1 = self.state_1, self.state_0
        self.sim_time += self.frame_dt

    def render(self):
        if self.viewer is None:
            return
        self.viewer.begin_frame(self.sim_time)
        self.viewer.log_state(self.state_0)
        self.viewer.end_frame()

    def close(self):
        """Writes the USD file (nothing happens without a stage path)."""
        if self.viewer is not None:
            self.viewer.close()


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--device", type=str, default=None, help="Override the default Warp device.")
    parser.add_argument(
        "--stage-path",
        type=lambda x: None if x == "None" else str(x),
        default="example_newton_pile.usd",
        help="Path to the output USD file (None: no file).",
    )
    parser.add_argument("--num-frames", type=int, default=120, help="Total number of frames.")
    parser.add_argument("--num-rings", type=int, default=3, help="Rings dropped over the peg.")
    parser.add_argument("--num-blocks", type=int, default=3, help="L-blocks dropped around it.")

    args = parser.parse_known_args()[0]

    with wp.ScopedDevice(args.device):
        example = Example(stage_path=args.stage_path, num_rings=args.num_rings, num_blocks=args.num_blocks)
        for _ in range(args.num_frames):
            example.step()
            example.render()
        example.close()
