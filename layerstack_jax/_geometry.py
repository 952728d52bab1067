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
  ``"ellipsometry:70:psi"`` … into a geometry.

Angles are degrees in [0, 90) everywhere at this surface; wavelengths in nm.
"""

from __future__ import annotations

import abc
from typing import ClassVar, Optional

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._custom_types import Array, Float, RealLike
from ._fresnel import exit_medium_ratio
from ._illumination import _snell, diffuse_joined, diffuse_resolved, hemisphere, natural_T_front
from ._optics import Optics, check_optics, coherent_films
from ._quadrature import DEFAULT_NODES
from ._response import join_interfaces, natural, stack_interfaces, stack_intensities
from ._stack import LambertianBackground, ResolvedStack, Stack, resolve
from ._validate import LayerstackError, check_angle_deg, is_concrete

# the illumination drivers are public through this module too (their historical home)
from ._illumination import Diffuse, Response, diffuse, specular  # noqa: F401  (re-exported)


__all__ = [
    "Geometry",
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
    """Interface of a measurement geometry (abstract).

    A concrete geometry implements:

    * :meth:`optics` — the :class:`~layerstack_jax.Optics` it needs for a resolved stack (the
      Fresnel algebra at its angles; hemispherical nodes over a background);
    * :meth:`read` — the measured quantity from those optics, ``(*angle, wl)``;
    * :attr:`label` and :meth:`parse` — its command-line spelling, both ways;
    * :attr:`quantity_label` — what its reading is ("reflectance", "BRDF (1/sr)" …);
    * :attr:`signed` — True when a reading may be negative (ellipsometric Δ, C, S);
    * optionally :meth:`background_factor` (for :func:`invert_background`),
      :meth:`prediction_columns` (the columns ``layerstack predict`` writes for it) and
      :meth:`residual` (model vs data in a fit: the difference, or a wrapped one for Δ).

    Geometries that do not go through :class:`~layerstack_jax.Optics` (an ellipsometer)
    override :meth:`measure` instead and return None from :meth:`optics`.
    """

    #: readings may be negative (ellipsometric Δ, C, S)
    signed: ClassVar[bool] = False
    #: over a background, the reading includes the diffuse light (hemispherical nodes needed)
    reads_diffuse_light: ClassVar[bool] = True
    #: the reading is a dimensionless fraction, normally in [0, 1] (a value > 1 suggests percent)
    reading_is_fraction: ClassVar[bool] = True

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "parse" in cls.__dict__ and cls not in _KINDS:  # a concrete kind parses its own spelling
            _KINDS.append(cls)

    # -- what it needs and how it reads it
    @abc.abstractmethod
    def optics(self, rs: ResolvedStack, background: bool, nodes: int) -> Optional[Optics]:
        """The :class:`~layerstack_jax.Optics` this geometry needs for ``rs``."""

    @abc.abstractmethod
    def read(self, rs: ResolvedStack, optics: Optics, background: bool) -> Float[Array, "*angle wl"]:
        """The instrument's reading from ``optics`` (made by :meth:`optics` for ``rs``)."""

    def measure(self, stack: Stack, wavelength_nm, *, nodes: int = DEFAULT_NODES,
                optics: Optional[Optics] = None) -> Float[Array, "*angle wl"]:
        """What this instrument reads for ``stack`` on ``wavelength_nm`` (nm), reusing
        ``optics`` (from :func:`fixed_optics`) when given. Shaped ``(*angle, wl)``."""
        rs = resolve(stack, wavelength_nm)
        background = isinstance(stack.exit, LambertianBackground)
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

    def prediction_columns(self, text: str) -> list:
        """``[(column name, geometry)]`` that ``layerstack predict -g text`` writes."""
        return [(text, self)]

    def background_factor(self, rs: ResolvedStack, nodes: int):
        r"""``(A, r_b, measured → ρg-form)`` of :func:`invert_background`: the reading is
        :math:`A\rho_g/(1-\rho_g r_b)` after ``prepare(measured)``."""
        raise LayerstackError(f"cannot invert a {type(self).__name__} measurement for rho_g")

    def polarized_columns(self, stack: Stack, wavelength_nm, name: str, polarization: str, nodes: int) -> dict:
        """Polarization-resolved columns for ``layerstack predict --polarization``."""
        raise LayerstackError(f"geometry {name!r}: --polarization applies to brdf:I:V geometries only")

    @property
    def supports_polarization(self) -> bool:
        return False


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


