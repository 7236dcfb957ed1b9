"""Broad phase: which pairs of axis-aligned boxes overlap.

Two implementations behind one interface (``launch(lower, upper, pairs)`` writes pairs ``(a, b)``,
``a < b``, into a :class:`~warp_ccd._src.runtime.buffers.GrowableBuffer` of ``wp.vec2i``, and ``counters`` lists
the buffers of its own whose counters the caller checks after it; boxes are closed, so touching
boxes overlap):

* :class:`BroadPhaseAllPairs`, the reference (method ``"all_pairs"``; ``"nxn"`` names it too, as the
  API contract does): one thread per pair index ``k < N (N - 1) / 2``. O(N^2) work, exact, limited to
  :data:`ALL_PAIRS_LIMIT` boxes.
* :class:`BroadPhaseSAP`, the default: sort-based sweep and prune on a grid (Liu et al. 2010).

Sweep and prune, as run on the device each frame:

1. Statistics of the boxes (on CUDA one box per thread up to 131,072 boxes, reduced per block, a few
   atomics per block): bounds of the scene, mean extent, variance of the centres per axis. The
   last block to finish (a counter behind a memory fence) reads them, lays out the grid below and
   empties the accumulators for the next frame, so the layout costs no launch of its own.
2. The sweep axis is the axis of greatest variance of the centres; the plane perpendicular to it
   is divided into a grid of cells ``cell_scale`` times the mean box extent wide. Sweeping along
   one axis alone is not enough at scale: with boxes spread over a volume the number of boxes
   overlapping one box along one axis grows like N^(2/3); per grid cell it stays constant.
3. Every box is entered in each cell it covers (usually 1 to 4), in slots that its block of
   threads reserves with one atomic add (:func:`~warp_ccd._src.runtime.buffers.block_reserve`; the sort puts
   the entries in order, so no count and scan are needed). A box covering
   more than ``max_cells_per_box`` cells (a huge box among small ones) is not entered in the
   grid; it goes to a short list tested against all boxes instead (O(N) per huge box).
4. Entries are sorted with ``wp.utils.radix_sort_pairs`` by an int32 key ``cell << q_bits | q``:
   the cell id, then the lower bound along the sweep axis quantised monotonically to ``q_bits``
   bits. Only the bits in use are sorted (``end_bit``; :func:`sap_key_bits` sizes them from
   ``N``, and the grid coarsens when it would need more cells): a radix pass costs as much for
   1,000 keys as for 10^5, so scenes up to 16,384 boxes sort 16 bits, not 32. Unused entry
   slots hold a key that sorts last (written by the statistics pass).
5. One thread per entry sweeps forward through its cell while the next quantised lower bound is
   not past its own quantised upper bound, tests the exact boxes, and reports a pair only from
   the cell holding the lower corner of the two boxes' intersection (both boxes are entered
   there), so no pair is reported twice and none is lost; a block's pairs are reserved with one
   atomic add. The same threads test the boxes against the big-box list.

Worlds and filters (a scene's :class:`~warp_ccd._src.scene.filter.CollisionFilter`, passed to ``launch``):
a box's world slot is the high part of its keys' cell field (``slot * ny * nz + cell``), so the one sort
puts every world's cells apart and the one sweep never meets a box of another world, whether the worlds
lie apart or on top of each other; each world's grid is sized for its share of the boxes
(:func:`~warp_ccd._src.broadphase.grid.sap_world_bits`). Boxes of world -1 go to the big-box list (tested
against every box). Groups, masks and excluded pairs are tested on each overlapping pair before it is
written (:func:`~warp_ccd._src.scene.filter.pair_allowed`): a filtered pair costs nothing after the broad phase.

Four launches per frame (statistics with the layout, emit, sort, sweep); O(N) work plus the output,
O(log N)-depth sort; everything stays on the device and the host reads nothing, so the frame can
be a CUDA graph (:meth:`BroadPhase.find_pairs`). A small scene (``all_pairs_max``, 2,048 boxes on
CUDA) tests all its pairs in one launch instead: in a graph, four launches and the sort's fixed
cost take tens of microseconds, a million box tests a few. Counters are int64 and every buffer grows: the
entry buffer and the pair buffer report overflow through their counters.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..geometry.box import BOX_EMPTY, boxes_overlap
from ..runtime.aliases import ArrayLike, DeviceLike
from ..runtime.arrays import host_array
from ..runtime.buffers import (
    ITEM_LIST_SIZE,
    CounterRead,
    GrowableBuffer,
    block_dim_for,
    block_reserve,
    emit_pair,
    used_count,
    vec_items,
)
from ..runtime.checks import integer_option
from ..runtime.frame import CountedFrame, FrameCache, frame_mode
from ..runtime.options import check_option
from ..scene.filter import CollisionFilter, PairFilter, inactive_filter, pair_allowed
from .grid import (
    STATS_BLOCK,
    STATS_CPU_BLOCK_BOXES,
    SapGrid,
    _cell,
    _quantise,
    _sap_stats_kernel,
    sap_key_bits,
    sap_world_bits,
)

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["ALL_PAIRS_LIMIT", "ALL_PAIRS_MAX", "BROAD_METHODS", "BroadPhase", "BroadPhaseAllPairs", "BroadPhaseSAP",
           "broad_phase_pairs", "find_pairs", "make_broad_phase", "sap_key_bits"]

ALL_PAIRS_LIMIT = 65536
"""Most boxes of the all-pairs reference (and of :attr:`BroadPhaseSAP.all_pairs_max`): it enumerates
pair indices in int32, at most ``65536 * 65535 / 2 < 2**31`` pairs."""

ALL_PAIRS_MAX = 2048
"""Default :attr:`BroadPhaseSAP.all_pairs_max` on CUDA: up to this many boxes the sweep and prune
tests all pairs in one launch."""


# ---------------------------------------------------------------------------------------------
# Reference: all pairs


@wp.kernel
def _all_pairs_kernel(
    lower: wp.array[wp.vec3],
    upper: wp.array[wp.vec3],
    pair_filter: PairFilter,
    pair_capacity: int,
    # Outputs
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
):
    """One thread per pair index ``k``: pair ``(j, i)`` with ``k = i (i - 1) / 2 + j``, ``j < i``,
    when the boxes overlap and the filter lets it through."""
    k = wp.int64(wp.tid())
    one = wp.float64(1.0)
    i = wp.int64((one + wp.sqrt(one + wp.float64(8.0) * wp.float64(k))) * wp.float64(0.5))
    while i * (i - wp.int64(1)) / wp.int64(2) > k:
        i = i - wp.int64(1)
    while (i + wp.int64(1)) * i / wp.int64(2) <= k:
        i = i + wp.int64(1)
    j = k - i * (i - wp.int64(1)) / wp.int64(2)
    a = int(j)
    b = int(i)
    if boxes_overlap(lower[a], upper[a], lower[b], upper[b]):
        if pair_allowed(pair_filter, a, b):
            emit_pair(a, b, pair, pair_count, pair_capacity)


def _device_filter(pair_filter: CollisionFilter | None, device: wp.Device, num_boxes: int) -> PairFilter:
    """The :class:`~warp_ccd._src.scene.filter.PairFilter` struct of a filter, or one that lets every
    pair through."""
    if pair_filter is None or not pair_filter.active:
        return inactive_filter(device)
    if pair_filter.device != device:
        raise ValueError(f"pair_filter: on {pair_filter.device}, the broad phase on {device}")
    if pair_filter.num_objects != num_boxes:
        raise ValueError(f"pair_filter: made for {pair_filter.num_objects} objects, given {num_boxes} boxes")
    return pair_filter.device_filter


class BroadPhase:
    """What both broad phases share: running alone, frame after frame (:meth:`find_pairs`).

    A subclass implements ``launch(lower, upper, pairs)`` and ``counters``. :meth:`find_pairs`
    owns the pair buffer and one :class:`~warp_ccd._src.runtime.frame.CountedFrame` per box arrays: each call
    is one frame with one counter read, replayed as a CUDA graph on CUDA (``graph``), so a user of
    the broad phase alone gets the pipeline's frame.

    Args:
        device: Warp device.
        graph: replay frames of :meth:`find_pairs` as CUDA graphs (default: on CUDA).
    """

    def __init__(self, *, device: DeviceLike = None, graph: bool | None = None) -> None:
        self.device = wp.get_device(device)
        self.mode = frame_mode(self.device, graph)
        self.pairs = None
        self._frames = None

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers of its own with counters that ``launch`` writes, besides ``pairs``."""
        return []

    def find_pairs(self, lower: wp.array, upper: wp.array, pair_filter: CollisionFilter | None = None) -> wp.array:
        """Overlapping pairs of the ``(N,)`` closed boxes ``lower``/``upper`` (``wp.vec3`` on this
        device), as one frame: launch, one counter read, grow and rerun if a buffer overflowed.
        ``pair_filter``: a :class:`~warp_ccd._src.scene.filter.CollisionFilter` of the boxes, or None.

        Returns:
            ``(K,)`` ``wp.vec2i`` pairs ``(a, b)``, ``a < b``, unsorted: a view of :attr:`pairs`,
            valid until the next call.

        Raises:
            ValueError: arrays of another type, shape or device.
        """
        for name, a in (("lower", lower), ("upper", upper)):
            if not isinstance(a, wp.array) or a.dtype != wp.vec3 or a.ndim != 1:
                raise ValueError(f"find_pairs: {name} must be a 1-D wp.array of wp.vec3")
            if a.device != self.device:
                raise ValueError(f"find_pairs: {name} is on {a.device}, the broad phase on {self.device}")
        if lower.shape != upper.shape:
            raise ValueError(f"find_pairs: lower and upper differ in shape, {lower.shape} and {upper.shape}")
        n = lower.shape[0]
        if self.pairs is None:
            self.pairs = GrowableBuffer(wp.vec2i, max(64, 4 * n), self.device, "broad-phase pairs")
            self._frames = FrameCache(CounterRead([self.pairs, *self.counters], self.device), self.mode)
        self._frames.get((lower.ptr, upper.ptr, n, id(pair_filter)),
                         lambda: self.launch(lower, upper, self.pairs, pair_filter)).run()
        return self.pairs.held()


