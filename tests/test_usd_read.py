"""The bulk transform read (``warp_ccd._src.usd.xforms``) against ``UsdGeom.XformCache``, and the import with it and
without it.

Every case compares the world matrices that :func:`~warp_ccd._src.usd.xforms.read_world_matrices` composes with one
``XformCache`` lookup per prim and time code (within 1e-12 of the matrix's size), at time codes on samples,
between them, before the first and after the last: every op type in double, float and half precision, inverse
ops and pivots, ``resetXformStack``, animated parents over static children, layer offsets of sublayers and
references, held and linear interpolation, defaults over weaker samples, value clips and value blocks (which
fall back), a seeded random stage of random op stacks; and checks which prims the bulk read took. The import
(``UsdMeshImport``) gives the same poses and world vertices with the bulk read as without it
(:data:`~warp_ccd._src.usd.xforms.FAST_XFORMS` off), in this process and in worker processes; the batched mesh read
gives what the one-by-one read gives.
"""

import os

import numpy as np
import pytest

from warp_ccd._src.usd import xforms
from warp_ccd._src.usd.importer import UsdMeshImport
from warp_ccd._src.usd.meshes import read_mesh, read_meshes
from warp_ccd._src.usd.xforms import read_world_matrices

pxr = pytest.importorskip("pxr")
from pxr import Gf, Sdf, Usd, UsdGeom  # noqa: E402
from usd_stages import define_mesh, mixed_stage, prism  # noqa: E402

from conftest import DEFAULT_DEVICE  # noqa: E402

SAMPLES = [0.0, 1.0, 2.6, 4.0]
TIMES = np.array([-2.0, 0.0, 0.25, 1.0, 1.5, 2.6, 3.1, 4.0, 5.5])  # before, on, between and after the samples
OP_TYPES = ["translate", "translateX", "translateY", "translateZ", "scale", "scaleX", "scaleY", "scaleZ", "rotateX",
            "rotateY", "rotateZ", "rotateXYZ", "rotateXZY", "rotateYXZ", "rotateYZX", "rotateZXY", "rotateZYX",
            "orient", "transform"]
PRECISIONS = {"double": (Gf.Vec3d, Gf.Quatd), "float": (Gf.Vec3f, Gf.Quatf), "half": (Gf.Vec3h, Gf.Quath)}


def cache_matrices(stage, prims, times) -> np.ndarray:
    """``(F, P, 4, 4)`` world matrices, one ``XformCache`` lookup per prim and time code."""
    return np.array([[np.array(UsdGeom.XformCache(Usd.TimeCode(float(t))).GetLocalToWorldTransform(p))
                      for p in prims] for t in times])


def assert_bulk_matches(stage, paths, times=TIMES, fast=None) -> np.ndarray:
    """The bulk read of ``paths`` equals ``XformCache`` within 1e-12 of each matrix's size; returns which prims
    it read in bulk (checked against ``fast`` when given)."""
    prims = [stage.GetPrimAtPath(p) for p in paths]
    got, bulk = read_world_matrices(stage, prims, np.asarray(times, np.float64))
    want = cache_matrices(stage, prims, times)
    size = np.maximum(1.0, np.abs(want).max(axis=(2, 3), keepdims=True))
    err = (np.abs(got - want) / size).max(axis=(0, 2, 3))
    bad = [(p, float(e)) for p, e in zip(paths, err) if not e <= 1e-12]
    assert not bad, f"bulk read differs from XformCache: {bad}"
    if fast is not None:
        assert dict(zip(paths, bulk.tolist())) == dict(zip(paths, fast))
    return bulk


