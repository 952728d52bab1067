r"""Kubelka–Munk scattering bodies (paint, ink, paper) as the exit medium of a stack.

A paint layer scatters: light that crossed the binder interface into it is redistributed over
all directions and comes back diffuse. That is exactly the body Simonot et al. §4 put under a
stack, of binder index :math:`n_g` and *internal* diffuse reflectance :math:`\rho_g`. A
Kubelka–Munk body computes that :math:`\rho_g(\lambda)` from its absorption and scattering, and
everything above it — the binder interface, a varnish, films, the instrument's geometry — stays
the library's exact machinery (:class:`KubelkaMunk` is an :class:`~layerstack_jax.ExitMedium`).
With no layer on top, the library's reading *is* Saunderson's formula (Saunderson 1942) with
:math:`k_1` the external Fresnel reflectance at the instrument's angle and :math:`k_2` the
hemispherical internal reflectance of the binder interface (docs/physics.md, §"Scattering
bodies").

Two-flux model (Kubelka & Munk 1931; Kubelka 1948, eqs. 1–2). Depth z from the top of a body of
thickness X, downward diffuse flux I, upward J, absorption K and scattering S per nm:

.. math::
    \frac{dI}{dz} = -(K+S)\,I + S\,J,\qquad -\frac{dJ}{dz} = -(K+S)\,J + S\,I,
    \qquad J(X) = R_g\,I(X).

Kubelka's hyperbolic solution (Kubelka 1948, eqs. 6–7, with :math:`a = 1 + K/S`,
:math:`b = \sqrt{a^2-1}`):

.. math::
    R = \frac{1 - R_g\,(a - b\coth bSX)}{a - R_g + b\coth bSX},\qquad
    T = \frac{b}{a\sinh bSX + b\cosh bSX},\qquad R_\infty = a - b.

Computed here in a form with no quotient by S or by :math:`bS` (docs/physics.md): with
:math:`\sigma = bS = \sqrt{K(K+2S)}` and :math:`\tau = \tanh(\sigma X)/\sigma`,

.. math::
    R = \frac{R_g + (S - R_g(S+K))\,\tau}{1 + (S + K - R_g S)\,\tau},\qquad
    \frac{I(X)}{I(0)} = \frac{\operatorname{sech}\sigma X}{1 + (S + K - R_g S)\,\tau},
    \qquad R_\infty = \frac{S}{S + K + \sigma}.

:math:`\tau` and :math:`\operatorname{sech}\sigma X` are analytic in :math:`u = \sigma^2`, so they
are evaluated as functions of u (a short series below :math:`uX^2 < 10^{-4}`, a double ``where``
keeping the other branch's gradient finite): values and gradients stay finite for S → 0 (pure
absorber, :math:`R \to R_g e^{-2KX}`, :math:`T = e^{-KX}`), K → 0 (white:
:math:`R = (R_g + SX(1-R_g))/(1 + SX(1-R_g))`), X → 0 (:math:`R \to R_g`), large SX or KX (no
overflow: tanh and sech only), and ``thickness=None`` (opaque, :math:`R_\infty`).

The diffuse fluxes of the two-flux model decay as :math:`e^{-KX}` per pass in a body without
scattering, so a round trip gives :math:`R_g e^{-2KX}`; for a Lambertian flux in a medium of
absorption coefficient α the mean path per unit thickness is 2, so :math:`K \approx 2\alpha` (the
exact diffuse transmittance is :math:`2E_3(\alpha X)`, which the two-flux model replaces by an
exponential). Light enters from the binder interface already diffuse in this model; the
collimated part of a 45°/0° or 8° illumination inside the first scattering lengths is what a
four-flux model would add (docs/physics.md).

Layering (Kubelka 1954, eq. 6 there): a body 1 over a body 2 (no interface between them) reflects
:math:`R_{12} = R_1 + T_1^2 R_2/(1 - R_1 R_2)` and transmits :math:`T_{12} = T_1T_2/(1-R_1R_2)`;
for a homogeneous body this equals the hyperbolic R with :math:`R_g = R_2`, which is how a
:class:`PaintLayer` over a :class:`PaintLayer` is evaluated (:func:`layered` is the formula).

Mixtures (Duncan 1940): the absorption and scattering of a mixture are the concentration-weighted
sums of its pigments' :math:`K = \sum_i c_i K_i`, :math:`S = \sum_i c_i S_i` (:class:`Mixture`);
linear in K and S, not in K/S. The single-constant form (one ratio K/S per pigment, S of the
white alone) is the special case of pigments that do not scatter but the white.

Units: K and S in 1/nm, thickness in nm (the library's units: only KX and SX matter); reflectances
and concentrations dimensionless.
"""

