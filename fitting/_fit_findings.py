r"""What a fit's numbers say, in words: the findings a :class:`~fitting.FitResult` reports.

The numbers (χ², degrees of freedom, covariance, standard errors, correlations, singular values,
unresolved components, parameters on a bound) come from :mod:`fitting._statistics`, the one
computation shared with :func:`~fitting.fit_batch`. This module turns them into words:

* **convergence** — "converged" only when the solver met its tolerance (:data:`fitting._status.STATUS`);
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

import math
from typing import Callable, Optional

import numpy as np

from ._objective import Objective
from ._statistics import CORRELATION_LIMIT, bound_contacts, strong_correlations

__all__ = ["quality_verdict", "percent_warnings", "delta_sign_warnings", "bounds_hit", "not_separated",
           "structural_degeneracy", "separability_warning", "identifiability_lines"]


def _combination(groups: list[tuple[str, float]]) -> str:
    """Name the product determined along a null direction of two parameters."""
    if len(groups) == 2:
        (n1, w1), (n2, w2) = groups
        p = -w1 / w2
        exp = "" if abs(p - 1) < 0.02 else f"^{p:.3g}"
        return f"{n1}·{n2}{exp}"
    return ", ".join(n for n, _ in groups[:6]) + (f" and {len(groups) - 6} more" if len(groups) > 6 else "")


#: Tail probability of the χ² distribution beyond which χ²/ν is called implausible.
IMPLAUSIBLE_P = 1e-6


def quality_verdict(reduced_chi2: float, dof: int, sigma_given: bool, s: float) -> tuple[str, list]:
    """Plain verdict on the fit quality: ``(verdict, warnings)``.

    With σ given, χ² of a correct model follows the χ² distribution with ν degrees of freedom:
    a χ² in either tail beyond probability :data:`IMPLAUSIBLE_P` (and χ²/ν beyond 1.5, resp.
    below 2/3) is implausible — the model misses the data (or σ is too small), resp. σ is too
    large. Without σ, the χ² computed with σ = 1 says nothing: the verdict states the σ
    estimated from the residuals, ``s``."""
    from scipy.special import (  # χ² cdf and sf (what scipy.stats.chi2 calls; lighter import)
        chdtr,
        chdtrc,
    )

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
    from scipy.special import (
        chdtrc,  # χ² sf (what scipy.stats.chi2.sf calls; lighter import)
    )

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
