r"""Gradient-based coating design: layer thicknesses to targets, thickness-error yield and
robust design.

The merit :math:`M` of the targets (:func:`~fitting.merit`, :mod:`fitting._design_targets`) is
minimised over the free thicknesses within bounds by L-BFGS-B, gradients by reverse-mode
autodiff through the Rouard recursion — the bounded driver shared with :func:`~fitting.fit`
(:mod:`fitting._bounded`): jaxopt's, several starts run as one vmapped solve, or SciPy's on the
host (one compiled merit and gradient, quick to start). The needle method, which grows a design
by inserting layers, is :mod:`fitting._needle`.

Units: thicknesses in nm, wavelengths in nm, angles in degrees (these are the edges).
"""

from __future__ import annotations

from typing import Literal, NamedTuple, Optional, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import layerstack_jax as ls
from layerstack_jax import LayerstackError

from ._bounded import BoundedSolution, compiled_lbfgsb, host_lbfgsb
from ._design_targets import merit

__all__ = [
    "DesignResult",
    "optimize_thicknesses",
    "RobustSpec",
    "YieldResult",
    "with_thicknesses",
    "thickness_yield",
]


# ------------------------------------------------------------------ free thicknesses
def _free_layers(stack: ls.Stack, free: Optional[Sequence[int]]) -> tuple[int, ...]:
    n = len(stack.layers)
    if free is None:
        free = [i for i, layer in enumerate(stack.layers) if layer.coherent]
    free = tuple(int(i) for i in free)
    for i in free:
        if not -n <= i < n:
            raise LayerstackError(f"free layer index {i} out of range for a stack of {n} layers")
    free = tuple(i % n for i in free)
    if len(set(free)) != len(free):
        raise LayerstackError(f"free layer indices repeat: {free}")
    if not free:
        raise LayerstackError("no free layer: the stack has no coherent layer and none was named in `free`")
    return free


def with_thicknesses(stack: ls.Stack, free: Sequence[int], d) -> ls.Stack:
    """``stack`` with the thicknesses of layers ``free`` replaced by ``d`` (nm, shape ``(F,)``)."""
    return eqx.tree_at(
        lambda s: tuple(s.layers[i].thickness for i in free), stack, tuple(d[k] for k in range(len(free)))
    )


def _bounds(bounds, n_free: int):
    lo, hi = (np.broadcast_to(np.asarray(b, float), (n_free,)).copy() for b in bounds)
    if np.any(lo < 0):
        raise LayerstackError(f"thickness bounds must be >= 0 nm, got lower bounds {lo}")
    if np.any(hi <= lo):
        raise LayerstackError(f"thickness bounds inverted or empty: lower {lo}, upper {hi}")
    return lo, hi


class DesignResult(NamedTuple):
    """Outcome of a thickness optimisation.

    ``stack``: the best design; ``thickness_nm``: its free thicknesses in nm, shape ``(F,)``; ``free``: their
    layer indices; ``merit`` and ``initial_merit``: merit of the best design and of the start;
    ``start_merits``: final merit of every start ``(S,)``; ``n_steps``: iterations of the best
    start; ``converged``: the best start met the tolerance before ``maxiter``; ``message``.
    Merits are dimensionless scalars (see :func:`merit`).
    """

    stack: ls.Stack
    thickness_nm: np.ndarray
    free: tuple
    merit: float
    initial_merit: float
    start_merits: np.ndarray
    n_steps: int
    converged: bool
    message: str


def _messages(sol: BoundedSolution, maxiter: int, tol: float, driver: str) -> list:
    return [
        f"converged in {int(k)} iterations ({driver}; projected-gradient norm {g:.1e}, tol {tol:g})" if ok
        else f"NOT converged: {int(k)} iterations (maxiter {maxiter}, {driver}), projected-gradient norm {g:.1e} > tol {tol:g}"
        for k, g, ok in zip(np.atleast_1d(sol.num_steps), np.atleast_1d(sol.gradient_norm), np.atleast_1d(sol.converged))
    ]


