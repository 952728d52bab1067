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

This module owns the forward kernels and the public entry points (:func:`packet_amplitudes`,
:func:`stack_packets`, :class:`PacketIntensities`).

**Forward.** :func:`_packet` runs the recursion film by film in one loop whose step forms the
film's normal wavevector, the Fresnel coefficients of the interface above it (s and p on one
axis) and its phase factor: no per-interface or per-film array is stored. Its arithmetic is
written so that XLA vectorizes it on CPU: complex division as :math:`z\bar w/|w|^2`
(:func:`~layerstack_jax._kernels.fresnel.divide`), the square root in real arithmetic, cosine and sine
by polynomial (:func:`~layerstack_jax._kernels.cos_sin._cos_sin`): XLA's own complex division (scaled, with special cases),
complex square root (through atan2, sine and cosine) and float64 sine and cosine (a scalar call
per element) are each several times slower on CPU. Measured in ``benchmarks/README.md`` (P1).

**Derivative.** :func:`_rouard` and :func:`_packet` are ``jax.custom_jvp`` functions whose
closed-form rules live in :mod:`layerstack_jax._kernels.coherent_derivatives`, which imports this
module and attaches them (``_rouard.defjvp``, ``_packet.defjvp``) when it is imported; the
package ``layerstack_jax._kernels`` imports it, so every import of this module has them.
"""


from __future__ import annotations

from typing import NamedTuple, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .._base.custom_types import Array, IndexSpectrum, Inexact
from .._base.numerics import abs2, as_complex, complex_dtype, safe_divide
from .cos_sin import _cos_sin
from .fresnel import divide, fresnel_amplitudes, normal_wavevector, power_flux

__all__ = ["PacketIntensities", "packet_amplitudes", "stack_packets"]

# Packets with more films than this run through lax.scan (compile time independent of the
# number of films); shorter ones are unrolled, which XLA fuses better.
_SCAN_THRESHOLD = 8


class PacketIntensities(NamedTuple):
    """Intensity reflectances and transmittances of a packet, per polarization: the four fields
    ``(R_front, T_front, R_back, T_back)`` that the adding rule
    (:func:`~layerstack_jax._kernels.incoherent.add_layer`) composes.

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


def _rouard_step(carry, x):
    """One step of the recursion (module docstring): film j and the interface above it;
    ``carry = (γ_{j+1}, τ_{j+1})`` below film j, ``x = (r_j, t_j, e^{iφ_j}, e^{2iφ_j})``."""
    return _rouard_update(*carry, *x), None


def _rouard_update(gamma, tau, r_j, t_j, e1, e2):
    """Hirayama eqs. 3–4 for film j: ``(γ_j, τ_j)`` from ``(γ_{j+1}, τ_{j+1})`` below it, the
    interface above it ``(r_j, t_j)`` and its phase factors ``e^{iφ_j}, e^{2iφ_j}``
    (:func:`~layerstack_jax._kernels.fresnel.divide`)."""
    u = gamma * e2
    den = 1.0 + r_j * u
    return divide(r_j + u, den), divide(t_j * tau * e1, den)


def _loop(step, carry, xs, n: int):
    """``step`` over the leading axis of the pytree ``xs`` (length n): unrolled for short packets
    (XLA fuses them better), ``lax.scan`` beyond :data:`_SCAN_THRESHOLD` (compile time
    independent of n). Returns ``(carry, ys)``, the ys stacked on a leading axis (None if none)."""
    if n > _SCAN_THRESHOLD:
        return lax.scan(step, carry, xs)
    ys = []
    for j in range(n):
        carry, y = step(carry, jax.tree_util.tree_map(lambda a: a[j], xs))
        ys.append(y)
    if not ys or ys[0] is None:
        return carry, None
    return carry, jax.tree_util.tree_map(lambda *a: jnp.stack(a), *ys)


@jax.custom_jvp
def _rouard(r, t, phase):
    """Rouard recursion over interfaces ``r[0..F]``, ``t[0..F]`` and film phases ``phase[0..F-1]``.

    Shapes: r, t ``(F+1, 2, *B)``, phase ``(F, 1, *B)``. Returns composite ``(gamma, tau)``.
    Its derivative is the closed form of :func:`_rouard_sensitivities` (one extra sweep).
    """
    (gamma, tau), _ = _loop(_rouard_step, (r[-1], t[-1]), _bottom_up(r, t, phase, own_loop=False),
                            phase.shape[0])
    return gamma, tau


