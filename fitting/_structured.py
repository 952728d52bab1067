r"""Structured least squares: Jacobians that are block-diagonal in wavelength plus a few
global columns, and the solves and covariances that exploit them.

A spectral parameter free at every wavelength (α(λ), ρg(λ), n(λ), k(λ) with ``basis="free"``:
an identity basis) has one component per model wavelength, and the model at wavelength
:math:`\lambda_i` depends on component :math:`i` alone. The Jacobian of the residual vector of
such a fit is then

.. math::

    J = \begin{pmatrix} J^s_1 & & & J^g_1\\ & \ddots & & \vdots\\ & & J^s_W & J^g_W\\
        & & & J^g_0 \end{pmatrix}

— per wavelength :math:`w` the ``k`` residual rows at :math:`w` (every dataset and sample), a
``(k, b)`` block :math:`J^s_w` over the ``b`` spectral values at :math:`w` (one per free
spectral parameter and, for a per-sample one, per sample), and ``g`` global columns (thicknesses,
dispersion coefficients, basis coefficients, instrument offsets) shared by all rows; rows that
depend on the globals alone (:math:`J^g_0`: smoothness penalties of basis parameters) close it.
A fit of two sheets for one n and α(λ) at 652 wavelengths has ``b = 1``, ``g = 1``: 653 columns
of which 651 are one diagonal.

**Compressed forward mode.** Wavelength :math:`w`'s rows depend only on the spectral values at
:math:`w`, so one tangent that moves *all* wavelengths of a spectral block at once gives in row
:math:`r` exactly :math:`\partial r / \partial v_{w(r)}` (Curtis, Powell & Reid 1974: columns
that share no row are computed together). The Jacobian is formed with ``g + b`` tangents — one
per global, one per spectral block — instead of one per component: :class:`CompressedJacobian`
``K`` ``(M, g + b)``. :func:`find_structure` finds the structure from the parameters and the
datasets' shapes and :func:`verify_structure` checks it numerically once per objective (a
second compressed Jacobian with random weights per wavelength must equal the first, weighted:
a model that couples wavelengths — a bandwidth, a colour conversion — fails it and is solved
densely).

**Solves.** The Levenberg–Marquardt step solves
:math:`\min_\delta \|J\delta - r\|^2 + \lambda\|\delta\|^2` (:class:`optimistix.DampedNewtonDescent`'s
system, λ = 1/step size) by block QR (the sparse QR of bundle adjustment; Triggs et al. 2000,
§6): per wavelength the QR of
:math:`\begin{pmatrix} J^s_w & J^g_w & r_w\\ \sqrt\lambda I & 0 & 0\end{pmatrix}` leaves
:math:`(R_w, G_w, t_w)` and a trailing block :math:`(H_w, h_w)` that involves the globals only;
the QR of all trailing blocks, the global-only rows and :math:`\sqrt\lambda I_g` gives
:math:`(R_g, t_g)`; then :math:`R_g\delta_g = t_g`, :math:`R_w\delta_w = t_w - G_w\delta_g`.
That is the Schur complement over the globals, formed orthogonally (the condition number is
not squared as in the normal equations). Cost per step: ``W`` QRs of ``(k + b) × (b + g + 1)``
and one of ``≈ W min(k, g+1) × (g + 1)`` — linear in the number of wavelengths.

**Covariance.** With the same factorisation of the column-normalised Jacobian
(:func:`fitting._statistics.structured_covariance`), :math:`R = \begin{pmatrix} R_s & G\\ 0 & R_g\end{pmatrix}`
(:math:`R_s` block-diagonal) and :math:`C = (J^\top J)^{-1} = R^{-1}R^{-\top}`:
:math:`C_{gg} = R_g^{-1}R_g^{-\top}`, :math:`C_{sg} = -W R_g^{-\top}`,
:math:`C_{ss} = \operatorname{blockdiag}(R_w^{-1}R_w^{-\top}) + W W^\top` with
:math:`W_w = R_w^{-1}G_w R_g^{-1}` — no dense ``P × P`` inverse. The rank test reads the
singular values of the block pivots :math:`R_w` and :math:`R_g`; a fit that fails it (a
direction the data do not determine) gets the dense SVD analysis of
:mod:`fitting._statistics` from the decompressed Jacobian, which names that direction.
"""

