"""MkDocs hooks (``mkdocs.yml``: ``hooks:``): add the generated pages of :mod:`tools.docs_gen` to
the build and list the API modules in the navigation.

Nothing is written into ``docs/``: the pages exist only in the build, so the parsers, the
parameter tables and the docstrings stay their only owners.
"""

from __future__ import annotations

import sys
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:         # mkdocs loads this file by path; the generators import the packages
    sys.path.insert(0, str(ROOT))

from tools import docs_gen  # noqa: E402

_PAGES: dict[str, str] = {}


def on_config(config, **kwargs):
    """Make the pages once per build and put the API modules under the nav's "Python API" entry."""
    _PAGES.clear()
    _PAGES.update(docs_gen.generated_pages())
    api = docs_gen.api_nav()        # the public API first, every module after it by package

    def walk(items):
        for i, item in enumerate(items):
            if isinstance(item, dict):
                for key, value in item.items():
                    if value == "reference/api/index.md":
                        items[i] = {key: api}
                    elif isinstance(value, list):
                        walk(value)
    walk(config["nav"])
    return config


def on_files(files, config, **kwargs):
    for path, text in _PAGES.items():
        files.append(File.generated(config, path, content=text))
    for path, source in docs_gen.copied_files().items():
        files.append(File.generated(config, path, abs_src_path=str(source)))
    return files


def on_page_content(html, page, config, files):
    """The docstrings' reST roles (``:mod:`x```) shown as plain code."""
    return docs_gen.strip_roles(html)
