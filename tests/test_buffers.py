"""Buffers with a capacity and a counter, the loop that makes every item fit, and the shared
binary search, against plain numpy."""

from typing import Any

import numpy as np
import pytest
import warp as wp

from warp_ccd._src.runtime.buffers import CounterRead, GrowableBuffer, reserve_slot, upper_bound
from warp_ccd._src.runtime.frame import CountedFrame


@wp.kernel
def _upper_bound_kernel(values: wp.array[Any], first: int, end: int, query: wp.array[Any], out: wp.array[int]):
    k = wp.tid()
    out[k] = upper_bound(values, first, end, query[k])


@wp.kernel
def _emit_kernel(capacity: int, data: wp.array[int], count: wp.array[wp.int64]):
    k = wp.tid()
    slot = reserve_slot(count, capacity)
    if slot >= 0:
        data[slot] = k


@pytest.mark.parametrize("dtype", [np.int32, np.int64])
def test_upper_bound_matches_searchsorted(device, dtype):
    rng = np.random.default_rng(4)
    values = np.sort(rng.integers(0, 40, 200)).astype(dtype)  # many repeats (empty blocks of a scan)
    query = np.arange(-2, 43, dtype=dtype)
    wp_dtype = wp.int32 if dtype == np.int32 else wp.int64
    v = wp.array(values, dtype=wp_dtype, device=device)
    q = wp.array(query, dtype=wp_dtype, device=device)
    for first, end in ((0, len(values)), (17, 150), (60, 60), (0, 1)):
        out = wp.zeros(len(query), dtype=int, device=device)
        wp.launch(_upper_bound_kernel, dim=len(query), inputs=[v, first, end, q, out], device=device)
        want = first + np.searchsorted(values[first:end], query, side="right")
        assert np.array_equal(out.numpy(), want), (first, end)


def test_counted_frame_grows_and_records_counts(device):
    """From capacity 1, the loop grows the buffer until all 1,000 items fit, and each buffer records
    its count; the items held are exactly the ones emitted."""
    items = GrowableBuffer(wp.int32, 1, device, "items")
    other = GrowableBuffer(wp.int32, 1, device, "untouched")
    counters = CounterRead([items, other], device)
    runs = []

    def launch():
        runs.append(1)
        items.reset()
        wp.launch(_emit_kernel, dim=1000, inputs=[items.capacity], outputs=[items.data, items.count], device=device)

    frame = CountedFrame(launch, counters)
    counts = frame.run()
    assert counts == [1000, 0] and len(runs) == 2
    assert items.last_count == 1000 and other.last_count == 0 and items.capacity >= 1000
    assert np.array_equal(np.sort(items.held().numpy()), np.arange(1000))
    assert frame.run() == [1000, 0] and len(runs) == 3  # fits at once now


@wp.kernel
def _relay_kernel(src: wp.array[int], src_count: wp.array[wp.int64], src_capacity: int, capacity: int,
                  data: wp.array[int], count: wp.array[wp.int64]):
    """Emits one item for every item of ``src`` that was stored (a downstream stage)."""
    k = wp.tid()
    if wp.int64(k) < wp.min(src_count[0], wp.int64(src_capacity)):
        slot = reserve_slot(count, capacity)
        if slot >= 0:
            data[slot] = src[k]


def test_downstream_buffers_grow_with_the_shortfall(device):
    """With stages, a buffer fed by one that overflowed 10x grows as if its count were 10x too: the
    second run fits both; without stages it takes a run per stage."""
    for stages, want_runs in (([0, 1], 2), (None, 3)):
        first = GrowableBuffer(wp.int32, 100, device, "first")
        second = GrowableBuffer(wp.int32, 100, device, "second", doubling=False)
        counters = CounterRead([first, second], device, stages=stages)
        runs = []

        def launch(first=first, second=second, runs=runs):
            runs.append(1)
            wp.launch(_emit_kernel, dim=1000, inputs=[first.capacity], outputs=[first.data, first.count],
                      device=device)
            wp.launch(_relay_kernel, dim=first.capacity,
                      inputs=[first.data, first.count, first.capacity, second.capacity],
                      outputs=[second.data, second.count], device=device)

        assert CountedFrame(launch, counters).run() == [1000, 1000] and len(runs) == want_runs
        assert np.array_equal(np.sort(second.held().numpy()), np.arange(1000))
    with pytest.raises(ValueError, match="stages"):
        CounterRead([first], device, stages=[0, 1])


def test_held_refuses_a_buffer_that_grew_at_its_read(device):
    items = GrowableBuffer(wp.int32, 1, device, "items")
    counters = CounterRead([items], device)
    wp.launch(_emit_kernel, dim=10, inputs=[items.capacity], outputs=[items.data, items.count], device=device)
    counters.enqueue()
    assert counters.finish() and not items.fitted and items.last_count == 10
    with pytest.raises(RuntimeError, match="items: the buffer grew"):
        items.held()


def test_counter_read_generation(device):
    """A reader's generation moves when one of its buffers gets new storage, or when a later reader
    adopts a counter: a graph of its frames is then stale. A buffer adopted away still moves the
    generation of both readers when it grows."""
    a = GrowableBuffer(wp.int32, 4, device, "a")
    b = GrowableBuffer(wp.int32, 4, device, "b")
    first = CounterRead([a, b], device)
    g = first.generation
    assert not a.ensure(4) and first.generation == g  # fits: same storage
    assert a.ensure(5) and first.generation == g + 1
    second = CounterRead([b], device)
    assert first.generation == g + 2 and second.generation == 0
    assert b.ensure(100)
    assert first.generation == g + 3 and second.generation == 1


def test_packed_arrays_are_typed_views_of_one_upload(device):
    """``packed_arrays``: each array as ``wp.array(host, dtype)`` would make it (vectors, transforms,
    integers, empty ones, big ones uploaded alone), the small ones views of one block."""
    from warp_ccd._src.runtime.arrays import PACK_ALIGN, packed_arrays

    rng = np.random.default_rng(0)
    items = [(rng.normal(size=(5, 3)).astype(np.float32), wp.vec3),
             (rng.integers(0, 9, (4, 3)).astype(np.int32), wp.vec3i),
             (np.arange(3, dtype=np.int32), wp.int32), (np.zeros(0, np.int32), wp.int32),
             (rng.normal(size=(2, 7)), wp.transformd), (rng.normal(size=(3, 3)), wp.vec3d),
             (rng.normal(size=(1000, 3)).astype(np.float32), wp.vec3)]
    out = packed_arrays(items, device, alone=4096)
    for (host, dtype), got in zip(items, out):
        want = wp.array(host, dtype=dtype, device=device)
        assert got.dtype == dtype and got.shape == want.shape and got.device == wp.get_device(device)
        assert np.array_equal(got.numpy(), want.numpy())
    small = [a for a, (h, _) in zip(out, items) if 0 < h.nbytes < 4096]
    assert all(a._ref is small[0]._ref and a.ptr % PACK_ALIGN == 0 for a in small)
    assert out[-1]._ref is not small[0]._ref  # a big one alone
