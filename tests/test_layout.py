"""The package's layout keeps its rule (``warp_ccd/_src/__init__.py``, docs/architecture): the implementation
lives under ``warp_ccd._src`` in one folder per concept, each importing only the concepts below it; the core
(runtime to pipeline) never imports USD, the check, the CLI, pictures or benchmarks; no module imports another
in a circle; the private core never imports a public module; the public modules are few.

The graph is read from the source (``ast``), every import counted wherever it stands (a function-level
import or one under ``TYPE_CHECKING`` is an edge too).
"""

from __future__ import annotations

import ast
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(ROOT, "warp_ccd")

CORE_ROOMS = {
    # concept: the concepts it may import besides itself
    "runtime": (),
    "geometry": ("runtime",),
    "scene": ("runtime", "geometry"),
    "trees": ("runtime", "geometry", "scene"),
    "broadphase": ("runtime", "geometry", "scene", "trees"),
    "midphase": ("runtime", "geometry", "scene", "trees"),
    "narrowphase": ("runtime", "geometry", "scene", "trees"),
    "queries": ("runtime", "geometry", "scene", "trees", "narrowphase"),
    "pipeline": ("runtime", "geometry", "scene", "trees", "broadphase", "midphase", "narrowphase", "queries"),
}
CORE = tuple(CORE_ROOMS)
ROOMS = {
    **CORE_ROOMS,
    "output": ("runtime",),
    "usd": (*CORE, "output"),
    "check": (*CORE, "output", "usd"),
    "preview": (*CORE, "output"),
    "cli": (*CORE, "output", "usd", "check", "preview", "bench"),
    "bench": (*CORE, "output", "cli"),
    "compat": CORE,
    "_src": (),
}
"""Every folder (or single module) of ``warp_ccd/_src`` and what it may import: a new concept gets its row here."""
CORE_THIRD_PARTY = {"warp", "numpy"}
"""What the core imports beyond the standard library: never pxr, PIL, tqdm, matplotlib."""
PUBLIC_MAX = 25


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
    """The concept folder of a private module (``warp_ccd._src.trees.bvh``: ``trees``), ``"public"`` for the
    public modules (no part starting with an underscore, and ``warp_ccd.__main__``)."""
    parts = module.split(".")
    if parts[1:2] == ["_src"]:
        return parts[2] if len(parts) > 2 else "_src"
    return "public"


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
    assert "warp_ccd._src.scene.scene" in GRAPH["warp_ccd._src.pipeline.pipeline"]
    assert any(room_of(m) == "trees" for m in GRAPH["warp_ccd._src.midphase.bvh"])
    assert "warp_ccd._src.usd.importer" in set().union(*(GRAPH[m] for m in MODULES if room_of(m) == "check"))
    assert {room_of(m) for m in MODULES} >= set(CORE) | {"usd", "check", "cli", "public"}


def test_every_private_module_is_in_a_known_concept():
    unknown = sorted(m for m in MODULES if room_of(m) not in ROOMS and room_of(m) != "public")
    assert not unknown, f"modules outside the concepts of ROOMS (add the concept, with what it may import): {unknown}"


def test_each_concept_says_what_it_holds():
    """Each concept folder opens with a docstring (what it holds), the room a newcomer reads first."""
    for room in ROOMS:
        init = os.path.join(PACKAGE, "_src", room, "__init__.py")
        if os.path.exists(init):
            assert ast.get_docstring(ast.parse(open(init).read())), f"_src/{room}/__init__.py has no docstring"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if room_of(m) != "public"))
def test_concepts_import_only_concepts_below(module):
    room = room_of(module)
    allowed = set(ROOMS.get(room, ())) | {room}
    wrong = sorted(f"{m} ({room_of(m)})" for m in GRAPH[module] if room_of(m) not in allowed)
    assert not wrong, f"{module} ({room}) imports {', '.join(wrong)}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if room_of(m) in CORE))
def test_core_imports_no_io_library(module):
    stdlib = __import__("sys").stdlib_module_names
    third = sorted(n for n in imports_of(module)[1] if n not in stdlib and n not in CORE_THIRD_PARTY)
    assert not third, f"{module} (core) imports {third}"


def test_public_modules_are_few_and_thin():
    """At most PUBLIC_MAX public module paths; each re-exports (its own code is imports and ``__all__``)."""
    public = sorted(m for m in MODULES if room_of(m) == "public")
    assert len(public) <= PUBLIC_MAX, public
    for module in public:
        tree = ast.parse(open(MODULES[module]).read())
        defs = [n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef))]
        assert not defs, f"{module} defines {defs}: public modules re-export, the code lives in warp_ccd._src"


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
    saved = set(GRAPH["warp_ccd._src.scene.scene"])
    try:
        GRAPH["warp_ccd._src.scene.scene"].add("warp_ccd._src.usd.importer")
        with pytest.raises(AssertionError, match="circle"):
            test_no_import_cycle()
        with pytest.raises(AssertionError, match="imports warp_ccd._src.usd.importer"):
            test_concepts_import_only_concepts_below("warp_ccd._src.scene.scene")
    finally:
        GRAPH["warp_ccd._src.scene.scene"] = saved


def test_readme_layout_names_folders_that_exist():
    """The README's layout table, where it has one, names concept folders (not modules), each of which exists."""
    text = open(os.path.join(ROOT, "README.md")).read()
    if "\n## Layout" not in text:
        return
    table = text.split("\n## Layout", 1)[1].split("\n## ", 1)[0]
    for row in table.splitlines():
        if row.startswith("| `"):
            name = row.split("|")[1].strip().strip("`").rstrip("/")
            assert os.path.isdir(os.path.join(ROOT, name)), f"README's layout names {name!r}, not a folder"
