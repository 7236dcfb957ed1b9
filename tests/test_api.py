"""The public API in levels: a short top level, namespaces for the rest, and the names of 0.1 that moved
still working for one release, each with a DeprecationWarning that names its new home."""

import importlib

import numpy as np
import pytest

import warp_ccd as wc

NAMESPACES = ("warp_ccd.geometry", "warp_ccd.scene", "warp_ccd.stages", "warp_ccd.usd")

MOVED = {  # top-level name of 0.1 -> (namespace, name)
    "SHAPES": ("warp_ccd.scene", "SHAPES"),
    "EllipseMotion": ("warp_ccd.scene", "EllipseMotion"),
    "icosphere": ("warp_ccd.scene", "icosphere"),
    "shape": ("warp_ccd.scene", "shape"),
    "validate_mesh": ("warp_ccd.scene", "validate_mesh"),
    "BroadPhaseSAP": ("warp_ccd.stages", "BroadPhaseSAP"),
    "BroadPhaseNxN": ("warp_ccd.stages", "BroadPhaseAllPairs"),
    "MidPhaseAllPairs": ("warp_ccd.stages", "MidPhaseAllPairs"),
    "MidPhaseBVH": ("warp_ccd.stages", "MidPhaseBVH"),
    "NarrowPhase": ("warp_ccd.stages", "NarrowPhase"),
    "SceneBVH": ("warp_ccd.stages", "SceneBVH"),
    "build_tree": ("warp_ccd.stages", "build_tree"),
    "tri_tri_edge_face": ("warp_ccd.geometry", "tri_tri_edge_face"),
    "tri_tri_moller": ("warp_ccd.geometry", "tri_tri_moller"),
    "render_frame": ("warp_ccd.preview", "render_frame"),
    "save_preview": ("warp_ccd.preview", "save_preview"),
    "UsdAnimationWriter": ("warp_ccd.usd", "UsdAnimationWriter"),
}


def test_top_level_is_short_and_resolves():
    assert len(wc.__all__) <= 13  # the one-shot calls (collide, distance, self_intersections, ...) and their classes
    assert {"collide", "Scene", "CollisionPipeline", "CollisionResult", "check_usd", "CheckReport"} <= set(wc.__all__)
    for name in wc.__all__:
        assert getattr(wc, name) is not None
    assert not set(MOVED) & set(wc.__all__)


@pytest.mark.parametrize("namespace", NAMESPACES)
def test_namespaces_export_what_they_list(namespace):
    module = importlib.import_module(namespace)
    assert module.__all__ and module.__doc__
    missing = [name for name in module.__all__ if not hasattr(module, name)]
    assert not missing, f"{namespace} lists {missing} but has no such names"


def test_stage_classes_live_in_stages_and_device_functions_in_geometry():
    from warp_ccd import geometry, stages

    for name in ("ObjectBounds", "SceneBVH", "BroadPhaseSAP", "BroadPhaseAllPairs", "MidPhaseBVH",
                 "MidPhaseAllPairs", "NarrowPhase", "make_broad_phase", "make_mid_phase", "make_narrow_phase"):
        assert name in stages.__all__, name
    for name in ("tri_tri_moller", "tri_tri_edge_face", "boxes_overlap", "TOLERANCE"):
        assert name in geometry.__all__, name


@pytest.mark.parametrize("old", sorted(MOVED))
def test_moved_top_level_names_warn_and_work(old):
    namespace, new = MOVED[old]
    with pytest.warns(DeprecationWarning, match=rf"warp_ccd\.{old} is deprecated .* use {namespace}\.{new}"):
        got = getattr(wc, old)
    assert got is getattr(importlib.import_module(namespace), new)


def test_unknown_top_level_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        wc.no_such_name  # noqa: B018


