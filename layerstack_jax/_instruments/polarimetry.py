r"""Polarimetry: polarization-resolved BRDF and Mueller matrices of any stack (Ellis 1996).

Stokes and Mueller conventions (fixed here for the package): the instruments' frame
-------------------------------------------------------------------------------------
* The basis of the transverse field is ``(p, s)``: the Jones vector is :math:`E = (E_p, E_s)`,
  with the amplitude conventions of :mod:`layerstack_jax._kernels.fresnel` (``tmm``/Born & Wolf:
  :math:`r_p = -r_s` at normal incidence), time dependence :math:`e^{-i\omega t}`.
* Stokes vector :math:`S_k = E^\dagger \sigma_k E` with
  :math:`\sigma_0 = 1`, :math:`\sigma_1 = \operatorname{diag}(1, -1)`,
  :math:`\sigma_2 = [[0, 1], [1, 0]]`, :math:`\sigma_3 = [[0, i], [-i, 0]]`, i.e.
  :math:`I = I_p + I_s`, :math:`Q = I_p - I_s`, :math:`U = 2\operatorname{Re}(E_p \bar E_s)`,
  :math:`V = 2\operatorname{Im}(E_p \bar E_s)`; intensities are power fluxes through the surface.
  This sign of V is the one of ellipsometers, whose Jones calculus is written with
  :math:`e^{+i\omega t}` (the conjugate amplitudes): it makes the Mueller matrix of a reflection
  the measured one. (With :math:`V = 2\operatorname{Im}(\bar E_p E_s)` instead, the
  "physics-frame" Mueller matrix — e.g. pyElli 0.23's ``Result.mueller_matrix`` — the elements
  of row 4 and column 4 change sign: :math:`M_\text{here} = D M_\text{physics} D`,
  :math:`D = \operatorname{diag}(1, 1, 1, -1)`.)
* A Jones matrix :math:`J` maps to the Mueller matrix
  :math:`M_{kl} = \tfrac12 \operatorname{tr}(J^\dagger\sigma_k J \sigma_l)`. For the reflection
  :math:`J = \operatorname{diag}(r_p, r_s)` this is
  :math:`m_{00}\,[[1, -N, 0, 0], [-N, 1, 0, 0], [0, 0, C, S], [0, 0, -S, C]]` with
  :math:`N = \cos 2\psi`, :math:`C = \sin 2\psi\cos\Delta`, :math:`S = \sin 2\psi\sin\Delta`
  and Δ as ellipsometers report it (:mod:`layerstack_jax._instruments.ellipsometry`): the frame of
  reflection ellipsometry as Mueller-matrix ellipsometers report it, in which a perfect
  mirror at normal incidence is :math:`\operatorname{diag}(1, 1, -1, -1)`. Checked against a
  measured Sentech Mueller matrix of 103 nm SiO2 on Si (tests/test_polarimetry.py): all 16
  elements agree to ~0.01 rms, where the physics frame misses M34 and M43 (1-based names,
  :math:`m_{23}, m_{32}` here) by 1.3 rms.
* Arrays: Stokes vectors ``(*batch, 4, wl)``, Mueller matrices ``(*batch, 4, 4, wl)`` — the
  wavelength stays the last axis, as everywhere in the package; :func:`apply_mueller` does the
  product. Polarization-resolved BRDFs ``(*angle, 2, 2, wl)``: axis −3 the illumination,
  axis −2 the analyser, each ordered ``(s, p)``.

Physics
-------
The Lambertian background re-emits unpolarized light, so the diffuse BRDF factorizes (Ellis 1996,
eqs. for :math:`f_{pp}, f_{ps}`; Simonot et al. eqs. 76–79 for the natural-light factor):

.. math::
    f_{ab}(\theta_i, \theta_r) = \tfrac12 K\, T_a(\theta_i)\, T_b(\theta_r), \qquad
    K = \Big(\frac{n_0}{n_g}\Big)^2 \frac{\rho_g}{\pi (1 - \rho_g r_b)},

with :math:`T_a` the stack's collimated transmittance for polarization *a* (the whole
per-polarization recursion, coherent, incoherent or mixed) and :math:`r_b` its diffuse
back-side reflectance. In Mueller form this is the rank-one partial polarizer
:math:`K\, v(\theta_r) v(\theta_i)^T`, :math:`v = (\bar T, (T_p - T_s)/2, 0, 0)`.

The specular part is the Mueller matrix of the stack's front reflection. Inside a thick
incoherent layer the phases of the multiply reflected beams are lost, but s and p of the *same*
beam travel the same path (the normal wavevector q does not depend on polarization), so the s–p
correlation :math:`X = \langle r_p \bar r_s\rangle` survives and composes through a thick layer
by the same adding rule as the intensities (Simonot eqs. 51, 53) with :math:`R \to X`,
:math:`T \to \tau_p\bar\tau_s` (flux-normalized) and the same Beer factor. A single coherent packet
gives :math:`|X|^2 = R_s R_p` (non-depolarizing); light returned from below a thick layer
depolarizes partially (:math:`|X|^2 < R_s R_p`).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._base.custom_types import Array, Float, RealLike, Spectrum
from .._base.numerics import as_complex, safe_divide, safe_sqrt
from .._base.programs import public_program
from .._base.validate import LayerstackError, check_angle_deg
from .._kernels.coherent import PacketIntensities, packet_amplitudes
from .._kernels.fresnel import exit_medium_ratio, normal_wavevector, power_flux
from .._kernels.incoherent import add_layers, beer_attenuation
from .._kernels.quadrature import DEFAULT_NODES
from .._stacks.illumination import diffuse_resolved, snell_invariant
from .._stacks.recursion import stack_intensities, thick_media
from .._stacks.stack import ResolvedStack, Stack, resolve

__all__ = [
    "PAULI",
    "polarized_brdf",
    "diffuse_mueller",
    "specular_mueller",
    "mueller_from_jones",
    "apply_mueller",
    "degree_of_polarization",
    "coherency_matrix",
    "cloude_eigenvalues",
    "is_physical",
    "stokes",
]

#: Pauli matrices σ0..σ3 in the (p, s) basis, σ3 with the sign of the instruments' frame
#: (V = 2 Im(E_p Ē_s); module docstring), shape (4, 2, 2).
PAULI = np.array(
    [[[1, 0], [0, 1]], [[1, 0], [0, -1]], [[0, 1], [1, 0]], [[0, 1j], [-1j, 0]]],
    dtype=complex,
)

#: Stokes vectors of unit-intensity pure states, keyed by name: 'unpolarized', 's', 'p',
#: '+45', '-45', 'R', 'L' (named by the sign of V in this module's frame: R is V = +1).
_STATES = {
    "unpolarized": (1.0, 0.0, 0.0, 0.0),
    "p": (1.0, 1.0, 0.0, 0.0),
    "s": (1.0, -1.0, 0.0, 0.0),
    "+45": (1.0, 0.0, 1.0, 0.0),
    "-45": (1.0, 0.0, -1.0, 0.0),
    "R": (1.0, 0.0, 0.0, 1.0),
    "L": (1.0, 0.0, 0.0, -1.0),
}


def stokes(state: str):
    """Unit-intensity Stokes vector of shape ``(4, 1)`` (broadcasts over wavelength) of a named
    state: 'unpolarized', 's', 'p', '+45', '-45', 'R' (V = +1), 'L' (V = −1). The components are
    dimensionless (I = 1); multiply by an intensity for other scales."""
    try:
        return jnp.asarray(_STATES[state])[:, None]
    except KeyError:
        raise LayerstackError(f"stokes: unknown state {state!r}; use one of {sorted(_STATES)}") from None


def _angles(incidence_deg, viewing_deg):
    incidence_deg = check_angle_deg("incidence_deg", incidence_deg)
    viewing_deg = check_angle_deg("viewing_deg", viewing_deg)
    i, v = jnp.broadcast_arrays(jnp.asarray(incidence_deg, dtype=float), jnp.asarray(viewing_deg, dtype=float))
    return jnp.deg2rad(i), jnp.deg2rad(v)


def _T_pol(rs: ResolvedStack, angle_rad):
    """Collimated transmittance per polarization, shaped ``(2, *angle, wl)``."""
    s = snell_invariant(rs.n[0], angle_rad)
    T = stack_intensities(rs, s, both_sides=False).T_front
    return jnp.broadcast_to(T, (2, *jnp.shape(angle_rad), rs.wavelength.shape[-1]))


def _background_factor(stack: Stack, rs: ResolvedStack, nodes: int) -> Spectrum:
    r""":math:`K = (n_0/n_g)^2 \rho_g / (\pi (1 - \rho_g r_b))`, shaped ``(wl,)``."""
    if rs.rho_g is None:
        raise LayerstackError(
            "exit: a polarized BRDF / diffuse Mueller matrix needs a diffusing exit (a LambertianBackground …) "
            "(a specular substrate has no diffuse part; use specular_mueller)"
        )
    r_b = diffuse_resolved(rs, "back", nodes).r
    rho = rs.rho_g
    return exit_medium_ratio(rs.n[0], rs.n[-1]) * rho / (jnp.pi * (1.0 - rho * r_b))


@public_program
def polarized_brdf(
    stack: Stack, wavelength_nm, incidence_deg: RealLike, viewing_deg: RealLike, *, nodes: int = DEFAULT_NODES
) -> Float[Array, "*angle 2 2 wl"]:
    r"""Polarization-resolved diffuse BRDF :math:`f_{ab}(\theta_i, \theta_r)` in 1/sr.

    :math:`f_{ab} = \tfrac12 K\,T_a(\theta_i)\,T_b(\theta_r)` (Ellis 1996; module docstring), for
    any stack over a :class:`~layerstack_jax.LambertianBackground`. Summed over the analyser and
    averaged over the illumination it is the natural-light BRDF of
    ``reflectance(stack, wl, BRDF(i, v))`` (Simonot eq. 76). The specular reflection (Ellis's
    :math:`R_a \delta(\cdot)` term) is not included: see :func:`specular_mueller`.

    Args:
        stack: any stack (coherent, incoherent or mixed) over a Lambertian background.
        wavelength_nm: ``(wl,)`` nm.
        incidence_deg, viewing_deg: polar angles of illumination and detection in the ambient,
            degrees in [0, 90), broadcast together to ``(*angle)``.
        nodes: quadrature nodes per segment for the diffuse back-side reflectance :math:`r_b`.

    Returns:
        Array ``(*angle, 2, 2, wl)``: axis −3 illumination polarization, axis −2 analyser,
        each ``(s, p)``; e.g. ``f[..., 1, 0, :]`` is Ellis's :math:`f_{ps}` (p in, s out).
    """
    th_i, th_v = _angles(incidence_deg, viewing_deg)
    rs = resolve(stack, wavelength_nm)
    K = _background_factor(stack, rs, nodes)
    T_i = jnp.moveaxis(_T_pol(rs, th_i), 0, -2)  # (*angle, 2, wl)
    T_v = jnp.moveaxis(_T_pol(rs, th_v), 0, -2)
    return 0.5 * K * T_i[..., :, None, :] * T_v[..., None, :, :]


def _partial_polarizer_vector(T):
    """``(T̄, (T_p − T_s)/2, 0, 0)`` from T shaped ``(2, *B)`` → ``(*B[:-1], 4, wl)``."""
    T_s, T_p = T[0], T[1]
    zero = jnp.zeros_like(T_s)
    return jnp.stack([0.5 * (T_s + T_p), 0.5 * (T_p - T_s), zero, zero], axis=-2)


@public_program
def diffuse_mueller(
    stack: Stack, wavelength_nm, incidence_deg: RealLike, viewing_deg: RealLike, *, nodes: int = DEFAULT_NODES
) -> Float[Array, "*angle 4 4 wl"]:
    r"""Mueller matrix of the diffuse BRDF (1/sr): the rank-one partial polarizer
    :math:`K\, v(\theta_r)\, v(\theta_i)^T`, :math:`v = (\bar T, (T_p - T_s)/2, 0, 0)`.

    :math:`m_{00}` is the natural-light BRDF; illuminating with the Stokes vector of *a* and
    projecting on the analyser *b* gives :func:`polarized_brdf`. Arguments as there; returns
    ``(*angle, 4, 4, wl)`` (conventions: module docstring).
    """
    th_i, th_v = _angles(incidence_deg, viewing_deg)
    rs = resolve(stack, wavelength_nm)
    K = _background_factor(stack, rs, nodes)
    v_in = _partial_polarizer_vector(_T_pol(rs, th_i))  # (*angle, 4, wl)
    v_out = _partial_polarizer_vector(_T_pol(rs, th_v))
    return K * v_out[..., :, None, :] * v_in[..., None, :, :]


# ------------------------------------------------------------------ specular: s–p correlations
# The correlations of a packet travel in a PacketIntensities whose leading axis is 3,
# (|a_s|², |a_p|², a_p ā_s) (complex dtype), instead of (s, p): the adding rule is the same.


def _triple(a_s, a_p, w_s=1.0, w_p=1.0):
    w_x = jnp.sqrt(w_s * w_p)
    w_s, w_p, w_x = (as_complex(w, a_s, a_p) for w in (w_s, w_p, w_x))
    return jnp.stack([a_s * jnp.conj(a_s) * w_s, a_p * jnp.conj(a_p) * w_p, a_p * jnp.conj(a_s) * w_x])


def _flux_ratio(n_to, q_to, n_from, q_from):
    ratio = safe_divide(power_flux(n_to, q_to), power_flux(n_from, q_from))
    return jnp.maximum(ratio, 0.0)


def _packet_correlations(n, d, s, wl, both_sides: bool) -> PacketIntensities:
    gamma, tau, q = packet_amplitudes(n, d, s, wl)
    n_first = jnp.asarray(n[0]).astype(q.dtype)
    n_last = jnp.asarray(n[-1]).astype(q.dtype)
    f = _flux_ratio(n_last, q[-1], n_first, q[0])  # (2, *B)
    R_f = _triple(gamma[0], gamma[1])
    T_f = _triple(tau[0], tau[1], f[0], f[1])
    if not both_sides:
        return PacketIntensities(R_f, T_f, None, None)
    gamma_b, tau_b, _ = packet_amplitudes(tuple(n)[::-1], tuple(d)[::-1], s, wl)
    fb = _flux_ratio(n_first, q[0], n_last, q[-1])
    return PacketIntensities(R_f, T_f, _triple(gamma_b[0], gamma_b[1]), _triple(tau_b[0], tau_b[1], fb[0], fb[1]))


def _front_reflection_correlations(rs: ResolvedStack, s):
    """``(R_s, R_p, X)`` of the front reflection, shaped ``(3, *B)`` (complex dtype)."""
    return front_correlations(rs, s).R_front


def front_correlations(rs: ResolvedStack, s) -> PacketIntensities:
    r"""The whole stack's correlations for light from the ambient at Snell invariant ``s``:
    a :class:`~layerstack_jax._kernels.coherent.PacketIntensities` whose ``R_front`` and ``T_front`` are
    each ``(3, *B)`` complex, :math:`(|a_s|^2, |a_p|^2, \langle a_p \bar a_s\rangle)` of the
    front reflection and of the transmission into the exit (flux-normalized: the first two are
    :math:`R_s, R_p` and :math:`T_s, T_p`), composed through thick layers by the adding rule
    (module docstring). ``R_back``, ``T_back``: the same for light from the exit side (None
    for a single coherent packet)."""
    wl = rs.wavelength
    thick = thick_media(rs.coherent)
    sides = len(thick) > 2
    packets = [_packet_correlations(rs.n[a : b + 1], rs.d[a : b - 1], s, wl, sides)
               for a, b in zip(thick[:-1], thick[1:])]
    beer = [beer_attenuation(rs.n[a], normal_wavevector(rs.n[a], s), rs.d[a - 1], rs.alpha[a - 1], wl)
            for a in thick[1:-1]]
    return add_layers(packets, beer)


def _reflection_mueller(R_s, R_p, X):
    r"""Mueller matrix ``(*B, 4, 4)``-by-``wl`` of a reflection with s–p correlation
    :math:`X = \langle r_p \bar r_s\rangle`, in the instruments' frame (module docstring):
    :math:`m_{23} = -\operatorname{Im} X = m_{00}\sin 2\psi\sin\Delta`."""
    m00 = 0.5 * (R_s + R_p)
    m01 = 0.5 * (R_p - R_s)
    re, im = jnp.real(X), jnp.imag(X)
    z = jnp.zeros_like(m00)
    rows = [
        [m00, m01, z, z],
        [m01, m00, z, z],
        [z, z, re, -im],
        [z, z, im, re],
    ]
    return jnp.stack([jnp.stack(row, axis=-2) for row in rows], axis=-3)


@public_program
def specular_mueller(stack: Stack, wavelength_nm, angle_deg: RealLike) -> Float[Array, "*angle 4 4 wl"]:
    r"""Mueller matrix of the stack's specular (front) reflection, dimensionless.

    From the per-polarization reflectances :math:`R_s, R_p` and the s–p correlation
    :math:`X = \langle r_p\bar r_s\rangle` (module docstring):

    .. math::
        M = \begin{pmatrix} \bar R & (R_p - R_s)/2 & 0 & 0\\ (R_p - R_s)/2 & \bar R & 0 & 0\\
            0 & 0 & \operatorname{Re}X & -\operatorname{Im}X\\ 0 & 0 & \operatorname{Im}X &
            \operatorname{Re}X\end{pmatrix}

    in the instruments' frame (module docstring: :math:`m_{23} = m_{00} \sin 2\psi \sin\Delta`
    with Δ as ellipsometers report it, positive over silicon).

    For a coherent top packet :math:`X = r_p \bar r_s` carries the s–p retardance
    (:math:`\Delta = -\arg X`); light returned through thick incoherent layers adds its
    correlation incoherently. :math:`m_{00}` is the natural-light specular reflectance.
    Ellis's specular BRDF term is this matrix times :math:`\delta(\theta_r-\theta_i)
    \delta(\phi_r-\phi_i+\pi)/(\cos\theta_r\sin\theta_r)`.

    Args:
        stack: any stack (exit: substrate, or a background's binder as its specular face).
        wavelength_nm: ``(wl,)`` nm.
        angle_deg: angle of incidence, degrees in [0, 90), any shape ``(*angle)``.

    Returns:
        ``(*angle, 4, 4, wl)``.
    """
    angle_deg = check_angle_deg("angle_deg", angle_deg)
    rs = resolve(stack, wavelength_nm)
    th = jnp.deg2rad(jnp.asarray(angle_deg, dtype=float))
    s = snell_invariant(rs.n[0], th)
    c = _front_reflection_correlations(rs, s)
    c = jnp.broadcast_to(c, (3, *jnp.shape(th), rs.wavelength.shape[-1]))
    return _reflection_mueller(jnp.real(c[0]), jnp.real(c[1]), c[2])


# ------------------------------------------------------------------ generic Mueller tools
def mueller_from_jones(J):
    r"""Mueller matrix :math:`M_{kl} = \tfrac12\operatorname{tr}(J^\dagger\sigma_k J\sigma_l)` of a
    Jones matrix ``J`` shaped ``(*batch, 2, 2)`` in the ``(p, s)`` basis; returns
    ``(*batch, 4, 4)`` (here the matrix axes are last: a helper for single matrices). J and M
    are dimensionless (amplitude and intensity transfer ratios)."""
    J = jnp.asarray(J)
    sig = jnp.asarray(PAULI)
    Jh = jnp.conj(jnp.swapaxes(J, -1, -2))
    M = 0.5 * jnp.einsum("...ab,kbc,...cd,lda->...kl", Jh, sig, J, sig)
    return jnp.real(M)


def apply_mueller(M, S):
    """Mueller matrix ``(*batch, 4, 4, wl)`` times Stokes vector ``(*batch, 4, wl)`` (broadcast).

    M is dimensionless (outgoing over incident intensity); the result ``(*batch, 4, wl)`` is
    in the unit of ``S``.
    """
    return jnp.sum(jnp.asarray(M) * jnp.asarray(S)[..., None, :, :], axis=-2)


def degree_of_polarization(S):
    r"""Degree of polarization :math:`\sqrt{Q^2+U^2+V^2}/I` of Stokes vectors ``(*batch, 4, wl)``;
    returns ``(*batch, wl)``, a dimensionless fraction in [0, 1] for physical Stokes vectors
    (0 where I = 0, with a finite gradient)."""
    S = jnp.asarray(S)
    I = S[..., 0, :]
    p2 = jnp.sum(S[..., 1:, :] ** 2, axis=-2)
    return safe_divide(safe_sqrt(p2), I)


def coherency_matrix(M):
    r"""Cloude coherency matrix :math:`H = \tfrac14\sum_{kl} m_{kl}\,\sigma_k\otimes\bar\sigma_l`
    (Cloude 1986) of a Mueller matrix ``(*batch, 4, 4, wl)``; returns ``(*batch, wl, 4, 4)``
    Hermitian with :math:`\operatorname{tr} H = m_{00}`. For a pure (Jones) Mueller matrix H is
    rank one; M is a convex sum of Jones systems (physically realizable) iff H ⪰ 0.
    The elements are dimensionless, like M."""
    sig = jnp.asarray(PAULI)
    basis = jnp.einsum("kab,lcd->klacbd", sig, jnp.conj(sig)).reshape(4, 4, 4, 4)
    return 0.25 * jnp.einsum("...klw,klij->...wij", as_complex(M, basis), basis)


def cloude_eigenvalues(M):
    """Eigenvalues (ascending) of the Cloude coherency matrix of ``M`` ``(*batch, 4, 4, wl)``;
    returns ``(*batch, 4, wl)``, dimensionless (they sum to :math:`m_{00}`). All ≥ 0 for a
    physically realizable Mueller matrix."""
    lam = jnp.linalg.eigvalsh(coherency_matrix(M))
    return jnp.moveaxis(lam, -1, -2)


def is_physical(M, tol: float = 1e-10):
    r"""True where ``M`` ``(*batch, 4, 4, wl)`` is physically realizable: every Cloude eigenvalue
    :math:`\ge -\text{tol}\cdot m_{00}`. Returns a boolean array ``(*batch, wl)``. ``tol`` is
    dimensionless (relative to :math:`m_{00}`)."""
    lam = cloude_eigenvalues(M)
    m00 = jnp.asarray(M)[..., 0, 0, :]
    return jnp.all(lam >= -tol * jnp.abs(m00)[..., None, :], axis=-2)
