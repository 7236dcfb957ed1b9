"""The check summary's tables of prim pairs: one layout for every section (collisions, continuous
contacts, soft clashes, duplicates)."""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["PRIM_WIDTH_MAX", "pair_table", "span"]

PRIM_WIDTH_MAX = 60
"""Widest a prim path column grows (longer paths run past it)."""


def span(row: dict) -> str:
    """A summary row's ``first..last`` time codes."""
    return f"{row['first']:g}..{row['last']:g}"


def pair_table(pairs: list[dict], top: int, head: str, cells: Callable[[dict], str], what: str = "pairs") -> list[str]:
    """The lines of a table of prim pairs: ``a`` and ``b`` in columns as wide as the paths shown (at most
    :data:`PRIM_WIDTH_MAX`), then the section's own columns; none when there are no pairs.

    Args:
        pairs: rows with ``"a"`` and ``"b"`` (prim paths), in the order shown.
        top: how many rows to show; a last line counts the others.
        head: the header of the section's own columns.
        cells: a row's own columns, as one string.
        what: what the rows are, in the line that counts the rows left out.

    Returns:
        The lines, each indented by two spaces.
    """
    shown = pairs[:top]
    if not shown:
        return []
    wa = min(max(len(p["a"]) for p in shown), PRIM_WIDTH_MAX)
    wb = min(max(len(p["b"]) for p in shown), PRIM_WIDTH_MAX)
    lines = [f"  {'prim a':<{wa}}  {'prim b':<{wb}}  {head}"]
    lines += [f"  {p['a']:<{wa}}  {p['b']:<{wb}}  {cells(p)}" for p in shown]
    if len(pairs) > top:
        lines.append(f"  ... {len(pairs) - top} more {what} (see the report)")
    return lines
