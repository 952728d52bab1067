"""How :func:`fitting.fit_cube` cuts a cube into regions: the tiling (:func:`cube_regions`) and
the ``chunk="auto"`` region size (:func:`auto_region`) from the memory where the regions run
(:func:`_budget_and_slots`) and the measured memory of the compiled solver
(:func:`_solver_memory`), shaped for the fewest padded solver calls (:func:`_region_shape`)."""

from __future__ import annotations

from typing import Optional

import jax.numpy as jnp
import numpy as np

from layerstack_jax import MEMORY_FRACTION, LayerstackError, MemoryBudget, memory_budget

from ._batch import fit_batch
from ._cube_store import _empty_maps
from ._objective import Objective

__all__ = ["cube_regions", "auto_region", "AUTO_REGION_MAX", "AUTO_REGIONS_PER_WORKER"]

#: Largest ``chunk="auto"`` region, rows × columns pixels (a strip of the same area may be
#: chosen on a narrow image): a lost region is cheap to redo.
AUTO_REGION_MAX = (64, 64)
#: ``chunk="auto"`` cuts at least this many regions per worker thread when the cube is large
#: enough (regions of at least ``chunk_size`` pixels): every worker is fed, and the last regions
#: do not leave the others idle for long.
AUTO_REGIONS_PER_WORKER = 4


