r"""Directional geometries: the 45°/0° reflectance factor :class:`Directional` (Simonot eqs. 77,
79) and the :class:`BRDF` (eq. 76: the same divided by π), with finite apertures and a cover glass.
"""

from __future__ import annotations

from typing import ClassVar, Optional

import equinox as eqx
import jax.numpy as jnp

from .._base.custom_types import RealLike, RealSpectrumLike
from .._base.validate import (
    LayerstackError,
    check_angle_deg,
)
from .._kernels.fresnel import exit_medium_ratio
from .._stacks.illumination import (
    diffuse_resolved,
    natural_T_front,
)
from .._stacks.recursion import join_interfaces, natural
from .geometry import OpticalGeometry
from .instrument import DEFAULT_CONE_NODES, check_cone
from .optical_parts import (
    _APERTURES,
    _COVER_DEFAULTS,
    _COVER_FLAGS,
    _COVER_OPTIONS,
    _aperture_mean,
    _back_hemisphere,
    _check_apertures,
    _check_cover,
    _cone_interfaces,
    _cone_mean,
    _cone_T,
    _covered,
    _diffuse_back,
    _incidence,
    _is_zero,
    _optics,
    _option_text,
    _options,
    _scalar_text,
    _substrate_has_no_diffuse_light,
)
from .optics import Optics


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


