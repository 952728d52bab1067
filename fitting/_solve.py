r"""Solvers: one least-squares layer over optimistix (public API only) and the shared bounded
L-BFGS-B driver (:mod:`fitting._bounded`).

* ``"lm"`` (default): Levenberg–Marquardt, composed from optimistix's parts
  (:class:`optimistix.AbstractGaussNewton` with a damped Newton descent and a trust-region
  search, :class:`fitting._least_squares.LevenbergMarquardt`);
* ``"gauss-newton"``: :class:`optimistix.GaussNewton`;
* ``"dogleg"``: :class:`optimistix.Dogleg`;
* ``"bfgs"``: :class:`optimistix.BFGS` on :math:`\tfrac12\|r\|^2`;
* ``"lbfgsb"``: L-BFGS-B (:func:`fitting._bounded.compiled_lbfgsb`) on :math:`\tfrac12\|r\|^2`
  in :math:`z = x/s`, bounds kept exactly. For optima on a bound (α = 0, ρg = 1, h = 0).
* ``"trf"``: :func:`scipy.optimize.least_squares` (trust-region reflective, Branch, Coleman & Li)
  on :math:`z = x/s` with the bounds kept exactly, driven from the host with the compiled residuals
  and the compiled forward-mode Jacobian. Gauss–Newton-fast like LM, and it does not stall on a
  bound: the choice for large joint fits (calibration series with α(λ) and ρg(λ) on bases).
  Single fits and multi-start (one host solve per start); not for :func:`~fitting.fit_batch`.

The unconstrained solvers (``lm``, ``gauss-newton``, ``dogleg``, ``bfgs``) work on transformed
coordinates that only approach a bound, so their step test could never be met on it. Inside their
solves a component that comes within 1e-4 of its scale of a finite bound is held exactly on that
bound (:func:`fitting._fit_functions.hold_on_bounds`, an active set): its derivative is zero there,
so the solver's own step test ends the solve once the other parameters have converged — a few steps,
not ``max_steps``. Afterwards (:func:`fitting._bound_settling.settle_on_bounds`) the bound's
optimality is checked (Karush–Kuhn–Tucker: the gradient presses against the bound): if it holds, the
fit is converged on the bound and the result says so (:attr:`~fitting.FitResult.note`); if it does not (the
bound was reached on the way, or the solver failed there), the fit is finished from that point with
L-BFGS-B, which keeps bounds exactly, and the note says so.

Each objective compiles one solve function (:func:`fitting._compiled_fit.compiled_fit`) per method
and options (cached on the objective); data travel in ``args``, so later fits with other data and
the starts of a multi-start reuse it (batched fits compile one vmapped copy). The least-squares
methods take the statistics' Jacobian, model and residuals from the solver's last evaluation
(:func:`fitting._fit_functions.jacobian_with_statistics`): the compiled fit holds one copy of the
model's Jacobian. A fit never raises on non-convergence: the result carries a status
(:data:`fitting._status.STATUS`) and the reason in the library's words.
"""

from __future__ import annotations

import functools
from typing import Optional

import jax
import numpy as np

from layerstack_jax import LayerstackError

from ._bound_settling import bound_note, settle_on_bounds
from ._compiled_fit import compiled_fit, refit_chi2
from ._multistart import TIE_RTOL, _multistart, multistart_points
from ._objective import Objective
from ._results import build_result
from ._solver_options import SolverOptions, starting_point
from ._statistics import bound_contacts
from ._status import ABANDONED, CONVERGED

__all__ = ["fit"]


