"""The continuous-collision benchmarks at tiny sizes: queries per second (and agreement with Tight Inclusion)
and the continuous frame against the discrete one."""

import json
import types

import numpy as np
import pytest
import warp as wp

import warp_ccd as wc
from warp_ccd._src.cli.common import EXIT_INTERNAL, EXIT_OK
from warp_ccd.bench import ccd_queries, continuous

TINY = ["--queries", "400", "--objects", "60", "--ipctk-queries", "100", "--repeats", "1", "--cpu-repeats", "1"]


def _run_queries(device, tmp_path, extra):
    out = tmp_path / "ccd.json"
    status = ccd_queries.main(["--device", device, *TINY, *extra, "--out", str(out)])
    return status, json.loads(out.read_text())


def test_ccd_queries_bench(device, tmp_path, capsys):
    status, doc = _run_queries(device, tmp_path, ["--no-ipctk"])
    assert status == EXIT_OK, capsys.readouterr().out
    assert {"device", "date", "git_commit", "rows", "checks", "sets", "ok"} <= set(doc) and doc["ok"]
    rows = doc["rows"]
    device_rows = [r for r in rows if r["method"] == "ours_device"]
    # Per set: each kind and both together, each precision, min_distance 0 and > 0.
    assert len(device_rows) == 2 * 3 * 2 * 2
    assert {r["queries"] for r in device_rows if r["kind"] != "all"} == {200}
    assert all(0 <= r["ms_min"] <= r["ms_median"] and r["us_per_query"] > 0 for r in device_rows)
    assert any(r["hits"] for r in device_rows if r["set"] == "random")
    assert any(r["min_distance"] > 0 for r in device_rows)
    cpu_rows = [r for r in rows if r["method"] == "ours_cpu"]
    assert len(cpu_rows) == (4 if wp.is_cpu_available() else 0)
    assert all(r["queries"] == 50 for r in cpu_rows)
    checks = {(c["set"], c["kind"], c["check"]) for c in doc["checks"]}
    assert ("mixed", "edge_edge", "float32_vs_float64") in checks
    assert doc["sets"]["mixed"]["candidates"] > 0 and not any(r["method"] == "ipctk" for r in rows)
    capsys.readouterr()


def test_ccd_queries_bench_against_ipctk(device, tmp_path, capsys):
    pytest.importorskip("ipctk")
    status, doc = _run_queries(device, tmp_path, ["--sets", "random"])
    assert status == EXIT_OK, capsys.readouterr().out
    agree = [c for c in doc["checks"] if c["check"] == "ipctk"]
    assert len(agree) == 2 and all(c["ok"] and c["missed"] == 0 and c["queries"] == 50 for c in agree)
    assert {r["kind"] for r in doc["rows"] if r["method"] == "ipctk"} == {"vertex_face", "edge_edge"}
    assert {r["ours"] for r in doc["ratios"]} == ({"ours_device", "ours_cpu"} if wp.is_cpu_available()
                                                   else {"ours_device"})
    capsys.readouterr()


def test_ccd_queries_bench_fails_on_a_missed_hit(device, tmp_path, monkeypatch, capsys):
    def always(*args, **kwargs):  # a peer that finds a collision at t = 0 in every query
        return True, 0.0, 0.0

    fake = types.SimpleNamespace(tight_inclusion=types.SimpleNamespace(point_triangle_ccd=always,
                                                                       edge_edge_ccd=always))
    monkeypatch.setitem(__import__("sys").modules, "ipctk", fake)
    status, doc = _run_queries(device, tmp_path, ["--sets", "random"])
    assert status == EXIT_INTERNAL and not doc["ok"]
    assert all(c["missed"] > 0 for c in doc["checks"] if c["check"] == "ipctk")
    assert "MISMATCH" in capsys.readouterr().out


def test_continuous_bench(device, tmp_path, capsys):
    out = tmp_path / "continuous.json"
    assert continuous.main(["--device", device, "--objects", "60", "200", "--frames", "2", "--warmup", "2",
                            "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert {"device", "date", "git_commit", "rows", "notes"} <= set(doc) and not doc["notes"]
    rows = doc["rows"]
    assert [(r["n_objects"], r["method"]) for r in rows] == [(60, "discrete"), (60, "continuous"),
                                                            (200, "discrete"), (200, "continuous")]
    assert all(0 <= r["ms_min"] <= r["ms_median"] and r["frames"] == 2 for r in rows)
    for disc, cont in zip(rows[::2], rows[1::2]):
        assert cont["ratio_median"] == pytest.approx(cont["ms_median"] / disc["ms_median"])
        assert cont["discrete_only"] == 0  # what collides at the step's end collides over the step
        assert cont["object_pairs_per_frame"] >= disc["object_pairs_per_frame"]
        assert 0 <= cont["between_frames"] <= cont["only_continuous"]
    assert rows[-1]["object_pairs_last"] > 0
    capsys.readouterr()


def test_continuous_bench_reports_a_continuous_pipeline_that_fails(device, tmp_path, monkeypatch, capsys):
    real = wc.CollisionPipeline

    def pipeline(scene, **options):
        if options.get("continuous"):
            raise RuntimeError("out of memory (simulated)")
        return real(scene, **options)

    monkeypatch.setattr(wc, "CollisionPipeline", pipeline)
    out = tmp_path / "continuous.json"
    assert continuous.main(["--device", device, "--objects", "60", "--frames", "1", "--warmup", "1",
                            "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert [r["method"] for r in doc["rows"]] == ["discrete"]
    assert len(doc["notes"]) == 1 and "out of memory" in doc["notes"][0]
    assert np.isfinite(doc["rows"][0]["ms_median"])
    capsys.readouterr()
