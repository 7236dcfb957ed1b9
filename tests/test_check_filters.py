"""``check`` with pair filters: ``--ignore-pairs`` (text and JSON; by path, by pattern, by an ``Xform`` parent),
the stage's ``UsdPhysics`` filtered pairs and collision groups (``--no-usd-filters``), ``--set-a`` / ``--set-b``,
``--worlds``; the report's ``filters`` section (schema-valid) and summary lines; bad inputs exit 2 with one line.
Stages of a few box-like prisms, two time codes (:func:`usd_stages.boxes_stage`)."""

import json

import numpy as np
import pytest

from warp_ccd._src.cli import commands as cli
from warp_ccd.usd import check_usd, report_schema, scene_from_usd

from conftest import DEFAULT_DEVICE

pxr = pytest.importorskip("pxr")
from usd_stages import boxes_stage, env_boxes  # noqa: E402

ABC = {"/World/A": (0.0, 0.0, 0.0), "/World/B": (0.3, 0.0, 0.0), "/World/C": (0.6, 0.0, 0.0)}


@pytest.fixture(scope="module")
def stages(tmp_path_factory):
    folder = tmp_path_factory.mktemp("filters")
    out = {"two": folder / "two.usda", "abc": folder / "abc.usda", "envs": folder / "envs.usda",
           "physics": folder / "physics.usda", "groups": folder / "groups.usda"}
    boxes_stage(out["two"])
    boxes_stage(out["abc"], ABC)
    boxes_stage(out["envs"], env_boxes())
    boxes_stage(out["physics"], filtered_pairs={"/World/A": ["/World/B"]})
    boxes_stage(out["groups"], ABC, collision_groups={"/Groups/G1": ["/World/A"], "/Groups/G2": ["/World/B"]},
                filtered_groups={"/Groups/G1": ["/Groups/G2"]})
    return {k: str(v) for k, v in out.items()}


def run(capsys, *argv):
    """``warp-ccd check ...`` in process: ``(exit status, stdout, stderr)``."""
    rc = cli.main(["check", *map(str, argv)])
    out = capsys.readouterr()
    return rc, out.out, out.err


def pairs_of(report, frame: int = 0) -> list:
    return sorted(tuple(sorted((report.object_path[a], report.object_path[b])))
                  for a, b in report.frames[frame].object_pairs.tolist())


def valid(data: dict) -> dict:
    """``data``, validated against the report's schema where jsonschema (a test extra) is installed."""
    try:
        import jsonschema
    except ImportError:
        return data
    jsonschema.Draft202012Validator(report_schema()).validate(data)
    return data


@pytest.mark.parametrize("content, name", [
    ("/World/A/Geom /World/B/Geom\n", "pairs.txt"),  # by path
    ("# parts meant to touch\n\n/World/A/Geom, /World/B/Geom  # the two boxes\n", "pairs.txt"),  # comma, comments
    ("/World/A /World/B\n", "pairs.txt"),  # by their Xform parents
    ("/World/A* /World/B*\n", "pairs.txt"),  # by patterns
    ('[["/World/A/Geom", "/World/B/Geom"]]', "pairs.json"),
    ('[["/World/A", "/World/*/Geom"]]', "pairs.json"),  # a pattern matching both sides: every pair is left
])
def test_ignore_pairs_makes_the_check_clean(stages, tmp_path, capsys, content, name):
    pairs = tmp_path / name
    pairs.write_text(content)
    report = tmp_path / "r.json"
    rc, out, err = run(capsys, stages["two"], "--device", DEFAULT_DEVICE, "--report", report)
    assert rc == 1, err
    assert "filters" not in valid(json.loads(report.read_text()))  # no filter, no section
    rc, out, err = run(capsys, stages["two"], "--device", DEFAULT_DEVICE, "--ignore-pairs", pairs, "--report", report)
    assert rc == 0, err
    data = valid(json.loads(report.read_text()))
    assert data["schema_version"] == "2.0" and data["findings"] is None
    f = data["filters"]
    assert (f["excluded_pairs"], f["excluded_given"], f["excluded_usd"], f["ignore_lines"]) == (1, 1, 0, 1)
    assert f["ignore_pairs"] == [str(pairs)] and f["usd_filters"] is True
    assert "excluded object pairs: 1 (1 given in 1 prim pairs" in out


def test_ignore_pairs_from_python(stages):
    report = check_usd(stages["abc"], device=DEFAULT_DEVICE,
                       ignore_pairs=[("/World/A", "/World/B"), ["/World/B", "/World/C"]])
    assert pairs_of(report) == [("/World/A", "/World/C")]
    assert report.filters.excluded == 2 and report.filters.ignore_files == []