from __future__ import annotations

from typing import ClassVar, Optional, Union

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._base.custom_types import RealLike, RealSpectrumLike
from .._base.leaves import leaf
from .._base.validate import LayerstackError, check_nonnegative, check_unit_interval, is_concrete
from .._media.materials import Material, as_material
from .stack import ExitMedium, as_spectrum

__all__ = ["Paint", "Mixture", "PaintLayer", "KubelkaMunk", "km_reflectance", "km_transmittance",
           "km_r_infinity", "layered", "k_over_s"]

#: Below this :math:`uX^2 = (\sigma X)^2` the series of tanh(σX)/σ and sech σX are used: their
#: first neglected terms are below 1e-17 relative there.
_SERIES = 1e-4


def _tau_sech(u, X):
    r""":math:`(\tanh(\sqrt u X)/\sqrt u,\ \operatorname{sech}(\sqrt u X))` for ``u`` ≥ 0 (1/nm²), ``X`` ≥ 0 (nm).

    Both are analytic in u: near :math:`v = uX^2 = 0` the series
    :math:`\tau = X(1 - v/3 + 2v^2/15 - 17v^3/315)`,
    :math:`\operatorname{sech} = 1 - v/2 + 5v^2/24 - 61v^3/720`; elsewhere the closed forms on a
    ``u`` kept away from 0 (double ``where``: the unused branch sees no 0 and no 0/0 in its gradient).
    sech is written :math:`2e^{-y}/(1+e^{-2y})`: no overflow for large y."""
    v = u * X * X
    small = v < _SERIES
    vs = jnp.where(small, v, 0.0)
    tau_series = X * (1.0 - vs / 3.0 + vs * vs * (2.0 / 15.0) - vs**3 * (17.0 / 315.0))
    sech_series = 1.0 - vs / 2.0 + vs * vs * (5.0 / 24.0) - vs**3 * (61.0 / 720.0)
    u_safe = jnp.where(small, 1.0, u)
    X_safe = jnp.where(small, 1.0, X)
    sigma = jnp.sqrt(u_safe)
    y = sigma * X_safe
    e = jnp.exp(-2.0 * y)
    tau_closed = jnp.tanh(y) / sigma
    sech_closed = 2.0 * jnp.exp(-y) / (1.0 + e)
    return jnp.where(small, tau_series, tau_closed), jnp.where(small, sech_series, sech_closed)


def _u(K, S):
    r""":math:`\sigma^2 = (bS)^2 = K(K + 2S)` (1/nm²): Kubelka's :math:`b^2 S^2 = ((S+K)^2 - S^2)`."""
    return K * (K + 2.0 * S)


def km_reflectance(K, S, X, Rg=0.0):
    r"""Diffuse reflectance of a Kubelka–Munk body over a ground (Kubelka 1948, eq. 6).

    Args:
        K, S: absorption and scattering coefficients of the two-flux model (1/nm, ≥ 0).
        X: thickness (nm, ≥ 0).
        Rg: diffuse reflectance of the ground under it (dimensionless, in [0, 1]).

    Returns :math:`R = \frac{R_g + (S - R_g(S+K))\tau}{1 + (S+K-R_gS)\tau}`,
    :math:`\tau = \tanh(\sigma X)/\sigma`, :math:`\sigma = \sqrt{K(K+2S)}` — Kubelka's
    :math:`\frac{1 - R_g(a - b\coth bSX)}{a - R_g + b\coth bSX}` multiplied through by
    :math:`S\tanh(bSX)/(bS)` (module docstring); all arguments broadcast together."""
    K, S, X, Rg = (jnp.asarray(a) for a in (K, S, X, Rg))
    tau, _ = _tau_sech(_u(K, S), X)
    return (Rg + (S - Rg * (S + K)) * tau) / (1.0 + (S + K - Rg * S) * tau)


