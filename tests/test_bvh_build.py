"""Tree builds by kernels: the same trees as the numpy reference, every layout array, on every
device; sizes from the counts alone; rebuilds from moved vertices; vectorised mesh validation."""

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.scene.shapes import validate_mesh, validate_meshes
from warp_ccd._src.trees.build import CUT_DEPTH_MAX, CUT_TRIANGLES, TreeBuild, TreeSizes
from warp_ccd._src.trees.reference import build_tree


def soup(rng, m: int, ties: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``m`` random triangles (rounded coordinates give equal centroid keys when ``ties``)."""
    v = rng.normal(size=(3 * m, 3)) * rng.uniform(0.1, 10)
    if ties:
        v = np.round(v)
    return v, np.arange(3 * m).reshape(-1, 3)


def built(meshes, device, **options) -> TreeBuild:
    vs = [np.asarray(v, np.float32) for v, _ in meshes]
    vstart = np.concatenate([[0], np.cumsum([len(v) for v in vs])]).astype(np.int32)
    tstart = np.concatenate([[0], np.cumsum([len(t) for _, t in meshes])])
    tri = wp.array(np.concatenate([t for _, t in meshes]).astype(np.int32), dtype=wp.vec3i, device=device)
    b = TreeBuild(tri, tstart, device=device, **options)
    b.layout()
    b.order(wp.array(np.concatenate(vs), dtype=wp.vec3, device=device), wp.array(vstart, dtype=wp.int32,
                                                                                device=device))
    return b


def assert_same_trees(b: TreeBuild, meshes, leaf_size: int, cut_depth: int) -> None:
    leaf_node, inner_node, cut_node = b.leaf_node.numpy(), b.inner_node.numpy(), b.cut_node.numpy()
    for s, (v, t) in enumerate(meshes):
        want = build_tree(v, t, leaf_size)
        got = b.shape_tree(s)
        for name in ("node_child", "node_parent", "node_triangle", "tri_order", "level_start", "leaf_node",
                     "node_leaf", "inner_node", "node_depth"):
            assert np.array_equal(getattr(got, name), getattr(want, name)), (s, len(t), name)
        # The concatenated device lists hold the same, at the shape's offsets.
        layout = b.shape_layout[s]
        assert np.array_equal(leaf_node[b.layout_leaf_start[layout]:b.layout_leaf_start[layout + 1]], want.leaf_node)
        assert np.array_equal(inner_node[b.layout_inner_start[layout]:b.layout_inner_start[layout + 1]],
                              want.inner_node)
        for deep in (0, 1):
            cut = cut_node[b.layout_cut_start[2 * layout + deep]:b.layout_cut_start[2 * layout + deep + 1]]
            depth = max(cut_depth, min(int(np.ceil(np.log2(max(len(t) / CUT_TRIANGLES, 1)))), CUT_DEPTH_MAX))
            assert b.layout_cut_depth[layout] == depth
            assert np.array_equal(cut, want.cut(depth + deep)), (s, deep)


@pytest.fixture(params=["thread", "block"])
def finish(request):
    """How the build finishes its small subtrees: one thread each, or one thread block each (on the
    CPU with Warp's CPU blocks on, so that a block has its lanes)."""
    saved = wp.config.enable_cpu_blocks
    wp.config.enable_cpu_blocks = request.param == "block" or saved
    yield request.param
    wp.config.enable_cpu_blocks = saved


@pytest.mark.parametrize("leaf_size", [1, 2, 3, 7])
@pytest.mark.parametrize("small, presort", [(None, None), (4, None), (16, None), (None, False), (None, True)])
def test_kernels_build_the_reference_trees(device, leaf_size, small, presort, finish):
    """Sizes from 1 to 400 triangles (all the layouts of small counts, ties among centroids), split
    level by level, then by one thread or one block a subtree, presorted or sorted by insertion: bit
    for bit the trees of the numpy reference."""
    rng = np.random.default_rng(leaf_size)
    counts = [1, 2, 3, 4, 5, 6, 7, 8, 9, 15, 16, 17, 31, 33, 63, 64, 65, 100, 255, 256, 257, 400]
    if presort is False:
        counts = [c for c in counts if c <= 100]  # insertion sorts of unsorted lists: keep them short
    meshes = [soup(rng, m, ties=k % 3 == 1) for k, m in enumerate(counts + counts[::3])]  # some counts twice
    for cut_depth in (0, 3):
        b = built(meshes, device, leaf_size=leaf_size, cut_depth=cut_depth, small=small, presort=presort,
                  finish=finish)
        assert b.finish == finish
        assert_same_trees(b, meshes, leaf_size, cut_depth)


def test_block_dims_follow_the_subtrees(device, finish):
    """A block has as many threads as the largest subtree needs (a warp at least); a scene of small
    shapes finished by blocks needs no lists, no sorts, no level kernels."""
    rng = np.random.default_rng(9)
    if finish != "block":
        pytest.skip("blocks only")
    for counts, dim, levels in (([5, 20], 32, 0), ([33, 2], 64, 0), ([200, 80], 256, 0), ([300, 20], 256, 1),
                                ([5000], 256, 5)):
        meshes = [soup(rng, m) for m in counts]
        b = built(meshes, device, finish=finish)
        assert (b.block_dim, b.num_global_levels, b.presort) == (dim, levels, levels > 0)
        assert_same_trees(b, meshes, 1, 3)
    with pytest.raises(ValueError, match="at most 256"):
        built([soup(rng, 10)], device, finish=finish, small=512)
    with pytest.raises(ValueError, match="at most 256"):
        built([soup(rng, 10)], device, finish=finish, leaf_size=129)


def test_no_shapes(device, finish):
    """A scene without shapes builds nothing, presorted or not."""
    for presort in (None, True):
        b = TreeBuild(wp.empty(0, dtype=wp.vec3i, device=device), np.zeros(1, np.int64), presort=presort,
                      finish=finish, device=device)
        b.layout()
        b.order(wp.empty(0, dtype=wp.vec3, device=device), wp.zeros(1, dtype=wp.int32, device=device))
        assert b.tri_order.shape == (0,)


def test_default_finish(device):
    """Blocks by default on CUDA, unless leaves or subtrees are too big for one; one thread on the CPU."""
    meshes = [soup(np.random.default_rng(2), 600)]
    block = "block" if wp.get_device(device).is_cuda else "thread"
    for options, want in (({}, block), ({"leaf_size": 128}, block), ({"leaf_size": 129}, "thread"),
                          ({"small": 300}, "thread")):
        b = built(meshes, device, **options)
        assert b.finish == want, options
        assert_same_trees(b, meshes, b.leaf_size, 3)


def test_shapes_of_one_count_share_a_layout(device):
    rng = np.random.default_rng(4)
    meshes = [soup(rng, m) for m in (80, 80, 7, 80, 7)]
    b = built(meshes, device)
    assert b.shape_layout.tolist() == [1, 1, 0, 1, 0] and len(b.layout_node_start) == 3
    assert_same_trees(b, meshes, 1, 3)


def test_single_big_shape_levels(device, finish):
    """One shape of 5,000 triangles split over many levels by the level-by-level kernels."""
    rng = np.random.default_rng(3)
    meshes = [soup(rng, 5000)]
    b = built(meshes, device, small=8, finish=finish)
    assert b.num_global_levels == 10
    assert_same_trees(b, meshes, 1, 3)


def test_identical_and_degenerate_triangles(device, finish):
    """All centroids equal (17 copies of one triangle, 300 copies), points and slivers: the order
    falls back on triangle ids, as numpy's stable sort does."""
    v = np.float32([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 2, 2], [-0.0, -0.0, -0.0]])
    same = (v, np.zeros((17, 3), np.int32) + [0, 1, 2])
    many = (v, np.zeros((300, 3), np.int32) + [0, 1, 2])
    points = (v, np.array([[3, 3, 3], [4, 4, 4], [0, 0, 0], [4, 4, 4]] * 5, np.int32))
    for small in (4, None):
        b = built([same, points, many], device, small=small, finish=finish)
        assert_same_trees(b, [same, points, many], 1, 3)


def test_block_finish_needs_cpu_blocks(device):
    """On the CPU a block is one lane unless Warp's CPU blocks are on: the build says so, when made and
    when its order is built after they were turned off."""
    if wp.get_device(device).is_cuda:
        pytest.skip("the CPU's blocks")
    saved = wp.config.enable_cpu_blocks
    wp.config.enable_cpu_blocks = True
    b = built([soup(np.random.default_rng(0), 10)], device, finish="block")
    wp.config.enable_cpu_blocks = False
    try:
        with pytest.raises(ValueError, match="turned off"):
            b.order(wp.zeros(30, dtype=wp.vec3, device=device), wp.array([0, 30], dtype=wp.int32, device=device))
        with pytest.raises(ValueError, match="enable_cpu_blocks"):
            built([soup(np.random.default_rng(0), 10)], device, finish="block")
        with pytest.raises(ValueError, match="finish must be"):
            built([soup(np.random.default_rng(0), 10)], device, finish="warp")
    finally:
        wp.config.enable_cpu_blocks = saved


def test_tree_sizes_match_the_reference():
    for leaf_size in (1, 2, 5):
        m = np.arange(1, 300)
        sizes = TreeSizes(m, leaf_size)
        for k, count in enumerate(m):
            tree = build_tree(*soup(np.random.default_rng(0), int(count)), leaf_size)
            assert sizes.num_nodes[k] == tree.num_nodes and sizes.num_leaves[k] == len(tree.leaf_node)
            assert sizes.num_levels[k] == tree.depth
            for d in range(tree.depth):
                first, count_d = sizes.level(d)
                assert first[k] == tree.level_start[d]
                assert count_d[k] == tree.level_start[d + 1] - tree.level_start[d]


def test_scene_trees_are_the_reference(device):
    """SceneBVH builds every shape of a scene (float64 too) with the kernels: the reference's trees."""
    shapes = [wc.scene.shape(s) for s in ("tetrahedron", "cube", "icosahedron")] + [wc.scene.icosphere(3)]
    for precision in ("float32", "float64"):
        scene = wc.Scene(shapes, [0, 1, 2, 3, 3], device=device, precision=precision)
        bvh = wc.stages.SceneBVH(scene)
        for s, (v, t) in enumerate(shapes):
            want, got = build_tree(v, t), bvh.shape_tree(s)
            assert np.array_equal(got.tri_order, want.tri_order) and np.array_equal(got.node_child, want.node_child)


def test_rebuild_sorts_the_moved_vertices(device):
    """After a deforming mesh moves, rebuild gives the tree of its new vertices (the layout stays) and
    the frame's pairs stay those of the reference mid phase."""
    v, t = wc.scene.icosphere(3)
    rng = np.random.default_rng(5)
    t = t[rng.permutation(len(t))]
    others = [(v * 0.5 + np.float32([1.2, 0, 0]), t), (v * 0.5 + np.float32([-1.0, 0.5, 0]), t)]
    scene = wc.Scene.from_meshes([(v, t), *others], deforming=True, device=device)
    pipe = wc.CollisionPipeline(scene)
    moved = np.stack([v[:, 0] * 2.5, v[:, 1], v[:, 2] * 0.4], axis=1).astype(np.float32)
    scene.set_world_vertices(np.concatenate([moved, *(m[0] for m in others)]))
    before = pipe.detect().triangle_pairs
    layout = pipe.boxes.build.node_child.numpy().copy()
    pipe.boxes.rebuild(scene)
    assert np.array_equal(pipe.boxes.shape_tree(0).tri_order, build_tree(moved, t, pipe.boxes.leaf_size).tri_order)
    assert np.array_equal(pipe.boxes.build.node_child.numpy(), layout)
    after = pipe.detect().triangle_pairs
    ref = wc.CollisionPipeline(scene, mid_phase="all_pairs").detect().triangle_pairs
    assert len(ref) > 0 and np.array_equal(after, ref) and np.array_equal(before, ref)


def test_rebuild_every(device):
    """``rebuild_every=k`` rebuilds before every k-th frame; results equal a pipeline that never does."""
    v, t = wc.scene.icosphere(2)
    scene = wc.Scene.from_meshes([(v, t), (v + np.float32([1.5, 0, 0]), t)], deforming=True, device=device)
    pipe = wc.CollisionPipeline(scene, rebuild_every=2)
    plain = wc.CollisionPipeline(scene)
    for k in range(4):
        scene.set_world_vertices(np.concatenate([v * (1 + 0.2 * k), v + np.float32([1.5, 0, 0])]))
        assert np.array_equal(pipe.detect().triangle_pairs, plain.detect().triangle_pairs)
    assert pipe.rebuilds == 2
    with pytest.raises(ValueError, match="rebuild_every"):
        wc.CollisionPipeline(scene, rebuild_every=-1)


# ------------------------------------------------------------------------------------ validation
BAD_MESHES = [
    (np.zeros((2, 3)), [[0, 1, 1]], "at least 3 vertices"),
    ([[0, 0, 0], [1, 0, np.nan], [0, 1, 0]], [[0, 1, 2]], r"vertex 1 is not finite"),
    ([[0, 0, 0], [1e39, 0, 0], [0, 1, 0]], [[0, 1, 2]], "overflow float32"),
    (np.eye(3), np.zeros((0, 3), np.int64), "no triangles"),
    (np.eye(3), [[0, 1, 3]], r"triangle 0 has vertex index out of range \[0, 3\)"),
    (np.eye(3), [[0, 1, 2], [0, -1, 2]], r"triangle 1 has vertex index out of range"),
    (np.eye(3), [[0.0, 1.0, 2.0]], "integer vertex indices"),
    (np.eye(3)[:, :2], [[0, 1, 2]], r"shape \(n, 3\)"),
    ([[0, 0, 0], [1, 0], [0, 1, 0]], [[0, 1, 2]], "not an array of numbers"),
    (np.array([["a", "b", "c"]] * 3), [[0, 1, 2]], "real numbers"),
]


@pytest.mark.parametrize("vertices, triangles, match", BAD_MESHES)
def test_validate_meshes_names_the_bad_mesh(vertices, triangles, match):
    """The vectorised checks name the same mesh and problem as the per-mesh ones."""
    good = wc.scene.shape("cube")
    meshes = [good, good, (vertices, triangles), good]
    with pytest.raises(ValueError, match=match) as vectorised:
        validate_meshes(meshes, labels=[3, 5, 8, 9])
    assert str(vectorised.value).startswith("mesh 8:")
    with pytest.raises(ValueError) as single:
        validate_mesh(vertices, triangles, name="mesh 8")
    assert str(vectorised.value) == str(single.value)
    with pytest.raises(ValueError, match="mesh 2:"):
        wc.collide(meshes)


def test_validate_meshes_packs():
    rng = np.random.default_rng(0)
    meshes = [soup(rng, m) for m in (1, 5, 3)] + [wc.scene.shape("cube")]
    packed = validate_meshes(meshes, dtype=np.float64)
    assert len(packed) == 4 and packed.vertices.dtype == np.float64 and packed.triangles.dtype == np.int32
    for k, (v, t) in enumerate(meshes):
        pv, pt = packed.mesh(k)
        assert np.array_equal(pv, np.asarray(v, np.float64)) and np.array_equal(pt, t)
    assert len(validate_meshes([])) == 0


def test_from_meshes_shares_only_the_same_arrays():
    a, b = wc.scene.shape("cube"), wc.scene.shape("tetrahedron")
    copy = (a[0].copy(), a[1])
    scene = wc.Scene.from_meshes([b, a, b, copy, a])
    assert scene.num_shapes == 3 and scene.object_shape_np.tolist() == [0, 1, 0, 2, 1]
    assert np.array_equal(scene.shape_meshes[2][0], copy[0])


def test_one_shot_runs_its_frame_once(device, monkeypatch):
    """collide() sizes its buffers from the scene: one run of the frame for 1,000 polyhedra, for
    big meshes in contact and for objects whose boxes overlap many others'."""
    runs = []
    detect = wc.CollisionPipeline.detect

    def counted(self, *args, **kwargs):
        result = detect(self, *args, **kwargs)
        runs.append(result.runs)
        return result

    monkeypatch.setattr(wc.CollisionPipeline, "detect", counted)
    rng = np.random.default_rng(2)
    scene = wc.Scene.random(1000, seed=2, device=device)
    scene.advance(0.3)
    assert len(wc.collide(scene.world_meshes(), device=device).object_pairs) > 0
    v, t = wc.scene.icosphere(4)
    meshes = [(v * rng.uniform(1, 2) + rng.uniform(-2, 2, 3).astype(np.float32), t) for _ in range(6)]
    assert len(wc.collide(meshes, device=device).object_pairs) > 0
    # Unit spheres on the even sites of a grid of spacing 1.9: each one's box overlaps those of its
    # twelve nearest neighbours (1.9 apart on two axes), far more box pairs than objects, but no two
    # spheres meet (2.69 apart).
    v, t = wc.scene.icosphere(1)
    sites = [(i, j, k) for i in range(5) for j in range(5) for k in range(5) if (i + j + k) % 2 == 0]
    meshes = [(v + 1.9 * np.array(c, np.float32), t) for c in sites]
    assert len(wc.collide(meshes, device=device).object_pairs) == 0
    assert runs == [1, 1, 1]


def test_validate_meshes_takes_any_iterable_pair():
    """A mesh is any pair that unpacks: a list, a tuple, or an object that only iterates."""
    class Pair:
        def __init__(self, v, t):
            self.v, self.t = v, t

        def __iter__(self):
            return iter((self.v, self.t))

    v, t = wc.scene.shape("tetrahedron")
    packed = validate_meshes([Pair(v, t), [v, t]])
    assert len(packed) == 2 and np.array_equal(packed.triangles[4:], t)
    with pytest.raises(ValueError, match="mesh 1"):
        validate_meshes([(v, t), Pair(v, t[:, :2])])


def test_validate_meshes_mixed_arrays():
    """Mixed kinds of arrays: bool ones are refused as validate_mesh refuses them, int64 beside
    uint64 indices are fine, pairs may be any tuple type, and the first bad mesh is named."""
    from collections import namedtuple

    cube = wc.scene.shape("cube")
    with pytest.raises(ValueError, match="mesh 1: triangles must be integer"):
        validate_meshes([cube, (np.eye(3), np.array([[True, False, True]]))])
    with pytest.raises(ValueError, match="mesh 1: vertices must be real numbers"):
        validate_meshes([cube, (np.eye(3, dtype=bool), [[0, 1, 2]])])
    packed = validate_meshes([(cube[0], cube[1].astype(np.int64)), (cube[0], cube[1].astype(np.uint64))])
    assert np.array_equal(packed.triangles, np.concatenate([cube[1], cube[1]]))
    with pytest.raises(ValueError, match=r"^mesh 0: triangle 0 has vertex index out of range"):
        validate_meshes([(np.eye(3), [[0, 1, 5]]), ([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])])
    with pytest.raises(ValueError, match=r"^mesh 0: vertices overflow"):
        validate_meshes([([[1e39, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]),
                         ([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])])
    pair = namedtuple("Pair", "vertices triangles")
    assert wc.Scene.from_meshes([pair(*cube), pair(*wc.scene.shape("tetrahedron"))]).num_shapes == 2
    assert wc.Scene((m for m in [cube, cube]), [0, 1]).num_shapes == 2
