"""The recorded scene results (``tests/data/scene_results.npz``, :mod:`scene_results`) judged by brute force.

:mod:`test_device_agreement` holds every device to the recorded results bit for bit; here the record
itself is held to independent references, so that devices agreeing with it agree on right answers.
The scenes are rebuilt (their world vertices are the same bits on every device) and, for every pair of
objects whose boxes widened by the tolerance overlap, every pair of triangles whose boxes do is decided
in float64 by :func:`oracles.touching_band`: pairs within ``eps / 4`` must touch, pairs ``4 eps`` apart
must not, in between either answer is right (``eps``: the tolerance times the longer triangle's longest
edge). Every other pair of triangles lies more than ``eps`` apart. Each recorded run (precision, scene,
option set) must then hold:

* triangle pairs: rows ``a < b``, sorted, unique; every pair that must touch recorded, none that must not;
* segments: both ends of every finite one on both triangles, within ``eps`` and two units in the last
  place of the stored coordinates (float32 coordinates near 1000 are 6e-5 apart);
* containment pairs ``(inner, outer)``: exactly the pairs whose surfaces are clearly apart and a vertex
  of ``inner`` lies inside ``outer`` (winding number in float64);
* flags: an object is colliding exactly where it is in a recorded triangle pair or containment pair.

Every pair of objects is covered, not a sample: about a second on the CPU.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from warp_ccd.geometry import TOLERANCE

import scene_results
from conftest import DEFAULT_DEVICE
from oracles import box_pairs_between, box_pairs_numpy, closed_triangle_distance, tolerance_length, touching_band

SEGMENT_ULPS = 2
"""How many units in the last place of its largest coordinate a stored segment end may lie beyond ``eps``."""


def winding_number(point: np.ndarray, tri: np.ndarray) -> float:
    """Winding number of ``point`` ``(3,)`` about the closed triangle mesh ``tri`` ``(m, 3, 3)``, float64: the
    sum of the triangles' solid angles (van Oosterom and Strackee) over ``4 pi``; +-1 inside, 0 outside."""
    r = tri - point
    n = np.linalg.norm(r, axis=2)
    a, b, c = r[:, 0], r[:, 1], r[:, 2]
    det = np.einsum("ij,ij->i", a, np.cross(b, c))
    den = (n[:, 0] * n[:, 1] * n[:, 2] + np.einsum("ij,ij->i", a, b) * n[:, 2]
           + np.einsum("ij,ij->i", b, c) * n[:, 0] + np.einsum("ij,ij->i", c, a) * n[:, 1])
    return float(np.arctan2(det, den).sum() / (2.0 * np.pi))


class SceneTruth:
    """The float64 reference of one scene.

    Attributes:
        num_objects: ``N``.
        tris: per object its world triangles, ``(m, 3, 3)`` float64.
        dtype: the scene's coordinate type (for the units in the last place of stored segments).
        rows: ``(K, 4)`` int64 candidate triangle pairs ``(obj_a, tri_a, obj_b, tri_b)``, ``a < b``:
            those whose boxes, widened by the largest ``eps`` of the scene, overlap.
        must_hit, must_miss: ``(K,)`` bool, :func:`oracles.touching_band` of the candidates.
        touching: object pairs ``(a, b)`` with a pair of triangles that must touch.
        unsure: object pairs with a pair of triangles in the band, and none that must touch.
        contains: ordered pairs ``(inner, outer)`` of objects whose surfaces are clearly apart (every
            candidate must miss) and a vertex of ``inner`` lies inside ``outer``.
    """

    def __init__(self, scene, precision: str):
        self.num_objects = scene.num_objects
        self.tris = [np.asarray(v, np.float64)[t] for v, t in scene.world_meshes()]
        self.dtype = np.float64 if precision == "float64" else np.float32
        edge = max(float(np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2).max()) for t in self.tris)
        margin = TOLERANCE * edge  # at least the eps of every pair of triangles
        lower = np.array([t.reshape(-1, 3).min(axis=0) for t in self.tris]) - margin
        upper = np.array([t.reshape(-1, 3).max(axis=0) for t in self.tris]) + margin
        rows, tri_a, tri_b = [], [], []
        objects = box_pairs_numpy(lower, upper).tolist()
        for a, b in objects:
            ta, tb = self.tris[a], self.tris[b]
            ij = box_pairs_between(ta.min(axis=1) - margin, ta.max(axis=1) + margin, tb.min(axis=1), tb.max(axis=1))
            rows.append(np.stack([np.full(len(ij), a), ij[:, 0], np.full(len(ij), b), ij[:, 1]], axis=1))
            tri_a.append(ta[ij[:, 0]])
            tri_b.append(tb[ij[:, 1]])
        self.rows = np.concatenate(rows).astype(np.int64)
        self.must_hit, self.must_miss = touching_band(np.concatenate(tri_a), np.concatenate(tri_b), TOLERANCE,
                                                      degenerate_slack=True)
        pair_of = [tuple(p) for p in self.rows[:, [0, 2]].tolist()]
        near = {p for p, miss in zip(pair_of, self.must_miss) if not miss}
        self.touching = {p for p, hit in zip(pair_of, self.must_hit) if hit}
        self.unsure = near - self.touching
        self.contains = set()
        for a, b in sorted(set(map(tuple, objects)) - near):
            for inner, outer in ((a, b), (b, a)):
                w = winding_number(self.tris[inner][0, 0], self.tris[outer])
                assert abs(w - round(w)) < 1e-6, f"winding number {w} of object {inner} in {outer}"
                if round(abs(w)) == 1:
                    self.contains.add((inner, outer))
        self.index = {r: k for k, r in enumerate(map(tuple, self.rows.tolist()))}