def fit(objective: Objective, method: str = "lm", *, data=None, x0=None, starts: int = 1, seed: int = 0,
        max_steps: int = 256, rtol: float = 1e-10, atol: float = 1e-12, gtol: float = 1e-9,
        sigma_tol: float = 1e-3, scale_covariance: Optional[bool] = None, rank_rtol: float = 1e-8, progress=None,
        structure: str = "auto", correlation_limit: float = 0.99):
    """Fit ``objective`` and return a :class:`~fitting.FitResult`.

    Args:
        objective: the :class:`~fitting.Objective`.
        method: ``"lm"`` (default), ``"gauss-newton"``, ``"dogleg"``, ``"bfgs"``, ``"lbfgsb"``
            (bounds kept exactly; for optima on a bound) or ``"trf"`` (scipy's bounded
            trust-region least squares on the host; bounds kept exactly; large joint fits).
            An unconstrained method holds a parameter that reaches a bound on it; where the
            bound is optimal the fit is converged there, else it is finished by L-BFGS-B (the
            result's ``note`` says which, :func:`fitting._bound_settling.settle_on_bounds`).
        data: optional replacement spectra (one ``(samples, wl)`` array per dataset): fits
            other data with the same compiled solver.
        x0: optional physical starting vector ``(P,)`` (default: from the parameters / stack).
        starts: multi-start: number of starting points (the first is ``x0``, the others drawn by
            :func:`fitting._multistart.multistart_points`), solved one after the other by the fit's own compiled
            solver (nothing more is compiled); with Levenberg–Marquardt a start still 10× above the
            best cost after 3× that start's steps is given up (:func:`fitting._multistart.give_up_rule`, counted
            in ``starts_abandoned``). The converged one with the lowest χ² wins (the first
            of those equal to round-off: ``x0``'s when it found that minimum).
        max_steps, rtol, atol, gtol, sigma_tol: stopping rules (:class:`fitting._solver_options.SolverOptions`): the
            least-squares methods stop when the step test is met or, with noisy data, when the
            point is within ``sigma_tol`` standard errors of the minimum.
        scale_covariance: scale the covariance by the reduced χ² (σ estimated from the
            residuals); default: True unless every dataset gives σ.
        rank_rtol: singular values of the normalised Jacobian below ``rank_rtol`` × the largest
            mark a non-identifiable combination.
        progress: multi-start progress — True (a tqdm bar), False, a callable ``f(done,
            total)``, or None (a bar when there are more than 16 starts).
        structure: ``"auto"`` (default) — spectral parameters free per wavelength (``basis=
            "free"``) make the Jacobian block-diagonal in wavelength plus a few global columns:
            it is then formed with one tangent per global and one per spectral block, and the
            steps and the covariance are solved by block QR (:mod:`fitting._structured`) where
            that is cheaper than dense; ``"dense"``: never; ``"structured"``: always (an error
            where the fit has no such structure). The same values and statistics either way.
        correlation_limit: parameters correlated beyond this magnitude are reported as poorly
            separable, grouped, with the combination the data determine
            (``result.separability``; :func:`fitting._statistics.separability_findings`).

    Never raises on non-convergence: see ``result.converged`` and ``result.reason``.
    ``x0`` and the result's values are in each parameter's own unit (nm for thicknesses, 1/nm
    for α, dimensionless for n and ρg).
    """
    o = SolverOptions(method, rtol, atol, gtol, max_steps, sigma_tol, structure)
    if objective.n_parameters == 0:
        raise LayerstackError("the objective has no free parameter")
    if not (isinstance(starts, int) and starts >= 1):
        raise LayerstackError(f"starts must be an integer >= 1, got {starts!r}")
    args = objective.args(data)
    x_start = objective.layout.x0 if x0 is None else np.asarray(x0, float)
    if x_start.shape != (objective.n_parameters,):
        raise LayerstackError(f"x0 must have {objective.n_parameters} values, got shape {x_start.shape}")
    pts = multistart_points(objective, starts, seed)
    pts[0] = x_start
    y0 = np.asarray(starting_point(objective, o, pts))  # host: no eager device ops (each compiles once)
    if starts == 1:
        one = compiled_fit(objective, o, batched=False)(y0[0], args, objective.optics)
        outs = jax.tree.map(lambda a: np.asarray(a)[None], one)
    else:
        outs = _multistart(objective, o, y0, args, progress)
    # the fits' args with a leading axis of starts (host views: only read by settle_on_bounds)
    bargs = jax.tree.map(lambda a: np.broadcast_to(np.asarray(a), (starts,) + a.shape), args)
    outs, settled, finished = settle_on_bounds(objective, o, outs, bargs)
    n_starts_converged = n_abandoned = None
    best = 0
    if starts > 1:
        cost = sum(np.sum(r ** 2, axis=(-2, -1)) for r in outs.residuals) + np.sum(outs.penalty ** 2, axis=-1)
        ok = (outs.status == CONVERGED) & np.isfinite(cost)
        n_starts_converged = int(ok.sum())
        n_abandoned = int((outs.status == ABANDONED).sum())
        pool = np.where(ok if ok.any() else np.isfinite(cost), cost, np.inf)
        # the first start within round-off of the lowest cost (starts that found the same minimum
        # differ by ~1e-13 in χ²: the objective's own start wins such a tie, as in a single fit)
        best = int(np.argmax(pool <= np.min(pool) * (1.0 + TIE_RTOL))) if np.isfinite(np.min(pool)) else 0
    out = jax.tree.map(lambda a: a[best], outs)
    lo, hi = bound_contacts(out.x, objective.layout.lower, objective.layout.upper, objective.layout.scale)
    names = [n for n, b in zip(objective.layout.names, lo | hi) if b]
    return build_result(objective, o, out, args, scale_covariance=scale_covariance, rank_rtol=rank_rtol,
                        starts=starts, starts_converged=n_starts_converged, starts_abandoned=n_abandoned,
                        note=bound_note(method, names, bool(settled[best]), int(finished[best])),
                        correlation_limit=correlation_limit, refit=functools.partial(refit_chi2, objective, o))
