"""Where output goes. A destination of the files the library writes (:mod:`warp_ccd._src.output`)
that is a FIFO, a device or another file that is not a regular one is refused, never replaced; a
symbolic link is written through to its target and stays a link. A standard output whose reader
has gone (a closed pipe) ends the command quietly with its verdict's status."""

import os

import pytest

from warp_ccd._src.output import check_output_path, prepare_text

from conftest import DEFAULT_DEVICE


def test_a_fifo_is_refused_not_replaced(tmp_path):
    fifo = tmp_path / "report.json"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match=f"cannot write {fifo}: it is a FIFO"):
        check_output_path(fifo, (".json",), "report")
    with pytest.raises(ValueError, match="FIFO"):
        prepare_text(fifo, "{}", (".json",), "report")
    assert os.path.exists(fifo) and not os.path.isfile(fifo)
    assert sorted(os.listdir(tmp_path)) == ["report.json"]  # no temporary file left


def test_a_link_to_a_device_is_refused(tmp_path):
    link = tmp_path / "report.json"
    link.symlink_to(os.devnull)
    with pytest.raises(ValueError, match=f"cannot write {link}: it is a character device .*{os.devnull}"):
        check_output_path(link, (".json",), "report")
    assert os.path.islink(link)


def test_the_destination_turned_fifo_before_the_rename_is_refused(tmp_path):
    path = tmp_path / "report.json"
    pending = prepare_text(path, "{}", (".json",), "report")
    os.mkfifo(path)
    with pytest.raises(ValueError, match="FIFO"):
        pending.commit()
    assert not os.path.isfile(path) and sorted(os.listdir(tmp_path)) == ["report.json"]


@pytest.mark.parametrize("dangling", [False, True])
def test_a_symbolic_link_is_written_through(tmp_path, dangling):
    """The link's target gets the new content; the link stays a link (a dangling one creates its target)."""
    (tmp_path / "real").mkdir()
    target = tmp_path / "real" / "out.json"
    if not dangling:
        target.write_text("old")
    link = tmp_path / "report.json"
    link.symlink_to(target)
    prepare_text(link, "new", (".json",), "report").commit()
    assert os.path.islink(link) and os.readlink(link) == str(target)
    assert target.read_text() == "new"
    assert sorted(os.listdir(tmp_path / "real")) == ["out.json"]


def test_the_cli_refuses_a_fifo_output(tmp_path, capsys):
    """``check --report FIFO``: exit 2 naming it, before the stage (missing here) is read."""
    from warp_ccd._src.cli import commands as cli

    fifo = tmp_path / "r.json"
    os.mkfifo(fifo)
    rc = cli.main(["check", str(tmp_path / "missing.usda"), "--report", str(fifo)])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith(f"warp-ccd check: error: cannot write {fifo}: it is a FIFO"), err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("report", [False, True])
def test_a_closed_standard_output_ends_quietly_with_the_verdict(tmp_path, report):
    """``warp-ccd check a.usda | true``: the reader has gone before the summary; the command ends with
    its verdict's status (1: the cubes penetrate), nothing on stderr about a broken pipe, and its
    files written all the same."""
    import subprocess
    import sys

    pytest.importorskip("pxr")
    from test_hostile_input import TRANSLATE, cube, ops, write_stage

    stage = write_stage(tmp_path, cube("B", xform=ops("double3 xformOp:translate = (0.3, 0, 0)", order=TRANSLATE)))
    out = tmp_path / "r.json"
    argv = ["check", str(stage), "--device", DEFAULT_DEVICE, *(["--report", str(out)] if report else [])]
    code = "import sys; from warp_ccd._src.cli.commands import main; sys.exit(main())"
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    p = subprocess.Popen([sys.executable, "-c", code, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=root)
    p.stdout.close()  # the reader goes before anything is written
    err = p.stderr.read().decode()
    assert p.wait() == 1, err
    assert "BrokenPipe" not in err and "Broken pipe" not in err and "Exception ignored" not in err, err
    assert out.is_file() == report
