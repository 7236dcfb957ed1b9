"""warp_ccd's mesh-mesh contacts in newton (:mod:`warp_ccd._src.compat.newton`): the pairs each pipeline gets, the
poses placed from ``body_q``, the rows appended to newton's arrays (against warp_ccd's own contacts and against
newton's conventions on boxes, where newton's own contacts exist), and a small stack under XPBD that comes to rest
without gaining energy or sinking."""

import numpy as np
import pytest
import warp as wp

from warp_ccd.scene import shape

from conftest import DEFAULT_DEVICE

newton = pytest.importorskip("newton")

from warp_ccd.newton import MeshContactBridge, mesh_pairs  # noqa: E402 (after the skip: it imports newton)


def box_mesh(half):
    """A cube of half-size ``half`` as a ``newton.Mesh``."""
    v, t = shape("cube")
    return newton.Mesh(v / np.abs(v).max() * half, t.reshape(-1))


def l_mesh():
    """An L-shaped prism (non-convex), about 0.4 x 0.2 x 0.4, as a ``newton.Mesh``."""
    outline = np.array([[0.0, 0.0], [0.4, 0.0], [0.4, 0.1], [0.1, 0.1], [0.1, 0.4], [0.0, 0.4]]) - [0.15, 0.15]
    v = np.concatenate([np.column_stack([outline[:, 0], np.full(6, y), outline[:, 1]]) for y in (-0.1, 0.1)])
    cap = [[0, 2, 1], [0, 3, 2], [0, 5, 3], [3, 5, 4]]
    t = cap + [[a + 6, c + 6, b + 6] for a, b, c in cap]
    t += [tri for k in range(6) for tri in ([k, (k + 1) % 6, (k + 1) % 6 + 6], [k, (k + 1) % 6 + 6, k + 6])]
    t = np.asarray(t, np.int32)
    a, b, c = (v[t[:, i]] for i in range(3))
    if np.einsum("ij,ij->i", a, np.cross(b, c)).sum() < 0:
        t = t[:, ::-1]
    return newton.Mesh(v.astype(np.float32), t.reshape(-1))


def quat_z(angle):
    return wp.quat_from_axis_angle(wp.vec3(0.0, 0.0, 1.0), float(angle))


def model_of(bodies, ground=True):
    """A model of one body per ``(position, yaw, kind)``, kind ``"mesh"`` (a mesh cube of half-size 0.1) or
    ``"box"`` (the same cube as newton's box primitive) or ``"l"`` (the L prism), on ``DEFAULT_DEVICE``."""
    b = newton.ModelBuilder()
    if ground:
        b.add_ground_plane()
    cube = box_mesh(0.1)
    ell = l_mesh()
    for pos, yaw, kind in bodies:
        body = b.add_body(xform=wp.transform(wp.vec3(*pos), quat_z(yaw)))
        if kind == "box":
            b.add_shape_box(body, hx=0.1, hy=0.1, hz=0.1)
        else:
            b.add_shape_mesh(body, mesh=cube if kind == "mesh" else ell)
    return b.finalize(device=DEFAULT_DEVICE)


def rows(contacts, start, stop):
    """newton's rigid contact arrays ``[start, stop)`` as numpy."""
    names = ("shape0", "shape1", "point0", "point1", "normal", "offset0", "offset1", "margin0", "margin1")
    return {n: getattr(contacts, f"rigid_contact_{n}").numpy()[start:stop] for n in names}


def tf(row):
    """A ``(7,)`` pose row as a ``wp.transform``."""
    return wp.transform(wp.vec3(*(float(x) for x in row[:3])), wp.quat(*(float(x) for x in row[3:])))


def to_world(body_q, shape_body, shapes, points):
    """Body-frame ``points`` of ``shapes`` in world space."""
    out = np.empty_like(points, dtype=np.float64)
    for i, (s, p) in enumerate(zip(shapes, points)):
        b = shape_body[s]
        out[i] = p if b < 0 else wp.transform_point(tf(body_q[b]), wp.vec3(p))
    return out


