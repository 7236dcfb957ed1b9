"""``check`` with USD Physics' own collision rules (``warp_ccd._src.usd.physics``, on unless ``--no-usd-filters``):
meshes of one rigid body are one object (nested bodies, disabled bodies, bodies in a PointInstancer's prototype);
bodies a joint joins with ``physics:collisionEnabled`` false are not checked against each other (targets under a
body, static targets, the world, disabled joints, flags over time, bad targets); articulation links follow their
joints; the report's counts per rule; newton's ``axis_cube.usda`` through the command. Stages of box-like prisms
(:func:`usd_stages.boxes_stage`: radius 0.7, so boxes 0.3 and 0.6 apart penetrate)."""

import importlib.util
import json
import os

import numpy as np
import pytest

from warp_ccd._src.cli import commands as cli
from warp_ccd._src.usd import filters
from warp_ccd._src.usd.filters import PrimIndex
from warp_ccd._src.usd.physics import body_keys, joint_keys, object_bodies
from warp_ccd.usd import check_usd, report_schema

from conftest import DEFAULT_DEVICE

pxr = pytest.importorskip("pxr")
from pxr import Gf, Sdf, UsdGeom, UsdPhysics, Vt  # noqa: E402
from usd_stages import boxes_stage, define_mesh, prism  # noqa: E402

ABC = {"/World/A/Geom": (0.0, 0.0, 0.0), "/World/B/Geom": (0.3, 0.0, 0.0), "/World/C/Geom": (0.6, 0.0, 0.0)}


def pairs_of(report, frame: int = 0) -> list:
    """The frame's prim pairs, a ``/Geom`` mesh named by its parent."""
    name = [p.removesuffix("/Geom") for p in report.object_path]
    return sorted(tuple(sorted((name[a], name[b]))) for a, b in report.frames[frame].object_pairs.tolist())


def valid(data: dict) -> dict:
    """``data``, validated against the report's schema where jsonschema (a test extra) is installed."""
    try:
        import jsonschema
    except ImportError:
        return data
    jsonschema.Draft202012Validator(report_schema()).validate(data)
    return data


def run(capsys, *argv):
    """``warp-ccd check ...`` in process: ``(exit status, stdout, stderr)``."""
    rc = cli.main(["check", *map(str, argv)])
    out = capsys.readouterr()
    return rc, out.out, out.err


def physics_stage(path, boxes, bodies=(), disabled=(), joints=(), articulations=()):
    """:func:`boxes_stage` with ``RigidBodyAPI`` on ``bodies`` (``rigidBodyEnabled`` false on ``disabled``),
    ``ArticulationRootAPI`` on ``articulations``, and ``joints``: ``(path, body0, body1, attributes)`` revolute
    joints (a body None: no target; a list: several), ``attributes`` ``{name: value}`` of the joint."""
    stage = boxes_stage(path, boxes)
    for p in bodies:
        api = UsdPhysics.RigidBodyAPI.Apply(stage.GetPrimAtPath(p))
        if p in disabled:
            api.CreateRigidBodyEnabledAttr(False)
    for p in articulations:
        UsdPhysics.ArticulationRootAPI.Apply(stage.GetPrimAtPath(p))
    for jpath, b0, b1, attrs in joints:
        joint = UsdPhysics.RevoluteJoint.Define(stage, jpath)
        for rel, target in ((joint.CreateBody0Rel(), b0), (joint.CreateBody1Rel(), b1)):
            if target is not None:
                rel.SetTargets([Sdf.Path(t) for t in ([target] if isinstance(target, str) else target)])
        for name, value in attrs.items():
            attr = joint.GetPrim().GetAttribute(f"physics:{name}")
            if isinstance(value, dict):  # time samples
                for t, v in value.items():
                    attr.Set(v, t)
            else:
                attr.Set(value)
    stage.GetRootLayer().Save()
    return str(path)


# ------------------------------------------------------------------ rigid bodies

