"""Preview rendering: image shape, coloured pixels exactly where colliding objects are, files."""

import numpy as np
import pytest

import warp_ccd as wc
from warp_ccd._src.preview import mesh_triangle_indices
from warp_ccd.preview import PreviewRenderer, render_frame, save_preview


def reddish(img):
    """Pixels whose red clearly dominates (colliding objects; free ones and the sky are grey-blue)."""
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r > g + 60) & (r > b + 60)


def two_cubes(device, overlap):
    cube = wc.scene.shape("cube")
    m = np.tile(np.eye(4), (3, 1, 1))
    m[1, 0, 3] = 0.8 if overlap else 3.0
    m[2, 0, 3] = -4.0
    return wc.Scene.from_meshes([cube, cube, cube], m, device=device)


def test_mesh_triangle_indices_match_world_meshes(device):
    scene = wc.Scene.random(7, seed=2, device=device)
    indices, owner = mesh_triangle_indices(scene)
    world = scene.world_vertex.numpy()
    tris = world[indices.reshape(-1, 3)]
    start = 0
    for i, (v, t) in enumerate(scene.world_meshes()):
        np.testing.assert_array_equal(tris[start : start + len(t)], v[t])
        assert (owner[start : start + len(t)] == i).all()
        start += len(t)
    assert start == scene.num_triangles


def test_colliding_objects_are_coloured(device):
    scene = two_cubes(device, overlap=True)
    res = wc.CollisionPipeline(scene).detect()
    assert res.colliding.tolist() == [True, True, False]
    img = render_frame(scene, res, width=96, height=64)
    assert img.shape == (64, 96, 3) and img.dtype == np.uint8
    assert reddish(img).sum() > 50
    # The same frame without collision flags has no coloured pixel, but the objects are visible.
    plain = render_frame(scene, None, width=96, height=64)
    assert reddish(plain).sum() == 0
    changed = np.abs(plain.astype(int) - img.astype(int)).sum(axis=2) > 0
    assert (changed >= reddish(img)).all()  # colour only where the flags changed something
    assert (img[changed, 0] > img[changed, 1]).all()
    # Background gradient: the top row is lighter than the bottom row.
    assert plain[0].mean() > plain[-1].mean()


def test_free_objects_are_grey(device):
    scene = two_cubes(device, overlap=False)
    res = wc.CollisionPipeline(scene).detect()
    assert not res.colliding.any()
    img = PreviewRenderer(scene, 64, 48).render(res)
    assert reddish(img).sum() == 0
    sky = img[0, 0].astype(int)
    assert (np.abs(img.astype(int) - sky).sum(axis=2) > 30).sum() > 100  # objects stand out


def test_save_preview_png_and_gif(tmp_path):
    from PIL import Image

    frames = [np.full((20, 30, 3), k * 40, np.uint8) for k in range(4)]
    png = save_preview(frames[0], tmp_path / "a.png")
    with Image.open(png) as im:
        assert im.size == (30, 20)
    gif = save_preview(frames, tmp_path / "a.gif", fps=25)
    with Image.open(gif) as im:
        assert im.n_frames == 4 and im.info["duration"] == 40
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.gif", "a.png"]
    with pytest.raises(ValueError, match="extension"):
        save_preview(frames, tmp_path / "a.jpg")
    with pytest.raises(ValueError, match="does not exist"):
        save_preview(frames, tmp_path / "nope" / "a.png")
    with pytest.raises(ValueError, match="no frames"):
        save_preview([], tmp_path / "b.gif")
