"""Output buffers with a capacity and a counter, and the reader of their counters.

A kernel that emits items reserves a slot with :func:`reserve_slot` (an atomic add on the int64
counter) and writes only while the slot is below the capacity; the counter keeps counting past it,
in 64 bits, so it cannot wrap. After the frame the host reads all counters once
(:class:`CounterRead`): if one passed its capacity, that buffer grows and the frame runs again
(:class:`~warp_ccd._src.runtime.frame.CountedFrame`), so no item is ever dropped silently.

Device helpers every stage shares live here too: :func:`emit_pair` (an object pair through that
protocol), :func:`upper_bound` (which block of a scanned count a flat work item falls in),
:func:`block_reserve` (slots for a whole block of threads with one atomic add) and
:func:`device_fence` (for a kernel whose last block finishes the work of all). Many small arrays go to the
device in one copy by :func:`~warp_ccd._src.runtime.arrays.packed_upload`.

Atomic adds on one counter are served one at a time when their increments differ from thread to
thread, which measured slow on a GPU where every thread reserved its own items (the measurements:
``docs/site/architecture/frame.md``, "Output reserved per block"): a kernel that emits many items
reserves them per block (:func:`block_reserve`: a scan of the block's counts in shared memory, one
atomic, a broadcast).
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from typing import Any

import numpy as np
import warp as wp

from .aliases import DeviceLike

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = [
    "BLOCK_DIM",
    "COUNT_LIMIT",
    "ITEM_LIST_SIZE",
    "CounterRead",
    "GrowableBuffer",
    "WorkArrays",
    "block_dim_for",
    "blocks_have_lanes",
    "block_reserve",
    "device_fence",
    "emit_pair",
    "reserve_slot",
    "upper_bound",
    "used_count",
    "vec_items",
]

COUNT_LIMIT = 2**31 - 1
"""Items are indexed in int32: a stage that would need more items than this raises OverflowError."""


BLOCK_DIM = 256
"""Threads per block of the kernels that reserve their output per block (:func:`block_reserve`)."""

ITEM_LIST_SIZE = wp.constant(16)
"""Items a thread gathers in registers (:data:`vec_items`) before its block reserves their slots."""

vec_items = wp.types.vector(length=ITEM_LIST_SIZE, dtype=wp.int32)


def blocks_have_lanes(device) -> bool:
    """Whether a thread block on ``device`` runs its threads side by side: on CUDA, and on the CPU
    only with ``wp.config.enable_cpu_blocks`` (else Warp runs a CPU block as one thread)."""
    return wp.get_device(device).is_cuda or wp.config.enable_cpu_blocks


def block_dim_for(device) -> int:
    """Block size of the per-block kernels on ``device``: :data:`BLOCK_DIM` where a block has its
    lanes (:func:`blocks_have_lanes`), else 1."""
    return BLOCK_DIM if blocks_have_lanes(device) else 1


@wp.func
def block_reserve(count: wp.array[wp.int64], lane: int, items: int) -> wp.int64:
    """Cooperative: every thread of the block calls it (``lane``: its own index in the block, from
    ``wp.tid()``) with its number of items; reserves them all with one atomic add on ``count`` and
    returns the thread's first slot. Like :func:`reserve_slot`, the counter counts past the
    capacity: the caller writes only slots below it. The block's items must stay below 2**31
    (int32 scan)."""
    start = wp.untile(wp.tile_scan_exclusive(wp.tile(items)))
    total = wp.tile_extract(wp.tile_from_thread(shape=1, value=start + items, thread_idx=wp.block_dim() - 1), 0)
    base = wp.int64(0)
    if lane == 0 and total > 0:
        base = wp.atomic_add(count, 0, wp.int64(total))
    base = wp.tile_extract(wp.tile_from_thread(shape=1, value=base, thread_idx=0), 0)
    return base + wp.int64(start)


@wp.func_native("""
#if defined(__CUDA_ARCH__)
__threadfence();
#endif
""")
def device_fence():
    """Memory fence over the device (CUDA's ``__threadfence``; nothing on the CPU, whose blocks run
    one after another): the calling thread's earlier writes and atomics are seen by every thread
    before its later ones. For a last-block-done counter: the blocks add their results, fence,
    count themselves; the block that counts last fences and reads the sum."""
    ...


@wp.func
def reserve_slot(count: wp.array[wp.int64], capacity: int) -> int:
    """Counts one item; returns its slot, or -1 when the buffer is full (the count goes on)."""
    slot = wp.atomic_add(count, 0, wp.int64(1))
    if slot < wp.int64(capacity):
        return int(slot)
    return -1


@wp.func
def used_count(count: wp.array[wp.int64], capacity: int) -> int:
    """Number of items actually stored: the counter, at most the capacity."""
    return int(wp.min(count[0], wp.int64(capacity)))


@wp.func
def emit_pair(a: int, b: int, pair: wp.array[wp.vec2i], pair_count: wp.array[wp.int64], pair_capacity: int):
    """Appends the object pair ``(min(a, b), max(a, b))`` through the capacity + counter protocol."""
    slot = reserve_slot(pair_count, pair_capacity)
    if slot >= 0:
        pair[slot] = wp.vec2i(wp.min(a, b), wp.max(a, b))


@wp.func
def upper_bound(values: wp.array[Any], first: int, end: int, x: Any) -> int:
    """First index ``k`` in ``[first, end)`` with ``values[k] > x`` (``end`` when there is none), for
    ``values`` sorted ascending. Over the ends of scanned counts, the block flat item ``x`` lies in."""
    lo = first
    hi = end
    while lo < hi:
        mid = (lo + hi) // 2
        if values[mid] > x:
            hi = mid
        else:
            lo = mid + 1
    return lo


class GrowableBuffer:
    """``data`` (capacity items of ``dtype``) plus ``count`` (int64, one element) on one device.

    Args:
        dtype: Warp dtype of the items.
        capacity: initial number of items (at least 1).
        device: Warp device.
        name: what the buffer holds, for error messages.
        factor: storage is ``factor * capacity`` items (2 for radix-sort scratch).
        doubling: a growth at least doubles the capacity (few regrowths); False: it becomes the
            items needed plus an eighth (for a buffer whose every slot costs work each frame, such
            as keys sorted in full).

    Attributes:
        last_count: the counter as the host last read it (:class:`CounterRead`), 0 before; once
            the frame fits, the number of items held.
        fitted: whether the items counted at that read were all stored (False when the buffer
            then grew: its new storage holds nothing yet).
    """

    def __init__(self, dtype: Any, capacity: int, device: DeviceLike, name: str, factor: int = 1,
                 doubling: bool = True) -> None:
        self.dtype = dtype
        self.device = wp.get_device(device)
        self.name = name
        self.factor = factor
        self.doubling = doubling
        self.capacity = 0
        self.last_count = 0
        self.fitted = True
        self.count = wp.zeros(1, dtype=wp.int64, device=self.device)
        self.readers = weakref.WeakSet()  # the CounterReads that read it
        self._allocate(max(1, int(capacity)))

    def _allocate(self, capacity: int) -> None:
        self.capacity = capacity
        self.data = wp.empty(self.factor * capacity, dtype=self.dtype, device=self.device)
        self.mark_stale()  # graphs of the readers' frames hold the old storage

    def mark_stale(self) -> None:
        """Moves on the :attr:`~CounterRead.generation` of every reader of this buffer: storage that
        their frames use changed (this buffer's, or scratch that a stage keeps beside it), so
        their captured graphs are stale."""
        for reader in self.readers:
            reader.generation += 1

    def reset(self) -> None:
        """Sets the counter to zero (on the device, no host sync)."""
        self.count.zero_()

    def ensure(self, needed: int) -> bool:
        """Grows the buffer when ``needed`` items do not fit; returns True if it grew.

        Raises:
            OverflowError: when ``needed`` reaches :data:`COUNT_LIMIT`.
        """
        if needed >= COUNT_LIMIT:
            raise OverflowError(f"{self.name}: {needed} items exceed the limit of {COUNT_LIMIT} per buffer")
        if needed <= self.capacity:
            return False
        grown = max(needed + needed // 4 + 16, 2 * self.capacity) if self.doubling else needed + needed // 8 + 16
        self._allocate(int(min(COUNT_LIMIT - 1, grown)))
        return True

    def numpy(self, count: int | None = None) -> np.ndarray:
        """The first ``count`` items (default: the counter, read now) as a numpy array."""
        if count is None:
            count = int(self.count.numpy()[0])
        count = min(count, self.capacity)
        if count:
            return self.data[:count].numpy()
        length = getattr(self.dtype, "_length_", None)
        scalar = wp.dtype_to_numpy(getattr(self.dtype, "_wp_scalar_type_", self.dtype))
        return np.zeros((0,) if length is None else (0, length), dtype=scalar)

    def held(self) -> wp.array:
        """The items held after the last read (``data[:last_count]``), a view on the device.

        Raises:
            RuntimeError: the buffer grew at that read (its items were not all stored): run the
                work that fills it again first.
        """
        if not self.fitted:
            raise RuntimeError(f"{self.name}: the buffer grew after its last read; run the frame again first")
        return self.data[: self.last_count]


class WorkArrays:
    """A stage's named work arrays on one device, sized by the call that asks: each is made anew, half again over the
    need (at least 64 rows), when asked for more rows than it holds or for another shape of row.

    Args:
        device: the Warp device.
    """

    def __init__(self, device: Any) -> None:
        self.device = device
        self._arrays: dict[str, wp.array] = {}

    def get(self, name: str, shape: int | tuple, dtype: Any) -> wp.array:
        """The array ``name`` of at least ``shape`` (an int: rows; a tuple: rows first), of ``dtype``."""
        rows, rest = (shape, ()) if isinstance(shape, int) else (shape[0], tuple(shape[1:]))
        a = self._arrays.get(name)
        if a is None or a.shape[0] < rows or tuple(a.shape[1:]) != rest:
            full = max(int(rows * 1.5), 64)
            a = wp.empty((full, *rest) if rest else full, dtype=dtype, device=self.device)
            self._arrays[name] = a
        return a

    def drop(self, name: str) -> None:
        """Forgets the array ``name`` (the next :meth:`get` makes it anew)."""
        self._arrays.pop(name, None)


@wp.kernel
def _publish_counters_kernel(block: wp.array[wp.int64], watch: wp.array[wp.int64], host: wp.array[wp.int64]):
    """Counter ``k`` into host memory (pinned, mapped into the device's address space); the last
    thread publishes the largest watched value."""
    k = wp.tid()
    if k < block.shape[0]:
        host[k] = block[k]
    else:
        m = wp.int64(0)
        for j in range(watch.shape[0]):
            m = wp.max(m, watch[j])
        host[k] = m


class CounterRead:
    """The counters of several buffers in one device block, reset with one memset and copied to
    the host by one small kernel, then read with one wait.

    On construction the reader adopts the buffers' counters: each buffer's ``count`` becomes a view
    of one slot of :attr:`block` (its value kept). :meth:`reset` zeroes them all at once and
    :meth:`enqueue` copies the block into pinned host memory; both only enqueue work, so a frame
    that starts with one and ends with the other can be captured in a CUDA graph. :meth:`finish`
    waits, records each buffer's :attr:`~GrowableBuffer.last_count` and grows the buffers that
    overflowed. A buffer adopted by a later reader leaves this one's block; this reader then resets
    and copies that buffer's counter on its own (slower, still right).

    Args:
        buffers: the buffers, fixed for the reader's life (their storage may grow).
        device: Warp device of the buffers.
        stages: optional ``(len(buffers),)`` order of the buffers in the frame's data flow (a
            buffer is filled from the items of buffers of lower stages). When a buffer overflows
            by a factor ``r``, those of later stages counted only the items that came through,
            so they grow to ``r`` times their count too: the next run usually fits everything,
            where growing one stage per run would take a run per stage. None for a buffer of
            work that does not flow from the others (it neither grows with them nor they with it).
        watch: optional int64 device array whose largest value is published with the counters (by
            the same kernel) and never reset by the reader: a scene's input faults
            (:class:`~warp_ccd._src.scene.inputs.InputCheck`), read in :attr:`watched` after each frame.

    Attributes:
        block: ``(len(buffers),)`` int64 counters on the device.
        counts: the counts of the last :meth:`finish`.
        watched: the largest value of ``watch`` at the end of the last frame (0 without one).
        generation: counts the new storages of its buffers (and counters adopted away by a later
            reader): a graph captured at one generation is stale at the next.
    """

    def __init__(self, buffers: Sequence[GrowableBuffer], device, stages: Sequence[int] | None = None,
                 watch: wp.array | None = None):
        self.buffers = list(buffers)
        if stages is not None and len(stages) != len(self.buffers):
            raise ValueError(f"stages: expected {len(self.buffers)} entries, got {len(stages)}")
        self.stages = None if stages is None else [None if x is None else int(x) for x in stages]
        self.device = wp.get_device(device)
        k = max(1, len(self.buffers))
        self.block = wp.zeros(k, dtype=wp.int64, device=self.device)
        self.watch = watch if watch is not None else wp.zeros(1, dtype=wp.int64, device=self.device)
        self.watched = 0
        self.generation = 0
        for slot, b in enumerate(self.buffers):
            wp.copy(self.block, b.count, dest_offset=slot, src_offset=0, count=1)
            b.count = self.block[slot : slot + 1]
            b.mark_stale()  # its counter moved out of the former readers' block
            b.readers.add(self)
        self.host = wp.zeros(k + self.watch.shape[0], dtype=wp.int64, device="cpu", pinned=self.device.is_cuda)
        # The pinned block as the device sees it: with unified addressing, pinned host memory is
        # mapped at the same address (else None: a copy node instead).
        self._host_mapped = self.host
        if self.device.is_cuda:
            self._host_mapped = (wp.array(ptr=self.host.ptr, dtype=wp.int64, shape=self.host.shape, device=self.device)
                                 if self.device.is_uva else None)
        self._host_view = self.host.numpy()[: len(self.buffers)]  # made once: a frame's read is a tolist()
        self._host_watch = self.host.numpy()[k:]
        self.counts = [0] * len(self.buffers)

    def _strays(self) -> list[tuple[int, GrowableBuffer]]:
        """Buffers whose counter is no longer this block's slot (adopted by another reader)."""
        base = self.block.ptr
        return [(k, b) for k, b in enumerate(self.buffers) if b.count.ptr != base + 8 * k]

    def reset(self) -> None:
        """Zeroes every counter (one memset; capturable)."""
        self.block.zero_()
        for _, b in self._strays():
            b.reset()

    def enqueue(self) -> None:
        """Copies every counter to the host: one kernel writing into the pinned block, which CUDA maps
        into the device's address space (capturable; a kernel node of a graph measured faster than a
        device-to-host copy node: ``docs/site/architecture/frame.md``). A device without unified
        addressing gets the copy."""
        if self.buffers:
            if self._host_mapped is not None:
                wp.launch(_publish_counters_kernel, dim=self.block.shape[0] + 1, inputs=[self.block, self.watch],
                          outputs=[self._host_mapped], device=self.device)
            else:
                wp.copy(self.host, self.block, count=len(self.buffers))
                wp.copy(self.host, self.watch, dest_offset=self.block.shape[0], count=self.watch.shape[0])
        for k, b in self._strays():
            wp.copy(self.host, b.count, dest_offset=k, src_offset=0, count=1)

    def finish(self) -> bool:
        """Waits for the device, then :meth:`read`; returns True when a buffer grew (run again).

        Raises:
            OverflowError: a counter reached :data:`COUNT_LIMIT`.
        """
        wp.synchronize_device(self.device)
        return self.read()

    def read(self) -> bool:
        """Records the counts that the device copied (call after waiting for it), grows the buffers
        that overflowed; returns True when one grew (run again).

        Raises:
            OverflowError: a counter reached :data:`COUNT_LIMIT`.
        """
        self.counts = counts = self._host_view.tolist()
        self.watched = int(self._host_watch.max())
        grew = False
        short = None
        for k, (b, c) in enumerate(zip(self.buffers, counts)):
            b.last_count = c
            if c > b.capacity or c >= COUNT_LIMIT:  # the rare case: grow (or raise past COUNT_LIMIT)
                short = short or {}
                short[k] = c / max(b.capacity, 1)
                b.fitted = not b.ensure(c)
                grew |= not b.fitted
            else:
                b.fitted = True
        if short and self.stages is not None:
            self._extrapolate(counts, short)
        return grew

    def _extrapolate(self, counts: list[int], short: dict[int, float]) -> None:
        """Grows the buffers downstream of those that overflowed (``short``: slot -> count over
        capacity) as if their counts scaled by the same factor."""
        for k, (b, c) in enumerate(zip(self.buffers, counts)):
            if self.stages[k] is None:
                continue
            r = max((x for j, x in short.items() if self.stages[j] is not None and self.stages[j] < self.stages[k]),
                    default=1.0)
            if r > 1.0 and b.ensure(min(COUNT_LIMIT - 1, int(c * r) + 1)):
                b.fitted = False
