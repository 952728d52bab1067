r"""Solvers: one least-squares layer over optimistix (public API only) and the shared bounded
L-BFGS-B driver (:mod:`fitting._bounded`).

* ``"lm"`` (default): Levenberg–Marquardt, composed from optimistix's parts
  (:class:`optimistix.AbstractGaussNewton` with a damped Newton descent and a trust-region
  search, :class:`LevenbergMarquardt`);
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
coordinates that only approach a bound, so their step test could never be met on it. Inside
their solves a component that comes within 1e-4 of its scale of a finite bound is held exactly
on that bound (:func:`hold_on_bounds`, an active set): its derivative is zero there, so the
solver's own step test ends the solve once the other parameters have converged — a few steps,
not ``max_steps``. Afterwards (:func:`settle_on_bounds`) the bound's optimality is checked
(Karush–Kuhn–Tucker: the gradient presses against the bound): if it holds, the fit is converged
on the bound and the result says so (:attr:`FitResult.note`); if it does not (the bound was
reached on the way, or the solver failed there), the fit is finished from that point with
L-BFGS-B, which keeps bounds exactly, and the note says so.

Each objective compiles one solve function per method and options (cached on the objective);
data travel in ``args``, so later fits with other data and the starts of a multi-start reuse it
(batched fits compile one vmapped copy). The least-squares methods take the statistics' Jacobian,
model and residuals from the solver's last evaluation (:func:`jacobian_with_statistics`): the
compiled fit holds one copy of the model's Jacobian.
A fit never raises on non-convergence: the result carries a status (:data:`STATUS`) and the
reason in the library's words.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from typing import Callable, NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.custom_derivatives import SymbolicZero
from jaxtyping import Array, Float, Int
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from layerstack_jax import LayerstackError, progress_reporter, traced_checks_off

from ._bounded import compiled_lbfgsb
from ._least_squares import LevenbergMarquardt, RoundoffTrustRegion, optx_solver, solver_status
from ._objective import Objective
from ._results import build_result
from ._statistics import bound_contacts
from ._structured import (STRUCTURE_MODES, CompressedJacobian, Structure, compressed_jacobian_function, find_structure,
                          residuals_with_jacobian, sparse_jacobian_function, structured_jacobian_with_statistics,
                          structured_statistics_function, verify_structure, with_args_tangent)
from ._watchdog import wait_for
from ._status import ABANDONED, CONVERGED, FAILED, MAX_STEPS, NONFINITE, STATUS, result_message

__all__ = ["SolverOptions", "METHODS", "HOST_METHODS", "STATUS", "FitOutput", "LevenbergMarquardt",
           "RoundoffTrustRegion", "compiled_fit", "result_message", "multistart_points", "starting_point",
           "settle_on_bounds", "fit"]

METHODS = ("lm", "gauss-newton", "dogleg", "bfgs", "lbfgsb", "trf")
#: Methods run on the host (scipy), one fit at a time.
HOST_METHODS = ("trf",)
#: Unconstrained methods (transformed coordinates) that a bound can stall.
_TRANSFORMED = ("lm", "gauss-newton", "dogleg", "bfgs")

@dataclasses.dataclass(frozen=True)
class SolverOptions:
    """Solver choice and stopping rules.

    ``rtol``/``atol``: optimistix step and cost tolerances on the unconstrained coordinates;
    ``gtol``: L-BFGS-B tolerance on the projected gradient of :math:`\\tfrac12\\|r\\|^2` (in z);
    ``max_steps``: iteration limit; ``sigma_tol``: the least-squares methods (``lm``,
    ``gauss-newton``, ``dogleg``) also stop as soon as the Gauss–Newton step still to go is
    shorter than ``sigma_tol`` standard errors (:func:`gauss_newton_distance`; 0 turns that
    rule off, leaving optimistix's step and cost test alone); ``structure``: the Jacobian's
    form (:data:`fitting._structured.STRUCTURE_MODES`) — ``"auto"`` uses the compressed,
    block-structured Jacobian of spectral parameters free per wavelength where it pays
    (:func:`structure_for`), ``"dense"`` never, ``"structured"`` always
    (an error where the fit has no such structure).
    """

    method: str = "lm"
    rtol: float = 1e-10
    atol: float = 1e-12
    gtol: float = 1e-9
    max_steps: int = 256
    sigma_tol: float = 1e-3
    structure: str = "auto"

    def __post_init__(self):
        if self.method not in METHODS:
            raise LayerstackError(f"method must be one of {METHODS}, got {self.method!r}")
        if self.structure not in STRUCTURE_MODES:
            raise LayerstackError(f"structure must be one of {STRUCTURE_MODES}, got {self.structure!r}")
        if not (isinstance(self.max_steps, (int, np.integer)) and self.max_steps >= 1):
            raise LayerstackError(f"max_steps must be an integer >= 1, got {self.max_steps!r}")
        for name in ("rtol", "atol", "gtol"):
            if not getattr(self, name) > 0:
                raise LayerstackError(f"{name} must be > 0, got {getattr(self, name)}")
        if not (isinstance(self.sigma_tol, (int, float, np.floating)) and 0 <= self.sigma_tol < 1):
            raise LayerstackError(f"sigma_tol must be in [0, 1) standard errors, got {self.sigma_tol!r}")


class FitOutput(NamedTuple):
    """What the compiled fit returns (leading axes: one per fit in batched calls).

    ``x``: physical solution ``(P,)``; ``num_steps``; ``status`` (:data:`STATUS`); ``model``:
    model values per dataset ``(samples, wl)``; ``residuals``: weighted data residuals per
    dataset; ``penalty``: penalty residuals; ``jacobian``: ``(M, P)`` of the full residual vector
    w.r.t. ``x / scale`` (a :class:`~fitting._structured.CompressedJacobian` standing for it
    when the fit uses the block structure of spectral parameters free per wavelength)."""

    x: Float[Array, "*fit P"]
    num_steps: Int[Array, "*fit"]
    status: Int[Array, "*fit"]
    model: tuple[Float[Array, "..."], ...]
    residuals: tuple[Float[Array, "..."], ...]
    penalty: Float[Array, "*fit K"]
    jacobian: Float[Array, "*fit M P"] | CompressedJacobian


# --------------------------------------------------------------------------- compiled solves
def _solve_function(objective: Objective, o: SolverOptions):
    """Pure ``(start, args, optics, give_up) -> (x, steps, status)``; ``start`` is ``u``
    (optimistix) or ``z`` (L-BFGS-B); ``optics`` the objective's fixed optics (or None);
    ``give_up`` the multi-start give-up rule ``(steps, cost)`` (Levenberg–Marquardt only:
    :meth:`LevenbergMarquardt.terminate`; :data:`NEVER` for a plain fit)."""
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


#: A component of an unconstrained solve within this fraction of its scale of a finite bound is
#: held on the bound. Closer than that the cost is flat at round-off level for the usual
#: parameters (α·h ≲ 1e-4 of an absorbance, ρg to 1e-4): a transformed coordinate would crawl
#: towards the bound for tens of steps. Where the optimum is in fact that close to the bound
#: but inside, the bound fails the optimality check and L-BFGS-B finishes the fit.
HOLD_RTOL = 1e-4


def hold_on_bounds(layout, x):
    """Physical ``x`` ``(P,)`` with each component in contact with a finite bound (within
    :data:`HOLD_RTOL` of its scale, :func:`fitting._statistics.bound_contacts`) put exactly on
    that bound.

    Used on the iterates of the unconstrained solvers: the held component's derivative is zero,
    so the solver stops moving it (an active set) instead of chasing a bound its transformed
    coordinate only approaches; the solver's step test then ends the solve. Whether the bound
    is optimal is checked afterwards (:func:`settle_on_bounds`)."""
    lo, hi = bound_contacts(x, layout.lower, layout.upper, layout.scale, rtol=HOLD_RTOL, xp=jnp)
    lower, upper = (jnp.asarray(b, dtype=x.dtype) for b in (layout.lower, layout.upper))
    return jnp.where(lo, lower, jnp.where(hi, upper, x))


def jacobian_with_statistics(objective: Objective, structure=None):
    r"""``fn(u, (args, optics)) -> (r, ((model, residuals, penalty), J))``: the residual
    vector of the solver's coordinates ``u`` for optimistix (``has_aux=True``), at
    :math:`z = x/s`, :math:`x` = :func:`hold_on_bounds` of ``layout.to_physical(u)``, and as
    auxiliary output what the statistics need at that point (:func:`_statistics_function`:
    model spectra, weighted data residuals, penalty residuals, :math:`J = \partial r/\partial z`).

    One forward-mode pass (``jax.jacfwd``: one primal pass and P tangents) gives ``r``, the
    by-products and :math:`J`; the derivative w.r.t. ``u`` is :math:`J\,D` with
    :math:`D = \partial z/\partial u` (zero for components held on a bound), applied as
    :math:`J\,(D\,\delta u)` (the JVP of ``z_of``; a custom JVP,
    :func:`fitting._structured.residuals_with_jacobian`): linearising ``fn`` costs one ``jacfwd``
    of the model. Tangents of ``args`` (never used by the solvers) are propagated exactly by a
    separate JVP.

    With a ``structure`` (:class:`fitting._structured.Structure`) the Jacobian is formed and
    applied in compressed form (:func:`fitting._structured.structured_jacobian_with_statistics`)."""
    layout = objective.layout
    scale = jnp.asarray(layout.scale)
    parts = _residuals_and_parts(objective)

    def z_of(u):
        return hold_on_bounds(layout, layout.to_physical(u)) / scale

    if structure is not None:
        return structured_jacobian_with_statistics(objective, structure, parts, z_of, _traced_once)

    return residuals_with_jacobian(parts, z_of, _traced_once, lambda f, z: jax.jacfwd(f, has_aux=True)(z),
                                   lambda J, dz: J @ dz)


def _traced_once(jitted: Callable) -> Callable:
    """``jitted`` called with JAX's abstract-mesh context made explicit (the ambient mesh, or
    the empty one where none is set: a no-op for the computation), so that its trace is found
    again in JAX's tracing cache whichever context calls it.

    Optimistix calls the residual function first in a structure pass (``eval_shape`` /
    ``closure_convert``, where that context is unset, ``None``) and then in the solve's loop
    (where JAX has set it to the empty mesh): the two cache keys differ in that field alone
    and the model's Jacobian — most of a fit's tracing time — was traced twice
    (``jax_explain_cache_misses``: "abstract_mesh_context_manager differs")."""

    def call(*args):
        with jax.sharding.use_abstract_mesh(jax.sharding.get_abstract_mesh()):
            return jitted(*args)

    return call


def dense_jacobian(fn):
    r"""``fn(u, args) -> r`` (``u`` of shape ``(P,)``, ``r`` of shape ``(M,)``) with the same
    values and a JVP rule that materialises the Jacobian :math:`J = \partial r/\partial u` once,
    by forward mode (one primal pass and P tangents, ``jax.jacfwd``), and applies it as the
    dense product :math:`J\,\delta u`. Linearising it (``jax.linearize``) thus costs one
    ``jacfwd``; materialising or transposing the linear map afterwards costs a matrix product
    instead of further passes through the model. Tangents of ``args`` (never used by the
    solvers) are propagated exactly by a separate JVP."""

    @jax.custom_jvp
    def g(u, args):
        return fn(u, args)

    def g_jvp(primals, tangents):
        u, args = primals
        du, dargs = tangents

        def value_twice(v):  # the Jacobian's function and, as aux, its value: one pass
            r = fn(v, args)
            return r, r

        J, r = jax.jacfwd(value_twice, has_aux=True)(u)
        out = jnp.zeros_like(r) if isinstance(du, SymbolicZero) else J @ du
        return r, with_args_tangent(out, lambda a: fn(u, a), args, dargs)

    g.defjvp(g_jvp, symbolic_zeros=True)
    return g


def starting_point(objective: Objective, o: SolverOptions, x0) -> np.ndarray:
    """Solver coordinates of physical ``x0`` (``(..., P)``)."""
    layout = objective.layout
    if o.method in ("lbfgsb", "trf"):
        return np.asarray(x0, float) / layout.scale
    return layout.to_unconstrained(x0)


def structure_for(objective, mode: str, method: str) -> Optional[Structure]:
    """The :class:`Structure` a fit of ``objective`` uses under ``mode``
    (:data:`STRUCTURE_MODES`), found and verified once and cached on the objective; None for
    the dense path. ``"auto"`` takes it when it exists and the compressed tangents are at most
    half the components (``g + b ≤ P/2``): below that the dense Jacobian is as cheap.
    ``"structured"`` raises :class:`LayerstackError` saying why when there is none."""
    if mode not in STRUCTURE_MODES:
        raise LayerstackError(f"structure must be one of {STRUCTURE_MODES}, got {mode!r}")
    if mode == "dense":
        return None
    cache = objective.cache
    if "structure" not in cache:
        cache["structure"] = find_structure(objective)
    st, why = cache["structure"]
    if st is None or (mode == "auto" and 2 * st.tangents > st.P):
        if mode == "structured":
            raise LayerstackError(f"structure='structured': this fit's Jacobian has no block structure: {why}")
        return None
    if "structure_checked" not in cache:  # once, and only where it would be used
        ok, why = verify_structure(objective, st, _residuals_and_parts(objective))
        cache["structure_checked"] = (ok, why)
    ok, why = cache["structure_checked"]
    if not ok:
        if mode == "structured":
            raise LayerstackError(f"structure='structured': this fit's Jacobian has no block structure: {why}")
        return None
    return st


# --------------------------------------------------------------------------- the solve


def refit_chi2(objective: Objective, o: SolverOptions, args) -> float:
    """χ² that the compiled fit of ``objective`` (the same program: no new compilation) reaches
    from the parameters' starting values on data ``args`` = ``(data, weight)``."""
    start = jnp.asarray(starting_point(objective, o, objective.layout.x0))
    out = compiled_fit(objective, o, batched=False)(start, args, objective.optics)
    return float(sum(np.sum(np.asarray(r, float) ** 2) for r in out.residuals))


