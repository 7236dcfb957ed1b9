"""The benchmark harness: the command end to end at tiny sizes, its peers, and its comparisons."""

import importlib.util
import json

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.broadphase.sap import find_pairs
from warp_ccd._src.cli.common import EXIT_INTERNAL, EXIT_OK, EXIT_USAGE
from warp_ccd._src.runtime.buffers import CounterRead, GrowableBuffer, reserve_slot
from warp_ccd._src.runtime.frame import MODES, CountedFrame
from warp_ccd.bench import box_tests, deforming, host_breakdown, methods, scaling
from warp_ccd.bench import broad_phase as broad_phase_bench
from warp_ccd.bench import pipeline as pipeline_bench
from warp_ccd.bench.command import add_out_option, add_row, add_run_options, bench_parser, start, write_result
from warp_ccd.bench.compare import (
    box_overlap_truth,
    classify_triangle_pairs,
    compare_exact,
    compare_triangle_pairs,
    triangle_distance,
)
from warp_ccd.bench.memory import _tracker_peak
from warp_ccd.bench.meshes import parse_triangles
from warp_ccd.bench.methods import device_modes
from warp_ccd.bench.peers import NewtonBroadPhaseSAP, PeerUnavailable, WarpBvhBroadPhase, WarpMeshPipeline
from warp_ccd.bench.timing import StageTimes

ROW_KEYS = {"method", "n_objects", "triangles_per_object", "stage", "ms_min", "ms_median", "object_pairs",
            "triangle_pairs"}
HAS_MATPLOTLIB = importlib.util.find_spec("matplotlib") is not None


