r"""Tables for renderers (Hirayama et al. §5): k_r, k_t and k_d of one coating over angle × wavelength.

Hirayama pre-computes the composite reflectance and transmittance "for each sampled incident
angle and wave length of light" and interpolates them linearly while ray tracing. Here the
tables hold, for films on a rough object (:mod:`layerstack_jax._appearance.coated_rough`):

* ``k_r[a, l]``, ``k_t[a, l]``: specular reflectance and transmittance at ``cos_theta[a]``,
  ``wavelength_nm[l]``;
* ``k_d[a, b, p, l]``: diffuse BRDF (1/sr) from incidence ``cos_theta[a]`` to the outgoing
  direction (``cos_theta_out[b]``, ``phi_out[p]``), φ measured from the forward (specular) side
  of the plane of incidence, in [0, π] (k_d is even in φ).

All arrays are plain numpy float64 (layout fixed by the Mitsuba plugin that reads them). Angle
grids are ascending in cos θ; by default uniform in θ (1° steps for 90 angles, cos θ = 1
included, the smallest cosine cos(89°)), or uniform in cos θ (``spacing="cos"``).

Interpolation error: the tables are also evaluated directly at the midpoints (in the table's own
coordinates: cos θ, cos θ_out, φ, λ) of the cells — all cells for k_r and k_t, a strided subset
of the in-angle cells (every cell in the other axes) for k_d — and compared with multilinear
interpolation of the table. The stated error is
:math:`\max |f_\text{interp} - f| / \max(|f|, 10^{-3}\max_\text{table}|f|)`: relative, with a
floor at 1e-3 of the table's peak so that the vanishing values at grazing directions do not
dominate it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._base.validate import LayerstackError, check_unit_interval
from .._stacks.illumination import snell_invariant_from_cos
from .._stacks.recursion import natural
from .._stacks.stack import Stack, resolve
from .coated_rough import check_coated_stack, check_options, rough_diffuse, rough_specular
from .he_torrance import auto_terms, check_roughness

__all__ = ["CoatingTables", "coating_tables", "angle_grid", "interpolate_k_r", "interpolate_k_t", "interpolate_k_d",
           "multilinear"]


class CoatingTables(NamedTuple):
    """Renderer tables of one coating (module docstring). Plain numpy float64 arrays:

    ``wavelength_nm`` (L,) ascending; ``cos_theta`` (A,) ascending in (0, 1]; ``k_r``, ``k_t``
    (A, L) dimensionless; ``phi_out`` (P,) radians in [0, π]; ``cos_theta_out`` (B,) ascending;
    ``k_d`` (A, B, P, L) in 1/sr, natural light, without the specular delta;
    ``interpolation_error``: the larger of the two measured errors below;
    ``interpolation_error_k_r`` (k_r and k_t) and ``interpolation_error_k_d``: measured max
    relative error of linear interpolation at cell midpoints (NaN when not estimated);
    ``absolute_error_k_r`` (dimensionless) and ``absolute_error_k_d`` (1/sr): the same as max
    absolute differences;
    ``sigma_nm``, ``tau_nm``, ``form``: the roughness and the diffuse form used."""

    wavelength_nm: np.ndarray
    cos_theta: np.ndarray
    k_r: np.ndarray
    k_t: np.ndarray
    phi_out: np.ndarray
    cos_theta_out: np.ndarray
    k_d: np.ndarray
    interpolation_error: float = float("nan")
    interpolation_error_k_r: float = float("nan")
    interpolation_error_k_d: float = float("nan")
    absolute_error_k_r: float = float("nan")
    absolute_error_k_d: float = float("nan")
    sigma_nm: float = 0.0
    tau_nm: float = 0.0
    form: str = "radiometric"


def angle_grid(n: int, spacing: str = "theta") -> np.ndarray:
    """Ascending grid of ``n`` cosines in (0, 1]: ``"theta"``: θ_j = 90°·j/n, j = 0…n−1 (cos θ = 1
    included); ``"cos"``: cos θ = j/n, j = 1…n."""
    if n < 2:
        raise LayerstackError(f"angle grids need at least 2 points, got {n}")
    if spacing == "theta":
        return np.cos(np.radians(90.0 * np.arange(n) / n))[::-1].copy()
    if spacing == "cos":
        return np.arange(1, n + 1) / n
    raise LayerstackError(f"spacing must be 'theta' or 'cos', got {spacing!r}")


@eqx.filter_jit
def _specular_tables(stack, wl, cos, sigma0, tau, shadowing_form):
    rs = resolve(stack, wl)
    n0 = jnp.real(jnp.asarray(rs.n[0]))
    R, T = rough_specular(rs, snell_invariant_from_cos(n0, cos)[:, None], sigma0, tau, shadowing_form=shadowing_form)
    return natural(R), natural(T)


@eqx.filter_jit
def _diffuse_block(stack, wl, cos_in, cos_out, phi, sigma0, tau, albedo, n_terms, form, shadowing_form):
    """k_d on one block of incidence cosines: ``(block, B, P, L)`` (1/sr)."""
    rs = resolve(stack, wl)
    n0 = jnp.real(jnp.asarray(rs.n[0]))
    s_in, s_out = snell_invariant_from_cos(n0, cos_in), snell_invariant_from_cos(n0, cos_out)
    return natural(rough_diffuse(rs, s_in[:, None, None, None], s_out[None, :, None, None],
                         phi[None, None, :, None], sigma0, tau, n_terms=n_terms, uniform_albedo=albedo, form=form,
                         shadowing_form=shadowing_form))


def _padded(x, n):
    """``x`` extended to length ``n`` by repeating its last value (so that one compiled shape
    serves the table and its midpoints)."""
    x = np.asarray(x, dtype=float)
    return np.concatenate([x, np.full(n - x.size, x[-1])]) if x.size < n else x


def _diffuse_table(stack, wl, cos_in, cos_out, phi, sigma0, tau, albedo, n_terms, form, shadowing_form, block):
    """k_d ``(len(cos_in), B, P, L)``: blocks of ``block`` incidence angles, each a call of one
    compiled function (the last block padded)."""
    out = []
    for start in range(0, cos_in.size, block):
        chunk = cos_in[start:start + block]
        res = _diffuse_block(stack, jnp.asarray(wl), jnp.asarray(_padded(chunk, block)), jnp.asarray(cos_out),
                             jnp.asarray(phi), sigma0, tau, albedo, n_terms, form, shadowing_form)
        out.append(np.asarray(res, dtype=np.float64)[: chunk.size])
    return np.concatenate(out, axis=0)


def multilinear(grids, values, points):
    """Multilinear interpolation of ``values`` (shape ``(*len(grids), *rest)``) on the ascending
    ``grids`` (a tuple of 1-D arrays) at ``points`` (a tuple of arrays broadcast together, one per
    grid); points outside a grid are clamped to its ends. Returns ``(*broadcast, *rest)``."""
    points = np.broadcast_arrays(*(np.asarray(p, dtype=float) for p in points))
    idx, wts = [], []
    for g, p in zip(grids, points):
        g = np.asarray(g, dtype=float)
        p = np.clip(p, g[0], g[-1])
        i = np.clip(np.searchsorted(g, p, side="right") - 1, 0, len(g) - 2)
        w = (p - g[i]) / (g[i + 1] - g[i])
        idx.append(i)
        wts.append(w)
    out = 0.0
    for corner in range(2 ** len(grids)):
        ix, w = [], 1.0
        for axis in range(len(grids)):
            bit = (corner >> axis) & 1
            ix.append(idx[axis] + bit)
            w = w * (wts[axis] if bit else 1.0 - wts[axis])
        v = values[tuple(ix)]
        out = out + w.reshape(w.shape + (1,) * (v.ndim - w.ndim)) * v
    return out


def _fold_phi(phi):
    """Azimuth folded into [0, π] (k_d is even in φ)."""
    return np.abs(np.mod(np.asarray(phi, dtype=float) + np.pi, 2 * np.pi) - np.pi)


def interpolate_k_r(tables: CoatingTables, cos_theta, wavelength_nm):
    """Linear interpolation of ``k_r`` at ``cos_theta`` and ``wavelength_nm`` (broadcast together)."""
    return multilinear((tables.cos_theta, tables.wavelength_nm), tables.k_r, (cos_theta, wavelength_nm))


def interpolate_k_t(tables: CoatingTables, cos_theta, wavelength_nm):
    """Linear interpolation of ``k_t`` at ``cos_theta`` and ``wavelength_nm`` (broadcast together)."""
    return multilinear((tables.cos_theta, tables.wavelength_nm), tables.k_t, (cos_theta, wavelength_nm))


def interpolate_k_d(tables: CoatingTables, cos_theta, cos_theta_out, phi_out, wavelength_nm):
    """Multilinear interpolation of ``k_d`` (1/sr) at incidence cosine, outgoing cosine, outgoing
    azimuth (radians, any sign: folded into [0, π]) and wavelength, broadcast together."""
    return multilinear((tables.cos_theta, tables.cos_theta_out, tables.phi_out, tables.wavelength_nm), tables.k_d,
                       (cos_theta, cos_theta_out, _fold_phi(phi_out), wavelength_nm))


def _midpoints(x):
    return 0.5 * (x[1:] + x[:-1])


def _relative_error(interp, direct, peak):
    floor = 1e-3 * peak
    return float(np.max(np.abs(interp - direct) / np.maximum(np.abs(direct), floor))) if peak > 0 else 0.0


def coating_tables(
    stack: Stack,
    wavelength_nm,
    *,
    n_angles: int = 90,
    n_angles_out: int = 30,
    n_phi: int = 19,
    spacing: str = "theta",
    sigma_nm: float = 0.0,
    tau_nm: float = 300.0,
    uniform_albedo: float = 0.0,
    form: str = "radiometric",
    shadowing_form: str = "corrected",
    include_diffuse: bool = True,
    estimate_error: bool = True,
    error_stride: int = 8,
    block: int = 8,
    n_terms: int | None = None,
) -> CoatingTables:
    r"""Pre-computed tables of one coating for a renderer (module docstring).

    Args:
        stack: ambient · coherent films · :class:`~layerstack_jax.Substrate` (the object).
        wavelength_nm: ``(L,)`` ascending wavelengths, nm.
        n_angles: incidence cosines A (grid :func:`angle_grid`); n_angles_out: outgoing cosines B;
            n_phi: outgoing azimuths P, uniform on [0, π]; spacing: ``"theta"`` or ``"cos"``.
        sigma_nm, tau_nm: roughness of the object (nm); σ0 = 0 gives a smooth stack (k_d = 0).
        uniform_albedo, form, shadowing_form: as in :func:`layerstack_jax._appearance.coated_rough.coated_rough`.
        include_diffuse: False leaves k_d empty ``(A, 0, 0, L)`` (specular tables only).
        estimate_error: evaluate the model at cell midpoints and state the interpolation error;
            error_stride: every how many incidence cells k_d's error is checked.
        block: incidence angles evaluated together by one compiled function (memory ~ block × B ×
            P × L × 2 complex); the midpoints reuse the same compiled shapes.
        n_terms: terms of He's D series (default from σ0 and the shortest wavelength).

    Returns:
        :class:`CoatingTables` (numpy float64).
    """
    check_coated_stack(stack)
    check_options(form, "view", shadowing_form)
    check_roughness(sigma_nm, tau_nm)
    check_unit_interval("uniform_albedo", uniform_albedo)
    wl = np.asarray(wavelength_nm, dtype=float)
    if wl.ndim != 1 or wl.size < 2 or np.any(np.diff(wl) <= 0):
        raise LayerstackError("wavelength_nm must be 1-D, strictly ascending, with at least 2 values")
    if n_phi < 2 and include_diffuse:
        raise LayerstackError(f"n_phi must be >= 2, got {n_phi}")
    cos = angle_grid(n_angles, spacing)
    sigma0, tau = jnp.asarray(float(sigma_nm)), jnp.asarray(float(tau_nm))
    wl_j = jnp.asarray(wl)
    k_r, k_t = (np.asarray(x, dtype=np.float64) for x in _specular_tables(stack, wl_j, jnp.asarray(cos), sigma0, tau,
                                                                          shadowing_form))
    err_r = abs_r = float("nan")
    if estimate_error:
        cm, wm = _midpoints(cos), _midpoints(wl)
        r_m, t_m = (np.asarray(x)[: cm.size, : wm.size] for x in _specular_tables(
            stack, jnp.asarray(_padded(wm, wl.size)), jnp.asarray(_padded(cm, cos.size)), sigma0, tau, shadowing_form))
        args = (cm[:, None], wm[None, :])
        i_r, i_t = multilinear((cos, wl), k_r, args), multilinear((cos, wl), k_t, args)
        err_r = max(_relative_error(i_r, r_m, np.max(np.abs(k_r))), _relative_error(i_t, t_m, np.max(np.abs(k_t))))
        abs_r = float(max(np.max(np.abs(i_r - r_m)), np.max(np.abs(i_t - t_m))))
    if not include_diffuse:
        empty = np.zeros((n_angles, 0, 0, wl.size))
        return CoatingTables(wl, cos, k_r, k_t, np.zeros(0), np.zeros(0), empty, err_r, err_r, float("nan"), abs_r,
                             float("nan"), float(sigma_nm), float(tau_nm), form)
    cos_out = angle_grid(n_angles_out, spacing)
    phi = np.linspace(0.0, math.pi, n_phi)
    terms = auto_terms(sigma_nm, wl, resolve(stack, wl).n[-2], n_terms)
    rest = (sigma0, tau, jnp.asarray(float(uniform_albedo)), terms, form, shadowing_form, int(block))
    k_d = _diffuse_table(stack, wl, cos, cos_out, phi, *rest)
    err_d = abs_d = float("nan")
    if estimate_error:
        cm = _midpoints(cos)[:: max(int(error_stride), 1)]
        com, pm, wm = _midpoints(cos_out), _midpoints(phi), _midpoints(wl)
        direct = _diffuse_table(stack, _padded(wm, wl.size), cm, _padded(com, cos_out.size), _padded(pm, phi.size),
                                *rest)[:, : com.size, : pm.size, : wm.size]
        interp = multilinear((cos, cos_out, phi, wl), k_d,
                             (cm[:, None, None, None], com[None, :, None, None], pm[None, None, :, None],
                              wm[None, None, None, :]))
        err_d = _relative_error(interp, direct, np.max(np.abs(k_d)))
        abs_d = float(np.max(np.abs(interp - direct)))
    err = float(np.nanmax([err_r, err_d])) if estimate_error else float("nan")
    return CoatingTables(wl, cos, k_r, k_t, phi, cos_out, k_d, err, err_r, err_d, abs_r, abs_d, float(sigma_nm),
                         float(tau_nm), form)
