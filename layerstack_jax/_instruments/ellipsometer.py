r"""The ellipsometer as a measurement geometry: :class:`Ellipsometric` — what it reads of a stack
(one quantity per dataset), with its non-idealities (angle offset, bandwidth, thickness
non-uniformity), how it prints and parses itself and how a fit compares its reading with data —
and the grouping of several readings of one stack that are computed together
(:class:`SharedReadings`, :func:`shared_readings`).

The physics it reads — ψ/Δ, the amplitudes, N, C, S of coherent and of depolarizing stacks,
their bandwidth and thickness averages, and the conventions (the sign of Δ) — is
:mod:`layerstack_jax._instruments.ellipsometry`; the sections "Instrument non-idealities",
"Thick substrates" and "Transmission ellipsometry" that the docstrings below cite as "module
docstring" are that module's.

Fitting ellipsometric data: three residual kinds
------------------------------------------------
:class:`Ellipsometric` is the measurement geometry of a fit (``fitting.Dataset``); its
``quantity`` chooses what is compared with the data, and :meth:`Ellipsometric.residual` how:

* ``'psi'``, ``'delta'`` (degrees): ψ/Δ. The Δ residual is the model−data difference wrapped
  into (−180°, 180°] (:func:`wrap_degrees`): a Δ that crosses ±180° within a spectrum, or
  data reported in [0°, 360°), is compared on the circle, not across a 360° jump.
* ``'N'``, ``'C'``, ``'S'``: the wrap-free combinations :math:`N = \cos 2\psi`,
  :math:`C = \sin 2\psi\cos\Delta`, :math:`S = \sin 2\psi \sin\Delta` (what rotating-compensator
  instruments measure, with the same Δ), smooth everywhere.
* ``'rho_re'``, ``'rho_im'``: real and imaginary parts of
  :math:`\rho = r_p/r_s = \tan\psi\,e^{-i\Delta}` — the library's one ρ convention (the same
  number as :attr:`Ellipsometry.rho`, ``Measurement.rho()`` and pyElli's ``Result.rho``), so
  :math:`\mathrm{Re}\,\rho = \tan\psi\cos\Delta`, :math:`\mathrm{Im}\,\rho = -\tan\psi\sin\Delta`
  with the instruments' Δ. Wrap-free as well; large where ψ → 90°.

Δ, S and Im ρ change sign with Δ (:attr:`Ellipsometric.odd_in_delta`): a file written in the
opposite Δ convention fits far better mirrored, which ``fitting`` reports. The normalized
Mueller matrix of the reflection is
:math:`[[1, -N, 0, 0], [-N, 1, 0, 0], [0, 0, C, S], [0, 0, -S, C]]`, as measured
(:mod:`layerstack_jax._instruments.polarimetry`).
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar, Optional, Sequence, Union

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._base.custom_types import Array, Float, RealLike
from .._base.validate import LayerstackError, check_angle_deg, check_finite, check_nonnegative, is_concrete
from .._stacks.stack import Stack
from .ellipsometry import (
    FWHM_TO_SIGMA,
    GAUSS_NODES,
    MODES,
    EllipsometerReading,
    Ellipsometry,
    averaged_ncs,
    ellipsometry,
    is_coherent,
    psi_delta,
    reading_from_ncs,
    standard_normal_rule,
    transmission_amplitudes,
    wrap_degrees,
)
from .geometry import Geometry

__all__ = ["Ellipsometric", "SharedReadings", "shared_readings"]

#: the quantities an :class:`Ellipsometric` geometry reads (one per dataset)
QUANTITIES = ("psi", "delta", "N", "C", "S", "rho_re", "rho_im", "depolarization")


class Ellipsometric(Geometry):
    r"""An ellipsometer's reading at ``angle_deg`` (degrees), as a measurement geometry: lets
    ψ/Δ spectra be fitted (``fitting.Dataset(Ellipsometric(70, "psi"), data)``).

    ``quantity`` (one per dataset; "Fitting ellipsometric data" in the module docstring):

    * ``'psi'`` or ``'delta'``: degrees, conventions of :func:`ellipsometry`; the Δ residual of
      a fit is wrapped into (−180°, 180°] (:meth:`residual`), so Δ data may cross ±180° or be
      reported in [0°, 360°);
    * ``'N'`` = cos 2ψ, ``'C'`` = sin 2ψ cos Δ, ``'S'`` = sin 2ψ sin Δ (dimensionless, wrap-free);
    * ``'rho_re'``, ``'rho_im'``: Re and Im of ρ = r_p/r_s = tan ψ e^{−iΔ} (dimensionless,
      wrap-free; the convention of :attr:`Ellipsometry.rho` and ``Measurement.rho()``);
    * ``'depolarization'``: :math:`1 - \sqrt{N^2 + C^2 + S^2}` in [0, 1] (0 for an ideal one).

    ``angle_deg``: scalar or array ``(*angle)`` of incidence angles in degrees; :meth:`measure`
    returns ``(*angle, wl)``.

    Non-idealities (module docstring, "Instrument non-idealities"; pytree leaves: differentiable,
    and fittable with ``fitting.instrument``; the defaults are the ideal instrument, read
    exactly as :func:`ellipsometry`):

    * ``angle_offset_deg``: added to every angle (degrees);
    * ``bandwidth_nm``: FWHM of the Gaussian instrument function in wavelength (nm, ≥ 0);
    * ``thickness_spread``: relative Gaussian σ of the thickness of layer ``nonuniform_layer``
      (position or name; dimensionless, ≥ 0, below :math:`1/x_K` — 0.127 with 21 nodes — so
      that every Gauss–Hermite node thickness stays positive);
    * ``average_nodes`` (static): Gauss–Hermite nodes per averaged variable (default 21;
      accuracy in the module docstring).

    ``mode`` (static): ``'reflection'`` (default) or ``'transmission'`` — ψ_t, Δ_t of
    :math:`t_p/t_s` (module docstring, "Transmission ellipsometry").

    Any stack: a stack with thick incoherent layers (a transparent substrate slab and its
    backside) is read as the depolarized incoherent sum of its beams (module docstring, "Thick
    substrates"); a coherent one through its amplitudes.
    """

    angle_deg: RealLike = 70.0
    quantity: str = eqx.field(static=True, default="psi")
    angle_offset_deg: RealLike = 0.0
    bandwidth_nm: RealLike = 0.0
    thickness_spread: RealLike = 0.0
    nonuniform_layer: Optional[Union[int, str]] = eqx.field(static=True, default=None)
    average_nodes: int = eqx.field(static=True, default=GAUSS_NODES)
    mode: str = eqx.field(static=True, default="reflection")

    def __check_init__(self):
        if self.mode not in MODES:
            raise LayerstackError(f"Ellipsometric.mode must be 'reflection' or 'transmission', got {self.mode!r}")
        if self.quantity not in QUANTITIES:
            raise LayerstackError(
                f"Ellipsometric.quantity must be one of {', '.join(map(repr, QUANTITIES))}, got {self.quantity!r}"
            )
        check_angle_deg("Ellipsometric.angle_deg", self.angle_deg)
        check_finite("Ellipsometric.angle_offset_deg (degrees)", self.angle_offset_deg)
        check_nonnegative("Ellipsometric.bandwidth_nm (FWHM, nm)", self.bandwidth_nm)
        check_nonnegative("Ellipsometric.thickness_spread (relative sigma)", self.thickness_spread)
        if not (isinstance(self.average_nodes, int) and self.average_nodes >= 1):
            raise LayerstackError(f"Ellipsometric.average_nodes must be an int >= 1, got {self.average_nodes!r}")
        if is_concrete(self.thickness_spread):
            spread = float(np.max(np.asarray(self.thickness_spread)))
            top = float(np.max(standard_normal_rule(self.average_nodes)[0]))
            if spread * top >= 1.0:
                raise LayerstackError(f"Ellipsometric.thickness_spread = {spread:g}: must stay below {1.0 / top:.4g} "
                                      f"with average_nodes = {self.average_nodes} (a node thickness would be <= 0)")
            if spread > 0 and self.nonuniform_layer is None:
                raise LayerstackError("Ellipsometric.thickness_spread > 0 needs nonuniform_layer (the layer, by "
                                      "position or name, whose thickness spreads)")

    spelling: ClassVar[str] = "ellipsometry:ANGLE:psi|delta|N|C|S|rho_re|rho_im|depolarization[:transmission]"
    signed: ClassVar[bool] = True  # Δ, C, S, Re ρ, Im ρ may be negative
    reading_is_fraction: ClassVar[bool] = False

    def _is_zero(self, name: str) -> bool:
        """True when non-ideality ``name`` is concretely 0 (then it is left out, not averaged)."""
        v = getattr(self, name)
        return is_concrete(v) and not np.any(np.asarray(v))

    @property
    def ideal(self) -> bool:
        """True when every non-ideality is concretely 0: the reading is :func:`ellipsometry`'s."""
        return all(self._is_zero(n) for n in ("angle_offset_deg", "bandwidth_nm", "thickness_spread"))

    def depolarizes(self, stack: Stack) -> bool:
        """True when the reading of ``stack`` is (in general) partly depolarized — thick
        incoherent layers, a bandwidth or a thickness spread (module docstring): its N, C, S
        are then shorter than 1, and ψ, Δ are reported from them (:func:`reading_from_ncs`)."""
        return not is_coherent(stack) or not (self._is_zero("bandwidth_nm") and self._is_zero("thickness_spread"))

    def ellipsometry_angle(self, stack: Stack) -> Optional[float]:
        """The angle (degrees) when this reading is :func:`ellipsometry`'s: the ideal instrument,
        in reflection, on a coherent stack, at one concrete angle (:func:`shared_readings` then
        reads several such geometries with one :func:`ellipsometry` over their angles); else None (transmission, thick layers, non-idealities read through :meth:`reading`)."""
        a = self.angle_deg
        if (self.mode != "reflection" or not is_coherent(stack) or not self.ideal or not is_concrete(a)
                or np.ndim(a) != 0):
            return None
        return float(np.asarray(a))

    def from_ellipsometry(self, e: Ellipsometry):
        """The quantity read, from the ideal instrument's :class:`Ellipsometry` of a coherent
        stack (:func:`ellipsometry` at :meth:`ellipsometry_angle`, or its transmission twin):
        what :meth:`measure` returns for the ideal instrument."""
        if self.quantity in ("rho_re", "rho_im"):
            return jnp.real(e.rho) if self.quantity == "rho_re" else jnp.imag(e.rho)
        if self.quantity == "depolarization":
            return jnp.zeros_like(e.psi_deg)
        return {"psi": e.psi_deg, "delta": e.delta_deg, "N": e.N, "C": e.C, "S": e.S}[self.quantity]

    def reading_group(self) -> Optional[tuple]:
        """``(key, angle)`` for :func:`shared_readings` (readings with equal keys differ only in angle
        and quantity, so one :meth:`reading` over their angles serves them all): the key holds every field but the
        angle and the quantity — the static ones (mode, averaging nodes, non-uniform layer) by
        value, the non-idealities by value when concrete scalars (None counts as 0), else the
        leaf itself by identity (one fitted offset put into several datasets,
        ``fitting.instrument``, groups them; two separate ones do not); None for an angle that
        is traced or not a scalar."""
        a = self.angle_deg
        if not is_concrete(a) or np.ndim(a) != 0:
            return None

        def setting(field):
            x = getattr(self, field.name)
            if field.metadata.get("static", False):
                return x
            if x is None:
                return 0.0
            return float(np.asarray(x)) if is_concrete(x) and np.ndim(x) == 0 else ("leaf", id(x))

        fields = [f for f in dataclasses.fields(self) if f.name not in ("angle_deg", "quantity")]
        return (type(self), *((f.name, setting(f)) for f in fields)), float(np.asarray(a))

    def at_angles(self, angles_deg) -> "Ellipsometric":
        """The same instrument at the angles ``angles_deg`` (degrees, ``(angle,)``), quantity
        unchanged (:meth:`reading_group`)."""
        return eqx.tree_at(lambda g: g.angle_deg, self, np.asarray(angles_deg, dtype=float))

    def from_reading(self, e: EllipsometerReading):
        """The quantity read, from a :meth:`reading` ``e`` (every field ``(*angle, wl)``)."""
        if self.quantity in ("rho_re", "rho_im"):
            t, d = jnp.tan(jnp.deg2rad(e.psi_deg)), jnp.deg2rad(e.delta_deg)
            return t * jnp.cos(d) if self.quantity == "rho_re" else -t * jnp.sin(d)
        return {"psi": e.psi_deg, "delta": e.delta_deg, "N": e.N, "C": e.C, "S": e.S,
                "depolarization": e.depolarization}[self.quantity]

    def _coherent_ellipsometry(self, stack: Stack, wavelength_nm, angle) -> Ellipsometry:
        """The ideal reading of a coherent stack from its amplitudes: :func:`ellipsometry`, or the
        same of :math:`(t_s, t_p)` in transmission."""
        if self.mode == "reflection":
            return ellipsometry(stack, wavelength_nm, angle)
        t_s, t_p = transmission_amplitudes(stack, wavelength_nm, angle)
        psi, delta = psi_delta(t_s, t_p)
        return Ellipsometry(jnp.rad2deg(psi), jnp.rad2deg(delta), t_p / t_s)

    def reading(self, stack: Stack, wavelength_nm) -> EllipsometerReading:
        """ψ, Δ, N, C, S and depolarization read for ``stack`` on ``wavelength_nm`` (nm), every
        field ``(*angle, wl)``: for a coherent stack, the ideal :func:`ellipsometry` (its
        transmission twin with ``mode='transmission'``); with a bandwidth or a thickness spread,
        or for a stack with thick incoherent layers (module docstring, "Thick substrates"), the
        (averaged) :func:`stack_ncs` reported by :func:`reading_from_ncs`."""
        angle = self.angle_deg if self._is_zero("angle_offset_deg") else (
            jnp.asarray(self.angle_deg) + self.angle_offset_deg)
        band, spread = not self._is_zero("bandwidth_nm"), not self._is_zero("thickness_spread")
        if not self.depolarizes(stack):
            e = self._coherent_ellipsometry(stack, wavelength_nm, angle)
            return EllipsometerReading(e.psi_deg, e.delta_deg, e.N, e.C, e.S, jnp.zeros_like(e.psi_deg))
        N, C, S = averaged_ncs(stack, wavelength_nm, angle, bandwidth_nm=self.bandwidth_nm,
                               thickness_spread=self.thickness_spread, nonuniform_layer=self.nonuniform_layer,
                               average_wavelength=band, average_thickness=spread, nodes=self.average_nodes,
                               mode=self.mode)
        return reading_from_ncs(N, C, S)

    def measure(self, stack: Stack, wavelength_nm, *, nodes: int = 0, optics=None) -> Float[Array, "*angle wl"]:
        """The quantity read for ``stack`` on ``wavelength_nm`` (nm); ``nodes`` and ``optics``
        are not used (an ellipsometer reads amplitudes, not the cached intensities)."""
        if self.ideal and is_coherent(stack):  # the amplitudes' ratio itself (reflection or transmission)
            return self.from_ellipsometry(self._coherent_ellipsometry(stack, wavelength_nm, self.angle_deg))
        return self.from_reading(self.reading(stack, wavelength_nm))

    def wavelengths_read(self, wavelength_nm) -> np.ndarray:
        """The grid, widened by the outermost wavelength nodes of the bandwidth average
        (:func:`averaged_ncs`: λ ± σ_λ x_max of :func:`standard_normal_rule`) when the bandwidth
        is concretely > 0 — where the material tables must have data."""
        grid = np.asarray(wavelength_nm, dtype=float)
        if self._is_zero("bandwidth_nm") or not is_concrete(self.bandwidth_nm):
            return grid
        reach = FWHM_TO_SIGMA * float(np.max(self.bandwidth_nm)) * float(np.max(standard_normal_rule(self.average_nodes)[0]))
        return np.concatenate([grid - reach, grid + reach])

    def residual(self, model, data):
        """Model − data; for ``'delta'`` wrapped into (−180°, 180°] by :func:`wrap_degrees`
        (derivative 1 in ``model``, NaN-free), so that Δ = 179° against data −179° is a 2° miss."""
        if self.quantity == "delta":
            return wrap_degrees(model - data)
        return model - data

    @property
    def odd_in_delta(self) -> bool:
        """True when the reading changes sign with Δ (Δ, S, Im ρ): data written in the opposite
        Δ convention are these readings negated (ψ, N, C, Re ρ are even in Δ)."""
        return self.quantity in ("delta", "S", "rho_im")

    # the Geometry interface: an ellipsometer needs no Optics (it overrides measure)
    @property
    def label(self) -> str:
        a = self.angle_deg
        text = f"{float(a):g}" if is_concrete(a) and jnp.ndim(a) == 0 else "array"
        return f"ellipsometry:{text}:{self.quantity}" + (":transmission" if self.mode == "transmission" else "")

    @property
    def quantity_label(self) -> str:
        if self.mode == "transmission":
            return "transmission " + self._quantity_label()
        return self._quantity_label()

    def _quantity_label(self) -> str:
        return {"psi": "psi (degrees)", "delta": "Delta (degrees)", "N": "N = cos 2psi", "C": "C = sin 2psi cos Delta",
                "S": "S = sin 2psi sin Delta", "rho_re": "Re rho = tan psi cos Delta",
                "rho_im": "Im rho = -tan psi sin Delta",
                "depolarization": "depolarization = 1 - sqrt(N^2 + C^2 + S^2)"}[self.quantity]

    @classmethod
    def parse(cls, text: str):
        """``ellipsometry:ANGLE:QUANTITY[:MODE]`` (QUANTITY psi, delta, N, C, S, rho_re, rho_im or depolarization,
        default psi; MODE reflection, the default, or transmission; case-insensitive), e.g.
        ``ellipsometry:70:psi``, ``ellipsometry:30:delta:transmission``."""
        if not text.startswith("ellipsometry"):
            return None
        parts = text.split(":")
        if not 2 <= len(parts) <= 4:
            raise ValueError(text)
        q = parts[2] if len(parts) > 2 else "psi"
        q = q.lower()
        q = q if q in ("psi", "delta", "rho_re", "rho_im", "depolarization") else q.upper()
        mode = parts[3].lower() if len(parts) > 3 else "reflection"
        if mode not in MODES:
            raise LayerstackError(f"{text!r}: the ellipsometer's mode is 'reflection' or 'transmission', got {parts[3]!r}")
        return cls(float(parts[1]), q, mode=mode)


class SharedReadings:
    """Readings of several geometries of one stack that are computed together
    (:func:`shared_readings`): ideal single-angle ellipsometer readings by one
    :func:`ellipsometry` over their angles, other single-angle readings of one ellipsometer (a
    thick substrate, transmission, non-idealities) by one :meth:`Ellipsometric.reading` over their
    angles. The same per-angle arithmetic as each geometry's own ``measure``; a compiled fit then
    holds one copy of the model per instrument instead of one per dataset."""

    def __init__(self, geometries: tuple, angles: list, ellipsometry_angle: dict, members: dict, groups: dict):
        self._geometries = geometries
        #: the angles (degrees) read by one :func:`ellipsometry` (empty: none shared)
        self.angles = angles
        self._angle = ellipsometry_angle
        self._members = members
        self._groups = groups

    @property
    def indices(self) -> frozenset:
        """The positions of the geometries read here (the others read themselves)."""
        shared = {i for i, a in self._angle.items() if a is not None} if self.angles else set()
        return frozenset(shared | set(self._members))

    def read(self, stack: Stack, wavelength_nm) -> dict:
        """``{position: reading (*angle, wl)}`` of the geometries in :attr:`indices`."""
        out = {}
        if self.angles:
            e = ellipsometry(stack, wavelength_nm, np.asarray(self.angles))
            for i, a in self._angle.items():
                if a is not None:
                    out[i] = self._geometries[i].from_ellipsometry(e)[self.angles.index(a)]
        readings = {key: self._geometries[first].at_angles(a).reading(stack, wavelength_nm)
                    for key, (first, a) in self._groups.items()}
        for i, (key, a) in self._members.items():
            out[i] = self._geometries[i].from_reading(readings[key])[self._groups[key][1].index(a)]
        return out


def shared_readings(geometries: Sequence[Optional[Geometry]], stack: Stack) -> SharedReadings:
    """Which of ``geometries`` (None: a position to leave alone) read ``stack`` together
    (:class:`SharedReadings`): two or more ideal single-angle ellipsometers in reflection on a
    coherent stack share one :func:`ellipsometry` over their angles
    (:meth:`Ellipsometric.ellipsometry_angle`); two or more readings of one ellipsometer that
    differ only in angle and quantity share one :meth:`Ellipsometric.reading`
    (:meth:`Ellipsometric.reading_group`). Decided from the concrete angles, once per model
    structure (``fitting.Objective`` calls it once)."""
    geometries = tuple(geometries)
    angle = {i: g.ellipsometry_angle(stack) for i, g in enumerate(geometries) if isinstance(g, Ellipsometric)}
    angles = sorted({a for a in angle.values() if a is not None})
    if sum(a is not None for a in angle.values()) < 2:
        angles = []  # nothing to share: each reads itself
    found = {i: geometries[i].reading_group() for i, a in angle.items() if a is None}
    found = {i: kg for i, kg in found.items() if kg is not None}
    keys = [kg[0] for kg in found.values()]
    members = {i: kg for i, kg in found.items() if keys.count(kg[0]) >= 2}
    groups = {}
    for i, (key, _) in members.items():
        if key not in groups:
            groups[key] = (i, sorted({a for k, a in members.values() if k == key}))
    return SharedReadings(geometries, angles, angle, members, groups)
