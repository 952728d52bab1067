r"""Fit results: values, uncertainties, identifiability, a report that tells the truth, JSON
and plot.

The numbers (χ², degrees of freedom, covariance, standard errors, correlations, singular values,
unresolved components, parameters on a bound) come from :mod:`fitting._statistics`, the one
computation shared with :func:`~fitting.fit_batch`. This module turns them into words:

* **convergence** — "converged" only when the solver met its tolerance (:data:`STATUS`);
* **fit quality** — a separate verdict: χ²/ν with ν, a plain warning when it is implausible
  (≫ 1 or ≪ 1 with σ given; no σ given: χ² is not meaningful and σ is estimated from the
  residuals), data > 1 of a reflectance that suggest percent, and ellipsometric data whose
  Δ sign is the opposite of the model's (:func:`delta_sign_warnings`);
* **σ used and its origin** — "given", "estimated from residuals" or "default 1 — χ² not
  meaningful";
* **parameters on a bound** — named with value and bound;
* **parameters the data cannot separate** — null directions of the normalised Jacobian
  (singular value below ``rank_rtol`` × the largest; only a combination such as α·h is
  determined) and parameters with |ρ| > 0.99 (``correlation_limit``), whatever the rank test
  says, grouped (:func:`fitting._statistics.separability_findings`): one finding per group of
  linked parameters, naming the combination the data determine ("d·n^3.8 is determined, not n
  and d separately"). The report stays short (a few findings, a few pairs); the JSON holds every
  finding and every pair;
* **structural degeneracies** — free parameters no data can separate by construction (an
  incoherent layer's thickness and α: only α·h enters Beer's law), with the advice to fix one
  (:func:`structural_degeneracy`, shared with :func:`~fitting.fit_cube`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from ._objective import Objective
from ._status import CONVERGED, result_message
from ._statistics import (CORRELATION_LIMIT, SIGMA_DEFAULT, SIGMA_GIVEN, bound_contacts, fit_statistics,
                          linearised_covariance, separability_findings, strong_correlations)

__all__ = ["FitResult", "linearised_covariance", "build_result", "quality_verdict", "percent_warnings",
           "delta_sign_warnings",
           "bounds_hit", "not_separated"]


def _fmt(v: float, e: Optional[float] = None) -> str:
    if e is None or not np.isfinite(e):
        return f"{v:.6g}"
    return f"{v:.6g} ± {e:.2g}"


def _combination(groups: list[tuple[str, float]]) -> str:
    """Name the product determined along a null direction of two parameters."""
    if len(groups) == 2:
        (n1, w1), (n2, w2) = groups
        p = -w1 / w2
        exp = "" if abs(p - 1) < 0.02 else f"^{p:.3g}"
        return f"{n1}·{n2}{exp}"
    return ", ".join(n for n, _ in groups[:6]) + (f" and {len(groups) - 6} more" if len(groups) > 6 else "")


def _mask(objective: Objective) -> tuple:
    """Used-point masks of the objective's datasets (``Objective.mask``)."""
    return tuple(objective.mask)


#: Tail probability of the χ² distribution beyond which χ²/ν is called implausible.
IMPLAUSIBLE_P = 1e-6


