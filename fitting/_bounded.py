r"""One bounded minimiser, L-BFGS-B (Byrd, Lu, Nocedal & Zhu, SIAM J. Sci. Comput. 16, 1190
(1995)), shared by :func:`~fitting.fit` (``method="lbfgsb"``) and the coating design
(:func:`~fitting.optimize_thicknesses`, :func:`~fitting.needle_design`).

Two drivers of the same method, with one result type (:class:`BoundedSolution`):

* :func:`compiled_lbfgsb` — jaxopt's L-BFGS-B as a pure, jit- and vmap-able function (several
  starts or fits in one compiled solve);
* :func:`host_lbfgsb` — SciPy's L-BFGS-B on the host, start after start, with the objective and
  its exact gradient compiled once (no solver to compile: seconds to start).

Both stop when the norm of the projected gradient :math:`\|P(x - \nabla f) - x\|` (P the
projection on the box) is at most ``tol``, and report that norm: "converged" means that test
was met, so a minimum on a bound (where the gradient itself need not vanish) is converged.

jaxopt is imported here only, when a compiled L-BFGS-B is first built: ``import fitting`` never
imports it (jaxopt warns at import that it is no longer maintained; the warning concerns this
library's choice of dependency, not the user's input, so it is not passed on).
"""

from __future__ import annotations

import warnings
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Bool, Float, Int

__all__ = ["BoundedSolution", "compiled_lbfgsb", "host_lbfgsb", "projected_gradient_norm"]


class BoundedSolution(NamedTuple):
    """Outcome of a bounded minimisation (leading axes: one per start or fit).

    ``x``: the solution ``(..., P)`` (the solver's coordinates); ``value``: the objective at
    ``x``; ``num_steps``: iterations; ``gradient_norm``: the norm of the projected gradient at
    ``x``; ``converged``: ``gradient_norm <= tol`` with finite ``x`` and ``value``. JAX arrays
    from the compiled driver, NumPy arrays from the host (scipy) one.
    """

    x: Float[ArrayLike, "*start P"]
    value: Float[ArrayLike, "*start"]
    num_steps: Int[ArrayLike, "*start"]
    gradient_norm: Float[ArrayLike, "*start"]
    converged: Bool[ArrayLike, "*start"]


def _jaxopt():
    """jaxopt, imported on first use, without its import-time deprecation warning."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*JAXopt is no longer maintained.*", category=DeprecationWarning)
        import jaxopt
    return jaxopt


def projected_gradient_norm(x, g, lower, upper):
    """:math:`\\|\\mathrm{clip}(x - g, l, u) - x\\|_2`: zero at a bound-constrained stationary
    point (KKT), also when the gradient ``g`` pushes ``x`` against a bound."""
    return jnp.linalg.norm(jnp.clip(x - g, lower, upper) - x)


def compiled_lbfgsb(fun: Callable, maxiter: int, tol: float) -> Callable:
    """Pure ``(x0, lower, upper, *args) -> BoundedSolution`` minimising ``fun(x, *args)`` over
    ``lower <= x <= upper`` by jaxopt's L-BFGS-B (``maxiter`` iterations at most, projected
    gradient norm ``<= tol``); traceable, so it can be jitted and vmapped over starts."""
    solver = _jaxopt().LBFGSB(fun=fun, maxiter=maxiter, tol=tol)

    def run(x0, lower, upper, *args):
        out = solver.run(x0, (lower, upper), *args)
        x, state = out.params, out.state
        finite = jnp.all(jnp.isfinite(x)) & jnp.isfinite(state.value)
        return BoundedSolution(x, state.value, state.iter_num, state.error, finite & (state.error <= tol))

    return run


def host_lbfgsb(fun: Callable, X0, lower, upper, maxiter: int, tol: float) -> BoundedSolution:
    """SciPy's L-BFGS-B from each row of ``X0`` ``(S, P)`` in turn, on the host; ``fun(x)`` is
    compiled once with its gradient (``jax.value_and_grad``). Returns a stacked
    :class:`BoundedSolution` (NumPy arrays with a leading axis S)."""
    from scipy.optimize import Bounds, minimize

    value_and_grad = jax.jit(jax.value_and_grad(fun))
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)

    def f(x):
        v, g = value_and_grad(jnp.asarray(x))
        return float(v), np.asarray(g, dtype=float)

    rows = []
    for x0 in np.atleast_2d(np.asarray(X0, float)):
        r = minimize(f, x0, jac=True, method="L-BFGS-B", bounds=Bounds(lower, upper),
                     options={"maxiter": maxiter, "gtol": tol, "ftol": 1e-12})
        v, g = f(r.x)
        pg = float(np.linalg.norm(np.clip(r.x - g, lower, upper) - r.x))
        finite = bool(np.all(np.isfinite(r.x)) and np.isfinite(v))
        # SciPy also stops on a relative change of the value (ftol) below round-off: that is a
        # converged solve too (the value cannot improve further), which SciPy reports as success
        rows.append((r.x, v, r.nit, pg, finite and (pg <= tol or bool(r.success))))
    x, v, n, pg, ok = zip(*rows)
    return BoundedSolution(np.asarray(x), np.asarray(v), np.asarray(n), np.asarray(pg), np.asarray(ok))
