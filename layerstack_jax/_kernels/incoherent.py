r"""Thick incoherent layers: Beer attenuation and the intensity adding rule.

Light in a thick layer (much thicker than the coherence length: varnish, ink film, glass)
adds in intensity. Per polarization, a layer bounded by two *interfaces* A (above) and B (below)
— each a plain Fresnel interface or a coherent packet — has (Simonot, Hébert & Hersch eqs. 30,
37, 40, 42 for one bounded layer, 51, 53, 59, 60 for k layers)

.. math::
    R_\text{front} &= R^A_f + \frac{T^A_f T^A_b R^B_f\, t^2}{1 - R^A_b R^B_f\, t^2}, &
    T_\text{front} &= \frac{T^A_f T^B_f\, t}{1 - R^A_b R^B_f\, t^2},\\
    R_\text{back} &= R^B_b + \frac{T^B_b T^B_f R^A_b\, t^2}{1 - R^A_b R^B_f\, t^2}, &
    T_\text{back} &= \frac{T^B_b T^A_b\, t}{1 - R^A_b R^B_f\, t^2},

with the Beer attenuation along the slanted path (eqs. 23, 56, 61)
:math:`t = \exp(-\alpha h / \cos\theta)`. The paper writes :math:`T^A_f = T^A_b`
(eq. 9); we keep both, which is exact also for absorbing coherent packets and absorbing thick
media. Natural light is the mean of s and p taken only at the very end (eqs. 33, 39, 57, 58).
"""

from __future__ import annotations

from typing import Sequence

import jax.numpy as jnp

from .._base.numerics import as_complex, safe_divide, safe_reciprocal
from .coherent import PacketIntensities

__all__ = ["slant_path", "beer_rates", "beer_factor", "beer_attenuation_along", "beer_attenuation", "add_layer",
           "add_layers"]


def slant_path(n, q):
    r"""What Beer's law needs of the direction of light in a thick layer of index ``n``
    at normal wavevector ``q``: :math:`(\operatorname{Re}\cos\theta, \operatorname{Im} q)`
    with :math:`\cos\theta = q/\tilde n` (real arrays). Depends on the indices and the angle
    only — not on thickness or α — so a fit of those can compute it once."""
    return jnp.real(q / n), jnp.imag(q)


def beer_rates(cos_real, im_q, alpha, wavelength):
    r"""Attenuation per nm of thickness of a thick layer along the slant path ``(cos_real, im_q)``
    of :func:`slant_path`: :math:`(\kappa, 1/\operatorname{Re}\cos\theta)` with
    :math:`t = e^{-\kappa h}`,

    .. math::
        \kappa = \frac{4\pi}{\lambda}\operatorname{Im} q + \frac{\alpha}{\operatorname{Re}\cos\theta}

    (1/nm; alpha in 1/nm or None, wavelength in nm). Where the layer is not reached
    (:math:`\operatorname{Re}\cos\theta \le 0`, past its critical angle) the α term and
    :math:`1/\operatorname{Re}\cos\theta` are returned as 0: finite, for the derivatives of
    :mod:`layerstack_jax._kernels.adding_sums`, which multiply them by t = 0 there."""
    inv_cos = safe_divide(1.0, cos_real)
    kappa = (4 * jnp.pi / wavelength) * im_q
    if alpha is not None:
        kappa = kappa + alpha * inv_cos
    return kappa, inv_cos


def beer_factor(kappa, thickness, cos_real, absorbing: bool):
    r"""Single-pass attenuation :math:`t = e^{-\kappa h}` from the rate ``kappa`` of
    :func:`beer_rates` (1/nm) and the thickness (nm); with an absorption coefficient given
    (``absorbing``), t = 0 where the layer is not reached (:math:`\operatorname{Re}\cos\theta \le 0`)."""
    t = jnp.exp(-kappa * thickness)
    return jnp.where(cos_real > 0, t, 0.0) if absorbing else t