def quality_verdict(reduced_chi2: float, dof: int, sigma_given: bool, s: float) -> tuple[str, list]:
    """Plain verdict on the fit quality: ``(verdict, warnings)``.

    With σ given, χ² of a correct model follows the χ² distribution with ν degrees of freedom:
    a χ² in either tail beyond probability :data:`IMPLAUSIBLE_P` (and χ²/ν beyond 1.5, resp.
    below 2/3) is implausible — the model misses the data (or σ is too small), resp. σ is too
    large. Without σ, the χ² computed with σ = 1 says nothing: the verdict states the σ
    estimated from the residuals, ``s``."""
    from scipy.special import chdtr, chdtrc  # χ² cdf and sf (what scipy.stats.chi2 calls; lighter import)

    if dof <= 0:
        return f"no degrees of freedom (ν = {dof}): χ² cannot judge the fit", [
            f"{-dof} more parameters than data points: the fit is underdetermined" if dof < 0 else
            "as many parameters as data points: nothing is left to judge the fit by"]
    if not sigma_given:
        return (f"no σ given: χ² with σ = 1 is not meaningful; σ estimated from the residuals "
                f"s = {s:.3g} (ν = {dof})"), []
    text = f"χ²/ν = {reduced_chi2:.4g} with ν = {dof} degrees of freedom (σ given)"
    if not np.isfinite(reduced_chi2):
        return text, ["χ² is not finite: the fit failed"]
    chi2 = reduced_chi2 * dof
    if reduced_chi2 > 1.5 and chdtrc(dof, chi2) < IMPLAUSIBLE_P:
        return text + ": implausibly large", [
            f"χ²/ν = {reduced_chi2:.4g} ≫ 1: the model does not describe the data within the given σ "
            f"(or σ is underestimated by a factor ~{math.sqrt(reduced_chi2):.3g}); the standard errors, "
            "computed from the given σ, are then too small"]
    if reduced_chi2 < 2.0 / 3.0 and chdtr(dof, chi2) < IMPLAUSIBLE_P:
        return text + ": implausibly small", [
            f"χ²/ν = {reduced_chi2:.4g} ≪ 1: the data scatter far less than the given σ (σ overestimated by a "
            f"factor ~{1 / math.sqrt(max(reduced_chi2, 1e-300)):.3g}, or noise-free data); the standard errors "
            "are then too large"]
    return text + ": consistent with the noise", []


def percent_warnings(objective: Objective, data: list) -> list:
    """Warnings for data above 1 of a geometry that reads a fraction (reflectance,
    transmittance, reflectance factor; not BRDF in 1/sr, ψ/Δ or CIELAB): most likely percent."""
    out = []
    for ds, d in zip(objective.datasets, data):
        if ds.colour is not None or not getattr(ds.geometry, "reading_is_fraction", True):
            continue
        top = float(np.nanmax(d)) if np.any(np.isfinite(d)) else float("nan")
        if top > 1.0:
            out.append(f"dataset {ds.label}: data reach {top:.4g} > 1 — a reflectance is a fraction; are these "
                       "percent? (divide by 100)")
    return out


#: The Δ-sign warning is given when the sign-flipped data refit to a χ² at least this many times smaller.
SIGN_FLIP_RATIO = 10.0


def delta_sign_warnings(objective: Objective, args, chi2: float, dof: int, refit: Optional[Callable]) -> list:
    """A plain warning when ellipsometric data probably carry the opposite Δ sign.

    Checked only when the fit has data odd in Δ (``Ellipsometric`` quantities Δ, S, Im ρ:
    ``geometry.odd_in_delta``) and, σ given, an implausibly large χ² (the tail test of
    :func:`quality_verdict`). Then the same compiled fit (no new compilation) is run once more
    from the parameters' starting values on the data with those readings negated — data written
    in the other Δ convention (Δ = arg(r_p/r_s) instead of the instruments' −arg(r_p/r_s) that the
    model reports). If that fit reaches a χ² at least :data:`SIGN_FLIP_RATIO` times smaller, the
    warning says so. Cost: one extra solve, only for such fits. ``args``: the fit's
    ``(data, weight)``; ``chi2``, ``dof``: the fit's χ² and degrees of freedom; ``refit(args)``:
    the χ² the same fit reaches on other data (:func:`fitting._compiled_fit.refit_chi2`; None: no check)."""
    from scipy.special import chdtrc  # χ² sf (what scipy.stats.chi2.sf calls; lighter import)

    odd = [ds.colour is None and bool(getattr(ds.geometry, "odd_in_delta", False)) for ds in objective.datasets]
    if refit is None or not any(odd) or not objective.sigma_given or dof <= 0 or not np.isfinite(chi2):
        return []
    if not (chi2 / dof > 1.5 and chdtrc(dof, chi2) < IMPLAUSIBLE_P):
        return []
    data, weight = args
    flipped = refit((tuple(-d if o else d for d, o in zip(data, odd)), weight))
    if not (np.isfinite(flipped) and flipped * SIGN_FLIP_RATIO <= chi2):
        return []
    which = ", ".join(ds.label for ds, o in zip(objective.datasets, odd) if o)
    return [f"Δ sign: with the sign of the Δ-odd data ({which}) flipped, the same fit reaches χ² = {flipped:.4g} "
            f"instead of {chi2:.4g} — the data most likely use the opposite Δ convention (Δ = arg(rp/rs), as in "
            "exp(-iωt) codes) to the instruments' Δ = -arg(rp/rs) that the model computes: negate Δ, S and Im ρ "
            "in the data (or check the file's convention)"]


