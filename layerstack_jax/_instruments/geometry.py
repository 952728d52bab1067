r"""Measurement geometries: what an instrument reads (Simonot et al. §4, eqs. 64–87).

A geometry is an :class:`equinox.Module` implementing the :class:`Geometry` interface — what
optics it needs (:meth:`Geometry.optics`), how it turns them into the measured quantity
(:meth:`Geometry.read`), how it prints (:attr:`Geometry.label`) and parses itself
(:meth:`Geometry.parse`), what its reading is called (:attr:`Geometry.quantity_label`) and
whether a reading may be negative (:attr:`Geometry.signed`). No code outside a geometry's own
module switches on its type: adding an instrument is one class (see ``docs/architecture.md``).

Public entry points built on the interface:

* :func:`reflectance` — what an instrument of the given geometry reads;
* :func:`fixed_optics` — the part of it that fits of thick layers reuse;
* :func:`invert_background` — intrinsic background reflectance ρg from a measurement;
* :func:`parse_geometry` — ``"sphere:8:sce"``, ``"45/0"``, ``"brdf:45:0"``, ``"specular:30"``,
  ``"ellipsometry:70:psi"`` … into a geometry (options of the instrument as built, e.g.
  ``"sphere:8:sce:cone=5"``, ``"45/0:illum=2:view=4"``: :mod:`layerstack_jax._instruments.instrument`).

Angles are degrees in [0, 90) everywhere at this surface; wavelengths in nm.
"""

from __future__ import annotations

import abc
import re
from typing import ClassVar, Optional

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._base.custom_types import Array, Float, RealLike, RealSpectrumLike
from .._base.programs import public_program
from .._base.validate import (
    LayerstackError,
    check_angle_deg,
    check_nonnegative,
    check_positive,
    check_unit_interval,
    is_concrete,
    warn_if_radians,
)
from .._kernels.fresnel import exit_medium_ratio
from .._kernels.quadrature import DEFAULT_NODES

# the illumination drivers are public through this module too (their historical home)
from .._stacks.illumination import (  # noqa: F401  (re-exported)
    Diffuse,
    Response,
    _snell,
    diffuse,
    diffuse_joined,
    diffuse_resolved,
    hemisphere,
    natural_T_front,
    specular,
)
from .._stacks.recursion import join_interfaces, natural, stack_intensities, stack_interfaces
from .._stacks.stack import LambertianBackground, ResolvedStack, Stack, as_spectrum, resolve
from .instrument import DEFAULT_CONE_NODES, cap_measure, check_cone, cone_rule, covered, substituted_reading
from .optics import Optics, check_optics, coherent_films

__all__ = [
    "Geometry",
    "OpticalGeometry",
    "Sphere",
    "Directional",
    "BRDF",
    "Specular",
    "parse_geometry",
    "reflectance",
    "invert_background",
    "fixed_optics",
    "geometry_kinds",
]

_KINDS: list = []  # concrete geometry classes, in registration order (parse_geometry tries each)


def _scalar_text(x) -> str:
    return f"{float(x):g}" if is_concrete(x) and jnp.ndim(x) == 0 else "array"


class Geometry(eqx.Module):
    """Interface of a measurement geometry (abstract): what every instrument needs to be read.

    * :meth:`measure` — what it reads for a stack on a wavelength grid, ``(*angle, wl)``;
    * :attr:`label` and :meth:`parse` — its command-line spelling, both ways (:attr:`spelling`
      the accepted forms, for messages);
    * :attr:`quantity_label` — what its reading is ("reflectance", "BRDF (1/sr)" …);
    * :attr:`signed`, :attr:`reading_is_fraction` — what values a reading may take (data checks);
    * :meth:`residual` — model vs data in a fit (the difference, or a wrapped one for Δ);
    * :meth:`wavelengths_read` — where the materials are evaluated (wider than the grid when the
      instrument averages over a band).

    Instruments that read intensities through the fixed :class:`~layerstack_jax.Optics` (the
    spectrophotometers) implement :class:`OpticalGeometry`; an ellipsometer, which reads the
    amplitudes' ratio, implements this interface directly.
    """

    #: readings may be negative (ellipsometric Δ, C, S)
    signed: ClassVar[bool] = False
    #: the reading is a dimensionless fraction, normally in [0, 1] (a value > 1 suggests percent)
    reading_is_fraction: ClassVar[bool] = True

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "parse" in cls.__dict__ and cls not in _KINDS:  # a concrete kind parses its own spelling
            _KINDS.append(cls)

    @abc.abstractmethod
    def measure(self, stack: Stack, wavelength_nm, *, nodes: int = DEFAULT_NODES,
                optics: Optional[Optics] = None) -> Float[Array, "*angle wl"]:
        """What this instrument reads for ``stack`` on ``wavelength_nm`` (nm), shaped ``(*angle,
        wl)``; ``optics`` (from :func:`fixed_optics`) is reused by geometries that have them."""

    # -- how it prints and parses itself
    @property
    @abc.abstractmethod
    def label(self) -> str:
        """The command-line spelling, e.g. ``"sphere:8:sce"`` (parsed back by :meth:`parse`)."""

    @property
    @abc.abstractmethod
    def quantity_label(self) -> str:
        """What the reading is, with its unit, for reports and plot axes."""

    @classmethod
    @abc.abstractmethod
    def parse(cls, text: str) -> Optional["Geometry"]:
        """The geometry spelled by ``text`` (lower case, stripped), or None if ``text`` is not
        this kind's spelling; a malformed spelling of this kind raises :class:`LayerstackError`."""

    #: the accepted spellings, for messages
    spelling: ClassVar[str] = ""

    # -- how a reading is compared with a measured one
    def residual(self, model, data):
        """Model minus data, in the reading's unit, for the residuals of a fit
        (``fitting.Objective``): ``model`` and ``data`` broadcast to ``(..., wl)``. The
        difference ``model - data`` unless the reading lives on a circle (an ellipsometer's Δ,
        wrapped into (−180°, 180°]); an override must stay differentiable in ``model``."""
        return model - data

    def wavelengths_read(self, wavelength_nm) -> np.ndarray:
        """The wavelengths (nm) at which the materials are evaluated for a reading on
        ``wavelength_nm``: the grid itself, or wider where the instrument averages over a band
        (an ellipsometer's bandwidth). ``fitting.Objective`` checks the material tables against it."""
        return np.asarray(wavelength_nm, dtype=float)

