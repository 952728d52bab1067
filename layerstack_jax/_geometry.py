r"""Measurement geometries and the quantities they measure (Simonot et al. §4, eqs. 64–87).

Public entry points:

* :func:`specular` — angle-resolved R, T (front and back) per polarization;
* :func:`diffuse` — hemispherical (Lambertian) reflectance and transmittance, either side;
* :func:`reflectance` — what an instrument reads for a given :class:`Geometry`;
* :func:`invert_background` — intrinsic background reflectance ρg from a measurement.

Angles are degrees in geometry objects and radians in :func:`specular`; wavelengths in nm.
"""

from __future__ import annotations

from typing import NamedTuple, Optional

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._adding_sums import hemispherical_sums
from ._quadrature import DEFAULT_NODES, evanescent_beyond, hemispherical_rule
from ._response import (Interfaces, join_interfaces, natural, stack_interfaces, stack_intensities, thick_layer_parameters,
                        thick_media)
from ._stack import LambertianBackground, ResolvedStack, Stack, resolve
from ._validate import LayerstackError, is_concrete

__all__ = [
    "Response",
    "Diffuse",
    "Geometry",
    "Sphere",
    "Directional",
    "BRDF",
    "Specular",
    "parse_geometry",
    "specular",
    "diffuse",
    "reflectance",
    "invert_background",
    "Optics",
    "fixed_optics",
]


class Response(NamedTuple):
    """Angle-resolved response. Arrays shaped ``(*angle, 2, wl)``: axis −2 is polarization
    ``(s, p)``. ``*_front``: light from the ambient; ``*_back``: from the exit medium at the same
    Snell invariant. ``T``: power entering the far medium. All are dimensionless fractions of
    the incident power, in [0, 1]; ``R_back`` and ``T_back`` are None when ``both_sides=False``.
    Use :meth:`natural` for unpolarized light (mean of s and p, taken after the whole recursion:
    Simonot eqs. 57–58): it returns a :class:`Response` with arrays ``(*angle, wl)``."""

    R_front: object
    T_front: object
    R_back: object
    T_back: object

    def natural(self) -> "Response":
        return Response(*(None if x is None else 0.5 * (x[..., 0, :] + x[..., 1, :]) for x in self))

    @property
    def absorptance_front(self):
        return 1.0 - self.R_front - self.T_front


class Diffuse(NamedTuple):
    """Hemispherical reflectance ``r`` and transmittance ``t`` for Lambertian natural light,
    shaped ``(wl,)``, dimensionless fractions in [0, 1] (Simonot eqs. 47, 49, 62, 63)."""

    r: object
    t: object


def _to_public(x):
    return None if x is None else jnp.moveaxis(x, 0, -2)


def _snell(rs: ResolvedStack, angle_rad):
    """Snell invariant ``n0 sin θ0`` shaped ``(*angle, 1)`` or ``(*angle, wl)``."""
    angle = jnp.asarray(angle_rad)
    return jnp.real(rs.n[0]) * jnp.sin(angle)[..., None]


def specular(stack: Stack, wavelength_nm, angle_rad, *, both_sides: bool = True) -> Response:
    r"""Specular reflectance and transmittance of ``stack`` for collimated light.

    Args:
        stack: the stack (with a substrate or a background; for a background, the exit
            medium is the background's binder of index :math:`n_g`).
        wavelength_nm: ``(wl,)`` vacuum wavelengths in nm.
        angle_rad: angle of incidence in the ambient, radians; scalar or any shape ``(*angle)``.
        both_sides: also return the response to light from the exit side.

    Returns:
        :class:`Response` with arrays ``(*angle, 2, wl)``.
    """
    rs = resolve(stack, wavelength_nm)
    out = stack_intensities(rs, _snell(rs, angle_rad), both_sides=both_sides)
    return Response(*(_to_public(x) for x in out))


def _hemisphere(rs: ResolvedStack, side: str, nodes: int):
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


def _diffuse_joined(rs: ResolvedStack, side: str, interfaces: Interfaces, w, plan=None) -> Diffuse:
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
    return Diffuse(r, jnp.zeros_like(r) + t)