def op_value(op_type: str, precision: str, rng, k: int):
    """A value for sample ``k`` of an op: non-unit and near-identity quaternions at samples 1 and 2."""
    vec, quat = PRECISIONS[precision]
    if op_type == "transform":
        q = rng.normal(size=4)
        m = Gf.Matrix4d().SetRotate(Gf.Quatd(*(q / np.linalg.norm(q)))) * Gf.Matrix4d().SetScale(rng.uniform(0.5, 2))
        return m.SetTranslateOnly(Gf.Vec3d(*rng.uniform(-3, 3, 3)))
    if op_type == "orient":
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        if k == 1:
            q *= 1.3
        elif k == 2:
            q = np.array([np.cos(5e-6), np.sin(5e-6), 0.0, 0.0])
        return quat(*map(float, q))
    low, high = (0.5, 2.0) if op_type.startswith("scale") else (-170.0, 170.0) if op_type.startswith("rotate") \
        else (-3.0, 3.0)
    if op_type in ("translate", "scale") or op_type.startswith("rotate") and len(op_type) == 9:
        return vec(*map(float, rng.uniform(low, high, 3)))
    return float(rng.uniform(low, high))


def add_op(xf, op_type: str, precision: str, rng, animated: bool, inverse: bool = False, suffix: str = ""):
    """Adds an op to ``xf``, time-sampled at :data:`SAMPLES` or static."""
    op = xf.AddXformOp(getattr(UsdGeom.XformOp, "Type" + op_type[0].upper() + op_type[1:]),
                       getattr(UsdGeom.XformOp, "Precision" + precision.capitalize()), suffix, inverse)
    attr = op.GetAttr()  # an inverse op's value is its attribute's
    if animated:
        for k, t in enumerate(SAMPLES):
            attr.Set(op_value(op_type, precision, rng, k), t)
    else:
        attr.Set(op_value(op_type, precision, rng, 0))
    return op


@pytest.mark.parametrize("precision", ["double", "float", "half"])
@pytest.mark.parametrize("op_type", OP_TYPES)
def test_every_op_type_and_precision(op_type, precision):
    """Each op animated and static, plain and inverse, under an animated translate: half values that need
    interpolating fall back; everything else is read in bulk and equals XformCache."""
    if op_type == "transform" and precision != "double":
        pytest.skip("a transform op is double only")
    rng = np.random.default_rng(OP_TYPES.index(op_type))
    stage = Usd.Stage.CreateInMemory()
    paths, fast = [], []
    for animated in (True, False):
        for inverse in (False, True):
            xf = UsdGeom.Xform.Define(stage, f"/W/{'anim' if animated else 'static'}{'_inv' if inverse else ''}")
            add_op(xf, "translate", "double", rng, animated=True)
            add_op(xf, op_type, precision, rng, animated, inverse, suffix="op")
            paths.append(str(xf.GetPath()))
            fast.append(not (animated and precision == "half") and not (inverse and op_type[:-1] == "scale"))
    assert_bulk_matches(stage, paths, fast=fast)


def test_pivots_and_inverse_pairs():
    """A pivot (translate:pivot ... !invert!translate:pivot) around animated ops, and a pivot next to its own
    inverse (USD skips the pair)."""
    rng = np.random.default_rng(1)
    stage = Usd.Stage.CreateInMemory()
    a = UsdGeom.Xform.Define(stage, "/W/Pivoted")
    add_op(a, "translate", "double", rng, True)
    add_op(a, "translate", "float", rng, False, suffix="pivot")
    add_op(a, "rotateXYZ", "float", rng, True)
    add_op(a, "scale", "float", rng, True)
    add_op(a, "translate", "float", rng, False, inverse=True, suffix="pivot")
    b = UsdGeom.Xform.Define(stage, "/W/Adjacent")
    add_op(b, "orient", "float", rng, True)
    add_op(b, "translate", "double", rng, True, suffix="pivot")
    add_op(b, "translate", "double", rng, True, inverse=True, suffix="pivot")
    add_op(b, "scale", "double", rng, False)
    assert_bulk_matches(stage, ["/W/Pivoted", "/W/Adjacent"], fast=[True, True])


