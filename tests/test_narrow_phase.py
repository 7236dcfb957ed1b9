"""Triangle tests against crafted cases, each other, and Warp's float64 built-in."""

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd import geometry
from warp_ccd._src.geometry.precision import precision_types
from warp_ccd._src.geometry.triangle import TOLERANCE, tri_tri_batch_kernel
from warp_ccd._src.narrowphase.discrete import NARROW_METHODS
from warp_ccd._src.runtime.buffers import GrowableBuffer

from oracles import intersect_tri_tri_f64

# As a user's module that calls the exact tests should be compiled: forward only (the tests have
# no gradient, and their adjoint takes minutes to compile for CUDA), no FMA contraction (the same
# verdict on every device).
wp.set_module_options({"enable_backward": False, "fuse_fp": False})


def run_test(ta, tb, device, method="moller", tol=TOLERANCE, precision="float32"):
    """Verdicts of ``tri_tri_batch_kernel`` on pairs ``(P, 3, 3)``, computed in ``precision``."""
    _, vec3, _, _ = precision_types(precision)
    dtype = np.dtype(precision)
    ta = np.asarray(ta, dtype).reshape(-1, 3, 3)
    tb = np.asarray(tb, dtype).reshape(-1, 3, 3)
    out = wp.zeros(len(ta), dtype=wp.int32, device=device)
    wp.launch(
        tri_tri_batch_kernel,
        dim=len(ta),
        inputs=[wp.array(ta, dtype=vec3, device=device), wp.array(tb, dtype=vec3, device=device),
                NARROW_METHODS[method], wp.float64(tol)],
        outputs=[out],
        device=device,
    )
    return out.numpy().astype(bool)


T1 = [[0, 0, 0], [2, 0, 0], [0, 2, 0]]
CASES = {
    "crossing": ([[0.5, -1, -1], [0.5, 3, -1], [0.5, 0.5, 1]], True),
    "separated": ([[0.5, -1, 1], [0.5, 3, 1], [0.5, 0.5, 3]], False),
    "piercing_edge_only": ([[2.5, -1, -1], [2.5, 3, -1], [2.5, 0.5, 1]], False),
    "vertex_on_vertex": ([[0, 0, 0], [1, 0, 1], [0, 1, 1]], True),
    "vertex_on_face": ([[0.5, 0.5, 0], [1, 0.5, 1], [0.5, 1, 1]], True),
    "vertex_above_face": ([[0.5, 0.5, 0.0625], [1, 0.5, 1], [0.5, 1, 1]], False),
    "shared_edge": ([[0, 0, 0], [2, 0, 0], [1, -1, -1]], True),
    "edge_on_face": ([[0.5, 0.5, 0], [1.0, 0.25, 0], [0.75, 0.5, 1]], True),
    "edge_edge": ([[1, 1, -1], [1, 1, 1], [2, 2, 0]], True),
    "edge_edge_apart": ([[1.0625, 1.0625, -1], [1.0625, 1.0625, 1], [2, 2, 0]], False),
    "coplanar_overlap": ([[0.5, 0.5, 0], [3, 0.5, 0], [0.5, 3, 0]], True),
    "coplanar_contained": ([[0.25, 0.25, 0], [0.75, 0.25, 0], [0.25, 0.75, 0]], True),
    "coplanar_containing": ([[-1, -1, 0], [5, -1, 0], [-1, 5, 0]], True),
    "coplanar_disjoint": ([[3, 3, 0], [4, 3, 0], [3, 4, 0]], False),
    "coplanar_vertex_touch": ([[2, 0, 0], [3, 0, 0], [3, 1, 0]], True),
    "coplanar_edge_touch": ([[2, 0, 0], [0, 2, 0], [2, 2, 0]], True),
    "coplanar_near_miss": ([[2.0625, 0, 0], [3, 0, 0], [3, 1, 0]], False),
    "parallel_planes": ([[0, 0, 0.5], [2, 0, 0.5], [0, 2, 0.5]], False),
    "identical": (T1, True),
    # A degenerate triangle is the segment or point it spans (tests/test_degenerate.py has more).
    "degenerate_collinear_crossing": ([[0.5, 0.5, -1], [0.5, 0.5, 1], [0.5, 0.5, 0]], True),
    "degenerate_collinear_beside": ([[2.5, 0.5, -1], [2.5, 0.5, 1], [2.5, 0.5, 0]], False),
    "degenerate_point": ([[0.5, 0.5, 0], [0.5, 0.5, 0], [0.5, 0.5, 0]], True),
    "degenerate_point_above": ([[0.5, 0.5, 0.0625], [0.5, 0.5, 0.0625], [0.5, 0.5, 0.0625]], False),
    "degenerate_repeated_vertex": ([[0.5, 0.5, -1], [0.5, 0.5, -1], [0.5, 0.5, 1]], True),
    "degenerate_in_plane": ([[-1, 0.5, 0], [3, 0.5, 0], [1, 0.5, 0]], True),
}
NAMES = sorted(CASES)