from __future__ import annotations

from typing import Callable, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.custom_derivatives import SymbolicZero

from layerstack_jax import traced_checks_off

__all__ = ["Structure", "CompressedJacobian", "find_structure", "verify_structure", "STRUCTURE_MODES",
           "StructuredDampedNewtonDescent", "structured_jacobian_with_statistics", "structured_statistics_function",
           "damped_block_solve", "dense_of", "compressed_jacobian_function", "sparse_jacobian_function",
           "with_args_tangent", "residuals_with_jacobian"]

#: ``structure=`` of :func:`~fitting.fit`: choose, always the dense Jacobian, or insist on the structured one.
STRUCTURE_MODES = ("auto", "dense", "structured")


class Structure:
    """The block structure of an objective's residual Jacobian (module docstring). Compared and
    hashed by identity: one per objective, kept in its compiled cache, so it can sit in the
    static part of pytrees and solvers.

    ``P`` free components, ``M`` residual rows, ``W`` wavelengths; ``global_index`` ``(g,)``:
    the free components that are globals; ``spectral_index`` ``(W, b)``: the free component of
    spectral block ``t`` at wavelength ``w`` (``P`` where that value is fixed: absent);
    ``block_rows`` ``(W, k)``: the residual rows at each wavelength; ``global_rows``: rows that
    depend on the globals alone; ``row_spectral`` ``(M, b)``: per row, the free components of its
    wavelength (``P`` for global rows); ``seeds`` ``(g + b, P)``: the compressed tangents."""

    def __init__(self, P: int, M: int, global_index, spectral_index, block_rows, global_rows, names):
        self.P, self.M = int(P), int(M)
        self.global_index = np.asarray(global_index, int)
        self.spectral_index = np.asarray(spectral_index, int)
        self.block_rows = np.asarray(block_rows, int)
        self.global_rows = np.asarray(global_rows, int)
        self.g = int(self.global_index.size)
        self.W, self.b = self.spectral_index.shape
        self.k = int(self.block_rows.shape[1])
        self.present = self.spectral_index < self.P
        row_wl = np.full(self.M, -1)
        row_wl[self.block_rows.ravel()] = np.repeat(np.arange(self.W), self.k)
        self.row_spectral = np.where(row_wl[:, None] >= 0, self.spectral_index[np.maximum(row_wl, 0)], self.P)
        seeds = np.zeros((self.g + self.b, self.P))
        seeds[np.arange(self.g), self.global_index] = 1.0
        for t in range(self.b):
            idx = self.spectral_index[:, t]
            seeds[self.g + t, idx[idx < self.P]] = 1.0
        self.seeds = seeds
        self.names = tuple(names)  # the spectral blocks, for messages

    @property
    def tangents(self) -> int:
        return self.g + self.b

    def __repr__(self) -> str:
        return (f"Structure(P={self.P}, M={self.M}, wavelengths={self.W}, spectral blocks={self.b} "
                f"({', '.join(self.names)}), globals={self.g}, rows per wavelength={self.k})")


@jax.tree_util.register_pytree_node_class
class CompressedJacobian:
    """The Jacobian of a fit's residual vector in compressed form: ``K`` ``(..., M, g + b)``,
    column ``j < g`` the global ``structure.global_index[j]``, column ``g + t`` the values of
    spectral block ``t``, row ``r`` holding the derivative w.r.t. the value at its own
    wavelength (:class:`Structure`). A pytree (``K`` its leaf), so batched fits, ``vmap`` and
    ``jax.tree.map`` carry it like the dense ``(M, P)`` array it stands for
    (:meth:`dense`)."""

    def __init__(self, K, structure: Structure):
        self.K = K
        self.structure = structure

    def tree_flatten(self):
        return (self.K,), self.structure

    @classmethod
    def tree_unflatten(cls, structure, children):
        return cls(children[0], structure)

    @property
    def shape(self) -> tuple:
        """The dense shape ``(..., M, P)``."""
        return tuple(np.shape(self.K)[:-1]) + (self.structure.P,)

    def dense(self) -> np.ndarray:
        """The dense ``(..., M, P)`` Jacobian (NumPy)."""
        return dense_of(np.asarray(self.K, float), self.structure)

    def __repr__(self) -> str:
        return f"CompressedJacobian(K {np.shape(self.K)}, {self.structure!r})"


