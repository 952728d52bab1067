r"""The fixed part of a measurement: :class:`Optics` holds everything that depends only on the
indices, the coherent films and the geometry (Fresnel coefficients of every interface or
coherent packet, slant paths in the thick layers, quadrature nodes), so that a fit of thick-layer
thicknesses, α(λ) and ρg(λ) computes the complex Fresnel algebra once. Made by
:func:`layerstack_jax.fixed_optics` through each geometry's :meth:`~layerstack_jax.Geometry.optics`.
"""

from __future__ import annotations

from typing import Optional

import equinox as eqx

from .._base.custom_types import Array, Float, IndexSpectrum, RealLike
from .._base.validate import LayerstackError, check_agree
from .._kernels.quadrature import DEFAULT_NODES
from .._stacks.recursion import Interfaces
from .._stacks.stack import ResolvedStack

__all__ = ["Optics", "check_optics", "coherent_films"]


class Optics(eqx.Module):
    r"""The part of a measurement that depends only on the indices, the coherent films and the
    geometry — Fresnel coefficients of every interface or coherent packet, slant paths in the
    thick layers and quadrature nodes, at the angles the geometry needs — and not on the thick
    layers' thicknesses, their α, or ρg. Made by :func:`fixed_optics`; passed to
    :func:`reflectance` (``optics=``) it is reused instead of recomputed: a fit of thick-layer
    thicknesses, α(λ) and ρg(λ) evaluates the complex Fresnel algebra once, not at every step.

    Fields (:class:`~layerstack_jax._stacks.recursion.Interfaces` or None): ``incidence`` at the
    illumination angle (at the directions of the illumination cone with a finite aperture),
    ``viewing`` at the viewing angle (:class:`Directional`, :class:`BRDF`; the directions of the
    viewing cone with a finite aperture) or at the directions of a :class:`Sphere`'s specular
    port cone (:mod:`layerstack_jax._instruments.instrument`),
    ``diffuse`` at the back-side hemispherical nodes (over a background) with their ``weights``;
    ``index`` and ``films``: the indices and coherent-film thicknesses they were made with
    (checked against the stack when both are concrete); ``reach`` (static): which packets each
    group of back-side nodes reaches (:func:`layerstack_jax._stacks.illumination.hemisphere`; None: all of them).

    Everything is on the wavelength grid ``(wl,)`` (nm) it was made for: the Fresnel arrays
    carry the geometry's angle axes ``(*angle)`` and, for ``diffuse``, a node axis; the values
    are dimensionless (amplitude and intensity ratios; μ = sin²θ nodes and weights).
    """

    geometry: eqx.Module  # the layerstack_jax.Geometry it was made for (which builds its Optics)
    incidence: Optional[Interfaces]
    viewing: Optional[Interfaces]
    diffuse: Optional[Interfaces]
    weights: Optional[Float[Array, "node wl"]]  # (node, 1 | wl) quadrature weights, dimensionless
    index: tuple[IndexSpectrum, ...]  # indices of the media, ambient first
    films: tuple[RealLike, ...]  # thicknesses of the coherent films, nm
    nodes: int = eqx.field(static=True, default=DEFAULT_NODES)
    reach: Optional[tuple] = eqx.field(static=True, default=None)


def coherent_films(rs: ResolvedStack) -> tuple:
    """Thicknesses (nm) of the coherent films of ``rs``, in stack order."""
    return tuple(d for d, c in zip(rs.d, rs.coherent) if c)


def check_optics(optics: Optics, rs: ResolvedStack, geometry, nodes: int) -> None:
    """Raise if ``optics`` were not made for ``geometry``, ``nodes`` and the indices and
    coherent films of ``rs`` (compared when concrete)."""
    if not isinstance(optics, Optics):
        raise LayerstackError(f"optics must come from fixed_optics(), got {type(optics).__name__}")
    if type(optics.geometry) is not type(geometry) or optics.nodes != nodes:
        raise LayerstackError(
            f"optics were made for {type(optics.geometry).__name__} with {optics.nodes} nodes, "
            f"not {type(geometry).__name__} with {nodes}"
        )
    pairs = [("index", a, b) for a, b in zip(optics.index, rs.n)] + [
        ("coherent film thickness", a, b) for a, b in zip(optics.films, coherent_films(rs))
    ]
    if len(optics.index) != len(rs.n) or len(optics.films) != len(coherent_films(rs)):
        raise LayerstackError("optics were made for a stack of another structure")
    for what, a, b in pairs:
        check_agree(f"optics were made with another {what}: rebuild them with fixed_optics() "
                    "(only thick-layer thicknesses, alpha and rho_g may change)", a, b, rtol=1e-12)