def _residuals_and_parts(objective: Objective):
    """Pure ``(z, args, optics) -> (r, (model spectra, weighted data residuals, penalty))`` at
    ``x = z * scale``: the full residual vector and its parts."""
    scale = jnp.asarray(objective.layout.scale)

    def residuals_and_parts(z, args, optics):
        x = z * scale
        model = objective.predict(x, optics)
        res = objective.weighted_residuals(x, args, optics, model=model)
        pen = objective.penalty(x)
        flat = jnp.concatenate([r.ravel() for r in res] + [pen])
        return flat, (model, res, pen)

    return residuals_and_parts


def _statistics_function(objective: Objective, structure=None):
    """Pure ``(x, args, optics) -> (model spectra, weighted data residuals, penalty, J)``, J the
    Jacobian of the full residual vector w.r.t. ``x / scale`` (scaled physical units; in
    compressed form with a ``structure``)."""
    scale = jnp.asarray(objective.layout.scale)
    residuals_and_parts = _residuals_and_parts(objective)
    if structure is not None:
        return structured_statistics_function(objective, structure, residuals_and_parts)

    def stats(x, args, optics):
        # one forward pass shared by the model, the residuals and the Jacobian
        J, (model, res, pen) = jax.jacfwd(lambda z: residuals_and_parts(z, args, optics), has_aux=True)(x / scale)
        return model, res, pen, J

    return stats