def bounds_hit(layout, x) -> list:
    """``[{"parameter", "value", "bound", "side"}]`` for the components of ``x`` on a bound."""
    lo, hi = bound_contacts(x, layout.lower, layout.upper, layout.scale)
    return [{"parameter": n, "value": float(v), "bound": float(layout.lower[j] if lo[j] else layout.upper[j]),
             "side": "lower" if lo[j] else "upper"}
            for j, (n, v) in enumerate(zip(layout.names, x)) if lo[j] or hi[j]]


def not_separated(names, correlation, non_identifiable: list, limit: float = CORRELATION_LIMIT) -> list:
    """Pairs of parameters the data cannot separate: ``[{"parameters", "correlation"}]`` with
    |ρ| > ``limit`` (the ±1 limit for pairs on a null direction), whatever the rank test says."""
    out = [{"parameters": [names[i], names[j]], "correlation": rho} for i, j, rho in strong_correlations(correlation, limit)]
    listed = {tuple(sorted(p["parameters"])) for p in out}
    for item in non_identifiable:  # a null direction of one component, or of components whose ρ is NaN
        key = tuple(sorted(item["parameters"]))
        if len(key) != 2 and key not in listed:
            out.append({"parameters": list(item["parameters"]), "correlation": None})
    return out


@dataclasses.dataclass
class FitResult:
    """Outcome of :func:`~fitting.fit`.

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


def _non_identifiable(layout, sv, rank, Vt, dirs, norms_zero) -> tuple[list, np.ndarray]:
    """Describe each null direction; return the list and a mask of the components involved."""
    P = len(sv)
    involved = np.zeros(P, bool)
    out = []
    for j in np.nonzero(norms_zero)[0]:
        involved[j] = True
        out.append({"parameters": [layout.names[j]], "direction": f"any change of {layout.names[j]}",
                    "combination": f"{layout.names[j]} has no effect on the data"})
    for r in range(int(rank), P):
        v, w = Vt[r], dirs[r]
        comp = np.nonzero((np.abs(v) > 0.05) & ~norms_zero)[0]
        if comp.size == 0:
            continue
        involved[comp] = True
        # group components by parameter; a parameter whose components move together counts once
        groups, names = [], []
        for i in sorted(set(layout.owner[comp])):
            idx = comp[layout.owner[comp] == i]
            ws = w[idx]
            name = layout.params[i].name
            # all free components of the parameter, also those too weak to stand out in the
            # normalised v (e.g. α where the layer barely absorbs): if they all move with the
            # strong ones by the same relative amount, the whole parameter is involved (α·h)
            every = np.nonzero((layout.owner == i) & ~norms_zero)[0]
            if np.allclose(w[every], ws[0], rtol=0.05, atol=0.02):
                involved[every] = True
                groups.append((name, float(ws[0])))
            else:
                groups += [(layout.names[c], float(w[c])) for c in idx]
            names.append(name)
        direction = ", ".join(f"δln {n} = {g:+.2f}" for n, g in groups[:6]) + (
            f" and {len(groups) - 6} more" if len(groups) > 6 else "")
        combo = _combination(groups)
        text = (f"only {combo} is determined" if len(groups) == 2 else f"the combination of {combo} along one direction")
        out.append({"parameters": names, "direction": direction, "combination": text})
    return out, involved


def structural_degeneracy(objective: Objective) -> list:
    """Degeneracies of ``objective`` by construction, known without computing anything: one
    message per incoherent layer whose thickness and α are both free (only α·h enters Beer's
    law, Simonot eq. 20: no data can separate them). A known value of either — one sample's
    thickness in a series, one fixed α coefficient — breaks the trade-off α → kα, h → h/k: no
    message then."""
    free = {p.path for p in objective.layout.params if not np.any(p.fixed)}
    out = []
    for i, layer in enumerate(objective.stack.layers):
        refs = (i, layer.name) if layer.name else (i,)
        if not layer.coherent and any(("layers", r, "thickness") in free for r in refs) \
                and any(("layers", r, "alpha") in free for r in refs):
            label = layer.name or f"layers[{i}]"
            out.append(f"{label}: thickness and alpha are both free, but an incoherent layer's spectra depend on "
                       "them only through alpha·h (Beer's law): fix one of them (e.g. a known thickness)")
    return out


#: The report shows at most this many findings of each kind and this many pairs; the JSON has all.
REPORT_FINDINGS, REPORT_PAIRS = 6, 5


def separability_warning(findings: list, pairs: list, limit: float = CORRELATION_LIMIT) -> str:
    """One line for the warnings: the groups the data cannot separate, by their combination."""
    if not findings:
        return ("the data cannot separate " + "; ".join(" / ".join(p["parameters"]) for p in pairs[:REPORT_PAIRS])
                + (f" and {len(pairs) - REPORT_PAIRS} more pairs" if len(pairs) > REPORT_PAIRS else ""))
    shown = [f["combination"] for f in findings[:3]]
    more = f" (and {len(findings) - 3} more groups)" if len(findings) > 3 else ""
    return (f"the data cannot separate {len(findings)} group(s) of parameters (|ρ| > {limit:g}, {len(pairs)} pair(s)): "
            + "; ".join(shown) + more + " — see identifiability")


def identifiability_lines(non_identifiable: list, findings: list, pairs: list,
                          limit: float = CORRELATION_LIMIT) -> list:
    """The identifiability lines of a report, at most a screenful: null directions grouped by the
    parameters they involve, the poorly separable groups with the combination the data
    determine, the first pairs beyond the correlation limit; what is left out is counted and
    found in the JSON (``identifiability``)."""
    lines = []
    if not non_identifiable and not findings and not pairs:
        return ["  all parameters are identifiable from these data"]
    by_params: dict = {}
    for item in non_identifiable:
        by_params.setdefault(tuple(item["parameters"]), []).append(item)
    for k, (params, items) in enumerate(by_params.items()):
        if k == REPORT_FINDINGS:
            lines.append(f"  … {len(by_params) - k} more kinds of non-identifiable direction (JSON: "
                         "identifiability.non_identifiable)")
            break
        item = items[0]
        count = f" ({len(items)} such directions, e.g.)" if len(items) > 1 else ""
        lines.append(f"  NOT IDENTIFIABLE{count}: {item['combination']}")
        lines.append(f"    moving along {item['direction']} leaves the spectra unchanged;")
        lines.append("    the values of these parameters are arbitrary along it (standard errors not reported)")
    poor = [f for f in findings if f["kind"] == "poorly separable"]
    for k, f in enumerate(poor):
        if k == REPORT_FINDINGS:
            lines.append(f"  … {len(poor) - k} more poorly separable groups (JSON: identifiability.findings)")
            break
        lines.append(f"  POORLY SEPARABLE (|ρ| up to {f['max_abs_correlation']:.4f} > {limit:g}, "
                     f"{f['pairs']} pair(s)): {f['combination']}")
        lines.append(f"    the data barely change along {f['direction']}")
    for item in pairs[:REPORT_PAIRS]:
        rho = item["correlation"]
        lines.append(f"  NOT SEPARATED by the data: {' / '.join(item['parameters'])}"
                     + (f" (correlation {rho:+.4f}, |ρ| > {limit:g})" if rho is not None else ""))
    if len(pairs) > REPORT_PAIRS:
        lines.append(f"  … {len(pairs) - REPORT_PAIRS} more pairs with |ρ| > {limit:g} (every pair: JSON "
                     "identifiability.not_separated)")
    return lines


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
    ``refit``: the same fit's χ² on other data, for :func:`delta_sign_warnings`."""
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
