"""Sphinx configuration of the drake_hybrid documentation site.

Build it (from the repository's root)::

    pip install ".[docs]"
    python -m sphinx -W --keep-going -n -b html docs docs/_build/html

Pages are Markdown (MyST) and the tutorials' notebooks (myst-nb, never executed by the build: it
renders the copies ``tests/test_notebooks.py`` saved when it ran them, see ``tutorial_sources``);
the reference is generated from the docstrings (autodoc and autosummary over the whole package, so
a module or name added later appears without editing these pages), with Drake's
``.. pydrake_system::`` port blocks drawn by ``docs/_ext/pydrake_system.py``.
"""

import os
import shutil
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(DOCS))

os.environ.setdefault("MPLBACKEND", "Agg")

from tutorial_sources import stage_tutorials  # noqa: E402

import drake_hybrid  # noqa: E402  (after the path set-up above)

project = "drake_hybrid"
author = "the drake_hybrid developers"
copyright = "the drake_hybrid developers, BSD-3-Clause"
release = version = drake_hybrid.__version__

extensions = [
    "myst_nb",                   # Markdown pages (MyST) and the tutorials' notebooks
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",       # the source of every documented name, in the site (no network)
    "sphinx_copybutton",
    "pydrake_system",            # docs/_ext: .. pydrake_system:: blocks as port diagrams
    "plain_docstrings",          # docs/_ext: the docstrings' plain-text fields and |x| as reST
    "reference_coverage",        # docs/_ext: a public name without a reference entry fails the build
]
pydrake_system_package = reference_coverage_package = "drake_hybrid"
reference_coverage_exclude = ("drake_hybrid.models",)   # the models' data package, not the API
autosummary_context = {"excluded_modules": reference_coverage_exclude}   # docs/_templates/autosummary/module.rst

source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
root_doc = "index"
templates_path = ["_templates"]
html_static_path = ["_static"]
html_css_files = ["site.css"]          # docs/_static/site.css: the pictures side by side (.figure-row)
exclude_patterns = ["_build", "_ext", "_templates", "**/.ipynb_checkpoints", "sweeps", "*.py", "*.json"]

html_theme = "furo"
html_title = f"drake_hybrid {release}"
html_logo = None
html_show_sourcelink = False

# Warnings are errors in CI (-W); nitpicky (-n) cross-references, except targets outside this
# project that no inventory here documents (the build reads no inventory over the network).
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(pydrake|numpy|np|scipy|sympy|dask|distributed|matplotlib|typing|collections|enum|pathlib|abc|os)\..*"),
    (r"py:.*", r"(drake_hybrid\.station\.ports\.)?SystemType"),     # a type variable of the annotations
    (r"py:.*", r"(Union|List|Dict|Tuple|Optional|Callable|Sequence|Mapping|Iterable|Any|NamedTuple)(\[.*)?"),
    (r"py:.*", r"(float|int|str|bool|object|list|dict|tuple|type|callable|optional|ndarray|array_like)"),
]

# The annotations' private type variables (e.g. drake_hybrid.core.errors._Owner) have no page of their own.
nitpick_ignore_regex.append((r"py:.*", r"drake_hybrid\.[\w.]*\._\w+"))

myst_enable_extensions = ["dollarmath", "colon_fence", "deflist", "attrs_inline"]
myst_heading_anchors = 3
nb_execution_mode = "off"         # the tutorials' outputs come from tests/test_notebooks.py's run
nb_merge_streams = True
nb_output_stderr = "remove"        # progress bars and Drake's log lines: not part of the lesson

# autosummary writes a page per module into docs/reference/generated/ (git-ignored; Sphinx reads
# sources only from docs/). Every build writes them again from clean: a page kept from an earlier
# build (a module since moved or removed, or a build that imported another copy of the package)
# would otherwise be read, and fail to import, under -W.
GENERATED_REFERENCE = DOCS / "reference" / "generated"
shutil.rmtree(GENERATED_REFERENCE, ignore_errors=True)
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "undoc-members": True, "show-inheritance": True,
                           "member-order": "bysource"}
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
add_module_names = False
autoclass_content = "both"

stage_tutorials(ROOT / "tutorials", DOCS / "tutorials",
                executed=Path(os.environ.get("DRAKE_HYBRID_EXECUTED_TUTORIALS", DOCS / "_build" / "executed_tutorials")),
                require_outputs=os.environ.get("DRAKE_HYBRID_DOCS_REQUIRE_OUTPUTS") == "1")