def test_pairs_split_respects_newton_filters():
    b = newton.ModelBuilder()
    b.add_ground_plane()  # shape 0
    cube = box_mesh(0.1)
    b0 = b.add_body(xform=wp.transform(wp.vec3(0.0, 0.0, 0.1), wp.quat_identity()))
    s1 = b.add_shape_mesh(b0, mesh=cube)
    s2 = b.add_shape_mesh(b0, mesh=cube, xform=wp.transform(wp.vec3(0.0, 0.0, 0.15), wp.quat_identity()))  # same body
    b1 = b.add_body(xform=wp.transform(wp.vec3(0.0, 0.0, 0.3), wp.quat_identity()))
    s3 = b.add_shape_mesh(b1, mesh=cube)
    b2 = b.add_body(xform=wp.transform(wp.vec3(0.0, 0.0, 0.5), wp.quat_identity()))
    s4 = b.add_shape_mesh(b2, mesh=cube)
    s5 = b.add_shape_box(b2, hx=0.1, hy=0.1, hz=0.1, xform=wp.transform(wp.vec3(0.3, 0.0, 0.0), wp.quat_identity()))
    b.add_shape_collision_filter_pair(s1, s4)
    model = b.finalize(device=DEFAULT_DEVICE)
    shapes, mesh_mesh, other = mesh_pairs(model)
    assert shapes.tolist() == [s1, s2, s3, s4]
    allowed = {tuple(shapes[p]) for p in mesh_mesh}
    assert allowed == {(s1, s3), (s2, s3), (s2, s4), (s3, s4)}  # not one body (s1, s2), not filtered (s1, s4)
    others = {tuple(sorted(p)) for p in other.tolist()}
    assert all(not (a in shapes and b in shapes) for a, b in others) and (0, s1) in others and (s3, s5) in others
    bridge = MeshContactBridge(model)
    f = bridge.scene.collision_filter
    everything = np.array([[i, j] for i in range(4) for j in range(i + 1, 4)])
    assert {tuple(shapes[p]) for p in everything[f.allowed(everything)]} == allowed


def test_poses_follow_body_q_shape_transform_and_scale():
    b = newton.ModelBuilder()
    v, t = shape("tetrahedron")
    mesh = newton.Mesh(v, t.reshape(-1))
    body = b.add_body(xform=wp.transform(wp.vec3(0.3, -0.2, 1.0), wp.quat_rpy(0.3, -0.5, 1.1)))
    xform = wp.transform(wp.vec3(0.1, 0.2, -0.05), wp.quat_rpy(-0.7, 0.2, 0.4))
    b.add_shape_mesh(body, mesh=mesh, xform=xform, scale=wp.vec3(0.5, 1.5, 2.0))
    b.add_shape_mesh(-1, mesh=mesh, xform=wp.transform(wp.vec3(2.0, 0.0, 0.0), wp.quat_identity()))  # static
    model = b.finalize(device=DEFAULT_DEVICE)
    bridge = MeshContactBridge(model)
    state = model.state()
    q = np.array([[0.5, 0.4, 0.3, *np.array(wp.quat_rpy(1.0, 0.2, -0.3))]], np.float32)
    state.body_q.assign(q)
    bridge.update_poses(state)
    world = bridge.scene.world_vertex.numpy()
    x = wp.transform_multiply(tf(q[0]), xform)
    expected = [wp.transform_point(x, wp.vec3(*(p * [0.5, 1.5, 2.0]))) for p in v]
    np.testing.assert_allclose(world[:4], np.array(expected), atol=1e-5)
    np.testing.assert_allclose(world[4:], v + [2.0, 0.0, 0.0], atol=1e-6)


