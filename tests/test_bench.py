"""The scaling benchmark (``warp-ccd bench``, ``python -m warp_ccd.bench``) through its public entry, at tiny
sizes: its results, its verdicts on this package and on its peers, its exit statuses; and the library's counted
frame that its device peers run on.

The developers' benchmarks (the repository's ``bench/``) are not tested here: ``DEVICE=cpu SMOKE=1 bash
bench/run_cuda.sh`` runs them at tiny sizes.
"""

import importlib.util
import json
import runpy
import sys

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.cli import main as cli_main
from warp_ccd._src.cli.common import EXIT_INTERNAL, EXIT_OK, EXIT_USAGE
from warp_ccd._src.runtime.buffers import CounterRead, GrowableBuffer, reserve_slot
from warp_ccd._src.runtime.frame import MODES, CountedFrame
from warp_ccd.bench import main

ROW_KEYS = {"method", "n_objects", "triangles_per_object", "stage", "ms_min", "ms_median", "object_pairs",
            "triangle_pairs"}
HAS_MATPLOTLIB = importlib.util.find_spec("matplotlib") is not None
TINY = ["--frames", "1", "--warmup", "0", "--no-memory"]


def test_bench_end_to_end(device, tmp_path, capsys):
    """Every peer at two sizes and two kinds of objects: rows, memory, and checks that all agree with this
    package (Warp's built-in pipeline and python-fcl by triangle pairs, the all-pairs broad phase exactly,
    newton's sweep and prune by box pairs)."""
    out = tmp_path / "results.json"
    plot = tmp_path / "scaling.png"
    status = main(["--device", device, "--objects", "30", "150", "--triangles", "poly", "80",
                   "--frames", "2", "--warmup", "1", "--out", str(out), "--plot", str(plot)])
    text = capsys.readouterr().out
    assert status == 0, text
    doc = json.loads(out.read_text())
    assert {"device", "date", "versions", "git_commit", "rows", "memory", "checks"} <= set(doc)
    assert doc["device"] == device and doc["versions"]["warp"] == wp.__version__
    rows = doc["rows"]
    assert rows and all(ROW_KEYS <= set(r) for r in rows)
    assert all(0 <= r["ms_min"] <= r["ms_median"] for r in rows)
    totals = {(r["n_objects"], r["triangles"]) for r in rows if r["method"] == "warp_ccd" and r["stage"] == "total"}
    assert totals == {(30, "poly"), (150, "poly"), (30, "80"), (150, "80")}
    assert {r["triangles_per_object"] for r in rows if r["triangles"] == "80"} == {80}
    stages = {r["stage"] for r in rows if r["method"] == "warp_ccd"}
    assert {"motion", "detect", "total"} <= stages and len(stages) >= 5  # plus the pipeline's own stages
    if wp.get_device(device).is_cuda:  # frames back to back after the checks; eager and graph, the faster quoted
        assert {"loop_graph", "host_loop_graph"} <= stages
        assert {r["mode"] for r in rows if r["method"] == "warp_builtin" and r["stage"] == "detect"} <= set(MODES)
    assert {"warp_ccd", "warp_builtin", "warp_ccd_nxn"} <= {r["method"] for r in rows}
    assert len(doc["memory"]) == 4 and all(m["pipeline_peak_bytes"] > 0 for m in doc["memory"])
    assert doc["checks"] and all(c["ok"] for c in doc["checks"]) and doc["ok"]
    peers = {c["peer"] for c in doc["checks"]}
    assert {"warp_builtin", "fcl", "warp_ccd_nxn"} <= peers
    if importlib.util.find_spec("newton") is not None:
        assert "newton_sap" in peers
    assert text.count("VERDICT") == 4
    if HAS_MATPLOTLIB:
        assert plot.stat().st_size > 1000
    else:
        assert not plot.exists() and "plot skipped" in text


@pytest.mark.parametrize("argv", [["--triangles", "81"], ["--peers", "builtin,bullet"], ["--objects", "1"],
                                  ["--device", "tpu:7"], ["--out", "results.txt"]])
def test_bench_bad_arguments(argv, capsys):
    assert main(argv) == EXIT_USAGE
    err = capsys.readouterr().err
    assert "error" in err and len(err.strip().splitlines()) == 1  # one line, no usage dump


def test_bench_fails_on_a_wrong_answer_of_this_package(device, monkeypatch, capsys):
    """A real difference charged to this package (here it reports no triangle pair at all) is a mismatch:
    status 3, after the results."""
    monkeypatch.setattr(wc.CollisionResult, "triangle_pairs", property(lambda self: np.zeros((0, 4), np.int32)))
    argv = ["--device", device, "--objects", "40", "--triangles", "poly", "--peers", "builtin", *TINY]
    assert main(argv) == EXIT_INTERNAL
    captured = capsys.readouterr()
    assert "MISMATCH: warp_ccd misses" in captured.out
    assert "VERDICT 40 objects, triangles poly: MISMATCH" in captured.out
    assert "MISMATCH" in captured.err


