"""Sphinx configuration of the uqgear documentation.

Build: ``pip install -e ".[docs]"`` then ``sphinx-build -W -b html docs docs/_build/html``.
The gallery scripts in ``examples/`` run at build time (sphinx-gallery) and their
figures and printed numbers appear on the pages. The API pages are written here,
before the build, from ``uqgear.__all__`` and each subpackage's ``__all__``, so a
public name cannot be left out of the reference.
"""

from __future__ import annotations

import importlib
import os
import shutil
import sys
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("UQGEAR_PROGRESS", "0")

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))

import uqgear  # noqa: E402

project = "uqgear"
author = "uqgear developers"
copyright = "2026, uqgear developers"
release = uqgear.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = [
    "_build",
    "**.ipynb_checkpoints",
    "auto_examples/*.ipynb",
    "auto_examples/*.py",
    "auto_examples/*.zip",
    "auto_examples/*.md5",
    "auto_examples/*.json",
    "auto_examples/*.codeobj.json",
    "api/generated/*.examples",
]
myst_heading_anchors = 4
myst_enable_extensions = ["colon_fence", "deflist"]

# ------------------------------------------------------------------ API reference
autosummary_generate = True
autodoc_typehints = "none"  # numpydoc puts the types in the parameter lists
autodoc_member_order = "bysource"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

#: The subpackages along the data path, in the order the reference lists them.
SUBPACKAGES = (
    "common",
    "physics",
    "dynamics",
    "uq",
    "report",
    "rig",
    "calibration",
    "diagnosis",
    "study",
)


def _api_pages() -> None:
    """Write ``api/index.rst`` and one page per subpackage from the ``__all__`` lists."""
    api = DOCS / "api"
    # autosummary writes a page per listed name into api/generated; pages of names no longer
    # listed would stay behind as orphans, so the folder is made afresh
    shutil.rmtree(api / "generated", ignore_errors=True)
    api.mkdir(exist_ok=True)
    lines = [
        "API reference",
        "=============",
        "",
        "Everything ``import uqgear`` offers, then each subpackage's public names along the data "
        "path. Each name links to its page, generated from its docstring.",
        "",
        ".. currentmodule:: uqgear",
        "",
        "Top level (``uqgear``)",
        "----------------------",
        "",
        ".. autosummary::",
        "   :toctree: generated",
        "",
    ]
    top = [name for name in uqgear.__all__ if not name.startswith("__")]
    lines += [f"   {name}" for name in top]
    lines += ["", ".. toctree::", "   :maxdepth: 1", "   :caption: Subpackages", ""]
    lines += [f"   {name}" for name in SUBPACKAGES]
    _write_if_changed(api / "index.rst", "\n".join(lines) + "\n")
    for name in SUBPACKAGES:
        module = importlib.import_module(f"uqgear.{name}")
        # a name ``import uqgear`` also offers has its page at the top level (one page per object)
        shared = [
            member
            for member in module.__all__
            if getattr(uqgear, member, None) is getattr(module, member)
        ]
        own = [member for member in module.__all__ if member not in shared]
        title = f"``uqgear.{name}``"
        body = [
            title,
            "=" * len(title),
            "",
            f".. automodule:: uqgear.{name}",
            "   :no-members:",
            "",
            f".. currentmodule:: uqgear.{name}",
            "",
        ]
        if own:
            body += (
                [".. autosummary::", "   :toctree: generated", ""]
                + [f"   {member}" for member in own]
                + [""]
            )
        if shared:
            body += [
                "Also in this subpackage, documented at the top level: "
                + ", ".join(f":obj:`uqgear.{member}`" for member in shared)
                + "."
            ]
        _write_if_changed(api / f"{name}.rst", "\n".join(body) + "\n")


def _write_if_changed(path: Path, text: str) -> None:
    # an unchanged page keeps its time stamp, so an incremental build does not redo it
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


_api_pages()

# ------------------------------------------------------------------ gallery
sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "abort_on_example_error": True,
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "image_scrapers": ("matplotlib",),
    "matplotlib_animations": False,
    "show_memory": False,
    "plot_gallery": "True",
}

# ------------------------------------------------------------------ HTML
html_theme = "pydata_sphinx_theme"
html_title = f"uqgear {release}"
html_static_path = ["_static"]
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": [],
}
html_show_sourcelink = False
