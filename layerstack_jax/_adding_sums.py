r"""Hemispherical sums of the adding rule, with a derivative that costs one extra sweep.

A diffuse reflectance or transmittance of a stack of thick layers is a weighted sum over
quadrature nodes of the per-node adding rule (Simonot et al. eqs. 59–63 under the Lambertian
integral of eqs. 47, 49):

.. math::
    r = \sum_i w_i \tfrac12\sum_{s,p} R(\mu_i; t_1 \dots t_L),

where the thick layers' thicknesses and absorption enter only through their single-pass Beer
factors :math:`t_j(\mu_i)`. A fit or a design differentiates r with respect to those
thicknesses, α(λ) and ρg; generic automatic differentiation carries one tangent per parameter
through every layer of the chain (forward mode) or stores the whole chain per node (reverse mode,
measured 10–16× the forward on the P2 benchmark). Here the derivative is written out instead.
With :math:`A_{j}` the composite of everything above layer *j* and :math:`B_{j}` everything
below it, the total is ``add_layer(A_j, B_j, t_j)`` and (back side; the front side mirrors it)

.. math::
    \frac{\partial R_b}{\partial t_j} = \frac{2 t_j\, T^B_b T^B_f R^A_b}{D_j^2}, \qquad
    \frac{\partial T_b}{\partial t_j} = \frac{T^B_b T^A_b\,(1 + R^A_b R^B_f t_j^2)}{D_j^2}, \qquad
    D_j = 1 - R^A_b R^B_f t_j^2 .

The :math:`A_j` are the running composition of the forward pass, the :math:`B_j` one more
sweep from the far side; the weighted, polarization-averaged sensitivities
:math:`k_j = w\,\tfrac12\sum_{s,p}\partial R/\partial t_j` are computed once, and each tangent
(or cotangent) then costs one multiply-and-sum per layer: forward-mode Jacobians and
reverse-mode gradients both cost about the same few forward passes, whatever the number of
parameters. When the interfaces or the weights themselves carry tangents (fitting an index or
a coherent film), the generic derivative is used.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero

from ._coherent import PacketIntensities
from ._incoherent import add_layer, safe_reciprocal

__all__ = ["hemispherical_adding_sums"]


def _natural_sum(w, x):
    """Σ over nodes (axis 0 after the polarization mean) of w · natural(x)."""
    return jnp.sum(w * 0.5 * (x[0] + x[1]), axis=0)


def _composites_above(packets, ts) -> list:
    """[packet 0, packets 0..1 joined, …, the whole stack]: the running adding rule."""
    above = [packets[0]]
    for t, packet in zip(ts, packets[1:]):
        above.append(add_layer(above[-1], packet, t))
    return above


def _sums(total: PacketIntensities, w, back: bool, transmits: bool):
    R, T = (total.R_back, total.T_back) if back else (total.R_front, total.T_front)
    r = _natural_sum(w, R)
    return r, (_natural_sum(w, T) if transmits else jnp.zeros_like(r))


def _plain(packets, ts, w, back: bool, transmits: bool):
    return _sums(_composites_above(packets, ts)[-1], w, back, transmits)


def _is_zero(tangent) -> bool:
    return all(isinstance(x, SymbolicZero) for x in jax.tree_util.tree_leaves(
        tangent, is_leaf=lambda x: isinstance(x, SymbolicZero)))


@functools.partial(jax.custom_jvp, nondiff_argnums=(3, 4))
def hemispherical_adding_sums(packets, ts, w, back: bool, transmits: bool):
    """``(r, t)``: Lambertian sums ``Σ w · natural(R)``, ``Σ w · natural(T)`` of the packets
    joined through thick layers of single-pass attenuation ``ts`` (one per gap between packets).

    Args:
        packets: :class:`PacketIntensities`, fields ``(2, node, wl)`` (or broadcastable).
        ts: Beer factors, one ``(node, wl)`` array per thick layer between the packets.
        w: quadrature weights ``(node, wl)``.
        back: sums of ``R_back, T_back`` (light from the last medium) instead of the front ones.
        transmits: False when T is known to be zero (an evanescent medium on the way): not computed.

    Returns ``(r, t)`` shaped ``(wl,)``; the derivative is the module's closed form.
    """
    return _plain(packets, ts, w, back, transmits)


def _jvp(back, transmits, primals, tangents):
    packets, ts, w = primals
    d_packets, d_ts, d_w = tangents
    if not (_is_zero(d_packets) and _is_zero(d_w)):
        # an index or a coherent film is being differentiated: generic derivative
        instantiate = lambda p, d: jnp.zeros_like(p) if isinstance(d, SymbolicZero) else d  # noqa: E731
        d_packets, d_ts, d_w = jax.tree_util.tree_map(
            instantiate, (packets, ts, w), (d_packets, d_ts, d_w), is_leaf=lambda x: isinstance(x, SymbolicZero)
        )
        return jax.jvp(lambda p, t, ww: _plain(p, t, ww, back, transmits), (packets, ts, w), (d_packets, d_ts, d_w))
    L = len(ts)
    above = _composites_above(packets, ts)  # above[j]: packets 0..j joined
    r, t_out = _sums(above[-1], w, back, transmits)
    below = [None] * (L + 1)  # below[j]: packets j..L joined
    below[L] = packets[L]
    for j in range(L - 1, 0, -1):
        below[j] = add_layer(packets[j], below[j + 1], ts[j])
    dr = jnp.zeros_like(r)
    dt = jnp.zeros_like(r)
    for j in range(L):
        if isinstance(d_ts[j], SymbolicZero):
            continue
        a, b, t = above[j], below[j + 1], ts[j]
        g = a.R_back * b.R_front * t * t
        inv2 = safe_reciprocal(1.0 - g) ** 2
        if back:
            dR = 2.0 * t * b.T_back * b.T_front * a.R_back * inv2
            dT = b.T_back * a.T_back * (1.0 + g) * inv2
        else:
            dR = 2.0 * t * a.T_front * a.T_back * b.R_front * inv2
            dT = a.T_front * b.T_front * (1.0 + g) * inv2
        dr = dr + _natural_sum(w * d_ts[j], dR)
        if transmits:
            dt = dt + _natural_sum(w * d_ts[j], dT)
    return (r, t_out), (dr, dt)


hemispherical_adding_sums.defjvp(_jvp, symbolic_zeros=True)
