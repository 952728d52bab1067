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

**Forward.** :func:`_packet` runs the recursion film by film in one loop whose step forms the
film's normal wavevector, the Fresnel coefficients of the interface above it (s and p on one
axis) and its phase factor: no per-interface or per-film array is stored. Its arithmetic is
written so that XLA vectorizes it on CPU: complex division as :math:`z\bar w/|w|^2`
(:func:`~layerstack_jax._kernels.fresnel.divide`), the square root in real arithmetic, cosine and sine
by polynomial (:func:`_cos_sin`): XLA's own complex division (scaled, with special cases),
complex square root (through atan2, sine and cosine) and float64 sine and cosine (a scalar call
per element) are each several times slower on CPU. Measured in ``benchmarks/README.md`` (P1).

**Derivative.** The recursion carries a closed-form derivative (``jax.custom_jvp``): film j's
update is a Möbius map of :math:`u_j = \gamma_{j+1}e^{2i\phi_j}` whose derivatives are products
of the update's own terms (:func:`_rouard_sensitivities`): the sensitivities of (γ, τ) to every
film's phase and every interface's r, t, and a tangent or cotangent of a thickness or an index
costs a multiply-add per film. Short packets (:func:`_packet_jvp_stored`) evaluate it on the
interface coefficients stored in one vectorized pass, the recursion unrolled (P3, two films on a
varnish over a background, 45°/0°, 401 λ: the 401 × 3 Jacobian by ``jacfwd`` costs 2.3 forwards
instead of 6.7 by JAX's own rules). Longer ones run it
in the loop form of the forward (:func:`_packet_sweep`): γ's tangent is carried up the films
with the recursion, τ's sensitivities come from one sweep back down over a few factors kept per
film, and reverse mode keeps one stacked array of coefficients per film and transposes the loop
into a multiply-add per film. P1 (10 films): value and thickness gradient in about 2.5 forwards,
half the time and a third of the temporaries of a reverse pass over stored coefficients
(broadcast per interface, copied in reverse, XLA's complex division).
"""


from __future__ import annotations

from typing import NamedTuple, Optional, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jax.custom_derivatives import SymbolicZero

from .._base.custom_types import Array, IndexSpectrum, Inexact
from .._base.numerics import abs2, as_complex, complex_dtype, safe_divide
from .fresnel import divide, fresnel_amplitudes, normal_wavevector, power_flux, reciprocal

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


# Cody–Waite split of π/2 (fdlibm's pio2_1, pio2_2, pio2_3 for float64: 33 + 33 + 53 bits, so
# that n·pio2_1 and n·pio2_2 are exact for |n| < 2^20; Cephes' DP1..3 × 2 for float32) and the
# minimax polynomials of fdlibm's __kernel_sin / __kernel_cos on [-π/4, π/4].
_PIO2 = {"float64": (1.57079632673412561417e+00, 6.07710050630396597660e-11, 2.02226624871116645580e-21),
         "float32": (1.5703125, 4.837512969970703125e-4, 7.54978995489188216e-8)}
_SIN = (-1.66666666666666324348e-01, 8.33333333332248946124e-03, -1.98412698298579493134e-04,
        2.75573137070700676789e-06, -2.50507602534068634195e-08, 1.58969099521155010221e-10)
_COS = (4.16666666666666019037e-02, -1.38888888888741095749e-03, 2.48015872894767294178e-05,
        -2.75573143513906633035e-07, 2.08757232129817482790e-09, -1.13596475577881948265e-11)


def _horner(z, coefficients):
    """The polynomial Σ_k coefficients[k]·z^k by Horner's rule."""
    acc = coefficients[-1]
    for c in coefficients[-2::-1]:
        acc = acc * z + c
    return acc


@jax.custom_jvp
def _cos_sin(x):
    r"""``(cos x, sin x)`` of a real array, in arithmetic that XLA vectorizes: reduction by
    n = round(2x/π) with π/2 in three parts (Cody–Waite), fdlibm's kernels on the remainder,
    the quadrant n mod 4 by swaps and sign flips. XLA's own float64 ``cos`` and ``sin`` on CPU
    cost ~20× as much (one scalar call per element), and every film needs both at every
    (angle, λ) point (P1: 640,000 pairs per evaluation). Within 2.2 ulp (|x| ≤ 1e6; absolute
    error ≤ 1.5e-16) of the correctly rounded values in float64, 6e-8 in float32; for |x|
    beyond ~1.6e6 (2^20 · π/2) the reduction loses ~|x|·1e-16 absolute, the size of the
    rounding error the phase itself carries there."""
    p = _PIO2["float64" if x.dtype == jnp.float64 else "float32"]
    n = jnp.round(x * (2 / np.pi))
    r = ((x - n * p[0]) - n * p[1]) - n * p[2]
    z = r * r
    sin = r + r * z * _horner(z, _SIN)
    half = 0.5 * z
    w = 1.0 - half
    cos = w + (((1.0 - w) - half) + z * z * _horner(z, _COS))
    quadrant = (n - 4 * jnp.floor(0.25 * n)).astype(jnp.int32)  # n mod 4: cos x = (c, −s, −c, s)[.], sin x = (s, c, −s, −c)[.]
    odd = (quadrant & 1) == 1
    cos, sin = jnp.where(odd, sin, cos), jnp.where(odd, cos, sin)
    return jnp.where(((quadrant + 1) & 2) == 2, -cos, cos), jnp.where((quadrant & 2) == 2, -sin, sin)


@_cos_sin.defjvp
def _cos_sin_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    cos, sin = _cos_sin(x)
    return (cos, sin), (-sin * dx, cos * dx)


def _kept_step(need_t: bool):
    """:func:`_rouard_step` with one reciprocal instead of two divisions, keeping what the
    derivative needs: ``(γ_{j+1}, e^{2iφ_j}, 1/D_j)`` and, for t, ``(τ_{j+1}, e^{iφ_j})``."""

    def step(carry, x):
        gamma, tau = carry
        r_j, t_j, e1, e2 = x
        u = gamma * e2
        inv = 1.0 / (1.0 + r_j * u)
        kept = (gamma, e2, inv, tau, e1) if need_t else (gamma, e2, inv)
        return ((r_j + u) * inv, t_j * tau * e1 * inv), kept

    return step


def _adjoint_step(need_phi: bool, need_r: bool, need_t: bool):
    r"""One step, from the incidence side down, of the sweep of :func:`_rouard_sensitivities`:
    film j and the interface above it. Carry ``(a_j, μ_j[, c_j])``, ``x`` = ``(r_j, t_j)`` and
    what :func:`_kept_step` kept of film j. Returns the carry below film j and the
    sensitivities asked for (``"phi"``, ``"r"``, ``"t"``)."""

    def step(carry, x):
        a, mu, c = carry
        r_j, t_j, g_in, e2, inv, *rest = x
        m = (1.0 - r_j * r_j) * inv * inv  # ∂γ_j/∂u
        r_inv = r_j * inv
        out = {}
        if need_r:
            u = g_in * e2
            g_r = (1.0 - u * u) * inv * inv  # ∂γ_j/∂r_j
            out["r"] = (a * g_r, mu * g_r - u * inv)
        if need_t:
            tau_in, e1 = rest
            out["t"] = c * tau_in * e1 * inv
            c = c * t_j * e1 * inv
        a = a * m * e2
        mu = (mu * m - r_inv) * e2
        if need_phi:
            out["phi"] = (2j * a * g_in, 2j * mu * g_in)
        return (a, mu, c), out

    return step


def _rouard_sensitivities(r, t, phase, need_phi: bool, need_r: bool, need_t: bool):
    r"""The recursion of :func:`_rouard` and the derivatives of its result in closed form.

    Film j (between interfaces j and j + 1) maps the composite amplitudes below it to
    :math:`\gamma_j = (r_j + u_j)/D_j`, :math:`\tau_j = t_j\tau_{j+1}e^{i\phi_j}/D_j` with
    :math:`u_j = \gamma_{j+1}e^{2i\phi_j}`, :math:`D_j = 1 + r_j u_j` (Hirayama eqs. 3–4): a Möbius
    map of :math:`u_j`, with

    .. math::
        \frac{\partial\gamma_j}{\partial u_j} = \frac{1 - r_j^2}{D_j^2} =: m_j,\quad
        \frac{\partial\gamma_j}{\partial r_j} = \frac{1 - u_j^2}{D_j^2},\quad
        \frac{\partial u_j}{\partial\phi_j} = 2iu_j,\quad
        \frac{\partial\log\tau_j}{\partial u_j} = -\frac{r_j}{D_j}.

    With :math:`a_j = \partial\gamma/\partial\gamma_j` and
    :math:`\mu_j = \partial\log\tau/\partial\gamma_j` (γ, τ of the whole packet), from the
    incidence side down (:math:`a_0 = 1`, :math:`\mu_0 = 0`)

    .. math::
        a_{j+1} = a_j m_j e^{2i\phi_j},\qquad
        \mu_{j+1} = \Big(\mu_j m_j - \frac{r_j}{D_j}\Big) e^{2i\phi_j},

    and the sensitivities to a film's phase :math:`\phi_j = 2\pi q_j d_j/\lambda` are

    .. math::
        \frac{\partial\gamma}{\partial\phi_j} = 2i\,a_{j+1}\gamma_{j+1},\qquad
        \frac{\partial\tau}{\partial\phi_j} = \tau\,\big(i + 2i\,\mu_{j+1}\gamma_{j+1}\big),

    to the interfaces' :math:`r_j` (:math:`j < F`): :math:`a_j(1-u_j^2)/D_j^2` and
    :math:`\tau\,(\mu_j(1-u_j^2)/D_j^2 - u_j/D_j)`, to the last one's: :math:`a_F`, :math:`\tau\mu_F`;
    to :math:`t_j`: :math:`c_j\tau_{j+1}e^{i\phi_j}/D_j` with
    :math:`c_j = \prod_{k<j} t_k e^{i\phi_k}/D_k` (:math:`= \tau/t_j`, written without the
    division). One sweep of multiplications over the stored steps, no new exponential and no
    new division; where a metal film's :math:`e^{2i\phi}` underflows to 0 the products vanish.
    All are holomorphic derivatives (γ and τ are analytic in r, t and the complex phases), so
    the tangent or cotangent of any parameter (a thickness through φ, an index through q, r and
    t) is their product with its own. The recursion itself runs with one reciprocal of
    :math:`D_j` instead of two divisions (values within a few ulp of :func:`_rouard`'s).

    Args:
        r, t: ``(F+1, 2, *B)``, phase ``(F, 1, *B)`` as for :func:`_rouard`; the flags say which
            sensitivities are wanted.

    Returns:
        ``((gamma, tau), sens)`` with ``sens["phi"] = (∂γ/∂φ, ∂log τ/∂φ − i)`` each ``(F, 2, *B)``,
        ``sens["r"] = (∂γ/∂r, ∂log τ/∂r)`` and ``sens["t"] = ∂τ/∂t``, each ``(F+1, 2, *B)``
        (only those asked for).
    """
    n = phase.shape[0]
    (gamma, tau), kept = _loop(_kept_step(need_t), (r[-1], t[-1]), _bottom_up(r, t, phase), n)
    one = jnp.ones_like(gamma)
    carry, sens = (one, jnp.zeros_like(gamma), one), {}
    if n:
        top_down = (r[:-1], t[:-1], *(k[::-1] for k in kept))
        carry, sens = _loop(_adjoint_step(need_phi, need_r, need_t), carry, top_down, n)
    last = dict(zip(("r", "t"), ((carry[0], carry[1]), carry[2])))  # the last interface starts the recursion
    for key, wanted in (("r", need_r), ("t", need_t)):
        if wanted:
            sens[key] = jax.tree_util.tree_map(lambda s, e: jnp.concatenate([s, e[None]]) if n else e[None],
                                               sens.get(key, last[key]), last[key])
    return (gamma, tau), sens


def _rouard_jvp(primals, tangents):
    """Forward-mode rule of :func:`_rouard`: the closed-form sensitivities of
    :func:`_rouard_sensitivities` times the tangents (linear in them, so JAX transposes it for
    reverse mode)."""
    r, t, phase = primals
    d_r, d_t, d_phase = tangents
    need_r, need_t, need_phi = (not isinstance(x, SymbolicZero) for x in tangents)
    need_phi = need_phi and phase.shape[0] > 0
    (gamma, tau), sens = _rouard_sensitivities(r, t, phase, need_phi, need_r, need_t)
    d_gamma, d_log_tau = jnp.zeros_like(gamma), jnp.zeros_like(tau)
    if need_phi:
        d_gamma = d_gamma + jnp.sum(sens["phi"][0] * d_phase, axis=0)
        d_log_tau = d_log_tau + jnp.sum(sens["phi"][1] * d_phase, axis=0) + 1j * jnp.sum(d_phase, axis=0)
    if need_r:
        d_gamma = d_gamma + jnp.sum(sens["r"][0] * d_r, axis=0)
        d_log_tau = d_log_tau + jnp.sum(sens["r"][1] * d_r, axis=0)
    d_tau = tau * d_log_tau
    if need_t:
        d_tau = d_tau + jnp.sum(sens["t"] * d_t, axis=0)
    return (gamma, tau), (d_gamma, d_tau)


_rouard.defjvp(_rouard_jvp, symbolic_zeros=True)


def _kept_update(gamma, tau, r, t, e1, need_inv: bool, need_t: bool):
    r"""The Rouard update of :func:`_rouard_update` for film j with one reciprocal
    :math:`1/D_j` (:func:`~layerstack_jax._kernels.fresnel.reciprocal`) instead of two divisions (values
    within a few ulp), and what the derivative sweep of :func:`_rouard_sensitivities` needs of
    this film: :math:`m_j = (1 - r_j^2)/D_j^2`, :math:`u_j = \gamma_{j+1}e^{2i\phi_j}`,
    :math:`w_j = r_j/D_j`, :math:`e^{2i\phi_j}`, and (flags) :math:`1/D_j` and
    :math:`(t_j, \tau_{j+1}, e^{i\phi_j})`. Returns ``((γ_j, τ_j), kept)``, kept a dict."""
    e2 = e1 * e1
    u = gamma * e2
    inv = reciprocal(1.0 + r * u)
    kept = {"m": (1.0 - r * r) * inv * inv, "u": u, "w": r * inv, "e2": e2}
    if need_inv:
        kept["inv"] = inv
    if need_t:
        kept.update(t=t, tau=tau, e1=e1)
    return ((r + u) * inv, t * tau * e1 * inv), kept


def _down_step(need_r: bool, need_t: bool):
    r"""One step, from the incidence side down, of the sweep of :func:`_rouard_sensitivities`
    in :func:`_packet_sweep`: film j and the interface above it, from what :func:`_kept_update`
    kept of it (:math:`\partial\gamma/\partial\phi_j = 2i\,a_j m_j u_j`,
    :math:`\partial\log\tau/\partial\phi_j - i = 2i(\mu_j m_j - w_j)u_j`: the forms of
    :func:`_rouard_sensitivities` with :math:`a_{j+1}\gamma_{j+1} = a_j m_j u_j`, so that only
    :math:`u_j` is kept of :math:`\gamma_{j+1}`). Carry ``(a_j, μ_j, c_j)``; returns the carry
    below film j and the film's sensitivities (``"phi"`` always — unused ones are removed by
    XLA —, ``"r"``, ``"t"`` by the flags)."""

    def step(carry, k):
        a, mu, c = carry
        m, u, w, e2 = k["m"], k["u"], k["w"], k["e2"]
        am, mu_m = a * m, mu * m - w  # a_{j+1} and μ_{j+1} before the factor e^{2iφ_j}
        out = {"phi": (2j * am * u, 2j * mu_m * u)}
        if need_r:
            inv = k["inv"]
            g_r = (1.0 - u * u) * inv * inv  # ∂γ_j/∂r_j
            out["r"] = (a * g_r, mu * g_r - u * inv)
        if need_t:
            e1_inv = k["e1"] * k["inv"]
            out["t"] = c * k["tau"] * e1_inv
            c = c * k["t"] * e1_inv
        return (am * e2, mu_m * e2, c), out

    return step


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


def _packet_sweep(n, q_ends, d, s, wavelength, tangents, need_r: bool, need_t: bool):
    r""":func:`_packet`'s recursion in its loop form, carrying the tangent of γ along, and the
    sweep of :func:`_rouard_sensitivities` back down for the sensitivities of τ.

    The loop up (a ``lax.scan`` over all F films, from the last) forms each film's normal
    wavevector, the interface above it and its phase factor as :func:`_packet` does (its last
    step is the interface with the incidence medium, whose given ``q_ends[0]`` replaces the
    wavevector the step forms; the phase factor it forms for that medium is unused). Film j's
    update (:func:`_kept_update`) is a Möbius map of :math:`u_j = \gamma_{j+1}e^{2i\phi_j}`, so
    the tangent of γ follows it linearly:

    .. math::
        \delta\gamma_j = m_j e^{2i\phi_j}\,\delta\gamma_{j+1} + 2i\,m_j u_j\,\delta\phi_j
        + \frac{1 - u_j^2}{D_j^2}\,\delta r_j,\qquad \delta\gamma_{F} = \delta r_F,

    with :math:`\delta\phi_j = (2\pi q_j/\lambda)\,\delta d_j` for a thickness alone (the
    coefficient :math:`2i m_j u_j 2\pi q_j/\lambda` is formed in the loop). The coefficients
    depend on the primals only and are stacked on one axis, multiplied by the stacked tangents:
    reverse mode keeps that one array per film (for a thickness gradient
    :math:`m_j e^{2i\phi_j}` and the thickness coefficient, ``(2, 2, *B)``; stacked, XLA fills
    and writes one buffer instead of copying a second: P1 ~4 ms) and runs the transposed loop
    down, a multiply-add per film; forward mode keeps nothing. τ's sensitivities come from the
    sweep down of :func:`_rouard_sensitivities` (:func:`_down_step`) over the factors kept per
    film (:math:`m_j, u_j, w_j, e^{2i\phi_j}`, :math:`q_j`; with the flags :math:`1/D_j` and
    :math:`(t_j, \tau_{j+1}, e^{i\phi_j})`): a separate loop, which XLA removes with those
    factors when τ has no cotangent (a gradient of reflectances only).

    Args:
        n, q_ends, d, s, wavelength: as for :func:`_packet`.
        tangents: ``(dd, d_phi, dr, dr_last)``, each None or: thickness tangents ``(F, *Bd)``
            (used alone), phase tangents ``(F, *B)``, those of the interfaces above the films
            ``(F, 2, *B)`` (all from the last film up) and of the last interface ``(2, *B)``.
        need_r, need_t: also τ's sensitivities to the interfaces' r, t.

    Returns:
        ``((gamma, tau), d_gamma, q, sens, (a_F, μ_F, c_F))``: amplitudes ``(2, *B)``, γ's
        tangent (None without tangents), the films' normal wavevectors ``(F, *Bq)`` and
        sensitivities ``(F, 2, *B)`` (keys as in :func:`_rouard_sensitivities`, here per film
        and its interface above), all ordered from the last film up, and the sensitivities to
        the last interface's r (of γ, of log τ) and t (of τ).
    """
    dd, d_phi, dr, dr_last = tangents
    tangent = any(x is not None for x in tangents)
    films = n.shape[0] - 2
    shape = jnp.broadcast_shapes(q_ends.shape[1:], d.shape[1:], jnp.shape(wavelength))
    k0 = as_complex(2 * jnp.pi / wavelength, q_ends)
    q_last = _film_wavevector(n[films], s)
    r, t = fresnel_amplitudes(n[films], q_last, n[-1], q_ends[1])
    e1 = jnp.broadcast_to(_phase_factor(_film_phase(q_last, d[-1], wavelength)), shape)
    q_last = jnp.broadcast_to(q_last, jnp.broadcast_shapes(q_last.shape, q_ends.shape[1:]))
    carry = (jnp.broadcast_to(r, (2, *shape)), jnp.broadcast_to(t, (2, *shape)), n[films], q_last, e1)
    if tangent:
        d_gamma = jnp.zeros((2, *shape), r.dtype) if dr_last is None else jnp.broadcast_to(dr_last, (2, *shape))
        carry = (*carry, d_gamma)

    def step(carry, x):  # film f (its phase factor e1 carried) and the medium above it, i
        gamma, tau, n_f, q_f, e1, *d_gamma = carry
        n_i, d_i, top, dd_f, d_phi_f, dr_f = x
        q_i = jnp.where(top, q_ends[0], _film_wavevector(n_i, s))
        r, t = fresnel_amplitudes(n_i, q_i, n_f, q_f)
        (gamma, tau), kept = _kept_update(gamma, tau, r, t, e1, need_r or need_t or dr_f is not None, need_t)
        e1 = jnp.broadcast_to(_phase_factor(_film_phase(q_i, d_i, wavelength)), shape)
        if tangent:  # the coefficients (primal), stacked so that reverse mode keeps one array
            m, u = kept["m"], kept["u"]
            coef, tan = [m * kept["e2"]], [d_gamma[0]]
            if dd_f is not None:
                coef.append(2j * m * u * (k0 * q_f))
                tan.append(as_complex(dd_f, q_f))
            if d_phi_f is not None:
                coef.append(2j * m * u)
                tan.append(d_phi_f)
            if dr_f is not None:
                coef.append((1.0 - u * u) * kept["inv"] * kept["inv"])
                tan.append(dr_f)
            coef = jnp.stack(jnp.broadcast_arrays(*coef))
            d_gamma = jnp.sum(coef * jnp.stack([jnp.broadcast_to(x, coef.shape[1:]) for x in tan]), axis=0)
            return (gamma, tau, n_i, q_i, e1, d_gamma), (q_f, kept)
        return (gamma, tau, n_i, q_i, e1), (q_f, kept)

    d_above = jnp.concatenate([d[:-1][::-1], jnp.zeros_like(d[:1])])  # the incidence medium: unused
    xs = (n[:films][::-1], d_above, jnp.arange(films) == films - 1, dd, d_phi, dr)
    (gamma, tau, *_, d_gamma), (q, kept) = lax.scan(step, carry, xs)
    one = jnp.ones_like(gamma)
    last, sens = lax.scan(_down_step(need_r, need_t), (one, jnp.zeros_like(gamma), one), kept, reverse=True)
    return (gamma, tau), (d_gamma if tangent else None), q, sens, last


def _interfaces_bottom_up(n, q_ends, s):
    """The Fresnel coefficients of a packet's interfaces in the order of :func:`_packet_sweep`:
    ``(r, t)`` ``(F, 2, *B)`` of the interface above each film from the last film up, and
    ``(r, t)`` ``(2, *B)`` of the last interface. Stored: only for the tangents of indices, the
    Snell invariant or the outer media's wavevectors."""
    q_films = _film_wavevector(n[1:-1], s)
    q_shape = jnp.broadcast_shapes(q_films.shape[1:], q_ends.shape[1:])
    q_above = jnp.concatenate([jnp.broadcast_to(q_ends[:1], (1, *q_shape)),
                               jnp.broadcast_to(q_films[:-1], (q_films.shape[0] - 1, *q_shape))])
    r, t = fresnel_amplitudes(n[:-2], q_above, n[1:-1], q_films)  # (2, F, *B), top film first
    r_last, t_last = fresnel_amplitudes(n[-2], q_films[-1], n[-1], q_ends[1])
    return jnp.moveaxis(r, 0, 1)[::-1], jnp.moveaxis(t, 0, 1)[::-1], r_last, t_last


def _jvp_of(fn, primals, tangents):
    """The tangent of ``fn(*primals)`` for the tangents that are not None (the other arguments
    held fixed: no zero tangent is formed)."""
    live = [i for i, dx in enumerate(tangents) if dx is not None]

    def restricted(*xs):
        args = list(primals)
        for i, x in zip(live, xs):
            args[i] = x
        return fn(*args)

    return jax.jvp(restricted, tuple(primals[i] for i in live), tuple(tangents[i] for i in live))[1]


def _packet_jvp_sweep(primals, tangents):
    r"""Derivative of :func:`_packet`, in the loop form of its forward (:func:`_packet_sweep`):
    γ's tangent carried up the films, τ's from the closed-form sensitivities of
    :func:`_rouard_sensitivities`, from the tangents of the films' phases
    :math:`\phi_j = 2\pi q_j d_j/\lambda` and, when an index, the Snell invariant or an outer
    medium's wavevector moves, of the interfaces' r and t (:func:`_interfaces_bottom_up`).
    Inputs without a tangent stay symbolic zeros: a thickness tangent alone enters the loop as
    one number per film, and needs no phase array.

    The rule is linear in the tangents with every coefficient computed from the primals, so that
    reverse mode (JAX linearizes this rule and transposes its linear part) keeps two arrays per
    film and transposes the loop into a multiply-add per film: for the thickness gradient of P1,
    :math:`\partial L/\partial d_j = \operatorname{Re}\sum \bar g_j\,2i m_j u_j 2\pi q_j/\lambda`
    over polarizations, angles and wavelengths, :math:`\bar g` the cotangent of γ carried down."""
    n, q_ends, d, s, wavelength = primals
    dn, dq_ends, dd, ds, dwl = (None if isinstance(x, SymbolicZero) else x for x in tangents)
    interfaces = any(x is not None for x in (dn, dq_ends, ds))
    generic_phases = any(x is not None for x in (dn, ds, dwl))
    phases = generic_phases or dd is not None
    d_phi = dr = dt = dr_last = dt_last = None
    if generic_phases:  # the phases' tangents formed here, from the last film up
        def bottom_up_phases(n_, d_, s_, wavelength_):
            return _film_phase(_film_wavevector(n_[1:-1][::-1], s_), d_[::-1], wavelength_)

        d_phi = _jvp_of(bottom_up_phases, (n, d, s, wavelength), (dn, dd, ds, dwl))[:, None]
    if interfaces:
        dr, dt, dr_last, dt_last = _jvp_of(_interfaces_bottom_up, (n, q_ends, s), (dn, dq_ends, ds))
    dd_bu = None if dd is None or generic_phases else dd[::-1]
    (gamma, tau), d_gamma, q, sens, (_, mu_last, c_last) = _packet_sweep(
        n, q_ends, d, s, wavelength, (dd_bu, d_phi, dr, dr_last), interfaces, interfaces)
    if d_gamma is None:
        return (gamma, tau), (jnp.zeros_like(gamma), jnp.zeros_like(tau))
    d_log_tau = jnp.zeros_like(tau)
    if phases:
        if d_phi is None:
            d_phi = (as_complex(2 * jnp.pi / wavelength, q) * q * as_complex(dd_bu, q))[:, None]
        d_log_tau = d_log_tau + jnp.sum(sens["phi"][1] * d_phi, axis=0) + 1j * jnp.sum(d_phi, axis=0)
    d_tau = tau * d_log_tau
    if interfaces:
        d_tau = tau * (d_log_tau + jnp.sum(sens["r"][1] * dr, axis=0) + mu_last * dr_last)
        d_tau = d_tau + jnp.sum(sens["t"] * dt, axis=0) + c_last * dt_last
    return (gamma, tau), (d_gamma, d_tau)


def _stored_coefficients(n, q_ends, d, s, wavelength):
    """The inputs ``(r, t, phase)`` of :func:`_rouard` for the packet of :func:`_packet`: the
    Fresnel coefficients of all its interfaces ``(F+1, 2, *B)`` and its films' phases
    ``(F, 1, *B)``, stored."""
    q_films = _film_wavevector(n[1:-1], s)
    q = jnp.concatenate([q_ends[:1], q_films, q_ends[1:]])
    r, t = fresnel_amplitudes(n[:-1], q[:-1], n[1:], q[1:])  # (2, F+1, *Bq)
    phase = _film_phase(q_films, d, wavelength)[:, None]  # (F, 1, *B)
    shape = (r.shape[1], 2, *phase.shape[2:])
    return jnp.broadcast_to(jnp.moveaxis(r, 0, 1), shape), jnp.broadcast_to(jnp.moveaxis(t, 0, 1), shape), phase


def _packet_jvp_stored(primals, tangents):
    """Derivative of :func:`_packet` for short packets: the closed form of :func:`_rouard` (its
    custom JVP, unrolled) on the stored coefficients (:func:`_stored_coefficients`, computed in
    one vectorized pass), whose own tangents come from those of the inputs that have one (the
    others stay symbolic zeros, so a thickness tangent costs the phase terms only)."""
    live = [i for i, dx in enumerate(tangents) if not isinstance(dx, SymbolicZero)]

    def through_stored(*xs):
        args = list(primals)
        for i, x in zip(live, xs):
            args[i] = x
        return _rouard(*_stored_coefficients(*args))

    if not live:
        out = through_stored()
        return out, jax.tree_util.tree_map(jnp.zeros_like, out)
    return jax.jvp(through_stored, tuple(primals[i] for i in live), tuple(tangents[i] for i in live))


def _packet_jvp(primals, tangents):
    """Derivative of :func:`_packet`. Up to :data:`_SCAN_THRESHOLD` films, on stored coefficients
    with the recursion unrolled (:func:`_packet_jvp_stored`; P3, two films, 48 samples: Jacobian
    296–321 ms, value and gradient 521 ms, against 393–407 and 583 ms in loop form, whose
    two-step ``lax.scan`` prevents fusion across films; the loop form unrolled: 1012 and 949 ms,
    XLA recomputing each film's wavevector and phase factor in their consumers). Beyond, in the
    forward's loop form (:func:`_packet_jvp_sweep`; P1, ten films: value and gradient ~2× faster
    than on stored coefficients, which materialised every interface's coefficients broadcast
    over (angle, λ))."""
    if primals[0].shape[0] - 2 <= _SCAN_THRESHOLD:
        return _packet_jvp_stored(primals, tangents)
    return _packet_jvp_sweep(primals, tangents)


_packet.defjvp(_packet_jvp, symbolic_zeros=True)


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
