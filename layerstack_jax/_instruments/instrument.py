r"""Spectrophotometers as they are built: the pieces of a non-ideal instrument that the geometries
of :mod:`layerstack_jax._instruments.geometry` (:class:`~layerstack_jax.Sphere`,
:class:`~layerstack_jax.Directional`) add to the ideal readings of Simonot et al. (eqs. 69, 77–79).
Pure functions of static node counts and traced numbers (every number here is a differentiable
leaf of the geometry: fittable with ``fitting.instrument``).

* :func:`cone_rule` — fixed Gauss–Legendre directions over a cone of half-angle β about a
  direction at polar angle θ_a: the specular port of a sphere (the diffuse light leaving into
  the port is lost in SCE), the illumination and viewing apertures of a 45/0 instrument.
* :func:`cone_projected_solid_angle` — its closed form :math:`\int_\text{cone}\cos\theta\,d\Omega
  = \pi\cos\theta_a\sin^2\beta` (the cone above the horizon).
* :func:`substituted_reading` — the single-beam sphere multiplier: what a sphere of wall
  reflectance ρ_w with ports reads for a sample when it is calibrated on a reference standard.
* :func:`covered` — the sample behind a cover glass: the glass (and an air gap) prepended to the
  resolved stack as thick, incoherent layers, so that the engine computes it exactly.

Angles are degrees, thicknesses nm, α in 1/nm, reflectances dimensionless.
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

from .._base.custom_types import Array, Float, RealLike
from .._base.numerics import as_complex, safe_sqrt
from .._base.validate import check, check_nonnegative, check_positive, is_concrete
from .._stacks.stack import ResolvedStack, as_spectrum

__all__ = ["cone_rule", "cap_measure", "cone_projected_solid_angle", "substituted_reading", "covered",
           "check_cone", "GAP_NM", "DEFAULT_CONE_NODES"]

#: Gauss–Legendre nodes across a cone's radius (the azimuth gets twice as many: 2·8² = 128
#: directions). Measured against scipy ``dblquad`` of the library's own point
#: readings, a 180 nm film on a 20 µm varnish (α = 2e-5/nm) over a background: port cones of
#: 5°, 12°, 25° about 8° and 10° about 30°, max error 6e-12, 2e-10, 5e-9, 1.3e-9 with 2 nodes,
#: ≤ 6e-15 with 4, ≤ 5e-17 from 6 on; a 10° illumination cone at 45°: 9e-8 (2), 1.6e-12 (4),
#: 5e-16 (6). T(θ) with angular fringes needs more: a 3 µm coherent film (n = 1.8) on that
#: varnish, a 10° cone about 45°: 6e-8 (4), 1.9e-9 (6), 7e-11 (8), 3e-14 (12) — hence 8.
#: Cost: 2 nodes² directions per cone (128 with 8), each one Fresnel evaluation of the stack.
DEFAULT_CONE_NODES = 8

#: Thickness (nm) of the air gap between a cover glass and the sample: any value gives the same
#: reading (a thick, non-absorbing layer adds intensities; no interference, no attenuation).
GAP_NM = 1.0e5


@functools.lru_cache(maxsize=None)
def _unit_cone_nodes(nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(x, φ, w)`` of the product rule on x ∈ [0, 1] (``nodes`` Gauss–Legendre nodes) × φ ∈
    [0, π] (``2 nodes``), flattened to ``(K,)``, K = 2 nodes²; ``w`` includes the factor 2 of
    the mirror half φ ∈ [π, 2π] (the integrands are even in φ), so ``sum(w) = 2π``."""
    v, wv = np.polynomial.legendre.leggauss(nodes)
    p, wp = np.polynomial.legendre.leggauss(2 * nodes)
    x, wx = 0.5 * (v + 1.0), 0.5 * wv
    phi, wphi = 0.5 * np.pi * (p + 1.0), 0.5 * np.pi * wp
    X, PHI = np.meshgrid(x, phi, indexing="ij")
    W = 2.0 * np.outer(wx, wphi)
    return X.ravel(), PHI.ravel(), W.ravel()