def test_hierarchies_resets_and_fallbacks():
    """An animated prim between static ones (its parent's world and the static ops below it, once), the stack
    reset on the animated prim, below it and above it, and two animated prims in one chain (falls back)."""
    rng = np.random.default_rng(2)
    stage = Usd.Stage.CreateInMemory()

    def xform(path, *ops, reset=False):
        xf = UsdGeom.Xform.Define(stage, path)
        for op_type, animated in ops:
            add_op(xf, op_type, "double", rng, animated)
        if reset:
            xf.SetResetXformStack(True)
        return path

    xform("/G", ("translate", False), ("rotateY", False), ("scale", False))
    xform("/G/A", ("translate", True), ("orient", True))
    xform("/G/A/C", ("rotateZ", False), ("translate", False))
    child = xform("/G/A/C/M", ("scale", False))
    plain = xform("/G/A/P")
    reset_a = xform("/G/R", ("translate", True), ("rotateX", True), reset=True)
    under_reset = xform("/G/R/Below", ("translate", False))
    reset_below = xform("/G/A/Reset", ("translate", False), reset=True)
    two = xform("/G/A/B", ("translate", True))
    two_child = xform("/G/A/B/M")
    static = xform("/G/S", ("translate", False))
    paths = [child, plain, reset_a, under_reset, reset_below, two, two_child, static]
    assert_bulk_matches(stage, paths, fast=[True, True, True, True, True, False, False, True])


def test_layer_offsets_of_sublayers_and_references(tmp_path):
    """Samples in a sublayer under an offset and scale, in a referenced prim under another, and a reference
    to a prim of the sublayer (both offsets), at stage time codes mapped onto and between their samples."""
    rng = np.random.default_rng(3)
    sub = Usd.Stage.CreateNew(str(tmp_path / "sub.usda"))
    src = UsdGeom.Xform.Define(sub, "/Src")
    add_op(src, "translate", "double", rng, True)
    add_op(src, "orient", "float", rng, True)
    add_op(src, "scale", "float", rng, False)
    sub.GetRootLayer().Save()
    root = Sdf.Layer.CreateNew(str(tmp_path / "root.usda"))
    root.subLayerPaths.append("sub.usda")
    root.subLayerOffsets[0] = Sdf.LayerOffset(10.0, 2.0)
    root.Save()
    stage = Usd.Stage.Open(root)
    ref = UsdGeom.Xform.Define(stage, "/Ref")
    ref.GetPrim().GetReferences().AddInternalReference("/Src", Sdf.LayerOffset(-3.0, 0.5))
    local = UsdGeom.Xform.Define(stage, "/Local")
    add_op(local, "rotateZ", "float", rng, True)
    other = UsdGeom.Xform.Define(stage, "/Other")
    other.GetPrim().GetReferences().AddInternalReference("/Local", Sdf.LayerOffset(4.0, 1.5))
    times = np.concatenate([np.arange(-6.0, 22.0, 0.75), [10.0, 12.0, 15.2, 18.0]])
    assert_bulk_matches(stage, ["/Src", "/Ref", "/Local", "/Other"], times, fast=[True] * 4)


@pytest.mark.parametrize("held", [False, True])
def test_linear_and_held_interpolation(held):
    rng = np.random.default_rng(4)
    stage = Usd.Stage.CreateInMemory()
    if held:
        stage.SetInterpolationType(Usd.InterpolationTypeHeld)
    paths = []
    for precision in ("double", "float"):
        xf = UsdGeom.Xform.Define(stage, f"/W/{precision}")
        for op_type in ("translate", "orient", "rotateYZX", "scale"):
            add_op(xf, op_type, precision, rng, True)
        paths.append(str(xf.GetPath()))
    times = np.linspace(-1.0, 5.0, 61)
    assert_bulk_matches(stage, paths, times, fast=[True, True])


