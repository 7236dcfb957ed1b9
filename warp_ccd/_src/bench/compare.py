"""Comparing what two methods found: box pairs for equality, triangle pairs by classification.

Pairs from two broad phases on the same boxes, or from two pipelines that share their narrow
phase, must be equal as sets (:func:`compare_exact`). Triangle pairs from different narrow phases
need not be: each test calls near-touching pairs its own way (this package within a tolerance
relative to the triangles, Warp's built-in test with an absolute 1e-6 snap, FCL in float64 on its
own transformed vertices). So :func:`compare_triangle_pairs` sends every triangle pair that only
one method found to an arbiter independent of both, and sorts it into a class:

* ``intersecting``: Warp's float64 ``wp.intersect_tri_tri`` says the two triangles intersect after
  the pair is moved to its centroid and scaled so that its longest edge is :data:`ARBITER_EDGE`
  long (translation and uniform scaling change no intersection; at that size Warp's absolute snap
  is negligible), and still does with both triangles shrunk about their centroids by
  :data:`GRAZE_REL`.
* ``grazing``: intersecting, but no longer once shrunk: touching to within :data:`GRAZE_REL` of
  the triangles' size.
* ``near``: apart, by at most :data:`NEAR_REL` times the longest edge, or by at most Warp's snap
  distance ``WARP_SNAP_FACTOR * 1e-6 / |n|`` (``n`` the smaller unnormalised normal).
* ``apart``: further apart than that.

Triangle-level differences are counted, never fatal. Object pairs decide the verdict: an object
pair found by one method only is a *real* difference when one of its triangle pairs is
``intersecting`` (the other method missed a real contact) or ``apart`` (this method reported a
clearly separated pair); when all of them are ``grazing`` or ``near`` it is counted as explained.
The arbiter judges the scene's own float32 world vertices, promoted to float64.

The benchmarks judge this package, not its peers. A real difference is charged to the method the
arbiter finds wrong: to the reference (this package), a *mismatch* (the benchmark fails); to the
peer, a *peer error*, a finding reported in the table and the JSON. Box pairs are judged the same
way when :func:`compare_exact` is given the boxes' truth (:func:`box_overlap_truth`); without a
truth every difference is a mismatch (two methods of this package must agree exactly).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

from ..scene.scene import Scene
from .peers import scene_triangle_vertex_index

__all__ = [
    "ARBITER_EDGE",
    "GRAZE_REL",
    "NEAR_REL",
    "PairCheck",
    "box_overlap_truth",
    "classify_triangle_pairs",
    "compare_exact",
    "compare_triangle_pairs",
    "sorted_rows",
    "triangle_distance",
]

ARBITER_EDGE = 10.0
"""Longest edge of a pair once scaled for the arbiter (scene units are irrelevant there)."""

GRAZE_REL = 1.0e-2
"""Shrink of each triangle about its centroid, relative, that separates a grazing contact."""

NEAR_REL = 1.0e-2
"""Largest gap, relative to the longest edge of the pair, of a near-touching pair."""

WARP_SNAP = 1.0e-6
"""Warp's absolute snap of plane distances computed on the unnormalised normal."""

WARP_SNAP_FACTOR = 10.0
"""Safety factor on the gap that Warp's snap can hide (``WARP_SNAP / |n|``)."""

CLASSES = ("intersecting", "grazing", "near", "apart")


@wp.kernel
def _arbiter_kernel(
    tri_a: wp.array2d[wp.vec3d],
    tri_b: wp.array2d[wp.vec3d],
    # Outputs
    hit: wp.array[wp.int32],
):
    """One thread per pair ``k``: Warp's float64 Möller test of ``tri_a[k]`` and ``tri_b[k]``."""
    k = wp.tid()
    hit[k] = wp.intersect_tri_tri(tri_a[k, 0], tri_a[k, 1], tri_a[k, 2], tri_b[k, 0], tri_b[k, 1], tri_b[k, 2])


