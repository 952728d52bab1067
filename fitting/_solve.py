r"""Solvers: optimistix least squares on unconstrained coordinates, jaxopt L-BFGS-B on bounded ones.

* ``"lm"`` (default): :class:`optimistix.LevenbergMarquardt`;
* ``"gauss-newton"``: :class:`optimistix.GaussNewton`;
* ``"dogleg"``: :class:`optimistix.Dogleg`;
* ``"bfgs"``: :class:`optimistix.BFGS` on :math:`\tfrac12\|r\|^2`;
* ``"lbfgsb"``: :class:`jaxopt.LBFGSB` on :math:`\tfrac12\|r\|^2` in :math:`z = x/s`, bounds kept
  exactly. Use it when a parameter sits on a bound at the optimum (α = 0, ρg = 1, h = 0): the
  transforms of the unconstrained solvers only approach a bound, slower and slower.

Each objective compiles one solve function per method and options (cached on the objective);
data travel in ``args``, so later fits with other data — and batched fits, multi-start — reuse it.
A fit never raises on non-convergence (``throw=False``): the result carries the flag and the
reason.
"""

from __future__ import annotations

import dataclasses
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from layerstack_jax import LayerstackError

from ._objective import Objective

__all__ = ["SolverOptions", "METHODS", "compiled_fit", "result_name", "result_message",
           "multistart_points", "fit"]

METHODS = ("lm", "gauss-newton", "dogleg", "bfgs", "lbfgsb")
_LBFGSB_CODES = {"successful": 0, "max_steps": 7, "nonfinite": 9}  # optimistix RESULTS indices


@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """Solver choice and stopping rules.

    ``rtol``/``atol``: optimistix step and cost tolerances on the unconstrained coordinates;
    ``gtol``: L-BFGS-B tolerance on the projected gradient of :math:`\\tfrac12\\|r\\|^2` (in z);
    ``max_steps``: iteration limit.
    """

    method: str = "lm"
    rtol: float = 1e-10
    atol: float = 1e-12
    gtol: float = 1e-9
    max_steps: int = 256

    def __post_init__(self):
        if self.method not in METHODS:
            raise LayerstackError(f"method must be one of {METHODS}, got {self.method!r}")
        if not (self.max_steps >= 1):
            raise LayerstackError(f"max_steps must be >= 1, got {self.max_steps}")
        for name in ("rtol", "atol", "gtol"):
            if not getattr(self, name) > 0:
                raise LayerstackError(f"{name} must be > 0, got {getattr(self, name)}")


def _optx_solver(o: SolverOptions):
    if o.method == "lm":
        return optx.LevenbergMarquardt(rtol=o.rtol, atol=o.atol)
    if o.method == "gauss-newton":
        return optx.GaussNewton(rtol=o.rtol, atol=o.atol)
    if o.method == "dogleg":
        return optx.Dogleg(rtol=o.rtol, atol=o.atol)
    return optx.BFGS(rtol=o.rtol, atol=o.atol)


def result_name(code: int) -> str:
    for name, item in optx.RESULTS._name_to_item.items():
        if int(item._value) == int(code):
            return name
    return f"code {code}"


def result_message(code: int) -> str:
    name = result_name(code)
    if name == "successful":
        return "converged"
    msg = optx.RESULTS._index_to_message[int(code)].split("\n")[0].strip()
    return f"{name}: {msg}" if msg else name


def _cache(objective: Objective) -> dict:
    c = objective.__dict__.get("_compiled")
    if c is None:
        c = objective.__dict__["_compiled"] = {}
    return c