def test_instance_names_of_scene_warn_and_reach_object_names():
    scene = wc.Scene([wc.scene.shape("cube")], [0, 0], object_scale=[1.0, 2.0])
    for old, new in (("instance_shape_np", "object_shape_np"), ("instance_scale_np", "object_scale_np"),
                     ("instance_vertex_start_np", "object_vertex_start_np"),
                     ("instance_triangle_start_np", "object_triangle_start_np")):
        with pytest.warns(DeprecationWarning, match=rf"Scene\.{old} is deprecated .* use Scene\.{new}"):
            np.testing.assert_array_equal(getattr(scene, old), getattr(scene, new))
    with pytest.warns(DeprecationWarning, match=r"Scene\.instance_pose"):
        assert scene.instance_pose is scene.object_pose
    with pytest.warns(DeprecationWarning, match=r"Scene\(instance_(shape|scale)=\.\.\.\) is deprecated"):
        old = wc.Scene([wc.scene.shape("cube")], instance_shape=[0, 0], instance_scale=[1.0, 2.0])
    np.testing.assert_array_equal(old.object_scale_np, scene.object_scale_np)
    with pytest.raises(TypeError, match="unexpected keyword argument 'instance_shapes'"):
        wc.Scene([wc.scene.shape("cube")], instance_shapes=[0])
    with pytest.raises(TypeError, match="missing 1 required argument: 'object_shape'"):
        wc.Scene([wc.scene.shape("cube")])


def test_scene_bvh_old_keyword_warns(device):
    scene = wc.Scene([wc.scene.shape("cube")], [0, 0], deforming=True, device=device)
    with pytest.warns(DeprecationWarning, match=r"SceneBVH\(instance_refit_max_nodes=\.\.\.\)"):
        old = wc.stages.SceneBVH(scene, instance_refit_max_nodes=0)
    new = wc.stages.SceneBVH(scene, object_refit_max_nodes=0)
    assert old.refit_plan.small_object.shape == new.refit_plan.small_object.shape


def test_scene_from_usd_warns_and_reads_the_stage(tmp_path, device):
    from pxr import Usd, UsdGeom

    path = str(tmp_path / "cube.usda")
    stage = Usd.Stage.CreateNew(path)
    mesh = UsdGeom.Mesh.Define(stage, "/World/Cube")
    v, t = wc.scene.shape("cube")
    mesh.CreatePointsAttr([tuple(map(float, p)) for p in v])
    mesh.CreateFaceVertexCountsAttr([3] * len(t))
    mesh.CreateFaceVertexIndicesAttr([int(i) for i in t.ravel()])
    stage.GetRootLayer().Save()
    with pytest.warns(DeprecationWarning, match=r"Scene\.from_usd is deprecated .* use warp_ccd\.usd\.scene_from_usd"):
        old = wc.Scene.from_usd(path, device=device)
    new = wc.usd.scene_from_usd(path, device=device)
    assert old.num_objects == new.num_objects == 1
    np.testing.assert_array_equal(old.world_vertex.numpy(), new.world_vertex.numpy())


def test_nxn_is_all_pairs(device):
    rng = np.random.default_rng(3)
    lower = rng.uniform(0, 10, (50, 3)).astype(np.float32)
    upper = lower + rng.uniform(0, 2, (50, 3)).astype(np.float32)
    want = wc.broad_phase_pairs(lower, upper, method="all_pairs", device=device)
    np.testing.assert_array_equal(wc.broad_phase_pairs(lower, upper, method="nxn", device=device), want)
    np.testing.assert_array_equal(wc.broad_phase_pairs(lower, upper, method="sap", device=device), want)
    assert len(want) > 10


MOVED_MODULES = {  # module path of 0.1 -> (its new home, a name to find through the old path[, where it lives])
    "warp_ccd.aabb": ("warp_ccd.geometry.box", "boxes_overlap"),
    "warp_ccd.precision": ("warp_ccd.geometry.precision", "PrecisionWarning"),
    "warp_ccd.shapes": ("warp_ccd.scene.shapes", "icosphere"),
    "warp_ccd.motion": ("warp_ccd.scene.motion", "EllipseMotion"),
    "warp_ccd.buffers": ("warp_ccd.stages.buffers", "GrowableBuffer"),
    "warp_ccd.frame": ("warp_ccd.stages.frame", "CountedFrame"),
    "warp_ccd.bvh": ("warp_ccd.stages.bvh", "SceneBVH"),
    "warp_ccd.bvh_build": ("warp_ccd.stages.bvh_build", "build_tree", "warp_ccd.stages.bvh_reference"),
    "warp_ccd.broad_phase": ("warp_ccd.stages.broad_phase", "BroadPhaseSAP"),
    "warp_ccd.mid_phase": ("warp_ccd.stages.mid_phase", "MidPhaseBVH"),
    "warp_ccd.narrow_phase": ("warp_ccd.stages.narrow_phase", "tri_tri_moller", "warp_ccd.geometry.triangle"),
    "warp_ccd.crossing": ("warp_ccd.stages.crossing", "surface_topology", "warp_ccd.stages.surface"),
    "warp_ccd.usd_import": ("warp_ccd.usd.importer", "open_stage", "warp_ccd.usd.stage"),
    "warp_ccd.check": ("warp_ccd.usd.check", "check_usd"),
    "warp_ccd.cli_common": ("warp_ccd.cli.common", "resolve_device"),
}


