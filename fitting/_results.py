r"""Fit results: the record :class:`FitResult` (values, uncertainties, identifiability, a report
that tells the truth, JSON and plot) and its making from a compiled fit's output
(:func:`build_result`).

The numbers come from :mod:`fitting._statistics`, the one computation shared with
:func:`~fitting.fit_batch`; the words of the report — the quality verdict, the warnings, the
parameters the data cannot separate — from :mod:`fitting._fit_findings`.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from ._fit_findings import (
    _non_identifiable,
    bounds_hit,
    delta_sign_warnings,
    identifiability_lines,
    not_separated,
    percent_warnings,
    quality_verdict,
    separability_warning,
    structural_degeneracy,
)
from ._objective import Objective
from ._statistics import (
    CORRELATION_LIMIT,
    SIGMA_DEFAULT,
    SIGMA_GIVEN,
    fit_statistics,
    separability_findings,
)
from ._status import CONVERGED, result_message

__all__ = ["FitResult", "build_result"]


def _fmt(v: float, e: Optional[float] = None) -> str:
    if e is None or not np.isfinite(e):
        return f"{v:.6g}"
    return f"{v:.6g} ± {e:.2g}"


def _mask(objective: Objective) -> tuple:
    """Used-point masks of the objective's datasets (``Objective.mask``)."""
    return tuple(objective.mask)


