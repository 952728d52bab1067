r"""Smooth coherent films on a rough object: Hirayama et al. §4.2, eqs. 8–17.

The *object surface* (the substrate) is rough, a He–Torrance boundary of rms roughness
:math:`\sigma_0` and autocorrelation length :math:`\tau` (:mod:`layerstack_jax._appearance.he_torrance`);
the films above it keep smooth, planar boundaries (the film next to the object has the mean
thickness). Roughness enters only through the amplitude ratios of the rough boundary, seen from
the last film (medium N, index :math:`n_N`):

* **specular** (eqs. 9–10): the Rouard recursion of :mod:`layerstack_jax._kernels.coherent` seeded with
  :math:`\gamma_{s,0} = \eta_s = r_{N+1}\,e^{-g/2}S` instead of :math:`r_{N+1}`; then
  :math:`k_r = \tfrac12(|\gamma_{s,\parallel}|^2 + |\gamma_{s,\perp}|^2)` (eq. 5). As σ0 → 0,
  :math:`\eta_s \to r_{N+1}` and :math:`k_r` is the smooth stack's reflectance;
* **diffuse** (eqs. 11–17): light scattered once by the rough object (He–Torrance directional
  and uniform diffuse, :math:`\rho = |\eta_d|^2` per polarization), the specular component
  reflected any number of times between the films and the object.

Two forms of the diffuse term (``form=``):

* ``"literal"``: eqs. 15–17 as printed. Per polarization,
  :math:`|\gamma_{d,N}|^2 = \rho\,|q_N/q_0|^2 \prod_j |t_j(\theta_v) e^{i\phi_j(\theta_v)}|^2\,|\tau_\downarrow(\theta_l)|^2`
  with :math:`\tau_\downarrow` the composite transmissivity into medium N of the Rouard recursion
  seeded with :math:`(\gamma, \tau) = (\eta_s, 1)` (the denominators :math:`1 + r_j\gamma_{s}e^{2i\phi_{l,j}}`
  of eq. 16) and :math:`\prod_j \hat n_j s_{z,j}/(\hat n_{j-1}s_{z,j-1}) = q_N/q_0` (eq. 17's
  prefactors telescope). Hirayama's :math:`\omega_l` is the light (our *incidence*), his
  :math:`\omega_i` the viewing ray (our *viewing* direction); only the light's leg carries the
  multiple reflections. The prefactor's :math:`s_z` is read at the viewing direction
  (``prefactor="view"``, eq. 13's :math:`t(\theta_{i,0})` comes first) or at the light's
  (``"light"``): the paper does not say. As written it is not reciprocal, it does not vanish
  at grazing viewing (``"view"``: :math:`|t(\theta_v)|^2/\cos^2\theta_v` stays finite) and it
  misses the radiance factor :math:`(n_0/n_N)^2` (too large by :math:`n_N^2` at normal
  incidence): it is not a radiometric BRDF.
* ``"radiometric"`` (default): energy bookkeeping of the same physics. The collimated power
  reaching the object through the films (with all the specular round trips) is
  :math:`T_\downarrow(\theta) = |\tau_\downarrow|^2\,\Phi_N/\Phi_0` (power fluxes of
  :func:`layerstack_jax._kernels.fresnel.power_flux`); the object scatters it with its BRDF
  :math:`\rho` in medium N; the scattered light leaves through the same films with the same
  transmittance (reciprocity of the film stack), and radiance is divided by
  :math:`n_N^2/n_0^2` on the way out (étendue). Per polarization
  :math:`k_d = (n_0/n_N)^2\,T_\downarrow(\theta_l)\,\rho\,T_\downarrow(\theta_v)`, then the mean of
  s and p. It is reciprocal whenever ρ is, vanishes at grazing incidence or viewing, and
  conserves energy (:math:`\int k_d\cos\theta_v d\omega_v \le T_\downarrow` times the object's albedo).

Both forms coincide without films. The medium next to the object must be transparent (a real
index; its real part is used otherwise) for the He–Torrance terms to be defined in it.

Transmission into a transparent object (``k_t``): the Rouard transmissivity with its last
interface's :math:`t_{N+1}` attenuated by the Kirchhoff coherent factor
:math:`\exp(-\tfrac12[k\sigma_0(q_N - q_{N+1})]^2)`, :math:`k = 2\pi/\lambda` (the mean
transmitted field of a Gaussian surface); 0 into an absorbing object (Hirayama eq. 6).

Natural light by default; per polarization on request, with the s/p frames of the local facets
taken as those of the plane of incidence, as Hirayama does (an exact polarized treatment needs
a Mueller calculus).

Which model for which object. This module: a rough *object* under films whose boundaries stay
flat (paint levelled over a rough metal, a polished coating on a sand-blasted part; roughness
heights σ0 ≲ λ, correlation lengths τ ~ λ, where wave effects — the e^{−g} specular loss that
grows as σ0/λ, the directional-diffuse lobe — matter). :func:`layerstack_jax.rough_brdf`
(:mod:`layerstack_jax._appearance.rough`): a *conformal* coating that follows a rough surface whose facets
are much larger than the wavelength, each facet carrying the whole stack (Cook–Torrance /
GGX / Beckmann, geometric optics, no σ0/λ dependence). Neither is the other's limit.
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._base.custom_types import Array, Complex, Float, RealLike
from .._base.numerics import abs2, as_complex, safe_divide, safe_divide_nonzero
from .._base.validate import LayerstackError, LayerstackWarning, is_concrete
from .._kernels.coherent import _lift_branch_point, _media, _packet_recursion
from .._kernels.fresnel import exit_medium_ratio, fresnel_amplitudes, normal_wavevector, power_flux
from .._stacks.illumination import snell_invariant
from .._stacks.recursion import natural
from .._stacks.stack import ResolvedStack, Stack, resolve
from .he_torrance import SHADOWING_FORMS, auto_terms, check_scattering_inputs, directional_diffuse, specular_attenuation

__all__ = ["CoatedRough", "coated_rough", "FORMS", "PREFACTORS", "check_coated_stack", "rough_specular",
           "rough_diffuse"]

FORMS = ("radiometric", "literal")
PREFACTORS = ("view", "light")


class CoatedRough(NamedTuple):
    """Response of smooth films on a rough object, natural light, arrays ``(*angle, wl)``:

    ``k_r``: specular (mirror-direction) reflectance at the incidence angle (Hirayama eq. 5
    with eqs. 9–10); ``k_t``: specular transmittance into the object at the incidence angle (0
    for an absorbing object); ``k_d``: diffuse BRDF in 1/sr (directional + uniform diffuse,
    eqs. 11–17), from the incidence to the viewing direction, excluding the specular delta."""

    k_r: Float[Array, "*angle wl"]
    k_t: Float[Array, "*angle wl"]
    k_d: Float[Array, "*angle wl"]


class _Direction(NamedTuple):
    """What the recursion needs of one direction (Snell invariant ``s``): media indices
    ``n`` and normal wavevectors ``q`` ``(media, *B)``, interface amplitudes ``r, t``
    ``(2, interface, *B)``, power fluxes ``(2, media, *B)`` and the cosine in medium N."""

    n: Complex[Array, "med *B"]
    q: Complex[Array, "med *B"]
    r: Complex[Array, "pol med-1 *B"]
    t: Complex[Array, "pol med-1 *B"]
    flux: Float[Array, "pol med *B"]
    cos_N: Float[Array, "*B"]


def _direction(rs: ResolvedStack, s) -> _Direction:
    n = _media(rs.n, s)
    q = normal_wavevector(n, s)
    if len(rs.n) > 2:
        q = q.at[1:-1].set(_lift_branch_point(q[1:-1]))
    r, t = fresnel_amplitudes(n[:-1], q[:-1], n[1:], q[1:])
    n_N = jnp.real(n[-2])
    cos_N = jnp.clip(jnp.real(q[-2]) / n_N, 0.0, 1.0)
    return _Direction(n, q, r, t, power_flux(n, q), cos_N)


def _seeded(x, seed):
    """Interface amplitudes ``(2, N+1, *B)`` with the last interface (onto the object) replaced."""
    shape = jnp.broadcast_shapes(x.shape, (2, x.shape[1], *jnp.shape(seed)[1:]))
    x = jnp.broadcast_to(x, shape)
    return x.at[:, -1].set(jnp.broadcast_to(seed, (2, *shape[2:])))


def _eta_specular(rs, dirn: _Direction, sigma0, tau, form):
    """η_s of the rough object seen from medium N, ``(2, *B)`` (Hirayama eq. 9)."""
    att = specular_attenuation(jnp.real(rs.n[-2]), dirn.cos_N, rs.wavelength, sigma0, tau, form=form)
    return dirn.r[:, -1] * as_complex(att, dirn.r)[None]


def rough_specular(rs: ResolvedStack, s, sigma0, tau, *, shadowing_form: str = "corrected"):
    r"""Per-polarization ``(R, T)`` ``(2, *B, wl)`` of the coated rough object for collimated light
    at Snell invariant ``s`` (broadcastable to ``(*B, wl)``): R from eqs. 9–10 (the recursion of
    :func:`layerstack_jax._kernels.coherent._packet_recursion` seeded with η_s), T into a transparent
    object (module docstring; 0 into an absorbing one)."""
    dirn = _direction(rs, s)
    d_films = tuple(rs.d)
    eta = _eta_specular(rs, dirn, sigma0, tau, shadowing_form)
    k0 = 2.0 * math.pi / rs.wavelength
    dq = dirn.q[-2] - dirn.q[-1]
    t_last = dirn.t[:, -1] * jnp.exp(-0.5 * (as_complex(k0 * sigma0, dq) * dq) ** 2)[None]
    gamma, tau_t = _packet_recursion(_seeded(dirn.r, eta), _seeded(dirn.t, t_last), dirn.q[1:-1], d_films,
                                     rs.wavelength)
    R = abs2(gamma)
    T = safe_divide(abs2(tau_t) * dirn.flux[:, -1], dirn.flux[:, 0])
    opaque = jnp.imag(dirn.n[-1]) > 0
    return R, jnp.where(opaque, 0.0, T)


def _down(rs, dirn: _Direction, eta):
    """Composite transmissivity into medium N with every specular round trip between the films
    and the object: the Rouard recursion seeded with (γ, τ) = (η_s, 1). ``(2, *B, wl)``."""
    one = jnp.ones_like(eta)
    _, tau_down = _packet_recursion(_seeded(dirn.r, eta), _seeded(dirn.t, one), dirn.q[1:-1], tuple(rs.d),
                                    rs.wavelength)
    return tau_down


def _single_pass(rs, dirn: _Direction):
    r""":math:`\prod_j t_j e^{i\phi_j}` over the films (no multiple reflections), ``(2, *B, wl)``."""
    amp = jnp.prod(dirn.t[:, :-1], axis=1)
    if not rs.d:
        return jnp.broadcast_to(amp, (2, *jnp.broadcast_shapes(amp.shape[1:], rs.wavelength.shape)))
    k0 = as_complex(2 * jnp.pi / rs.wavelength, dirn.q)  # vacuum wavenumber (1/nm) in the phases' complex dtype
    phase = sum(k0 * dirn.q[j + 1] * as_complex(d, dirn.q) for j, d in enumerate(rs.d))
    return amp * jnp.exp(1j * phase)


def rough_diffuse(rs: ResolvedStack, s_in, s_out, phi, sigma0, tau, *, n_terms: int, uniform_albedo=0.0,
                  form: str = "radiometric", prefactor: str = "view", shadowing_form: str = "corrected"):
    r"""Diffuse BRDF :math:`k_d` (1/sr) per polarization, ``(2, *B, wl)`` (s, p; natural light is
    their mean, :func:`layerstack_jax._stacks.recursion.natural`), of the coated rough object
    from incidence (Snell invariant ``s_in``) to viewing direction (``s_out``) at azimuth ``phi``
    (radians, 0 = forward side of the plane of incidence); the three have the same rank and broadcast to ``(*B, 1)`` or
    ``(*B, wl)``. ``form``, ``prefactor``: module docstring. Only the He–Torrance terms are
    evaluated on the full ``*B``; the film factors on the shapes of ``s_in`` and ``s_out``."""
    d_in, d_out = _direction(rs, s_in), _direction(rs, s_out)
    n_N = jnp.real(rs.n[-2])
    rho = directional_diffuse(n_N, rs.n[-1], d_in.cos_N, d_out.cos_N, phi, rs.wavelength, sigma0, tau,
                              n_terms=n_terms, form=shadowing_form)
    rho = rho + jnp.asarray(uniform_albedo) / math.pi
    down_in = _down(rs, d_in, _eta_specular(rs, d_in, sigma0, tau, shadowing_form))
    if form == "radiometric":
        down_out = _down(rs, d_out, _eta_specular(rs, d_out, sigma0, tau, shadowing_form))
        T_in = safe_divide(abs2(down_in) * d_in.flux[:, -2], d_in.flux[:, 0])
        T_out = safe_divide(abs2(down_out) * d_out.flux[:, -2], d_out.flux[:, 0])
        return exit_medium_ratio(rs.n[0], n_N) * (T_in * rho * T_out)
    if form == "literal":
        at = d_out if prefactor == "view" else d_in
        pref = abs2(safe_divide_nonzero(at.q[-2], at.q[0]))
        return pref * abs2(_single_pass(rs, d_out)) * abs2(down_in) * rho
    raise LayerstackError(f"form must be one of {FORMS}, got {form!r}")


def check_coated_stack(stack: Stack) -> None:
    """The coated-rough model needs coherent films over a specular :class:`Substrate` (the rough
    object)."""
    if stack.exit.diffuse:
        raise LayerstackError("coated_rough: stack.exit must be a Substrate (the rough object), not a background")
    for i, layer in enumerate(stack.layers):
        if not layer.coherent:
            raise LayerstackError(f"coated_rough: layers[{i}] ({layer.name or 'unnamed'}) must be coherent (a thin film)")


def warn_absorbing_neighbour(stack: Stack, n_next) -> None:
    """Warn when the film next to the rough object absorbs: the He–Torrance terms are defined in
    a transparent medium and are evaluated with its real index (module docstring)."""
    if stack.layers and is_concrete(n_next) and np.any(np.imag(np.asarray(n_next)) > 0):
        warnings.warn(f"layers[{len(stack.layers) - 1}] next to the rough object absorbs: the He-Torrance terms use "
                      "its real index only", LayerstackWarning, stacklevel=3)


def check_options(form, prefactor, shadowing_form):
    if form not in FORMS:
        raise LayerstackError(f"form must be one of {FORMS}, got {form!r}")
    if prefactor not in PREFACTORS:
        raise LayerstackError(f"prefactor must be one of {PREFACTORS}, got {prefactor!r}")
    if shadowing_form not in SHADOWING_FORMS:
        raise LayerstackError(f"shadowing_form must be one of {SHADOWING_FORMS}, got {shadowing_form!r}")


def coated_rough(
    stack: Stack,
    wavelength_nm,
    incidence_deg: RealLike,
    viewing_deg: RealLike,
    azimuth_deg: RealLike = 0.0,
    *,
    sigma_nm: RealLike,
    tau_nm: RealLike,
    uniform_albedo: RealLike = 0.0,
    form: str = "radiometric",
    prefactor: str = "view",
    shadowing_form: str = "corrected",
    n_terms: int | None = None,
    polarized: bool = False,
) -> CoatedRough:
    r"""Specular reflectance :math:`k_r(\theta, \lambda)`, specular transmittance :math:`k_t` and
    diffuse BRDF :math:`k_d(\omega_l, \omega_v, \lambda)` of coherent films on a rough object
    (Hirayama et al. eqs. 8–17 with a He–Torrance object; module docstring).

    Args:
        stack: ambient · coherent films · :class:`~layerstack_jax.Substrate` (the rough object,
            e.g. a metal or silicon). The film next to the object should be transparent.
        wavelength_nm: ``(wl,)`` vacuum wavelengths, nm.
        incidence_deg: polar angle of the light (Hirayama's ω_l) in the ambient, degrees in
            [0, 90]; viewing_deg: polar angle of the viewing direction (Hirayama's ω_i);
            azimuth_deg: azimuth of the viewing direction from the forward (specular) side of
            the plane of incidence, degrees. The three broadcast to ``(*angle)``.
        sigma_nm: rms roughness σ0 of the object (nm, ≥ 0); tau_nm: its autocorrelation length
            τ (nm, > 0). Differentiable, as are the wavelengths and every stack parameter.
        uniform_albedo: albedo a of the object's uniform-diffuse term a/π (in medium N).
        form: ``"radiometric"`` (default; reciprocal, energy-consistent) or ``"literal"``
            (eqs. 15–17 as printed); static.
        prefactor: for ``form="literal"``: where eq. 13/17's :math:`n s_z` ratio is read,
            ``"view"`` or ``"light"``; static.
        shadowing_form: ``"corrected"`` or ``"smith"`` (:mod:`layerstack_jax._appearance.he_torrance`).
        n_terms: terms of He's D series (static; default chosen from the inputs when concrete).
        polarized: False (default): natural light, arrays ``(*angle, wl)``; True: per
            polarization, arrays ``(*angle, 2, wl)`` with axis −2 ``(s, p)`` as in
            :func:`layerstack_jax.specular` (s and p of the plane of incidence; the facets' own
            frames are not rotated, as in Hirayama).

    Returns:
        :class:`CoatedRough` with arrays ``(*angle, wl)`` (or ``(*angle, 2, wl)``); ``k_r`` and
        ``k_t`` depend on the incidence angle only (broadcast).
    """
    check_coated_stack(stack)
    check_options(form, prefactor, shadowing_form)
    check_scattering_inputs(incidence_deg, viewing_deg, azimuth_deg, sigma_nm, tau_nm, uniform_albedo)
    wl = jnp.asarray(wavelength_nm)
    n_next = resolve(stack, wl).n[-2]
    warn_absorbing_neighbour(stack, n_next)
    n_terms = auto_terms(sigma_nm, wl, n_next, n_terms)
    return _coated_rough_core(stack, wl, jnp.asarray(incidence_deg), jnp.asarray(viewing_deg),
                              jnp.asarray(azimuth_deg), jnp.asarray(sigma_nm), jnp.asarray(tau_nm),
                              jnp.asarray(uniform_albedo), n_terms, form, prefactor, shadowing_form, bool(polarized))


@eqx.filter_jit
def _coated_rough_core(stack, wavelength_nm, incidence_deg, viewing_deg, azimuth_deg, sigma_nm, tau_nm,
                       uniform_albedo, n_terms: int, form: str, prefactor: str, shadowing_form: str,
                       polarized: bool) -> CoatedRough:
    """Compiled body of :func:`coated_rough` (inputs validated there)."""
    rs = resolve(stack, wavelength_nm)
    dtype = jnp.result_type(rs.wavelength.dtype, float)
    ti, to, ph = jnp.broadcast_arrays(*(jnp.deg2rad(x.astype(dtype)) for x in (incidence_deg, viewing_deg, azimuth_deg)))
    s_in, s_out = snell_invariant(rs.n[0], ti), snell_invariant(rs.n[0], to)
    sigma0, tau = sigma_nm.astype(dtype), tau_nm.astype(dtype)
    R, T = rough_specular(rs, s_in, sigma0, tau, shadowing_form=shadowing_form)
    k_d = rough_diffuse(rs, s_in, s_out, ph[..., None], sigma0, tau, n_terms=n_terms, uniform_albedo=uniform_albedo,
                        form=form, prefactor=prefactor, shadowing_form=shadowing_form)
    shape = jnp.broadcast_shapes(k_d.shape, R.shape)
    out = (jnp.broadcast_to(x, shape) for x in (R, T, k_d))
    return CoatedRough(*(jnp.moveaxis(x, 0, -2) if polarized else natural(x) for x in out))
