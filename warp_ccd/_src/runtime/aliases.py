"""Type aliases of the public API's signatures.

They name what a parameter accepts; nothing here is checked when a function runs (each function validates
its arguments itself and says, in its docstring, the shapes, dtypes and units it takes).
"""

from __future__ import annotations

import os
from typing import Any, TypeAlias

import warp as wp

ArrayLike: TypeAlias = Any
"""An array the API reads: a numpy array or anything ``numpy.asarray`` takes (nested lists and tuples), a
``wp.array``, or an object exposing ``__array_interface__``, ``__cuda_array_interface__`` or DLPack (a torch
or CuPy tensor). Shapes and dtypes are in each function's docstring."""

DeviceLike: TypeAlias = str | wp.Device | None
"""A Warp device: its name (``"cpu"``, ``"cuda:0"``), a ``wp.Device``, or None for Warp's default device."""

PathLike: TypeAlias = str | os.PathLike[str]
"""A file path: a string or a ``pathlib.Path``."""

__all__ = ["ArrayLike", "DeviceLike", "PathLike"]