@dataclasses.dataclass
class FitResult:
    r"""Outcome of :func:`~fitting.fit`.

    Attributes:
        values: ``{name: coefficients}`` (shapes as the parameter: ``()``, ``(m,)``,
            ``(samples,)`` or ``(samples, m)``); ``stderr``: same shapes (NaN where not
            identifiable); ``spectra``: ``{name: B c}`` on the model grid for spectral ones, and
            ``spectra_stderr``: their standard errors at every wavelength,
            :math:`\sqrt{\operatorname{diag}(B C B^T)}` with C the covariance of the
            coefficients (:func:`spectrum_stderr`).
        x, x_stderr, names: flat physical vector, its standard errors and component names.
        covariance, correlation: ``(P, P)``; ``covariance_scaled``: True if scaled by the
            reduced χ² (σ estimated from the residuals), False if from the given σ.
        chi2, reduced_chi2, dof, n_points: goodness of fit (data only, not penalties);
            ``cost``: the full objective :math:`\\tfrac12\\|r\\|^2` with penalties.
        model, data, residuals: per dataset ``(samples, wl)``; residuals = model − data,
            NaN at masked points.
        num_steps, converged, reason, result_code: solver outcome (``converged``: the solver
            met its tolerance; :data:`fitting._status.STATUS`).
        starts, starts_converged, starts_abandoned: multi-start: starts solved, converged, and
            given up far above the best start (:func:`fitting._multistart.give_up_rule`; None for one start).
        singular_values, rank: of the normalised Jacobian; ``non_identifiable``: list of
            ``{"parameters", "direction", "combination"}``.
        sigma_origin: σ behind the standard errors: ``"given"``, ``"estimated from residuals"``
            or ``"default 1 — χ² not meaningful"``; ``sigma_given``: every dataset gives σ;
            ``sigma_estimate``: :math:`\\sqrt{\\chi^2/\\nu}` (the σ estimated from the
            residuals, in units of the given σ or, without σ, of the data).
        quality: the verdict on the fit quality; ``warnings``: plain warnings (implausible χ²,
            percent data, bounds, inseparable parameters, non-convergence).
        at_bound: ``[{"parameter", "value", "bound", "side"}]``; ``not_separated``:
            ``[{"parameters", "correlation"}]`` (every pair with |ρ| > ``correlation_limit``);
            ``separability``: those pairs grouped, one finding per group of linked parameters
            with the combination the data determine
            (:func:`fitting._statistics.separability_findings`); ``note``: what the solver layer
            did besides the chosen method (e.g. finished on a bound by L-BFGS-B).
        identifiable: no null direction and no group of parameters with |ρ| above the limit.

    Values and errors are in each parameter's own unit (nm for thicknesses, 1/nm for α,
    dimensionless for n and ρg); ``model``, ``data`` and ``residuals`` in the unit the
    dataset's geometry reads (dimensionless reflectance, 1/sr for BRDF, degrees for ψ/Δ).
    """

    objective: Objective
    method: str
    x: np.ndarray
    x_stderr: np.ndarray
    names: list
    values: dict
    stderr: dict
    spectra: dict
    spectra_stderr: dict
    covariance: np.ndarray
    correlation: np.ndarray
    covariance_scaled: bool
    chi2: float
    reduced_chi2: float
    dof: int
    n_points: int
    cost: float
    model: list
    data: list
    residuals: list
    num_steps: int
    converged: bool
    reason: str
    result_code: int
    singular_values: np.ndarray
    rank: int
    non_identifiable: list
    starts: int = 1
    starts_converged: Optional[int] = None
    starts_abandoned: Optional[int] = None
    sigma_origin: str = SIGMA_GIVEN
    sigma_given: bool = True
    sigma_estimate: float = float("nan")
    quality: str = ""
    warnings: list = dataclasses.field(default_factory=list)
    at_bound: list = dataclasses.field(default_factory=list)
    not_separated: list = dataclasses.field(default_factory=list)
    note: str = ""
    rank_rtol: float = 1e-8
    separability: list = dataclasses.field(default_factory=list)
    correlation_limit: float = CORRELATION_LIMIT

    @property
    def identifiable(self) -> bool:
        """True when every parameter is determined on its own: no null direction and no group
        of parameters correlated beyond ``correlation_limit``."""
        return not self.non_identifiable and not self.separability

    def stack(self, sample: int = 0):
        """The fitted :class:`~layerstack_jax.Stack` of ``sample``."""
        return self.objective.stack_for(self.x, sample)

    def _sigma_line(self) -> str:
        if self.sigma_origin == SIGMA_GIVEN:
            return "given (uncertainties from the given σ, not rescaled)"
        if self.sigma_given:
            return (f"estimated from residuals: the given σ × {self.sigma_estimate:.3g} "
                    "(uncertainties rescaled by χ²/ν on request)")
        if self.sigma_origin == SIGMA_DEFAULT:
            return SIGMA_DEFAULT + " (no σ given and no rescaling requested: uncertainties are not meaningful)"
        return (f"estimated from residuals: s = {self.sigma_estimate:.3g} (no σ given; χ² computed with the "
                "default σ = 1 is not meaningful)")

    # ----------------------------------------------------------------- report
    def report(self) -> str:
        """Readable text report (see the module docstring for what it states)."""
        obj = self.objective
        conv = (f"yes — the solver met its tolerance after {self.num_steps} steps" if self.converged
                else f"NO — {self.reason} (after {self.num_steps} steps)")
        lines = [
            "layerstack fit report",
            "=====================",
            f"method            {self.method}" + (f" (multi-start: {self.starts_converged}/{self.starts} starts converged"
                                                  + (f", {self.starts_abandoned} given up far above the best"
                                                     if self.starts_abandoned else "") + ")"
                                                  if self.starts > 1 else ""),
            f"converged         {conv}",
        ]
        if self.note:
            lines.append(f"note              {self.note}")
        lines += [
            f"fit quality       {self.quality}",
            f"data              {self.n_points} points in {len(obj.datasets)} dataset(s) × {obj.n_samples} sample(s): "
            + ", ".join(ds.label for ds in obj.datasets),
            f"sigma             {self._sigma_line()}",
        ]
        if self.sigma_given:
            lines.append(f"chi2              {self.chi2:.6g}   reduced chi2 {self.reduced_chi2:.6g}   (dof {self.dof})")
        else:
            lines.append(f"chi2              not meaningful without σ (sum of squared residuals {self.chi2:.4g}, dof {self.dof})")
        for w in self.warnings:
            lines.append(f"WARNING           {w}")
        lines += ["", "parameters", "----------"]
        on_bound = {b["parameter"]: b for b in self.at_bound}
        for p in obj.layout.params:
            v, e = np.asarray(self.values[p.name]), np.asarray(self.stderr[p.name])
            lo, hi = p.lower.min(), p.upper.max()
            bounds = f"[{lo:g}, {hi:g}]"
            kind = "per sample" if p.per_sample else "shared"
            if v.size == 1:
                tag = ""
                if p.name in on_bound:
                    b = on_bound[p.name]
                    tag = f"  AT {b['side'].upper()} BOUND {b['bound']:g}"
                lines.append(f"  {p.name:<24} {_fmt(float(v.ravel()[0]), float(e.ravel()[0])):<28} {kind}, bounds {bounds}{tag}")
            else:
                what = "basis" if p.basis is not None and p.basis.shape[1] != p.basis.shape[0] else "values"
                if p.name in self.spectra and v.size > REPORT_VALUES_MAX:
                    lines.append(f"  {p.name:<24} {v.size} {what} ({kind}, bounds {bounds}): spectrum "
                                 + self._spectrum_line(p.name, on_bound))
                    continue
                lines.append(f"  {p.name:<24} {v.size} {what} ({kind}, bounds {bounds}):")
                for idx in np.ndindex(v.shape):
                    lab = "".join(f"[{i}]" for i, n in zip(idx, v.shape) if not (n == 1 and len(v.shape) > 1))
                    value = _fmt(float(v[idx]), float(e[idx]))
                    if p.fixed.reshape(v.shape)[idx]:
                        value += " (fixed)"
                    b = on_bound.get(p.name + lab)
                    if b is not None:
                        value += f"  AT {b['side'].upper()} BOUND {b['bound']:g}"
                    lines.append(f"      {lab:<12} {value}")
                if p.name in self.spectra:
                    lines.append(f"      {'spectrum':<12} {self._spectrum_line(p.name, on_bound)}")
        if self.at_bound:
            lines.append("  on a bound: " + "; ".join(f"{b['parameter']} = {b['value']:g} ({b['side']} bound {b['bound']:g})"
                                                     for b in self.at_bound))
        lines += ["", "identifiability", "---------------"]
        sv = self.singular_values
        lines.append(f"  rank {self.rank} of {len(self.x)} (singular values of the normalised Jacobian below "
                     f"{self.rank_rtol:g} × the largest count as zero); {np.nanmax(sv):.3g} … {np.nanmin(sv):.3g}")
        lines += identifiability_lines(self.non_identifiable, self.separability, self.not_separated,
                                       self.correlation_limit)
        lines += ["", "residuals (model - data)", "------------------------"]
        for ds, r in zip(obj.datasets, self.residuals):
            rms = np.sqrt(np.nanmean(r ** 2, axis=-1))
            lines.append(f"  {ds.label}: rms per sample " + ", ".join(f"{v:.3g}" for v in rms))
        return "\n".join(lines)

    def _spectrum_line(self, name: str, on_bound: dict) -> str:
        """One line on a fitted spectrum: its range on the grid, its σ(λ) and bound contacts."""
        y, e = np.asarray(self.spectra[name]), np.asarray(self.spectra_stderr[name])
        finite = e[np.isfinite(e)]
        sigma = (f"σ(λ) {np.min(finite):.3g} … {np.max(finite):.3g} (median {np.median(finite):.3g})"
                 if finite.size else "σ(λ) not determined")
        bound = sum(1 for k in on_bound if k.startswith(name + "["))
        return (f"{np.nanmin(y):.4g} … {np.nanmax(y):.4g} on the grid, {sigma}"
                + (f", {bound} values on a bound" if bound else "") + " — every value in the JSON and the plot")

    def __str__(self) -> str:
        return self.report()

    # ------------------------------------------------------------------- JSON
    def to_dict(self) -> dict:
        def clean(a):
            a = np.asarray(a, dtype=float)
            if a.ndim == 0:
                return float(a) if np.isfinite(a) else None
            return [clean(v) for v in a]

        obj = self.objective
        return {
            "method": self.method,
            "converged": bool(self.converged),
            "reason": self.reason,
            "note": self.note,
            "num_steps": int(self.num_steps),
            "quality": {"verdict": self.quality, "warnings": list(self.warnings)},
            "sigma": {"origin": self.sigma_origin, "given": bool(self.sigma_given),
                      "estimated": clean(self.sigma_estimate)},
            "chi2": clean(self.chi2),
            "reduced_chi2": clean(self.reduced_chi2),
            "chi2_meaningful": bool(self.sigma_given),
            "dof": int(self.dof),
            "n_points": int(self.n_points),
            "uncertainty_scaling": "reduced_chi2" if self.covariance_scaled else "given_sigma",
            "parameters": {
                p.name: {
                    "path": [str(s) for s in p.path],
                    "per_sample": p.per_sample,
                    "fixed": p.fixed.tolist(),
                    "value": clean(self.values[p.name]),
                    "stderr": clean(self.stderr[p.name]),
                    "lower": clean(p.lower),
                    "upper": clean(p.upper),
                    **({"spectrum": clean(self.spectra[p.name]), "spectrum_stderr": clean(self.spectra_stderr[p.name])}
                       if p.name in self.spectra else {}),
                }
                for p in obj.layout.params
            },
            "at_bound": self.at_bound,
            "names": list(self.names),
            "covariance": clean(self.covariance),
            "correlation": clean(self.correlation),
            "identifiability": {
                "rank": int(self.rank),
                "rank_rtol": float(self.rank_rtol),
                "singular_values": clean(self.singular_values),
                "non_identifiable": self.non_identifiable,
                "correlation_limit": float(self.correlation_limit),
                "findings": [{k: (v if k != "spread" or np.isfinite(v) else None) for k, v in f.items()}
                             for f in self.separability],
                "not_separated": self.not_separated,
            },
            "wavelength_nm": clean(obj.wavelength),
            "datasets": [
                {"name": ds.label, "data": clean(d), "model": clean(m), "residuals": clean(r)}
                for ds, d, m, r in zip(obj.datasets, self.data, self.model, self.residuals)
            ],
        }

    def to_json(self, path=None, indent: int = 1) -> str:
        """JSON text of :meth:`to_dict` (NaN written as null); also written to ``path`` if given."""
        text = json.dumps(self.to_dict(), indent=indent)
        if path is not None:
            p = Path(path)
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(text)
        return text

    # ------------------------------------------------------------------- plot
    def plot(self, path=None, title: str = "", sample_names=None):
        """Data (points) and fit (lines) per dataset with residuals below, and each fitted
        spectrum (α(λ), ρg(λ), …) with its ±1σ band, laid out as a grid of at most three panels
        per row; returns the matplotlib Figure (object API, Agg canvas) and writes a PNG when
        ``path`` is given. ``sample_names``: legend names of the samples (e.g. the data file's
        column names); the y axis says what the geometry reads (reflectance, reflectance factor,
        BRDF (1/sr) …)."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        obj = self.objective
        panels = len(obj.datasets) + len(self.spectra)
        ncols = min(3, panels)
        nrows = -(-panels // ncols)
        fig = Figure(figsize=(6 * ncols, 5.2 * nrows), dpi=110, layout="constrained")
        FigureCanvasAgg(fig)
        cells = list(np.ravel(fig.subfigures(nrows, ncols, squeeze=False)))
        for cell in cells[panels:]:
            cell.set_visible(False)
        names = (lambda s, rows: str(sample_names[s]) if sample_names is not None and len(sample_names) == rows
                 else f"sample {s}")
        for k, (ds, cell) in enumerate(zip(obj.datasets, cells)):
            self._plot_dataset(cell, k, ds, names)
        for (name, y), cell in zip(self.spectra.items(), cells[len(obj.datasets):]):
            self._plot_spectrum(cell, name, np.asarray(y), np.asarray(self.spectra_stderr[name]), names)
        status = "converged" if self.converged else "NOT converged"
        quality = (f"χ²/ν {self.reduced_chi2:.3g} (ν = {self.dof})" if self.sigma_given
                   else f"no σ given: σ from residuals {self.sigma_estimate:.3g}")
        fig.suptitle(f"{title + ': ' if title else ''}fit ({self.method}, {status}), {quality}"
                     + (" — see warnings" if self.warnings else ""), fontsize=11)
        if path is not None:
            p = Path(path)
            p.parent.mkdir(parents=True, exist_ok=True)
            fig.savefig(p)
        return fig

    def _plot_dataset(self, cell, k: int, ds, names) -> None:
        """Dataset ``k``: data and fit above, residuals below."""
        top, bottom = cell.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [3, 1]})
        rows = self.objective.samples_of(k)
        lab = ds.colour is not None
        x = np.arange(3) if lab else self.objective.wavelength
        for s in range(rows):
            color = f"C{s % 10}"
            top.plot(x, self.data[k][s], "o" if lab else ".", ms=6 if lab else 3, color=color, alpha=0.6)  # NaN: masked
            top.plot(x, self.model[k][s], "x" if lab else "-", ms=8, lw=1.4, color=color,
                     label=names(s, rows) if rows > 1 else "fit")
            bottom.plot(x, self.residuals[k][s], "o-" if lab else "-", lw=1.0, color=color)
        top.set_title(ds.label, fontsize=10)
        top.set_ylabel("CIELAB" if lab else ds.geometry.quantity_label)
        if lab:
            bottom.set_xticks([0, 1, 2], ["L*", "a*", "b*"])
        top.grid(True, alpha=0.3)
        top.legend(loc="best", frameon=False, fontsize=8)
        bottom.axhline(0.0, color="k", lw=0.6)
        bottom.set_xlabel("CIELAB coordinate" if lab else "wavelength (nm)")
        bottom.set_ylabel("model − data")
        bottom.grid(True, alpha=0.3)

    def _plot_spectrum(self, cell, name: str, y, e, names) -> None:
        """A fitted spectrum on the model grid with its ±1σ band (one curve per sample)."""
        ax = cell.subplots()
        wl = self.objective.wavelength
        y2, e2 = np.atleast_2d(y), np.atleast_2d(e)
        for s, (ys, es) in enumerate(zip(y2, e2)):
            color = f"C{s % 10}"
            ax.plot(wl, ys, lw=1.4, color=color, label=names(s, len(y2)) if len(y2) > 1 else "fitted")
            ax.fill_between(wl, ys - es, ys + es, color=color, alpha=0.25, lw=0, label="±1σ" if s == 0 else None)
        ax.set_title(f"{name} (±1σ band)", fontsize=10)
        ax.set_xlabel("wavelength (nm)")
        kind = name.split("[")[0]
        ax.set_ylabel(f"{kind} ({_UNITS[kind]})" if kind in _UNITS else kind)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", frameon=False, fontsize=8)


def spectrum_stderr(layout, covariance: np.ndarray) -> dict:
    r"""Standard errors of the spectra of the spectral parameters on the model grid,
    ``{name: (wl,) or (samples, wl)}``: the spectrum is :math:`B c` (basis ``B`` ``(wl, m)``,
    coefficients ``c``), so its variance at each wavelength is :math:`\operatorname{diag}(B C B^T)`
    with ``C`` the covariance block of ``c`` (fixed coefficients: 0; per sample: each sample's own block)."""
    position = {int(j): k for k, j in enumerate(layout.free_index)}
    out = {}
    for p, a, b in zip(layout.params, layout.offsets[:-1], layout.offsets[1:]):
        if p.basis is None:
            continue
        local = [t for t in range(b - a) if a + t in position]
        glob = [position[a + t] for t in local]
        C = np.zeros((b - a, b - a))
        C[np.ix_(local, local)] = covariance[np.ix_(glob, glob)]
        m = p.basis.shape[1]
        rows = (b - a) // m  # samples (1 for a shared spectrum)
        blocks = C.reshape(rows, m, rows, m)[np.arange(rows), :, np.arange(rows), :]  # (rows, m, m)
        var = np.einsum("lm,smn,ln->sl", p.basis, blocks, p.basis)
        out[p.name] = np.sqrt(np.maximum(var, 0.0)).reshape(p.x0.shape[:-1] + (p.basis.shape[0],))
    return out


#: Units of the spectral parameters' values, for plot labels.
_UNITS = {"alpha": "1/nm", "k": "dimensionless", "n": "dimensionless", "rho_g": "dimensionless"}

#: A spectral parameter with more values than this is summarised in the report (every value is in
#: the JSON and the plot).
REPORT_VALUES_MAX = 12


def _plain_residuals(objective: Objective, model, data) -> list:
    """Unweighted residuals of every dataset, :meth:`~fitting.Objective.residual_of` (``model − data``;
    Δ wrapped for an ellipsometer), as NumPy arrays: one compiled call, compiled once per objective
    and shapes and kept with it (op by op, the Δ wrap alone cost milliseconds per fit)."""
    import jax

    cache = objective.cache
    fn = cache.get("plain_residuals")
    if fn is None:
        fn = cache["plain_residuals"] = jax.jit(
            lambda ms, ds: tuple(objective.residual_of(i, m, d) for i, (m, d) in enumerate(zip(ms, ds))))
    return [np.asarray(r) for r in fn(tuple(model), tuple(data))]


def build_result(objective: Objective, options, out, args, *, scale_covariance, rank_rtol, starts=1,
                 starts_converged=None, note: str = "", stats=None, starts_abandoned=None,
                 correlation_limit: float = CORRELATION_LIMIT, refit: Optional[Callable] = None) -> FitResult:
    """:class:`FitResult` of one fit from its :class:`~fitting._fit_output.FitOutput` ``out``
    (NumPy, no batch axis) and data ``args``; ``stats``: its :class:`~fitting._statistics.FitStatistics`
    when already computed (a row of a batch's), else computed here by the same function;
    ``refit``: the same fit's χ² on other data, for :func:`fitting._fit_findings.delta_sign_warnings`."""
    layout = objective.layout
    x = np.asarray(out.x, float)
    code = int(out.status)
    res = [np.asarray(r) for r in out.residuals]
    model = [np.asarray(m) for m in out.model]
    J = out.jacobian  # dense (M, P), or in compressed form (fit_statistics knows both)
    if stats is None:
        stats = fit_statistics(J, x, res, layout, objective.n_points, sigma_given=objective.sigma_given,
                               scale_covariance=scale_covariance, rank_rtol=rank_rtol)
    chi2, red, dof = float(stats.chi2), float(stats.reduced_chi2), int(stats.dof)
    non_ident, _ = _non_identifiable(layout, stats.singular_values, stats.rank, stats.null_vectors,
                                     stats.log_directions, stats.zero_columns)
    err = np.asarray(stats.stderr)
    values = layout.values(x)
    stderr = layout.values(err, fill=np.nan)
    spectra = {p.name: p.spectrum(c) for p, c in zip(layout.params, layout.split(x)) if p.basis is not None}
    spectra_stderr = spectrum_stderr(layout, np.asarray(stats.covariance))
    masks = _mask(objective)
    data = [np.asarray(d) for d in args[0]]
    # the geometry's own residual (Δ wrapped into (−180°, 180°]), as in the fit itself
    residuals = [np.where(m, r, np.nan) for m, r in zip(masks, _plain_residuals(objective, model, data))]
    data = [np.where(m, d, np.nan) for m, d in zip(masks, data)]
    pen = np.asarray(out.penalty)
    cost = 0.5 * (chi2 + float(np.sum(pen ** 2)))
    s = math.sqrt(chi2 / dof) if dof > 0 and np.isfinite(chi2) else math.nan
    verdict, warnings = quality_verdict(red, dof, objective.sigma_given, s)
    warnings = warnings + percent_warnings(objective, data)
    warnings = warnings + delta_sign_warnings(objective, args, chi2, dof, refit)
    at_bound = bounds_hit(layout, x)
    separated = not_separated(list(layout.names), stats.correlation, non_ident, correlation_limit)
    findings = separability_findings(layout, x, stats.covariance, stats.correlation, stats.unresolved,
                                     np.asarray(stats.log_directions)[int(stats.rank):], correlation_limit)
    converged = code == CONVERGED
    if not converged:
        warnings.insert(0, f"the fit did not converge ({result_message(code)}): the values are where the solver stopped")
    if at_bound:
        warnings.append("on a bound: " + ", ".join(b["parameter"] for b in at_bound)
                        + " (the minimum within the bounds; its standard errors assume a free parameter)")
    structural = structural_degeneracy(objective)
    warnings += structural
    if findings or separated:
        warnings.append(separability_warning(findings, separated, correlation_limit))
    return FitResult(
        objective=objective, method=options.method, x=x, x_stderr=err, names=list(layout.names), values=values,
        stderr=stderr, spectra=spectra, spectra_stderr=spectra_stderr, covariance=np.asarray(stats.covariance), correlation=np.asarray(stats.correlation),
        covariance_scaled=stats.sigma_origin not in (SIGMA_GIVEN, SIGMA_DEFAULT), chi2=chi2,
        reduced_chi2=red, dof=dof, n_points=int(stats.n_points), cost=cost, model=model, data=data,
        residuals=residuals, num_steps=int(out.num_steps), converged=converged, reason=result_message(code),
        result_code=code, singular_values=np.asarray(stats.singular_values), rank=int(stats.rank),
        non_identifiable=non_ident, starts=starts, starts_converged=starts_converged, starts_abandoned=starts_abandoned,
        sigma_origin=stats.sigma_origin, sigma_given=bool(objective.sigma_given), sigma_estimate=s, quality=verdict,
        warnings=warnings, at_bound=at_bound, not_separated=separated, note=note, rank_rtol=float(rank_rtol),
        separability=findings, correlation_limit=float(correlation_limit),
    )
