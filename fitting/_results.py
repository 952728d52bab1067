r"""Fit results: values, uncertainties, identifiability, report, JSON and plot.

Uncertainties come from the Jacobian :math:`J` of the weighted residuals at the solution
(linearised least squares): :math:`C = s^2 (J^\top J)^{-1}`, with :math:`s^2 = 1` when every
dataset gives its σ (absolute covariance) or :math:`s^2 = \chi^2/(N-P)` otherwise (scaled by
the reduced χ²); the report says which.

Identifiability: the SVD of the Jacobian taken w.r.t. :math:`\ln x` (relative changes; w.r.t.
:math:`x/s` for a parameter at 0) with unit-norm columns. A singular value below ``rank_rtol``
× the largest marks a direction :math:`\delta\ln x` along which the data do not change: the
parameters involved are reported as a combination (for two parameters with directions
:math:`w_1, w_2`, only :math:`x_1 x_2^{-w_1/w_2}` is determined, e.g. α·h of an incoherent
layer) instead of arbitrary values with huge errors. The covariance is then the pseudo-inverse
on the identifiable subspace, and the standard errors of the parameters involved are NaN.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Optional

import numpy as np

from layerstack_jax import LayerstackError

from ._objective import Objective

__all__ = ["FitResult", "linearised_covariance", "build_result"]


def linearised_covariance(J, x, scale, rank_rtol: float):
    """Covariance of ``x`` (unit residual variance) from ``J = ∂r/∂(x/scale)``; works on
    stacked problems (leading batch axes).

    Returns ``(cov, singular_values, rank, null_vectors, log_directions)``: ``null_vectors``
    ``(..., P, P)`` rows of :math:`V^\\top` (only those beyond ``rank`` are null) in normalised
    coordinates, ``log_directions`` the same mapped to :math:`\\delta\\ln x` (or
    :math:`\\delta x/s` for x = 0), each scaled to max 1.
    """
    J = np.asarray(J, float)
    x = np.asarray(x, float)
    rel = np.where(x != 0, np.abs(x) / scale, 1.0)  # d/d ln x = (|x|/s) d/d(x/s)
    Jr = J * rel[..., None, :]
    norms = np.linalg.norm(Jr, axis=-2)
    safe = np.where(norms > 0, norms, 1.0)
    Jn = Jr / safe[..., None, :]
    # a fit that ended on non-finite values has no linearisation: NaN covariance, no rank claim
    bad = ~np.all(np.isfinite(Jn), axis=(-2, -1))
    Jn = np.where(bad[..., None, None], 0.0, Jn)
    _, sv, Vt = np.linalg.svd(Jn, full_matrices=False)
    top = sv[..., :1]
    keep = (sv > rank_rtol * top) & (top > 0)
    rank = np.where(bad, J.shape[-1], keep.sum(axis=-1))
    sv = np.where(bad[..., None], np.nan, sv)
    inv = np.where(keep, 1.0 / np.where(keep, sv, 1.0) ** 2, 0.0)
    cov_n = np.einsum("...ki,...k,...kj->...ij", Vt, inv, Vt)
    a = rel / safe  # J = Jn diag(1/a)
    cov_z = cov_n * a[..., :, None] * a[..., None, :]
    cov = cov_z * scale[..., :, None] * scale[..., None, :]
    cov = np.where(bad[..., None, None], np.nan, cov)
    dirs = Vt / safe[..., None, :]
    dirs = dirs / np.maximum(np.max(np.abs(dirs), axis=-1, keepdims=True), 1e-300)
    return cov, sv, rank, Vt, dirs


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
    return ", ".join(n for n, _ in groups)


@dataclasses.dataclass
class FitResult:
    """Outcome of :func:`~fitting.fit`.

    Attributes:
        values: ``{name: coefficients}`` (shapes as the parameter: ``()``, ``(m,)``,
            ``(samples,)`` or ``(samples, m)``); ``stderr``: same shapes (NaN where not
            identifiable); ``spectra``: ``{name: B c}`` on the model grid for spectral ones.
        x, x_stderr, names: flat physical vector, its standard errors and component names.
        covariance, correlation: ``(P, P)``; ``covariance_scaled``: True if scaled by the
            reduced χ² (no σ given), False if from the given σ.
        chi2, reduced_chi2, dof, n_points: goodness of fit (data only, not penalties);
            ``cost``: the full objective :math:`\\tfrac12\\|r\\|^2` with penalties.
        model, data, residuals: per dataset ``(samples, wl)``; residuals = model − data,
            NaN at masked points.
        num_steps, converged, reason, result_code: solver outcome.
        singular_values, rank: of the normalised Jacobian; ``non_identifiable``: list of
            ``{"parameters", "direction", "combination"}``.

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

    @property
    def identifiable(self) -> bool:
        return not self.non_identifiable

    def stack(self, sample: int = 0):
        """The fitted :class:`~layerstack_jax.Stack` of ``sample``."""
        return self.objective.stack_for(self.x, sample)

    # ----------------------------------------------------------------- report
    def report(self) -> str:
        """Readable text report."""
        obj = self.objective
        lines = [
            "layerstack fit report",
            "=====================",
            f"method            {self.method}" + (f" (multi-start: {self.starts_converged}/{self.starts} starts converged)"
                                                  if self.starts > 1 else ""),
            f"converged         {'yes' if self.converged else 'NO'} ({self.reason}) after {self.num_steps} steps",
            f"data              {self.n_points} points in {len(obj.datasets)} dataset(s) × {obj.n_samples} sample(s): "
            + ", ".join(ds.label for ds in obj.datasets),
            f"chi2              {self.chi2:.6g}   reduced chi2 {self.reduced_chi2:.6g}   (dof {self.dof})",
            "uncertainties     " + ("scaled by the reduced chi2 (no sigma given)" if self.covariance_scaled
                                    else "from the given sigma (not rescaled)"),
            "",
            "parameters",
            "----------",
        ]
        for p in obj.layout.params:
            v, e = np.asarray(self.values[p.name]), np.asarray(self.stderr[p.name])
            lo, hi = p.lower.min(), p.upper.max()
            bounds = f"[{lo:g}, {hi:g}]"
            kind = "per sample" if p.per_sample else "shared"
            if v.size == 1:
                lines.append(f"  {p.name:<24} {_fmt(float(v.ravel()[0]), float(e.ravel()[0])):<28} {kind}, bounds {bounds}")
            else:
                what = "basis" if p.basis is not None and p.basis.shape[1] != p.basis.shape[0] else "values"
                lines.append(f"  {p.name:<24} {v.size} {what} ({kind}, bounds {bounds}):")
                for idx in np.ndindex(v.shape):
                    lab = "".join(f"[{i}]" for i, n in zip(idx, v.shape) if not (n == 1 and len(v.shape) > 1))
                    value = _fmt(float(v[idx]), float(e[idx]))
                    if p.fixed.reshape(v.shape)[idx]:
                        value += " (fixed)"
                    lines.append(f"      {lab:<12} {value}")
        lo_all, hi_all, sc = obj.layout.lower, obj.layout.upper, obj.layout.scale
        tol = 1e-9 * sc
        at_bound = [n for n, xv, lo, hi, t in zip(self.names, self.x, lo_all, hi_all, tol)
                    if abs(xv - lo) <= t or abs(hi - xv) <= t]
        if at_bound:
            lines.append(f"  on a bound: {', '.join(at_bound)}")
        lines += ["", "identifiability", "---------------"]
        sv = self.singular_values
        lines.append(f"  rank {self.rank} of {len(self.x)}; normalised singular values {sv.max():.3g} … {sv.min():.3g}")
        if not self.non_identifiable:
            lines.append("  all parameters are identifiable from these data")
        for item in self.non_identifiable:
            lines.append(f"  NOT IDENTIFIABLE: {item['combination']}")
            lines.append(f"    moving along {item['direction']} leaves the spectra unchanged;")
            lines.append("    the values of these parameters are arbitrary along it (standard errors not reported)")
        if len(self.x) > 1:
            corr = self.correlation
            pairs = [(abs(corr[i, j]), i, j) for i in range(len(self.x)) for j in range(i) if np.isfinite(corr[i, j])]
            strong = sorted([p for p in pairs if p[0] > 0.95], reverse=True)[:5]
            if strong:
                lines.append("  strong correlations: " + "; ".join(
                    f"{self.names[i]} / {self.names[j]} {corr[i, j]:+.3f}" for _, i, j in strong))
        lines += ["", "residuals (model - data)", "------------------------"]
        for ds, r in zip(obj.datasets, self.residuals):
            rms = np.sqrt(np.nanmean(r ** 2, axis=-1))
            lines.append(f"  {ds.label}: rms per sample " + ", ".join(f"{v:.3g}" for v in rms))
        return "\n".join(lines)

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
            "num_steps": int(self.num_steps),
            "chi2": clean(self.chi2),
            "reduced_chi2": clean(self.reduced_chi2),
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
                    **({"spectrum": clean(self.spectra[p.name])} if p.name in self.spectra else {}),
                }
                for p in obj.layout.params
            },
            "names": list(self.names),
            "covariance": clean(self.covariance),
            "correlation": clean(self.correlation),
            "identifiability": {
                "rank": int(self.rank),
                "singular_values": clean(self.singular_values),
                "non_identifiable": self.non_identifiable,
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
    def plot(self, path=None, title: str = ""):
        """Data (points) and fit (lines) per dataset with residuals below; returns the
        matplotlib Figure (object API, Agg canvas) and writes a PNG when ``path`` is given."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        obj = self.objective
        nd = len(obj.datasets)
        fig = Figure(figsize=(7 * nd, 6), dpi=110, layout="constrained")
        FigureCanvasAgg(fig)
        axes = fig.subplots(2, nd, sharex="col", squeeze=False, gridspec_kw={"height_ratios": [3, 1]})
        wl = obj.wavelength
        for k, ds in enumerate(obj.datasets):
            top, bottom = axes[0, k], axes[1, k]
            mask = obj._mask[k]
            rows = obj.samples_of(k)
            lab = ds.colour is not None
            x = np.arange(3) if lab else wl
            for s in range(rows):
                color = f"C{s % 10}"
                y = np.where(mask[s], self.data[k][s], np.nan)
                top.plot(x, y, "o" if lab else ".", ms=6 if lab else 3, color=color, alpha=0.6)
                top.plot(x, self.model[k][s], "x" if lab else "-", ms=8, lw=1.4, color=color,
                         label=f"sample {s}" if rows > 1 else "fit")
                bottom.plot(x, self.residuals[k][s], "o-" if lab else "-", lw=1.0, color=color)
            top.set_title(ds.label, fontsize=10)
            top.set_ylabel("CIELAB" if lab else "reflectance")
            if lab:
                bottom.set_xticks([0, 1, 2], ["L*", "a*", "b*"])
            top.grid(True, alpha=0.3)
            top.legend(loc="best", frameon=False, fontsize=8)
            bottom.axhline(0.0, color="k", lw=0.6)
            bottom.set_xlabel("CIELAB coordinate" if lab else "wavelength (nm)")
            bottom.set_ylabel("model − data")
            bottom.grid(True, alpha=0.3)
        status = "converged" if self.converged else f"NOT converged ({self.reason})"
        fig.suptitle(f"{title + ': ' if title else ''}fit ({self.method}, {status}), reduced χ² {self.reduced_chi2:.3g}",
                     fontsize=11)
        if path is not None:
            p = Path(path)
            p.parent.mkdir(parents=True, exist_ok=True)
            fig.savefig(p)
        return fig


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
        direction = ", ".join(f"δln {n} = {g:+.2f}" for n, g in groups)
        combo = _combination(groups)
        text = (f"only {combo} is determined" if len(groups) == 2 else f"the combination of {combo} along one direction")
        out.append({"parameters": names, "direction": direction, "combination": text})
    return out, involved


def build_result(objective: Objective, options, x, steps, code, model, res, pen, J, args, *,
                 scale_covariance, rank_rtol, starts=1, starts_converged=None) -> FitResult:
    from ._solve import result_message

    layout = objective.layout
    chi2 = float(sum(np.sum(r ** 2) for r in res))
    n_points = objective.n_points
    P = layout.size
    dof = n_points - P
    scaled = (not objective.sigma_given) if scale_covariance is None else bool(scale_covariance)
    red = chi2 / dof if dof > 0 else math.nan
    cov, sv, rank, Vt, dirs = linearised_covariance(J, x, layout.scale, rank_rtol)
    norms_zero = np.linalg.norm(J, axis=0) == 0
    non_ident, involved = _non_identifiable(layout, sv, rank, Vt, dirs, norms_zero)
    if scaled:
        cov = cov * red
    err = np.sqrt(np.clip(np.diag(cov), 0, None))
    err = np.where(involved, np.nan, err)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(err, err)
    values = layout.values(x)
    stderr = layout.values(err, fill=np.nan)
    spectra = {p.name: p.spectrum(c) for p, c in zip(layout.params, layout.split(x)) if p.basis is not None}
    data = [np.asarray(d) for d in args[0]]
    residuals = [np.where(m, mod - d, np.nan) for m, mod, d in zip(objective._mask, model, data)]
    cost = 0.5 * (chi2 + float(np.sum(pen ** 2)))
    return FitResult(
        objective=objective, method=options.method, x=x, x_stderr=err, names=list(layout.names), values=values,
        stderr=stderr, spectra=spectra, covariance=cov, correlation=corr, covariance_scaled=scaled, chi2=chi2,
        reduced_chi2=red, dof=dof, n_points=n_points, cost=cost, model=model,
        data=[np.where(m, d, np.nan) for m, d in zip(objective._mask, data)], residuals=residuals,
        num_steps=steps, converged=code == 0, reason=result_message(code), result_code=code, singular_values=sv,
        rank=int(rank), non_identifiable=non_ident, starts=starts, starts_converged=starts_converged,
    )
