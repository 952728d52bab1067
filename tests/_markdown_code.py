"""The code blocks of a Markdown page, run as written (tests/test_readme.py, tests/test_guide.py).

* Python blocks (```` ```python ````) run in order in one namespace per page, with stdout captured;
  a ``print(...)`` line whose comment starts with ``→`` states what it prints, and that text must
  appear in the output.
* Each ``layerstack …`` command of the bash blocks (```` ```bash ````, ``\\`` continuations joined,
  ``# comments`` dropped) runs through the command line's ``main`` in the repository root, with
  its outputs (``-o``, ``--output``, ``--plot``) redirected to a temporary directory. It must exit
  0, unless its comment states another status (``# exit status 1: …``).
"""

from __future__ import annotations

import contextlib
import io
import re
import shlex
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: ``layerstack …  # exit status N: why``
_EXIT = re.compile(r"#\s*exit status (\d+)")

#: ``print(...)  # → expected text``
_EXPECTED = re.compile(r"^\s*print\(.*#\s*→\s*(.+?)\s*$", re.M)


def code_blocks(text: str, lang: str) -> list[str]:
    """The bodies of the fenced blocks of ``lang`` in ``text``, in order."""
    return re.findall(rf"^```{lang}\n(.*?)^```", text, re.S | re.M)


def layerstack_commands(text: str) -> list[str]:
    """The ``layerstack …`` command lines of the bash blocks of ``text``."""
    out = []
    for block in code_blocks(text, "bash"):
        for line in block.replace("\\\n", " ").splitlines():
            command, _, comment = line.partition(" #")
            if command.strip().startswith("layerstack "):
                stated = _EXIT.search("#" + comment)
                out.append(command.strip() + (f"  # exit status {stated.group(1)}" if stated else ""))
    return out


def expected_prints(code: str) -> list[str]:
    """What the ``print(...)  # → text`` lines of ``code`` say they print."""
    return _EXPECTED.findall(code)


def run_python(text: str, name: str) -> tuple[str, dict]:
    """Run the Python blocks of ``text`` in order in one namespace; return what they printed and
    the namespace. Checks every ``# →`` statement against the output."""
    code = "\n".join(code_blocks(text, "python"))
    buf = io.StringIO()
    namespace: dict = {"__name__": f"markdown:{name}"}
    with contextlib.redirect_stdout(buf):
        exec(compile(code, name, "exec"), namespace)  # noqa: S102 — our own documentation
    printed = buf.getvalue()
    for expected in expected_prints(code):
        assert expected in printed, f"{name}: expected {expected!r} in the printed output:\n{printed[-3000:]}"
    return printed, namespace


def run_command(command: str, tmp_path: Path, monkeypatch) -> None:
    """Run one ``layerstack …`` command line through ``layerstack_cli.main`` in the repository
    root, outputs redirected into ``tmp_path``; it must exit with the status its comment states
    (``# exit status N``), 0 if none."""
    from layerstack_cli import main

    stated = _EXIT.search(command)
    args = shlex.split(command, comments=True)[1:]
    for i, a in enumerate(args[:-1]):
        if a in ("-o", "--output", "--plot"):
            args[i + 1] = str(tmp_path / Path(args[i + 1]).name)
    monkeypatch.chdir(ROOT)
    assert main(args) == (int(stated.group(1)) if stated else 0), command


def local_links(text: str) -> list[str]:
    """Targets of the Markdown links of ``text`` that are paths, not URLs (anchors dropped)."""
    links = re.findall(r"\]\(([^)\s]+)\)", text)
    return [link.split("#", 1)[0] for link in links
            if not re.match(r"[a-z]+:", link) and not link.startswith("#")]