def sorted_rows(rows, width: int) -> np.ndarray:
    """Rows as int32 ``(K, width)`` sorted lexicographically; pairs (width 2) ordered ``a < b`` first."""
    r = np.asarray(rows, np.int64).reshape(-1, width)
    if width == 2:
        r = np.sort(r, axis=1)
    r = r[np.lexsort(r.T[::-1])] if len(r) else r
    return r.astype(np.int32)


def _row_keys(rows: np.ndarray) -> np.ndarray:
    """One int64 per row, equal exactly for equal rows."""
    if len(rows) == 0:
        return np.zeros(0, np.int64)
    _, inverse = np.unique(rows, axis=0, return_inverse=True)
    return inverse.reshape(-1).astype(np.int64)


def _object_pair_names(keys: np.ndarray, num_objects: int, limit: int) -> list:
    return [divmod(int(k), num_objects) for k in keys[:limit]]


@dataclass
class PairCheck:
    """What a comparison of two methods' pairs found.

    Attributes:
        reference, peer: method names.
        what: ``"box pairs"``, ``"triangle pairs"`` ...
        num_reference, num_peer: rows each found.
        num_common: rows both found.
        object_pairs: ``(reference, peer, common)`` object-pair counts (triangle comparisons only).
        classes: triangle pairs found by one method only, per ``"<method> only: <class>"``.
        explained: object pairs found by one method only whose triangle pairs all touch.
        mismatches: one line per real difference where the reference is wrong (or that no
            arbiter can charge to the peer); empty when the reference stands.
        peer_errors: one line per real difference where the peer is wrong (a finding).
    """

    reference: str
    peer: str
    what: str
    num_reference: int
    num_peer: int
    num_common: int
    object_pairs: tuple | None = None
    classes: dict = field(default_factory=dict)
    explained: int = 0
    mismatches: list = field(default_factory=list)
    peer_errors: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when the reference stands: no real difference is charged to it."""
        return not self.mismatches

    @property
    def peer_ok(self) -> bool:
        """True when no real difference is charged to the peer."""
        return not self.peer_errors

    def charge(self, wrong: str, line: str) -> None:
        """Records a real difference against method ``wrong`` (the reference or the peer)."""
        (self.mismatches if wrong == self.reference else self.peer_errors).append(line)

    def summary(self) -> str:
        """One line: counts, classes of differences, and the verdict."""
        verdict = "agree" if self.ok and self.peer_ok else f"MISMATCH ({len(self.mismatches)})"
        if self.ok and not self.peer_ok:
            verdict = f"{self.peer} WRONG ({len(self.peer_errors)}), {self.reference} stands"
        if self.object_pairs is None:
            text = f"{self.peer} vs {self.reference}: {self.what} {self.num_peer} vs {self.num_reference}"
            if self.num_peer != self.num_common or self.num_reference != self.num_common:
                text += f" ({self.num_reference - self.num_common} missing, {self.num_peer - self.num_common} extra)"
            return f"{text}: {verdict}"
        ref_obj, peer_obj, common_obj = self.object_pairs
        text = (f"{self.peer} vs {self.reference}: object pairs {peer_obj} vs {ref_obj} ({common_obj} common"
                f"{f', {self.explained} near-touching only' if self.explained else ''}), "
                f"triangle pairs {self.num_peer} vs {self.num_reference} ({self.num_common} common")
        diffs = [f"{k} {v}" for k, v in self.classes.items() if v]
        text += f"; {', '.join(diffs)})" if diffs else ")"
        return f"{text}: {verdict}"

    def to_dict(self) -> dict:
        """JSON-ready fields."""
        return {
            "reference": self.reference,
            "peer": self.peer,
            "what": self.what,
            "num_reference": self.num_reference,
            "num_peer": self.num_peer,
            "num_common": self.num_common,
            "object_pairs": list(self.object_pairs) if self.object_pairs is not None else None,
            "classes": dict(self.classes),
            "explained": self.explained,
            "ok": self.ok,
            "mismatches": list(self.mismatches),
            "peer_ok": self.peer_ok,
            "peer_errors": list(self.peer_errors),
        }


def box_overlap_truth(lower, upper):
    """The truth about box pairs: a function of ``(K, 2)`` rows giving ``(K,)`` bool, whether the
    closed boxes ``a`` and ``b`` of ``(N, 3)`` ``lower`` / ``upper`` overlap (numpy, exact)."""
    lo = np.asarray(lower.numpy() if isinstance(lower, wp.array) else lower).reshape(-1, 3)
    hi = np.asarray(upper.numpy() if isinstance(upper, wp.array) else upper).reshape(-1, 3)

    def truth(rows: np.ndarray) -> np.ndarray:
        a, b = rows[:, 0], rows[:, 1]
        inside = (a >= 0) & (b >= 0) & (a < len(lo)) & (b < len(lo)) & (a != b)
        a, b = np.where(inside, a, 0), np.where(inside, b, 0)
        return inside & np.all((lo[a] <= hi[b]) & (lo[b] <= hi[a]), axis=1)

    return truth


def compare_exact(reference: str, reference_rows, peer: str, peer_rows, what: str, width: int = 2,
                  max_listed: int = 5, truth=None) -> PairCheck:
    """Compares two sets of rows for equality (box pairs: rows are ordered ``a < b`` first).

    Args:
        reference, peer: method names.
        reference_rows, peer_rows: ``(K, width)`` int arrays, any order.
        what: what the rows are, for messages.
        width: columns per row.
        max_listed: rows named in the messages.
        truth: optional function of rows to bool (:func:`box_overlap_truth`): each row only one
            method has is charged to the method that is wrong about it. Without it, every
            difference is a mismatch.
    """
    ref = sorted_rows(reference_rows, width)
    got = sorted_rows(peer_rows, width)
    both = np.concatenate([ref, got])
    keys = _row_keys(both)
    kr, kg = keys[: len(ref)], keys[len(ref):]
    common = int(np.isin(kg, kr).sum())
    check = PairCheck(reference, peer, what, len(ref), len(got), common)
    missing = ref[~np.isin(kr, kg)]
    extra = got[~np.isin(kg, kr)]
    dup = len(got) - len(np.unique(kg))
    judged = truth is not None

    def charge(wrong: str, text: str, rows: np.ndarray | None = None) -> None:
        # Without a truth, every difference is the reference's: both methods are this package's.
        example = "" if rows is None else f", e.g. {rows[:max_listed].tolist()}"
        check.charge(wrong if judged else reference, text + example)

    real_missing = truth(missing) if judged else np.ones(len(missing), bool)
    real_extra = truth(extra) if judged else np.zeros(len(extra), bool)
    if real_missing.any():
        charge(peer, f"{peer} misses {real_missing.sum()} {what} of {reference}", missing[real_missing])
    if (~real_missing).any():
        charge(reference, f"{reference} reports {(~real_missing).sum()} {what} that are not true pairs",
               missing[~real_missing])
    if real_extra.any():
        charge(reference, f"{reference} misses {real_extra.sum()} {what} that {peer} finds", extra[real_extra])
    if (~real_extra).any():
        charge(peer, f"{peer} has {(~real_extra).sum()} {what} that {reference} has not", extra[~real_extra])
    if dup:
        charge(peer, f"{peer} reports {dup} duplicate {what}")
    return check


# ---------------------------------------------------------------------------------------------
# Triangle distance (float64, host)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


def _point_triangle_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Distance of points ``(P, 3)`` to triangles ``(a, b, c)`` (Ericson's closest-point regions)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    bp = p - b
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    cp = p - c
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4
    with np.errstate(divide="ignore", invalid="ignore"):
        regions = [
            ((d1 <= 0) & (d2 <= 0), a),
            ((d3 >= 0) & (d4 <= d3), b),
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + (d1 / (d1 - d3))[:, None] * ab),
            ((d6 >= 0) & (d5 <= d6), c),
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + (d2 / (d2 - d6))[:, None] * ac),
            ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
             b + ((d4 - d3) / ((d4 - d3) + (d5 - d6)))[:, None] * (c - b)),
        ]
        denom = 1.0 / (va + vb + vc)
        closest = a + ab * (vb * denom)[:, None] + ac * (vc * denom)[:, None]
    done = np.zeros(len(p), bool)
    for mask, q in regions:
        take = mask & ~done
        closest[take] = q[take]
        done |= take
    return np.linalg.norm(p - closest, axis=1)


def _segment_distance(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> np.ndarray:
    """Distance between segments ``p1 q1`` and ``p2 q2``, ``(P, 3)`` each (Ericson, non-degenerate)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = _dot(d1, d1), _dot(d2, d2), _dot(d2, r)
    c, b = _dot(d1, r), _dot(d1, d2)
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-300, np.clip((b * f - c * e) / denom, 0.0, 1.0), 0.0)
        t = (b * s + f) / e
        low, high = t < 0.0, t > 1.0
        s = np.where(low, np.clip(-c / a, 0.0, 1.0), np.where(high, np.clip((b - c) / a, 0.0, 1.0), s))
        t = np.clip(t, 0.0, 1.0)
    return np.linalg.norm(p1 + d1 * s[:, None] - (p2 + d2 * t[:, None]), axis=1)


