"""USD export: the written stage, reopened with pxr, must match what the pipeline saw, frame by frame.

Validation runs every validator registered with usd-core's ``UsdValidation`` (26.x). Those that
concern things these stages do not contain pass trivially: the usdz package checks
(``usdUtilsValidators:PackageEncapsulationValidator``, ``RootPackageValidator``,
``UsdzPackageValidator``, ``FileExtensionValidator``: no package), ``MissingReferenceValidator``
(no references), physics, skeleton, shading, lux and media validators (no such schemas). usd-core
registers no time-dependent validator and none that checks primvar element counts against
interpolation, so the tests check those themselves.
"""

import os

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.usd.export import COLOR_COLLIDING, COLOR_FREE, UsdAnimationWriter, validate_stage_path

pxr = pytest.importorskip("pxr")
from pxr import Gf, Usd, UsdGeom, UsdValidation  # noqa: E402

NUM_FRAMES = 6


def record_run(path, device, *, num_objects=60, aabb=False, seed=3):
    """Runs the pipeline for NUM_FRAMES frames, writing ``path``; returns what each frame held."""
    scene = wc.Scene.random(num_objects, seed=seed, density=0.08, device=device)
    pipe = wc.CollisionPipeline(scene)
    record = {"pose": [], "scale": [], "colliding": [], "world": []}
    with UsdAnimationWriter(path, scene, fps=60, aabb=aabb) as writer:
        for frame in range(NUM_FRAMES):
            scene.advance(1 / 60)
            res = pipe.detect()
            writer.add_frame(frame, res)
            record["pose"].append(scene.object_pose.numpy().reshape(-1, 7).copy())
            record["scale"].append(scene.object_scale.numpy().copy())
            record["colliding"].append(res.colliding.copy())
            record["world"].append(scene.world_vertex.numpy().copy())
    return scene, record


def validation_errors(stage):
    """Errors and warnings of every registered usd-core validator on ``stage``."""
    registry = UsdValidation.ValidationRegistry()
    validators = registry.GetOrLoadAllValidators()
    names = {v.GetMetadata().name for v in validators}
    # The validators that matter for these stages must be among them.
    assert {
        "usdGeomValidators:StageMetadataChecker",
        "usdValidation:StageMetadataChecker",
        "usdValidation:CompositionErrorTest",
        "usdValidation:AttributeTypeMismatch",
        "usdGeomValidators:EncapsulationChecker",
    } <= names
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    return [
        f"{e.GetValidator().GetMetadata().name if e.GetValidator() else '?'}: {e.GetMessage()}"
        for e in errors
        if e.GetType() in (UsdValidation.ValidationErrorType.Error, UsdValidation.ValidationErrorType.Warn)
    ]


@pytest.fixture(params=[".usda", ".usd"])
def rigid_run(request, tmp_path, device):
    path = tmp_path / f"run{request.param}"
    scene, record = record_run(path, device)
    stage = Usd.Stage.Open(str(path))
    yield scene, record, stage, path
    del stage


def test_rigid_stage_metadata_and_layout(rigid_run):
    scene, record, stage, path = rigid_run
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(1.0)
    assert stage.GetStartTimeCode() == 0
    assert stage.GetEndTimeCode() == NUM_FRAMES - 1
    assert stage.GetTimeCodesPerSecond() == 60
    assert stage.GetFramesPerSecond() == 60
    assert stage.GetDefaultPrim().GetPath() == "/World"
    with open(path, "rb") as f:
        head = f.read(8)
    assert head.startswith(b"#usda" if path.suffix == ".usda" else b"PXR-USDC")

    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Objects"))
    assert inst
    targets = inst.GetPrototypesRel().GetTargets()
    assert len(targets) == scene.num_shapes
    for k, t in enumerate(targets):
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(t))
        v, tri = scene.shape_meshes[k]
        np.testing.assert_array_equal(np.asarray(mesh.GetPointsAttr().Get()), v)
        np.testing.assert_array_equal(np.asarray(mesh.GetFaceVertexIndicesAttr().Get()), tri.reshape(-1))
        assert mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
    np.testing.assert_array_equal(np.asarray(inst.GetProtoIndicesAttr().Get()), scene.object_shape_np)

    for attr in (inst.GetPositionsAttr(), inst.GetOrientationsAttr(), inst.GetScalesAttr(), inst.GetExtentAttr()):
        assert attr.GetNumTimeSamples() == NUM_FRAMES, attr.GetName()
    color = UsdGeom.PrimvarsAPI(inst).GetPrimvar("displayColor")
    assert color.IsDefined()
    assert color.GetInterpolation() == UsdGeom.Tokens.vertex  # one element per instance
    assert color.GetAttr().GetNumTimeSamples() == NUM_FRAMES
    assert validation_errors(stage) == []