def km_transmittance(K, S, X, Rg=0.0):
    r"""Diffuse flux reaching the ground, :math:`I(X)/I(0)`, of a Kubelka–Munk body over a
    ground of reflectance ``Rg`` (units as :func:`km_reflectance`); for ``Rg = 0`` Kubelka's
    transmittance :math:`T = b/(a\sinh bSX + b\cosh bSX)` (Kubelka 1948, eq. 7), here
    :math:`\operatorname{sech}(\sigma X)/(1 + (S + K - R_g S)\tau)`. With a ground it equals
    :math:`T/(1 - R_0R_g)` (:math:`R_0` the reflectance over black: the interreflections)."""
    K, S, X, Rg = (jnp.asarray(a) for a in (K, S, X, Rg))
    tau, sech = _tau_sech(_u(K, S), X)
    return sech / (1.0 + (S + K - Rg * S) * tau)


def km_r_infinity(K, S):
    r"""Reflectance of an opaque body, :math:`R_\infty = a - b = 1 + K/S - \sqrt{(K/S)^2 + 2K/S}`
    (Kubelka 1948, eq. 8), as :math:`S/(S + K + \sqrt{K(K+2S)})` (no cancellation; 0 where
    K = S = 0, a body that neither absorbs nor scatters has no defined R∞: the light never comes
    back). Its derivative in K is infinite at K = 0 (:math:`R_\infty \approx 1 - \sqrt{2K/S}`): for
    u = K(K + 2S) below the square root of the smallest normal number the root is held at that
    floor, so the gradient there is finite (that of :math:`S/(S + K)`) instead of infinite.
    A finite thickness has no such singularity (:func:`km_reflectance` is analytic in K)."""
    K, S = jnp.asarray(K), jnp.asarray(S)
    u = _u(K, S)
    tiny = jnp.finfo(jnp.result_type(u, float)).tiny ** 0.5
    den = S + K + jnp.sqrt(jnp.maximum(u, tiny))
    ok = den > 0
    return jnp.where(ok, S / jnp.where(ok, den, 1.0), 0.0)


def k_over_s(r_infinity):
    r"""The Kubelka–Munk function :math:`K/S = (1 - R_\infty)^2 / (2R_\infty)` (Kubelka 1948, eq. 9),
    the single-constant inverse of :func:`km_r_infinity`."""
    r = jnp.asarray(r_infinity)
    return (1.0 - r) ** 2 / (2.0 * r)


def layered(R1, T1, R2, T2=0.0):
    r"""Kubelka's layering rule (Kubelka 1954): body 1 over body 2, in contact (no interface),
    each homogeneous (the same R and T from both sides). Returns
    :math:`(R_1 + T_1^2R_2/(1-R_1R_2),\ T_1T_2/(1-R_1R_2))`, dimensionless."""
    d = 1.0 - R1 * R2
    return R1 + T1 * T1 * R2 / d, T1 * T2 / d


