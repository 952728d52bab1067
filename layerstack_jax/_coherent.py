r"""Coherent film packets: the Rouard / Airy recursion (Hirayama et al. eqs. 1–6, Appendix A).

A *packet* is a run of zero or more coherent films between two semi-infinite media (the
ambient and the exit medium, or two thick incoherent layers of a mixed stack). Amplitudes add
with phase inside it. The recursion runs from the exit medium back to the incidence medium,

.. math::
    \gamma \leftarrow \frac{r_j + \gamma\, e^{2i\phi_j}}{1 + r_j \gamma\, e^{2i\phi_j}},\qquad
    \tau \leftarrow \frac{t_j\, \tau\, e^{i\phi_j}}{1 + r_j \gamma\, e^{2i\phi_j}},\qquad
    \phi_j = \frac{2\pi}{\lambda} q_j d_j,

(Hirayama eqs. 3–4, 24). Because :math:`\operatorname{Im} q_j \ge 0`, :math:`|e^{i\phi_j}| \le 1`:
a 10 µm metal film makes the phase factor underflow to 0, which gives the reflectance of the
bulk metal instead of an overflow (PHYSICS.md, trap 5). A forward transfer matrix would
contain :math:`e^{-i\phi_j}` and overflow there.
"""

from __future__ import annotations

from typing import NamedTuple, Optional, Sequence

import jax.numpy as jnp
import numpy as np
from jax import lax

from ._custom_types import Array, IndexSpectrum, Inexact
from ._fresnel import fresnel_amplitudes, normal_wavevector, power_flux
from ._numerics import abs2, as_complex, complex_dtype, safe_divide

__all__ = ["PacketIntensities", "packet_amplitudes", "stack_packets"]

# Packets with more films than this run through lax.scan (compile time independent of the
# number of films); shorter ones are unrolled, which XLA fuses better.
_SCAN_THRESHOLD = 8


class PacketIntensities(NamedTuple):
    """Intensity reflectances and transmittances of a packet, per polarization: the four fields
    ``(R_front, T_front, R_back, T_back)`` that the adding rule
    (:func:`~layerstack_jax._incoherent.add_layer`) composes.

    Each field is shaped ``(2, *batch)`` with the polarization axis ``(s, p)`` first,
    dimensionless fractions of the incident power (real). ``*_front``: light incident from the
    first medium of the packet; ``*_back``: from the last (None when not computed). The
    polarimetry module carries, in the same type, the s–p correlations
    ``(|a_s|², |a_p|², a_p ā_s)`` on a leading axis of 3 (complex dtype).
    """

    R_front: Inexact[Array, "pol *batch"]
    T_front: Inexact[Array, "pol *batch"]
    R_back: Optional[Inexact[Array, "pol *batch"]]
    T_back: Optional[Inexact[Array, "pol *batch"]]


def _rouard(r, t, phase):
    """Rouard recursion over interfaces ``r[0..F]``, ``t[0..F]`` and film phases ``phase[0..F-1]``.

    Shapes: r, t ``(F+1, 2, *B)``, phase ``(F, 1, *B)``. Returns composite ``(gamma, tau)``.
    """
    n_films = phase.shape[0]
    gamma, tau = r[-1], t[-1]

    def step(carry, x):
        gamma, tau = carry
        r_j, t_j, phi_j = x
        e1 = jnp.exp(1j * phi_j)
        e2 = e1 * e1
        den = 1.0 + r_j * gamma * e2
        return ((r_j + gamma * e2) / den, t_j * tau * e1 / den), None

    xs = (r[:-1][::-1], t[:-1][::-1], phase[::-1])
    if n_films <= _SCAN_THRESHOLD:
        carry = (gamma, tau)
        for j in range(n_films):
            carry, _ = step(carry, (xs[0][j], xs[1][j], xs[2][j]))
        return carry
    (gamma, tau), _ = lax.scan(step, (gamma, tau), xs)
    return gamma, tau


