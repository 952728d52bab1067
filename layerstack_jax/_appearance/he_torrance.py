r"""A rough boundary after He, Torrance, Sillion & Greenberg (SIGGRAPH 1991; Hirayama's ref. 17).

The boundary between a transparent medium *a* (real index :math:`n_a`, where the light travels)
and a medium *b* (complex :math:`\tilde n_b`: a metal, a semiconductor, a dielectric) is a
random surface with Gaussian heights of rms :math:`\sigma_0` and a Gaussian autocorrelation of
length :math:`\tau` (both in nm). Its BRDF is the sum of three terms (He et al. eq. numbers in
brackets; the paper's own numbering, as printed):

* **specular** (a delta in the mirror direction, weight a reflectance):
  :math:`\rho_\text{sp}(\theta) = |F(\theta)|^2\, e^{-g}\, S(\theta)^2`, with
  :math:`g = [k\sigma(\cos\theta_i + \cos\theta_r)]^2`, :math:`k = 2\pi n_a/\lambda`;
* **directional diffuse** (1/sr):
  :math:`\rho_\text{dd} = \dfrac{|F(\theta_\text{loc})|^2}{\pi}\,\dfrac{G\,S(\theta_i)S(\theta_r)\,D}{\cos\theta_i\cos\theta_r}`,
  :math:`D = \dfrac{(k\tau)^2}{16}\sum_{m\ge1}\dfrac{g^m e^{-g}}{m!\,m}\,
  \exp\!\Big(-\dfrac{(k\tau)^2 \hat v_{xy}^2}{4m}\Big)`;
* **uniform diffuse** (1/sr): :math:`a/\pi` (subsurface scattering; a given albedo, 0 for metals).

Notation. Unit vectors :math:`\hat k_i = (\sin\theta_i, 0, -\cos\theta_i)` (towards the surface)
and :math:`\hat k_r = (\sin\theta_r\cos\phi, \sin\theta_r\sin\phi, \cos\theta_r)`;
:math:`\hat v = \hat k_r - \hat k_i`. The local (facet) angle of incidence has
:math:`\cos\theta_\text{loc} = |\hat v|/2`, where the Fresnel factor :math:`F` is evaluated.
:math:`G = (\hat v\cdot\hat v/\hat v_z)^2` is He's geometrical factor for natural light (their
polarization vectors make :math:`[(\hat s_r\cdot\hat k_i)^2 + (\hat p_r\cdot\hat k_i)^2]
[(\hat s_i\cdot\hat k_r)^2 + (\hat p_i\cdot\hat k_r)^2] = |\hat k_r\times\hat k_i|^4`, which
cancels their :math:`1/|\hat k_r\times\hat k_i|^4`). :math:`\phi = 0` is the forward
(specular) side of the plane of incidence.

Choices made in the open (the paper is silent or ambiguous):

* **Normalisation of D.** He et al. print the prefactor as :math:`\pi^2\tau^2/(4\lambda^2)`, which
  is :math:`(k\tau)^2/16` with :math:`k = 2\pi/\lambda`: dimensionless, as it must be. With it, the
  directional-diffuse lobe of a slightly rough surface integrates to
  :math:`|F|^2(1 - e^{-g})` near the specular direction: exactly the power the specular term
  lost (checked in the tests).
* **g uses the effective roughness** σ (He et al.: "σ is the effective roughness"), in both the
  specular attenuation and the series, never σ0; the shadowing and the effective roughness use σ0.
* **Effective roughness**: :math:`\sigma = \sigma_0 / \sqrt{1 + (z_0/\sigma_0)^2}` with
  :math:`\sqrt{\pi/2}\, z_0 = \tfrac{\sigma_0}{4}(K_i + K_r)\, e^{-z_0^2/(2\sigma_0^2)}`,
  :math:`K = \tan\theta\,\operatorname{erfc}(\tau\cot\theta / (2\sigma_0))`. Solved in closed
  form: :math:`(z_0/\sigma_0)^2 = W_0\big((K_i + K_r)^2/(8\pi)\big)` (Lambert W), so it is
  smooth and exactly differentiable (no iteration to differentiate through).
* **Shadowing** (Smith 1967 for the Gaussian surface of rms slope :math:`\sqrt2\sigma_0/\tau`):
  :math:`\Lambda = \tfrac12\big(e^{-a^2}/(a\sqrt\pi) - \operatorname{erfc}a\big)`,
  :math:`a = \tau\cot\theta/(2\sigma_0)`. He et al. use Smith's original
  :math:`S = (1 - \tfrac12\operatorname{erfc}a)/(1 + \Lambda)`; their printed eq. 25 omits
  the factor :math:`e^{-a^2}` in Λ, which the errata of Pacanowski & Holzschuch ("Demystifying
  the He, Torrance, Sillion and Greenberg BRDF") restore, as Radiance's ``He3.cal`` and the
  BRDF benchmark's ``he.h`` do — Λ here has it. The numerator is the probability that a facet
  faces the source, which a slope-averaged BRDF already accounts for, and the form that
  satisfies the projected-area identity of the Smith microsurface
  (:math:`\int G_1 D \langle\omega,m\rangle = \cos\theta`, Heitz 2014) is
  :math:`S = 1/(1 + \Lambda)`: ``shadowing="smith"`` is the former (He et al. with their
  erratum), ``"corrected"`` (default) the latter (Heitz's normalised Smith form, not an erratum
  of He's). They agree within 1 % below 60° and differ by 9 % (σ0 = 25 nm) and 35 % (σ0 = 50
  nm) at 80°, τ = 300 nm. Both are even in the two directions, so reciprocity holds either way.
* **Amplitude η** (never defined by Hirayama): the specular amplitude of the rough boundary is
  the coherent (mean) reflected field, :math:`\eta_s = r\,e^{-g/2}\,S(\theta)` per polarization
  (:math:`e^{-g/2} = \langle e^{i v_z h}\rangle` for Gaussian heights; :math:`|\eta_s|^2` is He's
  specular term). The diffuse "amplitude" :math:`\eta_d = \sqrt{\rho_\text{dd}}` per
  polarization carries no phase: the diffuse field of a random surface has a random phase,
  and Hirayama's eqs. 15–17 only ever multiply it, so only :math:`|\eta_d|^2` matters.
* **Inside a film** the same formulas hold in the medium *a* above the substrate: the
  wavenumber is :math:`k = 2\pi n_a/\lambda` and the angles are those in medium *a*.

Energy. The model is a single-scattering Kirchhoff approximation, and it does not conserve
energy exactly. For a perfect mirror (:math:`|F| = 1`) the directional albedo (specular plus
:math:`\int\rho_\text{dd}\cos\theta_r\,d\omega_r`) exceeds 1 at oblique incidence. Measured with
corrected shadowing, τ = 300 nm, λ = 500 nm, on the incidence angles 0, 15, 30, 45, 60, 70, 75,
80, 85, 89° with the tests' Gauss–Legendre albedo (``tests/test_he_torrance.py``;
``test_albedo_of_perfect_mirror_is_not_bounded_by_one`` asserts the σ0/λ = 0.01 values at 0, 60
and 85° and the σ0/λ = 0.1 value at 75°):

* σ0/λ = 0.01: the excess is 4.9e-4 at 60° and grows to 5.4e-3 at 85°; the albedo stays
  below 1 from 0° to 45° (1 − 2.4e-5 at 0°) and at 89°;
* σ0/λ = 0.05: up to 5.3e-2 (75°);
* σ0/λ = 0.1: 9.4e-2 at 75° and 1.0e-1 at 70°;
* σ0/λ = 0.2: up to 5.6e-2 (70°).

For a lossless dielectric boundary (n = 1.33, 1.5, 2.4; σ0/λ = 0.01 to 0.3) the albedo stays
≤ 1 at every one of those angles (tested).
"""