def test_defaults_static_ops_and_samples_in_several_layers(tmp_path):
    """A stronger layer's default over a weaker layer's samples (static), a static op in one layer and the
    samples of another op in another, samples of one op in a stronger layer and of another in a weaker."""
    rng = np.random.default_rng(5)
    weak = Usd.Stage.CreateNew(str(tmp_path / "weak.usda"))
    xf = UsdGeom.Xform.Define(weak, "/X")
    add_op(xf, "translate", "double", rng, True)
    add_op(xf, "orient", "float", rng, True)
    add_op(xf, "scale", "float", rng, True)
    weak.GetRootLayer().Save()
    root = Sdf.Layer.CreateNew(str(tmp_path / "root.usda"))
    root.subLayerPaths.append("weak.usda")
    root.Save()
    stage = Usd.Stage.Open(root)
    prim = stage.GetPrimAtPath("/X")
    prim.GetAttribute("xformOp:scale").Set(Gf.Vec3f(1.5, 0.5, 2.0))  # a default over the weaker samples
    orient = prim.GetAttribute("xformOp:orient")
    for k, t in enumerate([0.5, 3.5]):  # stronger samples of another op
        orient.Set(op_value("orient", "float", rng, 3 * k), t)
    assert not prim.GetAttribute("xformOp:scale").ValueMightBeTimeVarying()
    assert_bulk_matches(stage, ["/X"], fast=[True])


def test_value_clips_and_value_blocks_fall_back(tmp_path):
    rng = np.random.default_rng(6)
    clip = Usd.Stage.CreateNew(str(tmp_path / "clip.usda"))
    add_op(UsdGeom.Xform.Define(clip, "/X"), "translate", "double", rng, True)
    clip.GetRootLayer().Save()
    stage = Usd.Stage.CreateNew(str(tmp_path / "root.usda"))
    clipped = UsdGeom.Xform.Define(stage, "/Clipped")
    clipped.AddTranslateOp()
    clips = Usd.ClipsAPI(clipped.GetPrim())
    clips.SetClipAssetPaths([Sdf.AssetPath("./clip.usda")])
    clips.SetClipPrimPath("/X")
    clips.SetClipActive([(0.0, 0)])
    clips.SetClipTimes([(0.0, 0.0), (4.0, 4.0)])
    blocked = UsdGeom.Xform.Define(stage, "/Blocked")
    op = add_op(blocked, "translate", "double", rng, True)
    op.GetAttr().Set(Sdf.ValueBlock(), 2.6)
    plain = UsdGeom.Xform.Define(stage, "/Plain")
    add_op(plain, "translate", "double", rng, True)
    assert clipped.GetPrim().GetAttribute("xformOp:translate").GetResolveInfo().GetSource() == \
        Usd.ResolveInfoSourceValueClips
    assert_bulk_matches(stage, ["/Clipped", "/Blocked", "/Plain"], fast=[False, False, True])


def test_instance_proxies_read_in_bulk():
    """Instance proxies under animated instanceable prims (the mixed stage's RefA and RefB) are read in bulk,
    with the static op of the prototype's mesh between them and the animated prim."""
    stage = mixed_stage(num_frames=8)
    paths = ["/World/RefA/Left", "/World/RefA/Right", "/World/RefB/Left", "/World/Movers/A/Geom",
             "/World/Movers/B/Geom", "/World/Stretched"]
    assert stage.GetPrimAtPath(paths[0]).IsInstanceProxy()
    assert_bulk_matches(stage, paths, np.linspace(-1.0, 8.0, 19), fast=[True] * len(paths))


