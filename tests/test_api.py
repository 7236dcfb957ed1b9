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
    assert len(wc.__all__) <= 12
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