def triangle_distance(tri_a: np.ndarray, tri_b: np.ndarray) -> np.ndarray:
    """Distance between triangles that do not intersect: the least of the 6 vertex-triangle and
    9 edge-edge distances (for intersecting triangles it is not 0 in general).

    Args:
        tri_a, tri_b: ``(P, 3, 3)`` float64 vertices.

    Returns:
        ``(P,)`` float64 distances (scene units).
    """
    a = np.asarray(tri_a, np.float64)
    b = np.asarray(tri_b, np.float64)
    dist = np.full(len(a), np.inf)
    for k in range(3):
        dist = np.minimum(dist, _point_triangle_distance(a[:, k], b[:, 0], b[:, 1], b[:, 2]))
        dist = np.minimum(dist, _point_triangle_distance(b[:, k], a[:, 0], a[:, 1], a[:, 2]))
    for i in range(3):
        for j in range(3):
            dist = np.minimum(dist, _segment_distance(a[:, i], a[:, (i + 1) % 3], b[:, j], b[:, (j + 1) % 3]))
    return dist


def _arbiter(tri_a: np.ndarray, tri_b: np.ndarray, device) -> np.ndarray:
    if len(tri_a) == 0:
        return np.zeros(0, bool)
    ta = wp.array(np.ascontiguousarray(tri_a), dtype=wp.vec3d, device=device)
    tb = wp.array(np.ascontiguousarray(tri_b), dtype=wp.vec3d, device=device)
    hit = wp.zeros(len(tri_a), dtype=wp.int32, device=device)
    wp.launch(_arbiter_kernel, dim=len(tri_a), inputs=[ta, tb], outputs=[hit], device=device)
    return hit.numpy().astype(bool)