def dense_of(K, st: Structure) -> np.ndarray:
    """Decompress ``K`` ``(..., M, g + b)`` into the dense ``(..., M, P)`` Jacobian (NumPy)."""
    K = np.asarray(K, float)
    lead = K.shape[:-2]
    J = np.zeros(lead + (st.M, st.P + 1))
    J[..., st.global_index] = K[..., :st.g]
    rows = np.broadcast_to(np.arange(st.M)[:, None], st.row_spectral.shape)
    J[..., rows, st.row_spectral] = K[..., st.g:]
    return J[..., :st.P]


def apply_compressed(K, st: Structure, dz):
    r""":math:`J\,\delta z` from the compressed ``K`` ``(M, g + b)`` and ``dz`` ``(P,)`` (JAX;
    linear in ``dz``, so JAX transposes it for :math:`J^\top r`)."""
    ext = jnp.concatenate([dz, jnp.zeros((1,), dz.dtype)])
    out = K[:, st.g:] * ext[st.row_spectral]
    out = jnp.sum(out, axis=-1)
    if st.g:
        out = out + K[:, :st.g] @ dz[st.global_index]
    return out


# --------------------------------------------------------------------------- finding the structure
def _identity_basis(p) -> bool:
    B = p.basis
    return B is not None and B.shape[0] == B.shape[1] and np.array_equal(B, np.eye(B.shape[0]))


def find_structure(objective) -> tuple[Optional[Structure], str]:
    """``(structure, "")`` of ``objective`` from its parameters and datasets, or ``(None,
    reason)`` when its Jacobian has no block structure to exploit (no free spectral parameter;
    a CIELAB dataset, which mixes wavelengths; a smoothness penalty on a free spectrum).
    Not yet checked numerically (:func:`verify_structure`)."""
    layout = objective.layout
    W = objective.wavelength.size
    P = layout.size
    free_of = np.full(layout.full_x0.size, P)  # full coefficient index -> free index (P: fixed)
    free_of[layout.free_index] = np.arange(P)
    blocks, names = [], []
    spectral = np.zeros(P, bool)
    for i, p in enumerate(layout.params):
        if not _identity_basis(p) or p.m != W:
            continue
        if p.parameter.smoothness > 0:
            return None, f"{p.name} is free per wavelength with a smoothness penalty (it couples wavelengths)"
        off = layout.offsets[i]
        rows = p.x0.shape[0] if p.per_sample else 1
        for s in range(rows):
            idx = free_of[off + s * W + np.arange(W)]
            if np.all(idx == P):
                continue
            blocks.append(idx)
            names.append(p.name + (f"[sample {s}]" if p.per_sample else ""))
            spectral[idx[idx < P]] = True
    if not blocks:
        return None, "no parameter is free per wavelength (basis 'free')"
    for ds in objective.datasets:
        if ds.colour is not None:
            return None, f"dataset {ds.label} compares CIELAB colours, which mix all wavelengths"
    rows, offset, block_rows = 0, 0, []
    for i, ds in enumerate(objective.datasets):
        n = objective.samples_of(i)
        block_rows.append(offset + np.arange(n)[None, :] * W + np.arange(W)[:, None])  # (W, n)
        offset += n * W
    n_pen = int(jax.eval_shape(objective.penalty, jnp.asarray(layout.x0)).shape[0])
    M = offset + n_pen
    spectral_index = np.stack(blocks, axis=1)  # (W, b)
    global_index = np.nonzero(~spectral)[0]
    st = Structure(P, M, global_index, spectral_index, np.concatenate(block_rows, axis=1),
                   np.arange(offset, M), names)
    return st, ""