class BroadPhaseAllPairs(BroadPhase):
    """Reference broad phase: tests all ``N (N - 1) / 2`` pairs, one thread each.

    Args:
        device: Warp device.
        graph: as for :class:`BroadPhase`.
    """

    def launch(self, lower: wp.array, upper: wp.array, pairs: GrowableBuffer,
               pair_filter: CollisionFilter | None = None) -> None:
        """Writes overlapping pairs of the ``(N,)`` boxes ``lower``/``upper`` into ``pairs``.

        The caller resets ``pairs`` (or not, to append) and checks its counter afterwards.

        Args:
            lower: ``(N,)`` ``wp.vec3`` lower corners of the closed boxes.
            upper: ``(N,)`` ``wp.vec3`` upper corners of the closed boxes.
            pairs: the output buffer.
            pair_filter: a :class:`~warp_ccd._src.scene.filter.CollisionFilter` of the ``N`` boxes' objects
                (worlds, groups, excluded pairs), or None (every overlapping pair).
        """
        n = lower.shape[0]
        if n > ALL_PAIRS_LIMIT:
            raise ValueError(f"all_pairs broad phase: at most {ALL_PAIRS_LIMIT} boxes, got {n}; use method='sap'")
        num_pairs = n * (n - 1) // 2
        if num_pairs == 0:
            return
        wp.launch(
            _all_pairs_kernel,
            dim=num_pairs,
            inputs=[lower, upper, _device_filter(pair_filter, self.device, n), pairs.capacity],
            outputs=[pairs.data, pairs.count],
            device=self.device,
        )


