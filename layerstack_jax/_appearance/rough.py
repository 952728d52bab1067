r"""Rough top surface, "locally smooth": a microfacet specular lobe over a conformal coating.

Which model for which object. This module: a *conformal* coating that follows a rough surface
whose facets are much larger than the wavelength, each facet carrying the whole stack
(Cook–Torrance / GGX / Beckmann, geometric optics, no σ0/λ dependence).
:func:`layerstack_jax.coated_rough` (:mod:`layerstack_jax._appearance.coated_rough`, Hirayama et al. §4.2,
eqs. 8–17, with He–Torrance's rough boundary): a rough *object* under films whose boundaries
stay flat (roughness heights σ0 ≲ λ, correlation lengths τ ~ λ, where wave effects — the
e^{−g} specular loss growing as σ0/λ, the directional-diffuse lobe — matter); that is the
paper's model. Neither is the other's limit.

The top surface is made of microfacets much larger than the wavelength, each coated with the
whole (locally smooth, planar) stack. Light reflected by a facet whose normal is the half vector
:math:`h = (i + o)/|i + o|` sees the stack at the *microfacet angle*
:math:`\cos\theta_d = i\cdot h` (Cook & Torrance 1981; Walter et al. 2007):

.. math::
    f_\text{spec}(i, o) = \frac{D(h)\, G_2(i, o)\, R(\theta_d)}{4 \cos\theta_i \cos\theta_o},

with :math:`R` the stack's natural-light front reflectance (any stack: the Fresnel term is
the full coherent / incoherent recursion), :math:`D` the GGX (Trowbridge–Reitz) or Beckmann
distribution of normals of roughness :math:`\alpha` (rms slope ~ α), and :math:`G_2` the
height-correlated Smith shadowing–masking :math:`1/(1 + \Lambda(i) + \Lambda(o))`.

The light that the facets transmit feeds the Lambertian background exactly as for a smooth
stack (Simonot eqs. 77–79), with the collimated transmittance :math:`\bar T(\theta)` replaced by
its rough counterpart, the transmittance of the facets seen from *i*, weighted by the visible
normal distribution:

.. math::
    E(\theta_i) = \int D(h)\, G_1(i, h)\, \frac{\max(0, i\cdot h)}{\cos\theta_i}\,
                  \bar T(\theta_d)\, d\omega_h,\qquad
    f_\text{diff} = K\, E(\theta_i)\, E(\theta_o),

:math:`K` as in :mod:`layerstack_jax._instruments.polarimetry` with the back-side reflectance of the rough
top (:func:`_rough_background_factor`). Energy: since
:math:`\int D G_1 \max(0, i\cdot h)/\cos\theta_i\, d\omega_h = 1` and :math:`G_2 \le G_1`,
:math:`R + \bar T \le 1` on each facet, the directional albedo
:math:`\int (f_\text{spec} + f_\text{diff}) \cos\theta_o\, d\omega_o \le 1` (white furnace;
light shadowed by the facets is lost, as in every single-scattering microfacet model). As
:math:`\alpha \to 0`, :math:`D` tends to a delta around the mean normal, the lobe integrates to
:math:`R(\theta_i)` and :math:`E \to \bar T`: the smooth model.

Natural light only (a polarized microfacet model needs the rotation of the s/p frames from each
facet to the plane of incidence). Roughness must be > 0; use the smooth functions for α = 0.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax.numpy as jnp
import jax.scipy.special as jsp
import numpy as np

from .._base.custom_types import Array, Float, RealLike, Spectrum
from .._base.programs import public_program
from .._base.validate import LayerstackError, check_angle_deg, check_finite, is_concrete
from .._kernels.fresnel import exit_medium_ratio
from .._kernels.quadrature import DEFAULT_NODES, unit_rule
from .._stacks.illumination import diffuse_resolved, snell_invariant_from_cos
from .._stacks.recursion import natural, stack_intensities
from .._stacks.stack import ResolvedStack, Stack, resolve

__all__ = ["RoughBRDF", "rough_brdf", "microfacet_distribution", "smith_lambda"]

_DISTRIBUTIONS = ("ggx", "beckmann")


class RoughBRDF(NamedTuple):
    """Natural-light BRDF of a stack with a rough top, in 1/sr, fields shaped ``(*angle, wl)``:
    ``specular`` (microfacet lobe), ``diffuse`` (Lambertian background through the rough
    stack; zeros over a substrate). :attr:`total` is their sum."""

    specular: Float[Array, "*angle wl"]
    diffuse: Float[Array, "*angle wl"]

    @property
    def total(self):
        return self.specular + self.diffuse


def _tan2(cos):
    c2 = jnp.clip(cos * cos, 1e-300, 1.0)
    return (1.0 - c2) / c2


def microfacet_distribution(cos_h, alpha, distribution: str = "ggx"):
    r"""Normal distribution :math:`D(h)` (1/sr), normalized as :math:`\int D\cos\theta_h d\omega_h = 1`.

    GGX: :math:`\alpha^2/(\pi\cos^4\theta_h(\alpha^2 + \tan^2\theta_h)^2)`;
    Beckmann: :math:`\exp(-\tan^2\theta_h/\alpha^2)/(\pi\alpha^2\cos^4\theta_h)`.

    ``cos_h``: cosine of the half-vector's polar angle (dimensionless); ``alpha``: roughness
    (dimensionless slope parameter); broadcast against each other to ``(*B)``. Returns D in
    1/sr, shape ``(*B)``. ``distribution``: ``'ggx'`` or ``'beckmann'``.
    """
    t2 = _tan2(cos_h)
    c4 = jnp.clip(cos_h, 1e-150, 1.0) ** 4
    a2 = alpha * alpha
    if distribution == "ggx":
        return a2 / (jnp.pi * c4 * (a2 + t2) ** 2)
    if distribution == "beckmann":
        return jnp.exp(-t2 / a2) / (jnp.pi * a2 * c4)
    raise LayerstackError(f"distribution must be one of {_DISTRIBUTIONS}, got {distribution!r}")


def smith_lambda(cos_v, alpha, distribution: str = "ggx"):
    r"""Smith's :math:`\Lambda` of a direction at polar cosine ``cos_v`` (:math:`G_1 = 1/(1+\Lambda)`).

    GGX: :math:`(-1 + \sqrt{1 + \alpha^2\tan^2\theta})/2`; Beckmann, with
    :math:`a = 1/(\alpha\tan\theta)`: :math:`(\operatorname{erf}(a) - 1)/2 + e^{-a^2}/(2a\sqrt\pi)`.

    ``cos_v`` and ``alpha`` (both dimensionless) broadcast against each other to ``(*B)``;
    returns Λ ≥ 0, dimensionless, shape ``(*B)`` (0 at normal incidence).
    """
    t2 = _tan2(cos_v)
    if distribution == "ggx":
        return 0.5 * (jnp.sqrt(1.0 + alpha * alpha * t2) - 1.0)
    if distribution == "beckmann":
        pos = t2 > 0
        a = jnp.where(pos, 1.0 / (alpha * jnp.sqrt(jnp.where(pos, t2, 1.0))), 1.0)
        lam = 0.5 * (jsp.erf(a) - 1.0) + jnp.exp(-a * a) / (2.0 * a * jnp.sqrt(jnp.pi))
        return jnp.where(pos & (a < 30.0), lam, 0.0)
    raise LayerstackError(f"distribution must be one of {_DISTRIBUTIONS}, got {distribution!r}")


def _natural_R_T(rs: ResolvedStack, cos_d):
    """Natural-light R and T of the stack at facet incidence cosine ``cos_d`` (``(*B)``) → ``(*B, wl)``."""
    out = stack_intensities(rs, snell_invariant_from_cos(rs.n[0], cos_d[..., None]), both_sides=False)
    return natural(out.R_front), natural(out.T_front)


def _facet_rule(alpha, distribution: str, n_u: int, n_phi: int):
    """Half vectors sampled by the slope distribution: ``(cos θh, sin θh, φ, weight)`` on a
    ``(n_u, n_phi)`` grid with ``Σ weight · g = ∫ P22(m) g d²m`` over slopes (φ ∈ [0, π], the
    integrands below are even in φ)."""
    v, wv = np.polynomial.legendre.leggauss(n_u)
    v, wv = 0.5 * (v + 1.0), 0.5 * wv
    u = 1.0 - (1.0 - v) ** 2  # clusters nodes at u -> 1 (steep facets)
    wu = wv * 2.0 * (1.0 - v)
    p, wp = np.polynomial.legendre.leggauss(n_phi)
    phi = 0.5 * np.pi * (p + 1.0)
    wphi = 0.5 * np.pi * wp
    if distribution == "ggx":
        r = jnp.sqrt(u / (1.0 - u))
    elif distribution == "beckmann":
        r = jnp.sqrt(-jnp.log1p(-u))
    else:
        raise LayerstackError(f"distribution must be one of {_DISTRIBUTIONS}, got {distribution!r}")
    tan_h = alpha * r[:, None]
    cos_h = 1.0 / jnp.sqrt(1.0 + tan_h * tan_h)
    sin_h = tan_h * cos_h
    w = (wu[:, None] * wphi[None, :]) / np.pi  # measure du dφ / (2π), doubled for φ ∈ [0, π]
    return cos_h, sin_h, jnp.asarray(phi)[None, :], jnp.asarray(w)


def _rough_transmittance(rs: ResolvedStack, theta, *, alpha, distribution: str, n_u: int, n_phi: int):
    r""":math:`E(\theta)` of the module docstring, ``(*angle, wl)``; normalized by the quadrature's
    own estimate of :math:`\int D G_1 \max(0, i\cdot h)/\cos\theta\, d\omega_h` (= 1), so that
    :math:`E \le 1` holds to rounding."""
    cos_h, sin_h, phi, w = _facet_rule(alpha, distribution, n_u, n_phi)  # (u, phi)
    th = theta[..., None, None]
    cos_i, sin_i = jnp.cos(th), jnp.sin(th)
    i_dot_h = sin_i * sin_h * jnp.cos(phi) + cos_i * cos_h
    vis = jnp.maximum(i_dot_h, 0.0)
    g1 = 1.0 / (1.0 + smith_lambda(cos_i, alpha, distribution))
    weight = w * g1 * vis / cos_h  # (*angle, u, phi); the 1/cos θi cancels in the ratio
    _, T = _natural_R_T(rs, jnp.clip(i_dot_h, 0.0, 1.0))  # (*angle, u, phi, wl)
    num = jnp.sum(weight[..., None] * T, axis=(-3, -2))
    den = jnp.sum(weight, axis=(-2, -1))[..., None]
    return num / den


def _rough_background_factor(rs: ResolvedStack, E, nodes: int) -> Spectrum:
    r""":math:`K` of the diffuse part with the rough top's back-side reflectance, ``(wl,)``.

    The rough top changes the diffuse exchange with the background: its diffuse front
    transmittance is :math:`t_f' = \int_0^1 E(\mu)\, d\mu` (:math:`\mu = \sin^2\theta` in the
    ambient), the back-side one :math:`t_b' = (n_0/n_g)^2 t_f'` (reciprocity, Simonot eqs. 8–10
    generalized), and we take the absorption of the diffuse flux from below as unchanged:
    :math:`r_b' = r_b + t_b - t_b'` (smooth :math:`r_b, t_b`). For a lossless stack this is exact
    energy bookkeeping, :math:`r_b' = 1 - t_b'`, which makes the white-furnace albedo
    :math:`\le 1`; as α → 0, :math:`E \to \bar T` and :math:`r_b' \to r_b`.
    """
    d = diffuse_resolved(rs, "back", nodes)
    x, w = unit_rule(nodes)
    theta = jnp.arcsin(jnp.sqrt(jnp.asarray(x)))
    t_f = jnp.sum(jnp.asarray(w)[:, None] * E(theta), axis=0)
    ratio = exit_medium_ratio(rs.n[0], rs.n[-1])
    t_b = ratio * t_f
    r_b = jnp.clip(d.r + d.t - t_b, 0.0, 1.0)
    rho = rs.rho_g
    return ratio * rho / (jnp.pi * (1.0 - rho * r_b))


@public_program
def rough_brdf(
    stack: Stack,
    wavelength_nm,
    incidence_deg: RealLike,
    viewing_deg: RealLike,
    azimuth_deg: RealLike = 180.0,
    *,
    roughness: RealLike,
    distribution: str = "ggx",
    nodes: int = DEFAULT_NODES,
    facet_nodes: int = 32,
    include_diffuse: bool = True,
) -> RoughBRDF:
    r"""Natural-light BRDF (1/sr) of a stack with a rough, locally smooth top (module docstring).

    Args:
        stack: any stack; over a :class:`~layerstack_jax.LambertianBackground` the diffuse
            part is included, over a substrate it is zero.
        wavelength_nm: ``(wl,)`` nm.
        incidence_deg, viewing_deg: polar angles in [0, 90) degrees.
        azimuth_deg: azimuth of the viewing direction relative to the incidence direction;
            180° is the plane of specular reflection (Ellis's :math:`\phi_r = \phi_i + \pi`).
            The three angles broadcast to ``(*angle)``.
        roughness: α > 0 of the GGX / Beckmann distribution (~ rms slope); traced, can be fitted.
        distribution: 'ggx' (default) or 'beckmann'; static.
        nodes: quadrature nodes per segment for the background's back-side reflectance.
        facet_nodes: nodes per axis of the half-vector quadrature of the rough transmittance E
            (memory ~ angles × facet_nodes² × wl: chunk long angle lists).
        include_diffuse: False skips the diffuse part (returned as zeros); static.

    Returns:
        :class:`RoughBRDF` with fields ``(*angle, wl)``.
    """
    if distribution not in _DISTRIBUTIONS:
        raise LayerstackError(f"distribution must be one of {_DISTRIBUTIONS}, got {distribution!r}")
    incidence_deg = check_angle_deg("incidence_deg", incidence_deg)
    viewing_deg = check_angle_deg("viewing_deg", viewing_deg)
    azimuth_deg = check_finite("azimuth_deg", azimuth_deg)
    if is_concrete(roughness) and np.any(np.asarray(roughness) <= 0):
        raise LayerstackError("roughness must be > 0 (use the smooth functions for a mirror-flat top)")
    rs = resolve(stack, wavelength_nm)
    ti, to, ph = jnp.broadcast_arrays(
        *(jnp.deg2rad(jnp.asarray(x, dtype=float)) for x in (incidence_deg, viewing_deg, azimuth_deg))
    )
    alpha = jnp.asarray(roughness, dtype=ti.dtype)
    i = jnp.stack([jnp.sin(ti), jnp.zeros_like(ti), jnp.cos(ti)])
    o = jnp.stack([jnp.sin(to) * jnp.cos(ph), jnp.sin(to) * jnp.sin(ph), jnp.cos(to)])
    hv = i + o
    h = hv / jnp.linalg.norm(hv, axis=0)  # i + o != 0: both in the upper hemisphere
    cos_d = jnp.clip(jnp.sum(i * h, axis=0), 0.0, 1.0)
    D = microfacet_distribution(h[2], alpha, distribution)
    G2 = 1.0 / (1.0 + smith_lambda(i[2], alpha, distribution) + smith_lambda(o[2], alpha, distribution))
    R, _ = _natural_R_T(rs, cos_d)
    spec = (D * G2 / (4.0 * i[2] * o[2]))[..., None] * R
    if include_diffuse and rs.rho_g is not None:
        E = functools.partial(_rough_transmittance, rs, alpha=alpha, distribution=distribution, n_u=facet_nodes, n_phi=facet_nodes)
        diff = _rough_background_factor(rs, E, nodes) * E(ti) * E(to)
    else:
        diff = jnp.zeros_like(spec)
    return RoughBRDF(spec, jnp.broadcast_to(diff, spec.shape))
