"""Output buffers with a capacity and a counter.

A kernel that emits items reserves a slot with :func:`reserve_slot` (an atomic add on the int64
counter) and writes only while the slot is below the capacity; the counter keeps counting past it,
in 64 bits, so it cannot wrap. After the frame the
host reads the counter once: if it passed the capacity, the buffer grows and the stage runs
again, so no item is ever dropped silently.
"""

from __future__ import annotations

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["COUNT_LIMIT", "GrowableBuffer", "read_counts", "reserve_slot", "used_count"]

COUNT_LIMIT = 2**31 - 1
"""Items are indexed in int32: a stage that would need more items than this raises OverflowError."""


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


class GrowableBuffer:
    """``data`` (capacity items of ``dtype``) plus ``count`` (int64, one element) on one device.

    Args:
        dtype: Warp dtype of the items.
        capacity: initial number of items (at least 1).
        device: Warp device.
        name: what the buffer holds, for error messages.
        factor: storage is ``factor * capacity`` items (2 for radix-sort scratch).
    """

    def __init__(self, dtype, capacity: int, device, name: str, factor: int = 1):
        self.dtype = dtype
        self.device = wp.get_device(device)
        self.name = name
        self.factor = factor
        self.capacity = 0
        self.count = wp.zeros(1, dtype=wp.int64, device=self.device)
        self._allocate(max(1, int(capacity)))

    def _allocate(self, capacity: int) -> None:
        self.capacity = capacity
        self.data = wp.empty(self.factor * capacity, dtype=self.dtype, device=self.device)

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
        self._allocate(int(min(COUNT_LIMIT - 1, max(needed + needed // 4 + 16, 2 * self.capacity))))
        return True

    def numpy(self, count: int | None = None) -> np.ndarray:
        """The first ``count`` items (default: the counter, read now) as a numpy array."""
        if count is None:
            count = int(self.count.numpy()[0])
        count = min(count, self.capacity)
        if count:
            return self.data[:count].numpy()
        length = getattr(self.dtype, "_length_", None)
        return np.zeros((0,) if length is None else (0, length), dtype=wp.dtype_to_numpy(getattr(self.dtype, "_wp_scalar_type_", self.dtype)))


def read_counts(counts: list[wp.array], device) -> list[int]:
    """Reads several one-element int64 counters with a single host synchronisation."""
    device = wp.get_device(device)
    host = wp.empty(len(counts), dtype=wp.int64, device="cpu", pinned=device.is_cuda)
    for k, c in enumerate(counts):
        wp.copy(host, c, dest_offset=k, src_offset=0, count=1)
    wp.synchronize_device(device)
    return [int(x) for x in host.numpy()]