# ---------------------------------------------------------------------------------------------
# Sweep and prune on a grid (its layout and keys: warp_ccd._src.broadphase.grid)


@wp.kernel
def _sap_emit_kernel(
    lower: wp.array[wp.vec3],
    upper: wp.array[wp.vec3],
    num_boxes: int,
    grid: wp.array[SapGrid],
    pair_filter: PairFilter,
    max_cells_per_box: int,
    entry_capacity: int,
    # Outputs
    box_cells: wp.array[wp.int32],
    big_box: wp.array[wp.int32],
    big_count: wp.array[wp.int32],
    entry_key: wp.array[wp.int32],
    entry_box: wp.array[wp.int32],
    entry_count: wp.array[wp.int64],
):
    """One thread per box: one (key, box) entry per grid cell it covers, in slots its block
    reserves with one atomic add (the sort orders them), or, covering more than
    ``max_cells_per_box`` cells or in world -1, none and a place in the big list; ``box_cells``
    records the count (0 for a big box). A box's cells are those of its world's slot: cell id
    ``slot * ny * nz + cell``."""
    block, lane = wp.tid()
    i = block * wp.block_dim() + lane
    g = grid[0]
    y0 = int(0)
    y1 = int(-1)
    z0 = int(0)
    z1 = int(-1)
    q = int(0)
    cells = int(0)
    world_base = int(0)
    if i < num_boxes:
        lo = lower[i]
        hi = upper[i]
        y0 = _cell(lo[g.ay], g.origin_y, g.inv_cell_y, g.ny)
        y1 = _cell(hi[g.ay], g.origin_y, g.inv_cell_y, g.ny)
        z0 = _cell(lo[g.az], g.origin_z, g.inv_cell_z, g.nz)
        z1 = _cell(hi[g.az], g.origin_z, g.inv_cell_z, g.nz)
        cells = (y1 - y0 + 1) * (z1 - z0 + 1)
        q = _quantise(lo[g.axis], g)
        wslot = int(0)
        if pair_filter.use_world != 0:
            wslot = pair_filter.object_world[i]
        world_base = wslot * g.ny * g.nz
        if cells > max_cells_per_box or wslot < 0:
            cells = 0
            big_box[wp.atomic_add(big_count, 0, 1)] = i
        box_cells[i] = cells
    slot = block_reserve(entry_count, lane, cells)
    if cells > 0:
        for y in range(y0, y1 + 1):
            for z in range(z0, z1 + 1):
                if slot < wp.int64(entry_capacity):
                    entry_key[int(slot)] = ((world_base + y * g.nz + z) << g.q_bits) | q
                    entry_box[int(slot)] = i
                slot += wp.int64(1)


