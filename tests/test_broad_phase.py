"""Broad phases against numpy truth on many box distributions, on every device."""

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.broadphase.sap import ALL_PAIRS_LIMIT, ALL_PAIRS_MAX, BroadPhaseAllPairs, make_broad_phase

from conftest import DEFAULT_DEVICE
from oracles import box_pairs_numpy


def boxes_random(rng, n, spread=10.0, size=(0.1, 1.0)):
    c = rng.uniform(-spread, spread, size=(n, 3))
    h = rng.uniform(*size, size=(n, 3)) / 2
    return (c - h).astype(np.float32), (c + h).astype(np.float32)


def boxes_clustered(rng, n):
    centres = rng.uniform(-50, 50, size=(5, 3))
    c = centres[rng.integers(0, 5, n)] + rng.normal(scale=1.0, size=(n, 3))
    h = rng.uniform(0.05, 0.5, size=(n, 3))
    return (c - h).astype(np.float32), (c + h).astype(np.float32)


def boxes_line(rng, n):
    c = np.zeros((n, 3))
    c[:, 0] = rng.uniform(0, 100, n)
    h = rng.uniform(0.1, 1.0, size=(n, 3))
    return (c - h).astype(np.float32), (c + h).astype(np.float32)


def boxes_plane(rng, n):
    c = np.zeros((n, 3))
    c[:, [0, 2]] = rng.uniform(0, 30, (n, 2))
    h = rng.uniform(0.1, 1.0, size=(n, 3))
    h[:, 1] = 0.0  # flat boxes in one plane
    return (c - h).astype(np.float32), (c + h).astype(np.float32)


def boxes_identical(rng, n):
    lo = np.tile(np.float32([1, 2, 3]), (n, 1))
    return lo, lo + np.float32(0.5)