def _compressed_jacobian(fn, z, seeds):
    """``(K, aux)``: ``fn(z) -> (flat, aux)`` differentiated along the rows of ``seeds``
    ``(T, P)`` by forward mode (``T`` tangents): ``K`` ``(M, T)``."""
    return jax.jacfwd(lambda c: fn(z + c @ seeds), has_aux=True)(jnp.zeros(seeds.shape[0], z.dtype))


def verify_structure(objective, st: Structure, residuals_and_parts) -> tuple[bool, str]:
    """Check numerically, once, at the objective's start, that row ``r`` depends on the
    spectral values at its own wavelength only: the compressed Jacobian with seeds weighted by
    random factors ``ρ_w ∈ [1, 2]`` per wavelength must equal ``ρ_{w(r)}`` times the plain one
    (a model that couples wavelengths gives sums of other columns there), and the global-only
    rows must not depend on spectral values. ``(ok, reason)``."""
    rng = np.random.default_rng(1)
    rho = rng.uniform(1.0, 2.0, st.W)
    weighted = st.seeds.copy()
    for t in range(st.b):
        idx = st.spectral_index[:, t]
        ok = idx < st.P
        weighted[st.g + t, idx[ok]] = rho[ok]
    z0 = jnp.asarray(objective.layout.x0 / objective.layout.scale)
    args = objective.args()

    def both(z):  # one forward pass with both sets of tangents: one copy of the model to compile
        f = lambda v: residuals_and_parts(v, args, objective.optics)  # noqa: E731
        with traced_checks_off():
            return _compressed_jacobian(f, z, jnp.concatenate([jnp.asarray(st.seeds), jnp.asarray(weighted)]))[0]

    K = np.asarray(jax.jit(both)(z0))
    K1, K2 = K[:, :st.tangents], K[:, st.tangents:]
    Ks1, Ks2 = K1[:, st.g:], K2[:, st.g:]
    if not (np.all(np.isfinite(Ks1)) and np.all(np.isfinite(Ks2))):
        return False, "the Jacobian at the start is not finite"
    row_wl = np.full(st.M, -1)
    row_wl[st.block_rows.ravel()] = np.repeat(np.arange(st.W), st.k)
    factor = np.where(row_wl >= 0, rho[np.maximum(row_wl, 0)], 0.0)[:, None]
    expected = factor * Ks1
    scale = np.max(np.abs(Ks1), axis=0, keepdims=True) + 1e-300
    bad = np.abs(Ks2 - expected) > 1e-9 * (np.abs(Ks2) + np.abs(expected)) + 1e-12 * scale
    if np.any(bad):
        r, t = np.argwhere(bad)[0]
        where = f"residual row {r}" + (f" (wavelength {objective.wavelength[row_wl[r]]:g} nm)" if row_wl[r] >= 0
                                         else " (a penalty)")
        return False, (f"{where} depends on the values of {st.names[t]} at other wavelengths (the model mixes "
                       "wavelengths: a bandwidth, a colour conversion or an interpolation)")
    return True, ""


def _qr_r(a):
    return jnp.linalg.qr(a, mode="r")


def _eliminate(A, b: int):
    """Householder reflections of the first ``b`` columns of every matrix of the batch ``A``
    ``(W, rows, cols)``, vectorised over the batch (``b`` is small and static: the reflections
    are unrolled): rows ``:b`` of the result hold the ``b`` rows of ``R`` (upper triangular in
    the first ``b`` columns), rows ``b:`` zeros in those columns and the rest reflected along —
    what the remaining columns' least-squares problem needs. (XLA's batched QR of many tiny
    matrices is a loop over the batch, far slower.)"""
    for j in range(b):
        x = A[:, j:, j]  # (W, rows - j)
        norm = jnp.sqrt(jnp.sum(x * x, axis=-1))
        sign = jnp.where(x[:, 0] < 0, -1.0, 1.0)
        alpha = -sign * norm
        v = x.at[:, 0].add(-alpha)
        vn = jnp.sqrt(jnp.sum(v * v, axis=-1))
        v = v / jnp.where(vn > 0, vn, 1.0)[:, None]  # a zero column: no reflection
        tail = A[:, j:, :]
        tail = tail - 2.0 * v[:, :, None] * jnp.einsum("wr,wrc->wc", v, tail)[:, None, :]
        A = A.at[:, j:, :].set(tail)
    return A


