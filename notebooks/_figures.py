"""Where the notebooks save their figures: ``notebooks/figures/`` (the rendered notebooks link to
it), or the folder named by ``NOTEBOOK_FIGURES`` (the tests write there, leaving the committed
PNGs alone). Imported by every ``notebooks/NN_*.py``; the notebooks run with this folder as
their script directory (``python notebooks/NN_*.py``, Jupyter via jupytext, ``execute.py``)."""

from __future__ import annotations

import os
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent  # the repository (examples/ lives there)
FIGURES = Path(os.environ.get("NOTEBOOK_FIGURES", HERE / "figures"))
FIGURES.mkdir(exist_ok=True)


def save(fig, name: str) -> None:
    """Save a matplotlib figure as ``<FIGURES>/<name>.png``."""
    fig.savefig(FIGURES / f"{name}.png", dpi=110, bbox_inches="tight")
