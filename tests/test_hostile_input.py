"""Hostile USD input to ``warp-ccd check``: every one exit status 2 and one line naming the file, the
prim, the attribute and the time code (the importer: a ValueError naming the prim), never an
internal error or a silent answer.

Xform ops of the wrong value type or not finite, mesh attributes of the wrong type (``points`` as a
flat ``float[]``, ``float[]`` indices or counts), negative counts, and zero or mirroring scales.
"""

import json
import re

import pytest

from warp_ccd._src.cli import commands as cli

from conftest import DEFAULT_DEVICE

pytest.importorskip("pxr")
from warp_ccd._src.usd.importer import UsdMeshImport  # noqa: E402

POINTS = "[(0,0,0),(1,0,0),(1,1,0),(0,1,0),(0,0,1),(1,0,1),(1,1,1),(0,1,1)]"
FLAT = "[0,0,0,1,0,0,1,1,0,0,1,0,0,0,1,1,0,1,1,1,1,0,1,1]"
INDICES = "[0, 3, 2, 1, 4, 5, 6, 7, 0, 1, 5, 4, 2, 3, 7, 6, 0, 4, 7, 3, 1, 2, 6, 5]"


def cube(name, points=f"point3f[] points = {POINTS}", counts="int[] faceVertexCounts = [4, 4, 4, 4, 4, 4]",
         indices=f"int[] faceVertexIndices = {INDICES}", xform=""):
    """A unit cube mesh ``/World/<name>`` as usda text, its attributes given as text."""
    body = "".join(f"        {line}\n" for line in (points, counts, indices, xform))
    return f'    def Mesh "{name}"\n    {{\n{body}    }}\n'


def ops(*lines, order):
    return "\n        ".join([*lines, f"uniform token[] xformOpOrder = {order}"])


def write_stage(tmp_path, b_text):
    """``/World/A`` (a unit cube at the origin) and ``b_text`` (``/World/B``), time codes 0 and 1."""
    path = tmp_path / "hostile.usda"
    path.write_text('#usda 1.0\n(\n    startTimeCode = 0\n    endTimeCode = 1\n)\ndef Xform "World"\n{\n'
                    + cube("A") + b_text + "}\n")
    return path


def check(path, capsys, *argv):
    rc = cli.main(["check", str(path), "--device", DEFAULT_DEVICE, *argv])
    return rc, capsys.readouterr()


TRANSLATE = '["xformOp:translate"]'
SCALE = '["xformOp:scale"]'

CASES = {
    "translate_string": (cube("B", xform=ops('string xformOp:translate = "abc"', order=TRANSLATE)),
                         "xformOp:translate at time 0", "'abc' (string)"),
    "translate_int": (cube("B", xform=ops("int xformOp:translate = 3", order=TRANSLATE)),
                      "xformOp:translate at time 0", "3 (int)"),
    "translate_nan": (cube("B", xform=ops("double3 xformOp:translate = (nan, 0, 0)", order=TRANSLATE)),
                      "xformOp:translate at time 0", "not finite"),
    "translate_nan_later": (cube("B", xform=ops("double3 xformOp:translate.timeSamples = {0: (0.3, 0, 0), "
                                                "1: (nan, 0, 0)}", order=TRANSLATE)),
                            "xformOp:translate at time 1", "not finite"),
    "indices_float": (cube("B", indices=f"float[] faceVertexIndices = {INDICES}"),
                      "faceVertexIndices at time 0", "not an integer array"),
    "counts_float": (cube("B", counts="float[] faceVertexCounts = [4, 4, 4, 4, 4, 4]"),
                     "faceVertexCounts at time 0", "not an integer array"),
    "counts_negative": (cube("B", counts="int[] faceVertexCounts = [4, 4, 4, 4, 4, -4]"),
                        "faceVertexCounts[5] = -4", "at least 3"),
    "points_flat": (cube("B", points=f"float[] points = {FLAT}"), "points at time 0", "not an array of 3-vectors"),
    "points_int": (cube("B", points=f"int[] points = {FLAT}"), "points at time 0", "not an array of 3-vectors"),
    "scale_zero": (cube("B", xform=ops("float3 xformOp:scale = (1, 0, 1)", order=SCALE)),
                   "xformOp:scale at time 0", "zero scale"),
    "scale_zero_later": (cube("B", xform=ops("float3 xformOp:scale.timeSamples = {0: (1, 1, 1), 1: (0, 0, 0)}",
                                             order=SCALE)), "xformOp:scale at time 1", "zero scale"),
    "mirror_comes": (cube("B", xform=ops("float3 xformOp:scale.timeSamples = {0: (1, 1, 1), 1: (-1, 1, 1)}",
                                         order=SCALE)), "at time 1 mirrors", "inside out"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_hostile_input_is_one_line_naming_file_prim_attribute_and_time(tmp_path, capsys, case):
    text, where, what = CASES[case]
    path = write_stage(tmp_path, text)
    rc, out = check(path, capsys)
    lines = out.err.strip().splitlines()
    assert rc == 2, out.err
    assert len(lines) == 1 and out.out == "", out
    assert lines[0].startswith(f"warp-ccd check: error: {path}: prim /World/B: "), lines
    assert where in lines[0] and what in lines[0], lines


@pytest.mark.parametrize("case", ["translate_string", "points_flat", "indices_float", "scale_zero"])
def test_hostile_input_to_the_importer_names_the_prim(tmp_path, case):
    text, where, what = CASES[case]
    with pytest.raises(ValueError, match=re.escape(f"prim /World/B: {where}")):
        UsdMeshImport(str(write_stage(tmp_path, text)), device=DEFAULT_DEVICE)


def test_a_constant_mirror_is_valid_and_wound_back(tmp_path, capsys):
    """A mirror (a negative scale at every time code) is a valid transform: the mirrored cube,
    wound back, penetrates the other as the same cube moved there does (same verdict and depth)."""
    mirrored = cube("B", xform=ops("double3 xformOp:translate = (0.3, 0, 0)", "float3 xformOp:scale = (-1, 1, 1)",
                                   order='["xformOp:translate", "xformOp:scale"]'))
    moved = cube("B", xform=ops("double3 xformOp:translate = (-0.7, 0, 0)", order=TRANSLATE))
    depths = []
    for text in (mirrored, moved):
        path = write_stage(tmp_path, text)
        rc, out = check(path, capsys, "--report", str(tmp_path / "r.json"))
        assert rc == 1, out.err
        report = json.loads((tmp_path / "r.json").read_text())
        depths.append(max(p["max_depth"] for p in report["pairs"]))
    assert depths[0] == pytest.approx(depths[1], rel=1e-9) and depths[0] > 0
