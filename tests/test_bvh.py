"""Trees: build invariants, refit bounds, traversal completeness, scenes with big meshes."""

import numpy as np
import pytest

import warp_ccd as wc
from warp_ccd._src.trees.reference import build_tree, centroid_keys

from oracles import triangle_pairs_fcl, triangle_pairs_warp64


def tree_invariants(tree, vertices, triangles, leaf_size):
    m = len(triangles)
    assert sorted(tree.tri_order.tolist()) == list(range(m))
    in_leaves = []
    centroid = centroid_keys(vertices, triangles)
    for node in range(tree.num_nodes):
        start, count = tree.node_triangle[node]
        left, right = tree.node_child[node]
        if left < 0:
            assert 1 <= count <= leaf_size
            in_leaves += tree.tri_order[start : start + count].tolist()
            continue
        assert tree.node_parent[left] == node and tree.node_parent[right] == node
        (s0, c0), (s1, c1) = tree.node_triangle[left], tree.node_triangle[right]
        assert s0 == start and s1 == start + c0 and c0 + c1 == count
        assert c0 == count // 2  # median split: balanced
        a = centroid[tree.tri_order[s0 : s0 + c0]]
        b = centroid[tree.tri_order[s1 : s1 + c1]]
        assert any(a[:, k].max() <= b[:, k].min() for k in range(3))  # separated along some axis
    assert sorted(in_leaves) == list(range(m))  # each triangle in exactly one leaf
    # breadth-first levels: children on the next level
    for level in range(tree.depth - 1):
        for node in range(tree.level_start[level], tree.level_start[level + 1]):
            left, right = tree.node_child[node]
            if left >= 0:
                assert tree.level_start[level + 1] <= left < right < tree.level_start[level + 2]
    assert tree.depth <= int(np.ceil(np.log2(max(1, m / leaf_size)))) + 1
    # every cut's subtrees partition the leaves, at most 2**depth of them
    for depth in range(tree.depth + 1):
        cut = tree.cut(depth)
        assert 1 <= len(cut) <= 2**depth
        under = np.concatenate([tree.leaf_node[f : f + c] for f, c in tree.node_leaf[cut]])
        assert sorted(under.tolist()) == sorted(tree.leaf_node.tolist())
    assert np.array_equal(tree.cut(0), [0])
    assert sorted(tree.cut(tree.depth).tolist()) == sorted(tree.leaf_node.tolist())


@pytest.mark.parametrize("leaf_size", [1, 3])
@pytest.mark.parametrize("mesh", ["tetrahedron", "triangle", "dodecahedron", "icosphere3", "random_soup"])
def test_build_invariants(mesh, leaf_size):
    if mesh == "random_soup":
        rng = np.random.default_rng(0)
        v = rng.normal(size=(999, 3)).astype(np.float32)
        t = np.arange(999).reshape(-1, 3)
    else:
        v, t = wc.scene.shape(mesh)
    tree_invariants(build_tree(v, t, leaf_size), v, t, leaf_size)


def test_build_identical_triangles():
    v = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    t = np.zeros((17, 3), np.int32) + [0, 1, 2]
    tree_invariants(build_tree(v, t, 1), v, t, 1)


def refit_contains(scene, bvh):
    """Every node box contains its children's boxes and its triangles, in its object's box space
    (a rigid object's shape's vertices, a deforming object's world vertices); every object box
    contains the object's world vertices."""
    wv = scene.world_vertex.numpy()
    sv = scene.shape_vertex.numpy()
    lo = bvh.tree.node_lower.numpy()
    hi = bvh.tree.node_upper.numpy()
    start = bvh.tree.object_node_start.numpy()
    deforming = scene.object_deforming_np
    for i in range(scene.num_objects):
        s = scene.object_shape_np[i]
        tr = bvh.shape_tree(s)
        base = start[i]
        tri = scene.shape_meshes[s][1]
        vs = wv[scene.object_vertex_start_np[i]:] if deforming[i] else sv[scene.shape_vertex_start_np[s]:]
        for node in range(tr.num_nodes):
            left, right = tr.node_child[node]
            if left >= 0:
                for c in (left, right):
                    assert (lo[base + node] <= lo[base + c]).all() and (hi[base + c] <= hi[base + node]).all()
            else:
                s0, c0 = tr.node_triangle[node]
                p = vs[tri[tr.tri_order[s0 : s0 + c0]].ravel()]
                assert (lo[base + node] <= p.min(0)).all() and (p.max(0) <= hi[base + node]).all()
        mine = wv[scene.object_vertex_start_np[i]:scene.object_vertex_start_np[i + 1]]
        assert (bvh.lower.numpy()[i] <= mine.min(0)).all() and (mine.max(0) <= bvh.upper.numpy()[i]).all()
    # a deforming object's root is its object box
    own = np.nonzero(deforming)[0]
    assert np.array_equal(lo[start[own]], bvh.lower.numpy()[own])


