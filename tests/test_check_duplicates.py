"""``check --duplicates``: coincident meshes. ``/World/Part`` and ``/World/Copy/Part`` (a copy placed
through another hierarchy) sit on each other at time codes 0 and 1; at 2 the copy is lifted by 0.5 into
the original (penetrating). An exact copy, one with its triangles shuffled and its vertices renumbered,
and one turned half a turn (its triangles land on the original's) are duplicates at 0 and 1, not
penetrating; a copy moved by 1e-3 of its size, or turned a quarter turn (the same box, other
triangles), is not. The report's section and rows (schema-valid), the summary, the overlay's colour, the
exit status; without ``--duplicates`` nothing changes. And :func:`~warp_ccd._src.check.duplicates.coincident`
itself on triangle soups: shuffled, wound the other way, a few ulps apart; a moved, replaced or
missing triangle."""

import itertools
import json

import numpy as np
import pytest

from warp_ccd._src.check.duplicates import COLOR_DUPLICATE, coincident
from warp_ccd._src.check.overlay import COLOR_PENETRATING
from warp_ccd._src.cli import commands as cli
from warp_ccd.usd import check_usd, report_schema

pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom  # noqa: E402
from usd_stages import DUPLICATE_CASES, duplicate_stage  # noqa: E402

PAIR = ("/World/Copy/Part", "/World/Part")
COINCIDE = {"exact": True, "reordered": True, "half_turn": True, "offset": False, "quarter_turn": False}


@pytest.fixture(scope="module")
def stage_paths(tmp_path_factory):
    folder = tmp_path_factory.mktemp("duplicates")
    for case in DUPLICATE_CASES:
        duplicate_stage(case, folder / f"{case}.usda")
    return {case: str(folder / f"{case}.usda") for case in DUPLICATE_CASES}


def names(report, pairs):
    return [tuple(sorted((report.object_path[a], report.object_path[b]))) for a, b in np.asarray(pairs).tolist()]


@pytest.mark.parametrize("case", DUPLICATE_CASES)
def test_duplicates_frame_by_frame(stage_paths, device, case):
    report = check_usd(stage_paths[case], device=device, duplicates=True)
    plain = check_usd(stage_paths[case], device=device)
    assert all(f.duplicates is None for f in plain.frames)
    assert [names(plain, f.object_pairs) for f in plain.frames] == [[PAIR]] * 3  # penetrating without the option
    if COINCIDE[case]:
        assert [names(report, f.duplicates) for f in report.frames] == [[PAIR], [PAIR], []]
        # Left out of the collisions at 0 and 1 (touching rows too), penetrating at 2 as before.
        assert [len(f.triangle_pairs) for f in report.frames[:2]] == [0, 0]
        assert [f.num_touching for f in report.frames[:2]] == [0, 0]
        np.testing.assert_array_equal(report.frames[2].triangle_pairs, plain.frames[2].triangle_pairs)
        assert report.duplicated and report.findings == "penetrating"
        first = check_usd(stage_paths[case], frames=slice(0, 1), device=device, duplicates=True)
        assert first.findings == "duplicates" and not first.penetrating and not first.touching
    else:
        assert [len(f.duplicates) for f in report.frames] == [0, 0, 0]
        for f, g in zip(report.frames, plain.frames):
            np.testing.assert_array_equal(f.triangle_pairs, g.triangle_pairs)
        assert not report.duplicated and report.findings == "penetrating"


def test_no_duplicates_without_the_option(stage_paths, device):
    report = check_usd(stage_paths["exact"], frames=slice(0, 1), device=device)
    assert report.findings == "penetrating" and not report.duplicated
    data = report.to_json()
    assert "duplicates" not in data and "duplicated" not in data and "duplicates" not in data["frames"][0]


def test_a_duplicate_is_no_soft_clash(stage_paths, device):
    report = check_usd(stage_paths["exact"], frames=slice(0, 1), device=device, duplicates=True, clearance=0.1)
    assert all(len(f.soft_clashes.object_pairs) == 0 for f in report.frames)
    assert report.findings == "duplicates"