def crafted(offset=(0.0, 0.0, 0.0), scale=1.0):
    ta = np.array([T1] * len(NAMES), np.float64) * scale + offset
    tb = np.array([CASES[n][0] for n in NAMES], np.float64) * scale + offset
    expect = np.array([CASES[n][1] for n in NAMES])
    return ta, tb, expect


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("method", sorted(NARROW_METHODS))
@pytest.mark.parametrize(
    "offset, scale",
    [((0, 0, 0), 1.0), ((1e4, -1e4, 1e4), 1.0), ((0, 0, 0), 1e-4), ((3e-4, 1e-4, -2e-4), 1e-4), ((0, 0, 0), 1e3)],
    ids=["unit", "far", "tiny", "tiny_offset", "huge"],
)
def test_crafted_cases(device, method, offset, scale, precision):
    ta, tb, expect = crafted(offset, scale)
    got = run_test(ta, tb, device, method, precision=precision)
    wrong = [n for n, g, e in zip(NAMES, got, expect) if g != e]
    assert not wrong, f"{method} {precision}: wrong answers for {wrong}"
    # symmetric: swapping the triangles, and cycling a triangle's vertices, change nothing
    assert (run_test(tb, ta, device, method, precision=precision) == expect).all()
    assert (run_test(ta[:, [1, 2, 0]], tb[:, [2, 0, 1]], device, method, precision=precision) == expect).all()


def test_crafted_cases_match_warp_float64(device):
    """The crafted truths agree with Warp's float64 test where it has no snapping issue."""
    ta, tb, expect = crafted(scale=10.0)
    degenerate = np.array([n.startswith("degenerate") for n in NAMES])
    got = intersect_tri_tri_f64(ta, tb, device=device)
    assert (got[~degenerate] == expect[~degenerate]).all()


def random_pairs(rng, n):
    ta = rng.uniform(-1, 1, size=(n, 3, 3))
    tb = rng.uniform(-1, 1, size=(n, 3, 3)) + rng.uniform(-0.5, 0.5, size=(n, 1, 3))
    return ta.astype(np.float32), tb.astype(np.float32)


def test_random_pairs_agree(device):
    """Möller, edge-face and Warp's float64 test agree on 10^5 random pairs away from the band."""
    rng = np.random.default_rng(7)
    ta, tb = random_pairs(rng, 100_000)
    res = {
        (m, tol): run_test(ta, tb, device, m, tol)
        for m in NARROW_METHODS
        for tol in (0.0, 1e-3)
    }
    # A pair is in the tolerance band when some test changes its answer between the tolerances
    # (no tolerance at all, and 100 times the default).
    stable = np.ones(len(ta), bool)
    for m in NARROW_METHODS:
        stable &= res[(m, 0.0)] == res[(m, 1e-3)]
    assert stable.mean() > 0.99
    moller = run_test(ta, tb, device, "moller")
    edge_face = run_test(ta, tb, device, "edge_face")
    assert np.array_equal(moller[stable], edge_face[stable])
    oracle = intersect_tri_tri_f64(ta.astype(np.float64) * 10.0, tb.astype(np.float64) * 10.0, device=device)
    assert np.array_equal(moller[stable], oracle[stable])
    assert 0.2 < moller.mean() < 0.8  # the sample holds both answers


def test_random_pairs_far_and_scaled(device):
    """Translation by 1e4 and scaling by 1e-4 keep the answers away from the band."""
    rng = np.random.default_rng(8)
    ta, tb = random_pairs(rng, 20_000)
    base = run_test(ta, tb, device)
    stable = base == run_test(ta, tb, device, tol=1e-2)
    for off, s in [((1e4, 1e4, -1e4), 1.0), ((0, 0, 0), 1e-4)]:
        got = run_test(ta.astype(np.float64) * s + off, tb.astype(np.float64) * s + off, device)
        mismatch = (got != base) & stable
        assert mismatch.mean() < 1e-3, f"offset {off} scale {s}: {mismatch.sum()} changed"


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("method", sorted(NARROW_METHODS))
def test_nearly_parallel_but_apart(device, method, precision):
    """Two nearly parallel triangles side by side, about 16,000 tolerances apart: their parts within
    eps of each other's plane do not lie on one line, so they must not be projected onto one."""
    a = [[0, 0, 0], [3, 0, 0], [0, 1, 0]]
    b = [[-0.5, 0, -1e-5], [-0.5, 1, -1e-5], [-3, 0.5, -6e-5]]
    touching = [[-0.5 + 1e-6, 0.5, 0], [-0.5, 1, -1e-5], [-3, 0.5, -6e-5]]  # b moved to a's edge line
    touching[0][0] = 0.0
    got = run_test([a, b, a, touching], [b, a, touching, a], device, method, precision=precision)
    assert got.tolist() == [False, False, True, True]


