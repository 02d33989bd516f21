# SPDX-License-Identifier: Apache-2.0
"""Sphinx configuration of the leadscrew_ros documentation (the layout rosdoc2 expects: doc/).

    sphinx-build -W --keep-going -b html doc doc/_build/html      # the site
    sphinx-build -W -b doctest doc doc/_build/doctest             # the pages' code examples

The parameter and topic tables are not pasted into the pages: on `builder-inited` this file
runs tools/param_tables.py's `write`, which renders them from the settings' field metadata into
doc/reference/_generated/*.md (git-ignored); the pages include those files. The API reference
is autosummary with `:recursive:` over the package (stubs in doc/reference/api/_autosummary,
git-ignored), so a new or split module appears without a list to maintain.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

DOC = Path(__file__).resolve().parent
ROOT = DOC.parent
sys.path.insert(0, str(ROOT))  # the package and tools/ from this checkout

project = "leadscrew_ros"
author = "leadscrew_ros maintainers"
copyright = "leadscrew_ros maintainers, Apache-2.0"
release = re.search(r"<version>([^<]+)</version>", (ROOT / "package.xml").read_text()).group(1)
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.doctest",
    "numpydoc",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "**/_generated", "Thumbs.db", ".DS_Store"]
myst_enable_extensions: list[str] = []
myst_heading_anchors = 3

# API: autosummary recursive over leadscrew_ros (doc/reference/api.rst), numpydoc docstrings.
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_typehints = "none"  # the numpydoc Parameters sections carry the types
numpydoc_show_class_members = False  # autodoc lists the members; no second table
numpydoc_class_members_toctree = False
numpydoc_validation_checks: set[str] = set()


def _compile_numpydoc_template_once() -> None:
    """numpydoc makes a template environment per docstring and compiles its one template in
    each (a quarter of this site's build time, ~6000 docstrings): keep the first compiled."""
    import numpydoc.docscrape_sphinx as docscrape_sphinx

    class OnceCompiled(docscrape_sphinx.SandboxedEnvironment):
        compiled: dict = {}

        def get_template(self, name, *args, **kwargs):  # type: ignore[no-untyped-def]
            if name not in self.compiled:
                self.compiled[name] = super().get_template(name, *args, **kwargs)
            return self.compiled[name]

    docscrape_sphinx.SandboxedEnvironment = OnceCompiled  # type: ignore[misc]


_compile_numpydoc_template_once()

# doctest: the pages' examples run against this checkout, with a plain Matplotlib backend.
doctest_global_setup = """
import os
os.environ.setdefault("MPLBACKEND", "Agg")
"""

html_theme = "sphinx_rtd_theme"
html_static_path = ["_static"]
html_css_files = ["readable.css"]  # tables and code fit the column at 1280 px
html_title = f"leadscrew_ros {release}"


def _write_tables(app) -> None:
    """Render the parameter and topic tables into doc/reference/_generated/ (builder-inited)."""
    spec = importlib.util.spec_from_file_location(
        "param_tables", ROOT / "tools" / "param_tables.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.write(DOC / "reference" / "_generated")


_BAR = re.compile(r"(?<!\\)\|")


def _plain_bars(app, what, name, obj, options, lines) -> None:
    """The docstrings write absolute values as plain text, |Vc|, |F_z|: escape each '|' outside
    code spans so that reST does not read |...| as a substitution (autodoc-process-docstring;
    a table's row or border and a doctest example stay as they are)."""
    in_example = False  # a doctest (>>> and its expected output, up to a blank line) is code
    for i, line in enumerate(lines):
        bare = line.strip()
        in_example = bare.startswith(">>>") or (in_example and bool(bare))
        if (
            in_example
            or "|" not in line
            or bare.startswith(("+-", "+="))
            or (bare.startswith("| ") and bare.endswith(" |"))
        ):
            continue
        parts = line.split("`")
        lines[i] = "`".join(p if k % 2 else _BAR.sub(r"\\|", p) for k, p in enumerate(parts))


def setup(app):
    """Sphinx extension entry point: tables before the build, plain bars in docstrings."""
    app.connect("builder-inited", _write_tables)
    app.connect("autodoc-process-docstring", _plain_bars)
    return {"parallel_read_safe": True}