def test_bench_end_to_end(device, tmp_path, capsys):
    out = tmp_path / "results.json"
    plot = tmp_path / "scaling.png"
    status = scaling.main(["--device", device, "--objects", "30", "150", "--triangles", "poly", "80",
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
    if wp.get_device(device).is_cuda:  # frames back to back after the checks
        assert {"loop_graph", "host_loop_graph"} <= stages
    assert {"warp_ccd", "warp_builtin", "warp_ccd_nxn"} <= {r["method"] for r in rows}
    assert len(doc["memory"]) == 4 and all(m["pipeline_peak_bytes"] > 0 for m in doc["memory"])
    assert doc["checks"] and all(c["ok"] for c in doc["checks"]) and doc["ok"]
    assert text.count("VERDICT") == 4
    if HAS_MATPLOTLIB:
        assert plot.stat().st_size > 1000
    else:
        assert not plot.exists() and "plot skipped" in text


@pytest.mark.parametrize("argv", [["--triangles", "81"], ["--peers", "builtin,bullet"], ["--objects", "1"],
                                  ["--device", "tpu:7"], ["--out", "results.txt"]])
def test_bench_bad_arguments(argv, capsys):
    assert scaling.main(argv) == EXIT_USAGE
    err = capsys.readouterr().err
    assert "error" in err and len(err.strip().splitlines()) == 1  # one line, no usage dump


def test_bench_exit_status_on_mismatch_and_peer_failure(device, monkeypatch, capsys):
    argv = ["--device", device, "--objects", "40",
            "--triangles", "poly", "--frames", "1", "--warmup", "0", "--peers", "builtin", "--no-memory"]
    real = methods.compare_triangle_pairs

    def disagreeing(*args, **kwargs):
        check = real(*args, **kwargs)
        check.mismatches.append("made up for the test")
        return check

    monkeypatch.setattr(methods, "compare_triangle_pairs", disagreeing)
    assert scaling.main(argv) == EXIT_INTERNAL
    captured = capsys.readouterr()
    assert "VERDICT 40 objects, triangles poly: MISMATCH" in captured.out and "MISMATCH" in captured.err
    monkeypatch.setattr(methods, "compare_triangle_pairs", real)

    def broken(self):
        raise RuntimeError("peer broke")

    monkeypatch.setattr(WarpMeshPipeline, "query", broken)
    assert scaling.main(argv) == EXIT_OK  # a peer that breaks is reported, not failed
    captured = capsys.readouterr()
    assert "ERROR warp_builtin failed at frame 0: RuntimeError: peer broke" in captured.out


def test_bench_reports_a_wrong_peer_and_exits_zero(device, monkeypatch, tmp_path, capsys):
    """A peer's wrong answer is a finding: reported, its rows marked, exit status 0."""
    out = tmp_path / "wrong.json"
    argv = ["--device", device, "--objects", "60", "--triangles", "poly", "--frames", "1", "--warmup", "0",
            "--peers", "builtin", "--no-memory", "--out", str(out)]
    monkeypatch.setattr(WarpMeshPipeline, "triangle_pairs", lambda self, count=None: np.zeros((0, 4), np.int32))
    assert scaling.main(argv) == EXIT_OK
    text = capsys.readouterr().out
    assert "PEER WRONG: warp_builtin misses" in text and "VERDICT 60 objects, triangles poly: OK" in text
    assert "warp_builtin*" in text
    doc = json.loads(out.read_text())
    assert doc["ok"]
    (check,) = doc["checks"]
    assert check["ok"] and not check["peer_ok"] and check["peer_errors"] and not check["mismatches"]
    assert {r["peer_wrong"] for r in doc["rows"] if r["method"] == "warp_builtin"} == {True}
    assert {r["peer_wrong"] for r in doc["rows"] if r["method"] == "warp_ccd"} == {False}


def test_parse_triangles():
    assert parse_triangles("poly") == ("poly", None)
    assert parse_triangles("80") == ("80", ("icosphere1",))
    assert parse_triangles("1280") == ("1280", ("icosphere3",))
    assert parse_triangles("icosphere2") == ("320", ("icosphere2",))
    with pytest.raises(ValueError):
        parse_triangles("100")


def test_mixed_meshes_are_valid_and_of_real_sizes(device):
    """The ``mixed`` scene's meshes: radius 1, indices in range, 120 to 12,640 triangles, each the
    same arrays at every call, and a scene of them runs."""
    label, meshes = parse_triangles("mixed")
    assert label == "mixed" and meshes is parse_triangles("mixed")[1]
    counts = sorted(len(t) for _, t in meshes)
    assert counts[0] == 120 and counts[-1] == 12640 and len(counts) == 7
    for v, t in meshes:
        wc.scene.validate_mesh(v, t)
        assert abs(np.linalg.norm(v, axis=1).max() - 1.0) < 1e-6
    scene = wc.Scene.random(8, seed=1, shapes=meshes, device=device)
    assert scene.num_shapes == 7 and wc.CollisionPipeline(scene).detect().num_objects == 8


@pytest.mark.parametrize("mode", MODES)
def test_builtin_peer_agrees_with_pipeline(device, mode):
    if mode not in device_modes(device):
        pytest.skip(f"{mode} frames of the built-in peer need CUDA")
    scene = wc.Scene.random(300, seed=3, shapes=("icosphere1", "cube", "dodecahedron"), device=device)
    peer = WarpMeshPipeline(scene, capacity=1)  # grows on the first frame
    frame = CountedFrame(peer.launch, CounterRead(peer.counters, device), mode)
    for _ in range(3):  # eager, captured, replayed (in graph mode): each frame sees the new vertices
        scene.advance(0.2)
        ours = wc.CollisionPipeline(scene).detect()
        (count,) = frame.run()
        got = peer.triangle_pairs(count)
        assert got.shape[1] == 4 and len(got) > 10 and peer.hits.capacity >= len(got)
        check = compare_triangle_pairs(scene, "warp_ccd", ours.triangle_pairs, "warp_builtin", got)
        assert check.ok and check.peer_ok, (check.mismatches, check.peer_errors)
        ref_obj, peer_obj, common = check.object_pairs
        assert common > 0 and ref_obj - common + peer_obj - common == check.explained


@wp.kernel
def _emit_kernel(capacity: int, item: wp.array[wp.int32], count: wp.array[wp.int64]):
    i = wp.tid()
    slot = reserve_slot(count, capacity)
    if slot >= 0:
        item[slot] = i


@pytest.mark.parametrize("mode", MODES)
def test_counted_frame_grows_and_captures_again(device, mode):
    """A counter past its capacity grows the buffer and reruns the frame (captured again in graph mode),
    also when another user of the buffer grew it."""
    if mode not in device_modes(device):
        pytest.skip(f"{mode} frames need CUDA")
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


def test_stage_times_best_of_modes():
    st = StageTimes()
    for eager, graph in ((1.0, 0.4), (1.2, 0.5), (0.9, 0.6)):
        st.add({"detect_eager": eager, "detect_graph": graph, "motion": 0.1})
    summary = st.summary()
    assert summary["detect"] == summary["detect_graph"] == (0.4, 0.5) and st.best_mode == {"detect": "graph"}
    assert st.has("detect") and st.has("motion") and not st.has("broad") and st.frames("detect") == 3


@pytest.mark.parametrize("name", ["warp_bvh", "warp_bvh_refit", "newton_sap"])
def test_broad_phase_peers_agree(device, name):
    if name == "newton_sap":
        try:
            broad = NewtonBroadPhaseSAP(device=device)
        except PeerUnavailable as exc:
            pytest.skip(f"newton_sap: {exc}")
    else:
        broad = WarpBvhBroadPhase(device=device, refit=name == "warp_bvh_refit")
    lo, hi = broad_phase_bench.random_boxes(3000, overlaps=2.0, seed=1)
    lower = wp.array(lo, dtype=wp.vec3, device=device)
    upper = wp.array(hi, dtype=wp.vec3, device=device)
    ref_pairs = GrowableBuffer(wp.vec2i, 16, device, "reference")
    n_ref = find_pairs(wc.stages.BroadPhaseSAP(device=device), lower, upper, ref_pairs)
    ref = ref_pairs.numpy(n_ref)
    assert 2 * n_ref / 3000 > 1.0  # about the requested 2 overlaps per box
    pairs = GrowableBuffer(wp.vec2i, 16, device, name)
    for _ in range(2):  # build, then rebuild or refit
        count = find_pairs(broad, lower, upper, pairs)
    check = compare_exact("sap", ref, name, pairs.numpy(count), "box pairs")
    assert check.ok, check.mismatches


def test_bench_command_setup(device, tmp_path, capsys):
    parser = bench_parser("a benchmark")
    parser.add_argument("--objects", type=int, default=10)
    add_run_options(parser, frames=5, warmup=2, out=False)
    parser.add_argument("--replays", type=int, default=3)
    add_out_option(parser, "JSON file")
    out = tmp_path / "r.json"
    args, dev, doc = start(parser, ["--device", device, "--frames", "7", "--out", str(out)])
    assert str(dev) == device and (args.objects, args.frames, args.warmup, args.replays) == (10, 7, 2, 3)
    assert not hasattr(args, "seed")  # only the options asked for
    assert list(doc) == ["device", "device_name", "date", "versions", "git_commit", "git_dirty", "config", "rows"]
    assert list(doc["config"]) == ["device", "objects", "frames", "warmup", "replays", "out"]  # the options' order
    assert doc["device"] == device and doc["rows"] == []
    add_row(doc, {"n": 1})
    assert capsys.readouterr().out == "{'n': 1}\n"
    write_result(None, doc)  # no --out: nothing written
    assert not out.exists()
    write_result(args.out, doc)
    assert json.loads(out.read_text())["rows"] == [{"n": 1}]
    defaults = bench_parser(None, device=device)  # a benchmark's own default device
    add_run_options(defaults, seed=4)
    args, dev, _ = start(defaults, [])
    assert str(dev) == device and args.seed == 4 and args.out is None and not hasattr(args, "frames")
    # An unknown device or a JSON file that cannot be written: a usage error before anything runs.
    for argv in (["--device", "tpu:7"], ["--out", str(tmp_path / "r.txt")], ["--out", str(tmp_path / "no" / "r.json")]):
        with pytest.raises(SystemExit) as exc:
            start(parser, argv)
        assert exc.value.code == 2
    assert capsys.readouterr().err.count("error:") == 3


def test_bench_scripts_run(device, tmp_path, capsys):
    out = tmp_path / "broad.json"
    assert broad_phase_bench.main(["--device", device, "--n", "300", "3000", "--frames", "1", "--warmup", "1",
                       "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert {"device", "date", "rows", "checks"} <= set(doc) and doc["ok"]
    assert {r["method"] for r in doc["rows"]} >= {"sap", "nxn", "warp_bvh", "warp_bvh_refit"}
    out = tmp_path / "pipeline.json"
    assert pipeline_bench.main(["--device", device, "--objects", "20", "--triangles", "80", "--frames", "1",
                          "--warmup", "1", "--no-memory", "--out", str(out), "--plot", str(tmp_path / "p.png")]) == 0
    doc = json.loads(out.read_text())
    assert {r["method"] for r in doc["rows"]} == {"warp_ccd", "warp_builtin"}
    out = tmp_path / "host.json"
    assert host_breakdown.main(["--device", device, "--objects", "40", "--triangles", "poly", "--frames", "2",
                           "--out", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert [r["variant"] for r in rows] == ["plain", "again"]
    assert all(0 <= r["min"]["host"] <= r["median"]["host"] and r["median"]["wait"] >= 0 for r in rows)
    out = tmp_path / "boxes.json"
    assert box_tests.main(["--device", device, "--cases", "poly:60", "--axes", "3", "6", "--bounds", "auto", "tree",
                       "--frames", "1", "--warmup", "1", "--out", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert {(r["separating_axes"], r["object_bounds"]) for r in rows} == {(3, "auto"), (3, "tree"), (6, "auto"),
                                                                          (6, "tree")}
    out = tmp_path / "deforming.json"
    assert deforming.main(["--device", device, "--objects", "40", "--level", "1", "--leaf-sizes", "1", "4",
                           "--frames", "1", "--warmup", "1", "--out", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert {r["method"] for r in rows} == {"warp_ccd", "warp_builtin"}
    assert len({r["triangle_pairs"] for r in rows if r["method"] == "warp_ccd"}) == 1  # every leaf size alike
    assert max(r["triangle_pairs"] for r in rows) > 0
    assert all(r["check"]["ok"] and r["check"]["peer_ok"] for r in rows if r["method"] == "warp_builtin")
    capsys.readouterr()


# ---------------------------------------------------------------------------------------------
# The comparisons' arbiter and verdicts


def tri(*points):
    return np.array(points, np.float64)


def test_classify_triangle_pairs(device):
    base = tri([0, 0, 0], [1, 0, 0], [0, 1, 0])
    cases = {
        "intersecting": tri([0.2, 0.2, -0.5], [0.3, 0.2, 0.5], [0.2, 0.3, 0.5]),
        "grazing": tri([1, 0, 0], [2, 0, 1], [2, 1, -1]),  # shares one vertex only
        "near": base + [0, 0, 1e-4],  # parallel, 1e-4 of an edge above
        "apart": base + [0, 0, 0.5],
    }
    got = classify_triangle_pairs(np.stack([base] * 4), np.stack(list(cases.values())), device=device)
    assert got.tolist() == list(cases)


def test_triangle_distance():
    a = tri([0, 0, 0], [1, 0, 0], [0, 1, 0])
    b = np.stack([a + [0, 0, 0.25], tri([2, 0, 0], [3, 0, 0], [2, 1, 0]), tri([0.5, 0.5, 1], [0.5, 0.5, 2], [1, 1, 2])])
    d = triangle_distance(np.stack([a] * 3), b)
    assert np.allclose(d, [0.25, 1.0, 1.0])


def test_compare_triangle_pairs_verdicts(device):
    cube = wc.scene.shape("cube")
    meshes = [(cube[0] + np.float32([x, 0, 0]), cube[1]) for x in (0.0, 0.5, 5.0)]  # 0-1 overlap, 2 far away
    scene = wc.Scene.from_meshes(meshes, device=device)
    ours = wc.CollisionPipeline(scene).detect().triangle_pairs
    assert set(map(tuple, ours[:, [0, 2]].tolist())) == {(0, 1)}
    same = compare_triangle_pairs(scene, "a", ours, "b", ours)
    assert same.ok and same.num_common == len(ours)
    # The peer (b) wrong: a finding charged to it, the reference stands.
    missed = compare_triangle_pairs(scene, "a", ours, "b", np.zeros((0, 4), np.int32))
    assert missed.ok and not missed.peer_ok and "b misses 1 object pairs" in missed.peer_errors[0]
    spurious = compare_triangle_pairs(scene, "a", ours, "b", np.concatenate([ours, [[1, 0, 2, 0]]]))
    assert spurious.ok and "clearly apart" in spurious.peer_errors[0] and spurious.classes["b only: apart"] == 1
    # The reference (a) wrong: a mismatch.
    missed = compare_triangle_pairs(scene, "a", np.zeros((0, 4), np.int32), "b", ours)
    assert not missed.ok and missed.peer_ok and "a misses 1 object pairs" in missed.mismatches[0]
    spurious = compare_triangle_pairs(scene, "a", np.concatenate([ours, [[1, 0, 2, 0]]]), "b", ours)
    assert not spurious.ok and "a reports 1 object pairs whose triangles are clearly apart" in spurious.mismatches[0]


def test_compare_exact():
    ref = np.array([[0, 1], [2, 5], [3, 4]])
    assert compare_exact("a", ref, "b", ref[::-1][:, ::-1], "box pairs").ok  # any order, either way round
    check = compare_exact("a", ref, "b", np.array([[0, 1], [2, 6], [3, 4], [3, 4]]), "box pairs")
    assert len(check.mismatches) == 3 and check.peer_ok  # one missing, one extra, one duplicate: no truth, all a's


def test_compare_exact_charges_the_method_the_truth_finds_wrong():
    lower = np.array([[0, 0, 0], [0.5, 0, 0], [5, 5, 5], [0.9, 0.9, 0.9]], np.float32)
    upper = lower + 1.0
    truth = box_overlap_truth(lower, upper)
    assert truth(np.array([[0, 1], [0, 2], [0, 3], [1, 3], [2, 3], [1, 1], [0, 9]])).tolist() == [
        True, False, True, True, False, False, False]
    ref = np.array([[0, 1], [0, 3], [1, 3]])  # all true
    peer_wrong = compare_exact("a", ref, "b", np.array([[0, 1], [0, 2], [1, 3], [1, 3]]), "box pairs", truth=truth)
    assert peer_wrong.ok and len(peer_wrong.peer_errors) == 3  # misses (0, 3), adds (0, 2), a duplicate
    ours_wrong = compare_exact("a", np.array([[0, 1], [0, 2]]), "b", ref, "box pairs", truth=truth)
    assert not ours_wrong.ok and ours_wrong.peer_ok and len(ours_wrong.mismatches) == 2


def test_tracker_peak_parse():
    text = ("Allocation Tracking Report\n  Total allocations:\n    cpu              46 (364.29 KB)\n"
            "  Peak usage:\n    cpu              348.27 KB\n    cuda:0           1.50 GB\n  Live allocations:\n")
    assert _tracker_peak(text, "cpu") == int(348.27 * 1024)
    assert _tracker_peak(text, "cuda:0") == int(1.5 * 1024**3)
    assert _tracker_peak(text, "cuda:1") is None
    assert _tracker_peak("nothing", "cpu") is None
