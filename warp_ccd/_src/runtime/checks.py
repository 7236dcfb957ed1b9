"""Checks of integer and real options, with one message shape for every option of the package.

Imports nothing of the package, so every room may use it:

* :func:`integer_option`: an integer (``bool`` refused, numpy integers taken) within bounds or
  among choices.
* :func:`number_option`: a finite real number (``bool`` refused, numpy scalars taken) within
  closed or open bounds.
* :func:`is_integer`: the test alone, for options that take an integer or something else.

A bad value raises ``ValueError("{name} must be an integer in [0, 16], got 17")``: the option's
name (a prefix such as ``"icosphere: "`` may be part of it), what it allows, the value as given.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["integer_option", "is_integer", "number_option"]


def is_integer(value) -> bool:
    """Whether ``value`` is a Python or numpy integer, not a ``bool``."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _is_number(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def _fmt(x) -> str:
    """A bound as the message writes it: ``0.1``, ``1``, ``1e-06``."""
    return repr(int(x)) if isinstance(x, (int, np.integer)) else f"{float(x):g}"


def _allowed(low, high, low_open: bool = False, high_open: bool = False) -> str:
    """``" in [low, high)"``, ``" >= low"``, ``" < high"`` or ``""`` (no bounds)."""
    if low is not None and high is not None:
        return f" in {'(' if low_open else '['}{_fmt(low)}, {_fmt(high)}{')' if high_open else ']'}"
    if low is not None:
        return f" {'>' if low_open else '>='} {_fmt(low)}"
    if high is not None:
        return f" {'<' if high_open else '<='} {_fmt(high)}"
    return ""


def integer_option(name: str, value, *, low: int | None = None, high: int | None = None,
                   choices=None, allow_none: bool = False) -> int | None:
    """``value`` as an ``int``, checked.

    Args:
        name: the option as the user wrote it (with a prefix where it helps: ``"add_frame: frame_index"``).
        value: what was given.
        low, high: inclusive bounds (None: unbounded on that side).
        choices: the allowed values, when they are not a range (``low``/``high`` then unused).
        allow_none: None is allowed too (and returned).

    Returns:
        ``int(value)``, or None when ``value`` is None and ``allow_none``.

    Raises:
        ValueError: ``"{name} must be an integer in [low, high], got {value!r}"`` (``>= low``,
            ``<= high``, ``in {a, b, c}``; ``" or None"`` when ``allow_none``).
    """
    if value is None and allow_none:
        return None
    if choices is not None:
        ok = is_integer(value) and value in choices
        allowed = " in {" + ", ".join(str(c) for c in choices) + "}"
    else:
        ok = is_integer(value) and (low is None or value >= low) and (high is None or value <= high)
        allowed = _allowed(low, high)
    if not ok:
        raise ValueError(f"{name} must be an integer{allowed}{' or None' if allow_none else ''}, got {value!r}")
    return int(value)


def number_option(name: str, value, *, low: float | None = None, high: float | None = None, low_open: bool = False,
                  high_open: bool = False) -> float:
    """``value`` as a finite ``float``, checked.

    Args:
        name: the option as the user wrote it (with a prefix where it helps: ``"advance: dt"``).
        value: what was given: a Python or numpy integer or float (not a ``bool``).
        low, high: bounds (None: unbounded on that side).
        low_open, high_open: exclude the bound itself (``(0, 1)``, ``> 0``).

    Returns:
        ``float(value)``.

    Raises:
        ValueError: ``"{name} must be a finite number in [low, high), got {value!r}"`` (``> low``,
            ``<= high``, ...).
    """
    try:
        x = float(value) if _is_number(value) else math.nan
    except OverflowError:  # an int beyond float's range
        x = math.nan
    ok = math.isfinite(x)
    if ok:
        if low is not None:
            ok = x > low if low_open else x >= low
        if ok and high is not None:
            ok = x < high if high_open else x <= high
    if not ok:
        raise ValueError(f"{name} must be a finite number{_allowed(low, high, low_open, high_open)}, got {value!r}")
    return x