def mixed_scene(device, n=40, seed=0):
    return wc.Scene.random(
        n, seed=seed, shapes=("cube", "icosahedron", "icosphere3", "icosphere4", "tetrahedron"), density=0.08,
        device=device,
    )


def test_refit_bounds_contain(device):
    scene = mixed_scene(device, n=12)
    pipe = wc.CollisionPipeline(scene)
    for _ in range(2):
        scene.advance(0.3)
        pipe.detect()
        refit_contains(scene, pipe.boxes)


def test_candidates_contain_exact_pairs(device):
    scene = mixed_scene(device, n=40, seed=1)
    scene.advance(0.2)
    pipe = wc.CollisionPipeline(scene)
    res = pipe.detect()
    cand = pipe.mid.candidates.numpy(res.num_candidates)
    exact = triangle_pairs_warp64(scene.world_meshes(), scale=20.0, device=device)
    assert len(exact) > 0
    assert set(map(tuple, exact)) <= set(map(tuple, cand))
    ref = wc.CollisionPipeline(scene, mid_phase="all_pairs").detect()
    assert res.num_candidates < ref.num_candidates / 10  # the trees prune


@pytest.mark.parametrize("seed", [2, 3])
def test_mixed_scene_matches_oracles(device, seed):
    scene = mixed_scene(device, n=60, seed=seed)
    pipe = wc.CollisionPipeline(scene)
    for _ in range(2):
        scene.advance(0.25)
        res = pipe.detect()
        meshes = scene.world_meshes()
        want = triangle_pairs_fcl(meshes)
        assert len(want) > 0
        assert np.array_equal(res.triangle_pairs, want)
        assert np.array_equal(res.triangle_pairs, triangle_pairs_warp64(meshes, scale=20.0, device=device))


@pytest.mark.parametrize(
    "options", [dict(), dict(leaf_size=2), dict(leaf_size=4), dict(candidate_capacity=1), dict(pair_capacity=1),
                dict(cut_depth=0), dict(cut_depth=1), dict(cut_depth=6), dict(cut_depth=2, leaf_size=3),
                dict(separating_axes=3), dict(object_bounds="tree"), dict(object_bounds="vertices")],
    ids=["leaf1", "leaf2", "leaf4", "capacity1", "pairs1", "cut0", "cut1", "cut6", "cut2leaf3", "axes3",
         "bounds_tree", "bounds_vertices"])
def test_options_same_result(device, options):
    """The traversal finds exactly the candidates that survive the reference's all triangle pairs."""
    scene = mixed_scene(device, n=30, seed=4)
    scene.advance(0.4)
    ref = wc.CollisionPipeline(scene, mid_phase="all_pairs").detect()
    got = wc.CollisionPipeline(scene, **options).detect()
    assert ref.num_triangle_pairs > 0
    assert np.array_equal(got.triangle_pairs, ref.triangle_pairs)


@pytest.mark.parametrize("num_blocks", [1, 2, 7, 64, 100000])
def test_traversal_rounds_split_anywhere(device, num_blocks):
    """However many threads share the work items, rounds that start or end inside a pair's block
    of items give the same candidates (the CPU's default is one thread, CUDA's many)."""
    scene = mixed_scene(device, n=30, seed=4)
    scene.advance(0.4)
    ref = wc.CollisionPipeline(scene, mid_phase="all_pairs").detect()
    pipe = wc.CollisionPipeline(scene)
    pipe.mid.num_blocks = num_blocks
    assert pipe.mid.walk.num_blocks == num_blocks  # the tree walk's grid, not only the whole-object pairs'
    got = pipe.detect()
    assert np.array_equal(got.triangle_pairs, ref.triangle_pairs)
    assert got.num_candidates == wc.CollisionPipeline(scene).detect().num_candidates


