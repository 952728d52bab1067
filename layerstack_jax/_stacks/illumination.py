r"""A stack under collimated and under diffuse (Lambertian) light: the two illuminations every
measurement geometry is built from (Simonot et al. §3–4; Hirayama et al. eqs. 1–6 inside the
packets).

* :func:`specular` — angle-resolved R, T (front and back) per polarization, at angles in degrees;
* :func:`diffuse` — hemispherical reflectance and transmittance for Lambertian natural light,
  either side, on the critical-angle-aware nodes of :mod:`layerstack_jax._kernels.quadrature`;
* :func:`snell_invariant` (from the angle) and :func:`snell_invariant_from_cos` (from its
  cosine) — the one place where an angle of incidence becomes the Snell invariant
  :math:`s = n_0 \sin\theta_0` that carries it through the stack.

Result types :class:`Response` (four fields per polarization) and :class:`Diffuse`.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import jax
import jax.numpy as jnp
import numpy as np

from .._base.custom_types import Array, ComplexLike, Float, RealLike, Spectrum
from .._base.numerics import sin_from_cos
from .._base.programs import public_program
from .._base.validate import LayerstackError, check_angle_deg, is_concrete, warn_if_implausible
from .._kernels.adding_sums import hemispherical_sums
from .._kernels.quadrature import DEFAULT_NODES, evanescent_beyond, hemispherical_rule
from .recursion import Interfaces, natural, stack_intensities, stack_interfaces, thick_layer_parameters, thick_media
from .stack import ResolvedStack, Stack, resolve

__all__ = ["Response", "Diffuse", "snell_invariant", "snell_invariant_from_cos", "specular", "diffuse",
           "diffuse_resolved", "natural_T_front", "hemisphere"]


class Response(NamedTuple):
    """Angle-resolved response. Arrays shaped ``(*angle, 2, wl)``: axis −2 is polarization
    ``(s, p)``. ``*_front``: light from the ambient; ``*_back``: from the exit medium at the same
    Snell invariant. ``T``: power entering the far medium. All are dimensionless fractions of
    the incident power, in [0, 1]; ``R_back`` and ``T_back`` are None when ``both_sides=False``.
    Use :meth:`natural` for unpolarized light (mean of s and p, taken after the whole recursion:
    Simonot eqs. 57–58): it returns a :class:`Response` with arrays ``(*angle, wl)``."""

    R_front: Float[Array, "*angle 2 wl"]
    T_front: Float[Array, "*angle 2 wl"]
    R_back: Optional[Float[Array, "*angle 2 wl"]]
    T_back: Optional[Float[Array, "*angle 2 wl"]]

    def natural(self) -> "Response":
        return Response(*(None if x is None else 0.5 * (x[..., 0, :] + x[..., 1, :]) for x in self))

    @property
    def absorptance_front(self):
        return 1.0 - self.R_front - self.T_front


class Diffuse(NamedTuple):
    """Hemispherical reflectance ``r`` and transmittance ``t`` for Lambertian natural light,
    shaped ``(wl,)``, dimensionless fractions in [0, 1] (Simonot eqs. 47, 49, 62, 63)."""

    r: Float[Array, " wl"]
    t: Float[Array, " wl"]


def _to_public(x):
    return None if x is None else jnp.moveaxis(x, 0, -2)


def snell_invariant(n0: ComplexLike, angle_rad: RealLike) -> Float[Array, "*angle wl"]:
    r"""Snell invariant :math:`s = n_0 \sin\theta_0` (Hirayama eq. 2; Simonot eq. 2) of light
    incident at ``angle_rad`` (radians, ``(*angle)``) from the ambient of real index ``n0``
    (scalar, ``(1,)`` or ``(wl,)``): shaped ``(*angle, 1)`` or ``(*angle, wl)``. Every
    :math:`\cos\theta_j` of the stack is derived from it (:mod:`layerstack_jax._kernels.fresnel`)."""
    return jnp.real(n0) * jnp.sin(jnp.asarray(angle_rad))[..., None]


def snell_invariant_from_cos(n0: ComplexLike, cos: RealLike) -> Float[Array, "*B"]:
    r"""Snell invariant :math:`s = n_0 \sin\theta_0 = n_0\sqrt{1 - \cos^2\theta_0}` of light whose
    direction is given by its cosine ``cos`` in a medium of real index ``n0`` (real part taken),
    e.g. a microfacet's local angle or a table's cosine grid. Unlike :func:`snell_invariant` no
    wavelength axis is added: the result has the broadcast shape ``(*B)`` of ``n0`` and ``cos``."""
    return jnp.real(n0) * sin_from_cos(cos)


def _snell(rs: ResolvedStack, angle_deg):
    """Snell invariant of ``rs``'s ambient at ``angle_deg`` (degrees), ``(*angle, 1 | wl)``."""
    return snell_invariant(rs.n[0], jnp.deg2rad(angle_deg))