class OpticalGeometry(Geometry):
    """A geometry read through the fixed :class:`~layerstack_jax.Optics` (abstract): the
    spectrophotometers — sphere, 45°/0°, BRDF, specular.

    * :meth:`optics` — the Optics it needs for a resolved stack (the Fresnel algebra at its
      angles; hemispherical nodes over a background), reused by :func:`fixed_optics`;
    * :meth:`read` — the measured quantity from those optics, ``(*angle, wl)``;
    * ``background_factor(rs, nodes)`` where the reading can be inverted for ρg — ``(A, r_b,
      prepare)``: the reading is :math:`A\rho_g/(1-\rho_g r_b)` after ``prepare(measured)``
      (:func:`invert_background`; the sphere, 45°/0° and BRDF have one, specular readings not);
    * :attr:`reads_diffuse_light` — over a background the reading includes diffuse light;
    * :meth:`_seen` — the stack as the instrument sees it (behind a cover glass).

    :meth:`measure` is the same for all of them: resolve, make (or check) the optics, read.
    """

    #: over a background, the reading includes the diffuse light (hemispherical nodes needed)
    reads_diffuse_light: ClassVar[bool] = True

    @abc.abstractmethod
    def optics(self, rs: ResolvedStack, background: bool, nodes: int) -> Optics:
        """The :class:`~layerstack_jax.Optics` this geometry needs for ``rs``."""

    @abc.abstractmethod
    def read(self, rs: ResolvedStack, optics: Optics, background: bool) -> Float[Array, "*angle wl"]:
        """The instrument's reading from ``optics`` (made by :meth:`optics` for ``rs``)."""

    def _seen(self, rs: ResolvedStack) -> ResolvedStack:
        """The resolved stack as the instrument sees it: ``rs`` itself, or ``rs`` behind what the
        instrument adds in front of the sample (a cover glass: :func:`~layerstack_jax._instruments.instrument.covered`)."""
        return rs

    def measure(self, stack: Stack, wavelength_nm, *, nodes: int = DEFAULT_NODES,
                optics: Optional[Optics] = None) -> Float[Array, "*angle wl"]:
        """What this instrument reads for ``stack`` on ``wavelength_nm`` (nm), reusing
        ``optics`` (from :func:`fixed_optics`) when given. Shaped ``(*angle, wl)``."""
        rs = self._seen(resolve(stack, wavelength_nm))
        background = rs.rho_g is not None
        if optics is None:
            optics = self.optics(rs, background, nodes)
        else:
            check_optics(optics, rs, self, nodes)
            if background and self.reads_diffuse_light and optics.diffuse is None:
                raise LayerstackError("optics were made for a stack over a substrate, this one has a background")
        try:
            out = self.read(rs, optics, background)
        except TypeError as e:  # leaves whose leading (batch) axes do not broadcast together
            raise LayerstackError(f"the stack's leaves do not broadcast together ({e}); to predict many spectra "
                                  "from leaves with batch axes use layerstack_jax.predict(stack, wavelength_nm, "
                                  "geometry), which maps over them in bounded memory") from None
        return jnp.broadcast_to(out, out.shape[:-1] + rs.wavelength.shape[-1:])


def _incidence(rs: ResolvedStack, angle_deg):
    return stack_interfaces(rs, _snell(rs, angle_deg), both_sides=False)


def _back_hemisphere(rs: ResolvedStack, nodes: int):
    s, weights, reach = hemisphere(rs, "back", nodes)
    return stack_interfaces(rs, s, both_sides=True), weights, reach


def _optics(geometry, rs, incidence, viewing=None, diffuse=None, weights=None, reach=None, nodes=DEFAULT_NODES):
    return Optics(geometry, incidence, viewing, diffuse, weights, tuple(rs.n), coherent_films(rs), nodes, reach)


def _diffuse_back(rs: ResolvedStack, o: Optics) -> Diffuse:
    return diffuse_joined(rs, "back", o.diffuse, o.weights, o.reach)


def _substrate_has_no_diffuse_light() -> LayerstackError:
    return LayerstackError(
        "a specular substrate has no diffuse reflectance factor: measure it with a specular geometry "
        "(Specular(angle), CLI 'specular:ANGLE') or put the stack over a LambertianBackground"
    )


def _split(text: str, kind: str, n_min: int, n_max: int) -> list[str]:
    parts = text.split(":")
    if not n_min <= len(parts) <= n_max:
        raise ValueError(kind)
    return parts


# ----------------------------------------------------------------- non-ideal instruments (issue 15)
# The cover-glass fields are shared by Sphere, Directional and BRDF; they are declared in each
# class after its own fields (not in a base class, whose fields would come first and change the
# positional construction Sphere(8.0, "excluded"), Directional(45.0, 0.0)).


def _is_zero(x) -> bool:
    """True when ``x`` is None or concretely 0 everywhere: that non-ideality is left out and the
    reading is computed exactly as by the ideal instrument (bit for bit)."""
    return x is None or (is_concrete(x) and not np.any(np.asarray(x)))


def _check_cover(name: str, g) -> None:
    """Eager checks of the cover-glass fields of geometry ``g`` (class name ``name``)."""
    if g.cover_index is None:
        return
    if not callable(g.cover_index):
        check_positive(f"{name}.cover_index", g.cover_index)
    check_nonnegative(f"{name}.cover_thickness_nm (nm)", g.cover_thickness_nm)
    check_nonnegative(f"{name}.cover_alpha_per_nm (1/nm)", g.cover_alpha_per_nm)


