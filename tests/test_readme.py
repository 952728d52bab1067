"""Every code block of the README runs as written (issue 18): the Python blocks in order in one
namespace, with their printed numbers checked; each ``layerstack`` command of the bash blocks
through the CLI's ``main`` (outputs redirected to a temporary directory)."""

from __future__ import annotations

import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, re.S)


def _commands() -> list[str]:
    out = []
    for block in _blocks("bash"):
        text = block.replace("\\\n", " ")
        for line in text.splitlines():
            line = line.split(" #", 1)[0].strip()
            if line.startswith("layerstack "):
                out.append(line)
    return out


def test_python_blocks_run_and_print_what_they_say():
    code = "\n".join(_blocks("python"))
    assert "import layerstack_jax" in code and "ft.fit(" in code
    buf = io.StringIO()
    namespace: dict = {}
    with contextlib.redirect_stdout(buf):
        exec(compile(code, "README.md", "exec"), namespace)  # noqa: S102 — the README is ours
    printed = buf.getvalue()
    assert "(81,) 0.2829" in printed
    assert "layerstack fit report" in printed and "converged         yes" in printed
    h, dh = namespace["h"], namespace["dh"]
    assert abs(h - 30_000.0) < 3 * dh and 10 < dh < 1_000, (h, dh)


@pytest.mark.parametrize("command", _commands(), ids=lambda c: " ".join(c.split()[:3]))
def test_shell_commands_run(command, tmp_path, monkeypatch):
    from layerstack_cli import main

    args = shlex.split(command)[1:]
    for i, a in enumerate(args[:-1]):
        if a in ("-o", "--output", "--plot"):
            args[i + 1] = str(tmp_path / Path(args[i + 1]).name)
    monkeypatch.chdir(ROOT)
    assert main(args) == 0, command