def near_parallel_pairs(rng, n, lift=0.0):
    """Triangle b tilted by 1e-6..1e-3 rad from triangle a's plane, through a's centroid, which lies
    deep inside both: every pair intersects (``lift`` = 0), or lies wholly above a's plane."""
    ta = np.zeros((n, 3, 3))
    ta[:, :, :2] = rng.uniform(-1, 1, size=(n, 3, 2))
    area = np.cross(ta[:, 1] - ta[:, 0], ta[:, 2] - ta[:, 0])[:, 2]
    keep = np.abs(area) > 0.3
    ta = ta[keep]
    m = len(ta)
    centre = ta.mean(axis=1)
    ang = rng.uniform(0, 2 * np.pi, size=(m, 1)) + np.array([0.0, 2.0, 4.0]) * np.pi / 3
    tb = np.stack([0.3 * np.cos(ang), 0.3 * np.sin(ang), np.zeros_like(ang)], axis=2)
    tilt = 10.0 ** rng.uniform(-6, -3, size=m)
    axis = rng.uniform(0, 2 * np.pi, size=m)
    u = np.stack([np.cos(axis), np.sin(axis)], 1)  # tilt about the in-plane axis u
    along = tb[:, :, 0] * -u[:, None, 1] + tb[:, :, 1] * u[:, None, 0]  # coordinate across the axis
    tb[:, :, 2] = along * np.sin(tilt)[:, None] + lift
    tb += centre[:, None, :]
    # rigid motion of both, so that no plane is axis-aligned
    from test_robustness import random_rotations

    r = random_rotations(rng, m)
    return np.einsum("nij,nkj->nki", r, ta), np.einsum("nij,nkj->nki", r, tb)


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("method", sorted(NARROW_METHODS))
def test_near_parallel_crossings(device, method, precision):
    """Snapping vertices within the tolerance to a nearly parallel plane must not lose a crossing."""
    rng = np.random.default_rng(17)
    ta, tb = near_parallel_pairs(rng, 20_000)
    got = run_test(ta, tb, device, method, precision=precision)
    assert got.all(), f"{(~got).sum()} of {len(got)} intersecting pairs missed"
    ta, tb = near_parallel_pairs(rng, 20_000, lift=2e-3)
    assert not run_test(ta, tb, device, method, precision=precision).any()


@wp.kernel
def _user_float64_kernel(tri_a: wp.array2d[wp.vec3d], tri_b: wp.array2d[wp.vec3d], out: wp.array2d[wp.int32]):
    """A user's own kernel: float64 vertices, the tolerance in float64 or a float32 literal."""
    k = wp.tid()
    a0, a1, a2 = tri_a[k, 0], tri_a[k, 1], tri_a[k, 2]
    b0, b1, b2 = tri_b[k, 0], tri_b[k, 1], tri_b[k, 2]
    out[k, 0] = wp.where(geometry.tri_tri_moller(a0, a1, a2, b0, b1, b2, wp.float64(geometry.TOLERANCE)), 1, 0)
    out[k, 1] = wp.where(geometry.tri_tri_edge_face(a0, a1, a2, b0, b1, b2, 1.0e-5), 1, 0)


def test_tests_called_from_a_user_kernel(device):
    """The public tests take either precision, and a tolerance of the other one."""
    ta, tb, expect = crafted(offset=(1e8, -3e8, 2e8))
    out = wp.zeros((len(ta), 2), dtype=wp.int32, device=device)
    wp.launch(_user_float64_kernel, dim=len(ta), inputs=[wp.array(ta, dtype=wp.vec3d, device=device),
              wp.array(tb, dtype=wp.vec3d, device=device)], outputs=[out], device=device)
    got = out.numpy().astype(bool)
    assert np.array_equal(got[:, 0], expect) and np.array_equal(got[:, 1], expect)


@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_narrow_phase_kernels_match_the_test(device, precision):
    """The pipeline's three kernels of Möller's test (steps 1 to 3, the touch step, the rare pairs:
    degenerate or coplanar) give the verdicts of the whole test, pair for pair, on the crafted
    cases, swapped and far from the origin."""
    ta, tb, expect = crafted()
    far_a, far_b, _ = crafted(offset=(1e4, -1e4, 1e4))
    ta, tb = np.concatenate([ta, tb, far_a]), np.concatenate([tb, ta, far_b])
    tri = np.array([[0, 1, 2]], np.int32)
    meshes = [(t, tri) for pair in zip(ta, tb) for t in pair]
    scene = wc.Scene.from_meshes(meshes, device=device, precision=precision)
    m = len(ta)
    rows = np.stack([2 * np.arange(m), np.zeros(m), 2 * np.arange(m) + 1, np.zeros(m)], axis=1).astype(np.int32)
    candidates = GrowableBuffer(wp.vec4i, m, device, "candidates")
    candidates.data.assign(wp.array(rows, dtype=wp.vec4i, device=device))
    candidates.count.fill_(m)
    narrow = wc.stages.NarrowPhase(scene.num_objects, device=device)
    narrow.launch(scene, candidates)
    hits = narrow.hits.numpy()
    got = np.zeros(m, bool)
    got[hits[:, 0] // 2] = True
    assert np.array_equal(got, run_test(ta, tb, device, precision=precision))
    assert narrow.rare.count.numpy()[0] > 0 and narrow.touch.count.numpy()[0] > 0