def test_meshes_of_one_rigid_body_are_one_object(tmp_path, capsys):
    path = physics_stage(tmp_path / "body.usda", {"/World/Body/A": (0, 0, 0), "/World/Body/B": (0.3, 0, 0)},
                         bodies=["/World/Body"])
    report = check_usd(path, device=DEFAULT_DEVICE)
    assert pairs_of(report) == []
    f = report.filters
    assert (f.excluded, f.excluded_usd, f.excluded_rigid_body, f.usd_rigid_bodies) == (1, 1, 1, 1)
    assert pairs_of(check_usd(path, device=DEFAULT_DEVICE, usd_filters=False)) == [("/World/Body/A", "/World/Body/B")]
    out_json = tmp_path / "r.json"
    rc, out, err = run(capsys, path, "--device", DEFAULT_DEVICE, "--report", out_json)
    assert rc == 0, err
    data = valid(json.loads(out_json.read_text()))
    assert data["schema_version"] == "2.0"
    assert (data["filters"]["excluded_rigid_body"], data["filters"]["usd_rigid_bodies"]) == (1, 1)
    assert "1 within 1 rigid bodies" in out
    rc, out, err = run(capsys, path, "--device", DEFAULT_DEVICE, "--no-usd-filters")
    assert rc == 1, err


@pytest.mark.parametrize("inner_enabled", [True, False])
def test_nested_rigid_bodies(tmp_path, inner_enabled):
    # /World/Body holds A and the body Inner, which holds B and C: B-C is Inner's own pair; A against B and C
    # are pairs of two bodies. With Inner disabled, all three meshes are /World/Body's.
    boxes = {"/World/Body/A": (0, 0, 0), "/World/Body/Inner/B": (0.3, 0, 0), "/World/Body/Inner/C": (0.6, 0, 0)}
    path = physics_stage(tmp_path / "nested.usda", boxes, bodies=["/World/Body", "/World/Body/Inner"],
                         disabled=[] if inner_enabled else ["/World/Body/Inner"])
    report = check_usd(path, device=DEFAULT_DEVICE)
    if inner_enabled:
        assert pairs_of(report) == [("/World/Body/A", "/World/Body/Inner/B"), ("/World/Body/A", "/World/Body/Inner/C")]
        assert (report.filters.usd_rigid_bodies, report.filters.excluded_rigid_body) == (2, 1)
    else:
        assert pairs_of(report) == []
        assert (report.filters.usd_rigid_bodies, report.filters.excluded_rigid_body) == (1, 3)
    assert len(pairs_of(check_usd(path, device=DEFAULT_DEVICE, usd_filters=False))) == 3


def test_rigid_body_in_a_point_instancer_prototype_is_one_body_per_instance(tmp_path):
    stage = boxes_stage(tmp_path / "inst.usda", {})
    inst = UsdGeom.PointInstancer.Define(stage, "/World/Inst")
    UsdGeom.Scope.Define(stage, "/World/Inst/Protos")
    body = UsdGeom.Xform.Define(stage, "/World/Inst/Protos/Body")
    UsdPhysics.RigidBodyAPI.Apply(body.GetPrim())
    points, counts, indices = prism(4, radius=0.7, height=1.0)
    for name, dx in (("G0", 0.0), ("G1", 0.3)):
        mesh = define_mesh(stage, f"/World/Inst/Protos/Body/{name}", points, counts, indices)
        UsdGeom.Xformable(mesh).AddTranslateOp().Set(Gf.Vec3d(dx, 0, 0))
    inst.CreatePrototypesRel().SetTargets([Sdf.Path("/World/Inst/Protos/Body")])
    inst.CreateProtoIndicesAttr(Vt.IntArray([0, 0]))
    inst.CreatePositionsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0), Gf.Vec3f(0.2, 0, 0)]))
    stage.GetRootLayer().Save()
    report = check_usd(str(tmp_path / "inst.usda"), device=DEFAULT_DEVICE)
    # Each instance's own two meshes are one body; the two instances are two bodies: their 4 pairs are checked.
    assert len(pairs_of(report)) == 4 and report.filters.excluded_rigid_body == 2
    assert all(a.split("]")[0] != b.split("]")[0] for a, b in pairs_of(report))
    assert len(pairs_of(check_usd(str(tmp_path / "inst.usda"), device=DEFAULT_DEVICE, usd_filters=False))) == 6


