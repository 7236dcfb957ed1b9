"""Continuous collision of vertex-face and edge-edge pairs (``warp_ccd.ccd_queries``) against the exact
reference (tests/ccd_reference.py), the crafted cases (tests/ccd_cases.py) and Tight Inclusion (ipctk).

Conservative means: no missed collision (the reference proves a contact, the query reports none) and no late
toi (a reported toi above the reference's certified upper bound). False positives are allowed within the
tolerance; they are counted and compared with ipctk's on the same queries.
"""

from __future__ import annotations

import functools
from fractions import Fraction

import numpy as np
import pytest
from ccd_cases import D, crafted_cases, random_queries
from ccd_reference import reference_ccd

import warp_ccd

KINDS = ("vertex_face", "edge_edge")
RANDOM_SETS = [(kind, d, n, variant) for kind in KINDS
               for d, n, variant in ((0.0, 400, "cube"), (D, 100, "cube"), (0.0, 60, "planar"), (0.0, 100, "far"))]
"""(kind, min_distance, number of queries, variant) of the seeded random sets: around the unit cube, the same
flattened into the plane z = 0.5 (always coplanar: the exact reference's hardest family), and moved by 1e4."""
SEED = 2026
EARLY_DISTANCE = 1e-5
"""A reported toi may be early, but not before the pair first comes within ``min_distance + EARLY_DISTANCE``
(ten times the default tolerance): an answer earlier than that is a false contact at that time."""


def _ids(sets):
    return [f"{kind}-d{d:g}-{variant}" for kind, d, _, variant in sets]


@functools.lru_cache(maxsize=None)
def _random_set(kind: str, d: float, n: int, variant: str):
    """Queries and the reference's verdicts (computed once per session)."""
    x0, x1 = random_queries(kind, n, seed=SEED + KINDS.index(kind) + 10 * len(variant), min_distance=d)
    if variant == "planar":
        x0[..., 2] = x1[..., 2] = 0.5
    elif variant == "far":
        x0, x1 = x0 + 1e4, x1 + 1e4
    refs = [reference_ccd(kind, x0[i], x1[i], d, max_boxes=5000) for i in range(n)]
    return x0, x1, refs


def _late(toi: float, ref) -> bool:
    return toi > 1.0 or Fraction(toi) > ref.hi


def _too_early(kind, x0, x1, d, toi, ref) -> bool:
    """Whether ``toi`` comes before the pair is first within ``d + EARLY_DISTANCE`` (``ref``: the reference's
    hit). The distance changes at most 2 max|velocity| per unit time, so nearby answers need no search."""
    speed = 2 * float(np.max(np.abs(np.asarray(x1, np.float64) - np.asarray(x0, np.float64))))
    if (float(ref.hi) - toi) * speed <= 0.5 * EARLY_DISTANCE:
        return False
    near = reference_ccd(kind, x0, x1, d + EARLY_DISTANCE, max_boxes=5000)
    return near.lo is not None and Fraction(toi) < near.lo


def _score(hit, toi, refs):
    """Counts against the reference, and the missed / late queries."""
    missed = [i for i, r in enumerate(refs) if r.hit and not hit[i]]
    late = [i for i, r in enumerate(refs) if r.hit and hit[i] and _late(toi[i], r)]
    false_pos = [i for i, r in enumerate(refs) if r.verdict == "no_hit" and hit[i]]
    return missed, late, false_pos


def _describe(kind, x0, x1, d, refs, hit, toi, rows):
    return "\n".join(f"{kind} d={d!r} x0={x0[i].tolist()!r} x1={x1[i].tolist()!r} expected={refs[i]} "
                     f"got hit={bool(hit[i])} toi={toi[i]!r}" for i in rows[:5])


# --- crafted cases --------------------------------------------------------------------------------------------------

CRAFTED = crafted_cases()


@pytest.mark.parametrize("kind", KINDS)
def test_crafted_cases(device, kind):
    cases = [c for c in CRAFTED if c.kind == kind]
    failures = []
    for d in sorted({c.min_distance for c in cases}):
        group = [c for c in cases if c.min_distance == d]
        x0 = np.stack([c.x0 for c in group])
        x1 = np.stack([c.x1 for c in group])
        hit, toi = warp_ccd.ccd_queries(kind, x0, x1, min_distance=d, device=device)
        assert hit.shape == (len(group),) and hit.dtype == bool and toi.dtype == np.float64
        for c, h, t in zip(group, hit, toi):
            if bool(h) != c.hit:
                failures.append(f"{c.name}: expected hit={c.hit}, got hit={bool(h)} toi={t!r}")
            elif c.hit and not t <= np.nextafter(c.toi, 2.0):  # (1 - d) / 3 is rounded
                failures.append(f"{c.name}: late toi: expected {c.toi!r}, got {t!r}")
            elif c.hit and _too_early(kind, c.x0, c.x1, d, t, reference_ccd(kind, c.x0, c.x1, d)):
                failures.append(f"{c.name}: early toi: expected {c.toi!r}, got {t!r} (not within "
                                f"d + {EARLY_DISTANCE:g} then)")
            elif not c.hit and t != np.inf:
                failures.append(f"{c.name}: no hit but toi {t!r}")
    assert not failures, f"{len(failures)} of {len(cases)} crafted {kind} cases:\n" + "\n".join(failures)


