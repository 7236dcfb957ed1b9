"""The ``warp-ccd`` command: a demo run end to end, and clean failures (one line, no traceback)."""

import os
import subprocess
import sys
import types

import numpy as np
import pytest

from warp_ccd._src.cli import commands as cli

from conftest import DEFAULT_DEVICE, message_lines

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_demo_writes_usd_and_png_and_prints_a_summary(tmp_path, device, capsys):
    pxr = pytest.importorskip("pxr")
    from PIL import Image

    out = tmp_path / "demo.usda"
    png = tmp_path / "preview.png"
    rc = cli.main(["demo", "--num-objects", "40", "--num-frames", "3", "--device", device,
                   "--out", str(out), "--preview", str(png), "--seed", "5", "--aabb"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "Traceback" not in captured.err
    for text in ("40 objects, 3 frames", "colliding objects / frame", "triangle pairs / frame",
                 "ms / frame by stage", "total", str(out), str(png)):
        assert text in captured.out
    stage = pxr.Usd.Stage.Open(str(out))
    assert stage.GetEndTimeCode() == 2
    assert stage.GetPrimAtPath("/World/Bounds")
    with Image.open(png) as im:
        assert im.size == (640, 480)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo.usda", "preview.png"]


def test_demo_segments_writes_the_intersection_segments_of_every_frame(tmp_path, capsys, monkeypatch):
    # --segments: a curve of two points per finite intersection segment of each frame's result.
    pxr = pytest.importorskip("pxr")
    from warp_ccd._src.pipeline import pipeline
    from warp_ccd._src.usd.export import segment_points

    seen = []
    detect = pipeline.CollisionPipeline.detect

    def recording_detect(self):
        res = detect(self)
        seen.append(segment_points(res.segments))
        return res

    monkeypatch.setattr(pipeline.CollisionPipeline, "detect", recording_detect)
    out = tmp_path / "segments.usda"
    rc = cli.main(["demo", "--num-objects", "40", "--num-frames", "3", "--device", DEFAULT_DEVICE,
                   "--out", str(out), "--seed", "5", "--segments"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert len(seen) == 3
    assert sum(len(p) for p in seen) > 0  # the scene has intersections to draw
    stage = pxr.Usd.Stage.Open(str(out))
    curves = pxr.UsdGeom.BasisCurves(stage.GetPrimAtPath("/World/Segments"))
    assert curves
    for frame, expected in enumerate(seen):
        code = pxr.Usd.TimeCode(frame)
        np.testing.assert_array_equal(np.asarray(curves.GetCurveVertexCountsAttr().Get(code)),
                                      np.full(len(expected) // 2, 2))
        np.testing.assert_array_equal(np.asarray(curves.GetPointsAttr().Get(code), np.float32).reshape(-1, 3),
                                      expected)


def test_demo_gif_has_one_image_per_frame(tmp_path, capsys):
    from PIL import Image

    gif = tmp_path / "anim.gif"
    rc = cli.main(["demo", "--num-objects", "10", "--num-frames", "3", "--device", DEFAULT_DEVICE,
                   "--out", str(tmp_path / "d.usd"), "--preview", str(gif)])
    assert rc == 0, capsys.readouterr().err
    with Image.open(gif) as im:
        assert im.n_frames == 3


@pytest.mark.parametrize(
    "args, message",
    [
        (["demo", "--num-objects", "-5"], "--num-objects"),
        (["demo", "--num-frames", "-1"], "--num-frames"),
        (["demo", "--num-frames", "abc"], "--num-frames"),
        (["demo", "--seed", "-3"], "--seed"),
        (["demo", "--device", "tpu:9"], "unknown device"),
        (["demo", "--out", "{tmp}/nope/out.usd"], "does not exist"),
        (["demo", "--out", "{tmp}/out.obj"], "unknown USD extension"),
        (["demo", "--out", "{tmp}"], "unknown USD extension"),
        (["demo", "--preview", "{tmp}/p.jpg"], "unknown preview extension"),
        (["demo", "--preview", "{tmp}/nope/p.png"], "does not exist"),
        (["demo", "--bogus"], "unrecognized arguments"),
        (["fly"], "invalid choice"),
        ([], "required"),
    ],
)
def test_bad_arguments_fail_with_one_line(tmp_path, capsys, args, message):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    if args[:1] == ["demo"] and "--out" not in args:
        args += ["--out", str(tmp_path / "never.usd")]
    rc = cli.main(args + ["--num-frames", "2"] if args[:1] == ["demo"] and "--num-frames" not in args else args)
    captured = capsys.readouterr()
    assert rc == 2
    lines = message_lines(captured.err)
    assert len(lines) == 1, captured.err
    assert message in lines[0] and "Traceback" not in captured.err
    assert captured.out == ""
    assert list(tmp_path.iterdir()) == []  # nothing written, no temporary file left


def test_unwritable_out_fails_before_the_run(tmp_path, capsys):
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        folder = "/proc"
        if not os.path.isdir("/proc/self"):
            pytest.skip("running as root without /proc")
    else:
        folder = tmp_path / "ro"
        folder.mkdir()
        folder.chmod(0o500)
    rc = cli.main(["demo", "--num-frames", "1", "--out", os.path.join(folder, "x.usd")])
    captured = capsys.readouterr()
    assert rc == 2
    assert len(message_lines(captured.err)) == 1 and "cannot" in captured.err
    assert captured.out == ""


def test_interrupt_leaves_no_file(tmp_path, capsys, monkeypatch):
    from warp_ccd._src.usd import export as usd

    out = tmp_path / "x.usd"
    out.write_bytes(b"previous")
    calls = []

    def add_frame(self, frame_index, result=None):
        calls.append(frame_index)
        if frame_index == 1:
            raise KeyboardInterrupt

    monkeypatch.setattr(usd.UsdAnimationWriter, "add_frame", add_frame)
    rc = cli.main(["demo", "--num-objects", "5", "--num-frames", "4", "--device", DEFAULT_DEVICE, "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 130 and calls == [0, 1]
    assert "interrupted" in captured.err and "Traceback" not in captured.err
    assert out.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["x.usd"]


def test_bench_forwards_arguments(monkeypatch):
    seen = []
    fake = types.ModuleType("warp_ccd.bench")
    fake.main = lambda argv: seen.append(argv) or 0
    monkeypatch.setitem(sys.modules, "warp_ccd.bench", fake)
    assert cli.main(["bench", "--num-objects", "10", "--help"]) == 0
    assert seen == [["--num-objects", "10", "--help"]]

    fake.main = lambda argv: 3
    assert cli.main(["bench"]) == 3


def test_bench_missing_module_is_a_clear_error(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "warp_ccd.bench", None)  # import fails as if the file were absent
    rc = cli.main(["bench", "--quick"])
    captured = capsys.readouterr()
    assert rc == 2
    assert message_lines(captured.err) == [
        "warp-ccd bench: error: the benchmark module warp_ccd.bench is not available in this installation"
    ]


def test_help_exits_zero(capsys):
    assert cli.main(["demo", "--help"]) == 0
    assert "--num-objects" in capsys.readouterr().out


def run_module(*args, cwd):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "warp_ccd", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


def test_python_dash_m_runs_the_demo(tmp_path):
    proc = run_module("demo", "--num-objects", "8", "--num-frames", "2", "--device", DEFAULT_DEVICE, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "collisions.usd").is_file()  # the default output, in the working folder
    assert "8 objects, 2 frames" in proc.stdout
    assert "Warp " not in proc.stdout  # Warp's start-up banner stays out of the summary


def test_python_dash_m_bad_argument_has_no_traceback(tmp_path):
    proc = run_module("demo", "--num-objects", "-1", cwd=tmp_path)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert len(message_lines(proc.stderr)) == 1
    assert list(tmp_path.iterdir()) == []


def test_summary_means(tmp_path, capsys, monkeypatch):
    # The summary's means are those of the frames' results.
    from warp_ccd._src.pipeline import pipeline

    seen = []
    detect = pipeline.CollisionPipeline.detect

    def recording_detect(self):
        res = detect(self)
        seen.append((int(res.colliding.sum()), res.num_triangle_pairs))
        return res

    monkeypatch.setattr(pipeline.CollisionPipeline, "detect", recording_detect)
    rc = cli.main(["demo", "--num-objects", "60", "--num-frames", "4", "--device", DEFAULT_DEVICE,
                   "--out", str(tmp_path / "s.usd")])
    out = capsys.readouterr().out
    assert rc == 0
    counts = np.array(seen)
    assert f"mean {counts[:, 0].mean():.1f}" in out
    assert f"mean {counts[:, 1].mean():.1f}" in out