class Sphere(Geometry):
    """Integrating sphere, collimated illumination at ``incidence_deg``; specular component
    ``'excluded'`` (SCE, Simonot eq. 78) or ``'included'`` (SCI: adds the front reflectance).

    ``incidence_deg`` in degrees from the normal, in [0, 90): a scalar, or an array ``(*angle)``
    that adds leading axes to the :func:`reflectance` output ``(*angle, wl)``.
    """

    incidence_deg: RealLike = 8.0
    specular: str = eqx.field(static=True, default="excluded")

    spelling: ClassVar[str] = "sphere:ANGLE:sce|sci"

    def __check_init__(self):
        if self.specular not in ("excluded", "included"):
            raise LayerstackError(f"Sphere.specular must be 'excluded' or 'included', got {self.specular!r}")
        check_angle_deg("Sphere.incidence_deg", self.incidence_deg)

    def optics(self, rs, background, nodes):
        incidence = _incidence(rs, check_angle_deg("Sphere.incidence_deg", self.incidence_deg))
        if not background:
            return _optics(self, rs, incidence, nodes=nodes)
        return _optics(self, rs, incidence, None, *_back_hemisphere(rs, nodes), nodes=nodes)

    def read(self, rs, o, background):
        front = join_interfaces(rs, o.incidence, both_sides=False)
        total = jnp.zeros_like(natural(front.R_front))
        if background:  # Simonot eqs. 69, 78
            d, rho = _diffuse_back(rs, o), rs.rho_g
            total = d.t * rho * natural(front.T_front) / (1.0 - rho * d.r)
        if self.specular == "included":
            total = total + natural(front.R_front)
        return total

    @property
    def label(self):
        return f"sphere:{_scalar_text(self.incidence_deg)}:{'sce' if self.specular == 'excluded' else 'sci'}"

    @property
    def quantity_label(self):
        return "reflectance"

    @classmethod
    def parse(cls, text):
        if not text.startswith("sphere"):
            return None
        parts = _split(text, "sphere", 1, 3)
        angle = float(parts[1]) if len(parts) > 1 and parts[1] else 8.0
        mode = parts[2] if len(parts) > 2 else "sce"
        if mode not in ("sce", "sci"):
            raise ValueError(mode)
        return cls(angle, "excluded" if mode == "sce" else "included")

    def background_factor(self, rs, nodes):
        d = diffuse_resolved(rs, "back", nodes)
        out = stack_intensities(rs, _snell(rs, self.incidence_deg), both_sides=False)
        specular_part = natural(out.R_front) if self.specular == "included" else 0.0
        return d.t * natural(out.T_front), d.r, lambda measured: measured - specular_part


