"""The JSON report's schema (``warp_ccd/usd/report.schema.json``, draft 2020-12): the schema itself is
valid; the report of every kind of check (plain, touching counted, with segments, ``--continuous``,
``--clearance``, ``--self``, ``--duplicates``, all at once) follows it, as a dict and as the text written;
a report with a field the schema does not know, of a wrong type, without a required field or of another
major version does not."""

import copy
import json
import os

import numpy as np
import pytest

from warp_ccd.usd import REPORT_SCHEMA_PATH, SCHEMA_VERSION, check_usd, report_schema

jsonschema = pytest.importorskip("jsonschema")
pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom, Vt  # noqa: E402
from usd_stages import define_mesh, duplicate_stage, grid, mixed_stage  # noqa: E402

from conftest import DEFAULT_DEVICE  # noqa: E402
from test_check_continuous import bullet_stage  # noqa: E402


def validator():
    return jsonschema.Draft202012Validator(report_schema())


def assert_valid(data: dict) -> None:
    errors = sorted(validator().iter_errors(data), key=lambda e: list(e.absolute_path))
    assert not errors, "\n".join(f"{list(e.absolute_path)}: {e.message}" for e in errors[:5])


def cloth_stage(path):
    """An 8 x 8 cloth flat at time code 0, its half beyond x = 0 folded back through the other at 1."""
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(1)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    points, counts, indices = grid(8, 2.0)
    attr = define_mesh(stage, "/World/Cloth", points, counts, indices).GetPointsAttr()
    attr.Set(Vt.Vec3fArray.FromNumpy(points.astype(np.float32)), 0)
    p = points.copy()
    f = p[:, 0] > 1e-9
    p[f, 1] = 0.2 * np.sin(3.0 * p[f, 2] + 0.3)
    p[f, 0] = 0.037 - p[f, 0]
    attr.Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)), 1)
    stage.GetRootLayer().Save()
    return path


@pytest.fixture(scope="module")
def stages(tmp_path_factory):
    folder = tmp_path_factory.mktemp("schema")
    mixed_stage(folder / "mixed.usda", num_frames=4)
    duplicate_stage("exact", folder / "twins.usda")
    return {"mixed": folder / "mixed.usda", "cloth": cloth_stage(folder / "cloth.usda"),
            "bullet": bullet_stage(folder / "bullet.usda", end_x=-0.05),
            "grazing": bullet_stage(folder / "grazing.usda", end_x=0.0, gap=0.03),
            "twins": folder / "twins.usda"}


CASES = {
    "plain": ("mixed", {}),
    "touching_counted": ("mixed", {"count_touching": True, "min_depth": 0.01}),
    "segments": ("mixed", {"segments": True}),
    "continuous": ("bullet", {"continuous": True}),
    "continuous_min_distance": ("grazing", {"continuous": True, "min_distance": 0.05}),
    "clearance": ("grazing", {"clearance": 0.05}),
    "clearance_mixed": ("mixed", {"clearance": 0.2}),
    "self": ("cloth", {"self_intersections": True}),
    "duplicates": ("twins", {"duplicates": True}),
    "everything": ("twins", {"duplicates": True, "continuous": True, "clearance": 0.1, "self_intersections": True,
                             "segments": True}),
}


def test_the_schema_is_a_valid_2020_12_schema():
    schema = report_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert os.path.isfile(REPORT_SCHEMA_PATH) and REPORT_SCHEMA_PATH.endswith("report.schema.json")
    with open(REPORT_SCHEMA_PATH) as fh:
        assert json.load(fh) == schema
    report_schema()["title"] = "changed"  # a new dict each call
    assert report_schema()["title"] != "changed"


def test_every_object_of_the_schema_lists_its_fields():
    def objects(node):
        if isinstance(node, dict):
            if node.get("type") == "object":
                yield node
            for value in node.values():
                yield from objects(value)
        elif isinstance(node, list):
            for value in node:
                yield from objects(value)

    found = list(objects(report_schema()))
    assert len(found) > 10
    for node in found:
        assert node["additionalProperties"] is False and set(node["required"]) <= set(node["properties"])


@pytest.mark.parametrize("case", list(CASES))
def test_reports_follow_the_schema(stages, device, case):
    name, options = CASES[case]
    report = check_usd(stages[name], device=device, **options)
    data = report.to_json()
    assert data["schema_version"] == SCHEMA_VERSION == "2.0"
    assert_valid(data)
    assert_valid(json.loads(report.json_text()))  # as written: tuples are lists, numbers plain
    # The optional sections are there when asked for, and only then.
    assert ("continuous" in data) == bool(options.get("continuous"))
    assert ("clearance" in data) == bool(options.get("clearance"))
    assert ("self_intersections" in data) == bool(options.get("self_intersections"))
    assert ("duplicates" in data) == bool(options.get("duplicates"))
    if options.get("segments"):
        assert any("segments" in p for f in data["frames"] for p in f["pairs"])
    if case == "duplicates":
        assert data["duplicated"] and data["duplicates"]["pairs"]


@pytest.fixture(scope="module")
def everything(stages):
    return check_usd(stages["twins"], device=DEFAULT_DEVICE, continuous=True, clearance=0.1, self_intersections=True,
                     segments=True, duplicates=True).to_json()


def frame_with_pairs(data):
    return next(f for f in data["frames"] if f["pairs"])


@pytest.mark.parametrize("change, where", [
    (lambda d: d.update(colour="red"), "top level: an unknown field"),
    (lambda d: frame_with_pairs(d).update(note=1), "a frame: an unknown field"),
    (lambda d: frame_with_pairs(d)["pairs"][0].update(depth=0.1), "a frame's pair: an unknown field"),
    (lambda d: d["continuous"]["intervals"][0].update(extra=[]), "an interval: an unknown field"),
    (lambda d: d["duplicates"]["pairs"][0].update(faces=[]), "a duplicate pair: an unknown field"),
    (lambda d: d["seconds"].update(export=0.1), "seconds: an unknown part"),
    (lambda d: d.update(objects="3"), "objects: a string"),
    (lambda d: d.update(penetrating=1), "penetrating: an integer"),
    (lambda d: d.update(findings="exploding"), "findings: an unknown verdict"),
    (lambda d: d["frames"][0].update(time=None), "a frame's time: null"),
    (lambda d: frame_with_pairs(d)["pairs"][0].update(faces=[[1, 2, 3]]), "a face pair of three"),
    (lambda d: d["duplicates"].update(duplicated="yes"), "duplicated: a string"),
    (lambda d: d.update(schema_version="3.0"), "another major version"),
    (lambda d: d.pop("findings"), "a required field missing"),
    (lambda d: d.pop("tunnelling"), "a section without its flag"),
    (lambda d: d["frames"][0].pop("pairs"), "a frame without its pairs"),
])
def test_drift_fails_validation(everything, change, where):
    assert_valid(everything)
    data = copy.deepcopy(everything)
    change(data)
    assert list(validator().iter_errors(data)), where
