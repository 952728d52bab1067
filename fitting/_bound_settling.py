r"""Fits of an unconstrained method that ended on a bound, settled there
(:func:`settle_on_bounds`): converged on the bound where it is optimal (Karush–Kuhn–Tucker),
else restarted once from that point and then finished by L-BFGS-B; :func:`bound_note` says
which in the result."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._compiled_fit import BLOCK, compiled_fit
from ._fit_output import FitOutput
from ._objective import Objective
from ._solver_options import SolverOptions, starting_point
from ._statistics import bound_contacts
from ._status import CONVERGED, FAILED, NONFINITE
from ._structured import CompressedJacobian
from ._watchdog import wait_for

__all__ = ["NOT_FINISHED", "RESTARTED", "BY_LBFGSB", "settle_on_bounds", "bound_note"]

#: Unconstrained methods (transformed coordinates) that a bound can stall.
_TRANSFORMED = ("lm", "gauss-newton", "dogleg", "bfgs")


#: How a fit was finished after its solver ended on a bound that is not optimal
#: (:func:`settle_on_bounds`): not at all, by the same solver restarted from there, by L-BFGS-B.
NOT_FINISHED, RESTARTED, BY_LBFGSB = 0, 1, 2


def settle_on_bounds(objective: Objective, o: SolverOptions, out: FitOutput, args, *,
                     restart: bool = True) -> tuple[FitOutput, np.ndarray, np.ndarray]:
    r"""Fits of an unconstrained method that ended with parameters on a bound, checked for
    optimality there (Karush–Kuhn–Tucker): the gradient of :math:`\tfrac12\|r\|^2` presses
    each such parameter against its bound, and — unless the solver met its own step test with
    them held (:func:`fitting._fit_functions.hold_on_bounds`) — the Gauss–Newton step of the other parameters is below
    :math:`\sqrt{\mathrm{rtol}}` of their (scaled) values.

    * Where it holds the fit is converged on the bound, its parameters in contact exactly on it.
    * Where it does not and the solver ended converged or failed (the bound was reached on the
      way — a first step that overshoots —, or a step failed there), the same solver is
      restarted once from that point (a start on a bound is moved inside it,
      :meth:`~fitting._parameters.Layout.to_unconstrained`) and its result checked the same
      way; a fit that ends on a non-optimal bound again is finished by L-BFGS-B
      (:func:`fitting._bounded.compiled_lbfgsb`, bounds kept exactly). The new output
      replaces the row; the steps of all runs are added.
    * A fit stopped by ``max_steps`` away from an optimal bound stays as it is.

    ``out``: NumPy :class:`~fitting._fit_output.FitOutput` with a leading axis of fits; ``args``: the fits' data
    ``(spectra, weights)`` with the same leading axis. Returns the updated output, the ``(N,)``
    mask of the fits settled on a bound and the ``(N,)`` codes of how fits were finished
    (:data:`NOT_FINISHED`, :data:`RESTARTED`, :data:`BY_LBFGSB`); other methods and fits are
    unchanged."""
    x, status = np.asarray(out.x, float), np.asarray(out.status)
    n = x.shape[0]
    settled, how = np.zeros(n, bool), np.full(n, NOT_FINISHED)
    if o.method not in _TRANSFORMED:
        return out, settled, how
    layout = objective.layout
    lo, hi = bound_contacts(x, layout.lower, layout.upper, layout.scale)
    active = lo | hi
    candidate = (status != NONFINITE) & np.all(np.isfinite(x), axis=-1) & active.any(axis=-1)
    if not candidate.any():
        return out, settled, how
    # (N, M, P) w.r.t. z = x / scale (decompressed: only fits touching a bound get here)
    J = out.jacobian.dense() if isinstance(out.jacobian, CompressedJacobian) else np.asarray(out.jacobian, float)
    r = np.concatenate([np.asarray(a, float).reshape(n, -1) for a in out.residuals]
                       + [np.asarray(out.penalty, float).reshape(n, -1)], axis=-1)
    with np.errstate(invalid="ignore"):
        g = np.einsum("nmp,nm->np", J, r)
        pressed = np.where(lo, g >= 0, np.where(hi, g <= 0, True)).all(axis=-1)
        free_J = np.where(active[:, None, :], 0.0, np.nan_to_num(J))
        step = -np.einsum("npm,nm->np", np.linalg.pinv(free_J), np.nan_to_num(r))
        z = x / layout.scale
        small = (np.abs(step) <= np.sqrt(o.rtol) * np.maximum(np.abs(z), 1.0)).all(axis=-1)
    settled = candidate & pressed & (small | (status == CONVERGED))
    x = np.where(settled[:, None] & lo, layout.lower, np.where(settled[:, None] & hi, layout.upper, x))
    out = out._replace(x=x, status=np.where(settled, CONVERGED, status))
    finish = candidate & ~settled & ((status == CONVERGED) | (status == FAILED))
    if not finish.any():
        return out, settled, how
    rows = np.flatnonzero(finish)
    sub = jax.tree.map(lambda a: np.asarray(a)[rows], args)
    if restart:
        again = _refit(objective, o, out, rows, sub)
        again, s2, h2 = settle_on_bounds(objective, o, again, sub, restart=False)
        settled[rows] = s2
        how[rows] = np.where(h2 == BY_LBFGSB, BY_LBFGSB, RESTARTED)
        return _put(out, again, rows), settled, how
    bounded = SolverOptions("lbfgsb", o.rtol, o.atol, o.gtol, o.max_steps, structure=o.structure)
    how[rows] = BY_LBFGSB
    return _put(out, _refit(objective, bounded, out, rows, sub), rows), settled, how


def _refit(objective: Objective, o: SolverOptions, out: FitOutput, rows, args) -> FitOutput:
    """The fits ``rows`` of ``out`` solved again by ``o``'s method, each started from its own
    solution (clipped into the bounds); NumPy output, one row per fit, with the steps of the
    earlier run added."""
    layout = objective.layout
    start = np.asarray(starting_point(objective, o, np.clip(np.asarray(out.x, float)[rows], layout.lower,
                                                            layout.upper)))
    if ("fit", o, True, BLOCK) not in objective.cache:
        # fits of ``fit`` (one start or a multi-start): the solver it has compiled, one fit after
        # the other, not a batched copy compiled for them (host rows in: no eager device ops)
        one = compiled_fit(objective, o, batched=False)
        new = [one(start[k], jax.tree.map(lambda a: np.asarray(a)[k], args), objective.optics)
               for k in range(len(rows))]
        new = jax.tree.map(lambda *a: np.stack([np.asarray(v) for v in a]), *new)
    else:
        start, args = jnp.asarray(start), jax.tree.map(jnp.asarray, args)
        new = wait_for(compiled_fit(objective, o, batched=True)(start, args, objective.optics),
                       what=f"{len(rows)} fit(s) solved again from a bound ({o.method})")
    return new._replace(num_steps=new.num_steps + np.asarray(out.num_steps)[rows])


def _put(out: FitOutput, new: FitOutput, rows) -> FitOutput:
    """``out`` with its ``rows`` replaced by ``new``."""

    def put(a, b):
        a = np.array(a, dtype=np.result_type(a, b))
        a[rows] = b
        return a

    return jax.tree.map(put, out, new)


def bound_note(method: str, names: list, settled: bool, finished: int = 0) -> str:
    """The result's note when a fit of ``method`` was settled on a bound, or finished by
    another run (:func:`settle_on_bounds`: ``finished`` is :data:`RESTARTED` or
    :data:`BY_LBFGSB`)."""
    if finished == BY_LBFGSB:
        return (f"{method} reached a bound that is not optimal there (the gradient pulls away from it, or a step "
                "failed on it), twice; the fit was finished from that point with L-BFGS-B (bounds kept exactly)")
    if finished == RESTARTED:
        return (f"{method} reached a bound on the way that is not optimal there (the gradient pulls away from it); "
                "it was restarted from that point" + (" and converged on a bound" if settled else ""))
    if not settled:
        return ""
    return (f"{method} held {', '.join(names)} on a bound (its transformed coordinates only approach a bound); the "
            "bound is optimal there (the gradient presses against it, the other parameters have converged): "
            "converged on the bound")
