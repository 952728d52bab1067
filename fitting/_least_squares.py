r"""The least-squares solvers, composed from optimistix's public parts: Levenberg–Marquardt
(:class:`LevenbergMarquardt`: a damped Newton descent with a trust-region search that tells a
rejected step from round-off, :class:`RoundoffTrustRegion`), Gauss–Newton and Dogleg, the
library's stopping rule (:func:`near_minimum`: the solve ends within ``sigma_tol`` standard
errors of its minimum, :func:`gauss_newton_distance`), the choice among them for a fit's options
(:func:`optx_solver`) and the library's status of an optimistix result (:func:`solver_status`).
:mod:`fitting._compiled_fit` drives them.
"""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx
from jaxtyping import Array, Float

from ._status import ABANDONED, CONVERGED, FAILED, MAX_STEPS, NONFINITE
from ._structured import StructuredDampedNewtonDescent, block_distance


class RoundoffTrustRegion(optx.AbstractSearch):
    """:class:`optimistix.ClassicalTrustRegion` (``region``) that also accepts a step when both
    its predicted and its actual change of the cost are at the round-off level of the cost
    (≤ 1000 ε |f|).

    There the ratio actual/predicted is noise: the classical rule rejects such steps at random
    and shrinks the region again and again, so a fit that has already converged spends many
    extra steps (each a full Jacobian) before its step-size test is met — 23 steps instead of 9
    on benchmark F1. Accepting them leaves the damping unchanged and lets the Cauchy test end the
    solve as soon as the steps are small."""

    region: optx.ClassicalTrustRegion = optx.ClassicalTrustRegion()

    def init(self, y, f_info_struct):
        return self.region.init(y, f_info_struct)

    def step(self, first_step, y, y_eval, f_info, f_eval_info, state):
        step_size, accept, result, new_state = self.region.step(first_step, y, y_eval, f_info, f_eval_info, state)
        f = f_info.as_min()
        noise = 1e3 * jnp.finfo(jnp.result_type(f)).eps * jnp.abs(f)
        y_diff = jax.tree.map(lambda a, b: a - b, y_eval, y)
        predicted = self.region.predict_reduction(y_diff, f_info)
        flat = (jnp.abs(predicted) <= noise) & (jnp.abs(f_eval_info.as_min() - f) <= noise)
        keep = flat & ~accept
        step_size = jnp.where(keep, state.step_size, step_size)
        new_state = jax.tree.map(lambda a, b: jnp.where(keep, a, b), state, new_state)
        return step_size, accept | flat, result, new_state


def _quiet(**kwargs) -> None:
    """No progress output from inside the compiled solve."""


def gauss_newton_distance(residual: Float[Array, " M"], jacobian: Float[Array, "M P"], dof: int):
    r"""``(d², s²)``: the squared length of the Gauss–Newton step still to go, in standard errors
    of the unscaled covariance, :math:`d^2 = g^\top (J^\top J)^{+} g` with :math:`g = J^\top r`
    — twice the cost decrease that step predicts, MINUIT's *estimated distance to the minimum*
    (James & Roos 1975) — and the residuals' variance :math:`s^2 = \|r\|^2/\mathrm{dof}`.

    Directions the data do not determine (eigenvalues of :math:`J^\top J` below 1e-12 of the
    largest, and the zero columns of components held on a bound) are left out. Invariant under
    a reparametrisation of the coordinates, so the solvers' coordinates ``u`` serve."""
    g = jacobian.T @ residual
    w, V = jnp.linalg.eigh(jacobian.T @ jacobian)
    kept = w > 1e-12 * jnp.max(w)
    d2 = jnp.sum(jnp.where(kept, (V.T @ g) ** 2 / jnp.where(kept, w, 1.0), 0.0))
    return d2, jnp.sum(residual * residual) / max(dof, 1)


def near_minimum(state, sigma_tol: float, dof: int, structure=None):
    r"""True once the last accepted point of a Gauss–Newton-family solve (optimistix state) is
    within ``sigma_tol`` standard errors of the minimum: :math:`d^2 \le`
    ``sigma_tol``\ :sup:`2` :math:`\min(1, s^2)` (:func:`gauss_newton_distance`).

    With σ given, :math:`s^2 \approx 1` and the distance is in the reported standard errors;
    without σ (unit weights) the factor :math:`s^2` converts it to the scaled ones, and with a
    σ that is too large (:math:`s^2 < 1`) it is as strict as the smaller errors. Residuals at the
    round-off level (noise-free data) leave :math:`s^2 \approx 0`: the rule never fires and
    optimistix's step and cost test ends the solve, as before. Later steps of a statistically
    converged fit move it by less than ``sigma_tol`` σ — each one a full Jacobian of the model."""
    r = jnp.concatenate([jnp.ravel(a) for a in jax.tree.leaves(state.f_info.residual)])
    if structure is not None:  # the block-structured descent's Jacobian: d² by its block QR
        d2, s2 = block_distance(state.descent_state, structure), jnp.sum(r * r) / max(dof, 1)
    else:
        d2, s2 = gauss_newton_distance(r, state.f_info.jac.as_matrix(), dof)
    return (state.num_accepted_steps >= 1) & (d2 <= sigma_tol ** 2 * jnp.minimum(1.0, s2))


