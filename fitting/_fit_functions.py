"""The pure functions of an objective that a compiled fit is built from: the full residual
vector with its parts (:func:`_residuals_and_parts`), the residuals with their forward-mode
Jacobian and the statistics' by-products for optimistix (:func:`jacobian_with_statistics`,
:func:`dense_jacobian`), the statistics at a point (:func:`_statistics_function`), the choice of
the Jacobian's block structure (:func:`structure_for`) and the hold of components on a bound
(:func:`hold_on_bounds`)."""

from __future__ import annotations

from typing import Callable, Optional

import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero

from layerstack_jax import LayerstackError

from ._objective import Objective
from ._statistics import bound_contacts
from ._structured import (
    STRUCTURE_MODES,
    Structure,
    find_structure,
    residuals_with_jacobian,
    structured_jacobian_with_statistics,
    structured_statistics_function,
    verify_structure,
    with_args_tangent,
)

__all__ = ["HOLD_RTOL", "hold_on_bounds", "jacobian_with_statistics", "dense_jacobian", "structure_for"]


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
    is optimal is checked afterwards (:func:`fitting._bound_settling.settle_on_bounds`)."""
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


def structure_for(objective, mode: str, method: str) -> Optional[Structure]:
    """The :class:`fitting._structured.Structure` a fit of ``objective`` uses under ``mode``
    (:data:`fitting._structured.STRUCTURE_MODES`), found and verified once and cached on the objective; None for
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