@functools.cache
def truths(precision: str) -> dict[str, SceneTruth]:
    scenes = scene_results.scenes(precision, DEFAULT_DEVICE)
    return {name: SceneTruth(scene, precision) for name, scene in scenes.items()}


@functools.cache
def recorded() -> dict:
    return scene_results.read_reference()


def run_of(precision: str, scene: str, options: str) -> dict:
    """``{field: array}`` of one recorded run (copies: a test may change them)."""
    prefix = f"{precision}/{scene}/{options}/"
    return {k[len(prefix):]: v.copy() for k, v in recorded().items() if k.startswith(prefix)}


def judge(truth: SceneTruth, run: dict) -> list[str]:
    """What is wrong with one recorded run (``{"triangle_pairs", "segments", "colliding",
    "containment_pairs": array}``) by the reference ``truth``: one line each, empty when nothing is."""
    problems = []
    rows = np.asarray(run["triangle_pairs"], np.int64)
    if rows.ndim != 2 or rows.shape[1] != 4:
        return [f"triangle_pairs: shape {rows.shape}, expected (M, 4)"]
    if len(rows) and not (rows[:, 0] < rows[:, 2]).all():
        problems.append(f"triangle_pairs: rows with obj_a >= obj_b, e.g. {rows[rows[:, 0] >= rows[:, 2]][0].tolist()}")
    if (np.lexsort(rows.T[::-1]) != np.arange(len(rows))).any():
        problems.append("triangle_pairs: rows not sorted")
    if len(np.unique(rows, axis=0)) != len(rows):
        problems.append("triangle_pairs: rows repeated")
    found = np.array([truth.index.get(r, -1) for r in map(tuple, rows.tolist())], np.int64)
    if (found < 0).any():
        problems.append(f"triangle_pairs: {int((found < 0).sum())} rows whose triangles are more than eps apart, "
                        f"e.g. {rows[found < 0][0].tolist()}")
    listed = np.zeros(len(truth.rows), bool)
    listed[found[found >= 0]] = True
    missed = np.nonzero(truth.must_hit & ~listed)[0]
    if len(missed):
        problems.append(f"triangle_pairs: {len(missed)} touching pairs missing, e.g. {truth.rows[missed[0]].tolist()}")
    false = np.nonzero(truth.must_miss & listed)[0]
    if len(false):
        problems.append(f"triangle_pairs: {len(false)} pairs apart recorded, e.g. {truth.rows[false[0]].tolist()}")

    seg = np.asarray(run["segments"], np.float64)
    if seg.shape != (len(rows), 2, 3):
        problems.append(f"segments: shape {seg.shape}, expected ({len(rows)}, 2, 3)")
    else:
        ok = np.isfinite(seg).all(axis=(1, 2)) & (found >= 0)
        seg, rows_ok = seg[ok], rows[ok]
        tri_a = np.array([truth.tris[a][i] for a, i, _, _ in rows_ok.tolist()]).reshape(-1, 3, 3)
        tri_b = np.array([truth.tris[b][j] for _, _, b, j in rows_ok.tolist()]).reshape(-1, 3, 3)
        eps = tolerance_length(tri_a, tri_b, TOLERANCE)
        for end in range(2):
            p = seg[:, end]
            ulp = np.spacing(np.abs(p).max(axis=1).astype(truth.dtype)).astype(np.float64)
            point = np.repeat(p[:, None], 3, axis=1)  # a point, as a degenerate triangle
            off = np.maximum(closed_triangle_distance(point, tri_a), closed_triangle_distance(point, tri_b))
            bad = np.nonzero(off > eps + SEGMENT_ULPS * ulp)[0]
            if len(bad):
                problems.append(f"segments: {len(bad)} ends off their triangles, e.g. of row "
                                f"{rows_ok[bad[0]].tolist()} by {off[bad[0]]:.3g} (eps {eps[bad[0]]:.3g})")

    contained = np.asarray(run["containment_pairs"], np.int64).reshape(-1, 2)
    got = set(map(tuple, contained.tolist()))
    lost = truth.contains - got
    if lost:
        problems.append(f"containment_pairs: {len(lost)} missing, e.g. {sorted(lost)[0]}")
    wrong = {(i, o) for i, o in got - truth.contains if (min(i, o), max(i, o)) not in truth.unsure}
    if wrong:
        problems.append(f"containment_pairs: {len(wrong)} not inside, e.g. {sorted(wrong)[0]}")

    flags = np.zeros(truth.num_objects, bool)
    flags[rows[:, [0, 2]].ravel()] = True
    flags[contained.ravel()] = True
    colliding = np.asarray(run["colliding"], bool)
    if colliding.shape != flags.shape or (colliding != flags).any():
        differ = np.nonzero(colliding != flags)[0] if colliding.shape == flags.shape else []
        problems.append(f"colliding: differs from the recorded pairs for objects {list(differ)[:8]}")
    return problems


