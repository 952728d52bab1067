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

from .._base.custom_types import Array, Float
from .._base.programs import public_program
from .._base.validate import (
    LayerstackError,
    warn_if_radians,
)
from .._kernels.quadrature import DEFAULT_NODES
from .._stacks.stack import LambertianBackground, ResolvedStack, Stack, resolve
from .optics import Optics, check_optics

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
    r"""A geometry read through the fixed :class:`~layerstack_jax.Optics` (abstract): the
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
