"""MkDocs hook: the command-line reference shows the ``--help`` text of ``layerstack`` itself.

A line ``<!-- help: layerstack COMMAND -->`` in a page is replaced by a code block with what
``layerstack COMMAND --help`` prints (``<!-- help: layerstack -->`` for the top level). The text is
taken from :func:`layerstack_cli.main` in-process (argparse at a fixed width of 100 columns), so
the page always matches the installed command line. Registered in ``mkdocs.yml`` (``hooks:``).
"""

from __future__ import annotations

import contextlib
import io
import os
import re

_MARKER = re.compile(r"^<!-- help: layerstack((?: [a-z][a-z-]*)*) -->$", re.MULTILINE)


def help_text(argv: list[str]) -> str:
    """What ``layerstack *argv --help`` prints (the command-line parser's own text)."""
    import layerstack_cli

    buffer = io.StringIO()
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"
    try:
        with contextlib.redirect_stdout(buffer):
            status = layerstack_cli.main([*argv, "--help"])
    finally:
        if previous is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = previous
    if status != 0 or not buffer.getvalue().strip():
        raise RuntimeError(f"`layerstack {' '.join(argv)} --help` exited {status} with no help text")
    return buffer.getvalue().rstrip()


def on_page_markdown(markdown: str, **kwargs) -> str:  # noqa: D103
    return _MARKER.sub(lambda m: "```text\n" + help_text(m.group(1).split()) + "\n```", markdown)
