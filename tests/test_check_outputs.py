"""``warp-ccd check`` on the command line: outputs that would overwrite an input, exit statuses
and what the report says about them, missing layers, all outputs or none, argument details, and
what it prints on stderr."""

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from warp_ccd._src.cli import commands as cli
from warp_ccd._src.cli import common as cli_common

pxr = pytest.importorskip("pxr")
from pxr import Gf, Sdf, Usd, UsdGeom  # noqa: E402
from usd_stages import define_mesh, grid, mixed_stage, prism  # noqa: E402

from conftest import DEFAULT_DEVICE, message_lines  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run_cli(capsys, args):
    rc = cli.main(args)
    captured = capsys.readouterr()
    return rc, captured


def listing(folder) -> dict:
    """Every file under ``folder`` (relative name -> bytes; a symbolic link -> its target)."""
    out = {}
    for base, _, files in os.walk(folder):
        for name in files:
            path = os.path.join(base, name)
            key = os.path.relpath(path, folder)
            out[key] = ("link", os.readlink(path)) if os.path.islink(path) else open(path, "rb").read()
    return out


def new_stage(path, start=0, end=3):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    stage.SetStartTimeCode(start)
    stage.SetEndTimeCode(end)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    return stage


def sunk_cube(stage, path="/World/Cube", depth=0.1):
    """A prism sunk ``depth`` into the floor (penetrating when ``depth > 0``, touching at 0)."""
    cube = define_mesh(stage, path, *prism(4, radius=0.7, height=1.0))
    UsdGeom.Xformable(cube).AddTranslateOp().Set(Gf.Vec3d(-3.0, -depth, -3.0))
    return cube


@pytest.fixture
def layered(tmp_path):
    """``anim.usda`` whose floor is a sublayer's, its cube a reference's, a second cube a payload's."""
    sub = new_stage(tmp_path / "sub.usda")
    define_mesh(sub, "/World/Floor", *grid(6, 12.0))
    sub.GetRootLayer().Save()
    ref = new_stage(tmp_path / "geo.usda")
    sunk_cube(ref)
    ref.GetRootLayer().Save()
    pay = new_stage(tmp_path / "pay.usda")
    define_mesh(pay, "/World/Box", *prism(4, radius=0.5, height=1.0))
    pay.GetRootLayer().Save()
    stage = new_stage(tmp_path / "anim.usda")
    stage.GetRootLayer().subLayerPaths.append("./sub.usda")
    stage.DefinePrim("/World/Ref").GetReferences().AddReference("./geo.usda", "/World")
    stage.DefinePrim("/World/Pay").GetPayloads().AddPayload("./pay.usda", "/World")
    stage.GetRootLayer().Save()
    return tmp_path / "anim.usda"


def test_layered_fixture_composes(layered, capsys):
    rc, captured = run_cli(capsys, ["check", str(layered), "--device", DEFAULT_DEVICE, "--frames", "0"])
    assert rc == 1, captured.err
    assert "/World/Ref/Cube" in captured.out and "/World/Floor" in captured.out


# ---------------------------------------------------------------------------------------------
# 1. never write over an input


@pytest.mark.parametrize("case", ["input", "sublayer", "reference", "payload", "symlink_to_input",
                                  "folder_link", "report_is_usd_out", "report_links_to_usd_out"])
