"""Every example runs with one frame (and few objects), in process on each device and as a script."""

import importlib.util
import json
import os
import subprocess
import sys

import pytest
import warp as wp

from conftest import DEFAULT_DEVICE

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = os.path.join(ROOT, "examples")


def load_example(name):
    spec = importlib.util.spec_from_file_location(name, os.path.join(EXAMPLES, f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def run_script(name, *args, cwd):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, os.path.join(EXAMPLES, f"{name}.py"), *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


def test_example_collision_one_frame(tmp_path, device):
    pxr = pytest.importorskip("pxr")
    module = load_example("example_collision")
    path = tmp_path / "collision.usda"
    with wp.ScopedDevice(device):
        example = module.Example(stage_path=str(path), num_objects=20)
        example.step()
        example.render()
        example.close()
    assert example.result.colliding.shape == (20,)
    stage = pxr.Usd.Stage.Open(str(path))
    positions = pxr.UsdGeom.PointInstancer(stage.GetPrimAtPath("/World/Objects")).GetPositionsAttr()
    assert positions.GetNumTimeSamples() == 1


def test_example_collision_without_stage(device):
    module = load_example("example_collision")
    with wp.ScopedDevice(device):
        example = module.Example(stage_path=None, num_objects=10)
        example.step()
        example.render()
        example.close()
    assert example.writer is None


def test_example_user_meshes_one_frame(tmp_path, device):
    pxr = pytest.importorskip("pxr")
    module = load_example("example_user_meshes")
    path = tmp_path / "user.usda"
    with wp.ScopedDevice(device):
        example = module.Example(stage_path=str(path))
        example.step()
        example.render()
        example.close()
    assert example.rigid.num_objects == 5 and example.deforming.deforming
    rigid = pxr.Usd.Stage.Open(str(path))
    assert rigid.GetPrimAtPath("/World/Objects").GetTypeName() == "PointInstancer"
    deforming = pxr.Usd.Stage.Open(str(tmp_path / "user_deforming.usda"))
    assert len(deforming.GetPrimAtPath("/World/Objects").GetChildren()) == 7


def test_example_user_meshes_collide_over_time():
    # Both scenes are built to collide part of the time: the rigid one at its first frames, the
    # pulsating sphere at the top of its first pulse (frame 30, t = 0.5 s).
    module = load_example("example_user_meshes")
    with wp.ScopedDevice(DEFAULT_DEVICE):
        example = module.Example(stage_path=None)
        rigid, deforming = set(), set()
        for _ in range(30):
            example.step()
            rigid.add(bool(example.rigid_result.colliding.any()))
            deforming.add(bool(example.deforming_result.colliding.any()))
    assert True in rigid
    assert deforming == {True, False}


NEWTON_VIEWER_NEEDS_CPU = "cpu" not in [str(d) for d in wp.get_devices()]
"""newton's USD viewer computes vertex normals in a CPU kernel: where Warp has no CPU compiler (a CUDA machine's
Warp may not), the newton example cannot write its animation."""


def test_example_newton_pile_one_frame(tmp_path, device):
    pytest.importorskip("newton")
    pxr = pytest.importorskip("pxr")
    if NEWTON_VIEWER_NEEDS_CPU:
        pytest.skip("newton's USD viewer needs Warp's CPU compiler, absent here")
    module = load_example("example_newton_pile")
    path = tmp_path / "pile.usda"
    with wp.ScopedDevice(device):
        example = module.Example(stage_path=str(path), num_rings=2, num_blocks=1)
        example.step()
        example.render()
        example.close()
    assert example.bridge.mesh_shapes.tolist() == [1, 2, 3, 4]  # the peg, two rings, a block: every mesh
    assert len(example.bridge.newton_pairs) == 3  # each body on the ground plane, left to newton
    z = example.state_0.body_q.numpy()[:, 2]
    assert (z < [0.9, 1.2, 2.1]).all()  # falling
    assert pxr.Usd.Stage.Open(str(path)).GetPseudoRoot().GetChildren()


@pytest.mark.parametrize(
    "name, args, files",
    [
        ("example_collision", ["--num-objects", "10"], ["example_collision.usd"]),
        ("example_user_meshes", [], ["example_user_meshes.usd", "example_user_meshes_deforming.usd"]),
        ("example_newton_pile", ["--num-rings", "1", "--num-blocks", "1"], ["example_newton_pile.usd"]),
    ],
)
def test_example_scripts_run_one_frame(tmp_path, name, args, files):
    if name == "example_newton_pile":
        pytest.importorskip("newton")
        if NEWTON_VIEWER_NEEDS_CPU:
            pytest.skip("newton's USD viewer needs Warp's CPU compiler, absent here")
    proc = run_script(name, "--device", DEFAULT_DEVICE, "--num-frames", "1", *args, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(files)  # default stage path(s)


def test_example_script_stage_path_none(tmp_path):
    proc = run_script("example_collision", "--device", DEFAULT_DEVICE, "--num-frames", "1", "--num-objects", "5",
                      "--stage-path", "None", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_example_usd_check(tmp_path, device, capsys):
    pytest.importorskip("pxr")
    module = load_example("example_usd_check")
    stage, report = tmp_path / "animation.usda", tmp_path / "report.json"
    status = module.main(["--device", device, "--stage-path", str(stage), "--num-frames", "8",
                          "--report", str(report)])
    out = capsys.readouterr().out
    assert status == 1  # the arm folds into the crate, the wheels roll 1-5 cm deep in the floor
    pairs = {(p["a"], p["b"]) for p in json.loads(report.read_text())["pairs"]}
    assert ("/World/Floor", "/World/WheelL/Tyre") in pairs and ("/World/Crate", "/World/Arm/Upper/Lower/Link") in pairs
    assert ("/World/Floor", "/World/Crate") not in pairs  # resting contact: touching, not penetrating
    assert "/World/WheelR/Tyre" in out
    # Shallow crossings forgiven: the wheels (at most 5 cm deep) are gone, the arm in the crate stays.
    status = module.main(["--device", device, "--stage-path", str(stage), "--num-frames", "8", "--min-depth", "0.06",
                          "--report", str(report)])
    pairs = {(p["a"], p["b"]) for p in json.loads(report.read_text())["pairs"]}
    assert status == 1 and all("Wheel" not in a + b for a, b in pairs) and pairs