def test_rigid_stage_matches_every_frame(rigid_run):
    scene, record, stage, _ = rigid_run
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Objects"))
    color = UsdGeom.PrimvarsAPI(inst).GetPrimvar("displayColor")
    n = scene.num_objects
    assert sum(int(c.sum()) for c in record["colliding"]) > 0, "the scene should have collisions"
    proto_points = [
        np.asarray(UsdGeom.Mesh(stage.GetPrimAtPath(t)).GetPointsAttr().Get(), np.float64)
        for t in inst.GetPrototypesRel().GetTargets()
    ]
    for frame in range(NUM_FRAMES):
        time = Usd.TimeCode(frame)
        pose = record["pose"][frame]
        position = np.asarray(inst.GetPositionsAttr().Get(time))
        np.testing.assert_array_equal(position, pose[:, :3])
        q = np.array([[o.GetImaginary()[0], o.GetImaginary()[1], o.GetImaginary()[2], o.GetReal()]
                      for o in inst.GetOrientationsAttr().Get(time)])
        np.testing.assert_allclose(q, pose[:, 3:], atol=2e-3)  # quath: half precision
        scales = np.asarray(inst.GetScalesAttr().Get(time))
        np.testing.assert_allclose(scales, np.repeat(record["scale"][frame][:, None], 3, axis=1), rtol=1e-6)

        colors = np.asarray(color.ComputeFlattened(time))
        assert colors.shape == (n, 3)
        expected = np.where(record["colliding"][frame][:, None], COLOR_COLLIDING, COLOR_FREE)
        np.testing.assert_allclose(colors, expected, atol=1e-6)

        # End to end: USD's own instance transforms, applied to the prototypes, give the scene's
        # world vertices of that frame (row-vector convention: p' = p M).
        xforms = inst.ComputeInstanceTransformsAtTime(time, time)
        assert len(xforms) == n
        world = record["world"][frame]
        for i in range(0, n, 7):
            m = np.array(xforms[i])
            local = proto_points[scene.object_shape_np[i]]
            got = np.c_[local, np.ones(len(local))] @ m
            a, b = scene.object_vertex_start_np[i], scene.object_vertex_start_np[i + 1]
            np.testing.assert_allclose(got[:, :3], world[a:b], atol=5e-3 * max(1.0, float(record["scale"][frame][i])))

        # The instancer's extent holds every world vertex.
        lo, hi = (np.asarray(e) for e in inst.GetExtentAttr().Get(time))
        assert (world >= lo - 1e-4).all() and (world <= hi + 1e-4).all()


def test_colours_are_sampled_every_frame_even_when_unchanged(tmp_path):
    scene = wc.Scene.random(5, seed=0)
    path = tmp_path / "const.usda"
    with UsdAnimationWriter(path, scene) as writer:
        for frame in range(4):
            writer.add_frame(frame, np.array([True, False, False, False, False]))
    stage = Usd.Stage.Open(str(path))
    color = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/Objects")).GetPrimvar("displayColor")
    assert color.GetAttr().GetTimeSamples() == [0, 1, 2, 3]
    # Between samples of the same colour nothing is interpolated.
    np.testing.assert_allclose(np.asarray(color.Get(Usd.TimeCode(1.5)))[0], COLOR_COLLIDING, atol=1e-6)


