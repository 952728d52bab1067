r"""Many independent fits at once, and the joint calibration-series fit.

:func:`fit_batch` fits N independent data sets with the same :class:`~fitting.Objective`
(same model, parameters and starting values; only the data differ) in one compiled solve
(each fit by the single fit's program, :data:`fitting._compiled_fit.BLOCK`), N processed in chunks of
``chunk_size`` (bounded memory; the last chunk is padded so that one compiled shape serves
all). Every fit keeps its own convergence status: a failed fit does not fail the batch, and a
batch that cannot finish says so (:func:`fitting._watchdog.wait_for`) instead of waiting.

:func:`calibration_series` builds the joint objective of a calibration series: several samples
of the same varnish, ink or sheet at different thicknesses share α(λ) (on a B-spline basis or
free at every wavelength), each has its own thickness, some known; over a Lambertian
background they also share ρg(λ), which starts from — or is fixed to — the inversion of a
bare-background measurement, :func:`layerstack_jax.invert_background` (Simonot et al. eqs.
86–87). The exit may also be a specular substrate or the ambient (a free-standing sheet), and
the samples may be measured in several geometries at once (reflectance and transmittance). With ρg free, that bare-background spectrum is also fitted, as a
dataset of its own (``Dataset(bare=True)``: the stack without its layers), so the joint fit
sees both the coated samples and the uncoated background.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Callable, Optional, Union

import jax
import jax.numpy as jnp
import numpy as np

from layerstack_jax import (
    Geometry,
    LambertianBackground,
    LayerstackError,
    Stack,
    invert_background,
    progress_reporter,
)

from ._bound_settling import BY_LBFGSB, RESTARTED, bound_note, settle_on_bounds
from ._compiled_fit import compiled_fit, refit_chi2
from ._dataset import Dataset
from ._multistart import multistart_points
from ._objective import Objective
from ._parameters import alpha as alpha_parameter
from ._parameters import rho_g as rho_g_parameter
from ._parameters import thickness as thickness_parameter
from ._results import build_result
from ._solver_options import SolverOptions, require_compiled_method, starting_point
from ._statistics import (
    SIGMA_DEFAULT,
    SIGMA_GIVEN,
    FitStatistics,
    batch_separability,
    bound_contacts,
    fit_statistics,
    separability_summary,
)
from ._status import CONVERGED, INVALID_DATA, result_message
from ._watchdog import STALL_S, wait_for

__all__ = ["BatchResult", "fit_batch", "calibration_series", "background_rho_g"]


@dataclasses.dataclass
class BatchResult:
    """Outcome of :func:`fit_batch`, one row per fit.

    Attributes:
        x, stderr: ``(N, P)`` physical values and standard errors (NaN where not identifiable,
            and for fits not made);
        values, errors: ``{name: (N, *shape)}`` per parameter;
        converged: ``(N,)`` bool (the solver met its tolerance); result_code ``(N,)``
            (:data:`fitting._status.STATUS`); num_steps ``(N,)``;
        chi2, reduced_chi2: ``(N,)``; dof: degrees of freedom of each fit; rank: ``(N,)`` of the
            normalised Jacobian; unresolved: ``(N, P)`` components the data do not determine;
        covariance_scaled: True if uncertainties are scaled by each fit's reduced χ²;
            sigma_origin: ``"given"``, ``"estimated from residuals"`` or ``"default 1 — χ² not
            meaningful"``;
        at_bound: ``(N, P)`` components on a bound; finished_on_bound: ``(N,)`` fits of an
            unconstrained method settled on an optimal bound; restarted: ``(N,)`` fits it ended
            on a bound that is not optimal, restarted from there; finished_with_lbfgsb: ``(N,)``
            fits that ended on such a bound again, finished by L-BFGS-B
            (:func:`fitting._bound_settling.settle_on_bounds`);
        invalid_data: ``{row: message}`` of the fits not made (their data failed the checks);
        separability: per fit, the groups of parameters correlated beyond 0.99 with the
            combination the data determine (:func:`fitting._statistics.separability_findings`;
            None for fits not made);
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
    dof: int = 0
    sigma_origin: str = ""
    unresolved: Optional[np.ndarray] = None
    at_bound: Optional[np.ndarray] = None
    finished_on_bound: Optional[np.ndarray] = None
    restarted: Optional[np.ndarray] = None
    finished_with_lbfgsb: Optional[np.ndarray] = None
    invalid_data: dict = dataclasses.field(default_factory=dict)
    separability: Optional[list] = None

    def __len__(self) -> int:
        return int(self.x.shape[0])

    @property
    def reasons(self) -> list:
        """Reason text of each fit (the library's words, :data:`fitting._status.STATUS`)."""
        return [result_message(c) + (f": {self.invalid_data[i]}" if i in self.invalid_data else "")
                for i, c in enumerate(self.result_code)]

    def summary(self) -> str:
        n = len(self)
        ok = int(self.converged.sum())
        lines = [f"{n} fits ({self.method}): {ok} converged, {n - ok} not"]
        codes, counts = np.unique(self.result_code[~self.converged], return_counts=True)
        for c, k in zip(codes, counts):
            lines.append(f"  {k} × {result_message(int(c))}")
        for i, msg in list(self.invalid_data.items())[:5]:
            lines.append(f"    fit {i}: {msg}")
        if self.finished_on_bound is not None and self.finished_on_bound.any():
            lines.append(f"  {int(self.finished_on_bound.sum())} fit(s) converged on a bound ({self.method} held the "
                         "parameter there; the bound is optimal)")
        if self.restarted is not None and self.restarted.any():
            lines.append(f"  {int(self.restarted.sum())} fit(s) restarted ({self.method} reached a bound on the way "
                         "that is not optimal there)")
        if self.finished_with_lbfgsb is not None and self.finished_with_lbfgsb.any():
            lines.append(f"  {int(self.finished_with_lbfgsb.sum())} fit(s) finished with L-BFGS-B ({self.method} reached "
                         "a bound that is not optimal there)")
        if self.at_bound is not None and self.at_bound.any():
            per = self.at_bound.sum(axis=0)
            lines.append("  on a bound: " + ", ".join(f"{nm} in {k} fit(s)" for nm, k in zip(self.names, per) if k))
        made = self.result_code != INVALID_DATA
        if made.any():
            lines.append(f"  steps: median {np.median(self.num_steps[made]):g}, max {self.num_steps[made].max()}")
        if self.sigma_origin == SIGMA_GIVEN or (self.sigma_origin != SIGMA_DEFAULT and self.covariance_scaled
                                                 and self.objective.sigma_given):
            lines.append(f"  reduced chi2: median {np.nanmedian(self.reduced_chi2) if made.any() else np.nan:.4g} "
                         f"(dof {self.dof}, σ given)")
        else:
            lines.append(f"  no σ given: χ² not meaningful; σ {self.sigma_origin}")
        if self.separability is not None:
            lines += separability_summary(self.separability)
        deficient = int((self.rank < self.x.shape[1]).sum())
        if deficient:
            lines.append(f"  {deficient} fit(s) with a non-identifiable parameter combination (rank deficient)")
        return "\n".join(lines)