def cube_regions(shape: tuple, chunk: tuple) -> list:
    """Regions ``(iy, ix, ys, xs)`` of a ``(ny, nx)`` image cut in ``chunk`` = (rows, cols) tiles."""
    ny, nx = shape
    ty, tx = chunk
    return [(iy, ix, slice(iy * ty, min((iy + 1) * ty, ny)), slice(ix * tx, min((ix + 1) * tx, nx)))
            for iy in range(-(-ny // ty)) for ix in range(-(-nx // tx))]


def _solver_memory(objective: Objective, method: str, chunk_size: int, bands: int, fit_opts: tuple) -> tuple:
    """``(temp, argument, output)`` bytes of the compiled solver of :func:`~fitting.fit_batch`
    for one call of ``chunk_size`` fits (``compiled.memory_analysis()``); the compilation is the
    one ``fit_batch`` then reuses in this process."""
    import inspect

    from ._compiled_fit import compiled_fit
    from ._solver_options import NEVER, SolverOptions, starting_point

    opts = {k: p.default for k, p in inspect.signature(fit_batch).parameters.items()
            if k in ("rtol", "atol", "gtol", "max_steps", "sigma_tol")}
    opts.update((k, v) for k, v in fit_opts if k in opts)
    o = SolverOptions(method, opts["rtol"], opts["atol"], opts["gtol"], opts["max_steps"], opts["sigma_tol"])
    args, _ = objective.batch_args([np.zeros((chunk_size, bands))])
    y0 = jnp.asarray(starting_point(objective, o, objective.layout.x0))
    y0 = jnp.broadcast_to(y0, (chunk_size,) + y0.shape)
    m = compiled_fit(objective, o, batched=True).lower(y0, args, objective.optics, NEVER).compile().memory_analysis()
    if m is None:  # pragma: no cover - a backend without memory analysis
        raise LayerstackError("fit_cube: chunk='auto' needs the compiled solver's memory analysis, which this JAX "
                              "backend does not give: give chunk=(rows, columns)")
    return int(m.temp_size_in_bytes), int(m.argument_size_in_bytes), int(m.output_size_in_bytes)


def _solver_calls(rows: int, cols: int, ny: int, nx: int, chunk_size: int) -> tuple:
    """``(solver calls, regions)`` of an ``(ny, nx)`` image cut in ``rows x cols`` tiles, every
    pixel fitted (each region's pixels padded to a multiple of ``chunk_size``)."""
    r_sizes = [(rows, ny // rows)] + ([(ny % rows, 1)] if ny % rows else [])
    c_sizes = [(cols, nx // cols)] + ([(nx % cols, 1)] if nx % cols else [])
    calls = sum(-(-(r * c) // chunk_size) * nr * nc for r, nr in r_sizes for c, nc in c_sizes)
    return calls, sum(n for _, n in r_sizes) * sum(n for _, n in c_sizes)


def _region_shape(pixels: int, ny: int, nx: int, chunk_size: int) -> tuple:
    """``(rows, columns)`` of the regions of at most ``pixels`` pixels that cut an ``(ny, nx)``
    image into the fewest solver calls of ``chunk_size`` fits (the least padding); among those,
    within 5 % of the fewest regions, the squarest (then the widest)."""
    pixels = max(int(pixels), 1)
    found = []
    for rows in range(1, min(ny, pixels) + 1):
        cols = min(nx, pixels // rows)
        found.append((*_solver_calls(rows, cols, ny, nx, chunk_size), rows, cols))
    calls = min(f[0] for f in found)
    found = [f for f in found if f[0] == calls]
    regions = min(f[1] for f in found)
    found = [f for f in found if f[1] <= 1.05 * regions]
    _, _, rows, cols = min(found, key=lambda f: (abs(f[2] - f[3]), f[1], -f[3]))
    return rows, cols


def _budget_and_slots(c, memory: Optional[int]):
    """``(MemoryBudget, worker threads)`` of where the regions run: this process (``c`` None),
    or the smallest ``memory_limit`` per thread of the cluster's workers (public
    ``Client.scheduler_info()``; this process's memory where the workers state no limit)."""
    slots, budget = 1, None
    if c is not None:
        try:
            info = c.scheduler_info(n_workers=-1)  # every worker (newer distributed shows 5 by default)
        except TypeError:  # pragma: no cover - distributed before n_workers=
            info = c.scheduler_info()
        workers = info.get("workers", {})
        slots = max(sum(int(w.get("nthreads", 1) or 1) for w in workers.values()), 1)
        per_thread = [(int(w["memory_limit"]) // max(int(w.get("nthreads", 1) or 1), 1), int(w["memory_limit"]),
                       int(w.get("nthreads", 1) or 1)) for w in workers.values() if w.get("memory_limit")]
        if per_thread:
            share, limit, threads = min(per_thread)
            f = MEMORY_FRACTION
            budget = MemoryBudget(int(share * f), share, f,
                                           f"smallest Dask worker memory_limit {limit / 1e6:.4g} MB / {threads} "
                                           f"thread(s), {len(workers)} worker(s)")
    if memory is not None:
        budget = MemoryBudget(int(memory), int(memory), 1.0, "given (memory=)")
    if budget is None:
        budget = memory_budget()
        if c is not None:
            budget = budget._replace(source=budget.source + " of this process (the workers state no memory limit)")
    return budget, slots


def auto_region(objective: Objective, shape: tuple, bands: int, itemsize: int, *, chunk_size: int = 128,
                method: str = "lm", fit_options: tuple = (), budget=None, slots: int = 1) -> tuple:
    """The ``chunk="auto"`` region ``(rows, columns)`` of :func:`fitting.fit_cube` and how it was sized.

    A region of ``p`` pixels needs (bytes)::

        p * per_pixel + solver
        per_pixel = bands * (itemsize + 16)          # the block as read, its float64 copy, the spectra fitted
                  + 2 * (A + O) / chunk_size         # fit_batch's data and results of every fit on the host
                  + 2 * maps                         # one pixel of every map, and its copy written to zarr
        solver    = T + A + O                        # one call of the compiled solver (chunk_size fits)

    ``T``, ``A``, ``O``: the temp, argument and output bytes of the compiled solver for
    ``chunk_size`` fits (``compiled.memory_analysis()``, measured); ``maps``: the bytes of one
    pixel of all the maps. ``p`` is the largest that fits ``budget`` (a
    :class:`layerstack_jax.MemoryBudget`; default: :func:`~layerstack_jax.memory_budget`),
    at most :data:`AUTO_REGION_MAX` (in pixels) and at most
    ``⌈pixels / (AUTO_REGIONS_PER_WORKER × slots)⌉`` (but not below ``chunk_size``: a smaller
    region would pad one solver call); then shaped by :func:`_region_shape` (the fewest padded
    solver calls over the image). Raises :class:`LayerstackError` naming ``chunk`` when not even a region
    of ``chunk_size`` pixels fits.

    Returns ``((rows, columns), sizing)``, ``sizing`` a dict of the numbers used (bytes).
    """
    ny, nx = shape
    budget = memory_budget() if budget is None else budget
    temp, args, outs = _solver_memory(objective, method, chunk_size, bands, tuple(fit_options))
    maps = sum(v.itemsize for v in _empty_maps((1, 1), tuple(objective.layout.names)).values())
    per_pixel = bands * (itemsize + 16) + 2 * (args + outs) / chunk_size + 2 * maps
    solver = temp + args + outs
    least = solver + chunk_size * per_pixel
    if budget.bytes < least:
        raise LayerstackError(
            f"fit_cube: chunk: the worker memory {budget.describe()} cannot hold one region of chunk_size="
            f"{chunk_size} pixels, {least / 1e6:.4g} MB (the compiled solver {solver / 1e6:.4g} MB and "
            f"{per_pixel / 1e3:.4g} kB per pixel): lower chunk_size, or give the workers more memory")
    fits = int((budget.bytes - solver) // per_pixel)
    feed = max(chunk_size, -(-ny * nx // (AUTO_REGIONS_PER_WORKER * max(int(slots), 1))))
    pixels = min(fits, AUTO_REGION_MAX[0] * AUTO_REGION_MAX[1], feed)
    region = _region_shape(min(pixels, ny * nx), ny, nx, chunk_size)
    sizing = {"budget_bytes": int(budget.bytes), "budget_source": budget.describe(), "per_pixel_bytes": per_pixel,
              "solver_bytes": solver, "solver_temp_bytes": temp, "memory_fit_pixels": fits, "worker_threads": slots}
    return region, sizing