def _wavelength_axis(x, rs: ResolvedStack):
    """``x`` ``(..., 1 | wl)`` broadcast to the grid's ``(..., wl)``: a stack of dispersionless
    media computes one column for all wavelengths; its results still carry the ``wl`` axis."""
    return None if x is None else jnp.broadcast_to(x, x.shape[:-1] + rs.wavelength.shape[-1:])


@public_program
def specular(stack: Stack, wavelength_nm, angle_deg: Optional[RealLike] = None, *,
             angle_rad: Optional[RealLike] = None, both_sides: bool = True) -> Response:
    r"""Specular reflectance and transmittance of ``stack`` for collimated light.

    Args:
        stack: the stack (with a substrate or a background; for a background, the exit
            medium is the background's binder of index :math:`n_g`).
        wavelength_nm: ``(wl,)`` vacuum wavelengths in nm.
        angle_deg: angle of incidence in the ambient, **degrees** in [0, 90]; scalar or any
            shape ``(*angle)``. (Until 0.1 this argument was in radians: pass
            ``angle_rad=`` for radians.)
        angle_rad: the same angle in radians (keyword only; give one of the two). Default:
            normal incidence.
        both_sides: also return the response to light from the exit side.

    Returns:
        :class:`Response` with arrays ``(*angle, 2, wl)`` (also for dispersionless stacks).
    """
    if angle_deg is not None and angle_rad is not None:
        raise LayerstackError("specular: give angle_deg or angle_rad, not both")
    if angle_rad is not None:
        angle_deg = jnp.rad2deg(jnp.asarray(angle_rad)) if not is_concrete(angle_rad) else np.rad2deg(np.asarray(angle_rad, float))
    else:  # until 0.1 the third argument was radians: a value that reads like one is called out
        warn_if_implausible("specular: angle_deg", angle_deg,
                            lambda a, xp: (xp.max(a) > 0) & (xp.max(a) <= xp.pi / 2) & xp.any(a != xp.round(a)),
                            "all within (0, pi/2] and not whole degrees: radians given? pass angle_rad= for radians")
    angle_deg = check_angle_deg("specular: angle of incidence (angle_deg)", 0.0 if angle_deg is None else angle_deg,
                                grazing=True)
    rs = resolve(stack, wavelength_nm)
    out = stack_intensities(rs, _snell(rs, angle_deg), both_sides=both_sides)
    return Response(*(_wavelength_axis(_to_public(x), rs) for x in out))


def hemisphere(rs: ResolvedStack, side: str, nodes: int):
    """Snell invariants ``s`` and weights ``w`` (``(node, wl)`` or ``(node, 1)``) of the
    hemispherical rule seen from the ambient (``side='front'``) or the exit medium ('back'),
    and the :func:`_reach` of each group of segments."""
    # Split at the critical angle of every other medium. Thin films add no branch point (their
    # response is even in their own q) but a sharp frustrated-TIR feature there, so they count too.
    if side == "front":
        n_from, others = rs.n[0], list(rs.n[1:])
    elif side == "back":
        n_from, others = rs.n[-1], list(rs.n[:-1])
    else:
        raise LayerstackError(f"side must be 'front' or 'back', got {side!r}")
    # at least (1,) so that the node axis stays in front of the wavelength axis
    n_from = np.atleast_1d(np.real(n_from)) if is_concrete(n_from) else jnp.atleast_1d(jnp.real(n_from))
    mu, w = hemispherical_rule(n_from, others, nodes)
    return jnp.real(jnp.asarray(n_from)) * jnp.sqrt(mu), w, _reach(rs, side, evanescent_beyond(n_from, others), nodes)