from __future__ import annotations

import math
import warnings
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.special as jsp
import numpy as np

from .._base.custom_types import Array, Float, RealLike
from .._base.numerics import abs2, as_complex, safe_divide, sin_from_cos
from .._base.validate import (
    LayerstackError,
    LayerstackWarning,
    check_angle_deg,
    check_finite,
    check_nonnegative,
    check_unit_interval,
    is_concrete,
)
from .._kernels.fresnel import fresnel_amplitudes, normal_wavevector
from .._media.materials import as_material
from .._stacks.illumination import snell_invariant_from_cos

__all__ = [
    "HeTorrance",
    "he_torrance_brdf",
    "lambert_w0",
    "shadowing",
    "effective_roughness",
    "roughness_exponent",
    "scattering_vector",
    "geometric_factor",
    "distribution_series",
    "series_terms",
    "specular_amplitudes",
    "specular_attenuation",
    "directional_diffuse",
    "SHADOWING_FORMS",
]

SHADOWING_FORMS = ("corrected", "smith")
_COS_MIN = 1e-12  # grazing directions are evaluated at this cosine (the terms vanish there)
_A_MAX = 1e6  # a = τ cot θ/(2σ0) used for a smooth boundary (σ0 = 0) or normal incidence


# ----------------------------------------------------------------------------- Lambert W
@jax.custom_jvp
def lambert_w0(z):
    r"""Principal branch :math:`W_0(z)` of the Lambert function (:math:`W e^W = z`) for real
    ``z >= 0``, any shape: Winitzki's starting value and five Halley steps (float64 to rounding
    for 0 ≤ z ≤ 1e300; tested against :func:`scipy.special.lambertw`). Derivative
    :math:`1/(e^W(1 + W))`, exact (custom JVP)."""
    z = jnp.asarray(z)
    lg = jnp.log1p(z)
    w = lg * (1.0 - jnp.log1p(lg) / (2.0 + lg))
    for _ in range(5):
        ew = jnp.exp(w)
        f = w * ew - z
        w = w - f / (ew * (w + 1.0) - (w + 2.0) * f / (2.0 * w + 2.0))
    return w