@pytest.mark.parametrize("precision", scene_results.PRECISIONS)
def test_recorded_scene_results_are_right(precision):
    scene_names = list(truths(precision))
    assert scene_names and sorted(f"{precision}/{s}/{o}" for s in scene_names for o in scene_results.OPTIONS) == \
        sorted({k.rsplit("/", 1)[0] for k in recorded() if k.startswith(f"{precision}/")})
    problems = []
    for scene, truth in truths(precision).items():
        assert truth.must_hit.any() and truth.must_miss.any()  # both answers are judged
        for options in scene_results.OPTIONS:
            problems += [f"{precision}/{scene}/{options}: {p}" for p in judge(truth, run_of(precision, scene, options))]
    assert not problems, "\n".join(problems)
    assert any(t.contains for t in truths(precision).values())  # containment is judged too


def _drop_touching_row(run, truth):
    run["triangle_pairs"] = run["triangle_pairs"][1:]
    run["segments"] = run["segments"][1:]


def _move_row_to_a_far_triangle(run, truth):
    a, i, b, j = run["triangle_pairs"][0].tolist()
    centre = truth.tris[a][i].mean(axis=0)
    far = int(np.argmax(np.linalg.norm(truth.tris[b].mean(axis=1) - centre, axis=1)))
    run["triangle_pairs"][0, 3] = far


def _shift_a_segment_end(run, truth):
    a, i, b, j = run["triangle_pairs"][0].tolist()
    size = np.linalg.norm(truth.tris[a][i][1] - truth.tris[a][i][0])
    run["segments"][0, 1] += 0.01 * size


def _drop_containment(run, truth):
    run["containment_pairs"] = run["containment_pairs"][1:]


def _clear_a_flag(run, truth):
    run["colliding"][run["triangle_pairs"][0, 0]] = False


@pytest.mark.parametrize("perturb, words", [
    (_drop_touching_row, "touching pairs missing"),
    (_move_row_to_a_far_triangle, "more than eps apart"),
    (_shift_a_segment_end, "ends off their triangles"),
    (_drop_containment, "containment_pairs: 1 missing"),
    (_clear_a_flag, "colliding: differs"),
])
@pytest.mark.parametrize("precision", scene_results.PRECISIONS)
def test_a_wrong_record_is_caught(precision, perturb, words):
    """The judgement fails on a record changed in memory, one way at a time."""
    truth = truths(precision)["far_spheres_and_cubes"]
    run = run_of(precision, "far_spheres_and_cubes", "default")
    assert judge(truth, run) == []
    perturb(run, truth)
    problems = judge(truth, run)
    assert any(words in p for p in problems), problems
