"""Old names kept for one release: each use warns (``DeprecationWarning``) and reaches the new name.

Imports nothing of the package, so every room may use it:

* :class:`renamed_attribute`: a class attribute standing for a renamed one
  (``instance_shape = renamed_attribute("object_shape")``).
* :func:`renamed_arguments`: a function's renamed keyword arguments, caught by its ``**renamed``.
* :func:`module_aliases`: a module's ``__getattr__`` for renamed or moved module-level names
  (``__getattr__ = module_aliases(__name__, {"BroadPhaseNxN": "warp_ccd.stages.broad_phase:BroadPhaseAllPairs"})``).
"""

from __future__ import annotations

import importlib
import warnings

__all__ = ["module_aliases", "renamed_arguments", "renamed_attribute", "warn_renamed"]


def warn_renamed(old: str, new: str, stacklevel: int = 3) -> None:
    """Warns that ``old`` is deprecated in favour of ``new`` (both as the user writes them)."""
    warnings.warn(f"{old} is deprecated and will be removed in the next release: use {new}",
                  DeprecationWarning, stacklevel=stacklevel)


class renamed_attribute:  # noqa: N801 (used like a function, as property is)
    """A class attribute whose name was changed: reading or writing it warns and reaches ``new``.

    Args:
        new: the attribute's current name.
    """

    def __init__(self, new: str):
        self.new = new
        self.old = new

    def __set_name__(self, owner, name: str) -> None:
        self.old = name
        self.owner = owner.__name__

    def __get__(self, obj, objtype=None):
        if obj is None:
            return self
        warn_renamed(f"{self.owner}.{self.old}", f"{self.owner}.{self.new}")
        return getattr(obj, self.new)

    def __set__(self, obj, value) -> None:
        warn_renamed(f"{self.owner}.{self.old}", f"{self.owner}.{self.new}")
        setattr(obj, self.new, value)


def module_aliases(module: str, aliases: dict[str, str]):
    """A module ``__getattr__`` that resolves deprecated names.

    Args:
        module: the module's ``__name__`` (for the message and the error of an unknown name).
        aliases: old name -> ``"package.module:name"`` of the object it stands for now.

    Returns:
        ``__getattr__(name)``: warns and returns the new object for an old name; raises
        ``AttributeError`` for any other name, as a module does.
    """

    def __getattr__(name: str):
        target = aliases.get(name)
        if target is None:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        where, _, attr = target.partition(":")
        warn_renamed(f"{module}.{name}", f"{where}.{attr}")
        return getattr(importlib.import_module(where), attr)

    return __getattr__


def renamed_arguments(where: str, given: dict, renames: dict[str, str]) -> dict:
    """Keyword arguments passed under old names, under their new names (each warns).

    Args:
        where: the function as the user calls it (``"Scene"``), for the messages.
        given: the ``**renamed`` keyword arguments the function caught.
        renames: old name -> new name.

    Returns:
        ``{new name: value}``.

    Raises:
        TypeError: for a name that is neither a parameter nor an old name, as Python would.
    """
    out = {}
    for old, value in given.items():
        if old not in renames:
            raise TypeError(f"{where}() got an unexpected keyword argument {old!r}")
        warn_renamed(f"{where}({old}=...)", f"{where}({renames[old]}=...)", stacklevel=4)
        out[renames[old]] = value
    return out