@lambert_w0.defjvp
def _lambert_w0_jvp(primals, tangents):
    (z,), (dz,) = primals, tangents
    w = lambert_w0(z)
    return w, dz / (jnp.exp(w) * (1.0 + w))


# ----------------------------------------------------------------------------- geometry
def _cot_parameter(cos, sigma0, tau):
    r""":math:`a = \tau\cot\theta/(2\sigma_0)`; :data:`_A_MAX` (no shadowing) where σ0 = 0 or at
    normal incidence. Double-where: the untaken branch never divides by 0 (NaN-free gradient)."""
    den = 2.0 * sigma0 * sin_from_cos(cos)
    return jnp.where(den > 0, jnp.minimum(safe_divide(tau * cos, den), _A_MAX), _A_MAX)


def shadowing(cos, sigma0, tau, form: str = "corrected"):
    r"""Smith's shadowing/masking :math:`S(\theta)` of one direction (module docstring),
    dimensionless in [0, 1].

    ``cos``: cos θ in the medium above the boundary (≥ 0); ``sigma0``, ``tau``: nm; broadcast
    together. With :math:`a = \tau\cot\theta/(2\sigma_0)` the corrected form is written
    :math:`S = 2a\sqrt\pi / \big(a\sqrt\pi(2 - \operatorname{erfc}a) + e^{-a^2}\big)`, which equals
    :math:`1/(1+\Lambda)` and is smooth down to grazing incidence (S → 0). ``form="smith"``
    multiplies by :math:`1 - \tfrac12\operatorname{erfc}a` (He et al. with their erratum's
    :math:`e^{-a^2}` in Λ).
    """
    if form not in SHADOWING_FORMS:
        raise LayerstackError(f"shadowing must be one of {SHADOWING_FORMS}, got {form!r}")
    a = _cot_parameter(cos, sigma0, tau)
    erfc = jsp.erfc(a)
    rt = math.sqrt(math.pi)
    s = 2.0 * a * rt / (a * rt * (2.0 - erfc) + jnp.exp(-a * a))
    if form == "smith":
        s = s * (1.0 - 0.5 * erfc)
    return s


