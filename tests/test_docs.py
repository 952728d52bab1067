"""The documentation site builds and its reference cannot go stale.

``mkdocs build --strict`` (mkdocs.yml: mkdocs-material, mkdocstrings from the docstrings) runs
once per session into a temporary folder; a docstring that breaks the reference, a broken link
between pages or a public name missing from the reference fails here. The public names are the
packages' ``__all__``, which must list exactly the public non-module names each package defines
or re-exports (checked here from the imported modules), independently of how the reference pages
list them. The reST-to-Markdown rewriting
of ``docs/griffe_rst.py`` is checked on hand-written docstrings.
"""

from __future__ import annotations

import __future__
import html
import importlib
import importlib.util
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# module -> its reference page (docs/reference/<page>.md, built as reference/<page>/index.html)
REFERENCE = {
    "layerstack_jax": "layerstack_jax",
    "layerstack_jax.io": "io",
    "fitting": "fitting",
    "layerstack_jax.render": "render",
}


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    missing = [m for m in ("mkdocs", "mkdocstrings", "material") if importlib.util.find_spec(m) is None]
    assert not missing, f"{missing} not installed: pip install -e '.[docs]' (make install does)"
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-5000:]}"
    return out


def public_names(module_name: str) -> list[str]:
    module = importlib.import_module(module_name)
    assert hasattr(module, "__all__"), f"{module_name} has no __all__"
    return list(module.__all__)


@pytest.mark.parametrize("module_name", list(REFERENCE))
def test_all_lists_exactly_the_public_names(module_name):
    module = importlib.import_module(module_name)
    names = public_names(module_name)
    defined = {n for n, v in vars(module).items() if not n.startswith("_") and not inspect.ismodule(v)
               and not isinstance(v, __future__._Feature)}
    assert len(names) == len(set(names)), f"{module_name}.__all__ has duplicates"
    assert set(names) == defined, (f"{module_name}.__all__ vs its public names: missing {sorted(defined - set(names))}, "
                                   f"not defined {sorted(set(names) - defined)}")


def page_text(site: Path, page: str) -> str:
    return (site / page / "index.html").read_text(encoding="utf-8")


def test_pages_built(site):
    for page in ["", "physics", "architecture", *(f"reference/{p}" for p in REFERENCE.values()), "reference/cli"]:
        assert (site / page / "index.html").is_file(), f"page {page or 'index'} not built"


@pytest.mark.parametrize("module_name", list(REFERENCE))
def test_every_public_name_in_reference(site, module_name):
    names = public_names(module_name)
    assert names, f"{module_name} exports nothing"
    ids = set(re.findall(r'id="([^"]+)"', page_text(site, f"reference/{REFERENCE[module_name]}")))
    missing = [n for n in names if f"{module_name}.{n}" not in ids]
    assert not missing, f"public names of {module_name} missing from its reference page: {missing}"


def test_key_entries_rendered_from_docstrings(site):
    text = html.unescape(re.sub(r"<[^>]+>", "", page_text(site, "reference/layerstack_jax")))
    # the opening words of each docstring (up to the first markup), as written in the source
    for name in ("reflectance", "specular", "Stack"):
        doc = inspect.getdoc(getattr(importlib.import_module("layerstack_jax"), name))
        first = re.split(r"[`:$*\n]", doc)[0].strip()
        assert len(first) >= 10 and first in text, f"docstring of {name} not rendered ({first!r})"
    fitting_text = page_text(site, "reference/fitting")
    assert 'id="fitting.Objective"' in fitting_text and 'id="fitting.fit_batch"' in fitting_text


def test_no_raw_rest_roles_left(site):
    for page in REFERENCE.values():
        text = page_text(site, f"reference/{page}")
        roles = re.findall(r":(?:math|func|class|meth|attr|data|mod|exc):<code>", text)
        assert not roles, f"reference/{page}: reST roles printed verbatim: {roles[:5]}"
        assert ".. math::" not in text, f"reference/{page}: a .. math:: block printed verbatim"
    assert 'class="arithmatex"' in page_text(site, "reference/layerstack_jax"), "no math rendered"


def test_cli_page_has_help_of_every_command(site):
    text = html.unescape(page_text(site, "reference/cli"))
    for command in ("predict", "fit", "fit-cube", "design"):
        assert f"usage: layerstack {command}" in text, f"`layerstack {command} --help` missing"


# -- docs/griffe_rst.py on hand-written docstrings (expected Markdown written out by hand) ---------

@pytest.fixture(scope="module")
def rst_to_markdown():
    spec = importlib.util.spec_from_file_location("griffe_rst", ROOT / "docs" / "griffe_rst.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.rst_to_markdown


def test_roles_to_markdown(rst_to_markdown):
    doc = "Index :math:`\\tilde n = n + ik` of\n:func:`~layerstack_jax.specular`, see :class:`a.Stack` and ``x``."
    assert rst_to_markdown(doc) == "Index $\\tilde n = n + ik$ of\n`specular`, see `a.Stack` and ``x``."
    # a role wrapped across lines stays one role
    assert rst_to_markdown(":math:`a +\n    b` end") == "$a +\n    b$ end"


def test_blocks_to_markdown(rst_to_markdown):
    doc = "Sum:\n\n.. math::\n    r = a\n        + b\n\nFile::\n\n    [x]\n      y = 1\n\nEnd :math:`x`."
    assert rst_to_markdown(doc) == "Sum:\n\n$$\nr = a\n+ b\n$$\n\nFile:\n\n```\n[x]\n  y = 1\n```\n\nEnd $x$."


def test_raises_continuation_indented(rst_to_markdown):
    doc = "Raises:\n    LayerstackError: a missing column,\n    a bad unit.\n    OSError: unreadable."
    assert rst_to_markdown(doc) == (
        "Raises:\n    LayerstackError: a missing column,\n        a bad unit.\n    OSError: unreadable.")
