r"""Ellipsometry: ψ and Δ as ellipsometers report them — of coherent stacks, of thick substrates
with their incoherent backside reflection, in reflection and in transmission.

This module owns the physics of the reading: the amplitudes (:func:`reflection_amplitudes`,
:func:`transmission_amplitudes`), ψ/Δ (:func:`psi_delta`, :func:`ellipsometry`), the normalized
Mueller elements N, C, S (:func:`mueller_ncs`, :func:`correlation_ncs`, :func:`stack_ncs`) and
their bandwidth and thickness averages (:func:`averaged_ncs`, :func:`reading_from_ncs`). The
instrument that reads them in a fit — the :class:`Ellipsometric` geometry, its quantities and
residuals, and the grouping of readings of one stack (:func:`shared_readings`) — is
:mod:`layerstack_jax._instruments.ellipsometer`.

An ellipsometer measures the change of polarization state on specular reflection, i.e. the
ratio of the complex amplitude reflection coefficients of the stack for p and s light,

.. math::
    \rho(\lambda, \theta_0) = \frac{r_p}{r_s} = \tan\psi\; e^{-i\Delta},

with :math:`r_s, r_p` the composite amplitudes :math:`\gamma` of the Rouard recursion
(Hirayama et al. eqs. 1–4; :func:`layerstack_jax._kernels.coherent.packet_amplitudes`).

Conventions (the package's physics, see :mod:`layerstack_jax._kernels.fresnel`)
-----------------------------------------------------------------------
* Time dependence :math:`e^{-i\omega t}`, index :math:`n + ik` with :math:`k \ge 0`.
* Amplitudes as in Born & Wolf and ``tmm``: :math:`r_s = (q_i - q_f)/(q_i + q_f)`,
  :math:`r_p = (n_f^2 q_i - n_i^2 q_f)/(n_f^2 q_i + n_i^2 q_f)`; at normal incidence
  :math:`r_p = -r_s`.

The reported Δ: the instruments' convention
--------------------------------------------
Ellipsometers (J. A. Woollam, Sentech SpectraRay, Accurion) and the peer codes pyElli and
refellips report :math:`\Delta = -\arg(r_p/r_s)` in the physics above — equivalently
:math:`\tan\psi\, e^{i\Delta} = r_p/r_s` written with :math:`e^{+i\omega t}` and
:math:`n - ik` (the "Nebraska" convention of Azzam & Bashara and Fujiwara). So does this
module:

* :math:`\Delta = -\arg(r_p/r_s)`, reported in (−180°, 180°] (a real negative :math:`\rho`
  gives +180°, never −180°); add 360° to negative values for an instrument's [0°, 360°) file.
  :math:`\psi = \arctan|r_p/r_s| \in [0°, 90°]`.
* Over a bare absorbing substrate :math:`\Delta \in (0°, 180°)`: silicon with its 2 nm native
  oxide at 70° reads :math:`\Delta \approx 110°`–174° from 250 to 800 nm in a Woollam RC2 file
  (tests/test_ellipsometry.py matches it to < 1° rms; the opposite sign misses it by > 40° rms).
* Lossless dielectric substrate: :math:`\Delta = 180°` below Brewster's angle, 0° above,
  :math:`\psi = 45°` at normal incidence, 0° at Brewster's angle (Fujiwara's textbook values).
* ``tmm.ellips`` returns the same ψ and :math:`\Delta_\text{tmm} = \arg(-r_p/r_s)`, so
  :math:`\Delta = 180° - \Delta_\text{tmm}` (wrapped into (−180°, 180°]).
* :attr:`Ellipsometry.rho` stays the physical ratio :math:`r_p/r_s = \tan\psi\,e^{-i\Delta}`
  (pyElli's ``Result.rho`` is the same number); the instruments' complex ratio
  :math:`\tan\psi\,e^{i\Delta}` is its complex conjugate.
* The wrap-free combinations :math:`N = \cos 2\psi`, :math:`C = \sin 2\psi\cos\Delta`,
  :math:`S = \sin 2\psi \sin\Delta` (what rotating-compensator instruments measure, with the
  same Δ) are smooth everywhere; the normalized Mueller matrix of the reflection is
  :math:`[[1, -N, 0, 0], [-N, 1, 0, 0], [0, 0, C, S], [0, 0, -S, C]]`, as measured
  (:mod:`layerstack_jax._instruments.polarimetry`).

Instrument non-idealities: offset, bandwidth, thickness non-uniformity, depolarization
-------------------------------------------------------------------------------------
:class:`Ellipsometric` also models the imperfections vendor software fits (all default to the
ideal instrument, whose reading is bit-identical to :func:`ellipsometry`):

* ``angle_offset_deg`` :math:`\delta\theta` (degrees): every angle read as
  :math:`\theta_0 + \delta\theta`.
* ``bandwidth_nm`` *b* (nm): the monochromator's Gaussian instrument function of FWHM *b*,
  :math:`\sigma_\lambda = b / (2\sqrt{2\ln 2})`.
* ``thickness_spread`` *s* (dimensionless): the thickness of layer ``nonuniform_layer`` is
  Gaussian over the light spot, :math:`d \sim \mathcal N(d_0, (s d_0)^2)`.

Light of different wavelengths or from different points of the spot adds incoherently, so the
instrument reads the *average* of the normalized Mueller elements (never of ρ):

.. math::
    \bar N = \langle N \rangle,\quad \bar C = \langle C \rangle,\quad \bar S = \langle S \rangle,
    \qquad N = \frac{|r_s|^2 - |r_p|^2}{|r_s|^2 + |r_p|^2},\;
    C + iS = \frac{2\, r_s \bar r_p}{|r_s|^2 + |r_p|^2}

(the same N = cos 2ψ, C = sin 2ψ cos Δ, S = sin 2ψ sin Δ as above, written in the amplitudes),
the mean over :math:`\lambda' \sim \mathcal N(\lambda, \sigma_\lambda^2)` and
:math:`d \sim \mathcal N(d_0, (s d_0)^2)` taken by a fixed Gauss–Hermite rule in each
variable, :math:`\langle f \rangle = \sum_k w_k f(\mu + \sigma x_k)` with
:math:`x_k = \sqrt 2\,t_k`, :math:`w_k = \omega_k/\sqrt\pi` (:math:`t_k, \omega_k` of
``numpy.polynomial.hermite.hermgauss``; exact for polynomials of degree ≤ 2K − 1), vectorised over
the nodes. K = ``Ellipsometric.average_nodes`` (static, default 21 per variable). The Airy
response of a film is far from a low-degree polynomial in its thickness (multiple-beam
harmonics): for 100 nm of n = 1.46 on n = 3.88 + 0.02i at 65–75°, 400–633 nm, the error of the
averaged N, C, S against dense quadrature is 4e-7 with 9 nodes, 6e-9 with 13 and < 2e-10 with
17 at a 5 % spread, but 3.5e-4 (9), 8e-6 (17) and 4e-7 (25) at 10 %; the default 21 gives 8e-12
(5 %) and 1.6e-6 (10 %) — raise ``average_nodes`` for wide spreads of thick films. The spread
is limited to :math:`s\,x_K < 1` (every node thickness positive: s < 0.127 with 21 nodes).
The averaged normalized Mueller matrix keeps the form
:math:`[[1, -\bar N, 0, 0], [-\bar N, 1, 0, 0], [0, 0, \bar C, \bar S], [0, 0, -\bar S, \bar C]]`
and is depolarizing: :math:`P = \sqrt{\bar N^2 + \bar C^2 + \bar S^2} \le 1` (the norm of a mean of unit vectors;
P = 1 for the ideal instrument, since :math:`N^2 + C^2 + S^2 = 1`). Reported from
:math:`\bar N, \bar C, \bar S`:

.. math::
    \psi = \tfrac12 \operatorname{atan2}\bigl(\sqrt{\bar C^2 + \bar S^2},\, \bar N\bigr),
    \qquad \Delta = \operatorname{atan2}(\bar S, \bar C),
    \qquad \text{depolarization} = 1 - P \in [0, 1]

(the ψ, Δ of the unit vector :math:`(\bar N, \bar C, \bar S)/P` — equal to the ideal ψ, Δ when
P = 1; depolarization as a fraction, not in %). The ``'N'``, ``'C'``, ``'S'`` quantities
read :math:`\bar N, \bar C, \bar S` themselves; ``'rho_re'``, ``'rho_im'`` read
:math:`\tan\psi\, e^{-i\Delta}` of the reported ψ, Δ. All three parameters are pytree
leaves of the geometry: differentiable and fittable (``fitting.instrument``).

Thick substrates: the incoherent backside reflection
----------------------------------------------------
A glass slide or wafer is declared as usual: coherent films, then ``Layer(n_glass, thickness,
coherent=False)``, then the medium behind it (``Substrate(1.0)`` for air). Light returned from the
backside reaches the detector as a train of beams m = 0, 1, 2, … — the front reflection, then
the beams that crossed the slab 2m times — whose mutual phases are lost (the slab is much
thicker than the coherence length), so they add in intensity: the instrument reads the
*incoherent sum* of their Mueller matrices, partially depolarized. For each beam the s and p
components travel the same path (the normal wavevector does not depend on polarization), so
their correlation :math:`X = \langle a_p \bar a_s\rangle` survives and composes through the slab
by the same adding rule as the intensities (:mod:`layerstack_jax._instruments.polarimetry`,
:func:`~layerstack_jax._instruments.polarimetry.front_correlations`; Simonot eqs. 51, 53 with
:math:`R \to X`):

.. math::
    X = r^A_p \bar r^A_s + \frac{(t^A_p t'^A_p)\,\overline{(t^A_s t'^A_s)}\; r^B_p \bar r^B_s\; t^2}
        {1 - r'^A_p \bar r'^A_s\, r^B_p \bar r^B_s\, t^2}
        = \sum_{m \ge 0} a_{p,m} \bar a_{s,m},

(A the front packet, B the back one, primes from inside the slab, t the slab's single-pass
intensity attenuation of :func:`layerstack_jax._kernels.incoherent.beer_attenuation`) and likewise
:math:`R_s, R_p` with :math:`|\cdot|^2`. The reading (:func:`stack_ncs`, :func:`correlation_ncs`):

.. math::
    N = \frac{R_s - R_p}{R_s + R_p},\qquad C = \frac{2\operatorname{Re}X}{R_s + R_p},\qquad
    S = -\frac{2\operatorname{Im}X}{R_s + R_p},

the normalized Mueller matrix :math:`[[1, -N, 0, 0], [-N, 1, 0, 0], [0, 0, C, S], [0, 0, -S, C]]`
of :func:`~layerstack_jax.specular_mueller`, reported as above:
:math:`\psi = \tfrac12\operatorname{atan2}(\sqrt{C^2+S^2}, N)`,
:math:`\Delta = \operatorname{atan2}(S, C)` (the instruments' Δ: for a single beam these are
:func:`psi_delta`'s), depolarization :math:`1 - \sqrt{N^2+C^2+S^2} \in [0, 1]`. It is 0 where
only one beam returns — the back index-matched (a taped backside, ``Substrate(n_glass)``), an
opaque slab — and at normal incidence (every beam has :math:`a_p = -a_s`); it grows with the
backside's share of the light, e.g. towards Brewster's angle of the front face. Such a stack is
read by :class:`Ellipsometric` (``reading``, ``measure``: every quantity, every non-ideality on
top — the bandwidth and thickness averages of N, C, S above apply to the incoherent sums as they
are); :func:`ellipsometry` keeps its ratio :math:`\rho = r_p/r_s`, defined for coherent stacks
only, and refuses. Checked against a beam-by-beam numpy summation of the Mueller matrices
(tests/test_ellipsometry_backside.py, ≤ 1e-10). A purely coherent stack still takes the
amplitude path (bit-identical to :func:`ellipsometry`): the branch is on the static stack
structure.

Transmission ellipsometry
-------------------------
``Ellipsometric(angle, quantity, mode="transmission")`` reads the beam transmitted into the
exit medium (which must be transparent: k = 0, a :class:`~layerstack_jax.Substrate`):

.. math::
    \rho_t = \frac{t_p}{t_s} = \tan\psi_t\, e^{-i\Delta_t},\qquad
    \Delta_t = -\arg(t_p/t_s) = \arg(t_s \bar t_p),

with the field amplitudes :math:`t_s, t_p` of ``tmm`` (Born & Wolf: one interface has
:math:`t_s = 2q_i/(q_i + q_f)`, :math:`t_p = 2 n_i n_f q_i/(n_f^2 q_i + n_i^2 q_f)`) and the same
Δ sign as in reflection; N, C, S, ``rho_re``, ``rho_im``, depolarization as above with
:math:`t` for :math:`r`. At normal incidence :math:`t_p = t_s`: ψ_t = 45°, Δ_t = 0. One
interface between transparent media gives a real
:math:`t_p/t_s = (n_i\cos\theta_i + n_f\cos\theta_f)/(n_f\cos\theta_i + n_i\cos\theta_f) \ge 1`:
Δ_t = 0, ψ_t ≥ 45°. Thick layers in the path (a slab between films) are summed incoherently as
in reflection (:math:`T_s, T_p`, :math:`X_t = \langle t_p \bar t_s\rangle` of the adding rule).
Spelled ``ellipsometry:ANGLE:QUANTITY:transmission`` on the command line and in files
(:meth:`Ellipsometric.parse`).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple, Union

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._base.custom_types import Array, Complex, Float, RealLike
from .._base.numerics import abs2, safe_abs, safe_atan2, safe_divide, safe_sqrt
from .._base.programs import public_program
from .._base.validate import LayerstackError, check, check_angle_deg
from .._kernels.coherent import packet_amplitudes
from .._stacks.illumination import snell_invariant
from .._stacks.stack import ResolvedStack, Stack, resolve
from .polarimetry import front_correlations

__all__ = ["Ellipsometry", "EllipsometerReading", "ellipsometry", "reflection_amplitudes", "psi_delta", "wrap_degrees"]

#: what an :class:`Ellipsometric` geometry analyses: the specular reflection or the transmitted beam
MODES = ("reflection", "transmission")

#: Gauss–Hermite nodes per averaged variable (wavelength, thickness): a static number (the
#: default of ``Ellipsometric.average_nodes``; accuracy in the module docstring)
GAUSS_NODES = 21

#: σ of a Gaussian per unit FWHM, :math:`1/(2\sqrt{2\ln 2})`
FWHM_TO_SIGMA = 1.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))


class Ellipsometry(NamedTuple):
    r"""Ellipsometric response, every field shaped ``(*angle, wl)``.

    Attributes:
        psi_deg: :math:`\psi` in degrees, in [0, 90].
        delta_deg: :math:`\Delta = -\arg(r_p/r_s)` in degrees, in (−180, 180]: the sign
            ellipsometers report (module docstring).
        rho: complex :math:`\rho = r_p/r_s = \tan\psi\, e^{-i\Delta}` (physics convention
            :math:`e^{-i\omega t}`, as pyElli's ``Result.rho``).
    """

    psi_deg: Float[Array, "*angle wl"]
    delta_deg: Float[Array, "*angle wl"]
    rho: Complex[Array, "*angle wl"]

    @property
    def N(self):
        r""":math:`\cos 2\psi` (smooth, for fitting)."""
        return jnp.cos(2 * jnp.deg2rad(self.psi_deg))

    @property
    def C(self):
        r""":math:`\sin 2\psi \cos\Delta` (smooth, for fitting)."""
        return jnp.sin(2 * jnp.deg2rad(self.psi_deg)) * jnp.cos(jnp.deg2rad(self.delta_deg))

    @property
    def S(self):
        r""":math:`\sin 2\psi \sin\Delta` (smooth, for fitting)."""
        return jnp.sin(2 * jnp.deg2rad(self.psi_deg)) * jnp.sin(jnp.deg2rad(self.delta_deg))


def wrap_degrees(angle_deg):
    r"""An angle difference in degrees wrapped into (−180°, 180°]: ``180 - ((180 - x) mod 360)``.

    ``angle_deg``: any shape (degrees); returns the same shape. Used for Δ residuals
    (:meth:`Ellipsometric.residual`): 350° − (−5°) = 355° is −5°, not 355°.

    Differentiable: away from the odd multiples of 180° it is :math:`x - 360°k` with a locally
    constant integer k, so its derivative is exactly 1 (JAX's ``remainder`` has derivative 1 in
    its first argument) — no trigonometry, no division, no NaN. At ±180° the wrapped value jumps
    from 180° to −180°, but the least-squares cost (its square) is continuous there: the
    residual of a point whose model and data are opposite on the circle is 180° either way.
    """
    return 180.0 - jnp.remainder(180.0 - jnp.asarray(angle_deg), 360.0)


def psi_delta(r_s, r_p):
    r""":math:`(\psi, \Delta)` in radians from the amplitude reflection coefficients.

    :math:`\psi = \operatorname{atan2}(|r_p|, |r_s|)`, :math:`\Delta = \arg(r_s \bar r_p)
    = -\arg(r_p/r_s)` (the instruments' sign, module docstring); both are NaN-free with
    finite gradients also at Brewster's angle (:math:`r_p = 0`).

    ``r_s``, ``r_p``: complex amplitude coefficients (dimensionless, convention
    :math:`e^{-i\omega t}`), broadcast against each other to ``(*B)`` (e.g. ``(*angle, wl)``).
    Returns ``(psi, delta)``, each ``(*B)``, in radians: ψ in [0, π/2], Δ in (−π, π].
    """
    psi = safe_atan2(safe_abs(r_p), safe_abs(r_s))
    c = r_s * jnp.conj(r_p)  # arg = -arg(r_p / r_s): the sign ellipsometers report
    delta = safe_atan2(jnp.imag(c), jnp.real(c))
    # atan2(-0.0, x < 0) = -pi: a real negative rho must give +pi (range (-pi, pi]).
    delta = jnp.where(delta <= -jnp.pi, jnp.pi, delta)
    return psi, delta


def is_coherent(stack: Stack) -> bool:
    """True when every layer of ``stack`` is coherent (static: the structure, not the numbers)."""
    return all(stack.coherent)


def _check_coherent(stack: Stack) -> None:
    for i, layer in enumerate(stack.layers):
        if not layer.coherent:
            raise LayerstackError(
                f"layers[{i}] ({layer.name or 'unnamed'}): ellipsometry() needs a fully coherent stack "
                "(a ratio r_p/r_s); a thick incoherent layer depolarizes: read it with "
                "layerstack_jax.Ellipsometric(angle_deg).reading(stack, wavelength_nm) (psi, Delta, N, C, S and "
                "the depolarization) or layerstack_jax.specular_mueller"
            )


def _amplitudes_resolved(rs: ResolvedStack, angle_rad):
    s = snell_invariant(rs.n[0], angle_rad)
    gamma, _, _ = packet_amplitudes(rs.n, rs.d, s, rs.wavelength)
    shape = jnp.broadcast_shapes(gamma.shape[1:], jnp.shape(s)[:-1] + (rs.wavelength.shape[-1],))
    return jnp.broadcast_to(gamma[0], shape), jnp.broadcast_to(gamma[1], shape)


def _check_transmission(stack: Stack, rs: ResolvedStack) -> ResolvedStack:
    """Transmission ellipsometry reads the beam leaving into a transparent specular exit medium:
    ``rs`` with its exit index checked (k = 0; eagerly, or by ``equinox.error_if`` when traced)."""
    if rs.rho_g is not None:
        raise LayerstackError("exit: transmission ellipsometry reads the beam transmitted into a specular exit "
                              "medium (a Substrate), not into a diffusing body (a LambertianBackground, a "
                              "KubelkaMunk body …)")
    n_exit = check("exit index", rs.n[-1], lambda a, xp: xp.imag(a) != 0,
                   "must be transparent (k = 0) for transmission ellipsometry: the transmitted beam reaches the "
                   "analyser through it")
    return rs._replace(n=(*rs.n[:-1], n_exit))


def transmission_amplitudes(stack: Stack, wavelength_nm, angle_deg: RealLike):
    r"""Complex amplitude transmission coefficients :math:`(t_s, t_p)` of a coherent stack
    into a transparent exit medium (the field ratios of ``tmm``: at normal incidence
    :math:`t_p = t_s`). Arguments as :func:`reflection_amplitudes`; returns two complex arrays
    ``(*angle, wl)``."""
    _check_coherent(stack)
    check_angle_deg("angle_deg", angle_deg)
    rs = _check_transmission(stack, resolve(stack, wavelength_nm))
    s = snell_invariant(rs.n[0], jnp.deg2rad(angle_deg))
    _, tau, _ = packet_amplitudes(rs.n, rs.d, s, rs.wavelength)
    shape = jnp.broadcast_shapes(tau.shape[1:], jnp.shape(s)[:-1] + (rs.wavelength.shape[-1],))
    return jnp.broadcast_to(tau[0], shape), jnp.broadcast_to(tau[1], shape)


@public_program
def reflection_amplitudes(stack: Stack, wavelength_nm, angle_deg: RealLike):
    r"""Complex amplitude reflection coefficients :math:`(r_s, r_p)` of a coherent stack.

    Args:
        stack: ambient · coherent films · exit (a :class:`~layerstack_jax.Substrate`, or the
            binder of a :class:`~layerstack_jax.LambertianBackground`: its specular face).
        wavelength_nm: ``(wl,)`` vacuum wavelengths, nm.
        angle_deg: angle of incidence in the ambient, degrees in [0, 90); any shape ``(*angle)``.

    Returns:
        ``(r_s, r_p)``, complex arrays shaped ``(*angle, wl)`` (module conventions).
    """
    _check_coherent(stack)
    check_angle_deg("angle_deg", angle_deg)
    rs = resolve(stack, wavelength_nm)
    return _amplitudes_resolved(rs, jnp.deg2rad(angle_deg))


@public_program
def ellipsometry(stack: Stack, wavelength_nm, angle_deg: RealLike) -> Ellipsometry:
    r"""Ellipsometric angles :math:`\psi, \Delta` and ratio :math:`\rho = r_p/r_s` of a coherent stack.

    A pure, jit-, vmap- and grad-compatible function of the stack's leaves (thicknesses, n, k):
    differentiate ``psi_deg``, ``delta_deg`` or (better, wrap-free) ``rho``, ``N``, ``C``, ``S``
    with respect to any of them.

    A stack with thick incoherent layers (a transparent substrate with its backside) has no
    single ratio :math:`r_p/r_s` and is refused: read it with :class:`Ellipsometric` (module
    docstring, "Thick substrates").

    Args:
        stack: ambient (real index) · coherent films · exit medium.
        wavelength_nm: ``(wl,)`` vacuum wavelengths, nm.
        angle_deg: angle of incidence, degrees in [0, 90); scalar or any shape ``(*angle)``.

    Returns:
        :class:`Ellipsometry` with fields shaped ``(*angle, wl)``; Δ with the sign and range
        ellipsometers report (Woollam, Sentech, Accurion, pyElli, refellips); relation to
        ``tmm.ellips`` in the module docstring.
    """
    r_s, r_p = reflection_amplitudes(stack, wavelength_nm, angle_deg)
    psi, delta = psi_delta(r_s, r_p)
    return Ellipsometry(jnp.rad2deg(psi), jnp.rad2deg(delta), r_p / r_s)



class EllipsometerReading(NamedTuple):
    r"""What a (possibly non-ideal) ellipsometer reads, every field shaped ``(*angle, wl)``.

    Attributes:
        psi_deg, delta_deg: ψ in [0, 90] and Δ in (−180, 180] degrees, from :math:`\bar N,
            \bar C, \bar S` (module docstring, "Instrument non-idealities").
        N, C, S: the (averaged) normalized Mueller elements, dimensionless.
        depolarization: :math:`1 - \sqrt{N^2 + C^2 + S^2}` in [0, 1] (0 for the ideal instrument).
    """

    psi_deg: Float[Array, "*angle wl"]
    delta_deg: Float[Array, "*angle wl"]
    N: Float[Array, "*angle wl"]
    C: Float[Array, "*angle wl"]
    S: Float[Array, "*angle wl"]
    depolarization: Float[Array, "*angle wl"]


@functools.lru_cache(maxsize=None)
def standard_normal_rule(nodes: int = GAUSS_NODES) -> tuple[np.ndarray, np.ndarray]:
    r"""Gauss–Hermite rule for the mean over a standard normal variable X (float64 numpy).

    Returns ``(x, w)``, each ``(nodes,)``, with :math:`E[f(X)] \approx \sum_k w_k f(x_k)`:
    :math:`x_k = \sqrt 2\, t_k`, :math:`w_k = \omega_k / \sqrt\pi` from the physicists' rule
    :math:`\int e^{-t^2} g(t)\,dt \approx \sum_k \omega_k g(t_k)` (exact for polynomials f of
    degree ≤ 2·nodes − 1); the weights sum to 1.
    """
    t, w = np.polynomial.hermite.hermgauss(nodes)
    return math.sqrt(2.0) * t, w / math.sqrt(math.pi)


def mueller_ncs(r_s, r_p):
    r"""Normalized Mueller elements :math:`(N, C, S)` of a non-depolarizing reflection.

    :math:`N = (|r_s|^2 - |r_p|^2)/(|r_s|^2 + |r_p|^2)` and
    :math:`C + iS = 2 r_s \bar r_p / (|r_s|^2 + |r_p|^2)` — the same cos 2ψ, sin 2ψ cos Δ,
    sin 2ψ sin Δ as :class:`Ellipsometry` (Δ = arg(r_s r̄_p), module docstring), written without
    angles so that they are smooth to average. ``r_s``, ``r_p``: complex, broadcast to ``(*B)``;
    returns three real ``(*B)`` arrays (0 where both amplitudes vanish).
    """
    total = abs2(r_s) + abs2(r_p)
    cross = 2.0 * r_s * jnp.conj(r_p)
    return (safe_divide(abs2(r_s) - abs2(r_p), total), safe_divide(jnp.real(cross), total),
            safe_divide(jnp.imag(cross), total))


def correlation_ncs(Q_s, Q_p, X):
    r"""Normalized Mueller elements :math:`(N, C, S)` of a partially depolarizing beam from its
    intensities :math:`Q_s, Q_p` (:math:`R_s, R_p` or :math:`T_s, T_p`) and s–p correlation
    :math:`X = \langle a_p \bar a_s\rangle` (:func:`layerstack_jax._instruments.polarimetry.front_correlations`):

    .. math::
        N = \frac{Q_s - Q_p}{Q_s + Q_p},\qquad C = \frac{2\operatorname{Re} X}{Q_s + Q_p},\qquad
        S = -\frac{2\operatorname{Im} X}{Q_s + Q_p}

    (for one coherent beam :math:`X = a_p \bar a_s` and these are :func:`mueller_ncs`).
    Real ``Q_s, Q_p``, complex ``X``, broadcast to ``(*B)``; returns three real ``(*B)`` arrays
    (0 where no light arrives)."""
    total = Q_s + Q_p
    return (safe_divide(Q_s - Q_p, total), safe_divide(2.0 * jnp.real(X), total),
            safe_divide(-2.0 * jnp.imag(X), total))


def stack_ncs(stack: Stack, wavelength_nm, angle_deg, mode: str = "reflection"):
    r"""What an ideal ellipsometer reads of any stack: the normalized Mueller elements
    :math:`(N, C, S)` of the specular reflection (``mode='reflection'``) or of the transmitted
    beam (``'transmission'``), each ``(*angle, wl)`` (module docstring, "Thick substrates").

    A coherent stack: :func:`mueller_ncs` of its amplitudes (non-depolarizing,
    :math:`N^2 + C^2 + S^2 = 1`). A stack with thick incoherent layers (e.g. a transparent
    substrate slab with its backside): :func:`correlation_ncs` of the intensities and s–p
    correlations composed through the thick layers by the adding rule
    (:func:`layerstack_jax._instruments.polarimetry.front_correlations`): the incoherent sum of the beams
    returned from the backside, partially depolarizing. ``mode`` and the stack structure are
    static."""
    if mode not in MODES:
        raise LayerstackError(f"mode must be one of {MODES}, got {mode!r}")
    if is_coherent(stack):
        amplitudes = reflection_amplitudes if mode == "reflection" else transmission_amplitudes
        return mueller_ncs(*amplitudes(stack, wavelength_nm, angle_deg))
    check_angle_deg("angle_deg", angle_deg)
    rs = resolve(stack, wavelength_nm)
    if mode == "transmission":
        rs = _check_transmission(stack, rs)
    th = jnp.deg2rad(jnp.asarray(angle_deg, dtype=float))
    s = snell_invariant(rs.n[0], th)
    c = front_correlations(rs, s)
    c = c.R_front if mode == "reflection" else c.T_front
    c = jnp.broadcast_to(c, (3, *jnp.shape(th), rs.wavelength.shape[-1]))
    return correlation_ncs(jnp.real(c[0]), jnp.real(c[1]), c[2])


def reading_from_ncs(N, C, S) -> EllipsometerReading:
    r"""ψ, Δ and depolarization reported from (averaged) :math:`N, C, S` (module docstring):
    :math:`\psi = \tfrac12\operatorname{atan2}(\sqrt{C^2+S^2}, N)`,
    :math:`\Delta = \operatorname{atan2}(S, C)` in (−180°, 180°],
    depolarization :math:`1 - \sqrt{N^2+C^2+S^2}` clipped to [0, 1]. Any shapes that broadcast."""
    psi = 0.5 * safe_atan2(safe_sqrt(C * C + S * S), N)
    delta = safe_atan2(S, C)
    delta = jnp.where(delta <= -jnp.pi, jnp.pi, delta)  # a real negative C/P gives +180°, as psi_delta
    depolarization = jnp.clip(1.0 - safe_sqrt(N * N + C * C + S * S), 0.0, 1.0)
    return EllipsometerReading(jnp.rad2deg(psi), jnp.rad2deg(delta), N, C, S, depolarization)


def _layer_index(stack: Stack, layer: Union[int, str, None]) -> int:
    """Position of the non-uniform layer given by position or name (``Ellipsometric.nonuniform_layer``)."""
    names = [layer_.name for layer_ in stack.layers]
    if isinstance(layer, str):
        hits = [i for i, n in enumerate(names) if n == layer]
        if len(hits) != 1:
            raise LayerstackError(f"Ellipsometric.nonuniform_layer: {len(hits)} layers are named {layer!r} "
                                  f"(layers: {names}); give one name or the position")
        return hits[0]
    if isinstance(layer, int) and not isinstance(layer, bool) and -len(names) <= layer < len(names):
        return layer % len(names)
    raise LayerstackError(f"Ellipsometric.nonuniform_layer: give the layer (position or name) whose thickness "
                          f"spreads; the stack has {len(names)} layer(s) {names}, got {layer!r}")


def averaged_ncs(stack: Stack, wavelength_nm, angle_deg, *, bandwidth_nm=0.0, thickness_spread=0.0,
                 nonuniform_layer: Union[int, str, None] = None, average_wavelength: bool = True,
                 average_thickness: bool = True, nodes: int = GAUSS_NODES, mode: str = "reflection"):
    r"""Incoherent averages :math:`\bar N, \bar C, \bar S` over the instrument's Gaussian
    wavelength band and the Gaussian thickness of one layer (module docstring).

    Args:
        stack: any stack (:func:`stack_ncs`); wavelength_nm: ``(wl,)`` nm; angle_deg: ``(*angle)``
            degrees.
        bandwidth_nm: FWHM b (nm) of the instrument function: :math:`\lambda' = \lambda +
            \sigma_\lambda x_j`, :math:`\sigma_\lambda = b/(2\sqrt{2\ln 2})`.
        thickness_spread: relative σ s of the thickness of ``nonuniform_layer``:
            :math:`d_i = d_0 (1 + s x_i)`.
        average_wavelength, average_thickness: static switches; False drops that variable's
            nodes (its mean is then the value at the centre).
        nodes: Gauss–Hermite nodes per averaged variable (static).
        mode: ``'reflection'`` or ``'transmission'`` (static; :func:`stack_ncs`).

    Returns ``(N, C, S)``, each ``(*angle, wl)``: :math:`\sum_{i,j} w_i w_j\, N(\lambda +
    \sigma_\lambda x_j;\, d_i)` etc., the nodes of :func:`standard_normal_rule` evaluated in one
    vectorised call (the thickness nodes by ``jax.vmap``).
    """
    x, w = standard_normal_rule(nodes)
    wl = jnp.asarray(wavelength_nm)
    one = (np.zeros(1), np.ones(1))
    xl, wlw = (x, w) if average_wavelength else one
    xd, wdw = (x, w) if average_thickness else one
    nodes_wl = (wl[None, :] + FWHM_TO_SIGMA * bandwidth_nm * jnp.asarray(xl)[:, None]).reshape(-1)  # (Kl*wl,)

    def ncs(st):
        values = jnp.stack(stack_ncs(st, nodes_wl, angle_deg, mode))  # (3, *angle, Kl*wl)
        values = values.reshape(values.shape[:-1] + (xl.size, wl.shape[-1]))
        return jnp.tensordot(values, jnp.asarray(wlw), axes=([-2], [0]))  # (3, *angle, wl)

    if average_thickness:
        i = _layer_index(stack, nonuniform_layer)
        d0 = stack.layers[i].thickness
        thicknesses = d0 * (1.0 + thickness_spread * jnp.asarray(xd))
        at = lambda d: ncs(eqx.tree_at(lambda s: s.layers[i].thickness, stack, d))  # noqa: E731
        values = jnp.tensordot(jnp.asarray(wdw), jax.vmap(at)(thicknesses), axes=([0], [0]))
    else:
        values = ncs(stack)
    return values[0], values[1], values[2]
