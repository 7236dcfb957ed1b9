"""The touch step and the rare pairs in one launch: the touch kernel's threads past the touch rows
take the rare rows (degenerate or coplanar triangles). Verdicts against the whole of Möller's test
(``tri_tri_moller``) on crafted rare cases, mixed with touch rows or alone, at capacities that
the lists pass."""

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd import geometry
from warp_ccd._src.runtime.buffers import GrowableBuffer

wp.set_module_options({"enable_backward": False, "fuse_fp": False})

T = [[0, 0, 0], [2, 0, 0], [0, 2, 0]]
RARE = {  # triangle b against T: coplanar or degenerate pairs, all to the rare list
    "coplanar_overlap": [[0.5, 0.5, 0], [3, 0.5, 0], [0.5, 3, 0]],
    "coplanar_inside": [[0.25, 0.25, 0], [1, 0.25, 0], [0.25, 1, 0]],
    "coplanar_apart": [[3, 3, 0], [4, 3, 0], [3, 4, 0]],
    "coplanar_vertex_touch": [[2, 0, 0], [3, 0, 0], [3, 1, 0]],
    "coplanar_edge_touch": [[2, 0, 0], [0, 2, 0], [2, 2, 0]],
    "degenerate_segment_through": [[0.5, 0.5, -1], [0.5, 0.5, 0], [0.5, 0.5, 1]],
    "degenerate_segment_above": [[0.5, 0.5, 1], [0.5, 0.5, 2], [0.5, 0.5, 3]],
    "degenerate_point_on_face": [[0.5, 0.5, 0], [0.5, 0.5, 0], [0.5, 0.5, 0]],
    "degenerate_point_off": [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [0.5, 0.5, 0.5]],
}
COMMON = {  # not rare: a crossing, separated pairs, and pairs for the touch step
    "crossing": [[0.5, -1, -1], [0.5, 3, -1], [0.5, 0.5, 1]],
    "separated": [[0.5, -1, 1], [0.5, 3, 1], [0.5, 0.5, 3]],
    "vertex_on_face": [[0.5, 0.5, 0], [1, 0.5, 1], [0.5, 1, 1]],
    "edge_on_face": [[0.5, 0.5, 0], [1.0, 0.25, 0], [0.75, 0.5, 1]],
    "edge_edge": [[1, 1, -1], [1, 1, 1], [2, 2, 0]],
    "edge_edge_apart": [[1.0625, 1.0625, -1], [1.0625, 1.0625, 1], [2, 2, 0]],  # to the touch step, apart
    "vertex_above_face": [[0.5, 0.5, 0.0625], [1, 0.5, 1], [0.5, 1, 1]],
}


@wp.kernel
def _moller_reference_kernel(tri_a: wp.array2d[wp.vec3], tri_b: wp.array2d[wp.vec3], out: wp.array[wp.int32]):
    k = wp.tid()
    hit = geometry.tri_tri_moller(tri_a[k, 0], tri_a[k, 1], tri_a[k, 2], tri_b[k, 0], tri_b[k, 1], tri_b[k, 2],
                                  wp.float64(geometry.TOLERANCE))
    out[k] = wp.where(hit, 1, 0)


def reference(ta: np.ndarray, tb: np.ndarray, device) -> np.ndarray:
    """Verdicts of ``tri_tri_moller`` on the pairs ``(P, 3, 3)`` (float32)."""
    out = wp.zeros(len(ta), dtype=wp.int32, device=device)
    wp.launch(_moller_reference_kernel, dim=len(ta),
              inputs=[wp.array(ta, dtype=wp.vec3, device=device), wp.array(tb, dtype=wp.vec3, device=device)],
              outputs=[out], device=device)
    return out.numpy().astype(bool)


