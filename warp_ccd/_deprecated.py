"""Old names kept for one release: each use warns (``DeprecationWarning``) and reaches the new name.

Imports nothing of the package, so every room may use it:

* :class:`renamed_attribute`: a class attribute standing for a renamed one
  (``instance_shape = renamed_attribute("object_shape")``).
* :func:`renamed_arguments`: a function's renamed keyword arguments, caught by its ``**renamed``.
* :func:`install_moved_modules`: modules that moved into a room (``warp_ccd.narrow_phase`` is now
  ``warp_ccd.stages.narrow_phase``): importing the old path warns once and gives a module whose names
  are looked up in the new homes.
* :func:`module_aliases`: a module's ``__getattr__`` for renamed or moved module-level names
  (``__getattr__ = module_aliases(__name__, {"BroadPhaseNxN": "warp_ccd.stages.broad_phase:BroadPhaseAllPairs"})``).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

__all__ = ["install_moved_modules", "module_aliases", "renamed_arguments", "renamed_attribute", "warn_renamed"]


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


class _MovedModules(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the old path of a moved module; its module looks names up in the new homes."""

    def __init__(self, moves: dict[str, tuple[str, ...]]):
        self.moves = moves

    def find_spec(self, fullname, path=None, target=None):
        return importlib.util.spec_from_loader(fullname, self) if fullname in self.moves else None

    def create_module(self, spec):
        return None  # the default: an empty module, filled by exec_module

    def exec_module(self, module: types.ModuleType) -> None:
        homes = self.moves[module.__name__]
        warn_renamed(module.__name__, homes[0], stacklevel=2)
        loaded = [importlib.import_module(h) for h in homes]

        def __getattr__(name: str):
            for home in loaded:
                if hasattr(home, name):
                    return getattr(home, name)
            raise AttributeError(f"module {module.__name__!r} (now {homes[0]}) has no attribute {name!r}")

        module.__getattr__ = __getattr__
        module.__doc__ = f"Deprecated: moved to :mod:`{homes[0]}`."


def install_moved_modules(moves: dict[str, tuple[str, ...]]) -> None:
    """Makes the old paths of moved modules importable for one release (once per process).

    Args:
        moves: old dotted path -> the new modules its names now live in, the main one first
            (``{"warp_ccd.narrow_phase": ("warp_ccd.stages.narrow_phase", "warp_ccd.geometry")}``).
    """
    if not any(isinstance(f, _MovedModules) for f in sys.meta_path):
        sys.meta_path.append(_MovedModules(moves))