def _covered(g, rs: ResolvedStack) -> ResolvedStack:
    if g.cover_index is None:
        return rs
    return covered(rs, g.cover_index, g.cover_thickness_nm, g.cover_alpha_per_nm, g.cover_contact)


def _cone_invariants(rs: ResolvedStack, axis_deg, half_angle_deg, nodes: int):
    """Snell invariants :math:`n_0\\sin\\theta_k` ``(*angle, K, 1 | wl)`` of the directions of
    :func:`~layerstack_jax._instruments.instrument.cone_rule` (from their sines: a finite derivative in β
    also where a direction meets the normal)."""
    _, sin_t, _ = cone_rule(axis_deg, half_angle_deg, nodes)
    return jnp.real(jnp.asarray(rs.n[0])) * sin_t[..., None]


def _cone_interfaces(rs: ResolvedStack, axis_deg, half_angle_deg, nodes: int):
    return stack_interfaces(rs, _cone_invariants(rs, axis_deg, half_angle_deg, nodes), both_sides=False)


def _cone_T(rs: ResolvedStack, axis_deg, half_angle_deg, nodes: int):
    """Natural-light collimated transmittance at the cone's directions, ``(*angle, K, 1 | wl)``."""
    s = _cone_invariants(rs, axis_deg, half_angle_deg, nodes)
    return natural(stack_intensities(rs, s, both_sides=False).T_front)


def _cone_mean(T_k, axis_deg, half_angle_deg, nodes: int):
    r"""Projected-solid-angle mean over the cone, :math:`\int T\cos\theta\,d\Omega /
    \int\cos\theta\,d\Omega`, of ``T_k`` ``(*angle, K, wl)`` at the :func:`cone_rule` directions:
    ``(*angle, wl)``. The factor :math:`1-\cos\beta` cancels (finite at β = 0)."""
    cos_t, _, w = cone_rule(axis_deg, half_angle_deg, nodes)
    c = w * cos_t
    c = c / jnp.sum(c, axis=-1, keepdims=True)
    return jnp.sum(c[..., None] * T_k, axis=-2)


def _stale_optics(what: str) -> LayerstackError:
    return LayerstackError(f"optics were made for {what}: rebuild them with fixed_optics() for this geometry")


def _aperture_mean(T, axis_deg, half_angle_deg, nodes: int):
    """``T`` from :class:`Optics` at a point (``half_angle_deg`` None: returned as is) or at the
    :func:`cone_rule` directions (averaged by :func:`_cone_mean`), after checking that the
    optics were made that way: a cone adds an axis of K = 2 nodes² directions before the
    wavelengths (leading batch axes of the stack's leaves may come in front of either)."""
    K = 2 * nodes * nodes
    has_cone_axis = T.ndim >= np.ndim(axis_deg) + 2 and T.shape[-2] == K
    if half_angle_deg is None:
        if has_cone_axis:
            raise _stale_optics("an aperture (a cone of directions), this geometry reads a point")
        return T
    if not has_cone_axis:
        raise _stale_optics("a point or another number of cone_nodes, this geometry reads an aperture")
    return _cone_mean(T, axis_deg, half_angle_deg, nodes)


def _port_escape(rs: ResolvedStack, T_k, axis_deg, half_angle_deg, nodes: int):
    r"""The part of the back-side diffuse transmittance :math:`t_b` that leaves into the specular
    port's cone (half-angle β about the specular direction θ_0), ``(*angle, wl)``:
    :math:`\frac{(n_0/n_g)^2}{\pi}\int_\text{cone} T(\theta)\cos\theta\,d\Omega` — the
    radiance leaving the stack towards θ is :math:`(n_0/n_g)^2 T(\theta)` times that of the
    diffuse flux under it (Simonot eq. 77, reciprocity), and over the whole hemisphere this
    integral is :math:`t_b` itself (eq. 49 with the same reciprocity)."""
    cos_t, _, w = cone_rule(axis_deg, half_angle_deg, nodes)
    ratio = exit_medium_ratio(rs.n[0], rs.n[-1])
    solid = cap_measure(half_angle_deg)[..., None]
    return ratio * solid / jnp.pi * jnp.sum((w * cos_t)[..., None] * T_k, axis=-2)


def _options(text: str, keys: dict, flags: dict) -> dict:
    """``key=value`` and flag options after a geometry's base spelling, as constructor keywords."""
    out = {}
    for part in text:
        if not part:
            continue
        if "=" in part:
            k, v = part.split("=", 1)
            if k not in keys:
                raise LayerstackError(f"unknown option {k!r} (known: {', '.join([*keys, *flags])})")
            out[keys[k]] = float(v)
        elif part in flags:
            out[flags[part]] = True
        else:
            raise LayerstackError(f"unknown option {part!r} (known: {', '.join([*keys, *flags])})")
    return out


def _option_text(g, keys: dict, flags: dict, defaults: dict) -> str:
    """The ``:key=value`` options of ``g`` whose value differs from the class default."""
    out = []
    for k, field in keys.items():
        v = getattr(g, field)
        if v is None or (is_concrete(v) and np.ndim(v) == 0 and float(v) == defaults.get(field)):
            continue
        out.append(f":{k}={_scalar_text(v) if not callable(v) else 'function'}")
    out += [f":{k}" for k, field in flags.items() if getattr(g, field)]
    return "".join(out)


_COVER_OPTIONS = {"cover": "cover_index", "cover_d": "cover_thickness_nm", "cover_alpha": "cover_alpha_per_nm"}
_COVER_FLAGS = {"contact": "cover_contact"}
_COVER_DEFAULTS = {"cover_thickness_nm": 1.0e6, "cover_alpha_per_nm": 0.0}


