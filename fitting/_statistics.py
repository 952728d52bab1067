r"""Statistics of a least-squares fit, computed once for :func:`~fitting.fit`,
:func:`~fitting.fit_batch` and :func:`~fitting.calibration_series` fits: χ², degrees of freedom,
linearised covariance, standard errors, correlations, identifiability, parameters on a bound,
and a plain verdict on the fit quality.

Every function takes arrays with optional leading batch axes (one per fit), so one batch of N
fits and N single fits give the same numbers.

Covariance (linearised least squares, e.g. Press et al., *Numerical Recipes* §15.4–15.6): with
:math:`J` the Jacobian of the weighted residuals :math:`r_i = (f_i - y_i)/\sigma_i` at the
solution, :math:`C = s^2 (J^\top J)^{+}`; :math:`s^2 = 1` when every dataset gives σ ("given"),
:math:`s^2 = \chi^2/\nu` (ν = N − P) when the σ of the data are estimated from the residuals.

Identifiability: the SVD of :math:`J` taken with respect to :math:`\ln x` (relative changes;
:math:`x/s` for a parameter at 0), columns normalised to unit length. A singular value below
``rank_rtol`` × the largest marks a direction along which the data do not change; the
components on it are *unresolved*: their standard errors are NaN (not arbitrary huge numbers)
and the pseudo-inverse is taken on the resolved subspace. Along such a direction ``v`` the
correlation of two components tends to :math:`\operatorname{sign}(v_i v_j) = \pm 1` as its
singular value tends to 0; that limit is what :attr:`FitStatistics.correlation` holds for them.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._structured import CompressedJacobian, dense_of

__all__ = [
    "FitStatistics",
    "fit_statistics",
    "linearised_covariance",
    "unresolved_components",
    "bound_contacts",
    "strong_correlations",
    "SIGMA_GIVEN",
    "SIGMA_ESTIMATED",
    "SIGMA_DEFAULT",
    "CORRELATION_LIMIT",
    "correlated_groups",
    "trade_off_direction",
    "describe_trade_off",
    "separability_findings",
    "batch_separability",
    "separability_summary",
]

#: σ origins, as reports write them.
SIGMA_GIVEN = "given"
SIGMA_ESTIMATED = "estimated from residuals"
SIGMA_DEFAULT = "default 1 — χ² not meaningful"
#: |correlation| above which two parameters are reported as not separated by the data.
CORRELATION_LIMIT = 0.99
#: components of a null vector (unit length) larger than this take part in it.
_NULL_COMPONENT = 0.05


class FitStatistics(NamedTuple):
    """Statistics of one fit or a batch of fits (leading axes ``...``; P parameters).

    ``chi2`` (data residuals only, not penalties), ``dof`` = n_points − P, ``reduced_chi2``
    (NaN when dof ≤ 0); ``covariance`` ``(..., P, P)`` in the parameters' units, already scaled
    by ``s²`` (``s2``: 1 for given σ, else χ²/dof); ``stderr`` ``(..., P)`` (NaN where
    ``unresolved``); ``correlation`` ``(..., P, P)`` (±1 limits for unresolved pairs on one null
    direction, NaN where undefined); ``singular_values`` ``(..., P)`` of the normalised Jacobian
    (descending), ``rank``; ``null_vectors`` rows of :math:`V^\\top` (normalised coordinates),
    ``log_directions`` the same as :math:`\\delta\\ln x` scaled to max 1; ``zero_columns``:
    components the data do not depend on; ``sigma_origin``: one of :data:`SIGMA_GIVEN`,
    :data:`SIGMA_ESTIMATED`, :data:`SIGMA_DEFAULT` (the σ behind ``stderr``), ``chi2_meaningful``.
    """

    chi2: np.ndarray
    n_points: int
    dof: int
    reduced_chi2: np.ndarray
    s2: np.ndarray
    covariance: np.ndarray
    stderr: np.ndarray
    correlation: np.ndarray
    singular_values: np.ndarray
    rank: np.ndarray
    null_vectors: np.ndarray
    log_directions: np.ndarray
    unresolved: np.ndarray
    zero_columns: np.ndarray
    sigma_origin: str
    chi2_meaningful: bool


def linearised_covariance(J, x, scale, rank_rtol: float):
    """Covariance of ``x`` for unit residual variance, from ``J = ∂r/∂(x/scale)``
    ``(..., M, P)``, and the SVD of the normalised Jacobian.

    Returns ``(cov, singular_values, rank, null_vectors, log_directions)``; ``null_vectors``
    ``(..., P, P)`` are the rows of :math:`V^\\top` in normalised coordinates (those beyond
    ``rank`` span the null space), ``log_directions`` the same as :math:`\\delta\\ln x`
    (:math:`\\delta x/s` for x = 0), each scaled to max 1. A fit with a non-finite Jacobian has
    NaN covariance and singular values and makes no rank claim (rank P).
    """
    J = np.asarray(J, float)
    x = np.asarray(x, float)
    scale = np.asarray(scale, float)
    rel = np.where(x != 0, np.abs(x) / scale, 1.0)  # d/d ln x = (|x|/s) d/d(x/s)
    Jr = J * rel[..., None, :]
    norms = np.linalg.norm(Jr, axis=-2)
    safe = np.where(norms > 0, norms, 1.0)
    Jn = Jr / safe[..., None, :]
    bad = ~np.all(np.isfinite(Jn), axis=(-2, -1))
    Jn = np.where(bad[..., None, None], 0.0, Jn)
    _, sv, Vt = np.linalg.svd(Jn, full_matrices=False)
    top = sv[..., :1]
    keep = (sv > rank_rtol * top) & (top > 0)
    rank = np.where(bad, J.shape[-1], keep.sum(axis=-1))
    sv = np.where(bad[..., None], np.nan, sv)
    inv = np.where(keep, 1.0 / np.where(keep, sv, 1.0) ** 2, 0.0)
    cov_n = np.einsum("...ki,...k,...kj->...ij", Vt, inv, Vt)
    a = rel / safe  # J = Jn diag(1/a)
    cov = cov_n * (a * scale)[..., :, None] * (a * scale)[..., None, :]
    cov = np.where(bad[..., None, None], np.nan, cov)
    dirs = Vt / safe[..., None, :]
    dirs = dirs / np.maximum(np.max(np.abs(dirs), axis=-1, keepdims=True), 1e-300)
    return cov, sv, rank, Vt, dirs


def unresolved_components(null_vectors, log_directions, rank, zero_columns, owner):
    """``(..., P)`` True for the components the data do not determine: columns of zero
    Jacobian, and components taking part in a null direction (rows ``>= rank`` of
    ``null_vectors``). A parameter (components sharing ``owner``) whose every free component
    moves along a null direction by the same relative amount as its strong ones is unresolved
    as a whole (α(λ) of a layer whose α·h alone is determined, also where it barely absorbs)."""
    Vt = np.asarray(null_vectors)
    P = Vt.shape[-1]
    owner = np.asarray(owner)
    # only the rows that are null in some fit (none at full rank)
    first_null = int(np.min(rank)) if np.size(rank) else P
    if first_null >= P:
        return np.asarray(zero_columns, bool).copy()
    Vt = Vt[..., first_null:, :]
    log_directions = np.asarray(log_directions)[..., first_null:, :]
    rows = np.arange(first_null, P)
    null = rows >= np.asarray(rank)[..., None]  # (..., rows) rows that are null
    comp = (np.abs(Vt) > _NULL_COMPONENT) & ~zero_columns[..., None, :] & null[..., :, None]  # (..., row, P)
    out = np.asarray(zero_columns, bool) | comp.any(axis=-2)
    for i in np.unique(owner):
        mine = owner == i
        in_row = comp & mine  # (..., row, P)
        has = in_row.any(axis=-1)  # (..., row)
        first = np.argmax(in_row, axis=-1)  # first strong component of parameter i per row
        w_first = np.take_along_axis(log_directions, first[..., None], axis=-1)  # (..., row, 1)
        every = mine & ~zero_columns[..., None, :]
        close = np.abs(log_directions - w_first) <= 0.02 + 0.05 * np.abs(w_first)
        whole = has & np.all(close | ~every, axis=-1)  # (..., row)
        out = out | np.any(whole[..., None] & every, axis=-2)
    return out


def fit_statistics(J, x, data_residuals, layout, n_points: int, *, sigma_given: bool, scale_covariance=None,
                   rank_rtol: float = 1e-8) -> FitStatistics:
    """All statistics of fits with Jacobians ``J`` ``(..., M, P)`` (w.r.t. ``x / layout.scale``;
    or a :class:`~fitting._structured.CompressedJacobian`, whose covariance is the structured
    inverse, :func:`structured_covariance`)
    at solutions ``x`` ``(..., P)``; ``data_residuals``: the weighted data residuals, one array
    ``(..., samples, wl)`` per dataset (0 at masked points); ``n_points`` the used data points.

    ``scale_covariance``: scale by χ²/dof (σ estimated from residuals); default: unless every
    dataset gives σ. Components with a zero Jacobian column or on a null direction (singular
    value < ``rank_rtol`` × the largest) get NaN standard errors."""
    x = np.asarray(x, float)
    lead = x.shape[:-1]
    P = x.shape[-1]
    chi2 = sum(np.sum(np.asarray(r, float) ** 2, axis=(-2, -1)) for r in data_residuals)
    chi2 = np.broadcast_to(chi2, lead).astype(float)
    dof = int(n_points) - P
    red = chi2 / dof if dof > 0 else np.full(lead, np.nan)
    scaled = (not sigma_given) if scale_covariance is None else bool(scale_covariance)
    if isinstance(J, CompressedJacobian):  # block structure: the structured inverse (fitting._structured)
        cov, sv, rank, Vt, dirs = structured_covariance(J, x, layout.scale, rank_rtol)
        zero = compressed_zero_columns(J)
    else:
        J = np.asarray(J, float)
        cov, sv, rank, Vt, dirs = linearised_covariance(J, x, layout.scale, rank_rtol)
        zero = np.linalg.norm(J, axis=-2) == 0
    unresolved = unresolved_components(Vt, dirs, rank, zero, layout.owner)
    s2 = red if scaled else np.ones(lead)
    cov = cov * np.asarray(s2)[..., None, None]
    var = np.diagonal(cov, axis1=-2, axis2=-1)
    err = np.where(unresolved, np.nan, np.sqrt(np.clip(var, 0, None)))
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.sqrt(np.clip(var, 0, None))
        corr = cov / (d[..., :, None] * d[..., None, :])
    corr = np.where(unresolved[..., :, None] | unresolved[..., None, :], np.nan, corr)
    # unresolved pairs on one null direction: the limit sign(v_i v_j) of their correlation
    # (only the rows that are null in some fit: (rows, P, P) per fit, none at full rank)
    first = int(np.min(rank)) if np.size(rank) else P
    if first < P:
        V = np.asarray(Vt)[..., first:, :]
        null = np.arange(first, P) >= np.asarray(rank)[..., None]
        strong = (np.abs(V) > _NULL_COMPONENT) & null[..., :, None] & ~zero[..., None, :]
        both = strong[..., :, :, None] & strong[..., :, None, :]  # (..., row, P, P)
        limit = np.sign(V[..., :, :, None] * V[..., :, None, :])
        on_null = both.any(axis=-3)
        lim = np.sum(np.where(both, limit, 0.0), axis=-3)
        corr = np.where(on_null, np.clip(lim, -1, 1), corr)
    eye = np.eye(P, dtype=bool)
    corr = np.where(eye & ~np.isnan(np.diagonal(cov, axis1=-2, axis2=-1))[..., None], 1.0, corr)
    origin = SIGMA_ESTIMATED if scaled else (SIGMA_GIVEN if sigma_given else SIGMA_DEFAULT)
    return FitStatistics(chi2, int(n_points), dof, red, np.asarray(s2, float), cov, err, corr, sv, rank, Vt, dirs,
                         unresolved, zero, origin, bool(sigma_given))


def bound_contacts(x, lower, upper, scale, rtol: float = 1e-6, xp=np):
    """``(at_lower, at_upper)``, each ``(..., P)`` bool: components within ``rtol`` × scale of
    a finite bound (L-BFGS-B and TRF end exactly on a bound; the transforms of the
    unconstrained solvers approach it exponentially, and their solves hold a component in
    contact on its bound, :func:`fitting._fit_functions.hold_on_bounds`). ``xp``: ``numpy`` (host) or
    ``jax.numpy`` (inside a compiled solve)."""
    x = np.asarray(x, float) if xp is np else x
    tol = rtol * np.asarray(scale, float)
    with np.errstate(invalid="ignore"):
        lo = np.isfinite(lower) & (x - lower <= tol)
        hi = np.isfinite(upper) & (upper - x <= tol)
    return lo, hi & ~lo


def strong_correlations(correlation, limit: float = CORRELATION_LIMIT) -> list:
    """``[(i, j, ρ)]`` of one fit's ``(P, P)`` correlation with ``|ρ| > limit`` (i > j), the
    strongest first."""
    c = np.asarray(correlation, float)
    i, j = np.tril_indices(c.shape[-1], -1)
    rho = c[i, j]
    pick = np.isfinite(rho) & (np.abs(rho) > limit)
    order = np.argsort(-np.abs(rho[pick]), kind="stable")
    return [(int(a), int(b), float(r)) for a, b, r in zip(i[pick][order], j[pick][order], rho[pick][order])]


def correlated_groups(correlation, limit: float = CORRELATION_LIMIT) -> list:
    """Groups of components linked by |correlation| > ``limit`` (one fit's ``(P, P)``
    correlation; the connected components of that graph with two or more members), each an
    index array, largest first. A parameter correlated beyond the limit with another is in the
    same group as it, and with everything that one is correlated with."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    c = np.asarray(correlation, float)
    P = c.shape[-1]
    with np.errstate(invalid="ignore"):
        link = np.isfinite(c) & (np.abs(c) > limit) & ~np.eye(P, dtype=bool)
    if not link.any():
        return []
    _, label = connected_components(csr_matrix(link), directed=False)
    groups = [np.flatnonzero(label == k) for k in np.unique(label)]
    groups = [g for g in groups if g.size >= 2]
    return sorted(groups, key=lambda g: (-g.size, g[0]))