def random_op_stage(path=None, seed: int = 0, num_prims: int = 40):
    """A stage of ``num_prims`` meshes under chains of one to three Xforms with random op stacks (types,
    precisions, inverse ops, resets, static or time-sampled at random times) and a box each; saved to ``path``
    when given. Returns ``(stage, mesh paths)``."""
    rng = np.random.default_rng(seed)
    stage = Usd.Stage.CreateNew(str(path)) if path is not None else Usd.Stage.CreateInMemory()
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(10)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    points, counts, indices = prism(4, radius=0.4, height=0.5)
    meshes = []
    for i in range(num_prims):
        parent = "/World"
        for depth in range(int(rng.integers(1, 4))):
            parent = f"{parent}/P{i}_{depth}"
            xf = UsdGeom.Xform.Define(stage, parent)
            for _ in range(int(rng.integers(0, 4))):
                op_type = str(rng.choice([t for t in OP_TYPES if t != "transform"]))
                precision = str(rng.choice(["double", "float", "float", "half"]))
                animated = bool(rng.random() < 0.6)
                times = np.sort(rng.choice(np.arange(0.0, 10.5, 0.5), int(rng.integers(2, 8)), replace=False))
                op = xf.AddXformOp(getattr(UsdGeom.XformOp, "Type" + op_type[0].upper() + op_type[1:]),
                                   getattr(UsdGeom.XformOp, "Precision" + precision.capitalize()),
                                   f"s{len(xf.GetOrderedXformOps())}", bool(rng.random() < 0.2))
                for k, t in enumerate(times if animated else [None]):
                    value = op_value(op_type, precision, rng, k % 1)
                    op.GetAttr().Set(value) if t is None else op.GetAttr().Set(value, float(t))
            if rng.random() < 0.1:
                xf.SetResetXformStack(True)
        meshes.append(str(define_mesh(stage, f"{parent}/M", points, counts, indices).GetPath()))
    if path is not None:
        stage.GetRootLayer().Save()
    return stage, meshes


def test_random_op_stacks_match_xform_cache():
    stage, meshes = random_op_stage(seed=7, num_prims=60)
    bulk = assert_bulk_matches(stage, meshes, np.concatenate([np.arange(-1.0, 11.5, 0.25), [0.3, 7.77]]))
    assert bulk.mean() > 0.5  # most chains have at most one animated prim and no interpolated half


def test_whole_and_one_by_one_sample_reads_agree(monkeypatch):
    """The dictionary read and the one-by-one read give the same matrices, and a short range of a long
    animation reads the samples of that range only."""
    rng = np.random.default_rng(8)
    stage = Usd.Stage.CreateInMemory()
    xf = UsdGeom.Xform.Define(stage, "/X")
    translate, orient = xf.AddTranslateOp(), xf.AddOrientOp()
    for t in range(1000):
        translate.Set(Gf.Vec3d(*rng.uniform(-3, 3, 3)), float(t))
        orient.Set(op_value("orient", "float", rng, 0), float(t))
    read = []
    real = xforms._Reader.samples

    def counted(self, spec, mapping, type_name):
        keys, values = real(self, spec, mapping, type_name)
        read.append(len(keys))
        return keys, values

    monkeypatch.setattr(xforms._Reader, "samples", counted)
    window = np.array([500.0, 500.5, 501.0, 502.0, 503.25, 509.0])
    got = {}
    for share in (0.0, np.inf):
        monkeypatch.setattr(xforms, "WHOLE_READ_SHARE", share)
        read.clear()
        got[share] = read_world_matrices(stage, [stage.GetPrimAtPath("/X")], window)[0]
        assert read == ([1000, 1000] if share == 0.0 else [6, 6])  # 500 to 504 and 509
    np.testing.assert_array_equal(got[0.0], got[np.inf])
    assert_bulk_matches(stage, ["/X"], window, fast=[True])


def assert_same_import(a: UsdMeshImport, b: UsdMeshImport) -> None:
    """Two imports of one stage: the same objects, poses within 1e-12, world vertices within 1e-12 of the scene's
    size at every frame."""
    assert a.object_path == b.object_path
    np.testing.assert_array_equal(a.object_deforming, b.object_deforming)
    np.testing.assert_allclose(a._anim_poses, b._anim_poses, rtol=0, atol=1e-12 * max(1.0, np.abs(b._anim_poses).max()))
    for k in range(len(a.times)):
        a.set_frame(k)
        b.set_frame(k)
        va, vb = a.scene.world_vertex.numpy(), b.scene.world_vertex.numpy()
        np.testing.assert_allclose(va, vb, rtol=0, atol=1e-12 * max(1.0, np.abs(vb).max()))


