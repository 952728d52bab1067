r"""Angle-resolved response of a whole stack at a Snell invariant: the mixed recursion.

The media are split at the thick (incoherent) layers. Each run of coherent films between two
thick media — possibly empty, i.e. a bare Fresnel interface — is a packet
(:mod:`layerstack_jax._kernels.coherent`) with intensity coefficients ``R_front, T_front, R_back, T_back``
per polarization. The packets are then joined through the thick layers by the adding rule of
:mod:`layerstack_jax._kernels.incoherent` (Simonot et al. eqs. 59–60). A purely coherent stack is one
packet (Hirayama et al.); a purely incoherent one is Simonot's recursion; a mixed stack (a thin
film on a varnish on paint) is exact in the same framework: a coherent run acts as one
interface with its own R_front ≠ R_back when its films absorb.
"""

from __future__ import annotations

from typing import NamedTuple

from .._base.custom_types import Array, Float, Inexact
from .._kernels.coherent import PacketIntensities, stack_packets
from .._kernels.incoherent import add_layers, beer_attenuation_along, slant_path
from .stack import ResolvedStack

__all__ = ["thick_media", "Interfaces", "stack_interfaces", "thick_layer_parameters", "beer_factors", "join_interfaces", "stack_intensities", "natural"]


def thick_media(coherent: tuple) -> list[int]:
    """Positions (in the media list ambient, layers…, exit) of the semi-infinite and thick media."""
    return [0] + [i + 1 for i, c in enumerate(coherent) if not c] + [len(coherent) + 1]


class Interfaces(NamedTuple):
    """Everything of a stack's response at given Snell invariants that does not depend on the
    thick layers' thicknesses and absorption coefficients (nor on ρg).

    ``packets``: one :class:`PacketIntensities` per run of coherent films between thick media
    (a bare Fresnel interface when the run is empty); ``paths``: per thick layer, its
    :func:`~layerstack_jax._kernels.incoherent.slant_path` ``(Re cos θ, Im q)``. Fields ``(2, *batch, wl)``
    (packets) and ``(*batch, wl)`` (paths).
    """

    packets: tuple[PacketIntensities, ...]
    paths: tuple[tuple[Float[Array, "*batch wl"], Float[Array, "*batch wl"]], ...]


def stack_interfaces(rs: ResolvedStack, s, *, both_sides: bool = True) -> Interfaces:
    """The :class:`Interfaces` of ``rs`` at Snell invariant ``s`` (see :func:`stack_intensities`)."""
    thick = thick_media(rs.coherent)
    # The running composition needs the back side of every packet but the last; XLA removes
    # whatever is not used by the caller.
    sides = both_sides or len(thick) > 2
    packets, q = stack_packets(rs.n, rs.d, thick, s, rs.wavelength, both_sides=sides)
    paths = tuple(slant_path(rs.n[a], q[k]) for k, a in enumerate(thick[1:-1], start=1))  # q of thick media only
    return Interfaces(packets, paths)


def thick_layer_parameters(rs: ResolvedStack, first: int = 0, last: int | None = None) -> tuple[tuple, tuple]:
    """``(thicknesses, alphas)`` (nm, 1/nm or None) of the thick layers between packets
    ``first … last-1`` (all of them by default), in stack order."""
    thick = thick_media(rs.coherent)
    last = len(thick) - 1 if last is None else last
    layers = [thick[j + 1] - 1 for j in range(first, last - 1)]  # thick[j + 1] lies between packets j and j + 1
    return tuple(rs.d[i] for i in layers), tuple(rs.alpha[i] for i in layers)


def beer_factors(rs: ResolvedStack, paths: tuple) -> tuple:
    """Single-pass attenuations :math:`t` of all the thick layers of ``rs`` from their slant
    ``paths`` (:class:`Interfaces`). (The diffuse sums compute theirs inside
    :func:`~layerstack_jax._kernels.adding_sums.hemispherical_sums`, which owns their derivative.)"""
    thickness, alpha = thick_layer_parameters(rs)
    return tuple(beer_attenuation_along(*p, h, a, rs.wavelength) for p, h, a in zip(paths, thickness, alpha))


def join_interfaces(rs: ResolvedStack, interfaces: Interfaces, *, both_sides: bool = True) -> PacketIntensities:
    """Join the packets through the thick layers of ``rs`` (Beer attenuation with the layers'
    thicknesses and α, then the adding rule, Simonot eqs. 59–60)."""
    total = add_layers(interfaces.packets, beer_factors(rs, interfaces.paths))
    if not both_sides:
        total = PacketIntensities(total.R_front, total.T_front, None, None)
    return total


def stack_intensities(rs: ResolvedStack, s, *, both_sides: bool = True) -> PacketIntensities:
    """Per-polarization intensity response of the stack for light at Snell invariant ``s``.

    Args:
        rs: stack sampled on its wavelength grid (:func:`layerstack_jax._stacks.stack.resolve`).
        s: Snell invariant :math:`n_0\\sin\\theta_0`, broadcastable to ``(*batch, wl)``, e.g.
            shaped ``(ang, 1)`` for several angles.
        both_sides: also compute the response to light coming from the exit medium.

    Returns:
        :class:`PacketIntensities` with fields ``(2, *batch, wl)``, polarization ``(s, p)``
        first. ``T_*`` is the power entering the far medium.
    """
    return join_interfaces(rs, stack_interfaces(rs, s, both_sides=both_sides), both_sides=both_sides)


def natural(x: Inexact[Array, "pol *batch"]) -> Inexact[Array, "*batch"]:
    """Natural (unpolarized) light: mean over the leading polarization axis (Simonot eqs. 33, 57)."""
    return 0.5 * (x[0] + x[1])
