r"""The integrating sphere (Simonot et al. eqs. 69, 78): :class:`Sphere`, specular component
included or excluded, with the instrument as built (specular port cone, sphere multiplier of wall
and ports, cover glass; :mod:`layerstack_jax._instruments.instrument`).
"""

from __future__ import annotations

from typing import ClassVar, Optional

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._base.custom_types import RealLike, RealSpectrumLike
from .._base.validate import (
    LayerstackError,
    check_angle_deg,
    check_unit_interval,
    is_concrete,
)
from .._stacks.illumination import (
    _snell,
    diffuse_resolved,
)
from .._stacks.recursion import join_interfaces, natural, stack_intensities
from .._stacks.stack import as_spectrum
from .geometry import OpticalGeometry
from .instrument import DEFAULT_CONE_NODES, check_cone, substituted_reading
from .optical_parts import (
    _COVER_DEFAULTS,
    _COVER_FLAGS,
    _COVER_OPTIONS,
    _back_hemisphere,
    _check_cover,
    _cone_interfaces,
    _cone_T,
    _covered,
    _diffuse_back,
    _incidence,
    _is_zero,
    _optics,
    _option_text,
    _options,
    _port_escape,
    _scalar_text,
    _stale_optics,
)


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