def test_usd_filtered_pairs(stages, capsys, tmp_path):
    report = tmp_path / "r.json"
    rc, out, err = run(capsys, stages["physics"], "--device", DEFAULT_DEVICE, "--report", report)
    assert rc == 0, err
    f = valid(json.loads(report.read_text()))["filters"]
    assert (f["excluded_usd"], f["usd_filtered_pairs"], f["excluded_given"]) == (1, 1, 0)
    rc, out, err = run(capsys, stages["physics"], "--device", DEFAULT_DEVICE, "--no-usd-filters", "--report", report)
    assert rc == 1, err
    data = valid(json.loads(report.read_text()))
    assert data["findings"] == "penetrating" and data["filters"]["usd_filters"] is False
    assert data["filters"]["excluded_pairs"] == 0 and "USD physics filters off" in out


def test_usd_collision_groups(stages):
    report = check_usd(stages["groups"], device=DEFAULT_DEVICE)
    assert pairs_of(report) == [("/World/A", "/World/C"), ("/World/B", "/World/C")]
    assert report.filters.usd_collision_groups == 2 and report.filters.excluded_usd == 1
    assert len(pairs_of(check_usd(stages["groups"], device=DEFAULT_DEVICE, usd_filters=False))) == 3


def test_set_a_against_set_b(stages, capsys, tmp_path):
    everything = check_usd(stages["abc"], device=DEFAULT_DEVICE)
    assert len(pairs_of(everything)) == 3  # A, B and C all penetrate each other
    path = tmp_path / "r.json"
    rc, out, err = run(capsys, stages["abc"], "--device", DEFAULT_DEVICE, "--set-a", "/World/A", "--set-b", "/World/B",
                       "--report", path)
    assert rc == 1, err
    data = valid(json.loads(path.read_text()))
    assert [(p["a"], p["b"]) for p in data["pairs"]] == [("/World/A", "/World/B")]
    f = data["filters"]
    assert (f["set_a"], f["set_b"], f["set_a_objects"], f["set_b_objects"]) == (["/World/A"], ["/World/B"], 1, 1)
    assert "only set A x set B: A /World/A (1 objects), B /World/B (1 objects)" in out
    # A prim in both sets pairs with every other prim of either set; repeated options and comma lists add up.
    report = check_usd(stages["abc"], device=DEFAULT_DEVICE, set_a=["/World/A", "/World/B"], set_b="/World/B")
    assert pairs_of(report) == [("/World/A", "/World/B")]  # B-B is no pair; A-A none either
    report = check_usd(stages["abc"], device=DEFAULT_DEVICE, set_a="/World/A,/World/B", set_b=["/World/B", "/World/C"])
    assert pairs_of(report) == [("/World/A", "/World/B"), ("/World/A", "/World/C"), ("/World/B", "/World/C")]
    report = check_usd(stages["abc"], device=DEFAULT_DEVICE, set_a="/World/[AB]", set_b="/World/C")
    assert pairs_of(report) == [("/World/A", "/World/C"), ("/World/B", "/World/C")]
    rc, out, err = run(capsys, stages["abc"], "--device", DEFAULT_DEVICE, "--set-a", "/World/A", "--set-a", "/World/C",
                       "--set-b", "/World/B", "--report", path)
    assert rc == 1, err
    data = valid(json.loads(path.read_text()))
    assert sorted((p["a"], p["b"]) for p in data["pairs"]) == [("/World/A", "/World/B"), ("/World/B", "/World/C")]
    assert data["filters"]["set_a"] == ["/World/A", "/World/C"]


def test_sets_combine_with_excluded_pairs(stages):
    report = check_usd(stages["abc"], device=DEFAULT_DEVICE, set_a="/World/A", set_b="/World/B,/World/C",
                       ignore_pairs=[("/World/A", "/World/C")])
    assert pairs_of(report) == [("/World/A", "/World/B")]


def test_worlds(stages, capsys, tmp_path):
    plain = check_usd(stages["envs"], device=DEFAULT_DEVICE)
    assert len(pairs_of(plain)) == 10  # the two environments on top of each other: every pair crosses
    report = tmp_path / "r.json"
    rc, out, err = run(capsys, stages["envs"], "--device", DEFAULT_DEVICE, "--worlds", "/World/envs/*", "--report",
                       report)
    assert rc == 1, err
    data = valid(json.loads(report.read_text()))
    got = sorted(tuple(sorted((p["a"], p["b"]))) for p in data["pairs"])
    ground = "/World/Ground/Geom"
    assert got == sorted([("/World/envs/env0/P", "/World/envs/env0/Q"), ("/World/envs/env1/P", "/World/envs/env1/Q")]
                         + [tuple(sorted((f"/World/envs/env{k}/{m}", ground))) for k in (0, 1) for m in "PQ"])
    f = data["filters"]
    assert (f["worlds"], f["world_count"], f["world_roots"]) == (
        ["/World/envs/*"], 2, ["/World/envs/env0", "/World/envs/env1"])
    assert "worlds: 2 (/World/envs/*)" in out
    # The import alone: world ids in the roots' order, -1 outside; two patterns, one world each.
    scene = scene_from_usd(stages["envs"], device=DEFAULT_DEVICE, worlds=["/World/envs/env1", "/World/envs/env0"])
    world = dict(zip(scene.usd.object_path, scene.usd.object_world.tolist()))
    assert world == {"/World/envs/env0/P": 0, "/World/envs/env0/Q": 0, "/World/envs/env1/P": 1,
                     "/World/envs/env1/Q": 1, ground: -1}
    np.testing.assert_array_equal(scene.collision_filter.object_world, scene.usd.object_world)


