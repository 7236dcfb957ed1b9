"""Per-block slot reservation (``buffers.block_reserve``) and the kernels that use it, with blocks
of many threads on every device: on CUDA always, on the CPU with ``wp.config.enable_cpu_blocks``
(by default Warp runs a CPU block as one thread, which the other tests cover)."""

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.runtime.buffers import BLOCK_DIM, block_dim_for, block_reserve

from oracles import box_pairs_numpy
from test_broad_phase import pairs_from_capacity_one


@pytest.fixture
def blocks():
    """Blocks of :data:`BLOCK_DIM` threads on the CPU too, for the test's duration."""
    saved = wp.config.enable_cpu_blocks
    wp.config.enable_cpu_blocks = True
    yield
    wp.config.enable_cpu_blocks = saved


@wp.kernel
def _reserve_kernel(n: int, count: wp.array[wp.int64], first: wp.array[wp.int64]):
    block, lane = wp.tid()
    i = block * wp.block_dim() + lane
    items = int(0)
    if i < n:
        items = (i * 7) % 5  # 0 to 4 items, zeros included
    slot = block_reserve(count, lane, items)
    if i < n:
        first[i] = slot


@pytest.mark.parametrize("n", [1, 255, 256, 1000])
def test_block_reserve_slots_are_disjoint(device, blocks, n):
    width = block_dim_for(device)
    assert width == BLOCK_DIM
    count = wp.full(1, 5, dtype=wp.int64, device=device)  # reservations start where the counter is
    first = wp.zeros(n, dtype=wp.int64, device=device)
    wp.launch_tiled(_reserve_kernel, dim=[-(-n // width)], inputs=[n, count, first], block_dim=width, device=device)
    items = (np.arange(n) * 7) % 5
    slots = np.concatenate([np.arange(s, s + m) for s, m in zip(first.numpy(), items)])
    assert sorted(slots.tolist()) == list(range(5, 5 + items.sum()))
    assert count.numpy()[0] == 5 + items.sum()


def test_sap_in_blocks(device, blocks):
    """Grid entries and pairs reserved per block, with identical boxes (every entry finds more
    pairs than a thread holds) and from buffers of capacity 1."""
    rng = np.random.default_rng(5)
    lo = rng.uniform(0, 10, (600, 3)).astype(np.float32)
    lo[:40] = 3.0  # 40 identical boxes: 39 pairs for the first entry among them
    hi = lo + rng.uniform(0.2, 1.5, (600, 3)).astype(np.float32)
    hi[:40] = 4.0
    wlo = wp.array(lo, dtype=wp.vec3, device=device)
    whi = wp.array(hi, dtype=wp.vec3, device=device)
    bp = wc.stages.BroadPhaseSAP(device=device, all_pairs_max=0)
    bp._resize(len(lo))
    bp.entry._allocate(1)
    got, rounds = pairs_from_capacity_one(bp, wlo, whi, device)  # both buffers overflow first
    assert rounds >= 2
    assert np.array_equal(got, box_pairs_numpy(lo, hi))


@pytest.mark.parametrize("whole_triangles_max", [0, 64])
@pytest.mark.parametrize("front_capacity", [1, None])
def test_traversal_in_blocks(device, blocks, front_capacity, whole_triangles_max):
    """Front entries and candidates reserved per block and round, with a candidate buffer (and a
    front) of capacity 1; the cube pairs by trees or as whole-object pairs."""
    scene = wc.Scene.random(30, seed=4, shapes=("cube", "icosphere3", "icosphere4"), density=0.08, device=device)
    scene.advance(0.4)
    ref = wc.CollisionPipeline(scene, mid_phase="all_pairs").detect()
    pipe = wc.CollisionPipeline(scene, candidate_capacity=1)
    pipe.mid.whole_triangles_max = whole_triangles_max
    if front_capacity is not None:
        pipe.mid.front._allocate(front_capacity)
    assert pipe.mid.block_dim == BLOCK_DIM
    got = pipe.detect()
    assert ref.num_triangle_pairs > 0
    assert np.array_equal(got.triangle_pairs, ref.triangle_pairs)


def test_traversal_in_blocks_many_pairs(device, blocks):
    """More object pairs than a block has threads: a block's items span many pairs."""
    scene = wc.Scene.random(700, seed=3, density=0.25, device=device)
    ref = wc.CollisionPipeline(scene, mid_phase="all_pairs").detect()
    got = wc.CollisionPipeline(scene).detect()
    assert got.num_broad_pairs > 2 * BLOCK_DIM
    assert np.array_equal(got.triangle_pairs, ref.triangle_pairs)
