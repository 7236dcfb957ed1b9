"""Arrays from anywhere (:mod:`warp_ccd._src.runtime.arrays`, :mod:`warp_ccd._src.scene.inputs`): torch tensors (on the
CPU here), Warp arrays and bare DLPack / ``__cuda_array_interface__`` producers are read in place, give the
results numpy gives, and bad rows are named by the frame that reads them; on CUDA, a frame driven from
device arrays issues no memory copy."""

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.geometry.precision import FLOAT32_MAX, coordinate_limit, needed_precision
from warp_ccd._src.runtime.arrays import device_view, host_array, is_device_array
from warp_ccd.scene import icosphere, matrix_to_quat, quat_to_matrix, shape

torch = pytest.importorskip("torch", reason="torch (a test extra) is not installed")


class DLPackOnly:
    """A producer that speaks DLPack alone (as JAX's and CuPy's arrays do), over a Warp array's memory."""

    def __init__(self, a: wp.array):
        self._a = a

    def __dlpack__(self, **kwargs):
        return self._a.__dlpack__(**kwargs)

    def __dlpack_device__(self):
        return self._a.__dlpack_device__()


class CudaInterfaceOnly:
    """A producer with ``__cuda_array_interface__`` alone (as Numba's device arrays), over a Warp array."""

    def __init__(self, a: wp.array):
        self._a = a
        self.__cuda_array_interface__ = a.__cuda_array_interface__


def _scene(device, n=4, **kwargs):
    v, t = icosphere(1)
    return wc.Scene.from_meshes([(v, t)] * n, device=device, **kwargs)


def _poses(n, rng):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    p = rng.uniform(0, 1.5, (n, 3))
    return np.concatenate([p, q], axis=1)


def _on(t, device: str):
    """Torch tensor ``t`` (made on the host) on the torch device of Warp's ``device`` (skipped where this
    torch has no CUDA)."""
    if not wp.get_device(device).is_cuda:
        return t
    if not torch.cuda.is_available():
        pytest.skip("this torch has no CUDA")
    return t.to(f"cuda:{wp.get_device(device).ordinal}")


def test_torch_tensors_are_read_in_place(device):
    t = _on(torch.arange(21, dtype=torch.float32).reshape(3, 7), device)
    view = device_view(t, "poses", device)
    assert view.ptr == t.data_ptr() and view.shape == (3, 7)
    strided = _on(torch.zeros(3, 14), device)[:, ::2]
    view = device_view(strided, "poses", device)
    assert view.ptr == strided.data_ptr() and view.strides == (56, 8)
    assert is_device_array(t) and not is_device_array(np.zeros(3))
    assert np.array_equal(host_array(t, "x"), t.cpu().numpy())
    vec = wp.array(np.ones((5, 3), np.float32), dtype=wp.vec3, device=device)
    assert device_view(vec, "v", device).shape == (5, 3)
    assert device_view(np.zeros((2, 7), np.int32), "p", device).dtype == wp.float64  # converted, a copy
    assert device_view(np.zeros((2, 7), np.float32), "p", device).dtype == wp.float32  # uploaded as it is


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_poses_from_torch_equal_numpy(device, rng, precision):
    n = 6
    poses = _poses(n, rng)
    a = _scene(device, n, precision=precision)
    b = _scene(device, n, precision=precision)
    pa, pb = wc.CollisionPipeline(a), wc.CollisionPipeline(b)
    for dtype in (torch.float32, torch.float64):
        a.set_poses(torch.tensor(poses, dtype=dtype))
        b.set_poses(poses.astype(np.float32 if dtype == torch.float32 else np.float64))
        ra, rb = pa.detect(), pb.detect()
        assert np.array_equal(ra.triangle_pairs, rb.triangle_pairs)
        assert np.array_equal(a.world_vertex.numpy(), b.world_vertex.numpy())
    assert len(ra.object_pairs)
    # (N, 4, 4) from torch through set_transforms, and (N, 7) there too
    m = np.tile(np.eye(4), (n, 1, 1))
    m[:, :3, :3] = quat_to_matrix(poses[:, 3:])
    m[:, :3, 3] = poses[:, :3]
    a.set_transforms(torch.tensor(m))
    b.set_transforms(m)
    assert np.array_equal(pa.detect().object_pairs, pb.detect().object_pairs)
    a.set_transforms(torch.tensor(poses))
    b.set_transforms(poses)
    assert np.array_equal(pa.detect().object_pairs, pb.detect().object_pairs)