# --- random queries against the exact reference --------------------------------------------------------------------


@pytest.mark.parametrize("kind, d, n, variant", RANDOM_SETS, ids=_ids(RANDOM_SETS))
def test_random_against_reference(device, kind, d, n, variant):
    x0, x1, refs = _random_set(kind, d, n, variant)
    hit, toi = warp_ccd.ccd_queries(kind, x0, x1, min_distance=d, device=device)
    conclusive = sum(r.conclusive for r in refs)
    missed, late, false_pos = _score(hit, toi, refs)
    early = [i for i, r in enumerate(refs) if r.hit and hit[i] and _too_early(kind, x0[i], x1[i], d, toi[i], r)]
    counts = (f"{conclusive} of {n} conclusive ({sum(r.hit for r in refs)} hits), {len(missed)} missed, "
              f"{len(late)} late, {len(early)} too early, {len(false_pos)} false positives")
    assert not early, f"tois too early: {counts}\n" + _describe(kind, x0, x1, d, refs, hit, toi, early)
    assert not missed, f"missed collisions: {counts}\n" + _describe(kind, x0, x1, d, refs, hit, toi, missed)
    assert not late, f"late tois: {counts}\n" + _describe(kind, x0, x1, d, refs, hit, toi, late)
    assert conclusive >= 0.9 * n, counts
    assert np.all((toi >= 0) & ((toi <= 1) | (toi == np.inf))) and np.array_equal(hit, toi <= 1), counts


@pytest.mark.parametrize("kind", KINDS)
def test_float32_same_as_float64(device, kind):
    x0, x1 = random_queries(kind, 200, seed=SEED + 7)
    x0, x1 = x0.astype(np.float32), x1.astype(np.float32)
    for d in (0.0, D):
        h32, t32 = warp_ccd.ccd_queries(kind, x0, x1, min_distance=d, device=device)
        h64, t64 = warp_ccd.ccd_queries(kind, x0.astype(np.float64), x1.astype(np.float64), min_distance=d,
                                        device=device)
        assert np.array_equal(h32, h64) and np.array_equal(t32, t64), (d, np.nonzero(t32 != t64)[0][:5])


# --- Tight Inclusion (ipctk) --------------------------------------------------------------------------------------


def _ipctk(kind, x0, x1, d):
    ipctk = pytest.importorskip("ipctk")
    ccd = ipctk.tight_inclusion.point_triangle_ccd if kind == "vertex_face" else ipctk.tight_inclusion.edge_edge_ccd
    hit = np.zeros(len(x0), bool)
    toi = np.full(len(x0), np.inf)
    for i in range(len(x0)):
        try:
            h, t, _ = ccd(*x0[i], *x1[i], min_distance=d, tolerance=1e-6, max_iterations=-1)
        except MemoryError:  # unbounded iterations can exhaust memory on degenerate queries: bound them
            h, t, _ = ccd(*x0[i], *x1[i], min_distance=d, tolerance=1e-6, max_iterations=10**6)
        hit[i], toi[i] = h, (t if h else np.inf)
    return hit, toi


IPCTK_SETS = [s for s in RANDOM_SETS if s[3] != "planar"]
"""The planar sets are left out: unbounded Tight Inclusion takes minutes on always-coplanar queries."""