def test_appended_contacts_are_warp_ccds():
    # Two mesh cubes sunk 0.02 into each other, the upper turned and shifted, on a ground plane.
    model = model_of([((0.0, 0.0, 0.1), 0.0, "mesh"), ((0.03, 0.02, 0.28), 0.4, "mesh")])
    bridge = MeshContactBridge(model, gap=0.0)
    contacts = bridge.contacts()
    state = model.state()
    bridge.newton_pipeline.collide(state, contacts)
    first = int(contacts.rigid_contact_count.numpy()[0])  # newton's own: the lower cube on the plane
    bridge.collide(state, contacts)
    ours = bridge.result.contacts
    assert 4 <= ours.count <= 8 and ours.object_pairs.tolist() == [[0, 1]]
    assert int(contacts.rigid_contact_count.numpy()[0]) == first + ours.count
    got = rows(contacts, first, first + ours.count)
    order = np.lexsort(got["point0"].T)  # the append's order is the threads'
    mine = np.lexsort(ours.point_a.T)
    shapes = bridge.mesh_shapes
    assert (got["shape0"] == shapes[0]).all() and (got["shape1"] == shapes[1]).all()
    body_q, shape_body = state.body_q.numpy(), model.shape_body.numpy()
    world0 = to_world(body_q, shape_body, got["shape0"], got["point0"])[order]
    world1 = to_world(body_q, shape_body, got["shape1"], got["point1"])[order]
    np.testing.assert_allclose(world0, ours.point_a[mine], atol=1e-5)
    np.testing.assert_allclose(world1, ours.point_b[mine], atol=1e-5)
    np.testing.assert_allclose(got["normal"][order], -ours.normal[mine], atol=1e-6)
    # newton's separation is minus warp_ccd's depth (margins 0 here)
    sep = np.einsum("ij,ij->i", got["normal"][order], world1 - world0)
    np.testing.assert_allclose(sep, -ours.depth[mine], atol=1e-5)
    assert (got["margin0"] == 0).all() and (got["offset0"] == 0).all() and (got["offset1"] == 0).all()
    assert bridge.dropped == 0


def test_normal_direction_is_newtons_on_a_box_on_a_box():
    # The same stack twice: newton's box primitives (its own contacts) and mesh cubes (warp_ccd's). The upper one
    # is shifted farther than the 0.01 they overlap: no corner inside the other cube is as near a side as the top
    # (where it is, warp_ccd's nearest point, and so the normal, is the side's).
    bodies = [((0.0, 0.0, 0.1), 0.0), ((0.03, -0.045, 0.29), 0.0)]
    newton_model = model_of([(p, y, "box") for p, y in bodies], ground=False)
    pipe = newton.CollisionPipeline(newton_model)
    theirs = pipe.contacts()
    pipe.collide(newton_model.state(), theirs)
    n_theirs = int(theirs.rigid_contact_count.numpy()[0])
    assert n_theirs >= 4
    t = rows(theirs, 0, n_theirs)
    assert (t["shape0"] == 0).all() and (t["shape1"] == 1).all()  # lower box first

    model = model_of([(p, y, "mesh") for p, y in bodies], ground=False)
    bridge = MeshContactBridge(model, gap=0.0)
    contacts = bridge.contacts()
    state = model.state()
    bridge.collide(state, contacts)
    n = int(contacts.rigid_contact_count.numpy()[0])
    assert n >= 4
    ours = rows(contacts, 0, n)
    assert (ours["shape0"] == 0).all() and (ours["shape1"] == 1).all()
    # The normals point the same way (newton's: +z, from the lower box toward the upper one) ...
    mean_theirs = t["normal"].mean(axis=0)
    np.testing.assert_allclose(mean_theirs, [0.0, 0.0, 1.0], atol=1e-5)
    deep = bridge.result.contacts.depth > 1e-3  # the contacts with a direction of their own
    assert deep.any() and (ours["normal"][deep] @ mean_theirs > 0.999).all()
    # ... and both separations say the same penetration, 0.01.
    body_q, shape_body = state.body_q.numpy(), model.shape_body.numpy()
    w0 = to_world(body_q, shape_body, ours["shape0"], ours["point0"])
    w1 = to_world(body_q, shape_body, ours["shape1"], ours["point1"])
    tw0 = to_world(body_q, shape_body, t["shape0"], t["point0"])
    tw1 = to_world(body_q, shape_body, t["shape1"], t["point1"])
    ours_sep = np.einsum("ij,ij->i", ours["normal"], w1 - w0)
    theirs_sep = np.einsum("ij,ij->i", t["normal"], tw1 - tw0)
    np.testing.assert_allclose(theirs_sep, -0.01, atol=1e-5)
    assert abs(ours_sep.min() - theirs_sep.min()) < 1e-4