class Paint(eqx.Module):
    r"""The two Kubelka–Munk constants of one scattering material.

    Attributes:
        absorption: K(λ), 1/nm, ≥ 0 — scalar, ``(wl,)`` on the model grid, or a callable spectrum
            (:class:`~layerstack_jax.TabulatedSpectrum`).
        scattering: S(λ), 1/nm, ≥ 0, same forms.
        name: label (a pigment's name).
    """

    absorption: RealSpectrumLike = leaf(spectral=True, per_wavelength=True, file_key="K_per_nm")
    scattering: RealSpectrumLike = leaf(spectral=True, per_wavelength=True, file_key="S_per_nm")
    name: str = eqx.field(static=True, default="")

    def __check_init__(self):
        for what, x in (("absorption K (1/nm)", self.absorption), ("scattering S (1/nm)", self.scattering)):
            if not callable(x):
                check_nonnegative(f"{self.name or 'paint'}: {what}", x)

    def file_table(self) -> dict:
        """Its entries in a stack file's ``[kubelka_munk]`` table (the inverse of the reader):
        ``K_per_nm``, ``S_per_nm`` and the values as held."""
        return {"K_per_nm": self.absorption, "S_per_nm": self.scattering}

    def constants(self, wavelength_nm):
        """``(K, S)`` on ``wavelength_nm`` (nm), each broadcastable to ``(*batch, wl)``, 1/nm."""
        label = self.name or "paint"
        return (check_nonnegative(f"{label}: absorption K (1/nm)", as_spectrum(self.absorption, wavelength_nm)),
                check_nonnegative(f"{label}: scattering S (1/nm)", as_spectrum(self.scattering, wavelength_nm)))


class Mixture(eqx.Module):
    r"""Duncan's two-constant mixture (Duncan 1940): :math:`K = \sum_i c_i K_i`,
    :math:`S = \sum_i c_i S_i`.

    Attributes:
        concentrations: :math:`c_i`, dimensionless, ≥ 0, shape ``(pigment,)`` (batched:
            ``(*batch, pigment)``). Whether they sum to one is the user's choice (a fit may free
            them all, or fix one): the mixture is linear in them either way.
        pigments: one :class:`Paint` per pigment, its K and S per unit concentration.
    """

    concentrations: RealLike = leaf(file_key="concentrations")
    pigments: tuple = eqx.field(converter=tuple)

    def __check_init__(self):
        if not self.pigments or not all(isinstance(p, Paint) for p in self.pigments):
            raise LayerstackError("Mixture: pigments must be a non-empty sequence of Paint")
        if is_concrete(self.concentrations):
            shape = jnp.shape(self.concentrations)
            if not shape or shape[-1] != len(self.pigments):
                raise LayerstackError(f"Mixture: concentrations must have {len(self.pigments)} values (one per "
                                      f"pigment) on their last axis, got shape {shape}")
            check_nonnegative("Mixture: concentrations", self.concentrations)

    def file_table(self) -> dict:
        """Its entries in a stack file's ``[kubelka_munk]`` table: one ``[[kubelka_munk.pigments]]``
        table per pigment (name, K, S, concentration); needs concrete concentrations of one mixture."""
        c = np.asarray(self.concentrations, dtype=float)
        if c.ndim != 1:
            raise LayerstackError(f"Mixture: a stack file holds one mixture (concentrations of shape "
                                  f"(pigment,)), got shape {c.shape}")
        return {"pigments": [{"name": p.name or f"pigment {i + 1}", **p.file_table(), "concentration": float(ci)}
                             for i, (p, ci) in enumerate(zip(self.pigments, c))]}

    def constants(self, wavelength_nm):
        """``(K, S)`` of the mixture on ``wavelength_nm`` (nm), 1/nm."""
        c = check_nonnegative("Mixture: concentrations", jnp.asarray(self.concentrations))
        K = S = 0.0
        for i, p in enumerate(self.pigments):
            Ki, Si = p.constants(wavelength_nm)
            ci = c[..., i:i + 1]  # (*batch, 1): broadcasts against (wl,)
            K, S = K + ci * Ki, S + ci * Si
        return K, S