def _relative_unit(x, scale) -> np.ndarray:
    """Per component, the unit of a relative change: |x|, or the scale where x = 0."""
    x = np.asarray(x, float)
    return np.where(x != 0, np.abs(x), np.asarray(scale, float))


def trade_off_direction(covariance, x, scale, members) -> tuple:
    """``(v, spread)``: the direction along which the components ``members`` are least
    determined, in relative units (:math:`\\delta x_i / |x_i|`; the top eigenvector of their
    relative covariance block, largest entry +1), and the ratio of its standard deviation to
    that of the next direction (how much that one direction dominates). None where their
    covariance is not finite."""
    u = _relative_unit(x, scale)[members]
    C = np.asarray(covariance, float)[np.ix_(members, members)] / np.outer(u, u)
    if not np.all(np.isfinite(C)):
        return None, np.nan
    w, V = np.linalg.eigh(C)
    v = V[:, -1]
    v = v / v[np.argmax(np.abs(v))]
    spread = np.sqrt(w[-1] / w[-2]) if w.size > 1 and w[-2] > 0 else np.inf
    return v, float(spread)


def _power(p: float) -> str:
    return "" if abs(p - 1) < 0.03 else f"^{p:.2g}"


def describe_trade_off(layout, x, members, v) -> dict:
    """Words for a trade-off direction ``v`` (relative units, :func:`trade_off_direction`) of
    the components ``members``: ``{"parameters", "groups", "direction", "combination"}``.

    Components of one parameter that move by the same relative amount count as that parameter
    (α(λ) scaled as a whole); the combination the data determine is the one constant along
    ``v``: for two positive quantities ``b·a^p`` with :math:`p = -w_b/w_a` (``α·h``: p = 1; a
    ratio: ``b·a^-1``), ``a`` the one that moves less along ``v`` (so :math:`|p| \\ge 1`);
    otherwise the components and their relative moves."""
    owner = np.asarray(layout.owner)
    x = np.asarray(x, float)
    groups = []  # (label, weight, components)
    for i in sorted(set(owner[members]), key=lambda k: int(np.min(np.flatnonzero(owner[members] == k)))):
        idx = members[owner[members] == i]
        w = v[np.searchsorted(members, idx)]
        name = layout.params[int(i)].name
        total = int(np.sum(owner == i))
        if np.allclose(w, w[0], rtol=0.05, atol=0.02):
            label = name if idx.size == total else layout.names[idx[0]] if idx.size == 1 else \
                f"{name} ({idx.size} of {total} components)"
            groups.append((label, float(np.mean(w)), idx))
        else:
            groups += [(layout.names[j], float(v[np.searchsorted(members, j)]), np.array([j])) for j in idx]
    shown = groups[:6]
    direction = ", ".join(f"δ{n}/{n} = {w:+.2g}" for n, w, _ in shown) + (
        f" and {len(groups) - 6} more" if len(groups) > 6 else "")
    positive = bool(np.all(x[members] > 0))
    if len(groups) == 2 and positive:
        (nb, wb, _), (na, wa, _) = sorted(groups, key=lambda grp: -abs(grp[1]))
        # constant along v: ln b + p ln a with w_b + p w_a = 0; the exponent on a, which moves less
        combination = f"{nb}·{na}{_power(-wb / wa)}" if wa != 0 else nb
        combination = f"{combination} is determined, not {groups[0][0]} and {groups[1][0]} separately"
    elif len(groups) == 1:
        combination = (f"the components of {groups[0][0]} are determined only together (moved together they "
                       "barely change the data)")
    else:
        names = ", ".join(n for n, _, _ in shown) + (f" and {len(groups) - 6} more" if len(groups) > 6 else "")
        combination = f"only combinations of {names} that stay constant along the direction below are determined"
    return {"parameters": sorted({layout.params[int(i)].name for i in owner[members]}),
            "groups": [{"name": n, "relative_move": w, "components": [layout.names[j] for j in idx]}
                       for n, w, idx in groups],
            "direction": direction, "combination": combination}