@wp.func
def _sweep_entry(
    e: int,
    total: int,
    lower: wp.array[wp.vec3],
    upper: wp.array[wp.vec3],
    g: SapGrid,
    pair_filter: PairFilter,
    entry_key: wp.array[wp.int32],
    entry_box: wp.array[wp.int32],
    pair_capacity: int,
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
):
    """Sorted entry ``e`` sweeps forward within its cell (of its world): the boxes of the pairs it
    owns that the filter lets through, the first :data:`ITEM_LIST_SIZE` gathered (returned with their
    number), any more emitted at once."""
    found = vec_items()
    num_found = int(0)
    key = entry_key[e]
    cell = key >> g.q_bits
    low_mask = (1 << g.q_bits) - 1
    i = entry_box[e]
    lo_i = lower[i]
    hi_i = upper[i]
    q_hi = _quantise(hi_i[g.axis], g)
    plane = cell % (g.ny * g.nz)  # the cell within its world's grid
    cy = plane / g.nz
    cz = plane - cy * g.nz
    for f in range(e + 1, total):
        key_f = entry_key[f]
        if (key_f >> g.q_bits) != cell:
            break
        if (key_f & low_mask) > q_hi:
            break
        j = entry_box[f]
        lo_j = lower[j]
        hi_j = upper[j]
        if boxes_overlap(lo_i, hi_i, lo_j, hi_j):
            # Report from the cell holding the lower corner of the intersection only.
            oy = _cell(wp.max(lo_i[g.ay], lo_j[g.ay]), g.origin_y, g.inv_cell_y, g.ny)
            oz = _cell(wp.max(lo_i[g.az], lo_j[g.az]), g.origin_z, g.inv_cell_z, g.nz)
            if oy == cy and oz == cz and pair_allowed(pair_filter, i, j):
                if num_found < ITEM_LIST_SIZE:
                    found[num_found] = j
                    num_found += 1
                else:
                    emit_pair(i, j, pair, pair_count, pair_capacity)
    return found, num_found


