"""``check_many``: files and long animations checked in parts, in this process or on a Ray cluster, and merged
into the report of the serial check (:func:`~warp_ccd._src.check.check.check_usd` over the whole file).

The oracle is the serial check itself: a merged report's JSON equals the serial one's text for text (``seconds``
apart, floats bit for bit), and so do its pair summary, findings, worst frame, precision and summary; the
overlay written from a merged or a pickled report (no stage carried) equals the overlay of the serial report.
Also: failing files among good ones, glob patterns, a file whose late time codes alone need float64, the plan
(parts, overlaps, order) and the merge, and on a local Ray cluster of two actors the same results, a worker
killed mid-task included. Small stages of :mod:`usd_stages`; the Ray group needs ``ray`` and is skipped without.
"""

import json
import os
import pickle
import signal
import threading
import time
import warnings

import numpy as np
import pytest

from warp_ccd._src.check.batch import MIN_FRAMES_PER_TASK, check_many, expand_paths, merge_reports, plan_tasks
from warp_ccd._src.check.check import check_usd
from warp_ccd._src.check.cluster import FAULT_ENV
from warp_ccd._src.check.overlay import write_overlay
from warp_ccd._src.check.tasks import EXIT_BAD_INPUT, EXIT_CLEAN, EXIT_FINDINGS, EXIT_INTERNAL, run_task
from warp_ccd._src.geometry.precision import PrecisionWarning
from warp_ccd.usd import CheckOptions

from conftest import DEFAULT_DEVICE

pxr = pytest.importorskip("pxr")
from usd_stages import (  # noqa: E402
    blinking_stage,
    boxes_stage,
    define_mesh,
    duplicate_stage,
    env_boxes,
    far_flight_stage,
    grid,
    mixed_stage,
    prism,
)

NUM_FRAMES = 24
ABC = {"/World/A": (0.0, 0.0, 0.0), "/World/B": (0.3, 0.0, 0.0), "/World/C": (0.6, 0.0, 0.0)}
APART = {"/World/A": (0.0, 0.0, 0.0), "/World/B": (5.0, 0.0, 0.0)}
EVERYTHING = {"continuous": True, "clearance": 0.2, "self_intersections": True, "duplicates": True, "segments": True,
              "count_touching": True}
"""Every kind of check at once."""


# ---------------------------------------------------------------------------------------------
# helpers


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict:
    """The stages, saved in one folder (read only)."""
    folder = tmp_path_factory.mktemp("many")
    out = {name: str(folder / f"{name}.usda") for name in
           ("mixed", "dup", "envs", "physics", "abc", "clean", "far")}
    mixed_stage(out["mixed"], num_frames=NUM_FRAMES)
    duplicate_stage("exact", out["dup"])
    boxes_stage(out["envs"], env_boxes())
    boxes_stage(out["physics"], filtered_pairs={"/World/A": ["/World/B"]})
    boxes_stage(out["abc"], ABC)
    boxes_stage(out["clean"], APART)
    far_flight_stage(out["far"])
    return out


_SERIAL: dict = {}


def serial(path: str, device: str, **options):
    """:func:`check_usd` over the whole file, in this process (once per file, device and options)."""
    key = (path, device, repr(sorted(options.items())))
    if key not in _SERIAL:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", PrecisionWarning)
            _SERIAL[key] = check_usd(path, device=device, **options)
    return _SERIAL[key]


def json_text(report) -> str:
    """The report's JSON text without its timings."""
    data = report.to_json()
    del data["seconds"]
    return json.dumps(data)