def _diffuse_resolved(rs: ResolvedStack, side: str, nodes: int) -> Diffuse:
    s, w, plan = _hemisphere(rs, side, nodes)
    return _diffuse_joined(rs, side, stack_interfaces(rs, s, both_sides=(side == "back")), w, plan)


def diffuse(stack: Stack, wavelength_nm, side: str = "front", *, nodes: int = DEFAULT_NODES) -> Diffuse:
    """Diffuse (Lambertian, natural light) reflectance and transmittance of the stack.

    ``side='front'``: light from the ambient (Simonot eqs. 47, 49, 62, 63); ``side='back'``: from
    the exit medium (:math:`r_{k+1..0}`, :math:`t_{k+1..0}` of eq. 78). ``nodes`` Gauss–Legendre
    nodes per critical-angle segment (see :mod:`layerstack_jax._quadrature`).
    Returns :class:`Diffuse` with arrays ``(wl,)``.
    """
    return _diffuse_resolved(resolve(stack, wavelength_nm), side, nodes)


class Geometry(eqx.Module):
    """Base class of measurement geometries."""


class Sphere(Geometry):
    """Integrating sphere, collimated illumination at ``incidence_deg``; specular component
    ``'excluded'`` (SCE, Simonot eq. 78) or ``'included'`` (SCI: adds the front reflectance).

    ``incidence_deg`` in degrees from the normal: a scalar, or an array ``(*angle)`` that adds
    leading axes to the :func:`reflectance` output ``(*angle, wl)``.
    """

    incidence_deg: object = 8.0
    specular: str = eqx.field(static=True, default="excluded")

    def __check_init__(self):
        if self.specular not in ("excluded", "included"):
            raise LayerstackError(f"Sphere.specular must be 'excluded' or 'included', got {self.specular!r}")


class Directional(Geometry):
    """Radiance detector: reflectance factor against a perfect white diffuser (Simonot eq. 79),
    illumination at ``incidence_deg``, viewing at ``viewing_deg`` (45/0, 0/45, …).

    Angles in degrees from the normal, scalars or arrays broadcastable to a common ``(*angle)``
    that adds leading axes to the :func:`reflectance` output ``(*angle, wl)``; the value is a
    dimensionless reflectance factor.
    """

    incidence_deg: object = 45.0
    viewing_deg: object = 0.0


class BRDF(Geometry):
    """Bidirectional reflectance distribution function in 1/sr (Simonot eq. 76): the
    :class:`Directional` reflectance factor divided by π (diffuse part only).

    Angles in degrees from the normal, scalars or arrays broadcastable to a common ``(*angle)``
    that adds leading axes to the :func:`reflectance` output ``(*angle, wl)``.
    """

    incidence_deg: object = 45.0
    viewing_deg: object = 0.0


class Specular(Geometry):
    """Specular measurement at ``angle_deg``: ``quantity`` 'R' (reflectance), 'T' (transmittance
    into the exit medium) or 'A' (absorptance, 1 − R − T), for natural light.

    ``angle_deg`` in degrees from the normal: a scalar, or an array ``(*angle)`` that adds
    leading axes to the :func:`reflectance` output ``(*angle, wl)`` (dimensionless fractions).
    """

    angle_deg: object = 0.0
    quantity: str = eqx.field(static=True, default="R")

    def __check_init__(self):
        if self.quantity not in ("R", "T", "A"):
            raise LayerstackError(f"Specular.quantity must be 'R', 'T' or 'A', got {self.quantity!r}")


def _check_angles(geometry: Geometry, text: str) -> Geometry:
    for name in ("incidence_deg", "viewing_deg", "angle_deg"):
        value = getattr(geometry, name, None)
        if value is not None and not 0.0 <= float(value) < 90.0:
            raise LayerstackError(f"geometry {text!r}: {name} must lie in [0, 90) degrees, got {value}")
    return geometry