def require_compiled_method(caller: str, method: str) -> None:
    """Refuse a host method (:data:`HOST_METHODS`: one fit at a time on the host) where
    ``caller`` needs a compiled, batched solver; the message names the methods that are."""
    if method in HOST_METHODS:
        compiled = ", ".join(repr(m) for m in METHODS if m not in HOST_METHODS)
        raise LayerstackError(f"{caller}: method {method!r} runs on the host one fit at a time; batched fits need a "
                              f"compiled solver: {compiled}")


#: XLA options of the compiled programs of a single fit on the CPU (:func:`fit_jit`): XLA's
#: classic fusion emitters rather than its MLIR ones. A fit of one measurement spends most of
#: its time compiling (E1: 3-angle × 700-λ ψ/Δ, Cauchy film on SiO2/Si: half the XLA time for
#: the solver's program, the further fits as fast; benchmarks/results/ellipsometry_fit_history.md);
#: batched fits (``fit_batch``, ``fit_cube``: run time dominates) keep XLA's defaults.
SINGLE_FIT_COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


@functools.cache
def _compiler_options(backend: str) -> Optional[dict]:
    """:data:`SINGLE_FIT_COMPILER_OPTIONS` where they apply: on the CPU backend, when this XLA
    knows them (probed once on a trivial program: an XLA without the option refuses it) and the
    user has not set one of them in ``XLA_FLAGS`` (theirs win); else None (XLA's defaults)."""
    flags = os.environ.get("XLA_FLAGS", "")
    if backend != "cpu" or any(name in flags for name in SINGLE_FIT_COMPILER_OPTIONS):
        return None
    try:
        jax.jit(lambda v: v + 1, compiler_options=SINGLE_FIT_COMPILER_OPTIONS).lower(1.0).compile()
    except Exception:  # noqa: BLE001 — an XLA without the option: its defaults
        return None
    return dict(SINGLE_FIT_COMPILER_OPTIONS)