class Directional(Geometry):
    """Radiance detector: reflectance factor against a perfect white diffuser (Simonot eq. 79),
    illumination at ``incidence_deg``, viewing at ``viewing_deg`` (45/0, 0/45, …).

    Angles in degrees from the normal, in [0, 90), scalars or arrays broadcastable to a common
    ``(*angle)`` that adds leading axes to the :func:`reflectance` output ``(*angle, wl)``; the
    value is a dimensionless reflectance factor.
    """

    incidence_deg: RealLike = 45.0
    viewing_deg: RealLike = 0.0

    spelling: ClassVar[str] = "ANGLE/ANGLE (e.g. 45/0)"

    def __check_init__(self):
        check_angle_deg(f"{type(self).__name__}.incidence_deg", self.incidence_deg)
        check_angle_deg(f"{type(self).__name__}.viewing_deg", self.viewing_deg)

    def optics(self, rs, background, nodes):
        if not background:
            raise _substrate_has_no_diffuse_light()
        name = type(self).__name__
        incidence = _incidence(rs, check_angle_deg(f"{name}.incidence_deg", self.incidence_deg))
        viewing = _incidence(rs, check_angle_deg(f"{name}.viewing_deg", self.viewing_deg))
        return _optics(self, rs, incidence, viewing, *_back_hemisphere(rs, nodes), nodes=nodes)

    def read(self, rs, o, background):
        if not background:
            raise _substrate_has_no_diffuse_light()
        front = join_interfaces(rs, o.incidence, both_sides=False)
        view = join_interfaces(rs, o.viewing, both_sides=False)
        d, rho = _diffuse_back(rs, o), rs.rho_g
        # Simonot eqs. 77, 79: (n0/n_g)² T(θ0) T(θ0') ρg / (1 − ρg r_b)
        ratio = exit_medium_ratio(rs.n[0], rs.n[-1])
        return ratio * natural(front.T_front) * natural(view.T_front) * rho / (1.0 - rho * d.r)

    @property
    def label(self):
        return f"{_scalar_text(self.incidence_deg)}/{_scalar_text(self.viewing_deg)}"

    @property
    def quantity_label(self):
        return "reflectance factor"

    @classmethod
    def parse(cls, text):
        if "/" not in text or ":" in text:
            return None
        i, v = text.split("/")
        return cls(float(i), float(v))

    def background_factor(self, rs, nodes):
        d = diffuse_resolved(rs, "back", nodes)
        ratio = exit_medium_ratio(rs.n[0], rs.n[-1])
        A = ratio * natural_T_front(rs, self.incidence_deg) * natural_T_front(rs, self.viewing_deg)
        return A, d.r, lambda measured: measured


class BRDF(Geometry):
    """Bidirectional reflectance distribution function in 1/sr (Simonot eq. 76): the
    :class:`Directional` reflectance factor divided by π (diffuse part only).

    Angles in degrees from the normal, in [0, 90), scalars or arrays broadcastable to a common
    ``(*angle)`` that adds leading axes to the :func:`reflectance` output ``(*angle, wl)``.
    """

    incidence_deg: RealLike = 45.0
    viewing_deg: RealLike = 0.0

    spelling: ClassVar[str] = "brdf:I:V"
    reading_is_fraction: ClassVar[bool] = False  # 1/sr

    def __check_init__(self):
        check_angle_deg("BRDF.incidence_deg", self.incidence_deg)
        check_angle_deg("BRDF.viewing_deg", self.viewing_deg)

    def _factor(self) -> Directional:
        return Directional(self.incidence_deg, self.viewing_deg)

    def optics(self, rs, background, nodes):
        o = self._factor().optics(rs, background, nodes)
        return Optics(self, o.incidence, o.viewing, o.diffuse, o.weights, o.index, o.films, o.nodes, o.reach)

    def read(self, rs, o, background):
        return self._factor().read(rs, o, background) / jnp.pi  # eq. 76

    @property
    def label(self):
        return f"brdf:{_scalar_text(self.incidence_deg)}:{_scalar_text(self.viewing_deg)}"

    @property
    def quantity_label(self):
        return "BRDF (1/sr)"

    @classmethod
    def parse(cls, text):
        if not text.startswith("brdf"):
            return None
        _, i, v = _split(text, "brdf", 3, 3)
        return cls(float(i), float(v))

    def background_factor(self, rs, nodes):
        A, r, _ = self._factor().background_factor(rs, nodes)
        return A, r, lambda measured: measured * jnp.pi

    @property
    def supports_polarization(self) -> bool:
        return True

    def polarized_columns(self, stack, wavelength_nm, name, polarization, nodes):
        """Diffuse part, 1/sr: ``f_AB`` (A illumination, B analyser, s or p) or the 16 Mueller
        elements ``GEOM_mIJ`` (Ellis 1996)."""
        import numpy as np

        from ._polarimetry import diffuse_mueller, polarized_brdf

        i, v = self.incidence_deg, self.viewing_deg
        if polarization == "mueller":
            M = np.asarray(diffuse_mueller(stack, wavelength_nm, i, v, nodes=nodes), dtype=float)
            return {f"{name}_m{a}{b}": M[a, b] for a in range(4) for b in range(4)}
        f = np.asarray(polarized_brdf(stack, wavelength_nm, i, v, nodes=nodes), dtype=float)
        a, b = ("sp".index(c) for c in polarization)
        return {f"{name}_{polarization}": f[a, b]}


