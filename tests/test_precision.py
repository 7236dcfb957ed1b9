"""The precision guard's measures of a scene (:mod:`warp_ccd._src.geometry.precision`) against the
straightforward versions they replaced, kept here as references: the same float64 values bit for
bit, on seeded random scenes and on edge cases (empty shapes, degenerate triangles, ties, shapes
sampled above :data:`~warp_ccd._src.geometry.precision.SIZE_SAMPLE`, coordinates near underflow and
overflow)."""

import numpy as np
import pytest

from warp_ccd._src.geometry import precision
from warp_ccd._src.geometry.precision import shape_radius, triangle_size


def reference_shape_radius(vertices, vertex_start):
    """Every vertex's ``np.linalg.norm``, the largest of each shape."""
    start = np.asarray(vertex_start, np.int64)
    radius = np.zeros(len(start) - 1)
    if len(vertices):
        norm = np.linalg.norm(np.asarray(vertices, np.float64), axis=1)
        has = start[1:] > start[:-1]
        radius[has] = np.maximum.reduceat(norm, start[:-1][has])
    return radius


def reference_triangle_size(vertices, triangles, vertex_start, triangle_start, object_shape, object_scale=None,
                            sample=4096):
    """Every sampled triangle's edges, each shape's median by a full sort."""
    tri = np.asarray(triangles)
    tstart = np.asarray(triangle_start, np.int64)
    vstart = np.asarray(vertex_start, np.int64)
    inst = np.asarray(object_shape, np.int64)
    if not len(tri) or not inst.size:
        return 0.0
    tcount = np.diff(tstart)
    num_shapes = len(tcount)
    if tcount.max() > sample:
        taken = np.minimum(tcount, sample)
        owner = np.repeat(np.arange(num_shapes), taken)
        m = tcount[owner]
        j = np.arange(len(owner)) - (np.cumsum(taken) - taken)[owner]
        tri, tcount = tri[tstart[owner] + np.where(m > sample, (j * m) // sample, j)], taken
    else:
        owner = np.repeat(np.arange(num_shapes), tcount)
    v = np.asarray(vertices)
    corner = (tri + vstart[owner, None]).T
    x, y, z = (v[corner, k].astype(np.float64, copy=False) for k in range(3))

    def squared(i, j):
        return ((x[j] - x[i]) ** 2 + (y[j] - y[i]) ** 2) + (z[j] - z[i]) ** 2

    longest = np.sqrt(np.maximum(np.maximum(squared(0, 1), squared(1, 2)), squared(2, 0)))
    keep = longest > 0.0
    values, owner = longest[keep], owner[keep]
    count = np.bincount(owner, minlength=num_shapes)
    order = np.argsort(values)
    key = np.sort(owner[order] * len(values) + np.arange(len(values)))
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    median = np.zeros(num_shapes)
    has = count > 0
    median[has] = values[order[key[first[has] + (count[has] - 1) // 2] % len(values)]]
    scale = np.ones(inst.size) if object_scale is None else np.asarray(object_scale, np.float64)
    size = median[inst] * scale
    weight = count[inst]
    use = (size > 0.0) & (weight > 0)
    if not use.any():
        return 0.0
    size, weight = size[use], weight[use]
    by_size = np.argsort(size)
    cum = np.cumsum(weight[by_size])
    return float(size[by_size][np.searchsorted(cum, 0.5 * cum[-1])])


def random_shapes(rng, num_shapes, max_triangles, dtype, degenerate=0.0, magnitude=1.0, grid=None):
    """``(vertices, triangles, vertex_start, triangle_start)`` of random triangle soups, some shapes
    empty; ``degenerate``: the fraction of triangles whose corners are one vertex; ``grid``: coordinates
    rounded to it (many equal edges)."""
    vs, ts = [], []
    for _ in range(num_shapes):
        nv = int(rng.integers(0, 40)) if rng.random() < 0.1 else int(rng.integers(3, 200))
        nt = 0 if nv < 3 or rng.random() < 0.05 else int(rng.integers(1, max_triangles + 1))
        v = rng.normal(size=(nv, 3)) * rng.uniform(0.1, 10.0) * magnitude + rng.normal(size=3) * magnitude
        if grid is not None:
            v = np.round(v / grid) * grid
        t = rng.integers(0, max(nv, 1), size=(nt, 3))
        flat = rng.random(nt) < degenerate
        t[flat] = t[flat, :1]
        vs.append(v.astype(dtype))
        ts.append(t.astype(np.int32))
    vstart = np.concatenate([[0], np.cumsum([len(v) for v in vs])])
    tstart = np.concatenate([[0], np.cumsum([len(t) for t in ts])])
    return (np.concatenate(vs).reshape(-1, 3).astype(dtype), np.concatenate(ts).reshape(-1, 3), vstart, tstart)


CASES = [  # (num_shapes, max_triangles, dtype, degenerate, magnitude, grid)
    (1, 30, np.float32, 0.0, 1.0, None),
    (50, 30, np.float64, 0.0, 1.0, None),
    (200, 12, np.float32, 0.3, 1.0, None),
    (40, 300, np.float64, 0.05, 1e-3, None),
    (30, 100, np.float64, 0.0, 1.0, 0.25),  # ties: many equal edges and norms
    (20, 60, np.float64, 0.5, 1e-160, None),  # squares near float64's underflow
    (20, 60, np.float64, 0.0, 1e150, None),  # squares overflow to inf
    (8, 9000, np.float32, 0.02, 1.0, None),  # sampled above SIZE_SAMPLE
]


@pytest.mark.parametrize("case", range(len(CASES)))
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_measures_match_references(case, seed):
    num_shapes, max_triangles, dtype, degenerate, magnitude, grid = CASES[case]
    rng = np.random.default_rng(seed)
    v, t, vstart, tstart = random_shapes(rng, num_shapes, max_triangles, dtype, degenerate, magnitude, grid)
    with np.errstate(over="ignore", invalid="ignore"):
        got, want = shape_radius(v, vstart), reference_shape_radius(v, vstart)
        assert got.dtype == want.dtype and np.array_equal(got, want, equal_nan=True)
        for num_objects in (1, 3 * num_shapes):
            inst = rng.integers(0, num_shapes, num_objects)
            scale = rng.uniform(0.5, 2.0, num_objects)
            for s in (None, scale):
                got = triangle_size(v, t, vstart, tstart, inst, s)
                want = reference_triangle_size(v, t, vstart, tstart, inst, s)
                assert type(got) is float and (got == want or np.isnan(got) and np.isnan(want))


@pytest.mark.parametrize("sample", [1, 2, 3, 7, 64])
def test_sampled_medians_match_reference(monkeypatch, sample):
    """Small samples: every shape sampled, medians of 1 to 7 values, odd and even counts."""
    monkeypatch.setattr(precision, "SIZE_SAMPLE", sample)
    rng = np.random.default_rng(sample)
    v, t, vstart, tstart = random_shapes(rng, 60, 100, np.float64, degenerate=0.2, grid=0.5)
    inst = np.arange(60)
    assert triangle_size(v, t, vstart, tstart, inst) == reference_triangle_size(v, t, vstart, tstart, inst,
                                                                                sample=sample)


def test_edge_cases():
    v = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, -1]])
    t = np.array([[0, 1, 2], [3, 4, 5], [0, 0, 0]], np.int32)
    local = np.array([[0, 1, 2], [0, 1, 2], [0, 0, 0]], np.int32)
    for t, vstart, tstart, inst in ((local, [0, 3, 3, 6], [0, 1, 1, 3], [0, 1, 2]),  # a shape without vertices
                                    (t, [0, 6], [0, 3], [0, 0]),
                                    (local, [0, 3, 6], [0, 1, 3], [0, 1]),
                                    (local[1:], [0, 3, 6], [0, 1, 2], [1])):  # only a degenerate triangle: size 0
        vstart, tstart = np.array(vstart), np.array(tstart)
        assert np.array_equal(shape_radius(v, vstart), reference_shape_radius(v, vstart))
        assert triangle_size(v, t, vstart, tstart, inst) == reference_triangle_size(v, t, vstart, tstart, inst)
    assert triangle_size(v, t[2:], [0, 6], [0, 1], [0]) == 0.0
    assert triangle_size(v, t, [0, 6], [0, 3], []) == 0.0
    assert np.array_equal(shape_radius(np.zeros((0, 3)), [0, 0, 0]), np.zeros(2))
    assert np.array_equal(shape_radius(np.ones((4, 3)), [0, 0, 0]), np.zeros(2))  # vertices, but no shape has any
    nan = v.copy()
    nan[4, 1] = np.nan  # a NaN vertex makes its shape's radius NaN, as the norm did
    with np.errstate(invalid="ignore"):
        got, want = shape_radius(nan, np.array([0, 3, 6])), reference_shape_radius(nan, np.array([0, 3, 6]))
    assert np.array_equal(got, want, equal_nan=True) and np.isnan(got[1])
