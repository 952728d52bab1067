"""The compiled fit of an objective (:func:`compiled_fit`): one jitted function per objective,
options and batching — the solve of each method (:func:`_solve_function`), then the statistics'
ingredients at the solution — cached on the objective; batched copies solve
:data:`BLOCK` fits at a time, split over the devices JAX sees. :func:`refit_chi2` runs it again
from the starting values on other data."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from layerstack_jax import traced_checks_off

from ._bounded import compiled_lbfgsb
from ._fit_functions import (
    _statistics_function,
    hold_on_bounds,
    jacobian_with_statistics,
    structure_for,
)
from ._fit_jit import fit_jit
from ._fit_output import FitOutput
from ._host_fit import _host_fit
from ._least_squares import optx_solver, solver_status
from ._objective import Objective
from ._solver_options import HOST_METHODS, NEVER, SolverOptions, starting_point
from ._status import CONVERGED, MAX_STEPS, NONFINITE

__all__ = ["compiled_fit", "refit_chi2", "BLOCK"]


def _solve_function(objective: Objective, o: SolverOptions):
    """Pure ``(start, args, optics, give_up) -> (x, steps, status)``; ``start`` is ``u``
    (optimistix) or ``z`` (L-BFGS-B); ``optics`` the objective's fixed optics (or None);
    ``give_up`` the multi-start give-up rule ``(steps, cost)`` (Levenberg–Marquardt only:
    :meth:`fitting._least_squares.LevenbergMarquardt.terminate`; :data:`fitting._solver_options.NEVER` for a plain fit)."""
    layout = objective.layout
    if o.method == "lbfgsb":
        scale = jnp.asarray(layout.scale)
        lower = jnp.asarray(layout.lower / layout.scale)
        upper = jnp.asarray(layout.upper / layout.scale)

        def cost(z, args, optics):
            r = objective.residuals(z * scale, args, optics)
            return 0.5 * jnp.sum(r * r)

        run = compiled_lbfgsb(cost, o.max_steps, o.gtol)

        def solve(z0, args, optics, give_up):
            sol = run(z0, lower, upper, args, optics)
            finite = jnp.all(jnp.isfinite(sol.x)) & jnp.isfinite(sol.value)
            status = jnp.where(~finite, NONFINITE, jnp.where(sol.converged, CONVERGED, MAX_STEPS))
            return sol.x * scale, sol.num_steps, status

        return solve

    structure = structure_for(objective, o.structure, o.method)
    solver = optx_solver(o, objective.n_points - objective.n_parameters, structure)

    if o.method == "bfgs":  # BFGS needs only the gradient: plain reverse mode
        def residuals(u, args_optics):
            return objective.residuals(hold_on_bounds(layout, layout.to_physical(u)), *args_optics)

        def solve(u0, args, optics, give_up):
            sol = optx.minimise(lambda u, a: 0.5 * jnp.sum(residuals(u, a) ** 2), solver, u0, args=(args, optics),
                                max_steps=o.max_steps, throw=False)
            x = hold_on_bounds(layout, layout.to_physical(sol.value))
            return x, sol.stats["num_steps"], solver_status(sol.result, x)

        return solve

    # Least squares: optimistix linearises the residuals at every step and then materialises
    # and transposes that linear map several times (QR of the damped system, gradient, trust
    # region); with the Jacobian materialised once per step by forward mode, all of those are
    # small dense products. That Jacobian is the statistics' one (w.r.t. z = x / scale, with
    # the model values and residuals as its by-products, _statistics_function) times the
    # derivative of z(u): optimistix keeps it, as the auxiliary output of its last accepted point,
    # which is the solution — so the compiled fit holds one copy of the model's Jacobian, not two.
    fn = jacobian_with_statistics(objective, structure)

    def solve(u0, args, optics, give_up):
        # the give-up rule: Levenberg–Marquardt only (its terminate reads it)
        sol = optx.least_squares(fn, solver, u0, args=(args, optics), has_aux=True, max_steps=o.max_steps,
                                 throw=False, options={"give_up": give_up} if o.method == "lm" else None)
        x = hold_on_bounds(layout, layout.to_physical(sol.value))
        # the aux of the solution: the final state's (Solution.aux lags one accepted step behind)
        (model, res, pen), J = sol.state.aux
        return x, sol.stats["num_steps"], solver_status(sol.result, x), (model, res, pen, J)

    return solve


def refit_chi2(objective: Objective, o: SolverOptions, args) -> float:
    """χ² that the compiled fit of ``objective`` (the same program: no new compilation) reaches
    from the parameters' starting values on data ``args`` = ``(data, weight)``."""
    start = jnp.asarray(starting_point(objective, o, objective.layout.x0))
    out = compiled_fit(objective, o, batched=False)(start, args, objective.optics)
    return float(sum(np.sum(np.asarray(r, float) ** 2) for r in out.residuals))