def beer_attenuation_along(cos_real, im_q, thickness, alpha, wavelength):
    r"""Single-pass attenuation :math:`t = e^{-\kappa h}` (see :func:`beer_attenuation` and
    :func:`beer_rates`) from the slant path ``(cos_real, im_q)`` of :func:`slant_path`; thickness
    in nm, alpha in 1/nm (or None), wavelength in nm. With α given, t = 0 where the layer is not
    reached (:math:`\operatorname{Re}\cos\theta \le 0`)."""
    kappa, _ = beer_rates(cos_real, im_q, alpha, wavelength)
    return beer_factor(kappa, thickness, cos_real, alpha is not None)


def beer_attenuation(n, q, thickness, alpha, wavelength):
    r"""Single-pass intensity attenuation of a thick layer, for light with normal wavevector q.

    .. math::
        t = \exp\!\Big(-\frac{4\pi}{\lambda}\operatorname{Im}(q)\,h
                       - \frac{\alpha\, h}{\operatorname{Re}\cos\theta}\Big),
        \qquad \cos\theta = q/\tilde n.

    The first term is the absorption of a complex index (as in ``tmm.inc_tmm``); the second is
    Beer's law with an absorption coefficient given directly (Simonot eq. 61), whose interfaces
    see the real index only. For a real index and s below the critical angle, the first term is
    zero and the second is exactly :math:`\exp(-\alpha h/\cos\theta)`. At and beyond the critical
    angle (:math:`\cos\theta \to 0`) the layer is not reached and t = 0, with a finite gradient
    (PHYSICS.md, traps 2 and 3).

    Args:
        n: complex index, q: normal wavevector (same shape or broadcastable),
        thickness: nm, alpha: 1/nm (or None), wavelength: nm.
    """
    return beer_attenuation_along(*slant_path(n, q), thickness, alpha, wavelength)


def add_layer(above: PacketIntensities, below: PacketIntensities, t) -> PacketIntensities:
    """Compose two interfaces around a thick layer of single-pass attenuation ``t``.

    ``above`` and ``below`` are any 4-field tuples ``(R_front, T_front, R_back, T_back)`` of the
    same type (intensities, or the s–p correlations of the polarimetry module); so is the result.

    The adding rule of the module docstring (Simonot eqs. 51, 53 and their mirror images).
    All arguments broadcast; the polarization axis is carried along unchanged.
    """
    t2 = t * t
    if jnp.iscomplexobj(above.R_front):  # s–p correlations: the real attenuation joins them as complex
        t, t2 = as_complex(t, above.R_front), as_complex(t2, above.R_front)
    den = 1.0 - above.R_back * below.R_front * t2
    # den -> 0 only for a lossless cavity between two perfect mirrors (R = 1 on both sides with
    # t = 1), where no light enters: the numerators vanish as well. (`!= 0` rather than `> 0`
    # so that the same rule serves complex s–p correlations, :mod:`layerstack_jax._instruments.polarimetry`.)
    inv = safe_reciprocal(den)
    R_f = above.R_front + above.T_front * above.T_back * below.R_front * t2 * inv
    T_f = above.T_front * below.T_front * t * inv
    R_b = below.R_back + below.T_back * below.T_front * above.R_back * t2 * inv
    T_b = below.T_back * above.T_back * t * inv
    return type(above)(R_f, T_f, R_b, T_b)


def add_layers(packets: Sequence[PacketIntensities], beer: Sequence) -> PacketIntensities:
    """Join ``packets`` (L + 1 four-field tuples, in stack order) through the L thick layers
    between them, of single-pass attenuations ``beer`` (L arrays), by :func:`add_layer` from the
    top down (Simonot eqs. 59–60). Returns the type of the packets; one packet is returned as is."""
    total = packets[0]
    for t, packet in zip(beer, packets[1:]):
        total = add_layer(total, packet, t)
    return total
