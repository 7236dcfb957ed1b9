"""Build hooks of the documentation site (``mkdocs.yml``: ``hooks``).

The site's pages live in ``docs/site/``; the pictures of ``docs/``, the benchmarks' plots and the README stay
where the repository keeps them, and the site reads them from there:

* :func:`on_files` serves the pictures of ``docs/`` under ``docs/`` of the site and the plots of
  ``bench/results/`` under ``bench/results/``, so the paths the README writes (``docs/preview.png``,
  ``bench/results/scaling_cuda0.png``) name the same files on the site as in the repository.
* :func:`on_config` lets the docstrings of the modules in :data:`PENDING_DOCSTRINGS` warn without
  failing a strict build, until they are mended.
* :func:`on_page_markdown` replaces a line ``<!-- README: Title -->`` of a page by the README's section of
  that title (its ``## Title`` heading and the text up to the next ``## `` heading; ``<!-- README -->``
  alone: the text before the first one), so the site and the README stay one text.
* Links are written as GitHub reads them: a page's from its place in ``docs/site/``
  (``../preview.png``, ``../../bench/results/scaling_cuda0.png``), the README's from the repository root
  (``docs/site/continuous.md``, ``docs/preview.png``); :func:`site_links` makes them relative to the page on
  the site, so the same files resolve in both.
"""

from __future__ import annotations

import logging
import os
import posixpath
import re

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File, Files
from mkdocs.structure.pages import Page

SERVED = {"docs": (".png", ".gif", ".svg"), "bench/results": (".png",)}
"""Folders of the repository whose files of these extensions the site serves, under the same path (the
example scripts and the benchmarks' JSON it does not)."""

SITE_PAGES = "docs/site/"
"""Where the site's pages are, seen from the repository root (as the README links them)."""

PENDING_DOCSTRINGS = (
    # Modules being reworked, whose docstrings still list several parameters on one line of their Args
    # (griffe: "Parameter 'a, b' does not appear in the function signature"), or an item wrapped onto a line
    # of its own (griffe: "Failed to get 'name: description' pair"). Remove each once mended; the tuple is
    # meant to end empty.
    "warp_ccd/_src/check/batch.py",  # FileResult's Attributes: exit_status's description wrapped at "input,"
)


class _PendingDocstrings(logging.Filter):
    """Logs griffe's warnings about the docstrings of :data:`PENDING_DOCSTRINGS` as information."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno == logging.WARNING and any(f"{path}:" in record.getMessage() for path in PENDING_DOCSTRINGS):
            record.levelno, record.levelname = logging.INFO, "INFO"
        return True


_PENDING_FILTER = _PendingDocstrings()

README_SECTION = re.compile(r"^<!-- README(?:: (?P<title>.+?))? -->$", re.MULTILINE)


def _repository(config: MkDocsConfig) -> str:
    return os.path.dirname(config["config_file_path"])


def on_config(config: MkDocsConfig) -> MkDocsConfig:
    """Installs the filter of :data:`PENDING_DOCSTRINGS` on griffe's logger (as mkdocstrings names it)."""
    logging.getLogger("mkdocs.plugins.griffe").addFilter(_PENDING_FILTER)
    return config


def on_files(files: Files, config: MkDocsConfig) -> Files:
    """Adds the pictures of ``docs/`` and the plots of ``bench/results/`` to the site, under the same paths."""
    root = _repository(config)
    for folder, extensions in SERVED.items():
        for name in sorted(os.listdir(os.path.join(root, folder))):
            path = os.path.join(root, folder, name)
            if os.path.isfile(path) and name.endswith(extensions):
                files.append(File.generated(config, f"{folder}/{name}", abs_src_path=path))
    return files


def readme_section(readme: str, title: str | None) -> str:
    """The README's section ``title`` (heading included), or its text before the first section (None).

    Raises:
        PluginError: the README has no section of that title.
    """
    parts = re.split(r"^(?=## )", readme, flags=re.MULTILINE)
    if title is None:
        return parts[0].strip()
    for part in parts[1:]:
        if part.splitlines()[0][3:].strip() == title:
            return part.strip()
    raise PluginError(f"README.md has no section '## {title}'")


LINK = re.compile(r"(\]\()([^)\s]+)(\))")
"""A Markdown link's or picture's target: ``](target)``."""


def site_links(text: str, page: str, base: str) -> str:
    """``text``'s relative link targets, written from the repository folder ``base`` (``""``: the root, as the
    README writes them; ``docs/site``: a page of the site, as GitHub reads it), made relative to the site page
    ``page`` (its path under ``docs/site/``). A target under ``docs/site/`` is that site page; any other path
    (a picture of ``docs/``, a plot of ``bench/results/``) is served under its repository path (:func:`on_files`).
    Addresses (``https:``), anchors, absolute paths and fenced code are left as they are."""
    start = posixpath.dirname(page) or "."

    def relative(m: re.Match) -> str:
        target = m[2]
        if re.match(r"[a-z][a-z0-9+.-]*:|[#/]", target):
            return m[0]
        path, sep, anchor = target.partition("#")
        path = posixpath.normpath(posixpath.join(base, path))
        path = path.removeprefix(SITE_PAGES)
        return f"{m[1]}{posixpath.relpath(path, start)}{sep}{anchor}{m[3]}"

    parts = re.split(r"(^```.*?^```)", text, flags=re.MULTILINE | re.DOTALL)  # odd items: fenced code
    return "".join(part if k % 2 else LINK.sub(relative, part) for k, part in enumerate(parts))


def on_page_markdown(markdown: str, page: Page, config: MkDocsConfig, files: Files) -> str:
    """Replaces each ``<!-- README: Title -->`` line by the README's section of that title, and makes the
    page's links, written as GitHub reads them from ``docs/site/``, and the README's, written from the
    repository root, relative to the page on the site (:func:`site_links`)."""
    src = page.file.src_uri
    base = posixpath.dirname(SITE_PAGES + src)
    markdown = site_links(markdown, src, base)
    if not README_SECTION.search(markdown):
        return markdown
    with open(os.path.join(_repository(config), "README.md"), encoding="utf-8") as fh:
        readme = fh.read()
    return README_SECTION.sub(lambda m: site_links(readme_section(readme, m["title"]), src, ""), markdown)