def test_collide_takes_poses_and_tensors(device, rng):
    n = 5
    poses = _poses(n, rng)
    m = np.tile(np.eye(4), (n, 1, 1))
    m[:, :3, :3] = quat_to_matrix(poses[:, 3:])
    m[:, :3, 3] = poses[:, :3]
    v, t = icosphere(1)
    meshes = [(v, t)] * n
    want = wc.collide(meshes, m, device=device)
    for transforms in (poses, torch.tensor(poses), torch.tensor(m), wp.array(poses, dtype=wp.transformd)):
        got = wc.collide([(torch.tensor(v), torch.tensor(t))] * n if isinstance(transforms, torch.Tensor) else meshes,
                         transforms, device=device)
        assert np.array_equal(got.triangle_pairs, want.triangle_pairs)
    assert len(want.object_pairs)
    assert np.allclose(np.abs(matrix_to_quat(quat_to_matrix(poses[:, 3:])) @ poses[:, 3:].T).diagonal(), 1.0)


def test_bad_device_inputs_are_named_by_the_frame(device):
    scene = _scene(device, 3)
    pipe = wc.CollisionPipeline(scene)
    good = torch.tensor([[0, 0, 0, 0, 0, 0, 1.0], [0.5, 0, 0, 0, 0, 0, 1], [3, 0, 0, 0, 0, 0, 1]])
    scene.set_poses(good)
    assert pipe.detect().object_pairs.tolist() == [[0, 1]]
    bad = good.clone()
    bad[2, 3:] = torch.tensor([0.5, 0.0, 0.0, 0.5])
    scene.set_poses(bad)
    with pytest.raises(ValueError, match="set_poses: row 2 has a quaternion that is not unit"):
        pipe.detect()
    assert pipe.detect().object_pairs.tolist() == [[0, 1]]  # the fault is cleared, the good rows kept
    bad = good.clone()
    bad[1, 0] = float("nan")
    bad[2, 0] = float("inf")
    scene.set_poses(bad)
    with pytest.raises(ValueError, match="set_poses: row 1 is not finite"):
        pipe.detect()
    m = torch.eye(4).repeat(3, 1, 1)
    m[1, 0, 0] = -1.0  # a reflection
    scene.set_transforms(m)
    with pytest.raises(ValueError, match="set_transforms: row 1 is not a rigid transform"):
        scene.check_inputs()
    m = torch.eye(4).repeat(3, 1, 1)
    m[0, 3, 0] = 1.0
    scene.set_transforms(m)
    with pytest.raises(ValueError, match="set_transforms: row 0 is not a rigid transform"):
        pipe.detect()
    for wrong in (torch.zeros(3, 6), torch.zeros(2, 7), torch.zeros(3, 4, 3)):
        with pytest.raises(ValueError, match=r"expected shape \(3, 4, 4\) or \(3, 7\)"):
            scene.set_transforms(wrong)
    with pytest.raises(ValueError, match=r"set_poses: expected shape \(3, 7\)"):
        scene.set_poses(torch.zeros(3, 4, 4))
    with pytest.raises(ValueError, match="set_poses: cannot read this Tensor through DLPack"):
        scene.set_poses(torch.zeros(3, 7, dtype=torch.complex64))
    with pytest.raises(ValueError, match="set_poses: expected real numbers"):
        scene.set_poses(torch.zeros(3, 7, dtype=torch.bool))


def test_world_vertices_from_torch(device):
    v, t = icosphere(1)
    scene = wc.Scene.from_meshes([(v, t), (v, t)], deforming=np.array([True, False]), device=device)
    pipe = wc.CollisionPipeline(scene)
    world = torch.tensor(np.concatenate([v + [0.5, 0, 0], v]), dtype=torch.float32)
    scene.set_world_vertices(world)
    assert pipe.detect().object_pairs.tolist() == [[0, 1]]
    assert np.array_equal(scene.world_vertex.numpy(), world.numpy())
    world[0] += 10.0  # moves one vertex of object 0; read in place by the next call
    scene.set_world_vertices(world)
    assert np.array_equal(scene.world_vertex.numpy()[0], world.numpy()[0])
    world[7, 2] = float("inf")
    scene.set_world_vertices(world)
    with pytest.raises(ValueError, match="set_world_vertices: vertex 7 is not finite"):
        pipe.detect()
    with pytest.raises(ValueError, match=r"set_world_vertices: expected shape"):
        scene.set_world_vertices(torch.zeros(5, 3))