def _rows(data, n):
    return [d[n] if np.ma.isMaskedArray(d) else np.asarray(d)[n] for d in data]  # a per-fit mask kept


def _screen(objective: Objective, data):
    """``(args, n, good, invalid)``: the checked batch args of the fits whose data pass the
    objective's checks, their row indices ``good`` and ``{row: message}`` of the others.
    A problem common to every fit (shapes, counts) raises as before."""
    data = list(data) if isinstance(data, (list, tuple)) else [data]
    try:
        args, n = objective.batch_args(data)
        return args, n, np.arange(n), {}
    except LayerstackError as first:
        sizes = {np.shape(d)[0] if np.ndim(d) >= 2 else None for d in data}
        if len(sizes) != 1 or None in sizes:
            raise
        n = sizes.pop()
        invalid = {}
        for i in range(n):  # only when some fit's data fail: find which
            try:
                objective.batch_args(_rows(data, slice(i, i + 1)))
            except LayerstackError as e:
                invalid[i] = str(e)
        good = np.array([i for i in range(n) if i not in invalid], dtype=int)
        if good.size == 0:
            raise first
        args, _ = objective.batch_args(_rows(data, good))
        return args, n, good, invalid


class LookupTable:
    r"""Model spectra of an objective at ``size`` points of its parameter box, for starting each of
    many fits near its own optimum (``fit_batch(..., start="lookup")``).

    The points are those of a multi-start (:func:`fitting._multistart.multistart_points`: the
    objective's start, then draws uniform between finite bounds and log-uniform within a factor
    10 of the start where one side is open); their spectra are computed once, by one compiled
    ``lax.map``, and do not depend on the data. :meth:`nearest` gives, for each fit, the point
    with the smallest weighted squared residual :math:`\sum w^2 r(m, y)^2` to its data, ``r`` the
    objective's own residual (:meth:`~fitting.Objective.residual_of`: Δ wrapped for an
    ellipsometer) — for all the fits of a chunk at once, a block of table points at a time."""

    #: Table points compared with all the fits of a chunk at once (memory: fits × BLOCK × points).
    BLOCK = 32

    def __init__(self, objective: Objective, size: int = 256, seed: int = 0):
        if not (isinstance(size, int) and size >= 1):
            raise LayerstackError(f"lookup size must be an integer >= 1, got {size!r}")
        self._objective = objective
        self.points = multistart_points(objective, size, seed)  # (G, P) physical
        model = jax.jit(lambda X: jax.lax.map(lambda x: objective.predict(x, objective.optics), X, batch_size=16))
        self.spectra = tuple(np.asarray(m).reshape(size, -1) for m in model(jnp.asarray(self.points)))

    @classmethod
    def of(cls, objective: Objective, size: int = 256, seed: int = 0) -> "LookupTable":
        """The table of ``objective``, made once and kept with its compiled solvers (the
        regions of a cube fit reuse it)."""
        cache = objective.cache
        key = ("lookup", size, seed)
        if key not in cache:
            cache[key] = cls(objective, size, seed)
        return cache[key]

    def nearest(self, ys, ws) -> np.ndarray:
        """``(N, P)`` physical starting points for data ``ys`` with weights ``ws`` (one
        ``(N, samples, wl)`` array per dataset each)."""
        n = np.asarray(ys[0]).shape[0]
        g = self.points.shape[0]
        d = np.zeros((n, g))
        for i, (y, w, m) in enumerate(zip(ys, ws, self.spectra)):
            y = jnp.asarray(y).reshape(n, 1, -1)
            w = jnp.asarray(w).reshape(n, 1, -1)
            for a in range(0, g, self.BLOCK):  # (N, block, points) at a time: bounded memory
                r = w * self._objective.residual_of(i, jnp.asarray(m[None, a:a + self.BLOCK]), y)
                d[:, a:a + self.BLOCK] += np.asarray(jnp.sum(r * r, axis=-1))
        return self.points[np.argmin(np.where(np.isfinite(d), d, np.inf), axis=1)]