def damped_block_solve(K, r, lam, st: Structure):
    r"""``(δ, ‖t‖²)``: the solution of :math:`\min_\delta \|J\delta - r\|^2 + \lambda\|\delta\|^2`
    (``δ`` ``(P,)``) for the Jacobian in compressed form ``K`` ``(M, g + b)`` by the block QR of
    the module docstring, and :math:`\|t\|^2 = r^\top J (J^\top J + \lambda I)^{-1} J^\top r`
    (the squared length of the projection of ``r`` on the damped column space)."""
    g, b, W = st.g, st.b, st.W
    dtype = K.dtype
    Kb = K[st.block_rows]  # (W, k, g + b)
    rb = r[st.block_rows]  # (W, k)
    present = jnp.asarray(st.present)
    root = jnp.sqrt(lam)
    damp = jnp.where(present, root, jnp.ones((), dtype))  # absent values: unit rows, decoupled
    top = jnp.concatenate([Kb[..., g:], Kb[..., :g], rb[..., None]], axis=-1)
    eye = jnp.eye(b, dtype=dtype)
    bottom = jnp.concatenate([eye * damp[:, None, :], jnp.zeros((W, b, g + 1), dtype)], axis=-1)
    R = _eliminate(jnp.concatenate([bottom, top], axis=-2), b)  # (W, b + k, b + g + 1)
    Rs, G, t = R[:, :b, :b], R[:, :b, b:b + g], R[:, :b, -1]
    t = jnp.where(present, t, 0.0)
    norm2 = jnp.sum(t * t)
    if g:
        H = R[:, b:, b:].reshape(-1, g + 1)
        Kg0 = K[st.global_rows][:, :g]
        r0 = r[st.global_rows]
        glob = jnp.concatenate([H, jnp.concatenate([Kg0, r0[:, None]], axis=-1),
                                jnp.concatenate([root * jnp.eye(g, dtype=dtype), jnp.zeros((g, 1), dtype)], axis=-1)])
        Rg = _qr_r(glob)[:g + 1]
        tg = Rg[:g, g]
        norm2 = norm2 + jnp.sum(tg * tg)
        dg = jax.scipy.linalg.solve_triangular(Rg[:g, :g], tg, lower=False)
        rhs = t - jnp.einsum("wij,j->wi", G, dg)
    else:
        dg = jnp.zeros((0,), dtype)
        rhs = t
    ds = _back_substitute(Rs, rhs)
    delta = jnp.zeros((st.P + 1,), dtype)
    delta = delta.at[jnp.asarray(st.spectral_index).ravel()].set(jnp.where(present, ds, 0.0).ravel())
    if g:
        delta = delta.at[jnp.asarray(st.global_index)].set(dg)
    return delta[:st.P], norm2


def _back_substitute(R, v):
    """Solve the upper-triangular ``(W, b, b)`` systems ``R x = v`` (``v`` ``(W, b)``),
    vectorised over the batch, the ``b`` rows unrolled."""
    b = R.shape[-1]
    xs = [None] * b
    for i in range(b - 1, -1, -1):
        acc = v[:, i]
        for j in range(i + 1, b):
            acc = acc - R[:, i, j] * xs[j]
        xs[i] = acc / R[:, i, i]
    return jnp.stack(xs, axis=-1)


class _BlockDescentState(eqx.Module):
    K: jax.Array
    residual: jax.Array