class Sphere(OpticalGeometry):
    r"""Integrating sphere, collimated illumination at ``incidence_deg``; specular component
    ``'excluded'`` (SCE, Simonot eq. 78) or ``'included'`` (SCI: adds the front reflectance).

    ``incidence_deg`` in degrees from the normal, in [0, 90): a scalar, or an array ``(*angle)``
    that adds leading axes to the :func:`reflectance` output ``(*angle, wl)``.

    The ideal sphere reads, over a :class:`LambertianBackground`,
    :math:`\rho_s = t_b\,\rho_g T(\theta_0)/(1-\rho_g r_b)` (+ :math:`R(\theta_0)` in SCI).
    The instrument as built (every field a differentiable pytree leaf, fittable with
    ``fitting.instrument``; the defaults are the ideal sphere, read bit for bit as before):

    * ``port_half_angle_deg`` β (degrees, SCE only): the specular exclusion port removes a cone
      of half-angle β about the specular direction, not a single direction: the diffuse light
      leaving into it is lost too,

      .. math::
          \rho_s = \rho_g T(\theta_0)\,\frac{t_b - \frac{(n_0/n_g)^2}{\pi}
          \int_\text{cone} T(\theta)\cos\theta\,d\Omega}{1-\rho_g r_b},

      integrated on the fixed nodes of :func:`~layerstack_jax._instruments.instrument.cone_rule`
      (``cone_nodes`` × 2 ``cone_nodes`` directions). For a Lambertian exitance the fraction
      lost is :math:`\cos\theta_0\sin^2\beta`. θ_0 + β < 90°.
    * ``wall_reflectance`` ρ_w (None: the ideal sphere), ``sample_port_fraction`` f_s,
      ``open_port_fraction`` f_h (entrance, detector and open specular ports; area fractions
      of the sphere), ``reference_reflectance`` ρ_ref (the calibration standard; None: ρ_w):
      the single-beam substitution reading (sphere multiplier; Labsphere technical guide §1.4,
      Hanssen & Snail 2002) :math:`R = \rho_s(1-\rho_w f_w-\rho_\text{ref} f_s)/(1-\rho_w f_w
      -\rho'_s f_s)`, :math:`f_w = 1-f_s-f_h`, :math:`\rho'_s` the sample's reflectance for
      Lambertian light (:func:`~layerstack_jax._instruments.instrument.substituted_reading`). Each a scalar,
      an array on the grid or a callable spectrum (ρ_w, ρ_ref).
    * ``cover_index`` (None: no cover glass; a number, an array on the grid or a callable of
      λ in nm), ``cover_thickness_nm`` (nm), ``cover_alpha_per_nm`` (1/nm), ``cover_contact``
      (static): the sample behind a cover glass — a thick incoherent glass, then an air gap
      (or, with ``cover_contact``, in optical contact), prepended to the stack
      (:func:`~layerstack_jax._instruments.instrument.covered`); its specular reflection is excluded with
      the sample's in SCE and included in SCI.

    CLI: ``sphere:8:sce``, options ``:cone=5``, ``:wall=0.98:port=0.03:open=0.02:ref=0.99``,
    ``:cover=1.52[:cover_d=1e6][:cover_alpha=0][:contact]``.
    """

    incidence_deg: RealLike = 8.0
    specular: str = eqx.field(static=True, default="excluded")
    port_half_angle_deg: RealLike = 0.0
    wall_reflectance: Optional[RealSpectrumLike] = None
    sample_port_fraction: RealLike = 0.0
    open_port_fraction: RealLike = 0.0
    reference_reflectance: Optional[RealSpectrumLike] = None
    cover_index: Optional[RealSpectrumLike] = None
    cover_thickness_nm: RealLike = 1.0e6
    cover_alpha_per_nm: RealLike = 0.0
    cover_contact: bool = eqx.field(static=True, default=False)
    cone_nodes: int = eqx.field(static=True, default=DEFAULT_CONE_NODES)

    spelling: ClassVar[str] = "sphere:ANGLE:sce|sci[:cone=DEG][:wall=R:port=F:open=F:ref=R][:cover=N]"
    _OPTIONS: ClassVar[dict] = {"cone": "port_half_angle_deg", "wall": "wall_reflectance",
                                "port": "sample_port_fraction", "open": "open_port_fraction",
                                "ref": "reference_reflectance", **_COVER_OPTIONS}
    _DEFAULTS: ClassVar[dict] = {"port_half_angle_deg": 0.0, "sample_port_fraction": 0.0, "open_port_fraction": 0.0,
                                 **_COVER_DEFAULTS}

    def __check_init__(self):
        if self.specular not in ("excluded", "included"):
            raise LayerstackError(f"Sphere.specular must be 'excluded' or 'included', got {self.specular!r}")
        check_angle_deg("Sphere.incidence_deg", self.incidence_deg)
        if not (isinstance(self.cone_nodes, int) and self.cone_nodes >= 1):
            raise LayerstackError(f"Sphere.cone_nodes must be an int >= 1, got {self.cone_nodes!r}")
        if not _is_zero(self.port_half_angle_deg):
            if self.specular == "included":
                raise LayerstackError("Sphere.port_half_angle_deg: the specular port is closed in SCI "
                                      "(specular='included'); the port cone applies to SCE only")
            check_cone("Sphere.port_half_angle_deg (degrees)", self.incidence_deg, self.port_half_angle_deg)
        if self.wall_reflectance is None:
            for name in ("sample_port_fraction", "open_port_fraction", "reference_reflectance"):
                if not _is_zero(getattr(self, name)):
                    raise LayerstackError(f"Sphere.{name} is given without wall_reflectance: the sphere "
                                          "multiplier needs the wall reflectance (give wall_reflectance=...)")
        else:
            for name in ("wall_reflectance", "reference_reflectance"):
                v = getattr(self, name)
                if v is not None and not callable(v):
                    check_unit_interval(f"Sphere.{name}", v)
            check_unit_interval("Sphere.sample_port_fraction", self.sample_port_fraction)
            check_unit_interval("Sphere.open_port_fraction", self.open_port_fraction)
            if is_concrete((self.sample_port_fraction, self.open_port_fraction)):
                check_unit_interval("Sphere.sample_port_fraction + open_port_fraction",
                                    np.asarray(self.sample_port_fraction, float)
                                    + np.asarray(self.open_port_fraction, float))
        _check_cover("Sphere", self)

    def _has_port(self) -> bool:
        return self.specular == "excluded" and not _is_zero(self.port_half_angle_deg)

    def _port(self):
        """(θ_0, β), checked (eagerly, or at run time under jit)."""
        theta = check_angle_deg("Sphere.incidence_deg", self.incidence_deg)
        return theta, check_cone("Sphere.port_half_angle_deg (degrees)", theta, self.port_half_angle_deg)

    def _seen(self, rs):
        return _covered(self, rs)

    def optics(self, rs, background, nodes):
        incidence = _incidence(rs, check_angle_deg("Sphere.incidence_deg", self.incidence_deg))
        if not background:
            return _optics(self, rs, incidence, nodes=nodes)
        port = _cone_interfaces(rs, *self._port(), self.cone_nodes) if self._has_port() else None
        return _optics(self, rs, incidence, port, *_back_hemisphere(rs, nodes), nodes=nodes)

    def read(self, rs, o, background):
        front = join_interfaces(rs, o.incidence, both_sides=False)
        total = jnp.zeros_like(natural(front.R_front))
        d = None
        if background:  # Simonot eqs. 69, 78
            d, rho = _diffuse_back(rs, o), rs.rho_g
            escape = d.t
            if self._has_port():  # the diffuse light leaving into the port's cone is lost
                if o.viewing is None:
                    raise _stale_optics("a sphere without a port cone")
                T_k = natural(join_interfaces(rs, o.viewing, both_sides=False).T_front)
                escape = d.t - _port_escape(rs, T_k, *self._port(), self.cone_nodes)
            total = escape * rho * natural(front.T_front) / (1.0 - rho * d.r)
        if self.specular == "included":
            total = total + natural(front.R_front)
        if self.wall_reflectance is not None:
            total = self._substituted(rs, total, self._lambertian_reflectance(rs, o.nodes, d))
        return total

    # -- the sphere multiplier (substitution reading)
    def _sphere(self, rs):
        """(ρ_w, f_s, f_h, ρ_ref) on the grid, checked."""
        wl = rs.wavelength
        wall = check_unit_interval("Sphere.wall_reflectance", as_spectrum(self.wall_reflectance, wl))
        ref = wall if self.reference_reflectance is None else check_unit_interval(
            "Sphere.reference_reflectance", as_spectrum(self.reference_reflectance, wl))
        fs = check_unit_interval("Sphere.sample_port_fraction", self.sample_port_fraction)
        fh = check_unit_interval("Sphere.open_port_fraction", self.open_port_fraction)
        return wall, fs, fh, ref

    def _lambertian_reflectance(self, rs, nodes, d):
        r""":math:`\rho'_s`: the sample's reflectance for Lambertian light from the ambient,
        :math:`r_f + t_f\rho_g t_b/(1-\rho_g r_b)` over a background (``d``: its back-side
        :class:`Diffuse`), :math:`r_f` over a substrate."""
        f = diffuse_resolved(rs, "front", nodes)
        if d is None:
            return f.r
        rho = rs.rho_g
        return f.r + f.t * rho * d.t / (1.0 - rho * d.r)

    def _substituted(self, rs, first, lambertian):
        wall, fs, fh, ref = self._sphere(rs)
        return substituted_reading(first, lambertian, wall, fs, fh, ref)

    @property
    def label(self):
        base = f"sphere:{_scalar_text(self.incidence_deg)}:{'sce' if self.specular == 'excluded' else 'sci'}"
        return base + _option_text(self, self._OPTIONS, _COVER_FLAGS, self._DEFAULTS)

    @property
    def quantity_label(self):
        return "reflectance"

    @classmethod
    def parse(cls, text):
        if not text.startswith("sphere"):
            return None
        parts = text.split(":")
        head, options = parts[:3], parts[3:]
        if any("=" in p for p in head[1:]) or head[-1] == "contact":  # options right after the angle
            raise ValueError("sphere: options follow sphere:ANGLE:sce|sci")
        angle = float(head[1]) if len(head) > 1 and head[1] else 8.0
        mode = head[2] if len(head) > 2 else "sce"
        if mode not in ("sce", "sci"):
            raise ValueError(mode)
        return cls(angle, "excluded" if mode == "sce" else "included",
                   **_options(options, cls._OPTIONS, _COVER_FLAGS))

    def background_factor(self, rs, nodes):
        d = diffuse_resolved(rs, "back", nodes)
        out = stack_intensities(rs, _snell(rs, self.incidence_deg), both_sides=False)
        specular_part = natural(out.R_front) if self.specular == "included" else 0.0
        escape = d.t
        if self._has_port():
            theta, beta = self._port()
            escape = d.t - _port_escape(rs, _cone_T(rs, theta, beta, self.cone_nodes), theta, beta, self.cone_nodes)
        A = escape * natural(out.T_front)
        if self.wall_reflectance is None:
            return A, d.r, lambda measured: measured - specular_part
        # measured R = (S + A X) K / (base - f_s (r_f + B X)), X = ρg/(1 - ρg r_b): solved for A X
        wall, fs, fh, ref = self._sphere(rs)
        f = diffuse_resolved(rs, "front", nodes)
        base = 1.0 - wall * (1.0 - fs - fh)
        K, B = base - ref * fs, f.t * d.t

        def prepare(measured):
            X = (measured * (base - fs * f.r) - K * specular_part) / (K * A + measured * fs * B)
            return A * X

        return A, d.r, prepare