class fit_jit:
    """``jax.jit(fn)`` for a single fit's programs: called from Python (not under a JAX
    transformation) it compiles with :data:`SINGLE_FIT_COMPILER_OPTIONS` on the CPU
    (:func:`_compiler_options`), and its attributes (``lower``, ``_cache_size`` …) are that
    function's; traced inside another function, where JAX takes compiler options only from the
    outermost ``jit``, it is the plain ``jax.jit(fn)``."""

    def __init__(self, fn: Callable):
        self.jitted = jax.jit(fn)
        options = _compiler_options(jax.default_backend())
        self.top = self.jitted if options is None else jax.jit(fn, compiler_options=options)

    def __call__(self, *args, **kwargs):
        traced = any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves((args, kwargs)))
        return (self.jitted if traced else self.top)(*args, **kwargs)

    def __getattr__(self, name):
        try:
            top = object.__getattribute__(self, "top")
        except AttributeError:  # not built yet (copy, pickle)
            raise AttributeError(name) from None
        return getattr(top, name)


#: Fits per vmapped block inside a batched solve (``jax.lax.map`` over blocks). 1: on a single
#: device each fit is solved by the single fit's own program, one fit after the other, so no
#: LAPACK call in it carries a batch axis. A least-squares step holds two LAPACK calls that do not
#: depend on each other (the QR of the damped Gauss–Newton system, the eigenvalues of
#: :func:`near_minimum`'s stopping test), which XLA runs at the same time; vmapped, each becomes
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