def test_a_bool_mask_of_deforming_objects():
    """``deforming=`` takes an (N,) numpy bool mask (it raised numpy's "truth value is ambiguous")."""
    v, t = icosphere(1)
    scene = wc.Scene.from_meshes([(v, t)] * 3, deforming=np.array([False, True, False]))
    assert scene.object_deforming_np.tolist() == [False, True, False] and scene.deforming
    with pytest.raises(ValueError, match="deforming: expected a bool or"):
        wc.Scene.from_meshes([(v, t)] * 3, deforming=np.array([1, 0, 1]))


def test_filters_and_ids_from_tensors():
    meshes = [shape("cube")] * 4
    poses = torch.zeros(4, 7)
    poses[:, 6] = 1
    poses[:, 0] = torch.tensor([0.0, 0.5, 0.0, 0.5])
    res = wc.collide(meshes, poses, world=torch.tensor([0, 0, 1, 1]), exclude_pairs=torch.tensor([[2, 3]]))
    assert res.object_pairs.tolist() == [[0, 1]]
    assert res.pair_world.tolist() == [0]


def test_results_to_torch_without_a_copy():
    res = wc.collide([shape("cube")] * 2, np.array([[0, 0, 0, 0, 0, 0, 1.0], [0.5, 0, 0, 0, 0, 0, 1]]))
    flags = torch.from_dlpack(res.device_colliding)
    assert flags.data_ptr() == res.device_colliding.ptr
    assert flags.tolist() == [1, 1]
    pairs = torch.from_dlpack(res.device_triangle_pairs)
    assert pairs.shape[0] == res.num_triangle_pairs
    assert wp.to_torch(res.device_colliding).data_ptr() == res.device_colliding.ptr