def effective_roughness(cos_i, cos_r, sigma0, tau):
    r"""He et al.'s effective roughness :math:`\sigma` (nm) of the illuminated and visible part
    of the surface: :math:`\sigma_0/\sqrt{1 + W_0(K^2/(8\pi))}`, :math:`K = K_i + K_r`,
    :math:`K = \tan\theta\operatorname{erfc}(\tau\cot\theta/(2\sigma_0))` (module docstring).
    Equals σ0 at normal incidence and for σ0 → 0; decreases towards grazing directions.
    Arguments broadcast together (cosines ≥ 0, lengths in nm)."""

    def k_term(cos):
        c = jnp.maximum(cos, _COS_MIN)
        return sin_from_cos(c) / c * jsp.erfc(_cot_parameter(c, sigma0, tau))

    k = k_term(cos_i) + k_term(cos_r)
    return sigma0 / jnp.sqrt(1.0 + lambert_w0(k * k / (8.0 * math.pi)))


def roughness_exponent(cos_i, cos_r, sigma, wavenumber):
    r"""He et al.'s :math:`g = [k\sigma(\cos\theta_i + \cos\theta_r)]^2` (dimensionless);
    ``sigma`` in nm (the effective roughness), ``wavenumber`` :math:`k = 2\pi n_a/\lambda` in 1/nm.
    The specular amplitude is attenuated by :math:`e^{-g/2}`."""
    return (wavenumber * sigma * (cos_i + cos_r)) ** 2


class ScatteringVector(NamedTuple):
    """Components of :math:`\\hat v = \\hat k_r - \\hat k_i` (unit wave vectors, dimensionless):
    ``vxy2`` = :math:`\\hat v_x^2 + \\hat v_y^2`, ``vz`` = :math:`\\cos\\theta_i + \\cos\\theta_r`,
    ``v2`` = :math:`|\\hat v|^2`."""

    vxy2: Float[Array, "*B"]
    vz: Float[Array, "*B"]
    v2: Float[Array, "*B"]


def scattering_vector(cos_i, cos_r, phi) -> ScatteringVector:
    r""":math:`\hat v` of incidence cosine ``cos_i``, reflection cosine ``cos_r`` and azimuth
    ``phi`` (radians, 0 = forward/specular side), broadcast together. Symmetric under
    ``cos_i <-> cos_r`` (reciprocity)."""
    sin_i, sin_r = sin_from_cos(cos_i), sin_from_cos(cos_r)
    vxy2 = sin_i * sin_i + sin_r * sin_r - 2.0 * sin_i * sin_r * jnp.cos(phi)
    vxy2 = jnp.maximum(vxy2, 0.0)
    vz = cos_i + cos_r
    return ScatteringVector(vxy2, vz, vxy2 + vz * vz)


def geometric_factor(v: ScatteringVector):
    r"""He et al.'s :math:`G = (\hat v\cdot\hat v / \hat v_z)^2` for natural light
    (dimensionless; :math:`4\cos^2\theta` in the specular direction)."""
    vz = jnp.maximum(v.vz, _COS_MIN)
    return (v.v2 / vz) ** 2


def series_terms(g_max: float, tol: float = 1e-15) -> int:
    """Number of terms of the D series (:func:`distribution_series`) that leaves a relative
    truncation error below ``tol`` for every g ≤ ``g_max``: the Poisson(g) mass above the last
    term, bounded with a Chernoff bound; rounded up to a multiple of 8 (fewer recompilations)."""
    g = max(float(g_max), 1e-6)
    log_mass = math.log(-math.expm1(-g))  # the whole series is <= 1 - e^{-g}
    m = int(math.ceil(g)) + 1
    # Chernoff: P(X >= m) <= e^{-g} (e g / m)^m for m > g, X ~ Poisson(g)
    while -g + m * (1.0 + math.log(g / m)) - log_mass > math.log(tol):
        m += 1
    return int(8 * math.ceil(m / 8))


def distribution_series(g, a2, n_terms: int):
    r""":math:`\sum_{m=1}^{M} \dfrac{g^m e^{-g}}{m!\,m}\exp(-a_2/m)` (dimensionless), the series of
    He et al.'s D without its prefactor; ``a2`` = :math:`(k\tau)^2\hat v_{xy}^2/4`. Terms are
    formed in log space (no overflow for any g); ``n_terms`` (static) from :func:`series_terms`.
    At g = 0 the series is exactly 0 with a finite gradient (double-where)."""
    m = np.arange(1, n_terms + 1, dtype=float)
    log_const = -np.array([math.lgamma(k + 1.0) for k in m]) - np.log(m)
    pos = g > 0
    g_safe = jnp.where(pos, g, 1.0)
    log_g = jnp.log(g_safe)[..., None]
    terms = jnp.exp(m * log_g - g_safe[..., None] + log_const - a2[..., None] / m)
    return jnp.where(pos, jnp.sum(terms, axis=-1), 0.0)