def _lift_branch_point(q):
    """Move a film's normal wavevector off exactly 0 (its own critical angle).

    There the recursion is 0/0 (r = +1 and −1 on the film's two faces, e^{2iφ} = 1), though the
    response of a finite film is an even, analytic function of its q: shifting q from 0 to ε
    changes it by O((2π d ε/λ)²). Close to 0 the interface form loses ~ (machine ε)/|q| to
    cancellation, so ε = (machine ε)^(1/3) balances the two (~1e-11 in float64 for a 100 nm
    film; a characteristic-matrix form with sin(φ)/q would remove both errors).
    """
    eps = float(jnp.finfo(jnp.real(q).dtype).eps) ** (1.0 / 3.0)
    return jnp.where(jnp.abs(q) < eps, eps + 0j, q).astype(q.dtype)


def packet_amplitudes(n: Sequence[IndexSpectrum], d: Sequence, s, wavelength):
    r"""Composite amplitude reflection and transmission coefficients :math:`(\gamma, \tau)` of a
    coherent packet illuminated from its first medium (Hirayama et al. eqs. 1–4).

    Args:
        n: complex indices of the media ``[incidence, film_1, …, film_F, exit]``, each
            broadcastable to the batch shape ``*B`` (typically ``(*angle, wl)``).
        d: thicknesses of the F films in nm, each broadcastable to ``*B``.
        s: Snell invariant, broadcastable to ``*B``.
        wavelength: vacuum wavelength in nm, broadcastable to ``*B``.

    Returns:
        ``(gamma, tau, q)``: amplitudes shaped ``(2, *B)`` (polarization ``(s, p)`` first) and
        the normal wavevectors ``q`` of all media, shaped ``(F + 2, *B)``.
    """
    n_arr = _media(n, s)
    q = normal_wavevector(n_arr, s)
    if len(n) > 2:
        q = q.at[1:-1].set(_lift_branch_point(q[1:-1]))
    r, t = fresnel_amplitudes(n_arr[:-1], q[:-1], n_arr[1:], q[1:])  # (2, F+1, *B)
    gamma, tau = _packet_recursion(r, t, q[1:-1], d, wavelength)
    return gamma, tau, q


def _media(n: Sequence, s):
    """The indices stacked ``(media, *B)`` as complex, B the broadcast shape of the indices and
    the Snell invariant only: Fresnel terms depend on nothing else, so they stay at that (often
    wavelength-free) shape and nothing wavelength-independent is computed per wavelength."""
    shape_n = jnp.broadcast_shapes(*(jnp.shape(x) for x in (*n, s)))
    dtype = complex_dtype(*n, jnp.complex64)
    return jnp.stack([jnp.broadcast_to(jnp.asarray(x).astype(dtype), shape_n) for x in n])


def _packet_recursion(r, t, q_films, d: Sequence, wavelength):
    """Rouard recursion of one packet from its interface amplitudes ``r, t`` ``(2, F+1, *B)``,
    its films' normal wavevectors ``(F, *B)`` and thicknesses (nm). Returns ``(gamma, tau)``
    shaped ``(2, *B')`` (B' also broadcast against the thicknesses and the wavelength)."""
    r, t = jnp.moveaxis(r, 0, 1), jnp.moveaxis(t, 0, 1)  # (F+1, 2, *B)
    if not d:
        return r[0], t[0]
    shape = jnp.broadcast_shapes(q_films.shape[1:], *(jnp.shape(x) for x in d), jnp.shape(wavelength))
    d_arr = jnp.stack([jnp.broadcast_to(jnp.asarray(x), shape) for x in d])
    phase = (as_complex(2 * jnp.pi / wavelength, q_films) * q_films * as_complex(d_arr, q_films))[:, None]  # (F, 1, *B)
    r = jnp.broadcast_to(r, (r.shape[0], 2, *shape))
    t = jnp.broadcast_to(t, (t.shape[0], 2, *shape))
    return _rouard(r, t, phase)


