"""Command line: ``layerstack predict STACK.toml --geometry 45/0 -o out.csv [--plot out.png]``,
``layerstack fit STACK.toml DATA.csv -g 45/0 -o result.json [--plot fit.png]``,
``layerstack fit-cube MODEL.toml CUBE -o maps.zarr`` and
``layerstack design DESIGN.toml -o design.toml [--plot design.png]``.

Runnable as ``layerstack`` (console script) or ``python -m layerstack_cli``. This package sits
above both :mod:`layerstack_jax` (physics) and :mod:`fitting` (inverse problems, design); neither
imports it. One module per command (:mod:`._predict`, :mod:`._fit`, :mod:`._cube`, :mod:`._design`); shared
helpers in :mod:`._common`. The stack file
format is described in :mod:`layerstack_jax.io`.

Unlike the library, the command line enables float64 (``jax_enable_x64``) unless ``--float32``
is given, and restores the previous setting when it returns (so ``main`` can be called
in-process). It also keeps the programs it compiles on disk (JAX's persistent compilation
cache, in ``$LAYERSTACK_CACHE_DIR`` or ``~/.cache/layerstack/xla``; ``LAYERSTACK_CACHE_DIR=`` turns
it off), so a later run of the same model structure does not compile them again. ``fit`` exits with status 1 when the fit did not converge (the report says why), ``fit-cube``
when a pixel's fit is not to be trusted (not converged, χ² implausible, a parameter on a bound:
its status map says which);
``design`` exits with status 1 when the design misses a target (or the required yield) — it
still writes the best design found, and the report says which target failed; a design that
meets every target exits 0 even if the optimizer hit its step limit. Input problems (bad stack
or design file, CSV table, geometry, wavelength grid, unwritable output) print
``layerstack: error: <message>`` to stderr and give exit status 2.
"""

from ._main import main as main

__all__ = ["main"]