@pytest.mark.skipif(not wp.is_cuda_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("producer", [DLPackOnly, CudaInterfaceOnly, "warp"])
def test_cuda_frame_from_device_arrays_copies_nothing(rng, producer):
    """A frame driven from device arrays of another library (here bare DLPack and
    ``__cuda_array_interface__`` producers over CUDA memory) issues no memory copy of Warp's (timed
    with Warp's activity timing, memcpy only), eager or replayed as a graph."""
    n = 64
    device = "cuda:0"
    poses = _poses(n, rng)
    poses[:, :3] *= 4.0
    for graph in (False, True):
        scene = _scene(device, n)
        pipe = wc.CollisionPipeline(scene, graph=graph)
        want = wc.CollisionPipeline(_scene(device, n), graph=graph)
        want.scene.set_poses(poses.astype(np.float32))
        expect = want.detect().triangle_pairs
        memory = wp.array(poses.astype(np.float32), device=device)
        source = memory if producer == "warp" else producer(memory)
        scene.set_poses(source)
        pipe.detect()  # warm: modules loaded, graph captured
        wp.synchronize_device(device)
        wp.timing_begin(cuda_filter=wp.TIMING_MEMCPY)
        for _ in range(3):
            scene.set_poses(source)
            res = pipe.detect()
        copies = wp.timing_end()
        assert copies == [], [(c.name, c.elapsed) for c in copies]
        assert np.array_equal(res.triangle_pairs, expect)


def test_device_faults_name_their_setter_and_follow_the_latest_call(device):
    """A pose beyond float32 is a fault (not an inf pose); each kind of input's fault is that of its latest
    call (good poses after bad ones clear it) and names the setter that made it; the one-object frame and
    the distance query raise it too."""
    scene = wc.Scene.from_meshes([shape("cube")] * 2, device=device)
    pipe = wc.CollisionPipeline(scene)
    scene.set_poses(torch.tensor([[0, 0, 0, 0, 0, 0, 1.0], [1e39, 0, 0, 0, 0, 0, 1]], dtype=torch.float64))
    with pytest.raises(ValueError, match="set_poses: row 1 is not finite"):
        pipe.detect()
    assert np.isfinite(scene.object_pose.numpy()).all()
    bent = torch.eye(4).repeat(2, 1, 1)
    bent[1, 0, 0] = 2.0
    scene.set_transforms(bent)
    scene.set_poses(torch.tensor([[0, 0, 0, 0, 0, 0, 1.0], [3, 0, 0, 0, 0, 0, 1]]))
    assert pipe.detect().object_pairs.shape == (0, 2)  # the good poses replaced the bad transforms
    scene.set_transforms(bent)
    with pytest.raises(ValueError, match="set_transforms: row 1 is not a rigid transform"):
        pipe.detect()
    query = wc.DistanceQuery(scene, [(0, 1)])
    scene.set_poses(torch.tensor([[0, 0, 0, 0, 0, 0, 1.0], [5, 0, 0, 0, 0, 0, 3]]))
    with pytest.raises(ValueError, match="set_poses: row 1 has a quaternion that is not unit"):
        query.query()
    one = wc.Scene.from_meshes([shape("cube")], device=device)
    single = wc.CollisionPipeline(one)
    one.set_poses(torch.tensor([[0, 0, 0, 0, 0, 0, 3.0]]))
    with pytest.raises(ValueError, match="set_poses: row 0 has a quaternion that is not unit"):
        single.detect()


def test_coordinates_beyond_the_scenes_precision_are_named_by_the_frame(device):
    """A device input with a coordinate the scene's precision cannot resolve at its triangle size
    (``needed_precision``, the rule ``collide()`` refuses by) is a fault the frame raises, naming the setter
    and the row, as a host input is refused at once (at 1e20 one vertex of two cubes overlapping by 0.7 made
    the frame find no pair); the bad row is not written."""
    v, t = shape("cube")
    w = np.concatenate([v, v + [0.3, 0, 0]])
    scene = wc.Scene.from_meshes([(v, t), (v + [0.3, 0, 0], t)], deforming=True, device=device)
    pipe = wc.CollisionPipeline(scene)
    assert pipe.detect().object_pairs.tolist() == [[0, 1]]
    far = w.copy()
    far[3, 0] = 1e20
    for given in (wp.array(far, dtype=wp.float32, device=device), torch.tensor(far, dtype=torch.float64)):
        scene.set_world_vertices(given)
        with pytest.raises(ValueError, match=r"set_world_vertices: vertex 3 has a coordinate beyond 7\.35e\+12, "
                                             r"what float64 resolves .*: move the scene nearer the origin"):
            pipe.detect()
        assert pipe.detect().object_pairs.tolist() == [[0, 1]]  # the fault is cleared, the far vertex not written
    with pytest.raises(ValueError, match="set_world_vertices: vertex 3 has a coordinate beyond 7.35e"):
        scene.set_world_vertices(far)  # a host array: refused here
    near = w.copy()
    near[3, 0] = 1e5  # beyond float32 at triangles of 1.63 (1.37e4), within float64
    scene.set_world_vertices(wp.array(near, dtype=wp.float64, device=device))
    with pytest.raises(ValueError, match=r"vertex 3 has a coordinate beyond 1\.37e\+04, what float32 resolves at "
                                         r"this scene's triangle size \(1\.63\): use precision='float64'"):
        pipe.detect()
    wide = wc.Scene.from_meshes([(v, t), (v + [0.3, 0, 0], t)], deforming=True, device=device, precision="float64")
    wide.set_world_vertices(wp.array(near, dtype=wp.float64, device=device))
    wc.CollisionPipeline(wide).detect()  # float64 resolves it

    rigid = wc.Scene.from_meshes([(v, t)] * 2, device=device)
    pipe = wc.CollisionPipeline(rigid)
    poses = np.array([[0, 0, 0, 0, 0, 0, 1.0], [0.3, 0, 0, 0, 0, 0, 1]])
    rigid.set_poses(poses)
    assert pipe.detect().object_pairs.tolist() == [[0, 1]]
    poses[1, 1] = -1.37e4  # its corners reach 1.37e4 + 0.87: beyond float32's limit
    rigid.set_poses(wp.array(poses, dtype=wp.float64, device=device))
    with pytest.raises(ValueError, match="set_poses: row 1 places its object beyond 1.37e.*use precision='float64'"):
        pipe.detect()
    m = torch.eye(4, dtype=torch.float64).repeat(2, 1, 1)
    m[1, 2, 3] = 1e20
    rigid.set_transforms(m)
    with pytest.raises(ValueError, match="set_transforms: row 1 places its object beyond 7.35e.*nearer the origin"):
        pipe.detect()
    with pytest.raises(ValueError, match="set_transforms: row 1 places its object beyond 7.35e"):
        rigid.set_transforms(m.numpy())
    with pytest.raises(ValueError, match="set_poses: row 1 places its object beyond 1.37e"):
        rigid.set_poses(poses)
    assert pipe.detect().object_pairs.tolist() == [[0, 1]]


def test_coordinate_limit_is_needed_precisions_rule():
    rng = np.random.default_rng(5)
    for r, s in zip(10.0 ** rng.uniform(-3, 39, 2000), 10.0 ** rng.uniform(-6, 36, 2000)):
        within = [p for p in ("float32", "float64") if r <= coordinate_limit(s, p)]
        assert needed_precision(r, s) == (within[0] if within else None)
    assert coordinate_limit(1.0, "float32") == 1e-3 * 2**23 and coordinate_limit(0.0, "float64") == FLOAT32_MAX