def test_outputs_never_overwrite_an_input(layered, capsys, case):
    folder = layered.parent
    report = None
    usd_out = folder / "over.usda"
    if case == "input":
        usd_out, named = layered, "anim.usda"
    elif case == "sublayer":
        usd_out, named = folder / "sub.usda", "sub.usda"
    elif case == "reference":
        usd_out, named = folder / "geo.usda", "geo.usda"
    elif case == "payload":
        usd_out, named = folder / "pay.usda", "pay.usda"
    elif case == "symlink_to_input":
        os.symlink(layered, folder / "link.usda")
        usd_out, named = folder / "link.usda", "link.usda"
    elif case == "folder_link":  # the input again, through a link to its folder
        os.symlink(folder, folder / "again")
        usd_out, named = folder / "again" / "anim.usda", "anim.usda"
    elif case == "report_is_usd_out":
        report = usd_out = folder / "out.json"
        named = "out.json"
    else:
        (folder / "over.usda").write_text("#usda 1.0\n")
        os.symlink(folder / "over.usda", folder / "r.json")
        report, named = folder / "r.json", "over.usda"
    before = listing(folder)
    args = ["check", str(layered), "--device", DEFAULT_DEVICE, "--usd-out", str(usd_out)]
    if report is not None:
        args += ["--report", str(report)]
    rc, captured = run_cli(capsys, args)
    assert rc == 2, captured.err
    (line,) = message_lines(captured.err)
    assert line.startswith("warp-ccd check: error:") and named in line and "written over" in line
    assert "Traceback" not in captured.err and captured.out == ""
    assert listing(folder) == before  # nothing written, nothing changed


def test_write_overlay_refuses_a_layer_of_the_stage(layered):
    from warp_ccd._src.check.check import check_usd
    from warp_ccd._src.check.overlay import write_overlay

    report = check_usd(layered, frames=[0.0], device=DEFAULT_DEVICE)
    before = (layered.parent / "sub.usda").read_bytes()
    with pytest.raises(ValueError, match="sub.usda"):
        write_overlay(report, layered.parent / "sub.usda")
    assert (layered.parent / "sub.usda").read_bytes() == before
    assert write_overlay(report, layered.parent / "over.usda") == str(layered.parent / "over.usda")


# ---------------------------------------------------------------------------------------------
# 2. honest exit status


@pytest.fixture
def resting(tmp_path):
    """A cube resting on the floor every frame: touching, never penetrating."""
    stage = new_stage(tmp_path / "resting.usda")
    define_mesh(stage, "/World/Floor", *grid(6, 12.0))
    sunk_cube(stage, depth=0.0)
    stage.GetRootLayer().Save()
    return tmp_path / "resting.usda"


def test_findings_touching_and_penetrating(resting, tmp_path, capsys):
    report = tmp_path / "r.json"
    rc, captured = run_cli(capsys, ["check", str(resting), "--device", DEFAULT_DEVICE, "--report", str(report)])
    assert rc == 0, captured.err
    data = json.loads(report.read_text())
    assert (data["findings"], data["penetrating"], data["touching"]) == (None, False, True)

    rc, captured = run_cli(capsys, ["check", str(resting), "--device", DEFAULT_DEVICE, "--count-touching",
                                    "--report", str(report)])
    assert rc == 1, captured.err
    data = json.loads(report.read_text())
    assert (data["findings"], data["penetrating"], data["touching"]) == ("touching", False, True)
    assert data["pairs"]  # the touching pair is reported

    sunk = tmp_path / "sunk.usda"
    stage = new_stage(sunk)
    define_mesh(stage, "/World/Floor", *grid(6, 12.0))
    sunk_cube(stage, depth=0.1)
    stage.GetRootLayer().Save()
    for extra in ([], ["--count-touching"]):
        rc, captured = run_cli(capsys, ["check", str(sunk), "--device", DEFAULT_DEVICE, "--report", str(report),
                                        *extra])
        assert rc == 1, captured.err
        data = json.loads(report.read_text())
        assert (data["findings"], data["penetrating"]) == ("penetrating", True)


def test_report_findings_property(resting):
    from warp_ccd._src.check.check import check_usd

    strict = check_usd(resting, frames=[0.0], device=DEFAULT_DEVICE)
    assert (strict.findings, strict.penetrating, strict.touching) == (None, False, True)
    counted = check_usd(resting, frames=[0.0], count_touching=True, device=DEFAULT_DEVICE)
    assert len(counted.frames[0].triangle_pairs) > 0
    assert (counted.findings, counted.penetrating, counted.touching) == ("touching", False, True)
    deep = check_usd(resting, frames=[0.0], count_touching=True, min_depth=1.0, device=DEFAULT_DEVICE)
    assert deep.findings == "touching"


