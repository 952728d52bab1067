"""The API reference cannot go stale: docs/api.md equals what docs/make_api.py writes from the
docstrings of the public names (``make docs`` regenerates it)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_api_reference_is_up_to_date():
    proc = subprocess.run([sys.executable, str(ROOT / "docs" / "make_api.py"), "--check"], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, f"docs/api.md is out of date: run `make docs`\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}"