@pytest.mark.parametrize("old", sorted(MOVED_MODULES))
def test_moved_modules_import_from_their_old_paths(old):
    """``from warp_ccd.narrow_phase import tri_tri_moller`` (0.1) works, with one warning naming the new home;
    a name the module never had is still an AttributeError."""
    import sys

    home, name, *where = MOVED_MODULES[old]
    short = old.split(".")[1]
    for fresh in (lambda: importlib.import_module(old), lambda: getattr(wc, short)):  # wc.narrow_phase too
        sys.modules.pop(old, None)
        wc.__dict__.pop(short, None)
        with pytest.warns(DeprecationWarning, match=rf"{old} is deprecated .* use {home}"):
            module = fresh()
        assert module is sys.modules[old]
        assert getattr(module, name) is getattr(importlib.import_module((where or [home])[0]), name)
        with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
            module.no_such_name  # noqa: B018


def test_names_of_the_usd_module_of_0_1():
    from warp_ccd.usd import export

    for name in ("COLOR_COLLIDING", "STAGE_EXTENSIONS", "validate_stage_path", "segment_points"):
        with pytest.warns(DeprecationWarning, match=rf"warp_ccd\.usd\.{name} is deprecated"):
            assert getattr(wc.usd, name) is getattr(export, name)


def test_instance_names_of_scene_bvh_and_motion(device):
    scene = wc.Scene.random(4, seed=1, device=device)
    bvh = wc.stages.SceneBVH(scene)
    with pytest.warns(DeprecationWarning, match=r"SceneBVH\.rigid_instance"):
        assert bvh.rigid_instance is bvh.rigid_object
    with pytest.warns(DeprecationWarning, match=r"SceneBVH\.instance_deforming"):
        assert bvh.instance_deforming is bvh.object_deforming
    want = wp_clone_numpy(scene.object_pose)
    with pytest.warns(DeprecationWarning, match=r"EllipseMotion\.launch\(instance_pose=\.\.\.\)"):
        scene.motion.launch(scene.time, instance_pose=scene.object_pose)
    np.testing.assert_array_equal(scene.object_pose.numpy(), want)


def wp_clone_numpy(a):
    return a.numpy().copy()


def test_importing_the_package_needs_no_io_library():
    """``import warp_ccd`` (the façade, which gathers the usd room too) works without pxr, Pillow, tqdm and
    matplotlib: they are imported where they are used."""
    import subprocess
    import sys

    code = ("import sys\n"
            "for name in ('pxr', 'PIL', 'tqdm', 'matplotlib'):\n"
            "    sys.modules[name] = None\n"
            "import warp_ccd, warp_ccd.stages, warp_ccd.usd\n"
            "print(sorted(n for n in ('pxr', 'PIL', 'tqdm', 'matplotlib') if sys.modules.get(n) is not None))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_mid_phase_all_pairs_old_path_warns():
    """MidPhaseAllPairs left stages.mid_phase for a module of its own: the old path warns one release."""
    from warp_ccd.stages import mid_phase, mid_phase_all_pairs

    with pytest.warns(DeprecationWarning, match="mid_phase.MidPhaseAllPairs is deprecated"):
        got = mid_phase.MidPhaseAllPairs
    assert got is mid_phase_all_pairs.MidPhaseAllPairs

