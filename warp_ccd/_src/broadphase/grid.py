"""Sweep and prune's grid: the per-frame layout chosen on the device (sweep axis, cells, key bits)
and the statistics pass that chooses it, for :class:`~warp_ccd._src.broadphase.sap.BroadPhaseSAP` (whose
module docs tell the whole sweep).

A key is ``cell << q_bits | q``: the grid cell (within its world: ``slot * ny * nz + cell``), then the
lower bound along the sweep axis quantised to ``q_bits`` bits; :func:`sap_key_bits` and
:func:`sap_world_bits` size them.
"""

from __future__ import annotations

import warp as wp

from ..geometry.box import BOX_EMPTY
from ..runtime.buffers import device_fence

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["GRID_CELLS_MAX", "KEY_BITS_MAX", "KEY_PAD", "Q_BITS_MIN", "SMALL_SCENE_BOXES", "STATS_BLOCK",
           "STATS_CPU_BLOCK_BOXES", "SapGrid", "sap_key_bits", "sap_world_bits"]


@wp.struct
class SapGrid:
    """Per-frame layout chosen on the device: sweep axis, perpendicular grid, key quantisation."""

    axis: int
    ay: int
    az: int
    origin_y: float
    origin_z: float
    inv_cell_y: float
    inv_cell_z: float
    ny: int
    nz: int
    axis_min: wp.float64
    qscale: wp.float64
    q_max: wp.float64
    q_bits: int


KEY_PAD = wp.constant(wp.int32(2147483647))
"""Sort key of unused entries (the largest int32): its low bits are all ones, so it sorts after
every real entry (whose cell bits never are) whatever the number of key bits sorted."""

GRID_CELLS_MAX = wp.constant(32768)
"""Most grid cells along each axis of the grid perpendicular to the sweep axis."""

KEY_BITS_MAX = 31
"""Bits of a sort key (int32, sign bit unused): ``cell_bits + q_bits``."""

Q_BITS_MIN = 8
"""Fewest bits of the quantised lower bound in a key."""

SMALL_SCENE_BOXES = 16384
"""Most boxes whose keys are sorted on 16 bits (see :func:`sap_key_bits`)."""