def test_deforming_twisting_sphere(device):
    """A pulsating, twisting icosphere among rigid ones: refit alone keeps results exact."""
    v, t = wc.scene.icosphere(3)
    others = [(v * 0.6 + np.float32(c), t) for c in ([2.2, 0, 0], [0, -2.0, 0.3], [-1.5, 1.5, 0])]
    scene = wc.Scene.from_meshes([(v, t), *others], deforming=True, device=device)
    pipe = wc.CollisionPipeline(scene)
    rest = np.concatenate([m[0] for m in others])
    hits = 0
    for k in range(6):
        phase = 0.7 * k
        r = 1.0 + 0.5 * np.sin(phase)
        ang = 1.5 * v[:, 2:3] * np.sin(phase)  # twist about z, growing with height
        x = v[:, 0:1] * np.cos(ang) - v[:, 1:2] * np.sin(ang)
        y = v[:, 0:1] * np.sin(ang) + v[:, 1:2] * np.cos(ang)
        deformed = np.concatenate([x, y, v[:, 2:3]], axis=1) * r
        scene.set_world_vertices(np.concatenate([deformed, rest]))
        res = pipe.detect()
        want = triangle_pairs_warp64(scene.world_meshes(), scale=10.0, device=device)
        assert np.array_equal(res.triangle_pairs, want)
        hits += len(want) > 0
    assert hits >= 2


def deforming_copy(scene, mask=True):
    """The scene's objects where they are now, one shape each, as a scene whose objects in ``mask``
    deform (all of them by default)."""
    return wc.Scene(scene.world_meshes(), np.arange(scene.num_objects), deforming=mask, device=scene.device)


def test_refit_paths_agree(device):
    """Leaves then inner nodes (small trees) and level by level give the same boxes."""
    from warp_ccd._src.trees.bvh import SceneBVH

    rigid = mixed_scene(device, n=25, seed=6)
    rigid.advance(0.3)
    scene = deforming_copy(rigid)
    per_level = SceneBVH(scene, margin_rel=1e-5, object_refit_max_nodes=0)
    per_instance = SceneBVH(scene, margin_rel=1e-5, object_refit_max_nodes=10**9)
    mixed = SceneBVH(scene, margin_rel=1e-5)
    assert per_level.refit_plan.small_object.shape[0] == 0
    assert per_instance.refit_plan.small_object.shape[0] == 25
    assert 0 < mixed.refit_plan.small_object.shape[0] < 25
    for bvh in (per_level, per_instance, mixed):
        bvh.refit(scene)
    ref = per_level.tree.node_lower.numpy(), per_level.tree.node_upper.numpy(), per_level.lower.numpy()
    for bvh in (per_instance, mixed):
        assert np.array_equal(bvh.tree.node_lower.numpy(), ref[0])
        assert np.array_equal(bvh.tree.node_upper.numpy(), ref[1])
        assert np.array_equal(bvh.lower.numpy(), ref[2])
    refit_contains(scene, mixed)


def test_rigid_trees_are_shared_and_never_refit(device):
    """Rigid objects keep one tree per shape, in shape space: its boxes do not change as they move."""
    scene = mixed_scene(device, n=30, seed=7)
    pipe = wc.CollisionPipeline(scene)
    shapes = np.unique(scene.object_shape_np)
    assert pipe.boxes.num_node_slots == sum(pipe.boxes.shape_tree(s).num_nodes for s in shapes)
    before = pipe.boxes.tree.node_lower.numpy().copy(), pipe.boxes.tree.node_upper.numpy().copy()
    for _ in range(2):
        scene.advance(0.3)
        pipe.detect()
        refit_contains(scene, pipe.boxes)
    assert np.array_equal(pipe.boxes.tree.node_lower.numpy(), before[0])
    assert np.array_equal(pipe.boxes.tree.node_upper.numpy(), before[1])


@pytest.mark.parametrize("object_bounds", ["auto", "tree", "vertices"])
def test_object_bounds_hold_their_objects(device, object_bounds):
    """Every way of finding a rigid object's box gives one that holds its world vertices; the
    vertices' way is the plain box of the vertices (padded by the tolerance)."""
    scene = mixed_scene(device, n=20, seed=8)
    scene.advance(0.2)
    pipe = wc.CollisionPipeline(scene, object_bounds=object_bounds)
    pipe.detect()
    refit_contains(scene, pipe.boxes)
    if object_bounds == "vertices":
        ref = wc.CollisionPipeline(scene, mid_phase="all_pairs")
        ref.detect()
        assert np.array_equal(pipe.boxes.lower.numpy(), ref.boxes.lower.numpy())
        assert np.array_equal(pipe.boxes.upper.numpy(), ref.boxes.upper.numpy())