#: (axis field, aperture half-angle field) of a radiance-detector geometry (Directional, BRDF)
_APERTURES = (("incidence_deg", "illumination_half_angle_deg"), ("viewing_deg", "viewing_half_angle_deg"))


def _check_apertures(name: str, g) -> None:
    """Each non-zero aperture of ``g`` (Directional, BRDF) a cone above the horizon (eager and under jit)."""
    for axis, half in _APERTURES:
        if not _is_zero(getattr(g, half)):
            check_cone(f"{name}.{half} (degrees)", getattr(g, axis), getattr(g, half))


class Directional(OpticalGeometry):
    r"""Radiance detector: reflectance factor against a perfect white diffuser (Simonot eq. 79),
    illumination at ``incidence_deg``, viewing at ``viewing_deg`` (45/0, 0/45, …).

    Angles in degrees from the normal, in [0, 90), scalars or arrays broadcastable to a common
    ``(*angle)`` that adds leading axes to the :func:`reflectance` output ``(*angle, wl)``; the
    value is a dimensionless reflectance factor,
    :math:`(n_0/n_g)^2 T(\theta_0) T(\theta_0')\rho_g/(1-\rho_g r_b)` (eqs. 77, 79).

    The instrument as built (differentiable leaves, fittable with ``fitting.instrument``; the
    defaults are the ideal instrument, read bit for bit as before):

    * ``illumination_half_angle_deg`` β_i, ``viewing_half_angle_deg`` β_v (degrees): finite
      apertures. The illumination is a cone of uniform radiance of half-angle β_i about
      ``incidence_deg``, the detector accepts a cone of half-angle β_v about ``viewing_deg``
      with uniform responsivity; both readings (sample and white standard) are then weighted by
      the projected solid angle :math:`\cos\theta\,d\Omega`, so the reading is the
      :math:`\cos\theta\,d\Omega`-weighted mean of the point reading over both cones. The point
      reading factorises in θ_0 and θ_0', so it is
      :math:`(n_0/n_g)^2\,\bar T_i\,\bar T_v\,\rho_g/(1-\rho_g r_b)` with :math:`\bar T =
      \int_\text{cone} T\cos\theta\,d\Omega / \int_\text{cone}\cos\theta\,d\Omega` on the fixed
      nodes of :func:`~layerstack_jax._instruments.instrument.cone_rule` (``cone_nodes``). Each cone must
      stay above the horizon.
    * ``cover_index``, ``cover_thickness_nm``, ``cover_alpha_per_nm``, ``cover_contact``: a
      cover glass in front of the sample, as for :class:`Sphere`.

    CLI: ``45/0``, options ``:illum=DEG``, ``:view=DEG``, ``:cover=N`` … (e.g. ``45/0:illum=2:view=4``).
    """

    incidence_deg: RealLike = 45.0
    viewing_deg: RealLike = 0.0
    illumination_half_angle_deg: RealLike = 0.0
    viewing_half_angle_deg: RealLike = 0.0
    cover_index: Optional[RealSpectrumLike] = None
    cover_thickness_nm: RealLike = 1.0e6
    cover_alpha_per_nm: RealLike = 0.0
    cover_contact: bool = eqx.field(static=True, default=False)
    cone_nodes: int = eqx.field(static=True, default=DEFAULT_CONE_NODES)

    spelling: ClassVar[str] = "ANGLE/ANGLE (e.g. 45/0)[:illum=DEG][:view=DEG][:cover=N]"
    _OPTIONS: ClassVar[dict] = {"illum": "illumination_half_angle_deg", "view": "viewing_half_angle_deg",
                                **_COVER_OPTIONS}
    _DEFAULTS: ClassVar[dict] = {"illumination_half_angle_deg": 0.0, "viewing_half_angle_deg": 0.0, **_COVER_DEFAULTS}

    def __check_init__(self):
        name = type(self).__name__
        check_angle_deg(f"{name}.incidence_deg", self.incidence_deg)
        check_angle_deg(f"{name}.viewing_deg", self.viewing_deg)
        if not (isinstance(self.cone_nodes, int) and self.cone_nodes >= 1):
            raise LayerstackError(f"{name}.cone_nodes must be an int >= 1, got {self.cone_nodes!r}")
        _check_apertures(name, self)
        _check_cover(name, self)

    def _seen(self, rs):
        return _covered(self, rs)

    def _apertures(self):
        """((θ, β or None) of the illumination, of the viewing), checked; β None: a point."""
        name = type(self).__name__
        out = []
        for axis, half in _APERTURES:
            theta = check_angle_deg(f"{name}.{axis}", getattr(self, axis))
            beta = None if _is_zero(getattr(self, half)) else check_cone(f"{name}.{half} (degrees)", theta,
                                                                          getattr(self, half))
            out.append((theta, beta))
        return out

    def optics(self, rs, background, nodes):
        if not background:
            raise _substrate_has_no_diffuse_light()
        (ti, bi), (tv, bv) = self._apertures()
        incidence = _incidence(rs, ti) if bi is None else _cone_interfaces(rs, ti, bi, self.cone_nodes)
        viewing = _incidence(rs, tv) if bv is None else _cone_interfaces(rs, tv, bv, self.cone_nodes)
        return _optics(self, rs, incidence, viewing, *_back_hemisphere(rs, nodes), nodes=nodes)

    def read(self, rs, o, background):
        if not background:
            raise _substrate_has_no_diffuse_light()
        (ti, bi), (tv, bv) = self._apertures()
        front = natural(join_interfaces(rs, o.incidence, both_sides=False).T_front)
        view = natural(join_interfaces(rs, o.viewing, both_sides=False).T_front)
        front = _aperture_mean(front, ti, bi, self.cone_nodes)
        view = _aperture_mean(view, tv, bv, self.cone_nodes)
        d, rho = _diffuse_back(rs, o), rs.rho_g
        # Simonot eqs. 77, 79: (n0/n_g)² T(θ0) T(θ0') ρg / (1 − ρg r_b)
        ratio = exit_medium_ratio(rs.n[0], rs.n[-1])
        return ratio * front * view * rho / (1.0 - rho * d.r)

    @property
    def label(self):
        return (f"{_scalar_text(self.incidence_deg)}/{_scalar_text(self.viewing_deg)}"
                + _option_text(self, self._OPTIONS, _COVER_FLAGS, self._DEFAULTS))

    @property
    def quantity_label(self):
        return "reflectance factor"

    @classmethod
    def parse(cls, text):
        base, *options = text.split(":")
        if "/" not in base:
            return None
        i, v = base.split("/")
        return cls(float(i), float(v), **_options(options, cls._OPTIONS, _COVER_FLAGS))

    def _mean_T(self, rs, theta, beta):
        if beta is None:
            return natural_T_front(rs, theta)
        return _cone_mean(_cone_T(rs, theta, beta, self.cone_nodes), theta, beta, self.cone_nodes)

    def background_factor(self, rs, nodes):
        d = diffuse_resolved(rs, "back", nodes)
        ratio = exit_medium_ratio(rs.n[0], rs.n[-1])
        (ti, bi), (tv, bv) = self._apertures()
        A = ratio * self._mean_T(rs, ti, bi) * self._mean_T(rs, tv, bv)
        return A, d.r, lambda measured: measured