@pytest.mark.parametrize("kind, d, n, variant", IPCTK_SETS, ids=_ids(IPCTK_SETS))
def test_against_ipctk(device, kind, d, n, variant):
    x0, x1, refs = _random_set(kind, d, n, variant)
    ip_hit, ip_toi = _ipctk(kind, x0, x1, d)
    hit, toi = warp_ccd.ccd_queries(kind, x0, x1, min_distance=d, device=device)
    confirmed = [i for i, r in enumerate(refs) if ip_hit[i] and r.hit]
    behind = [i for i in confirmed if not hit[i] or _late(toi[i], refs[i])]
    ours_fp = _score(hit, toi, refs)[2]
    ip_missed, ip_late, ip_fp = _score(ip_hit, ip_toi, refs)
    counts = (f"{len(confirmed)} ipctk hits confirmed; false positives: ours {len(ours_fp)}, ipctk {len(ip_fp)}; "
              f"ipctk missed {len(ip_missed)}, late {len(ip_late)}")
    assert not behind, f"confirmed ipctk hits we miss or report late: {counts}\n" + _describe(
        kind, x0, x1, d, refs, hit, toi, behind)
    assert len(ours_fp) <= len(ip_fp), f"{counts}\n" + _describe(kind, x0, x1, d, refs, hit, toi, ours_fp)


# --- input checks -------------------------------------------------------------------------------------------------


def test_bad_input(device):
    x = np.random.default_rng(0).random((3, 4, 3))
    bad = [
        dict(kind="vertex_edge"),
        dict(x0=x[:, :3]),
        dict(x0=x.reshape(3, 12)),
        dict(x1=x[:2]),
        dict(min_distance=-1e-3),
        dict(min_distance=float("nan")),
    ]
    for value in (np.nan, np.inf, -np.inf):
        y = x.copy()
        y[1, 2, 0] = value
        bad += [dict(x0=y), dict(x1=y.astype(np.float32))]
    for change in bad:
        args = dict(kind="edge_edge", x0=x, x1=x, min_distance=0.0) | change
        with pytest.raises(ValueError):
            warp_ccd.ccd_queries(args.pop("kind"), args.pop("x0"), args.pop("x1"), device=device, **args)


@pytest.mark.parametrize("kind", KINDS)
def test_empty(device, kind):
    for dtype in (np.float32, np.float64):
        x = np.zeros((0, 4, 3), dtype)
        hit, toi = warp_ccd.ccd_queries(kind, x, x, min_distance=0.0, device=device)
        assert hit.shape == (0,) and toi.shape == (0,) and hit.dtype == bool and toi.dtype == np.float64


@pytest.mark.parametrize("scale, tolerance", [(1.0, 6.448096526425068e-17), (2.0**34, 1.1077745480978747e-06)])
def test_tolerance_below_float64_resolution_terminates(device, scale, tolerance):
    """A tolerance that asks for parameter widths below 2^-53 (tiny, or the default at coordinates
    near 1e10) once made the search revisit one box for ever: widths stop at 2^-53, where every box
    corner is exact, and the answer stays conservative. A face collapsed to a point, a vertex
    falling through it: it comes within d (infinity norm) at t = (1 - d) / 2."""
    x0 = np.array([[[0, 0, 1.0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]]) * scale
    x1 = np.array([[[0, 0, -1.0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]]) * scale
    d = 0.8373815668597853 * scale
    hit, toi = warp_ccd.ccd_queries("vertex_face", x0, x1, min_distance=d, tolerance=tolerance, device=device)
    assert hit.tolist() == [True]
    assert toi[0] <= (1 - d / scale) / 2 and toi[0] > (1 - d / scale) / 2 - 1e-3


def test_kind_must_be_a_name(device):
    x = np.zeros((1, 4, 3))
    with pytest.raises(ValueError, match="kind"):
        warp_ccd.ccd_queries(["vertex_face"], x, x, device=device)


@pytest.mark.parametrize("scale, refused", [(1e300, True), (1e39, True), (1e14, True), (1e6, False)])
def test_coordinates_the_precision_cannot_resolve_are_refused(device, scale, refused):
    """A vertex falling through a unit triangle's plane at ``t = 0.5``, the whole query scaled: at 1e300
    the answer was ``toi 0`` (the squares overflow); as ``collide()``, coordinates that float64 cannot
    resolve at the query's size (or beyond float32's range) are refused, naming the query; a far but
    resolvable query keeps its answer."""
    x0 = np.array([[[0.25, 0.25, 1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    x1 = x0.copy()
    x1[0, 0, 2] = -1.0
    if refused:  # the same query moved far from the origin at its size, or all of it scaled up
        x0f, x1f = (x0 * scale, x1 * scale) if scale > 1e38 else (x0 + scale, x1 + scale)
        with pytest.raises(ValueError, match=r"query 0: coordinates up to .* are beyond"):
            warp_ccd.ccd_queries("vertex_face", x0f, x1f, device=device)
    else:
        hit, toi = warp_ccd.ccd_queries("vertex_face", x0 * scale, x1 * scale, device=device)
        assert hit[0] and toi[0] <= 0.5 and toi[0] > 0.49
