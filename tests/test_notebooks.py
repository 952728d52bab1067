"""The notebooks run top to bottom and their own assertions hold.

Each ``notebooks/NN_*.py`` (a jupytext percent script) is executed as a script in a fresh Python
process, as a reader would run it: the notebook turns on float64 itself, asserts its key numbers
against closed forms written from the papers (not computed by the library), and saves its
figures — here into a temporary folder (``NOTEBOOK_FIGURES``), so the committed PNGs under
``notebooks/figures/`` are left alone. The Agg backend keeps matplotlib headless.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.py"))
# minutes of table building and Monte-Carlo rendering: run by `make test-slow`; the plugin itself
# is tested in the default run (tests/test_render_mitsuba.py, tests/test_render_lookup.py)
SLOW = {"07_rendering_coated_objects"}


def test_notebooks_found():
    assert NOTEBOOKS, "no notebooks/NN_*.py found"


@pytest.mark.parametrize(
    "script", [pytest.param(p, marks=pytest.mark.slow) if p.stem in SLOW else p for p in NOTEBOOKS],
    ids=[p.stem for p in NOTEBOOKS],
)
def test_notebook_runs(script, tmp_path):
    env = dict(os.environ)
    env["MPLBACKEND"] = "Agg"
    env["NOTEBOOK_FIGURES"] = str(tmp_path)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    proc = subprocess.run(
        [sys.executable, str(script)], cwd=script.parent, env=env, capture_output=True, text=True, timeout=900
    )
    assert proc.returncode == 0, f"{script.name} failed:\n{proc.stdout[-4000:]}\n{proc.stderr[-4000:]}"
    assert sorted(p.name for p in tmp_path.glob("*.png")), f"{script.name} saved no figure"
