r"""Many independent fits at once, and the joint calibration-series fit.

:func:`fit_batch` fits N independent data sets with the same :class:`~fitting.Objective`
(same model, parameters and starting values; only the data differ) in one compiled, vmapped
solve, N processed in chunks of ``chunk_size`` (bounded memory; the last chunk is padded so
that one compiled shape serves all). Every fit keeps its own convergence status: a failed fit
does not fail the batch.

:func:`calibration_series` builds the joint objective of a calibration series: several samples
of the same varnish or ink at different thicknesses over the same background share α(λ) and
ρg(λ) (each on a B-spline basis), each has its own thickness; ρg starts from — or is fixed
to — the inversion of a bare-background measurement, :func:`layerstack_jax.invert_background`
(Simonot et al. eqs. 86–87). With ρg free, that bare-background spectrum is also fitted, as a
dataset of its own (``Dataset(bare=True)``: the stack without its layers), so the joint fit
sees both the coated samples and the uncoated background.
"""

from __future__ import annotations

import dataclasses
import sys
from typing import Callable, Optional, Union

import jax
import jax.numpy as jnp
import numpy as np

from layerstack_jax import Geometry, LambertianBackground, LayerstackError, Stack, invert_background

from ._objective import Dataset, Objective
from ._parameters import alpha as alpha_parameter
from ._parameters import rho_g as rho_g_parameter
from ._parameters import thickness as thickness_parameter
from ._results import linearised_covariance
from ._solve import HOST_METHODS, SolverOptions, compiled_fit, result_message, starting_point

__all__ = ["BatchResult", "fit_batch", "calibration_series", "background_rho_g"]


@dataclasses.dataclass
class BatchResult:
    """Outcome of :func:`fit_batch`, one row per fit.

    Attributes:
        x, stderr: ``(N, P)`` physical values and standard errors (NaN where not identifiable);
        values, errors: ``{name: (N, *shape)}`` per parameter;
        converged: ``(N,)`` bool; result_code ``(N,)``; num_steps ``(N,)``;
        chi2, reduced_chi2: ``(N,)``; rank: ``(N,)`` of the normalised Jacobian;
        covariance_scaled: True if uncertainties are scaled by each fit's reduced χ².
        wall_time_s: wall-clock time of the batch, seconds.
        results: with ``fit_batch(..., full_results=True)``, one :class:`~fitting.FitResult` per
            fit (report, residual spectra, covariance, plot, JSON), else None.

    Values and errors are in each parameter's own unit (nm for thicknesses, 1/nm for α,
    dimensionless for n and ρg); χ² values are dimensionless.
    """

    objective: Objective
    method: str
    names: list
    x: np.ndarray
    stderr: np.ndarray
    values: dict
    errors: dict
    converged: np.ndarray
    result_code: np.ndarray
    num_steps: np.ndarray
    chi2: np.ndarray
    reduced_chi2: np.ndarray
    rank: np.ndarray
    covariance_scaled: bool
    wall_time_s: float = float("nan")
    results: Optional[list] = None

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @property
    def reasons(self) -> list:
        """Reason text of each fit."""
        return [result_message(c) for c in self.result_code]

    def summary(self) -> str:
        n = len(self)
        ok = int(self.converged.sum())
        lines = [f"{n} fits ({self.method}): {ok} converged, {n - ok} not"]
        codes, counts = np.unique(self.result_code[~self.converged], return_counts=True)
        for c, k in zip(codes, counts):
            lines.append(f"  {k} × {result_message(int(c))}")
        lines.append(f"  steps: median {np.median(self.num_steps):g}, max {self.num_steps.max()}")
        lines.append(f"  reduced chi2: median {np.nanmedian(self.reduced_chi2):.4g}")
        deficient = int((self.rank < self.x.shape[1]).sum())
        if deficient:
            lines.append(f"  {deficient} fit(s) with a non-identifiable parameter combination (rank deficient)")
        return "\n".join(lines)