def boxes_mixed(rng, n):
    lo, hi = boxes_random(rng, n, spread=20.0, size=(0.01, 0.5))
    big = rng.choice(n, size=max(1, n // 50), replace=False)
    c = (lo[big] + hi[big]) / 2
    lo[big] = c - rng.uniform(5, 30, (len(big), 3)).astype(np.float32)
    hi[big] = c + rng.uniform(5, 30, (len(big), 3)).astype(np.float32)
    return lo, hi


def boxes_touching(rng, n):
    """A grid of unit cubes that touch their neighbours exactly (faces, edges, corners)."""
    k = int(np.ceil(n ** (1 / 3)))
    idx = np.stack(np.meshgrid(np.arange(k), np.arange(k), np.arange(k), indexing="ij"), -1).reshape(-1, 3)[:n]
    lo = idx.astype(np.float32) * np.float32(0.5)
    return lo, lo + np.float32(0.5)


def boxes_far(rng, n):
    lo, hi = boxes_random(rng, n, spread=5.0, size=(0.5, 2.0))
    off = np.float32([1e6, -1e6, 1e6])
    return lo + off, hi + off


def boxes_degenerate_points(rng, n):
    p = rng.integers(0, 4, size=(n, 3)).astype(np.float32)  # many repeated points
    return p, p.copy()


DISTRIBUTIONS = {
    "random": boxes_random,
    "clustered": boxes_clustered,
    "line": boxes_line,
    "plane": boxes_plane,
    "identical": boxes_identical,
    "mixed_huge_tiny": boxes_mixed,
    "touching": boxes_touching,
    "far_1e6": boxes_far,
    "points": boxes_degenerate_points,
}


SAP_PATHS = {"sweep": 0, "all_pairs": ALL_PAIRS_LIMIT}
"""``all_pairs_max`` of :class:`BroadPhaseSAP` that makes it sweep, or test all pairs, at any size
(by default a small scene tests all pairs on CUDA and sweeps on the CPU)."""


def pairs_of(method: str, lo, hi, device) -> np.ndarray:
    """Sorted pairs of a method of :func:`wc.stages.broad_phase_pairs`, or of a path of the SAP (``sap_sweep``,
    ``sap_all_pairs``) forced with ``all_pairs_max``."""
    if not method.startswith("sap_"):
        return wc.stages.broad_phase_pairs(lo, hi, method=method, device=device)
    if len(lo) < 2:
        return np.zeros((0, 2), np.int32)
    bp = wc.stages.BroadPhaseSAP(device=device, all_pairs_max=SAP_PATHS[method[4:]])
    got = bp.find_pairs(wp.array(lo, dtype=wp.vec3, device=device), wp.array(hi, dtype=wp.vec3, device=device))
    got = got.numpy().reshape(-1, 2).astype(np.int32)
    return got[np.lexsort((got[:, 1], got[:, 0]))]


@pytest.mark.parametrize("method", ["sap", "sap_sweep", "sap_all_pairs", "all_pairs"])
@pytest.mark.parametrize("dist", sorted(DISTRIBUTIONS))
def test_equals_numpy(device, method, dist):
    rng = np.random.default_rng(abs(hash(dist)) % 2**32)
    n = 200 if dist == "identical" else 1500
    lo, hi = DISTRIBUTIONS[dist](rng, n)
    got = pairs_of(method, lo, hi, device)
    want = box_pairs_numpy(lo, hi)
    assert got.dtype == np.int32 and got.shape[1] == 2
    assert np.array_equal(got, want), f"{dist}/{method}: {len(got)} pairs, truth {len(want)}"
    if dist in ("touching", "identical", "points"):
        assert len(want) > 0


def test_sap_key_bits():
    """16-bit keys (two radix passes) up to 16,384 boxes, wider keys above, never past 31 bits."""
    from warp_ccd._src.broadphase.grid import SMALL_SCENE_BOXES, sap_key_bits

    assert sap_key_bits(2) == sap_key_bits(1000) == sap_key_bits(SMALL_SCENE_BOXES) == (8, 8)
    assert sum(sap_key_bits(SMALL_SCENE_BOXES + 1)) > 16
    for n in (10**5, 10**6, 10**7, 2**31 - 1):
        cell_bits, q_bits = sap_key_bits(n)
        assert q_bits >= 8 and cell_bits + q_bits <= 31


@pytest.mark.parametrize("n", [16384, 16385])
def test_sap_either_side_of_16_bit_keys(device, n):
    rng = np.random.default_rng(n)
    lo, hi = boxes_random(rng, n, spread=40.0, size=(0.3, 2.0))
    assert np.array_equal(wc.stages.broad_phase_pairs(lo, hi, device=device), box_pairs_numpy(lo, hi))


@pytest.mark.parametrize("n", [0, 1, 2, 3])
def test_tiny_counts(device, n):
    rng = np.random.default_rng(n)
    lo, hi = boxes_random(rng, n, spread=0.1)
    for method in ("sap", "sap_sweep", "sap_all_pairs", "all_pairs"):
        got = pairs_of(method, lo.reshape(-1, 3), hi.reshape(-1, 3), device)
        assert np.array_equal(got.reshape(-1, 2), box_pairs_numpy(lo, hi).reshape(-1, 2))


def pairs_from_capacity_one(bp, wlo, whi, device):
    """Runs ``bp`` from a pair buffer of capacity 1 (and its own buffers as they are) until every
    buffer holds its items, growing them as the counters ask; returns ``(sorted pairs, runs)``."""
    from warp_ccd._src.runtime.buffers import CounterRead, GrowableBuffer

    pairs = GrowableBuffer(wp.vec2i, 1, device, "pairs")
    counters = CounterRead([pairs, *bp.counters], device)
    rounds = 0
    while True:
        rounds += 1
        pairs.reset()
        bp.launch(wlo, whi, pairs)
        counters.enqueue()
        if not counters.finish():
            break
    got = pairs.numpy(pairs.last_count)
    return got[np.lexsort((got[:, 1], got[:, 0]))], rounds


def test_capacity_one_is_complete(device):
    """Starting from buffers of capacity 1, every pair is still returned (buffers grow)."""
    rng = np.random.default_rng(3)
    lo, hi = boxes_clustered(rng, 800)
    want = box_pairs_numpy(lo, hi)
    wlo = wp.array(lo, dtype=wp.vec3, device=device)
    whi = wp.array(hi, dtype=wp.vec3, device=device)
    for bp in (wc.stages.BroadPhaseSAP(device=device, all_pairs_max=0),
               wc.stages.BroadPhaseSAP(device=device, all_pairs_max=800),
               BroadPhaseAllPairs(device=device)):
        for b in bp.counters:
            b._allocate(1)
        got, rounds = pairs_from_capacity_one(bp, wlo, whi, device)
        assert rounds >= 2
        assert np.array_equal(got, want)


def test_sap_grid_entries_grow(device):
    """Boxes that each cover a dozen grid cells need more entries than the buffer starts with:
    the frame grows it and runs again, and every pair is found."""
    rng = np.random.default_rng(11)
    tiny_lo, tiny_hi = boxes_random(rng, 3000, spread=5.0, size=(0.005, 0.015))
    mid_lo, mid_hi = boxes_random(rng, 600, spread=5.0, size=(2.45, 2.55))
    lo, hi = np.concatenate([tiny_lo, mid_lo]), np.concatenate([tiny_hi, mid_hi])
    bp = wc.stages.BroadPhaseSAP(device=device, all_pairs_max=0)
    bp._resize(len(lo))
    start = bp.entry.capacity  # the room it starts with
    got = bp.find_pairs(wp.array(lo, dtype=wp.vec3, device=device), wp.array(hi, dtype=wp.vec3, device=device))
    got = got.numpy().reshape(-1, 2)
    assert bp.entry.last_count > start and bp.entry.capacity > start  # it grew
    assert np.array_equal(got[np.lexsort((got[:, 1], got[:, 0]))], box_pairs_numpy(lo, hi))


def test_float64_input_rounds_outward(device):
    lo = np.array([[0.0, 0, 0], [1.0 + 1e-12, 0, 0]])
    hi = np.array([[1.0, 1, 1], [2.0, 1, 1]])
    # float32 cannot tell 1 + 1e-12 from 1: rounding outward keeps the pair (never loses one)
    assert wc.stages.broad_phase_pairs(lo, hi, device=device).tolist() == [[0, 1]]


@pytest.mark.parametrize(
    "lower, upper, match",
    [
        (np.zeros((2, 3)), np.ones((3, 3)), "shapes differ"),
        (np.zeros((2, 2)), np.ones((2, 2)), r"shape \(N, 3\)"),
        (np.array([[0, 0, np.nan], [0, 0, 0]]), np.ones((2, 3)), "box 0 is not finite"),
        (np.zeros((2, 3)), np.array([[1, 1, 1], [np.inf, 1, 1]]), "box 1 is not finite"),
        (np.array([[0, 0, 0], [2, 0, 0]]), np.ones((2, 3)), "box 1: lower"),
        (np.array([["a"] * 3] * 2), np.ones((2, 3)), "real numbers"),
    ],
)
def test_bad_input(lower, upper, match):
    with pytest.raises(ValueError, match=match):
        wc.stages.broad_phase_pairs(lower, upper)


@pytest.mark.parametrize("value", [-1, ALL_PAIRS_LIMIT + 1, 2.5, True, "all"])
def test_bad_all_pairs_max(value, device):
    with pytest.raises(ValueError, match="all_pairs_max"):
        wc.stages.BroadPhaseSAP(device=device, all_pairs_max=value)


def test_sap_all_pairs_below_the_limit(device):
    """Up to ``all_pairs_max`` boxes the SAP tests every pair in one launch (no grid entries), above
    it sweeps; frame after frame with one broad phase, sizes either side of the limit, the pairs are
    the numpy truth; CUDA's default limit is :data:`ALL_PAIRS_MAX`, the CPU's 0."""
    default = ALL_PAIRS_MAX if wp.get_device(device).is_cuda else 0
    assert wc.stages.BroadPhaseSAP(device=device).all_pairs_max == default
    rng = np.random.default_rng(17)
    bp = wc.stages.BroadPhaseSAP(device=device, all_pairs_max=400)
    for n in (400, 401, 2, 400):
        lo, hi = boxes_random(rng, n, spread=4.0, size=(0.2, 1.5))
        got = bp.find_pairs(wp.array(lo, dtype=wp.vec3, device=device), wp.array(hi, dtype=wp.vec3, device=device))
        got = got.numpy().reshape(-1, 2)
        assert np.array_equal(got[np.lexsort((got[:, 1], got[:, 0]))], box_pairs_numpy(lo, hi)), n
        assert (bp.entry.last_count == 0) == (n <= 400), n


def test_unknown_method():
    with pytest.raises(ValueError, match=r"^broad_phase must be one of \['all_pairs', 'nxn', 'sap'\], got 'bvh'$"):
        wc.stages.broad_phase_pairs(np.zeros((2, 3)), np.ones((2, 3)), method="bvh")


def test_nxn_is_an_alias_of_all_pairs(device):
    """``"nxn"`` names the all-pairs method too (the contract's name for it); no other old name remains."""
    import warp_ccd._src.broadphase.sap as broad_phase

    assert type(make_broad_phase("nxn", device=device)) is BroadPhaseAllPairs
    for gone in ("BroadPhaseNxN", "NXN_MAX_BOXES"):
        assert not hasattr(broad_phase, gone)


@pytest.mark.parametrize("method", ["sap", "all_pairs"])
def test_find_pairs_frame_after_frame(device, method):
    """A broad phase run alone, frame after frame (a CUDA graph on CUDA), finds the numpy truth as
    the boxes move and the pair buffer grows."""
    rng = np.random.default_rng(7)
    bp = make_broad_phase(method, device=device)
    lo = rng.uniform(0, 20, (800, 3)).astype(np.float32)
    lower = wp.array(lo, dtype=wp.vec3, device=device)
    upper = wp.array(lo + 1.0, dtype=wp.vec3, device=device)
    for k in range(5):
        lo = lo + np.float32(0.3 * k)
        size = np.float32(1.0 + k)  # more pairs each frame: the buffer grows
        lower.assign(lo)
        upper.assign(lo + size)
        got = bp.find_pairs(lower, upper).numpy().reshape(-1, 2)
        got = got[np.lexsort((got[:, 1], got[:, 0]))]
        assert np.array_equal(got, box_pairs_numpy(lo, lo + size))
    with pytest.raises(ValueError, match="lower"):
        bp.find_pairs(lo, upper)


def test_sap_statistics_last_block(device):
    """The statistics pass runs in several blocks, and the last block to finish lays out the grid:
    frame after frame (moving boxes), the sweep axis is that of greatest variance of the centres,
    the grid starts at the lowest box, every accumulator is empty again after the frame, and the
    pairs are the numpy truth."""
    from warp_ccd._src.geometry.box import BOX_EMPTY

    rng = np.random.default_rng(5)
    n = 9000  # three blocks on the CPU, 36 on CUDA
    bp = wc.stages.BroadPhaseSAP(device=device)
    lower = wp.empty(n, dtype=wp.vec3, device=device)
    upper = wp.empty(n, dtype=wp.vec3, device=device)
    for stretch in ((40.0, 10.0, 10.0), (10.0, 10.0, 40.0), (10.0, 40.0, 10.0)):
        lo, hi = boxes_random(rng, n, spread=1.0, size=(0.02, 0.2))
        lo, hi = lo * np.float32(stretch), hi * np.float32(stretch)
        lower.assign(lo)
        upper.assign(hi)
        got = bp.find_pairs(lower, upper).numpy().reshape(-1, 2)
        assert np.array_equal(got[np.lexsort((got[:, 1], got[:, 0]))], box_pairs_numpy(lo, hi))
        grid = bp.grid.numpy()[0]
        axis = int(np.argmax(stretch))
        assert grid["axis"] == axis
        ay = (axis + 1) % 3
        assert grid["origin_y"] == lo[:, ay].min()
        assert bp.blocks_done.numpy()[0] == 0
        assert (bp.stat_sum.numpy() == 0).all()
        assert (bp.stat_lo.numpy() == BOX_EMPTY).all() and (bp.stat_hi.numpy() == -BOX_EMPTY).all()


def test_find_pairs_box_sets_of_different_sizes(device):
    """One broad phase, two box arrays of different sizes in turn (a frame each, a graph each on
    CUDA): the scratch grows for the larger and serves the smaller, and each frame of either finds
    the numpy truth, also after the other grew the shared buffers."""
    rng = np.random.default_rng(21)
    bp = wc.stages.BroadPhaseSAP(device=device)
    sets = []
    for n, spread in ((500, 6.0), (3000, 10.0), (5000, 6.0)):
        lo, hi = boxes_random(rng, n, spread=spread, size=(0.2, 1.5))
        sets.append((lo, hi, wp.array(lo, dtype=wp.vec3, device=device), wp.array(hi, dtype=wp.vec3, device=device)))
    for k in (0, 1, 0, 2, 0, 1, 2, 0):
        lo, hi, lower, upper = sets[k]
        got = bp.find_pairs(lower, upper).numpy().reshape(-1, 2)
        assert np.array_equal(got[np.lexsort((got[:, 1], got[:, 0]))], box_pairs_numpy(lo, hi)), k


@pytest.mark.parametrize("method", ["sap", "all_pairs"])
@pytest.mark.parametrize("bad", [0, -1, 1.5, "3", True, 2**31])
def test_entry_capacity_checked_for_every_method(method, bad):
    """``entry_capacity`` is checked whichever broad phase takes it (the all-pairs one ignores a good one)."""
    with pytest.raises(ValueError, match="entry_capacity"):
        make_broad_phase(method, device=DEFAULT_DEVICE, entry_capacity=bad)
    make_broad_phase(method, device=DEFAULT_DEVICE, entry_capacity=8)