def cone_rule(axis_deg: RealLike, half_angle_deg: RealLike, nodes: int = DEFAULT_CONE_NODES):
    r"""Directions and weights of a fixed product rule over the cone of half-angle β
    (``half_angle_deg``) about the direction at polar angle θ_a (``axis_deg``), degrees.

    A direction of the cone is at angle ψ ≤ β from the axis and azimuth φ about it; its polar
    angle θ from the surface normal follows from

    .. math::
        \cos\theta = \cos\psi\cos\theta_a - \sin\psi\cos\varphi\sin\theta_a,\qquad
        \sin^2\theta = (\cos\psi\sin\theta_a + \sin\psi\cos\varphi\cos\theta_a)^2
                       + \sin^2\psi\sin^2\varphi .

    The radius is mapped to equal areas, :math:`1-\cos\psi = x\,(1-\cos\beta)` with x ∈ [0, 1],
    so that :math:`d\Omega = (1-\cos\beta)\,dx\,d\varphi`, written with half angles
    (:math:`\sin(\psi/2) = \sqrt{x}\sin(\beta/2)`) to stay smooth in β down to β = 0; then
    Gauss–Legendre in x and in φ ∈ [0, π] (integrands that depend on θ only are even in φ).

    Args:
        axis_deg: polar angle of the cone's axis, ``(*angle)``.
        half_angle_deg: β, broadcastable with ``axis_deg``; the cone must lie above the horizon
            (θ_a + β < 90°, checked by the geometries).
        nodes: static; ``nodes`` × ``2 nodes`` directions, K = 2 nodes².

    Returns:
        ``(cos θ, sin θ, w)``, each ``(*angle, K)``: :math:`\int_\text{cone} g(\theta)\,d\Omega
        \approx (1-\cos\beta)\sum_k w_k\, g(\theta_k)`, :math:`\sum_k w_k = 2\pi`. Multiply by
        :math:`1-\cos\beta = 2\sin^2(\beta/2)` for solid-angle weights (sr); a normalised
        average needs no such factor (it cancels, also at β = 0).
    """
    X, PHI, W = _unit_cone_nodes(nodes)
    a = jnp.deg2rad(jnp.asarray(axis_deg))[..., None]
    h = jnp.sin(0.5 * jnp.deg2rad(jnp.asarray(half_angle_deg)))[..., None]
    sin_half = np.sqrt(X) * h
    cos_half = jnp.sqrt(1.0 - X * h * h)
    sin_psi, cos_psi = 2.0 * sin_half * cos_half, 1.0 - 2.0 * X * h * h
    cos_t = cos_psi * jnp.cos(a) - sin_psi * np.cos(PHI) * jnp.sin(a)
    along = cos_psi * jnp.sin(a) + sin_psi * np.cos(PHI) * jnp.cos(a)
    across = sin_psi * np.sin(PHI)
    sin_t = safe_sqrt(along * along + across * across)  # zero derivative at the normal, not NaN
    shape = jnp.broadcast_shapes(cos_t.shape, sin_t.shape)
    return jnp.broadcast_to(cos_t, shape), jnp.broadcast_to(sin_t, shape), jnp.broadcast_to(jnp.asarray(W), shape)


def cap_measure(half_angle_deg: RealLike) -> Float[Array, "..."]:
    r""":math:`1-\cos\beta = 2\sin^2(\beta/2)`: the solid angle of a cone of half-angle β over 2π."""
    return 2.0 * jnp.sin(0.5 * jnp.deg2rad(jnp.asarray(half_angle_deg))) ** 2


def cone_projected_solid_angle(axis_deg: RealLike, half_angle_deg: RealLike) -> Float[Array, "..."]:
    r"""Closed form :math:`\int_\text{cone}\cos\theta\,d\Omega = \pi\cos\theta_a\sin^2\beta` (sr)
    of a cone of half-angle β about polar angle θ_a (degrees) above the horizon (θ_a + β ≤ 90°):
    the :math:`\sin\psi\cos\varphi` term of :math:`\cos\theta` (:func:`cone_rule`) integrates to
    zero over φ, leaving :math:`2\pi\cos\theta_a\int_0^\beta\cos\psi\sin\psi\,d\psi`. Divided by
    π: the fraction of a Lambertian (constant-radiance) exitance that leaves into the cone."""
    a, b = jnp.deg2rad(jnp.asarray(axis_deg)), jnp.deg2rad(jnp.asarray(half_angle_deg))
    return jnp.pi * jnp.cos(a) * jnp.sin(b) ** 2