@wp.func
def _big_box_pairs(
    j: int,
    lower: wp.array[wp.vec3],
    upper: wp.array[wp.vec3],
    box_cells: wp.array[wp.int32],
    big_box: wp.array[wp.int32],
    nb: int,
    pair_filter: PairFilter,
    pair_capacity: int,
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
):
    """Box ``j`` against every big box ``i`` (a pair of two big boxes once), the filter's pairs."""
    lo_j = lower[j]
    hi_j = upper[j]
    j_big = box_cells[j] == 0
    for b in range(nb):
        i = big_box[b]
        if i == j or (j_big and j < i):
            continue
        if boxes_overlap(lower[i], upper[i], lo_j, hi_j):
            if pair_allowed(pair_filter, i, j):
                emit_pair(i, j, pair, pair_count, pair_capacity)


@wp.kernel
def _sap_sweep_kernel(
    lower: wp.array[wp.vec3],
    upper: wp.array[wp.vec3],
    grid: wp.array[SapGrid],
    pair_filter: PairFilter,
    entry_key: wp.array[wp.int32],
    entry_box: wp.array[wp.int32],
    entry_count: wp.array[wp.int64],
    entry_capacity: int,
    box_cells: wp.array[wp.int32],
    big_box: wp.array[wp.int32],
    big_count: wp.array[wp.int32],
    pair_capacity: int,
    # Outputs
    pair: wp.array[wp.vec2i],
    pair_count: wp.array[wp.int64],
):
    """Thread ``t``: sorted entry ``t`` sweeps its cell, its block reserves the pairs found with
    one atomic add (an entry's first :data:`~warp_ccd._src.runtime.buffers.ITEM_LIST_SIZE`; any more take one
    atomic each); box ``t`` is tested against the big boxes."""
    block, lane = wp.tid()
    t = block * wp.block_dim() + lane
    total = used_count(entry_count, entry_capacity)
    found = vec_items()
    num_found = int(0)
    i = int(0)
    if t < total:
        i = entry_box[t]
        found, num_found = _sweep_entry(t, total, lower, upper, grid[0], pair_filter, entry_key, entry_box,
                                        pair_capacity, pair, pair_count)
    slot = block_reserve(pair_count, lane, num_found)
    for m in range(num_found):
        if slot < wp.int64(pair_capacity):
            pair[int(slot)] = wp.vec2i(wp.min(i, found[m]), wp.max(i, found[m]))
        slot += wp.int64(1)
    nb = big_count[0]
    if nb > 0 and t < lower.shape[0]:
        _big_box_pairs(t, lower, upper, box_cells, big_box, nb, pair_filter, pair_capacity, pair, pair_count)