class BRDF(OpticalGeometry):
    """Bidirectional reflectance distribution function in 1/sr (Simonot eq. 76): the
    :class:`Directional` reflectance factor divided by π (diffuse part only).

    Angles in degrees from the normal, in [0, 90), scalars or arrays broadcastable to a common
    ``(*angle)`` that adds leading axes to the :func:`reflectance` output ``(*angle, wl)``.

    The instrument as built: finite apertures (``illumination_half_angle_deg``,
    ``viewing_half_angle_deg``) and a cover glass (``cover_*``), as for :class:`Directional`
    (the reading is its reading divided by π); ideal by default. CLI: ``brdf:45:0:illum=2:view=4``.
    """

    incidence_deg: RealLike = 45.0
    viewing_deg: RealLike = 0.0
    illumination_half_angle_deg: RealLike = 0.0
    viewing_half_angle_deg: RealLike = 0.0
    cover_index: Optional[RealSpectrumLike] = None
    cover_thickness_nm: RealLike = 1.0e6
    cover_alpha_per_nm: RealLike = 0.0
    cover_contact: bool = eqx.field(static=True, default=False)
    cone_nodes: int = eqx.field(static=True, default=DEFAULT_CONE_NODES)

    spelling: ClassVar[str] = "brdf:I:V[:illum=DEG][:view=DEG][:cover=N]"
    reading_is_fraction: ClassVar[bool] = False  # 1/sr

    def __check_init__(self):
        check_angle_deg("BRDF.incidence_deg", self.incidence_deg)
        check_angle_deg("BRDF.viewing_deg", self.viewing_deg)
        _check_apertures("BRDF", self)
        _check_cover("BRDF", self)

    def _factor(self) -> Directional:
        if _is_zero(self.illumination_half_angle_deg) and _is_zero(self.viewing_half_angle_deg) \
                and self.cover_index is None and self.cone_nodes == DEFAULT_CONE_NODES:
            return Directional(self.incidence_deg, self.viewing_deg)
        return Directional(self.incidence_deg, self.viewing_deg, self.illumination_half_angle_deg,
                           self.viewing_half_angle_deg, self.cover_index, self.cover_thickness_nm,
                           self.cover_alpha_per_nm, self.cover_contact, self.cone_nodes)

    def _seen(self, rs):
        return _covered(self, rs)

    @property
    def ideal(self) -> bool:
        """True without apertures and cover glass (the instrument of Simonot eq. 76 itself)."""
        return (_is_zero(self.illumination_half_angle_deg) and _is_zero(self.viewing_half_angle_deg)
                and self.cover_index is None)

    def optics(self, rs, background, nodes):
        o = self._factor().optics(rs, background, nodes)
        return Optics(self, o.incidence, o.viewing, o.diffuse, o.weights, o.index, o.films, o.nodes, o.reach)

    def read(self, rs, o, background):
        return self._factor().read(rs, o, background) / jnp.pi  # eq. 76

    @property
    def label(self):
        return (f"brdf:{_scalar_text(self.incidence_deg)}:{_scalar_text(self.viewing_deg)}"
                + _option_text(self, Directional._OPTIONS, _COVER_FLAGS, Directional._DEFAULTS))

    @property
    def quantity_label(self):
        return "BRDF (1/sr)"

    @classmethod
    def parse(cls, text):
        if not text.startswith("brdf"):
            return None
        parts = text.split(":")
        if len(parts) < 3:
            raise ValueError("brdf")
        _, i, v = parts[:3]
        return cls(float(i), float(v), **_options(parts[3:], Directional._OPTIONS, _COVER_FLAGS))

    def background_factor(self, rs, nodes):
        A, r, _ = self._factor().background_factor(rs, nodes)
        return A, r, lambda measured: measured * jnp.pi


