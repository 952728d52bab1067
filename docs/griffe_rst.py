"""Griffe extension: the reST markup of layerstack's docstrings, as Markdown for mkdocstrings.

The docstrings are Google style (``Args:``, ``Returns:`` …, which mkdocstrings parses) with reST
inline roles and blocks, which Markdown would print verbatim. Before rendering, this rewrites

* ``:math:`x``` → ``$x$`` and a ``.. math::`` block → a ``$$ … $$`` block (MathJax through
  ``pymdownx.arithmatex``, generic mode);
* ``:func:`~a.b.f``` / ``:class:`a.B``` / ``:mod:`` … → the code span ```f``` / ```a.B``` (a
  leading ``~`` keeps the last dotted part, as in Sphinx);
* a paragraph ending in ``::`` followed by an indented block → the paragraph ending in ``:`` and a
  fenced code block;
* in a ``Raises:`` section, a wrapped line written at the indentation of the items (not
  ``Error: …``) → indented as the continuation it is (Google style wants it deeper).

``\\`x\\``` (double backticks) is already a Markdown code span. Public names: every documented
package (``layerstack_jax``, ``layerstack_jax.io``, ``layerstack_jax.render``, ``fitting``) lists
them in ``__all__``, which griffe reads as the module's exports.

Loaded by ``mkdocs.yml`` (``plugins: mkdocstrings: handlers: python: options: extensions``).
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_MATH_ROLE = re.compile(r":math:`([^`]+)`")
_XREF_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|attr|data|mod|obj|exc|const):`(~?)([^`]+)`")


def _inline(text: str) -> str:
    text = _MATH_ROLE.sub(lambda m: f"${m.group(1).strip()}$", text)
    return _XREF_ROLE.sub(lambda m: f"`{m.group(2).split('.')[-1] if m.group(1) else m.group(2)}`", text)


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _block(lines: list[str], start: int, indent: int) -> tuple[list[str], int]:
    """The lines from ``start`` indented deeper than ``indent`` (blank lines included, trailing
    blanks excluded), and the index after them."""
    end = start
    while end < len(lines) and (not lines[end].strip() or _indent(lines[end]) > indent):
        end += 1
    while end > start and not lines[end - 1].strip():
        end -= 1
    return lines[start:end], end


_EXCEPTION_ITEM = re.compile(r"^[A-Za-z_][\w.]*\s*:")


def _indent_raises_continuations(lines: list[str]) -> list[str]:
    out: list[str] = []
    item_indent = None  # indentation of the items of the Raises section we are in
    for line in lines:
        if item_indent is not None and line.strip() and _indent(line) < item_indent:
            item_indent = None
        if item_indent is not None and line.strip() and _indent(line) == item_indent \
                and not _EXCEPTION_ITEM.match(line.strip()):
            line = " " * 4 + line
        if line.strip() == "Raises:":
            item_indent = _indent(line) + 4
        out.append(line)
    return out


def rst_to_markdown(doc: str) -> str:
    """Rewrite the reST constructs of one docstring (see the module docstring) as Markdown."""
    lines = _indent_raises_continuations(doc.splitlines())
    # runs of text (roles may wrap across lines) and verbatim blocks (math, code), in order
    runs: list[tuple[bool, list[str]]] = [(False, [])]

    def emit(verbatim: bool, new: list[str]) -> None:
        if runs[-1][0] == verbatim:
            runs[-1][1].extend(new)
        else:
            runs.append((verbatim, list(new)))

    i = 0
    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        indent = _indent(line)
        pad = " " * indent
        if stripped.startswith(".. math::"):
            first = stripped[len(".. math::"):].strip()
            body, i = _block(lines, i + 1, indent)
            equations = ([first] if first else []) + [b.strip() for b in body if b.strip()]
            emit(True, [f"{pad}$$", *(pad + e for e in equations), f"{pad}$$"])
            continue
        if stripped.endswith("::") and not stripped.startswith(".."):
            j = i + 1
            while j < len(lines) and not lines[j].strip():
                j += 1
            if j < len(lines) and _indent(lines[j]) > indent:
                body, i = _block(lines, j, indent)
                text = stripped[:-2].rstrip()
                if text:
                    emit(False, [pad + text + ":", ""])
                cut = min(_indent(b) for b in body if b.strip())
                emit(True, [f"{pad}```", *(pad + b[cut:] if b.strip() else "" for b in body), f"{pad}```"])
                continue
        emit(False, [line])
        i += 1
    return "\n".join("\n".join(block) if verbatim else _inline("\n".join(block))
                     for verbatim, block in runs if block)


class RstToMarkdown(griffe.Extension):
    """Rewrite reST in every docstring."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:  # noqa: D102
        if obj.docstring is not None:
            obj.docstring.value = rst_to_markdown(obj.docstring.value)
