"""What ``warp-ccd check --continuous`` adds: contacts between time codes, and tunnelling.

Between two consecutive time codes ``t_k`` and ``t_{k+1}`` of a check, every world vertex is taken
to move linearly from its position at ``t_k`` to its position at ``t_{k+1}`` (as a viewer
interpolates the animation). A continuous :class:`~warp_ccd._src.pipeline.pipeline.CollisionPipeline` reports
the prim pairs whose surfaces touch (or come within its ``min_distance``) at some time of that
motion, with the earliest such time ``toi`` as a fraction of the interval (never later than the
true one); its time code is ``t_k + toi * (t_{k+1} - t_k)``. A pair is *tunnelling* in an interval
when neither end frame shows it intersecting (the discrete exact test, touching included): the
frames alone would miss that contact, as they miss a fast thin object passing through a wall.

:class:`SweepInterval` holds one interval's pairs; :func:`sweep_interval` makes it from a
continuous result; :func:`sweep_json`, :func:`sweep_summary` and :func:`tunnelling_flags` give
the report's JSON section, its lines of the summary and the overlay's flags.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .tables import pair_table

__all__ = ["COLOR_TUNNELLING", "SweepInterval", "sweep_interval", "sweep_json", "sweep_summary",
           "tunnelling_flags"]

COLOR_TUNNELLING = (1.0, 0.6, 0.0)
"""displayColor (linear RGB) in the overlay of a prim that tunnels in the interval starting at a
time code (where it does not penetrate at that time code: penetrating wins)."""


@dataclass
class SweepInterval:
    """The prim pairs that touch at some time between two consecutive time codes.

    Attributes:
        start: the interval's first time code ``t_k``.
        end: its last time code ``t_{k+1}``.
        object_pairs: ``(K, 2)`` int32 object pairs ``(a, b)``, ``a < b``, sorted.
        toi: ``(K,)`` float64 earliest time of impact of each pair, a fraction of the interval in ``[0, 1]``.
        tunnelling: ``(K,)`` bool, neither end frame shows the pair intersecting.
        triangle_pairs: ``(K,)`` int64, how many triangle pairs of each object pair touch in the interval.
        faces: ``(K, 2)`` int32 USD face indices ``(face_a, face_b)`` of each pair's earliest triangle pair.
    """

    start: float
    end: float
    object_pairs: np.ndarray
    toi: np.ndarray
    tunnelling: np.ndarray
    triangle_pairs: np.ndarray
    faces: np.ndarray

    @property
    def time(self) -> np.ndarray:
        """``(K,)`` float64 time codes of the first contacts: ``start + toi * (end - start)``."""
        return self.start + self.toi * (self.end - self.start)


def sweep_interval(imp, result, start: float, end: float, intersecting_start, intersecting_end) -> SweepInterval:
    """One interval's pairs from a continuous result.

    Args:
        imp: the :class:`~warp_ccd._src.usd.importer.UsdMeshImport` (its triangles' USD faces).
        result: a continuous :class:`~warp_ccd._src.pipeline.pipeline.CollisionResult` over the motion from
            ``start`` to ``end``.
        start, end: the interval's time codes.
        intersecting_start, intersecting_end: ``(J, 2)`` object pairs ``(a, b)``, ``a < b``, that
            intersect (touching included) at ``start`` and at ``end``.

    Returns:
        The :class:`SweepInterval`.
    """
    rows = np.asarray(result.triangle_pairs, np.int64).reshape(-1, 4)
    toi = np.asarray(result.triangle_toi, np.float64).reshape(-1)
    if len(rows) == 0:
        return SweepInterval(float(start), float(end), np.zeros((0, 2), np.int32), np.zeros(0), np.zeros(0, bool),
                             np.zeros(0, np.int64), np.zeros((0, 2), np.int32))
    # Per object pair, its earliest triangle pair (the first row of equals in the result's order).
    order = np.lexsort((np.arange(len(rows)), toi, rows[:, 2], rows[:, 0]))
    rows, toi = rows[order], toi[order]
    first = np.ones(len(rows), bool)
    first[1:] = (rows[1:, [0, 2]] != rows[:-1, [0, 2]]).any(axis=1)
    starts = np.nonzero(first)[0]
    counts = np.diff(np.append(starts, len(rows)))
    lead = rows[starts]
    pairs = lead[:, [0, 2]].astype(np.int32)
    faces = np.stack([imp.faces(lead[:, 0], lead[:, 1]), imp.faces(lead[:, 2], lead[:, 3])], axis=1).astype(np.int32)
    seen = np.concatenate([_pair_keys(intersecting_start), _pair_keys(intersecting_end)])
    tunnelling = ~np.isin(_pair_keys(pairs), seen)
    return SweepInterval(float(start), float(end), pairs, toi[starts], tunnelling, counts.astype(np.int64), faces)


def _pair_keys(pairs) -> np.ndarray:
    """``(K,)`` int64 keys ``a << 32 | b`` of ``(K, 2)`` object pairs (indices below ``2**31``)."""
    p = np.asarray(pairs, np.int64).reshape(-1, 2)
    return (p[:, 0] << 32) | p[:, 1]


def _tunnelling_rows(intervals, object_path) -> list[dict]:
    rows = []
    for iv in intervals:
        for (a, b), t, tc, tun in zip(iv.object_pairs.tolist(), iv.toi.tolist(), iv.time.tolist(),
                                      iv.tunnelling.tolist()):
            if tun:
                rows.append({"a": object_path[a], "b": object_path[b], "start": iv.start, "end": iv.end,
                             "toi": t, "time": tc})
    return rows


def sweep_json(intervals, object_path, min_distance: float, tolerance: float) -> dict:
    """The report's ``"continuous"`` section.

    Returns:
        ``{"min_distance", "tolerance", "tunnelling_pairs" (the (interval, prim pair) entries
        marked tunnelling), "intervals_with_contacts", "intervals": [{"start", "end", "pairs":
        [{"a", "b", "toi", "time", "tunnelling", "triangle_pairs", "faces"}]}]}``, one interval per
        pair of consecutive time codes, pairs by earliest toi.
    """
    out = []
    for iv in intervals:
        pairs = []
        for k in np.lexsort((iv.object_pairs[:, 1], iv.object_pairs[:, 0], iv.toi)).tolist():
            a, b = iv.object_pairs[k].tolist()
            pairs.append({"a": object_path[a], "b": object_path[b], "toi": float(iv.toi[k]),
                          "time": float(iv.time[k]), "tunnelling": bool(iv.tunnelling[k]),
                          "triangle_pairs": int(iv.triangle_pairs[k]), "faces": iv.faces[k].tolist()})
        out.append({"start": iv.start, "end": iv.end, "pairs": pairs})
    return {"min_distance": float(min_distance), "tolerance": float(tolerance),
            "tunnelling_pairs": int(sum(int(iv.tunnelling.sum()) for iv in intervals)),
            "intervals_with_contacts": int(sum(1 for iv in intervals if len(iv.object_pairs))),
            "intervals": out}


def sweep_summary(intervals, object_path, min_distance: float, top: int = 10) -> list[str]:
    """The summary's lines on the intervals: how many have contacts, the tunnelling pairs (the
    earliest ``top``) with their interval, toi and time code."""
    n = len(intervals)
    with_contacts = sum(1 for iv in intervals if len(iv.object_pairs))
    rows = _tunnelling_rows(intervals, object_path)
    lines = [f"  continuous (min distance {min_distance:g}): intervals with contacts {with_contacts} of {n}; "
             f"tunnelling pairs (neither end frame intersects): {len(rows)}"]
    rows = sorted(rows, key=lambda r: (r["time"], r["a"], r["b"]))
    ws = max([8] + [len(_interval(r)) for r in rows[:top]])
    return lines + pair_table(rows, top, f"{'interval':<{ws}}  toi       time",
                              lambda r: f"{_interval(r):<{ws}}  {r['toi']:<8.4f}  {r['time']:g}", "tunnelling pairs")


def _interval(row: dict) -> str:
    """A tunnelling row's interval ``start..end``."""
    return f"{row['start']:g}..{row['end']:g}"


def tunnelling_flags(intervals, times, num_objects: int) -> np.ndarray:
    """``(len(times), num_objects)`` bool: the objects that tunnel in the interval starting at each
    time code (the last time code starts none)."""
    flags = np.zeros((len(times), num_objects), bool)
    index = {float(t): k for k, t in enumerate(times)}
    for iv in intervals:
        k = index.get(float(iv.start))
        if k is not None:
            flags[k, iv.object_pairs[iv.tunnelling].ravel()] = True
    return flags