class Specular(OpticalGeometry):
    """Specular measurement at ``angle_deg``: ``quantity`` 'R' (reflectance), 'T' (transmittance
    into the exit medium) or 'A' (absorptance, 1 − R − T), for natural light.

    ``angle_deg`` in degrees from the normal, in [0, 90): a scalar, or an array ``(*angle)`` that
    adds leading axes to the :func:`reflectance` output ``(*angle, wl)`` (dimensionless fractions).
    """

    angle_deg: RealLike = 0.0
    quantity: str = eqx.field(static=True, default="R")

    spelling: ClassVar[str] = "specular:ANGLE[:R|T|A]"
    reads_diffuse_light: ClassVar[bool] = False

    def __check_init__(self):
        if self.quantity not in ("R", "T", "A"):
            raise LayerstackError(f"Specular.quantity must be 'R', 'T' or 'A', got {self.quantity!r}")
        check_angle_deg("Specular.angle_deg", self.angle_deg)

    def optics(self, rs, background, nodes):
        return _optics(self, rs, _incidence(rs, check_angle_deg("Specular.angle_deg", self.angle_deg)), nodes=nodes)

    def read(self, rs, o, background):
        front = join_interfaces(rs, o.incidence, both_sides=False)
        R, T = natural(front.R_front), natural(front.T_front)
        return {"R": R, "T": T, "A": 1.0 - R - T}[self.quantity]

    @property
    def label(self):
        return f"specular:{_scalar_text(self.angle_deg)}:{self.quantity}"

    @property
    def quantity_label(self):
        return {"R": "reflectance", "T": "transmittance", "A": "absorptance"}[self.quantity]

    @classmethod
    def parse(cls, text):
        if not text.startswith("specular"):
            return None
        parts = _split(text, "specular", 2, 3)
        return cls(float(parts[1]), parts[2].upper() if len(parts) > 2 else "R")


