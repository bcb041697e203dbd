"""Sphinx configuration of imu-square's documentation site.

Built by ``python3 dev.py docs`` (into ``docs/_build/html``); CI builds it with
warnings as errors (``-W --keep-going``) and runs the gallery.
"""

import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))

from imu_square import __version__  # noqa: E402

project = "imu-square"
author = "the imu-square authors"
copyright = "the imu-square authors, MIT licence"
release = __version__
version = ".".join(__version__.split(".")[:2])

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",
    "sphinxarg.ext",
    "sphinx_gallery.gen_gallery",
    "imu_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = [
    "_build",
    "_templates",
    "examples/README.rst",
    "auto_examples/*.ipynb",
    "**/*.py.md5",
]
# A class page documents its methods and properties (those with a docstring), so
# numpydoc validates them; a dataclass's fields are under the class's Attributes.
templates_path = ["_templates"]

# MyST: the Markdown pages written before the site (model.md, discrepancy.md,
# protocol.md) render in place; their "#1-overview" style links need heading anchors.
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

# API reference from the numpydoc docstrings.
autosummary_generate = True
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
# Validation of every public object the API reference documents. Left out, each
# for a reason that holds for the whole project:
numpydoc_validation_checks = {
    "all",
    # GL08 (no docstring) is what autodoc shows for a dataclass's generated
    # __init__; every class documents its fields under Attributes instead.
    "GL08",
    # ES01 (no extended summary), SA01 (no See Also), EX01 (no Examples):
    # the gallery holds the worked examples, and a one-line summary that says
    # it all is the project's style (STYLE.md 5).
    "ES01",
    "SA01",
    "EX01",
    # RT02 (the first line of Returns should be the type only): the project
    # names what is returned, "dict of str to str" style, as numpydoc allows.
    "RT02",
    # SS05 (summary starts with an infinitive verb "Return" not "Returns"):
    # the project's summaries say what a function gives ("The argument
    # parser: ..."), a noun phrase, as ObsPy and pvlib do.
    "SS05",
    # SS03, PR09, RT05 (a summary or a description must end with "."): the
    # project puts a quantity's unit in brackets after the sentence,
    # "Nominal sample rate. [Hz]" (STYLE.md 5, as pvlib does).
    "SS03",
    "PR09",
    "RT05",
}
# Checks skipped where a docstring's own shape answers them:
numpydoc_validation_overrides = {
    # A dataclass documents its fields under Attributes, not Parameters.
    "PR01": [r"\n\s*Attributes\n\s*-{3,}\n"],
    # A returned object of a documented class names itself: "Returns / RunResult".
    "RT03": [r"Returns\n\s*-{3,}\n(\s*\w+ : )?\s*[\w.]*[A-Z]\w*(\n|$)"],
}
# What is validated: the public functions and classes the API reference lists, and
# their public methods and properties; a dataclass's generated __init__ is not.
numpydoc_validation_exclude = {r"\.__init__$", r"\.__post_init__$"}

# The gallery: each example runs at every build and its figures are rendered.
sphinx_gallery_conf = {
    "examples_dirs": "examples",
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "within_subsection_order": "FileNameSortKey",
    "abort_on_example_error": True,
    "download_all_examples": False,
    "remove_config_comments": True,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "min_reported_time": 0,
    "show_memory": False,
}

html_theme = "pydata_sphinx_theme"
html_title = f"imu-square {release}"
html_static_path = ["_static"]
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
}
html_sidebars = {"index": [], "whatsnew/*": []}
html_show_sourcelink = False

# No request leaves the build (CI has no network but the package registries).
os.environ.setdefault("MPLBACKEND", "Agg")