def test_aabb_wireframes_match_world_bounds(tmp_path, device):
    path = tmp_path / "boxes.usda"
    scene, record = record_run(path, device, num_objects=12, aabb=True)
    stage = Usd.Stage.Open(str(path))
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/World/Bounds"))
    assert curves.GetTypeAttr().Get() == UsdGeom.Tokens.linear
    counts = np.asarray(curves.GetCurveVertexCountsAttr().Get())
    assert counts.sum() == 16 * scene.num_objects
    assert curves.GetPointsAttr().GetNumTimeSamples() == NUM_FRAMES
    start = scene.object_vertex_start_np
    for frame in (0, NUM_FRAMES - 1):
        pts = np.asarray(curves.GetPointsAttr().Get(Usd.TimeCode(frame))).reshape(scene.num_objects, 16, 3)
        world = record["world"][frame]
        for i in range(scene.num_objects):
            v = world[start[i] : start[i + 1]]
            np.testing.assert_allclose(pts[i].min(axis=0), v.min(axis=0), atol=1e-6)
            np.testing.assert_allclose(pts[i].max(axis=0), v.max(axis=0), atol=1e-6)
            # 12 distinct edges along the 4 polylines, each parallel to one axis.
            edges = set()
            offset = 0
            for c in counts[4 * i : 4 * i + 4]:
                seg = pts[i, offset : offset + c]
                for a, b in zip(seg[:-1], seg[1:]):
                    assert np.count_nonzero(np.abs(a - b) > 0) == 1
                    edges.add(tuple(sorted((tuple(a), tuple(b)))))
                offset += c
            assert len(edges) == 12
    assert validation_errors(stage) == []


def test_deforming_scene_writes_meshes_with_points(tmp_path, device):
    v, t = wc.scene.icosphere(1)
    scene = wc.Scene.from_meshes([(v, t), (v + [3.0, 0.0, 0.0], t)], deforming=True, device=device)
    pipe = wc.CollisionPipeline(scene)
    path = tmp_path / "deform.usda"
    record = []
    with UsdAnimationWriter(path, scene) as writer:
        for frame in range(NUM_FRAMES):
            shift = 3.0 - 0.5 * frame  # the second sphere approaches, then overlaps the first
            world = np.concatenate([v * (1.0 + 0.05 * frame), v + [shift, 0.0, 0.0]])
            scene.set_world_vertices(world)
            res = pipe.detect()
            writer.add_frame(frame, res)
            record.append((world.astype(np.float32), res.colliding.copy()))
    assert not record[0][1].any() and record[-1][1].all()
    stage = Usd.Stage.Open(str(path))
    meshes = [UsdGeom.Mesh(p) for p in stage.GetPrimAtPath("/World/Objects").GetChildren()]
    assert len(meshes) == 2
    for i, mesh in enumerate(meshes):
        assert mesh.GetPointsAttr().GetNumTimeSamples() == NUM_FRAMES
        color = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("displayColor")
        assert color.GetInterpolation() == UsdGeom.Tokens.constant
        assert color.GetAttr().GetNumTimeSamples() == NUM_FRAMES
        np.testing.assert_array_equal(np.asarray(mesh.GetFaceVertexIndicesAttr().Get()), t.reshape(-1))
        for frame, (world, colliding) in enumerate(record):
            pts = np.asarray(mesh.GetPointsAttr().Get(Usd.TimeCode(frame)))
            np.testing.assert_array_equal(pts, world[i * len(v) : (i + 1) * len(v)])
            expected = COLOR_COLLIDING if colliding[i] else COLOR_FREE
            np.testing.assert_allclose(np.asarray(color.Get(Usd.TimeCode(frame)))[0], expected, atol=1e-6)
    assert validation_errors(stage) == []


@pytest.mark.parametrize(
    "name, message",
    [
        ("out.obj", "unknown USD extension"),
        ("out", "unknown USD extension"),
        ("missing/out.usd", "does not exist"),
        ("a_folder.usd", "is a folder"),
    ],
)
def test_bad_paths_fail_when_the_writer_is_created(tmp_path, name, message):
    (tmp_path / "a_folder.usd").mkdir()
    scene = wc.Scene.random(3, seed=0)
    with pytest.raises(ValueError, match=message):
        UsdAnimationWriter(tmp_path / name, scene)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a_folder.usd"]


def unwritable_folder(tmp_path):
    """A folder in which no file can be created (a read-only one; /proc when running as root)."""
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        if not os.path.isdir("/proc/self"):
            pytest.skip("running as root without /proc: no unwritable folder to test with")
        return "/proc"
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    return str(folder)


def test_unwritable_folder_fails_early(tmp_path):
    folder = unwritable_folder(tmp_path)
    scene = wc.Scene.random(3, seed=0)
    with pytest.raises(ValueError, match="cannot"):
        validate_stage_path(os.path.join(folder, "x.usd"))
    with pytest.raises(ValueError, match="cannot"):
        UsdAnimationWriter(os.path.join(folder, "x.usd"), scene)