def _bottom_up(r, t, phase, own_loop: bool = True):
    """The steps' inputs ``(r_j, t_j, e^{iφ_j}, e^{2iφ_j})`` from the last film up.

    ``own_loop`` (static): the phase factors are computed in a loop of their own
    (:func:`jax.lax.map` over the films) so that XLA keeps them in memory — for the derivative
    sweep, where fused into their readers their sine and cosine would be recomputed up to six
    times (P3: the Jacobian and the value+gradient in about 40 % of the time). The plain forward
    (``own_loop=False``) lets XLA fuse them: a separate loop would materialise (F, A, wl) arrays
    that fusion never builds (P1 with dispersionless media: 3× slower; with per-wavelength
    indices the same either way)."""
    e1 = lax.map(_phase_factor, phase[::-1]) if own_loop else _phase_factor(phase[::-1])
    return r[:-1][::-1], t[:-1][::-1], e1, e1 * e1


def _phase_factor(phi):
    r""":math:`e^{i\phi}` of a film's phase φ (complex, ``Im φ ≥ 0``), from the real exponential
    of its imaginary part and the cosine and sine of its real part (:func:`_cos_sin`)."""
    magnitude = jnp.exp(-jnp.imag(phi))
    cos, sin = _cos_sin(jnp.real(phi))
    return lax.complex(magnitude * cos, magnitude * sin)


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


def _film_wavevector(n, s):
    """Normal wavevector of a film (:func:`~layerstack_jax._kernels.fresnel.normal_wavevector`) lifted
    off its branch point (:func:`_lift_branch_point`)."""
    return _lift_branch_point(normal_wavevector(n, s))


def _film_phase(q, d, wavelength):
    r"""Phase :math:`\phi = 2\pi q d/\lambda` of a film of thickness ``d`` (nm) at vacuum
    wavelength λ (nm) (Hirayama eq. 24); complex, the broadcast shape of the three."""
    return as_complex(2 * jnp.pi / wavelength, q) * q * as_complex(d, q)


def _film_step(gamma, tau, e1, n_i, q_i, n_f, q_f):
    r"""Film f and the interface above it in one step: the Fresnel coefficients of the interface
    from medium i into film f (:func:`~layerstack_jax._kernels.fresnel.fresnel_amplitudes`) and the
    Rouard update (:func:`_rouard_update`) with the film's phase factor
    :math:`e^{i\phi_f}` (``e1``). ``gamma``, ``tau``: ``(2, *B)``, below the film."""
    r, t = fresnel_amplitudes(n_i, q_i, n_f, q_f)
    return _rouard_update(gamma, tau, r, t, e1, e1 * e1)


@jax.custom_jvp
def _packet(n, q_ends, d, s, wavelength):
    r"""Composite :math:`(\gamma, \tau)` ``(2, *B)`` of a packet (Hirayama eqs. 1–4), film by film
    from the exit medium up: each step forms the normal wavevector of the film above, the
    Fresnel coefficients of the interface between them and that film's phase factor inside the
    loop (:func:`_film_step`), so that nothing is stored per interface or per film — only the
    running (γ, τ), the last normal wavevector and the next phase factor. The same values as
    :func:`_rouard` on stored coefficients (to a few ulp); its derivative is the closed form of
    :func:`_rouard_sensitivities` run in the same loop form (:func:`_packet_jvp`).

    On P1 (10 films, 64 angles × 1000 λ) the stored form moved ~700 MB through memory
    (broadcast indices, r and t of every interface, their reversed copies); this one keeps five
    arrays of ``(*B)`` (two of ``(2, *B)``) live across steps. The loop is a ``lax.scan`` for
    any number of films: unrolled, XLA fuses consecutive steps into kernels that recompute or
    store their shared terms (P1 3× slower in a trial).

    Args:
        n: ``(F + 2, *Bn)`` complex indices ``[incidence, film_1, …, film_F, exit]`` (F ≥ 1).
        q_ends: ``(2, *Bq)`` normal wavevectors of the incidence and exit media.
        d: ``(F, *Bd)`` film thicknesses (nm).
        s: Snell invariant; wavelength: vacuum wavelength (nm). All of the same rank.
    """
    films = n.shape[0] - 2
    shape = jnp.broadcast_shapes(q_ends.shape[1:], d.shape[1:], jnp.shape(wavelength))
    q_last = _film_wavevector(n[films], s)
    r, t = fresnel_amplitudes(n[films], q_last, n[-1], q_ends[1])
    e1 = jnp.broadcast_to(_phase_factor(_film_phase(q_last, d[-1], wavelength)), shape)
    carry = (jnp.broadcast_to(r, (2, *shape)), jnp.broadcast_to(t, (2, *shape)), n[films], q_last, e1)

    def step(carry, x):  # film f (its phase factor e1 carried) and the film above it, i
        gamma, tau, n_f, q_f, e1 = carry
        n_i, d_i = x
        q_i = _film_wavevector(n_i, s)
        gamma, tau = _film_step(gamma, tau, e1, n_i, q_i, n_f, q_f)
        return (gamma, tau, n_i, q_i, jnp.broadcast_to(_phase_factor(_film_phase(q_i, d_i, wavelength)), shape)), None

    if films > 1:
        carry, _ = lax.scan(step, carry, (n[1:films][::-1], d[:-1][::-1]))
    gamma, tau, n_f, q_f, e1 = carry
    return _film_step(gamma, tau, e1, n[0], q_ends[0], n_f, q_f)