def fit_batch(objective: Objective, data, method: str = "lm", *, chunk_size: int = 128,
              progress: Union[None, bool, Callable[[int, int], None]] = None, max_steps: int = 256,
              rtol: float = 1e-10, atol: float = 1e-12, gtol: float = 1e-9, sigma_tol: float = 1e-3,
              scale_covariance: Optional[bool] = None,
              rank_rtol: float = 1e-8, full_results: bool = False, start: str = "objective",
              lookup_size: int = 256, structure: str = "auto", timeout_s: Optional[float] = None,
              stall_s: Optional[float] = STALL_S) -> BatchResult:
    """N independent fits of ``objective`` to N data sets, in one compiled solve.

    Args:
        objective: the model; its own data are not used, its σ / weights and masks are.
        data: one array per dataset shaped ``(N, samples, wl)`` (``(N, wl)`` for one sample),
            or a single array when the objective has one dataset.
        method, max_steps, rtol, atol, gtol, sigma_tol, scale_covariance, rank_rtol, structure: as
            :func:`~fitting.fit`.
        chunk_size: fits per compiled call (memory bound); N is processed in ⌈N/chunk⌉ calls
            of the same compiled function.
        progress: a callback ``f(done, total)`` called after each chunk, True for a tqdm
            progress bar, False for none; default: a bar when there is more than one chunk.
        full_results: also build a full :class:`~fitting.FitResult` per fit
            (``BatchResult.results``; memory grows with N: for tens or hundreds of fits).
        start: ``"objective"`` — every fit starts from the objective's start; ``"lookup"`` —
            each fit starts from the nearest of ``lookup_size`` precomputed model spectra over
            the parameter box (:class:`LookupTable`): fewer solver steps for data spread over a
            wide box, at the cost of ``lookup_size`` forward spectra computed once.
        timeout_s: wall-clock limit of the batch in seconds (None: none): past it,
            :class:`~layerstack_jax.LayerstackError` says how many chunks were done.
        stall_s: a chunk solved on the CPU whose process has used no CPU time for this many
            seconds is stuck, not slow: :class:`~layerstack_jax.LayerstackError` says so
            (:func:`fitting._watchdog.wait_for`; None: wait as long as it takes).

    A fit whose data fail the objective's checks (NaN, a negative reflectance …) is not made:
    it is flagged in its own row (status ``INVALID_DATA``, NaN values, the reason in
    ``invalid_data``) and the others are fitted as usual. A fit of an unconstrained method that
    stops on an optimal bound is converged there (``finished_on_bound``), as in :func:`~fitting.fit`.
    The statistics are those of :func:`~fitting.fit` (:func:`fitting._statistics.fit_statistics`):
    the same numbers for the same data.

    Data are in the unit each dataset's geometry reads (a dimensionless reflectance or
    reflectance factor, 1/sr for BRDF, degrees for ψ/Δ). Returns a :class:`BatchResult` with
    parameters in their own units (nm, 1/nm, dimensionless).
    """
    import time

    start_time = time.perf_counter()
    o = SolverOptions(method, rtol, atol, gtol, max_steps, sigma_tol, structure)
    require_compiled_method("fit_batch", method)
    if not (isinstance(chunk_size, int) and chunk_size >= 1):
        raise LayerstackError(f"chunk_size must be an integer >= 1, got {chunk_size!r}")
    if objective.n_parameters == 0:
        raise LayerstackError("the objective has no free parameter")
    (ys, ws), n_all, good, invalid = _screen(objective, data)
    n = good.size
    chunk = min(chunk_size, n)
    n_chunks = -(-n // chunk)
    pad = n_chunks * chunk - n
    if pad:
        ys = tuple(jnp.concatenate([y, jnp.broadcast_to(y[:1], (pad,) + y.shape[1:])]) for y in ys)
        ws = tuple(jnp.concatenate([w, jnp.broadcast_to(w[:1], (pad,) + w.shape[1:])]) for w in ws)
    if start not in ("objective", "lookup"):
        raise LayerstackError(f"start must be 'objective' or 'lookup', got {start!r}")
    table = LookupTable.of(objective, lookup_size) if start == "lookup" else None
    y0 = jnp.asarray(starting_point(objective, o, objective.layout.x0))
    y0 = jnp.broadcast_to(y0, (chunk,) + y0.shape)
    fn = compiled_fit(objective, o, batched=True)
    report = progress_reporter(progress, n, desc="fit_batch", unit="fit", auto=n_chunks > 1)
    for name, v in (("timeout_s", timeout_s), ("stall_s", stall_s)):
        if v is not None and not (isinstance(v, (int, float)) and v > 0):
            raise LayerstackError(f"{name} must be > 0 seconds or None, got {v!r}")
    deadline = None if timeout_s is None else start_time + timeout_s
    outs = []
    for c in range(n_chunks):
        sl = slice(c * chunk, (c + 1) * chunk)
        part = (tuple(y[sl] for y in ys), tuple(w[sl] for w in ws))
        if table is not None:
            y0 = jnp.asarray(starting_point(objective, o, table.nearest(*part)))
        out = fn(y0, part, objective.optics)
        outs.append(wait_for(out, what=f"fit_batch: chunk {c + 1} of {n_chunks} ({chunk} fits)", stall_s=stall_s,
                             deadline=deadline, hint=f"{c} of {n_chunks} chunks were done"))
        if report is not None:
            report(min((c + 1) * chunk, n))
    out = jax.tree.map(lambda *a: np.concatenate(a)[:n], *outs)
    args = (tuple(np.asarray(y)[:n] for y in ys), tuple(np.asarray(w)[:n] for w in ws))
    out, settled, finished = settle_on_bounds(objective, o, out, args)
    layout = objective.layout
    stats = fit_statistics(out.jacobian, out.x, out.residuals, layout, objective.n_points,
                           sigma_given=objective.sigma_given, scale_covariance=scale_covariance, rank_rtol=rank_rtol)
    lo, hi = bound_contacts(out.x, layout.lower, layout.upper, layout.scale)
    full = None
    if full_results:
        full = [None] * n_all
        for k, i in enumerate(good):
            row = jax.tree.map(lambda a: a[k], out)
            names = [nm for nm, b in zip(layout.names, lo[k] | hi[k]) if b]
            full[i] = build_result(objective, o, row, jax.tree.map(lambda a: a[k], args),
                                   scale_covariance=scale_covariance, rank_rtol=rank_rtol,
                                   note=bound_note(method, names, bool(settled[k]), int(finished[k])),
                                   stats=_row(stats, k), refit=functools.partial(refit_chi2, objective, o))

    def spread(a, fill):  # rows of the fits made -> all N rows
        a = np.asarray(a)
        full_a = np.full((n_all,) + a.shape[1:], fill, dtype=np.result_type(a, type(fill)))
        full_a[good] = a
        return full_a

    x = spread(out.x, np.nan)
    err = spread(stats.stderr, np.nan)
    code = spread(out.status, INVALID_DATA)
    return BatchResult(
        objective, method, list(layout.names), x, err, layout.values(x), layout.values(err, fill=np.nan),
        code == CONVERGED, code, spread(out.num_steps, 0), spread(stats.chi2, np.nan),
        spread(stats.reduced_chi2, np.nan), spread(stats.rank, layout.size),
        stats.sigma_origin not in (SIGMA_GIVEN, SIGMA_DEFAULT), time.perf_counter() - start_time, full,
        dof=stats.dof, sigma_origin=stats.sigma_origin, unresolved=spread(stats.unresolved, False),
        at_bound=spread(lo | hi, False), finished_on_bound=spread(settled, False),
        restarted=spread(finished == RESTARTED, False), finished_with_lbfgsb=spread(finished == BY_LBFGSB, False),
        invalid_data=invalid, separability=spread_list(batch_separability(stats, out.x, layout), good, n_all),
    )


def spread_list(items: list, good, n_all: int) -> list:
    """Per-fit ``items`` of the fits made (rows ``good``) → all ``n_all`` rows (None for the others)."""
    out = [None] * n_all
    for k, i in enumerate(good):
        out[int(i)] = items[k]
    return out


def _row(stats: FitStatistics, k: int) -> FitStatistics:
    """Row ``k`` of a batch's statistics."""
    per_fit = ("chi2", "reduced_chi2", "s2", "covariance", "stderr", "correlation", "singular_values", "rank",
               "null_vectors", "log_directions", "unresolved", "zero_columns")
    return stats._replace(**{f: np.asarray(getattr(stats, f))[k] for f in per_fit})


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


#: ``rho_g_basis`` by default: 20 B-spline functions over a Lambertian background, no ρg otherwise.
_AUTO = "auto"


def _per_dataset(what: str, value, n: int, several: bool) -> list:
    """``value`` as one entry per dataset: given per dataset (a list or tuple of ``n``) when
    there are ``several``, else the one value."""
    if not several:
        return [value]
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise LayerstackError(f"calibration_series: with {n} geometries give {what} as a list of {n} (one per "
                              f"geometry), got {type(value).__name__}")
    return list(value)


def calibration_series(stack: Stack, wavelength_nm, spectra, geometry, *, layer=0, thicknesses=None,
                       alpha_basis=20, rho_g_basis=_AUTO, background=None, background_geometry=None,
                       known=(0,), sigma=None, alpha_smoothness: float = 0.0, fit_background: bool = True,
                       background_sigma=None, nodes: Optional[int] = None, parameters=()) -> Objective:
    """Joint objective of a calibration series (see the module docstring): samples of one layer
    at several thicknesses share its α(λ) (and ρg(λ) over a Lambertian background), each sample
    has its own thickness, some of them known.

    Args:
        stack: template stack: the layer (``layer``, position or name) over any exit — a
            :class:`~layerstack_jax.LambertianBackground`, a specular substrate, or the ambient
            again for a free-standing sheet (``Substrate(1.0)`` in air); its α (and ρg) are
            starting values.
        wavelength_nm: model grid (nm) on which ``spectra`` (and ``background``) are given.
        spectra: ``(samples, wl)`` measured spectra of the samples — or, with several
            geometries, one such array per geometry (the same samples measured in each: e.g.
            their reflectance and their transmittance, fitted together).
        geometry: their measurement geometry, or a list of geometries (one per array of
            ``spectra``), e.g. ``[Specular(8, "R"), Specular(0, "T")]``.
        thicknesses: ``(samples,)`` starting thicknesses in nm (default: the stack's); those of
            the ``known`` samples are kept.
        known: samples whose thickness is known (kept at its value in ``thicknesses``). At
            least one is needed: an incoherent layer's spectra depend on α and h only through
            α·h (Beer, Simonot eq. 61), so without a known thickness only α·h of each sample
            is determined (the fit then reports that combination as non-identifiable).
        alpha_basis: B-spline functions for α(λ) (int), ``"free"``, or a matrix.
        rho_g_basis: over a Lambertian background: B-spline functions for ρg(λ),
            ``"free"``, a matrix, or None to keep ρg fixed (to the inverted background when
            ``background`` is given, else to the stack's); default 20. Other exits have no ρg
            (leave the default).
        background: optional ``(wl,)`` measurement of the bare Lambertian background: ρg from
            :func:`background_rho_g` becomes the start (or the fixed value) of ρg.
        background_geometry: geometry of that measurement (default: ``geometry``, the first one).
        sigma: σ of the spectra (scalar or ``(samples, wl)``; one per geometry with several), or None.
        fit_background: when ρg is free and ``background`` is given, also fit the bare-background
            spectrum (a :class:`~fitting.Dataset` with ``bare=True``): it pins ρg(λ) where the
            coated samples are dark and ρg would otherwise trade off against α(λ).
        background_sigma: σ of the background spectrum (scalar or ``(wl,)``; default ``sigma``
            when that is a scalar).
        nodes: quadrature nodes per segment of the diffuse integrals (default
            :data:`layerstack_jax.DEFAULT_NODES`), for the fit and the ρg inversion.
        parameters: further :class:`~fitting.Parameter` objects fitted with the series, shared
            by the samples unless per sample (e.g. ``fitting.index_n("sheet")``: one n).
    """
    lambertian = stack.exit.diffuse
    if isinstance(rho_g_basis, str) and rho_g_basis == _AUTO:
        rho_g_basis = 20 if lambertian else None
    if not lambertian and (rho_g_basis is not None or background is not None):
        raise LayerstackError("calibration_series: rho_g and a bare-background measurement belong to a "
                              "LambertianBackground exit; this stack's exit is a specular substrate (or the ambient)")
    several = isinstance(geometry, (list, tuple))
    geometries = list(geometry) if several else [geometry]
    if not geometries:
        raise LayerstackError("calibration_series: no geometry given")
    ys = [np.asarray(y, dtype=float) for y in _per_dataset("spectra", spectra, len(geometries), several)]
    sigmas = _per_dataset("sigma", sigma, len(geometries), several and isinstance(sigma, (list, tuple)))
    sigmas = sigmas * len(geometries) if len(sigmas) == 1 else sigmas
    for y in ys:
        if y.ndim != 2:
            raise LayerstackError(f"calibration_series: spectra must be (samples, wl), got shape {y.shape}")
    if len({y.shape for y in ys}) != 1:
        raise LayerstackError("calibration_series: the spectra of each geometry must hold the same samples on the "
                              f"same grid, got shapes {[y.shape for y in ys]}")
    n_samples = ys[0].shape[0]
    wl = np.asarray(wavelength_nm, dtype=float)
    rho = None
    if background is not None:
        n_g = np.real(np.asarray(stack.exit.index(wl)))
        if np.ndim(n_g):
            raise LayerstackError("calibration_series: the background index must be a constant to invert ρg")
        rho = background_rho_g(wl, background, background_geometry or geometries[0], float(n_g),
                               float(np.real(np.asarray(stack.ambient(wl)))), nodes=nodes)
        stack = dataclasses.replace(stack, exit=LambertianBackground(stack.exit.index, rho))
    fixed = np.zeros(n_samples, bool)
    for s in known:
        if not -n_samples <= int(s) < n_samples:
            raise LayerstackError(f"calibration_series: known sample {s} does not exist ({n_samples} samples)")
        fixed[int(s)] = True
    params = [thickness_parameter(layer, value=thicknesses, per_sample=True, fixed=fixed)]
    params.append(alpha_parameter(layer, basis=alpha_basis, smoothness=alpha_smoothness))
    if rho_g_basis is not None:
        params.append(rho_g_parameter(basis=rho_g_basis))
    params.extend(parameters)
    name = "calibration series"
    datasets = [Dataset(g, y, sigma=sg, name=name if len(geometries) == 1 else f"{name}: {g.label}")
                for g, y, sg in zip(geometries, ys, sigmas)]
    if background is not None and rho_g_basis is not None and fit_background:
        sigma = sigmas[0]
        if background_sigma is None and sigma is not None and np.ndim(sigma) > 0:
            raise LayerstackError("calibration_series: give background_sigma (sigma is per point)")
        s_bg = sigma if background_sigma is None else background_sigma
        if (s_bg is None) != (sigma is None):
            raise LayerstackError("calibration_series: give sigma for both the spectra and the background, or neither")
        datasets.append(Dataset(background_geometry or geometries[0], np.asarray(background, float), sigma=s_bg,
                                name="bare background", bare=True))
    kw = {} if nodes is None else {"nodes": nodes}
    return Objective(stack, wl, datasets, params, n_samples=n_samples, **kw)