def classify_triangle_pairs(tri_a: np.ndarray, tri_b: np.ndarray, device=None) -> np.ndarray:
    """Class of each triangle pair (see module docs).

    Args:
        tri_a, tri_b: ``(P, 3, 3)`` vertices (scene units), promoted to float64.
        device: Warp device of the arbiter's kernel.

    Returns:
        ``(P,)`` array of class names: ``intersecting``, ``grazing``, ``near`` or ``apart``.
    """
    a = np.asarray(tri_a, np.float64).reshape(-1, 3, 3)
    b = np.asarray(tri_b, np.float64).reshape(-1, 3, 3)
    out = np.empty(len(a), dtype=object)
    if len(a) == 0:
        return out
    edges = np.concatenate([np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2) for t in (a, b)], axis=1)
    longest = np.maximum(edges.max(axis=1), 1e-300)
    centre = np.concatenate([a, b], axis=1).mean(axis=1, keepdims=True)
    scale = (ARBITER_EDGE / longest)[:, None, None]
    sa, sb = (a - centre) * scale, (b - centre) * scale
    hit = _arbiter(sa, sb, device)
    shrink = 1.0 - GRAZE_REL
    ca, cb = sa.mean(axis=1, keepdims=True), sb.mean(axis=1, keepdims=True)
    deep = _arbiter(ca + (sa - ca) * shrink, cb + (sb - cb) * shrink, device)
    gap = triangle_distance(a, b)
    normal = np.minimum(*(np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1) for t in (a, b)))
    with np.errstate(divide="ignore"):
        snap = WARP_SNAP_FACTOR * WARP_SNAP / normal
    near = gap <= np.maximum(NEAR_REL * longest, snap)
    out[:] = np.where(hit, np.where(deep, "intersecting", "grazing"), np.where(near, "near", "apart"))
    return out