def assert_same(got, want):
    """``got`` (merged, or from elsewhere) is the serial report ``want``, timings apart."""
    assert got.source is None
    assert json_text(got) == json_text(want)
    assert got.pair_summary() == want.pair_summary()
    assert got.findings == want.findings
    assert got.worst_frame == want.worst_frame
    assert (got.precision, got.precision_note, got.max_coordinate) == (want.precision, want.precision_note,
                                                                       want.max_coordinate)
    assert got.extent == want.extent
    assert set(got.seconds) == set(want.seconds)
    assert got.summary().splitlines()[:-1] == want.summary().splitlines()[:-1]  # the last line: the timings
    for a, b in zip(got.frames, want.frames, strict=True):
        np.testing.assert_array_equal(a.triangle_pairs, b.triangle_pairs)
        np.testing.assert_array_equal(a.depth, b.depth)


def broken_mesh_stage(path):
    """A floor and ``/World/Bad``, a box-like prism with a face index out of range; time codes 0..2."""
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path))
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(2)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    define_mesh(stage, "/World/Floor", *grid(2, 4.0))
    points, counts, indices = prism(4, radius=0.7, height=1.0)
    define_mesh(stage, "/World/Bad", points, counts, indices[:-1] + [len(points)])
    stage.GetRootLayer().Save()


# ---------------------------------------------------------------------------------------------
# 1. in this process: the merged report is the serial one


CASES = {
    "plain": ("mixed", {}),
    "continuous": ("mixed", {"continuous": True}),
    "clearance": ("mixed", {"clearance": 0.3}),
    "self_segments": ("mixed", {"self_intersections": True, "segments": True}),
    "touching": ("mixed", {"count_touching": True, "min_depth": 0.01}),
    "everything": ("mixed", EVERYTHING),
    "duplicates": ("dup", {"duplicates": True, "continuous": True, "segments": True}),
    "worlds": ("envs", {"worlds": "/World/envs/*", "continuous": True}),
    "physics": ("physics", {"clearance": 0.1}),
    "sets": ("abc", {"set_a": "/World/A", "set_b": "/World/B,/World/C", "ignore_pairs": [("/World/A", "/World/C")]}),
}