def test_object_bounds_by_vertex_count(device):
    """An integer ``object_bounds`` takes the vertices' box of objects of up to that many vertices
    and the tree's of bigger ones: here the polyhedra (at most 12 vertices) as with ``"vertices"``
    and the icospheres (642 and 2,562) as with ``"tree"``; every choice gives the same pairs."""
    scene = mixed_scene(device, n=30, seed=3)
    scene.advance(0.2)
    boxes, pairs = {}, {}
    for bounds in ("vertices", "tree", 100, 0):
        pipe = wc.CollisionPipeline(scene, object_bounds=bounds)
        res = pipe.detect()
        boxes[bounds] = pipe.boxes.lower.numpy(), pipe.boxes.upper.numpy()
        pairs[bounds] = res.copy().triangle_pairs
    counts = np.diff(scene.object_vertex_start_np)
    small = counts <= 100
    assert small.any() and (~small).any()
    for k in range(2):
        assert np.array_equal(boxes[100][k][small], boxes["vertices"][k][small])
        assert np.array_equal(boxes[100][k][~small], boxes["tree"][k][~small])
        assert np.array_equal(boxes[0][k], boxes["tree"][k])
    for bounds in (100, 0, "tree"):
        assert np.array_equal(pairs[bounds], pairs["vertices"])


@pytest.mark.parametrize("value", ["box", -1, 2**31, 1.5, True, None])
def test_bad_object_bounds(value):
    with pytest.raises(ValueError, match="object_bounds"):
        wc.CollisionPipeline(wc.Scene.random(3), object_bounds=value)


def test_rigid_and_deforming_objects_share_one_traversal(device):
    """A scene of rigid objects and deforming ones (every other object): the traversal maps boxes
    between shape spaces and the world, and finds what the reference finds, frame after frame."""
    rigid = mixed_scene(device, n=30, seed=9)
    rigid.advance(0.5)
    mask = np.arange(30) % 2 == 1
    scene = deforming_copy(rigid, mask)
    pipe = wc.CollisionPipeline(scene)
    assert pipe.boxes.rigid_object.shape[0] == 15
    world = scene.world_vertex.numpy()
    start = scene.object_vertex_start_np
    moved = 0
    for k in range(3):
        v = world.copy()
        for i in np.nonzero(mask)[0]:  # the deforming ones swell and drift
            part = v[start[i]:start[i + 1]]
            c = part.mean(0)
            v[start[i]:start[i + 1]] = c + (part - c) * (1.0 + 0.15 * k) + np.float32([0.1 * k, 0, 0])
        scene.set_world_vertices(v)
        res = pipe.detect()
        ref = wc.CollisionPipeline(scene, mid_phase="all_pairs").detect()
        assert np.array_equal(res.triangle_pairs, ref.triangle_pairs)  # all triangle pairs, same exact test
        moved += ref.num_triangle_pairs > 0
    assert moved >= 2


def test_poses_whose_quaternions_are_not_unit(device):
    """Poses are accepted with quaternions up to 1e-3 from unit length; world vertices are then
    rotated and scaled by them as Warp's transform_point does, and the traversal maps boxes by
    that very map."""
    scene = mixed_scene(device, n=30, seed=10)
    scene.advance(0.4)
    poses = scene.object_pose.numpy().astype(np.float64)
    poses[:, 3:] *= 1.0 + 9e-4 * np.cos(np.arange(30))[:, None]
    moved = wc.Scene(scene.shapes, scene.object_shape_np, object_scale=scene.object_scale_np, poses=poses,
                     device=device)
    got = wc.CollisionPipeline(moved).detect()
    ref = wc.CollisionPipeline(moved, mid_phase="all_pairs").detect()
    assert ref.num_triangle_pairs > 0
    assert np.array_equal(got.triangle_pairs, ref.triangle_pairs)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_poses_far_from_the_origin(device, precision):
    """Rigid objects placed 3e4 from the origin: their world vertices carry the rounding of the
    pose, which the traversal's paddings bound; it finds what the reference (world boxes) finds."""
    scene = mixed_scene(device, n=30, seed=11)
    scene.advance(0.4)
    poses = scene.object_pose.numpy().astype(np.float64)
    poses[:, :3] += [3e4, -2e4, 1e4]
    moved = wc.Scene(scene.shapes, scene.object_shape_np, object_scale=scene.object_scale_np, poses=poses,
                     device=device, precision=precision)
    got = wc.CollisionPipeline(moved).detect()
    ref = wc.CollisionPipeline(moved, mid_phase="all_pairs").detect()
    assert ref.num_triangle_pairs > 0
    assert np.array_equal(got.triangle_pairs, ref.triangle_pairs)