def parse_geometry(text: str) -> Geometry:
    """Parse ``sphere:8:sce``, ``sphere:8:sci``, ``45/0``, ``0/45``, ``brdf:45:0``, ``specular:30``
    (optionally ``specular:30:T`` / ``:A``)."""
    t = text.strip().lower()
    try:
        if t.startswith("sphere"):
            parts = t.split(":")
            angle = float(parts[1]) if len(parts) > 1 and parts[1] else 8.0
            mode = parts[2] if len(parts) > 2 else "sce"
            if mode not in ("sce", "sci"):
                raise ValueError
            return _check_angles(Sphere(angle, "excluded" if mode == "sce" else "included"), text)
        if t.startswith("brdf"):
            _, i, v = t.split(":")
            return _check_angles(BRDF(float(i), float(v)), text)
        if t.startswith("specular"):
            parts = t.split(":")
            q = parts[2].upper() if len(parts) > 2 else "R"
            return _check_angles(Specular(float(parts[1]), q), text)
        if "/" in t:
            i, v = t.split("/")
            return _check_angles(Directional(float(i), float(v)), text)
    except LayerstackError:
        raise
    except (ValueError, IndexError):
        pass
    raise LayerstackError(
        f"unknown geometry {text!r}: use sphere:ANGLE:sce|sci, ANGLE/ANGLE (e.g. 45/0), brdf:I:V or specular:ANGLE[:R|T|A]"
    )


def _natural_T_front(rs: ResolvedStack, angle_deg):
    s = _snell(rs, jnp.deg2rad(angle_deg))
    return natural(stack_intensities(rs, s, both_sides=False).T_front)


class Optics(eqx.Module):
    r"""The part of a measurement that depends only on the indices, the coherent films and the
    geometry — Fresnel coefficients of every interface or coherent packet, slant paths in the
    thick layers and quadrature nodes, at the angles the geometry needs — and not on the thick
    layers' thicknesses, their α, or ρg. Made by :func:`fixed_optics`; passed to
    :func:`reflectance` (``optics=``) it is reused instead of recomputed: a fit of thick-layer
    thicknesses, α(λ) and ρg(λ) evaluates the complex Fresnel algebra once, not at every step.

    Fields (:class:`~layerstack_jax._response.Interfaces` or None): ``incidence`` at the
    illumination angle, ``viewing`` at the viewing angle (:class:`Directional`, :class:`BRDF`),
    ``diffuse`` at the back-side hemispherical nodes (over a background) with their ``weights``;
    ``index`` and ``films``: the indices and coherent-film thicknesses they were made with
    (checked against the stack when both are concrete); ``reach`` (static): which packets each
    group of back-side nodes reaches (:func:`_reach`; None: all of them).

    Everything is on the wavelength grid ``(wl,)`` (nm) it was made for: the Fresnel arrays
    carry the geometry's angle axes ``(*angle)`` and, for ``diffuse``, a node axis; the values
    are dimensionless (amplitude and intensity ratios; μ = sin²θ nodes and weights).
    """

    geometry: Geometry
    incidence: object
    viewing: object
    diffuse: object
    weights: object
    index: tuple
    films: tuple
    nodes: int = eqx.field(static=True, default=DEFAULT_NODES)
    reach: Optional[tuple] = eqx.field(static=True, default=None)


def _films(rs: ResolvedStack) -> tuple:
    return tuple(d for d, c in zip(rs.d, rs.coherent) if c)


def _optics_resolved(rs: ResolvedStack, background: bool, geometry: Geometry, nodes: int) -> Optics:
    incidence = viewing = diffuse = weights = reach = None
    if isinstance(geometry, Specular):
        incidence = stack_interfaces(rs, _snell(rs, jnp.deg2rad(geometry.angle_deg)), both_sides=False)
    elif isinstance(geometry, (Sphere, Directional, BRDF)):
        incidence = stack_interfaces(rs, _snell(rs, jnp.deg2rad(geometry.incidence_deg)), both_sides=False)
        if isinstance(geometry, (Directional, BRDF)):
            if not background:
                raise LayerstackError(
                    "a specular substrate has no diffuse reflectance factor: measure it with a specular geometry "
                    "(Specular(angle), CLI 'specular:ANGLE') or put the stack over a LambertianBackground"
                )
            viewing = stack_interfaces(rs, _snell(rs, jnp.deg2rad(geometry.viewing_deg)), both_sides=False)
        if background:
            s, weights, reach = _hemisphere(rs, "back", nodes)
            diffuse = stack_interfaces(rs, s, both_sides=True)
    else:
        raise LayerstackError(f"unsupported geometry {geometry!r}")
    return Optics(geometry, incidence, viewing, diffuse, weights, tuple(rs.n), _films(rs), nodes, reach)


