"""The host method ``"trf"``: :func:`scipy.optimize.least_squares` driven by the objective's
jitted residuals and Jacobian (:func:`_host_fit`, what :func:`fitting._compiled_fit.compiled_fit`
returns for it)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from layerstack_jax import traced_checks_off

from ._fit_functions import _statistics_function, structure_for
from ._fit_jit import fit_jit
from ._fit_output import FitOutput
from ._objective import Objective
from ._solver_options import SolverOptions
from ._status import CONVERGED, FAILED, MAX_STEPS, NONFINITE
from ._structured import compressed_jacobian_function, sparse_jacobian_function

__all__ = []


def _host_fit(objective: Objective, o: SolverOptions, batched: bool):
    """:func:`fitting._compiled_fit.compiled_fit` for the host method ``"trf"``: :func:`scipy.optimize.least_squares`
    on ``z = x / scale`` with exact bounds, fed by the jitted residuals and the jitted
    forward-mode Jacobian (one compile each, reused by later fits of the objective); then the
    jitted statistics. ``batched`` (multi-start) solves the starts one after the other."""
    from scipy.optimize import least_squares

    layout = objective.layout
    scale = jnp.asarray(layout.scale)
    lower, upper = layout.lower / layout.scale, layout.upper / layout.scale

    def residuals(z, args, optics):
        with traced_checks_off():
            return objective.residuals(z * scale, args, optics)

    def statistics(x, args, optics):
        with traced_checks_off():
            return _statistics_function(objective, structure_for(objective, o.structure, o.method))(x, args, optics)

    res_fn = fit_jit(residuals)  # one fit at a time on the host (multi-starts too): compile time dominates
    structure = structure_for(objective, o.structure, o.method)
    if structure is None:
        jac_fn = fit_jit(jax.jacfwd(residuals))
    else:  # compressed forward mode, handed to scipy as a sparse matrix (its TRF then takes LSMR steps)
        jac_fn = sparse_jacobian_function(fit_jit(compressed_jacobian_function(residuals, structure)), structure)
    stats = fit_jit(statistics)

    def one(z0, args, optics, give_up=None):  # no give-up rule on the host
        z0 = np.clip(np.asarray(z0, dtype=float), lower, upper)
        sol = least_squares(
            lambda z: np.asarray(res_fn(z, args, optics), dtype=float),
            z0,
            jac=lambda z: jac_fn(z, args, optics) if structure is not None else np.asarray(jac_fn(z, args, optics),
                                                                                            dtype=float),
            bounds=(lower, upper), method="trf", x_scale=1.0,
            xtol=o.rtol, ftol=o.rtol, gtol=o.gtol, max_nfev=o.max_steps,
        )
        # TRF iterates stay strictly inside the box: snap a component that ended within 1e-8
        # (scaled units) of a bound the gradient pushes it against onto that bound.
        z, g = sol.x.copy(), sol.grad
        with np.errstate(invalid="ignore"):
            near_lo = np.isfinite(lower) & (z - lower <= 1e-8 * np.maximum(1.0, np.abs(lower))) & (g > 0)
            near_hi = np.isfinite(upper) & (upper - z <= 1e-8 * np.maximum(1.0, np.abs(upper))) & (g < 0)
        z = np.where(near_lo, lower, np.where(near_hi, upper, z))
        x = z * layout.scale
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(sol.fun))):
            status = NONFINITE
        else:  # scipy: status > 0 — one of its tolerances met; 0 — max_nfev; -1 — failure
            status = CONVERGED if sol.status > 0 else MAX_STEPS if sol.status == 0 else FAILED
        x = jnp.asarray(x)
        return FitOutput(x, jnp.asarray(sol.nfev), jnp.asarray(status), *stats(x, args, optics))

    if not batched:
        return one

    def run_all(starts, args, optics, give_up=None):
        outs = [one(starts[i], jax.tree.map(lambda a: a[i], args), optics) for i in range(starts.shape[0])]
        return jax.tree.map(lambda *a: jnp.stack(a), *outs)

    return run_all