def test_interrupted_run_leaves_the_old_file_and_no_partial_file(tmp_path):
    path = tmp_path / "keep.usd"
    path.write_bytes(b"old content")
    scene = wc.Scene.random(4, seed=0)
    with pytest.raises(KeyboardInterrupt):
        with UsdAnimationWriter(path, scene) as writer:
            writer.add_frame(0, None)
            raise KeyboardInterrupt
    assert path.read_bytes() == b"old content"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.usd"]

    # A completed run replaces it, with ordinary permission bits, and leaves no temporary file.
    with UsdAnimationWriter(path, scene) as writer:
        writer.add_frame(0, None)
    assert path.read_bytes().startswith(b"PXR-USDC")
    assert [p.name for p in tmp_path.iterdir()] == ["keep.usd"]


def test_new_file_gets_umask_permissions(tmp_path):
    scene = wc.Scene.random(2, seed=0)
    mask = os.umask(0o022)
    try:
        UsdAnimationWriter(tmp_path / "m.usda", scene).close()
    finally:
        os.umask(mask)
    assert (tmp_path / "m.usda").stat().st_mode & 0o777 == 0o644


def test_writer_rejects_bad_frames_and_use_after_close(tmp_path):
    scene = wc.Scene.random(4, seed=0)
    writer = UsdAnimationWriter(tmp_path / "w.usda", scene)
    with pytest.raises(ValueError, match="shape"):
        writer.add_frame(0, np.zeros(3, bool))
    with pytest.raises(ValueError, match="frame_index"):
        writer.add_frame(-1, None)
    with pytest.raises(ValueError, match="fps"):
        UsdAnimationWriter(tmp_path / "f.usda", scene, fps=0)
    writer.close()  # no frame: the current state as frame 0
    with pytest.raises(ValueError, match="closed"):
        writer.add_frame(1, None)
    stage = Usd.Stage.Open(str(tmp_path / "w.usda"))
    inst = UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Objects"))
    assert inst.GetPositionsAttr().GetNumTimeSamples() == 1
    assert validation_errors(stage) == []


def test_orientation_layout_matches_gf_quath():
    # wp.transform stores (x, y, z, w); GfQuath's memory is (imaginary, real), Gf.Quath(real, i, j, k).
    from pxr import Vt

    q = Vt.QuathArray.FromNumpy(np.array([[0.1, 0.2, 0.3, 0.9]], np.float16))[0]
    assert q == Gf.Quath(np.float16(0.9), np.float16(0.1), np.float16(0.2), np.float16(0.3))
    assert wp.transform(wp.vec3(), wp.quat(0.1, 0.2, 0.3, 0.9)).q[3] == pytest.approx(0.9)


def test_segment_markers(tmp_path, device):
    from pxr import Usd, UsdGeom

    import warp_ccd as wc

    scene = wc.Scene.random(150, seed=3, device=device)
    pipe = wc.CollisionPipeline(scene, segments=True)
    path = tmp_path / "segments.usda"
    counts = []
    with wc.usd.UsdAnimationWriter(path, scene, segments=True) as writer:
        for frame in range(3):
            scene.advance(0.2)
            res = pipe.detect()
            counts.append(int(np.isfinite(res.segments).all(axis=(1, 2)).sum()))
            writer.add_frame(frame, res)
    stage = Usd.Stage.Open(str(path))
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/World/Segments"))
    for frame, n in enumerate(counts):
        assert len(curves.GetCurveVertexCountsAttr().Get(frame)) == n
        assert len(curves.GetPointsAttr().Get(frame)) == 2 * n
    assert sum(counts) > 0
    with pytest.raises(ValueError, match="segments=True"):
        with wc.usd.UsdAnimationWriter(tmp_path / "x.usd", scene, segments=True) as writer:
            writer.add_frame(0, wc.CollisionPipeline(scene).detect())


def test_writer_reads_every_private_attribute_it_stores():
    # A private attribute that the writer sets and never reads is dead state.
    import ast
    import inspect

    from warp_ccd._src.usd import export

    tree = ast.parse(inspect.getsource(export))
    stored, read = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "self":
            (stored if isinstance(node.ctx, ast.Store) else read).add(node.attr)
    assert sorted(a for a in stored - read if a.startswith("_")) == []