def _solve_function(objective: Objective, o: SolverOptions):
    """Pure ``(start, args) -> (x, steps, code)``; ``start`` is ``u`` (optimistix) or ``z`` (L-BFGS-B)."""
    layout = objective.layout
    if o.method == "lbfgsb":
        import jaxopt

        scale = jnp.asarray(layout.scale)
        lower = jnp.asarray(layout.lower / layout.scale)
        upper = jnp.asarray(layout.upper / layout.scale)

        def cost(z, args):
            r = objective.residuals(z * scale, args)
            return 0.5 * jnp.sum(r * r)

        solver = jaxopt.LBFGSB(fun=cost, maxiter=o.max_steps, tol=o.gtol, jit=True)

        def solve(z0, args):
            out = solver.run(z0, bounds=(lower, upper), args=args)
            z, state = out.params, out.state
            finite = jnp.all(jnp.isfinite(z)) & jnp.isfinite(state.value)
            ok = state.error <= o.gtol
            code = jnp.where(~finite, _LBFGSB_CODES["nonfinite"],
                             jnp.where(ok, _LBFGSB_CODES["successful"], _LBFGSB_CODES["max_steps"]))
            return z * scale, state.iter_num, code

        return solve

    solver = _optx_solver(o)

    def fn(u, args):
        return objective.residuals(layout.to_physical(u), args)

    def solve(u0, args):
        if o.method == "bfgs":
            sol = optx.minimise(lambda u, a: 0.5 * jnp.sum(fn(u, a) ** 2), solver, u0, args=args,
                                max_steps=o.max_steps, throw=False)
        else:
            sol = optx.least_squares(fn, solver, u0, args=args, max_steps=o.max_steps, throw=False)
        x = layout.to_physical(sol.value)
        code = sol.result._value
        code = jnp.where(jnp.all(jnp.isfinite(x)), code, _LBFGSB_CODES["nonfinite"])
        return x, sol.stats["num_steps"], code

    return solve


def starting_point(objective: Objective, o: SolverOptions, x0) -> np.ndarray:
    """Solver coordinates of physical ``x0`` (``(..., P)``)."""
    layout = objective.layout
    if o.method == "lbfgsb":
        return np.asarray(x0, float) / layout.scale
    return layout.to_unconstrained(x0)


def _statistics_function(objective: Objective):
    """Pure ``(x, args) -> (model spectra, weighted data residuals, penalty, J)``, J the
    Jacobian of the full residual vector w.r.t. ``x / scale`` (scaled physical units)."""
    scale = jnp.asarray(objective.layout.scale)

    def residuals_and_parts(z, args):
        data, weight = args
        x = z * scale
        model = objective.predict(x)
        res = tuple(w * (f - y) for f, y, w in zip(model, data, weight))
        pen = objective.penalty(x)
        flat = jnp.concatenate([r.ravel() for r in res] + [pen])
        return flat, (model, res, pen)

    def stats(x, args):
        # one forward pass shared by the model, the residuals and the Jacobian
        J, (model, res, pen) = jax.jacfwd(lambda z: residuals_and_parts(z, args), has_aux=True)(x / scale)
        return model, res, pen, J

    return stats


def compiled_fit(objective: Objective, o: SolverOptions, batched: bool):
    """The jitted ``(start, args) -> (x, steps, code, model, residuals, penalty, J)`` of
    ``objective`` for options ``o`` — solve, then the statistics at the solution, in one
    compiled function — vmapped over a leading axis of start and args when ``batched``.
    Compiled once per objective, options and batching; cached on the objective."""
    key = ("fit", o, batched)
    cache = _cache(objective)
    if key not in cache:
        solve = _solve_function(objective, o)
        stats = _statistics_function(objective)

        def run(start, args):
            x, steps, code = solve(start, args)
            return (x, steps, code) + tuple(stats(x, args))

        cache[key] = jax.jit(jax.vmap(run) if batched else run)
    return cache[key]


def multistart_points(objective: Objective, starts: int, seed: int) -> np.ndarray:
    """``(starts, P)`` physical starting points: the objective's start first, then random
    draws — uniform between finite bounds, log-uniform within a factor 10 of the start above a
    lone lower (below a lone upper) bound, normal of width ``scale`` otherwise."""
    layout = objective.layout
    x0 = layout.x0
    rng = np.random.default_rng(seed)
    pts = np.tile(x0, (starts, 1))
    k = starts - 1
    if k <= 0:
        return pts
    lo, hi, s = layout.lower, layout.upper, layout.scale
    draw = pts[1:]
    b, lw, hg, fr = layout.both, layout.low, layout.high, layout.free
    draw[:, b] = lo[b] + (hi[b] - lo[b]) * rng.uniform(0.02, 0.98, (k, b.size))
    base = np.maximum(x0[lw] - lo[lw], 1e-3 * s[lw])
    draw[:, lw] = lo[lw] + base * 10.0 ** rng.uniform(-1, 1, (k, lw.size))
    base = np.maximum(hi[hg] - x0[hg], 1e-3 * s[hg])
    draw[:, hg] = hi[hg] - base * 10.0 ** rng.uniform(-1, 1, (k, hg.size))
    draw[:, fr] = x0[fr] + s[fr] * rng.normal(size=(k, fr.size))
    pts[1:] = draw
    return pts