def test_command_line_report_summary_and_overlay(stage_paths, device, tmp_path, capsys):
    jsonschema = pytest.importorskip("jsonschema", reason="jsonschema (a test extra) is not installed")

    src = stage_paths["reordered"]
    report_path, overlay = tmp_path / "r.json", tmp_path / "over.usda"
    rc = cli.main(["check", src, "--device", device, "--duplicates", "--report", str(report_path),
                   "--usd-out", str(overlay)])
    out = capsys.readouterr()
    assert rc == 1, out.err
    assert "duplicates (coincident meshes, not reported as collisions): 1 prim pairs in 2 of 3 frames" in out.out
    line = next(x for x in out.out.splitlines() if "/World/Copy/Part" in x and "0..1" in x)
    assert "/World/Part" in line
    data = json.loads(report_path.read_text())
    jsonschema.validate(data, report_schema())
    assert data["findings"] == "penetrating" and data["duplicated"] is True
    (pair,) = data["duplicates"]["pairs"]
    assert {pair["a"], pair["b"]} == set(PAIR)
    assert (pair["frames"], pair["first"], pair["last"], pair["times"]) == (2, 0.0, 1.0, [0.0, 1.0])
    assert [len(f["duplicates"]) for f in data["frames"]] == [1, 1, 0]
    assert [f["pairs"] for f in data["frames"][:2]] == [[], []]
    assert data["duplicates"]["tolerance"] == 1e-6
    stage = Usd.Stage.Open(str(overlay))
    for path in PAIR:
        colour = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath(path)).GetPrimvar("displayColor")
        for tc in (0.0, 1.0):
            np.testing.assert_allclose(colour.Get(tc)[0], COLOR_DUPLICATE, atol=1e-6)
        np.testing.assert_allclose(colour.Get(2.0)[0], COLOR_PENETRATING, atol=1e-6)
    # The duplicate frames alone: the duplicates are the finding; without the option, a penetration.
    rc = cli.main(["check", src, "--device", device, "--duplicates", "--frames", "0:1", "--report", str(report_path)])
    assert rc == 1 and json.loads(report_path.read_text())["findings"] == "duplicates"
    rc = cli.main(["check", src, "--device", device, "--frames", "0:1", "--report", str(report_path)])
    assert rc == 1 and json.loads(report_path.read_text())["findings"] == "penetrating"
    capsys.readouterr()


def soup(m: int, seed: int = 0, dtype=np.float64):
    """``m`` random triangles in a unit box, vertices not shared: ``(vertices (3m, 3), triangles (m, 3))``."""
    rng = np.random.default_rng(seed)
    return rng.random((3 * m, 3)).astype(dtype), np.arange(3 * m).reshape(m, 3)


def shuffled(vertices, triangles, seed: int = 1):
    """The same triangles listed in another order, each one's vertices rotated or reversed, the vertices renumbered."""
    rng = np.random.default_rng(seed)
    tri = triangles[rng.permutation(len(triangles))]
    orders = np.array(list(itertools.permutations(range(3))))
    tri = np.take_along_axis(tri, orders[rng.integers(0, 6, len(tri))], axis=1)
    new_of_old = rng.permutation(len(vertices))
    out = np.empty_like(vertices)
    out[new_of_old] = vertices
    return out, new_of_old[tri]


def test_coincident_triangle_sets():
    v, t = soup(2000)
    assert coincident(v, t, *shuffled(v, t))
    # A few float32 ulps apart (copies placed through different transforms), shifted far from the origin.
    rng = np.random.default_rng(2)
    v32 = (v * 10.0 + 1e3).astype(np.float32)
    step = np.where(rng.random(v32.shape) < 0.5, np.inf, -np.inf).astype(np.float32)
    w = np.where(rng.random(v32.shape) < 0.5, np.nextafter(v32, step), v32)
    assert not np.array_equal(w, v32)
    assert coincident(v32, t, *shuffled(w, t))
    # Not: a triangle moved by 1e-3 of the size, replaced, missing; another mesh.
    moved = v.copy()
    moved[t[7]] += 1e-3
    assert not coincident(v, t, *shuffled(moved, t))
    replaced = v.copy()
    replaced[t[7]] = np.random.default_rng(3).random((3, 3))
    assert not coincident(v, t, replaced, t)
    assert not coincident(v, t, v, t[1:])
    assert not coincident(v, t, *soup(2000, seed=4))
    assert not coincident(v[:0], t[:0], v[:0], t[:0])


def test_near_ties_in_the_sort_are_matched():
    # Clusters of triangles whose sort keys tie (translates of one triangle along a line the sort
    # direction is blind to): a perturbation of an ulp reorders them, the window matches them again.
    from warp_ccd._src.check.duplicates import _SORT

    blind = np.cross(_SORT, [0.0, 0.0, 1.0])
    blind *= 1e-2 / np.linalg.norm(blind)
    rng = np.random.default_rng(5)
    clusters = []
    for c in range(4):
        base = rng.random((3, 3)) * 5.0
        clusters += [base + k * blind for k in range(3)]
    v = np.concatenate(clusters + [soup(200)[0] * 5.0])
    t = np.arange(len(v)).reshape(-1, 3)
    w = v * (1.0 + 1e-14 * rng.standard_normal(v.shape))
    v2, t2 = shuffled(w, t)
    canon = [np.sort(np.round(x[y] @ _SORT, 9).sum(axis=1)) for x, y in ((v, t), (v2, t2))]
    np.testing.assert_allclose(canon[0], canon[1], atol=1e-8)  # the same keys, up to the perturbation
    assert coincident(v, t, v2, t2)
    far = v.copy()
    far[:3] += blind * 0.5  # a triangle of a cluster moved to between two others: not in the set
    assert not coincident(v, t, far, t)