#: The give-up rule ``(steps, cost)`` that never fires: a plain fit's (Python scalars: one
#: compiled program serves every rule).
NEVER = (2 ** 31 - 1, math.inf)


class _with_give_up:
    """``jitted(start, args, optics, give_up)`` callable as ``(start, args, optics)`` too (the
    rule :data:`NEVER`); the jitted function's own attributes (``lower``, ``_cache_size`` …)
    are its."""

    def __init__(self, jitted):
        self.jitted = jitted

    def __call__(self, start, args, optics, give_up=NEVER):
        return self.jitted(start, args, optics, give_up)

    def __getattr__(self, name):
        return getattr(self.__dict__["jitted"], name)


def _host_fit(objective: Objective, o: SolverOptions, batched: bool):
    """:func:`compiled_fit` for the host method ``"trf"``: :func:`scipy.optimize.least_squares`
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


#: How a fit was finished after its solver ended on a bound that is not optimal
#: (:func:`settle_on_bounds`): not at all, by the same solver restarted from there, by L-BFGS-B.
NOT_FINISHED, RESTARTED, BY_LBFGSB = 0, 1, 2


def settle_on_bounds(objective: Objective, o: SolverOptions, out: FitOutput, args, *,
                     restart: bool = True) -> tuple[FitOutput, np.ndarray, np.ndarray]:
    r"""Fits of an unconstrained method that ended with parameters on a bound, checked for
    optimality there (Karush–Kuhn–Tucker): the gradient of :math:`\tfrac12\|r\|^2` presses
    each such parameter against its bound, and — unless the solver met its own step test with
    them held (:func:`hold_on_bounds`) — the Gauss–Newton step of the other parameters is below
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

    ``out``: NumPy :class:`FitOutput` with a leading axis of fits; ``args``: the fits' data
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


#: Multi-start: costs within this relative difference of the lowest are the same minimum.
TIE_RTOL = 1e-9

#: Above this many starts a multi-start shows a progress bar by default.
STARTS_PER_CALL = 16