def test_internal_error_is_one_line_exit_3(resting, capsys, monkeypatch):
    from warp_ccd._src.check import check

    def broken(*args, **kwargs):
        raise RuntimeError("device lost\nsecond line")

    monkeypatch.setattr(check, "check_usd", broken)
    rc, captured = run_cli(capsys, ["check", str(resting), "--device", DEFAULT_DEVICE])
    assert rc == cli_common.EXIT_INTERNAL == 3
    (line,) = message_lines(captured.err)
    assert "internal error" in line and "RuntimeError: device lost" in line and "--debug" in line
    assert "Traceback" not in captured.err

    rc, captured = run_cli(capsys, ["check", str(resting), "--device", DEFAULT_DEVICE, "--debug"])
    assert rc == 3
    assert "Traceback" in captured.err and "RuntimeError: device lost" in captured.err

    def no_memory(*args, **kwargs):
        raise MemoryError()

    monkeypatch.setattr(check, "check_usd", no_memory)
    rc, captured = run_cli(capsys, ["check", str(resting), "--device", DEFAULT_DEVICE])
    assert rc == 3
    (line,) = message_lines(captured.err)
    assert "internal error: MemoryError" in line


def test_absurd_frame_count_is_bad_input(resting, tmp_path, capsys):
    rc, captured = run_cli(capsys, ["check", str(resting), "--device", DEFAULT_DEVICE, "--frames", "0:3:1e-9",
                                    "--report", str(tmp_path / "r.json")])
    assert rc == 2, captured.err
    (line,) = message_lines(captured.err)
    assert line.startswith("warp-ccd check: error:") and "Traceback" not in captured.err
    assert not (tmp_path / "r.json").exists()


@pytest.fixture
def missing_ref(tmp_path):
    stage = new_stage(tmp_path / "holes.usda")
    define_mesh(stage, "/World/Floor", *grid(6, 12.0))
    sunk_cube(stage, depth=0.1)
    stage.DefinePrim("/World/Gone").GetReferences().AddReference("./gone.usda")
    stage.GetRootLayer().Save()
    return tmp_path / "holes.usda"


def test_missing_reference_is_an_error_unless_allowed(missing_ref, tmp_path, capsys):
    report = tmp_path / "r.json"
    rc, captured = run_cli(capsys, ["check", str(missing_ref), "--device", DEFAULT_DEVICE, "--report", str(report)])
    assert rc == 2, captured.err
    (line,) = message_lines(captured.err)
    assert "gone.usda" in line and "--allow-missing" in line
    assert not report.exists()

    rc, captured = run_cli(capsys, ["check", str(missing_ref), "--device", DEFAULT_DEVICE, "--report", str(report),
                                    "--allow-missing"])
    assert rc == 1, captured.err
    data = json.loads(report.read_text())
    assert data["missing"] == [str(tmp_path / "gone.usda")]
    assert "gone.usda" in captured.out  # the summary says what was not checked


def test_missing_layers_and_check_usd_allow_missing(missing_ref, layered, tmp_path):
    from warp_ccd._src.check.check import check_usd
    from warp_ccd._src.usd.stage import missing_layers, open_stage

    sub = tmp_path / "withsub.usda"
    stage = new_stage(sub)
    stage.GetRootLayer().subLayerPaths.append("./nosuch.usda")
    stage.DefinePrim("/World/P").GetPayloads().AddPayload("./nopayload.usda")
    define_mesh(stage, "/World/Floor", *grid(6, 12.0))
    stage.GetRootLayer().Save()
    assert missing_layers(open_stage(sub)) == [str(tmp_path / "nopayload.usda"), str(tmp_path / "nosuch.usda")]
    assert missing_layers(open_stage(layered)) == []

    with pytest.raises(ValueError, match="gone.usda"):
        check_usd(missing_ref, device=DEFAULT_DEVICE)
    report = check_usd(missing_ref, device=DEFAULT_DEVICE, allow_missing=True)
    assert report.missing == [str(tmp_path / "gone.usda")] and report.penetrating
    assert report.to_json()["missing"] == report.missing
    assert check_usd(layered, frames=[0.0], device=DEFAULT_DEVICE).to_json()["missing"] == []