#: Fits per vmapped block inside a batched solve (``jax.lax.map`` over blocks). 1: on a single
#: device each fit is solved by the single fit's own program, one fit after the other, so no
#: LAPACK call in it carries a batch axis. A least-squares step holds two LAPACK calls that do not
#: depend on each other (the QR of the damped Gauss–Newton system, the eigenvalues of
#: :func:`fitting._least_squares.near_minimum`'s stopping test), which XLA runs at the same time; vmapped, each becomes
#: a batched call, and jaxlib's CPU LAPACK kernels of the 0.10 series split a batch over XLA's
#: intra-op thread pool and block their pool thread until the parts are done. With as many such
#: calls at once as the pool has threads (two on a 2-core machine) no thread is left to run the
#: parts: the solve waited forever at 0 % CPU. Fit by fit, each fit also stops at its own
#: convergence (a vmapped block runs until its slowest fit ends).
BLOCK = 1


def compiled_fit(objective: Objective, o: SolverOptions, batched: bool, block: int = BLOCK):
    """The jitted ``(start, args, optics) -> FitOutput`` of ``objective`` for options ``o`` —
    solve, then the statistics' ingredients at the solution, in one compiled function. When
    ``batched``, start and args carry a leading axis of fits, solved ``block`` at a time
    (vmapped when ``block`` > 1, see :data:`BLOCK`) by ``jax.lax.map``; ``optics`` (the objective's fixed optics,
    :attr:`Objective.optics`) is shared. Where JAX sees several devices (accelerators, or CPU
    devices made by ``XLA_FLAGS=--xla_force_host_platform_device_count``), each block's fits are
    split over them (sharding of the fits' axis; the block is padded to a multiple of the device
    count). Compiled once per objective, options and batching; cached on the objective."""
    key = ("fit", o, batched, block if batched else None)
    cache = objective.cache
    if key not in cache and o.method in HOST_METHODS:
        cache[key] = _host_fit(objective, o, batched)
    if key not in cache:
        solve = _solve_function(objective, o)
        structure = structure_for(objective, o.structure, o.method)
        stats = _statistics_function(objective) if structure is None else _statistics_function(objective, structure)

        def run(start, args, optics, give_up):
            with traced_checks_off():  # trial points are the solver's business (traced_checks_off)
                x, steps, status, *at_x = solve(start, args, optics, give_up)
                # least squares: the statistics' ingredients come with the solution (aux)
                return FitOutput(x, steps, status, *(at_x[0] if at_x else stats(x, args, optics)))

        if batched:
            devices = jax.devices()
            k = len(devices)

            def run_all(starts, args, optics, give_up):
                n = starts.shape[0]
                b = -(-min(block, n) // k) * k  # a multiple of the device count
                if b == 1:  # one device: fit by fit, each by the single fit's program (BLOCK)
                    return jax.lax.map(lambda sa: run(sa[0], sa[1], optics, give_up), (starts, args))
                pad = -n % b
                nb = (n + pad) // b
                blocks = jax.tree.map(  # (n_blocks, b, ...): the last block padded with copies of fit 0
                    lambda a: jnp.concatenate([a, jnp.broadcast_to(a[:1], (pad,) + a.shape[1:])]).reshape(
                        (nb, b) + a.shape[1:]), (starts, args))
                if k > 1:  # each block's fits split over the devices (the solves are independent)
                    split = NamedSharding(Mesh(np.asarray(devices), ("fits",)), PartitionSpec(None, "fits"))
                    blocks = jax.lax.with_sharding_constraint(blocks, split)
                out = jax.lax.map(jax.vmap(lambda sa: run(sa[0], sa[1], optics, give_up)), blocks)
                return jax.tree.map(lambda a: a.reshape((nb * b,) + a.shape[2:])[:n], out)

            cache[key] = _with_give_up(jax.jit(run_all))
        else:
            cache[key] = _with_give_up(fit_jit(run))
    return cache[key]


class _with_give_up:
    """``jitted(start, args, optics, give_up)`` callable as ``(start, args, optics)`` too (the
    rule :data:`fitting._solver_options.NEVER`); the jitted function's own attributes (``lower``, ``_cache_size`` …)
    are its."""

    def __init__(self, jitted):
        self.jitted = jitted

    def __call__(self, start, args, optics, give_up=NEVER):
        return self.jitted(start, args, optics, give_up)

    def __getattr__(self, name):
        return getattr(self.__dict__["jitted"], name)