#: The multi-start give-up rule (:func:`give_up_rule`): a start is given up once it has taken
#: ``max(GIVE_UP_MIN_STEPS, GIVE_UP_STEPS × n)`` steps, n the steps of the best start converged
#: before it, while its cost is still above ``GIVE_UP_COST`` × that start's cost.
GIVE_UP_MIN_STEPS, GIVE_UP_STEPS, GIVE_UP_COST = 32, 3, 10.0


def give_up_rule(best_cost: float, best_steps: int) -> tuple:
    """``(steps, cost)`` of :meth:`LevenbergMarquardt.terminate` for a start solved after a
    converged start of cost :math:`\tfrac12\|r\|^2` = ``best_cost`` found in ``best_steps``
    steps (:data:`GIVE_UP_MIN_STEPS`, :data:`GIVE_UP_STEPS`, :data:`GIVE_UP_COST`); :data:`NEVER`
    while no start has converged.

    A start still a factor 10 above the best cost after three times the steps that start needed
    is descending into another, worse minimum or wandering (on benchmark E1, 10 of 16 starts
    ran 60–256 steps to costs 1e5–1e7 times the best, or to ``max_steps``): it cannot become the
    chosen start, so solving it further is wasted time. It is counted as not converged
    (:data:`fitting._status.ABANDONED`)."""
    if not np.isfinite(best_cost):
        return NEVER
    return max(GIVE_UP_MIN_STEPS, GIVE_UP_STEPS * int(best_steps)), GIVE_UP_COST * float(best_cost)


def _cost(out: FitOutput) -> np.ndarray:
    """:math:`\tfrac12\|r\|^2` (data and penalty residuals) of NumPy fit output(s)."""
    lead = np.shape(out.status)
    data = sum(np.sum(np.asarray(r, float).reshape(lead + (-1,)) ** 2, axis=-1) for r in out.residuals)
    return 0.5 * (data + np.sum(np.asarray(out.penalty, float).reshape(lead + (-1,)) ** 2, axis=-1))


def _multistart(objective: Objective, o: SolverOptions, y0, args, progress) -> FitOutput:
    """All starts ``y0`` ``(S, P)`` (solver coordinates) on the same ``args``, solved one after
    the other by the fit's own compiled solver (:func:`compiled_fit`, not a batched copy: no
    further compilation), each start after the first under the give-up rule of the best start
    converged so far (:func:`give_up_rule`; Levenberg–Marquardt). On a CPU that is also the
    fastest order: a vmapped block of starts costs per start about twice a single solve's step
    and runs until its slowest start ends (benchmark E1). ``progress`` as
    :func:`layerstack_jax.progress_reporter` (by default a bar above :data:`STARTS_PER_CALL`
    starts). NumPy output, one row per start."""
    n = y0.shape[0]
    fn = compiled_fit(objective, o, batched=False)
    update = progress_reporter(progress, n, desc="multi-start", unit="start", auto=n > STARTS_PER_CALL)
    outs = []
    best_cost, best_steps = math.inf, 0
    for i in range(n):
        out = jax.tree.map(np.asarray, fn(y0[i], args, objective.optics, give_up_rule(best_cost, best_steps)))
        cost = float(_cost(out))
        if int(out.status) == CONVERGED and cost < best_cost:
            best_cost, best_steps = cost, int(out.num_steps)
        outs.append(out)
        if update is not None:
            update(i + 1)
    return jax.tree.map(lambda *a: np.stack(a), *outs)


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
            result's ``note`` says which, :func:`settle_on_bounds`).
        data: optional replacement spectra (one ``(samples, wl)`` array per dataset): fits
            other data with the same compiled solver.
        x0: optional physical starting vector ``(P,)`` (default: from the parameters / stack).
        starts: multi-start: number of starting points (the first is ``x0``, the others drawn by
            :func:`multistart_points`), solved one after the other by the fit's own compiled
            solver (nothing more is compiled); with Levenberg–Marquardt a start still 10× above the
            best cost after 3× that start's steps is given up (:func:`give_up_rule`, counted
            in ``starts_abandoned``). The converged one with the lowest χ² wins (the first
            of those equal to round-off: ``x0``'s when it found that minimum).
        max_steps, rtol, atol, gtol, sigma_tol: stopping rules (:class:`SolverOptions`): the
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