class Specular(Geometry):
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

    def prediction_columns(self, text):
        """``specular:θ`` gives three columns ``R_θ, T_θ, A_θ``; ``specular:θ:Q`` gives ``Q_θ``."""
        parts = text.split(":")
        angle = parts[1].strip()
        quantities = ("R", "T", "A") if len(parts) == 2 else (self.quantity,)
        return [(f"{q}_{angle}", Specular(self.angle_deg, q)) for q in quantities]


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
            return g
    raise LayerstackError(f"unknown geometry {text!r}: use " + ", ".join(k.spelling for k in _KINDS if k.spelling))


def fixed_optics(stack: Stack, wavelength_nm, geometry: Geometry, *, nodes: int = DEFAULT_NODES) -> Optics:
    """The :class:`Optics` of ``stack`` measured in ``geometry`` on ``wavelength_nm`` (nm).

    Valid for any stack with the same structure, indices and coherent-film thicknesses: only
    thick-layer thicknesses, α and ρg may differ when it is passed to :func:`reflectance`.
    The grid ``wavelength_nm`` ``(wl,)`` must be the one later passed to :func:`reflectance`.
    Returns None for a geometry that reads without optics (an ellipsometer).
    """
    _check_geometry(geometry)
    rs = resolve(stack, wavelength_nm)
    return geometry.optics(rs, isinstance(stack.exit, LambertianBackground), nodes)


def _check_geometry(geometry) -> None:
    if not isinstance(geometry, Geometry):
        raise LayerstackError(f"geometry must be a layerstack_jax Geometry (e.g. Sphere(8.0), parse_geometry('45/0')), "
                              f"got {geometry!r}")


def reflectance(stack: Stack, wavelength_nm, geometry: Geometry, *, nodes: int = DEFAULT_NODES,
                optics: Optional[Optics] = None) -> Float[Array, "*angle wl"]:
    r"""What an instrument of the given geometry reads, for natural light, shaped ``(wl,)``
    (more leading axes ``(*angle, wl)`` if the geometry's angles are arrays) — also for a stack
    of dispersionless media.

    Over a :class:`LambertianBackground` of intrinsic reflectance :math:`\rho_g` and index
    :math:`n_g`, with :math:`T(\theta)` the collimated transmittance of the stack, and
    :math:`r_b, t_b` its diffuse reflectance and transmittance from the background side:

    * :class:`Sphere`: :math:`t_b\,\rho_g T(\theta_0)/(1-\rho_g r_b)` (eqs. 69, 78), plus
      :math:`R(\theta_0)` when the specular component is included;
    * :class:`Directional`: :math:`(n_0/n_g)^2 T(\theta_0) T(\theta_0')\rho_g/(1-\rho_g r_b)` (eqs. 77, 79);
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
    _check_geometry(geometry)
    measured = jnp.asarray(measured)
    unit = eqx.tree_at(lambda st: st.exit.reflectance, stack, 1.0)
    rs = resolve(unit, wavelength_nm)
    A, r_b, prepare = geometry.background_factor(rs, nodes)
    measured = prepare(measured)
    return measured / (A + r_b * measured)