def _reach(rs: ResolvedStack, side: str, beyond, nodes: int):
    r"""Which packets light from ``side`` can reach, segment by segment of the hemispherical rule.

    Past the critical angle of a thick medium of real index, the packet in front of it carries
    no power into it (Re q = 0: total internal reflection, frustrated or not by coherent films),
    so the layers behind it do not change the response: their Beer factors are exactly zero.
    Those segments need only the packets up to that medium — on P2-like stacks (a varnish of
    n ≈ 1.5 over a background of n_g ≈ 1.52) half of the back-side nodes never touch the
    thicknesses or α, so a fit or a batch evaluates their adding rule once, not per sample.

    Returns a tuple of ``(start, stop, (first, last), transmits)``: node range, packet range
    (packets ``first … last-1`` and the thick layers between them) and whether any power can cross the
    whole stack (False once the far medium or a thick medium on the way is evanescent: then
    T = 0 exactly and is not computed); consecutive segments alike merged. None when the segment
    layout is not static (then every node joins every packet).
    """
    if beyond is None:
        return None
    thick = thick_media(rs.coherent)
    m = len(thick) - 1  # number of packets
    shift = 0 if side == "back" else 1  # position in rs.n of entry p of `others`
    plan: list = []
    for i, media in enumerate(beyond):
        cuts = [thick.index(p + shift) for p in media if p + shift in thick and _is_real(rs.n[p + shift])]
        reach = (max(cuts, default=0), m) if side == "back" else (0, min(cuts, default=m))
        key = (reach, not cuts)
        if plan and plan[-1][2:] == key:
            plan[-1] = (plan[-1][0], (i + 1) * nodes, *key)
        else:
            plan.append((i * nodes, (i + 1) * nodes, *key))
    return tuple(plan)


def _is_real(n) -> bool:
    return is_concrete(n) and bool(np.all(np.imag(np.asarray(n)) == 0))


def _node_slice(x, start: int, stop: int):
    """Nodes ``start:stop`` of a quadrature array: the node axis is the second to last."""
    return None if x is None else x[..., start:stop, :]


def diffuse_joined(rs: ResolvedStack, side: str, interfaces: Interfaces, w, plan=None) -> Diffuse:
    """Hemispherical sums of the joined response (:func:`_reach` ``plan``: which packets each
    group of nodes sees; those beyond an evanescent thick medium carry no transmittance)."""
    m = len(interfaces.packets)
    back = side == "back"
    if plan is None:
        plan = ((0, w.shape[0], (0, m), True),)
    r = t = 0.0
    for start, stop, packets, transmits in plan:
        if (start, stop) == (0, w.shape[0]):
            sub, ws = interfaces, w
        else:
            sub = jax.tree_util.tree_map(lambda x: _node_slice(x, start, stop), interfaces)
            ws = w[start:stop]
        first, last = packets
        thickness, alpha = thick_layer_parameters(rs, first, last)
        # transmits=False: T = 0 exactly (an evanescent medium is in the way), not computed
        r_part, t_part = hemispherical_sums(tuple(sub.packets[first:last]), tuple(sub.paths[first:last - 1]),
                                            thickness, alpha, rs.wavelength, ws, back, transmits)
        r, t = r + r_part, t + t_part
    r = _wavelength_axis(jnp.broadcast_to(r, jnp.broadcast_shapes(jnp.shape(r), jnp.shape(t))), rs)
    return Diffuse(r, jnp.zeros_like(r) + t)


def diffuse_resolved(rs: ResolvedStack, side: str, nodes: int) -> Diffuse:
    s, w, plan = hemisphere(rs, side, nodes)
    return diffuse_joined(rs, side, stack_interfaces(rs, s, both_sides=(side == "back")), w, plan)


@public_program
def diffuse(stack: Stack, wavelength_nm, side: str = "front", *, nodes: int = DEFAULT_NODES) -> Diffuse:
    """Diffuse (Lambertian, natural light) reflectance and transmittance of the stack.

    ``side='front'``: light from the ambient (Simonot eqs. 47, 49, 62, 63); ``side='back'``: from
    the exit medium (:math:`r_{k+1..0}`, :math:`t_{k+1..0}` of eq. 78). ``nodes`` Gauss–Legendre
    nodes per critical-angle segment (see :mod:`layerstack_jax._kernels.quadrature`).
    Returns :class:`Diffuse` with arrays ``(wl,)``.
    """
    return diffuse_resolved(resolve(stack, wavelength_nm), side, nodes)


def natural_T_front(rs: ResolvedStack, angle_deg) -> Spectrum:
    """Natural-light collimated transmittance into the exit medium at ``angle_deg`` (degrees,
    ``(*angle)``), dimensionless, ``(*angle, 1 | wl)``."""
    s = _snell(rs, angle_deg)
    return natural(stack_intensities(rs, s, both_sides=False).T_front)