class PaintLayer(eqx.Module):
    r"""A Kubelka–Munk body without an interface on top: a paint (or a mixture) of thickness X
    over a ground, which is a diffuse reflectance :math:`R_g(\lambda)` or another
    :class:`PaintLayer` (Kubelka's layering: paint on ground on canvas).

    Attributes:
        paint: a :class:`Paint` (K, S) or a :class:`Mixture` of paints.
        thickness: X in nm (≥ 0), scalar or broadcastable to ``(*batch, wl)``; None: opaque
            (:math:`R = R_\infty`, the ground unseen).
        ground: :math:`R_g` in [0, 1] (scalar, ``(wl,)``, a callable spectrum) or a
            :class:`PaintLayer`.
    """

    paint: Union[Paint, Mixture]
    thickness: Optional[RealLike] = leaf(spectral=True, file_key="thickness_nm", default=None)
    ground: Union[RealSpectrumLike, "PaintLayer"] = leaf(spectral=True, per_wavelength=True,
                                                         file_key="ground_reflectance", default=0.0)

    def __check_init__(self):
        if not isinstance(self.paint, (Paint, Mixture)):
            raise LayerstackError(f"a Kubelka–Munk body's paint must be a Paint or a Mixture, got {self.paint!r}")
        if self.thickness is not None:
            check_nonnegative("Kubelka-Munk body: thickness (nm)", self.thickness)
        if not (callable(self.ground) or isinstance(self.ground, PaintLayer)):
            check_unit_interval("Kubelka-Munk body: ground reflectance", self.ground)

    def reflectance(self, wavelength_nm):
        r"""Diffuse reflectance R(λ) of the body over its ground (:func:`km_reflectance`, or
        :func:`km_r_infinity` when opaque), dimensionless, broadcastable to ``(*batch, wl)``."""
        K, S = self.paint.constants(wavelength_nm)
        if self.thickness is None:
            return km_r_infinity(K, S)
        if isinstance(self.ground, PaintLayer):
            Rg = self.ground.reflectance(wavelength_nm)
        else:
            Rg = check_unit_interval("Kubelka-Munk body: ground reflectance", as_spectrum(self.ground, wavelength_nm))
        X = check_nonnegative("Kubelka-Munk body: thickness (nm)", jnp.asarray(self.thickness))
        return km_reflectance(K, S, X, Rg)

    def transmittance(self, wavelength_nm):
        """Diffuse transmittance of the body alone (over black), dimensionless (0 when opaque)."""
        K, S = self.paint.constants(wavelength_nm)
        if self.thickness is None:
            return jnp.zeros_like(K + S)
        return km_transmittance(K, S, jnp.asarray(self.thickness))


class KubelkaMunk(ExitMedium):
    r"""A Kubelka–Munk scattering body as the exit medium: the binder of index ``index`` holds a
    paint of two-flux constants K, S (or a Duncan mixture), thickness X, over a ground. It lowers
    to the internal diffuse reflectance :math:`\rho_g = R_\text{KM}(K, S, X, R_g)` (module
    docstring) under the binder interface; that interface, varnishes and films above it are the
    stack's.

    Attributes:
        index: the binder's index :math:`n_g` (real): material or number.
        paint: a :class:`Paint` or a :class:`Mixture`.
        thickness: X in nm, or None for an opaque body.
        ground: :math:`R_g(\lambda)` in [0, 1], or a :class:`PaintLayer` under this one.

    Every number but the binder's index changes only ρg: fitting K, S, X, concentrations or the
    ground keeps the Fresnel algebra fixed (:func:`~layerstack_jax.fixed_optics`).
    """

    index: Material = leaf(converter=as_material)
    paint: Union[Paint, Mixture] = leaf(fixed_optics=True)
    thickness: Optional[RealLike] = leaf(spectral=True, fixed_optics=True, file_key="thickness_nm", default=None)
    ground: Union[RealSpectrumLike, PaintLayer] = leaf(spectral=True, fixed_optics=True, per_wavelength=True,
                                                       file_key="ground_reflectance", default=0.0)
    diffuse: ClassVar[bool] = True
    table: ClassVar[str] = "kubelka_munk"
    label: ClassVar[str] = "Kubelka-Munk body"

    def __check_init__(self):
        PaintLayer(self.paint, self.thickness, self.ground)  # the same checks

    def body(self) -> PaintLayer:
        """The body without its binder interface."""
        return PaintLayer(self.paint, self.thickness, self.ground)

    def lower(self, wavelength_nm):
        return self.body().reflectance(wavelength_nm)
