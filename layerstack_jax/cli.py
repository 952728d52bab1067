"""Deprecated location of the command line: it moved to :mod:`layerstack_cli`, a package above
both :mod:`layerstack_jax` and :mod:`fitting` (the physics package depends on nothing built on
it). ``layerstack`` (the console script) and ``python -m layerstack_cli`` are the entry points;
``python -m layerstack_jax.cli`` and ``layerstack_jax.cli.main`` keep working with a
:class:`DeprecationWarning` until the next minor release.
"""

from __future__ import annotations

import importlib
import sys
import warnings

__all__ = ["main"]

_MOVED = "layerstack_jax.cli moved to layerstack_cli (run `layerstack` or `python -m layerstack_cli`)"


def main(argv=None) -> int:
    """Deprecated alias of :func:`layerstack_cli.main` (looked up at call time: the physics
    package imports nothing above it)."""
    warnings.warn(_MOVED, DeprecationWarning, stacklevel=2)
    return importlib.import_module("layerstack_cli").main(argv)


if __name__ == "__main__":
    sys.exit(main())
