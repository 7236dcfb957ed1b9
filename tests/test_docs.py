"""The documentation site's sources hold together (``mkdocs.yml``, ``docs/site/``), without building it.

CI builds the site with ``mkdocs build --strict`` (``.ci/run``); these checks are the cheap part: every
page of the nav exists, every README section a page includes exists, every relative link of a page names a
file of the repository (as GitHub reads it), and every public name of the top level and every public
namespace has its place in the API reference.

And every ```` ```python ```` block of every page runs as it stands, as the README's do
(``tests/test_readme.py``): on a machine without a GPU, naming no CUDA device, defining what it uses. The
blocks of a page run in order in one temporary folder, so a block may read a file an earlier block of its
page wrote (the USD check's page checks the animation its first block writes), never a name. The
``exec="on"`` blocks, which the site runs as it is built, run here too.
"""

import importlib.util
import os
import re

import pytest
import yaml
from test_readme import python_blocks, run_blocks

import warp_ccd

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NAMESPACES = ("scene", "stages", "geometry", "usd", "preview", "bench", "trimesh")


def load_config() -> dict:
    with open(os.path.join(ROOT, "mkdocs.yml"), encoding="utf-8") as fh:
        return yaml.safe_load(fh)


CONFIG = load_config()
DOCS_DIR = os.path.join(ROOT, CONFIG["docs_dir"])


def nav_pages(nav) -> list[str]:
    """Every page path of a nav, in order."""
    out = []
    for item in nav:
        value = next(iter(item.values())) if isinstance(item, dict) else item
        out.extend(nav_pages(value) if isinstance(value, list) else [value])
    return out


def page_file(page: str) -> str:
    """The file of a nav page: in ``docs/site/``, or in ``docs/`` for ``docs/...`` (served by the hooks)."""
    if page.startswith("docs/"):
        return os.path.join(ROOT, page)
    return os.path.join(DOCS_DIR, page)


def read(page: str) -> str:
    with open(page_file(page), encoding="utf-8") as fh:
        return fh.read()


def load_hooks():
    pytest.importorskip("mkdocs", reason="the site's hooks need mkdocs (a test extra)")
    path = os.path.join(ROOT, CONFIG["hooks"][0])
    spec = importlib.util.spec_from_file_location("site_hooks", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


PAGES = nav_pages(CONFIG["nav"])
API_PAGES = [p for p in PAGES if p.startswith("api/")]


def test_nav_pages_exist():
    assert len(PAGES) >= 5 and "index.md" in PAGES
    missing = [p for p in PAGES if not os.path.isfile(page_file(p))]
    assert not missing, f"pages in mkdocs.yml's nav that do not exist: {missing}"


def test_every_page_is_in_the_nav():
    """A page written under docs/site/ but left out of the nav would be built and never reached."""
    on_disk = {os.path.relpath(os.path.join(folder, f), DOCS_DIR).replace(os.sep, "/")
               for folder, _, files in os.walk(DOCS_DIR) for f in files if f.endswith(".md")}
    assert sorted(on_disk - set(PAGES)) == []


def test_readme_sections_included_exist():
    """Each ``<!-- README: Title -->`` of a page names a section of the README (renaming one breaks it)."""
    hooks = load_hooks()
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        readme = fh.read()
    found = 0
    for page in PAGES:
        for m in hooks.README_SECTION.finditer(read(page)):
            assert hooks.readme_section(readme, m["title"]).strip(), (page, m["title"])
            found += 1
    assert found >= 1


SITE_PAGES = [p for p in PAGES if not p.startswith("docs/")]
"""The nav's pages under ``docs/site/`` (their links are read as GitHub reads them, from their folder)."""


@pytest.mark.parametrize("page", SITE_PAGES)
def test_page_links_name_files_that_exist(page):
    """A relative link or picture of a page names a file of the repository from the page's folder (so it works
    on GitHub; the site's hooks serve the same files, :func:`site_links`)."""
    text = re.sub(r"^```.*?^```", "", read(page), flags=re.S | re.M)
    folder = os.path.dirname(page_file(page))
    targets = [t.split("#")[0] for t in re.findall(r"\]\(([^)\s]+)\)", text)
               if not re.match(r"[a-z][a-z0-9+.-]*:|[#/]", t)]
    missing = [t for t in targets if not os.path.isfile(os.path.normpath(os.path.join(folder, t)))]
    assert not missing, f"{page} links to files that do not exist: {missing}"


PAGES_WITH_CODE = [p for p in SITE_PAGES if python_blocks(read(p))]


def test_pages_have_code():
    """The guard of the parametrised test below: the pages that teach the API have blocks to run."""
    assert {"pipeline.md", "continuous.md", "clearance.md", "check.md", "kernels.md"} <= set(PAGES_WITH_CODE)


@pytest.mark.parametrize("page", PAGES_WITH_CODE)
def test_page_python_blocks_run_as_pasted(page, tmp_path, monkeypatch):
    blocks = python_blocks(read(page))
    code = "\n".join(blocks)
    if "warp_ccd.usd" in code or "check_usd" in code:
        pytest.importorskip("pxr")
    if re.search(r"^import torch", code, flags=re.M):
        pytest.importorskip("torch")
    monkeypatch.chdir(tmp_path)
    name = re.sub(r"\W", "_", page.removesuffix(".md"))
    run_blocks(blocks, tmp_path, f"docs_{name}")


def test_top_level_names_in_the_api_reference():
    """Every name of ``warp_ccd.__all__`` is a member of the ``::: warp_ccd`` block or linked from the page."""
    text = read("api/index.md")
    block = text.split("::: warp_ccd\n", 1)[1].split("\n\n", 1)[0]
    members = set(re.findall(r"^\s+- (\w+)$", block, flags=re.MULTILINE))
    linked = set(re.findall(r"\[`warp_ccd\.(\w+)`\]\[", text))
    missing = sorted(set(warp_ccd.__all__) - members - linked)
    assert not missing, f"names of warp_ccd.__all__ missing from docs/site/api/index.md: {missing}"
    unknown = sorted((members | linked) - set(warp_ccd.__all__))
    assert not unknown, f"docs/site/api/index.md names what warp_ccd.__all__ does not: {unknown}"


def test_every_namespace_has_its_api_page():
    text = "\n".join(read(p) for p in API_PAGES)
    missing = [ns for ns in NAMESPACES if not re.search(rf"^::: warp_ccd\.{ns}$", text, flags=re.MULTILINE)]
    assert not missing, f"public namespaces without a ::: block in the API reference: {missing}"