def test_missing_layers_print_nothing_of_usds_own(missing_ref, tmp_path):
    """USD's warnings about the layers it cannot open ("Warning: in _ReportErrors at line ... Could not open
    asset @gone.usda@ ...") are not printed: the command's standard error is its one line, which names them;
    check_usd prints nothing either, raising or keeping them in the report (a child process: the warnings are
    written to the C-level standard error, which capsys does not see)."""
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    stage = new_stage(tmp_path / "sub.usda")
    stage.GetRootLayer().subLayerPaths.append("./nosuch.usda")
    stage.GetRootLayer().Save()
    for path in (missing_ref, tmp_path / "sub.usda"):
        proc = subprocess.run([sys.executable, "-m", "warp_ccd", "check", str(path), "--device", DEFAULT_DEVICE],
                              cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 2, proc.stderr
        (line,) = message_lines(proc.stderr)
        assert line.startswith("warp-ccd check: error:") and ("gone.usda" in line or "nosuch.usda" in line)
    code = ("import sys\nfrom warp_ccd.usd import check_usd\n"
            f"try:\n    check_usd({str(missing_ref)!r}, device={DEFAULT_DEVICE!r})\n"
            "except ValueError as exc:\n    print(exc)\n"
            f"print(check_usd({str(missing_ref)!r}, device={DEFAULT_DEVICE!r}, allow_missing=True).missing)")
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert message_lines(proc.stderr) == []
    assert "cannot open" in proc.stdout and str(tmp_path / "gone.usda") in proc.stdout


# ---------------------------------------------------------------------------------------------
# 3. all outputs or none


@pytest.fixture
def mixed_file(tmp_path):
    path = tmp_path / "anim.usda"
    mixed_stage(path, num_frames=8)
    return path


def test_failed_overlay_leaves_every_output_as_it_was(mixed_file, tmp_path, capsys, monkeypatch):
    outs = {"r.json": b"old report", "o.usda": b"old overlay", "p.png": b"old picture"}
    for name, data in outs.items():
        (tmp_path / name).write_bytes(data)
    prepared = []
    from warp_ccd._src.check.report import CheckReport

    prepare_json = CheckReport.prepare_json

    def recording(self, path):
        pending = prepare_json(self, path)
        prepared.append(pending.temp_path)
        return pending

    monkeypatch.setattr(CheckReport, "prepare_json", recording)
    monkeypatch.setattr(Sdf.Layer, "Export", lambda self, *args, **kwargs: False)
    before = listing(tmp_path)
    rc, captured = run_cli(capsys, ["check", str(mixed_file), "--frames", "0:6:3", "--device", DEFAULT_DEVICE,
                                    "--report", str(tmp_path / "r.json"), "--usd-out", str(tmp_path / "o.usda"),
                                    "--preview", str(tmp_path / "p.png")])
    assert rc == 2, captured.err
    (line,) = message_lines(captured.err)
    assert "o.usda" in line and "export failed" in line
    assert len(prepared) == 1  # the report was written (to its temporary file) before the overlay failed
    assert listing(tmp_path) == before  # old outputs unchanged, no temporary file left


def test_interrupt_while_drawing_leaves_every_output_as_it_was(mixed_file, tmp_path, capsys, monkeypatch):
    from warp_ccd import preview

    for name in ("r.json", "o.usda"):
        (tmp_path / name).write_bytes(b"old " + name.encode())

    def interrupted(self, colliding=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(preview.PreviewRenderer, "render", interrupted)
    before = listing(tmp_path)
    rc, captured = run_cli(capsys, ["check", str(mixed_file), "--frames", "0:6:3", "--device", DEFAULT_DEVICE,
                                    "--report", str(tmp_path / "r.json"), "--usd-out", str(tmp_path / "o.usda"),
                                    "--preview", str(tmp_path / "p.png")])
    assert rc == 130
    assert "interrupted" in captured.err and "Traceback" not in captured.err
    assert listing(tmp_path) == before


def test_all_outputs_written_together(mixed_file, tmp_path, capsys, monkeypatch):
    from warp_ccd._src import output

    order = []
    commit = output.PendingFile.commit

    def recording(self):
        order.append(("commit", os.path.basename(self.path)))
        return commit(self)

    init = output.PendingFile.__init__

    def created(self, path):
        order.append(("create", os.path.basename(path)))
        init(self, path)

    monkeypatch.setattr(output.PendingFile, "commit", recording)
    monkeypatch.setattr(output.PendingFile, "__init__", created)
    rc, captured = run_cli(capsys, ["check", str(mixed_file), "--frames", "0:6:3", "--device", DEFAULT_DEVICE,
                                    "--report", str(tmp_path / "r.json"), "--usd-out", str(tmp_path / "o.usda"),
                                    "--preview", str(tmp_path / "p.png")])
    assert rc == 1, captured.err
    assert [kind for kind, _ in order] == ["create"] * 3 + ["commit"] * 3
    assert sorted(os.listdir(tmp_path)) == ["anim.usda", "o.usda", "p.png", "r.json"]


# ---------------------------------------------------------------------------------------------
# 4. arguments


def test_directory_input_says_so(tmp_path, capsys):
    rc, captured = run_cli(capsys, ["check", str(tmp_path)])
    assert rc == 2
    (line,) = message_lines(captured.err)
    assert "is a directory" in line and "no such file" not in line


def test_prims_do_not_swallow_the_input(mixed_file, tmp_path, capsys):
    report = tmp_path / "r.json"
    rc, captured = run_cli(capsys, ["check", "--prims", "/World/Floor,/World/Stretched", str(mixed_file),
                                    "--frames", "0", "--device", DEFAULT_DEVICE, "--report", str(report)])
    assert rc == 1, captured.err
    assert json.loads(report.read_text())["objects"] == 2
    rc, captured = run_cli(capsys, ["check", "--prims", "/World/Floor", str(mixed_file), "--prims",
                                    "/World/Stretched", "--prims", "/World/Movers/*", "--frames", "0",
                                    "--device", DEFAULT_DEVICE, "--report", str(report)])
    assert rc == 1, captured.err
    assert json.loads(report.read_text())["objects"] == 4
    rc, captured = run_cli(capsys, ["check", "--prims", "/World/Floor,", str(mixed_file)])
    assert rc == 2 and "--prims" in message_lines(captured.err)[0]
    # Paths and patterns together: each path's subtree, and what the patterns match.
    from warp_ccd._src.usd.importer import UsdMeshImport

    imp = UsdMeshImport(mixed_file, prims=["/World/Floor", "/World/Movers/*"])
    assert sorted(imp.object_path) == ["/World/Floor", "/World/Movers/A/Geom", "/World/Movers/B/Geom"]
    with pytest.raises(ValueError, match=re.escape("/World/Zz*")):
        UsdMeshImport(mixed_file, prims=["/World/Floor", "/World/Zz*"])


def test_negative_frames_without_equals(tmp_path, capsys):
    path = tmp_path / "neg.usda"
    stage = new_stage(path, start=-5, end=10)
    define_mesh(stage, "/World/Floor", *grid(6, 12.0))
    sunk_cube(stage, depth=0.0)
    stage.GetRootLayer().Save()
    report = tmp_path / "r.json"
    for frames in (["--frames", "-5:10"], ["--frames", "-5:0:2.5"], ["--frames", "-5"], ["--frames=-5:10"]):
        rc, captured = run_cli(capsys, ["check", str(path), *frames, "--device", DEFAULT_DEVICE,
                                        "--report", str(report)])
        assert rc == 0, (frames, captured.err)
        assert json.loads(report.read_text())["times"][0] == -5.0
    assert json.loads(report.read_text())["times"] == np.arange(-5.0, 10.5).tolist()


def test_summary_counts_face_pairs_per_frame(mixed_file, capsys):
    from warp_ccd._src.check.check import check_usd

    rc, captured = run_cli(capsys, ["check", str(mixed_file), "--frames", "0:6:3", "--device", DEFAULT_DEVICE])
    assert rc == 1, captured.err
    out = captured.out
    assert "triangle pairs" not in out and "face pairs / frame" in out and "max face pairs" in out
    report = check_usd(mixed_file, frames=[0.0, 3.0, 6.0], device=DEFAULT_DEVICE)
    rows = np.array([len(f.triangle_pairs) for f in report.frames])
    touching = np.array([f.num_touching for f in report.frames])
    assert touching.sum() != touching.mean()  # else the test would not tell a total from a mean
    line = next(x for x in out.splitlines() if "face pairs / frame" in x)
    assert f"mean {rows.mean():.1f}, max {rows.max()}" in line
    assert f"mean {touching.mean():.1f}, max {touching.max()}" in line
    assert str(touching.sum()) not in line.split(";")[1].replace(f"{touching.max()}", "")


# ---------------------------------------------------------------------------------------------
# 5. what it prints on stderr


def test_compiling_kernels_notice(resting, capsys, monkeypatch):
    seen = []

    def uncached(device, names):
        seen.append((str(device), tuple(names)))
        return ["warp_ccd._src.narrowphase.discrete"]

    monkeypatch.setattr(cli, "uncached_modules", uncached)
    rc, captured = run_cli(capsys, ["check", str(resting), "--device", DEFAULT_DEVICE, "--frames", "0"])
    assert rc == 0, captured.err
    (line,) = [x for x in captured.err.splitlines() if "compiling" in x]
    assert f"compiling kernels for {DEFAULT_DEVICE}" in line
    assert seen and "warp_ccd._src.narrowphase.discrete" in seen[0][1]
    monkeypatch.setattr(cli, "uncached_modules", lambda device, names: [])
    rc, captured = run_cli(capsys, ["check", str(resting), "--device", DEFAULT_DEVICE, "--frames", "0"])
    assert rc == 0 and "compiling" not in captured.err


def test_uncached_modules_reads_the_kernel_cache(resting, tmp_path, capsys, monkeypatch):
    import warp as wp

    rc, captured = run_cli(capsys, ["check", str(resting), "--device", DEFAULT_DEVICE, "--frames", "0"])
    assert rc == 0, captured.err
    assert cli_common.uncached_modules(DEFAULT_DEVICE, cli.CHECK_KERNEL_MODULES) == []  # just compiled or loaded
    monkeypatch.setattr(wp.config, "kernel_cache_dir", str(tmp_path / "empty"))
    assert cli_common.uncached_modules(DEFAULT_DEVICE, cli.CHECK_KERNEL_MODULES) == list(cli.CHECK_KERNEL_MODULES)


def test_no_cuda_driver_notice(resting, tmp_path):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-m", "warp_ccd", "check", str(resting), "--frames", "0",
                           "--device", DEFAULT_DEVICE], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "Warp CUDA" not in proc.stderr and "Warp " not in proc.stdout


# ---------------------------------------------------------------------------------------------
# 6. --report -: the JSON report on stdout, everything else on stderr


def test_report_to_stdout(mixed_file, resting, tmp_path, capsys):
    jsonschema = pytest.importorskip("jsonschema", reason="jsonschema (a test extra) is not installed")

    from warp_ccd.usd import report_schema

    rc, captured = run_cli(capsys, ["check", str(mixed_file), "--frames", "0:6:3", "--device", DEFAULT_DEVICE,
                                    "--report", "-"])
    assert rc == 1, captured.err
    data = json.loads(captured.out)  # stdout holds the report alone
    jsonschema.validate(data, report_schema())
    assert data["findings"] == "penetrating" and data["times"] == [0.0, 3.0, 6.0]
    assert "face pairs / frame" in captured.err and "report : standard output" in captured.err  # the summary
    # The same report as a file (but for the time each part took).
    file_report = tmp_path / "r.json"
    rc, _ = run_cli(capsys, ["check", str(mixed_file), "--frames", "0:6:3", "--device", DEFAULT_DEVICE,
                             "--report", str(file_report)])
    on_file = json.loads(file_report.read_text())
    assert rc == 1 and {**on_file, "seconds": None} == {**data, "seconds": None}
    rc, captured = run_cli(capsys, ["check", str(resting), "--device", DEFAULT_DEVICE, "--frames", "0",
                                    "--report", "-"])
    assert rc == 0, captured.err
    assert json.loads(captured.out)["findings"] is None and json.loads(captured.out)["touching"] is True


def test_report_to_stdout_with_files(mixed_file, tmp_path, capsys, monkeypatch):
    args = ["check", str(mixed_file), "--frames", "0:6:3", "--device", DEFAULT_DEVICE, "--report", "-",
            "--usd-out", str(tmp_path / "o.usda"), "--preview", str(tmp_path / "p.png")]
    rc, captured = run_cli(capsys, args)
    assert rc == 1, captured.err
    assert json.loads(captured.out)["findings"] == "penetrating"
    assert sorted(os.listdir(tmp_path)) == ["anim.usda", "o.usda", "p.png"]
    assert str(tmp_path / "o.usda") in captured.err and str(tmp_path / "o.usda") not in captured.out
    # All or none: a failed overlay leaves the files as they were and prints no report.
    before = listing(tmp_path)
    monkeypatch.setattr(Sdf.Layer, "Export", lambda self, *a, **k: False)
    rc, captured = run_cli(capsys, args)
    assert rc == 2 and captured.out == ""
    line = message_lines(captured.err)[-1]  # after the summary, on stderr too
    assert line.startswith("warp-ccd check: error:") and "export failed" in line
    assert listing(tmp_path) == before


def test_report_to_stdout_bad_input_and_internal_error(tmp_path, resting, capsys, monkeypatch):
    rc, captured = run_cli(capsys, ["check", str(tmp_path / "nope.usda"), "--report", "-"])
    assert rc == 2 and captured.out == ""
    assert len(message_lines(captured.err)) == 1
    rc, captured = run_cli(capsys, ["check", str(resting), "--report", "-", "--usd-out", "-"])
    assert rc == 2 and captured.out == "" and "--usd-out" not in captured.out  # '-' is for the report only
    assert "unknown USD extension" in message_lines(captured.err)[0]
    from warp_ccd._src.check import check

    def broken(*args, **kwargs):
        raise RuntimeError("device lost")

    monkeypatch.setattr(check, "check_usd", broken)
    rc, captured = run_cli(capsys, ["check", str(resting), "--device", DEFAULT_DEVICE, "--report", "-"])
    assert rc == 3 and captured.out == ""
    assert "internal error" in message_lines(captured.err)[0]


def test_report_to_stdout_in_a_process(resting, tmp_path):
    # A fresh interpreter: Warp's start-up, kernel loading and the progress bars stay off stdout.
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-m", "warp_ccd", "check", str(resting), "--frames", "0:1",
                           "--device", DEFAULT_DEVICE, "--report", "-", "--count-touching"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr
    data = json.loads(proc.stdout)
    assert data["findings"] == "touching" and data["times"] == [0.0, 1.0]
    assert "frames with intersecting (touching included) pairs: 2 of 2" in proc.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["resting.usda"]  # no file named "-"