def _solve_compiled(total, X0, lo, hi, maxiter: int, tol: float) -> BoundedSolution:
    """All starts ``X0`` ``(S, F)`` in one compiled, vmapped L-BFGS-B solve
    (:func:`fitting._bounded.compiled_lbfgsb`)."""
    run = compiled_lbfgsb(lambda x: total(x), maxiter, tol)
    lower, upper = jnp.asarray(lo), jnp.asarray(hi)

    @jax.jit
    def solve_all(X):
        if X.shape[0] == 1:  # one start: no vmap (compiles ~1.5x faster)
            return jax.tree.map(lambda a: a[None], run(X[0], lower, upper))
        return jax.vmap(lambda x0: run(x0, lower, upper))(X)

    return BoundedSolution(*(np.asarray(a) for a in solve_all(jnp.asarray(X0))))


def optimize_thicknesses(
    stack: ls.Stack,
    targets: Sequence,
    *,
    free: Optional[Sequence[int]] = None,
    bounds_nm=(0.0, 1000.0),
    starts_nm=None,
    n_starts: int = 1,
    seed: int = 0,
    maxiter: int = 500,
    tol: float = 1e-9,
    robust: Optional["RobustSpec"] = None,
    method: Literal["jaxopt", "scipy"] = "jaxopt",
) -> DesignResult:
    """Minimise the merit over the thicknesses of layers ``free`` within ``bounds_nm``.

    Args:
        stack: starting design (its thicknesses are the first start).
        targets: :class:`SpectralTarget` list.
        free: indices of the layers whose thickness varies (default: every coherent layer).
        bounds_nm: ``(lower, upper)`` in nm, scalars or one per free layer.
        starts_nm: optional extra starts ``(S, F)`` in nm; with ``n_starts > 1`` and no
            ``starts_nm``, uniform random starts within the bounds are added (``seed``).
        maxiter, tol: L-BFGS-B iteration cap and tolerance on the projected gradient.
        robust: optimise the expected merit under random thickness errors (:class:`RobustSpec`).
        method: ``"jaxopt"``: all starts run in one vmapped, compiled L-BFGS-B solve (jaxopt) —
            for many starts or an accelerator, at ~10 s or more of compilation; ``"scipy"``:
            SciPy's L-BFGS-B on the host, start after start, with the merit and its gradient
            compiled once — seconds to start, for small designs and the command line.

    The best start is returned.
    """
    if method not in ("jaxopt", "scipy"):
        raise LayerstackError(f"optimize_thicknesses: method must be 'jaxopt' or 'scipy', got {method!r}")
    free = _free_layers(stack, free)
    lo, hi = _bounds(bounds_nm, len(free))
    d0 = np.array([float(np.asarray(stack.layers[i].thickness)) for i in free])
    if np.any(d0 < lo) or np.any(d0 > hi):
        raise LayerstackError(f"starting thicknesses {d0} nm lie outside the bounds [{lo}, {hi}]")
    starts = [d0[None]]
    if starts_nm is not None:
        s = np.atleast_2d(np.asarray(starts_nm, float))
        if s.shape[1] != len(free):
            raise LayerstackError(f"starts_nm must be shaped (S, {len(free)}), got {s.shape}")
        starts.append(np.clip(s, lo, hi))
    elif n_starts > 1:
        rng = np.random.default_rng(seed)
        starts.append(rng.uniform(lo, hi, (n_starts - 1, len(free))))
    X0 = np.concatenate(starts)
    scale = 100.0  # nm: variables of order one for L-BFGS-B

    def total(x):
        # The model sees thicknesses >= 0 and finite: under vmap, the lanes of starts that have
        # already stopped keep being evaluated on whatever they hold, and the stack's own checks
        # (thickness >= 0 and finite) would stop the whole solve. A start whose iterate is NaN is
        # still reported as not converged (BoundedSolution checks its x).
        d = jnp.maximum(jnp.where(jnp.isfinite(x), x, 0.0) * scale, 0.0)
        if robust is None:
            return merit(with_thicknesses(stack, free, d), targets)
        return _expected_merit(stack, targets, free, d, robust)

    if method == "jaxopt":
        sol = _solve_compiled(total, X0 / scale, lo / scale, hi / scale, maxiter, tol)
    else:
        sol = host_lbfgsb(total, X0 / scale, lo / scale, hi / scale, maxiter, tol)
    messages = _messages(sol, maxiter, tol, "jaxopt L-BFGS-B" if method == "jaxopt" else "SciPy L-BFGS-B")
    initial = float(total(jnp.asarray(X0[0] / scale)))
    values = np.where(np.isfinite(sol.value), sol.value, np.inf)
    best = int(np.argmin(values))
    d_best = sol.x[best] * scale
    iters, ok = sol.num_steps, sol.converged
    return DesignResult(
        stack=with_thicknesses(stack, free, jnp.asarray(d_best)),
        thickness_nm=d_best,
        free=free,
        merit=float(values[best]),
        initial_merit=float(initial),
        start_merits=values,
        n_steps=int(iters[best]),
        converged=bool(ok[best]),
        message=messages[best],
    )