# ----------------------------------------------------------------------------- terms
def _fresnel_at(n_a, n_b, cos):
    """Fresnel amplitudes ``(r, t)`` ``(2, *B)`` from medium a (real n_a) onto b at cosine ``cos``
    in a (reuses :func:`layerstack_jax._kernels.fresnel.fresnel_amplitudes`)."""
    n_a = jnp.asarray(n_a).astype(complex)
    s = snell_invariant_from_cos(n_a, cos)
    q_a = n_a * as_complex(cos, n_a)
    q_b = normal_wavevector(n_b, s)
    return fresnel_amplitudes(n_a, q_a, jnp.asarray(n_b), q_b)


def specular_attenuation(n_a, cos, wavelength_nm, sigma0, tau, *, form: str = "corrected"):
    r"""Real factor :math:`e^{-g/2}S(\theta)` by which roughness scales the specular amplitude of a
    boundary seen from medium a (real index ``n_a``) at cosine ``cos``, vacuum wavelength
    ``wavelength_nm`` (nm), σ0 and τ (nm); broadcast together. 1 for σ0 = 0."""
    k = 2.0 * math.pi * n_a / wavelength_nm
    sigma = effective_roughness(cos, cos, sigma0, tau)
    g = roughness_exponent(cos, cos, sigma, k)
    return jnp.exp(-0.5 * g) * shadowing(cos, sigma0, tau, form)


def specular_amplitudes(n_a, n_b, cos, wavelength_nm, sigma0, tau, *, form: str = "corrected"):
    r"""Specular amplitude ratio :math:`\eta_s = r\,e^{-g/2}S(\theta)` of the rough boundary, per
    polarization, complex ``(2, *B)`` (s, p): the seed of Hirayama eq. 9.

    ``n_a``: real index of the medium of incidence; ``n_b``: complex index beyond; ``cos``: cos θ
    in medium a; ``wavelength_nm``: vacuum wavelength; σ0, τ in nm; all broadcast to ``*B``.
    For σ0 = 0 it is the Fresnel amplitude exactly."""
    r, _ = _fresnel_at(n_a, n_b, cos)
    return r * as_complex(specular_attenuation(n_a, cos, wavelength_nm, sigma0, tau, form=form), r)[None]


def directional_diffuse(n_a, n_b, cos_i, cos_r, phi, wavelength_nm, sigma0, tau, *, n_terms: int,
                        form: str = "corrected"):
    r"""He et al.'s directional-diffuse BRDF :math:`\rho_\text{dd}` (1/sr) per polarization,
    ``(2, *B)`` (s, p), from medium a (real ``n_a``) on medium b (complex ``n_b``).

    Arguments as in :func:`specular_amplitudes`, plus ``cos_i``, ``cos_r`` (cosines in medium a of
    the incidence and reflection directions) and ``phi`` (radians, 0 = forward side). Symmetric in
    ``cos_i <-> cos_r`` (reciprocal). ``n_terms`` (static): :func:`series_terms`.
    """
    ci, cr = jnp.maximum(cos_i, _COS_MIN), jnp.maximum(cos_r, _COS_MIN)
    v = scattering_vector(ci, cr, phi)
    k = 2.0 * math.pi * jnp.real(jnp.asarray(n_a)) / wavelength_nm
    sigma = effective_roughness(ci, cr, sigma0, tau)
    g = roughness_exponent(ci, cr, sigma, k)
    kt2 = (k * tau) ** 2
    d = kt2 / 16.0 * distribution_series(g, kt2 * v.vxy2 / 4.0, n_terms)
    geo = geometric_factor(v) * shadowing(ci, sigma0, tau, form) * shadowing(cr, sigma0, tau, form)
    cos_loc = jnp.clip(0.5 * jnp.sqrt(v.v2), 0.0, 1.0)
    r, _ = _fresnel_at(n_a, n_b, cos_loc)
    return abs2(r) * (geo * d / (math.pi * ci * cr))[None]