def separability_findings(layout, x, covariance, correlation, unresolved=None, null_directions=None,
                          limit: float = CORRELATION_LIMIT) -> list:
    """The parameters a fit cannot separate, grouped: one finding per group of components
    linked by |correlation| > ``limit`` (:func:`correlated_groups`), each
    ``{"kind", "parameters", "components", "max_abs_correlation", "pairs", "combination",
    "direction", "groups", "spread"}`` — ``kind`` ``"not identifiable"`` when the group holds
    components the data do not determine at all (``unresolved``, a null direction: its
    correlations are the ±1 limits), else ``"poorly separable"``; ``combination`` the quantity
    the data do determine in words (:func:`describe_trade_off`); ``pairs`` the number of pairs
    beyond the limit in the group (all of them are in ``FitResult.not_separated``);
    ``null_directions``: rows of :attr:`FitStatistics.log_directions` beyond the rank (the
    direction of a not-identifiable group is read from the one it lies on)."""
    c = np.asarray(correlation, float)
    unresolved = np.zeros(c.shape[-1], bool) if unresolved is None else np.asarray(unresolved, bool)
    out = []
    for members in correlated_groups(c, limit):
        block = c[np.ix_(members, members)]
        with np.errstate(invalid="ignore"):
            off = np.abs(block[~np.eye(members.size, dtype=bool)])
        off = off[np.isfinite(off)]
        kind = "not identifiable" if unresolved[members].any() else "poorly separable"
        v, spread = None, np.inf
        if kind == "not identifiable" and null_directions is not None and len(null_directions):
            # the null direction it lies on (the covariance, a pseudo-inverse, leaves it out)
            D = np.asarray(null_directions, float)[:, members]
            v = D[np.argmax(np.sum(np.abs(D), axis=1))]
            v = v / v[np.argmax(np.abs(v))] if np.any(v) else None
        if v is None and kind == "poorly separable":
            v, spread = trade_off_direction(covariance, x, layout.scale, members)
        if v is None:  # the sign pattern of the correlation limits with the first member
            v = np.sign(np.where(np.isfinite(block[0]), block[0], 0.0))
            v[0] = 1.0
        words = describe_trade_off(layout, x, members, v)
        out.append({"kind": kind, "parameters": words["parameters"],
                    "components": [layout.names[j] for j in members],
                    "max_abs_correlation": float(off.max()) if off.size else float("nan"),
                    "pairs": int(np.sum(off > limit) // 2), "combination": words["combination"],
                    "direction": words["direction"], "groups": words["groups"], "spread": spread})
    return out


def batch_separability(stats: FitStatistics, x, layout, limit: float = CORRELATION_LIMIT) -> list:
    """:func:`separability_findings` of every fit of a batch (``stats`` with a leading axis of
    fits, ``x`` ``(N, P)``): one list of findings per fit."""
    x = np.asarray(x, float)
    rank = np.asarray(stats.rank)
    out = []
    for k in range(x.shape[0]):
        dirs = np.asarray(stats.log_directions[k])[int(rank[k]):]
        out.append(separability_findings(layout, x[k], stats.covariance[k], stats.correlation[k],
                                         stats.unresolved[k], dirs, limit))
    return out


def separability_summary(per_fit: list, limit: float = CORRELATION_LIMIT, at_most: int = 6) -> list:
    """Summary lines of many fits' findings (:func:`batch_separability`): per kind of finding
    (the parameters involved), in how many fits, with one fit's combination as example."""
    counts: dict = {}
    for findings in per_fit:
        for f in findings or []:
            key = (f["kind"], tuple(f["parameters"]))
            n, example = counts.get(key, (0, f["combination"]))
            counts[key] = (n + 1, example)
    lines = []
    for i, ((kind, params), (n, example)) in enumerate(sorted(counts.items(), key=lambda kv: -kv[1][0])):
        if i == at_most:
            lines.append(f"  … {len(counts) - i} more kinds of inseparable parameters (see each fit's findings)")
            break
        lines.append(f"  {n} fit(s): {kind} (|ρ| > {limit:g}): {', '.join(params)} — e.g. {example}")
    return lines


def _np_qr_r(a):
    return np.linalg.qr(a, mode="r")


def structured_covariance(J: CompressedJacobian, x, scale, rank_rtol: float):
    """:func:`linearised_covariance` for a Jacobian in compressed form
    (module docstring): ``(cov, singular_values, rank, null_vectors, log_directions)`` with
    optional leading batch axes, the same normalisation (columns w.r.t. :math:`\\ln x`, unit
    length) and the same covariance.

    ``singular_values`` are those of the block pivots :math:`R_w` and :math:`R_g` of the
    normalised Jacobian (sorted; the same rank in exact arithmetic as the singular values of the
    whole, which they bound). Fits with full rank get zero ``null_vectors`` and
    ``log_directions`` (there is no null direction); fits below full rank (or with a
    non-finite Jacobian) get the dense analysis of their decompressed Jacobian."""
    st = J.structure
    K = np.asarray(J.K, float)
    x = np.asarray(x, float)
    scale = np.asarray(scale, float)
    lead = x.shape[:-1]
    P, g, b, W = st.P, st.g, st.b, st.W
    K = K.reshape((-1,) + K.shape[-2:])
    xs = x.reshape(-1, P)
    N = K.shape[0]
    rel = np.where(xs != 0, np.abs(xs) / scale, 1.0)  # (N, P)
    Kb = K[:, st.block_rows]  # (N, W, k, T)
    norms = np.zeros((N, P + 1))
    norms[:, st.global_index] = np.linalg.norm(K[:, :, :g], axis=1)
    norms[:, st.spectral_index] = np.linalg.norm(Kb[..., g:], axis=2)  # absent ones land in the dummy
    norms = norms[:, :P] * rel
    safe = np.where(norms > 0, norms, 1.0)
    a = rel / safe  # J_normalised = J diag(a)
    a_ext = np.concatenate([a, np.zeros((N, 1))], axis=1)
    present = st.present
    Js = Kb[..., g:] * a_ext[:, st.spectral_index][:, :, None, :]  # (N, W, k, b)
    Jg = Kb[..., :g] * a[:, None, None, st.global_index]
    bad = ~(np.all(np.isfinite(Js), axis=(1, 2, 3)) & np.all(np.isfinite(Jg), axis=(1, 2, 3))
            & np.all(np.isfinite(K), axis=(1, 2)))
    Js = np.where(bad[:, None, None, None], 0.0, Js)
    Jg = np.where(bad[:, None, None, None], 0.0, Jg)
    unit = np.broadcast_to(np.eye(b) * ~present[:, None, :], (N, W, b, b))  # absent values: decoupled unit rows
    blocks = np.concatenate([np.concatenate([Js, Jg], axis=-1),
                             np.concatenate([unit, np.zeros((N, W, b, g))], axis=-1)], axis=-2)
    R = _np_qr_r(blocks)  # (N, W, min(k + b, b + g), b + g)
    Rs, G = R[..., :b, :b], R[..., :b, b:]
    sv_blocks = np.linalg.svd(Rs * present[None, :, :, None] * present[None, :, None, :], compute_uv=False)
    if g:
        H = R[..., b:, b:].reshape(N, -1, g)
        Jg0 = K[:, st.global_rows, :g] * a[:, None, st.global_index]
        Jg0 = np.where(bad[:, None, None], 0.0, Jg0)
        Rg = _np_qr_r(np.concatenate([H, Jg0], axis=1))[:, :g]  # (N, g, g)
        if Rg.shape[1] < g:  # fewer rows than globals: rank deficient
            Rg = np.concatenate([Rg, np.zeros((N, g - Rg.shape[1], g))], axis=1)
        sv_g = np.linalg.svd(Rg, compute_uv=False)
    else:
        Rg = np.zeros((N, 0, 0))
        sv_g = np.zeros((N, 0))
    absent = int((~present).sum())
    sv = np.sort(np.concatenate([sv_blocks.reshape(N, -1), sv_g], axis=1), axis=1)[:, ::-1]
    sv = sv[:, :sv.shape[1] - absent]  # the zeros of the absent values
    top = sv[:, :1]
    keep = (sv > rank_rtol * top) & (top > 0)
    rank = keep.sum(axis=1)
    full = (rank == P) & ~bad
    cov = np.full((N, P, P), np.nan)
    if full.any():
        f = np.nonzero(full)[0]
        n = f.size
        S = W * b  # block order: the spectral values wavelength by wavelength, then the globals
        Rs_inv = np.linalg.solve(Rs[f], np.broadcast_to(np.eye(b), Rs[f].shape))  # (n, W, b, b)
        Rs_inv = Rs_inv * present[None, :, :, None] * present[None, :, None, :]  # absent values: out
        B = np.zeros((n, S + g, S + g))
        if g:
            Rg_inv = np.linalg.solve(Rg[f], np.broadcast_to(np.eye(g), Rg[f].shape))
            Wm = (Rs_inv @ G[f] @ Rg_inv[:, None]).reshape(n, S, g)  # W_w = R_w^-1 G_w R_g^-1
            B[:, :S, :S] = Wm @ np.swapaxes(Wm, -1, -2)
            B[:, :S, S:] = -(Wm @ np.swapaxes(Rg_inv, -1, -2))
            B[:, S:, :S] = np.swapaxes(B[:, :S, S:], -1, -2)
            B[:, S:, S:] = Rg_inv @ np.swapaxes(Rg_inv, -1, -2)
        diag = B[:, :S, :S].reshape(n, W, b, W, b)  # a view: add blockdiag(R_w^-1 R_w^-T)
        w = np.arange(W)
        diag[:, w, :, w, :] += np.moveaxis(Rs_inv @ np.swapaxes(Rs_inv, -1, -2), 1, 0)
        pos = np.empty(P, int)  # free component -> its place in block order
        sflat = st.spectral_index.ravel()
        pos[sflat[sflat < P]] = np.flatnonzero(sflat < P)
        pos[st.global_index] = S + np.arange(g)
        cn = np.take(np.take(B, pos, axis=1), pos, axis=2)
        s = a[f] * scale
        cov[f] = cn * s[:, :, None] * s[:, None, :]
    Vt = np.zeros((N, P, P))
    dirs = np.zeros((N, P, P))
    sv_out = np.where(bad[:, None], np.nan, sv)
    rank = np.where(bad, P, rank)
    rest = np.nonzero(~full)[0]
    if rest.size:  # a direction the data do not determine (or a non-finite Jacobian): the dense analysis names it
        Jd = dense_of(K[rest], st)
        c2, sv2, rank2, Vt2, dirs2 = linearised_covariance(Jd, xs[rest], scale, rank_rtol)
        cov[rest], sv_out[rest], rank[rest], Vt[rest], dirs[rest] = c2, sv2, rank2, Vt2, dirs2
    return (cov.reshape(lead + (P, P)), sv_out.reshape(lead + (P,)), rank.reshape(lead),
            Vt.reshape(lead + (P, P)), dirs.reshape(lead + (P, P)))


def compressed_zero_columns(J: CompressedJacobian) -> np.ndarray:
    """``(..., P)`` True where the dense Jacobian's column is zero."""
    st = J.structure
    K = np.asarray(J.K, float)
    lead = K.shape[:-2]
    n = np.zeros(lead + (st.P + 1,))
    n[..., st.global_index] = np.linalg.norm(K[..., :st.g], axis=-2)
    Kb = K[..., st.block_rows, st.g:]  # (..., W, k, b)
    n[..., st.spectral_index] = np.linalg.norm(Kb, axis=-2)
    return n[..., :st.P] == 0