def _stacked_indices(n: Sequence, *others):
    """The indices stacked ``(media, *Bn)`` as complex, Bn their own broadcast shape with unit
    axes up to the rank of ``others`` (Snell invariant, wavelength, thicknesses): nothing is
    broadcast over angles or wavelengths here; the normal wavevectors and phases are."""
    rank = len(jnp.broadcast_shapes(*(jnp.shape(x) for x in others)))
    shape = jnp.broadcast_shapes(*(jnp.shape(x) for x in n), (1,) * rank)
    dtype = complex_dtype(*n, jnp.complex64)
    return jnp.stack([jnp.broadcast_to(jnp.asarray(x).astype(dtype), shape) for x in n])


def _stacked_thicknesses(d: Sequence, rank: int):
    """Film thicknesses (nm) stacked ``(F, *Bd)``, Bd their broadcast shape with unit axes up to
    ``rank``."""
    shape = jnp.broadcast_shapes(*(jnp.shape(x) for x in d), (1,) * rank)
    return jnp.stack([jnp.broadcast_to(jnp.asarray(x), shape) for x in d])


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
    power fluxes of :func:`layerstack_jax._kernels.fresnel.power_flux` (Hirayama eqs. 5–6 per polarization,
    before any averaging). ``T`` is the power that enters the packet's last medium, also when
    that medium absorbs. Light arriving at grazing incidence or from an evanescent medium has
    zero flux; its ``T`` is set to 0. The back side (light from the last medium) is the same
    recursion on the reversed packet; with an absorbing film ``R_back != R_front`` while
    ``T_back == T_front`` for real outer media (reciprocity, Simonot eq. 44).

    The normal wavevectors and power fluxes of the thick and outer media and the Fresnel
    coefficients of the bare interfaces between them are computed in one vectorized pass (front
    and back), so a stack of many thick layers compiles to a few kernels instead of a few per
    interface (P2 benchmark: 63 instead of 204, 0.8 s instead of 1.9 s of XLA compilation).
    The price: those interfaces share one shape, so when one medium is dispersive the others
    are computed per wavelength too (Fresnel algebra only; a fit computes it once, see
    :func:`layerstack_jax.fixed_optics`). Packets that hold films run :func:`_packet`, which
    forms its films' wavevectors and coefficients inside its own loop.

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
        of the media at ``bounds`` ``(len(bounds), *B)``.
    """
    n_arr = _stacked_indices(n, s, wavelength, *d)
    q = normal_wavevector(n_arr[np.asarray(bounds)], s)  # (bounds, *B): the thick and outer media
    flux = power_flux(n_arr[np.asarray(bounds)], q)  # (2, bounds, *B)
    # bare interfaces (no film between two thick media), all in one vectorized pass
    bare = np.array([k for k in range(len(bounds) - 1) if bounds[k + 1] == bounds[k] + 1], dtype=int)
    if bare.size:
        n_i, n_f = n_arr[np.asarray(bounds)[bare]], n_arr[np.asarray(bounds)[bare] + 1]
        r_f, t_f = fresnel_amplitudes(n_i, q[bare], n_f, q[bare + 1])  # (2, bare, *B)
        R_f, T_f = abs2(r_f), safe_divide(abs2(t_f) * flux[:, bare + 1], flux[:, bare])
        if both_sides:
            r_b, t_b = fresnel_amplitudes(n_f, q[bare + 1], n_i, q[bare])
            R_b, T_b = abs2(r_b), safe_divide(abs2(t_b) * flux[:, bare], flux[:, bare + 1])
    packets = []
    for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
        if b == a + 1:  # a bare interface
            i = int(np.searchsorted(bare, k))
            backs = (R_b[:, i], T_b[:, i]) if both_sides else (None, None)
            packets.append(PacketIntensities(R_f[:, i], T_f[:, i], *backs))
            continue
        film_d = _stacked_thicknesses(d[a : b - 1], n_arr.ndim - 1)
        gamma, tau = _packet(n_arr[a : b + 1], q[k : k + 2], film_d, s, wavelength)
        front = (abs2(gamma), safe_divide(abs2(tau) * flux[:, k + 1], flux[:, k]))
        backs = (None, None)
        if both_sides:  # the reversed packet: interfaces b-1 … a seen from their far side
            gamma, tau = _packet(n_arr[a : b + 1][::-1], q[k : k + 2][::-1], film_d[::-1], s, wavelength)
            backs = (abs2(gamma), safe_divide(abs2(tau) * flux[:, k], flux[:, k + 1]))
        packets.append(PacketIntensities(*front, *backs))
    return tuple(packets), q