# ----------------------------------------------------------------------------- public
class HeTorrance(NamedTuple):
    """He–Torrance BRDF of a rough boundary, natural light, arrays ``(*angle, wl)``:
    ``specular``: reflectance (dimensionless) carried by the delta in the mirror direction of
    the incidence angle; ``directional_diffuse`` and ``uniform_diffuse``: BRDF in 1/sr."""

    specular: Float[Array, "*angle wl"]
    directional_diffuse: Float[Array, "*angle wl"]
    uniform_diffuse: Float[Array, "*angle wl"]

    @property
    def diffuse(self):
        """Directional plus uniform diffuse BRDF (1/sr)."""
        return self.directional_diffuse + self.uniform_diffuse


def check_roughness(sigma_nm, tau_nm) -> None:
    """σ0 ≥ 0 and τ > 0 (nm), finite; warns when σ0/τ > 0.5 (rms slope √2σ0/τ > 0.7: far outside the
    gentle slopes the Kirchhoff approximation of He et al. assumes)."""
    check_nonnegative("sigma_nm (rms roughness sigma0)", sigma_nm)
    check_finite("tau_nm (autocorrelation length)", tau_nm)
    if is_concrete(tau_nm) and np.any(np.asarray(tau_nm) <= 0):
        raise LayerstackError("tau_nm (autocorrelation length) must be > 0")
    if is_concrete((sigma_nm, tau_nm)) and np.any(np.asarray(sigma_nm) > 0.5 * np.asarray(tau_nm)):
        warnings.warn("sigma_nm / tau_nm > 0.5: rms slope beyond the gentle slopes the He-Torrance model assumes",
                      LayerstackWarning, stacklevel=3)


def check_scattering_inputs(incidence_deg, viewing_deg, azimuth_deg, sigma_nm, tau_nm, uniform_albedo) -> None:
    """The inputs every He–Torrance BRDF takes (:func:`he_torrance_brdf`,
    :func:`layerstack_jax.coated_rough`): polar angles in [0, 90] degrees, a finite azimuth
    (degrees), σ0 ≥ 0 and τ > 0 (nm, :func:`check_roughness`), an albedo in [0, 1]."""
    check_angle_deg("incidence_deg", incidence_deg, grazing=True)
    check_angle_deg("viewing_deg", viewing_deg, grazing=True)
    check_finite("azimuth_deg", azimuth_deg)
    check_roughness(sigma_nm, tau_nm)
    check_unit_interval("uniform_albedo", uniform_albedo)


def auto_terms(sigma_nm, wavelength_nm, n_a, n_terms) -> int:
    """``n_terms`` when given, else :func:`series_terms` for the largest g the inputs allow
    (:math:`(4\\pi n_a\\sigma_0/\\lambda_{min})^2`) when they are concrete, else 64 (g ≲ 25)."""
    if n_terms is not None:
        return int(n_terms)
    if is_concrete((sigma_nm, wavelength_nm, n_a)):
        g_max = float(np.max((4 * math.pi * np.max(np.real(np.asarray(n_a))) * np.asarray(sigma_nm)
                              / np.min(np.asarray(wavelength_nm))) ** 2))
        return series_terms(g_max)
    return 64


