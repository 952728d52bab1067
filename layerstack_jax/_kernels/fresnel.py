r"""Interface optics: branch-safe normal wavevector and Fresnel amplitude coefficients.

Conventions (fixed here for the whole package)
------------------------------------------------
* Time dependence :math:`e^{-i\omega t}`; complex index :math:`\tilde n = n + ik` with
  :math:`k \ge 0` for an absorbing medium.
* The angle travels through a stack as the Snell invariant :math:`s = n_0 \sin\theta_0`
  (Simonot et al. eqs. 1, 24). In medium *j* we never form :math:`\theta_j` itself; we use the
  *normal wavevector ratio* :math:`q_j = \tilde n_j \cos\theta_j = \sqrt{\tilde n_j^2 - s^2}`.
* Branch (PHYSICS.md, trap 1): the root with :math:`\operatorname{Im} q \ge 0` (a forward wave that
  decays, or an evanescent wave beyond the critical angle) and :math:`\operatorname{Re} q \ge 0`
  when :math:`\operatorname{Im} q = 0`.
* Fresnel amplitudes follow Born & Wolf / the ``tmm`` package: for p the ratio of electric fields
  with the sign convention of ``tmm.interface_r``, in which :math:`r_p = -r_s` at normal
  incidence (so the ellipsometric :math:`\Delta` is 180° there; :mod:`layerstack_jax._instruments.ellipsometry`).
* Polarization axis: index 0 is *s* (TE, perpendicular), index 1 is *p* (TM, parallel).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax

from .._base.custom_types import Array, Complex, ComplexLike, Float, RealLike
from .._base.numerics import as_complex

__all__ = [
    "normal_wavevector",
    "fresnel_amplitudes",
    "divide",
    "reciprocal",
    "power_flux",
    "exit_medium_ratio",
]


@jax.custom_jvp
def _forward_sqrt(z):
    r"""The root of ``z`` with Im ≥ 0 (Re ≥ 0 when Im = 0): the decaying branch. Written out in
    real arithmetic (Kahan's form: :math:`a = \sqrt{(|z| + |x|)/2}`, the other part
    :math:`|y|/2a`, no cancellation), which XLA vectorizes; its complex ``sqrt`` goes through
    ``atan2``, sine and cosine (P1: 5× the time). Equal to the principal root to ~1 ulp, with
    the sign of both parts flipped where its imaginary part would be negative (y < 0)."""
    x, y = jnp.real(z), jnp.imag(z)
    a = jnp.sqrt(0.5 * (jnp.hypot(x, y) + jnp.abs(x)))
    b = 0.5 * jnp.abs(y) / jnp.where(a == 0, 1.0, a)
    re, im = jnp.where(x >= 0, a, b), jnp.where(x >= 0, b, a)
    return lax.complex(jnp.where(y < 0, -re, re), im)


@_forward_sqrt.defjvp
def _forward_sqrt_jvp(primals, tangents):
    (z,), (dz,) = primals, tangents
    w = _forward_sqrt(z)
    # d sqrt(z) = dz / (2 sqrt z). At the branch point z = 0 (exactly the critical angle) the
    # derivative is infinite; we return 0 there instead of inf/NaN (PHYSICS.md, trap 3).
    zero = w == 0
    w_safe = jnp.where(zero, jnp.ones_like(w), w)
    return w, jnp.where(zero, jnp.zeros_like(w), dz / (2 * w_safe))


def normal_wavevector(n: ComplexLike, s: RealLike) -> Complex[Array, "..."]:
    r"""Normal wavevector ratio :math:`q = \tilde n \cos\theta = \sqrt{\tilde n^2 - s^2}`.

    Args:
        n: complex index of the medium (dimensionless), any shape.
        s: Snell invariant :math:`n_0 \sin\theta_0` (real, dimensionless; θ0 in radians inside
            the sine), broadcastable against ``n``.

    Returns:
        Complex, dimensionless array of the broadcast shape of ``n`` and ``s``, with
        :math:`\operatorname{Im} q \ge 0` (forward, decaying wave; purely
        imaginary past the critical angle of a lossless medium).
    """
    n = as_complex(n, jnp.complex64)
    s = as_complex(jnp.asarray(s), n)
    # (n - s)(n + s), not n² - s²: exactly 0 at a critical angle or grazing incidence (s = n)
    # however the compiler contracts the products (a fused multiply-add leaves the rounding
    # error of s², ~1e-16, and q ~ 1e-8 where it must be 0)
    return _forward_sqrt((n - s) * (n + s))


def divide(num: ComplexLike, den: ComplexLike) -> Complex[Array, "..."]:
    r""":math:`z/w = z\bar w/|w|^2` (complex, ``den`` nonzero; broadcast shape): a complex
    multiply and two real divisions. XLA's complex division (a scaled Smith algorithm with the
    C99 special cases) costs several times that on CPU, and the coherent kernel divides four
    times per interface and polarization (P1: 3× less CPU time with this form). ``num == den``
    gives exactly 1 (an interface at its critical angle: R = 1 exactly). |w|² must not
    overflow: fine for the amplitude denominators here (|w| ≲ 1e3; the limit is 1e154 in
    float64, 1e19 in float32)."""
    num = jnp.asarray(num)
    a, b = jnp.real(num), jnp.imag(num)
    x, y = jnp.real(den), jnp.imag(den)
    # Re(z w̄) and |w|² written alike, so that they round alike when z = w
    return lax.complex((a * x + b * y) / (x * x + y * y), (b * x - a * y) / (x * x + y * y))


def reciprocal(den: ComplexLike) -> Complex[Array, "..."]:
    r""":math:`1/w = \bar w/|w|^2` (complex, ``den`` nonzero): one real division and two
    multiplications, in the vectorizable form of :func:`divide`. For a quantity divided by the
    same denominator several times (the Rouard update's :math:`1/D_j` and the derivative terms
    built on it, :mod:`layerstack_jax._kernels.coherent`); each product with it is then within ~2 ulp
    of the corresponding :func:`divide`. Same range limit as :func:`divide`."""
    den = jnp.asarray(den)
    x, y = jnp.real(den), jnp.imag(den)
    h = 1.0 / (x * x + y * y)
    return lax.complex(x * h, -y * h)


def _by_polarization(s_value, p_value):
    """The s and p values of one quantity stacked on a new leading axis ``(s, p)`` at their
    common broadcast shape."""
    return jnp.stack(jnp.broadcast_arrays(s_value, p_value))


def fresnel_amplitudes(n_i: ComplexLike, q_i: ComplexLike, n_f: ComplexLike, q_f: ComplexLike
                       ) -> tuple[Complex[Array, "2 *B"], Complex[Array, "2 *B"]]:
    r"""Fresnel amplitude coefficients of the interface from medium *i* into medium *f*.

    .. math::
        r_s = \frac{q_i - q_f}{q_i + q_f},\quad t_s = \frac{2 q_i}{q_i + q_f},\quad
        r_p = \frac{\tilde n_f^2 q_i - \tilde n_i^2 q_f}{\tilde n_f^2 q_i + \tilde n_i^2 q_f},\quad
        t_p = \frac{2 \tilde n_i \tilde n_f q_i}{\tilde n_f^2 q_i + \tilde n_i^2 q_f}

    (the intensity forms are Simonot et al. eqs. 2–3; the amplitudes are the r_j, t_j of
    Hirayama et al. eqs. 1–4). Both polarizations are one formula, :math:`r = (x - y)/(x + y)`,
    :math:`t = 2c/(x + y)` with :math:`(x, y, c) = (q_i, q_f, q_i)` for s and
    :math:`(\tilde n_f^2 q_i, \tilde n_i^2 q_f, \tilde n_i\tilde n_f q_i)` for p, evaluated on the
    stacked polarization axis (:func:`divide`).

    Args:
        n_i, n_f: complex indices of the two media (dimensionless).
        q_i, q_f: their normal wavevector ratios :math:`\tilde n\cos\theta` (dimensionless,
            from :func:`normal_wavevector`). All four broadcast to a common shape ``(*B)``.

    Returns:
        ``(r, t)``: complex, dimensionless amplitude ratios, each shaped ``(2, *B)``: stacked
        on a new leading polarization axis ``(s, p)``.
    """
    x = _by_polarization(q_i, n_f * n_f * q_i)
    y = _by_polarization(q_f, n_i * n_i * q_f)
    c = _by_polarization(q_i, n_i * n_f * q_i)
    den = x + y
    # den = 0 only for a non-interface (both q = 0 at grazing incidence in equal media);
    # guard so that the untaken branch never produces NaN (trap 3).
    zero = den == 0
    den = jnp.where(zero, 1.0, den)
    return jnp.where(zero, -1.0 + 0j, divide(x - y, den)), jnp.where(zero, 0j, divide(2 * c, den))


def power_flux(n: ComplexLike, q: ComplexLike) -> Float[Array, "2 *B"]:
    r"""Normal component of the time-averaged Poynting vector per unit :math:`|E|^2`, up to a
    common constant, for s and p (stacked on a leading axis).

    s: :math:`\operatorname{Re}(q)`; p: :math:`\operatorname{Re}(\tilde n\,\overline{\cos\theta})`
    with :math:`\cos\theta = q/\tilde n` (the ``tmm`` convention). The transmittance of a packet
    is :math:`|t|^2` times the ratio of the fluxes of the exit and incidence media
    (Hirayama et al. eq. 6 for real media).
    """
    cos = q / n
    return jnp.stack([jnp.real(q), jnp.real(n * jnp.conj(cos))])


def exit_medium_ratio(n0: ComplexLike, n_exit: ComplexLike) -> Float[Array, "..."]:
    r""":math:`(n_0/n_g)^2` (real parts; dimensionless, the broadcast shape of the two indices):
    the radiance of light leaving a medium of index :math:`n_g` into the ambient :math:`n_0` is
    divided by :math:`(n_g/n_0)^2` (étendue: :math:`L/n^2` is conserved across an interface),
    and a diffuse flux seen from the other side scales the same way (reciprocity of the
    diffuse transmittances). Simonot et al. eqs. 77, 79 with :math:`n_g` the background's
    binder; the same factor for the object under films of Hirayama's coated rough surface."""
    return (jnp.real(n0) / jnp.real(n_exit)) ** 2