def test_gap_decides_which_apart_pairs_are_written():
    # Two cubes 0.05 apart: newton's default gap (0.1 a shape) writes a speculative contact, a gap of 0.02 none.
    bodies = [((0.0, 0.0, 0.1), 0.0, "mesh"), ((0.0, 0.0, 0.35), 0.0, "mesh")]
    model = model_of(bodies, ground=False)
    for gap, expected in ((None, True), (0.02, False)):
        bridge = MeshContactBridge(model, gap=gap)
        assert bridge.margin == pytest.approx(0.2 if gap is None else 0.02)
        contacts = bridge.contacts()
        bridge.collide(model.state(), contacts)
        n = int(contacts.rigid_contact_count.numpy()[0])
        assert (n > 0) == expected
        if expected:
            r = rows(contacts, 0, n)
            assert np.allclose(r["normal"], [0.0, 0.0, 1.0], atol=1e-5)
            assert np.allclose(bridge.result.contacts.depth, -0.05, atol=1e-5)


def test_slop_is_a_negative_thickness():
    # The surfaces rest ``slop`` deep: each side's thickness is -slop / 2, its friction anchor shifted by it.
    model = model_of([((0.0, 0.0, 0.1), 0.0, "mesh"), ((0.03, -0.045, 0.29), 0.4, "mesh")], ground=False)
    bridge = MeshContactBridge(model, gap=0.0, slop=0.004)
    contacts = bridge.contacts()
    state = model.state()
    bridge.collide(state, contacts)
    n = int(contacts.rigid_contact_count.numpy()[0])
    r = rows(contacts, 0, n)
    assert n == bridge.result.contacts.count > 0
    np.testing.assert_allclose(r["margin0"], -0.002)
    np.testing.assert_allclose(r["margin1"], -0.002)
    q = state.body_q.numpy()
    rot1 = np.array(wp.quat_to_matrix(wp.quat(*q[1, 3:]))).reshape(3, 3)
    np.testing.assert_allclose(r["offset0"], -0.002 * r["normal"], atol=1e-7)  # body 0 unturned
    np.testing.assert_allclose(r["offset1"], 0.002 * r["normal"] @ rot1, atol=1e-7)  # in body 1's frame


def test_dropped_contacts_are_counted_and_warned():
    model = model_of([((0.0, 0.0, 0.1), 0.0, "mesh"), ((0.03, 0.02, 0.28), 0.4, "mesh")], ground=False)
    bridge = MeshContactBridge(model, gap=0.0, mesh_contact_max=2, rigid_contact_max=2)
    contacts = bridge.contacts()
    with pytest.warns(RuntimeWarning, match="mesh_contact_max"):
        bridge.collide(model.state(), contacts)
    assert bridge.dropped == bridge.result.contacts.count - 2


def test_no_mesh_pairs_is_newtons_pipeline_alone():
    model = model_of([((0.0, 0.0, 0.1), 0.0, "mesh"), ((0.5, 0.0, 0.1), 0.0, "box")])
    bridge = MeshContactBridge(model)
    assert bridge.scene is None and len(bridge.newton_pairs) == 3
    contacts = bridge.contacts()
    bridge.collide(model.state(), contacts)
    assert int(contacts.rigid_contact_count.numpy()[0]) > 0  # both on the plane, by newton


def energies(model, state):
    """Per body kinetic plus potential energy [J]."""
    q, qd = state.body_q.numpy(), state.body_qd.numpy()
    mass, inertia, com = model.body_mass.numpy(), model.body_inertia.numpy(), model.body_com.numpy()
    g = model.gravity.numpy().reshape(-1, 3)[0]
    out = []
    for i in range(len(q)):
        r = np.array(wp.quat_to_matrix(wp.quat(*q[i, 3:]))).reshape(3, 3)
        v, w = qd[i, :3], qd[i, 3:]
        x = q[i, :3] + r @ com[i]
        out.append(0.5 * mass[i] * v @ v + 0.5 * w @ (r @ inertia[i] @ r.T) @ w - mass[i] * g @ x)
    return np.array(out)


