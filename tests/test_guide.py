"""The user guide (docs/guide/*.md) and the site's front page run as written, like the README
(tests/test_readme.py): each page's Python blocks in order in one namespace, their ``# →`` lines
checked against what they print; every ``layerstack …`` command through the CLI's ``main`` with
outputs redirected to a temporary directory; every TOML block read as a stack file, and an
"(abridged)" copy of a shipped example checked key by key against that file. The numbers the
guide states about the code (cache size, CSV limit, output suffixes) are read from the code."""

from __future__ import annotations

import re
import tomllib

import pytest

from _markdown_code import ROOT, code_blocks, layerstack_commands, local_links, run_command, run_python

DOCS = ROOT / "docs"
PAGES = {p.relative_to(DOCS).as_posix(): p.read_text(encoding="utf-8")
         for p in [DOCS / "index.md", *sorted((DOCS / "guide").glob("*.md"))]}
GUIDE = "\n".join(text for name, text in PAGES.items() if name.startswith("guide/"))


def test_guide_pages_in_nav():
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    missing = [name for name in PAGES if name.startswith("guide/") and f": {name}" not in nav]
    assert not missing, f"guide pages missing from mkdocs.yml's nav: {missing}"
    assert len(PAGES) >= 3


@pytest.mark.parametrize("name", [n for n, t in PAGES.items() if code_blocks(t, "python")])
def test_python_blocks_run_and_print_what_they_say(name):
    text = PAGES[name]
    assert "# →" in "\n".join(code_blocks(text, "python")), f"{name}: say what the blocks print (# → ...)"
    run_python(text, f"docs/{name}")


COMMANDS = [(name, c) for name, text in PAGES.items() for c in layerstack_commands(text)]


@pytest.mark.parametrize(("name", "command"), COMMANDS, ids=[f"{n}:{' '.join(c.split()[:3])}" for n, c in COMMANDS])
def test_shell_commands_run(name, command, tmp_path, monkeypatch):
    run_command(command, tmp_path, monkeypatch)


def test_every_command_documented():
    commands = {c.split()[1] for _, c in COMMANDS}
    assert {"predict", "fit", "fit-cube", "design"} <= commands, commands


def _within(part, whole, where: str) -> None:
    """``part`` (an abridged TOML table) says nothing that ``whole`` (the file) does not."""
    if isinstance(part, dict):
        assert isinstance(whole, dict), where
        for key, value in part.items():
            assert key in whole, f"{where}.{key} is not in the file"
            _within(value, whole[key], f"{where}.{key}")
    elif isinstance(part, list) and part and isinstance(part[0], dict):
        assert isinstance(whole, list) and len(part) <= len(whole), where
        for i, (p, w) in enumerate(zip(part, whole)):
            _within(p, w, f"{where}[{i}]")
    else:
        assert part == whole, f"{where}: {part!r} here, {whole!r} in the file"


TOML = [(name, block) for name, text in PAGES.items() for block in code_blocks(text, "toml")]


@pytest.mark.parametrize(("name", "block"), TOML, ids=[f"{n}:{i}" for i, (n, _) in enumerate(TOML)])
def test_toml_blocks_are_stack_files(name, block):
    from layerstack_jax.io import stack_from_dict

    data = tomllib.loads(block)
    stack_from_dict(data, ROOT / "examples", source=f"docs/{name}")
    m = re.match(r"# (examples/\S+\.toml) \(abridged\)", block)
    if m:
        _within(data, tomllib.loads((ROOT / m.group(1)).read_text(encoding="utf-8")), m.group(1))


def test_links_between_pages_lead_somewhere():
    for name, text in PAGES.items():
        base = (DOCS / name).parent
        missing = [link for link in local_links(text) if not (base / link).exists()]
        assert not missing, f"docs/{name} links to missing files: {missing}"


def test_stated_numbers_are_the_code_s(monkeypatch):
    from layerstack_cli import _predict
    from layerstack_jax._base import programs as _programs

    assert _programs.CACHE_MAX_BYTES == 2 ** 30 and "limited to 1 GiB" in GUIDE
    monkeypatch.delenv("LAYERSTACK_CACHE_DIR", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    assert _programs.compilation_cache_dir().endswith("/.cache/layerstack/xla")
    monkeypatch.setenv("LAYERSTACK_CACHE_DIR", "")
    assert _programs.compilation_cache_dir() == ""
    assert _predict.CSV_MAX_COLUMNS == 2000 and "at most 2000 spectra" in GUIDE
    for suffix in _predict.OUTPUT_SUFFIXES:
        assert f"`{suffix}`" in GUIDE, f"predict -o {suffix} not described in the guide"
