"""The exact continuous-collision reference (tests/ccd_reference.py) on queries whose answers are known."""

from fractions import Fraction

import numpy as np
import pytest
from ccd_cases import D, crafted_cases, random_queries
from ccd_reference import reference_ccd

CRAFTED = crafted_cases()


@pytest.mark.parametrize("case", CRAFTED, ids=[f"{c.kind}: {c.name}" for c in CRAFTED])
def test_crafted_answers(case):
    ref = reference_ccd(case.kind, case.x0, case.x1, case.min_distance)
    assert ref.verdict == ("hit" if case.hit else "no_hit"), ref
    if case.hit:
        toi = Fraction(case.toi)
        # expected tois that are not dyadic ((1 - d) / 3) are rounded to the nearest float
        slack = Fraction(0) if toi.denominator & (toi.denominator - 1) == 0 else Fraction(2.0**-50)
        assert ref.lo - slack <= toi <= ref.hi + slack, (ref, case.toi)


@pytest.mark.parametrize("case", [c for c in CRAFTED if c.min_distance == 0.0 and "+" not in c.name],
                         ids=lambda c: f"{c.kind}: {c.name}")
def test_box_method_agrees_on_dyadic_contacts(case):
    """At d = 0 the box method finds the crafted (dyadic) contacts exactly, and never contradicts."""
    alg = reference_ccd(case.kind, case.x0, case.x1, method="algebraic")
    box = reference_ccd(case.kind, case.x0, case.x1, method="boxes", max_boxes=3000)
    if case.hit:
        assert box.hit and box.hi == Fraction(case.toi) and alg.lo <= box.hi, (alg, box)
    else:
        assert box.verdict in ("no_hit", "inconclusive"), box


def _tilting(x_offset):
    """A vertex meeting a tilting triangle's plane at t = 1/sqrt(2): the plane at height t (y + 10) / 10 over
    (0, y), the vertex at height 1 and y = 20 t - 10 (inside the triangle at x = 0, outside at x = 5)."""
    x0 = np.array([[x_offset, -10, 1], [-10, -10, 0], [10, -10, 0], [0, 10, 0]], np.float64)
    x1 = np.array([[x_offset, 10, 1], [-10, -10, 0], [10, -10, 0], [0, 10, 2]], np.float64)
    return x0, x1


def test_irrational_root():
    ref = reference_ccd("vertex_face", *_tilting(0.0))
    assert ref.hit and ref.lo**2 <= Fraction(1, 2) <= ref.hi**2 and ref.hi - ref.lo <= Fraction(1, 2**60), ref
    assert reference_ccd("vertex_face", *_tilting(5.0)).verdict == "no_hit"
    box = reference_ccd("vertex_face", *_tilting(0.0), min_distance=2.0**-30)
    assert box.hit and box.hi**2 <= Fraction(1, 2), box  # within d earlier than the contact


def test_edge_edge_irrational_root():
    """Edge a, from (0, -10, 0) to (0, 10, 2t), tilts in the plane x = 0 (height t (y + 10) / 10 at y); edge b,
    along x at height 1 and y = 20 t - 10, crosses that plane where a's height is 2 t^2: they meet at 1/sqrt(2)."""
    x0 = np.array([[0, -10, 0], [0, 10, 0], [-1, -10, 1], [1, -10, 1]], np.float64)
    x1 = np.array([[0, -10, 0], [0, 10, 2], [-1, 10, 1], [1, 10, 1]], np.float64)
    ref = reference_ccd("edge_edge", x0, x1)
    assert ref.hit and ref.lo**2 <= Fraction(1, 2) <= ref.hi**2, ref
    x0[2:, 0] += 2.0  # edge b beside the plane x = 0
    x1[2:, 0] += 2.0
    assert reference_ccd("edge_edge", x0, x1).verdict == "no_hit"


def _permuted(kind, x0, x1, k):
    """The same query with the triangle's vertices rotated / reversed, or the edges and their ends swapped."""
    if kind == "vertex_face":
        order = [[0, 1, 2, 3], [0, 2, 3, 1], [0, 3, 2, 1]][k % 3]
    else:
        order = [[0, 1, 2, 3], [2, 3, 0, 1], [1, 0, 3, 2]][k % 3]
    return x0[order], x1[order]


@pytest.mark.parametrize("kind", ["vertex_face", "edge_edge"])
def test_random_invariances(kind):
    """Exact answers do not depend on the order of the vertices or on an exact translation; nearly all random
    queries are conclusive at d = 0."""
    x0, x1 = random_queries(kind, 80, seed=7)
    shift = np.array([0.5, -2.0, 4.0])
    conclusive = 0
    for i in range(len(x0)):
        ref = reference_ccd(kind, x0[i], x1[i])
        conclusive += ref.conclusive
        other = reference_ccd(kind, *_permuted(kind, x0[i], x1[i], i + 1))
        moved = reference_ccd(kind, x0[i] + shift, x1[i] + shift)
        if np.array_equal(x0[i] + shift - shift, x0[i]) and np.array_equal(x1[i] + shift - shift, x1[i]):
            assert moved.verdict == ref.verdict and moved.lo == ref.lo, (i, ref, moved)
        assert other.verdict == ref.verdict, (i, ref, other)
        if ref.hit:
            assert max(ref.lo, other.lo) <= min(ref.hi, other.hi), (i, ref, other)
    assert conclusive == len(x0)


@pytest.mark.parametrize("kind", ["vertex_face", "edge_edge"])
def test_min_distance_monotone(kind):
    """A larger d hits whatever a smaller one hits, no later; d = 0 hits imply d > 0 hits."""
    x0, x1 = random_queries(kind, 16, seed=11, min_distance=D)
    for i in range(len(x0)):
        exact = reference_ccd(kind, x0[i], x1[i])
        small = reference_ccd(kind, x0[i], x1[i], D / 2, max_boxes=5000)
        large = reference_ccd(kind, x0[i], x1[i], 2 * D, max_boxes=5000)
        if exact.hit and small.conclusive:
            assert small.hit and small.lo <= exact.hi, (i, exact, small)
        if small.hit and large.conclusive:
            assert large.hit and large.lo <= small.hi, (i, small, large)
        if large.verdict == "no_hit":
            assert small.verdict != "hit" and exact.verdict != "hit", (i, exact, small, large)


def test_rejects_bad_input():
    x = np.zeros((4, 3))
    with pytest.raises(ValueError):
        reference_ccd("vertex_edge", x, x)
    with pytest.raises(ValueError):
        reference_ccd("edge_edge", x, x, -1.0)
    with pytest.raises(ValueError):
        reference_ccd("edge_edge", np.zeros((3, 3)), x)
    bad = x.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError):
        reference_ccd("edge_edge", bad, x)