def compare_triangle_pairs(scene: Scene, reference: str, reference_rows, peer: str, peer_rows,
                           max_listed: int = 3) -> PairCheck:
    """Compares two methods' triangle pairs on the scene's current world vertices.

    Args:
        scene: the scene both methods ran on (its ``world_vertex`` as they saw it).
        reference, peer: method names.
        reference_rows, peer_rows: ``(M, 4)`` int rows ``(obj_a, tri_a, obj_b, tri_b)``.
        max_listed: object pairs named per mismatch line.

    Returns:
        A :class:`PairCheck` with object-pair counts, classes of the triangle-level differences
        and the real differences, each charged to the method the arbiter finds wrong (see module
        docs).
    """
    ref = sorted_rows(reference_rows, 4)
    got = sorted_rows(peer_rows, 4)
    tstart = scene.object_triangle_start_np.astype(np.int64)

    def global_keys(rows):
        ga = tstart[rows[:, 0]] + rows[:, 1]
        gb = tstart[rows[:, 2]] + rows[:, 3]
        return ga * max(scene.num_triangles, 1) + gb, ga, gb

    kr, ra, rb = global_keys(ref)
    kg, pa, pb = global_keys(got)
    only_ref = ~np.isin(kr, kg)
    only_peer = ~np.isin(kg, kr)
    obj_ref = np.unique(ref[:, [0, 2]], axis=0) if len(ref) else np.zeros((0, 2), np.int32)
    obj_got = np.unique(got[:, [0, 2]], axis=0) if len(got) else np.zeros((0, 2), np.int32)
    okr = obj_ref[:, 0].astype(np.int64) * scene.num_objects + obj_ref[:, 1]
    okg = obj_got[:, 0].astype(np.int64) * scene.num_objects + obj_got[:, 1]
    check = PairCheck(reference, peer, "triangle pairs", len(ref), len(got), int((~only_peer).sum()),
                      object_pairs=(len(obj_ref), len(obj_got), int(np.isin(okg, okr).sum())))

    world = scene.world_vertex.numpy()
    sides = ((reference, ref, only_ref, ra, rb, okg), (peer, got, only_peer, pa, pb, okr))
    for name, rows, only, ga, gb, other_obj in sides:
        other = peer if name == reference else reference
        tri_a = world[scene_triangle_vertex_index(scene, ga[only])]
        tri_b = world[scene_triangle_vertex_index(scene, gb[only])]
        cls = classify_triangle_pairs(tri_a, tri_b, device=scene.device)
        for c in CLASSES:
            check.classes[f"{name} only: {c}"] = int((cls == c).sum())
        diff_rows = rows[only]
        okey = diff_rows[:, 0].astype(np.int64) * scene.num_objects + diff_rows[:, 2]
        lone = ~np.isin(okey, other_obj)  # rows of object pairs the other method lacks entirely
        lone_keys = np.unique(okey[lone])
        missed = np.unique(okey[lone & (cls == "intersecting")])
        spurious = np.setdiff1d(np.unique(okey[lone & (cls == "apart")]), missed)
        check.explained += len(lone_keys) - len(missed) - len(spurious)
        if len(missed):
            check.charge(other, f"{other} misses {len(missed)} object pairs where {name} finds intersecting "
                                f"triangles, e.g. {_object_pair_names(missed, scene.num_objects, max_listed)}")
        if len(spurious):
            check.charge(name, f"{name} reports {len(spurious)} object pairs whose triangles are clearly apart, "
                               f"e.g. {_object_pair_names(spurious, scene.num_objects, max_listed)}")
    return check
