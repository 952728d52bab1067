r"""Measurement geometries and the quantities they measure (Simonot et al. §4, eqs. 64–87).

Public entry points:

* :func:`specular` — angle-resolved R, T (front and back) per polarization;
* :func:`diffuse` — hemispherical (Lambertian) reflectance and transmittance, either side;
* :func:`reflectance` — what an instrument reads for a given :class:`Geometry`;
* :func:`invert_background` — intrinsic background reflectance ρg from a measurement.

Angles are degrees in geometry objects and radians in :func:`specular`; wavelengths in nm.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._quadrature import DEFAULT_NODES, hemispherical_rule
from ._response import natural, stack_intensities
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
]


class Response(NamedTuple):
    """Angle-resolved response. Arrays shaped ``(*angle, 2, wl)``: axis −2 is polarization
    ``(s, p)``. ``*_front``: light from the ambient; ``*_back``: from the exit medium at the same
    Snell invariant. ``T``: power entering the far medium. Use :meth:`natural` for unpolarized
    light (mean of s and p, taken after the whole recursion: Simonot eqs. 57–58)."""

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
    shaped ``(wl,)`` (Simonot eqs. 47, 49, 62, 63)."""

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


def _diffuse_resolved(rs: ResolvedStack, side: str, nodes: int) -> Diffuse:
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
    s = jnp.real(jnp.asarray(n_from)) * jnp.sqrt(mu)
    out = stack_intensities(rs, s, both_sides=(side == "back"))
    R, T = (out.R_front, out.T_front) if side == "front" else (out.R_back, out.T_back)
    return Diffuse(jnp.sum(w * natural(R), axis=0), jnp.sum(w * natural(T), axis=0))


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
    ``'excluded'`` (SCE, Simonot eq. 78) or ``'included'`` (SCI: adds the front reflectance)."""

    incidence_deg: object = 8.0
    specular: str = eqx.field(static=True, default="excluded")

    def __check_init__(self):
        if self.specular not in ("excluded", "included"):
            raise LayerstackError(f"Sphere.specular must be 'excluded' or 'included', got {self.specular!r}")


class Directional(Geometry):
    """Radiance detector: reflectance factor against a perfect white diffuser (Simonot eq. 79),
    illumination at ``incidence_deg``, viewing at ``viewing_deg`` (45/0, 0/45, …)."""

    incidence_deg: object = 45.0
    viewing_deg: object = 0.0


class BRDF(Geometry):
    """Bidirectional reflectance distribution function in 1/sr (Simonot eq. 76): the
    :class:`Directional` reflectance factor divided by π (diffuse part only)."""

    incidence_deg: object = 45.0
    viewing_deg: object = 0.0


class Specular(Geometry):
    """Specular measurement at ``angle_deg``: ``quantity`` 'R' (reflectance), 'T' (transmittance
    into the exit medium) or 'A' (absorptance, 1 − R − T)."""

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


def reflectance(stack: Stack, wavelength_nm, geometry: Geometry, *, nodes: int = DEFAULT_NODES):
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
    """
    rs = resolve(stack, wavelength_nm)
    if isinstance(geometry, Specular):
        out = stack_intensities(rs, _snell(rs, jnp.deg2rad(geometry.angle_deg)), both_sides=False)
        R, T = natural(out.R_front), natural(out.T_front)
        return {"R": R, "T": T, "A": 1.0 - R - T}[geometry.quantity]
    background = isinstance(stack.exit, LambertianBackground)
    if isinstance(geometry, Sphere):
        out = stack_intensities(rs, _snell(rs, jnp.deg2rad(geometry.incidence_deg)), both_sides=False)
        total = jnp.zeros_like(natural(out.R_front))
        if background:
            d = _diffuse_resolved(rs, "back", nodes)
            rho = rs.rho_g
            total = d.t * rho * natural(out.T_front) / (1.0 - rho * d.r)
        if geometry.specular == "included":
            total = total + natural(out.R_front)
        return total
    if isinstance(geometry, (Directional, BRDF)):
        if not background:
            raise LayerstackError(
                "a specular substrate has no diffuse reflectance factor: measure it with a specular geometry "
                "(Specular(angle), CLI 'specular:ANGLE') or put the stack over a LambertianBackground"
            )
        d = _diffuse_resolved(rs, "back", nodes)
        rho = rs.rho_g
        ratio = (jnp.real(rs.n[0]) / jnp.real(rs.n[-1])) ** 2
        factor = ratio * _natural_T_front(rs, geometry.incidence_deg) * _natural_T_front(rs, geometry.viewing_deg)
        value = factor * rho / (1.0 - rho * d.r)
        return value / jnp.pi if isinstance(geometry, BRDF) else value
    raise LayerstackError(f"unsupported geometry {geometry!r}")


def invert_background(stack: Stack, wavelength_nm, measured, geometry: Geometry, *, nodes: int = DEFAULT_NODES):
    r"""Intrinsic reflectance :math:`\rho_g` of the background from a measured spectrum.

    Generalises Simonot eqs. 86 (sphere) and 87 (radiance detector) from a bare background to
    any stack: with :math:`R = A\rho_g/(1-\rho_g r_b)` the model of :func:`reflectance`,
    :math:`\rho_g = R/(A + r_b R)`. For a bare background pass ``Stack(ambient, [],
    LambertianBackground(n_g, 0.0))``; the stack's own ρg is ignored. For SCI the specular
    reflectance is subtracted first.
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
