"""Build hooks of the documentation site (``mkdocs.yml``: ``hooks``).

The site's pages live in ``docs/site/``; the design notes (``docs/ARCHITECTURE.md``), the pictures of
``docs/`` and the README stay where the repository keeps them, and the site reads them from there:

* :func:`on_files` serves the pages and pictures of ``docs/`` under ``docs/`` of the site, so the links
  the README and ARCHITECTURE.md write (``docs/preview.png``, ``crossing_cases.png``) resolve on the site
  as they do in the repository.
* :func:`on_config` lets the docstrings of the modules in :data:`PENDING_DOCSTRINGS` warn without
  failing a strict build, until they are mended.
* :func:`on_page_markdown` replaces a line ``<!-- README: Title -->`` of a page by the README's section of
  that title (its ``## Title`` heading and the text up to the next ``## `` heading; ``<!-- README -->``
  alone: the text before the first one), so the site and the README stay one text.
"""

from __future__ import annotations

import logging
import os
import re

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File, Files
from mkdocs.structure.pages import Page

SERVED = (".md", ".png", ".gif", ".svg")
"""Extensions of the files of ``docs/`` the site serves (the example scripts it does not)."""

PENDING_DOCSTRINGS = (
    # Modules being reworked, whose docstrings still list several parameters on one line of their Args
    # (griffe: "Parameter 'a, b' does not appear in the function signature"). Remove each once mended;
    # the tuple is meant to end empty.
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
    """Adds every page and picture of ``docs/`` to the site, under ``docs/``."""
    folder = os.path.dirname(os.path.normpath(config["docs_dir"]))
    for name in sorted(os.listdir(folder)):
        path = os.path.join(folder, name)
        if os.path.isfile(path) and name.endswith(SERVED):
            files.append(File.generated(config, f"docs/{name}", abs_src_path=path))
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


def on_page_markdown(markdown: str, page: Page, config: MkDocsConfig, files: Files) -> str:
    """Replaces each ``<!-- README: Title -->`` line by the README's section of that title."""
    if not README_SECTION.search(markdown):
        return markdown
    with open(os.path.join(_repository(config), "README.md"), encoding="utf-8") as fh:
        readme = fh.read()
    return README_SECTION.sub(lambda m: readme_section(readme, m["title"]), markdown)