def stack_packets(n: Sequence[IndexSpectrum], d: Sequence, bounds: Sequence[int], s, wavelength, *, both_sides: bool = True):
    r"""Intensity reflectance and transmittance, from both sides, of every packet of a stack:
    the runs of coherent films between the media at positions ``bounds`` (the ambient, the thick
    layers and the exit medium).

    :math:`R = |\gamma|^2` and :math:`T = |\tau|^2\,\Phi_\text{exit} / \Phi_\text{incidence}` with the
    power fluxes of :func:`layerstack_jax._fresnel.power_flux` (Hirayama eqs. 5–6 per polarization,
    before any averaging). ``T`` is the power that enters the packet's last medium, also when
    that medium absorbs. Light arriving at grazing incidence or from an evanescent medium has
    zero flux; its ``T`` is set to 0. The back side (light from the last medium) is the same
    recursion on the reversed packet; with an absorbing film ``R_back != R_front`` while
    ``T_back == T_front`` for real outer media (reciprocity, Simonot eq. 44).

    The normal wavevectors, Fresnel coefficients and power fluxes of all media and interfaces
    are computed in one vectorized pass (front and back), so a stack of many thick layers
    compiles to a few kernels instead of a few per interface (P2 benchmark: 63 instead of 204,
    0.8 s instead of 1.9 s of XLA compilation); only packets that hold films run their own
    Rouard recursion. The price: all interfaces share one shape, so when one medium is
    dispersive the interfaces between dispersionless media are computed per wavelength too
    (Fresnel algebra only; a fit computes it once, see :func:`layerstack_jax.fixed_optics`).

    Args:
        n: complex indices of all media (ambient, layers…, exit), each broadcastable to ``*B``.
        d: thicknesses (nm) of the layers (``len(n) - 2``); only those of films are used.
        bounds: increasing positions in ``n`` of the semi-infinite and thick media, first 0 and
            last ``len(n) - 1``.
        s: Snell invariant, broadcastable to ``*B``; wavelength: nm.
        both_sides: also the response to light from each packet's last medium.

    Returns:
        ``(packets, q)``: a tuple of :class:`PacketIntensities` (fields ``(2, *B)``, backs None
        unless ``both_sides``), one per pair of consecutive bounds, and the normal wavevectors
        of all media ``(media, *B)``.
    """
    n_arr = _media(n, s)
    q = normal_wavevector(n_arr, s)
    films = np.array([i for i in range(1, len(n) - 1) if i not in bounds], dtype=int)
    if films.size:
        q = q.at[films].set(_lift_branch_point(q[films]))
    flux = power_flux(n_arr, q)  # (2, media, *B)
    r_f, t_f = fresnel_amplitudes(n_arr[:-1], q[:-1], n_arr[1:], q[1:])  # (2, interface, *B)
    R_f, T_f = abs2(r_f), safe_divide(abs2(t_f) * flux[:, 1:], flux[:, :-1])
    if both_sides:
        r_b, t_b = fresnel_amplitudes(n_arr[1:], q[1:], n_arr[:-1], q[:-1])
        R_b, T_b = abs2(r_b), safe_divide(abs2(t_b) * flux[:, :-1], flux[:, 1:])
    packets = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b == a + 1:  # a bare interface
            backs = (R_b[:, a], T_b[:, a]) if both_sides else (None, None)
            packets.append(PacketIntensities(R_f[:, a], T_f[:, a], *backs))
            continue
        film_d = tuple(d[a : b - 1])
        gamma, tau = _packet_recursion(r_f[:, a:b], t_f[:, a:b], q[a + 1 : b], film_d, wavelength)
        front = (abs2(gamma), safe_divide(abs2(tau) * flux[:, b], flux[:, a]))
        backs = (None, None)
        if both_sides:  # the reversed packet: interfaces b-1 … a seen from their far side
            gamma, tau = _packet_recursion(r_b[:, a:b][:, ::-1], t_b[:, a:b][:, ::-1], q[a + 1 : b][::-1],
                                           film_d[::-1], wavelength)
            backs = (abs2(gamma), safe_divide(abs2(tau) * flux[:, a], flux[:, b]))
        packets.append(PacketIntensities(*front, *backs))
    return tuple(packets), q