def geometry_kinds() -> tuple:
    """The registered geometry classes (each parses its own spelling)."""
    return tuple(_KINDS)


def parse_geometry(text: str) -> Geometry:
    """The geometry spelled ``text``: ``sphere:8:sce``, ``sphere:8:sci``, ``45/0``, ``0/45``,
    ``brdf:45:0``, ``specular:30`` (optionally ``specular:30:T`` / ``:A``),
    ``ellipsometry:70:psi`` … (each kind parses its own spelling; angles in degrees)."""
    t = str(text).strip().lower()
    for kind in _KINDS:
        try:
            g = kind.parse(t)
        except LayerstackError as e:
            raise LayerstackError(f"geometry {text!r}: {e}") from None
        except (ValueError, IndexError):
            g = None
            break
        if g is not None:
            warn_if_radians(f"geometry {text!r}: angles (degrees)", _spelled_angles(t))
            return g
    raise LayerstackError(f"unknown geometry {text!r}: use " + ", ".join(k.spelling for k in _KINDS if k.spelling))


def _spelled_angles(text: str) -> np.ndarray:
    """The numbers of a geometry's spelling outside its ``key=value`` options (its angles:
    ``specular:30``, ``45/0``, ``brdf:45:0``, ``ellipsometry:65,70:psi``)."""
    numbers = []
    for part in re.split(r"[:/,]", text):
        try:
            numbers.append(float(part))
        except ValueError:
            pass
    return np.asarray(numbers if numbers else [0.0])


def fixed_optics(stack: Stack, wavelength_nm, geometry: Geometry, *, nodes: int = DEFAULT_NODES) -> Optics:
    """The :class:`Optics` of ``stack`` measured in ``geometry`` on ``wavelength_nm`` (nm).

    Valid for any stack with the same structure, indices and coherent-film thicknesses: only
    thick-layer thicknesses, α and ρg may differ when it is passed to :func:`reflectance`.
    The grid ``wavelength_nm`` ``(wl,)`` must be the one later passed to :func:`reflectance`.
    Returns None for a geometry that reads without optics (an ellipsometer).
    """
    _check_geometry(geometry)
    if not isinstance(geometry, OpticalGeometry):
        return None
    rs = geometry._seen(resolve(stack, wavelength_nm))
    return geometry.optics(rs, rs.rho_g is not None, nodes)


def _check_geometry(geometry) -> None:
    if not isinstance(geometry, Geometry):
        raise LayerstackError(f"geometry must be a layerstack_jax Geometry (e.g. Sphere(8.0), parse_geometry('45/0')), "
                              f"got {geometry!r}")


@public_program
def reflectance(stack: Stack, wavelength_nm, geometry: Geometry, *, nodes: int = DEFAULT_NODES,
                optics: Optional[Optics] = None) -> Float[Array, "*angle wl"]:
    r"""What an instrument of the given geometry reads, for natural light, shaped ``(wl,)``
    (more leading axes ``(*angle, wl)`` if the geometry's angles are arrays) — also for a stack
    of dispersionless media.

    Over a :class:`LambertianBackground` of intrinsic reflectance :math:`\rho_g` and index
    :math:`n_g`, with :math:`T(\theta)` the collimated transmittance of the stack, and
    :math:`r_b, t_b` its diffuse reflectance and transmittance from the background side:

    * :class:`Sphere`: :math:`t_b\,\rho_g T(\theta_0)/(1-\rho_g r_b)` (eqs. 69, 78), plus
      :math:`R(\theta_0)` when the specular component is included (a specular port's cone, the
      sphere multiplier of wall and ports, a cover glass: fields of :class:`Sphere`);
    * :class:`Directional`: :math:`(n_0/n_g)^2 T(\theta_0) T(\theta_0')\rho_g/(1-\rho_g r_b)` (eqs. 77, 79;
      finite apertures and a cover glass: fields of :class:`Directional`);
    * :class:`BRDF`: the above divided by π (eq. 76);
    * :class:`Specular`: R, T or A of the stack at the angle;
    * any other :class:`Geometry`: its :meth:`~Geometry.measure`.

    Over a :class:`Substrate` there is no diffuse light: the sphere reads R (SCI) or 0 (SCE);
    directional geometries raise an error.

    ``optics``: the :func:`fixed_optics` of a stack with the same indices and coherent films
    (only thick-layer thicknesses, α and ρg may differ): reused instead of recomputed.
    """
    _check_geometry(geometry)
    return geometry.measure(stack, wavelength_nm, nodes=nodes, optics=optics)


@public_program
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
    if not stack.exit.diffuse:
        raise LayerstackError("invert_background needs a stack over a LambertianBackground")
    _check_geometry(geometry)
    if not callable(getattr(geometry, "background_factor", None)):
        raise LayerstackError(f"cannot invert a {type(geometry).__name__} measurement for rho_g (a reading of the "
                              "diffuse light is needed: sphere, 45/0 or BRDF)")
    measured = jnp.asarray(measured)
    unit = Stack(stack.ambient, stack.layers, LambertianBackground(stack.exit.index, 1.0))  # ρg = 1, same binder
    rs = geometry._seen(resolve(unit, wavelength_nm))
    A, r_b, prepare = geometry.background_factor(rs, nodes)
    measured = prepare(measured)
    return measured / (A + r_b * measured)