def fixed_optics(stack: Stack, wavelength_nm, geometry: Geometry, *, nodes: int = DEFAULT_NODES) -> Optics:
    """The :class:`Optics` of ``stack`` measured in ``geometry`` on ``wavelength_nm`` (nm).

    Valid for any stack with the same structure, indices and coherent-film thicknesses: only
    thick-layer thicknesses, α and ρg may differ when it is passed to :func:`reflectance`.
    The grid ``wavelength_nm`` ``(wl,)`` must be the one later passed to :func:`reflectance`.
    """
    rs = resolve(stack, wavelength_nm)
    return _optics_resolved(rs, isinstance(stack.exit, LambertianBackground), geometry, nodes)


def _check_optics(optics: Optics, rs: ResolvedStack, geometry: Geometry, nodes: int) -> None:
    if not isinstance(optics, Optics):
        raise LayerstackError(f"optics must come from fixed_optics(), got {type(optics).__name__}")
    if type(optics.geometry) is not type(geometry) or optics.nodes != nodes:
        raise LayerstackError(
            f"optics were made for {type(optics.geometry).__name__} with {optics.nodes} nodes, "
            f"not {type(geometry).__name__} with {nodes}"
        )
    pairs = [("index", a, b) for a, b in zip(optics.index, rs.n)] + [
        ("coherent film thickness", a, b) for a, b in zip(optics.films, _films(rs))
    ]
    if len(optics.index) != len(rs.n) or len(optics.films) != len(_films(rs)):
        raise LayerstackError("optics were made for a stack of another structure")
    for what, a, b in pairs:
        if is_concrete((a, b)) and not np.allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=0):
            raise LayerstackError(
                f"optics were made with another {what}: rebuild them with fixed_optics() "
                "(only thick-layer thicknesses, alpha and rho_g may change)"
            )


def reflectance(stack: Stack, wavelength_nm, geometry: Geometry, *, nodes: int = DEFAULT_NODES,
                optics: Optional[Optics] = None):
    r"""What an instrument of the given geometry reads, for natural light, shaped ``(wl,)``
    (more leading axes if the geometry's angles are arrays).

    Over a :class:`LambertianBackground` of intrinsic reflectance :math:`\rho_g` and index
    :math:`n_g`, with :math:`T(\theta)` the collimated transmittance of the stack, and
    :math:`r_b, t_b` its diffuse reflectance and transmittance from the background side:

    * :class:`Sphere`: :math:`t_b\,\rho_g T(\theta_0)/(1-\rho_g r_b)` (eqs. 69, 78), plus
      :math:`R(\theta_0)` when the specular component is included;
    * :class:`Directional`: :math:`(n_0/n_g)^2 T(\theta_0) T(\theta_0')\rho_g/(1-\rho_g r_b)` (eqs. 77, 79);
    * :class:`BRDF`: the above divided by π (eq. 76);
    * :class:`Specular`: R, T or A of the stack at the angle.

    Over a :class:`Substrate` there is no diffuse light: the sphere reads R (SCI) or 0 (SCE);
    directional geometries raise an error.

    ``optics``: the :func:`fixed_optics` of a stack with the same indices and coherent films
    (only thick-layer thicknesses, α and ρg may differ): reused instead of recomputed.
    """
    rs = resolve(stack, wavelength_nm)
    background = isinstance(stack.exit, LambertianBackground)
    if optics is None:
        o = _optics_resolved(rs, background, geometry, nodes)
    else:
        _check_optics(optics, rs, geometry, nodes)
        if background and optics.diffuse is None and not isinstance(geometry, Specular):
            raise LayerstackError("optics were made for a stack over a substrate, this one has a background")
        if isinstance(geometry, (Directional, BRDF)) and not background:
            return _optics_resolved(rs, background, geometry, nodes)  # raises the substrate message
        o = optics
    front = join_interfaces(rs, o.incidence, both_sides=False)
    if isinstance(geometry, Specular):
        R, T = natural(front.R_front), natural(front.T_front)
        return {"R": R, "T": T, "A": 1.0 - R - T}[geometry.quantity]
    d = _diffuse_joined(rs, "back", o.diffuse, o.weights, o.reach) if background else None
    if isinstance(geometry, Sphere):
        total = jnp.zeros_like(natural(front.R_front))
        if background:
            rho = rs.rho_g
            total = d.t * rho * natural(front.T_front) / (1.0 - rho * d.r)
        if geometry.specular == "included":
            total = total + natural(front.R_front)
        return total
    # Directional / BRDF (checked by _optics_resolved)
    rho = rs.rho_g
    ratio = (jnp.real(rs.n[0]) / jnp.real(rs.n[-1])) ** 2
    view = join_interfaces(rs, o.viewing, both_sides=False)
    factor = ratio * natural(front.T_front) * natural(view.T_front)
    value = factor * rho / (1.0 - rho * d.r)
    return value / jnp.pi if isinstance(geometry, BRDF) else value