# ------------------------------------------------------------------ tolerances and yield
class RobustSpec(NamedTuple):
    """Random thickness errors: Gaussian, ``sigma_nm`` absolute plus ``relative`` × thickness,
    ``samples`` fixed draws (common random numbers: the robust merit stays smooth).

    ``sigma_nm`` in nm, ``relative`` a dimensionless fraction; the draws are standard normals of
    shape ``(samples, F)`` (F free layers), seeded by ``seed``; perturbed thicknesses are
    clipped at 0."""

    sigma_nm: float = 0.0
    relative: float = 0.0
    samples: int = 64
    seed: int = 0


def _perturbations(spec: RobustSpec, n_free: int) -> np.ndarray:
    if spec.sigma_nm < 0 or spec.relative < 0 or spec.samples < 1:
        raise LayerstackError("thickness errors need sigma_nm >= 0, relative >= 0, samples >= 1")
    return np.random.default_rng(spec.seed).standard_normal((spec.samples, n_free))


def _perturbed(d, z, spec: RobustSpec):
    return jnp.maximum(d + z * (spec.sigma_nm + spec.relative * d), 0.0)


def _expected_merit(stack, targets, free, d, spec: RobustSpec):
    z = jnp.asarray(_perturbations(spec, len(free)))
    return jnp.mean(jax.vmap(lambda zi: merit(with_thicknesses(stack, free, _perturbed(d, zi, spec)), targets))(z))


class YieldResult(NamedTuple):
    """Monte-Carlo of thickness errors: ``fraction`` of draws within spec (a dimensionless
    scalar in [0, 1]), per-draw ``merits`` (dimensionless) and ``within`` flags, each of shape
    ``(samples,)``."""

    fraction: float
    merits: np.ndarray
    within: np.ndarray


def thickness_yield(
    stack: ls.Stack,
    targets: Sequence,
    errors: RobustSpec,
    *,
    free: Optional[Sequence[int]] = None,
) -> YieldResult:
    """Fraction of manufactured designs within spec (every target point within its tolerance)
    when the thicknesses of layers ``free`` carry random errors ``errors`` (one vmapped call).

    ``errors``: a :class:`RobustSpec` (``sigma_nm`` in nm). Returns a :class:`YieldResult`: the
    fraction is a dimensionless scalar in [0, 1]; ``merits`` and ``within`` have shape
    ``(samples,)``."""
    free = _free_layers(stack, free)
    d = jnp.asarray([float(np.asarray(stack.layers[i].thickness)) for i in free])
    z = jnp.asarray(_perturbations(errors, len(free)))

    @jax.jit
    def one(zi):
        st = with_thicknesses(stack, free, _perturbed(d, zi, errors))
        ok = jnp.all(jnp.stack([t.within_spec(st) for t in targets]))
        return merit(st, targets), ok

    merits, within = (np.asarray(a) for a in jax.vmap(one)(z))
    return YieldResult(float(np.mean(within)), merits, within)