class StructuredDampedNewtonDescent(optx.AbstractDescent):
    """:class:`optimistix.DampedNewtonDescent`'s step — the solution of
    :math:`\\min \\|J\\delta - r\\|^2 + \\lambda\\|\\delta\\|^2`, λ = 1/step size, moving by
    :math:`-\\delta` — solved by block QR (:func:`damped_block_solve`) for a Jacobian of
    :class:`Structure` ``structure``.

    ``query`` (once per accepted point) reads the Jacobian in compressed form from optimistix's
    linearisation itself — ``f_info.jac.mv`` of the ``g + b`` compressed seeds, each a cheap
    product (the residual function's JVP rule applies the compressed Jacobian,
    :func:`structured_jacobian_with_statistics`) — so the descent needs nothing but the public
    :class:`optimistix.AbstractDescent` interface, and composes with any search."""

    structure: Structure = eqx.field(static=True)

    def init(self, y, f_info_struct):
        st = self.structure
        return _BlockDescentState(jnp.zeros((st.M, st.tangents), y.dtype), jnp.zeros((st.M,), y.dtype))

    def query(self, y, f_info, state):
        seeds = jnp.asarray(self.structure.seeds, y.dtype)
        K = jax.vmap(f_info.jac.mv)(seeds).T  # (M, g + b): J_u along the compressed seeds
        return _BlockDescentState(K, f_info.residual)

    def step(self, step_size, state):
        eps = jnp.finfo(step_size.dtype).eps
        pred = step_size > eps
        lam = jnp.where(pred, 1 / jnp.where(pred, step_size, 1), jnp.finfo(step_size.dtype).max)
        delta, _ = damped_block_solve(state.K, state.residual, lam, self.structure)
        return -delta, optx.RESULTS.successful


def block_distance(descent_state, structure: Structure):
    r"""``d²`` of :func:`fitting._least_squares.gauss_newton_distance` from a
    :class:`StructuredDampedNewtonDescent` state: :math:`g^\top (J^\top J)^{+} g = \|P_J r\|^2`
    by the block QR, with directions of eigenvalue below 1e-12 of the largest column norm²
    damped away (as the dense rule leaves them out)."""
    K, r = descent_state.K, descent_state.residual
    st = structure
    col2 = jnp.concatenate([jnp.sum(K[:, :st.g] ** 2, axis=0),
                            jnp.sum(K[st.block_rows][..., st.g:] ** 2, axis=1).ravel()])
    lam = 1e-12 * jnp.maximum(jnp.max(col2), jnp.finfo(K.dtype).tiny)
    return damped_block_solve(K, r, lam, st)[1]


# --------------------------------------------------------------------------- residual functions
def with_args_tangent(out, of_args: Callable, args, dargs):
    """``out`` plus the exact JVP of ``of_args`` at ``args`` along ``dargs`` (symbolic zeros
    among them made concrete), or ``out`` itself when every tangent of ``args`` is a symbolic
    zero (always, in the solvers): the ``args`` part of the custom JVPs of
    :func:`fitting._fit_functions.jacobian_with_statistics`, :func:`fitting._fit_functions.dense_jacobian` and
    :func:`structured_jacobian_with_statistics`."""
    is_zero = lambda t: isinstance(t, SymbolicZero)  # noqa: E731
    if all(is_zero(t) for t in jax.tree.leaves(dargs, is_leaf=is_zero)):
        return out
    dargs = jax.tree.map(lambda t, a: jnp.zeros_like(a) if is_zero(t) else t, dargs, args, is_leaf=is_zero)
    return out + jax.jvp(of_args, (args,), (dargs,))[1]