def invert_background(stack: Stack, wavelength_nm, measured, geometry: Geometry, *, nodes: int = DEFAULT_NODES):
    r"""Intrinsic reflectance :math:`\rho_g` of the background from a measured spectrum.

    Generalises Simonot eqs. 86 (sphere) and 87 (radiance detector) from a bare background to
    any stack: with :math:`R = A\rho_g/(1-\rho_g r_b)` the model of :func:`reflectance`,
    :math:`\rho_g = R/(A + r_b R)`. For a bare background pass ``Stack(ambient, [],
    LambertianBackground(n_g, 0.0))``; the stack's own ρg is ignored. For SCI the specular
    reflectance is subtracted first.

    Args:
        stack: a stack over a :class:`LambertianBackground`.
        wavelength_nm: ``(wl,)`` vacuum wavelengths in nm.
        measured: the instrument reading, broadcastable to ``(*angle, wl)``: a dimensionless
            reflectance (factor) for :class:`Sphere` / :class:`Directional`, in 1/sr for
            :class:`BRDF`.
        geometry: a :class:`Sphere`, :class:`Directional` or :class:`BRDF` (angles in degrees).
        nodes: Gauss–Legendre nodes per critical-angle segment.

    Returns:
        ρg, dimensionless, shaped like ``measured`` broadcast against ``(*angle, wl)``.
    """
    if not isinstance(stack.exit, LambertianBackground):
        raise LayerstackError("invert_background needs a stack over a LambertianBackground")
    measured = jnp.asarray(measured)
    unit = eqx.tree_at(lambda st: st.exit.reflectance, stack, 1.0)
    rs = resolve(unit, wavelength_nm)
    d = _diffuse_resolved(rs, "back", nodes)
    if isinstance(geometry, Sphere):
        out = stack_intensities(rs, _snell(rs, jnp.deg2rad(geometry.incidence_deg)), both_sides=False)
        if geometry.specular == "included":
            measured = measured - natural(out.R_front)
        A = d.t * natural(out.T_front)
    elif isinstance(geometry, (Directional, BRDF)):
        if isinstance(geometry, BRDF):
            measured = measured * jnp.pi
        ratio = (jnp.real(rs.n[0]) / jnp.real(rs.n[-1])) ** 2
        A = ratio * _natural_T_front(rs, geometry.incidence_deg) * _natural_T_front(rs, geometry.viewing_deg)
    else:
        raise LayerstackError(f"cannot invert a {type(geometry).__name__} measurement for rho_g")
    return measured / (A + d.r * measured)
