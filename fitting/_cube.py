r"""Fitting a hyperspectral cube pixel by pixel, out of core, resumable, locally or on Dask.

:func:`fit_cube` fits every pixel spectrum of a cube ``(y, x, wavelength)`` (read lazily:
:func:`layerstack_jax.open_cube`) with the same :class:`~fitting.Objective` — one
dataset, one sample; only the data differ, as in :func:`~fitting.fit_batch`, which does the
fitting — and writes maps into a zarr store, region by region:

* the cube is cut into regions of ``chunk`` = (rows, columns) pixels, all bands; a region is
  read, its valid pixels are fitted by :func:`~fitting.fit_batch` (padded to a multiple of its
  ``chunk_size`` so that one compiled solver serves every region), and its maps are written to
  the store's chunk of the same size (``to_zarr(region=...)``: regions never share a chunk, so
  workers write in parallel without locks). Memory is bounded by one region and one solver
  chunk per worker, whatever the cube size.
* once a region is written, a *completion marker* ``<out>.regions/<iy>_<ix>`` is
  created (beside the store, which stays a plain zarr hierarchy) (atomically: written under a temporary name, then renamed). A restarted run
  (``resume=True``) skips the regions whose marker exists and redoes the others, whose chunks
  it overwrites completely: no pixel is lost or fitted twice, and the maps are bit-identical
  to those of an uninterrupted run (each pixel's fit depends on its spectrum only; the same
  compiled solver runs on the same padded shapes).
* **bad bands, not bad pixels**: at each pixel, a band the dataset uses is *bad* when its
  reading is NaN or infinite, at or above ``saturation``, or further below zero than
  ``negative_sigmas`` × σ (:data:`NEGATIVE_SIGMAS` = 5 by default: a dark, dark-corrected
  reading scatters around 0, and one below −5σ is not noise — the library's own rule for a
  :class:`~fitting.Dataset`; σ is the dataset's σ of that band, or without σ the library's
  absolute floor :data:`~fitting._dataset.NEGATIVE_READING_FLOOR` taken as 5σ). Readings below
  zero but above that floor are data and are fitted (dropping them would leave the least dark
  pixels of a dark region: its map biased thin). A pixel's bad bands are left out of *its* fit only (weight 0 on those residuals:
  one compiled shape for every pixel; the ``bands_used`` map counts the others, and its degrees
  of freedom ν = ``bands_used`` − free parameters). A pixel is fitted when ν ≥ 1; else it gets
  NaN values and status 2, 3 or 4 after the most frequent reason. Outside the user ``mask``:
  status 1.
* **honest pixels**: a fit made gets status 0 ("fitted") only when it is trustworthy; else,
  with its values kept in the maps, the first that applies of: 7 the solver did not converge;
  5 *implausible χ²* — with σ given, χ² above the upper edge of the central
  :data:`CHI2_CENTRAL` = 99.9 % of the χ² distribution of ν degrees of freedom (upper-tail
  probability < 0.05 %): a local minimum or a wrong model (a good pixel lands there once in
  2000); 6 a parameter on a bound (within 1e-6 of its scale, :func:`fitting._statistics.bound_contacts`):
  the optimum may lie beyond it. A χ² below the lower edge (σ overstated: the standard errors
  are too large, the values are not wrong) keeps status 0 and is counted by the command line.
  Without σ, χ² is a sum of squared residuals and is not tested.
* maps: one per free parameter component (its name in :attr:`fitting.BatchResult.names`,
  made safe for zarr), its standard error (``<name>_stderr``), ``chi2``, ``reduced_chi2``,
  ``num_steps``, ``converged``, ``result_code``, ``rank`` of the normalised Jacobian and
  ``identifiable`` (rank = number of free parameters and no group of parameters correlated
  beyond 0.99, :attr:`fitting.BatchResult.separability`: the pixel's *identifiability verdict*;
  where the rank is short, the stderr of the parameters involved are NaN), ``bands_used`` and
  ``status``. ``reduced_chi2`` = χ²/ν with each pixel's own ν; without σ, the standard errors are
  scaled by it (σ estimated from that pixel's residuals).
* before any pixel is fitted, the objective is checked for a degeneracy *by construction*: the
  thickness and α of the same incoherent layer both free (Beer: only α·h enters, Simonot
  eq. 20) — refused unless ``allow_degenerate=True`` (then warned once) — and the rank of the
  Jacobian at the starting point (a warning, once, if it is deficient).
* ``client``: None runs the regions one after the other in this process (XLA uses every core
  for each solve); ``"processes"`` starts a :class:`distributed.LocalCluster` of ``n_workers``
  single-threaded worker processes and closes it at the end; a :class:`distributed.Client` or a
  scheduler address runs the same regions on that cluster. The objective is scattered once to
  every worker, so each worker compiles the solver once and reuses it for all its regions; a
  worker reads its region from the cube itself (a file-backed cube is never shipped whole).
  Workers run in the client's precision (``jax_enable_x64`` is set to the caller's value in
  the worker processes that run a region).
* progress: pixels done, rate and ETA on a tqdm bar and in the ``fitting.cube`` logger.
* ``chunk="auto"`` (the default) sizes the regions from the memory of where they run
  (:func:`fitting._cube_regions.auto_region`): the budget is half (:data:`layerstack_jax.MEMORY_FRACTION`)
  of the smallest Dask worker's ``memory_limit`` per thread (``Client.scheduler_info()``), or of
  this process's available memory (:func:`layerstack_jax.memory_budget`) without a
  cluster; the solver's memory is measured on the compiled solver for ``chunk_size`` fits (the
  program every region runs: in this process the compilation is reused; with a cluster this
  process compiles it once more, to measure it). The resolved region
  size is what the job's fingerprint holds and the store records (attributes ``chunk``,
  ``chunk_size``, ``chunk_sizing``); a resumed run with ``"auto"`` takes the store's own region
  size, whatever memory the machine resuming it has.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import time
import warnings
from pathlib import Path
from typing import Callable, Optional, Union

import jax
import jax.numpy as jnp
import numpy as np

from layerstack_jax import LayerstackError, open_cube, progress_reporter

from ._batch import fit_batch
from ._cube_regions import _budget_and_slots, auto_region, cube_regions
from ._cube_store import (
    _empty_maps,
    _fingerprint,
    _init_store,
    _mark_done,
    _marker,
    _var,
    _write_region,
)
from ._fit_findings import structural_degeneracy
from ._objective import Objective
from ._solver_options import require_compiled_method
from ._statistics import linearised_covariance

__all__ = ["fit_cube", "CUBE_STATUS", "FIT_MADE", "NEGATIVE_SIGMAS", "CHI2_CENTRAL", "status_counts",
           "rank_at_start"]

log = logging.getLogger("fitting.cube")


#: ``status`` codes of the pixel maps of :func:`fit_cube` (dimensionless integers). 2, 3, 4:
#: not fitted, too few usable bands (the most frequent reason named); 5, 6, 7: fitted, values
#: in the maps, but not to be trusted as they are (module docstring).
CUBE_STATUS = {
    -1: "not fitted yet",
    0: "fitted",
    1: "outside the mask",
    2: "no data (NaN or infinite values)",
    3: "saturated",
    4: "far below zero",
    5: "implausible chi2",
    6: "parameter on a bound",
    7: "not converged",
}
#: Status codes of the pixels whose fit was made (values in the maps).
FIT_MADE = (0, 5, 6, 7)
#: Readings down to −NEGATIVE_SIGMAS × σ are kept as noise around a dark reading (default of
#: ``fit_cube(negative_sigmas=)``; at most this: the library's :class:`~fitting.Dataset` check).
NEGATIVE_SIGMAS = 5.0
#: With σ given, a pixel's χ² above the upper edge of this central fraction of the χ²(ν)
#: distribution marks it "implausible chi2" (status 5).
CHI2_CENTRAL = 0.999


def rank_at_start(objective: Objective, *, rank_rtol: float = 1e-8) -> int:
    """Rank of the normalised Jacobian of the residuals at the starting values
    (:func:`fitting._statistics.linearised_covariance`; compare with the number of free parameters)."""
    layout = objective.layout
    x0 = jnp.asarray(layout.x0)
    args = objective.args()
    jac = objective.cache.get("rank_at_start")  # compiled once per objective, not once per fit_cube call
    if jac is None:
        jac = objective.cache["rank_at_start"] = jax.jit(jax.jacfwd(objective.residuals))
    J = jac(x0, args, objective.optics)
    J = np.asarray(J) * layout.scale[None, :]
    return int(linearised_covariance(J, np.asarray(x0), layout.scale, rank_rtol)[2])


@dataclasses.dataclass(frozen=True)
class _Settings:
    """What every region task needs besides the objective and its pixels."""

    out: str
    names: tuple
    method: str
    chunk_size: int
    saturation: Optional[float]
    used_bands: Optional[np.ndarray]
    fit_options: tuple
    x64: bool
    floor: Optional[np.ndarray] = None  # (wl,) readings below it are bad bands; None: none are
    sigma_given: bool = False


def _negative_floor(objective: Objective, k: float) -> np.ndarray:
    """``(wl,)`` the lowest reading kept at each band: −k σ (σ of the dataset's band), or without σ
    −k/5 × :data:`~fitting._dataset.NEGATIVE_READING_FLOOR` (the library's floor is 5 "σ");
    computed as the :class:`~fitting.Dataset` check computes −5σ, so that k = 5 is its rule."""
    from ._dataset import NEGATIVE_READING_FLOOR

    w = np.asarray(objective.args()[1][0], dtype=float).reshape(-1)
    if objective.sigma_given:
        with np.errstate(divide="ignore"):
            return np.where(w > 0, -float(k) / np.where(w > 0, w, 1.0), -np.inf)
    return np.full(w.shape, -float(k) / NEGATIVE_SIGMAS * NEGATIVE_READING_FLOOR)


def _pixel_status(block: np.ndarray, user_mask: Optional[np.ndarray], s: _Settings, n_free: int = 0) -> tuple:
    """``(status, bad)`` of a region block ``(ry, rx, wl)``: the ``status`` code of every pixel
    (0 where it is to be fitted; :data:`CUBE_STATUS`) and the boolean ``(ry, rx, wl)`` bad bands
    (used bands that are NaN/infinite, saturated or below the floor), left out of each pixel's fit.
    A pixel is fitted when more than ``n_free`` used bands are good."""
    used = np.ones(block.shape[-1], bool) if s.used_bands is None else np.asarray(s.used_bands, bool)
    nonfinite = ~np.isfinite(block) & used
    with np.errstate(invalid="ignore"):
        saturated = (block >= s.saturation) & used & ~nonfinite if s.saturation is not None else \
            np.zeros(block.shape, bool)
        below = (block < s.floor) & used & ~nonfinite if s.floor is not None else np.zeros(block.shape, bool)
    bad = nonfinite | saturated | below
    good = np.sum(used & ~bad, axis=-1)
    status = np.zeros(block.shape[:2], np.int8)
    few = good <= n_free
    counts = np.stack([nonfinite.sum(-1), saturated.sum(-1), below.sum(-1)])  # ties: the first reason
    status[few] = (2 + np.argmax(counts, axis=0).astype(np.int8))[few]
    if user_mask is not None:
        status[~user_mask] = 1
    return status, bad


def _fit_region(objective: Objective, block, user_mask, iy: int, ix: int, ys: slice, xs: slice, s: _Settings):
    """Fit one region and write it, then its completion marker. Runs in this process or on a
    Dask worker. Returns ``{"region", "pixels", "fitted", "seconds"}``."""
    t0 = time.perf_counter()
    if bool(jax.config.jax_enable_x64) != s.x64:  # a fresh worker process: the caller's precision
        jax.config.update("jax_enable_x64", s.x64)
    data = np.asarray(getattr(block, "values", block), dtype=np.float64)
    mask = None if user_mask is None else np.asarray(getattr(user_mask, "values", user_mask), dtype=bool)
    n_free = len(s.names)
    status, bad = _pixel_status(data, mask, s, n_free)
    maps = _empty_maps(status.shape, s.names)
    valid = np.nonzero(status.ravel() == 0)[0]
    if valid.size:
        spectra = data.reshape(-1, data.shape[-1])[valid]
        dropped = bad.reshape(-1, data.shape[-1])[valid]
        pad = -valid.size % s.chunk_size  # same padded shape in every region: one compiled solver
        if pad:
            spectra = np.concatenate([spectra, np.broadcast_to(spectra[:1], (pad, spectra.shape[1]))])
            dropped = np.concatenate([dropped, np.broadcast_to(dropped[:1], (pad, dropped.shape[1]))])
        # bad bands: weight 0 in this pixel's fit (the same compiled shape for every pixel)
        spectra = np.ma.MaskedArray(np.where(dropped, 0.0, spectra), mask=dropped)
        r = fit_batch(objective, spectra, s.method, chunk_size=s.chunk_size, progress=False, **dict(s.fit_options))
        used = np.ones(data.shape[-1], bool) if s.used_bands is None else np.asarray(s.used_bands, bool)
        bands = np.sum(used & ~dropped, axis=-1)
        dof = bands - n_free
        # the batch's statistics count every used band; each pixel has its own ν
        with np.errstate(invalid="ignore", divide="ignore"):
            reduced = np.where(dof > 0, r.chi2 / np.maximum(dof, 1), np.nan)
            stderr = r.stderr * (np.sqrt(r.dof / np.maximum(dof, 1))[:, None] if r.covariance_scaled else 1.0)
        verdict = np.zeros(dof.shape, np.int8)
        if s.sigma_given:
            from scipy.special import (
                chdtrc,  # the χ² upper tail (scipy.stats.chi2.sf), without importing scipy.stats
            )

            tail = chdtrc(np.maximum(dof, 1), r.chi2)
            verdict[~(tail >= (1.0 - CHI2_CENTRAL) / 2)] = 5  # NaN χ² too
        if r.at_bound is not None:
            verdict[(verdict == 0) & np.any(r.at_bound, axis=1)] = 6
        verdict[~r.converged] = 7

        def put(name, values):
            flat = maps[name].reshape(-1)
            flat[valid] = values[:valid.size]

        for j, n in enumerate(s.names):
            put(_var(n), r.x[:, j])
            put(_var(n) + "_stderr", stderr[:, j])
        put("chi2", r.chi2)
        put("reduced_chi2", reduced)
        put("num_steps", r.num_steps)
        put("result_code", r.result_code)
        put("rank", r.rank)
        put("converged", r.converged.astype(np.int8))
        separable = np.array([not f for f in (r.separability or [None] * len(r.rank))])  # no |ρ| > 0.99 group
        put("identifiable", ((r.rank == n_free) & separable).astype(np.int8))
        put("bands_used", bands.astype(np.int16))
        status.reshape(-1)[valid] = verdict[:valid.size]
    maps["status"] = status
    _write_region(s.out, maps, ys, xs)
    _mark_done(s.out, iy, ix)
    return {"region": (iy, ix), "pixels": int(status.size), "fitted": int(valid.size),
            "seconds": time.perf_counter() - t0}


def _check_objective(objective: Objective, cube) -> Optional[np.ndarray]:
    """The objective must be a one-dataset, one-sample spectral fit on the cube's bands.
    Returns the boolean band mask the dataset uses (None: all)."""
    if not isinstance(objective, Objective):
        raise LayerstackError(f"fit_cube: objective must be a fitting.Objective, got {type(objective).__name__}")
    if len(objective.datasets) != 1 or objective.n_samples != 1:
        raise LayerstackError("fit_cube: the objective must have one dataset of one sample (one spectrum per pixel)")
    ds = objective.datasets[0]
    if ds.colour is not None or ds.bare:
        raise LayerstackError("fit_cube: the dataset must compare spectra (no colour, not bare)")
    grid = np.asarray(objective.wavelength if ds.wavelength_nm is None else ds.wavelength_nm, dtype=float)
    wl = np.asarray(cube["wavelength"].values, dtype=float)
    if wl.shape != grid.shape or not np.allclose(wl, grid, rtol=0, atol=1e-6):
        raise LayerstackError(
            f"fit_cube: the cube's {wl.size} bands ({wl.min():g}–{wl.max():g} nm) are not the wavelengths of the "
            f"objective's dataset ({grid.size}, {grid.min():g}–{grid.max():g} nm): build the Dataset on the cube's "
            "wavelengths (wavelength_nm=cube.wavelength) or resample the cube")
    if ds.mask is None:
        return None
    m = np.asarray(ds.mask, bool)
    if m.ndim == 2:
        m = m[0]
    return m if m.ndim == 1 and m.size == wl.size else None


def _client(client, n_workers: int):
    """``(client, owned)`` for ``client`` = None / 'processes' / Client / address."""
    if client is None:
        return None, None
    from distributed import Client, LocalCluster

    if isinstance(client, Client):
        return client, None
    if client == "processes":
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None)
        c = Client(cluster)
        return c, (c, cluster)
    if isinstance(client, str):
        c = Client(client)
        return c, (c, None)
    raise LayerstackError(f"fit_cube: client must be None, 'processes', a distributed.Client or an address, got {client!r}")


def fit_cube(objective: Objective, cube, *, out: Union[str, os.PathLike], mask=None, chunk="auto",
             saturation: Optional[float] = None, method: str = "lm", chunk_size: int = 128, client=None,
             n_workers: int = 2, resume: bool = True, progress: Union[bool, Callable[[int, int], None]] = True,
             allow_degenerate: bool = False, wavelength_nm=None, variable: Optional[str] = None,
             memory: Optional[int] = None, negative_sigmas: float = NEGATIVE_SIGMAS, **fit_options):
    """Fit every pixel of ``cube`` with ``objective`` and write the maps to the zarr store ``out``
    (module docstring).

    Args:
        objective: a :class:`~fitting.Objective` with one dataset of one sample on the cube's
            wavelengths; its data are a placeholder (only σ/weights and band mask are used).
        cube: a cube (anything :func:`layerstack_jax.open_cube` opens: a
            path, an array ``(y, x, band)`` with ``wavelength_nm``, a DataArray).
        out: path of the zarr store written (created, or resumed).
        mask: optional boolean ``(y, x)``, True where pixels are to be fitted.
        chunk: region size (rows, columns) in pixels: the unit of work, of writing and of
            resuming; or ``"auto"`` (default): sized from the workers' memory (:func:`fitting._cube_regions.auto_region`),
            or, resuming a store, the store's own region size.
        saturation: a reading >= this is a bad band of its pixel (left out of its fit).
        negative_sigmas: k, readings below zero are kept down to −k σ (σ of the dataset's band;
            without σ, k/5 × 0.01 absolute); further below they are bad bands of their pixel.
            0 ≤ k ≤ :data:`NEGATIVE_SIGMAS` (5, the default: the :class:`~fitting.Dataset`
            check refuses a reading below −5σ); 0 drops every reading below zero.
        method, chunk_size, fit_options: passed to :func:`~fitting.fit_batch` (``chunk_size``
            fits per compiled call; options e.g. ``max_steps``, ``rtol``, ``scale_covariance``).
        client: None (this process), ``"processes"`` (a LocalCluster of ``n_workers``), a
            :class:`distributed.Client` or a scheduler address.
        resume: skip the regions already written by a previous run of the same job (a store of
            another job is an error); False starts afresh (the store is overwritten).
        progress: True for a progress bar, or a callable ``f(pixels_done, pixels_total)``.
        allow_degenerate: fit even an objective degenerate by construction (warned once).
        memory: bytes one region may fill for ``chunk="auto"`` (default: measured where the
            regions run: :func:`fitting._cube_regions._budget_and_slots`).

    Returns:
        :class:`xarray.Dataset` (lazy, opened from ``out``): maps ``(y, x)`` of every free
        parameter component (its own unit: nm, 1/nm, dimensionless) and ``<name>_stderr``,
        ``chi2``, ``reduced_chi2``, ``num_steps``, ``converged``, ``result_code``, ``rank``,
        ``identifiable``, ``bands_used``, ``status`` (:data:`CUBE_STATUS`: 0 only for a
        trustworthy fit, 5/6/7 for fits made but implausible, on a bound or not converged);
        attributes name the parameters, state the rules (``negative_sigmas``,
        ``chi2_central``) and
        record the region size (``chunk``, ``chunk_size``, and for ``"auto"`` ``chunk_sizing``:
        the budget and the measured bytes it came from).
    """
    import xarray as xr

    t_start = time.perf_counter()
    cube = open_cube(cube, wavelength_nm, variable=variable)
    used_bands = _check_objective(objective, cube)
    ny, nx = cube.sizes["y"], cube.sizes["x"]
    auto = isinstance(chunk, str)
    if auto and chunk != "auto":
        raise LayerstackError(f"fit_cube: chunk must be (rows, columns) >= 1 or 'auto', got {chunk!r}")
    if not auto:
        chunk = tuple(int(c) for c in chunk)
        if len(chunk) != 2 or min(chunk) < 1:
            raise LayerstackError(f"fit_cube: chunk must be (rows, columns) >= 1 or 'auto', got {chunk!r}")
    if not (isinstance(chunk_size, int) and chunk_size >= 1):
        raise LayerstackError(f"fit_cube: chunk_size must be an integer >= 1, got {chunk_size!r}")
    require_compiled_method("fit_cube", method)
    if memory is not None and not (isinstance(memory, (int, np.integer)) and memory >= 1):
        raise LayerstackError(f"fit_cube: memory must be a number of bytes >= 1, got {memory!r}")
    k = negative_sigmas
    if isinstance(k, bool) or not isinstance(k, (int, float, np.integer, np.floating)) or \
            not 0.0 <= float(k) <= NEGATIVE_SIGMAS:
        raise LayerstackError(f"fit_cube: negative_sigmas must be a number from 0 to {NEGATIVE_SIGMAS:g} (readings "
                              f"below -{NEGATIVE_SIGMAS:g} sigma are refused by the Dataset check), got {k!r}")
    negative_sigmas = float(k)
    if mask is not None:
        mask = np.asarray(getattr(mask, "values", mask))
        if mask.dtype != bool or mask.shape != (ny, nx):
            raise LayerstackError(f"fit_cube: mask must be boolean shaped {(ny, nx)} (True = fit), got "
                                  f"{mask.dtype} {mask.shape}")
    # degeneracies: before any pixel is fitted
    structural = structural_degeneracy(objective)
    if structural:
        text = "fit_cube: the objective is degenerate by construction: " + "; ".join(structural)
        if not allow_degenerate:
            raise LayerstackError(text + " (allow_degenerate=True fits anyway; every pixel is then non-identifiable)")
        warnings.warn(text, stacklevel=2)
    elif (rank0 := rank_at_start(objective)) < objective.n_parameters:
        warnings.warn(f"fit_cube: the Jacobian at the starting values has rank {rank0} < {objective.n_parameters} free "
                      "parameters: some combination is not determined there (see each pixel's 'identifiable' map)",
                      stacklevel=2)
    fit_opts = tuple(sorted(fit_options.items()))
    names = tuple(objective.layout.names)
    if len({_var(n) for n in names}) != len(names):
        raise LayerstackError(f"fit_cube: parameter names {names} collide once made zarr-safe: name the parameters")
    out = str(out)
    existing = Path(out).exists()
    stored = None
    if existing and resume:
        try:
            stored = dict(xr.open_zarr(out, consolidated=False).attrs)
        except Exception:
            stored = {}
    c, owned = _client(client, n_workers)
    try:
        sizing = None
        if auto and stored and "chunk" in stored:  # resuming: the store's regions, whatever this machine's memory
            chunk = tuple(int(v) for v in json.loads(stored["chunk"]))
            log.info("fit_cube: chunk auto -> the store's regions of %d x %d pixels (resuming %s)", *chunk, out)
        elif auto:
            budget, slots = _budget_and_slots(c, memory)
            chunk, sizing = auto_region(objective, (ny, nx), int(cube.sizes["wavelength"]), cube.dtype.itemsize,
                                        chunk_size=chunk_size, method=method, fit_options=fit_opts, budget=budget,
                                        slots=slots)
            log.info("fit_cube: chunk auto -> regions of %d x %d pixels (%d regions, %d worker thread(s)); "
                     "chunk_size %d; measured: the compiled solver %.4g MB per call, %.4g kB per pixel; "
                     "budget %s (fits %d pixels)", chunk[0], chunk[1], len(cube_regions((ny, nx), chunk)), slots,
                     chunk_size, sizing["solver_bytes"] / 1e6, sizing["per_pixel_bytes"] / 1e3,
                     sizing["budget_source"], sizing["memory_fit_pixels"])
        fp = _fingerprint(objective, cube, chunk, method, chunk_size, (saturation, negative_sigmas), mask, fit_opts)
        attrs = {"fit_cube_job": fp, "parameters": json.dumps(list(names)),
                 "parameter_variables": json.dumps([_var(n) for n in names]), "method": method,
                 "status_codes": json.dumps({str(k): v for k, v in CUBE_STATUS.items()}),
                 "negative_sigmas": negative_sigmas, "chi2_central": CHI2_CENTRAL,
                 "sigma_given": int(objective.sigma_given),
                 "chunk": json.dumps(list(chunk)), "chunk_size": int(chunk_size),
                 "chunk_sizing": json.dumps(sizing if sizing is not None else "given"),
                 "source": str(cube.attrs.get("source", "array"))}
        if stored is not None:
            if stored.get("fit_cube_job") != fp:
                raise LayerstackError(f"fit_cube: {out} holds the maps of another job (objective, cube or settings "
                                      "differ): choose another store, or resume=False to overwrite it")
        else:
            _init_store(out, cube, names, chunk, attrs)
        regions = cube_regions((ny, nx), chunk)
        pending = [r for r in regions if not _marker(out, r[0], r[1]).exists()]
        done_px = sum((r[2].stop - r[2].start) * (r[3].stop - r[3].start) for r in regions) - \
            sum((r[2].stop - r[2].start) * (r[3].stop - r[3].start) for r in pending)
        total = ny * nx
        if len(pending) < len(regions):
            log.info("fit_cube: resuming %s: %d of %d regions already written", out, len(regions) - len(pending),
                     len(regions))
        settings = _Settings(out, names, method, chunk_size, saturation, used_bands, fit_opts,
                             bool(jax.config.jax_enable_x64), _negative_floor(objective, negative_sigmas),
                             bool(objective.sigma_given))
        report = progress_reporter(progress, total, desc="fit_cube", unit="px", initial=done_px)
        t0 = time.perf_counter()
        done0 = done_px

        def finished(summary):
            nonlocal done_px
            done_px += summary["pixels"]
            rate = (done_px - done0) / max(time.perf_counter() - t0, 1e-9)
            eta = (total - done_px) / rate if rate > 0 else float("inf")
            log.info("fit_cube: region %s: %d pixels (%d fitted) in %.3g s; %d/%d pixels, %.4g px/s, ETA %.0f s",
                     summary["region"], summary["pixels"], summary["fitted"], summary["seconds"], done_px, total, rate,
                     eta)
            if report is not None:
                report(done_px)

        def block_of(ys, xs):
            return cube.isel(y=ys, x=xs), None if mask is None else mask[ys, xs]

        if c is None:
            for iy, ix, ys, xs in pending:
                blk, m = block_of(ys, xs)
                finished(_fit_region(objective, blk.values, m, iy, ix, ys, xs, settings))
        elif pending:
            from distributed import as_completed

            obj = c.scatter(objective, broadcast=True, hash=False)
            futures = []
            for iy, ix, ys, xs in pending:
                blk, m = block_of(ys, xs)
                futures.append(c.submit(_fit_region, obj, blk, m, iy, ix, ys, xs, settings, pure=False,
                                        key=f"fit_cube-{fp[:12]}-{iy}-{ix}"))
            for f in as_completed(futures):
                finished(f.result())
    finally:
        if owned is not None:
            client_, cluster = owned
            client_.close()
            if cluster is not None:
                cluster.close()
    if report is not None and not pending:
        report(total)
    maps = xr.open_zarr(out, consolidated=False)
    counts = status_counts(maps)
    log.info("fit_cube: %s complete (%d pixels) in %.3g s; status: %s", out, total, time.perf_counter() - t_start,
             ", ".join(f"{CUBE_STATUS[c]} {k}" for c, k in counts.items() if k))
    flagged = {c: counts[c] for c in (5, 6, 7) if counts[c]}
    if flagged:
        warnings.warn(f"fit_cube: {sum(flagged.values())} pixel fit(s) not to be trusted as they are ("
                      + ", ".join(f"{k} {CUBE_STATUS[c]} (status {c})" for c, k in flagged.items())
                      + "): their values are in the maps, their 'status' is not 0", stacklevel=2)
    return maps


def status_counts(maps) -> dict:
    """``{code: pixels}`` of every :data:`CUBE_STATUS` code in the ``status`` map of ``maps``
    (counted chunk by chunk: bounded memory)."""
    import dask.array as da

    status = maps["status"].data
    status = status if isinstance(status, da.Array) else da.from_array(np.asarray(status))
    codes = sorted(CUBE_STATUS)
    found = da.bincount((status.astype(np.int16) - codes[0]).ravel(), minlength=len(codes)).compute()
    return {c: int(found[i]) for i, c in enumerate(codes)}