@pytest.mark.parametrize("build", ["mixed", "random"])
def test_import_with_and_without_the_bulk_read(tmp_path, monkeypatch, build):
    path = tmp_path / "anim.usda"
    if build == "mixed":
        mixed_stage(path, num_frames=12)
    else:
        random_op_stage(path, seed=9, num_prims=30)
    times = np.arange(-0.5, 11.0, 0.75)
    fast = UsdMeshImport(path, times=times, device=DEFAULT_DEVICE, precision="float64", workers=0)
    pooled = UsdMeshImport(path, times=times, device=DEFAULT_DEVICE, precision="float64", workers=2)
    monkeypatch.setattr(xforms, "FAST_XFORMS", False)
    slow = UsdMeshImport(path, times=times, device=DEFAULT_DEVICE, precision="float64", workers=0)
    assert_same_import(fast, slow)
    assert pooled.object_path == fast.object_path  # the prims split over two processes: bit for bit
    np.testing.assert_array_equal(pooled._anim_poses, fast._anim_poses)
    for k in (0, len(times) - 1):
        pooled.set_frame(k)
        fast.set_frame(k)
        np.testing.assert_array_equal(pooled.scene.world_vertex.numpy(), fast.scene.world_vertex.numpy())


def test_transform_not_finite_at_some_time_names_the_prim():
    stage = Usd.Stage.CreateInMemory()
    mesh = define_mesh(stage, "/World/Box", *prism(4))
    op = UsdGeom.Xformable(mesh).AddTranslateOp()
    for f in range(4):
        op.Set(Gf.Vec3d(float("nan") if f == 2 else 0.0, 0.0, 0.0), f)
    with pytest.raises(ValueError, match="/World/Box: xformOp:translate at time 2 is not finite"):
        UsdMeshImport(stage, times=[0, 1, 2, 3], workers=0, device=DEFAULT_DEVICE)


def test_batched_mesh_read_matches_one_by_one():
    """read_meshes over every mesh of the mixed stage gives what read_mesh gives one by one; with two bad
    meshes, the first in order is named."""
    stage = mixed_stage(num_frames=4)
    code = Usd.TimeCode(0.0)
    prims = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    names = [str(p.GetPath()) for p in prims]
    for one, many in zip([read_mesh(p, n, code) for p, n in zip(prims, names)], read_meshes(prims, names, code)):
        np.testing.assert_array_equal(one.points, many.points)
        np.testing.assert_array_equal(one.triangles, many.triangles)
        np.testing.assert_array_equal(one.triangle_face, many.triangle_face)
        assert (one.key, one.deforming, one.path) == (many.key, many.deforming, many.path)
    bad = Usd.Stage.CreateInMemory()
    points, counts, indices = prism(4)
    define_mesh(bad, "/A", points, counts, indices)
    define_mesh(bad, "/B", points, counts[:-1] + [2], indices[:-2])
    define_mesh(bad, "/C", points, counts, indices[:-1] + [99])
    prims = [bad.GetPrimAtPath(p) for p in ("/A", "/B", "/C")]
    with pytest.raises(ValueError, match=r"prim /B: face 5 has 2 vertices"):
        read_meshes(prims, ["/A", "/B", "/C"], code)
    with pytest.raises(ValueError, match=r"prim /C: faceVertexIndices\[23\] = 99 is outside its 8 points"):
        read_meshes(prims[::-2], ["/C", "/A"], code)


def test_samples_of_two_value_types_fall_back(tmp_path):
    """An attribute whose samples were written as two types (through Sdf: a quatd then a quatf): USD holds the
    lower sample between them rather than interpolating; the bulk read falls back to XformCache."""
    stage = Usd.Stage.CreateInMemory()
    layer = stage.GetRootLayer()
    UsdGeom.Xform.Define(stage, "/X").AddOrientOp(UsdGeom.XformOp.PrecisionDouble)
    path = "/X.xformOp:orient"
    layer.SetTimeSample(path, 0, Gf.Quatd(1, 0, 0, 0))
    layer.GetAttributeAtPath(path).SetInfo("typeName", "quatf")
    layer.SetTimeSample(path, 10, Gf.Quatf(0, 0, 0, 1))
    layer.GetAttributeAtPath(path).SetInfo("typeName", "quatd")
    define_mesh(stage, "/X/M", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [3], [0, 1, 2])
    layer.Export(str(tmp_path / "mixed.usdc"))
    assert_bulk_matches(Usd.Stage.Open(str(tmp_path / "mixed.usdc")), ["/X"], [0.0, 5.0, 10.0], fast=[False])