def test_a_rigid_body_beyond_the_excluded_pairs_limit_is_an_error(tmp_path, monkeypatch):
    path = physics_stage(tmp_path / "big.usda", {"/World/Body/A": (0, 0, 0), "/World/Body/B": (0.3, 0, 0)},
                         bodies=["/World/Body"])
    monkeypatch.setattr(filters, "MAX_EXCLUDED", 0)
    with pytest.raises(ValueError, match="rigid body /World/Body: its 2 meshes"):
        check_usd(path, device=DEFAULT_DEVICE)
    assert len(pairs_of(check_usd(path, device=DEFAULT_DEVICE, usd_filters=False))) == 1


# ------------------------------------------------------------------ joints

BODIES = ["/World/A", "/World/B", "/World/C"]


@pytest.mark.parametrize("attrs, excluded", [
    ({}, True),  # collisionEnabled false: the schema's default
    ({"collisionEnabled": False}, True),
    ({"collisionEnabled": True}, False),
    ({"jointEnabled": False}, False),  # a disabled joint is absent: it filters nothing
])
def test_joint_collision_enabled(tmp_path, attrs, excluded):
    path = physics_stage(tmp_path / "joint.usda", ABC, bodies=BODIES,
                         joints=[("/World/J", "/World/A", "/World/B", attrs)])
    report = check_usd(path, device=DEFAULT_DEVICE)
    everything = [("/World/A", "/World/B"), ("/World/A", "/World/C"), ("/World/B", "/World/C")]
    assert pairs_of(report) == [p for p in everything if not (excluded and p == ("/World/A", "/World/B"))]
    assert (report.filters.usd_joints, report.filters.excluded_joints) == (1, int(excluded))
    assert pairs_of(check_usd(path, device=DEFAULT_DEVICE, usd_filters=False)) == everything


@pytest.mark.parametrize("body0, body1", [
    ("/World/A/Geom", "/World/B"),  # a target under a body names the body
    ("/World/A", "/World/B/Geom"),
    ("/World/A/Geom", "/World/B/Geom"),
])
def test_joint_target_under_a_body(tmp_path, body0, body1):
    path = physics_stage(tmp_path / "child.usda", ABC, bodies=BODIES, joints=[("/World/J", body0, body1, {})])
    assert pairs_of(check_usd(path, device=DEFAULT_DEVICE)) == [("/World/A", "/World/C"), ("/World/B", "/World/C")]


def test_joint_to_a_static_prim(tmp_path):
    # /World/A is no rigid body: a static collider; the joint excludes its meshes against body B's.
    path = physics_stage(tmp_path / "static.usda", ABC, bodies=["/World/B", "/World/C"],
                         joints=[("/World/J", "/World/A", "/World/B", {})])
    assert pairs_of(check_usd(path, device=DEFAULT_DEVICE)) == [("/World/A", "/World/C"), ("/World/B", "/World/C")]


@pytest.mark.parametrize("body0, note", [
    (None, None),  # a joint to the world: nothing to exclude
    ("/World/Nowhere", "no prim of the stage"),  # a dangling target: read as the world, with a note
])
def test_joint_with_one_body_missing(tmp_path, body0, note):
    path = physics_stage(tmp_path / "world.usda", ABC, bodies=BODIES, joints=[("/World/J", body0, "/World/B", {})])
    report = check_usd(path, device=DEFAULT_DEVICE)
    assert len(pairs_of(report)) == 3 and report.filters.excluded_joints == 0
    assert report.filters.usd_joints == 1
    if note:
        assert any(note in n and "/World/J" in n for n in report.filters.notes)


