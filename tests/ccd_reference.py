"""An exact reference for continuous collision of a vertex and a triangle, or of two edges, in rationals.

Every vertex moves linearly from its position at t=0 to t=1. The inputs are floats, read exactly (a float
is a dyadic rational), and every decision below is made on exact integers or :class:`fractions.Fraction`\\ s,
so a verdict of this module is a proof, not an estimate. Two methods, both certified:

* ``min_distance == 0``, :func:`_algebraic`: contact needs coplanarity, the cubic ``g(t)``
  (``det(f1-f0, f2-f0, p-f0)``, or ``det(ea1-ea0, eb0-ea0, eb1-ea0)``). When ``g`` is not identically
  zero, the earliest contact is one of its real roots in [0, 1]; the roots are isolated exactly (Sturm
  sequences of the square-free part, bisection on rationals) and at each root the point-in-triangle
  (segments-meet) predicate is evaluated exactly as signs of polynomials at an algebraic number: a
  polynomial vanishes at the root when its gcd with ``g`` has a root in the isolating interval; otherwise
  the interval shrinks until the polynomial has no root in it. Degenerate triangles (collapsing to a
  segment or a point at that instant) and parallel or collinear edges fall back to exact
  point-on-segment tests. When ``g`` is identically zero (motion in a plane), the predicate is a boolean
  formula of the signs of finitely many polynomials (its *atoms*), so its truth is constant between
  their roots and, the contact set being closed, the earliest contact is t=0 or one of those roots:
  every candidate is tested the same way. No family is left inconclusive; only the work caps are.
* ``min_distance > 0`` (infinity norm), :func:`_boxes`: a best-first bisection of (t, u, v) on exact
  integers (everything scaled by a power of two). ``F(t, u, v)`` (the point minus the triangle's point
  at barycentric (u, v), or the difference of the edges' points at parameters u, v) is multilinear, so its
  range over a box lies in the hull of its 8 corner values: a box is rejected exactly when one axis has
  all corners above ``d`` or all below ``-d``; a corner inside the domain with ``|F|_inf <= d`` is a
  witness (an upper bound of the toi), and the earliest unrejected box is a lower bound. It also decides
  ``min_distance == 0`` queries whose contact is at a dyadic point (axis-aligned crafted cases).

:func:`reference_ccd` returns a :class:`Verdict`: ``"hit"`` with a certified bracket ``lo <= toi <= hi``
(Fractions), ``"no_hit"``, or ``"inconclusive"`` when a work cap was reached.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

KINDS = ("vertex_face", "edge_edge")
BRACKET_BITS = 60
"""Hit brackets of the algebraic method are refined to a width of ``2**-BRACKET_BITS``."""
_ISOLATION_STEPS = 400
_SIGN_STEPS = 400


class _Inconclusive(Exception):
    pass


@dataclass(frozen=True)
class Verdict:
    """The reference's answer: ``verdict`` in {"hit", "no_hit", "inconclusive"}; for a hit, the true
    earliest time of impact lies in ``[lo, hi]`` (exact Fractions); for an inconclusive answer ``lo`` is still
    a certified lower bound of any contact (None where not known)."""

    verdict: str
    lo: Fraction | None = None
    hi: Fraction | None = None
    method: str = ""

    @property
    def hit(self) -> bool:
        return self.verdict == "hit"

    @property
    def conclusive(self) -> bool:
        return self.verdict != "inconclusive"


# --- exact inputs -------------------------------------------------------------------------------------------------


def _as_integers(values) -> tuple[list[int], int]:
    """Floats as integers ``x * 2**e`` (all exact) and the shared exponent ``e``."""
    ratios = []
    for x in values:
        x = float(x)
        if not math.isfinite(x):
            raise ValueError(f"non-finite input {x}")
        ratios.append(x.as_integer_ratio())
    e = max(den.bit_length() - 1 for _, den in ratios)
    return [num << (e - (den.bit_length() - 1)) for num, den in ratios], e


# --- polynomials in t: coefficient lists, lowest power first ------------------------------------------------------


def _trim(p):
    p = list(p)
    while p and p[-1] == 0:
        p.pop()
    return p


def _add(p, q):
    n = max(len(p), len(q))
    return _trim([(p[i] if i < len(p) else 0) + (q[i] if i < len(q) else 0) for i in range(n)])


def _sub(p, q):
    return _add(p, [-c for c in q])


def _mul(p, q):
    if not p or not q:
        return []
    out = [0] * (len(p) + len(q) - 1)
    for i, a in enumerate(p):
        if a:
            for j, b in enumerate(q):
                out[i + j] += a * b
    return _trim(out)


def _eval(p, x):
    acc = 0
    for c in reversed(p):
        acc = acc * x + c
    return acc


def _sign(x) -> int:
    return (x > 0) - (x < 0)


def _deriv(p):
    return _trim([i * p[i] for i in range(1, len(p))])


def _divmod(p, q):
    """Quotient and remainder of ``p / q`` over the rationals."""
    p = [Fraction(c) for c in p]
    quot = [Fraction(0)] * max(len(p) - len(q) + 1, 1)
    lead = Fraction(q[-1])
    while len(p) >= len(q) and p:
        k = len(p) - len(q)
        c = p[-1] / lead
        quot[k] = c
        for i, b in enumerate(q):
            p[i + k] -= c * b
        p = _trim(p)
    return _trim(quot), p


def _monic(p):
    lead = Fraction(p[-1])
    return [Fraction(c) / lead for c in p]


def _gcd(p, q):
    p, q = _trim(p), _trim(q)
    while q:
        p, q = q, _divmod(p, q)[1]
    return _monic(p) if p else []


def _squarefree(p):
    g = _gcd(p, _deriv(p))
    return _divmod(p, g)[0] if len(g) > 1 else _monic(p)


def _sturm(p):
    chain = [p, _deriv(p)]
    while len(chain[-1]) > 1:
        r = _divmod(chain[-2], chain[-1])[1]
        if not r:
            break
        chain.append([-c for c in r])
    return chain


def _variations(chain, x) -> int:
    signs = [s for s in (_sign(_eval(q, x)) for q in chain) if s]
    return sum(1 for a, b in zip(signs, signs[1:]) if a != b)


def _count(chain, a, b) -> int:
    """Distinct real roots of ``chain[0]`` in ``(a, b]`` (``a``, ``b`` not roots)."""
    return _variations(chain, a) - _variations(chain, b)


class _Root:
    """A real algebraic number: the one root of the square-free ``poly`` in the open interval ``(lo, hi)``
    (endpoints not roots), or the rational ``lo == hi`` when ``exact``."""

    def __init__(self, poly, lo, hi, exact=False):
        self.poly, self.lo, self.hi, self.exact = poly, Fraction(lo), Fraction(hi), exact
        self.slo = 0 if exact else _sign(_eval(poly, self.lo))

    def refine(self) -> None:
        if self.exact:
            return
        mid = (self.lo + self.hi) / 2
        s = _sign(_eval(self.poly, mid))
        if s == 0:
            self.lo = self.hi = mid
            self.exact = True
        elif s == self.slo:
            self.lo = mid
        else:
            self.hi = mid

    def refine_to(self, width) -> None:
        while not self.exact and self.hi - self.lo > width:
            self.refine()

    def sign(self, h, cache) -> int:
        """The exact sign of the polynomial ``h`` at this number."""
        if self.exact:
            return _sign(_eval(h, self.lo))
        if not h:
            return 0
        if len(h) == 1:
            return _sign(h[0])
        g = _gcd(self.poly, h)
        if len(g) > 1 and _count(_sturm(g), self.lo, self.hi) > 0:
            return 0
        key = tuple(h)
        if key not in cache:
            cache[key] = _sturm(h)
        chain = cache[key]
        for _ in range(_SIGN_STEPS):
            s_lo = _sign(_eval(h, self.lo))
            if s_lo and _eval(h, self.hi) and _count(chain, self.lo, self.hi) == 0:
                return s_lo
            self.refine()
            if self.exact:
                return _sign(_eval(h, self.lo))
        raise _Inconclusive("sign steps")


def _roots_in_unit(p) -> list[_Root]:
    """Every distinct real root of ``p`` (not identically zero) in [0, 1], isolated."""
    p = _trim(p)
    if len(p) <= 1:
        return []
    q = _squarefree(p)
    found = []
    for x in (Fraction(0), Fraction(1)):
        if _eval(q, x) == 0:
            found.append(_Root(None, x, x, exact=True))
            q = _divmod(q, [-x, 1])[0]
    intervals = []
    if len(q) > 1:
        chain = _sturm(q)
        stack = [(Fraction(0), Fraction(1))]
        steps = 0
        while stack:
            steps += 1
            if steps > _ISOLATION_STEPS:
                raise _Inconclusive("isolation steps")
            a, b = stack.pop()
            c = _count(chain, a, b)
            if c == 0:
                continue
            if c == 1:
                intervals.append((a, b))
                continue
            m = (a + b) / 2
            if _eval(q, m) == 0:
                found.append(_Root(None, m, m, exact=True))
                q = _divmod(q, [-m, 1])[0]
                chain = _sturm(q)
            stack += [(a, m), (m, b)]
    return found + [_Root(q, a, b) for a, b in intervals]


# --- vectors of polynomials ---------------------------------------------------------------------------------------


def _vsub(a, b):
    return [_sub(x, y) for x, y in zip(a, b)]


def _cross(a, b):
    return [_sub(_mul(a[1], b[2]), _mul(a[2], b[1])), _sub(_mul(a[2], b[0]), _mul(a[0], b[2])),
            _sub(_mul(a[0], b[1]), _mul(a[1], b[0]))]


def _dot(a, b):
    return _add(_add(_mul(a[0], b[0]), _mul(a[1], b[1])), _mul(a[2], b[2]))


def _segment_atoms(p, a, b):
    """Polynomials whose signs decide whether ``p`` lies on the closed segment ``[a, b]``."""
    ab, ap = _vsub(b, a), _vsub(p, a)
    c = _cross(ab, ap)
    return (_dot(c, c), _dot(ap, ab), _dot(_vsub(p, b), _vsub(a, b)), _dot(ab, ab), _dot(ap, ap))


def _on_segment(sign, atoms) -> bool:
    cross2, d_a, d_b, length2, dist2 = atoms
    return (sign(cross2) == 0 and sign(d_a) >= 0 and sign(d_b) >= 0
            and (sign(length2) != 0 or sign(dist2) == 0))


def _problem(kind, x0, x1):
    """(g, predicate(sign, skip_coplanar), atoms) of a query, as integer polynomials in t."""
    ints, _ = _as_integers(list(np.asarray(x0, np.float64).ravel()) + list(np.asarray(x1, np.float64).ravel()))
    pts = [[[ints[3 * i + k], ints[12 + 3 * i + k] - ints[3 * i + k]] for k in range(3)] for i in range(4)]
    pts = [[_trim(c) for c in pt] for pt in pts]
    if kind == "vertex_face":
        p, f0, f1, f2 = pts
        n = _cross(_vsub(f1, f0), _vsub(f2, f0))
        g = _dot(n, _vsub(p, f0))
        big_n = _dot(n, n)
        sides = [_dot(n, _cross(_vsub(b, a), _vsub(p, a))) for a, b in ((f0, f1), (f1, f2), (f2, f0))]
        segs = [_segment_atoms(p, a, b) for a, b in ((f0, f1), (f1, f2), (f2, f0))]

        def predicate(sign, skip_coplanar=False):
            if not skip_coplanar and sign(g) != 0:
                return False
            if sign(big_n) != 0:
                return all(sign(s) >= 0 for s in sides)
            return any(_on_segment(sign, s) for s in segs)

        atoms = [g, big_n, *sides] + [a for s in segs for a in s]
    elif kind == "edge_edge":
        a0, a1, b0, b1 = pts
        u, w = _vsub(a1, a0), _vsub(b1, b0)
        g = _dot(_cross(u, _vsub(b0, a0)), _vsub(b1, a0))
        m = _cross(u, w)
        big_m = _dot(m, m)
        side_b = [_dot(m, _cross(u, _vsub(b, a0))) for b in (b0, b1)]
        side_a = [_dot(m, _cross(w, _vsub(a, b0))) for a in (a0, a1)]
        segs = [_segment_atoms(a0, b0, b1), _segment_atoms(a1, b0, b1), _segment_atoms(b0, a0, a1),
                _segment_atoms(b1, a0, a1)]

        def predicate(sign, skip_coplanar=False):
            if not skip_coplanar and sign(g) != 0:
                return False
            if sign(big_m) != 0:
                return sign(side_b[0]) * sign(side_b[1]) <= 0 and sign(side_a[0]) * sign(side_a[1]) <= 0
            return any(_on_segment(sign, s) for s in segs)

        atoms = [g, big_m, *side_b, *side_a] + [a for s in segs for a in s]
    else:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    return g, predicate, atoms


def _algebraic(kind, x0, x1) -> Verdict:
    """The exact earliest contact at ``min_distance == 0`` (module docstring)."""
    g, predicate, atoms = _problem(kind, x0, x1)
    if g:
        candidates = _roots_in_unit(g)
        skip = True
    else:
        candidates = [_Root(None, 0, 0, exact=True)]
        seen = set()
        for a in atoms:
            if len(a) > 1 and tuple(a) not in seen:
                seen.add(tuple(a))
                candidates += _roots_in_unit(a)
        skip = False
    candidates.sort(key=lambda r: r.lo)
    width = Fraction(1, 2**BRACKET_BITS)
    lo = hi = None
    cache = {}
    for root in candidates:
        if hi is not None and root.lo > hi:
            break
        if predicate(lambda h, r=root: r.sign(h, cache), skip):
            root.refine_to(width)
            lo = root.lo if lo is None else min(lo, root.lo)
            hi = root.hi if hi is None else min(hi, root.hi)
    if hi is None:
        return Verdict("no_hit", method="algebraic")
    return Verdict("hit", lo, hi, method="algebraic")


# --- min_distance >= 0: exact inclusion bisection over (t, u, v) --------------------------------------------------

_LEVEL = 64
"""Box corners are integers over ``2**_LEVEL`` in every dimension."""


def _coefficients(kind, x0, x1, d):
    """Integer (A, B, C, D, E, G) per axis with ``F = A + tB + u(C + tD) + v(E + tG)``, and ``d``, all
    scaled by the same power of two."""
    ints, _ = _as_integers(list(np.asarray(x0, np.float64).ravel()) + list(np.asarray(x1, np.float64).ravel())
                           + [d])
    d_int = ints[24]

    def at(i, k):
        return ints[3 * i + k], ints[12 + 3 * i + k] - ints[3 * i + k]  # (value at 0, velocity)

    axes = []
    for k in range(3):
        if kind == "vertex_face":
            (p, vp), (f0, v0), (f1, v1), (f2, v2) = at(0, k), at(1, k), at(2, k), at(3, k)
            axes.append((p - f0, vp - v0, -(f1 - f0), -(v1 - v0), -(f2 - f0), -(v2 - v0)))
        else:
            (a0, va0), (a1, va1), (b0, vb0), (b1, vb1) = at(0, k), at(1, k), at(2, k), at(3, k)
            axes.append((a0 - b0, va0 - vb0, a1 - a0, va1 - va0, -(b1 - b0), -(vb1 - vb0)))
    return axes, d_int


def _boxes(kind, x0, x1, d, *, max_boxes=20000, width=Fraction(1, 2**40)) -> Verdict:
    """Certified inclusion bisection (module docstring); ``width``: the bracket to reach."""
    axes, d_int = _coefficients(kind, x0, x1, d)
    one = 1 << _LEVEL
    scaled = [(a << 2 * _LEVEL, b << _LEVEL, c << _LEVEL, dd, e << _LEVEL, gg) for a, b, c, dd, e, gg in axes]
    thresh = d_int << 2 * _LEVEL
    vf = kind == "vertex_face"
    target = int(width * one)
    witness = None  # earliest t (integer over 2**_LEVEL) with a certified contact
    heap = [(0, 0, (0, one, 0, one, 0, one))]
    counter = 1
    processed = 0
    unresolved = None  # earliest t of an unrejected box too small to split
    while heap:
        t0 = heap[0][0]
        if witness is not None and witness - t0 <= target:
            break
        _, _, box = heapq.heappop(heap)
        processed += 1
        if processed > max_boxes:
            heapq.heappush(heap, (t0, 0, box))
            break
        ta, tb, ua, ub, va, vb = box
        if vf and ua + va > one:
            continue
        # corner values per axis, indexed [it][iu][iv]
        rejected = False
        vals = []
        for a2, b1, c1, dd, e1, gg in scaled:
            ax = []
            for t in (ta, tb):
                base, cu, cv = a2 + t * b1, c1 + t * dd, e1 + t * gg
                for u in (ua, ub):
                    bu = base + u * cu
                    ax.append(bu + va * cv)
                    ax.append(bu + vb * cv)
            if min(ax) > thresh or max(ax) < -thresh:
                rejected = True
                break
            vals.append(ax)
        if rejected:
            continue
        touching = False
        for i in range(8):
            t = (ta, tb)[i >> 2]
            u, v = (ua, ub)[(i >> 1) & 1], (va, vb)[i & 1]
            if (not vf or u + v <= one) and all(abs(ax[i]) <= thresh for ax in vals):
                touching = True
                if witness is None or t < witness:
                    witness = t
        # split the dimension contributing most to the corners' spread
        spread = [0, 0, 0]
        for ax in vals:
            for i in range(8):
                for dim, bit in enumerate((4, 2, 1)):
                    if not i & bit:
                        spread[dim] = max(spread[dim], abs(ax[i | bit] - ax[i]))
        widths = (tb - ta, ub - ua, vb - va)
        order = [0, 1, 2] if touching else sorted(range(3), key=lambda k: -spread[k] * widths[k])
        dim = next((k for k in order if widths[k] > 1), None)
        if dim is None:
            unresolved = ta if unresolved is None else min(unresolved, ta)
            continue
        lo_hi = [(ta, tb), (ua, ub), (va, vb)]
        a, b = lo_hi[dim]
        m = (a + b) // 2
        for half in ((a, m), (m, b)):
            child = list(lo_hi)
            child[dim] = half
            ct0 = child[0][0]
            if witness is not None and ct0 >= witness:
                continue
            heapq.heappush(heap, (ct0, counter, (child[0][0], child[0][1], child[1][0], child[1][1], child[2][0],
                                                 child[2][1])))
            counter += 1
    open_lo = min(([heap[0][0]] if heap else []) + ([unresolved] if unresolved is not None else []), default=None)
    if witness is None:
        if open_lo is not None:
            return Verdict("inconclusive", Fraction(open_lo, one), None, method="boxes")
        return Verdict("no_hit", method="boxes")
    lo = witness if open_lo is None else min(open_lo, witness)
    return Verdict("hit", Fraction(lo, one), Fraction(witness, one), method="boxes")


def reference_ccd(kind: str, x0, x1, min_distance: float = 0.0, *, method: str = "auto", max_boxes: int = 20000,
                  width: Fraction = Fraction(1, 2**40)) -> Verdict:
    """The exact verdict of one query.

    Args:
        kind: "vertex_face" (rows p, f0, f1, f2) or "edge_edge" (rows ea0, ea1, eb0, eb1).
        x0, x1: (4, 3) positions at t=0 and t=1 (any float dtype, read exactly).
        min_distance: ``d >= 0`` in the infinity norm.
        method: "auto" (algebraic at ``d == 0``, boxes otherwise), "algebraic" or "boxes".
        max_boxes, width: the box method's work cap and the bracket width it aims for.
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    d = float(min_distance)
    if not d >= 0.0 or not math.isfinite(d):
        raise ValueError(f"min_distance must be finite and >= 0, got {min_distance}")
    if np.shape(x0) != (4, 3) or np.shape(x1) != (4, 3):
        raise ValueError("x0 and x1 must have shape (4, 3)")
    if method == "auto":
        method = "algebraic" if d == 0.0 else "boxes"
    try:
        if method == "algebraic":
            if d != 0.0:
                raise ValueError("the algebraic method decides min_distance == 0 only")
            return _algebraic(kind, x0, x1)
        return _boxes(kind, x0, x1, d, max_boxes=max_boxes, width=width)
    except _Inconclusive as e:
        return Verdict("inconclusive", method=f"{method}: {e}")
