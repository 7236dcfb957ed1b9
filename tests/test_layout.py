"""The package's layout keeps its rule (docs/ARCHITECTURE.md, "Rooms"): the core (geometry, scene, stages,
pipeline) never imports I/O (usd, preview, output) or the applications (cli, bench), every room imports only
the rooms below it, no module imports another in a circle, and no module grows past its size.

The graph is read from the source (``ast``), every import counted wherever it stands (a function-level
import is an edge too: it is how ``Scene.from_usd`` once closed a circle). A package's ``__init__`` that
gathers its own modules' names is an edge from the package to them, as written. The top-level
``warp_ccd/__init__.py`` is the façade: it may import anything, and only the applications (cli, bench)
import it.
"""

from __future__ import annotations

import ast
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(ROOT, "warp_ccd")

ROOMS = {
    # room: (module prefixes, rooms it may import besides itself)
    "floor": (("warp_ccd._arrays", "warp_ccd._deprecated", "warp_ccd._typing", "warp_ccd.options"), ()),
    "geometry": (("warp_ccd.geometry",), ("floor",)),
    "scene": (("warp_ccd.scene",), ("floor", "geometry")),
    "stages": (("warp_ccd.stages",), ("floor", "geometry", "scene")),
    "pipeline": (("warp_ccd.pipeline", "warp_ccd.result", "warp_ccd.query"), ("floor", "geometry", "scene", "stages")),
    "output": (("warp_ccd.output",), ("floor",)),
    "usd": (("warp_ccd.usd",), ("floor", "geometry", "scene", "stages", "pipeline", "output")),
    "preview": (("warp_ccd.preview",), ("floor", "geometry", "scene", "stages", "pipeline", "output")),
    "cli": (("warp_ccd.cli", "warp_ccd.__main__"),
            ("floor", "geometry", "scene", "stages", "pipeline", "output", "usd", "preview", "bench", "facade")),
    "bench": (("warp_ccd.bench",),
              ("floor", "geometry", "scene", "stages", "pipeline", "output", "usd", "preview", "cli", "facade")),
    "facade": (("warp_ccd",), tuple()),  # may import anything (see the module docstring)
}
CORE = ("geometry", "scene", "stages", "pipeline")
CORE_THIRD_PARTY = {"warp", "numpy"}
"""What the core imports beyond the standard library: never pxr, PIL, tqdm, matplotlib."""

MODULE_LINES_MAX = 800
STAGE_LINES_MAX = {"warp_ccd.stages.narrow_phase": 500}


def module_files() -> dict[str, str]:
    """Dotted module name -> file, for every module of the package."""
    out = {}
    for folder, _, files in os.walk(PACKAGE):
        for f in files:
            if f.endswith(".py"):
                rel = os.path.relpath(os.path.join(folder, f), ROOT)[:-3].replace(os.sep, ".")
                out[rel.removesuffix(".__init__")] = os.path.join(folder, f)
    return out


MODULES = module_files()


def room_of(module: str) -> str:
    best = max((p for r, (prefixes, _) in ROOMS.items() for p in prefixes
                if module == p or module.startswith(p + ".")), key=len)
    return next(r for r, (prefixes, _) in ROOMS.items() if best in prefixes)


def imports_of(module: str) -> tuple[set[str], set[str]]:
    """``(package modules, top-level third-party names)`` that ``module`` imports, anywhere in its file."""
    file = MODULES[module]
    package = module if file.endswith("__init__.py") else module.rsplit(".", 1)[0]
    inner, outer = set(), set()

    def add(name: str) -> None:
        # a.b.c names a module, or a name inside module a.b
        while name not in MODULES and "." in name:
            name = name.rsplit(".", 1)[0]
        inner.add(name)

    for node in ast.walk(ast.parse(open(file).read(), file)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                (add if alias.name.split(".")[0] == "warp_ccd" else outer.add)(
                    alias.name if alias.name.startswith("warp_ccd") else alias.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            elif (node.module or "").split(".")[0] == "warp_ccd":
                target = node.module
            else:
                outer.add(node.module.split(".")[0])
                continue
            for alias in node.names:
                full = f"{target}.{alias.name}"
                add(full if full in MODULES else target)
    inner.discard(module)
    return inner, outer


GRAPH = {m: imports_of(m)[0] for m in MODULES}


def test_the_graph_was_read():
    """The parser sees the edges it must (a guard against a test that passes on an empty graph)."""
    assert "warp_ccd.scene.scene" in GRAPH["warp_ccd.pipeline"]
    assert any(m.startswith("warp_ccd.stages") for m in GRAPH["warp_ccd.pipeline"])
    assert "warp_ccd.usd.importer" in set().union(*(GRAPH[m] for m in MODULES if m.startswith("warp_ccd.usd")))
    assert all(room_of(m) for m in MODULES)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_rooms_import_only_rooms_below(module):
    room = room_of(module)
    if room == "facade":
        return
    allowed = set(ROOMS[room][1]) | {room}
    wrong = sorted(f"{m} ({room_of(m)})" for m in GRAPH[module] if room_of(m) not in allowed)
    assert not wrong, f"{module} ({room}) imports {', '.join(wrong)}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if room_of(m) in CORE))
def test_core_imports_no_io_library(module):
    stdlib = __import__("sys").stdlib_module_names
    third = sorted(n for n in imports_of(module)[1] if n not in stdlib and n not in CORE_THIRD_PARTY)
    assert not third, f"{module} (core) imports {third}"


def test_no_import_cycle():
    """Tarjan's strongly connected components of the module graph: every one a single module."""
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    assert not cycles, f"modules importing each other in a circle: {cycles}"


def test_cycle_and_room_checks_catch_a_bad_edge():
    """The checks fail on the edges they exist for: scene -> usd (a core -> I/O edge closing a circle)."""
    saved = set(GRAPH["warp_ccd.scene.scene"])
    try:
        GRAPH["warp_ccd.scene.scene"].add("warp_ccd.usd.importer")
        with pytest.raises(AssertionError, match="circle"):
            test_no_import_cycle()
        with pytest.raises(AssertionError, match="imports warp_ccd.usd.importer"):
            test_rooms_import_only_rooms_below("warp_ccd.scene.scene")
    finally:
        GRAPH["warp_ccd.scene.scene"] = saved


@pytest.mark.parametrize("module", sorted(MODULES))
def test_module_size(module):
    lines = sum(1 for _ in open(MODULES[module]))
    limit = STAGE_LINES_MAX.get(module, MODULE_LINES_MAX)
    assert lines < limit, f"{module} has {lines} lines (at most {limit - 1}: split it along a seam)"


def test_readme_layout_table_matches_the_tree():
    """Every module of the package has its row in the README's layout table, and every row names a file."""
    text = open(os.path.join(ROOT, "README.md")).read()
    table = text.split("\n## Layout", 1)[1].split("\n## ", 1)[0]
    named = set()
    for row in table.splitlines():
        if row.startswith("| `"):
            folder, modules = (c.strip() for c in row.split("|")[1:3])
            folder = folder.strip("`").rstrip("/")
            for name in re.findall(r"`([\w.]+)`", modules):
                named.add(f"{folder}/{name}")
    files = {os.path.relpath(f, ROOT).replace(os.sep, "/") for f in MODULES.values()}
    files = {f for f in files if not f.endswith(("__init__.py", "__main__.py"))}
    assert sorted(named - files) == [], "README's layout table names files that do not exist"
    assert sorted(files - named) == [], "modules missing from README's layout table"