@pytest.mark.parametrize("case, frames_per_task", [
    *[(c, n) for c in ("plain", "continuous", "everything") for n in (1, 5, 7, None)],
    ("clearance", 5), ("self_segments", 7), ("touching", 5),
    *[(c, n) for c in ("duplicates", "worlds", "physics", "sets") for n in (1, None)],
])
def test_parts_merge_to_the_serial_report(files, device, case, frames_per_task):
    name, options = CASES[case]
    want = serial(files[name], device, **options)
    assert want.frames
    batch = check_many(files[name], frames_per_task=frames_per_task, device=device, **options)
    (result,) = batch.files
    count = len(want.frames)
    assert result.tasks == (1 if frames_per_task is None else -(-count // frames_per_task))
    assert (result.path, result.error) == (files[name], None)
    assert result.exit_status == (EXIT_FINDINGS if want.findings else EXIT_CLEAN)
    assert (batch.engine, batch.workers, batch.exit_status) == ("serial", 1, result.exit_status)
    assert_same(result.report, want)
    if options.get("continuous"):
        assert len(result.report.intervals) == count - 1


@pytest.mark.parametrize("frames, options, frames_per_task", [
    (slice(3, 17), {"continuous": True}, 5),
    (slice(2, 21, 3), {"clearance": 0.2}, 2),
    ([0.0, 2.5, 7.0, 7.25, 11.0, 16.0, 23.0], {"continuous": True, "segments": True}, 3),
    (12.0, {"continuous": True}, 1),
])
def test_sub_ranges_merge_to_the_serial_report(files, device, frames, options, frames_per_task):
    want = serial(files["mixed"], device, frames=frames, **options)
    batch = check_many(files["mixed"], frames=frames, frames_per_task=frames_per_task, device=device, **options)
    assert batch.files[0].tasks == -(-len(want.frames) // frames_per_task)
    assert_same(batch.files[0].report, want)


def test_a_lone_file_is_cut_for_the_workers(files, device):
    """In this process, ``workers`` cuts a lone file into parts of at least MIN_FRAMES_PER_TASK time codes."""
    frames = slice(0, NUM_FRAMES - 1, 0.5)  # 47 time codes: 2 parts of 32 at most, for 3 workers
    options = {"continuous": True, "clearance": 0.2}
    want = serial(files["mixed"], device, frames=frames, **options)
    assert len(want.frames) == 47
    batch = check_many(files["mixed"], frames=frames, workers=3, device=device, **options)
    assert (batch.files[0].tasks, batch.workers) == (2, 3)
    assert_same(batch.files[0].report, want)
    whole = check_many([files["mixed"], files["dup"]], workers=2, device=device)
    assert [(f.tasks, f.error) for f in whole.files] == [(1, None), (1, None)]  # as many files as workers: whole


def test_pickled_report_is_plain_data(files, device):
    want = serial(files["mixed"], device, **EVERYTHING)
    assert want.source is not None
    copy = pickle.loads(pickle.dumps(want))
    assert copy.source is None and want.source is not None  # pickling left the original alone
    assert copy.to_json() == want.to_json()
    assert_same(copy, want)


# ---------------------------------------------------------------------------------------------
# 2. the overlay from a report alone


@pytest.mark.parametrize("build, options", [
    (lambda p: mixed_stage(p, num_frames=NUM_FRAMES), EVERYTHING),
    (lambda p: duplicate_stage("offset", p), {"duplicates": True, "segments": True}),
], ids=["mixed", "dup"])
def test_overlay_from_a_merged_or_pickled_report(tmp_path, device, build, options):
    stage_path = str(tmp_path / "anim.usda")
    build(stage_path)
    want = check_usd(stage_path, device=device, **options)
    merged = check_many(stage_path, frames_per_task=1, device=device, **options).files[0].report
    pickled = pickle.loads(pickle.dumps(want))
    assert merged.source is None and pickled.source is None and want.source is not None
    texts = {}
    for name, report in (("serial", want), ("merged", merged), ("pickled", pickled)):
        out = write_overlay(report, tmp_path / f"{name}.usda")  # one folder: the same relative sublayer
        assert out == str(tmp_path / f"{name}.usda")
        texts[name] = (tmp_path / f"{name}.usda").read_text()
    assert "displayColor" in texts["serial"] and "@anim.usda@" in texts["serial"]
    assert texts["merged"] == texts["serial"]
    assert texts["pickled"] == texts["serial"]


# ---------------------------------------------------------------------------------------------
# 3. failing files among good ones; globs


@pytest.mark.parametrize("frames_per_task", [None, 1])
def test_failing_files_among_good_ones(tmp_path, files, device, frames_per_task):
    missing, garbage, broken = tmp_path / "missing.usda", tmp_path / "garbage.usda", tmp_path / "broken.usda"
    garbage.write_text("this is not a USD file\n" * 10)
    broken_mesh_stage(broken)
    paths = [files["abc"], missing, garbage, files["clean"], broken, files["dup"]]
    batch = check_many(paths, frames_per_task=frames_per_task, device=device)
    assert [f.path for f in batch.files] == [str(p) for p in paths]
    assert [f.exit_status for f in batch.files] == [EXIT_FINDINGS, EXIT_BAD_INPUT, EXIT_BAD_INPUT, EXIT_CLEAN,
                                                    EXIT_BAD_INPUT, EXIT_FINDINGS]
    assert batch.exit_status == EXIT_BAD_INPUT
    assert [r is None for r in batch.reports] == [False, True, True, False, True, False]
    by_name = {os.path.basename(f.path): f for f in batch.files}
    assert str(missing) in by_name["missing.usda"].error and "no such file" in by_name["missing.usda"].error
    assert str(garbage) in by_name["garbage.usda"].error and "not a USD file" in by_name["garbage.usda"].error
    assert "/World/Bad" in by_name["broken.usda"].error and "faceVertexIndices" in by_name["broken.usda"].error
    assert all("\n" not in f.error for f in batch.files if f.error)
    if frames_per_task is not None:  # files that could not be opened to count their time codes: no task; a file
        # with a part at fault checked again whole (one task: the error one run meets)
        assert [f.tasks for f in batch.files] == [2, 0, 0, 2, 1, 3]
    for f in batch.files:
        if f.report is not None:
            assert f.error is None
            assert_same(f.report, serial(f.path, device))
    data = json.loads(json.dumps(batch.to_json()))
    assert data["exit_status"] == EXIT_BAD_INPUT and data["engine"] == "serial"
    assert [sorted(f) for f in data["files"]] == [["exit_status", "path", "report"], ["error", "exit_status", "path"],
                                                  ["error", "exit_status", "path"], ["exit_status", "path", "report"],
                                                  ["error", "exit_status", "path"], ["exit_status", "path", "report"]]
    lines = batch.summary().splitlines()
    assert f"{broken}: error: {by_name['broken.usda'].error}" in lines
    assert lines[-1].startswith("6 files: 2 with findings, 3 failed")


def test_exit_status_is_the_worst(files, device):
    assert check_many(files["clean"], device=device).exit_status == EXIT_CLEAN
    assert check_many([files["clean"], files["abc"]], device=device).exit_status == EXIT_FINDINGS


def test_an_internal_error_is_reported_and_the_others_go_on(files, device, monkeypatch):
    import warp_ccd._src.check.check as check_module

    def failing(path, *args, **kwargs):
        if str(path).endswith("abc.usda"):
            raise RuntimeError("out of cheese")
        return check_usd(path, *args, **kwargs)

    monkeypatch.setattr(check_module, "check_usd", failing)
    batch = check_many([files["abc"], files["clean"]], device=device)
    assert [f.exit_status for f in batch.files] == [EXIT_INTERNAL, EXIT_CLEAN]
    assert batch.files[0].error == "internal error: RuntimeError: out of cheese"
    assert batch.exit_status == EXIT_INTERNAL


def test_expand_paths(tmp_path, files):
    for rel in ("a.usda", "b.usda", "sub/c.usda", "sub/deeper/d.usd", "notes.txt"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("#usda 1.0\n")
    (tmp_path / "dir.usda").mkdir()  # a folder matched by a pattern is no file
    t = str(tmp_path)
    assert expand_paths(f"{t}/*.usda") == [f"{t}/a.usda", f"{t}/b.usda"]
    assert expand_paths([f"{t}/**/*.usd*"]) == sorted([f"{t}/a.usda", f"{t}/b.usda", f"{t}/sub/c.usda",
                                                       f"{t}/sub/deeper/d.usd"])
    assert expand_paths(tmp_path / "sub" / "**" / "?.usd") == [f"{t}/sub/deeper/d.usd"]
    assert expand_paths([f"{t}/b.usda", f"{t}/[ab].usda", f"{t}/sub/../a.usda"]) == [f"{t}/b.usda", f"{t}/a.usda"]
    assert expand_paths(f"{t}/missing.usda") == [f"{t}/missing.usda"]  # no pattern: kept, the check names it
    with pytest.raises(ValueError, match="nothing-\\*.usda: no file matches this pattern"):
        expand_paths([f"{t}/a.usda", f"{t}/nothing-*.usda"])
    with pytest.raises(ValueError, match="no USD files given"):
        expand_paths([])
    with pytest.raises(ValueError, match="no file matches"):
        check_many(f"{t}/**/*.usdz")
    folder = os.path.dirname(files["abc"])
    batch = check_many(os.path.join(folder, "[ac]*.usda"), device=DEFAULT_DEVICE)
    assert [os.path.basename(f.path) for f in batch.files] == ["abc.usda", "clean.usda"]
    assert [f.exit_status for f in batch.files] == [EXIT_FINDINGS, EXIT_CLEAN]


@pytest.mark.parametrize("bad, message", [
    ({"frames_per_task": 0}, "frames_per_task must be an integer >= 1 or None, got 0"),
    ({"frames_per_task": 2.5}, "frames_per_task must be an integer >= 1 or None, got 2.5"),
    ({"workers": 0}, "workers must be an integer >= 1 or None, got 0"),
    ({"min_depth": -1.0}, "min_depth must be a finite number >= 0, got -1.0"),
    ({"precision": "float16"}, "precision must be one of ['float32', 'float64'], got 'float16'"),
], ids=lambda bad: "{}={!r}".format(*next(iter(bad.items()))) if isinstance(bad, dict) else "")
def test_bad_options_raise(files, bad, message):
    """Before any file is read: the missing one would be an error of its own."""
    with pytest.raises(ValueError) as info:
        check_many([files["clean"], "/nonexistent/*.usda"], **bad)
    assert str(info.value) == message


@pytest.mark.parametrize("bad", [{"clearence": 0.1}, {"stage_or_path": "x"}, {"options": {"clearance": 0.1}}])
def test_unknown_options_are_type_errors(files, bad):
    with pytest.raises(TypeError, match="check_many"):
        check_many([files["clean"]], **bad)


# ---------------------------------------------------------------------------------------------
# 4. one precision for a whole file


def test_late_frames_needing_float64_make_every_part_float64(files, device):
    path = files["far"]
    want = serial(path, device, continuous=True, segments=True)
    assert want.precision == "float64" and "checking in float64" in want.precision_note
    assert want.penetrating and len(want.frames[-1].triangle_pairs) > 0  # far away, B and C still penetrate
    tasks, errors = plan_tasks([path], frames_per_task=4, continuous=True)
    assert not errors and [t.times[0] for t in sorted(tasks, key=lambda t: t.part)] == [0.0, 3.0, 7.0]
    options = CheckOptions(continuous=True, segments=True)
    alone = {t.part: run_task(t, options, device=device).report for t in tasks}
    assert [alone[k].precision for k in range(3)] == ["float32", "float32", "float64"]  # early parts alone
    batch = check_many(path, frames_per_task=4, device=device, continuous=True, segments=True)
    merged = batch.files[0].report
    assert merged.precision == "float64"
    assert_same(merged, want)
    # Asked for float64: every part float64 at once, without a note; the same frames.
    asked = check_many(path, frames_per_task=4, device=device, precision="float64", continuous=True, segments=True)
    assert asked.files[0].report.precision_note is None
    assert_same(asked.files[0].report, serial(path, device, precision="float64", continuous=True, segments=True))


# ---------------------------------------------------------------------------------------------
# 5. the plan and the merge


def test_plan_cuts_every_time_code_once(files):
    path = files["mixed"]
    for continuous in (False, True):
        for size in (1, 5, 7, 24, 100):
            tasks, errors = plan_tasks([path], frames_per_task=size, continuous=continuous)
            assert not errors
            assert [t.frames for t in tasks] == sorted((t.frames for t in tasks), reverse=True)  # largest first
            parts = sorted(tasks, key=lambda t: t.part)
            assert [t.part for t in parts] == list(range(len(parts))) == list(range(-(-NUM_FRAMES // size)))
            assert all(t.file == 0 and t.path == path for t in parts)
            assert [t.skip for t in parts] == [0] + [int(continuous)] * (len(parts) - 1)
            own = np.concatenate([t.times[t.skip:] for t in parts])
            np.testing.assert_array_equal(own, np.arange(NUM_FRAMES, dtype=np.float64))  # each time code once
            assert max(t.frames - t.skip for t in parts) <= size
            for before, after in zip(parts, parts[1:]):  # continuous: one time code shared, the cut's interval
                assert (after.times[0] == before.times[-1]) == continuous


def test_plan_shares_files_among_workers(files):
    many = [files["mixed"], files["dup"], files["abc"]]
    tasks, errors = plan_tasks(many, workers=3)  # as many files as workers: whole files, not opened
    assert not errors and [(t.file, t.times, t.skip) for t in tasks] == [(0, None, 0), (1, None, 0), (2, None, 0)]
    frames = slice(0, NUM_FRAMES - 1, 0.25)  # 93 time codes
    for workers, parts in ((2, 2), (4, 3), (16, 3)):  # an even share, or parts of MIN_FRAMES_PER_TASK (32)
        tasks, _ = plan_tasks([files["mixed"]], frames=frames, workers=workers, continuous=False)
        assert len(tasks) == parts == -(-93 // max(MIN_FRAMES_PER_TASK, -(-93 // workers)))
        assert sum(t.frames for t in tasks) == 93 and max(t.frames for t in tasks) - min(t.frames for t in tasks) <= 1
    # Fewer files than workers: every file cut; the largest parts first, whatever file they are of.
    tasks, errors = plan_tasks([files["dup"], files["mixed"], "/nonexistent/x.usda"], workers=4,
                               frames_per_task=5, continuous=True)
    assert list(errors) == [2] and "/nonexistent/x.usda" in errors[2]
    assert [(t.file, t.frames) for t in tasks] == [(1, 6), (1, 6), (1, 6), (1, 5), (1, 5), (0, 3)]


def test_merge_of_run_parts_is_the_serial_report(files, device):
    options = CheckOptions(continuous=True, clearance=0.2)
    tasks, _ = plan_tasks([files["mixed"]], frames_per_task=7, continuous=True)
    parts = sorted(tasks, key=lambda t: t.part)
    reports = [run_task(t, options, device=device).report for t in parts]
    merged = merge_reports(reports, [t.skip for t in parts])
    assert_same(merged, serial(files["mixed"], device, continuous=True, clearance=0.2))
    assert merged.seconds == {k: round(sum(r.seconds[k] for r in reports), 4) for k in reports[0].seconds}
    assert merge_reports(reports[:1]).frames == reports[0].frames


def test_merge_refuses_parts_that_do_not_belong_together(files, device):
    mine = run_task(plan_tasks([files["abc"]], frames_per_task=1)[0][0], CheckOptions(), device=device).report
    other = run_task(plan_tasks([files["envs"]], frames_per_task=1)[0][0], CheckOptions(), device=device).report
    with pytest.raises(ValueError, match="disagree"):
        merge_reports([mine, other])
    wide = run_task(plan_tasks([files["abc"]], frames_per_task=1)[0][1], CheckOptions(precision="float64"),
                    device=device).report
    with pytest.raises(ValueError, match="disagree"):
        merge_reports([mine, wide])
    with pytest.raises(ValueError, match="no parts"):
        merge_reports([])


def test_run_task_reports_bad_input_as_an_outcome(tmp_path):
    (task,), _ = plan_tasks([str(tmp_path / "missing.usda")])
    outcome = run_task(task, CheckOptions())
    assert outcome.report is None and outcome.status == EXIT_BAD_INPUT and "missing.usda" in outcome.error


# ---------------------------------------------------------------------------------------------
# time codes where a prim is invisible: the import reads visibility at a part's first time code


def test_parts_that_disagree_on_objects_do_not_stop_the_batch(tmp_path, files, device):
    blinking_stage(tmp_path / "blink.usda")
    batch = check_many([files["abc"], tmp_path / "blink.usda"], frames_per_task=2, device=device)
    assert batch.files[0].exit_status == EXIT_FINDINGS


def test_animated_visibility_parts_merge_to_the_serial_report(tmp_path, device):
    path = str(tmp_path / "blink.usda")
    blinking_stage(path)
    want = check_usd(path, device=device)
    assert want.object_path == ["/World/A/Geom"] and want.skipped == [("/World/B", "invisible")]
    assert_same(check_many(path, frames_per_task=2, device=device).files[0].report, want)


# ---------------------------------------------------------------------------------------------
# 6. on a local Ray cluster: two actors


@pytest.fixture(scope="module")
def ray_cluster(tmp_path_factory):
    """A local cluster of 2 CPUs whose workers see FAULT_ENV naming a marker file; the marker exists (the fault is
    disarmed) until a test removes it. ``(ray, marker path)``."""
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'warp-ccd[distributed]')")
    marker = tmp_path_factory.mktemp("fault") / "fault.pid"
    marker.write_text("disarmed")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, logging_level="ERROR",
             runtime_env={"env_vars": {FAULT_ENV: str(marker)}})
    yield ray, marker
    ray.shutdown()


def ray_workers(ray) -> int:
    """The actors of :func:`ray_check`: 2, or as many as there are GPUs, 2 at most, where there are GPUs (an actor
    holds one)."""
    return min(2, int(ray.cluster_resources().get("GPU", 0))) or 2


def ray_check(ray, paths, **options):
    """check_many on the fixture's cluster with :func:`ray_workers` actors; the cluster is left running."""
    workers = ray_workers(ray)
    batch = check_many(paths, ray=True, workers=workers, **options)
    assert (batch.engine, batch.workers) == ("ray", workers)
    assert ray.is_initialized()
    return batch


def test_ray_parts_merge_to_the_serial_reports(ray_cluster, files):
    ray, _ = ray_cluster
    options = dict(EVERYTHING, clearance=0.1)
    paths = [files["mixed"], files["dup"], files["abc"]]
    batch = ray_check(ray, paths, frames_per_task=5, **options)
    assert [f.tasks for f in batch.files] == [5, 1, 1]
    for f in batch.files:
        assert f.error is None and f.exit_status == EXIT_FINDINGS
        assert_same(f.report, serial(f.path, DEFAULT_DEVICE, **options))


def test_ray_lone_file_split_across_workers(ray_cluster, files):
    """A lone file is cut into a part per actor (on a cluster of one GPU, whose one actor holds it, into two parts
    by ``frames_per_task``), continuous across the cut, and the parts merge to the serial report."""
    ray, _ = ray_cluster
    frames = slice(0, NUM_FRAMES - 1, 0.5)  # 47 time codes: 2 parts, continuous across the cut
    split = {} if ray_workers(ray) >= 2 else {"frames_per_task": 24}
    batch = ray_check(ray, files["mixed"], frames=frames, continuous=True, segments=True, **split)
    assert batch.files[0].tasks == 2
    assert_same(batch.files[0].report, serial(files["mixed"], DEFAULT_DEVICE, frames=frames, continuous=True,
                                              segments=True))


def test_ray_failing_files_among_good_ones(ray_cluster, tmp_path, files):
    ray, _ = ray_cluster
    missing, garbage, broken = tmp_path / "missing.usda", tmp_path / "garbage.usda", tmp_path / "broken.usda"
    garbage.write_text("this is not a USD file\n" * 10)
    broken_mesh_stage(broken)
    batch = ray_check(ray, [files["mixed"], missing, broken, files["clean"], garbage, files["far"]])
    assert [f.exit_status for f in batch.files] == [EXIT_FINDINGS, EXIT_BAD_INPUT, EXIT_BAD_INPUT, EXIT_CLEAN,
                                                    EXIT_BAD_INPUT, EXIT_FINDINGS]
    assert batch.exit_status == EXIT_BAD_INPUT
    assert str(missing) in batch.files[1].error and "/World/Bad" in batch.files[2].error
    assert str(garbage) in batch.files[4].error
    for f in batch.files:
        if f.report is not None:
            assert_same(f.report, serial(f.path, DEFAULT_DEVICE))


def test_ray_worker_killed_mid_task_is_retried(ray_cluster, files):
    """A worker killed while it runs a task (the first task to start writes its process id to the marker and waits:
    this test kills that process, once) is restarted and the task run again, once: the report equals a clean
    run's, however loaded the machine (Ray refused the retries sent while it restarted the actor: on a loaded
    machine four refusals, each counted as a loss, failed the file)."""
    ray, marker = ray_cluster
    starts = marker.with_name(marker.name + ".starts")
    starts.unlink(missing_ok=True)
    marker.unlink()  # armed
    killed = []

    def kill_when_started():
        deadline = time.monotonic() + 600.0
        while time.monotonic() < deadline:
            pid = marker.read_text().strip() if marker.exists() else ""
            if pid:
                os.kill(int(pid), signal.SIGKILL)
                killed.append(int(pid))
                return
            time.sleep(0.05)

    killer = threading.Thread(target=kill_when_started, daemon=True)
    killer.start()
    options = {"continuous": True, "clearance": 0.2}
    batch = ray_check(ray, files["mixed"], frames_per_task=7, **options)
    killer.join(timeout=10.0)
    assert len(killed) == 1  # the fault happened, once, to a task that had started
    assert batch.files[0].tasks == 4 and batch.files[0].error is None
    lines = starts.read_text().split()
    assert len(lines) == 4 + 1 and lines.count(str(killed[0])) == 1  # one task ran twice: once killed, once again
    assert_same(batch.files[0].report, serial(files["mixed"], DEFAULT_DEVICE, **options))


def test_a_part_at_fault_checks_its_file_whole(tmp_path, device):
    """A set naming a prim invisible at the file's first time code is an error of one run; a part starting where
    the prim is visible would accept it: the file is checked again whole and fails as one run does."""
    path = str(tmp_path / "blink.usda")
    blinking_stage(path)
    with pytest.raises(ValueError) as one_run:
        check_usd(path, device=device, set_a="/World/A", set_b="/World/B")
    batch = check_many(path, frames_per_task=2, device=device, set_a="/World/A", set_b="/World/B")
    f = batch.files[0]
    assert f.exit_status == EXIT_BAD_INPUT and f.error == str(one_run.value) and f.tasks == 1


def test_cli_ray_before_the_file(ray_cluster, files, tmp_path):
    """``warp-ccd check --ray IN.usd``: the file is a file, not the cluster's address; the report is one run's."""
    from warp_ccd._src.cli.commands import main

    out = tmp_path / "ray.json"
    assert main(["check", "--ray", files["abc"], "--workers", "2", "--frames-per-task", "5",
                 "--report", str(out)]) == EXIT_FINDINGS
    got = json.loads(out.read_text())
    want = serial(files["abc"], DEFAULT_DEVICE).to_json()
    got.pop("seconds"), want.pop("seconds")
    assert json.dumps(got) == json.dumps(want)


def test_ray_read_tasks_equal_one_process(ray_cluster, files, monkeypatch):
    """A GPU worker's reads as cluster tasks (``workers.POOL``): shares of the prims read by Ray tasks give the
    poses one process reads, bit for bit."""
    import numpy as np
    from pxr import Usd

    from warp_ccd._src.check.cluster import _ray_pool
    from warp_ccd._src.usd import workers

    stage = Usd.Stage.Open(files["mixed"])
    prims = [p for p in stage.Traverse() if p.GetTypeName() == "Mesh"]
    paths = [str(p.GetPath()) for p in prims]
    times = np.arange(0.0, NUM_FRAMES)
    alone = workers.read_shared(stage, prims, paths, times, 0)
    calls = []
    monkeypatch.setattr(workers, "POOL", lambda fn, tasks: calls.append(len(tasks)) or _ray_pool(fn, tasks))
    monkeypatch.setattr(workers, "POOL_WORKERS", 2)
    assert workers.auto_workers() == 2
    shared = workers.read_shared(stage, prims, paths, times, 3)
    assert calls == [2]  # two shares as cluster tasks, the third read here
    for name in ("first", "poses", "scale", "ok", "finite", "fast"):
        assert np.array_equal(getattr(alone, name), getattr(shared, name)), name
