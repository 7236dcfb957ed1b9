"""The public API in levels: a short top level, a few public modules for the rest, the implementation private
(``warp_ccd._src``), and no shim for names never released."""

import importlib

import numpy as np
import pytest

import warp_ccd as wc

NAMESPACES = ("warp_ccd.geometry", "warp_ccd.scene", "warp_ccd.stages", "warp_ccd.usd", "warp_ccd.trimesh")

def test_top_level_is_short_and_resolves():
    assert len(wc.__all__) <= 15  # the one-shot calls (collide, distance, ...), their classes and options
    assert {"collide", "Scene", "CollisionPipeline", "CollisionResult", "check_usd", "CheckReport"} <= set(wc.__all__)
    for name in wc.__all__:
        assert getattr(wc, name) is not None


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


def test_unknown_top_level_name_is_an_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        wc.no_such_name  # noqa: B018


@pytest.mark.parametrize("old", ["SceneBVH", "icosphere", "BroadPhaseNxN", "render_frame", "narrow_phase",
                                 "stages.kinds"])
def test_names_never_released_are_gone(old):
    """Nothing was released before 0.1.0: no alias of an earlier name, no module path kept by a shim."""
    *module, name = ["warp_ccd", *old.split(".")]
    with pytest.raises((AttributeError, ModuleNotFoundError)):
        getattr(importlib.import_module(".".join(module)), name)
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(f"warp_ccd.{old}")


def test_scene_takes_object_names_only():
    scene = wc.Scene([wc.scene.shape("cube")], [0, 0], object_scale=[1.0, 2.0])
    np.testing.assert_array_equal(scene.object_scale_np, [1.0, 2.0])
    assert not hasattr(scene, "instance_shape")
    with pytest.raises(TypeError, match="unexpected keyword argument 'instance_shape'"):
        wc.Scene([wc.scene.shape("cube")], instance_shape=[0])
    with pytest.raises(TypeError, match="missing 1 required positional argument: 'object_shape'"):
        wc.Scene([wc.scene.shape("cube")])


def test_public_module_paths_are_few():
    """Public modules (no part of the path starting with an underscore) are the short surface users import;
    everything else lives under ``warp_ccd._src``."""
    import os

    root = os.path.dirname(wc.__file__)
    public = []
    for folder, _, files in os.walk(root):
        for f in files:
            if f.endswith(".py"):
                rel = os.path.relpath(os.path.join(folder, f), os.path.dirname(root))[:-3].split(os.sep)
                if rel[-1] == "__init__":
                    rel = rel[:-1]
                if not any(part.startswith("_") for part in rel):
                    public.append(".".join(rel))
    assert len(public) <= 25, sorted(public)
    assert {"warp_ccd", "warp_ccd.geometry", "warp_ccd.scene", "warp_ccd.usd"} <= set(public)


def test_nxn_is_all_pairs(device):
    rng = np.random.default_rng(3)
    lower = rng.uniform(0, 10, (50, 3)).astype(np.float32)
    upper = lower + rng.uniform(0, 2, (50, 3)).astype(np.float32)
    want = wc.stages.broad_phase_pairs(lower, upper, method="all_pairs", device=device)
    np.testing.assert_array_equal(wc.stages.broad_phase_pairs(lower, upper, method="nxn", device=device), want)
    np.testing.assert_array_equal(wc.stages.broad_phase_pairs(lower, upper, method="sap", device=device), want)
    assert len(want) > 10


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