def sap_key_bits(num_boxes: int, num_worlds: int = 1) -> tuple[int, int]:
    """``(cell_bits, q_bits)`` of the int32 sort keys for ``num_boxes`` boxes: key =
    ``cell << q_bits | q``, sorted on its low ``cell_bits + q_bits <= 31`` bits only. Boxes spread
    over a volume fill a grid column per cell width, about ``N**(2/3)`` cells in the plane: the
    grid gets fewer than ``2**cell_bits = 2 * N**(2/3)`` cells (coarser when the scene needs
    more); the lower bounds along the sweep axis are quantised to ``q_bits`` bits, about 16
    quanta per box of a column of ``N**(1/3)``: order within a quantum only costs box tests,
    never a pair. 26 bits at 10^6 boxes, 23 at 10^5.

    Up to :data:`SMALL_SCENE_BOXES` boxes the keys have 16 bits (8 + 8: at most 255 cells), two
    radix passes: a third pass measured costlier on a GPU than what the sweep loses to columns a few
    times fuller (``docs/site/architecture/broad-phase.md``).

    With ``num_worlds`` ``W > 1`` worlds, each world's grid is sized for its share of the boxes and
    the cell field of a key holds ``slot * cells + cell`` (``cell_bits`` counts the world's bits too):
    :func:`sap_world_bits`.
    """
    if num_worlds > 1:
        return sap_world_bits(num_boxes, num_worlds)[1:]
    if num_boxes <= SMALL_SCENE_BOXES:
        return Q_BITS_MIN, Q_BITS_MIN
    log_n = max(1, int(num_boxes - 1).bit_length())
    cell_bits = min(KEY_BITS_MAX - Q_BITS_MIN, max(4, -(-2 * log_n // 3) + 1))
    q_bits = min(KEY_BITS_MAX - cell_bits, max(Q_BITS_MIN, -(-log_n // 3) + 4))
    return cell_bits, q_bits


def sap_world_bits(num_boxes: int, num_worlds: int) -> tuple[int, int, int]:
    """``(cell_limit, field_bits, q_bits)`` of the keys of ``num_boxes`` boxes in ``num_worlds``
    worlds: a key is ``(slot * ny * nz + cell) << q_bits | q`` on ``field_bits + q_bits <= 31`` bits,
    with ``ny * nz < cell_limit`` cells a world (the grid coarsens until it fits), so the largest cell
    field ``W * ny * nz - 1`` never has all its bits set (the padding key's). Each world's grid gets
    the bits :func:`sap_key_bits` gives its average share of the boxes, fewer (at least 2) when the
    worlds' bits need them, then fewer bits of sweep order (at least :data:`Q_BITS_MIN`).
    """
    w = max(1, int(num_worlds))
    world_bits = w.bit_length() if w > 1 else 0
    cell_bits, q_bits = sap_key_bits(-(-max(num_boxes, 1) // w))
    while world_bits + cell_bits + q_bits > KEY_BITS_MAX and cell_bits > 2:
        cell_bits -= 1
    while world_bits + cell_bits + q_bits > KEY_BITS_MAX and q_bits > Q_BITS_MIN:
        q_bits -= 1
    field_bits = world_bits + cell_bits
    if field_bits + q_bits > KEY_BITS_MAX:
        raise ValueError(f"{w} worlds: too many for the sweep's 31-bit keys")
    return ((1 << field_bits) - 1) // w, field_bits, q_bits


STATS_BLOCK = 256
"""Threads per block of the statistics pass: each block reduces its threads' values in shared
memory (Warp tiles, two reductions of vectors) and adds them to the accumulators with one atomic
per value."""

STATS_CPU_BLOCK_BOXES = 4096
"""Boxes per block of the statistics pass on the CPU (on CUDA one a thread, 256 a block): Warp runs
a CPU block as one thread (256 with ``wp.config.enable_cpu_blocks``), whose reductions cost more
than its boxes; a few blocks keep the last-block layout in use there too."""

vec6f = wp.types.vector(length=6, dtype=wp.float32)
vec9d = wp.types.vector(length=9, dtype=wp.float64)


@wp.func
def _cell_size(mean_extent: float, span: float, cell_scale: float, max_cells: float) -> float:
    cell = cell_scale * mean_extent
    cell = wp.max(cell, span / max_cells)
    if cell <= 0.0:
        cell = 1.0
    return cell


@wp.func
def _sap_setup(
    num_boxes: int,
    cell_scale: float,
    cell_limit: int,
    q_bits: int,
    stat_lo: wp.array[wp.float32],
    stat_hi: wp.array[wp.float32],
    stat_sum: wp.array[wp.float64],
    big_count: wp.array[wp.int32],
    entry_count: wp.array[wp.int64],
    grid: wp.array[SapGrid],
):
    """One thread, once every block has added its statistics: sweep axis of greatest centre
    variance, grid of the other two axes with fewer than ``cell_limit`` cells, key quantisation
    to ``q_bits`` bits. Reads the accumulators by exchanging them with their empty values (atomics:
    the values other blocks added, and empty for the next frame); empties the big-box list and
    the entry counter for this frame."""
    lo = wp.vec3()
    hi = wp.vec3()
    for k in range(3):
        lo[k] = wp.atomic_exch(stat_lo, k, BOX_EMPTY)
        hi[k] = wp.atomic_exch(stat_hi, k, -BOX_EMPTY)
    sums = vec9d()
    for k in range(9):
        sums[k] = wp.atomic_exch(stat_sum, k, wp.float64(0.0))
    inv_n = wp.float64(1.0) / wp.float64(wp.max(num_boxes, 1))
    best = int(0)
    best_var = wp.float64(-1.0)
    for k in range(3):
        mean = sums[k] * inv_n
        var = sums[3 + k] * inv_n - mean * mean
        if var > best_var:
            best_var = var
            best = k
    g = SapGrid()
    g.axis = best
    g.ay = (best + 1) % 3
    g.az = (best + 2) % 3
    max_cells = float(GRID_CELLS_MAX - 1)
    span_y = hi[g.ay] - lo[g.ay]
    span_z = hi[g.az] - lo[g.az]
    cell_y = _cell_size(float(sums[6 + g.ay] * inv_n), span_y, cell_scale, max_cells)
    cell_z = _cell_size(float(sums[6 + g.az] * inv_n), span_z, cell_scale, max_cells)
    ny = wp.min(int(span_y / cell_y) + 1, GRID_CELLS_MAX)
    nz = wp.min(int(span_z / cell_z) + 1, GRID_CELLS_MAX)
    while ny * nz >= cell_limit:  # coarser cells until the ids fit their bits
        cell_y = cell_y * 1.5
        cell_z = cell_z * 1.5
        ny = wp.min(int(span_y / cell_y) + 1, GRID_CELLS_MAX)
        nz = wp.min(int(span_z / cell_z) + 1, GRID_CELLS_MAX)
    g.origin_y = lo[g.ay]
    g.origin_z = lo[g.az]
    g.inv_cell_y = 1.0 / cell_y
    g.inv_cell_z = 1.0 / cell_z
    g.ny = ny
    g.nz = nz
    g.axis_min = wp.float64(lo[best])
    g.q_bits = q_bits
    g.q_max = wp.float64((1 << q_bits) - 1)
    span = wp.float64(hi[best]) - g.axis_min
    g.qscale = wp.float64(0.0)
    if span > wp.float64(0.0):
        g.qscale = g.q_max / span
    grid[0] = g
    big_count[0] = 0
    entry_count[0] = wp.int64(0)


@wp.kernel
def _sap_stats_kernel(
    lower: wp.array[wp.vec3],
    upper: wp.array[wp.vec3],
    num_boxes: int,
    num_blocks: int,
    entry_capacity: int,
    cell_scale: float,
    cell_limit: int,
    q_bits: int,
    # Outputs
    stat_lo: wp.array[wp.float32],
    stat_hi: wp.array[wp.float32],
    stat_sum: wp.array[wp.float64],
    blocks_done: wp.array[wp.int32],
    entry_key: wp.array[wp.int32],
    big_count: wp.array[wp.int32],
    entry_count: wp.array[wp.int64],
    grid: wp.array[SapGrid],
):
    """Strided pass over the boxes by ``num_blocks`` blocks: scene bounds (``stat_lo``/``stat_hi``,
    3 each) and sums (``stat_sum``, 9: centres, squared centres, extents per axis), reduced per
    block, then one atomic per value per block, into accumulators that the previous frame (or the
    constructor) left empty. The same threads fill the entry keys with the padding key (the emit
    kernel overwrites the slots this frame's entries use). The last block to finish (counted in
    ``blocks_done``, fenced) lays out this frame's grid (:func:`_sap_setup`) and empties the
    accumulators and ``blocks_done`` for the next."""
    block, lane = wp.tid()
    width = wp.block_dim()
    bounds = vec6f(BOX_EMPTY, BOX_EMPTY, BOX_EMPTY, BOX_EMPTY, BOX_EMPTY, BOX_EMPTY)  # (lo, -hi): both by min
    sums = vec9d()  # centres, squared centres, extents
    i = block * width + lane
    stride = num_blocks * width
    while i < num_boxes:
        a = lower[i]
        b = upper[i]
        bounds = wp.min(bounds, vec6f(a[0], a[1], a[2], -b[0], -b[1], -b[2]))
        c = wp.vec3d(wp.float64(0.5) * (wp.float64(a[0]) + wp.float64(b[0])),
                     wp.float64(0.5) * (wp.float64(a[1]) + wp.float64(b[1])),
                     wp.float64(0.5) * (wp.float64(a[2]) + wp.float64(b[2])))
        sums = sums + vec9d(c[0], c[1], c[2], c[0] * c[0], c[1] * c[1], c[2] * c[2], wp.float64(b[0] - a[0]),
                            wp.float64(b[1] - a[1]), wp.float64(b[2] - a[2]))
        i += stride
    e = block * width + lane
    while e < entry_capacity:
        entry_key[e] = KEY_PAD
        e += stride
    # Two block reductions (of vectors), then one atomic per value.
    block_bounds = wp.tile_extract(wp.tile_reduce(wp.min, wp.tile(bounds, preserve_type=True)), 0)
    block_sums = wp.tile_extract(wp.tile_sum(wp.tile(sums, preserve_type=True)), 0)
    if lane == 0:
        for k in range(3):
            wp.atomic_min(stat_lo, k, block_bounds[k])
            wp.atomic_max(stat_hi, k, -block_bounds[3 + k])
        for k in range(9):
            wp.atomic_add(stat_sum, k, block_sums[k])
        device_fence()  # this block's sums are visible before its count
        if wp.atomic_add(blocks_done, 0, 1) == num_blocks - 1:
            device_fence()
            _sap_setup(num_boxes, cell_scale, cell_limit, q_bits, stat_lo, stat_hi, stat_sum, big_count, entry_count,
                       grid)
            blocks_done[0] = 0


@wp.func
def _cell(x: float, origin: float, inv_cell: float, count: int) -> int:
    """Monotonic cell coordinate of ``x``, clamped to ``[0, count)``."""
    c = wp.floor((x - origin) * inv_cell)
    c = wp.clamp(c, 0.0, float(count - 1))
    return int(c)


@wp.func
def _quantise(x: float, g: SapGrid) -> int:
    """Monotonic quantisation of ``x`` along the sweep axis to ``g.q_bits`` bits."""
    q = wp.floor((wp.float64(x) - g.axis_min) * g.qscale)
    q = wp.clamp(q, wp.float64(0.0), g.q_max)
    return int(q)
