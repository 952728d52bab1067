r"""Closed-form derivatives of the coherent packet kernels of
:mod:`layerstack_jax._kernels.coherent`: the ``jax.custom_jvp`` rules of its Rouard recursion on
stored coefficients (:func:`_rouard_jvp`) and of its loop-form packet (:func:`_packet_jvp`), the
sensitivity sweeps they run (:func:`_rouard_sensitivities`, :func:`_packet_sweep`) and the
stored-coefficient derivative of short packets (:func:`_packet_jvp_stored`).

This module imports the forward one and attaches the rules to its functions when imported
(``_rouard.defjvp``, ``_packet.defjvp`` at the end); the package ``layerstack_jax._kernels``
imports it, so the forward kernels never run without them.

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

import jax
import jax.numpy as jnp
from jax import lax
from jax.custom_derivatives import SymbolicZero

from .._base.numerics import as_complex
from .coherent import (
    _SCAN_THRESHOLD,
    _bottom_up,
    _film_phase,
    _film_wavevector,
    _loop,
    _packet,
    _phase_factor,
    _rouard,
)
from .fresnel import fresnel_amplitudes, reciprocal


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