def near_contacts(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``n`` triangles b with a vertex within 1e-7 of a point of T's edge on the x axis, the rest
    below it: most decided by the touch step (its rows), most of those touching."""
    rng = np.random.default_rng(seed)
    p = np.stack([rng.uniform(0, 2, n), np.zeros(n), np.zeros(n)], 1) + rng.normal(size=(n, 3)) * 1e-7
    d = rng.normal(size=(n, 2, 3))
    d[:, :, 1] = -np.abs(d[:, :, 1])
    tb = np.stack([p, p + d[:, 0], p + d[:, 1]], 1).astype(np.float32)
    return np.broadcast_to(np.array(T, np.float32), tb.shape), tb


def pairs(names: list[str], offset=(0.0, 0.0, 0.0), near: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The cases ``names`` and ``near`` :func:`near_contacts` as triangle pairs, each also swapped,
    moved by ``offset``."""
    tb = np.array([{**RARE, **COMMON}[n] for n in names], np.float32).reshape(-1, 3, 3)
    ta = np.broadcast_to(np.array(T, np.float32), tb.shape)
    near_a, near_b = near_contacts(near)
    ta, tb = np.concatenate([ta, near_a]), np.concatenate([tb, near_b])
    shift = np.array(offset, np.float32)
    return np.concatenate([ta, tb]) + shift, np.concatenate([tb, ta]) + shift


def narrow_verdicts(ta: np.ndarray, tb: np.ndarray, device, touch_capacity: int = 1024, rare_capacity: int = 64):
    """Per-pair verdicts of :class:`NarrowPhase` (one object per triangle, candidate ``k`` = objects
    ``2k, 2k + 1``), its flags, and its touch and rare counts; the lists start at the given
    capacities and grow as a frame would grow them."""
    tri = np.array([[0, 1, 2]], np.int32)
    scene = wc.Scene.from_meshes([(t, tri) for pair in zip(ta, tb) for t in pair], device=device)
    m = len(ta)
    rows = np.stack([2 * np.arange(m), np.zeros(m), 2 * np.arange(m) + 1, np.zeros(m)], axis=1).astype(np.int32)
    candidates = GrowableBuffer(wp.vec4i, m, device, "candidates")
    candidates.data.assign(wp.array(rows, dtype=wp.vec4i, device=device))
    candidates.count.fill_(m)
    narrow = wc.stages.NarrowPhase(scene.num_objects, capacity=touch_capacity, device=device)  # hits, touch
    narrow.rare = GrowableBuffer(wp.vec4i, rare_capacity, device, "rare")
    while True:
        narrow.launch(scene, candidates)
        counts = [int(b.count.numpy()[0]) for b in (narrow.hits, narrow.touch, narrow.rare)]
        grew = [b.ensure(c) for b, c in zip((narrow.hits, narrow.touch, narrow.rare), counts)]
        if not any(grew):
            break
    hits = narrow.hits.numpy()
    got = np.zeros(m, bool)
    got[hits[:, 0] // 2] = True
    assert len(np.unique(hits[:, 0])) == len(hits)  # each pair once
    flags = narrow.object_colliding.numpy().astype(bool)
    return got, flags, narrow.touch.numpy()[:, 0] // 2, narrow.rare.numpy()[:, 0] // 2


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (1e3, -1e3, 1e3)])
def test_rare_rows_beside_touch_rows(device, offset):
    """Rare and touch rows in the same launch: every verdict is ``tri_tri_moller``'s, each object
    flagged when one of its pairs hits."""
    ta, tb = pairs(list(RARE) + list(COMMON), offset, near=24)
    got, flags, touch, rare = narrow_verdicts(ta, tb, device)
    expect = reference(ta, tb, device)
    assert np.array_equal(got, expect)
    assert np.array_equal(flags, np.repeat(expect, 2))
    assert len(rare) == 2 * len(RARE) and got[rare].any() and not got[rare].all()
    assert len(touch) > 0
    if offset == (0.0, 0.0, 0.0):  # far from the origin float32 rounds the near contacts away
        assert got[touch].any() and not got[touch].all()


def test_rare_rows_alone(device):
    """Only rare rows (the touch list empty): the threads past the touch rows still take them."""
    ta, tb = pairs(list(RARE))
    got, flags, touch, rare = narrow_verdicts(ta, tb, device)
    assert len(touch) == 0 and len(rare) == len(ta)
    expect = reference(ta, tb, device)
    assert np.array_equal(got, expect) and expect.any() and not expect.all()
    assert np.array_equal(flags, np.repeat(expect, 2))


def test_lists_past_their_capacity(device):
    """Touch and rare lists of one slot each: the first launch counts past both capacities (the
    rare threads start after the touch rows' capacity and read no row beyond their own); grown,
    the verdicts are the test's."""
    ta, tb = pairs(list(RARE) + list(COMMON) + list(RARE), near=24)
    got, flags, touch, rare = narrow_verdicts(ta, tb, device, touch_capacity=1, rare_capacity=1)
    expect = reference(ta, tb, device)
    assert np.array_equal(got, expect)
    assert np.array_equal(flags, np.repeat(expect, 2))
    assert len(touch) > 1 and len(rare) > 1