def fit(objective: Objective, method: str = "lm", *, data=None, x0=None, starts: int = 1, seed: int = 0,
        max_steps: int = 256, rtol: float = 1e-10, atol: float = 1e-12, gtol: float = 1e-9,
        scale_covariance: Optional[bool] = None, rank_rtol: float = 1e-8):
    """Fit ``objective`` and return a :class:`~fitting.FitResult`.

    Args:
        objective: the :class:`~fitting.Objective`.
        method: ``"lm"`` (default), ``"gauss-newton"``, ``"dogleg"``, ``"bfgs"`` or ``"lbfgsb"``
            (bounds kept exactly; for optima on a bound).
        data: optional replacement spectra (one ``(samples, wl)`` array per dataset): fits
            other data with the same compiled solver.
        x0: optional physical starting vector ``(P,)`` (default: from the parameters / stack).
        starts: multi-start: number of starting points (the first is ``x0``, the others drawn by
            :func:`multistart_points`), solved in one vmapped call; the converged one with the
            lowest χ² wins.
        max_steps, rtol, atol, gtol: stopping rules (:class:`SolverOptions`).
        scale_covariance: scale the covariance by the reduced χ²; default: True unless every
            dataset gives σ.
        rank_rtol: singular values of the normalised Jacobian below ``rank_rtol`` × the largest
            mark a non-identifiable combination.

    Never raises on non-convergence: see ``result.converged`` and ``result.reason``.
    """
    from ._results import build_result

    o = SolverOptions(method, rtol, atol, gtol, max_steps)
    if objective.n_parameters == 0:
        raise LayerstackError("the objective has no free parameter")
    if not (isinstance(starts, int) and starts >= 1):
        raise LayerstackError(f"starts must be an integer >= 1, got {starts!r}")
    args = objective.args(data)
    x_start = objective.layout.x0 if x0 is None else np.asarray(x0, float)
    if x_start.shape != (objective.n_parameters,):
        raise LayerstackError(f"x0 must have {objective.n_parameters} values, got shape {x_start.shape}")
    if starts == 1:
        y0 = jnp.asarray(starting_point(objective, o, x_start))
        out = compiled_fit(objective, o, batched=False)(y0, args)
        n_starts_converged = None
    else:
        pts = multistart_points(objective, starts, seed)
        pts[0] = x_start
        y0 = jnp.asarray(starting_point(objective, o, pts))
        bargs = jax.tree.map(lambda a: jnp.broadcast_to(a, (starts,) + a.shape), args)
        outs = compiled_fit(objective, o, batched=True)(y0, bargs)
        codes = np.asarray(outs[2])
        cost = np.asarray(sum(jnp.sum(r**2, axis=(-2, -1)) for r in outs[4]) + jnp.sum(outs[5] ** 2, axis=-1))
        ok = (codes == 0) & np.isfinite(cost)
        n_starts_converged = int(ok.sum())
        best = int(np.argmin(np.where(ok, cost, np.inf))) if ok.any() else int(np.argmin(np.where(np.isfinite(cost), cost, np.inf)))
        out = jax.tree.map(lambda a: a[best], outs)
    x, steps, code, model, res, pen, J = out
    return build_result(objective, o, np.asarray(x), int(steps), int(code), [np.asarray(m) for m in model],
                        [np.asarray(r) for r in res], np.asarray(pen), np.asarray(J), args,
                        scale_covariance=scale_covariance, rank_rtol=rank_rtol, starts=starts,
                        starts_converged=n_starts_converged)