def he_torrance_brdf(
    wavelength_nm,
    incidence_deg: RealLike,
    viewing_deg: RealLike,
    azimuth_deg: RealLike = 0.0,
    *,
    n_substrate,
    sigma_nm: RealLike,
    tau_nm: RealLike,
    n_ambient: RealLike = 1.0,
    uniform_albedo: RealLike = 0.0,
    shadowing_form: str = "corrected",
    n_terms: int | None = None,
    polarized: bool = False,
) -> HeTorrance:
    r"""He–Torrance BRDF of a bare rough boundary (module docstring), natural light.

    Args:
        wavelength_nm: ``(wl,)`` vacuum wavelengths, nm.
        incidence_deg, viewing_deg: polar angles of the incident and the viewing direction in
            the ambient, degrees in [0, 90]; azimuth_deg: azimuth of the viewing direction from
            the forward (specular) side of the plane of incidence, degrees (0 = specular side,
            180 = back towards the source). The three broadcast to ``(*angle)``.
        n_substrate: index of the medium below (complex n + ik, a material, or an array on
            ``wl``); n_ambient: real index above.
        sigma_nm: rms roughness σ0 (nm, ≥ 0); tau_nm: autocorrelation length τ (nm, > 0).
            Both, and the wavelength, are differentiable.
        uniform_albedo: a in [0, 1] of the uniform-diffuse term :math:`a/\pi`.
        shadowing_form: ``"corrected"`` (default) or ``"smith"`` (He et al. as printed); static.
        n_terms: terms of the D series (static); default from :func:`series_terms` when the
            inputs are concrete.
        polarized: True returns arrays ``(*angle, 2, wl)``, axis −2 ``(s, p)`` (Fresnel factor
            of that polarization; the uniform term is unpolarized); default natural light.

    Returns:
        :class:`HeTorrance`, arrays ``(*angle, wl)`` (or ``(*angle, 2, wl)``).
    """
    wl = jnp.asarray(wavelength_nm)
    if wl.ndim != 1:
        raise LayerstackError(f"wavelength_nm must be 1-D, got shape {wl.shape}")
    check_finite("wavelength_nm", wl)
    if is_concrete(wl) and np.any(np.asarray(wl) <= 0):
        raise LayerstackError("wavelength_nm must be > 0")
    check_scattering_inputs(incidence_deg, viewing_deg, azimuth_deg, sigma_nm, tau_nm, uniform_albedo)
    if shadowing_form not in SHADOWING_FORMS:
        raise LayerstackError(f"shadowing_form must be one of {SHADOWING_FORMS}, got {shadowing_form!r}")
    n_b = as_material(n_substrate)(wl)
    n_a = as_material(n_ambient)(wl)
    if is_concrete(n_a) and np.any(np.imag(np.asarray(n_a)) != 0):
        raise LayerstackError("n_ambient must be real: light is incident from it")
    n_a = jnp.real(jnp.asarray(n_a))
    n_terms = auto_terms(sigma_nm, wl, n_a, n_terms)
    return _he_torrance_core(wl, jnp.asarray(incidence_deg), jnp.asarray(viewing_deg), jnp.asarray(azimuth_deg),
                             n_a, jnp.asarray(n_b), jnp.asarray(sigma_nm), jnp.asarray(tau_nm),
                             jnp.asarray(uniform_albedo), n_terms, shadowing_form, bool(polarized))


@eqx.filter_jit
def _he_torrance_core(wl, incidence_deg, viewing_deg, azimuth_deg, n_a, n_b, sigma_nm, tau_nm, uniform_albedo,
                      n_terms: int, shadowing_form: str, polarized: bool) -> HeTorrance:
    """Compiled body of :func:`he_torrance_brdf` (inputs validated there)."""
    dtype = jnp.result_type(wl.dtype, float)
    ti, to, ph = jnp.broadcast_arrays(*(jnp.deg2rad(x.astype(dtype)) for x in (incidence_deg, viewing_deg, azimuth_deg)))
    ci, co, ph = jnp.cos(ti)[..., None], jnp.cos(to)[..., None], ph[..., None]
    sigma0, tau = sigma_nm.astype(dtype), tau_nm.astype(dtype)
    eta = specular_amplitudes(n_a, n_b, ci, wl, sigma0, tau, form=shadowing_form)
    spec = abs2(eta)
    dd = directional_diffuse(n_a, n_b, ci, co, ph, wl, sigma0, tau, n_terms=n_terms, form=shadowing_form)
    if polarized:
        spec, dd = jnp.moveaxis(spec, 0, -2), jnp.moveaxis(dd, 0, -2)
    else:
        spec, dd = 0.5 * (spec[0] + spec[1]), 0.5 * (dd[0] + dd[1])
    shape = jnp.broadcast_shapes(spec.shape, dd.shape)
    ud = jnp.broadcast_to(uniform_albedo.astype(dtype) / math.pi, shape)
    return HeTorrance(jnp.broadcast_to(spec, shape), jnp.broadcast_to(dd, shape), ud)