class BroadPhaseSAP(BroadPhase):
    """Sort-based sweep and prune on a grid perpendicular to the sweep axis (see module docs).

    Owns its scratch arrays, sized for ``N`` boxes and grown on demand.

    Args:
        device: Warp device.
        graph: as for :class:`BroadPhase`.
        cell_scale: grid cell width relative to the mean box extent.
        max_cells_per_box: boxes covering more cells go to the big-box list.
        stats_blocks: most blocks (of :data:`STATS_BLOCK` threads) of the statistics pass; on
            CUDA it uses one per 256 boxes up to that (a box per thread: each box more per thread
            adds a round trip to memory).
        all_pairs_max: up to this many boxes, every pair is tested in one launch instead
            (:class:`BroadPhaseAllPairs`' kernel): a few microseconds for a small scene, where the four
            launches and the sort's fixed cost take tens. Default :data:`ALL_PAIRS_MAX` on CUDA, 0
            on the CPU (whose threads run one by one).
        entry_capacity: initial capacity of the grid entries (it grows; default 1,024, and at
            least two a box once boxes come: a persistent frame sorts every slot, so it starts
            lean and grows once where boxes cover more cells). A one-shot frame passes more
            (:func:`~warp_ccd._src.pipeline.pipeline.collide`: boxes of cells twice their mean extent cover
            2.25 cells on average, more with varied sizes).
    """

    def __init__(self, *, device: DeviceLike = None, graph: bool | None = None, cell_scale: float = 2.0,
                 max_cells_per_box: int = 64, stats_blocks: int = 512, all_pairs_max: int | None = None,
                 entry_capacity: int | None = None) -> None:
        super().__init__(device=device, graph=graph)
        if all_pairs_max is None:
            all_pairs_max = ALL_PAIRS_MAX if self.device.is_cuda else 0
        self.all_pairs_max = integer_option("all_pairs_max", all_pairs_max, low=0, high=ALL_PAIRS_LIMIT)
        self.cell_scale = float(cell_scale)
        self.max_cells_per_box = int(max_cells_per_box)
        self.stats_blocks = int(stats_blocks)
        d = self.device
        # Empty accumulators; each frame's last statistics block empties them again after reading them.
        self.stat_lo = wp.full(3, BOX_EMPTY, dtype=wp.float32, device=d)
        self.stat_hi = wp.full(3, -BOX_EMPTY, dtype=wp.float32, device=d)
        self.stat_sum = wp.zeros(9, dtype=wp.float64, device=d)
        self.blocks_done = wp.zeros(1, dtype=wp.int32, device=d)
        self.grid = wp.zeros(1, dtype=SapGrid, device=d)
        self.big_count = wp.zeros(1, dtype=wp.int32, device=d)
        self._scratch_boxes = -1  # boxes the per-box scratch holds
        self._entry_box = None
        # Every slot is sorted each frame: the capacity follows the entries (an eighth above them).
        capacity = check_option("entry_capacity", entry_capacity) or 1024
        self.entry = GrowableBuffer(wp.int32, capacity, d, "sap grid entries", factor=2, doubling=False)

    def _resize(self, n: int) -> None:
        """Scratch for ``n`` boxes. It only grows: a captured frame holds its pointers, so a frame of
        fewer boxes uses the larger scratch, and new scratch marks the frames reading the entries
        stale (:meth:`~warp_ccd._src.runtime.buffers.GrowableBuffer.mark_stale`)."""
        if n > self._scratch_boxes:
            d = self.device
            self._scratch_boxes = n
            self.box_cells = wp.zeros(max(n, 1), dtype=wp.int32, device=d)
            self.big_box = wp.zeros(max(n, 1), dtype=wp.int32, device=d)
            self.entry.mark_stale()
        self.entry.ensure(2 * n)  # room for 2 entries a box (they cover 1.5 to 2.5 cells): grows if short

    def _entry_arrays(self) -> tuple[wp.array, wp.array]:
        if self._entry_box is None or self._entry_box.shape[0] != 2 * self.entry.capacity:
            self._entry_box = wp.empty(2 * self.entry.capacity, dtype=wp.int32, device=self.device)
        return self.entry.data, self._entry_box

    @property
    def counters(self) -> list[GrowableBuffer]:
        """The buffers of its own with counters that :meth:`launch` writes, whose counters the caller
        reads after it (besides ``pairs``): the grid entries (their counter emptied by a kernel)."""
        return [self.entry]

    def launch(self, lower: wp.array, upper: wp.array, pairs: GrowableBuffer,
               pair_filter: CollisionFilter | None = None) -> None:
        """Writes overlapping pairs of the ``(N,)`` boxes into ``pairs``; host reads nothing.

        Four launches: statistics (with the padding of the keys and the grid layout), emit, sort
        (of the key bits in use), sweep. The caller resets ``pairs`` (or not, to append). After
        the frame, check ``pairs`` and :attr:`counters`; if a counter passed its capacity,
        ``ensure`` it and launch again (:func:`find_pairs` does).

        Args:
            lower: ``(N,)`` ``wp.vec3`` lower corners of the closed boxes.
            upper: ``(N,)`` ``wp.vec3`` upper corners of the closed boxes.
            pairs: the output buffer.
            pair_filter: a :class:`~warp_ccd._src.scene.filter.CollisionFilter` of the ``N`` boxes' objects,
                or None. Its worlds are sorted and swept in the same launches (a world's slot is the
                high part of its entries' keys, :func:`sap_world_bits`); its groups, masks and
                excluded pairs are tested on each overlapping pair before it is written.
        """
        n = lower.shape[0]
        self._resize(n)
        pf = _device_filter(pair_filter, self.device, n)
        if n <= self.all_pairs_max:  # no grid entries: their counter stays as the frame's reset left it
            if n >= 2:
                wp.launch(_all_pairs_kernel, dim=n * (n - 1) // 2, inputs=[lower, upper, pf, pairs.capacity],
                          outputs=[pairs.data, pairs.count], device=self.device)
            return
        if n < 2:
            self.entry.reset()
            return
        d = self.device
        key, box = self._entry_arrays()
        cap = self.entry.capacity
        worlds = pair_filter.num_worlds if pair_filter is not None and pair_filter.use_world else 1
        cell_limit, cell_bits, q_bits = sap_world_bits(n, worlds)
        per_block = STATS_BLOCK if d.is_cuda else STATS_CPU_BLOCK_BOXES
        blocks = max(1, min(self.stats_blocks, -(-n // per_block)))
        wp.launch_tiled(_sap_stats_kernel, dim=[blocks],
                        inputs=[lower, upper, n, blocks, cap, self.cell_scale, cell_limit, q_bits],
                        outputs=[self.stat_lo, self.stat_hi, self.stat_sum, self.blocks_done, key, self.big_count,
                                 self.entry.count, self.grid], block_dim=STATS_BLOCK, device=d)
        width = block_dim_for(d)
        wp.launch_tiled(_sap_emit_kernel, dim=[-(-n // width)],
                        inputs=[lower, upper, n, self.grid, pf, self.max_cells_per_box, cap],
                        outputs=[self.box_cells, self.big_box, self.big_count, key, box, self.entry.count],
                        block_dim=width, device=d)
        wp.utils.radix_sort_pairs(key, box, cap, end_bit=cell_bits + q_bits)
        wp.launch_tiled(_sap_sweep_kernel, dim=[-(-max(n, cap) // width)],
                        inputs=[lower, upper, self.grid, pf, key, box, self.entry.count, cap, self.box_cells,
                                self.big_box,
                                self.big_count, pairs.capacity],
                        outputs=[pairs.data, pairs.count], block_dim=width, device=d)


BROAD_METHODS = {"sap": BroadPhaseSAP, "all_pairs": BroadPhaseAllPairs, "nxn": BroadPhaseAllPairs}
"""Broad-phase classes by method name (:func:`make_broad_phase`); ``"nxn"`` names
``"all_pairs"`` too (the API contract's name for it)."""


def make_broad_phase(method: str, *, device: DeviceLike = None, graph: bool | None = None,
                     entry_capacity: int | None = None) -> BroadPhase:
    """The broad phase of a method name.

    Args:
        method: ``"sap"`` (:class:`BroadPhaseSAP`) or ``"all_pairs"`` (:class:`BroadPhaseAllPairs`,
            the reference; ``"nxn"`` is an alias).
        device: Warp device.
        graph: as for :class:`BroadPhase`.
        entry_capacity: initial capacity of the grid entries (``"sap"``; see :class:`BroadPhaseSAP`),
            None for its default; the all-pairs reference has none and ignores it.

    Raises:
        ValueError: an unknown method (the message lists the known ones).
    """
    method = check_option("broad_phase", method)
    if BROAD_METHODS[method] is BroadPhaseSAP:
        return BroadPhaseSAP(device=device, graph=graph, entry_capacity=entry_capacity)
    check_option("entry_capacity", entry_capacity)  # checked though the all-pairs reference has no grid
    return BROAD_METHODS[method](device=device, graph=graph)


def find_pairs(broad: BroadPhase, lower: wp.array, upper: wp.array, pairs: GrowableBuffer,
               pair_filter: CollisionFilter | None = None) -> int:
    """Runs a broad phase until its buffers hold everything; returns the number of pairs.

    Resets ``pairs``, launches, reads the counters of ``pairs`` and of the broad phase's own
    ``counters`` with one synchronisation, grows what overflowed and launches again if needed
    (an eager :class:`~warp_ccd._src.runtime.frame.CountedFrame`).

    Args:
        broad: an object with ``launch(lower, upper, pairs)`` (and ``counters``, when it writes
            buffers of its own).
        lower: ``(N,)`` ``wp.vec3`` lower corners of the boxes, on the broad phase's device.
        upper: ``(N,)`` ``wp.vec3`` upper corners of the boxes, on the broad phase's device.
        pairs: ``wp.vec2i`` output buffer.
        pair_filter: a :class:`~warp_ccd._src.scene.filter.CollisionFilter` of the boxes, or None.
    """
    reader = CounterRead([pairs, *getattr(broad, "counters", [])], pairs.device)
    launch = (lambda: broad.launch(lower, upper, pairs)) if pair_filter is None else (
        lambda: broad.launch(lower, upper, pairs, pair_filter))
    return CountedFrame(launch, reader).run()[0]


def _boxes_to_float32(a: ArrayLike, name: str, outward: int) -> np.ndarray:
    try:
        arr = np.asarray(a)
    except Exception as exc:
        raise ValueError(f"{name}: not an array of numbers ({exc})") from None
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(f"{name}: expected real numbers, got dtype {arr.dtype}")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name}: expected shape (N, 3), got {arr.shape}")
    if not np.isfinite(arr).all():
        bad = int(np.argmin(np.isfinite(arr).all(axis=1)))
        raise ValueError(f"{name}: box {bad} is not finite ({arr[bad].tolist()})")
    with np.errstate(over="ignore"):
        f32 = arr.astype(np.float32)
    if not np.isfinite(f32).all():
        raise ValueError(f"{name}: coordinates overflow float32")
    if arr.dtype != np.float32:
        # Round outward so no overlap is lost by the conversion.
        wide = arr.astype(np.float64)
        off = (f32.astype(np.float64) - wide) * outward < 0
        f32[off] = np.nextafter(f32[off], np.float32(outward * np.inf))
    return f32


def broad_phase_pairs(lower: ArrayLike, upper: ArrayLike, method: str = "sap", device: DeviceLike = None, *,
                      world: ArrayLike | None = None, group: ArrayLike | None = None, mask: ArrayLike | None = None,
                      exclude_pairs: ArrayLike | None = None) -> np.ndarray:
    """Overlapping pairs among ``N`` closed axis-aligned boxes.

    Args:
        lower: ``(N, 3)`` lower corners.
        upper: ``(N, 3)`` upper corners, ``upper >= lower``. Inputs that are not float32 are
            rounded outward to float32 (a pair may be added, never lost).
        method: ``"sap"`` (default) or ``"all_pairs"`` (the reference; ``"nxn"`` is an alias).
        device: Warp device (default: Warp's default device).
        world: ``(N,)`` world id of each box (``-1`` pairs with every world), or None: one world
            (see :class:`~warp_ccd._src.scene.filter.CollisionFilter`).
        group: ``(N,)`` 32-bit collision group of each box, or None: every bit set.
        mask: ``(N,)`` 32-bit collision mask of each box, or None: every bit set (a pair collides
            when ``group[a] & mask[b]`` and ``group[b] & mask[a]`` are non-zero).
        exclude_pairs: ``(E, 2)`` box indices of pairs that never pair, or None.

    Returns:
        ``(K, 2)`` int32 pairs ``(a, b)``, ``a < b``, rows sorted.

    Raises:
        ValueError: bad shapes, non-finite values, ``lower > upper``, unknown method.
    """
    lo = _boxes_to_float32(host_array(lower, "lower"), "lower", -1)
    hi = _boxes_to_float32(host_array(upper, "upper"), "upper", +1)
    if lo.shape != hi.shape:
        raise ValueError(f"lower and upper: shapes differ, {lo.shape} and {hi.shape}")
    bad = (lo > hi).any(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"box {i}: lower {lo[i].tolist()} exceeds upper {hi[i].tolist()}")
    device = wp.get_device(device)
    bp = make_broad_phase(method, device=device, graph=False)  # one frame: nothing to replay
    n = lo.shape[0]
    filters = (world, group, mask, exclude_pairs)
    pair_filter = None if all(f is None for f in filters) else CollisionFilter(
        n, world=world, group=group, mask=mask, exclude_pairs=exclude_pairs, device=device)
    if n < 2:
        return np.zeros((0, 2), np.int32)
    wlo = wp.array(lo, dtype=wp.vec3, device=device)
    whi = wp.array(hi, dtype=wp.vec3, device=device)
    out = bp.find_pairs(wlo, whi, pair_filter).numpy().reshape(-1, 2).astype(np.int32)
    return out[np.lexsort((out[:, 1], out[:, 0]))]