def test_joint_flags_over_time_exclude_nothing(tmp_path):
    path = physics_stage(tmp_path / "animated.usda", ABC, bodies=BODIES,
                         joints=[("/World/J", "/World/A", "/World/B", {"collisionEnabled": {0: False, 1: True}})])
    report = check_usd(path, device=DEFAULT_DEVICE)
    assert len(pairs_of(report)) == 3
    assert any("joint /World/J: physics:collisionEnabled changes over time" in n for n in report.filters.notes)


@pytest.mark.parametrize("body0, message", [
    (["/World/A", "/World/C"], "joint /World/J: physics:body0 has 2 targets"),
    ("/World/A.physics:velocity", "joint /World/J: physics:body0 targets /World/A.physics:velocity, which is not"),
])
def test_bad_joint_targets_are_errors_naming_the_joint(tmp_path, capsys, body0, message):
    path = physics_stage(tmp_path / "bad.usda", ABC, bodies=BODIES, joints=[("/World/J", body0, "/World/B", {})])
    with pytest.raises(ValueError, match=message):
        check_usd(path, device=DEFAULT_DEVICE)
    rc, out, err = run(capsys, path, "--device", DEFAULT_DEVICE)
    assert rc == 2 and message in err
    assert len(pairs_of(check_usd(path, device=DEFAULT_DEVICE, usd_filters=False))) == 3


# ------------------------------------------------------------------ articulations

@pytest.mark.parametrize("bc_collides", [False, True])
def test_articulation_links_follow_their_joints(tmp_path, bc_collides):
    # A chain A - B - C under an articulation root: the joints' collisionEnabled decides, link by link; A and C,
    # which no joint joins, are checked (the schema filters nothing more for an articulation).
    path = physics_stage(tmp_path / "arm.usda", ABC, bodies=BODIES, articulations=["/World"],
                         joints=[("/World/J0", "/World/A", "/World/B", {}),
                                 ("/World/J1", "/World/B", "/World/C", {"collisionEnabled": bc_collides})])
    report = check_usd(path, device=DEFAULT_DEVICE)
    expected = [("/World/A", "/World/C")] + ([("/World/B", "/World/C")] if bc_collides else [])
    assert pairs_of(report) == expected
    f = report.filters
    assert (f.usd_articulations, f.usd_joints, f.excluded_joints) == (1, 2, 2 - bc_collides)


# ------------------------------------------------------------------ counts, newton's asset

def test_counts_per_rule(tmp_path, capsys):
    # A and B one body; C jointed to it; D filtered against A; E and F in two groups that do not collide.
    boxes = {"/World/AB/A": (0, 0, 0), "/World/AB/B": (0.3, 0, 0), "/World/C/Geom": (0.6, 0, 0),
             "/World/D/Geom": (0, 0.3, 0), "/World/E/Geom": (0, 3, 0), "/World/F/Geom": (0.3, 3, 0)}
    stage = boxes_stage(tmp_path / "all.usda", boxes, filtered_pairs={"/World/D": ["/World/AB/A"]},
                        collision_groups={"/Groups/G1": ["/World/E"], "/Groups/G2": ["/World/F"]},
                        filtered_groups={"/Groups/G1": ["/Groups/G2"]})
    for p in ("/World/AB", "/World/C"):
        UsdPhysics.RigidBodyAPI.Apply(stage.GetPrimAtPath(p))
    joint = UsdPhysics.FixedJoint.Define(stage, "/World/J")
    joint.CreateBody0Rel().SetTargets([Sdf.Path("/World/AB")])
    joint.CreateBody1Rel().SetTargets([Sdf.Path("/World/C")])
    stage.GetRootLayer().Save()
    out_json = tmp_path / "r.json"
    rc, out, err = run(capsys, tmp_path / "all.usda", "--device", DEFAULT_DEVICE, "--report", out_json)
    f = valid(json.loads(out_json.read_text()))["filters"]
    assert (f["excluded_rigid_body"], f["excluded_joints"], f["excluded_filtered_pairs"],
            f["excluded_collision_groups"], f["excluded_usd"], f["excluded_pairs"]) == (1, 2, 1, 1, 5, 5)
    assert (f["usd_rigid_bodies"], f["usd_joints"], f["usd_articulations"]) == (2, 1, 0)
    assert ("excluded object pairs: 5 (0 given in 0 prim pairs; 5 from USD physics filters (1 within 2 rigid "
            "bodies, 2 by 1 joints, 1 by 1 filtered pairs, 1 by 2 collision groups))") in out