def residuals_with_jacobian(residuals_and_parts, z_of, traced_once, jacobian: Callable, apply: Callable):
    r"""``fn(u, (args, optics)) -> (r, ((model, residuals, penalty), J))``: the residuals at
    ``z = z_of(u)`` with the Jacobian ``J`` formed once per evaluation by ``jacobian(f, z) ->
    (J, aux)`` (``f`` returns its value and by-products as aux: one pass), and a JVP rule that
    applies it, ``apply(J, dz)``, instead of differentiating the model again. Linearising ``fn``
    (``jax.linearize``, the solvers) thus costs one Jacobian; tangents of ``args`` (never used by
    the solvers) are propagated exactly by :func:`with_args_tangent`. The dense form
    (:func:`fitting._fit_functions.jacobian_with_statistics`: ``jax.jacfwd``, ``J @ dz``) and the
    compressed one (:func:`structured_jacobian_with_statistics`) differ only in the two callables."""

    def evaluate(u, args_optics):
        def value_twice(z):
            flat, by = residuals_and_parts(z, *args_optics)
            return flat, (flat, by)

        J, (r, by) = jacobian(value_twice, z_of(u))
        return r, (by, J)

    # jitted: optimistix traces the primal for its shapes and the JVP rule below for the solve;
    # the second trace is then a cache hit (inlined by XLA: nothing changes at run time)
    evaluate = traced_once(jax.jit(evaluate))

    @jax.custom_jvp
    def g(u, args_optics):
        return evaluate(u, args_optics)

    def g_jvp(primals, tangents):
        u, args_optics = primals
        du, dargs = tangents
        r, aux = evaluate(u, args_optics)
        out = jnp.zeros_like(r) if isinstance(du, SymbolicZero) else apply(aux[1], jax.jvp(z_of, (u,), (du,))[1])
        out = with_args_tangent(out, lambda a: residuals_and_parts(z_of(u), *a)[0], args_optics, dargs)
        return (r, aux), (out, jax.tree.map(jnp.zeros_like, aux))

    g.defjvp(g_jvp, symbolic_zeros=True)
    return g


def structured_jacobian_with_statistics(objective, st: Structure, residuals_and_parts, z_of, traced_once):
    r""":func:`fitting._fit_functions.jacobian_with_statistics` with the Jacobian formed in compressed
    form (``g + b`` tangents, :func:`_compressed_jacobian`) and applied by
    :func:`apply_compressed` in the JVP rule: ``fn(u, (args, optics)) -> (r, ((model,
    residuals, penalty), CompressedJacobian))``."""
    seeds = jnp.asarray(st.seeds)

    def jacobian(f, z):
        K, aux = _compressed_jacobian(f, z, seeds.astype(z.dtype))
        return CompressedJacobian(K, st), aux

    return residuals_with_jacobian(residuals_and_parts, z_of, traced_once, jacobian,
                                   lambda J, dz: apply_compressed(J.K, st, dz))


def structured_statistics_function(objective, st: Structure, residuals_and_parts):
    """:func:`fitting._fit_functions._statistics_function` with the Jacobian in compressed form:
    ``(x, args, optics) -> (model, residuals, penalty, CompressedJacobian)``."""
    scale = jnp.asarray(objective.layout.scale)
    seeds = jnp.asarray(st.seeds)

    def stats(x, args, optics):
        K, (model, res, pen) = _compressed_jacobian(lambda z: residuals_and_parts(z, args, optics),
                                                    x / scale, seeds.astype(x.dtype))
        return model, res, pen, CompressedJacobian(K, st)

    return stats


def compressed_jacobian_function(residuals, st: Structure):
    """``(z, args, optics) -> K`` ``(M, g + b)``: the compressed Jacobian of the pure
    ``residuals(z, args, optics)`` (``g + b`` forward-mode tangents)."""
    seeds = jnp.asarray(st.seeds)

    def K(z, args, optics):
        return _compressed_jacobian(lambda v: (residuals(v, args, optics), None), z, seeds.astype(z.dtype))[0]

    return K


def sparse_jacobian_function(compressed, st: Structure):
    """``(z, args, optics) -> scipy.sparse.csr_matrix`` ``(M, P)`` from a compressed-Jacobian
    function (:func:`compressed_jacobian_function`): the host solver's (scipy TRF) Jacobian."""
    from scipy.sparse import csr_matrix

    rows = np.broadcast_to(np.arange(st.M)[:, None], (st.M, st.tangents))
    cols = np.concatenate([np.broadcast_to(st.global_index, (st.M, st.g)), st.row_spectral], axis=1)
    keep = cols < st.P
    rows, cols = rows[keep], cols[keep]

    def jac(z, args, optics):
        K = np.asarray(compressed(z, args, optics), dtype=float)
        return csr_matrix((K[keep], (rows, cols)), shape=(st.M, st.P))

    return jac


# --------------------------------------------------------------------------- covariance
