"""Sphinx configuration of the opa-mc documentation.

Build (warnings are errors, as in .ci/run):

    pip install -e '.[docs]'
    sphinx-build -W --keep-going -b html docs build/docs

The tutorials (``tutorials/*.md``, MyST notebooks) are executed at build time by myst-nb,
so their numbers and figures are those of the code as it is.
"""

import os
import re

os.environ.setdefault("MPLBACKEND", "Agg")

project = "opa-mc"
author = "the opa-mc developers"
copyright = "opa-mc developers"

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "numpydoc",
]

# the pages are MyST markdown; the tutorials are MyST notebooks run at build time
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
nb_execution_mode = "force"
nb_execution_timeout = 600
nb_execution_raise_on_error = True
nb_merge_streams = True

exclude_patterns = ["_build", "jupyter_execute", "*.py", "images/README*"]

# numpydoc renders the docstrings; the class pages list only what autodoc asks for
numpydoc_show_class_members = False
numpydoc_xref_param_type = False
autodoc_member_order = "bysource"
autodoc_typehints = "none"

html_theme = "alabaster"
html_title = "opa-mc"
html_theme_options = {"description": "OPA against Monte Carlo for vibro-impact oscillators",
                      "fixed_sidebar": True}


def _plain_docstring(app, what, name, obj, options, lines):
    """The docstrings are written to be read as text: a shape ``(*B, q)``, an absolute value
    ``|x|`` and a literal broken over two lines of a numpydoc field are not reST markup.
    Literals, ``:math:`` roles and ``.. math::`` blocks are left as they are."""
    open_literal = False
    math_indent = None  # the indentation of the ``.. math::`` directive we are inside
    for i, line in enumerate(lines):
        indent = len(line) - len(line.lstrip())
        if math_indent is not None:
            if not line.strip() or indent > math_indent:
                continue
            math_indent = None
        if line.strip().startswith(".. math::"):
            math_indent = indent
            continue
        if open_literal:
            line = re.sub(r"^(\s*)", r"\1``", line, count=1)
            open_literal = False
        if line.count("``") % 2:
            line += "``"
            open_literal = True
        parts = re.split(r"(``.*?``|:math:`[^`]*`)", line)
        for j in range(0, len(parts), 2):  # outside literals and math only
            text = parts[j]
            text = re.sub(r"(?<!\\)\|", r"\\|", text)
            text = re.sub(r"(?<=[(, \[])\*(?=\w)(?![^*]*\w\*)", r"\\*", text)
            parts[j] = text
        lines[i] = "".join(parts)


def setup(app):
    app.connect("autodoc-process-docstring", _plain_docstring, priority=100)
