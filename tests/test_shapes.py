import numpy as np
import pytest

import warp_ccd as wc
from warp_ccd._src.scene import shapes

ALL = [*shapes.SHAPES, "icosphere0", "icosphere1", "icosphere3"]


@pytest.mark.parametrize("name", ALL)
def test_shape_is_unit_and_outward(name):
    v, t = wc.scene.shape(name)
    assert v.dtype == np.float32 and t.dtype == np.int32
    assert v.ndim == 2 and v.shape[1] == 3 and t.ndim == 2 and t.shape[1] == 3
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-6)
    a, b, c = (v[t[:, k]].astype(np.float64) for k in range(3))
    normal = np.cross(b - a, c - a)
    assert (np.linalg.norm(normal, axis=1) > 1e-3).all()
    if name == "triangle":
        assert normal[0, 2] > 0
        return
    # outward winding, closed and consistently oriented: every directed edge appears once, reversed once
    assert (np.einsum("ij,ij->i", normal, a + b + c) > 0).all()
    edges = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    directed = set(map(tuple, edges))
    assert len(directed) == len(edges)
    assert all((j, i) in directed for i, j in directed)
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6
    assert 0.4 < volume < 4.19


def test_counts():
    names = ("tetrahedron", "cube", "octahedron", "dodecahedron", "icosahedron")
    assert [len(wc.scene.shape(s)[1]) for s in names] == [
        4, 12, 8, 36, 20]
    assert [len(wc.scene.icosphere(k)[1]) for k in range(5)] == [20, 80, 320, 1280, 5120]


def test_unknown_shape():
    with pytest.raises(ValueError, match="unknown shape"):
        wc.scene.shape("torus")
    with pytest.raises(ValueError, match="level"):
        wc.scene.icosphere(-1)


@pytest.mark.parametrize(
    "vertices, triangles, match",
    [
        ([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]], [[0, 1, 2]], "vertex 2 is not finite"),
        ([[0, 0, 0], [1, 0, 0], [np.inf, 1, 0]], [[0, 1, 2]], "not finite"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]], "out of range"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, -1, 2]], "out of range"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.zeros((0, 3), np.int32), "no triangles"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0.0, 1.0, 2.0]], "integer"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1]], r"shape \(m, 3\)"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [0, 1, 2], r"shape \(m, 3\)"),
        ([[0, 0], [1, 0], [0, 1]], [[0, 1, 2]], r"shape \(n, 3\)"),
        ([["a", "b", "c"]] * 3, [[0, 1, 2]], "real numbers"),
        ([[0, 0, 0], [1, 0, 0]], [[0, 1, 1]], "at least 3"),
        ([[0, 0, 0], [1, 0, 0], [0, 1e39, 0]], [[0, 1, 2]], "overflow"),
    ],
)
def test_validate_mesh_rejects(vertices, triangles, match):
    with pytest.raises(ValueError, match=match) as err:
        wc.scene.validate_mesh(vertices, triangles, name="mesh 7")
    assert "mesh 7" in str(err.value)


def test_validate_mesh_accepts_int64_and_float64():
    v, t = wc.scene.validate_mesh(np.eye(3, dtype=np.float64), np.array([[0, 1, 2]], np.int64))
    assert v.dtype == np.float32 and t.dtype == np.int32