def test_ill_conditioned_inverse_matrix_op_falls_back():
    """``!invert!xformOp:transform`` of a matrix whose inverse USD computes differently from numpy (condition
    number 1e8): read by XformCache."""
    stage = Usd.Stage.CreateInMemory()
    xf = UsdGeom.Xform.Define(stage, "/X")
    op = xf.AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 0)
    op.Set(Gf.Vec3d(1, 0, 0), 1)
    q1, q2 = Gf.Quatd(0.3, 0.5, -0.7, 0.2).GetNormalized(), Gf.Quatd(0.6, -0.2, 0.4, 0.66).GetNormalized()
    m = Gf.Matrix4d().SetRotate(q1) * Gf.Matrix4d().SetScale(Gf.Vec3d(1e4, 1, 1e-4)) * Gf.Matrix4d().SetRotate(q2)
    m.SetTranslateOnly(Gf.Vec3d(1.5, -2, 3))
    xf.AddTransformOp(opSuffix="m", isInverseOp=True).GetAttr().Set(m)
    assert_bulk_matches(stage, ["/X"], [0.0, 0.5, 1.0], fast=[False])


@pytest.mark.parametrize("setting", ["held", "unloaded"])
def test_workers_read_here_a_stage_not_opened_as_by_default(tmp_path, setting):
    """Worker processes open the file as ``Usd.Stage.Open`` does: a stage read with held interpolation, or with
    payloads unloaded, is read in this process alone (every prim the same way)."""
    path = str(tmp_path / "stage.usda")
    stage = Usd.Stage.CreateNew(path)
    for i in range(4):
        xf = UsdGeom.Xform.Define(stage, f"/X{i}")
        op = xf.AddTranslateOp()
        op.Set(Gf.Vec3d(0, 0, 0), 0)
        op.Set(Gf.Vec3d(10, 0, 0), 10)
        define_mesh(stage, f"/X{i}/M", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [3], [0, 1, 2])
    stage.GetRootLayer().Save()
    opened = Usd.Stage.Open(path, Usd.Stage.LoadNone if setting == "unloaded" else Usd.Stage.LoadAll)
    if setting == "held":
        opened.SetInterpolationType(Usd.InterpolationTypeHeld)
    alone = UsdMeshImport(opened, times=[0, 5, 10], device=DEFAULT_DEVICE, precision="float64", workers=0)
    shared = UsdMeshImport(opened, times=[0, 5, 10], device=DEFAULT_DEVICE, precision="float64", workers=2)
    assert np.array_equal(alone._anim_poses, shared._anim_poses)
    if setting == "held":
        assert (alone._anim_poses[1, :, 0] == 0.0).all()  # held at the sample of time 0


def test_worker_processes_register_the_packages_of_their_folders():
    """A reading worker (``python -c``) registers ``warp_ccd`` and the packages down to the workers' module as
    bare packages of their folders: each must be the folder of that package, or a worker on a machine where the
    package is not installed (only on ``PYTHONPATH``) cannot import its module."""
    import importlib

    from warp_ccd._src.usd import workers

    packages = workers.boot_packages()
    assert [name for name, _ in packages] == ["warp_ccd", "warp_ccd._src", "warp_ccd._src.usd"]
    for name, folder in packages:
        assert os.path.samefile(folder, os.path.dirname(importlib.import_module(name).__file__)), name
    assert "warp_ccd._src.usd.workers import main" in workers.BOOTSTRAP