def _progress_callback(progress) -> Optional[Callable[[int, int], None]]:
    if progress is None or progress is False:
        return None
    if callable(progress):
        return progress
    try:  # optional nicety
        from tqdm.auto import tqdm  # type: ignore

        bar = {}

        def tq(done, total):
            if "bar" not in bar:
                bar["bar"] = tqdm(total=total, unit="fit")
            bar["bar"].update(done - bar["bar"].n)
            if done >= total:
                bar["bar"].close()

        return tq
    except ImportError:
        def plain(done, total):
            print(f"\rfitting: {done}/{total}", end="\n" if done >= total else "", file=sys.stderr, flush=True)

        return plain


def fit_batch(objective: Objective, data, method: str = "lm", *, chunk_size: int = 128,
              progress: Union[None, bool, Callable[[int, int], None]] = None, max_steps: int = 256,
              rtol: float = 1e-10, atol: float = 1e-12, gtol: float = 1e-9, scale_covariance: Optional[bool] = None,
              rank_rtol: float = 1e-8, full_results: bool = False) -> BatchResult:
    """N independent fits of ``objective`` to N data sets, in one compiled vmapped solve.

    Args:
        objective: the model; its own data are not used, its σ / weights and masks are.
        data: one array per dataset shaped ``(N, samples, wl)`` (``(N, wl)`` for one sample),
            or a single array when the objective has one dataset.
        method, max_steps, rtol, atol, gtol, scale_covariance, rank_rtol: as :func:`~fitting.fit`.
        chunk_size: fits per compiled call (memory bound); N is processed in ⌈N/chunk⌉ calls
            of the same compiled function.
        progress: a callback ``f(done, total)`` called after each chunk, or True for a
            progress bar (tqdm if installed, else a line on stderr).
        full_results: also build a full :class:`~fitting.FitResult` per fit
            (``BatchResult.results``; memory grows with N: for tens or hundreds of fits).

    Data are in the unit each dataset's geometry reads (a dimensionless reflectance or
    reflectance factor, 1/sr for BRDF, degrees for ψ/Δ). Returns a :class:`BatchResult` with
    parameters in their own units (nm, 1/nm, dimensionless).
    """
    import time

    start_time = time.perf_counter()
    o = SolverOptions(method, rtol, atol, gtol, max_steps)
    if method in HOST_METHODS:
        raise LayerstackError(
            f"fit_batch: method {method!r} runs on the host one fit at a time; batched fits need a compiled "
            "solver: 'lm', 'gauss-newton', 'dogleg', 'bfgs' or 'lbfgsb'"
        )
    if not (isinstance(chunk_size, int) and chunk_size >= 1):
        raise LayerstackError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    if objective.n_parameters == 0:
        raise LayerstackError("the objective has no free parameter")
    (ys, ws), n = objective.batch_args(data)
    chunk = min(chunk_size, n)
    n_chunks = -(-n // chunk)
    pad = n_chunks * chunk - n
    if pad:
        ys = tuple(jnp.concatenate([y, jnp.broadcast_to(y[:1], (pad,) + y.shape[1:])]) for y in ys)
        ws = tuple(jnp.concatenate([w, jnp.broadcast_to(w[:1], (pad,) + w.shape[1:])]) for w in ws)
    y0 = jnp.asarray(starting_point(objective, o, objective.layout.x0))
    y0 = jnp.broadcast_to(y0, (chunk,) + y0.shape)
    fn = compiled_fit(objective, o, batched=True)
    report = _progress_callback(progress)
    outs = []
    for c in range(n_chunks):
        sl = slice(c * chunk, (c + 1) * chunk)
        out = fn(y0, (tuple(y[sl] for y in ys), tuple(w[sl] for w in ws)), objective.optics)
        outs.append(jax.tree.map(np.asarray, out))
        if report is not None:
            report(min((c + 1) * chunk, n), n)
    x, steps, code, _model, res, pen, J = (
        np.concatenate([o_[k] for o_ in outs])[:n] if not isinstance(outs[0][k], tuple)
        else tuple(np.concatenate([o_[k][j] for o_ in outs])[:n] for j in range(len(outs[0][k])))
        for k in range(7)
    )
    layout = objective.layout
    chi2 = sum(np.sum(r ** 2, axis=(-2, -1)) for r in res)
    dof = objective.n_points - layout.size
    red = chi2 / dof if dof > 0 else np.full(n, np.nan)
    scaled = (not objective.sigma_given) if scale_covariance is None else bool(scale_covariance)
    cov, sv, rank, _, _ = linearised_covariance(J, x, layout.scale, rank_rtol)
    if scaled:
        cov = cov * red[:, None, None]
    err = np.sqrt(np.clip(np.diagonal(cov, axis1=-2, axis2=-1), 0, None))
    err = np.where((rank < layout.size)[:, None], np.nan, err)
    values = layout.values(x)
    errors = layout.values(err, fill=np.nan)
    full = None
    if full_results:
        from ._results import build_result

        full = [build_result(objective, o, x[i], int(steps[i]), int(code[i]), [m[i] for m in _model],
                             [r[i] for r in res], pen[i], J[i], (tuple(y[i] for y in ys), tuple(w[i] for w in ws)),
                             scale_covariance=scale_covariance, rank_rtol=rank_rtol) for i in range(n)]
    return BatchResult(objective, method, list(layout.names), x, err, values, errors, code == 0, code, steps, chi2,
                       red, rank, scaled, time.perf_counter() - start_time, full)


def background_rho_g(wavelength_nm, measured, geometry: Geometry, n_g: float = 1.5, ambient: float = 1.0,
                     *, nodes: Optional[int] = None) -> np.ndarray:
    """Intrinsic reflectance ρg of a bare Lambertian background (index ``n_g``) from its
    measured spectrum — Simonot eq. 86 (sphere) or 87 (radiance detector), through
    :func:`layerstack_jax.invert_background` — clipped to [0, 1] and checked.

    ``wavelength_nm`` (nm) and ``measured`` both ``(wl,)``; ``measured`` as the geometry reads it
    (a dimensionless reflectance (factor), or 1/sr for :class:`~layerstack_jax.BRDF`). Returns
    ρg ``(wl,)``, a dimensionless fraction."""
    y = np.asarray(measured, dtype=float)
    wl = np.asarray(wavelength_nm, dtype=float)
    if y.shape != wl.shape:
        raise LayerstackError(f"background spectrum: {y.size} values for {wl.size} wavelengths")
    if np.any(~np.isfinite(y)) or np.any(y < 0):
        raise LayerstackError("background spectrum: values must be finite and >= 0")
    bare = Stack(ambient, [], LambertianBackground(n_g, 0.0))
    kw = {} if nodes is None else {"nodes": nodes}
    rho = np.asarray(invert_background(bare, wl, y, geometry, **kw))
    if np.any(rho > 1 + 1e-6):
        raise LayerstackError(
            f"background spectrum: inverted rho_g reaches {rho.max():.4g} > 1; check the geometry and n_g"
        )
    return np.clip(rho, 0.0, 1.0)


def calibration_series(stack: Stack, wavelength_nm, spectra, geometry: Geometry, *, layer=0, thicknesses=None,
                       alpha_basis=20, rho_g_basis: Optional[int] = 20, background=None, background_geometry=None,
                       known=(0,), sigma=None, alpha_smoothness: float = 0.0, fit_background: bool = True,
                       background_sigma=None, nodes: Optional[int] = None) -> Objective:
    """Joint objective of a calibration series (see the module docstring).

    Args:
        stack: template stack: the layer (``layer``, position or name) over a
            :class:`~layerstack_jax.LambertianBackground`; its α and ρg are starting values.
        wavelength_nm: model grid (nm) on which ``spectra`` (and ``background``) are given.
        spectra: ``(samples, wl)`` measured spectra of the coated samples.
        geometry: their measurement geometry.
        thicknesses: ``(samples,)`` starting thicknesses in nm (default: the stack's).
        known: samples whose thickness is known (kept at its value in ``thicknesses``). At
            least one is needed: an incoherent layer's spectra depend on α and h only through
            α·h (Beer, Simonot eq. 61), so without a known thickness only α·h of each sample
            is determined (the fit then reports that combination as non-identifiable).
        alpha_basis: B-spline functions for α(λ) (int), ``"free"``, or a matrix.
        rho_g_basis: B-spline functions for ρg(λ), or None to keep ρg fixed (to the inverted
            background when ``background`` is given, else to the stack's).
        background: optional ``(wl,)`` measurement of the bare background: ρg from
            :func:`background_rho_g` becomes the start (or the fixed value) of ρg.
        background_geometry: geometry of that measurement (default: ``geometry``).
        sigma: σ of the spectra (scalar or ``(samples, wl)``), or None.
        fit_background: when ρg is free and ``background`` is given, also fit the bare-background
            spectrum (a :class:`~fitting.Dataset` with ``bare=True``): it pins ρg(λ) where the
            coated samples are dark and ρg would otherwise trade off against α(λ).
        background_sigma: σ of the background spectrum (scalar or ``(wl,)``; default ``sigma``
            when that is a scalar).
        nodes: quadrature nodes per segment of the diffuse integrals (default
            :data:`layerstack_jax.DEFAULT_NODES`), for the fit and the ρg inversion.
    """
    if not isinstance(stack.exit, LambertianBackground):
        raise LayerstackError("calibration_series: the stack must lie over a LambertianBackground")
    y = np.asarray(spectra, dtype=float)
    if y.ndim != 2:
        raise LayerstackError(f"calibration_series: spectra must be (samples, wl), got shape {y.shape}")
    wl = np.asarray(wavelength_nm, dtype=float)
    rho = None
    if background is not None:
        n_g = np.real(np.asarray(stack.exit.index(wl)))
        if np.ndim(n_g):
            raise LayerstackError("calibration_series: the background index must be a constant to invert ρg")
        rho = background_rho_g(wl, background, background_geometry or geometry, float(n_g),
                               float(np.real(np.asarray(stack.ambient(wl)))), nodes=nodes)
        stack = dataclasses.replace(stack, exit=LambertianBackground(stack.exit.index, rho))
    fixed = np.zeros(y.shape[0], bool)
    for s in known:
        if not -y.shape[0] <= int(s) < y.shape[0]:
            raise LayerstackError(f"calibration_series: known sample {s} does not exist ({y.shape[0]} samples)")
        fixed[int(s)] = True
    params = [thickness_parameter(layer, value=thicknesses, per_sample=True, fixed=fixed)]
    params.append(alpha_parameter(layer, basis=alpha_basis, smoothness=alpha_smoothness))
    if rho_g_basis is not None:
        params.append(rho_g_parameter(basis=rho_g_basis))
    datasets = [Dataset(geometry, y, sigma=sigma, name="calibration series")]
    if background is not None and rho_g_basis is not None and fit_background:
        if background_sigma is None and sigma is not None and np.ndim(sigma) > 0:
            raise LayerstackError("calibration_series: give background_sigma (sigma is per point)")
        s_bg = sigma if background_sigma is None else background_sigma
        if (s_bg is None) != (sigma is None):
            raise LayerstackError("calibration_series: give sigma for both the spectra and the background, or neither")
        datasets.append(Dataset(background_geometry or geometry, np.asarray(background, float), sigma=s_bg,
                                name="bare background", bare=True))
    kw = {} if nodes is None else {"nodes": nodes}
    return Objective(stack, wl, datasets, params, n_samples=y.shape[0], **kw)
