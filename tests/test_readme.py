"""Every code block of the README runs as written (issue 18): the Python blocks in order in one
namespace, with their printed numbers checked; each ``layerstack`` command of the bash blocks
through the CLI's ``main`` (outputs redirected to a temporary directory). The README opens with
the two commands a newcomer runs, and its links lead to files that exist. The guide's blocks are
run the same way by tests/test_guide.py (helpers in tests/_markdown_code.py)."""

from __future__ import annotations

import pytest

from _markdown_code import ROOT, code_blocks, layerstack_commands, local_links, run_command, run_python

README = (ROOT / "README.md").read_text(encoding="utf-8")


def test_starts_with_make_demo_and_make_test():
    first = README.split("```", 2)
    assert first[0].strip() == "# layerstack", "the README's first block must come right after the title"
    commands = [line.split("#", 1)[0].strip() for line in code_blocks(README, "bash")[0].splitlines()]
    assert commands[:2] == ["make demo", "make test"], commands


def test_is_one_page():
    lines = README.count("\n")
    assert lines <= 130, f"the README is a first page, not the reference ({lines} lines): move text to docs/guide/"


def test_links_lead_somewhere():
    missing = [link for link in local_links(README) if not (ROOT / link).exists()]
    assert not missing, f"README links to missing files: {missing}"


def test_python_blocks_run_and_print_what_they_say():
    code = "\n".join(code_blocks(README, "python"))
    assert "import layerstack_jax" in code and "ft.fit(" in code
    printed, namespace = run_python(README, "README.md")
    assert "(81,) 0.2829" in printed
    assert "layerstack fit report" in printed and "converged         yes" in printed
    h, dh = namespace["h"], namespace["dh"]
    assert abs(h - 30_000.0) < 3 * dh and 10 < dh < 1_000, (h, dh)


def test_has_a_command_line_fit():
    assert any(c.startswith("layerstack fit ") for c in layerstack_commands(README))


@pytest.mark.parametrize("command", layerstack_commands(README), ids=lambda c: " ".join(c.split()[:3]))
def test_shell_commands_run(command, tmp_path, monkeypatch):
    run_command(command, tmp_path, monkeypatch)
