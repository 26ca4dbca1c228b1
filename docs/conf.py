# SPDX-License-Identifier: LicenseRef-tofmat-proprietary
# Sphinx configuration of tofmat's documentation site: `make docs` (mk/docs.mk) builds it into
# build/docs with warnings as errors. The pages are the Markdown files of docs/ (MyST), the user
# guide in docs/guide/, the API reference in docs/api/ (autodoc) and the `tofmat` command's
# reference (sphinx-click).
from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.util.docutils import SphinxDirective

DOCS = Path(__file__).resolve().parent
SDK = DOCS.parent / "sdk" / "tofmat"


def _import_sdk_from_checkout() -> None:
    """Import ``tofmat`` from this checkout's sdk/tofmat, with the compiled extension
    (tofmat._tofmat) and the files the build adds (bin/, sim_data/) from the installed SDK.

    The API reference then shows the docstrings of the Python sources as they are in the checkout,
    without a reinstall; the extension's docstrings are those of the installed build
    (`make build-python` rebuilds it).
    """
    installed = importlib.util.find_spec("tofmat")
    if installed is None or not installed.submodule_search_locations:
        raise RuntimeError("the tofmat SDK is not installed: make build-python (pip install ./sdk)")
    search = [str(SDK), *installed.submodule_search_locations]
    spec = importlib.util.spec_from_file_location("tofmat", SDK / "__init__.py", submodule_search_locations=search)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["tofmat"] = module
    spec.loader.exec_module(module)


_import_sdk_from_checkout()
import tofmat  # noqa: E402  (the checkout's, imported above)

project = "tofmat"
author = "the tofmat developers"
copyright = "the tofmat developers"
release = tofmat.__version__
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx_click",
]

source_suffix = {".md": "markdown"}
root_doc = "index"
# docs/ also holds files that are not pages: the man pages (troff, formatted into manpages.md),
# the figures, the simulator's calibration log (linked as a download) and the pins of this build.
exclude_patterns = [
    "man/**",
    "img/**",
    "sim_calibration_log.txt",
    "requirements.txt",
]

# MyST: GitHub-style anchors for headings down to ###, so `protocol.md#roles` links resolve as
# they do on the forge; `$` maths is not used (the pages write formulas as code).
myst_heading_anchors = 3

# autodoc: members in source order, type hints in the description (the signatures stay short).
autodoc_typehints = "description"
autodoc_member_order = "bysource"
# The extension's constructors carry their signature and arguments in __init__'s docstring.
autoclass_content = "both"
autodoc_default_options = {"members": True}

# The SDK's docstrings and the click commands' help write `code` with single backticks, which
# reStructuredText would read as a title: show it as code.
default_role = "literal"

html_theme = "alabaster"
html_title = f"tofmat {release}"
html_theme_options = {
    "description": "Material classification from Time-of-Flight depth distortion",
    "page_width": "1140px",
    "sidebar_width": "240px",
    "fixed_sidebar": True,
    "code_font_size": "0.8em",
}
html_sidebars = {"**": ["about.html", "navigation.html", "relations.html", "searchbox.html"]}
html_show_sourcelink = False


class ManPage(SphinxDirective):
    """``{man-page} man/tofmatd.8``: the man page as `man` shows it (groff's text output, 78 columns),
    as a literal block, so the site carries the daemon's reference without a second copy of it.
    groff's warnings are the build's (``groff -man -ww``), so a man page that does not format well
    fails `make docs` as it fails the man pages' own check."""

    required_arguments = 1

    def run(self) -> list[nodes.Node]:
        rel, path = self.env.relfn2path(self.arguments[0], self.env.docname)
        self.env.note_dependency(rel)
        groff = shutil.which("groff")
        if groff is None:
            raise self.error("man-page needs groff (Debian: apt-get install groff-base)")
        # -P-cbou: plain text, no overstrike bold or underline; -ww: every warning.
        run = subprocess.run(
            [groff, "-man", "-Tutf8", "-P-cbou", "-ww", path],
            capture_output=True,
            text=True,
            env={"PATH": "/usr/bin:/bin", "LC_ALL": "C.UTF-8"},
            check=False,
        )
        if run.returncode != 0 or run.stderr.strip():
            raise self.error(f"groff on {rel}: {run.stderr.strip() or f'exit status {run.returncode}'}")
        text = "\n".join(line.rstrip() for line in run.stdout.strip("\n").splitlines())
        block = nodes.literal_block(text, text, classes=["man-page"])
        block["language"] = "none"
        return [block]


# The extension's (pybind11's) signatures, in the words a user of the package reads them: without
# `self`, with `tofmat.` for the private module `tofmat._tofmat`, and with the numbers pybind11
# accepts (`typing.SupportsFloat | typing.SupportsIndex`) written as the plain types they are.
_PYBIND_TYPES = {
    "tofmat._tofmat.": "tofmat.",
    "typing.SupportsFloat | typing.SupportsIndex": "float",
    "typing.SupportsInt | typing.SupportsIndex": "int",
    "collections.abc.": "",
    "numpy.typing.NDArray[numpy.float64]": "numpy.ndarray[float64]",
    "numpy.typing.NDArray[numpy.float32]": "numpy.ndarray[float32]",
    "numpy.typing.NDArray": "numpy.ndarray",
}


def _plain_types(text: str) -> str:
    for long, short in _PYBIND_TYPES.items():
        text = text.replace(long, short)
    return text


def _is_extension(obj: object) -> bool:
    module = getattr(obj, "__module__", None) or getattr(getattr(obj, "__objclass__", None), "__module__", "")
    return module == "tofmat._tofmat" or type(obj).__name__ in ("instancemethod", "builtin_function_or_method")


def _pybind_signature(
    app: Sphinx, what: str, name: str, obj: object, options: Any, signature: str | None, return_annotation: str | None
) -> tuple[str | None, str | None] | None:
    if signature is None or not name.startswith("tofmat.") or not _is_extension(obj):
        return None
    inner = signature[1:-1]
    if inner.startswith("self"):  # self: tofmat._tofmat.X[, ...]
        inner = inner.partition(", ")[2] if ", " in inner else ""
    return f"({_plain_types(inner)})", _plain_types(return_annotation) if return_annotation else return_annotation


def _pybind_property_type(app: Sphinx, what: str, name: str, obj: object, options: Any, lines: list[str]) -> None:
    """A pybind11 property's type is only in its getter's docstring, "(arg0: X) -> TYPE": show it."""
    getter = getattr(obj, "fget", None)
    doc = getattr(getter, "__doc__", None) or ""
    if what != "property" or type(getter).__name__ != "builtin_function_or_method" or " -> " not in doc:
        return
    kind = _plain_types(doc.splitlines()[0].rpartition(" -> ")[2].strip())
    lines[:] = [f"``{kind}``" + (f": {lines[0]}" if lines else ""), *lines[1:]]


def _no_type_docstring(app: Sphinx, what: str, name: str, obj: object, options: Any, lines: list[str]) -> None:
    """A constant without a doc comment gets its type's docstring from autodoc (tuple's, str's): drop it,
    the page says what the constant is."""
    if (
        what in ("data", "attribute")
        and lines
        and type(obj).__doc__
        and "\n".join(lines).strip() == "\n".join(line.strip() for line in type(obj).__doc__.strip().splitlines())
    ):
        lines.clear()


def setup(app: Sphinx) -> dict[str, Any]:
    app.add_directive("man-page", ManPage)
    app.connect("autodoc-process-signature", _pybind_signature)
    app.connect("autodoc-process-docstring", _pybind_property_type)
    app.connect("autodoc-process-docstring", _no_type_docstring)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