class _GaussNewtonFamily(optx.AbstractGaussNewton):
    """The Gauss–Newton-family solvers of :func:`fit`: optimistix's composition (a descent
    within a search, :class:`optimistix.AbstractGaussNewton`) whose solves also stop near the
    minimum (:func:`near_minimum`, ``sigma_tol`` standard errors; 0: never) — ``dof`` the
    fit's degrees of freedom."""

    rtol: float
    atol: float
    sigma_tol: float = 0.0
    dof: int = 1
    norm: Callable = optx.max_norm
    verbose: Callable = _quiet

    def terminate(self, fn, y, args, options, state, tags):
        done, result = super().terminate(fn, y, args, options, state, tags)
        if not self.sigma_tol:
            return done, result
        structure = getattr(self.descent, "structure", None)
        near = jnp.invert(done) & near_minimum(state, self.sigma_tol, self.dof, structure)
        return done | near, optx.RESULTS.where(near, optx.RESULTS.successful, result)


class GaussNewton(_GaussNewtonFamily):
    """:class:`optimistix.GaussNewton`'s parts (undamped Newton steps, unit learning rate)."""

    descent: optx.AbstractDescent = optx.NewtonDescent()
    search: optx.AbstractSearch = optx.LearningRate(1.0)


class Dogleg(_GaussNewtonFamily):
    """:class:`optimistix.Dogleg`'s parts (dogleg steps in a classical trust region)."""

    descent: optx.AbstractDescent = optx.DoglegDescent()
    search: optx.AbstractSearch = optx.ClassicalTrustRegion()


class LevenbergMarquardt(_GaussNewtonFamily):
    """Levenberg–Marquardt composed from optimistix parts, as optimistix documents for custom
    solvers: Gauss–Newton steps damped by :class:`optimistix.DampedNewtonDescent` (QR of the
    damped system) within the :class:`RoundoffTrustRegion` update."""

    descent: optx.AbstractDescent = optx.DampedNewtonDescent(linear_solver=lx.QR())
    search: optx.AbstractSearch = RoundoffTrustRegion()

    def terminate(self, fn, y, args, options, state, tags):
        r"""The family's test, and the multi-start give-up rule: with ``options["give_up"] =
        (steps, cost)``, a solve that has taken ``steps`` steps while its cost
        :math:`\tfrac12\|r\|^2` is still above ``cost`` ends, marked
        ``RESULTS.nonlinear_divergence`` (:data:`fitting._status.ABANDONED`; a result the
        Gauss–Newton family never gives otherwise). A single fit passes :data:`NEVER`."""
        done, result = super().terminate(fn, y, args, options, state, tags)
        give_up = (options or {}).get("give_up")
        if give_up is None:
            return done, result
        steps, cost = give_up
        f = 0.5 * sum(jnp.sum(jnp.square(r)) for r in jax.tree.leaves(state.f_info.residual))
        hopeless = jnp.invert(done) & (state.num_steps >= steps) & (f > cost)
        return done | hopeless, optx.RESULTS.where(hopeless, optx.RESULTS.nonlinear_divergence, result)


def optx_solver(o, dof: int, structure=None):
    """The optimistix solver of ``o`` for a fit with ``dof`` degrees of freedom;
    Levenberg–Marquardt with the block-QR descent when the Jacobian has a ``structure``
    (:class:`fitting._structured.StructuredDampedNewtonDescent`)."""
    least_squares = {"lm": LevenbergMarquardt, "gauss-newton": GaussNewton, "dogleg": Dogleg}
    if o.method == "lm" and structure is not None:
        return LevenbergMarquardt(rtol=o.rtol, atol=o.atol, sigma_tol=o.sigma_tol, dof=dof,
                                  descent=StructuredDampedNewtonDescent(structure))
    if o.method in least_squares:
        return least_squares[o.method](rtol=o.rtol, atol=o.atol, sigma_tol=o.sigma_tol, dof=dof)
    return optx.BFGS(rtol=o.rtol, atol=o.atol)


def solver_status(result, x):
    """The library's status (traced int) of an optimistix ``result`` at solution ``x``."""
    code = jnp.where(result == optx.RESULTS.successful, CONVERGED,
                     jnp.where(result == optx.RESULTS.nonlinear_max_steps_reached, MAX_STEPS,
                               jnp.where(result == optx.RESULTS.nonfinite, NONFINITE,
                                         jnp.where(result == optx.RESULTS.nonlinear_divergence, ABANDONED, FAILED))))
    return jnp.where(jnp.all(jnp.isfinite(x)), code, NONFINITE)