def _axis_cube() -> str | None:
    spec = importlib.util.find_spec("newton")
    if spec is None or spec.origin is None:
        return None
    path = os.path.join(os.path.dirname(spec.origin), "examples", "assets", "axis_cube.usda")
    return path if os.path.exists(path) else None


@pytest.mark.skipif(_axis_cube() is None, reason="newton (with its example assets) is not installed")
def test_newton_axis_cube(tmp_path, capsys):
    # A rigid body holding a collision cube and a visual cube flush on its faces: one object, nothing to report.
    out_json = tmp_path / "r.json"
    rc, out, err = run(capsys, _axis_cube(), "--device", DEFAULT_DEVICE, "--report", out_json)
    assert rc == 0, err
    data = valid(json.loads(out_json.read_text()))
    assert data["findings"] is None
    assert (data["filters"]["excluded_rigid_body"], data["filters"]["usd_rigid_bodies"]) == (1, 1)
    assert "1 within 1 rigid bodies" in out
    rc, out, err = run(capsys, _axis_cube(), "--device", DEFAULT_DEVICE, "--no-usd-filters")
    assert rc == 1, err
    assert "/AxisCube/CollisionCube" in out and "/AxisCube/VisualCube" in out


# ------------------------------------------------------------------ the pair lists, against brute force

def test_body_and_joint_keys_match_brute_force():
    rng = np.random.default_rng(0)
    names = [f"/W/B{k}/M{j}" for k in range(12) for j in range(int(rng.integers(1, 5)))] + ["/W/S/M0", "/W/S/M1"]
    order = rng.permutation(len(names))
    names = [names[i] for i in order]
    index = PrimIndex(names)
    bodies = [f"/W/B{k}" for k in range(12)]
    body, group = object_bodies(index, bodies)
    budget = [10**6]
    keys = np.unique(body_keys(group, index, body, budget))
    owner = np.array([n.split("/")[2] for n in names])
    expect = {(i, j) for i in range(len(names)) for j in range(i + 1, len(names)) if owner[i] == owner[j] != "S"}
    assert {(int(k >> 32), int(k & 0xFFFFFFFF)) for k in keys} == expect
    joints = [("/W/J0", "/W/B0", "/W/B1/M0"), ("/W/J1", "/W/S", "/W/B2"), ("/W/J2", "/W/B3", None),
              ("/W/J3", "/W/B4", "/W/B4")]
    keys = np.unique(joint_keys(joints, index, body, bodies, budget))
    sides = [({"B0"}, {"B1"}), ({"S"}, {"B2"})]
    expect = {(min(i, j), max(i, j)) for a, b in sides for i in range(len(names)) for j in range(len(names))
              if owner[i] in a and owner[j] in b}
    assert {(int(k >> 32), int(k & 0xFFFFFFFF)) for k in keys} == expect
    within = sum(int(np.sum(owner == o) * (np.sum(owner == o) - 1) // 2) for o in set(owner) - {"S"})
    across = sum(int(np.isin(owner, list(a)).sum() * np.isin(owner, list(b)).sum()) for a, b in sides)
    assert budget[0] == 10**6 - within - across