def substituted_reading(first: RealLike, diffuse: RealLike, wall: RealLike, sample_port: RealLike,
                        open_ports: RealLike, reference: RealLike) -> Float[Array, "..."]:
    r"""What a single-beam integrating sphere reads for a sample, calibrated on a reference
    standard in the same port (the substitution method; the sphere multiplier of the Labsphere
    technical guide "A guide to integrating sphere theory and applications", §1.4, and of Hanssen
    & Snail, "Integrating spheres for mid- and near-infrared reflection spectroscopy", Handbook
    of Vibrational Spectroscopy, 2002, §3 "substitution error"):

    .. math::
        R_\text{read} = \rho_s\;
        \frac{1 - \rho_w (1 - f_s - f_h) - \rho_\text{ref} f_s}
             {1 - \rho_w (1 - f_s - f_h) - \rho'_s f_s}.

    The beam reflected by the sample (first reflection ρ_s, the ideal reading) is spread over
    the sphere; each further bounce returns the fraction :math:`\bar\rho = \rho_w f_w + \rho'_s
    f_s` (wall of reflectance ρ_w over the area fraction :math:`f_w = 1 - f_s - f_h`, the
    sample over its port's fraction f_s, nothing from the open ports f_h), so the wall radiance
    the detector sees is :math:`\propto \rho_s/(1-\bar\rho)`. The reading is that ratio for the
    sample over the same for the reference standard (reflectance ρ_ref, in the sample port
    during calibration), times ρ_ref. :math:`\rho'_s` is the sample's reflectance for the
    diffuse light of the sphere wall (Lambertian illumination); f_s = 0 reads ρ_s exactly.

    Args (broadcast together; dimensionless):
        first: ρ_s, the ideal reading (first reflection of the beam into the sphere).
        diffuse: ρ'_s, the sample's reflectance for Lambertian light.
        wall: ρ_w in [0, 1]; sample_port: f_s, open_ports: f_h (area fractions of the sphere);
        reference: ρ_ref, the reflectance of the calibration standard.
    """
    base = 1.0 - wall * (1.0 - sample_port - open_ports)
    return first * (base - reference * sample_port) / (base - diffuse * sample_port)


def covered(rs: ResolvedStack, index, thickness_nm: RealLike, alpha_per_nm: RealLike,
            contact: bool) -> ResolvedStack:
    r"""``rs`` seen through a cover glass: the glass (index ``index``, a number, an array on the
    grid or a callable of the wavelength in nm; thickness ``thickness_nm``; absorption
    coefficient ``alpha_per_nm`` in 1/nm, Beer's law as Simonot eq. 20) is inserted after the
    ambient as a thick, incoherent layer, followed by an air gap (a thick layer of the ambient's
    index, :data:`GAP_NM` thick: its thickness does not matter) unless ``contact`` (the glass in
    optical contact with the first layer or the exit medium, e.g. through an index-matching
    liquid of the glass's index). The engine then treats the stack exactly (mixed coherent /
    incoherent stacks, Simonot eqs. 59–60); the result equals the stack with those layers
    written out. Checked (eagerly, or at run time under ``jit``): index real part > 0,
    thickness ≥ 0, α ≥ 0."""
    wl = rs.wavelength
    n_cover = check_positive("cover glass index (cover_index)", jnp.real(jnp.asarray(as_spectrum(index, wl))))
    n_cover = as_complex(n_cover, rs.n[0])
    d = jnp.asarray(check_nonnegative("cover glass thickness (cover_thickness_nm, nm)", thickness_nm))
    alpha = jnp.asarray(check_nonnegative("cover glass alpha (cover_alpha_per_nm, 1/nm)", alpha_per_nm))
    if contact:
        media, ds, alphas, coh = (n_cover,), (d,), (alpha,), (False,)
    else:
        gap = jnp.asarray(GAP_NM, dtype=jnp.real(jnp.asarray(rs.n[0])).dtype)
        media, ds, alphas, coh = (n_cover, rs.n[0]), (d, gap), (alpha, None), (False, False)
    return rs._replace(n=(rs.n[0], *media, *rs.n[1:]), d=(*ds, *rs.d), alpha=(*alphas, *rs.alpha),
                       coherent=(*coh, *rs.coherent))


def check_cone(name: str, axis_deg, half_angle_deg):
    """β (``half_angle_deg``, named ``name``) in [0, 90°) with the cone above the horizon,
    θ_a + β < 90° — eagerly, or at run time under ``jit``; returned broadcast against
    ``axis_deg`` (use the returned value: it carries the traced check)."""
    if is_concrete((axis_deg, half_angle_deg)):
        b = np.asarray(half_angle_deg, float) + 0.0 * np.asarray(axis_deg, float)
        axis = np.asarray(axis_deg, float)
    else:
        b = jnp.asarray(half_angle_deg) + 0.0 * jnp.asarray(axis_deg)
        axis = jnp.asarray(axis_deg)
    return check(name, b, lambda x, xp: ~xp.isfinite(x) | (x < 0) | (x + axis >= 90),
                 "must be >= 0 and keep the cone above the horizon (axis angle + half-angle < 90 degrees)")