@pytest.mark.parametrize("content, name, message", [
    ("/World/A /World/B /World/C\n", "bad.txt", "bad.txt:1: expected two prim paths separated by whitespace or"),
    ("# fine\n/World/A\n", "bad.txt", "bad.txt:2: expected two prim paths"),
    ("World/A World/B\n", "bad.txt", "bad.txt:1: expected a prim path or pattern starting with '/'"),
    ("/World/A /World/Nowhere\n", "bad.txt", "bad.txt:1: /World/Nowhere names no prim of the stage"),
    ("/World/A /World/Q*\n", "bad.txt", "bad.txt:1: /World/Q* names no prim of the stage"),
    ('[["/World/A"]]', "bad.json", "bad.json: entry 0: expected a pair [a, b] of prim paths"),
    ('{"a": 1}', "bad.json", "bad.json: expected a JSON list of [a, b] prim path pairs"),
    ("[[", "bad.json", "bad.json:1: not valid JSON"),
])
def test_bad_ignore_pairs_files(stages, tmp_path, capsys, content, name, message):
    bad = tmp_path / name
    bad.write_text(content)
    rc, out, err = run(capsys, stages["two"], "--device", DEFAULT_DEVICE, "--ignore-pairs", bad)
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err


def test_missing_prims_with_allow_missing_are_notes(stages, tmp_path, capsys):
    pairs = tmp_path / "pairs.txt"
    pairs.write_text("/World/A /World/B\n/World/A /World/Nowhere\n")
    report = tmp_path / "r.json"
    rc, out, err = run(capsys, stages["two"], "--device", DEFAULT_DEVICE, "--ignore-pairs", pairs, "--allow-missing",
                       "--report", report)
    assert rc == 0, err
    f = valid(json.loads(report.read_text()))["filters"]
    assert f["excluded_given"] == 1 and len(f["notes"]) == 1 and "/World/Nowhere names no prim" in f["notes"][0]
    assert "note: " in out and "pair ignored" in out
    report = check_usd(stages["abc"], device=DEFAULT_DEVICE, set_a="/World/A,/World/Nowhere", set_b="/World/B",
                       allow_missing=True)
    assert pairs_of(report) == [("/World/A", "/World/B")] and "set_a: /World/Nowhere" in report.filters.notes[0]


@pytest.mark.parametrize("argv, message", [
    (["--ignore-pairs", "{missing}"], "cannot read the ignore-pairs file {missing}: no such file"),
    (["--ignore-pairs", "{folder}"], "it is a folder"),
    (["--set-a", "/World/A"], "set_a and set_b go together (--set-a and --set-b): pairs of one prim of each are "
                              "checked; only set_a given"),
    (["--set-b", "/World/A"], "only set_b given"),
    (["--set-a", "/World/A", "--set-b", "/World/Nowhere"], "set_b: /World/Nowhere matches no mesh that is checked"),
    (["--worlds", "/World/envs/*"], "worlds: /World/envs/* matches no mesh that is checked"),
])
def test_bad_arguments_exit_2(stages, tmp_path, capsys, argv, message):
    names = {"missing": str(tmp_path / "missing.txt"), "folder": str(tmp_path)}
    argv = [a.format(**names) for a in argv]
    rc, out, err = run(capsys, stages["two"], "--device", DEFAULT_DEVICE, *argv)
    assert rc == 2 and message.format(**names) in err and len(err.strip().splitlines()) == 1, err
    assert out == ""


def test_filters_pass_before_the_stage_is_read(tmp_path, capsys):
    """A bad ignore-pairs file or a lone set is reported even when the stage is missing too: the
    arguments first."""
    rc, _, err = run(capsys, tmp_path / "none.usda", "--set-a", "/World/A")
    assert rc == 2 and "(--set-a and --set-b)" in err


def test_the_root_names_every_mesh(stages):
    """``/`` is the stage's root: a pair with it excludes every pair of the other side's meshes; a pattern
    never matches the root itself (``/*`` is every top prim)."""
    report = check_usd(stages["abc"], device=DEFAULT_DEVICE, ignore_pairs=[("/", "/World/A")])
    assert pairs_of(report) == [("/World/B", "/World/C")]
    report = check_usd(stages["abc"], device=DEFAULT_DEVICE, worlds="/*")
    assert len(pairs_of(report)) == 3  # one top prim, /World: one world