def simulate(model, steps: int, dt: float = 1.0 / 480.0):
    """``steps`` XPBD steps of ``model`` with the bridge's contacts: ``(bridge, last state, (steps, bodies) energies
    [J], (steps,) deepest contact [m] of each step)``."""
    bridge = MeshContactBridge(model)
    contacts = bridge.contacts()
    solver = newton.solvers.SolverXPBD(model, iterations=8)
    s0, s1, control = model.state(), model.state(), model.control()
    energy, depth = [], []
    for _ in range(steps):
        s0.clear_forces()
        bridge.collide(s0, contacts)
        c = bridge.result.contacts
        depth.append(c.depth.max() if c.count else 0.0)
        solver.step(s0, s1, control, contacts, dt)
        s0, s1 = s1, s0
        energy.append(energies(model, s0))
    return bridge, s0, np.array(energy), np.array(depth)


def test_stack_comes_to_rest_without_gaining_energy_or_sinking():
    # Three mesh cubes (0.2 a side): two stacked on the ground, the third dropped onto them, under XPBD at 480 Hz
    # for 1.25 s; all still by 0.6 s.
    bodies = [((0.0, 0.0, 0.1), 0.0, "mesh"), ((0.03, 0.02, 0.302), 0.3, "mesh"), ((-0.02, 0.0, 0.58), 0.6, "mesh")]
    model = model_of(bodies)
    bridge, state, energy, depth = simulate(model, 600)
    q = state.body_q.numpy()
    np.testing.assert_allclose(q[:, 2], [0.1, 0.3, 0.5], atol=2e-3)  # stacked, none fallen off
    assert np.abs(q[:, :2] - [b[0][:2] for b in bodies]).max() < 0.05  # nor slid far
    assert bridge.dropped == 0
    rest = 288  # 0.6 s
    tolerance = model.body_mass.numpy() * 9.81 * 0.002  # the energy of a 2 mm rise (1% of a cube's side)
    gained = (energy[rest:] - energy[rest]).max(axis=0)
    assert (gained <= tolerance).all(), (gained, tolerance)
    assert depth[rest:].max() < 0.01 * 0.2, depth[rest:].max()  # 1% of the smallest body's size


def ring_mesh():
    """A ring (torus: radii 0.3 and 0.08, 256 triangles) as a ``newton.Mesh``, outward triangles."""
    u = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)[:, None]
    w = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)[None, :]
    r = 0.3 + 0.08 * np.cos(w)
    v = np.stack([r * np.cos(u), r * np.sin(u), 0.08 * np.sin(w) + 0.0 * u], axis=2).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(16), np.arange(8), indexing="ij")
    a, b, c, d = i * 8 + j, (i + 1) % 16 * 8 + j, (i + 1) % 16 * 8 + (j + 1) % 8, i * 8 + (j + 1) % 8
    t = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return newton.Mesh(v.astype(np.float32), t.astype(np.int32).reshape(-1))


@pytest.mark.slow
def test_ring_on_a_ring_settles_without_gaining_energy():
    # Non-convex: a ring lying across another on the ground (XPBD, 480 Hz, 0.75 s): about a minute on a CPU.
    b = newton.ModelBuilder()
    b.add_ground_plane()
    ring = ring_mesh()
    for k, z in enumerate((0.08, 0.245)):
        body = b.add_body(xform=wp.transform(wp.vec3(0.1 * k, 0.0, z), quat_z(0.3 * k)))
        b.add_shape_mesh(body, mesh=ring)
    model = b.finalize(device=DEFAULT_DEVICE)
    _, state, energy, depth = simulate(model, 360)
    z = state.body_q.numpy()[:, 2]
    assert z[0] == pytest.approx(0.08, abs=2e-3) and 0.2 < z[1] < 0.245  # the upper ring still on the lower one
    rest = 120
    tolerance = model.body_mass.numpy() * 9.81 * 0.0016  # a 1.6 mm rise (1% of the ring's thickness)
    assert ((energy[rest:] - energy[rest]).max(axis=0) <= tolerance).all()
    assert depth[rest:].max() < 0.01 * 0.16