def test_bench_reports_a_peer_that_breaks(device, monkeypatch, capsys):
    def broken(self):
        raise RuntimeError("peer broke")

    monkeypatch.setattr(wp.Mesh, "refit", broken)  # Warp's built-in pipeline refits a wp.Mesh, this package not
    argv = ["--device", device, "--objects", "40", "--triangles", "poly", "--peers", "builtin", *TINY]
    assert main(argv) == EXIT_OK  # a peer that breaks is reported, not failed
    assert "ERROR warp_builtin failed at frame 0: RuntimeError: peer broke" in capsys.readouterr().out


def test_bench_reports_a_wrong_peer_and_exits_zero(device, monkeypatch, tmp_path, capsys):
    """A peer's wrong answer is a finding: reported, its rows marked, exit status 0. Here Warp's built-in
    pipeline searches a mesh moved far away from the triangles it tests, and so finds nothing."""
    real_mesh = wp.Mesh

    def far_mesh(points, indices, **kwargs):
        far = wp.array(points.numpy() + np.float32(1e5), dtype=wp.vec3, device=points.device)
        return real_mesh(points=far, indices=indices, **kwargs)

    monkeypatch.setattr(wp, "Mesh", far_mesh)
    out = tmp_path / "wrong.json"
    argv = ["--device", device, "--objects", "60", "--triangles", "poly", "--peers", "builtin", *TINY,
            "--out", str(out)]
    assert main(argv) == EXIT_OK
    text = capsys.readouterr().out
    assert "PEER WRONG: warp_builtin misses" in text and "VERDICT 60 objects, triangles poly: OK" in text
    assert "warp_builtin*" in text
    doc = json.loads(out.read_text())
    assert doc["ok"]
    (check,) = doc["checks"]
    assert check["ok"] and not check["peer_ok"] and check["peer_errors"] and not check["mismatches"]
    assert {r["peer_wrong"] for r in doc["rows"] if r["method"] == "warp_builtin"} == {True}
    assert {r["peer_wrong"] for r in doc["rows"] if r["method"] == "warp_ccd"} == {False}


def test_bench_mixed_meshes(device, tmp_path, capsys):
    """The ``mixed`` scene: meshes of the sizes of real assets, 120 to 12,640 triangles each."""
    out = tmp_path / "mixed.json"
    argv = ["--device", device, "--objects", "8", "--triangles", "mixed", "--peers", "none", *TINY, "--out", str(out)]
    assert main(argv) == EXIT_OK, capsys.readouterr().out
    rows = json.loads(out.read_text())["rows"]
    assert {(r["n_objects"], r["triangles"]) for r in rows} == {(8, "mixed")}
    assert 120 <= rows[0]["triangles_per_object"] <= 12640
    capsys.readouterr()


def test_warp_ccd_bench_command(device, monkeypatch, capsys):
    """``warp-ccd bench`` runs the benchmark (its arguments and exit status), ``python -m warp_ccd.bench`` too."""
    assert cli_main(["bench", "--device", device, "--objects", "20", "--triangles", "poly", "--peers", "none",
                     *TINY]) == EXIT_OK
    assert "VERDICT 20 objects, triangles poly: OK" in capsys.readouterr().out
    assert cli_main(["bench", "--objects", "1"]) == EXIT_USAGE
    assert "warp-ccd bench: error:" in capsys.readouterr().err
    monkeypatch.setattr(sys, "argv", ["python -m warp_ccd.bench", "--objects", "1"])
    with pytest.raises(SystemExit) as exc:
        runpy.run_module("warp_ccd.bench", run_name="__main__")
    assert exc.value.code == EXIT_USAGE and "python -m warp_ccd.bench: error:" in capsys.readouterr().err


@wp.kernel
def _emit_kernel(capacity: int, item: wp.array[wp.int32], count: wp.array[wp.int64]):
    i = wp.tid()
    slot = reserve_slot(count, capacity)
    if slot >= 0:
        item[slot] = i


@pytest.mark.parametrize("mode", MODES)
def test_counted_frame_grows_and_captures_again(device, mode):
    """The library's counted frame, which the benchmark's device peers run on: a counter past its capacity grows
    the buffer and reruns the frame (captured again in graph mode), also when another user of the buffer grew it."""
    if mode == "graph" and not wp.get_device(device).is_cuda:
        pytest.skip("graph frames need CUDA")
    size = [50]
    buf = GrowableBuffer(wp.int32, 4, device, "items")

    def launch():
        buf.reset()
        wp.launch(_emit_kernel, dim=size[0], inputs=[buf.capacity], outputs=[buf.data, buf.count], device=device)

    frame = CountedFrame(launch, CounterRead([buf], device), mode)
    for _ in range(3):
        assert frame.run() == [50] and buf.capacity >= 50
        assert sorted(buf.numpy(50).tolist()) == list(range(50))
    buf.ensure(4 * buf.capacity)  # grown elsewhere: the graph must not write to the old storage
    assert frame.run() == [50] and sorted(buf.numpy(50).tolist()) == list(range(50))
    if mode == "graph":
        assert frame.graph is not None
